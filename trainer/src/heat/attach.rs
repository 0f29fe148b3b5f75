//! Attachment of each vertex to its nearest visible bone segment(s): the `H` and `p` of the
//! heat equation.
//!
//! A segment is visible from vertex `v` when (Pinocchio's two tests)
//! - the straight segment from `v` to the segment's closest point crosses no triangle (a BVH
//!   query; triangles incident to `v` are ignored, as the query starts on them), and
//! - the direction from that closest point to `v` lies within the cone of half-angle
//!   `acos(cone_cos)` (60° by default, Pinocchio's value) about `v`'s normal, the normalised sum
//!   of its incident unit face normals.
//!
//! Unlike Pinocchio, which takes the nearest segment overall and gives the vertex no heat when
//! that one is hidden, the nearest *visible* segment is used: segments are tried in order of
//! distance. Every visible segment within a relative `tie_tolerance` of the nearest visible
//! distance `d` shares the heat: `H_ii = c / d²`, `p_ij = (number of tied segments of joint j) /
//! (number of tied segments)`.

use glam::DVec3;
use rayon::prelude::*;

use super::bones::BoneSegment;
use crate::triangle_bvh::TriangleBvh;

/// The attachment of one vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Attachment {
    /// Distance to the nearest attached segment (0 when none).
    pub distance: f64,
    /// Joints and their shares `p_ij` (summing to 1); empty when no segment is visible.
    pub joints: Vec<(u32, f64)>,
}

/// Parameters of [`attach`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct AttachParams {
    pub tie_tolerance: f64,
    pub cone_cos: f64,
    /// Ignore visibility (nearest segment(s) by distance only).
    pub ignore_visibility: bool,
    /// Distances are floored at this (a vertex on a bone would get infinite heat).
    pub min_distance: f64,
}

/// Unit vertex normals as the normalised sum of incident unit face normals (zero where
/// undefined). Only triangles flagged in `used` count.
#[must_use]
pub(crate) fn cone_normals(
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    used: &[bool],
) -> Vec<DVec3> {
    let mut n = vec![DVec3::ZERO; positions.len()];
    for (t, &u) in triangles.iter().zip(used) {
        if !u {
            continue;
        }
        let p = t.map(|v| positions[v as usize]);
        let f = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        for &v in t {
            n[v as usize] += f;
        }
    }
    n.iter().map(|v| v.normalize_or_zero()).collect()
}

/// Attaches every vertex flagged in `active`; the others get an empty attachment.
#[must_use]
pub(crate) fn attach(
    positions: &[DVec3],
    normals: &[DVec3],
    active: &[bool],
    segments: &[BoneSegment],
    bvh: &TriangleBvh,
    params: AttachParams,
) -> Vec<Attachment> {
    (0..positions.len())
        .into_par_iter()
        .map_init(Vec::new, |order: &mut Vec<(f64, usize)>, v| {
            if !active[v] {
                return Attachment::default();
            }
            attach_one(v, positions[v], normals[v], segments, bvh, params, order)
        })
        .collect()
}

