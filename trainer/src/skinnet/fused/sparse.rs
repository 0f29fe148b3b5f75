//! The parts of the fused pass that use the structure of what training feeds it, where it pays:
//! pose locality's input ([`LocalPoses`]: the input layers' pose product per row from a donor's
//! product plus the relevant joints' columns) and the candidate joints (the output layer
//! computes, normalises and differentiates only each point's candidate logits, the others being
//! −∞).
//!
//! Both give the dense pass's values up to the order of summation (the tests compare them with
//! candle's graph). Whether each is used is decided per call by [`worth_sparse`] from the sizes:
//! with 8 candidates of 24 joints the dense products cost the same (measured,
//! `cargo bench -p skinfield-benches --bench skinnet_step -- skinnet_pose_locality`), and the
//! dense path keeps the results of the small rigs bit for bit what they were.

use rayon::prelude::*;

use super::gemm::{MatMut, MatRef, matmul};
use super::pass::CHUNK_ROWS;
use crate::skinnet::LocalPoses;
use crate::skinnet::local_poses::JointLists;

/// Whether a structure with `kept` of `total` entries (relevant or candidate joints, summed over
/// the points) is worth computing sparsely: at most a quarter of the entries.
#[must_use]
pub(crate) fn worth_sparse(kept: usize, total: usize) -> bool {
    kept.saturating_mul(4) <= total
}

/// The additive logit mask `[V, J]` (0 or −∞ for candidate masks; any finite values are allowed
/// and then only added), and each point's candidate joints when the mask is a candidate mask
/// whose candidates are few enough to compute alone ([`worth_sparse`]).
#[derive(Debug)]
pub(crate) struct LogitMask {
    pub(crate) additive: Vec<f32>,
    candidates: Option<JointLists>,
}

impl LogitMask {
    /// The mask of `joints` columns; its candidate lists when every entry is 0 or −∞, every
    /// point keeps at least one joint and [`worth_sparse`] says so.
    pub(crate) fn new(additive: Vec<f32>, joints: usize) -> Self {
        let candidates = Self::candidates(&additive, joints);
        Self {
            additive,
            candidates,
        }
    }

    /// The mask without candidate lists: the output layer stays dense.
    pub(crate) fn dense(additive: Vec<f32>) -> Self {
        Self {
            additive,
            candidates: None,
        }
    }

    fn candidates(additive: &[f32], joints: usize) -> Option<JointLists> {
        if joints == 0
            || !additive.len().is_multiple_of(joints)
            || additive.iter().any(|&m| m != 0.0 && m != f32::NEG_INFINITY)
        {
            return None;
        }
        let lists = JointLists::where_true(additive, joints, |&m| m == 0.0);
        (worth_sparse(lists.total(), additive.len()) && !lists.has_empty()).then_some(lists)
    }

    /// Whether the output layer is computed over the candidates alone.
    pub(crate) fn is_sparse(&self) -> bool {
        self.candidates.is_some()
    }

    fn of(&self, v: usize) -> &[u32] {
        self.candidates.as_ref().map_or(&[], |c| c.of(v))
    }
}

/// `Σ a_i b_i` in eight lanes (so the compiler vectorises it).
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut lanes = [0.0f32; 8];
    let (ac, bc) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ac
        .remainder()
        .iter()
        .zip(bc.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ac.zip(bc) {
        for k in 0..8 {
            lanes[k] += x[k] * y[k];
        }
    }
    lanes.iter().sum::<f32>() + tail
}

/// Two parallel tasks' pairs of accumulators summed element-wise (what their reductions need).
fn add_pairs(
    (mut a, mut b): (Vec<f32>, Vec<f32>),
    (c, d): (Vec<f32>, Vec<f32>),
) -> (Vec<f32>, Vec<f32>) {
    a.iter_mut().zip(c).for_each(|(x, y)| *x += y);
    b.iter_mut().zip(d).for_each(|(x, y)| *x += y);
    (a, b)
}

/// `y += a·x`.
fn axpy(y: &mut [f32], a: f32, x: &[f32]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}

/// The output layer over the candidates (`mask` sparse): `out` (rows × J) gets each row's
/// softmax over its point's candidate logits `b_j + h·W_j` and 0 elsewhere; `h` is the last
/// hidden layer (rows × inp), `w` the layer's weight (J × inp).
#[allow(clippy::too_many_arguments)]
pub(super) fn sparse_output_forward(
    out: &mut [f32],
    h: &[f32],
    w: &[f32],
    bias: &[f32],
    mask: &LogitMask,
    joints: usize,
    inp: usize,
    vertices: usize,
) {
    out.par_chunks_mut(joints * CHUNK_ROWS)
        .zip(h.par_chunks(inp * CHUNK_ROWS))
        .enumerate()
        .for_each(|(chunk, (outs, hs))| {
            for (k, (row, hr)) in outs
                .chunks_exact_mut(joints)
                .zip(hs.chunks_exact(inp))
                .enumerate()
            {
                row.fill(0.0);
                let cand = mask.of((chunk * CHUNK_ROWS + k) % vertices);
                let mut top = f32::NEG_INFINITY;
                for &j in cand {
                    let j = j as usize;
                    let z = bias[j] + dot(hr, &w[j * inp..(j + 1) * inp]);
                    row[j] = z;
                    top = top.max(z);
                }
                let mut sum = 0.0;
                for &j in cand {
                    let e = (row[j as usize] - top).exp();
                    row[j as usize] = e;
                    sum += e;
                }
                let inv = 1.0 / sum;
                for &j in cand {
                    row[j as usize] *= inv;
                }
            }
        });
}

