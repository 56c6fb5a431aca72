//! Plots. This module draws the evaluation's plot — MSE(k) of every estimator on a log axis
//! (the papers' MSE figures) above one run's true and estimated trajectories, one panel per
//! state — and holds what every plot shares (font, palette, legend, file check); the others
//! are [`bound`] (seed 003's Fig. 3), [`tokens`] (seed 004's Fig. 2), [`latency`] (percentile
//! ladders), [`trace`] (latency over a run) and [`trajectories`] (a run's estimates with their
//! bands and the node strip, after `demo`).
//!
//! `.svg` or `.png` by the file's extension. PNG text is rendered with DejaVu Sans, embedded
//! from `assets/` (Bitstream Vera licence, `assets/DejaVuSans.LICENSE`).

pub mod bound;
pub mod latency;
pub mod rate;
pub mod tokens;
pub mod trace;
pub mod trajectories;

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::eval::EvalResult;

/// The font family every plot uses (registered from the embedded DejaVu Sans).
pub(crate) const FONT: &str = "sans-serif";
const WIDTH: u32 = 1100;
const MSE_HEIGHT: u32 = 460;
const STATE_HEIGHT: u32 = 260;

/// Errors unless `path` ends in `.svg` or `.png`.
pub fn check_extension(path: &Path) -> Result<(), String> {
    match extension(path).as_deref() {
        Some("svg" | "png") => Ok(()),
        _ => Err(format!(
            "--plot {}: the file must end in .svg or .png",
            path.display()
        )),
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}

/// Registers the embedded font once per process (PNG text needs it; SVG names the family).
/// The font is embedded here only, for every plot module.
pub(crate) fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid; a failure would only lose the PNG's text.
        let _ = plotters::style::register_font(
            FONT,
            FontStyle::Normal,
            include_bytes!("../../assets/DejaVuSans.ttf"),
        );
    });
}

/// Writes the plot of `result` to `path` (`.svg` or `.png`).
pub fn plot(result: &EvalResult, path: &Path) -> anyhow::Result<()> {
    check_extension(path).map_err(anyhow::Error::msg)?;
    register_font();
    let nx = result.trajectory.nx;
    let size = (WIDTH, MSE_HEIGHT + STATE_HEIGHT * nx as u32);
    if extension(path).as_deref() == Some("png") {
        let root = BitMapBackend::new(path, size).into_drawing_area();
        draw(result, &root)?;
        root.present()?;
    } else {
        let root = SVGBackend::new(path, size).into_drawing_area();
        draw(result, &root)?;
        root.present()?;
    }
    Ok(())
}

/// Tick values for a log axis over `[lo, hi]`: 1-2-5 per decade, every integer mantissa when
/// the range is narrower than that gives, only powers of ten when it is wide.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let ticks = |mantissas: &[f64]| -> Vec<f64> {
        let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        (d0..=d1)
            .flat_map(|d| mantissas.iter().map(move |m| m * 10f64.powi(d)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    let standard = ticks(&[1.0, 2.0, 5.0]);
    if standard.len() < 4 {
        ticks(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
    } else if standard.len() > 14 {
        // Every n-th decade, so that a diverged estimator's 200 decades do not overprint.
        let decades = ticks(&[1.0]);
        let step = decades.len().div_ceil(LOG_TICKS_MAX).max(1);
        decades.into_iter().step_by(step).collect()
    } else {
        standard
    }
}

/// Most ticks on a log axis.
const LOG_TICKS_MAX: usize = 12;

/// A log-axis tick: plain decimals in the readable range, scientific outside it.
fn tick(v: f64) -> String {
    if (1e-3..1e4).contains(&v.abs()) {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        format!("{v:.1e}")
    }
}

/// The legend every plot draws: a white, framed box at `pos`, labels at `size` pt.
pub(crate) fn draw_legend<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    pos: SeriesLabelPosition,
    size: u32,
) -> anyhow::Result<()>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    X: Ranged,
    Y: Ranged,
{
    chart
        .configure_series_labels()
        .position(pos)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, size))
        .draw()?;
    Ok(())
}

/// Width of the legend column beside a chart: legends never cover data.
const LEGEND_WIDTH: u32 = 300;

/// One legend line: label, colour, line width.
pub(crate) type LegendEntry = (String, RGBColor, u32);

