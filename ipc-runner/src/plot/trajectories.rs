//! The plot `demo` writes after its run (`trajectories.svg`): one panel per state component
//! with the truth and every estimator's x̂ inside its ±2σ band, then a strip per sensor node
//! marking each instant delivered, dropped by the channel, lost or late — what the live view
//! shows while the run goes on (docs/view.md), so that a run kept on disk reads the same.
//! The legend has a column of its own to the right, off the data.
//!
//! The band is x̂ ± 2√P_ii from the covariance (or bound, `cov_kind`, docs/wire.md) the
//! estimator published at that instant; an estimator that publishes none has no band, and an
//! instant without a finite variance splits the band there. Only the first session is drawn.

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{color, register_font, FONT};
use crate::run::Trajectories;
use crate::view::tap::{DELIVERED, DROPPED, LATE, LOST};

const WIDTH: u32 = 1100;
/// The legend's column.
const LEGEND_WIDTH: u32 = 210;
const STATE_HEIGHT: u32 = 260;
/// A node's row in the strip, and the strip's axes.
const NODE_ROW: u32 = 22;
const STRIP_AXES: u32 = 72;

/// The strip's colours by slot status, as the live page draws them (ipc-runner/view/view.js).
const STATUS: [(u8, RGBColor, &str); 4] = [
    (DELIVERED, RGBColor(0x3a, 0x9d, 0x3a), "delivered"),
    (
        DROPPED,
        RGBColor(0xf0, 0xa0, 0x30),
        "dropped by the channel",
    ),
    (LOST, RGBColor(0xd6, 0x27, 0x28), "lost (IPC or network)"),
    (LATE, RGBColor(0x8e, 0x44, 0xad), "late (--lag)"),
];

/// A band's contiguous pieces: `(k, x̂ − 2σ, x̂ + 2σ)` over the instants where estimator `e`
/// published a finite variance of component `j` (first session).
pub(crate) fn bands(traj: &Trajectories, e: usize, j: usize) -> Vec<Vec<(f64, f64, f64)>> {
    let (nx, ne) = (traj.nx.max(1), traj.names.len());
    let mut out: Vec<Vec<(f64, f64, f64)>> = Vec::new();
    let mut open = false;
    for i in 0..first_session(traj) {
        let at = (i * ne + e) * nx + j;
        let (x, v) = (
            traj.estimates.get(at).copied().unwrap_or(f64::NAN),
            traj.var.get(at).copied().unwrap_or(f64::NAN),
        );
        if x.is_finite() && v.is_finite() && v >= 0.0 {
            let s2 = 2.0 * v.sqrt();
            if !open {
                out.push(Vec::new());
                open = true;
            }
            if let Some(piece) = out.last_mut() {
                piece.push((f64::from(traj.keys[i].1), x - s2, x + s2));
            }
        } else {
            open = false;
        }
    }
    out
}

/// Runs of one status in node `node`'s row: `(first k, last k, status)` (first session).
pub(crate) fn strip_runs(traj: &Trajectories, node: usize) -> Vec<(u32, u32, u8)> {
    let mut out: Vec<(u32, u32, u8)> = Vec::new();
    for i in 0..first_session(traj) {
        let Some(&s) = traj.status.get(i * traj.nodes + node) else {
            break;
        };
        let k = traj.keys[i].1;
        match out.last_mut() {
            Some(run) if run.2 == s && run.1.saturating_add(1) == k => run.1 = k,
            _ => out.push((k, k, s)),
        }
    }
    out
}

/// Recorded instants of the first session.
fn first_session(traj: &Trajectories) -> usize {
    let first = traj.keys.first().map_or(1, |f| f.0);
    traj.keys.iter().take_while(|(s, _)| *s == first).count()
}

/// Writes the plot of `traj` to `path`: SVG, or PNG when `path` ends in `.png`.
pub fn plot(traj: &Trajectories, path: &Path, title: &str) -> Result<()> {
    register_font();
    let strip = if traj.nodes > 0 {
        STRIP_AXES + NODE_ROW * traj.nodes as u32
    } else {
        0
    };
    let size = (WIDTH, STATE_HEIGHT * traj.nx.max(1) as u32 + strip);
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        draw(
            &BitMapBackend::new(path, size).into_drawing_area(),
            traj,
            title,
            strip,
        )
    } else {
        draw(
            &SVGBackend::new(path, size).into_drawing_area(),
            traj,
            title,
            strip,
        )
    }
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    traj: &Trajectories,
    title: &str,
    strip: u32,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: &dyn std::fmt::Display| anyhow!("plot: {e}");
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (data, legend) = root.split_horizontally(WIDTH - LEGEND_WIDTH);
    let height = data.dim_in_pixel().1;
    let (states, nodes) = data.split_vertically(height - strip);
    let nx = traj.nx.max(1);
    let n = first_session(traj);
    let kmax = f64::from(traj.keys.get(n.saturating_sub(1)).map_or(1, |k| k.1).max(1));
    let has_band: Vec<bool> = (0..traj.names.len())
        .map(|e| (0..nx).any(|j| !bands(traj, e, j).is_empty()))
        .collect();
    for (j, panel) in states.split_evenly((nx, 1)).iter().enumerate() {
        draw_state(panel, traj, title, j, n, kmax).map_err(|e| err(&e))?;
    }
    if strip > 0 {
        draw_strip(&nodes, traj, kmax).map_err(|e| err(&e))?;
    }
    draw_legend(&legend, traj, &has_band).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

