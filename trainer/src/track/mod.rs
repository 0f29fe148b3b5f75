//! Skeletal motion from multi-view 2D detections (`trainer track`): DeepCap's kinematics and
//! global alignment layers, its keypoint loss and joint-limit prior, fitted frame by frame.
//!
//! - [`kinematics`]: joint angles and root rotation → landmark positions (f64);
//! - [`alignment`]: the root translation in closed form from the rays through the detections;
//! - [`solve`]: the per-frame robust Levenberg–Marquardt fit;
//! - `dense`: the normal equations and Cholesky solves of the fits;
//! - [`calibration`]: bone offsets shared by every frame, fitted to the keypoints;
//! - [`silhouette`]: the optional silhouette refinement on the skinned template;
//! - [`landmarks`]: which point of the skeleton each keypoint of a detector sees;
//! - [`capture`]: synthetic keypoints in a capture, tracking all its frames;
//! - [`filter`]: a zero-phase Gaussian filter of the tracked motion over each clip;
//! - [`mirror`]: the left/right pairs of a detector's keypoints (by name, else by the bind
//!   pose's symmetry), which a synthetic swap exchanges;
//! - [`synthetic`]: detections projected from known landmarks, with noise, drops and swaps.

pub mod alignment;
pub mod calibration;
pub mod capture;
mod dense;
pub mod filter;
pub mod kinematics;
pub mod landmarks;
pub mod mirror;
pub mod silhouette;
pub mod solve;
pub mod synthetic;

pub use alignment::{Alignment, Ray, global_alignment};
pub use calibration::BoneCalibration;
pub use kinematics::{Kinematics, Landmark};
pub use solve::{
    Detection, FrameFit, FrameReport, JacobianMethod, TrackError, TrackOptions, Tracker,
};

#[cfg(test)]
pub(crate) mod tests {
    use glam::{DMat4, DQuat, DVec3, Mat4, Quat};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use skinfield_formats::{Camera, JointDofs, Skeleton};

    use super::*;
    use crate::synth::character::build_skeleton;
    use crate::synth::rig::camera_rig;

    /// Random angles within each Euler joint's limits (Free joints: up to 0.5 rad).
    pub(crate) fn random_angles(skeleton: &Skeleton, rng: &mut ChaCha8Rng) -> Vec<f32> {
        let mut out = Vec::new();
        for d in skeleton.dofs() {
            match d {
                JointDofs::Euler { limits, .. } => {
                    for l in limits {
                        out.push(rng.random_range(l[0] * 0.8..=l[1] * 0.8 + 1e-6));
                    }
                }
                other => {
                    for _ in 0..other.count() {
                        out.push(rng.random_range(-0.5..0.5));
                    }
                }
            }
        }
        out
    }

    /// Every point projected into every camera, exactly, with one confidence.
    pub(crate) fn exact_detections(
        cameras: &[Camera],
        points: &[DVec3],
        confidence: f64,
    ) -> Vec<Vec<Option<Detection>>> {
        cameras
            .iter()
            .map(|c| {
                points
                    .iter()
                    .map(|p| {
                        c.project_f64(*p)
                            .map(|pixel| Detection { pixel, confidence })
                    })
                    .collect()
            })
            .collect()
    }

    /// Fits one frame without a predecessor; returns the fit and its worst landmark distance
    /// from `truth` (world positions).
    fn fit_and_worst(
        kin: &Kinematics,
        landmarks: &[Landmark],
        cameras: &[Camera],
        detections: &[Vec<Option<Detection>>],
        truth: &[DVec3],
    ) -> (FrameFit, f64) {
        let tracker = Tracker::new(
            kin.clone(),
            landmarks.to_vec(),
            cameras,
            DVec3::Y,
            TrackOptions::default(),
        );
        let fit = tracker.fit(detections, None).unwrap();
        let mut worlds = vec![DMat4::IDENTITY; kin.joint_count()];
        let mut got = vec![DVec3::ZERO; landmarks.len()];
        kin.landmarks(
            fit.root_rotation,
            &fit.angles,
            landmarks,
            &mut worlds,
            &mut got,
        );
        let worst = got
            .iter()
            .zip(truth)
            .map(|(g, t)| (*g + fit.world_shift).distance(*t))
            .fold(0.0, f64::max);
        (fit, worst)
    }

