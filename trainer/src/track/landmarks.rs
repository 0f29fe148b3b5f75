//! Landmark maps: which point of the skeleton each of a detector's keypoints sees (BODY_25 on
//! the built-in character, a keypoint per joint, points beside each joint, on the surface, or a
//! ring of surface points around each bone), and the tracker's landmarks of a map.

use glam::DMat4;
use skinfield_formats::capture::keypoints::{BODY_25, LandmarkEntry, LandmarkMapFile};
use skinfield_formats::{Skeleton, Template};

use super::kinematics::Landmark;
use super::synthetic::BUILT_IN_BODY_25;
use crate::triangle_bvh::TriangleBvh;

/// The landmark map for `skeleton`: OpenPose BODY_25 when it has the built-in character's
/// joints, otherwise one keypoint per joint (detector `joints`, keypoint = joint name), the
/// layout of a detector trained on that rig.
#[must_use]
pub fn default_landmark_map(skeleton: &Skeleton) -> LandmarkMapFile {
    let builtin = BUILT_IN_BODY_25
        .iter()
        .all(|(_, joint, _)| skeleton.find(joint).is_some());
    if builtin {
        LandmarkMapFile {
            format: "skinfield-landmarks".into(),
            detector: "BODY_25".into(),
            keypoints: BODY_25.iter().map(|s| (*s).to_owned()).collect(),
            landmarks: BUILT_IN_BODY_25
                .iter()
                .map(|(k, j, o)| LandmarkEntry {
                    keypoint: (*k).to_owned(),
                    joint: (*j).to_owned(),
                    offset: *o,
                })
                .collect(),
        }
    } else {
        LandmarkMapFile {
            format: "skinfield-landmarks".into(),
            detector: "joints".into(),
            keypoints: skeleton.names().to_vec(),
            landmarks: joint_landmarks(skeleton),
        }
    }
}

/// The landmark map of a detector that sees, besides every joint, a point beside it: one
/// keypoint per joint (named as the joint) and one per joint named `{joint}.side`, offset from
/// the joint perpendicular to its bone by a quarter of the bone's length (the bone to its first
/// child, or for a leaf the bone from its parent). A leaf, whose bone has no end to see, also
/// gets `{joint}.tip`, a quarter of the length further along its bone. The side points observe
/// each limb's twist about its bone, which a keypoint per joint cannot
/// (docs/experiments/tracking.md), as the surface keypoints of a marker set or a dense
/// detector do.
#[must_use]
pub fn joint_side_landmark_map(skeleton: &Skeleton) -> LandmarkMapFile {
    side_landmark_map(skeleton, "joints+sides", Around::Side, |_, offset| offset)
}

/// Which points off its bone a joint gets.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Around {
    /// One, `{joint}.side`.
    Side,
    /// Four, `{joint}.ring0` … `{joint}.ring3`, a quarter turn about the bone apart.
    Ring,
}

/// The landmarks of [`joint_side_landmark_map`] moved out to the template's surface: each
/// `.side` and `.tip` point goes in the same direction from its joint, but as far as the first
/// crossing of the bind-pose mesh (`template`, in the skeleton's bind space), where a marker or
/// a dense detector's surface point would be. Why: a quarter of a short bone is a centimetre or
/// two (CesiumMan's head: 1.3 cm), so pixel noise turns the head and the feet by 10° or more,
/// while the surface is 5–15 cm from those joints (a face's landmarks, the toes). A point whose
/// ray leaves through a hole, or never meets the mesh within twice its bounding-box diagonal,
/// keeps the quarter-bone offset; a joint outside the mesh gets the point where its ray enters it.
#[must_use]
pub fn joint_surface_landmark_map(skeleton: &Skeleton, template: &Template) -> LandmarkMapFile {
    surface_landmark_map(skeleton, template, Around::Side)
}

/// [`joint_surface_landmark_map`] with four surface points around every bone instead of one:
/// `{joint}.ring0` … `{joint}.ring3`, the side direction turned about the bone by 0°, 90°,
/// 180° and 270° and moved out to the first crossing of the template (leaves keep their
/// `{joint}.tip`), as a marker set places several markers on a segment. Why: one surface point
/// sees a short bone's turn through a single lever arm, so its pixel noise turns the bone
/// directly; four levers on opposite sides average the noise and see the bend of the bone
/// in both directions across it.
#[must_use]
pub fn joint_ring_landmark_map(skeleton: &Skeleton, template: &Template) -> LandmarkMapFile {
    surface_landmark_map(skeleton, template, Around::Ring)
}

