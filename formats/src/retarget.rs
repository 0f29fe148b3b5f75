//! Motion retargeting between two skeletons whose joints differ in names, proportions, rest
//! pose and orientation: a pose of the *source* skeleton (the one a clip was authored for)
//! becomes a pose of the *target* skeleton that points every mapped bone the same way.
//!
//! The method is the usual bone-direction transfer of engine retargeters, in world space:
//!
//! 1. **Frames.** The two characters may face different ways or be modelled in different units.
//!    A similarity `(G, s)` aligns them: `G` is the rotation that best maps the source's mapped
//!    joints (rest positions, centred) onto the target's (Horn's closed form, a 4 × 4 symmetric
//!    eigenproblem solved by Jacobi sweeps), `s` the ratio of the mapped bones' summed lengths
//!    (insensitive to the rest poses differing, unlike a ratio of spreads).
//! 2. **Rest poses.** A target joint whose bone runs to exactly one mapped joint (its *aim*: the
//!    nearest mapped descendants, through unmapped joints) gets the smallest rotation `A_t` that
//!    turns its rest bone onto the direction of the corresponding source bone (`G`-rotated); so a
//!    T-posed motion drives an A-posed character correctly. Branching joints (pelvis, chest) and
//!    chain ends take `A_t = 1`.
//! 3. **Per frame.** Each mapped source joint's world rotation relative to its rest,
//!    `Δ_s = R_s · R̄_s⁻¹`, carried into the target's frame, gives the target joint's world
//!    rotation `R_t = (G Δ_s G⁻¹) · A_t · R̄_t`. Unmapped target joints keep their rest local
//!    rotation (they follow their parent). Every local translation keeps the target's rest bone
//!    lengths, except the mapped joints without a mapped ancestor (the hips), whose world
//!    position moves by the source's displacement from rest, rotated by `G` and scaled by `s`
//!    ([`Retarget::in_place`] keeps only its vertical part).
//!
//! The rest of each skeleton is its bind pose ([`Skeleton::bind_local`]: the pose its mesh was
//! modelled in). World rotations come from the decomposed world matrices, which is exact only
//! for uniform scales: a joint whose world scale differs between its axes (by more than
//! [`SCALE_TOLERANCE`], or mirrors one of them) in either rest pose, or in a source pose, is
//! refused with [`RetargetError::NonUniformScale`] rather than retargeted wrong. Retargeting is
//! an import-time step (it allocates per call); an engine that plays retargeted clips bakes them
//! once.

use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;

use glam::{Mat4, Quat, Vec3};

use crate::pose::Pose;
use crate::skeleton::{Skeleton, SkeletonError};

/// Why a retargeting cannot be set up or applied.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RetargetError {
    /// The joint map pairs no joints.
    #[error("the joint map is empty")]
    EmptyMap,
    /// A name in the map is not a joint of the source skeleton.
    #[error("source joint `{0}` of the joint map is not in the source skeleton")]
    UnknownSourceJoint(String),
    /// A name in the map is not a joint of the target skeleton.
    #[error("target joint `{0}` of the joint map is not in the target skeleton")]
    UnknownTargetJoint(String),
    /// A target joint is mapped twice.
    #[error("target joint `{0}` is mapped more than once")]
    DuplicateTargetJoint(String),
    /// A source pose does not fit the source skeleton (wrong joint count, non-finite values).
    #[error("source pose: {0}")]
    SourcePose(SkeletonError),
    /// The retargeted pose is not finite (a degenerate world matrix on the way).
    #[error("the retargeted pose of target joint `{0}` is not finite")]
    NonFinite(String),
    /// A joint's world matrix scales its axes unequally (or mirrors one), so no rotation
    /// describes its orientation: in the target's rest pose, the source's, or a source pose.
    #[error(
        "{skeleton} joint `{joint}` has the world scale ({}, {}, {}) in {}; retargeting needs \
         uniform scales",
        scale[0], scale[1], scale[2],
        if *posed { "a pose to retarget" } else { "its rest pose" }
    )]
    NonUniformScale {
        /// `"source"` or `"target"`.
        skeleton: &'static str,
        /// The joint's name.
        joint: String,
        /// Its world scale along its three axes (a negative one: mirrored).
        scale: [f32; 3],
        /// Whether it is a source pose given to [`Retarget::apply`] (otherwise a rest pose).
        posed: bool,
    },
}

