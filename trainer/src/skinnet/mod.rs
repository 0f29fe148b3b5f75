//! SkinNet (paper §3.2, supplementary D): `w = softmax(MLP([x̂, γ(x̂), θ̃]))`.
//!
//! The architecture comes from [`ModelConfig`] (the same definition the `.skf` file stores and
//! the runtime reads): hidden widths, the skip layer that takes `[h, input]`, Softplus β, the
//! positional-encoding frequency count. Linear layers are weight-normalised (`w = g · v/‖v‖` per
//! output row, Salimans & Kingma 2016) during training; [`export`] folds that into plain weights.
//!
//! One forward pass evaluates `V` canonical vertices under `F` poses. The first layer and the
//! skip layer see `[position part, pose part]`; their matmuls are split so that the position
//! part is computed once per vertex (`[V, out]`), the pose part once per frame (`[F, out]`), and
//! the two are broadcast-added to `[F·V, out]` — instead of multiplying an `[F·V, in]` input.

pub mod export;
pub mod fused;
pub mod local_poses;
pub mod softplus;

use std::sync::Arc;

use candle_core::{DType, Device, Result, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::{ModelConfig, Net, SkfView};

pub use local_poses::{LocalPoses, LocalPosesError};
pub use softplus::{softmax_last, softplus, softplus_composite};

/// How the forward pass (and so the backward pass) is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Backend {
    /// One custom op for the whole network ([`fused`]), f32 only: the training default.
    #[default]
    Fused,
    /// candle's graph of tensor ops with the given Softplus: any dtype; the reference the
    /// fused op is tested and benchmarked against.
    Candle(Activation),
}

/// Which Softplus implementation the candle graph uses ([`Backend::Candle`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Activation {
    /// The Softplus custom op with its own backward ([`softplus::Softplus`]).
    #[default]
    SoftplusOp,
    /// candle primitives (the reference for tests and the bench).
    Composite,
}

/// A weight-normalised linear layer: `y = x · (g ⊙ v/‖v‖_row)ᵀ + b`.
#[derive(Clone, Debug)]
pub struct WnLinear {
    v: Tensor,
    g: Tensor,
    b: Tensor,
}

impl WnLinear {
    /// Reads `v` `[out, in]`, `g` `[out]` and `b` `[out]` from `vb` (scoped to this layer).
    pub fn new(vb: &VarBuilder, out: usize, inp: usize) -> Result<Self> {
        Ok(Self {
            v: vb.get((out, inp), "v")?,
            g: vb.get(out, "g")?,
            b: vb.get(out, "b")?,
        })
    }

    /// The effective weight `g ⊙ v/‖v‖` `[out, in]` (differentiable in `v` and `g`).
    pub fn weight(&self) -> Result<Tensor> {
        let norm = self.v.sqr()?.sum_keepdim(1)?.sqrt()?;
        self.v
            .broadcast_mul(&self.g.unsqueeze(1)?.broadcast_div(&norm)?)
    }

    /// The bias `[out]`.
    #[must_use]
    pub fn bias(&self) -> &Tensor {
        &self.b
    }

    /// The parameters `(v, g, b)`.
    #[must_use]
    pub fn parts(&self) -> (&Tensor, &Tensor, &Tensor) {
        (&self.v, &self.g, &self.b)
    }
}

/// SkinNet as trained: candle variables of the weight-normalised MLP (skip connection,
/// Softplus, softmax over joints), differentiable. The runtime's `SkinNet` is the same network
/// expanded for inference from the exported `.skf`.
#[derive(Clone, Debug)]
pub struct TrainableSkinNet {
    config: ModelConfig,
    layers: Vec<WnLinear>,
    backend: Backend,
    /// Whether the fused op uses the structure of candidate masks and pose locality's input.
    structured: bool,
    /// The fused op's architecture, SIMD kernel and buffer pool (shared by clones).
    fused: Arc<fused::FusedContext>,
}

