//! SkinNet's forward and backward pass as one candle custom op: the training step's MLP without
//! a graph of small tensors.
//!
//! `profile.csv` of a stage-1 run put about 85 % of an iteration in SkinNet's forward and
//! backward through candle's graph (≈ 0.4 s + 0.8 s for 4 frames × 2,500 rows). The work itself
//! is a few dense products; what cost was everything around them: a tensor allocated and
//! written per op, weight normalisation and Softplus as chains of elementwise ops, the split
//! first and skip layers broadcast through `[F·V, out]` temporaries. This op does the same
//! arithmetic in place:
//!
//! - the effective weights `W = g ⊙ v/‖v‖` are formed once per call; weight normalisation's
//!   backward is the exact closed form (`∂g`, `∂v` from `∂W`);
//! - the position parts of the first and the skip layer are one `[V, P]` product per call and
//!   the pose parts one `[F, Q]` product, broadcast into the rows; backward sums their
//!   gradients over the frames (`Σ_f`) or the vertices (`Σ_v`) once before one small product;
//! - dense products run on the `gemm` crate over strided views (transposes are free) on the
//!   current rayon pool's threads;
//! - Softplus and its slope `sigmoid(βz)` come out of one SIMD pass (the runtime's kernels and
//!   polynomials, [`skinfield_runtime::kernels::softplus_with_slope`]); backward multiplies by
//!   the stored slope instead of re-deriving it;
//! - the activation buffers live in a pool owned by the net and are reused from step to step.
//!
//! The op takes the parameters packed into one flat tensor ([`ParamLayout`]; `Tensor::cat` of
//! the variables, whose backward hands each variable its slice), the encoded positions `[V, P]`
//! and the pose features `[F, Q]` (constants), and returns the weights `[F, V, J]`. Forward
//! keeps its activations for the backward pass of the same op instance; a backward without
//! them (a second backward through the same graph) recomputes them. Only f32 is supported; the
//! candle graph ([`super::Backend::Candle`]) remains for f64 and as the reference the tests and
//! the bench compare with.

pub(crate) mod gemm;
mod pass;
mod sparse;

use std::sync::{Arc, Mutex};

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor, bail};
use skinfield_formats::skf::{ModelConfig, Net};
use skinfield_runtime::Kernel;

use super::LocalPoses;

pub(crate) use pass::Activations;
use sparse::LogitMask;
pub(crate) use sparse::worth_sparse;

/// Where each layer's `v`, `g` and `b` sit in the flat parameter vector: layer by layer, `v`
/// (`out × in`, row-major), then `g` (`out`), then `b` (`out`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamLayout {
    /// `(out, in, offset of v)` per layer; `g` follows `v`, `b` follows `g`.
    layers: Vec<(usize, usize, usize)>,
    len: usize,
}

impl ParamLayout {
    /// The layout of SkinNet for `config`.
    #[must_use]
    pub fn new(config: &ModelConfig) -> Self {
        let mut offset = 0;
        let layers = config
            .layer_shapes(Net::Skin)
            .map(|(out, inp)| {
                let at = offset;
                offset += out * inp + 2 * out;
                (out, inp, at)
            })
            .collect();
        Self {
            layers,
            len: offset,
        }
    }

    /// Total number of parameters.
    #[must_use]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no parameters.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Number of layers.
    #[must_use]
    pub fn layer_count(&self) -> usize {
        self.layers.len()
    }

    /// `(out, in)` of layer `i`.
    #[must_use]
    pub fn shape(&self, i: usize) -> (usize, usize) {
        let (out, inp, _) = self.layers[i];
        (out, inp)
    }

    /// The ranges of `v`, `g` and `b` of layer `i` in the flat vector.
    #[must_use]
    pub fn ranges(&self, i: usize) -> [std::ops::Range<usize>; 3] {
        let (out, inp, at) = self.layers[i];
        let g = at + out * inp;
        [at..g, g..g + out, g + out..g + 2 * out]
    }
}

/// A pool of f32 buffers reused across training steps (the activations are ~100 MB per step
/// at the demo's size; allocating them afresh page-faults every page every step).
#[derive(Debug, Default)]
pub(crate) struct BufferPool(Mutex<Vec<Vec<f32>>>);

