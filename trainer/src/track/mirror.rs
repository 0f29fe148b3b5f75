//! Left/right pairs of a detector's keypoints: the labels a detector confuses when it swaps a
//! person's sides, which the synthetic detector's gross outliers reproduce.
//!
//! Joints pair by the bind pose's mirror symmetry, then by name (`l_knee`/`r_knee`,
//! `LeftHand`/`mixamorig:RightHand`, `arm.L`/`arm.R`, `leg_joint_L_1`/`leg_joint_R_1`) where
//! the pose is not symmetric: glTF rigs name their sides inconsistently (CesiumMan's left arm
//! is `Skeleton_arm_joint_L__4_` … `L__2_`, shoulder to wrist, its right arm
//! `Skeleton_arm_joint_R` … `R__3_`), and a detector's side swap does not care what the rig
//! calls them.

use glam::Vec3;
use skinfield_formats::Skeleton;
use skinfield_formats::capture::keypoints::LandmarkMapFile;

use super::synthetic::BODY_25_PAIRS;

/// Share of the skeleton's extent within which a joint's mirror image must meet another joint.
pub const MIRROR_TOLERANCE: f32 = 0.02;

/// Left/right keypoint pairs `(i, j)`, `i < j`, of `map` on `skeleton`: BODY_25's, else
/// `{A}{suffix}`/`{B}{suffix}` where landmarks sit on joints `A` and `B` that mirror each other
/// ([`mirror_joints`]), then keypoints left whose names differ only in their side.
#[must_use]
pub fn left_right_pairs(map: &LandmarkMapFile, skeleton: &Skeleton) -> Vec<(usize, usize)> {
    if map.detector == "BODY_25" {
        return BODY_25_PAIRS.to_vec();
    }
    let keypoints = &map.keypoints;
    let index = |name: &str| keypoints.iter().position(|n| n == name);
    let mut partner: Vec<Option<usize>> = vec![None; keypoints.len()];
    let joints = mirror_joints(skeleton);
    let names = skeleton.names();
    for landmark in &map.landmarks {
        let (Some(i), Some(a)) = (index(&landmark.keypoint), skeleton.find(&landmark.joint)) else {
            continue;
        };
        let Some(suffix) = landmark.keypoint.strip_prefix(names[a].as_str()) else {
            continue;
        };
        if let Some(b) = joints[a] {
            pair(&mut partner, i, index(&format!("{}{suffix}", names[b])));
        }
    }
    for (i, name) in keypoints.iter().enumerate() {
        pair(&mut partner, i, mirror_name(name).and_then(|m| index(&m)));
    }
    partner
        .iter()
        .enumerate()
        .filter_map(|(i, p)| p.filter(|&j| i < j).map(|j| (i, j)))
        .collect()
}

/// Pairs `i` with `j` when `j` is another item and neither has a partner yet.
fn pair(partner: &mut [Option<usize>], i: usize, j: Option<usize>) {
    if let Some(j) = j.filter(|&j| j != i && partner[i].is_none() && partner[j].is_none()) {
        partner[i] = Some(j);
        partner[j] = Some(i);
    }
}

/// For every joint, the joint at its mirror image in the bind pose (`None` on the plane of
/// symmetry or without a partner): positions first, across the plane through the joints' mean
/// perpendicular to the bind space's axis (x, y or z) about which the most joints pair up,
/// within [`MIRROR_TOLERANCE`] of the skeleton's extent, only mutual nearest partners; then
/// names ([`mirror_name`]) for the joints left. Positions first because names mislead:
/// CesiumMan's `Skeleton_arm_joint_L__3_` is an elbow, `…_R__3_` the other wrist.
#[must_use]
pub fn mirror_joints(skeleton: &Skeleton) -> Vec<Option<usize>> {
    let positions: Vec<Vec3> = skeleton
        .inverse_bind()
        .iter()
        .map(|m| m.inverse().w_axis.truncate())
        .collect();
    let mut partner = if positions.len() >= 2 && positions.iter().all(|p| p.is_finite()) {
        symmetric_partners(&positions)
    } else {
        vec![None; positions.len()]
    };
    for (i, name) in skeleton.names().iter().enumerate() {
        pair(
            &mut partner,
            i,
            mirror_name(name).and_then(|m| skeleton.find(&m)),
        );
    }
    partner
}

