//! Latency over the run: when the tail happened. A histogram says how many instants were
//! slow; this says whether they came as a steady sprinkle (interrupts, timer ticks), in
//! bursts (the runner preempted, slots queueing behind one another) or at start-up.
//!
//! The run is cut into at most [`BINS`] equal time bins; per bin the plot shows the median
//! and the maximum of the end-to-end latency and the maximum of the runner's own share
//! (received → estimates published; the rest is transport), on a log axis, with the run's
//! end-to-end p99 as a dashed line.

use std::path::Path;

use plotters::prelude::*;

use crate::plot::{check_extension, color, draw_legend, register_font, FONT};

const WIDTH: u32 = 1000;
const HEIGHT: u32 = 520;
/// Bins across the run: a few pixels each at the plot's width.
pub const BINS: usize = 400;

/// One instant: `(seconds since the first send, transport µs, end to end µs)`.
pub type Point = (f64, f64, f64);

/// One time bin of the trace.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bin {
    /// Start of the bin, s.
    pub t: f64,
    /// Median end-to-end latency, µs.
    pub median: f64,
    /// Maximum end-to-end latency, µs.
    pub max: f64,
    /// Maximum transport latency (slot sent → received), µs.
    pub max_transport: f64,
    /// Maximum of received → estimates published (end to end − transport): the runner's own
    /// share, µs.
    pub max_after_receipt: f64,
}

/// The trace cut into at most [`BINS`] equal time bins (empty bins left out).
pub fn bins(points: &[Point]) -> Vec<Bin> {
    let Some(t_end) = points.iter().map(|p| p.0).reduce(f64::max) else {
        return Vec::new();
    };
    let n = BINS.min(points.len()).max(1);
    let width = (t_end / n as f64).max(1e-9);
    let mut per: Vec<Vec<(f64, f64)>> = vec![Vec::new(); n];
    for &(t, tr, e2e) in points {
        let b = ((t / width) as usize).min(n - 1);
        per[b].push((tr, e2e));
    }
    per.into_iter()
        .enumerate()
        .filter(|(_, v)| !v.is_empty())
        .map(|(b, mut v)| {
            let max_tr = v.iter().map(|p| p.0).fold(0.0, f64::max);
            let max_after = v.iter().map(|p| p.1 - p.0).fold(0.0, f64::max);
            v.sort_by(|a, b| a.1.total_cmp(&b.1));
            // The lower median: one spike in a bin of two is not the bin's typical latency.
            let med = v[(v.len() - 1) / 2].1;
            let max = v[v.len() - 1].1;
            Bin {
                t: b as f64 * width,
                median: med,
                max,
                max_transport: max_tr,
                max_after_receipt: max_after,
            }
        })
        .collect()
}

/// The `q`-quantile (0..1) of the end-to-end latencies, by rank.
pub fn quantile_e2e(points: &[Point], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = points.iter().map(|p| p.2).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let i = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    Some(v[i])
}

/// Writes the trace of `points` to `path` (`.svg` or `.png`); an error without points.
pub fn plot_trace(title: &str, points: &[Point], path: &Path) -> anyhow::Result<()> {
    check_extension(path).map_err(anyhow::Error::msg)?;
    let b = bins(points);
    anyhow::ensure!(!b.is_empty(), "no latency samples to plot");
    let p99 = quantile_e2e(points, 0.99).unwrap_or(0.0);
    register_font();
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
        draw(title, &b, p99, &root)?;
        root.present()?;
    } else {
        let root = SVGBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
        draw(title, &b, p99, &root)?;
        root.present()?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(
    title: &str,
    b: &[Bin],
    p99: f64,
    root: &DrawingArea<DB, plotters::coord::Shift>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (lo, hi) = decades(b, p99)?;
    let t_end = b.last().map_or(1.0, |r| r.t).max(1e-6);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 22))
        .margin(14)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..t_end, (lo..hi).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("time since the first slot, s")
        .y_desc("latency, µs (log scale)")
        .y_label_formatter(&|v| {
            if *v >= 1.0 {
                format!("{v:.0}")
            } else {
                format!("{v}")
            }
        })
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .draw()?;
    type Field = fn(&Bin) -> f64;
    // The maximum last and wider: where a bin's max is its median, the max stays visible.
    let series: [(usize, &str, Field, u32); 3] = [
        (1, "end to end, median per bin", |r| r.median, 1),
        (
            2,
            "received → estimates published, max per bin",
            |r| r.max_after_receipt,
            1,
        ),
        (0, "end to end, max per bin", |r| r.max, 2),
    ];
    for (j, label, f, width) in series {
        let c = color(j);
        let pts: Vec<(f64, f64)> = b
            .iter()
            .map(|r| (r.t, f(r)))
            .filter(|p| positive(p.1))
            .collect();
        chart
            .draw_series(LineSeries::new(pts, c.stroke_width(width)))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3)));
    }
    draw_peaks(&mut chart, b, p99, t_end)?;
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 14)
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