/// Parameter-name prefix of SkinNet inside a [`VarMap`] (matches [`Net::prefix`]).
pub const PREFIX: &str = "skin";

impl TrainableSkinNet {
    /// Builds the layers from a `VarBuilder` already scoped to the net (e.g. `vb.pp("skin")`);
    /// layer `i` reads `l{i}.v`, `l{i}.g`, `l{i}.b`.
    pub fn new(vb: &VarBuilder, config: ModelConfig) -> Result<Self> {
        if let Err(e) = config.validate() {
            candle_core::bail!("SkinNet config: {e}");
        }
        let layers = config
            .layer_shapes(Net::Skin)
            .enumerate()
            .map(|(i, (out, inp))| WnLinear::new(&vb.pp(format!("l{i}")), out, inp))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            config,
            layers,
            backend: Backend::default(),
            structured: true,
            fused: Arc::new(fused::FusedContext::new(config)),
        })
    }

    /// Fills `varmap` with seeded initial parameters under `prefix` (`skin.l{i}.{v,g,b}`):
    /// `v` and `b` uniform in `±1/√in` (PyTorch's Linear default), `g = ‖v‖_row` so the first
    /// effective weight equals `v`. The output layer is scaled by `out_scale` (small values start
    /// near uniform weights; the warm start then regresses the initial skinning).
    pub fn init_varmap(
        varmap: &VarMap,
        config: &ModelConfig,
        prefix: &str,
        seed: u64,
        out_scale: f32,
        device: &Device,
    ) -> Result<()> {
        init_net_varmap(varmap, config, Net::Skin, prefix, seed, out_scale, device)
    }

    /// A freshly initialised SkinNet and the `VarMap` holding its parameters (f32, CPU).
    pub fn seeded(config: ModelConfig, seed: u64, out_scale: f32) -> Result<(Self, VarMap)> {
        let varmap = VarMap::new();
        Self::init_varmap(&varmap, &config, PREFIX, seed, out_scale, &Device::Cpu)?;
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
        Ok((Self::new(&vb.pp(PREFIX), config)?, varmap))
    }

    /// Chooses how the forward and backward passes are computed.
    #[must_use]
    pub fn with_backend(mut self, backend: Backend) -> Self {
        self.backend = backend;
        self
    }

    /// Whether the fused op may use the structure of what it is fed where that pays (the
    /// default): candidate masks (the output layer computes each point's candidates alone) and
    /// pose locality's [`LocalPoses`] (multiplied without writing the rows out). Off, it
    /// multiplies dense rows through a full output layer, as before 2026-12-07: the reference
    /// the bench measures against. The values agree up to the order of summation.
    #[must_use]
    pub fn with_structure(mut self, structured: bool) -> Self {
        self.structured = structured;
        self
    }

    /// How the forward and backward passes are computed.
    #[must_use]
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// The layers, hidden first, then the output layer.
    #[must_use]
    pub fn layers(&self) -> &[WnLinear] {
        &self.layers
    }

    /// Every layer's `v`, `g`, `b` flattened and concatenated in [`fused::ParamLayout`] order
    /// (differentiable: the concatenation's backward hands each variable its slice).
    pub fn packed_parameters(&self) -> Result<Tensor> {
        let mut parts = Vec::with_capacity(3 * self.layers.len());
        for l in &self.layers {
            parts.push(l.v.flatten_all()?);
            parts.push(l.g.clone());
            parts.push(l.b.clone());
        }
        Tensor::cat(&parts, 0)
    }

    /// Skinning weights `[F, V, J]` for encoded positions `[V, 3 + 6L]` ([`position_inputs_tensor`])
    /// and pose features `[F, 3J]`; rows sum to one. With [`Backend::Fused`] and f32 inputs the
    /// fused op computes it (other dtypes fall back to the candle graph).
    pub fn forward(&self, positions: &Tensor, poses: &Tensor) -> Result<Tensor> {
        self.forward_masked(positions, poses, None)
    }

    /// [`TrainableSkinNet::forward`] with the softmax restricted to candidate joints: `mask` is `[V, J]`,
    /// 0 where joint `j` is a candidate of vertex `v` and −∞ elsewhere ([`crate::candidates`]).
    ///
    /// `poses` is either `[F, 3J]` (one pose per frame, shared by every vertex) or `[F, V, 3J]`
    /// (a pose per row: what the training step's pose-locality augmentation feeds,
    /// [`crate::train::TrainConfig::pose_locality`]).
    pub fn forward_masked(
        &self,
        positions: &Tensor,
        poses: &Tensor,
        mask: Option<&Tensor>,
    ) -> Result<Tensor> {
        let (v, p) = positions.dims2()?;
        let (f, q, per_row) = match *poses.dims() {
            [f, q] => (f, q, false),
            [f, rows, q] if rows == v => (f, q, true),
            _ => candle_core::bail!(
                "SkinNet pose features {:?}, expected [F, {}] or [F, {v}, {}]",
                poses.dims(),
                self.config.pose_width(),
                self.config.pose_width()
            ),
        };
        if p != self.config.position_width() || q != self.config.pose_width() {
            candle_core::bail!(
                "SkinNet input widths {p} + {q}, expected {} + {}",
                self.config.position_width(),
                self.config.pose_width()
            );
        }
        let activation = match self.backend {
            Backend::Fused if positions.dtype() == DType::F32 && poses.dtype() == DType::F32 => {
                return fused::forward(
                    &self.fused,
                    &self.packed_parameters()?,
                    positions,
                    poses,
                    mask,
                    self.structured,
                );
            }
            Backend::Fused => Activation::SoftplusOp,
            Backend::Candle(a) => a,
        };
        let beta = self.config.softplus_beta;
        let act = |x: &Tensor| match activation {
            Activation::SoftplusOp => softplus(x, beta),
            Activation::Composite => softplus_composite(x, beta),
        };
        let n = self.layers.len() - 1;
        let skip = self.config.skip_layer as usize;
        // Position part [V, out] + (pose part + bias) [F, out] (or [F, V, out] with a pose per
        // row), broadcast to [F·V, out].
        let split = |w: &Tensor, b: &Tensor, at: usize| -> Result<Tensor> {
            let wp = w.narrow(1, at, p)?;
            let wq = w.narrow(1, at + p, q)?;
            let a = positions.matmul(&wp.t()?)?;
            let out = w.dim(0)?;
            let c = if per_row {
                poses
                    .reshape((f * v, q))?
                    .matmul(&wq.t()?)?
                    .broadcast_add(b)?
                    .reshape((f, v, out))?
            } else {
                poses.matmul(&wq.t()?)?.broadcast_add(b)?.unsqueeze(1)?
            };
            a.unsqueeze(0)?.broadcast_add(&c)?.reshape((f * v, out))
        };
        let mut h: Option<Tensor> = None;
        for (i, layer) in self.layers.iter().enumerate() {
            let w = layer.weight()?;
            let z = match &h {
                None => split(&w, &layer.b, 0)?,
                Some(h) if i == skip => {
                    let prev = h.dim(1)?;
                    let zh = h.matmul(&w.narrow(1, 0, prev)?.t()?)?;
                    (zh + split(&w, &layer.b, prev)?)?
                }
                Some(h) => h.matmul(&w.t()?)?.broadcast_add(&layer.b)?,
            };
            h = Some(if i < n { act(&z)? } else { z });
        }
        let logits = h.ok_or_else(|| candle_core::Error::Msg("SkinNet has no layers".into()))?;
        let j = self.config.joint_count as usize;
        let logits = logits.reshape((f, v, j))?;
        let logits = match mask {
            Some(m) => logits.broadcast_add(&m.to_dtype(logits.dtype())?.unsqueeze(0)?)?,
            None => logits,
        };
        softmax_last(&logits)?.reshape((f, v, j))
    }
}

