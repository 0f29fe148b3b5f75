//! Plots of a run's CSV logs (`losses.csv`, `validation.csv`) as SVG, so a run can be judged at
//! a glance without a plotting tool: one panel per column against the iteration, each with a
//! title, labelled axes with units (a log scale where the values span more than a decade), the
//! raw values as dots and their moving average as a line, and a legend.
//!
//! SVG because its text needs no font files: a PNG with labels would need a font rasteriser
//! and a font on every machine that runs the demo. Written atomically.

use std::path::{Path, PathBuf};

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// Panel size in pixels.
const PANEL: (u32, u32) = (520, 300);
/// Panels per row.
const COLUMNS: usize = 2;
/// Window of the moving average (iterations).
pub const MOVING_AVERAGE: usize = 25;

/// A plot could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The CSV has no numeric column after the iteration.
    #[error("{path}: the log has no data column to plot")]
    NoData {
        /// The plot being written.
        path: PathBuf,
    },
    /// Drawing failed.
    #[error("{path}: drawing the plot: {message}")]
    Draw {
        /// The plot being written.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// Writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The plot being written.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// The unit of a log column, from its name.
#[must_use]
pub fn unit_of(column: &str) -> &'static str {
    match column {
        c if c.ends_with("_px") || c.starts_with("silhouette") => "pixels",
        "laplacian" => "diagonal²",
        "iou" => "intersection / union",
        "position_relative" => "fraction of the diagonal",
        "kl" => "nats",
        "total" => "weighted sum",
        _ => "mean per vertex",
    }
}

/// The trailing moving average of `values` over `window` entries (shorter at the start).
#[must_use]
pub fn moving_average(values: &[f64], window: usize) -> Vec<f64> {
    let window = window.max(1);
    let mut sum = 0.0;
    values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            sum += v;
            if i >= window {
                sum -= values[i - window];
            }
            sum / (i + 1).min(window) as f64
        })
        .collect()
}

/// Draws every numeric column of the CSV text `csv` (after the first, the iteration) in its own
/// panel under the figure title `title`; writes SVG to `path`.
pub fn plot_log(csv: &str, title: &str, path: &Path) -> Result<(), PlotError> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let rows: Vec<Vec<f64>> = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|v| v.trim().parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    let columns: Vec<(&str, Vec<(f64, f64)>)> = header
        .iter()
        .enumerate()
        .skip(1)
        .map(|(c, name)| {
            let points = rows
                .iter()
                .filter_map(|r| Some((*r.first()?, *r.get(c)?)))
                .filter(|(i, v)| i.is_finite() && v.is_finite())
                .collect();
            (*name, points)
        })
        .filter(|(_, p): &(&str, Vec<(f64, f64)>)| !p.is_empty())
        .collect();
    if columns.is_empty() {
        return Err(PlotError::NoData {
            path: path.to_owned(),
        });
    }
    let draw_err = |e: &dyn std::fmt::Display| PlotError::Draw {
        path: path.to_owned(),
        message: e.to_string(),
    };
    let panel_rows = columns.len().div_ceil(COLUMNS);
    let size = (
        PANEL.0 * COLUMNS.min(columns.len()) as u32,
        PANEL.1 * panel_rows as u32 + 40,
    );
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(&e))?;
        let root = root
            .titled(title, ("sans-serif", 22))
            .map_err(|e| draw_err(&e))?;
        let panels = root.split_evenly((panel_rows, COLUMNS.min(columns.len())));
        for (panel, (name, points)) in panels.iter().zip(&columns) {
            draw_panel(panel, name, points).map_err(|e| draw_err(&e))?;
        }
        root.present().map_err(|e| draw_err(&e))?;
    }
    skinfield_formats::skf::write_atomic(path, svg.as_bytes()).map_err(|source| PlotError::Io {
        path: path.to_owned(),
        source,
    })
}

