//! Tracking a capture on disk: synthetic keypoints written into a capture, and the
//! frame-by-frame tracking of all its frames.

use std::ops::Range;

use glam::{DVec3, Mat4};
use skinfield_formats::capture::keypoints::{Keypoint2d, LandmarkMapFile};
use skinfield_formats::capture::{Capture, CaptureError, CaptureWriter, ClipEntry};
use skinfield_formats::{Pose, Skeleton, SkeletonError, StaticSkin};

use super::calibration::BoneCalibration;
use super::filter::{FilterError, MotionFilter};
use super::kinematics::{Kinematics, Landmark};
use super::landmarks::landmarks_of;
use super::mirror::left_right_pairs;
use super::silhouette::{BodySkinMismatch, TrackingBody};
use super::solve::{Detection, FrameFit, TrackError, TrackOptions, Tracker};
use super::synthetic::{DetectionNoise, detect, noise_rng};
use crate::template::hull::HullView;

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
    /// The temporal filter's setting (or the motion it was given) was refused.
    #[error("temporal filter: {0}")]
    Filter(#[from] FilterError),
    /// A clip named for the temporal filter is not in the manifest.
    #[error("temporal filter: the manifest has no clip `{0}` (field `clips`)")]
    FilterClip(String),
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
    let pairs: Vec<(usize, usize)> = left_right_pairs(map, &capture.skeleton)
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
    /// One pose per frame (after the temporal filter, [`TrackOptions::filter_sigma_frames`]).
    pub poses: Vec<Pose>,
    /// The fit of every frame (before the filter: its residuals are the fit's own).
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
/// a first pass's motion did not (`docs/experiments/tracking.md`). With
/// [`TrackOptions::filter_sigma_frames`], each clip's poses are then filtered over time
/// ([`super::filter`]). `progress` is called after each frame of the final fit.
pub fn track_capture(
    capture: &Capture,
    options: &TrackOptions,
    body_skin: Option<&StaticSkin>,
    mut progress: impl FnMut(usize),
) -> Result<TrackedMotion, CaptureTrackError> {
    let (filter, runs) = temporal_filter(options, &capture.manifest.clips)?;
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
        .collect::<Result<Vec<_>, _>>()?;
    let poses = filter.apply(&poses, &runs)?;
    Ok(TrackedMotion {
        poses,
        fits,
        calibration,
    })
}

/// The temporal filter of `options` ([`TrackOptions::filter_sigma_frames`]) and the frame runs
/// it filters: the clips of `clips` named in [`TrackOptions::filter_clips`], or every clip when
/// it names none. A caller that writes files first can check the settings with it beforehand.
///
/// # Errors
/// [`CaptureTrackError::Filter`] for a bad σ, [`CaptureTrackError::FilterClip`] for a name that
/// is not a clip of `clips`.
pub fn temporal_filter(
    options: &TrackOptions,
    clips: &[ClipEntry],
) -> Result<(MotionFilter, Vec<Range<usize>>), CaptureTrackError> {
    let filter = MotionFilter::new(options.filter_sigma_frames)?;
    if let Some(name) = options
        .filter_clips
        .iter()
        .find(|name| !clips.iter().any(|c| &c.name == *name))
    {
        return Err(CaptureTrackError::FilterClip(name.clone()));
    }
    let runs = clips
        .iter()
        .filter(|c| options.filter_clips.is_empty() || options.filter_clips.contains(&c.name))
        .map(|c| c.first..c.first + c.count)
        .collect();
    Ok((filter, runs))
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
pub(super) mod tests {
    use skinfield_formats::capture::load_capture;

    use super::*;
    use crate::track::landmarks::default_landmark_map;

    /// Detections without noise, drops or swaps.
    pub(in crate::track) const EXACT: DetectionNoise = DetectionNoise {
        sigma_px: 0.0,
        drop_rate: 0.0,
        swap_rate: 0.0,
        seed: 0,
    };

    /// A tiny synthetic capture (4 cameras at 96², one frame per clip) in `dir`, without
    /// keypoints.
    pub(in crate::track) fn tiny_capture(dir: &std::path::Path) -> Capture {
        tiny_capture_with_frames(dir, 1)
    }

    /// [`tiny_capture`] with `train_frames` frames per training clip.
    fn tiny_capture_with_frames(dir: &std::path::Path, train_frames: usize) -> Capture {
        let config = crate::synth::SynthConfig {
            cameras: 4,
            width: 96,
            height: 96,
            train_frames_per_clip: train_frames,
            ..crate::synth::SynthConfig::tiny()
        };
        crate::synth::synthesize(dir, &config).unwrap();
        load_capture(dir).unwrap()
    }

    /// `capture` (in `dir`) with exact keypoints of its default landmark map written into it.
    fn with_exact_keypoints(dir: &std::path::Path, capture: &Capture) -> Capture {
        write_synthetic_keypoints(capture, &default_landmark_map(&capture.skeleton), &EXACT)
            .unwrap();
        load_capture(dir).unwrap()
    }

    /// [`tiny_capture`] with exact keypoints of its default landmark map written into it.
    fn exact_keypoint_capture(dir: &std::path::Path) -> Capture {
        with_exact_keypoints(dir, &tiny_capture(dir))
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
    fn the_temporal_filter_runs_on_the_named_clips_only() {
        // Three frames per training clip, so that a clip has a frame with neighbours.
        let dir = tempfile::tempdir().unwrap();
        let capture = with_exact_keypoints(dir.path(), &tiny_capture_with_frames(dir.path(), 3));
        let keypoints_only = TrackOptions {
            silhouette_weight: 0.0,
            ..TrackOptions::default()
        };
        let raw = track_capture(&capture, &keypoints_only, None, |_| {}).unwrap();
        let clip = capture
            .manifest
            .clips
            .iter()
            .find(|c| c.count > 2)
            .unwrap()
            .clone();
        let filtered_options = TrackOptions {
            filter_sigma_frames: 1.0,
            filter_clips: vec![clip.name.clone()],
            ..keypoints_only.clone()
        };
        let filtered = track_capture(&capture, &filtered_options, None, |_| {}).unwrap();
        // Exactly the filter of the raw motion over that clip, every other frame as fitted.
        let range = clip.first..clip.first + clip.count;
        let expected = MotionFilter::new(1.0)
            .unwrap()
            .apply(&raw.poses, std::slice::from_ref(&range))
            .unwrap();
        assert_eq!(filtered.poses, expected);
        assert_eq!(filtered.fits, raw.fits);
        assert!(range.clone().any(|f| filtered.poses[f] != raw.poses[f]));
        for f in (0..capture.frame_count()).filter(|f| !range.contains(f)) {
            assert_eq!(filtered.poses[f], raw.poses[f], "frame {f}");
        }
        let unknown = TrackOptions {
            filter_clips: vec!["no such clip".into()],
            ..filtered_options
        };
        assert!(matches!(
            track_capture(&capture, &unknown, None, |_| {}),
            Err(CaptureTrackError::FilterClip(name)) if name == "no such clip"
        ));
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
}