/// [`side_landmark_map`]'s offsets moved out to the first crossing of `template`.
fn surface_landmark_map(
    skeleton: &Skeleton,
    template: &Template,
    around: Around,
) -> LandmarkMapFile {
    let bvh = TriangleBvh::new(&template.positions, &template.triangles);
    // Infinite (every point keeps its quarter-bone offset) for an empty or non-finite mesh.
    let reach = template
        .bounds()
        .map_or(f64::INFINITY, |b| 2.0 * f64::from(b.size().length()));
    // Bind-space matrix of every joint (None where the inverse bind cannot be inverted).
    let bind: Vec<Option<DMat4>> = skeleton
        .inverse_bind()
        .iter()
        .map(|m| {
            let m = m.as_dmat4();
            (m.determinant().abs() > 1e-12).then(|| m.inverse())
        })
        .collect();
    let detector = match around {
        Around::Side => "joints+surface",
        Around::Ring => "joints+ring",
    };
    side_landmark_map(skeleton, detector, around, |j, offset| {
        let Some(b) = bind[j] else {
            return offset;
        };
        let head = b.w_axis.truncate();
        let along = b.transform_vector3(offset.as_dvec3());
        let length = along.length();
        if !(reach.is_finite() && length > 0.0) {
            return offset;
        }
        match bvh.first_hit(head, head + along * (reach / length)) {
            Some(t) => offset * (t * reach / length) as f32,
            None => offset,
        }
    })
}

/// One keypoint per joint plus `{joint}.side` (or the ring of four, `around`) and `{joint}.tip`
/// for leaves at the quarter-bone offsets of [`joint_side_landmark_map`], each passed through
/// `place(joint, offset)` (the joint's local frame) before it is stored.
fn side_landmark_map(
    skeleton: &Skeleton,
    detector: &str,
    around: Around,
    place: impl Fn(usize, glam::Vec3) -> glam::Vec3,
) -> LandmarkMapFile {
    let local = skeleton.bind_local();
    let mut landmarks = joint_landmarks(skeleton);
    for (j, name) in skeleton.names().iter().enumerate() {
        // The bone in the joint's own frame: to the first child, or back to the parent.
        let first_child = skeleton.children(j).next();
        let leaf = first_child.is_none();
        let bone = match first_child {
            Some(c) => local[c].translation,
            None if skeleton.parents()[j].is_some() => {
                -(local[j].rotation.inverse() * local[j].translation)
            }
            None => continue,
        };
        let length = bone.length();
        if !(length.is_finite() && length > 0.0) {
            continue;
        }
        let along = bone / length;
        // The joint's local axis least aligned with the bone, made perpendicular to it.
        let axis = [glam::Vec3::X, glam::Vec3::Y, glam::Vec3::Z]
            .into_iter()
            .min_by(|a, b| a.dot(along).abs().total_cmp(&b.dot(along).abs()))
            .expect("three axes");
        let side = (axis - along * axis.dot(along)).normalize() * (0.25 * length);
        let mut add = |suffix: &str, offset: glam::Vec3| {
            landmarks.push(LandmarkEntry {
                keypoint: format!("{name}.{suffix}"),
                joint: name.clone(),
                offset: place(j, offset).to_array(),
            });
        };
        match around {
            Around::Side => add("side", side),
            Around::Ring => {
                let cross = along.cross(side);
                for (k, offset) in [side, cross, -side, -cross].into_iter().enumerate() {
                    add(&format!("ring{k}"), offset);
                }
            }
        }
        if leaf {
            add("tip", -0.25 * bone);
        }
    }
    LandmarkMapFile {
        format: "skinfield-landmarks".into(),
        detector: detector.into(),
        // One keypoint per landmark, in the same order.
        keypoints: landmarks.iter().map(|l| l.keypoint.clone()).collect(),
        landmarks,
    }
}

/// One landmark per joint, at the joint, its keypoint named as the joint.
fn joint_landmarks(skeleton: &Skeleton) -> Vec<LandmarkEntry> {
    skeleton
        .names()
        .iter()
        .map(|n| LandmarkEntry {
            keypoint: n.clone(),
            joint: n.clone(),
            offset: [0.0; 3],
        })
        .collect()
}

