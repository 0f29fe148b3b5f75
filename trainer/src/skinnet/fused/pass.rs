//! The arithmetic of the fused op: forward with saved activations, and the exact backward pass
//! to every layer's `v`, `g` and `b`.
//!
//! Notation per layer `i`: `Z_i = X_i·W_iᵀ + b_i` (rows × out), `H_i = softplus(Z_i)`,
//! `S_i = sigmoid(β·Z_i) = ∂H_i/∂Z_i`; the last layer's `Z` goes through the softmax. `X_0` is
//! `[position, pose]`, the skip layer's `X` is `[H_{s−1}, position, pose]`, every other layer's
//! is `H_{i−1}`. A row is `(frame f, vertex v)` at `f·V + v`.

use candle_core::{Result, bail};
use rayon::prelude::*;
use skinfield_runtime::kernels::softplus_with_slope;

use super::FusedContext;
use super::gemm::{MatMut, MatRef, matmul};
use super::sparse::{
    LogitMask, local_pose_backward, local_pose_forward, sparse_output_backward,
    sparse_output_forward,
};
use crate::skinnet::LocalPoses;

/// Rows per parallel task of the elementwise and row passes (here and in [`super::sparse`]).
pub(super) const CHUNK_ROWS: usize = 256;

/// Activations and slopes below this (2^-40 ≈ 9e-13) are stored as zero, and gradients below
/// this fraction of the largest output gradient are flushed to zero. Products of such values
/// inside the matrix products are subnormal floats, which x86 cores handle in microcode at
/// ~100 cycles each: on a net trained for a few hundred steps they made the backward pass 4×
/// slower. What is dropped is below 1e-12 of the terms that remain.
const FLUSH: f32 = 9.094_947e-13;

/// Sets the entries of `x` smaller in magnitude than `tau` to zero.
fn flush(x: &mut [f32], tau: f32) {
    for v in x {
        if v.abs() < tau {
            *v = 0.0;
        }
    }
}

