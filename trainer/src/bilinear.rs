//! A single-channel f32 image sampled bilinearly, and the sample as a differentiable candle op
//! (w.r.t. the image point): the rendering loss reads captured colours through it, so that
//! moving a surface point moves where the image is read.
//!
//! Pixel centres are at integer + 0.5 ([`skinfield_formats::Camera`]'s convention); samples
//! outside the image are clamped to its border.

use std::sync::Arc;

use candle_core::{CpuStorage, CustomOp1, Layout, Result, Shape, Tensor, bail};

/// An image of `width × height` f32 values, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct BilinearImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Values, row-major.
    pub data: Vec<f32>,
}

impl BilinearImage {
    /// Bilinear sample at image point `(u, v)` (pixel centres at +0.5, clamped to the border)
    /// and its gradient `(∂/∂u, ∂/∂v)`.
    #[must_use]
    pub fn sample(&self, u: f32, v: f32) -> (f32, [f32; 2]) {
        let (d, g) = self.sample64(f64::from(u), f64::from(v));
        (d as f32, [g[0] as f32, g[1] as f32])
    }

    /// [`BilinearImage::sample`] in f64 (the values are f32; the interpolation is not rounded).
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

/// Bilinear sample of an image at `[N, 2]` image points → `[N]`, with backward.
#[derive(Clone, Debug)]
struct BilinearSample(Arc<BilinearImage>);

/// `∇d` at `[N, 2]` image points → `[N, 2]` (no backward: the sample is piecewise bilinear and
/// the loss never needs second derivatives).
#[derive(Clone, Debug)]
struct BilinearGrad(Arc<BilinearImage>);

/// Applies `f` to each `[u, v]` row of a contiguous `[N, 2]` f32/f64 tensor and keeps the first
/// `out_width` outputs (`[N]` when 1, else `[N, out_width]`).
fn map_points(
    storage: &CpuStorage,
    layout: &Layout,
    op: &str,
    f: impl Fn(f64, f64) -> [f64; 2],
    out_width: usize,
) -> Result<(CpuStorage, Shape)> {
    let dims = layout.shape().dims();
    if dims.len() != 2 || dims[1] != 2 {
        bail!("{op}: expected [N, 2] points, got {dims:?}");
    }
    let Some((a, b)) = layout.contiguous_offsets() else {
        bail!("{op} needs a contiguous input")
    };
    let n = dims[0];
    let shape: Shape = if out_width == 1 {
        n.into()
    } else {
        (n, out_width).into()
    };
    let out = match storage {
        CpuStorage::F32(d) => CpuStorage::F32(
            d[a..b]
                .chunks(2)
                .flat_map(|p| {
                    f(f64::from(p[0]), f64::from(p[1]))
                        .into_iter()
                        .take(out_width)
                        .map(|x| x as f32)
                })
                .collect(),
        ),
        CpuStorage::F64(d) => CpuStorage::F64(
            d[a..b]
                .chunks(2)
                .flat_map(|p| f(p[0], p[1]).into_iter().take(out_width))
                .collect(),
        ),
        _ => bail!("{op}: only f32 and f64 are supported"),
    };
    Ok((out, shape))
}

impl CustomOp1 for BilinearSample {
    fn name(&self) -> &'static str {
        "bilinear-sample"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        map_points(
            storage,
            layout,
            "bilinear-sample",
            |u, v| [self.0.sample64(u, v).0, 0.0],
            1,
        )
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let g = arg
            .contiguous()?
            .apply_op1_no_bwd(&BilinearGrad(self.0.clone()))?;
        Ok(Some(g.broadcast_mul(&grad_res.unsqueeze(1)?)?))
    }
}

impl CustomOp1 for BilinearGrad {
    fn name(&self) -> &'static str {
        "bilinear-grad"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        map_points(
            storage,
            layout,
            "bilinear-grad",
            |u, v| self.0.sample64(u, v).1,
            2,
        )
    }
}

/// `image(uv)` for image points `[N, 2]` → `[N]`, bilinear, differentiable w.r.t. `uv`.
pub fn sample_bilinear(image: &Arc<BilinearImage>, uv: &Tensor) -> Result<Tensor> {
    uv.contiguous()?.apply_op1(BilinearSample(image.clone()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_image(w: usize, h: usize, seed: u64) -> BilinearImage {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        BilinearImage {
            width: w,
            height: h,
            data: (0..w * h).map(|_| rng.random_range(0.0..10.0)).collect(),
        }
    }

    #[test]
    fn samples_at_pixel_centres_are_the_pixels_and_between_them_bilinear() {
        let img = random_image(5, 4, 1);
        for y in 0..4 {
            for x in 0..5 {
                let (v, _) = img.sample(x as f32 + 0.5, y as f32 + 0.5);
                assert!((v - img.data[y * 5 + x]).abs() < 1e-6);
            }
        }
        let (v, g) = img.sample(1.0, 0.5);
        let expect = 0.5 * (img.data[0] + img.data[1]);
        assert!((v - expect).abs() < 1e-6);
        assert!((g[0] - (img.data[1] - img.data[0])).abs() < 1e-6);
        // Clamped outside: constant along the clamped axis, zero gradient there.
        let (v, g) = img.sample(-3.0, 0.5);
        assert!((v - img.data[0]).abs() < 1e-6 && g[0] == 0.0);
    }

    #[test]
    fn sample_gradient_matches_finite_differences() {
        let img = random_image(30, 20, 9);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for _ in 0..50 {
            let (u, v) = (
                rng.random_range(1.0..29.0f32),
                rng.random_range(1.0..19.0f32),
            );
            let (_, g) = img.sample(u, v);
            let h = 1e-3;
            // Skip points within h of a cell edge, where the bilinear gradient jumps.
            if ((u - 0.5).fract() < 2.0 * h)
                || ((u - 0.5).fract() > 1.0 - 2.0 * h)
                || ((v - 0.5).fract() < 2.0 * h)
                || ((v - 0.5).fract() > 1.0 - 2.0 * h)
            {
                continue;
            }
            let fu = (img.sample(u + h, v).0 - img.sample(u - h, v).0) / (2.0 * h);
            let fv = (img.sample(u, v + h).0 - img.sample(u, v - h).0) / (2.0 * h);
            assert!(
                (g[0] - fu).abs() < 2e-2 && (g[1] - fv).abs() < 2e-2,
                "{g:?} vs {fu} {fv}"
            );
        }
    }

    #[test]
    fn the_op_matches_the_sampler_and_its_gradient() {
        use candle_core::{Device, Var};
        let img = Arc::new(random_image(12, 9, 4));
        let pts = [[2.3f64, 3.7], [7.9, 1.2], [0.2, 8.8]];
        let uv = Var::from_tensor(&Tensor::new(&pts, &Device::Cpu).unwrap()).unwrap();
        let s = sample_bilinear(&img, uv.as_tensor()).unwrap();
        let values = s.to_vec1::<f64>().unwrap();
        let g = s.sum_all().unwrap().backward().unwrap();
        let g = g.get(uv.as_tensor()).unwrap().to_vec2::<f64>().unwrap();
        for (i, p) in pts.iter().enumerate() {
            let (v, grad) = img.sample64(p[0], p[1]);
            assert!((values[i] - v).abs() < 1e-12);
            assert!((g[i][0] - grad[0]).abs() < 1e-12 && (g[i][1] - grad[1]).abs() < 1e-12);
        }
    }
}
