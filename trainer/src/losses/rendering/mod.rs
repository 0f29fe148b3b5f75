//! Rendering loss (paper Eq. 5): L1 between the posed, coloured mesh rendered into a training
//! view and the captured image, `L_rend = Σ_c ‖Π_c(V, C_c) − I_c‖₁`.
//!
//! # What is differentiated, and the approximation
//!
//! The z-buffered rasteriser ([`crate::raster`]) is run on the current posed mesh once per
//! view and iteration; it fixes, per pixel, the visible triangle `(i, j, k)` and the
//! perspective-correct barycentrics `b` of the pixel centre. Those are constants of the step:
//! visibility changes and silhouette-edge motion get no gradient (the silhouette loss handles
//! the outline). A fixed, seeded subset of the visible pixels is used ([`sample_visible`]).
//! For each sampled pixel `s` the loss term is
//!
//! `ℓ_s = ‖ I(π(Σ_m b_m x_m)) − Σ_m b_m c_m ‖₁`   (sum over the three colour channels)
//!
//! - `Σ_m b_m c_m` is the rasterised colour, exactly linear in the vertex colours `c_m`, so the
//!   gradient into the appearance nets is the exact gradient of the pixel-space L1 loss.
//! - `X_s = Σ_m b_m x_m` is the surface point seen through the pixel. At the current positions
//!   `π(X_s)` is that pixel's centre, so the value of `ℓ_s` equals the pixel-space loss. Moving
//!   the vertices moves `π(X_s)`, and `I` is sampled there bilinearly, so `∂ℓ/∂x` is
//!   `−sign(r)·∇I · ∂π/∂X · b_m`: the surface point carries its colour, and the gradient moves it
//!   to where the image shows that colour (the image-gradient or inverse-warping form). This is
//!   not the derivative of the rendered image w.r.t. the vertices (which needs edge sampling);
//!   it is what `docs/design.md` (*Losses*) describes and what the finite-difference tests check,
//!   with `b` and the sample set held fixed.
//!
//! The bilinear sampler is [`sample_bilinear`] on one [`BilinearImage`] per colour channel
//! (differentiable, edge-clamped).

use std::sync::Arc;

use candle_core::{DType, Result, Tensor};
use glam::Vec3;
use rand::Rng;
use skinfield_formats::Camera;

use super::projection::project;
use crate::bilinear::{BilinearImage, sample_bilinear};
use crate::raster::{Fragments, NO_TRIANGLE};

mod blur;
pub use blur::blur_within_mask;

/// A captured colour image as three bilinearly sampled channels.
#[derive(Clone, Debug)]
pub struct RgbTarget {
    channels: [Arc<BilinearImage>; 3],
}

/// Why a colour image cannot be a rendering target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RgbTargetError {
    /// The pixel count is not `width × height` (or the image is empty).
    #[error("{len} pixels for a {width}×{height} image")]
    Size {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Pixels given.
        len: usize,
    },
}

impl RgbTarget {
    /// Wraps a row-major linear-RGB image.
    pub fn new(
        width: usize,
        height: usize,
        rgb: &[Vec3],
    ) -> std::result::Result<Self, RgbTargetError> {
        if width < 2 || height < 2 || width.checked_mul(height) != Some(rgb.len()) {
            return Err(RgbTargetError::Size {
                width,
                height,
                len: rgb.len(),
            });
        }
        let channel = |k: usize| {
            Arc::new(BilinearImage {
                width,
                height,
                data: rgb.iter().map(|c| c[k]).collect(),
            })
        };
        Ok(Self {
            channels: [channel(0), channel(1), channel(2)],
        })
    }

    /// Width in pixels.
    #[must_use]
    pub fn width(&self) -> usize {
        self.channels[0].width
    }

    /// Height in pixels.
    #[must_use]
    pub fn height(&self) -> usize {
        self.channels[0].height
    }

    /// Bilinear colour at image points `[N, 2]` → `[N, 3]`, differentiable w.r.t. the points.
    pub fn sample(&self, uv: &Tensor) -> Result<Tensor> {
        let c = self
            .channels
            .iter()
            .map(|ch| sample_bilinear(ch, uv))
            .collect::<Result<Vec<_>>>()?;
        Tensor::stack(&c, 1)
    }
}