/// A legend drawn in its own `area` beside the chart (entries top to bottom).
pub(crate) fn side_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
    size: u32,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let line = size as i32 + 6;
    for (i, (label, c, w)) in entries.iter().enumerate() {
        let y = 20 + i as i32 * line;
        area.draw(&PathElement::new(
            vec![(6, y), (34, y)],
            c.stroke_width((*w).max(2)),
        ))?;
        area.draw(&Text::new(
            label.clone(),
            (42, y - size as i32 / 2 - 1),
            (FONT, size),
        ))?;
    }
    Ok(())
}

/// An average MSE for a legend: short, whatever its size.
fn legend_figure(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v.is_infinite() {
        "diverged".into()
    } else if v.abs() >= 1e5 || (v != 0.0 && v.abs() < 1e-3) {
        format!("{v:.2e}")
    } else {
        format!("{v:.4}")
    }
}

/// Line colour `j`: the colour-blind-safe Okabe–Ito palette, then darker variants, so that up
/// to 12 lines are told apart.
pub(crate) fn color(j: usize) -> RGBColor {
    const P: [RGBColor; 12] = [
        RGBColor(0, 114, 178),
        RGBColor(213, 94, 0),
        RGBColor(0, 158, 115),
        RGBColor(204, 121, 167),
        RGBColor(230, 159, 0),
        RGBColor(86, 180, 233),
        RGBColor(120, 120, 120),
        // Not black: the truth is drawn in black.
        RGBColor(150, 120, 0),
        RGBColor(0, 70, 110),
        RGBColor(140, 60, 0),
        RGBColor(0, 100, 70),
        RGBColor(130, 70, 110),
    ];
    P[j % P.len()]
}

fn draw<DB: DrawingBackend>(
    result: &EvalResult,
    root: &DrawingArea<DB, Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (top, bottom) = root.split_vertically(MSE_HEIGHT);
    let (chart, legend) = top.split_horizontally(WIDTH - LEGEND_WIDTH);
    let entries = draw_mse(result, &chart)?;
    side_legend(&legend, &entries, 15)?;
    let nx = result.trajectory.nx;
    if nx > 0 {
        let panels = bottom.split_evenly((nx, 1));
        for (i, panel) in panels.iter().enumerate() {
            let (chart, legend) = panel.split_horizontally(WIDTH - LEGEND_WIDTH);
            let entries = draw_state(result, &chart, i)?;
            side_legend(&legend, &entries, 14)?;
        }
    }
    Ok(())
}

fn draw_mse<DB: DrawingBackend>(
    result: &EvalResult,
    area: &DrawingArea<DB, Shift>,
) -> anyhow::Result<Vec<LegendEntry>>
where
    DB::ErrorType: 'static,
{
    let t = result.horizon as usize;
    // k = 1..=T: k = 0 is the prior, the same for every estimator.
    let values = result
        .estimators
        .iter()
        .flat_map(|(_, r)| r.mse[1..].iter().copied())
        .filter(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    let (lo, hi) = if lo.is_finite() {
        (lo / 1.5, hi * 1.5)
    } else {
        (1e-3, 1.0)
    };
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "{}: MSE(k) over {} runs (seed {})",
                result.scenario, result.runs, result.seed
            ),
            (FONT, 24),
        )
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(80)
        .build_cartesian_2d(
            1f64..t.max(2) as f64,
            (lo..hi).log_scale().with_key_points(log_ticks(lo, hi)),
        )?;
    chart
        .configure_mesh()
        .x_desc("instant k")
        .y_desc("MSE(k), mean over runs of squared error norm (log scale)")
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| tick(*v))
        .draw()?;
    let mut entries = Vec::new();
    for (j, (name, r)) in result.estimators.iter().enumerate() {
        let c = color(j);
        chart.draw_series(LineSeries::new(
            (1..=t)
                .filter(|&k| r.mse[k].is_finite() && r.mse[k] > 0.0)
                .map(|k| (k as f64, r.mse[k])),
            c.stroke_width(2),
        ))?;
        entries.push((format!("{name} (avg {})", legend_figure(r.avg_mse)), c, 2));
    }
    entries.push(("lower is better".into(), WHITE, 0));
    Ok(entries)
}