/// One column: raw values as dots and their moving average as a line (a long log), or the
/// values joined by a line (a short one, e.g. validation every 100 iterations).
fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    name: &str,
    points: &[(f64, f64)],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (x0, x1) = (
        points.first().map_or(0.0, |p| p.0),
        points.last().map_or(1.0, |p| p.0),
    );
    let x1 = if x1 > x0 { x1 } else { x0 + 1.0 };
    let ys: Vec<f64> = points.iter().map(|p| p.1).collect();
    let smooth = points.len() >= 4 * MOVING_AVERAGE;
    let line: Vec<(f64, f64)> = if smooth {
        points
            .iter()
            .zip(moving_average(&ys, MOVING_AVERAGE))
            .map(|(p, a)| (p.0, a))
            .collect()
    } else {
        points.to_vec()
    };
    let lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let unit = unit_of(name);
    let mut builder = ChartBuilder::on(area);
    builder
        .caption(format!("{name} ({unit})"), ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(70);
    // A log scale where the values are positive and span more than a decade.
    if lo > 0.0 && hi / lo > 10.0 {
        let mut chart = builder.build_cartesian_2d(x0..x1, (lo * 0.9..hi * 1.1).log_scale())?;
        chart
            .configure_mesh()
            .light_line_style(RGBColor(238, 238, 238))
            .x_labels(6)
            .y_labels(6)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.1e}"))
            .x_desc("iteration")
            .y_desc(format!("{unit} (log scale)"))
            .draw()?;
        draw_series(&mut chart, points, line, smooth)
    } else {
        let pad = ((hi - lo) * 0.05).max(1e-12);
        let mut chart = builder.build_cartesian_2d(x0..x1, lo - pad..hi + pad)?;
        chart
            .configure_mesh()
            .light_line_style(RGBColor(238, 238, 238))
            .x_labels(6)
            .y_labels(6)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.3}"))
            .x_desc("iteration")
            .y_desc(unit)
            .draw()?;
        draw_series(&mut chart, points, line, smooth)
    }
}

/// The dots, the line and the legend of one panel.
fn draw_series<'a, DB, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>,
    points: &[(f64, f64)],
    line: Vec<(f64, f64)>,
    smooth: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    Y: Ranged<ValueType = f64>,
{
    let dot = RGBColor(120, 140, 220).filled();
    let pen = RGBColor(200, 30, 30).stroke_width(2);
    let radius = if smooth { 1 } else { 3 };
    chart
        .draw_series(points.iter().map(|&p| Circle::new(p, radius, dot)))?
        .label(if smooth { "raw" } else { "value" })
        .legend(move |(x, y)| Circle::new((x + 8, y), 3, dot));
    let label = if smooth {
        format!("moving average ({MOVING_AVERAGE} points)")
    } else {
        "joined".to_string()
    };
    chart
        .draw_series(LineSeries::new(line, pen))?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], pen));
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fmt::Write as _;

    #[test]
    fn moving_average_is_the_trailing_mean() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(moving_average(&v, 2), vec![1.0, 1.5, 2.5, 3.5, 4.5]);
        assert_eq!(moving_average(&v, 10), vec![1.0, 1.5, 2.0, 2.5, 3.0]);
        assert_eq!(moving_average(&v, 1), v.to_vec());
    }

    #[test]
    fn every_column_gets_a_titled_panel_with_axes_units_and_a_legend() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.svg");
        let mut csv = String::from("iteration,silhouette_boundary,laplacian\n");
        for i in 1..=4 * MOVING_AVERAGE as u32 {
            // One column spans three decades (log axis), the other less than one.
            let _ = writeln!(
                csv,
                "{i},{},{}",
                1.0 / f64::from(i * i),
                1.0 + f64::from(i) * 1e-3
            );
        }
        plot_log(&csv, "SkinNet losses", &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for text in [
            "SkinNet losses",
            "silhouette_boundary (pixels)",
            "laplacian (diagonal²)",
            "iteration",
            "pixels (log scale)",
            "moving average (25 points)",
            "raw",
        ] {
            assert!(svg.contains(text), "missing `{text}`");
        }
        // One line per panel (the moving averages) besides the axes.
        assert!(svg.matches("<polyline").count() >= 2);
        assert!(matches!(
            plot_log("iteration\n1\n", "t", &path),
            Err(PlotError::NoData { .. })
        ));
    }

    #[test]
    fn units_follow_the_column_names() {
        assert_eq!(unit_of("silhouette_px"), "pixels");
        assert_eq!(unit_of("iou"), "intersection / union");
        assert_eq!(unit_of("total"), "weighted sum");
        assert_eq!(unit_of("skinning"), "mean per vertex");
    }
}