impl TrainableSkinNet {
    /// [`TrainableSkinNet::forward_masked`] with a pose per row given as pose locality's
    /// [`LocalPoses`] (`[F, V, 3J]` in structure): the fused op multiplies the structure
    /// ([`local_poses`]) where that pays ([`LocalPoses::worth_structure`]); otherwise, and in
    /// the candle graph, the network gets the rows written out.
    pub fn forward_local(
        &self,
        positions: &Tensor,
        local: &Arc<LocalPoses>,
        mask: Option<&Tensor>,
    ) -> Result<Tensor> {
        let (v, p) = positions.dims2()?;
        let q = 3 * local.joints();
        if local.vertices() != v || q != self.config.pose_width() {
            candle_core::bail!(
                "SkinNet local poses for {} vertices × {q} features, expected {v} × {}",
                local.vertices(),
                self.config.pose_width()
            );
        }
        if self.backend == Backend::Fused
            && positions.dtype() == DType::F32
            && self.structured
            && local.worth_structure()
        {
            if p != self.config.position_width() {
                candle_core::bail!(
                    "SkinNet position width {p}, expected {}",
                    self.config.position_width()
                );
            }
            return fused::forward_local(
                &self.fused,
                &self.packed_parameters()?,
                positions,
                local,
                mask,
            );
        }
        let rows = Tensor::from_vec(
            local.rows(),
            (local.frame_count(), v, q),
            positions.device(),
        )?
        .to_dtype(positions.dtype())?;
        self.forward_masked(positions, &rows, mask)
    }
}

