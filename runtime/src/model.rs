//! Model expansion: a validated `.skf` view becomes f32 weight panels in the kernels' layout,
//! once, in caller memory ([`SkinNet::expand_into`], sized by [`expanded_len`]) or owned
//! ([`SkinNetModel`]); the kernel is picked here, once.
//!
//! Each linear layer is split by what its input columns depend on:
//! - the hidden part (`W_h`, previous layer's activations) → MR-row panels for the GEMM;
//! - the position part (`W_pos · [x̂, γ(x̂)]`, layer 0 and the skip layer) → panels used once
//!   per mesh at bind time ([`crate::BoundMesh`]);
//! - the pose part (`W_pose · θ̃`, same layers) → row-major, used once per frame together with
//!   the bias ([`crate::FrameState`]).

use alloc::vec;
use alloc::vec::Vec;
use core::sync::atomic::{AtomicU64, Ordering};

use glam::Vec3;
use skinfield_formats::skf::{MAX_HIDDEN_LAYERS, ModelConfig, Net, SkfView, TensorView};
use skinfield_formats::{Pose, Skeleton};

use crate::activation::Act;
use crate::error::RuntimeError;
use crate::kernels::{self, Kernel, LayerArgs, MR, TILE, pack_panels};

/// Maximum layers (hidden + output).
const MAX_LAYERS: usize = MAX_HIDDEN_LAYERS + 1;

/// Where one layer's parts live in the expanded weights.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct LayerLayout {
    /// Output width.
    pub rows: usize,
    /// Output width rounded up to [`MR`].
    pub rows_p: usize,
    /// Hidden input width (0 for layer 0).
    pub k_h: usize,
    /// Offset of the hidden panels (`rows_p × k_h`).
    pub h_off: usize,
    /// Offset of the position panels (`rows_p × pos_w`), if the layer sees the input.
    pub pos_off: Option<usize>,
    /// Offset of the row-major pose weights (`rows × pose_w`), if the layer sees the input.
    pub pose_off: usize,
    /// Offset of the bias (`rows_p`).
    pub bias_off: usize,
    /// Offset of this layer's rows in a bound tile block (× TILE), if it has a position part.
    pub pre_off: usize,
    /// Offset of this layer's per-frame bias in [`Layout::frame_bias_len`].
    pub fb_off: usize,
}

/// The expanded model's layout: a pure function of the configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Layout {
    pub layers: [LayerLayout; MAX_LAYERS],
    pub count: usize,
    /// Floats of expanded weights.
    pub total: usize,
    /// `3 + 6L`.
    pub pos_w: usize,
    /// `3J`.
    pub pose_w: usize,
    /// Rows of a bound tile block (sum of `rows_p` over layers with a position part).
    pub pre_rows: usize,
    /// Floats of per-frame bias.
    pub frame_bias_len: usize,
    /// Largest `rows_p` (scratch rows).
    pub max_rows_p: usize,
    /// Joint count.
    pub joints: usize,
}

impl Layout {
    pub(crate) fn new(config: &ModelConfig) -> Self {
        let pos_w = config.position_width();
        let pose_w = config.pose_width();
        let mut layers = [LayerLayout::default(); MAX_LAYERS];
        let mut count = 0;
        let (mut total, mut pre_rows, mut fb, mut max_rows_p) = (0, 0, 0, 0);
        let skip = config.skip_layer as usize;
        for (i, (rows, inp)) in config.layer_shapes(Net::Skin).enumerate().take(MAX_LAYERS) {
            let rows_p = rows.div_ceil(MR) * MR;
            let sees_input = i == 0 || (i == skip && i > 0);
            let k_h = if i == 0 {
                0
            } else {
                inp - if sees_input { pos_w + pose_w } else { 0 }
            };
            let mut l = LayerLayout {
                rows,
                rows_p,
                k_h,
                h_off: total,
                ..LayerLayout::default()
            };
            total += rows_p * k_h;
            if sees_input {
                l.pos_off = Some(total);
                total += rows_p * pos_w;
                l.pose_off = total;
                total += rows * pose_w;
                l.pre_off = pre_rows;
                pre_rows += rows_p;
            }
            l.bias_off = total;
            total += rows_p;
            l.fb_off = fb;
            fb += rows_p;
            max_rows_p = max_rows_p.max(rows_p);
            layers[i] = l;
            count = i + 1;
        }
        Self {
            layers,
            count,
            total,
            pos_w,
            pose_w,
            pre_rows,
            frame_bias_len: fb,
            max_rows_p,
            joints: config.joint_count as usize,
        }
    }

