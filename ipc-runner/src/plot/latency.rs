//! Latency ladders: p50, p90, p99, p99.9 and max of several paths on one log axis, one line
//! per path. Tables give the numbers; the ladder shows at a glance where paths part (the
//! median, or only the tail) and by how many decades.

use std::path::Path;

use plotters::prelude::*;

use crate::latency::Percentiles;
use crate::plot::{check_extension, color, draw_legend, register_font, FONT};

const WIDTH: u32 = 1000;
const HEIGHT: u32 = 560;
const LEVELS: [&str; 5] = ["p50", "p90", "p99", "p99.9", "max"];

fn levels(p: &Percentiles) -> [f64; 5] {
    [p.p50_us, p.p90_us, p.p99_us, p.p999_us, p.max_us]
}

/// Writes the ladder of `rows` (label, percentiles) to `path` (`.svg` or `.png`). Rows
/// without samples are left out; an error if none is left.
pub fn plot_ladder(title: &str, rows: &[(String, Percentiles)], path: &Path) -> anyhow::Result<()> {
    check_extension(path).map_err(anyhow::Error::msg)?;
    let rows: Vec<&(String, Percentiles)> = rows
        .iter()
        .filter(|(_, p)| p.count > 0 && levels(p).iter().all(|v| v.is_finite() && *v > 0.0))
        .collect();
    anyhow::ensure!(!rows.is_empty(), "no latency samples to plot");
    register_font();
    let png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if png {
        let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
        draw(title, &rows, &root)?;
        root.present()?;
    } else {
        let root = SVGBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
        draw(title, &rows, &root)?;
        root.present()?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(
    title: &str,
    rows: &[&(String, Percentiles)],
    root: &DrawingArea<DB, plotters::coord::Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let all = rows.iter().flat_map(|(_, p)| levels(p));
    let (lo, hi) = all.fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    // Whole decades, so the reader counts orders of magnitude on the grid.
    let (lo, hi) = (
        10f64.powf(lo.log10().floor()),
        10f64.powf(hi.log10().ceil()),
    );
    let decades: Vec<f64> = {
        let (d0, d1) = (lo.log10().round() as i32, hi.log10().round() as i32);
        (d0..=d1).map(|d| 10f64.powi(d)).collect()
    };
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 22))
        .margin(14)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(
            -0.2f64..(LEVELS.len() as f64 - 0.8),
            (lo..hi).log_scale().with_key_points(decades),
        )?;
    chart
        .configure_mesh()
        .x_labels(LEVELS.len())
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && (0.0..LEVELS.len() as f64).contains(&i) {
                LEVELS[i as usize].to_string()
            } else {
                String::new()
            }
        })
        .y_label_formatter(&|v| {
            if *v >= 1.0 {
                format!("{v:.0}")
            } else {
                format!("{v}")
            }
        })
        .x_desc("percentile")
        .y_desc("latency, µs (log scale)")
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .disable_x_mesh()
        .draw()?;
    for (j, (label, p)) in rows.iter().enumerate() {
        let c = color(j);
        let pts: Vec<(f64, f64)> = levels(p)
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64, *v))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3)));
        chart.draw_series(pts.into_iter().map(|pt| Circle::new(pt, 4, c.filled())))?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pct(scale: f64) -> Percentiles {
        Percentiles {
            count: 100,
            p50_us: scale,
            p90_us: 2.0 * scale,
            p99_us: 5.0 * scale,
            p999_us: 20.0 * scale,
            max_us: 100.0 * scale,
        }
    }

    #[test]
    fn writes_an_svg_with_every_label_and_refuses_empty_input() {
        let dir = std::env::temp_dir().join(format!("plot-latency-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let svg = dir.join("ladder.svg");
        let rows = vec![
            ("raw iceoryx2".to_string(), pct(0.5)),
            ("pipeline".to_string(), pct(0.9)),
            ("empty".to_string(), Percentiles::default()),
        ];
        plot_ladder("test ladder", &rows, &svg).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        for want in ["test ladder", "raw iceoryx2", "pipeline", "p99.9", "max"] {
            assert!(text.contains(want), "{want} missing");
        }
        // The empty row is left out of the legend.
        assert!(!text.contains(">empty<"));
        assert!(plot_ladder("x", &rows[2..], &svg).is_err());
        assert!(plot_ladder("x", &rows, &dir.join("ladder.txt")).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
