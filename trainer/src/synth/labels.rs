//! Part-label images of a synthetic capture: what a human-parsing network would paint, rendered
//! from the ground truth, with optional errors along the part boundaries (where real parsers
//! err).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::capture::NO_LABEL;
use skinfield_formats::{Camera, PartLabel};

use crate::raster::{NO_TRIANGLE, rasterize};

/// Colour of each part label in the label images (index = [`PartLabel`] value): skin, clothing.
pub const PART_PALETTE: [[u8; 3]; 2] = [[230, 150, 110], [40, 90, 210]];

/// Renders the part label of every pixel (the label of the visible triangle's vertex nearest
/// to the pixel, [`NO_LABEL`] off the subject) of a posed mesh.
#[must_use]
pub fn render_labels(
    camera: &Camera,
    positions: &[glam::Vec3],
    triangles: &[[u32; 3]],
    parts: &[PartLabel],
) -> Vec<u8> {
    let frags = rasterize(camera, positions, triangles);
    frags
        .triangle
        .iter()
        .zip(&frags.bary)
        .map(|(&t, b)| {
            if t == NO_TRIANGLE {
                return NO_LABEL;
            }
            let tri = triangles[t as usize];
            let k = (0..3).max_by(|&i, &j| b[i].total_cmp(&b[j])).unwrap_or(0);
            parts.get(tri[k] as usize).map_or(NO_LABEL, |&p| p as u8)
        })
        .collect()
}

/// Boundary noise: every pixel with a 4-neighbour of another label (the background included)
/// takes, with probability `p`, the label of one of those neighbours, chosen at random. Seeded;
/// decisions are made on the clean image, so the result does not depend on the scan order.
#[must_use]
pub fn with_boundary_noise(
    labels: &[u8],
    width: usize,
    height: usize,
    p: f32,
    seed: u64,
) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = labels.to_vec();
    if p <= 0.0 {
        return out;
    }
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            let mut others = [NO_LABEL; 4];
            let mut n = 0;
            let neighbours = [
                (x > 0).then(|| i - 1),
                (x + 1 < width).then(|| i + 1),
                (y > 0).then(|| i - width),
                (y + 1 < height).then(|| i + width),
            ];
            for j in neighbours.into_iter().flatten() {
                if labels[j] != labels[i] {
                    others[n] = labels[j];
                    n += 1;
                }
            }
            if n > 0 && rng.random::<f32>() < p {
                out[i] = others[rng.random_range(0..n)];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boundary_noise_touches_only_boundary_pixels_at_about_its_rate() {
        // Left half skin, right half clothing, a background border.
        let (w, h) = (40, 30);
        let labels: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if x == 0 || y == 0 || x == w - 1 || y == h - 1 {
                    NO_LABEL
                } else {
                    u8::from(x >= w / 2)
                }
            })
            .collect();
        assert_eq!(with_boundary_noise(&labels, w, h, 0.0, 1), labels);
        let noisy = with_boundary_noise(&labels, w, h, 0.5, 1);
        assert_eq!(noisy, with_boundary_noise(&labels, w, h, 0.5, 1), "seeded");
        let changed: Vec<usize> = (0..w * h).filter(|&i| noisy[i] != labels[i]).collect();
        for &i in &changed {
            let (x, y) = (i % w, i / w);
            let boundary =
                x <= 1 || y <= 1 || x >= w - 2 || y >= h - 2 || x + 1 == w / 2 || x == w / 2;
            assert!(boundary, "pixel ({x}, {y}) is not on a boundary");
        }
        // Boundary pixels: the outer ring (2 px wide with its inner neighbours) and the seam.
        let boundary = (0..w * h)
            .filter(|&i| {
                let (x, y) = (i % w, i / w);
                x <= 1 || y <= 1 || x >= w - 2 || y >= h - 2 || x + 1 == w / 2 || x == w / 2
            })
            .count();
        let rate = changed.len() as f32 / boundary as f32;
        assert!((0.35..0.65).contains(&rate), "{rate}");
    }
}
