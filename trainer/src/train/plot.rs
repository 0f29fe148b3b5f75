//! A PNG of the loss curves in `losses.csv` (one panel per column, log-scaled values), so a run
//! can be judged at a glance without a plotting tool.

use std::path::Path;

use glam::Vec3;
use skinfield_formats::capture::{CaptureError, write_image_png};

/// Panel size in pixels.
const PANEL: (usize, usize) = (320, 160);

/// Draws every numeric column of the CSV text (after the first, the iteration) against the
/// iteration, each in its own panel normalised to its own log10 range; writes `path` as PNG.
pub fn plot_losses(csv: &str, path: &Path) -> Result<(), CaptureError> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|v| v.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    let series = header.len().saturating_sub(1).max(1);
    let (w, h) = (PANEL.0, PANEL.1 * series);
    let mut img = vec![Vec3::ONE; w * h];
    let colors = [
        Vec3::new(0.8, 0.1, 0.1),
        Vec3::new(0.1, 0.4, 0.8),
        Vec3::new(0.1, 0.6, 0.2),
        Vec3::new(0.6, 0.2, 0.7),
    ];
    for s in 0..series {
        let top = s * PANEL.1;
        // Panel frame.
        for x in 0..w {
            img[top * w + x] = Vec3::splat(0.6);
        }
        let values: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| Some((*r.first()?, *r.get(s + 1)?)))
            .filter(|(i, v)| i.is_finite() && v.is_finite() && *v > 0.0)
            .map(|(i, v)| (i, v.log10()))
            .collect();
        if values.len() < 2 {
            continue;
        }
        let (x0, x1) = (
            values[0].0,
            values[values.len() - 1].0.max(values[0].0 + 1.0),
        );
        let lo = values.iter().map(|v| v.1).fold(f64::INFINITY, f64::min);
        let hi = values
            .iter()
            .map(|v| v.1)
            .fold(f64::NEG_INFINITY, f64::max)
            .max(lo + 1e-9);
        let color = colors[s % colors.len()];
        for (i, v) in &values {
            let x = ((i - x0) / (x1 - x0) * (w - 1) as f64) as usize;
            let y = top + 4 + ((hi - v) / (hi - lo) * (PANEL.1 - 9) as f64) as usize;
            for dy in 0..2 {
                img[(y + dy).min(h - 1) * w + x.min(w - 1)] = color;
            }
        }
    }
    write_image_png(path, w as u32, h as u32, &img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_one_panel_per_series_and_marks_pixels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        let csv = "iteration,a,b\n1,1.0,0.5\n2,0.5,0.4\n3,0.25,0.3\n";
        plot_losses(csv, &path).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(
            (img.width() as usize, img.height() as usize),
            (PANEL.0, 2 * PANEL.1)
        );
        // The first series falls from the top-left to the bottom-right of its panel.
        let red = |x: u32, y: u32| img.get_pixel(x, y)[0] > 150 && img.get_pixel(x, y)[1] < 100;
        assert!((0..12).any(|dy| red(0, 4 + dy)));
        assert!((0..12).any(|dy| red(PANEL.0 as u32 - 1, PANEL.1 as u32 - 12 + dy)));
    }
}