/// The log axis's range: whole decades around every positive latency drawn, one at least.
fn decades(b: &[Bin], p99: f64) -> anyhow::Result<(f64, f64)> {
    let vals = b
        .iter()
        .flat_map(|r| [r.median, r.max, r.max_after_receipt])
        .chain([p99])
        .filter(|v| positive(*v));
    let (lo, hi) = vals.fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    anyhow::ensure!(hi > 0.0, "no positive latency to plot");
    Ok((
        10f64.powf(lo.log10().floor()),
        10f64.powf(hi.log10().ceil().max(lo.log10().floor() + 1.0)),
    ))
}

/// The run's largest latency and its p99, over the bins' lines.
fn draw_peaks<'a, DB>(
    chart: &mut ChartContext<
        'a,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, LogCoord<f64>>,
    >,
    b: &[Bin],
    p99: f64,
    t_end: f64,
) -> anyhow::Result<()>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
{
    // The run's largest latency, marked and named: a single spike is one bin wide.
    if let Some(top) = b
        .iter()
        .filter(|r| positive(r.max))
        .max_by(|a, b| a.max.total_cmp(&b.max))
    {
        let c = color(0);
        chart
            .draw_series([Circle::new((top.t, top.max), 5, c.stroke_width(2))])?
            .label(format!("end to end max of the run ({:.1} µs)", top.max))
            .legend(move |(x, y)| Circle::new((x + 12, y), 5, c.stroke_width(2)));
    }
    if positive(p99) {
        let c = BLACK.mix(0.6);
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, p99), (t_end, p99)],
                6,
                4,
                c.stroke_width(1),
            ))?
            .label(format!("end to end p99 of the run ({p99:.1} µs)"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(2)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_keep_every_maximum_and_the_median() {
        // 1000 instants over 1 s at 1 µs, one 50 µs spike at 0.5 s.
        let pts: Vec<Point> = (0..1000)
            .map(|i| {
                let t = i as f64 * 1e-3;
                let e = if i == 500 { 50.0 } else { 1.0 };
                (t, e / 2.0, e)
            })
            .collect();
        let b = bins(&pts);
        assert_eq!(b.len(), BINS);
        let max = b.iter().map(|r| r.max).fold(0.0, f64::max);
        assert_eq!(max, 50.0);
        assert!(
            b.iter().all(|r| r.median == 1.0),
            "the spike is no bin's median"
        );
        let spike = b.iter().find(|r| r.max == 50.0).unwrap();
        assert!((spike.t - 0.5).abs() < 1e-2, "spike binned at {}", spike.t);
        assert_eq!(spike.max_transport, 25.0);
        assert_eq!(spike.max_after_receipt, 25.0);
        assert_eq!(quantile_e2e(&pts, 0.99), Some(1.0));
        assert_eq!(quantile_e2e(&pts, 1.0), Some(50.0));
        assert!(bins(&[]).is_empty());
    }

    #[test]
    fn writes_an_svg_and_refuses_empty_input() {
        let dir = std::env::temp_dir().join(format!("plot-trace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let svg = dir.join("trace.svg");
        let pts: Vec<Point> = (0..100).map(|i| (i as f64 * 1e-4, 0.5, 1.0)).collect();
        plot_trace("test trace", &pts, &svg).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        for want in [
            "test trace",
            "max per bin",
            "p99 of the run",
            "max of the run",
        ] {
            assert!(text.contains(want), "{want} missing");
        }
        // Series are drawn (and listed) in order: the max over the median, not under it.
        let at = |w: &str| text.find(w).unwrap();
        assert!(at("median per bin") < at("end to end, max per bin"));
        assert!(plot_trace("x", &[], &svg).is_err());
        assert!(plot_trace("x", &pts, &dir.join("trace.txt")).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
