//! Top-k influences for stock engine skinning: each vertex's `K` strongest joints of the fast
//! path's weights, renormalised and written in the layouts engines upload (u8/u16 joint
//! indices; unorm8, unorm16 or f32 weights), quantised by largest remainder so that the
//! integers sum exactly to the format's one.

use skinfield_formats::MAX_JOINTS;

use super::job::{BaseTile, FastFrame, check_range};
use super::mesh::FastMesh;
use super::{Influence, MAX_INFLUENCES};
use crate::error::RuntimeError;
use crate::frame::FrameState;
use crate::kernels::tiles;

/// The `out.len()` largest of `weights` (joint order; ties keep the lower joint first),
/// strongest first, negative values clamped to zero and renormalised to sum to one. Slots past
/// `weights.len()` get joint 0 with weight 0; NaN never wins a slot.
pub fn strongest_influences(weights: &[f32], out: &mut [Influence]) {
    if out.is_empty() {
        return;
    }
    let nan_last = |w: f32| if w.is_nan() { f32::NEG_INFINITY } else { w };
    let len = select(weights.iter().map(|&w| nan_last(w)).enumerate(), out);
    renormalise(out, len);
}

/// [`strongest_influences`] of the dense weights whose only non-zero entries are `entries`
/// (`(joint, weight)`, distinct joints below `joints`, weights finite and non-negative, in any
/// order), in a time that grows with `entries` and `out`, not with the joint count: the result is
/// the same, joint indices of zero-weight slots included (the dense selection fills them with
/// the lowest joints that hold no weight).
pub(crate) fn strongest_sparse(
    entries: impl Iterator<Item = (usize, f32)>,
    joints: usize,
    out: &mut [Influence],
) {
    let k = out.len();
    if k == 0 {
        return;
    }
    // The positive entries in joint order, so that ties resolve as in the dense selection.
    let mut positive = [(0usize, 0.0f32); MAX_INFLUENCES];
    let mut n = 0;
    for (j, w) in entries.filter(|e| e.1 > 0.0).take(MAX_INFLUENCES) {
        let mut at = n;
        while at > 0 && positive[at - 1].0 > j {
            positive[at] = positive[at - 1];
            at -= 1;
        }
        positive[at] = (j, w);
        n += 1;
    }
    let mut len = select(positive[..n].iter().copied(), out);
    let mut j = 0;
    while len < k && j < joints {
        // Only reached when every positive entry already holds a slot.
        if !positive[..n].iter().any(|p| p.0 == j) {
            out[len] = Influence {
                index: j as u32,
                weight: 0.0,
            };
            len += 1;
        }
        j += 1;
    }
    renormalise(out, len);
}

/// Keeps the `out.len()` largest of `(joint, weight)` candidates given in joint order (a later
/// candidate must be strictly larger to displace an earlier one), strongest first. Returns the
/// slots filled.
fn select(candidates: impl Iterator<Item = (usize, f32)>, out: &mut [Influence]) -> usize {
    let k = out.len();
    let mut len = 0;
    for (j, w) in candidates {
        if len == k && w <= out[k - 1].weight {
            continue;
        }
        // First slot holding a strictly smaller weight: equal weights stay in joint order.
        let mut at = len.min(k - 1);
        while at > 0 && out[at - 1].weight < w {
            at -= 1;
        }
        let end = len.min(k - 1);
        out.copy_within(at..end, at + 1);
        out[at] = Influence {
            index: j as u32,
            weight: w,
        };
        len = (len + 1).min(k);
    }
    len
}

/// Clears the slots past `len` (joint 0, weight 0) and renormalises the weights, negative ones
/// clamped to zero, to sum to one (all zero: the first slot takes it all).
fn renormalise(out: &mut [Influence], len: usize) {
    for o in &mut out[len..] {
        *o = Influence::default();
    }
    let sum: f32 = out.iter().map(|o| o.weight.max(0.0)).sum();
    for (i, o) in out.iter_mut().enumerate() {
        o.weight = if sum > 0.0 {
            o.weight.max(0.0) / sum
        } else if i == 0 {
            1.0
        } else {
            0.0
        };
    }
}

