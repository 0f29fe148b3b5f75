//! The tracker's silhouette term (DeepCap's silhouette loss, Eq. 8, on the posed template):
//! after the keypoint fit of a frame, the pose is refined so that the outline vertices of the
//! skinned template project onto the masks' outlines.
//!
//! Why it is needed: keypoints place joints, not the twist of a limb about its bone, nor the
//! orientation of a hand or a foot when the detector has one point there. A twisted limb moves
//! its whole surface; SkinNet trained on such poses learns weights that explain the wrong
//! twists (`docs/experiments/tracking.md`). The masks see the surface.
//!
//! - The body is the capture's template simplified to [`BODY_VERTICES`] (a subset of its
//!   vertices, so the initial weights carry over), skinned by linear blend skinning with its four
//!   strongest initial weights per vertex, in f64 like the rest of the tracker.
//! - The residual of one outline vertex in one view is `c·tanh(d/c)`, with `d` the signed
//!   distance (pixels, negative inside) from its projection to the mask's 50 % coverage outline
//!   (the hull's [`HullView`]) and `c` = [`SILHOUETTE_SCALE_PX`]: the plain distance near the
//!   outline, bounded for a vertex matched to the wrong part of the mask (robust, and smooth for
//!   the finite-difference Jacobian).
//! - The outline vertices (true silhouette vertices on the projected outline, the selection the
//!   training loss uses) are chosen at the keypoint fit's pose and kept through the refinement,
//!   at most [`MAX_OUTLINE_VERTICES`] per view, evenly spread.

use glam::{DMat4, DVec3, Vec2, Vec3};
use skinfield_formats::{Skeleton, StaticSkin, Template};

use crate::losses::silhouette::EdgeTable;
use crate::losses::silhouette::edges::{ViewGeometry, mesh_outline};
use crate::template::hull::HullView;
use crate::train::data::simplify_template;

/// Vertices of the tracking body (the template simplified).
pub const BODY_VERTICES: usize = 1500;
/// Outline vertices per view, at most.
pub const MAX_OUTLINE_VERTICES: usize = 96;
/// Scale of the bounded residual `c·tanh(d/c)` (pixels).
pub const SILHOUETTE_SCALE_PX: f64 = 8.0;
/// Influences per vertex.
const INFLUENCES: usize = 4;

/// Weights that do not fit the template and skeleton of a [`TrackingBody`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "the silhouette term's body weights cover {vertices} vertices and {joints} joints, the \
     template has {template_vertices} vertices and the skeleton {skeleton_joints} joints"
)]
pub struct BodySkinMismatch {
    /// Vertices the weights cover.
    pub vertices: usize,
    /// Joints the weights cover.
    pub joints: usize,
    /// Template vertices.
    pub template_vertices: usize,
    /// Skeleton joints.
    pub skeleton_joints: usize,
}

/// The skinned template the silhouette term poses.
#[derive(Clone, Debug)]
pub struct TrackingBody {
    rest: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    table: EdgeTable,
    influences: Vec<[(usize, f64); INFLUENCES]>,
    inverse_bind: Vec<DMat4>,
}

impl TrackingBody {
    /// The body of `template` bound to `skeleton` with `skin` (one row per template vertex,
    /// one column per joint; anything else is refused).
    pub fn new(
        template: &Template,
        skin: &StaticSkin,
        skeleton: &Skeleton,
    ) -> Result<Self, BodySkinMismatch> {
        if skin.vertex_count() != template.vertex_count() || skin.joint_count() != skeleton.len() {
            return Err(BodySkinMismatch {
                vertices: skin.vertex_count(),
                joints: skin.joint_count(),
                template_vertices: template.vertex_count(),
                skeleton_joints: skeleton.len(),
            });
        }
        let (body, source) = simplify_template(template, BODY_VERTICES);
        let (offsets, joints, weights) = (skin.offsets(), skin.joints(), skin.weights());
        let influences = source
            .iter()
            .map(|&v| {
                let range = offsets[v as usize] as usize..offsets[v as usize + 1] as usize;
                let mut row: Vec<(usize, f64)> = range
                    .map(|k| (joints[k] as usize, f64::from(weights[k])))
                    .collect();
                row.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                row.truncate(INFLUENCES);
                let total: f64 = row.iter().map(|r| r.1).sum();
                let mut out = [(0, 0.0); INFLUENCES];
                for (o, r) in out.iter_mut().zip(&row) {
                    *o = (r.0, if total > 0.0 { r.1 / total } else { 0.0 });
                }
                out
            })
            .collect();
        Ok(Self {
            rest: body.positions.iter().map(|p| p.as_dvec3()).collect(),
            table: EdgeTable::new(body.vertex_count(), &body.triangles),
            triangles: body.triangles,
            influences,
            inverse_bind: skeleton
                .inverse_bind()
                .iter()
                .map(|m| m.as_dmat4())
                .collect(),
        })
    }

