//! The token level of the shared bucket and every node's trigger instants over one run (seed
//! 004, Fig. 2).
//!
//! The run is replayed from the scenario's pre-channel observations through fresh instances
//! of its [`TobitCensoring`] and [`TriggeredTokenBucket`] stages (neither draws random numbers),
//! and every replayed decision is checked against what the channel delivered in the real run,
//! so the plot shows exactly the evaluated run `run` of seed `seed`.

use std::path::{Path, PathBuf};

use channel_sim::channel::event_trigger::TriggeredTokenBucket;
use channel_sim::channel::tobit::TobitCensoring;
use channel_sim::channel::Stage;
use channel_sim::rng::{run_rng, Stream};
use channel_sim::scenario::ComposedScenario;
use channel_sim::{Scenario, Simulation};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::plot::{register_font, FONT};

/// One run's protocol record.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TokenTrace {
    /// ξ_k, k = 0..=T (ξ_0 first).
    pub level: Vec<u32>,
    /// Bucket capacity b.
    pub capacity: u32,
    /// The level at which every node is granted (L · max c_m).
    pub grant_level: u32,
    /// Per node, the instants k whose trigger fired and was sent.
    pub sent: Vec<Vec<u32>>,
    /// Per node, the instants k whose trigger fired but was blocked for lack of tokens.
    pub blocked: Vec<Vec<u32>>,
    /// Per node, η_{m,k} used at k = 1..=T (negative values show the λχ ≤ 1 violation).
    pub eta: Vec<Vec<f64>>,
}

/// Replays run `run` of `scenario` (`None` when the scenario has no token bucket stage).
pub fn trace(
    scenario: &dyn Scenario,
    seed: u64,
    run: u64,
    horizon: u32,
) -> anyhow::Result<Option<TokenTrace>> {
    let Some(composed) = scenario.as_any().downcast_ref::<ComposedScenario>() else {
        return Ok(None);
    };
    let Some(spec) = composed.stage::<TriggeredTokenBucket>() else {
        return Ok(None);
    };
    let mut censor = composed.stage::<TobitCensoring>().cloned();
    let mut stage = channel_sim::channel::event_trigger::build_stage(spec);
    let l = spec.nodes();
    let (xi0, _, capacity) = spec.bucket();
    let mut out = TokenTrace {
        level: vec![xi0],
        capacity,
        grant_level: l as u32 * spec.costs().iter().copied().max().unwrap_or(0),
        sent: vec![Vec::new(); l],
        blocked: vec![Vec::new(); l],
        eta: vec![Vec::new(); l],
    };
    let mut sim = composed.simulate(seed, run);
    // The replayed stages draw nothing; a generator is only needed for the signature.
    let mut rng = run_rng(seed, run, Stream::Channel);
    for k in 1..=horizon {
        let inst = sim.next_instant();
        let mut obs: Vec<_> = sim
            .raw_observations()
            .ok_or_else(|| anyhow::anyhow!("the simulation has no pre-channel observations"))?
            .to_vec();
        if let Some(c) = &mut censor {
            c.apply(k, &[], &mut obs, &mut rng);
        }
        stage.apply(k, &[], &mut obs, &mut rng);
        out.level.push(stage.level());
        for m in 0..l {
            let d = stage
                .decision(m)
                .ok_or_else(|| anyhow::anyhow!("k = {k}: no decision for node {}", m + 1))?;
            anyhow::ensure!(
                d.sent == inst.obs[m].delivered,
                "k = {k}, node {}: the replay differs from the evaluated run (another stage \
                 acts on the packets)",
                m + 1
            );
            out.eta[m].push(d.eta);
            if d.sent {
                out.sent[m].push(k);
            } else if d.blocked() {
                out.blocked[m].push(k);
            }
        }
    }
    Ok(Some(out))
}

/// `FILE.png` → `FILE-tokens.png` (same for `.svg`).
pub fn sibling_path(plot: &Path) -> PathBuf {
    let stem = plot.file_stem().unwrap_or_default().to_string_lossy();
    let ext = plot.extension().unwrap_or_default().to_string_lossy();
    plot.with_file_name(format!("{stem}-tokens.{ext}"))
}

/// Writes Fig. 2 for run 0 of the evaluation next to `plot` (see [`sibling_path`]); returns the
/// path written, or `None` when the scenario has no token bucket.
pub fn plot_for(
    scenario: &dyn Scenario,
    seed: u64,
    horizon: u32,
    plot: &Path,
) -> anyhow::Result<Option<PathBuf>> {
    let Some(t) = trace(scenario, seed, 0, horizon)? else {
        return Ok(None);
    };
    let path = sibling_path(plot);
    crate::plot::check_extension(&path).map_err(anyhow::Error::msg)?;
    draw_file(
        &t,
        &path,
        &format!("{} (seed {seed}, run 0)", scenario.name()),
    )?;
    Ok(Some(path))
}

/// Draws a trace to `path` (`.png` or `.svg`).
pub fn draw_file(t: &TokenTrace, path: &Path, title: &str) -> anyhow::Result<()> {
    register_font();
    let size = (1100, 380 + 60 * t.sent.len() as u32 + 120);
    let png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if png {
        let root = BitMapBackend::new(path, size).into_drawing_area();
        draw(t, &root, title)?;
        root.present()?;
    } else {
        let root = SVGBackend::new(path, size).into_drawing_area();
        draw(t, &root, title)?;
        root.present()?;
    }
    Ok(())
}

