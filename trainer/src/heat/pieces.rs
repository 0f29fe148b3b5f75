//! Small separate pieces of a mesh take the weights of the surface they sit on.
//!
//! Real assets carry details modelled as separate little meshes: eyebrows, pupils, buttons,
//! bolts, the trim of a helmet. Bone heat solves each connected component on its own, and a
//! piece of a few vertices sees only the bone nearest to it, which is not necessarily the one
//! that carries the surface below it: on the zoo's robot, 4- to 6-vertex details on the sides
//! and the front of the head (bound to `Head` by the asset) went to an upper arm 7 cm away and
//! to the IK helpers `PoleTarget.L/R` in front of the face; those were the worst vertices of
//! every test frame, and, `Head` not being among their candidate joints, no training could move
//! them to it. Such a piece belongs to the larger surface it touches or hovers over, so each of
//! its vertices copies the solved weights of the nearest vertex of a large component (what
//! "transfer weights from the nearest surface" does in a DCC tool).
//!
//! "Small" is relative: a component whose bounding-box diagonal is below
//! [`super::HeatOptions::small_piece_fraction`] of the whole mesh's. The robot's limbs and
//! the skirts and capes of the other characters are separate components too, but far larger (a
//! fifth of the size and more), and keep their own solution.

use glam::DVec3;

/// Replaces the rows of the vertices of small components (see the module docs) by the row of
/// the nearest vertex of a large one; returns how many vertices changed. Nothing changes when
/// no component is large, or `fraction` is 0.
pub(super) fn inherit_small_pieces(
    positions: &[DVec3],
    component: &[u32],
    components: usize,
    rows: &mut [Vec<(u32, f32)>],
    fraction: f64,
) -> usize {
    if fraction <= 0.0 || components < 2 {
        return 0;
    }
    let mut lo = vec![DVec3::splat(f64::INFINITY); components];
    let mut hi = vec![DVec3::splat(f64::NEG_INFINITY); components];
    let (mut all_lo, mut all_hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for (p, &c) in positions.iter().zip(component) {
        if let Some(c) = usize::try_from(c).ok().filter(|&c| c < components) {
            lo[c] = lo[c].min(*p);
            hi[c] = hi[c].max(*p);
            all_lo = all_lo.min(*p);
            all_hi = all_hi.max(*p);
        }
    }
    let limit = fraction * (all_hi - all_lo).length();
    let small: Vec<bool> = lo
        .iter()
        .zip(&hi)
        .map(|(l, h)| (*h - *l).length() < limit)
        .collect();
    let is_small = |c: u32| small.get(c as usize).copied().unwrap_or(false);
    let (mut anchors, mut anchor_vertex) = (Vec::new(), Vec::new());
    let (mut points, mut point_vertex) = (Vec::new(), Vec::new());
    for (v, (p, &c)) in positions.iter().zip(component).enumerate() {
        if (c as usize) >= components {
            continue;
        }
        if is_small(c) {
            points.push(p.as_vec3());
            point_vertex.push(v);
        } else {
            anchors.push(p.as_vec3());
            anchor_vertex.push(v);
        }
    }
    if anchors.is_empty() || points.is_empty() {
        return 0;
    }
    let nearest: Vec<u32> = skinfield_runtime::candidates::nearest_anchors(&anchors, &points);
    for (&v, &a) in point_vertex.iter().zip(&nearest) {
        rows[v] = rows[anchor_vertex[a as usize]].clone();
    }
    point_vertex.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(j: u32) -> Vec<(u32, f32)> {
        vec![(j, 1.0)]
    }

    #[test]
    fn a_small_piece_copies_the_nearest_large_vertex_and_large_pieces_keep_theirs() {
        // Component 0: a 1 m strip along x (joints 0, 0, 1, 4 along it); component 1: a 10 cm
        // piece hovering above x = 0.85–0.95 (solved to joint 2); component 2: another large
        // strip (joint 3) 3 m away. Mesh diagonal √10 m: 5 % of it is 16 cm.
        let positions = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(0.4, 0.0, 0.0),
            DVec3::new(0.8, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.85, 0.05, 0.0),
            DVec3::new(0.95, 0.05, 0.0),
            DVec3::new(0.0, 3.0, 0.0),
            DVec3::new(1.0, 3.0, 0.0),
            DVec3::ZERO,
        ];
        let component = [0, 0, 0, 0, 1, 1, 2, 2, u32::MAX];
        let mut rows = vec![
            row(0),
            row(0),
            row(1),
            row(4),
            row(2),
            row(2),
            row(3),
            row(3),
            Vec::new(),
        ];
        let before = rows.clone();
        let changed = inherit_small_pieces(&positions, &component, 3, &mut rows, 0.05);
        assert_eq!(changed, 2);
        // x = 0.85 is nearest to x = 0.8 (joint 1), x = 0.95 to x = 1.0 (joint 4).
        assert_eq!(rows[4], row(1));
        assert_eq!(rows[5], row(4));
        assert_eq!(rows[..4], before[..4]);
        assert_eq!(rows[6..], before[6..]);
        // Off, or a threshold below the piece's size: nothing changes.
        let mut off = before.clone();
        assert_eq!(
            inherit_small_pieces(&positions, &component, 3, &mut off, 0.0),
            0
        );
        assert_eq!(
            inherit_small_pieces(&positions, &component, 3, &mut off, 0.02),
            0
        );
        assert_eq!(off, before);
        // Every component small (a mesh of crumbs): nothing to copy from.
        let mut crumbs = before.clone();
        assert_eq!(
            inherit_small_pieces(&positions[4..6], &[0, 0], 1, &mut crumbs[4..6], 0.5),
            0
        );
    }
}