/// Quantises non-negative `weights` (any positive sum; they are normalised first) to integers
/// summing exactly to `one`: each gets `floor(w · one)`, then the shortfall (fewer units than
/// weights) goes one unit each to the largest fractional parts (ties: the earlier slot). The
/// order of the weights is kept. All weights zero (or no positive sum) puts `one` in slot 0.
pub fn quantise_largest_remainder(weights: &[f32], one: u32, out: &mut [u32]) {
    debug_assert_eq!(weights.len(), out.len());
    let n = weights.len().min(out.len()).min(MAX_INFLUENCES);
    if n == 0 {
        return;
    }
    let total: f64 = weights[..n].iter().map(|&w| f64::from(w.max(0.0))).sum();
    if !(total > 0.0 && total.is_finite()) {
        out.fill(0);
        out[0] = one;
        return;
    }
    let mut frac = [0.0f64; MAX_INFLUENCES];
    let mut given: u64 = 0;
    for i in 0..n {
        let x = f64::from(weights[i].max(0.0)) / total * f64::from(one);
        let q = libm::floor(x);
        out[i] = q as u32;
        frac[i] = x - q;
        given += q as u64;
    }
    // Σ floor(x_i) ≤ Σ x_i = one, and the shortfall is below the slot count.
    let mut short = u64::from(one).saturating_sub(given);
    while short > 0 {
        let mut best = 0;
        for i in 1..n {
            if frac[i] > frac[best] {
                best = i;
            }
        }
        out[best] += 1;
        frac[best] = -1.0;
        short -= 1;
    }
}

/// Where [`TopKJob`] writes joint indices: `K` per vertex.
#[derive(Debug)]
pub enum TopKIndices<'a> {
    /// One byte per index (joint counts up to 256), e.g. glTF `JOINTS_0` as `UNSIGNED_BYTE`.
    U8(&'a mut [u8]),
    /// Two bytes per index.
    U16(&'a mut [u16]),
}

/// Where [`TopKJob`] writes weights: `K` per vertex, each vertex's summing exactly to one in
/// the format (255, 65535, or 1.0 in any summation order).
#[derive(Debug)]
pub enum TopKWeights<'a> {
    /// unorm8: 255 is one.
    Unorm8(&'a mut [u8]),
    /// unorm16: 65535 is one.
    Unorm16(&'a mut [u16]),
    /// f32 multiples of 2⁻²⁴, so every partial sum is exact and the total is exactly 1.0.
    F32(&'a mut [f32]),
}

impl TopKIndices<'_> {
    fn len(&self) -> usize {
        match self {
            Self::U8(s) => s.len(),
            Self::U16(s) => s.len(),
        }
    }
}

impl TopKWeights<'_> {
    fn len(&self) -> usize {
        match self {
            Self::Unorm8(s) => s.len(),
            Self::Unorm16(s) => s.len(),
            Self::F32(s) => s.len(),
        }
    }

    /// The integer that stands for 1.0.
    fn one(&self) -> u32 {
        match self {
            Self::Unorm8(_) => 255,
            Self::Unorm16(_) => 65535,
            Self::F32(_) => 1 << 24,
        }
    }
}

/// Writes the `influences` strongest joints of every vertex of a range (`out_indices.len() /
/// influences` vertices from `first_vertex`), strongest first, for an engine's own skinning.
pub struct TopKJob<'a> {
    /// The mesh bound for the fast path.
    pub mesh: &'a FastMesh,
    /// The posed frame.
    pub frame: &'a FrameState,
    /// The nodes, updated for `frame`'s pose.
    pub nodes: &'a FastFrame,
    /// Joints per vertex `K`, 1..=[`MAX_INFLUENCES`].
    pub influences: usize,
    /// First vertex of the range.
    pub first_vertex: usize,
    /// Joint indices, `K` per vertex (its length sets the range).
    pub out_indices: TopKIndices<'a>,
    /// Weights, `K` per vertex (the same length as `out_indices`).
    pub out_weights: TopKWeights<'a>,
}

