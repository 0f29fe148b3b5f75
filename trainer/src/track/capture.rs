//! Tracking a capture on disk: the landmark map of a skeleton, synthetic keypoints written into
//! a capture, and the frame-by-frame tracking of all its frames.

use glam::{DMat4, DVec3, Mat4};
use skinfield_formats::capture::keypoints::{BODY_25, Keypoint2d, LandmarkEntry, LandmarkMapFile};
use skinfield_formats::capture::{Capture, CaptureError, CaptureWriter};
use skinfield_formats::{Pose, Skeleton, SkeletonError, StaticSkin, Template};

use super::calibration::BoneCalibration;
use super::kinematics::{Kinematics, Landmark};
use super::silhouette::{BodySkinMismatch, TrackingBody};
use super::solve::{Detection, FrameFit, TrackError, TrackOptions, Tracker};
use super::synthetic::{BODY_25_PAIRS, BUILT_IN_BODY_25, DetectionNoise, detect, noise_rng};
use crate::template::hull::HullView;
use crate::triangle_bvh::TriangleBvh;

/// Folder the synthetic keypoints go to, relative to the capture.
pub const KEYPOINTS_FOLDER: &str = "keypoints";

/// Why tracking a capture failed.
#[derive(Debug, thiserror::Error)]
pub enum CaptureTrackError {
    /// Reading or writing the capture.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// The capture has no keypoints.
    #[error("the capture has no keypoints (manifest field `keypoints`)")]
    NoKeypoints,
    /// A frame could not be fitted.
    #[error("frame {frame}: {source}")]
    Frame {
        /// The frame.
        frame: usize,
        /// Why.
        source: TrackError,
    },
    /// A joint asked to translate is not a non-root joint of the skeleton.
    #[error("translating joint `{0}`: the skeleton has no such non-root joint")]
    TranslatingJoint(String),
    /// The skeleton calibration failed.
    #[error("skeleton calibration: {0}")]
    Calibration(TrackError),
    /// A pose did not fit the skeleton.
    #[error(transparent)]
    Skeleton(#[from] SkeletonError),
    /// The silhouette term's body could not be skinned (initial weights).
    #[error("the silhouette term's body: {0}")]
    Body(#[from] crate::train::data::DataError),
    /// The weights given for the silhouette term's body do not fit the capture.
    #[error(transparent)]
    BodySkin(#[from] BodySkinMismatch),
    /// A mask has no outline for the silhouette term.
    #[error("frame {frame}, camera {camera}: mask: {source}")]
    Mask {
        /// The frame.
        frame: usize,
        /// The camera index.
        camera: usize,
        /// Why.
        source: crate::losses::silhouette::OutlineError,
    },
}

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
    side_landmark_map(skeleton, "joints+sides", |_, offset| offset)
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
    side_landmark_map(skeleton, "joints+surface", |j, offset| {
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

/// One keypoint per joint plus `{joint}.side` (and `{joint}.tip` for leaves) at the quarter-bone
/// offsets of [`joint_side_landmark_map`], each passed through `place(joint, offset)` (the
/// joint's local frame) before it is stored.
fn side_landmark_map(
    skeleton: &Skeleton,
    detector: &str,
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
        add("side", side);
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

/// Left/right keypoint pairs of a map (BODY_25's, or joints named `l_*`/`r_*`, `Left*`/`Right*`
/// or `*.L`/`*.R`), the pairs a synthetic swap exchanges.
#[must_use]
pub fn left_right_pairs(map: &LandmarkMapFile) -> Vec<(usize, usize)> {
    if map.detector == "BODY_25" {
        return BODY_25_PAIRS.to_vec();
    }
    let mirror = |n: &str| -> Option<String> {
        for (l, r) in [("l_", "r_"), ("Left", "Right"), ("left", "right")] {
            if let Some(rest) = n.strip_prefix(l) {
                return Some(format!("{r}{rest}"));
            }
        }
        n.strip_suffix(".L").map(|rest| format!("{rest}.R"))
    };
    let k = &map.keypoints;
    (0..k.len())
        .filter_map(|i| {
            let m = mirror(&k[i])?;
            let j = k.iter().position(|n| *n == m)?;
            Some((i, j))
        })
        .collect()
}

/// World positions of `landmarks` in `pose` (f32 forward kinematics, widened).
fn landmark_positions(
    skeleton: &Skeleton,
    pose: &Pose,
    landmarks: &[(usize, Landmark)],
    worlds: &mut [Mat4],
) -> Result<Vec<DVec3>, SkeletonError> {
    skeleton.world_matrices(pose, worlds)?;
    Ok(landmarks
        .iter()
        .map(|(_, l)| worlds[l.joint].as_dmat4().transform_point3(l.offset))
        .collect())
}

/// Writes synthetic detections of every frame and camera into the capture (its `keypoints`
/// folder and landmark map), projected from the capture's motion with `noise`, and sets the
/// manifest's `keypoints` field.
pub fn write_synthetic_keypoints(
    capture: &Capture,
    map: &LandmarkMapFile,
    noise: &DetectionNoise,
) -> Result<(), CaptureTrackError> {
    capture.require_motion()?;
    let mut manifest = capture.manifest.clone();
    manifest.keypoints = Some(KEYPOINTS_FOLDER.into());
    let writer = CaptureWriter::new(&capture.dir, manifest)?;
    writer.write_landmark_map(map)?;
    let landmarks = landmarks_of(map, &capture.skeleton);
    // Pairs of keypoints, as pairs of landmark slots (the order `detect` sees).
    let slot = |k: usize| landmarks.iter().position(|(i, _)| *i == k);
    let pairs: Vec<(usize, usize)> = left_right_pairs(map)
        .into_iter()
        .filter_map(|(a, b)| Some((slot(a)?, slot(b)?)))
        .collect();
    let mut rng = noise_rng(noise);
    let mut worlds = vec![Mat4::IDENTITY; capture.skeleton.len()];
    for (frame, pose) in capture.poses.iter().enumerate() {
        let points = landmark_positions(&capture.skeleton, pose, &landmarks, &mut worlds)?;
        let views = detect(&capture.rig.cameras, &points, &pairs, noise, &mut rng);
        for (cam, view) in views.iter().enumerate() {
            let mut keypoints = vec![None; map.keypoints.len()];
            for ((k, _), d) in landmarks.iter().zip(view) {
                keypoints[*k] = d.map(|d| Keypoint2d {
                    x: d.pixel.x as f32,
                    y: d.pixel.y as f32,
                    confidence: d.confidence as f32,
                });
            }
            writer.write_keypoints(cam, frame, &keypoints)?;
        }
    }
    writer.finish()?;
    Ok(())
}

/// One tracked capture.
#[derive(Clone, Debug)]
pub struct TrackedMotion {
    /// One pose per frame.
    pub poses: Vec<Pose>,
    /// The fit of every frame.
    pub fits: Vec<FrameFit>,
    /// The last skeleton calibration ([`TrackOptions::calibration_rounds`]); its offsets are in
    /// the poses' local translations. `None` without calibration.
    pub calibration: Option<BoneCalibration>,
}

/// Tracks every frame of `capture` from its keypoints, in frame order; a frame starts from the
/// previous one when both belong to the same clip (the manifest's clips), otherwise from a
/// heading search. With [`TrackOptions::calibration_rounds`], the skeleton's bones are first
/// calibrated to the keypoints ([`super::calibration`]). The silhouette term's body is the
/// template skinned with `body_skin` (one row per template vertex), or with the capture's
/// initial weights (bone heat when it ships none) when `None`. A body closer to the truth
/// biases the outline fit less (the true weights do, on CesiumMan); static weights learned from
/// a first pass's motion did not (`docs/experiments/tracking.md`). `progress` is called after
/// each frame of the final fit.
pub fn track_capture(
    capture: &Capture,
    options: &TrackOptions,
    body_skin: Option<&StaticSkin>,
    mut progress: impl FnMut(usize),
) -> Result<TrackedMotion, CaptureTrackError> {
    let map = capture
        .landmark_map()?
        .ok_or(CaptureTrackError::NoKeypoints)?;
    let landmarks = landmarks_of(&map, &capture.skeleton);
    let body = if options.silhouette_weight > 0.0 {
        let initial;
        let skin = match body_skin {
            Some(skin) => skin,
            None => {
                initial = crate::train::data::initial_weights(capture)?;
                &initial
            }
        };
        Some(TrackingBody::new(
            &capture.template,
            skin,
            &capture.skeleton,
        )?)
    } else {
        None
    };
    let mut detections = Vec::with_capacity(capture.frame_count());
    for frame in 0..capture.frame_count() {
        let mut views = Vec::with_capacity(capture.rig.cameras.len());
        for cam in 0..capture.rig.cameras.len() {
            let k = capture.keypoints(cam, frame, map.keypoints.len())?;
            views.push(
                landmarks
                    .iter()
                    .map(|(i, _)| {
                        k[*i].map(|d| Detection {
                            pixel: glam::DVec2::new(f64::from(d.x), f64::from(d.y)),
                            confidence: f64::from(d.confidence),
                        })
                    })
                    .collect::<Vec<_>>(),
            );
        }
        detections.push(views);
    }
    let translating = options
        .translating_joints
        .iter()
        .map(|name| {
            capture
                .skeleton
                .find(name)
                .filter(|&j| capture.skeleton.parents()[j].is_some())
                .ok_or_else(|| CaptureTrackError::TranslatingJoint(name.clone()))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut tracker = Tracker::new(
        Kinematics::new(&capture.skeleton).with_translating_joints(&translating),
        landmarks.iter().map(|(_, l)| *l).collect(),
        &capture.rig.cameras,
        capture.up_axis.unit().as_dvec3(),
        options.clone(),
    );
    let mut calibration = None;
    for _ in 0..options.calibration_rounds {
        let fits = fit_frames(capture, &tracker, &detections, false, |_| {})?;
        let frames: Vec<_> = detections.iter().map(Vec::as_slice).zip(&fits).collect();
        let c = tracker
            .calibrate_bones(&frames)
            .map_err(CaptureTrackError::Calibration)?;
        tracker = tracker.with_bone_offsets(&c.offsets);
        calibration = Some(c);
    }
    if let Some(body) = &body {
        tracker = tracker.with_body(body);
    }
    let fits = fit_frames(
        capture,
        &tracker,
        &detections,
        body.is_some(),
        &mut progress,
    )?;
    let poses = fits
        .iter()
        .map(|fit| {
            tracker.kinematics().pose(
                &capture.skeleton,
                fit.root_rotation,
                fit.world_shift,
                &fit.angles,
            )
        })
        .collect::<Result<_, _>>()?;
    Ok(TrackedMotion {
        poses,
        fits,
        calibration,
    })
}

/// Fits every frame of `capture` in order with `tracker` (each frame from its clip's previous
/// one), with the masks for the silhouette term when `with_masks`.
fn fit_frames(
    capture: &Capture,
    tracker: &Tracker<'_>,
    detections: &[Vec<Vec<Option<Detection>>>],
    with_masks: bool,
    mut progress: impl FnMut(usize),
) -> Result<Vec<FrameFit>, CaptureTrackError> {
    let clip_of = |f: usize| {
        capture
            .manifest
            .clips
            .iter()
            .position(|c| (c.first..c.first + c.count).contains(&f))
    };
    let mut fits: Vec<FrameFit> = Vec::with_capacity(detections.len());
    for (frame, views) in detections.iter().enumerate() {
        let previous =
            (frame > 0 && clip_of(frame).is_some() && clip_of(frame) == clip_of(frame - 1))
                .then(|| &fits[frame - 1]);
        let masks = if with_masks {
            Some(frame_masks(capture, frame)?)
        } else {
            None
        };
        let fit = tracker
            .fit_with_masks(views, previous, masks.as_deref())
            .map_err(|source| CaptureTrackError::Frame { frame, source })?;
        fits.push(fit);
        progress(frame);
    }
    Ok(fits)
}

/// Every camera's mask of `frame` with its outline, for the silhouette term.
fn frame_masks(capture: &Capture, frame: usize) -> Result<Vec<HullView>, CaptureTrackError> {
    (0..capture.rig.cameras.len())
        .map(|camera| {
            let mask = capture.load_mask(camera, frame)?;
            HullView::new(capture.rig.cameras[camera].clone(), mask.coverage).map_err(|source| {
                CaptureTrackError::Mask {
                    frame,
                    camera,
                    source,
                }
            })
        })
        .collect()
}

/// Mean per-joint position error between two motions of the same skeleton, per frame (units
/// of the skeleton).
pub fn mpjpe(skeleton: &Skeleton, a: &[Pose], b: &[Pose]) -> Result<Vec<f64>, SkeletonError> {
    per_frame_joint_mean(skeleton, a, b, |x, y| {
        f64::from(x.w_axis.truncate().distance(y.w_axis.truncate()))
    })
}

/// Mean over joints of the angle (degrees) between two motions' world rotations of each joint,
/// per frame. MPJPE does not see a leaf's turn (the head, a foot, a hand move no joint), which
/// is what the surface turns with; this does.
pub fn mean_turn_error_deg(
    skeleton: &Skeleton,
    a: &[Pose],
    b: &[Pose],
) -> Result<Vec<f64>, SkeletonError> {
    per_frame_joint_mean(skeleton, a, b, |x, y| {
        let (_, qa, _) = x.to_scale_rotation_translation();
        let (_, qb, _) = y.to_scale_rotation_translation();
        f64::from(qa.angle_between(qb)).to_degrees()
    })
}

/// Per frame, the mean over joints of `measure(world_a, world_b)`.
fn per_frame_joint_mean(
    skeleton: &Skeleton,
    a: &[Pose],
    b: &[Pose],
    measure: impl Fn(&Mat4, &Mat4) -> f64,
) -> Result<Vec<f64>, SkeletonError> {
    let mut wa = vec![Mat4::IDENTITY; skeleton.len()];
    let mut wb = vec![Mat4::IDENTITY; skeleton.len()];
    a.iter()
        .zip(b)
        .map(|(pa, pb)| {
            skeleton.world_matrices(pa, &mut wa)?;
            skeleton.world_matrices(pb, &mut wb)?;
            Ok(wa.iter().zip(&wb).map(|(x, y)| measure(x, y)).sum::<f64>()
                / skeleton.len().max(1) as f64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use skinfield_formats::capture::load_capture;

    use super::*;

    /// Detections without noise, drops or swaps.
    const EXACT: DetectionNoise = DetectionNoise {
        sigma_px: 0.0,
        drop_rate: 0.0,
        swap_rate: 0.0,
        seed: 0,
    };

    /// A tiny synthetic capture (4 cameras at 96²) in `dir`, without keypoints.
    fn tiny_capture(dir: &std::path::Path) -> Capture {
        let config = crate::synth::SynthConfig {
            cameras: 4,
            width: 96,
            height: 96,
            ..crate::synth::SynthConfig::tiny()
        };
        crate::synth::synthesize(dir, &config).unwrap();
        load_capture(dir).unwrap()
    }

    /// [`tiny_capture`] with exact keypoints of its default landmark map written into it.
    fn exact_keypoint_capture(dir: &std::path::Path) -> Capture {
        let capture = tiny_capture(dir);
        write_synthetic_keypoints(&capture, &default_landmark_map(&capture.skeleton), &EXACT)
            .unwrap();
        load_capture(dir).unwrap()
    }

    #[test]
    fn a_turn_of_the_root_turns_every_joint_by_its_angle() {
        let skeleton = crate::synth::character::build_skeleton().unwrap();
        let pose = skeleton.bind_pose();
        let mut turned = pose.clone();
        let root = skeleton.parents().iter().position(Option::is_none).unwrap();
        turned.locals[root].rotation =
            glam::Quat::from_rotation_y(10f32.to_radians()) * turned.locals[root].rotation;
        let e = mean_turn_error_deg(
            &skeleton,
            &[pose.clone(), turned.clone()],
            &[pose, turned.clone()],
        )
        .unwrap();
        assert!(e[0].abs() < 1e-3, "{e:?}");
        assert!(e[1].abs() < 1e-3, "{e:?}");
        let e = mean_turn_error_deg(&skeleton, &[turned], &[skeleton.bind_pose()]).unwrap();
        assert!((e[0] - 10.0).abs() < 1e-2, "{e:?}");
    }

    #[test]
    fn exact_keypoints_written_into_a_capture_track_back_to_its_motion() {
        let dir = tempfile::tempdir().unwrap();
        let capture = tiny_capture(dir.path());
        assert!(capture.landmark_map().unwrap().is_none());
        assert!(matches!(
            track_capture(&capture, &TrackOptions::default(), None, |_| {}),
            Err(CaptureTrackError::NoKeypoints)
        ));
        let map = default_landmark_map(&capture.skeleton);
        assert_eq!(map.detector, "BODY_25");
        write_synthetic_keypoints(&capture, &map, &EXACT).unwrap();
        let capture = load_capture(dir.path()).unwrap();
        assert_eq!(capture.landmark_map().unwrap().as_ref(), Some(&map));
        let mut frames = 0;
        // The keypoint layers alone: the silhouette refinement trades joint accuracy for the
        // outline of a body that cannot match the deformer's masks exactly (tested below).
        let keypoints_only = TrackOptions {
            silhouette_weight: 0.0,
            ..TrackOptions::default()
        };
        let tracked = track_capture(&capture, &keypoints_only, None, |_| frames += 1).unwrap();
        assert_eq!(frames, capture.frame_count());
        // Every detected landmark lands where it was (joints no keypoint sees, such as the
        // spine or the clavicles, are only determined up to the skeleton's null space, so MPJPE
        // over all joints is a measurement, not an identity).
        let landmarks = landmarks_of(&map, &capture.skeleton);
        let mut worlds = vec![Mat4::IDENTITY; capture.skeleton.len()];
        let mut worst = 0.0f64;
        for (got, want) in tracked.poses.iter().zip(&capture.poses) {
            let g = landmark_positions(&capture.skeleton, got, &landmarks, &mut worlds).unwrap();
            let w = landmark_positions(&capture.skeleton, want, &landmarks, &mut worlds).unwrap();
            for (a, b) in g.iter().zip(&w) {
                worst = worst.max(a.distance(*b));
            }
        }
        // f32 poses and pixels: micrometres.
        assert!(worst < 1e-5, "worst landmark {worst} m");
        let errors = mpjpe(&capture.skeleton, &tracked.poses, &capture.poses).unwrap();
        assert!(errors.iter().all(|e| *e < 1e-3), "{errors:?}");
    }

    #[test]
    fn the_silhouette_refinement_explains_the_masks_and_keeps_an_exact_fit() {
        let dir = tempfile::tempdir().unwrap();
        let capture = exact_keypoint_capture(dir.path());
        let oracle = capture.evaluation_true_weights().unwrap().unwrap();
        // A negligible weight measures the outline misfit of the keypoint fit itself.
        let track = |weight: f64, body: Option<&StaticSkin>| {
            let options = TrackOptions {
                silhouette_weight: weight,
                ..TrackOptions::default()
            };
            let tracked = track_capture(&capture, &options, body, |_| {}).unwrap();
            let rms: Vec<f64> = tracked
                .fits
                .iter()
                .map(|f| f.report.silhouette_rms_px.unwrap())
                .collect();
            let errors = mpjpe(&capture.skeleton, &tracked.poses, &capture.poses).unwrap();
            (rms.iter().sum::<f64>() / rms.len() as f64, errors)
        };
        let (before, _) = track(1e-9, None);
        let (after, errors) = track(1.0, None);
        // The body is the template under LBS with bone heat, the masks show DQS with bulges and
        // a skirt pushed out by the legs, so the outline cannot fit exactly. The refinement
        // must fit it better than the keypoints alone; it trades some joint accuracy for that
        // (measured: up to 2.1 cm on a frame at weight 1, where exact keypoints alone give
        // micrometres; with realistic detection noise it halves the joint error instead).
        assert!(
            after < before,
            "outline RMS {after} px after, {before} px before"
        );
        let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
        assert!(
            mean(&errors) < 0.015 && errors.iter().all(|e| *e < 0.03),
            "{errors:?}"
        );
        // A body skinned with the deformer's own weights is closer to the masks' shape: the
        // outline pulls the joints less far from the exact fit.
        let (_, oracle_errors) = track(1.0, Some(&oracle));
        assert!(
            mean(&oracle_errors) < mean(&errors),
            "oracle body {oracle_errors:?}, bone heat body {errors:?}"
        );
    }

    #[test]
    fn a_body_skin_that_does_not_fit_the_template_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let capture = exact_keypoint_capture(dir.path());
        let joints = capture.skeleton.len();
        let short = StaticSkin::from_dense(&vec![1.0 / joints as f32; 3 * joints], joints).unwrap();
        let e =
            track_capture(&capture, &TrackOptions::default(), Some(&short), |_| {}).unwrap_err();
        assert!(
            matches!(
                e,
                CaptureTrackError::BodySkin(BodySkinMismatch { vertices: 3, .. })
            ),
            "{e}"
        );
    }

    #[test]
    fn left_right_pairs_are_found_by_name() {
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
        assert_eq!(left_right_pairs(&map), vec![(1, 2), (3, 4), (5, 6)]);
    }

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
