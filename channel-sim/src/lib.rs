//! Plants, sensors and channel models that turn the papers' numerical examples into sample
//! streams, plus the wire format shared with `ipc-runner`.
