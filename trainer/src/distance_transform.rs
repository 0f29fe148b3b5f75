//! Exact Euclidean distance transforms (Felzenszwalb & Huttenlocher 2012) and the silhouette
//! contour they are taken of.
//!
//! The silhouette loss (paper supplementary E, DeepCap Eq. 11) samples `d_c(u)`, the distance from
//! image point `u` to the mask contour, so the contour is the zero set. Pixel centres are at
//! integer + 0.5 ([`skinfield_formats::Camera`]'s convention); samples between centres are
//! bilinear, which makes the loss differentiable with respect to the projected position.

/// Why a distance transform cannot be built.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DistanceError {
    /// Width or height is zero, or `width × height` overflows.
    #[error("image is {width}×{height}")]
    BadSize {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
    /// The input has a different number of pixels than `width × height`.
    #[error("image has {len} pixels, expected {expected}")]
    Length {
        /// Given.
        len: usize,
        /// Expected.
        expected: usize,
    },
    /// No site pixel: the distance is undefined everywhere.
    #[error("no site pixel (empty contour)")]
    NoSites,
}

/// Stand-in for +∞ in the lower-envelope computation (∞ − ∞ would be NaN).
const FAR: f64 = 1e20;

/// Squared distance transform of a sampled function in 1D: `d(q) = min_p (q − p)² + f(p)`.
/// `v` and `z` are scratch of length `n` and `n + 1`.
fn dt1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let sq = |q: usize| (q * q) as f64;
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        // z[0] = −∞, so k never drops below 0.
        let mut s = ((f[q] + sq(q)) - (f[v[k]] + sq(v[k]))) / (2.0 * (q as f64 - v[k] as f64));
        while s <= z[k] {
            k -= 1;
            s = ((f[q] + sq(q)) - (f[v[k]] + sq(v[k]))) / (2.0 * (q as f64 - v[k] as f64));
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, dq) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        let dx = q as f64 - p as f64;
        *dq = dx * dx + f[p];
    }
}

/// A distance image: `data[y · width + x]` is the Euclidean distance (pixels) from pixel
/// `(x, y)`'s centre to the nearest site pixel's centre.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Distances, row-major.
    pub data: Vec<f32>,
}

fn check(width: usize, height: usize, len: usize) -> Result<(), DistanceError> {
    let expected = width
        .checked_mul(height)
        .filter(|&n| n > 0)
        .ok_or(DistanceError::BadSize { width, height })?;
    if len != expected {
        return Err(DistanceError::Length { len, expected });
    }
    Ok(())
}

impl DistanceImage {
    /// Exact Euclidean distance to the nearest `true` pixel of `sites` (two 1D passes).
    pub fn from_sites(width: usize, height: usize, sites: &[bool]) -> Result<Self, DistanceError> {
        check(width, height, sites.len())?;
        if !sites.iter().any(|&s| s) {
            return Err(DistanceError::NoSites);
        }
        let n = width.max(height);
        let mut grid: Vec<f64> = sites.iter().map(|&s| if s { 0.0 } else { FAR }).collect();
        let (mut f, mut d, mut v, mut z) = (
            vec![0.0; n],
            vec![0.0; n],
            vec![0usize; n],
            vec![0.0; n + 1],
        );
        for x in 0..width {
            for y in 0..height {
                f[y] = grid[y * width + x];
            }
            dt1d(&f[..height], &mut d[..height], &mut v, &mut z);
            for y in 0..height {
                grid[y * width + x] = d[y];
            }
        }
        for y in 0..height {
            let row = &mut grid[y * width..(y + 1) * width];
            f[..width].copy_from_slice(row);
            dt1d(&f[..width], &mut d[..width], &mut v, &mut z);
            row.copy_from_slice(&d[..width]);
        }
        Ok(Self {
            width,
            height,
            data: grid.iter().map(|&s| s.sqrt() as f32).collect(),
        })
    }

    /// The distance transform of `mask`'s contour ([`mask_contour`]).
    pub fn of_mask_contour(
        width: usize,
        height: usize,
        mask: &[bool],
    ) -> Result<Self, DistanceError> {
        Self::from_sites(width, height, &mask_contour(width, height, mask)?)
    }

    /// Bilinear sample at image point `(u, v)` (pixel centres at +0.5, clamped to the border)
    /// and its gradient `(∂/∂u, ∂/∂v)`.
    #[must_use]
    pub fn sample(&self, u: f32, v: f32) -> (f32, [f32; 2]) {
        let (d, g) = self.sample64(f64::from(u), f64::from(v));
        (d as f32, [g[0] as f32, g[1] as f32])
    }

    /// [`DistanceImage::sample`] in f64 (the distances are f32; the interpolation is not rounded).
    #[must_use]
    pub fn sample64(&self, u: f64, v: f64) -> (f64, [f64; 2]) {
        let (w, h) = (self.width, self.height);
        let clamp = |t: f64, n: usize| {
            if t.is_finite() {
                (t - 0.5).clamp(0.0, (n - 1) as f64)
            } else {
                0.0
            }
        };
        let (x, y) = (clamp(u, w), clamp(v, h));
        let (x0, y0) = (
            (x.floor() as usize).min(w.saturating_sub(2)),
            (y.floor() as usize).min(h.saturating_sub(2)),
        );
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let at = |x: usize, y: usize| f64::from(self.data[y * w + x]);
        let (a, b, c, d) = (at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1));
        let value =
            a * (1.0 - fx) * (1.0 - fy) + b * fx * (1.0 - fy) + c * (1.0 - fx) * fy + d * fx * fy;
        // Outside the image (clamped) the sample is constant along the clamped axis.
        let inside_u = u - 0.5 > 0.0 && u - 0.5 < (w - 1) as f64;
        let inside_v = v - 0.5 > 0.0 && v - 0.5 < (h - 1) as f64;
        let du = if inside_u {
            (b - a) * (1.0 - fy) + (d - c) * fy
        } else {
            0.0
        };
        let dv = if inside_v {
            (c - a) * (1.0 - fx) + (d - b) * fx
        } else {
            0.0
        };
        (value, [du, dv])
    }
}

