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
//! | [`address_space`] | the address-space limit (`ulimit -v`): what it leaves, one heap for every thread under it |
//! | [`shm_leftovers`] | the data segment a failed port creation left in `/dev/shm`, removed |
//! | [`whole_file`] | a report file written whole or not at all (temporary file renamed over it) |

pub mod address_space;
pub mod console;
pub mod flags;
pub mod node;
pub mod shm_leftovers;
pub mod signal;
pub mod whole_file;