/// The pose input: one pose per frame (broadcast over the frame's vertices), one per row, or one
/// per row in pose locality's structure (the training step's input).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Poses<'a> {
    /// `[F, Q]`.
    PerFrame(&'a [f32]),
    /// `[F·V, Q]`.
    PerRow(&'a [f32]),
    /// `[F·V, Q]` as frames, donors and relevant joints ([`LocalPoses`]).
    Local(&'a LocalPoses),
}

/// What the forward pass keeps for the backward pass.
#[derive(Debug)]
pub(crate) struct Activations {
    frames: usize,
    vertices: usize,
    /// Effective weights `W_i = g_i ⊙ v_i/‖v_i‖`, `out × in` row-major.
    weights: Vec<Vec<f32>>,
    /// `‖v_i‖` per output row.
    norms: Vec<Vec<f32>>,
    /// `H_i` of the hidden layers (rows × out).
    hidden: Vec<Vec<f32>>,
    /// `S_i` of the hidden layers (rows × out).
    slopes: Vec<Vec<f32>>,
    /// The softmax output (rows × J).
    output: Vec<f32>,
}

impl Activations {
    /// The skinning weights, `[F·V, J]` row-major.
    pub(crate) fn output(&self) -> &[f32] {
        &self.output
    }

    pub(crate) fn into_buffers(self) -> impl Iterator<Item = Vec<f32>> {
        self.hidden
            .into_iter()
            .chain(self.slopes)
            .chain(std::iter::once(self.output))
    }
}

/// The effective weight of each layer and its rows' norms.
fn effective_weights(ctx: &FusedContext, params: &[f32]) -> (Vec<Vec<f32>>, Vec<Vec<f32>>) {
    (0..ctx.layout.layer_count())
        .map(|i| {
            let (out, inp) = ctx.layout.shape(i);
            let [rv, rg, _] = ctx.layout.ranges(i);
            let (v, g) = (&params[rv], &params[rg]);
            let norms: Vec<f32> = v
                .chunks_exact(inp)
                .map(|row| row.iter().map(|x| x * x).sum::<f32>().sqrt())
                .collect();
            let mut w = Vec::with_capacity(out * inp);
            for (o, row) in v.chunks_exact(inp).enumerate() {
                let scale = g[o] / norms[o];
                w.extend(row.iter().map(|x| x * scale));
            }
            (w, norms)
        })
        .unzip()
}

/// Whether the output layer is computed over the candidates alone: a sparse mask, and an output
/// layer that reads only the last hidden layer.
fn sparse_output(ctx: &FusedContext, mask: &LogitMask) -> bool {
    let n = ctx.layout.layer_count();
    mask.is_sparse() && n > 1 && !reads_input(ctx, n - 1)
}

/// Whether layer `i` reads the network input (positions and poses).
fn reads_input(ctx: &FusedContext, i: usize) -> bool {
    i == 0 || i == ctx.config.skip_layer as usize
}

/// Width of the hidden input of layer `i` (0 for the first layer).
fn hidden_input(ctx: &FusedContext, i: usize) -> usize {
    if i == 0 { 0 } else { ctx.layout.shape(i - 1).0 }
}

/// Fills `z` (rows × out) with `b` plus the layer's input parts: for a layer that reads the
/// network input, the per-vertex product `positions·W_posᵀ` and the per-frame product
/// `poses·W_poseᵀ`, each computed once and broadcast over the rows (with a pose per row, that
/// product is one per row instead).
#[allow(clippy::too_many_arguments)]
fn init_rows(
    ctx: &FusedContext,
    i: usize,
    z: &mut [f32],
    w: &[f32],
    bias: &[f32],
    positions: &[f32],
    poses: Poses<'_>,
    frames: usize,
    vertices: usize,
    threads: usize,
) {
    let (out, inp) = ctx.layout.shape(i);
    if !reads_input(ctx, i) {
        z.par_chunks_mut(out * CHUNK_ROWS).for_each(|c| {
            for row in c.chunks_exact_mut(out) {
                row.copy_from_slice(bias);
            }
        });
        return;
    }
    let (pw, qw) = (ctx.config.position_width(), ctx.config.pose_width());
    let prev = hidden_input(ctx, i);
    let wm = MatRef::row_major(w, out, inp);
    let mut per_vertex = vec![0.0; vertices * out];
    matmul(
        MatMut::row_major(&mut per_vertex, vertices, out),
        MatRef::row_major(positions, vertices, pw),
        wm.columns(prev, pw).t(),
        false,
        threads,
    );
    // One row per frame: the bias, plus with a pose per frame that frame's pose product.
    let mut per_frame: Vec<f32> = (0..frames).flat_map(|_| bias.iter().copied()).collect();
    if let Poses::PerFrame(data) = poses {
        matmul(
            MatMut::row_major(&mut per_frame, frames, out),
            MatRef::row_major(data, frames, qw),
            wm.columns(prev + pw, qw).t(),
            true,
            1,
        );
    }
    z.par_chunks_mut(vertices * out)
        .zip(per_frame.par_chunks(out))
        .for_each(|(frame_rows, c)| {
            for (row, a) in frame_rows
                .chunks_exact_mut(out)
                .zip(per_vertex.chunks_exact(out))
            {
                for ((z, a), c) in row.iter_mut().zip(a).zip(c) {
                    *z = a + c;
                }
            }
        });
    match poses {
        Poses::PerFrame(_) => {}
        Poses::PerRow(data) => matmul(
            MatMut::row_major(z, frames * vertices, out),
            MatRef::row_major(data, frames * vertices, qw),
            wm.columns(prev + pw, qw).t(),
            true,
            threads,
        ),
        Poses::Local(local) => {
            local_pose_forward(z, w, inp, prev + pw, local, out, threads);
        }
    }
}

/// Row-wise softmax in place (`width` columns).
fn softmax_rows(z: &mut [f32], width: usize) {
    z.par_chunks_mut(width * CHUNK_ROWS).for_each(|c| {
        for row in c.chunks_exact_mut(width) {
            let m = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let mut sum = 0.0;
            for x in row.iter_mut() {
                *x = (*x - m).exp();
                sum += *x;
            }
            let inv = 1.0 / sum;
            for x in row.iter_mut() {
                *x *= inv;
            }
        }
    });
}

/// The forward pass over `frames × vertices` rows; keeps what backward needs.
pub(crate) fn forward(
    ctx: &FusedContext,
    params: &[f32],
    positions: &[f32],
    poses: Poses<'_>,
    mask: Option<&LogitMask>,
    frames: usize,
    vertices: usize,
) -> Result<Activations> {
    let rows = frames * vertices;
    let threads = rayon::current_num_threads();
    let (weights, norms) = effective_weights(ctx, params);
    let n = ctx.layout.layer_count();
    let beta = ctx.config.softplus_beta;
    let mut hidden: Vec<Vec<f32>> = Vec::with_capacity(n - 1);
    let mut slopes: Vec<Vec<f32>> = Vec::with_capacity(n - 1);
    let mut output = Vec::new();
    for (i, w) in weights.iter().enumerate() {
        let (out, inp) = ctx.layout.shape(i);
        let [_, _, rb] = ctx.layout.ranges(i);
        let mut z = ctx.pool.take(rows * out);
        if let (Some(mask), Some(h)) = (mask, hidden.last())
            && i + 1 == n
            && sparse_output(ctx, mask)
        {
            sparse_output_forward(&mut z, h, w, &params[rb], mask, out, inp, vertices);
            output = z;
            break;
        }
        init_rows(
            ctx,
            i,
            &mut z,
            w,
            &params[rb],
            positions,
            poses,
            frames,
            vertices,
            threads,
        );
        let prev = hidden_input(ctx, i);
        if let Some(h) = hidden.last() {
            matmul(
                MatMut::row_major(&mut z, rows, out),
                MatRef::row_major(h, rows, prev),
                MatRef::row_major(w, out, inp).columns(0, prev).t(),
                true,
                threads,
            );
        }
        if i + 1 < n {
            let mut s = ctx.pool.take(rows * out);
            let failed = z
                .par_chunks_mut(out * CHUNK_ROWS)
                .zip(s.par_chunks_mut(out * CHUNK_ROWS))
                .map(|(z, s)| {
                    let failed = softplus_with_slope(ctx.kernel, z, s, beta).is_err();
                    flush(z, FLUSH);
                    flush(s, FLUSH);
                    failed
                })
                .reduce(|| false, |a, b| a || b);
            if failed {
                bail!("fused SkinNet: the Softplus kernel is unavailable");
            }
            hidden.push(z);
            slopes.push(s);
        } else {
            if let Some(mask) = mask {
                // Non-candidate logits become −∞: their weights are exactly 0 and their
                // gradients too (the softmax's backward multiplies by the weight).
                z.par_chunks_mut(vertices * out).for_each(|frame_rows| {
                    for (z, m) in frame_rows.iter_mut().zip(&mask.additive) {
                        *z += m;
                    }
                });
            }
            softmax_rows(&mut z, out);
            output = z;
        }
    }
    Ok(Activations {
        frames,
        vertices,
        weights,
        norms,
        hidden,
        slopes,
        output,
    })
}

/// `(Σ_f dZ[f, v], Σ_v dZ[f, v])`: the gradient reaching the per-vertex and the per-frame input
/// products of a layer that reads the network input.
fn frame_and_vertex_sums(
    dz: &[f32],
    out: usize,
    frames: usize,
    vertices: usize,
) -> (Vec<f32>, Vec<f32>) {
    let mut per_vertex = vec![0.0f32; vertices * out];
    let mut per_frame = vec![0.0f32; frames * out];
    for (f, frame_rows) in dz.chunks_exact(vertices * out).enumerate() {
        let pf = &mut per_frame[f * out..(f + 1) * out];
        for (row, pv) in frame_rows
            .chunks_exact(out)
            .zip(per_vertex.chunks_exact_mut(out))
        {
            for ((d, a), b) in row.iter().zip(pv.iter_mut()).zip(pf.iter_mut()) {
                *a += d;
                *b += d;
            }
        }
    }
    (per_vertex, per_frame)
}

/// Weight normalisation's backward for one layer: from `∂L/∂W` to `∂L/∂v` and `∂L/∂g`, with
/// `W = g·v/‖v‖` per row: `∂g = ⟨∂W, v⟩/‖v‖`, `∂v = (g/‖v‖)(∂W − (⟨∂W, v⟩/‖v‖²)·v)`.
fn weight_norm_backward(
    dw: &[f32],
    v: &[f32],
    g: &[f32],
    norms: &[f32],
    inp: usize,
    dv: &mut [f32],
    dg: &mut [f32],
) {
    for (o, ((dw_row, v_row), dv_row)) in dw
        .chunks_exact(inp)
        .zip(v.chunks_exact(inp))
        .zip(dv.chunks_exact_mut(inp))
        .enumerate()
    {
        let norm = norms[o];
        let dot: f32 = dw_row.iter().zip(v_row).map(|(a, b)| a * b).sum();
        dg[o] = dot / norm;
        let scale = g[o] / norm;
        let along = dot / (norm * norm);
        for ((d, &a), &x) in dv_row.iter_mut().zip(dw_row).zip(v_row) {
            *d = scale * (a - along * x);
        }
    }
}

/// `∂Z = ∂H ⊙ S` in place, rows of `width`, flushing what falls below `tau` (see [`FLUSH`]).
fn scale_by_slopes(dh: &mut [f32], slopes: &[f32], width: usize, tau: f32) {
    dh.par_chunks_mut(width * CHUNK_ROWS)
        .zip(slopes.par_chunks(width * CHUNK_ROWS))
        .for_each(|(d, s)| {
            for (d, s) in d.iter_mut().zip(s) {
                *d *= s;
            }
            flush(d, tau);
        });
}

/// The backward pass: `∂L/∂params` (flat, [`super::ParamLayout`] order) from `∂L/∂weights`
/// (`grad`, rows × J). Returns the activation buffers to the pool.
pub(crate) fn backward(
    ctx: &FusedContext,
    params: &[f32],
    positions: &[f32],
    poses: Poses<'_>,
    mask: Option<&LogitMask>,
    acts: Activations,
    grad: &[f32],
) -> Result<Vec<f32>> {
    let (frames, vertices) = (acts.frames, acts.vertices);
    let rows = frames * vertices;
    let n = ctx.layout.layer_count();
    let joints = ctx.layout.shape(n - 1).0;
    if grad.len() != rows * joints {
        bail!(
            "fused SkinNet: gradient has {} entries, expected {rows} × {joints}",
            grad.len()
        );
    }
    let threads = rayon::current_num_threads();
    let (pw, qw) = (ctx.config.position_width(), ctx.config.pose_width());
    // Softmax backward: ∂z = y ⊙ (g − ⟨g, y⟩).
    let mut dz = ctx.pool.take(rows * joints);
    dz.par_chunks_mut(joints * CHUNK_ROWS)
        .zip(acts.output.par_chunks(joints * CHUNK_ROWS))
        .zip(grad.par_chunks(joints * CHUNK_ROWS))
        .for_each(|((d, y), g)| {
            for ((d, y), g) in d
                .chunks_exact_mut(joints)
                .zip(y.chunks_exact(joints))
                .zip(g.chunks_exact(joints))
            {
                let dot: f32 = y.iter().zip(g).map(|(a, b)| a * b).sum();
                for ((d, &y), &g) in d.iter_mut().zip(y).zip(g) {
                    *d = y * (g - dot);
                }
            }
        });
    // Gradients this far below the largest one at the output are flushed (see `FLUSH`).
    let tau = FLUSH * dz.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    flush(&mut dz, tau);
    let mut dparams = vec![0.0f32; ctx.layout.len()];
    let mut dw = Vec::new();
    for i in (0..n).rev() {
        let (out, inp) = ctx.layout.shape(i);
        let prev = hidden_input(ctx, i);
        dw.clear();
        dw.resize(out * inp, 0.0);
        let [rv, rg, rb] = ctx.layout.ranges(i);
        if let Some(mask) = mask.filter(|m| i + 1 == n && sparse_output(ctx, m)) {
            let mut dh = ctx.pool.take(rows * prev);
            sparse_output_backward(
                &dz,
                &acts.hidden[i - 1],
                &acts.weights[i],
                mask,
                out,
                inp,
                vertices,
                threads,
                &mut dw,
                &mut dparams[rb],
                &mut dh,
            );
            scale_by_slopes(&mut dh, &acts.slopes[i - 1], prev, tau);
            ctx.pool.give([std::mem::replace(&mut dz, dh)]);
            let (dv, dg) = dparams[rv.start..rg.end].split_at_mut(rv.len());
            weight_norm_backward(&dw, &params[rv], &params[rg], &acts.norms[i], inp, dv, dg);
            continue;
        }
        let dzm = MatRef::row_major(&dz, rows, out);
        if i > 0 {
            matmul(
                MatMut::row_major(&mut dw, out, inp).columns(0, prev),
                dzm.t(),
                MatRef::row_major(&acts.hidden[i - 1], rows, prev),
                false,
                threads,
            );
        }
        let mut db = vec![0.0f32; out];
        if reads_input(ctx, i) {
            let (per_vertex, per_frame) = frame_and_vertex_sums(&dz, out, frames, vertices);
            matmul(
                MatMut::row_major(&mut dw, out, inp).columns(prev, pw),
                MatRef::row_major(&per_vertex, vertices, out).t(),
                MatRef::row_major(positions, vertices, pw),
                false,
                threads,
            );
            match poses {
                Poses::PerRow(data) => matmul(
                    MatMut::row_major(&mut dw, out, inp).columns(prev + pw, qw),
                    dzm.t(),
                    MatRef::row_major(data, rows, qw),
                    false,
                    threads,
                ),
                Poses::PerFrame(data) => matmul(
                    MatMut::row_major(&mut dw, out, inp).columns(prev + pw, qw),
                    MatRef::row_major(&per_frame, frames, out).t(),
                    MatRef::row_major(data, frames, qw),
                    false,
                    1,
                ),
                Poses::Local(local) => {
                    local_pose_backward(&mut dw, inp, prev + pw, &dz, local, out, threads);
                }
            }
            for row in per_frame.chunks_exact(out) {
                for (b, d) in db.iter_mut().zip(row) {
                    *b += d;
                }
            }
        } else {
            for row in dz.chunks_exact(out) {
                for (b, d) in db.iter_mut().zip(row) {
                    *b += d;
                }
            }
        }
        if i > 0 {
            // ∂H_{i−1} = ∂Z_i · W_i[:, :prev], then ∂Z_{i−1} = ∂H_{i−1} ⊙ S_{i−1}.
            let mut dh = ctx.pool.take(rows * prev);
            matmul(
                MatMut::row_major(&mut dh, rows, prev),
                dzm,
                MatRef::row_major(&acts.weights[i], out, inp).columns(0, prev),
                false,
                threads,
            );
            scale_by_slopes(&mut dh, &acts.slopes[i - 1], prev, tau);
            ctx.pool.give([std::mem::replace(&mut dz, dh)]);
        }
        dparams[rb].copy_from_slice(&db);
        // `v` and `g` are adjacent in the layout: one split gives both.
        let (dv, dg) = dparams[rv.start..rg.end].split_at_mut(rv.len());
        weight_norm_backward(&dw, &params[rv], &params[rg], &acts.norms[i], inp, dv, dg);
    }
    ctx.pool
        .give(acts.into_buffers().chain(std::iter::once(dz)));
    Ok(dparams)
}