    /// Vertex count.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.rest.len()
    }

    /// Poses the body with the joints' world matrices `worlds` (root translation zero, as
    /// [`super::Kinematics::world_matrices`] gives them) and the world shift `shift`.
    pub fn pose(&self, worlds: &[DMat4], shift: DVec3, out: &mut Vec<DVec3>) {
        let mut skinning = Vec::with_capacity(worlds.len());
        self.skinning_matrices(worlds, &mut skinning);
        out.clear();
        out.extend((0..self.rest.len()).map(|v| self.skin_vertex(v, &skinning) + shift));
    }

    /// Each joint's inverse bind matrix.
    pub(super) fn inverse_bind(&self) -> &[DMat4] {
        &self.inverse_bind
    }

    /// Each joint's skinning matrix (world times inverse bind) for `worlds`, into `out`.
    pub(super) fn skinning_matrices(&self, worlds: &[DMat4], out: &mut Vec<DMat4>) {
        out.clear();
        out.extend(worlds.iter().zip(&self.inverse_bind).map(|(w, b)| *w * *b));
    }

    /// Vertex `v` skinned by `skinning` (no shift). The map is linear in the matrices, so the
    /// derivatives of the skinning matrices give the vertex's derivative.
    pub(super) fn skin_vertex(&self, v: usize, skinning: &[DMat4]) -> DVec3 {
        let x = self.rest[v];
        let mut p = DVec3::ZERO;
        for &(j, w) in &self.influences[v] {
            if w > 0.0 {
                p += w * skinning[j].transform_point3(x);
            }
        }
        p
    }

    /// The outline vertices of the posed body in every view (at most
    /// [`MAX_OUTLINE_VERTICES`] each, evenly spread over the sorted list).
    #[must_use]
    pub fn outline_vertices(&self, views: &[HullView], posed: &[DVec3]) -> Vec<Vec<u32>> {
        let posed: Vec<Vec3> = posed.iter().map(|p| p.as_vec3()).collect();
        views
            .iter()
            .map(|v| {
                let geometry = ViewGeometry::new(&v.camera, &posed);
                let all = mesh_outline(&v.camera, &posed, &self.triangles, &self.table, &geometry)
                    .vertices;
                let n = all.len();
                if n <= MAX_OUTLINE_VERTICES {
                    return all;
                }
                (0..MAX_OUTLINE_VERTICES)
                    .map(|i| all[i * n / MAX_OUTLINE_VERTICES])
                    .collect()
            })
            .collect()
    }
}

/// The bounded silhouette residual (pixels) of a posed vertex `x` in `view`.
#[must_use]
pub fn outline_residual(view: &HullView, x: DVec3) -> f64 {
    let Some(p) = view.camera.project_f64(x) else {
        return SILHOUETTE_SCALE_PX;
    };
    let d = f64::from(view.signed_pixels(Vec2::new(p.x as f32, p.y as f32)));
    SILHOUETTE_SCALE_PX * (d / SILHOUETTE_SCALE_PX).tanh()
}

