//! The command line, and where things are.

use anyhow::{anyhow, bail, Result};
use std::path::PathBuf;

const USAGE: &str =
    "report [--quick] [--plain-release] [--skip criterion,icount,firmware,pipeline,bridge,eval-baseline,eval,view] [--out FILE]";

/// The parts, in the order they run (`--skip` takes these names).
pub const PARTS: &[&str] = &[
    "criterion",
    "icount",
    "firmware",
    "pipeline",
    "bridge",
    "eval-baseline",
    "eval",
    "view",
];

pub struct Opts {
    pub quick: bool,
    /// The benchmark binaries were built by a plain `cargo build --release` instead of
    /// `profile.bench` (`--plain-release`: said in the header and by the instruction counts).
    pub plain_release: bool,
    pub skip: Vec<String>,
    pub out: PathBuf,
    pub root: PathBuf,
    pub target: PathBuf,
}

impl Opts {
    /// Reads the command line; `None` if it asked for the usage (printed here).
    pub fn from_args() -> Result<Option<Self>> {
        Self::parse(std::env::args().skip(1))
    }

    /// Reads `args` (the command line without the program's name).
    fn parse(mut args: impl Iterator<Item = String>) -> Result<Option<Self>> {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .ok_or_else(|| anyhow!("no workspace root"))?
            .to_path_buf();
        let mut o = Self {
            quick: false,
            plain_release: false,
            skip: Vec::new(),
            out: root.join("BENCHMARKS.md"),
            target: std::env::var_os("CARGO_TARGET_DIR")
                .map(PathBuf::from)
                .unwrap_or_else(|| root.join("target")),
            root,
        };
        while let Some(a) = args.next() {
            match a.as_str() {
                "--quick" => o.quick = true,
                "--plain-release" => o.plain_release = true,
                "--skip" => {
                    o.skip = args
                        .next()
                        .ok_or_else(|| anyhow!("--skip needs a list"))?
                        .split(',')
                        .map(str::to_string)
                        .collect();
                    if let Some(bad) = o.skip.iter().find(|p| !PARTS.contains(&p.as_str())) {
                        bail!("--skip: no part {bad:?} (parts: {})", PARTS.join(","));
                    }
                }
                "--out" => o.out = PathBuf::from(args.next().ok_or_else(|| anyhow!("--out FILE"))?),
                "-h" | "--help" => {
                    println!("{USAGE}");
                    return Ok(None);
                }
                x => bail!("unknown argument {x:?}"),
            }
        }
        Ok(Some(o))
    }

    /// Whether `part` is to run (not in `--skip`).
    pub fn runs(&self, part: &str) -> bool {
        !self.skip.iter().any(|s| s == part)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Result<Option<Opts>> {
        Opts::parse(args.iter().map(|a| a.to_string()))
    }

    #[test]
    fn skip_takes_only_part_names() {
        let o = parse(&["--skip", "criterion,eval-baseline"])
            .unwrap()
            .unwrap();
        assert!(!o.runs("criterion") && !o.runs("eval-baseline"));
        assert!(o.runs("firmware") && o.runs("eval"));
        // A retired part (`ipc`) or a typo is refused with one line naming the parts.
        for bad in ["ipc", "criterion,firmwre", ""] {
            let e = parse(&["--skip", bad]).err().unwrap().to_string();
            assert!(e.starts_with("--skip: no part"), "{e}");
            assert!(e.contains(&PARTS.join(",")) && !e.contains('\n'), "{e}");
        }
        assert!(parse(&["--skip"]).is_err());
        assert!(parse(&["--bogus"]).is_err());
        assert!(parse(&["--help"]).unwrap().is_none());
    }
}
