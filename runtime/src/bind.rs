//! Binding a mesh: any resolution, any vertex order. Everything that depends only on the
//! canonical position is computed here, once: the normalised position `x̂`, its positional
//! encoding `γ(x̂)` and the position parts `W_pos · [x̂, γ(x̂)]` of the layers that see the input
//! (layer 0 and the skip layer), stored tile by tile in the kernels' layout so that per frame
//! they cost one add.

use alloc::vec;
use alloc::vec::Vec;

use glam::Vec3;

use crate::error::RuntimeError;
use crate::kernels::TILE;
use crate::model::SkinNet;

/// Largest vertex count a mesh may have.
pub const MAX_BIND_VERTICES: usize = 1 << 24;

/// A mesh bound to one model: rest positions and the per-vertex position parts, tile by tile.
#[derive(Clone, Debug)]
pub struct BoundMesh {
    model_id: u64,
    rest: Vec<Vec3>,
    /// `tiles × pre_rows × TILE`.
    pre: Vec<f32>,
    pre_rows: usize,
    /// With a model that has candidate joints: `tiles × TILE × k` lists (the nearest anchor's
    /// per vertex; lanes past the mesh padded with `NO_JOINT`), and `k`.
    candidates: Option<(Vec<u16>, usize)>,
}

impl BoundMesh {
    /// Binds canonical positions (any count ≥ 1, any order; points outside the file's box are
    /// allowed: the network extrapolates) to `model`.
    pub fn bind<W: AsRef<[f32]>>(
        model: &SkinNet<W>,
        positions: &[Vec3],
    ) -> Result<Self, RuntimeError> {
        let n = positions.len();
        if n == 0 || n > MAX_BIND_VERTICES {
            return Err(RuntimeError::VertexCount(n));
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(RuntimeError::NonFinite {
                field: "positions",
                index: i,
            });
        }
        let layout = model.layout();
        let (pos_w, pre_rows) = (layout.pos_w, layout.pre_rows);
        let tiles = n.div_ceil(TILE);
        let block = pre_rows * TILE;
        let mut pre = vec![0.0; tiles * block];
        let zeros = vec![0.0; layout.max_rows_p];
        let mut pe = vec![0.0; pos_w * TILE];
        for (t, out) in pre.chunks_exact_mut(block).enumerate() {
            pe.fill(0.0);
            for (lane, p) in positions[t * TILE..n.min((t + 1) * TILE)]
                .iter()
                .enumerate()
            {
                // The one encoding the trainer and the GPU upload use too.
                for (f, v) in model.config().position_input(*p).enumerate() {
                    pe[f * TILE + lane] = v;
                }
            }
            model.position_parts(&pe, &zeros, out);
        }
        let candidates = model.anchors().map(|a| {
            let k = a.k();
            let mut lists = a.lists_for(positions);
            lists.resize(
                tiles * TILE * k,
                skinfield_formats::skf::candidates::NO_JOINT,
            );
            (lists, k)
        });
        Ok(Self {
            model_id: model.id(),
            rest: positions.to_vec(),
            pre,
            pre_rows,
            candidates,
        })
    }

    /// The candidate joints of vertex `v` (`k` slots padded with `0xFFFF`), if the model has
    /// candidates.
    #[must_use]
    pub fn candidates(&self, v: usize) -> Option<&[u16]> {
        self.candidates
            .as_ref()
            .and_then(|(l, k)| l.get(v * k..(v + 1) * k))
    }

    /// The candidate lists of tile `t`'s lanes.
    pub(crate) fn tile_candidates(&self, t: usize) -> Option<&[u16]> {
        self.candidates
            .as_ref()
            .map(|(l, k)| &l[t * TILE * k..(t + 1) * TILE * k])
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.rest.len()
    }

    /// Canonical (rest) positions.
    #[must_use]
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest
    }

    pub(crate) fn model_id(&self) -> u64 {
        self.model_id
    }

    /// The bound block of tile `t`.
    pub(crate) fn tile(&self, t: usize) -> &[f32] {
        let block = self.pre_rows * TILE;
        &self.pre[t * block..(t + 1) * block]
    }
}
