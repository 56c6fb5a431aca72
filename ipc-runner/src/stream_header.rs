//! `ipc-runner stream-header`: the [`StreamHeader`] every slot of a scenario's stream must
//! carry, as one line of JSON. A foreign publisher (`clients/python`, `clients/c`) copies it
//! instead of computing the model fingerprint itself (`docs/wire.md`, Stream header).

use anyhow::Result;
use estpipe_wire::StreamHeader;
use std::path::PathBuf;

/// Options of `ipc-runner stream-header`.
#[derive(Clone, Debug, clap::Args)]
pub struct StreamHeaderArgs {
    /// Scenario preset name.
    #[arg(long, default_value = "occlusion", conflicts_with = "config")]
    pub scenario: String,
    /// Scenario TOML file (instead of a preset).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Estimator spec TOML file (as `run --estimator-spec`): the header a publisher of that
    /// model announces, so that a runner configured by the same file accepts it.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["config", "scenario"])]
    pub estimator_spec: Option<PathBuf>,
}

/// `{"wire_version":6,"scenario":"linear","nodes":1,"nx":2,"ny":[1],"model":"0x…"}`: the
/// model as a hex string, since a 64-bit integer does not survive every JSON parser.
pub fn to_json(h: &StreamHeader) -> serde_json::Value {
    serde_json::json!({
        "wire_version": h.version,
        "scenario": h.scenario_name(),
        "nodes": h.nodes,
        "nx": h.nx,
        "ny": h.ny_per_node(),
        "model": format!("{:#018x}", h.model),
    })
}

/// Prints the header of `--scenario`/`--config` (or `--estimator-spec`). The line is the command's whole product,
/// so a stdout that cannot take it (a full disk, a closed pipe) fails the command (exit 1)
/// instead of leaving an empty `header.json` behind a success.
pub fn main(args: &StreamHeaderArgs) -> Result<i32> {
    use anyhow::Context as _;
    use std::io::Write as _;
    let source = crate::source::Source::resolve(
        &args.scenario,
        args.config.as_deref(),
        args.estimator_spec.as_deref(),
        0,
        0,
    )?;
    let header = source.spec.stream_header();
    if let Some(w) = name_cut(&source.spec.name, &header) {
        estpipe_process::errln!("ipc-runner: warning: {w}");
    }
    let line = to_json(&header);
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}")
        .and_then(|()| out.flush())
        .context("cannot write the stream header to stdout")?;
    Ok(0)
}

/// Says so when the header carries less of the spec's `name` than the whole: the field holds
/// 32 bytes (docs/wire.md, StreamHeader); the name is informational, so the stream still
/// works, but a user should not find a different name without a word.
fn name_cut(name: &str, header: &StreamHeader) -> Option<String> {
    let kept = header.scenario_name();
    (kept != name).then(|| {
        format!(
            "the name {name:?} has {} bytes; the stream header carries its first {} ({kept:?})",
            name.len(),
            kept.len()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_name_longer_than_the_field_is_said_cut() {
        let long = "a-scenario-name-longer-than-thirty-two-bytes";
        let h = StreamHeader::new(long, 1, 2, &[1], 0);
        let w = name_cut(long, &h).expect("a warning");
        assert!(
            w.contains("has 44 bytes") && w.contains(h.scenario_name()),
            "{w}"
        );
        let short = StreamHeader::new("linear", 1, 2, &[1], 0);
        assert_eq!(name_cut("linear", &short), None);
    }
}
