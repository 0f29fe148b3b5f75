//! The candidate joints of a run as masks: per training vertex (and per query cell) the joints
//! its weights may use, as an additive `−∞` mask on the logits, so the softmax is exactly zero
//! elsewhere (the runtime applies the same lists at bind time).

use super::*;

/// The candidate joints of a run and the masks they make.
pub(super) struct Candidates {
    /// Per training vertex, its candidate joints (ascending).
    pub(super) lists: Vec<Vec<u16>>,
    /// Additive mask `[V, J]` of the training vertices (0 or −∞).
    pub(super) mask: Tensor,
    /// Additive mask `[N, J]` of the full-resolution query points (their nearest training
    /// vertex's list, the runtime's rule), or a copy of `mask` without query cells.
    pub(super) query_mask: Tensor,
}

impl Candidates {
    /// The candidates of `data`'s training vertices ([`crate::candidates::candidate_sets`] with
    /// `k` joints and neighbour reach `reach`; `None` when `k` is 0), and the initial weights
    /// of `data` — the warm start's target and the regularisers' reference — restricted to
    /// them and renormalised, since weights outside the candidates cannot be represented.
    pub(super) fn new(data: &mut TrainData, k: usize, reach: f32) -> Option<Self> {
        if k == 0 {
            return None;
        }
        let j = data.skeleton.len();
        let lists = crate::candidates::candidate_sets(
            &data.init_weights,
            &data.skeleton,
            &data.template.positions,
            k,
            reach,
        );
        restrict(&mut data.init_weights, j, &lists, |i| i);
        let mask_values = crate::candidates::additive_mask(&lists, j);
        let v = lists.len();
        let mask = Tensor::from_vec(mask_values.clone(), (v, j), &Device::Cpu).ok()?;
        let query_mask = match &mut data.queries {
            Some(q) => {
                let anchor = skinfield_runtime::candidates::nearest_anchors(
                    &data.template.positions,
                    &q.positions,
                );
                restrict(&mut q.init_weights, j, &lists, |i| anchor[i] as usize);
                let rows: Vec<f32> = anchor
                    .iter()
                    .flat_map(|&a| {
                        mask_values[a as usize * j..(a as usize + 1) * j]
                            .iter()
                            .copied()
                    })
                    .collect();
                Tensor::from_vec(rows, (anchor.len(), j), &Device::Cpu).ok()?
            }
            None => mask.clone(),
        };
        Some(Self {
            lists,
            mask,
            query_mask,
        })
    }
}

/// Zeroes each row's weights outside `lists[list_of(row)]` and renormalises the row (a row
/// left with no weight gets its candidates' uniform blend).
pub(super) fn restrict(
    weights: &mut [f32],
    j: usize,
    lists: &[Vec<u16>],
    list_of: impl Fn(usize) -> usize,
) {
    for (i, row) in weights.chunks_mut(j.max(1)).enumerate() {
        let list = &lists[list_of(i)];
        let mut keep = vec![false; j];
        for &c in list {
            keep[c as usize] = true;
        }
        for (w, k) in row.iter_mut().zip(&keep) {
            if !k {
                *w = 0.0;
            }
        }
        let sum: f32 = row.iter().sum();
        if sum > 0.0 {
            row.iter_mut().for_each(|w| *w /= sum);
        } else {
            for &c in list {
                row[c as usize] = 1.0 / list.len() as f32;
            }
        }
    }
}