fn node_color(m: usize) -> RGBColor {
    // The paper's Fig. 2: node 1 black, node 2 blue, node 3 red.
    const P: [RGBColor; 6] = [
        RGBColor(0, 0, 0),
        RGBColor(0, 90, 200),
        RGBColor(210, 30, 30),
        RGBColor(0, 150, 110),
        RGBColor(200, 120, 0),
        RGBColor(140, 80, 160),
    ];
    P[m % P.len()]
}

fn draw<DB: DrawingBackend>(
    t: &TokenTrace,
    root: &DrawingArea<DB, Shift>,
    title: &str,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let horizon = t.level.len().saturating_sub(1) as u32;
    let (top, bottom) = root.split_vertically(380);
    draw_levels(t, &top, title, horizon)?;
    draw_triggers(t, &bottom, horizon)
}

/// The upper panel: the bucket's level over k against its capacity and the level that
/// grants every node.
fn draw_levels<DB: DrawingBackend>(
    t: &TokenTrace,
    top: &DrawingArea<DB, Shift>,
    title: &str,
    horizon: u32,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let mut c = ChartBuilder::on(top)
        .caption(
            format!("Tokens ξ_k of the shared bucket — {title}"),
            (FONT, 20),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(50)
        .build_cartesian_2d(0u32..horizon, 0u32..t.capacity + t.capacity / 2)?;
    c.configure_mesh()
        .x_desc("k")
        .y_desc("tokens")
        .label_style((FONT, 14))
        .draw()?;
    c.draw_series(LineSeries::new(
        t.level.iter().enumerate().map(|(k, &v)| (k as u32, v)),
        RGBColor(0, 160, 60).stroke_width(2),
    ))?
    .label("ξ_k")
    .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], RGBColor(0, 160, 60).stroke_width(2)));
    for (level, name, col) in [
        (t.capacity, "capacity b", RGBColor(120, 120, 120)),
        (
            t.grant_level,
            "all nodes granted (ξ ≥ l·c)",
            RGBColor(200, 120, 0),
        ),
    ] {
        c.draw_series(LineSeries::new(
            [(0, level), (horizon, level)],
            col.stroke_width(1),
        ))?
        .label(name)
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], col));
    }
    crate::plot::draw_legend(&mut c, SeriesLabelPosition::UpperRight, 14)?;
    Ok(())
}

/// The lower panel: each node's row of sent and blocked trigger instants.
fn draw_triggers<DB: DrawingBackend>(
    t: &TokenTrace,
    bottom: &DrawingArea<DB, Shift>,
    horizon: u32,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let l = t.sent.len() as u32;
    let mut c = ChartBuilder::on(bottom)
        .caption(
            "Trigger instants (filled: sent, small grey: blocked by the bucket)",
            (FONT, 16),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(50)
        .build_cartesian_2d(0u32..horizon, 0u32..l + 1)?;
    c.configure_mesh()
        .x_desc("k")
        .y_labels(l as usize + 2)
        .y_label_formatter(&|v| {
            if *v >= 1 && *v <= l {
                format!("node {v}")
            } else {
                String::new()
            }
        })
        .label_style((FONT, 14))
        .draw()?;
    for m in 0..t.sent.len() {
        let row = m as u32 + 1;
        let col = node_color(m);
        match m % 3 {
            0 => {
                c.draw_series(
                    t.sent[m]
                        .iter()
                        .map(|&k| Cross::new((k, row), 5, col.stroke_width(2))),
                )?;
            }
            1 => {
                c.draw_series(
                    t.sent[m]
                        .iter()
                        .map(|&k| Circle::new((k, row), 4, col.stroke_width(2))),
                )?;
            }
            _ => {
                c.draw_series(
                    t.sent[m]
                        .iter()
                        .map(|&k| TriangleMarker::new((k, row), 5, col.filled())),
                )?;
            }
        }
        c.draw_series(
            t.blocked[m]
                .iter()
                .map(|&k| Circle::new((k, row), 2, RGBColor(150, 150, 150).filled())),
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replay_matches_the_channel_and_bucket_rules() {
        let s = channel_sim::scenario::preset("tobit-fusion").unwrap();
        let t = trace(&*s, 11, 0, 200).unwrap().unwrap();
        assert_eq!(t.level.len(), 201);
        assert_eq!(t.level[0], 10);
        // Eq. (17) by hand from the recorded sends: ξ_k = min(ξ_{k−1} + 5 − 3·sent_k, 30).
        for k in 1..=200u32 {
            let sent = t.sent.iter().filter(|v| v.contains(&k)).count() as u32;
            let want = (t.level[k as usize - 1] + 5 - 3 * sent).min(30);
            assert_eq!(t.level[k as usize], want, "k = {k}");
        }
        assert!(t.blocked.iter().any(|b| !b.is_empty()));
        let lin = channel_sim::scenario::preset("linear").unwrap();
        assert!(trace(&*lin, 0, 0, 10).unwrap().is_none());
        assert_eq!(
            sibling_path(Path::new("/tmp/a/plot.png")),
            PathBuf::from("/tmp/a/plot-tokens.png")
        );
    }
}
