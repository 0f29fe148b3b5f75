//! The ground-truth deformer of the built-in character, independent of SkinNet. It contains
//! what static linear blend skinning cannot represent, so no single set of static weights fits
//! it:
//!
//! 1. **Dual-quaternion skinning** (Kavan et al. 2007) with the true weights: twisted forearms
//!    and bent knees keep their volume instead of collapsing (no candy wrapper). Blending uses
//!    the hemisphere of the vertex's strongest influence.
//! 2. **Bulge at flexed elbows and knees**: skin vertices move along their posed normal by
//!    `BULGE_PER_RADIAN · φ · exp(−(|x̄ − c|/BULGE_RADIUS)²) · m`, with `φ` the joint's flexion
//!    angle, `c` its bind position, `x̄` the vertex's bind position and `m` the vertex's total
//!    weight on the joint, its parent and its children (so the bulge stays on the limb).
//! 3. **Skirt pushed out by the legs**: each skirt vertex inside a posed leg capsule (thigh and
//!    shin round cones with a clearance [`SKIRT_CLEARANCE`]) is moved radially onto its surface;
//!    the push-out displacement is then smoothed over the skirt's mesh neighbours (three Jacobi
//!    steps, so the cloth does not crease) and the projection applied once more (so it never
//!    ends inside a leg).
//!
//! Normals of the result are recomputed from the deformed triangles.

use glam::{Mat4, Quat, Vec3, Vec4};
use skinfield_formats::math::quat_to_rotvec;
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_formats::{Pose, Skeleton, SkeletonError, StaticSkin};

use super::body::Part;
use super::character::{bind_positions, joint, segment_distance};

/// Bulge amplitude per radian of flexion at the joint centre (metres).
pub const BULGE_PER_RADIAN: f32 = 0.012;
/// Gaussian radius of the bulge around the joint (metres).
pub const BULGE_RADIUS: f32 = 0.07;
/// Space kept between a leg's surface and the skirt (metres).
pub const SKIRT_CLEARANCE: f32 = 0.02;

/// Which parts of the deformer to apply (all of them for the ground truth; tests switch them
/// off to measure each one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeformParts {
    /// Apply the flexion bulge.
    pub bulge: bool,
    /// Apply the skirt push-out.
    pub skirt: bool,
}

impl DeformParts {
    /// Everything: the ground truth.
    pub const ALL: Self = Self {
        bulge: true,
        skirt: true,
    };
    /// Dual-quaternion skinning only.
    pub const DQS_ONLY: Self = Self {
        bulge: false,
        skirt: false,
    };
}

/// A leg capsule of the push-out: joint at each end and the body radius there.
const LEG_CAPSULES: [(usize, usize, f32, f32); 4] = [
    (joint::L_HIP, joint::L_KNEE, 0.078, 0.054),
    (joint::L_KNEE, joint::L_ANKLE, 0.052, 0.037),
    (joint::R_HIP, joint::R_KNEE, 0.078, 0.054),
    (joint::R_KNEE, joint::R_ANKLE, 0.052, 0.037),
];
const BULGE_JOINTS: [usize; 4] = [joint::L_ELBOW, joint::R_ELBOW, joint::L_KNEE, joint::R_KNEE];

/// The ground-truth deformer for one character.
#[derive(Clone, Debug)]
pub struct GroundTruthDeformer {
    skeleton: Skeleton,
    skin: StaticSkin,
    rest: Vec<Vec3>,
    rest_normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    parts: Vec<Part>,
    /// Skirt vertices and their skirt neighbours (CSR), for the displacement smoothing.
    skirt: Vec<u32>,
    skirt_offsets: Vec<u32>,
    skirt_neighbours: Vec<u32>,
    /// Joints that bulge when flexed.
    bulge_joints: Vec<usize>,
    /// Leg capsules the skirt is pushed out of: end joints and body radii there.
    leg_capsules: Vec<(usize, usize, f32, f32)>,
    /// Scale of the bulge's amplitude and radius (1 for a 1.75 m character in metres).
    bulge_scale: f32,
    /// Vertices of hard parts that move rigidly with their joint and never bulge (empty: none).
    rigid: Vec<bool>,
}

/// Dual quaternion `(real, dual)` of a skinning matrix, which DQS takes as rigid: any scale
/// (none for the built-in character) is dropped.
fn dual_quat(m: &Mat4) -> (Vec4, Vec4) {
    let (_, r, t) = m.to_scale_rotation_translation();
    let r = r.normalize();
    let rv = Vec4::from(r);
    // dual = ½ (t, 0) · r
    let d = qmul(Vec4::new(t.x, t.y, t.z, 0.0), rv) * 0.5;
    (rv, d)
}

/// Quaternion product on `(x, y, z, w)` vectors (no unit-length assumption).
fn qmul(a: Vec4, b: Vec4) -> Vec4 {
    let (av, bv) = (a.truncate(), b.truncate());
    let v = a.w * bv + b.w * av + av.cross(bv);
    Vec4::new(v.x, v.y, v.z, a.w * b.w - av.dot(bv))
}

