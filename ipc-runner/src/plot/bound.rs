//! Seed 003's bound plot: log₁₀ tr P̄_k (Theorem 1's bound) against log₁₀ tr E[e_k e_kᵀ]
//! (the Monte-Carlo MSE of `nn`) per k, and the baselines' MSE for scale — the paper's Fig. 3.
//!
//! The y axis is log₁₀ of the trace on a linear scale, because the bound spans hundreds of
//! decades when δ₁ ≥ 1.

use std::path::Path;

use plotters::prelude::*;

use crate::eval::EvalResult;

use crate::plot::{register_font, FONT};

/// Writes the bound-versus-empirical plot of the `nn` entry of `result` to `path` (`.png` or
/// `.svg`). Errors if `result` has no `nn` entry with `bound_trace`.
pub fn plot_bound(result: &EvalResult, path: &Path) -> anyhow::Result<()> {
    register_font();
    let (_, nn) = result
        .estimators
        .iter()
        .find(|(n, _)| n == "nn")
        .ok_or_else(|| anyhow::anyhow!("no `nn` estimator in the result"))?;
    let bound = &nn
        .diagnostics
        .iter()
        .find(|(n, _)| n == "bound_trace")
        .ok_or_else(|| anyhow::anyhow!("`nn` has no bound_trace"))?
        .1;
    let mut series: Vec<Series> = vec![(
        "tr Pbar_k (Theorem 1 bound)".into(),
        log_points(bound),
        RGBColor(213, 94, 0),
    )];
    let palette = [
        RGBColor(0, 114, 178),
        RGBColor(0, 158, 115),
        RGBColor(204, 121, 167),
        RGBColor(86, 180, 233),
        RGBColor(230, 159, 0),
    ];
    for (j, (name, r)) in result.estimators.iter().enumerate() {
        let label = if name == "nn" {
            "nn: tr E[e e^T] (MSE)".to_owned()
        } else {
            format!("{name}: MSE")
        };
        series.push((label, log_points(&r.mse), palette[j % palette.len()]));
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, pts, _) in &series {
        for &(_, y) in pts {
            lo = lo.min(y);
            hi = hi.max(y);
        }
    }
    anyhow::ensure!(lo.is_finite() && hi.is_finite(), "nothing finite to plot");
    let pad = ((hi - lo) * 0.05).max(0.5);
    let size = (1100, 620);
    let is_png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    let title = format!(
        "{}: Theorem 1 bound vs empirical covariance trace ({} runs)",
        result.scenario, result.runs
    );
    let range = ((lo - pad), (hi + pad));
    if is_png {
        let root = BitMapBackend::new(path, size).into_drawing_area();
        draw(&root, &title, result.horizon, range, &series)?;
    } else {
        let root = SVGBackend::new(path, size).into_drawing_area();
        draw(&root, &title, result.horizon, range, &series)?;
    }
    Ok(())
}

type Series = (String, Vec<(f64, f64)>, RGBColor);

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    horizon: u32,
    (lo, hi): (f64, f64),
    series: &[Series],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..horizon as f64, lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("k")
        .y_desc("log10(trace)")
        .label_style((FONT, 14))
        .draw()?;
    for (label, pts, color) in series {
        let c = *color;
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    crate::plot::draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;
    root.present()?;
    Ok(())
}

fn log_points(v: &[f64]) -> Vec<(f64, f64)> {
    v.iter()
        .enumerate()
        .filter(|(_, &y)| y.is_finite() && y > 0.0)
        .map(|(k, &y)| (k as f64, y.log10()))
        .collect()
}