impl TopKJob<'_> {
    /// Checks every field; the error names the first one that is wrong.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        self.nodes.check(self.mesh, self.frame)?;
        let k = self.influences;
        if !(1..=MAX_INFLUENCES).contains(&k) {
            return Err(RuntimeError::Setting {
                field: "influences",
                value: k,
                min: 1,
                max: MAX_INFLUENCES,
            });
        }
        let len = self.out_indices.len();
        if !len.is_multiple_of(k) {
            return Err(RuntimeError::BufferLength {
                field: "out_indices",
                len,
                expected: len / k * k,
            });
        }
        if self.out_weights.len() != len {
            return Err(RuntimeError::BufferLength {
                field: "out_weights",
                len: self.out_weights.len(),
                expected: len,
            });
        }
        let j = self.mesh.joint_count();
        if matches!(self.out_indices, TopKIndices::U8(_)) && j > 256 {
            return Err(RuntimeError::Setting {
                field: "out_indices (u8: joint count)",
                value: j,
                min: 1,
                max: 256,
            });
        }
        check_range(self.mesh, self.first_vertex, len / k)
    }

    /// Validates, then writes the range. Never allocates.
    pub fn run(&mut self) -> Result<(), RuntimeError> {
        self.validate()?;
        let (mesh, nodes) = (self.mesh, self.nodes);
        let k = self.influences;
        let j = mesh.joint_count();
        let mut top = [Influence::default(); MAX_INFLUENCES];
        let top = &mut top[..k];
        let count = self.out_indices.len() / k;
        if mesh.options().base_influences > 0 {
            // A tile of base weights at a time; each vertex's selection costs its base.
            let mut tile = BaseTile::new();
            for (start, len) in tiles(count) {
                nodes.base_tile(mesh, self.first_vertex + start, len, &mut tile);
                for i in start..start + len {
                    strongest_sparse(tile.entries(mesh, self.first_vertex + i), j, top);
                    self.write(i, top);
                }
            }
        } else {
            let mut dense = [0.0f32; MAX_JOINTS];
            let dense = &mut dense[..j];
            for i in 0..count {
                nodes.convex_weights(mesh, self.first_vertex + i, dense);
                strongest_influences(dense, top);
                self.write(i, top);
            }
        }
        Ok(())
    }

    /// Writes vertex `i` of the range: `top`'s joints and its weights quantised to the format.
    fn write(&mut self, i: usize, top: &[Influence]) {
        let k = top.len();
        let one = self.out_weights.one();
        let mut w = [0.0f32; MAX_INFLUENCES];
        let mut q = [0u32; MAX_INFLUENCES];
        for (w, t) in w.iter_mut().zip(top) {
            *w = t.weight;
        }
        quantise_largest_remainder(&w[..k], one, &mut q[..k]);
        let range = i * k..(i + 1) * k;
        match &mut self.out_indices {
            TopKIndices::U8(o) => {
                for (o, t) in o[range.clone()].iter_mut().zip(top) {
                    *o = t.index as u8;
                }
            }
            TopKIndices::U16(o) => {
                for (o, t) in o[range.clone()].iter_mut().zip(top) {
                    *o = t.index as u16;
                }
            }
        }
        match &mut self.out_weights {
            TopKWeights::Unorm8(o) => {
                for (o, &q) in o[range].iter_mut().zip(&q[..k]) {
                    *o = q as u8;
                }
            }
            TopKWeights::Unorm16(o) => {
                for (o, &q) in o[range].iter_mut().zip(&q[..k]) {
                    *o = q as u16;
                }
            }
            TopKWeights::F32(o) => {
                for (o, &q) in o[range].iter_mut().zip(&q[..k]) {
                    *o = q as f32 * (1.0 / (1u32 << 24) as f32);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strongest_picks_the_largest_in_order_and_renormalises() {
        let w = [0.1, 0.3, -0.05, 0.3, 0.2, 0.15];
        let mut out = [Influence::default(); 3];
        strongest_influences(&w, &mut out);
        // Ties (joints 1 and 3) keep joint order.
        assert_eq!(out.map(|o| o.index), [1, 3, 4]);
        let s = 0.3 + 0.3 + 0.2;
        for (o, want) in out.iter().zip([0.3 / s, 0.3 / s, 0.2 / s]) {
            assert!((o.weight - want).abs() < 1e-6);
        }
        // More slots than joints: the rest are (0, 0); a negative chosen weight becomes 0.
        let mut out = [Influence::default(); 4];
        strongest_influences(&[0.9, -0.1], &mut out);
        assert_eq!(
            out,
            [
                Influence {
                    index: 0,
                    weight: 1.0
                },
                Influence {
                    index: 1,
                    weight: 0.0
                },
                Influence::default(),
                Influence::default()
            ]
        );
        // NaN never wins.
        let mut out = [Influence::default(); 1];
        strongest_influences(&[f32::NAN, 0.2], &mut out);
        assert_eq!(out[0].index, 1);
    }

    /// The sparse selection (a vertex's base entries) gives what the dense one gives on the
    /// scattered weights, joints of zero-weight slots included: ties, exact zeros among the
    /// entries, fewer entries than slots, entries in any order.
    #[test]
    fn sparse_selection_equals_the_dense_one() {
        let mut state = 777u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            state >> 8
        };
        for case in 0..2000 {
            let joints = 1 + (next() % 70) as usize;
            let count = (next() as usize % MAX_INFLUENCES.min(joints)) + 1;
            let mut entries: Vec<(usize, f32)> = Vec::new();
            while entries.len() < count {
                let j = next() as usize % joints;
                if entries.iter().all(|e| e.0 != j) {
                    // Coarse values make ties; every fourth entry is an exact zero.
                    let w = if next() % 4 == 0 {
                        0.0
                    } else {
                        (1 + next() % 4) as f32 / 8.0
                    };
                    entries.push((j, w));
                }
            }
            let mut dense = vec![0.0f32; joints];
            for &(j, w) in &entries {
                dense[j] = w;
            }
            for k in 1..=MAX_INFLUENCES {
                let mut want = vec![Influence::default(); k];
                strongest_influences(&dense, &mut want);
                let mut got = vec![Influence::default(); k];
                strongest_sparse(entries.iter().copied(), joints, &mut got);
                assert_eq!(got, want, "case {case}, k = {k}, {entries:?}");
            }
        }
    }

    #[test]
    fn strongest_matches_a_full_sort() {
        let mut state = 12345u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        for k in 1..=MAX_INFLUENCES {
            for _ in 0..50 {
                let w: Vec<f32> = (0..24).map(|_| (next() * 8.0).floor() / 8.0).collect();
                let mut out = vec![Influence::default(); k];
                strongest_influences(&w, &mut out);
                let mut order: Vec<usize> = (0..w.len()).collect();
                order.sort_by(|&a, &b| w[b].total_cmp(&w[a]).then(a.cmp(&b)));
                let want: Vec<u32> = order[..k].iter().map(|&j| j as u32).collect();
                let got: Vec<u32> = out.iter().map(|o| o.index).collect();
                assert_eq!(got, want, "{w:?}");
            }
        }
    }

    #[test]
    fn largest_remainder_sums_exactly_and_rounds_sensibly() {
        let mut q = [0u32; 4];
        quantise_largest_remainder(&[0.5, 0.25, 0.125, 0.125], 255, &mut q);
        // 127.5, 63.75, 31.875, 31.875 → floors 127, 63, 31, 31 (252); +1 to the three largest
        // fractions: .875, .875 (slots 2, 3), then .75 (slot 1).
        assert_eq!(q, [127, 64, 32, 32]);
        assert_eq!(q.iter().sum::<u32>(), 255);
        quantise_largest_remainder(&[1.0, 1.0, 1.0, 0.0], 255, &mut q);
        assert_eq!(q, [85, 85, 85, 0]);
        quantise_largest_remainder(&[0.0; 4], 65535, &mut q);
        assert_eq!(q, [65535, 0, 0, 0]);
        // Unnormalised input is normalised; every result sums exactly.
        let mut state = 7u32;
        for _ in 0..1000 {
            let w: Vec<f32> = (0..4)
                .map(|_| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (state >> 9) as f32 / 8_388_608.0
                })
                .collect();
            for one in [255, 65535, 1 << 24] {
                quantise_largest_remainder(&w, one, &mut q);
                assert_eq!(q.iter().sum::<u32>(), one);
                let total: f64 = w.iter().map(|&x| f64::from(x)).sum();
                for (qi, wi) in q.iter().zip(&w) {
                    let exact = f64::from(*wi) / total * f64::from(one);
                    assert!((f64::from(*qi) - exact).abs() < 1.0, "{q:?} {w:?}");
                }
            }
        }
    }

    #[test]
    fn f32_grid_weights_sum_to_one_in_any_order() {
        let mut q = [0u32; 4];
        quantise_largest_remainder(&[0.3, 0.3, 0.3, 0.1], 1 << 24, &mut q);
        let w: Vec<f32> = q
            .iter()
            .map(|&q| q as f32 * (1.0 / (1u32 << 24) as f32))
            .collect();
        assert_eq!(((w[0] + w[1]) + w[2]) + w[3], 1.0);
        assert_eq!(w[3] + (w[2] + (w[1] + w[0])), 1.0);
        assert_eq!((w[0] + w[3]) + (w[1] + w[2]), 1.0);
    }
}