/// Largest relative difference between a joint's three world scales that counts as uniform.
pub const SCALE_TOLERANCE: f32 = 1e-3;

/// `Err` naming `joint` of `skeleton` if its world `scale` (from the decomposed world matrix)
/// differs between the axes or mirrors one.
fn check_uniform(
    scale: Vec3,
    skeleton: &Skeleton,
    which: &'static str,
    joint: usize,
    posed: bool,
) -> Result<(), RetargetError> {
    let largest = scale.abs().max_element();
    if (scale.max_element() - scale.min_element()) <= SCALE_TOLERANCE * largest {
        return Ok(());
    }
    Err(RetargetError::NonUniformScale {
        skeleton: which,
        joint: skeleton.names()[joint].clone(),
        scale: scale.to_array(),
        posed,
    })
}

/// A set-up retargeting from one skeleton to another; [`Retarget::apply`] converts poses.
#[derive(Clone, Debug)]
pub struct Retarget {
    source: Skeleton,
    target: Skeleton,
    /// Per target joint, its source joint.
    source_of: Vec<Option<usize>>,
    /// Per target joint, whether it moves its world position with the source (a mapped joint
    /// with no mapped ancestor).
    translates: Vec<bool>,
    /// The rest world rotation of every source joint, inverted.
    source_rest_inverse: Vec<Quat>,
    /// The rest world position of every source joint.
    source_rest_position: Vec<Vec3>,
    /// Per target joint, `A_t · R̄_t` (the rest world rotation turned onto the source's bone).
    target_aligned_rest: Vec<Quat>,
    /// The rest world position of every target joint.
    target_rest_position: Vec<Vec3>,
    /// `G`, source frame to target frame.
    frame: Quat,
    /// `s`, source lengths to target lengths.
    scale: f32,
    /// With [`Retarget::in_place`], the unit up axis of the target's world: the hips' travel
    /// across it is dropped.
    in_place_up: Option<Vec3>,
}

impl Retarget {
    /// Sets up the retargeting of poses of `source` onto `target`; `map` pairs a target joint
    /// name with a source joint name. Every name must exist; a target joint is mapped at most
    /// once (a source joint may drive several).
    pub fn new(
        source: &Skeleton,
        target: &Skeleton,
        map: &[(String, String)],
    ) -> Result<Self, RetargetError> {
        if map.is_empty() {
            return Err(RetargetError::EmptyMap);
        }
        let mut source_of = vec![None; target.len()];
        for (t_name, s_name) in map {
            let t = target
                .find(t_name)
                .ok_or_else(|| RetargetError::UnknownTargetJoint(t_name.clone()))?;
            let s = source
                .find(s_name)
                .ok_or_else(|| RetargetError::UnknownSourceJoint(s_name.clone()))?;
            if source_of[t].replace(s).is_some() {
                return Err(RetargetError::DuplicateTargetJoint(t_name.clone()));
            }
        }
        // The source's unmapped joints drive nothing; every target joint's rotation is used
        // (as the parent of the next).
        let mut driving = vec![false; source.len()];
        for &s in source_of.iter().flatten() {
            driving[s] = true;
        }
        let (source_rest_rotation, source_rest_position) =
            world_rest(source, "source", |s| driving[s])?;
        let (target_rest_rotation, target_rest_position) = world_rest(target, "target", |_| true)?;
        let translates: Vec<bool> = (0..target.len())
            .map(|t| {
                source_of[t].is_some() && !ancestors(target, t).any(|a| source_of[a].is_some())
            })
            .collect();
        // Per target joint with an aim: its rest bone and the corresponding source bone.
        let bones: Vec<Option<(Vec3, Vec3)>> = (0..target.len())
            .map(|t| {
                let s = source_of[t]?;
                let a = aim(target, &source_of, t)?;
                let sa = source_of[a]?;
                Some((
                    target_rest_position[a] - target_rest_position[t],
                    source_rest_position[sa] - source_rest_position[s],
                ))
            })
            .collect();
        let pairs: Vec<(Vec3, Vec3)> = source_of
            .iter()
            .enumerate()
            .filter_map(|(t, s)| s.map(|s| (source_rest_position[s], target_rest_position[t])))
            .collect();
        let frame = best_rotation(&pairs);
        let (target_length, source_length) = bones
            .iter()
            .flatten()
            .fold((0.0f32, 0.0f32), |(t, s), (bt, bs)| {
                (t + bt.length(), s + bs.length())
            });
        let scale = if source_length > 0.0 && target_length > 0.0 {
            target_length / source_length
        } else {
            1.0
        };
        let target_aligned_rest = bones
            .iter()
            .zip(&target_rest_rotation)
            .map(|(bone, &rest)| {
                let align = bone
                    .and_then(|(from, to)| {
                        Some(Quat::from_rotation_arc(
                            from.try_normalize()?,
                            (frame * to).try_normalize()?,
                        ))
                    })
                    .unwrap_or(Quat::IDENTITY);
                (align * rest).normalize()
            })
            .collect();
        Ok(Self {
            source: source.clone(),
            target: target.clone(),
            source_of,
            translates,
            source_rest_inverse: source_rest_rotation.iter().map(|q| q.inverse()).collect(),
            source_rest_position,
            target_aligned_rest,
            target_rest_position,
            frame,
            scale,
            in_place_up: None,
        })
    }