/// Mutual nearest mirror images among `positions` (finite, at least two) across the plane
/// through their mean perpendicular to the axis about which the most pair up.
fn symmetric_partners(positions: &[Vec3]) -> Vec<Option<usize>> {
    let lo = positions.iter().fold(Vec3::INFINITY, |a, p| a.min(*p));
    let hi = positions.iter().fold(Vec3::NEG_INFINITY, |a, p| a.max(*p));
    let tolerance = MIRROR_TOLERANCE * (hi - lo).length();
    let mean = positions.iter().sum::<Vec3>() / positions.len() as f32;
    let by_axis = |axis: usize| -> Vec<Option<usize>> {
        let nearest = |i: usize| -> Option<usize> {
            let p = positions[i];
            if (p[axis] - mean[axis]).abs() <= tolerance {
                return None;
            }
            let mut image = p;
            image[axis] = 2.0 * mean[axis] - p[axis];
            (0..positions.len())
                .filter(|&j| j != i)
                .map(|j| (j, positions[j].distance(image)))
                .filter(|&(_, d)| d <= tolerance)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(j, _)| j)
        };
        let nearest: Vec<Option<usize>> = (0..positions.len()).map(nearest).collect();
        (0..positions.len())
            .map(|i| nearest[i].filter(|&j| nearest[j] == Some(i)))
            .collect()
    };
    (0..3)
        .map(by_axis)
        .max_by_key(|p| p.iter().flatten().count())
        .expect("three axes")
}

/// `name` with its side exchanged, if it names one: a `l_`/`r_` prefix, `Left`/`Right` or
/// `left`/`right` anywhere, or a separate `L`/`R` (`l`/`r`) token between `_`, `.`, `:` or
/// `-` (`arm.L`, `leg_joint_L_1`).
#[must_use]
pub fn mirror_name(name: &str) -> Option<String> {
    for (a, b) in [("l_", "r_"), ("r_", "l_")] {
        if let Some(rest) = name.strip_prefix(a) {
            return Some(format!("{b}{rest}"));
        }
    }
    for (a, b) in [
        ("Left", "Right"),
        ("Right", "Left"),
        ("left", "right"),
        ("right", "left"),
    ] {
        if name.contains(a) {
            return Some(name.replacen(a, b, 1));
        }
    }
    let separator = |c: char| matches!(c, '_' | '.' | ':' | '-');
    let mut start = 0;
    for token in name.split(separator) {
        let swapped = match token {
            "L" => Some("R"),
            "R" => Some("L"),
            "l" => Some("r"),
            "r" => Some("l"),
            _ => None,
        };
        if let Some(s) = swapped {
            return Some(format!(
                "{}{s}{}",
                &name[..start],
                &name[start + token.len()..]
            ));
        }
        start += token.len() + 1;
    }
    None
}

#[cfg(test)]
mod tests {
    use skinfield_formats::capture::keypoints::LandmarkEntry;

    use super::*;
    use crate::synth::character::build_skeleton;

    #[test]
    fn names_pair_by_their_side() {
        for (name, mirrored) in [
            ("l_knee", Some("r_knee")),
            ("r_knee", Some("l_knee")),
            ("LeftHand", Some("RightHand")),
            ("mixamorig:RightFoot", Some("mixamorig:LeftFoot")),
            ("upperarm_left", Some("upperarm_right")),
            ("arm.L", Some("arm.R")),
            ("leg_joint_L_1", Some("leg_joint_R_1")),
            ("Skeleton_arm_joint_L__4_", Some("Skeleton_arm_joint_R__4_")),
            ("thigh-r", Some("thigh-l")),
            ("hips", None),
            ("Lower", None),
            ("spine_2", None),
        ] {
            assert_eq!(mirror_name(name).as_deref(), mirrored, "{name}");
        }
    }

    #[test]
    fn keypoints_pair_by_name() {
        let map = LandmarkMapFile {
            format: "skinfield-landmarks".into(),
            detector: "joints".into(),
            keypoints: [
                "hips",
                "l_knee",
                "r_knee",
                "LeftHand",
                "RightHand",
                "arm.L",
                "arm.R",
            ]
            .map(String::from)
            .to_vec(),
            landmarks: Vec::new(),
        };
        let skeleton = build_skeleton().unwrap();
        assert_eq!(
            left_right_pairs(&map, &skeleton),
            vec![(1, 2), (3, 4), (5, 6)]
        );
    }