/// Sampled visible pixels of one rasterised view.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PixelSamples {
    /// Pixel index (row-major) of each sample.
    pub pixels: Vec<u32>,
    /// The visible triangle's vertex indices, three per sample.
    pub corners: Vec<u32>,
    /// Perspective-correct barycentrics of each sample's pixel centre.
    pub bary: Vec<[f32; 3]>,
}

impl PixelSamples {
    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    /// True when no pixel is visible.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }
}

/// Up to `count` distinct visible pixels drawn uniformly with `rng` (all of them, in pixel order,
/// when fewer are visible or `count == 0`).
pub fn sample_visible(
    frags: &Fragments,
    triangles: &[[u32; 3]],
    count: usize,
    rng: &mut impl Rng,
) -> PixelSamples {
    let mut visible: Vec<u32> = frags
        .triangle
        .iter()
        .enumerate()
        .filter(|&(_, &t)| t != NO_TRIANGLE && (t as usize) < triangles.len())
        .map(|(p, _)| p as u32)
        .collect();
    if count > 0 && count < visible.len() {
        // Partial Fisher–Yates: the first `count` entries become a uniform sample.
        for i in 0..count {
            let j = rng.random_range(i..visible.len());
            visible.swap(i, j);
        }
        visible.truncate(count);
    }
    let mut out = PixelSamples::default();
    for p in visible {
        let t = triangles[frags.triangle[p as usize] as usize];
        out.pixels.push(p);
        out.corners.extend_from_slice(&t);
        out.bary.push(frags.bary[p as usize]);
    }
    out
}

/// `Σ_m b_m · rows_m` for per-corner rows `[3N, C]` → `[N, C]`.
fn interpolate(corner_rows: &Tensor, bary: &Tensor) -> Result<Tensor> {
    let (n3, c) = corner_rows.dims2()?;
    corner_rows
        .reshape((n3 / 3, 3, c))?
        .broadcast_mul(bary)?
        .sum(1)
}

/// The samples' barycentrics as `[N, 3, 1]` of type `dtype`.
fn bary_tensor(
    samples: &PixelSamples,
    dtype: DType,
    device: &candle_core::Device,
) -> Result<Tensor> {
    let b: Vec<f32> = samples.bary.iter().flatten().copied().collect();
    Tensor::from_vec(b, (samples.len(), 3, 1), device)?.to_dtype(dtype)
}

/// Image points `[N, 2]` of the samples' surface points `Σ_m b_m x_m` for posed vertices
/// `posed` `[V, 3]` (differentiable in `posed`).
pub fn sample_points(camera: &Camera, samples: &PixelSamples, posed: &Tensor) -> Result<Tensor> {
    let idx = Tensor::from_slice(&samples.corners, samples.corners.len(), posed.device())?;
    let b = bary_tensor(samples, posed.dtype(), posed.device())?;
    let surface = interpolate(&posed.index_select(&idx, 0)?, &b)?;
    project(camera, &surface)
}

/// Sum over samples of `ℓ_s` (module docs) for posed vertices `posed` `[V, 3]` and the colours
/// of each sample's three corners in this view, `corner_colours` `[3N, 3]` (sample-major). Both
/// are differentiable; divide by [`PixelSamples::len`] for a mean. Zero for no samples.
pub fn rendering_loss(
    camera: &Camera,
    target: &RgbTarget,
    samples: &PixelSamples,
    posed: &Tensor,
    corner_colours: &Tensor,
) -> Result<Tensor> {
    if samples.is_empty() {
        return Tensor::zeros((), posed.dtype(), posed.device());
    }
    let (rows, width) = corner_colours.dims2()?;
    if rows != samples.corners.len() || width != 3 {
        candle_core::bail!(
            "rendering_loss: corner colours {rows}×{width}, expected {}×3",
            samples.corners.len()
        );
    }
    let observed = target.sample(&sample_points(camera, samples, posed)?)?;
    let b = bary_tensor(samples, corner_colours.dtype(), corner_colours.device())?;
    let predicted = interpolate(corner_colours, &b)?;
    (observed - predicted)?.abs()?.sum_all()
}

#[cfg(test)]
mod tests;