impl BufferPool {
    /// A buffer of `len` floats whose contents are unspecified (the caller overwrites every
    /// element), reusing a pooled allocation when one is large enough.
    pub(crate) fn take(&self, len: usize) -> Vec<f32> {
        let mut pool = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let found = pool
            .iter()
            .enumerate()
            .filter(|(_, b)| b.capacity() >= len)
            .min_by_key(|(_, b)| b.capacity())
            .map(|(i, _)| i);
        let mut buf = match found {
            Some(i) => pool.swap_remove(i),
            None => Vec::new(),
        };
        // Shrinking keeps the old values, growing adds zeros: either way no pass over memory the
        // caller is about to overwrite.
        buf.resize(len, 0.0);
        buf
    }

    /// Returns buffers to the pool.
    pub(crate) fn give(&self, buffers: impl IntoIterator<Item = Vec<f32>>) {
        let mut pool = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        pool.extend(buffers.into_iter().filter(|b| b.capacity() > 0));
    }
}

/// What the op needs besides its three inputs: the architecture, the SIMD kernel chosen once
/// and the buffer pool, shared by every call of one net.
#[derive(Debug)]
pub(crate) struct FusedContext {
    pub(crate) config: ModelConfig,
    pub(crate) layout: ParamLayout,
    pub(crate) kernel: Kernel,
    pub(crate) pool: BufferPool,
}

impl FusedContext {
    pub(crate) fn new(config: ModelConfig) -> Self {
        Self {
            layout: ParamLayout::new(&config),
            config,
            kernel: Kernel::detect(),
            pool: BufferPool::default(),
        }
    }
}

/// The custom op: `(params [P], positions [V, Pw], poses [F, Qw] or [F, V, Qw]) → weights
/// [F, V, J]`, with an
/// optional additive mask `[V, J]` (0 on candidate joints, −∞ elsewhere) applied to the logits.
/// With `local`, the pose input is that structure and the third input is its frames' poses
/// `[F, Q]` (only their shape is read).
struct FusedSkinNet {
    context: Arc<FusedContext>,
    mask: Option<LogitMask>,
    local: Option<Arc<LocalPoses>>,
    saved: Mutex<Option<Activations>>,
}

impl Drop for FusedSkinNet {
    /// Activations a backward pass never consumed (an evaluation-only forward) go back to the
    /// pool rather than to the allocator.
    fn drop(&mut self) {
        let saved = self
            .saved
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        if let Some(acts) = saved {
            self.context.pool.give(acts.into_buffers());
        }
    }
}

/// `(frames, pose width, per row)` of the pose input: `[F, Q]` (a pose per frame) or
/// `[F, V, Q]` (a pose per row).
fn pose_shape(shape: &Shape, vertices: usize) -> Result<(usize, usize, bool)> {
    match *shape.dims() {
        [f, q] => Ok((f, q, false)),
        [f, rows, q] if rows == vertices => Ok((f, q, true)),
        _ => bail!("fused SkinNet: poses {shape:?} are neither [F, Q] nor [F, {vertices}, Q]"),
    }
}

/// The contiguous f32 data of a storage, or an error naming the argument.
fn f32_data<'a>(s: &'a CpuStorage, l: &Layout, what: &str) -> Result<&'a [f32]> {
    let CpuStorage::F32(d) = s else {
        bail!("fused SkinNet: `{what}` must be f32")
    };
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&d[a..b]),
        None => bail!("fused SkinNet: `{what}` must be contiguous"),
    }
}

impl FusedSkinNet {
    /// The pose input of `F` frames of `V` vertices: the structure when the op has one (checked
    /// against those counts), else the third input's data.
    fn pose_input<'a>(
        &'a self,
        data: &'a [f32],
        per_row: bool,
        frames: usize,
        vertices: usize,
    ) -> Result<pass::Poses<'a>> {
        Ok(match &self.local {
            Some(local) => {
                if per_row
                    || local.frame_count() != frames
                    || local.vertices() != vertices
                    || 3 * local.joints() != self.context.config.pose_width()
                {
                    bail!(
                        "fused SkinNet: local poses of {} frames × {} vertices × {} joints for \
                         {frames} frames × {vertices} vertices × {} pose features",
                        local.frame_count(),
                        local.vertices(),
                        local.joints(),
                        self.context.config.pose_width()
                    );
                }
                pass::Poses::Local(local)
            }
            None if per_row => pass::Poses::PerRow(data),
            None => pass::Poses::PerFrame(data),
        })
    }
}