    pub(crate) fn layers(&self) -> &[LayerLayout] {
        &self.layers[..self.count]
    }
}

/// Floats of caller memory [`SkinNet::expand_into`] needs for a file with this configuration
/// (the same for every kernel: they share one layout).
#[must_use]
pub fn expanded_len(config: &ModelConfig) -> usize {
    Layout::new(config).total
}

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// SkinNet expanded for evaluation. `W` is the weight storage: `Vec<f32>` ([`SkinNetModel`]) or
/// `&[f32]` in caller memory.
#[derive(Clone, Debug)]
pub struct SkinNet<W> {
    weights: W,
    layout: Layout,
    config: ModelConfig,
    skeleton: Skeleton,
    kernel: Kernel,
    id: u64,
    /// The candidate joints of the canonical anchors (`CAND`); `None`: every joint everywhere.
    anchors: Option<crate::candidates::AnchorSet>,
    /// Per pose feature, the training range `(low, high)` the features are clamped into
    /// (`PRNG`); empty: not clamped.
    pose_range: Vec<(f32, f32)>,
}

/// A SkinNet that owns its expanded weights.
pub type SkinNetModel = SkinNet<Vec<f32>>;

/// Element `i` of `t`, finite, or an error naming the tensor.
fn element(t: &TensorView<'_>, i: usize) -> Result<f32, RuntimeError> {
    match t.get(i) {
        Some(v) if v.is_finite() => Ok(v),
        _ => Err(RuntimeError::NonFiniteWeight {
            tensor: t.name,
            index: i,
        }),
    }
}

/// Fills `out` (exactly `layout.total` floats) from the view.
fn expand(view: &SkfView<'_>, layout: &Layout, out: &mut [f32]) -> Result<(), RuntimeError> {
    for (i, l) in layout.layers().iter().enumerate() {
        let (w, b) = view.layer(Net::Skin, i).ok_or(RuntimeError::Mismatch {
            field: "skin tensors",
        })?;
        let ld = w.dims[1] as usize;
        let h_cols = if i == 0 { 0 } else { l.k_h };
        let h = &mut out[l.h_off..l.h_off + l.rows_p * l.k_h];
        // Hidden columns come first in the stored `[h, input]` order.
        pack_panels(l.rows, l.k_h, h, |o, c| element(&w, o * ld + c))?;
        if let Some(pos_off) = l.pos_off {
            let pos = &mut out[pos_off..pos_off + l.rows_p * layout.pos_w];
            pack_panels(l.rows, layout.pos_w, pos, |o, c| {
                element(&w, o * ld + h_cols + c)
            })?;
            let pose = &mut out[l.pose_off..l.pose_off + l.rows * layout.pose_w];
            for (o, row) in pose.chunks_exact_mut(layout.pose_w).enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v = element(&w, o * ld + h_cols + layout.pos_w + c)?;
                }
            }
        }
        for (o, v) in out[l.bias_off..l.bias_off + l.rows_p]
            .iter_mut()
            .enumerate()
        {
            *v = if o < l.rows { element(&b, o)? } else { 0.0 };
        }
    }
    Ok(())
}

impl SkinNetModel {
    /// Validates `.skf` bytes and expands SkinNet with the fastest available kernel.
    pub fn from_skf(bytes: &[u8]) -> Result<Self, RuntimeError> {
        Self::from_view(&SkfView::parse(bytes)?)
    }

    /// Expands SkinNet from a parsed view with the fastest available kernel.
    pub fn from_view(view: &SkfView<'_>) -> Result<Self, RuntimeError> {
        let mut weights = vec![0.0; expanded_len(view.config())];
        let net = SkinNet::expand_into(view, &mut weights)?;
        let (layout, config, skeleton, kernel, id, anchors, pose_range) = (
            net.layout,
            net.config,
            net.skeleton,
            net.kernel,
            net.id,
            net.anchors,
            net.pose_range,
        );
        Ok(SkinNet {
            weights,
            layout,
            config,
            skeleton,
            kernel,
            id,
            anchors,
            pose_range,
        })
    }