/// The gradient of [`outline_residual`] with respect to `x` (zero behind the camera, where
/// the residual is constant).
#[must_use]
pub fn outline_residual_gradient(view: &HullView, x: DVec3) -> DVec3 {
    let Some(p) = view.camera.project_f64(x) else {
        return DVec3::ZERO;
    };
    let (d, g) = view.signed_pixels_with_gradient(Vec2::new(p.x as f32, p.y as f32));
    let th = (f64::from(d) / SILHOUETTE_SCALE_PX).tanh();
    let g = g.as_dvec2() * (1.0 - th * th);
    let j = projection_jacobian(&view.camera, x);
    DVec3::new(g.dot(j[0]), g.dot(j[1]), g.dot(j[2]))
}

/// The derivative of `camera.project_f64` at `x` with respect to each world coordinate (one
/// pixel-space column per axis), by central differences in f64 (the lens distortion has no
/// closed-form derivative here); zero columns where a side of the difference is behind the
/// camera.
#[must_use]
pub fn projection_jacobian(camera: &skinfield_formats::Camera, x: DVec3) -> [glam::DVec2; 3] {
    let h = 1e-6 * x.length().max(1.0);
    let mut out = [glam::DVec2::ZERO; 3];
    for (k, col) in out.iter_mut().enumerate() {
        let mut e = DVec3::ZERO;
        e[k] = h;
        if let (Some(a), Some(b)) = (camera.project_f64(x + e), camera.project_f64(x - e)) {
            *col = (a - b) / (2.0 * h);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use glam::DQuat;

    use super::*;
    use crate::track::Kinematics;

    #[test]
    fn the_body_in_the_bind_pose_is_its_rest_shape_and_moves_with_the_shift() {
        let dir = tempfile::tempdir().unwrap();
        crate::synth::synthesize(dir.path(), &crate::synth::SynthConfig::tiny()).unwrap();
        let capture = skinfield_formats::capture::load_capture(dir.path()).unwrap();
        let skin = crate::train::data::initial_weights(&capture).unwrap();
        let body = TrackingBody::new(&capture.template, &skin, &capture.skeleton).unwrap();
        assert!((1000..=BODY_VERTICES).contains(&body.vertex_count()));
        let kinematics = Kinematics::new(&capture.skeleton);
        let mut worlds = vec![DMat4::IDENTITY; capture.skeleton.len()];
        let angles = vec![0.0; kinematics.angle_count()];
        kinematics.world_matrices(DQuat::IDENTITY, &angles, &mut worlds);
        let shift = DVec3::new(0.1, -0.2, 0.3);
        let mut posed = Vec::new();
        body.pose(&worlds, shift, &mut posed);
        for (p, r) in posed.iter().zip(&body.rest) {
            assert!((*p - shift - *r).length() < 1e-5, "{p} vs {r}");
        }
        // Every outline vertex of a view lies on the rendered outline of the body in that view
        // (the capture's first camera at 4 × its 40² pixels, so that gaps between the limbs
        // and the body are resolved).
        let mut camera = capture.rig.cameras[0].clone();
        (camera.width, camera.height) = (160, 160);
        for f in [
            &mut camera.fx,
            &mut camera.fy,
            &mut camera.cx,
            &mut camera.cy,
        ] {
            *f *= 4.0;
        }
        let rest: Vec<Vec3> = body.rest.iter().map(|p| p.as_vec3()).collect();
        let mask = crate::raster::coverage(&camera, &rest, &body.triangles, 4);
        let view = HullView::new(camera, mask).unwrap();
        let outline = body.outline_vertices(std::slice::from_ref(&view), &body.rest);
        // The traced 50 % outline cuts the corners of the projected polygon, whose corners the
        // outline vertices are: within a pixel, a quarter on average.
        assert!(!outline[0].is_empty());
        let distances: Vec<f64> = outline[0]
            .iter()
            .map(|&v| outline_residual(&view, body.rest[v as usize]).abs())
            .collect();
        let mean = distances.iter().sum::<f64>() / distances.len() as f64;
        assert!(
            distances.iter().all(|d| *d < 1.0) && mean < 0.25,
            "{distances:?}"
        );
    }
}