/// The tracker's landmarks of a (validated) map, and for each the index of its keypoint in the
/// detector's output.
#[must_use]
pub fn landmarks_of(map: &LandmarkMapFile, skeleton: &Skeleton) -> Vec<(usize, Landmark)> {
    map.landmarks
        .iter()
        .filter_map(|l| {
            let k = map.keypoints.iter().position(|n| *n == l.keypoint)?;
            let joint = skeleton.find(&l.joint)?;
            Some((
                k,
                Landmark {
                    joint,
                    offset: glam::Vec3::from_array(l.offset).as_dvec3(),
                },
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use glam::Mat4;
    use skinfield_formats::capture::load_capture;

    use super::*;
    use crate::track::TrackOptions;
    use crate::track::capture::tests::{EXACT, tiny_capture};
    use crate::track::capture::{track_capture, write_synthetic_keypoints};

    #[test]
    fn surface_points_lie_on_the_template_along_the_side_points() {
        let dir = tempfile::tempdir().unwrap();
        let capture = tiny_capture(dir.path());
        let (skeleton, template) = (&capture.skeleton, &capture.template);
        let sides = joint_side_landmark_map(skeleton);
        let surface = joint_surface_landmark_map(skeleton, template);
        assert_eq!(surface.detector, "joints+surface");
        assert_eq!(surface.keypoints, sides.keypoints);
        let bvh = TriangleBvh::new(&template.positions, &template.triangles);
        let size = template.bounds().unwrap().size().length();
        let (mut moved, mut longer) = (0, 0);
        for (side, point) in sides.landmarks.iter().zip(&surface.landmarks) {
            assert_eq!(
                (&side.keypoint, &side.joint),
                (&point.keypoint, &point.joint)
            );
            let (a, b) = (
                glam::Vec3::from_array(side.offset),
                glam::Vec3::from_array(point.offset),
            );
            if a == glam::Vec3::ZERO {
                assert_eq!(b, glam::Vec3::ZERO, "{}", point.keypoint);
                continue;
            }
            // The same direction from the joint; either on the mesh or the quarter-bone point.
            assert!(
                a.normalize().dot(b.normalize()) > 1.0 - 1e-5,
                "{}",
                point.keypoint
            );
            let j = skeleton.find(&point.joint).unwrap();
            let at = skeleton.inverse_bind()[j].inverse().transform_point3(b);
            let off = bvh.closest(at).unwrap().distance_squared.sqrt();
            if a == b {
                continue;
            }
            assert!(
                off < 1e-4 * size,
                "{} is {off} off the mesh",
                point.keypoint
            );
            moved += 1;
            longer += usize::from(b.length() > a.length());
        }
        // Nearly every ray from inside the body meets it, mostly beyond the quarter bone.
        let with_offsets = sides.landmarks.len() - skeleton.len();
        assert!(
            5 * moved >= 4 * with_offsets,
            "{moved} of {with_offsets} moved"
        );
        assert!(2 * longer >= moved, "{longer} of {moved} longer");
        // Exact detections of the surface points give every joint's orientation back.
        let worst = worst_rotation_entry(dir.path(), &surface);
        assert!(worst < 1e-3, "with surface points: {worst}");
    }

    #[test]
    fn ring_points_circle_each_bone_on_the_template() {
        let dir = tempfile::tempdir().unwrap();
        let capture = tiny_capture(dir.path());
        let (skeleton, template) = (&capture.skeleton, &capture.template);
        let surface = joint_surface_landmark_map(skeleton, template);
        let ring = joint_ring_landmark_map(skeleton, template);
        let sides = joint_side_landmark_map(skeleton);
        let bvh = TriangleBvh::new(&template.positions, &template.triangles);
        let size = template.bounds().unwrap().size().length();
        assert_eq!(ring.detector, "joints+ring");
        assert_eq!(ring.keypoints.len(), ring.landmarks.len());
        let offset = |map: &LandmarkMapFile, keypoint: &str| {
            map.landmarks
                .iter()
                .find(|l| l.keypoint == keypoint)
                .map(|l| glam::Vec3::from_array(l.offset))
        };
        let (mut joints_with_rings, mut tips) = (0, 0);
        for name in skeleton.names() {
            // A leaf's tip is the surface map's.
            if let Some(tip) = offset(&surface, &format!("{name}.tip")) {
                assert_eq!(offset(&ring, &format!("{name}.tip")), Some(tip));
                tips += 1;
            }
            let Some(side) = offset(&surface, &format!("{name}.side")) else {
                assert!(offset(&ring, &format!("{name}.ring0")).is_none(), "{name}");
                continue;
            };
            joints_with_rings += 1;
            let r: Vec<glam::Vec3> = (0..4)
                .map(|k| offset(&ring, &format!("{name}.ring{k}")).unwrap())
                .collect();
            // The first is the surface map's side point; the others a quarter turn apart
            // about the bone: opposite pairs, the two pairs perpendicular.
            assert_eq!(r[0], side, "{name}");
            // Each on the mesh, or at the quarter-bone distance where its ray meets nothing.
            let quarter = offset(&sides, &format!("{name}.side")).unwrap().length();
            let j = skeleton.find(name).unwrap();
            for (k, point) in r.iter().enumerate() {
                let at = skeleton.inverse_bind()[j]
                    .inverse()
                    .transform_point3(*point);
                let off = bvh.closest(at).unwrap().distance_squared.sqrt();
                assert!(
                    off < 1e-4 * size || (point.length() - quarter).abs() < 1e-6 * size,
                    "{name}.ring{k} is {off} off the mesh"
                );
            }
            let dir: Vec<glam::Vec3> = r.iter().map(|v| v.normalize()).collect();
            for (a, b, cos) in [(0, 2, -1.0), (1, 3, -1.0), (0, 1, 0.0), (2, 3, 0.0)] {
                assert!(
                    (dir[a].dot(dir[b]) - cos).abs() < 1e-5,
                    "{name}: ring{a}·ring{b} = {}",
                    dir[a].dot(dir[b])
                );
            }
        }
        assert_eq!(
            ring.landmarks.len(),
            skeleton.len() + 4 * joints_with_rings + tips
        );
        assert!(joints_with_rings + 1 >= skeleton.len());
        // Exact detections of the ring give every joint's orientation back.
        let worst = worst_rotation_entry(dir.path(), &ring);
        assert!(worst < 1e-3, "with ring points: {worst}");
    }

    /// Tracks `capture` from exact detections of `map` (keypoints only) and returns the largest
    /// difference, over frames and joints, between an entry of a tracked and a true world
    /// matrix's rotation part.
    fn worst_rotation_entry(dir: &std::path::Path, map: &LandmarkMapFile) -> f32 {
        let capture = load_capture(dir).unwrap();
        write_synthetic_keypoints(&capture, map, &EXACT).unwrap();
        let capture = load_capture(dir).unwrap();
        let keypoints_only = TrackOptions {
            silhouette_weight: 0.0,
            ..TrackOptions::default()
        };
        let tracked = track_capture(&capture, &keypoints_only, None, |_| {}).unwrap();
        let n = capture.skeleton.len();
        let (mut got, mut want) = (vec![Mat4::IDENTITY; n], vec![Mat4::IDENTITY; n]);
        let mut worst = 0.0f32;
        for (g, w) in tracked.poses.iter().zip(&capture.poses) {
            capture.skeleton.world_matrices(g, &mut got).unwrap();
            capture.skeleton.world_matrices(w, &mut want).unwrap();
            for (a, b) in got.iter().zip(&want) {
                let d = glam::Mat3::from_mat4(*a) - glam::Mat3::from_mat4(*b);
                worst = worst.max(d.to_cols_array().iter().fold(0.0, |m, x| m.max(x.abs())));
            }
        }
        worst
    }

    #[test]
    fn side_keypoints_see_the_twists_that_joint_keypoints_miss() {
        let dir = tempfile::tempdir().unwrap();
        let capture = tiny_capture(dir.path());
        let sides = joint_side_landmark_map(&capture.skeleton);
        let skeleton = &capture.skeleton;
        // A keypoint at every joint, and beside every joint with a bone: perpendicular to the
        // bone, a quarter of its length away; a leaf also a quarter further along its bone.
        let leaves = (0..skeleton.len())
            .filter(|&j| skeleton.children(j).next().is_none())
            .count();
        assert_eq!(sides.keypoints.len(), sides.landmarks.len());
        assert_eq!(sides.landmarks.len(), 2 * skeleton.len() + leaves);
        for l in sides.landmarks.iter().filter(|l| l.keypoint.contains('.')) {
            let j = skeleton.find(&l.joint).unwrap();
            let bone = match skeleton.children(j).next() {
                Some(c) => skeleton.bind_local()[c].translation,
                None => {
                    let t = skeleton.bind_local()[j];
                    -(t.rotation.inverse() * t.translation)
                }
            };
            let offset = glam::Vec3::from_array(l.offset);
            assert!(
                (offset.length() - 0.25 * bone.length()).abs() < 1e-5,
                "{}",
                l.keypoint
            );
            if l.keypoint == format!("{}.side", l.joint) {
                assert!(
                    offset.dot(bone).abs() < 1e-5 * bone.length_squared(),
                    "{}",
                    l.keypoint
                );
            } else {
                assert_eq!(l.keypoint, format!("{}.tip", l.joint));
                assert!((offset + 0.25 * bone).length() < 1e-6, "{}", l.keypoint);
            }
        }
        // Exact detections: with the side points every joint's orientation comes back; with
        // the joints alone (the same map less its side points) the limbs' twists do not.
        let joints_only = LandmarkMapFile {
            detector: "joints".into(),
            keypoints: skeleton.names().to_vec(),
            landmarks: sides
                .landmarks
                .iter()
                .filter(|l| !l.keypoint.contains('.'))
                .cloned()
                .collect(),
            ..sides.clone()
        };
        let with_sides = worst_rotation_entry(dir.path(), &sides);
        let without = worst_rotation_entry(dir.path(), &joints_only);
        assert!(with_sides < 1e-3, "with side points: {with_sides}");
        assert!(without > 0.05, "joints only: {without}");
    }
}