impl CustomOp3 for FusedSkinNet {
    fn name(&self) -> &'static str {
        "fused-skinnet"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let ctx = &self.context;
        let params = f32_data(s1, l1, "params")?;
        let positions = f32_data(s2, l2, "positions")?;
        let poses = f32_data(s3, l3, "poses")?;
        let (v, p) = l2.shape().dims2()?;
        let (f, q, per_row) = pose_shape(l3.shape(), v)?;
        if params.len() != ctx.layout.len()
            || p != ctx.config.position_width()
            || q != ctx.config.pose_width()
        {
            bail!(
                "fused SkinNet: {} parameters, inputs {p} + {q} wide; expected {}, {} + {}",
                params.len(),
                ctx.layout.len(),
                ctx.config.position_width(),
                ctx.config.pose_width()
            );
        }
        if self
            .mask
            .as_ref()
            .is_some_and(|m| m.additive.len() != v * ctx.config.joint_count as usize)
        {
            bail!("fused SkinNet: the mask is not [V, J]");
        }
        let poses = self.pose_input(poses, per_row, f, v)?;
        let acts = pass::forward(ctx, params, positions, poses, self.mask.as_ref(), f, v)?;
        let weights = acts.output().to_vec();
        *self
            .saved
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(acts);
        let j = ctx.config.joint_count as usize;
        Ok((CpuStorage::F32(weights), Shape::from((f, v, j))))
    }

    fn bwd(
        &self,
        params: &Tensor,
        positions: &Tensor,
        poses: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let ctx = &self.context;
        let taken = self
            .saved
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        let params_v = params.flatten_all()?.to_vec1::<f32>()?;
        let positions_v = positions.flatten_all()?.to_vec1::<f32>()?;
        let poses_v = poses.flatten_all()?.to_vec1::<f32>()?;
        let (v, _) = positions.dims2()?;
        let (f, _, per_row) = pose_shape(poses.shape(), v)?;
        let poses_p = self.pose_input(&poses_v, per_row, f, v)?;
        let acts = match taken {
            Some(a) => a,
            None => pass::forward(
                ctx,
                &params_v,
                &positions_v,
                poses_p,
                self.mask.as_ref(),
                f,
                v,
            )?,
        };
        let grad = grad_res
            .to_dtype(candle_core::DType::F32)?
            .flatten_all()?
            .to_vec1::<f32>()?;
        let dparams = pass::backward(
            ctx,
            &params_v,
            &positions_v,
            poses_p,
            self.mask.as_ref(),
            acts,
            &grad,
        )?;
        let n = dparams.len();
        Ok((
            Some(Tensor::from_vec(dparams, n, params.device())?),
            None,
            None,
        ))
    }
}

/// The additive logit mask `[V, J]`, if any, with its candidate lists where they pay and
/// `structured` allows them.
fn logit_mask(mask: Option<&Tensor>, structured: bool) -> Result<Option<LogitMask>> {
    mask.map(|m| {
        let joints = m.dims().last().copied().unwrap_or(0);
        let values = m
            .to_dtype(candle_core::DType::F32)?
            .flatten_all()?
            .to_vec1()?;
        Ok(if structured {
            LogitMask::new(values, joints)
        } else {
            LogitMask::dense(values)
        })
    })
    .transpose()
}

/// SkinNet's weights `[F, V, J]` by the fused op: `params` is the flat parameter vector in
/// [`ParamLayout`] order (differentiable), `positions` `[V, P]` and `poses` `[F, Q]` (or
/// `[F, V, Q]`, a pose per row) constants,
/// `mask` an optional additive `[V, J]` mask of the logits (0 or −∞).
pub(crate) fn forward(
    context: &Arc<FusedContext>,
    params: &Tensor,
    positions: &Tensor,
    poses: &Tensor,
    mask: Option<&Tensor>,
    structured: bool,
) -> Result<Tensor> {
    let mask = logit_mask(mask, structured)?;
    params.apply_op3(
        &positions.contiguous()?,
        &poses.contiguous()?,
        FusedSkinNet {
            context: context.clone(),
            mask,
            local: None,
            saved: Mutex::new(None),
        },
    )
}

/// [`forward`] with a pose per row given in pose locality's structure ([`LocalPoses`]), which
/// the op multiplies without writing the rows out.
pub(crate) fn forward_local(
    context: &Arc<FusedContext>,
    params: &Tensor,
    positions: &Tensor,
    local: &Arc<LocalPoses>,
    mask: Option<&Tensor>,
) -> Result<Tensor> {
    let mask = logit_mask(mask, true)?;
    let frames = Tensor::from_slice(
        local.frames(),
        (local.frame_count(), 3 * local.joints()),
        params.device(),
    )?;
    params.apply_op3(
        &positions.contiguous()?,
        &frames,
        FusedSkinNet {
            context: context.clone(),
            mask,
            local: Some(local.clone()),
            saved: Mutex::new(None),
        },
    )
}

#[cfg(test)]
mod tests;