    /// The same retargeting "in place": the hips keep the source's vertical motion (along `up`,
    /// in the target's world frame) but not its travel across the floor, so a walk stays on
    /// the spot, as a capture volume or a game's root-motion split wants. `up` of zero length
    /// leaves the travel in.
    #[must_use]
    pub fn in_place(mut self, up: Vec3) -> Self {
        self.in_place_up = up.try_normalize();
        self
    }

    /// The rotation `G` from the source's frame to the target's.
    #[must_use]
    pub fn frame(&self) -> Quat {
        self.frame
    }

    /// The factor `s` from source lengths to target lengths.
    #[must_use]
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The source joint driving each target joint (`None`: unmapped, keeps its rest rotation).
    #[must_use]
    pub fn source_of(&self) -> &[Option<usize>] {
        &self.source_of
    }

    /// The target skeleton's pose for a pose of the source skeleton.
    pub fn apply(&self, source_pose: &Pose) -> Result<Pose, RetargetError> {
        let mut source_world = vec![Mat4::IDENTITY; self.source.len()];
        self.source
            .world_matrices(source_pose, &mut source_world)
            .map_err(RetargetError::SourcePose)?;
        let bind = self.target.bind_local();
        let mut locals = bind.to_vec();
        let mut world = vec![Mat4::IDENTITY; self.target.len()];
        for t in 0..self.target.len() {
            let parent = match self.target.parents()[t] {
                Some(p) => world[p],
                None => self.target.base(),
            };
            if let Some(s) = self.source_of[t] {
                let (scale, rotation, position) = source_world[s].to_scale_rotation_translation();
                check_uniform(scale, &self.source, "source", s, true)?;
                let delta = rotation * self.source_rest_inverse[s];
                let wanted =
                    (self.frame * delta * self.frame.inverse()) * self.target_aligned_rest[t];
                let (_, parent_rotation, _) = parent.to_scale_rotation_translation();
                locals[t].rotation = (parent_rotation.inverse() * wanted).normalize();
                if self.translates[t] {
                    let mut travel =
                        self.frame * (position - self.source_rest_position[s]) * self.scale;
                    if let Some(up) = self.in_place_up {
                        travel = up * travel.dot(up);
                    }
                    let moved = self.target_rest_position[t] + travel;
                    locals[t].translation = parent.inverse().transform_point3(moved);
                }
            }
            if !locals[t].is_finite() {
                return Err(RetargetError::NonFinite(self.target.names()[t].clone()));
            }
            world[t] = parent * locals[t].to_mat4();
        }
        Ok(Pose { locals })
    }
}

