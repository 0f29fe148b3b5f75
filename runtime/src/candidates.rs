//! Candidate joints: the joints each vertex may be skinned to (a `.skf` of version 1.1 with a
//! `CAND` section).
//!
//! The trainer restricts SkinNet's softmax to a few joints near each point (the support of the
//! initial bone-heat weights and their skeleton neighbours), so a vertex can only move with
//! joints near it. The file stores anchors in the canonical space with their candidate lists; a
//! vertex of any mesh takes the list of its nearest anchor ([`nearest_anchors`], the same rule
//! the trainer uses for its query points), and every other joint's weight is exactly zero
//! (`mask_logits` before the softmax, `clear_masked` after it).

use alloc::vec;
use alloc::vec::Vec;

use glam::Vec3;
use skinfield_formats::skf::CandidatesView;
use skinfield_formats::skf::candidates::NO_JOINT;

use crate::kernels::TILE;

/// The anchors of a model and their candidate lists.
#[derive(Clone, Debug, PartialEq)]
pub struct AnchorSet {
    positions: Vec<Vec3>,
    /// `k` joints per anchor, ascending, padded with [`NO_JOINT`].
    joints: Vec<u16>,
    k: usize,
}

impl AnchorSet {
    /// Copies a validated `CAND` section.
    #[must_use]
    pub fn from_view(view: &CandidatesView<'_>) -> Self {
        let k = view.k();
        let mut joints = vec![NO_JOINT; view.len() * k];
        for a in 0..view.len() {
            for (slot, j) in joints[a * k..(a + 1) * k].iter_mut().zip(view.joints(a)) {
                *slot = j;
            }
        }
        Self {
            positions: (0..view.len())
                .map(|a| Vec3::from_array(view.position(a)))
                .collect(),
            joints,
            k,
        }
    }

    /// List slots per anchor.
    #[must_use]
    pub fn k(&self) -> usize {
        self.k
    }

    /// The anchors' canonical positions.
    #[must_use]
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The list of anchor `a` (`k` slots, padded with [`NO_JOINT`]).
    #[must_use]
    pub fn list(&self, a: usize) -> &[u16] {
        &self.joints[a * self.k..(a + 1) * self.k]
    }

    /// The candidate lists of `points` (each the nearest anchor's), `k` slots per point.
    #[must_use]
    pub fn lists_for(&self, points: &[Vec3]) -> Vec<u16> {
        let nearest = nearest_anchors(&self.positions, points);
        let mut out = Vec::with_capacity(points.len() * self.k);
        for a in nearest {
            out.extend_from_slice(self.list(a as usize));
        }
        out
    }
}