    /// The built-in skeleton with every joint renamed `j{index}`.
    fn anonymous_skeleton() -> (Skeleton, Skeleton) {
        let named = build_skeleton().unwrap();
        let names: Vec<String> = (0..named.len()).map(|j| format!("j{j}")).collect();
        let anonymous = Skeleton::new(
            names,
            named.parents().to_vec(),
            named.bind_local().to_vec(),
            Some(named.inverse_bind().to_vec()),
            Some(named.dofs().to_vec()),
            named.base(),
        )
        .unwrap();
        (named, anonymous)
    }

    #[test]
    fn joints_without_side_names_pair_by_the_bind_pose_symmetry() {
        let (named, anonymous) = anonymous_skeleton();
        let by_name = mirror_joints(&named);
        assert!(
            by_name.iter().flatten().count() >= 8,
            "the built-in skeleton names its sides"
        );
        assert_eq!(mirror_joints(&anonymous), by_name);
        // Symmetric and never a joint with itself.
        for (i, p) in by_name.iter().enumerate() {
            if let Some(j) = *p {
                assert_ne!(i, j);
                assert_eq!(by_name[j], Some(i));
            }
        }
    }

    #[test]
    fn cesium_mans_arms_pair_although_their_names_do_not() {
        let Some(data) = skinfield_formats::shared_data::shared_data_dir() else {
            return;
        };
        let path = data.join("khronos-cesiumman/CesiumMan.glb");
        let doc = skinfield_formats::gltf_io::load_gltf(&path).unwrap();
        let skeleton = &doc.largest_skin().unwrap().skeleton;
        let partner = mirror_joints(skeleton);
        let name_of = |name: &str| {
            let j = skeleton.find(name).unwrap_or_else(|| panic!("{name}"));
            partner[j].map(|p| skeleton.names()[p].as_str())
        };
        // By name (the legs) and by the bind pose (the arms: L__4_ … L__2_ against R … R__3_).
        for (left, right) in [
            ("leg_joint_L_1", "leg_joint_R_1"),
            ("leg_joint_L_5", "leg_joint_R_5"),
            ("Skeleton_arm_joint_L__4_", "Skeleton_arm_joint_R"),
            ("Skeleton_arm_joint_L__3_", "Skeleton_arm_joint_R__2_"),
            ("Skeleton_arm_joint_L__2_", "Skeleton_arm_joint_R__3_"),
        ] {
            assert_eq!(name_of(left), Some(right));
            assert_eq!(name_of(right), Some(left));
        }
        for spine in [
            "Skeleton_torso_joint_1",
            "torso_joint_3",
            "Skeleton_neck_joint_2",
        ] {
            assert_eq!(name_of(spine), None, "{spine}");
        }
    }

    #[test]
    fn surface_keypoints_of_mirrored_joints_pair_by_suffix() {
        let (named, anonymous) = anonymous_skeleton();
        let pairs = mirror_joints(&named);
        let names = anonymous.names();
        let mut keypoints = Vec::new();
        let mut landmarks = Vec::new();
        for name in names {
            for suffix in ["", ".side"] {
                keypoints.push(format!("{name}{suffix}"));
                landmarks.push(LandmarkEntry {
                    keypoint: format!("{name}{suffix}"),
                    joint: name.clone(),
                    offset: [0.0; 3],
                });
            }
        }
        let map = LandmarkMapFile {
            format: "skinfield-landmarks".into(),
            detector: "joints+sides".into(),
            keypoints,
            landmarks,
        };
        let mut want: Vec<(usize, usize)> = pairs
            .iter()
            .enumerate()
            .filter_map(|(a, b)| b.filter(|&b| a < b).map(|b| (a, b)))
            .flat_map(|(a, b)| [(2 * a, 2 * b), (2 * a + 1, 2 * b + 1)])
            .collect();
        want.sort_unstable();
        assert_eq!(left_right_pairs(&map, &anonymous), want);
    }
}
