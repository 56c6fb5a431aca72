//! The plumbing every process of the pipeline shares (`channel-sim`, `ipc-runner` and its
//! subcommands, the bridge), beneath the simulator, the runner and the bridge so that none of
//! them imports another for it:
//!
//! | module | what |
//! |---|---|
//! | [`console`] | [`out!`], [`outln!`], [`errln!`]: lines a broken pipe cannot kill; one-line messages; iceoryx2's log level |
//! | [`signal`] | SIGINT, SIGTERM, SIGHUP, SIGXCPU as a flag that stays set; every other signal harmless |
//! | [`flags`] | checked command-line values (no `nan` seconds) and [`flags::BadInput`], the mark of input that exits with code 2 |
//! | [`node`] | the process's iceoryx2 node, and one clear line when the iceoryx2 directories belong to another user |

pub mod console;
pub mod flags;
pub mod node;
pub mod signal;
