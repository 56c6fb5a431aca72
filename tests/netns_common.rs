//! Two network namespaces joined by a veth pair, for the tests of links between hosts
//! (`pipeline_lossy_link`, `pipeline_congested_link`): each test process makes its own pair,
//! removed on drop and, from runs that crashed, at the next start. Root, `ip netns` and a
//! veth are needed; without them [`Netns::pair`] says why and the test skips.

#![allow(dead_code)] // each test uses what it needs

use std::path::Path;

use crate::common::{self, Proc};

/// The address of namespace A's end.
pub const ADDR_A: &str = "10.77.0.1";
/// The address of namespace B's end.
pub const ADDR_B: &str = "10.77.0.2";

/// Runs `args`: its stdout, or one line naming the command and its stderr.
pub fn sh(args: &[&str]) -> Result<String, String> {
    let out = std::process::Command::new(args[0])
        .args(&args[1..])
        .output()
        .map_err(|e| format!("{}: {e}", args.join(" ")))?;
    if out.status.success() {
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    } else {
        Err(format!(
            "{}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Namespaces `a` and `b`, A's veth end `va` with [`ADDR_A`], B's `vb` with [`ADDR_B`].
pub struct Netns {
    pub a: String,
    pub b: String,
    pub va: String,
    pub vb: String,
}

impl Netns {
    /// A fresh pair, both ends and loopback up; `tag` (one letter) keeps the names apart
    /// from another test's in the same process.
    pub fn pair(tag: char) -> Result<Self, String> {
        // Namespaces of earlier runs whose process is gone (a crash skips Drop).
        if let Ok(list) = sh(&["ip", "netns", "list"]) {
            for name in list.split_whitespace().filter(|n| n.starts_with("estp-")) {
                let pid = name.split('-').nth(1).unwrap_or("");
                if !Path::new(&format!("/proc/{pid}")).exists() {
                    let _ = sh(&["ip", "netns", "del", name]);
                }
            }
        }
        let id = std::process::id();
        let n = Self {
            a: format!("estp-{id}-{tag}a"),
            b: format!("estp-{id}-{tag}b"),
            va: format!("ev{id}{tag}a"),
            vb: format!("ev{id}{tag}b"),
        };
        sh(&["ip", "netns", "add", &n.a])?;
        sh(&["ip", "netns", "add", &n.b])?;
        sh(&[
            "ip", "link", "add", &n.va, "netns", &n.a, "type", "veth", "peer", "name", &n.vb,
            "netns", &n.b,
        ])?;
        n.exec(
            &n.a,
            &["ip", "addr", "add", &format!("{ADDR_A}/24"), "dev", &n.va],
        )?;
        n.exec(
            &n.b,
            &["ip", "addr", "add", &format!("{ADDR_B}/24"), "dev", &n.vb],
        )?;
        for (ns, v) in [(&n.a, &n.va), (&n.b, &n.vb)] {
            n.exec(ns, &["ip", "link", "set", v, "up"])?;
            n.exec(ns, &["ip", "link", "set", "lo", "up"])?;
        }
        Ok(n)
    }

    /// `ip netns exec <ns> <args>`.
    pub fn exec(&self, ns: &str, args: &[&str]) -> Result<String, String> {
        let mut v = vec!["ip", "netns", "exec", ns];
        v.extend_from_slice(args);
        sh(&v)
    }

    /// `ip netns exec <ns> pipeline-node <args>`.
    pub fn start(&self, ns: &str, dir: &Path, name: &str, args: &[&str]) -> Proc {
        let exe = common::node_exe();
        let mut v = vec!["netns", "exec", ns, exe.to_str().unwrap()];
        v.extend_from_slice(args);
        Proc::start_program(dir, name, Path::new("/usr/sbin/ip"), &v)
    }
}

/// One bridge of a test's chain across the pair: its side's prefix, the zenoh key and the
/// sensor side's endpoint.
pub struct BridgeArgs<'a> {
    pub side: &'a str,
    /// `--listen` or `--connect`.
    pub role: &'a str,
    pub prefix: &'a str,
    pub key: &'a str,
    pub endpoint: &'a str,
}

impl Netns {
    /// `bridge` in namespace `ns` with a 30 s `--connect-timeout`, its report in
    /// `dir/bridge-<side>.json`, and `extra`.
    pub fn bridge(&self, ns: &str, dir: &Path, b: &BridgeArgs<'_>, extra: &[&str]) -> Proc {
        let report = dir.join(format!("bridge-{}.json", b.side));
        let mut args = vec![
            "bridge",
            "--side",
            b.side,
            "--prefix",
            b.prefix,
            "--key",
            b.key,
            b.role,
            b.endpoint,
            "--connect-timeout",
            "30",
            "--report",
            report.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        self.start(ns, dir, &format!("bridge-{}", b.side), &args)
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = sh(&["ip", "netns", "del", &self.a]);
        let _ = sh(&["ip", "netns", "del", &self.b]);
    }
}
