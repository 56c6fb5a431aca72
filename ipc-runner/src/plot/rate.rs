//! MSE against transmission rate: one line per estimator, one point per trigger threshold
//! (docs/tobit-fusion.md, "The linear case").

use std::path::Path;

use plotters::prelude::*;

use crate::plot::{check_extension, color, draw_legend, register_font, FONT};

const WIDTH: u32 = 900;
const HEIGHT: u32 = 560;

/// One estimator's points `(transmission rate, MSE)`, in the order drawn.
pub type RateSeries = (String, Vec<(f64, f64)>);

/// Writes the plot of `series` to `path` (`.svg` or `.png`).
pub fn plot_rate(title: &str, series: &[RateSeries], path: &Path) -> anyhow::Result<()> {
    check_extension(path).map_err(anyhow::Error::msg)?;
    let finite = series
        .iter()
        .flat_map(|(_, p)| p.iter())
        .all(|(r, m)| r.is_finite() && m.is_finite() && *m > 0.0);
    anyhow::ensure!(finite && !series.is_empty(), "nothing finite to plot");
    register_font();
    let png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if png {
        let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
        draw(title, series, &root)?;
        root.present()?;
    } else {
        let root = SVGBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
        draw(title, series, &root)?;
        root.present()?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(
    title: &str,
    series: &[RateSeries],
    root: &DrawingArea<DB, plotters::coord::Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let hi = series
        .iter()
        .flat_map(|(_, p)| p.iter())
        .fold(0.0f64, |h, (_, m)| h.max(*m));
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 20))
        .margin(14)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0f64..1.0, 0.0..hi * 1.1)?;
    chart
        .configure_mesh()
        .x_desc("transmission rate (delivered measurements per instant)")
        .y_desc("average MSE over k = 1..T")
        .y_label_formatter(&|v| format!("{v:.3}"))
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .draw()?;
    for (j, (label, p)) in series.iter().enumerate() {
        let c = color(j);
        chart
            .draw_series(LineSeries::new(p.clone(), c.stroke_width(2)))?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3)));
        chart.draw_series(p.iter().map(|pt| Circle::new(*pt, 4, c.filled())))?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 15)
}