/// Contour pixels of a binary mask: foreground pixels with a 4-neighbour that is background or
/// outside the image.
pub fn mask_contour(
    width: usize,
    height: usize,
    mask: &[bool],
) -> Result<Vec<bool>, DistanceError> {
    check(width, height, mask.len())?;
    let at = |x: isize, y: isize| {
        x >= 0
            && y >= 0
            && (x as usize) < width
            && (y as usize) < height
            && mask[y as usize * width + x as usize]
    };
    let mut out = vec![false; mask.len()];
    for y in 0..height as isize {
        for x in 0..width as isize {
            if at(x, y) && !(at(x - 1, y) && at(x + 1, y) && at(x, y - 1) && at(x, y + 1)) {
                out[y as usize * width + x as usize] = true;
            }
        }
    }
    Ok(out)
}

/// Pixel centres `(x + 0.5, y + 0.5)` of the `true` pixels, row-major order.
#[must_use]
pub fn site_centres(width: usize, sites: &[bool]) -> Vec<[f32; 2]> {
    sites
        .iter()
        .enumerate()
        .filter(|(_, s)| **s)
        .map(|(i, _)| [(i % width) as f32 + 0.5, (i / width) as f32 + 0.5])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn brute(width: usize, height: usize, sites: &[bool]) -> Vec<f32> {
        let pts: Vec<(usize, usize)> = (0..sites.len())
            .filter(|&i| sites[i])
            .map(|i| (i % width, i / width))
            .collect();
        (0..width * height)
            .map(|i| {
                let (x, y) = (i % width, i / width);
                pts.iter()
                    .map(|&(a, b)| {
                        ((x as f64 - a as f64).powi(2) + (y as f64 - b as f64).powi(2)).sqrt()
                    })
                    .fold(f64::INFINITY, f64::min) as f32
            })
            .collect()
    }

    #[test]
    fn equals_brute_force_on_random_sites() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for (w, h, p) in [
            (37, 23, 0.02),
            (1, 17, 0.2),
            (19, 1, 0.2),
            (40, 40, 0.001),
            (16, 9, 0.5),
        ] {
            let mut sites: Vec<bool> = (0..w * h).map(|_| rng.random_bool(p)).collect();
            sites[rng.random_range(0..w * h)] = true;
            let dt = DistanceImage::from_sites(w, h, &sites).unwrap();
            for (i, (a, b)) in dt.data.iter().zip(brute(w, h, &sites)).enumerate() {
                assert!((a - b).abs() < 1e-4, "{w}×{h} pixel {i}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn contour_of_a_square_and_distance_inside_it() {
        // 3..7 × 3..7 square in a 10×10 image: the contour is its 12-pixel ring.
        let mask: Vec<bool> = (0..100)
            .map(|i| (3..7).contains(&(i % 10)) && (3..7).contains(&(i / 10)))
            .collect();
        let c = mask_contour(10, 10, &mask).unwrap();
        assert_eq!(c.iter().filter(|&&b| b).count(), 12);
        let dt = DistanceImage::of_mask_contour(10, 10, &mask).unwrap();
        assert_eq!(dt.data[4 * 10 + 4], 1.0);
        assert_eq!(dt.data[0], (18.0f32).sqrt()); // (0,0) → (3,3)
        // Bilinear: halfway between pixel (0,0) and (1,0) centres.
        let (v, g) = dt.sample(1.0, 0.5);
        let expect = 0.5 * (dt.data[0] + dt.data[1]);
        assert!((v - expect).abs() < 1e-6);
        assert!((g[0] - (dt.data[1] - dt.data[0])).abs() < 1e-6);
    }

    #[test]
    fn sample_gradient_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let sites: Vec<bool> = (0..30 * 20).map(|_| rng.random_bool(0.01)).collect();
        let dt = DistanceImage::from_sites(30, 20, &sites).unwrap();
        for _ in 0..50 {
            let (u, v) = (
                rng.random_range(1.0..29.0f32),
                rng.random_range(1.0..19.0f32),
            );
            let (_, g) = dt.sample(u, v);
            let h = 1e-3;
            // Skip points within h of a cell edge, where the bilinear gradient jumps.
            if ((u - 0.5).fract() < 2.0 * h)
                || ((u - 0.5).fract() > 1.0 - 2.0 * h)
                || ((v - 0.5).fract() < 2.0 * h)
                || ((v - 0.5).fract() > 1.0 - 2.0 * h)
            {
                continue;
            }
            let fu = (dt.sample(u + h, v).0 - dt.sample(u - h, v).0) / (2.0 * h);
            let fv = (dt.sample(u, v + h).0 - dt.sample(u, v - h).0) / (2.0 * h);
            assert!(
                (g[0] - fu).abs() < 2e-2 && (g[1] - fv).abs() < 2e-2,
                "{g:?} vs {fu} {fv}"
            );
        }
    }

    #[test]
    fn rejects_bad_input() {
        assert_eq!(
            DistanceImage::from_sites(0, 3, &[]),
            Err(DistanceError::BadSize {
                width: 0,
                height: 3
            })
        );
        assert_eq!(
            DistanceImage::from_sites(2, 2, &[true; 3]),
            Err(DistanceError::Length {
                len: 3,
                expected: 4
            })
        );
        assert_eq!(
            DistanceImage::from_sites(2, 2, &[false; 4]),
            Err(DistanceError::NoSites)
        );
    }
}