    #[test]
    fn kinematics_layer_matches_the_formats_forward_kinematics() {
        let skeleton = build_skeleton().unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // Calibrated bones too (the root's offset is ignored: the alignment places the root).
        let offsets: Vec<DVec3> = (0..skeleton.len())
            .map(|_| DVec3::new(rng.random_range(-0.02..0.02), 0.01, -0.005))
            .collect();
        let mut ours = vec![DMat4::IDENTITY; skeleton.len()];
        let mut theirs = vec![Mat4::IDENTITY; skeleton.len()];
        // And joints translated per frame (an ankle, a shoulder).
        let translating = [
            skeleton.find("l_ankle").unwrap(),
            skeleton.find("r_shoulder").unwrap(),
        ];
        for i in 0..12 {
            let kin = match i % 3 {
                0 => Kinematics::new(&skeleton),
                1 => Kinematics::new(&skeleton).with_bone_offsets(&offsets),
                _ => Kinematics::new(&skeleton)
                    .with_bone_offsets(&offsets)
                    .with_translating_joints(&translating),
            };
            let angles = random_angles(&skeleton, &mut rng);
            let root =
                Quat::from_euler(glam::EulerRot::YXZ, rng.random_range(-3.0..3.0), 0.3, -0.2);
            let shift = DVec3::new(0.4, -0.1, 1.3);
            let mut a64: Vec<f64> = angles.iter().map(|&x| f64::from(x)).collect();
            a64.resize_with(kin.param_count(), || rng.random_range(-0.3..0.3));
            kin.world_matrices(root.as_dquat(), &a64, &mut ours);
            let pose = kin.pose(&skeleton, root.as_dquat(), shift, &a64).unwrap();
            skeleton.world_matrices(&pose, &mut theirs).unwrap();
            for (o, t) in ours.iter().zip(&theirs) {
                let o = o.as_mat4();
                let p = o.w_axis.truncate() + shift.as_vec3();
                assert!(
                    p.distance(t.w_axis.truncate()) < 1e-5,
                    "{p} vs {}",
                    t.w_axis
                );
                for c in 0..3 {
                    assert!(o.col(c).distance(t.col(c)) < 1e-5);
                }
            }
        }
    }