fn draw_state<DB: DrawingBackend>(
    result: &EvalResult,
    area: &DrawingArea<DB, Shift>,
    i: usize,
) -> anyhow::Result<Vec<LegendEntry>>
where
    DB::ErrorType: 'static,
{
    let tr = &result.trajectory;
    let (nx, t) = (tr.nx, result.horizon as usize);
    let series = |v: &[f64]| -> Vec<(f64, f64)> {
        (0..=t)
            .map(|k| (k as f64, v[k * nx + i]))
            .filter(|p| p.1.is_finite())
            .collect()
    };
    let truth = series(&tr.truth);
    let estimates: Vec<Vec<(f64, f64)>> = tr.estimates.iter().map(|e| series(e)).collect();
    let axis = StateAxis::fit(&truth, &estimates);
    let (lo, hi) = (axis.lo, axis.hi);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("run 0: state x{} — truth and estimates", i + 1),
            (FONT, 18),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(80)
        .build_cartesian_2d(0f64..t as f64, lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("instant k")
        .y_desc(format!("x{}", i + 1))
        .x_label_formatter(&|v| format!("{v:.0}"))
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .draw()?;
    chart.draw_series(LineSeries::new(truth, BLACK.stroke_width(2)))?;
    let mut entries = vec![("truth".to_owned(), BLACK, 2)];
    for (j, (points, name)) in estimates.into_iter().zip(&tr.names).enumerate() {
        let c = color(j);
        let label = if axis.near(&points) {
            (*name).to_owned()
        } else {
            format!("{name} (partly off scale)")
        };
        // An off-scale series is drawn in the pieces that stay inside the axis: clamped to
        // its edges it would paint the panel with vertical strokes and hide the truth.
        let inside = |v: f64| v >= lo && v <= hi;
        let mut piece: Vec<(f64, f64)> = Vec::new();
        for (k, v) in points {
            if inside(v) {
                piece.push((k, v));
            } else if !piece.is_empty() {
                chart.draw_series(LineSeries::new(piece.drain(..), c.stroke_width(1)))?;
            }
        }
        chart.draw_series(LineSeries::new(piece, c.stroke_width(1)))?;
        entries.push((label, c, 1));
    }
    Ok(entries)
}

/// The y axis of a state's panel: it fits the truth and every estimate that stays near it;
/// one that leaves (a diverging EKF) is drawn where it is inside and named so, not allowed to
/// flatten the rest.
struct StateAxis {
    /// The truth's range.
    t_lo: f64,
    t_hi: f64,
    /// How far beyond the truth's range an estimate may go and still be near.
    reach: f64,
    lo: f64,
    hi: f64,
}

impl StateAxis {
    fn fit(truth: &[(f64, f64)], estimates: &[Vec<(f64, f64)>]) -> Self {
        let (t_lo, t_hi) = span(truth);
        let reach = 3.0 * (t_hi - t_lo).max(1e-9);
        let mut axis = Self {
            t_lo,
            t_hi,
            reach,
            lo: f64::NAN,
            hi: f64::NAN,
        };
        let (lo, hi) = estimates
            .iter()
            .filter(|e| axis.near(e))
            .map(|e| span(e))
            .fold((t_lo, t_hi), |(l, h), (a, b)| (l.min(a), h.max(b)));
        (axis.lo, axis.hi) = if lo.is_finite() && hi > lo {
            let pad = 0.08 * (hi - lo);
            (lo - pad, hi + pad)
        } else {
            (-1.0, 1.0)
        };
        axis
    }

    /// Whether the series stays within reach of the truth (or there is no truth to reach).
    fn near(&self, pts: &[(f64, f64)]) -> bool {
        let (lo, hi) = span(pts);
        !self.t_lo.is_finite() || (lo >= self.t_lo - self.reach && hi <= self.t_hi + self.reach)
    }
}

/// The least and greatest y of `pts` (∞, −∞ when there are none).
fn span(pts: &[(f64, f64)]) -> (f64, f64) {
    pts.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.1), hi.max(p.1))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_axis_over_two_hundred_decades_has_a_dozen_ticks() {
        let t = log_ticks(1e-3, 1e200);
        assert!(t.len() <= LOG_TICKS_MAX && t.len() >= 6, "{t:?}");
        assert!(t.windows(2).all(|w| w[1] > w[0]));
        // The readable ranges keep their 1-2-5 ticks.
        assert_eq!(log_ticks(0.9, 11.0), vec![1.0, 2.0, 5.0, 10.0]);
    }

    #[test]
    fn legend_figures_are_short_whatever_the_mse() {
        assert_eq!(legend_figure(3.04361), "3.0436");
        assert_eq!(legend_figure(1.5407e200), "1.54e200");
        assert_eq!(legend_figure(f64::INFINITY), "diverged");
        for v in [0.0, 1e-300, 99_999.0, 1e5, -1e300, f64::NAN] {
            assert!(legend_figure(v).len() <= 10, "{v}: {}", legend_figure(v));
        }
    }
}