fn qconj(a: Vec4) -> Vec4 {
    Vec4::new(-a.x, -a.y, -a.z, a.w)
}

/// Per-joint skinning matrices of a pose.
fn skinning_matrices(skeleton: &Skeleton, pose: &Pose) -> Result<Vec<Mat4>, SkeletonError> {
    let mut m = vec![Mat4::IDENTITY; skeleton.len()];
    skeleton.skinning_matrices(pose, &mut m)?;
    Ok(m)
}

/// Dual-quaternion skinning of positions and normals.
pub fn dqs(
    skeleton: &Skeleton,
    skin: &StaticSkin,
    positions: &[Vec3],
    normals: &[Vec3],
    pose: &Pose,
) -> Result<(Vec<Vec3>, Vec<Vec3>), SkeletonError> {
    let dq: Vec<(Vec4, Vec4)> = skinning_matrices(skeleton, pose)?
        .iter()
        .map(dual_quat)
        .collect();
    let mut out_p = Vec::with_capacity(positions.len());
    let mut out_n = Vec::with_capacity(positions.len());
    for (v, (&p, &n)) in positions.iter().zip(normals).enumerate() {
        let (js, ws) = skin.influences(v);
        let pivot = js
            .iter()
            .zip(ws)
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0, |(&j, _)| j as usize);
        let (mut br, mut bd) = (Vec4::ZERO, Vec4::ZERO);
        for (&j, &w) in js.iter().zip(ws) {
            let (r, d) = dq[j as usize];
            let s = if r.dot(dq[pivot].0) < 0.0 { -w } else { w };
            br += r * s;
            bd += d * s;
        }
        let len = br.length().max(1e-12);
        let (r, d) = (br / len, bd / len);
        let rot = Quat::from_vec4(r);
        let t = qmul(d, qconj(r)).truncate() * 2.0;
        out_p.push(rot * p + t);
        out_n.push((rot * n).normalize_or(Vec3::Y));
    }
    Ok((out_p, out_n))
}

/// Linear blend skinning of positions (for comparisons with [`dqs`]).
pub fn lbs(
    skeleton: &Skeleton,
    skin: &StaticSkin,
    positions: &[Vec3],
    pose: &Pose,
) -> Result<Vec<Vec3>, SkeletonError> {
    let m = skinning_matrices(skeleton, pose)?;
    Ok(positions
        .iter()
        .enumerate()
        .map(|(v, &p)| {
            let (js, ws) = skin.influences(v);
            js.iter()
                .zip(ws)
                .map(|(&j, &w)| m[j as usize].transform_point3(p) * w)
                .sum()
        })
        .collect())
}

impl GroundTruthDeformer {
    /// A deformer for a template (`positions`, `normals`, `triangles` in the bind pose) with
    /// its true weights and fine parts.
    #[must_use]
    pub fn new(
        skeleton: Skeleton,
        skin: StaticSkin,
        rest: Vec<Vec3>,
        rest_normals: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        parts: Vec<Part>,
    ) -> Self {
        let skirt: Vec<u32> = (0..rest.len() as u32)
            .filter(|&v| parts[v as usize] == Part::Skirt)
            .collect();
        let mut local = vec![u32::MAX; rest.len()];
        for (k, &v) in skirt.iter().enumerate() {
            local[v as usize] = k as u32;
        }
        let mut adj: Vec<Vec<u32>> = vec![Vec::new(); skirt.len()];
        for t in &triangles {
            for k in 0..3 {
                let (a, b) = (local[t[k] as usize], local[t[(k + 1) % 3] as usize]);
                if a != u32::MAX && b != u32::MAX {
                    adj[a as usize].push(b);
                    adj[b as usize].push(a);
                }
            }
        }
        let mut skirt_offsets = vec![0u32];
        let mut skirt_neighbours = Vec::new();
        for mut a in adj {
            a.sort_unstable();
            a.dedup();
            skirt_neighbours.extend(a);
            skirt_offsets.push(skirt_neighbours.len() as u32);
        }
        Self {
            skeleton,
            skin,
            rest,
            rest_normals,
            triangles,
            parts,
            skirt,
            skirt_offsets,
            skirt_neighbours,
            bulge_joints: BULGE_JOINTS.to_vec(),
            leg_capsules: LEG_CAPSULES.to_vec(),
            bulge_scale: 1.0,
            rigid: Vec::new(),
        }
    }

    /// Replaces the built-in character's bulging joints and leg capsules (for another
    /// skeleton): `bulge_joints` flex-bulge, `leg_capsules` are `(joint, end joint, radius at
    /// joint, radius at end)` the skirt is pushed out of.
    #[must_use]
    pub fn with_rig(
        mut self,
        bulge_joints: Vec<usize>,
        leg_capsules: Vec<(usize, usize, f32, f32)>,
    ) -> Self {
        self.bulge_joints = bulge_joints;
        self.leg_capsules = leg_capsules;
        self
    }

    /// Scales the bulge's amplitude and radius (for a character of another size or unit).
    #[must_use]
    pub fn with_bulge_scale(mut self, scale: f32) -> Self {
        self.bulge_scale = scale;
        self
    }