    /// Convenience for tests and exporters: the SkinNet weights (`J` per point, joint order of
    /// the file's skeleton) of canonical points `points` in `pose`, from `.skf` bytes.
    pub fn weights_for_skf(
        bytes: &[u8],
        points: &[Vec3],
        pose: &Pose,
    ) -> Result<Vec<f32>, RuntimeError> {
        let model = Self::from_skf(bytes)?;
        let mut out = vec![0.0; points.len() * model.joint_count()];
        model.weights_for(points, pose, &mut out)?;
        Ok(out)
    }
}

impl<'w> SkinNet<&'w [f32]> {
    /// Expands SkinNet into caller memory (`buf.len() ≥` [`expanded_len`]) with the fastest
    /// available kernel. The skeleton is copied (small); the weights live in `buf`.
    pub fn expand_into(view: &SkfView<'_>, buf: &'w mut [f32]) -> Result<Self, RuntimeError> {
        let config = *view.config();
        let layout = Layout::new(&config);
        if buf.len() < layout.total {
            return Err(RuntimeError::BufferLength {
                field: "buf",
                len: buf.len(),
                expected: layout.total,
            });
        }
        let buf = &mut buf[..layout.total];
        expand(view, &layout, buf)?;
        let skeleton = view.skeleton().to_skeleton()?;
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        Ok(SkinNet {
            weights: buf,
            layout,
            config,
            skeleton,
            kernel: Kernel::detect(),
            id,
            anchors: view
                .candidates()
                .map(|c| crate::candidates::AnchorSet::from_view(&c)),
            pose_range: view
                .pose_range()
                .map(|r| (0..r.len()).map(|i| (r.low(i), r.high(i))).collect())
                .unwrap_or_default(),
        })
    }
}

impl<W: AsRef<[f32]>> SkinNet<W> {
    /// Network configuration from the file.
    #[must_use]
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// The anchors and candidate joints of the file (`None`: every joint is a candidate of
    /// every vertex).
    #[must_use]
    pub fn anchors(&self) -> Option<&crate::candidates::AnchorSet> {
        self.anchors.as_ref()
    }

    /// Per pose feature, the range of the training poses that [`crate::FrameState::set_pose`]
    /// clamps the features into (`PRNG`; empty for a file without one: not clamped).
    #[must_use]
    pub fn pose_range(&self) -> &[(f32, f32)] {
        &self.pose_range
    }

    /// The file's skeleton (joint order = output order = pose-feature order).
    #[must_use]
    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    /// Number of joints `J`.
    #[must_use]
    pub fn joint_count(&self) -> usize {
        self.layout.joints
    }

    /// The kernel in use.
    #[must_use]
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// Switches kernel (benches and tests compare them); refused when not available.
    pub fn set_kernel(&mut self, kernel: Kernel) -> Result<(), RuntimeError> {
        if !kernel.is_available() {
            return Err(RuntimeError::KernelUnavailable(kernel));
        }
        self.kernel = kernel;
        Ok(())
    }

    /// Multiply-adds per vertex per frame actually executed by the tile MLP (the position and
    /// pose parts are precomputed and excluded): the figure GFLOP/s are computed from.
    #[must_use]
    pub fn macs_per_vertex(&self) -> usize {
        self.layout.layers().iter().map(|l| l.rows * l.k_h).sum()
    }

    pub(crate) fn id(&self) -> u64 {
        self.id
    }

    pub(crate) fn layout(&self) -> &Layout {
        &self.layout
    }

    pub(crate) fn weights(&self) -> &[f32] {
        self.weights.as_ref()
    }

    /// Per-frame bias of every layer: `b + W_pose · θ̃` for layers that see the input, `b` for
    /// the others (`out.len() == frame_bias_len`, `theta.len() == pose_w`).
    pub(crate) fn frame_bias(&self, theta: &[f32], out: &mut [f32]) {
        let w = self.weights();
        let pw = self.layout.pose_w;
        for l in self.layout.layers() {
            let fb = &mut out[l.fb_off..l.fb_off + l.rows_p];
            fb.copy_from_slice(&w[l.bias_off..l.bias_off + l.rows_p]);
            if l.pos_off.is_some() {
                for (o, f) in fb.iter_mut().enumerate().take(l.rows) {
                    let row = &w[l.pose_off + o * pw..l.pose_off + (o + 1) * pw];
                    *f += row.iter().zip(theta).map(|(a, b)| a * b).sum::<f32>();
                }
            }
        }
    }