/// The output layer's backward over the candidates: from `dz` (rows × J, zero outside each
/// row's candidates) the weight gradient `dw` (J × inp, overwritten), the bias gradient `db`
/// (J, overwritten) and `dh = dz·W` (rows × inp, overwritten), touching only candidate entries.
#[allow(clippy::too_many_arguments)]
pub(super) fn sparse_output_backward(
    dz: &[f32],
    h: &[f32],
    w: &[f32],
    mask: &LogitMask,
    joints: usize,
    inp: usize,
    vertices: usize,
    threads: usize,
    dw: &mut [f32],
    db: &mut [f32],
    dh: &mut [f32],
) {
    let rows = dz.len() / joints;
    let per_task = rows.div_ceil(threads.max(1)).max(1);
    let zeros = || (vec![0.0f32; joints * inp], vec![0.0f32; joints]);
    let (gw, gb) = dz
        .par_chunks(per_task * joints)
        .zip(h.par_chunks(per_task * inp))
        .zip(dh.par_chunks_mut(per_task * inp))
        .enumerate()
        .map(|(task, ((dzs, hs), dhs))| {
            let (mut gw, mut gb) = zeros();
            for (k, ((dzr, hr), dhr)) in dzs
                .chunks_exact(joints)
                .zip(hs.chunks_exact(inp))
                .zip(dhs.chunks_exact_mut(inp))
                .enumerate()
            {
                dhr.fill(0.0);
                for &j in mask.of((task * per_task + k) % vertices) {
                    let j = j as usize;
                    let d = dzr[j];
                    if d != 0.0 {
                        axpy(&mut gw[j * inp..(j + 1) * inp], d, hr);
                        gb[j] += d;
                        axpy(dhr, d, &w[j * inp..(j + 1) * inp]);
                    }
                }
            }
            (gw, gb)
        })
        .reduce(zeros, add_pairs);
    dw.copy_from_slice(&gw);
    db.copy_from_slice(&gb);
}

/// Adds each row's pose product to `z` (rows × out) for a [`LocalPoses`] input, whose pose
/// columns start at `at` in `w` (out × inp): the donor's product (one `[D, out]` product for
/// the pool) plus, for each joint relevant to the row's vertex, its three features' difference
/// from the donor's times their columns ([`crate::skinnet::local_poses`]).
pub(super) fn local_pose_forward(
    z: &mut [f32],
    w: &[f32],
    inp: usize,
    at: usize,
    local: &LocalPoses,
    out: usize,
    threads: usize,
) {
    let q = 3 * local.joints();
    let d = local.donor_count();
    let mut donors = vec![0.0f32; d * out];
    matmul(
        MatMut::row_major(&mut donors, d, out),
        MatRef::row_major(local.pool(), d, q),
        MatRef::row_major(w, out, inp).columns(at, q).t(),
        false,
        threads,
    );
    // The pose columns transposed, `[Q, out]`, so each feature's column is contiguous.
    let mut columns = vec![0.0f32; q * out];
    for (o, row) in w.chunks_exact(inp).enumerate() {
        for (c, &x) in row[at..at + q].iter().enumerate() {
            columns[c * out + o] = x;
        }
    }
    z.par_chunks_mut(out * CHUNK_ROWS)
        .enumerate()
        .for_each(|(chunk, rows)| {
            for (k, row) in rows.chunks_exact_mut(out).enumerate() {
                let r = chunk * CHUNK_ROWS + k;
                let dn = local.donor(r);
                for (z, x) in row.iter_mut().zip(&donors[dn * out..(dn + 1) * out]) {
                    *z += x;
                }
                for (c, diff) in local.differences(r) {
                    axpy(row, diff, &columns[c * out..(c + 1) * out]);
                }
            }
        });
}

/// The gradient of the pose columns of a layer, `∂W[:, at..at + Q]`, for a [`LocalPoses`]
/// input, written into `dw` (out × inp): `Σ_d S_dᵀ·pool_d`, with `S_d` the sum of `dZ` over the
/// rows whose donor is `d`, plus each row's `dZ` times its relevant features' difference from
/// the donor's (the split of [`local_pose_forward`]).
pub(super) fn local_pose_backward(
    dw: &mut [f32],
    inp: usize,
    at: usize,
    dz: &[f32],
    local: &LocalPoses,
    out: usize,
    threads: usize,
) {
    let q = 3 * local.joints();
    let d = local.donor_count();
    let rows = dz.len() / out;
    let per_task = rows.div_ceil(threads.max(1)).max(1);
    // Per task: the donor sums `[D, out]` and the relevant features' part `[Q, out]`.
    let zeros = || (vec![0.0f32; d * out], vec![0.0f32; q * out]);
    let (sums, relevant) = dz
        .par_chunks(per_task * out)
        .enumerate()
        .map(|(task, chunk)| {
            let (mut sums, mut relevant) = zeros();
            for (k, drow) in chunk.chunks_exact(out).enumerate() {
                let r = task * per_task + k;
                let dn = local.donor(r);
                for (s, x) in sums[dn * out..(dn + 1) * out].iter_mut().zip(drow) {
                    *s += x;
                }
                for (c, diff) in local.differences(r) {
                    axpy(&mut relevant[c * out..(c + 1) * out], diff, drow);
                }
            }
            (sums, relevant)
        })
        .reduce(zeros, add_pairs);
    matmul(
        MatMut::row_major(dw, out, inp).columns(at, q),
        MatRef::row_major(&sums, d, out).t(),
        MatRef::row_major(local.pool(), d, q),
        false,
        threads,
    );
    for (o, row) in dw.chunks_exact_mut(inp).enumerate() {
        for (c, x) in row[at..at + q].iter_mut().enumerate() {
            *x += relevant[c * out + o];
        }
    }
}