fn attach_one(
    v: usize,
    p: DVec3,
    normal: DVec3,
    segments: &[BoneSegment],
    bvh: &TriangleBvh,
    params: AttachParams,
    order: &mut Vec<(f64, usize)>,
) -> Attachment {
    order.clear();
    order.extend(
        segments
            .iter()
            .enumerate()
            .map(|(s, seg)| (seg.closest_point(p).distance(p), s)),
    );
    order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let visible = |s: usize| -> bool {
        if params.ignore_visibility {
            return true;
        }
        let c = segments[s].closest_point(p);
        let to_vertex = p - c;
        let len = to_vertex.length();
        if len <= params.min_distance {
            return true;
        }
        if to_vertex.dot(normal) <= params.cone_cos * len {
            return false;
        }
        !bvh.segment_hits(p, c, 1e-6, v as u32)
    };
    let mut nearest: Option<f64> = None;
    let mut tied: Vec<u32> = Vec::new();
    for &(d, s) in order.iter() {
        if let Some(d0) = nearest
            && d > d0.max(params.min_distance) * (1.0 + params.tie_tolerance)
        {
            break;
        }
        if visible(s) {
            nearest.get_or_insert(d);
            tied.push(segments[s].joint);
        }
    }
    let Some(d) = nearest else {
        return Attachment::default();
    };
    tied.sort_unstable();
    let share = 1.0 / tied.len() as f64;
    let mut joints: Vec<(u32, f64)> = Vec::with_capacity(tied.len());
    for j in tied {
        match joints.last_mut() {
            Some(last) if last.0 == j => last.1 += share,
            _ => joints.push((j, share)),
        }
    }
    Attachment {
        distance: d.max(params.min_distance),
        joints,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(joint: u32, a: [f64; 3], b: [f64; 3]) -> BoneSegment {
        BoneSegment {
            joint,
            a: DVec3::from_array(a),
            b: DVec3::from_array(b),
        }
    }

    #[test]
    fn nearest_visible_wins_and_ties_share() {
        // A wall (two triangles in the plane x = 0.5) hides the bone at x = 1.
        let wall = [
            DVec3::new(0.5, -5.0, -5.0),
            DVec3::new(0.5, 5.0, -5.0),
            DVec3::new(0.5, 5.0, 5.0),
            DVec3::new(0.5, -5.0, 5.0),
        ];
        let bvh = TriangleBvh::new_f64(&wall, &[[0, 1, 2], [0, 2, 3]]);
        let segs = [
            seg(0, [1.0, -1.0, 0.0], [1.0, 1.0, 0.0]),
            seg(1, [-1.5, -1.0, 0.0], [-1.5, 1.0, 0.0]),
        ];
        let params = AttachParams {
            tie_tolerance: 1e-4,
            cone_cos: 0.5,
            ignore_visibility: false,
            min_distance: 1e-9,
        };
        // The query vertex is index 4, after the wall's corners (the BVH skips triangles that
        // have the query vertex as a corner).
        let p = [wall[0], wall[1], wall[2], wall[3], DVec3::ZERO];
        let active = [false, false, false, false, true];
        let run = |normal: DVec3, params: AttachParams| {
            let normals = [DVec3::X, DVec3::X, DVec3::X, DVec3::X, normal];
            attach(&p, &normals, &active, &segs, &bvh, params)
                .pop()
                .unwrap()
        };
        // Normal +X: the direction from bone 0 to the vertex is -X, outside the cone; bone 1,
        // farther but along +X, is visible.
        let a = run(DVec3::X, params);
        assert_eq!(a.joints, vec![(1, 1.0)]);
        assert!((a.distance - 1.5).abs() < 1e-12);
        // Normal -X: bone 0 passes the cone but the wall hides it; bone 1 fails the cone.
        assert!(run(DVec3::NEG_X, params).joints.is_empty());
        // Without the wall bone 0 is seen.
        let no_wall = attach(
            &p[4..],
            &[DVec3::NEG_X],
            &[true],
            &segs,
            &TriangleBvh::new_f64(&[], &[]),
            params,
        );
        assert_eq!(no_wall[0].joints, vec![(0, 1.0)]);
        assert_eq!(
            run(
                DVec3::NEG_X,
                AttachParams {
                    ignore_visibility: true,
                    ..params
                }
            )
            .joints,
            vec![(0, 1.0)]
        );
        let p = [DVec3::ZERO];
        // Two bones at the same distance, both visible (no wall): they share.
        let empty = TriangleBvh::new_f64(&[], &[]);
        let segs = [
            seg(3, [0.0, -1.0, -1.0], [0.0, 1.0, -1.0]),
            seg(5, [0.0, -1.0, 1.0], [0.0, 1.0, 1.0]),
        ];
        let a = attach(
            &p,
            &[DVec3::Y],
            &[true],
            &segs,
            &empty,
            AttachParams {
                cone_cos: -1.0,
                ..params
            },
        );
        assert_eq!(a[0].joints, vec![(3, 0.5), (5, 0.5)]);
        assert_eq!(
            attach(&p, &[DVec3::Y], &[false], &segs, &empty, params)[0],
            Attachment::default()
        );
    }
}