    /// Position part of every input-seeing layer for one tile: `pe` is `[pos_w][TILE]`, `out`
    /// a bound tile block (`pre_rows × TILE`), `zeros` at least `max_rows_p` zeros.
    pub(crate) fn position_parts(&self, pe: &[f32], zeros: &[f32], out: &mut [f32]) {
        let w = self.weights();
        for l in self.layout.layers() {
            if let Some(pos_off) = l.pos_off {
                kernels::layer(
                    self.kernel,
                    LayerArgs {
                        panels: &w[pos_off..pos_off + l.rows_p * self.layout.pos_w],
                        k: self.layout.pos_w,
                        input: pe,
                        bias: zeros,
                        pre: None,
                        out: &mut out[l.pre_off * TILE..(l.pre_off + l.rows_p) * TILE],
                        rows_p: l.rows_p,
                        act: Act::Identity,
                    },
                );
            }
        }
    }

    /// The MLP over one tile: `pre` is the tile's bound block, `fb` the frame bias; `a` and `b`
    /// are scratch (`max_rows_p × TILE` each). Returns the softmaxed weights, `[J][TILE]`.
    pub(crate) fn forward_tile<'s>(
        &self,
        pre: &[f32],
        fb: &[f32],
        candidates: Option<&[u16]>,
        a: &'s mut [f32],
        b: &'s mut [f32],
    ) -> &'s [f32] {
        let w = self.weights();
        let beta = self.config.softplus_beta;
        let n = self.layout.count;
        let (mut src, mut dst) = (a, b);
        for (i, l) in self.layout.layers().iter().enumerate() {
            kernels::layer(
                self.kernel,
                LayerArgs {
                    panels: &w[l.h_off..l.h_off + l.rows_p * l.k_h],
                    k: l.k_h,
                    input: src,
                    bias: &fb[l.fb_off..l.fb_off + l.rows_p],
                    pre: l
                        .pos_off
                        .map(|_| &pre[l.pre_off * TILE..(l.pre_off + l.rows_p) * TILE]),
                    out: dst,
                    rows_p: l.rows_p,
                    act: if i + 1 < n {
                        Act::Softplus { beta }
                    } else {
                        Act::Identity
                    },
                },
            );
            core::mem::swap(&mut src, &mut dst);
        }
        let joints = self.layout.joints;
        match (candidates, &self.anchors) {
            (Some(lists), Some(a)) => {
                crate::candidates::mask_logits(src, joints, lists, a.k());
                kernels::softmax_tile(self.kernel, src, joints);
                crate::candidates::clear_masked(src, joints, lists, a.k());
            }
            _ => kernels::softmax_tile(self.kernel, src, joints),
        }
        src
    }

    /// The SkinNet weights of canonical points `points` in `pose` into `out`
    /// (`points.len() × J`, row-major). Allocates (it binds the points); for repeated frames use
    /// [`crate::BoundMesh`], [`crate::FrameState`] and [`crate::WeightsJob`].
    pub fn weights_for(
        &self,
        points: &[Vec3],
        pose: &Pose,
        out: &mut [f32],
    ) -> Result<(), RuntimeError> {
        let expected = points
            .len()
            .checked_mul(self.joint_count())
            .ok_or(RuntimeError::VertexCount(points.len()))?;
        if out.len() != expected {
            return Err(RuntimeError::BufferLength {
                field: "out",
                len: out.len(),
                expected,
            });
        }
        if points.is_empty() {
            return Ok(());
        }
        let mesh = crate::BoundMesh::bind(self, points)?;
        let mut frame = crate::FrameState::new(self);
        frame.set_pose(self, pose)?;
        let mut scratch = crate::Scratch::new(self);
        crate::WeightsJob {
            model: self,
            mesh: &mesh,
            frame: &frame,
            first_vertex: 0,
            out_weights: out,
        }
        .run(&mut scratch)
    }
}
