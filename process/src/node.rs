//! The process's iceoryx2 node, with one clear line instead of iceoryx2's `InternalError` when
//! the shared iceoryx2 directories belong to another user (docs/security.md).
//!
//! iceoryx2 0.10 keeps every node's and service's files under one root directory
//! (`/tmp/iceoryx2/` by default) whose subdirectories it creates `rwxr-x---`; a second user on
//! the machine can then create no node at all, and iceoryx2 reports that as an internal
//! error. The way out is the user's own root (and file prefix) in an iceoryx2 config file,
//! which this module's message names.

use anyhow::{anyhow, Result};
use estpipe_wire::ContractError;
use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// The node name of both sides of a bridge (`ipc-runner bridge`, `estpipe_bridge`). The
/// runner tells by it that its slot publisher is a bridge's estimator side, a relay that may go
/// away and come back with the same stream (docs/bridge.md, "A bridge that goes away"); it is
/// here, beneath both, so that a runner built without the bridge knows it too.
pub const BRIDGE_NODE_NAME: &str = "estpipe-bridge";

/// Creates this process's node named `name` (`"channel-sim"`, `"ipc-runner"`,
/// [`BRIDGE_NODE_NAME`]).
pub fn create(name: &str) -> Result<Node<ipc::Service>> {
    let node_name = NodeName::new(name).map_err(|e| anyhow!("node name {name:?}: {e:?}"))?;
    NodeBuilder::new()
        .name(&node_name)
        .create::<ipc::Service>()
        .map_err(|e| match foreign_directory() {
            // Exit code 2: the environment, not the product, is at fault.
            Some(why) => {
                ContractError::Refused(format!("cannot create iceoryx2 node: {why}")).into()
            }
            None => anyhow!("cannot create iceoryx2 node: {e:?}"),
        })
}

/// The iceoryx2 root, node and service directories of the global config (the one every node
/// of this process uses).
pub fn directories() -> [PathBuf; 3] {
    let g = &Config::global_config().global;
    [
        PathBuf::from(g.root_path().to_string()),
        PathBuf::from(g.node_dir().to_string()),
        PathBuf::from(g.service_dir().to_string()),
    ]
}

/// The uid this process runs as (`/proc/self` belongs to the effective uid).
fn my_uid() -> Option<u32> {
    std::fs::metadata("/proc/self").ok().map(|m| m.uid())
}

/// Why an iceoryx2 directory is not usable by this user, as one sentence with the remedy;
/// `None` when every existing one is ours (or we are root).
pub fn foreign_directory() -> Option<String> {
    let me = my_uid()?;
    if me == 0 {
        return None;
    }
    directories()
        .iter()
        .find_map(|d| not_ours(d, me).map(|owner| (d.clone(), owner)))
        .map(|(dir, owner)| {
            format!(
                "the iceoryx2 directory {} belongs to uid {owner}, not to you (uid {me}), and \
                 iceoryx2 cannot share it between users; give yourself an iceoryx2 root of your \
                 own: a config file config/iceoryx2.toml (in the working directory) or \
                 ~/.config/iceoryx2/iceoryx2.toml with [global] root-path = \"/tmp/iceoryx2-{me}/\" \
                 and prefix = \"iox2_{me}_\", the same for every process of the pipeline (see \
                 docs/security.md)",
                dir.display()
            )
        })
}

/// The owner of `dir` if it exists, is someone else's and we may not write into it.
fn not_ours(dir: &Path, me: u32) -> Option<u32> {
    let m = std::fs::metadata(dir).ok()?;
    if m.uid() == me {
        return None;
    }
    // Writable by everyone (iceoryx2's `dev_permissions` builds): usable, if not private.
    let everyone_writes = m.mode() & 0o003 == 0o003;
    (!everyone_writes).then_some(m.uid())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_directory_of_another_user_is_named_with_its_owner_and_ours_is_not() {
        let own = std::env::temp_dir();
        let me = my_uid().unwrap();
        // The temporary directory is world-writable (sticky): never "not ours".
        assert_eq!(not_ours(&own, me.wrapping_add(1)), None);
        // `/` belongs to root and is not world-writable: foreign for anyone else.
        if me != 0 {
            assert_eq!(not_ours(Path::new("/"), me), Some(0));
        } else {
            assert_eq!(not_ours(Path::new("/"), 12345), Some(0));
            assert_eq!(not_ours(Path::new("/"), 0), None);
        }
        assert_eq!(not_ours(Path::new("/nonexistent-estpipe"), me), None);
    }
}
