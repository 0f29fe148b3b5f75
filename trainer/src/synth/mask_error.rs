//! Masks as a segmentation would get them wrong: the outline moved by a constant margin.
//!
//! A capture's masks come from background subtraction or a segmentation network, whose
//! commonest error is a bias: every outline a fraction of a pixel to a few pixels too far out
//! (halos, motion blur, shadows counted as foreground) or too far in. The silhouette loss is
//! unbiased at the mask's 50 % coverage outline (module `losses::silhouette`), so such a bias
//! is exactly what it would teach the weights to reproduce, and the validation guard, scored
//! against masks with the same bias, cannot see it. [`offset_coverage`] writes the masks of a
//! synthetic capture with that error, so how much of it training tolerates can be measured
//! against the exact ground truth.
//!
//! The moved mask is the anti-aliased coverage of the outline offset along its normals:
//! `clamp(0.5 + s(p) + δ, 0, 1)` at every pixel centre `p`, with `s` the signed distance in
//! pixels to the 50 % outline (positive inside). Its 50 % outline is the original one moved out
//! by `δ` (in by `−δ`) wherever the outline's curvature radius exceeds `|δ|`, and its coverage
//! ramps over one pixel across the outline, as a box-filtered edge does.

use glam::Vec2;

use crate::losses::silhouette::outline::Outline;

/// The coverage `coverage` (row-major `width × height`, values in `[0, 1]`) with its 50 %
/// outline moved outwards by `offset_px` pixels (inwards when negative). An empty mask is
/// returned unchanged, as is any mask at an offset of 0. Outside the image counts as uncovered
/// (as for the loss), so a mask covering the border has an outline there that moves too.
#[must_use]
pub fn offset_coverage(coverage: &[f32], width: usize, height: usize, offset_px: f32) -> Vec<f32> {
    if offset_px == 0.0 {
        return coverage.to_vec();
    }
    let Ok(outline) = Outline::from_coverage(width, height, coverage) else {
        return coverage.to_vec();
    };
    coverage
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            let p = Vec2::new((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
            let (d, _) = outline.distance(p);
            let signed = if c >= 0.5 { d } else { -d };
            (0.5 + signed + offset_px).clamp(0.0, 1.0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Anti-aliased disc of radius `r` centred in an `n × n` image (4 × 4 supersampling).
    fn disc(n: usize, r: f32) -> Vec<f32> {
        let c = n as f32 / 2.0;
        (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f32, (i / n) as f32);
                let mut inside = 0;
                for sy in 0..4 {
                    for sx in 0..4 {
                        let p = Vec2::new(x + (sx as f32 + 0.5) / 4.0, y + (sy as f32 + 0.5) / 4.0);
                        if (p - Vec2::splat(c)).length() < r {
                            inside += 1;
                        }
                    }
                }
                inside as f32 / 16.0
            })
            .collect()
    }

    /// The area of the 50 % region, in pixels, from the coverage (a box-filtered edge's
    /// coverage sums to the area it encloses).
    fn area(coverage: &[f32]) -> f32 {
        coverage.iter().sum()
    }

    #[test]
    fn the_outline_moves_by_the_offset() {
        let (n, r) = (64, 20.0);
        let base = disc(n, r);
        for offset in [-2.0f32, -0.5, 0.5, 1.0, 3.0] {
            let moved = offset_coverage(&base, n, n, offset);
            // The area of a disc of radius r + offset, within a tenth of a pixel of radius.
            let radius = (area(&moved) / core::f32::consts::PI).sqrt();
            assert!(
                (radius - (r + offset)).abs() < 0.1,
                "offset {offset}: radius {radius}"
            );
            assert!(moved.iter().all(|c| (0.0..=1.0).contains(c)));
        }
    }

    #[test]
    fn no_offset_and_an_empty_mask_change_nothing() {
        let base = disc(32, 9.0);
        assert_eq!(offset_coverage(&base, 32, 32, 0.0), base);
        let empty = vec![0.0; 32 * 32];
        assert_eq!(offset_coverage(&empty, 32, 32, 1.5), empty);
    }
}
