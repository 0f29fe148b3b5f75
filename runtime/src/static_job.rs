//! Static skinning: the same job shape with a [`StaticSkin`] (any number of influences per
//! vertex) instead of SkinNet — the runtime as an ordinary LBS/DQS skinning library.

use glam::{Vec3, Vec4};
use skinfield_formats::StaticSkin;

use crate::error::RuntimeError;
use crate::frame::Palette;
use crate::job::VertexOutputs;
use crate::kernels::{Kernel, blend, tiles};
use crate::skinning::{
    Method, dqs, lbs_normal_unnormalised, lbs_point, lbs_tangent_unnormalised, normalise_block,
};

/// Skins `out_positions.len()` vertices from `first_vertex` with static weights.
pub struct StaticSkinJob<'a> {
    /// Sparse weights (vertex count = `rest_positions.len()`).
    pub skin: &'a StaticSkin,
    /// The posed joints (at least `skin.joint_count()` of them).
    pub palette: &'a Palette,
    /// LBS or DQS.
    pub method: Method,
    /// First vertex of the range.
    pub first_vertex: usize,
    /// Rest positions of the whole mesh.
    pub rest_positions: &'a [Vec3],
    /// Rest normals of the whole mesh (required for `out_normals`).
    pub rest_normals: Option<&'a [Vec3]>,
    /// Rest tangents of the whole mesh (required for `out_tangents`).
    pub rest_tangents: Option<&'a [Vec4]>,
    /// Skinned positions of the range.
    pub out_positions: &'a mut [Vec3],
    /// Skinned unit normals of the range.
    pub out_normals: Option<&'a mut [Vec3]>,
    /// Skinned unit tangents of the range.
    pub out_tangents: Option<&'a mut [Vec4]>,
}

impl StaticSkinJob<'_> {
    /// Checks every field; the error names the first one that is wrong.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        let n = self.rest_positions.len();
        if self.skin.vertex_count() != n {
            return Err(RuntimeError::BufferLength {
                field: "rest_positions",
                len: n,
                expected: self.skin.vertex_count(),
            });
        }
        if self.palette.joint_count() < self.skin.joint_count() {
            return Err(RuntimeError::BufferLength {
                field: "palette",
                len: self.palette.joint_count(),
                expected: self.skin.joint_count(),
            });
        }
        if !self.palette.is_ready() {
            return Err(RuntimeError::NoPose);
        }
        let count = self.out_positions.len();
        if self
            .first_vertex
            .checked_add(count)
            .is_none_or(|end| end > n)
        {
            return Err(RuntimeError::Range {
                first: self.first_vertex,
                count,
                vertex_count: n,
            });
        }
        VertexOutputs {
            rest_normals: self.rest_normals,
            out_normals: self.out_normals.as_deref(),
            rest_tangents: self.rest_tangents,
            out_tangents: self.out_tangents.as_deref(),
            out_weights: None,
        }
        .check(n, count, 0)
    }

    /// Validates, then skins the range. Never allocates.
    pub fn run(&mut self) -> Result<(), RuntimeError> {
        self.validate()?;
        let kernel = Kernel::detect();
        // LBS normals and tangents are normalised a block at a time (`lbs_normal_unnormalised`).
        for (start, len) in tiles(self.out_positions.len()) {
            for i in start..start + len {
                self.skin_one(kernel, i);
            }
            if self.method == Method::Lbs {
                normalise_block(
                    self.out_normals.as_deref_mut(),
                    self.out_tangents.as_deref_mut(),
                    start..start + len,
                );
            }
        }
        Ok(())
    }

    /// Skins output `i`; LBS leaves its normal and tangent unnormalised.
    #[inline]
    fn skin_one(&mut self, kernel: Kernel, i: usize) {
        let (mats, dq) = (self.palette.matrices(), self.palette.dual_quats());
        let v = self.first_vertex + i;
        let (joints, weights) = self.skin.influences(v);
        let infl = joints.iter().zip(weights).map(|(&j, &w)| (j as usize, w));
        let p = self.rest_positions[v];
        match self.method {
            Method::Lbs => {
                // Only the requested outputs are computed.
                let mut m = glam::Mat4::ZERO;
                blend(kernel, &mut m, mats, infl);
                self.out_positions[i] = lbs_point(&m, p);
                if let (Some(o), Some(r)) = (self.out_normals.as_deref_mut(), self.rest_normals) {
                    o[i] = lbs_normal_unnormalised(&m, r[v]);
                }
                if let (Some(o), Some(r)) = (self.out_tangents.as_deref_mut(), self.rest_tangents) {
                    o[i] = lbs_tangent_unnormalised(&m, r[v]);
                }
            }
            Method::Dqs => {
                let n = self.rest_normals.map_or(Vec3::Y, |r| r[v]);
                let t = self.rest_tangents.map_or(Vec4::X, |r| r[v]);
                let s = dqs(mats, dq, infl, p, n, t);
                self.out_positions[i] = s.position;
                if let Some(o) = self.out_normals.as_deref_mut() {
                    o[i] = s.normal;
                }
                if let Some(o) = self.out_tangents.as_deref_mut() {
                    o[i] = s.tangent;
                }
            }
        }
    }
}