    #[test]
    fn exact_detections_recover_the_pose_to_near_machine_precision() {
        let skeleton = build_skeleton().unwrap();
        let kin = Kinematics::new(&skeleton);
        let rig = camera_rig(8, 256, 256, 1);
        // Every joint, plus two offset landmarks on the head (DeepCap's face landmarks).
        let head = skeleton.find("head").unwrap();
        let mut landmarks: Vec<Landmark> = (0..skeleton.len())
            .map(|joint| Landmark {
                joint,
                offset: DVec3::ZERO,
            })
            .collect();
        for x in [-0.04, 0.04] {
            landmarks.push(Landmark {
                joint: head,
                offset: DVec3::new(x, 0.1, 0.09),
            });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let angles: Vec<f64> = random_angles(&skeleton, &mut rng)
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        let root = DQuat::from_rotation_y(2.2);
        let shift = DVec3::new(0.15, 0.02, -0.1);
        let mut worlds = vec![DMat4::IDENTITY; skeleton.len()];
        let mut truth = vec![DVec3::ZERO; landmarks.len()];
        kin.landmarks(root, &angles, &landmarks, &mut worlds, &mut truth);
        let world: Vec<DVec3> = truth.iter().map(|p| *p + shift).collect();
        let detections = exact_detections(&rig.cameras, &world, 1.0);
        let (fit, worst) = fit_and_worst(&kin, &landmarks, &rig.cameras, &detections, &world);
        assert!(worst < 1e-9, "worst landmark {worst} m, {:?}", fit.report);
        assert!(fit.report.rms_inlier_px < 1e-8, "{:?}", fit.report);
        assert_eq!(fit.report.inliers, fit.report.detections);
    }

    /// A rig whose animation moves a joint by translation (here a foot and a hand, 3–6 cm off
    /// their bones) is fitted exactly once those joints translate, and not without.
    #[test]
    fn translating_joints_follow_a_joint_moved_off_its_bone() {
        let skeleton = build_skeleton().unwrap();
        let moved = [
            skeleton.find("l_ankle").unwrap(),
            skeleton.find("r_wrist").unwrap(),
        ];
        let kin = Kinematics::new(&skeleton).with_translating_joints(&moved);
        let landmarks: Vec<Landmark> =
            landmarks::landmarks_of(&landmarks::joint_side_landmark_map(&skeleton), &skeleton)
                .into_iter()
                .map(|(_, l)| l)
                .collect();
        let rig = camera_rig(8, 256, 256, 1);
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let mut params: Vec<f64> = random_angles(&skeleton, &mut rng)
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        // In units of 10 % of the skeleton's size (about 20 cm).
        params.extend([0.15, -0.1, 0.2, -0.2, 0.3, 0.1]);
        assert_eq!(params.len(), kin.param_count());
        let root = DQuat::from_rotation_y(0.8);
        let mut worlds = vec![DMat4::IDENTITY; skeleton.len()];
        let mut truth = vec![DVec3::ZERO; landmarks.len()];
        kin.landmarks(root, &params, &landmarks, &mut worlds, &mut truth);
        let detections = exact_detections(&rig.cameras, &truth, 1.0);

        let (fit, worst) = fit_and_worst(&kin, &landmarks, &rig.cameras, &detections, &truth);
        // The translations' weak prior pulls by a few micrometres.
        assert!(worst < 1e-4, "worst landmark {worst} m, {:?}", fit.report);
        let fixed = Kinematics::new(&skeleton);
        let (_, worst) = fit_and_worst(&fixed, &landmarks, &rig.cameras, &detections, &truth);
        assert!(
            worst > 0.02,
            "without translation: worst landmark {worst} m"
        );
    }

    #[test]
    fn a_left_right_swap_in_one_view_is_rejected_as_an_outlier() {
        use crate::track::synthetic::BODY_25_PAIRS;
        let skeleton = build_skeleton().unwrap();
        let kin = Kinematics::new(&skeleton);
        let rig = camera_rig(8, 256, 256, 1);
        let landmarks: Vec<Landmark> =
            landmarks::landmarks_of(&landmarks::default_landmark_map(&skeleton), &skeleton)
                .into_iter()
                .map(|(_, l)| l)
                .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let angles: Vec<f64> = random_angles(&skeleton, &mut rng)
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        let root = DQuat::from_rotation_y(-0.7);
        let mut worlds = vec![DMat4::IDENTITY; skeleton.len()];
        let mut truth = vec![DVec3::ZERO; landmarks.len()];
        kin.landmarks(root, &angles, &landmarks, &mut worlds, &mut truth);
        let mut detections = exact_detections(&rig.cameras, &truth, 0.9);
        // Wrists and ankles swapped in view 0.
        for &(a, b) in &[BODY_25_PAIRS[2], BODY_25_PAIRS[5]] {
            detections[0].swap(a, b);
        }
        let (fit, worst) = fit_and_worst(&kin, &landmarks, &rig.cameras, &detections, &truth);
        // The Geman–McClure weights of the four swapped detections are not exactly zero, so
        // they pull by a small residual amount: well under a millimetre.
        assert!(worst < 1e-3, "worst landmark {worst} m, {:?}", fit.report);
        assert_eq!(
            fit.report.detections - fit.report.inliers,
            4,
            "{:?}",
            fit.report
        );
    }
}