/// World rotations and positions of a skeleton's bind pose (`which` names it in errors); the
/// joints `checked` selects must have uniform world scales.
fn world_rest(
    skeleton: &Skeleton,
    which: &'static str,
    checked: impl Fn(usize) -> bool,
) -> Result<(Vec<Quat>, Vec<Vec3>), RetargetError> {
    let mut world = vec![Mat4::IDENTITY; skeleton.len()];
    // The bind pose of a valid skeleton always fits it.
    if skeleton
        .world_matrices(&skeleton.bind_pose(), &mut world)
        .is_err()
    {
        return Ok((
            vec![Quat::IDENTITY; skeleton.len()],
            vec![Vec3::ZERO; skeleton.len()],
        ));
    }
    let mut rotations = Vec::with_capacity(world.len());
    let mut positions = Vec::with_capacity(world.len());
    for (j, m) in world.iter().enumerate() {
        let (scale, rotation, position) = m.to_scale_rotation_translation();
        if checked(j) {
            check_uniform(scale, skeleton, which, j, false)?;
        }
        rotations.push(rotation);
        positions.push(position);
    }
    Ok((rotations, positions))
}

/// The ancestors of `joint`, nearest first.
fn ancestors(skeleton: &Skeleton, joint: usize) -> impl Iterator<Item = usize> + '_ {
    core::iter::successors(skeleton.parents()[joint], |&p| skeleton.parents()[p])
}

/// The one mapped joint that `joint`'s bone aims at: the nearest mapped descendants (reached
/// through unmapped joints only), if there is exactly one.
fn aim(skeleton: &Skeleton, source_of: &[Option<usize>], joint: usize) -> Option<usize> {
    let mut found = None;
    let mut stack: Vec<usize> = skeleton.children(joint).collect();
    while let Some(c) = stack.pop() {
        if source_of[c].is_some() {
            if found.replace(c).is_some() {
                return None;
            }
        } else {
            stack.extend(skeleton.children(c));
        }
    }
    found
}

/// The rotation `G` minimising `Σ ‖G (a_i − ā) − (b_i − b̄)‖²` (Horn 1987): the eigenvector of
/// the largest eigenvalue of a 4 × 4 symmetric matrix built from the cross-covariance. Fewer
/// than three pairs, or points that do not span a plane, leave it undetermined about some
/// axis; the result is then still a rotation, the one the eigensolver settles on.
fn best_rotation(pairs: &[(Vec3, Vec3)]) -> Quat {
    if pairs.len() < 2 {
        return Quat::IDENTITY;
    }
    let n = pairs.len() as f32;
    let (ca, cb) = pairs
        .iter()
        .fold((Vec3::ZERO, Vec3::ZERO), |(a, b), (p, q)| (a + *p, b + *q));
    let (ca, cb) = (ca / n, cb / n);
    // Cross-covariance S[i][j] = Σ a_i b_j, in f64 for the eigensolver.
    let mut s = [[0.0f64; 3]; 3];
    for (p, q) in pairs {
        let (a, b) = ((*p - ca).to_array(), (*q - cb).to_array());
        for i in 0..3 {
            for j in 0..3 {
                s[i][j] += f64::from(a[i]) * f64::from(b[j]);
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    // Horn's N, for the quaternion (w, x, y, z).
    let m = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (values, vectors) = jacobi_eigen(m);
    let best = (0..4)
        .max_by(|&i, &j| values[i].total_cmp(&values[j]))
        .unwrap_or(0);
    let v = [0, 1, 2, 3].map(|r| vectors[r][best]);
    let q = Quat::from_xyzw(v[1] as f32, v[2] as f32, v[3] as f32, v[0] as f32);
    if q.is_finite() && q.length() > 0.5 {
        q.normalize()
    } else {
        Quat::IDENTITY
    }
}

/// Eigenvalues and eigenvectors (columns) of a symmetric 4 × 4 matrix by cyclic Jacobi sweeps.
fn jacobi_eigen(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0f64; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _ in 0..64 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let scale: f64 = (0..4).map(|i| a[i][i] * a[i][i]).sum::<f64>() + off;
        if off <= 1e-24 * scale.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + libm::sqrt(theta * theta + 1.0));
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / libm::sqrt(t * t + 1.0);
                let s = t * c;
                for row in &mut a {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (row_p, row_q) = (a[p], a[q]);
                for (k, (apk, aqk)) in row_p.into_iter().zip(row_q).enumerate() {
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in &mut v {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2], a[3][3]], v)
}
