//! Low-pass filtering of the rendering loss's target images to the detail the colour model
//! can show.
//!
//! The rendered colour of a sample is interpolated from the training template's vertices (or
//! from a field that, within a few hundred iterations, has learned only its low frequencies),
//! so it is a blurred version of what the camera saw. Against a sharp image that blur is
//! not neutral: with the L1 loss, a surface point on either side of a texture edge reads a
//! residual whose sign sends it *towards* the edge, so the rendering term pulls the geometry
//! onto the texture's edges. Blurring the target to a comparable bandwidth weakens that pull at
//! the true geometry while keeping the image gradients that carry a drifted point back.
//!
//! The blur is a normalised convolution inside the foreground mask, `G∗(I·M) / G∗M`, so the
//! background never bleeds into the subject's colours; background pixels are left as they are
//! (the subject's outline is the silhouette loss's business).

use glam::Vec3;

/// Separable Gaussian taps `exp(−x²/2σ²)` for `x ∈ [−r, r]`, `r = ⌈3σ⌉` (unnormalised: the
/// normalised convolution divides by the mask's own response).
fn taps(sigma: f32) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as i64;
    (-r..=r)
        .map(|x| (-(x * x) as f32 / (2.0 * sigma * sigma)).exp())
        .collect()
}

/// One separable pass along rows (`horizontal`) or columns of `[value, weight]` pairs, edges
/// treated as empty.
fn pass(
    width: usize,
    height: usize,
    src: &[[f32; 4]],
    taps: &[f32],
    horizontal: bool,
) -> Vec<[f32; 4]> {
    let r = (taps.len() / 2) as i64;
    let mut out = vec![[0.0; 4]; src.len()];
    for y in 0..height {
        for x in 0..width {
            let mut acc = [0.0f32; 4];
            for (k, &t) in taps.iter().enumerate() {
                let d = k as i64 - r;
                let (sx, sy) = if horizontal {
                    (x as i64 + d, y as i64)
                } else {
                    (x as i64, y as i64 + d)
                };
                if sx < 0 || sy < 0 || sx >= width as i64 || sy >= height as i64 {
                    continue;
                }
                let s = &src[sy as usize * width + sx as usize];
                for (a, v) in acc.iter_mut().zip(s) {
                    *a += t * v;
                }
            }
            out[y * width + x] = acc;
        }
    }
    out
}

/// `rgb` blurred with a Gaussian of `sigma` pixels inside `inside` (normalised convolution);
/// pixels outside the mask, and every pixel when `sigma` is not positive, are returned as
/// they are. `rgb` and `inside` are row-major `width × height`; returns `None` when their
/// lengths differ from it.
#[must_use]
pub fn blur_within_mask(
    width: usize,
    height: usize,
    rgb: &[Vec3],
    inside: &[bool],
    sigma: f32,
) -> Option<Vec<Vec3>> {
    let n = width.checked_mul(height)?;
    if rgb.len() != n || inside.len() != n {
        return None;
    }
    if sigma.is_nan() || sigma <= 0.0 {
        return Some(rgb.to_vec());
    }
    let taps = taps(sigma);
    let masked: Vec<[f32; 4]> = rgb
        .iter()
        .zip(inside)
        .map(|(c, &m)| if m { [c.x, c.y, c.z, 1.0] } else { [0.0; 4] })
        .collect();
    let blurred = pass(
        width,
        height,
        &pass(width, height, &masked, &taps, true),
        &taps,
        false,
    );
    Some(
        rgb.iter()
            .zip(inside)
            .zip(&blurred)
            .map(|((&c, &m), b)| {
                // Inside the mask the pixel's own tap (weight 1) keeps the denominator ≥ 1.
                if m {
                    Vec3::new(b[0], b[1], b[2]) / b[3]
                } else {
                    c
                }
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_sigma_and_constant_images_are_unchanged_and_sizes_are_checked() {
        let rgb: Vec<Vec3> = (0..20).map(|i| Vec3::splat(i as f32 / 20.0)).collect();
        let inside = vec![true; 20];
        assert_eq!(blur_within_mask(5, 4, &rgb, &inside, 0.0).unwrap(), rgb);
        assert_eq!(
            blur_within_mask(5, 4, &rgb, &inside, f32::NAN).unwrap(),
            rgb
        );
        let flat = vec![Vec3::new(0.2, 0.4, 0.6); 20];
        for c in blur_within_mask(5, 4, &flat, &inside, 1.5).unwrap() {
            assert!((c - flat[0]).length() < 1e-6);
        }
        assert!(blur_within_mask(5, 4, &rgb[1..], &inside, 1.0).is_none());
        assert!(blur_within_mask(5, 4, &rgb, &inside[1..], 1.0).is_none());
        assert!(blur_within_mask(usize::MAX, 2, &rgb, &inside, 1.0).is_none());
    }

    /// Against a direct 2-D Gaussian sum over the masked pixels (an independent reference):
    /// the background is untouched and never leaks into the foreground.
    #[test]
    fn matches_a_direct_masked_gaussian_and_keeps_the_background_out() {
        let (w, h, sigma) = (13usize, 9usize, 1.3f32);
        let rgb: Vec<Vec3> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                Vec3::new((0.9 * x).sin().abs(), (0.4 * y).cos().abs(), 0.3)
            })
            .collect();
        let inside: Vec<bool> = (0..w * h).map(|i| (i % w) + (i / w) < 14).collect();
        let out = blur_within_mask(w, h, &rgb, &inside, sigma).unwrap();
        let r = (3.0 * sigma).ceil() as i64;
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let i = (y as usize) * w + x as usize;
                if !inside[i] {
                    assert_eq!(out[i], rgb[i]);
                    continue;
                }
                let (mut sum, mut weight) = (Vec3::ZERO, 0.0);
                for v in (y - r).max(0)..=(y + r).min(h as i64 - 1) {
                    for u in (x - r).max(0)..=(x + r).min(w as i64 - 1) {
                        let j = v as usize * w + u as usize;
                        if inside[j] {
                            let g = (-(((u - x).pow(2) + (v - y).pow(2)) as f32)
                                / (2.0 * sigma * sigma))
                                .exp();
                            sum += rgb[j] * g;
                            weight += g;
                        }
                    }
                }
                assert!((out[i] - sum / weight).length() < 1e-5, "pixel ({x}, {y})");
            }
        }
        // A white background next to a black subject: the subject stays black.
        let rgb: Vec<Vec3> = inside
            .iter()
            .map(|&m| if m { Vec3::ZERO } else { Vec3::ONE })
            .collect();
        let out = blur_within_mask(w, h, &rgb, &inside, 2.0).unwrap();
        assert!(
            out.iter()
                .zip(&inside)
                .all(|(c, &m)| !m || *c == Vec3::ZERO)
        );
    }
}