fn draw_state<DB: DrawingBackend>(
    panel: &DrawingArea<DB, Shift>,
    traj: &Trajectories,
    title: &str,
    j: usize,
    n: usize,
    kmax: f64,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let (nx, ne) = (traj.nx.max(1), traj.names.len());
    let k = |i: usize| f64::from(traj.keys[i].1);
    let truth: Vec<(f64, f64)> = (0..n)
        .map(|i| {
            (
                k(i),
                traj.truth.get(i * nx + j).copied().unwrap_or(f64::NAN),
            )
        })
        .filter(|p| p.1.is_finite())
        .collect();
    let est = |e: usize| -> Vec<(f64, f64)> {
        (0..n)
            .map(|i| {
                let at = (i * ne + e) * nx + j;
                (k(i), traj.estimates.get(at).copied().unwrap_or(f64::NAN))
            })
            .filter(|p| p.1.is_finite())
            .collect()
    };
    let bands: Vec<_> = (0..ne).map(|e| bands(traj, e, j)).collect();
    // The axis holds the truth and the estimates; a band wider than those (a filter not yet
    // converged) is cut at the panel's edge rather than flattening everything else.
    let (lo, hi) = truth
        .iter()
        .map(|p| p.1)
        .chain((0..ne).flat_map(|e| est(e).into_iter().map(|p| p.1)))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (lo, hi) = if lo < hi { (lo, hi) } else { (-1.0, 1.0) };
    let pad = 0.08 * (hi - lo);
    let (ylo, yhi) = (lo - pad, hi + pad);
    let mut chart = ChartBuilder::on(panel)
        .caption(format!("{title}: x{}", j + 1), (FONT, 16))
        .margin(8)
        .margin_right(24)
        .x_label_area_size(28)
        .y_label_area_size(56)
        .build_cartesian_2d(0f64..kmax, ylo..yhi)?;
    chart
        .configure_mesh()
        .x_desc("k")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    let clamp = |v: f64| v.clamp(ylo, yhi);
    for (e, pieces) in bands.iter().enumerate() {
        let fill = color(e).mix(0.18).filled();
        chart.draw_series(pieces.iter().map(|piece| {
            let upper = piece.iter().map(|&(k, _, h)| (k, clamp(h)));
            let lower = piece.iter().rev().map(|&(k, l, _)| (k, clamp(l)));
            Polygon::new(upper.chain(lower).collect::<Vec<_>>(), fill)
        }))?;
    }
    chart.draw_series(LineSeries::new(truth, BLACK.stroke_width(2)))?;
    for e in 0..ne {
        chart.draw_series(LineSeries::new(est(e), color(e).stroke_width(1)))?;
    }
    Ok(())
}

fn draw_strip<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    traj: &Trajectories,
    kmax: f64,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let nodes = traj.nodes;
    let mut chart = ChartBuilder::on(area)
        .caption("sensor nodes: each instant's slot", (FONT, 14))
        .margin(8)
        .margin_right(24)
        .x_label_area_size(24)
        .y_label_area_size(56)
        .build_cartesian_2d(0f64..kmax, 0f64..nodes as f64)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_y_axis()
        .x_label_formatter(&|v| format!("{v:.0}"))
        .x_label_style((FONT, 12))
        .draw()?;
    // The rows' names left of the strip (node 0 on top).
    let font = (FONT, 12).into_font().color(&BLACK);
    let (_, y0) = area.get_base_pixel();
    for node in 0..nodes {
        let (_, y) = chart.backend_coord(&(0.0, (nodes - node) as f64 - 0.5));
        area.draw(&Text::new(
            format!("node {node}"),
            (4, y - y0 - 6),
            font.clone(),
        ))?;
    }
    for node in 0..nodes {
        let top = (nodes - node) as f64;
        chart.draw_series(strip_runs(traj, node).into_iter().map(|(a, b, s)| {
            let c = STATUS
                .iter()
                .find(|x| x.0 == s)
                .map_or(RGBColor(150, 150, 150), |x| x.1);
            Rectangle::new(
                [
                    (f64::from(a) - 0.5, top - 0.1),
                    (f64::from(b) + 0.5, top - 0.9),
                ],
                c.filled(),
            )
        }))?;
    }
    Ok(())
}