impl TrainableSkinNet {
    /// Convenience for exporters and cross-checks: weights of canonical `points` for each pose
    /// feature vector in `poses` (each `3J`), flattened `[F, V, J]` row-major.
    pub fn evaluate(&self, points: &[Vec3], poses: &[Vec<f32>]) -> Result<Vec<f32>> {
        let dev = Device::Cpu;
        let q = self.config.pose_width();
        if poses.iter().any(|p| p.len() != q) {
            candle_core::bail!("pose features must have {q} entries");
        }
        let enc = position_inputs_tensor(&self.config, points, &dev)?;
        let flat: Vec<f32> = poses.iter().flatten().copied().collect();
        let dt = self.layers.first().map_or(DType::F32, |l| l.v.dtype());
        let w = self.forward(
            &enc.to_dtype(dt)?,
            &Tensor::from_vec(flat, (poses.len(), q), &dev)?.to_dtype(dt)?,
        )?;
        w.to_dtype(DType::F32)?.flatten_all()?.to_vec1()
    }
}

/// Why a net could not be read from a `.skf`.
#[derive(Debug, thiserror::Error)]
pub enum SkfNetError {
    /// A layer's tensor is missing or unreadable.
    #[error("layer {layer}: {reason}")]
    Tensor {
        /// Layer index.
        layer: usize,
        /// What is wrong.
        reason: String,
    },
    /// Building the variables failed.
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
}

/// The variables `{prefix}.l{i}.{v,g,b}` of `net` as stored in a parsed `.skf`: the file's plain
/// weights become `v` with `g = ‖v‖_row`, so the effective weights are the file's (weight
/// normalisation was folded at export) and training can continue from them.
pub fn varmap_from_skf(view: &SkfView, net: Net) -> std::result::Result<VarMap, SkfNetError> {
    let varmap = VarMap::new();
    let mut data = varmap
        .data()
        .lock()
        .map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
    for (i, (out, inp)) in view.config().layer_shapes(net).enumerate() {
        let bad = |reason: String| SkfNetError::Tensor { layer: i, reason };
        let (wv, bv) = view.layer(net, i).ok_or_else(|| bad("not stored".into()))?;
        let mut w = vec![0.0; out * inp];
        let mut b = vec![0.0; out];
        wv.to_f32(&mut w).map_err(|e| bad(e.to_string()))?;
        bv.to_f32(&mut b).map_err(|e| bad(e.to_string()))?;
        let g: Vec<f32> = w
            .chunks(inp)
            .map(|r| r.iter().map(|x| x * x).sum::<f32>().sqrt())
            .collect();
        let dev = Device::Cpu;
        let name = |p: &str| format!("{}.l{i}.{p}", net.prefix());
        for (n, t) in [
            (name("v"), Tensor::from_vec(w, (out, inp), &dev)?),
            (name("g"), Tensor::from_vec(g, out, &dev)?),
            (name("b"), Tensor::from_vec(b, out, &dev)?),
        ] {
            data.insert(n, Var::from_tensor(&t)?);
        }
    }
    drop(data);
    Ok(varmap)
}