/// For every point, the index of the nearest anchor (ties: the lower index), with a uniform grid
/// over the anchors (about two per cell; exact: rings are searched until no nearer anchor can
/// remain). Empty `anchors` give an empty result.
#[must_use]
pub fn nearest_anchors(anchors: &[Vec3], points: &[Vec3]) -> Vec<u32> {
    if anchors.is_empty() {
        return Vec::new();
    }
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &a in anchors {
        lo = lo.min(a);
        hi = hi.max(a);
    }
    let extent = (hi - lo).max_element().max(1e-6);
    let side = libm::ceilf(libm::cbrtf(anchors.len() as f32 / 2.0)).clamp(1.0, 128.0);
    let cell = extent / side * 1.0001;
    let dims: [i64; 3] = core::array::from_fn(|k| ((hi[k] - lo[k]) / cell) as i64 + 1);
    let cell_of = |p: Vec3| -> [i64; 3] {
        core::array::from_fn(|k| libm::floorf((p[k] - lo[k]) / cell) as i64)
    };
    let index = |c: [i64; 3]| ((c[2] * dims[1] + c[1]) * dims[0] + c[0]) as usize;
    let ncell = (dims[0] * dims[1] * dims[2]) as usize;
    let mut start = vec![0usize; ncell + 1];
    for &a in anchors {
        start[index(cell_of(a)) + 1] += 1;
    }
    for c in 0..ncell {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut items = vec![0u32; anchors.len()];
    for (i, &a) in anchors.iter().enumerate() {
        let c = index(cell_of(a));
        items[fill[c]] = i as u32;
        fill[c] += 1;
    }
    points
        .iter()
        .map(|&p| {
            // Rings are counted from the grid cell nearest to p (p itself may lie outside the
            // grid, arbitrarily far): a cell in ring r + 1 is then at least r cells from p on
            // some axis, inside the grid or not.
            let c: [i64; 3] = {
                let raw = cell_of(p);
                core::array::from_fn(|k| raw[k].clamp(0, dims[k] - 1))
            };
            let reach = (0..3)
                .map(|k| c[k].max(dims[k] - 1 - c[k]))
                .max()
                .unwrap_or(0);
            let span = |k: usize, r: i64| (c[k] - r).max(0)..=(c[k] + r).min(dims[k] - 1);
            let mut best = (f32::INFINITY, 0u32);
            for r in 0..=reach {
                for z in span(2, r) {
                    for y in span(1, r) {
                        for x in span(0, r) {
                            let ring = (x - c[0]).abs() == r
                                || (y - c[1]).abs() == r
                                || (z - c[2]).abs() == r;
                            if !ring {
                                continue;
                            }
                            let cell = index([x, y, z]);
                            for &i in &items[start[cell]..start[cell + 1]] {
                                let d = (anchors[i as usize] - p).length_squared();
                                if d < best.0 || (d == best.0 && i < best.1) {
                                    best = (d, i);
                                }
                            }
                        }
                    }
                }
                if libm::sqrtf(best.0) <= r as f32 * cell {
                    break;
                }
            }
            best.1
        })
        .collect()
}

/// Before the softmax: sets the logits of every joint that is not a candidate of its vertex to
/// −∞. `tile` is `[joint][TILE]`; `lists` holds `k` slots per lane (lanes past the mesh hold
/// only [`NO_JOINT`] and are left alone).
pub(crate) fn mask_logits(tile: &mut [f32], joints: usize, lists: &[u16], k: usize) {
    fill_non_candidates(tile, joints, lists, k, f32::NEG_INFINITY);
}

/// After the softmax: the weights of non-candidates are exactly zero (the SIMD exponential
/// clamps its argument, so −∞ came out as ~1e-38).
pub(crate) fn clear_masked(tile: &mut [f32], joints: usize, lists: &[u16], k: usize) {
    fill_non_candidates(tile, joints, lists, k, 0.0);
}

/// Writes `value` at every joint of every lane that is not among the lane's candidates.
fn fill_non_candidates(tile: &mut [f32], joints: usize, lists: &[u16], k: usize, value: f32) {
    for (lane, list) in lists.chunks_exact(k).enumerate().take(TILE) {
        if list[0] == NO_JOINT {
            continue;
        }
        let mut next = 0;
        for j in 0..joints {
            if next < k && list[next] as usize == j {
                next += 1;
            } else {
                tile[j * TILE + lane] = value;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn nearest_anchors_equal_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut v = || {
            Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-2.0..2.0),
                rng.random_range(0.0..0.3),
            )
        };
        let anchors: Vec<Vec3> = (0..300).map(|_| v()).collect();
        let points: Vec<Vec3> = (0..2000).map(|_| v() * 1.3).collect();
        let got = nearest_anchors(&anchors, &points);
        for (p, g) in points.iter().zip(&got) {
            let d = |i: usize| (anchors[i] - *p).length_squared();
            let best = (0..anchors.len())
                .min_by(|&a, &b| d(a).total_cmp(&d(b)))
                .unwrap();
            assert_eq!(d(*g as usize), d(best), "{p}");
        }
        assert!(nearest_anchors(&[], &points).is_empty());
        assert_eq!(
            nearest_anchors(&[Vec3::ONE], &[Vec3::ZERO, Vec3::X]),
            vec![0, 0]
        );
        // Points far outside a degenerate (one-cell) grid end after a single ring.
        assert_eq!(
            nearest_anchors(
                &[Vec3::ONE, Vec3::ONE],
                &[Vec3::splat(-1e6), Vec3::splat(1e6)]
            ),
            vec![0, 0]
        );
    }

    #[test]
    fn masking_keeps_the_candidates_only() {
        let joints = 4;
        let k = 2;
        let mut tile = vec![1.0f32; joints * TILE];
        let mut lists = vec![NO_JOINT; TILE * k];
        lists[0..2].copy_from_slice(&[1, 3]);
        lists[2..4].copy_from_slice(&[0, NO_JOINT]);
        mask_logits(&mut tile, joints, &lists, k);
        let col =
            |t: &[f32], lane: usize| (0..joints).map(|j| t[j * TILE + lane]).collect::<Vec<_>>();
        let ninf = f32::NEG_INFINITY;
        assert_eq!(col(&tile, 0), vec![ninf, 1.0, ninf, 1.0]);
        assert_eq!(col(&tile, 1), vec![1.0, ninf, ninf, ninf]);
        assert_eq!(col(&tile, 2), vec![1.0; 4], "padding lanes are left alone");
        let mut w = vec![0.25f32; joints * TILE];
        clear_masked(&mut w, joints, &lists, k);
        assert_eq!(col(&w, 0), vec![0.0, 0.25, 0.0, 0.25]);
    }
}