    /// Marks hard vertices: `rigid[v]` for vertex `v` (vertices past the mask's end are soft).
    /// Hard vertices never bulge. A glTF mesh node parented to a joint is a rigid part (a
    /// robot's metal elbow ball): soft-tissue bulge on it would be a swelling no real capture
    /// shows, and a deformation no skinning of a rigid part should have to learn.
    #[must_use]
    pub fn with_rigid_vertices(mut self, rigid: Vec<bool>) -> Self {
        self.rigid = rigid;
        self
    }

    /// The true static weights.
    #[must_use]
    pub fn skin(&self) -> &StaticSkin {
        &self.skin
    }

    /// The ground-truth posed positions and normals of `pose`.
    pub fn deform(&self, pose: &Pose) -> Result<(Vec<Vec3>, Vec<Vec3>), SkeletonError> {
        self.deform_with(pose, DeformParts::ALL)
    }

    /// Like [`GroundTruthDeformer::deform`] with a choice of stages.
    pub fn deform_with(
        &self,
        pose: &Pose,
        parts: DeformParts,
    ) -> Result<(Vec<Vec3>, Vec<Vec3>), SkeletonError> {
        let (mut p, n) = dqs(
            &self.skeleton,
            &self.skin,
            &self.rest,
            &self.rest_normals,
            pose,
        )?;
        let mut world = vec![Mat4::IDENTITY; self.skeleton.len()];
        self.skeleton.world_matrices(pose, &mut world)?;
        if parts.bulge {
            self.bulge(pose, &n, &mut p);
        }
        if parts.skirt {
            self.push_skirt(&world, &n, &mut p);
        }
        let normals = area_weighted_normals(&p, &self.triangles);
        Ok((p, normals))
    }

    fn bulge(&self, pose: &Pose, normals: &[Vec3], p: &mut [Vec3]) {
        let centres = bind_positions(&self.skeleton);
        for &j in &self.bulge_joints {
            let rel = self.skeleton.bind_local()[j].rotation.inverse() * pose.locals[j].rotation;
            let phi = quat_to_rotvec(rel.normalize()).length();
            if phi < 1e-4 {
                continue;
            }
            let parent = self.skeleton.parents()[j];
            let children: Vec<usize> = self.skeleton.children(j).collect();
            for (v, pos) in p.iter_mut().enumerate() {
                if matches!(self.parts[v], Part::Skirt | Part::Sleeve)
                    || self.rigid.get(v).copied().unwrap_or(false)
                {
                    continue;
                }
                let r = (self.rest[v] - centres[j]).length() / (BULGE_RADIUS * self.bulge_scale);
                if r > 3.0 {
                    continue;
                }
                let (js, ws) = self.skin.influences(v);
                let m: f32 = js
                    .iter()
                    .zip(ws)
                    .filter(|(jj, _)| {
                        let jj = **jj as usize;
                        jj == j || Some(jj) == parent || children.contains(&jj)
                    })
                    .map(|(_, w)| w)
                    .sum();
                *pos +=
                    normals[v] * (BULGE_PER_RADIAN * self.bulge_scale * phi * (-r * r).exp() * m);
            }
        }
    }

    fn push_skirt(&self, world: &[Mat4], normals: &[Vec3], p: &mut [Vec3]) {
        if self.skirt.is_empty() || self.leg_capsules.is_empty() {
            return;
        }
        let capsules: Vec<(Vec3, Vec3, f32, f32)> = self
            .leg_capsules
            .iter()
            .map(|&(a, b, ra, rb)| {
                (
                    world[a].w_axis.truncate(),
                    world[b].w_axis.truncate(),
                    ra + SKIRT_CLEARANCE,
                    rb + SKIRT_CLEARANCE,
                )
            })
            .collect();
        let project = |q: Vec3, n: Vec3| -> Vec3 {
            let mut q = q;
            for _ in 0..2 {
                for &(a, b, ra, rb) in &capsules {
                    let (d, t) = segment_distance(q, a, b);
                    let r = ra + (rb - ra) * t;
                    if d < r {
                        let axis = a + (b - a) * t;
                        let dir = (q - axis).try_normalize().unwrap_or(n);
                        q = axis + dir * r;
                    }
                }
            }
            q
        };
        let base: Vec<Vec3> = self.skirt.iter().map(|&v| p[v as usize]).collect();
        let mut delta: Vec<Vec3> = self
            .skirt
            .iter()
            .zip(&base)
            .map(|(&v, &b)| project(b, normals[v as usize]) - b)
            .collect();
        for _ in 0..3 {
            let prev = delta.clone();
            for (k, d) in delta.iter_mut().enumerate() {
                let nb = &self.skirt_neighbours
                    [self.skirt_offsets[k] as usize..self.skirt_offsets[k + 1] as usize];
                if nb.is_empty() {
                    continue;
                }
                let mean = nb.iter().map(|&o| prev[o as usize]).sum::<Vec3>() / nb.len() as f32;
                *d = 0.5 * prev[k] + 0.5 * mean;
            }
        }
        for (k, &v) in self.skirt.iter().enumerate() {
            p[v as usize] = project(base[k] + delta[k], normals[v as usize]);
        }
    }
}