/// The legend column: the truth, every estimator (its line, and its band where it has one)
/// and the strip's colours with each status's count over all nodes.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    traj: &Trajectories,
    has_band: &[bool],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB::ErrorType: 'static,
{
    let text = (FONT, 13).into_font().color(&BLACK);
    let mut y = 30;
    let x = 10;
    area.draw(&PathElement::new(
        vec![(x, y), (x + 24, y)],
        BLACK.stroke_width(2),
    ))?;
    area.draw(&Text::new("truth", (x + 32, y - 7), text.clone()))?;
    for (e, name) in traj.names.iter().enumerate() {
        y += 22;
        if has_band.get(e).copied().unwrap_or(false) {
            area.draw(&Rectangle::new(
                [(x, y - 7), (x + 24, y + 7)],
                color(e).mix(0.18).filled(),
            ))?;
        }
        area.draw(&PathElement::new(vec![(x, y), (x + 24, y)], color(e)))?;
        let label = if has_band.get(e).copied().unwrap_or(false) {
            format!("{name} ± 2σ")
        } else {
            format!("{name} (no covariance)")
        };
        area.draw(&Text::new(label, (x + 32, y - 7), text.clone()))?;
    }
    if traj.nodes > 0 {
        y += 36;
        area.draw(&Text::new("slots (all nodes)", (x, y - 7), text.clone()))?;
        let n = first_session(traj) * traj.nodes;
        for (s, c, what) in STATUS {
            y += 22;
            let count = traj.status.iter().take(n).filter(|&&v| v == s).count();
            area.draw(&Rectangle::new([(x, y - 7), (x + 24, y + 7)], c.filled()))?;
            area.draw(&Text::new(
                format!("{what}: {count}"),
                (x + 32, y - 7),
                text.clone(),
            ))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two estimators, two components, two nodes, six instants: estimator 0 publishes a
    /// variance everywhere but instant 3 of component 1, estimator 1 none.
    fn traj() -> Trajectories {
        let (nx, nodes, n) = (2, 2, 6u32);
        let mut t = Trajectories {
            nx,
            nodes,
            names: vec!["kf".into(), "blind".into()],
            ..Trajectories::default()
        };
        for k in 1..=n {
            let kf = f64::from(k);
            t.keys.push((1, k));
            t.truth.extend([kf, -kf]);
            // kf: x̂ = (k, −k + 0.5), P_ii = (k², 4); blind: x̂ = (0, 0), no variance.
            t.estimates.extend([kf, -kf + 0.5, 0.0, 0.0]);
            let v1 = if k == 3 { f64::NAN } else { 4.0 };
            t.var.extend([kf * kf, v1, f64::NAN, f64::NAN]);
            let s1 = match k {
                2 => DROPPED,
                4 => LATE,
                5 => LOST,
                _ => DELIVERED,
            };
            t.status.extend([DELIVERED, s1]);
        }
        t
    }

    #[test]
    fn the_band_is_the_estimate_plus_minus_two_sigma() {
        let t = traj();
        let b = bands(&t, 0, 0);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].len(), 6);
        for &(k, lo, hi) in &b[0] {
            // σ = k: [k − 2k, k + 2k].
            assert_eq!((lo, hi), (k - 2.0 * k, k + 2.0 * k), "k = {k}");
        }
        // Component 1: split at instant 3, σ = 2 around −k + 0.5.
        let b = bands(&t, 0, 1);
        assert_eq!(b.iter().map(Vec::len).collect::<Vec<_>>(), [2, 3]);
        assert_eq!(b[1][0], (4.0, -3.5 - 4.0, -3.5 + 4.0));
        assert!(bands(&t, 1, 0).is_empty() && bands(&t, 1, 1).is_empty());
    }

    #[test]
    fn the_strip_merges_runs_of_one_status() {
        let t = traj();
        assert_eq!(strip_runs(&t, 0), [(1, 6, DELIVERED)]);
        assert_eq!(
            strip_runs(&t, 1),
            [
                (1, 1, DELIVERED),
                (2, 2, DROPPED),
                (3, 3, DELIVERED),
                (4, 4, LATE),
                (5, 5, LOST),
                (6, 6, DELIVERED),
            ]
        );
    }

    /// The SVG holds one polygon per band piece (three here: estimator 0's two components,
    /// one split in two; none for the estimator without a covariance), one rectangle per
    /// strip run in the status colours, and the legend's labels.
    #[test]
    fn the_svg_has_the_bands_the_strip_and_the_legend() {
        let dir = std::env::temp_dir().join(format!("estpipe-plot-traj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.svg");
        plot(&traj(), &path, "test").unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(svg.matches("<polygon").count(), 3, "{svg}");
        let fill = |c: RGBColor| format!("fill=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        // Strip rectangles (node 0: one run; node 1: three delivered runs) plus one legend
        // swatch per status.
        let count = |c: RGBColor| svg.matches(&fill(c)).count();
        assert_eq!(count(STATUS[0].1), 1 + 3 + 1, "delivered");
        assert_eq!(count(STATUS[1].1), 1 + 1, "dropped");
        assert_eq!(count(STATUS[2].1), 1 + 1, "lost");
        assert_eq!(count(STATUS[3].1), 1 + 1, "late");
        assert!(svg.contains("kf ± 2σ") && svg.contains("blind (no covariance)"));
        assert!(svg.contains("delivered: 9") && svg.contains("late (--lag): 1"));
    }
}