impl TrainableSkinNet {
    /// SkinNet as stored in a parsed `.skf` ([`varmap_from_skf`]), with the variables holding
    /// its parameters (f32, CPU).
    pub fn from_skf(view: &SkfView) -> std::result::Result<(Self, VarMap), SkfNetError> {
        let varmap = varmap_from_skf(view, Net::Skin)?;
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
        let mut config = *view.config();
        config.nets = Net::Skin.bit();
        Ok((Self::new(&vb.pp(Net::Skin.prefix()), config)?, varmap))
    }
}

/// [`TrainableSkinNet::init_varmap`] for any of the file's nets (the appearance nets share SkinNet's
/// hyper-parameters, paper supplementary D): layer `i` of `net` under `{prefix}.l{i}.{v,g,b}`.
pub fn init_net_varmap(
    varmap: &VarMap,
    config: &ModelConfig,
    net: Net,
    prefix: &str,
    seed: u64,
    out_scale: f32,
    device: &Device,
) -> Result<()> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let shapes: Vec<_> = config.layer_shapes(net).collect();
    let mut data = varmap
        .data()
        .lock()
        .map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
    for (i, &(out, inp)) in shapes.iter().enumerate() {
        let bound = 1.0 / (inp as f32).sqrt();
        let scale = if i + 1 == shapes.len() {
            out_scale
        } else {
            1.0
        };
        let v: Vec<f32> = (0..out * inp)
            .map(|_| scale * rng.random_range(-bound..bound))
            .collect();
        let g: Vec<f32> = v
            .chunks(inp)
            .map(|r| r.iter().map(|x| x * x).sum::<f32>().sqrt())
            .collect();
        let b: Vec<f32> = (0..out)
            .map(|_| scale * rng.random_range(-bound..bound))
            .collect();
        let name = |p: &str| format!("{prefix}.l{i}.{p}");
        data.insert(
            name("v"),
            Var::from_tensor(&Tensor::from_vec(v, (out, inp), device)?)?,
        );
        data.insert(
            name("g"),
            Var::from_tensor(&Tensor::from_vec(g, out, device)?)?,
        );
        data.insert(
            name("b"),
            Var::from_tensor(&Tensor::from_vec(b, out, device)?)?,
        );
    }
    Ok(())
}

/// `[x̂, γ(x̂)]` for each point ([`ModelConfig::position_input`], the encoding the runtime
/// uses too), row-major `[V, 3 + 6L]`.
#[must_use]
pub fn position_inputs(config: &ModelConfig, points: &[Vec3]) -> Vec<f32> {
    let mut out = Vec::with_capacity(points.len() * config.position_width());
    for &x in points {
        out.extend(config.position_input(x));
    }
    out
}

/// [`position_inputs`] as an f32 tensor `[V, 3 + 6L]` on `device`.
pub fn position_inputs_tensor(
    config: &ModelConfig,
    points: &[Vec3],
    device: &Device,
) -> Result<Tensor> {
    Tensor::from_vec(
        position_inputs(config, points),
        (points.len(), config.position_width()),
        device,
    )
}

#[cfg(test)]
pub(crate) mod tests;
