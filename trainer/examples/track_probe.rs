//! Lab probe for `trainer track` (issue 21): tracks the built-in character's motion library from
//! synthetic BODY_25 detections and prints the mean per-joint position error (MPJPE) against
//! the true motion, for several noise levels and camera counts.
//!
//! ```text
//! cargo run --release -p skinfield-trainer --example track_probe [-- --worst]
//! ```
//!
//! Every row: the built-in skeleton (24 joints), the motion library's 80 training and 24 test
//! frames (seed 0), cameras of `trainer synth` (256², seed 1), detections with the given pixel
//! noise, 10 % dropped and 1 % left/right swaps per view and pair (seed 0). Frames are tracked
//! in order; a frame starts from the previous one of its clip, the first of a clip from a
//! heading search. MPJPE over all 24 joints, in cm.
use std::time::Instant;

use glam::{DVec3, Mat4};
use skinfield_trainer::synth::character::build_skeleton;
use skinfield_trainer::synth::motion::{TestMotions, library};
use skinfield_trainer::synth::rig::camera_rig;
use skinfield_trainer::track::capture::mpjpe;
use skinfield_trainer::track::landmarks::{default_landmark_map, landmarks_of};
use skinfield_trainer::track::synthetic::{BODY_25_PAIRS, DetectionNoise, detect, noise_rng};
use skinfield_trainer::track::{FrameFit, Kinematics, Landmark, TrackOptions, Tracker};

fn main() {
    // `-- --worst`: also print every frame whose MPJPE exceeds 5 cm.
    let verbose = std::env::args().any(|a| a == "--worst");
    let skeleton = build_skeleton().unwrap();
    let kin = Kinematics::new(&skeleton);
    let frames = library(&skeleton, 16, 8, TestMotions::Novel, 0).unwrap();
    let landmarks: Vec<Landmark> = landmarks_of(&default_landmark_map(&skeleton), &skeleton)
        .into_iter()
        .map(|(_, l)| l)
        .collect();
    let rows: Vec<(f64, usize)> = vec![
        (0.0, 12),
        (1.0, 12),
        (2.0, 12),
        (4.0, 12),
        (2.0, 4),
        (2.0, 8),
    ];
    println!(
        "| noise (px) | cameras | MPJPE (cm) | worst frame MPJPE (cm) | median reprojection (px) | seconds |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    let mut worlds = vec![Mat4::IDENTITY; skeleton.len()];
    for (sigma, cams) in rows {
        let rig = camera_rig(cams, 256, 256, 1);
        let noise = DetectionNoise {
            sigma_px: sigma,
            ..DetectionNoise::REFERENCE
        };
        let mut rng = noise_rng(&noise);
        let tracker = Tracker::new(
            kin.clone(),
            landmarks.clone(),
            &rig.cameras,
            DVec3::Y,
            TrackOptions::default(),
        );
        let start = Instant::now();
        let mut previous: Option<(usize, FrameFit)> = None;
        let (mut sum, mut worst, mut count) = (0.0, 0.0f64, 0);
        let mut medians = Vec::new();
        for f in &frames {
            skeleton.world_matrices(&f.pose, &mut worlds).unwrap();
            let truth: Vec<DVec3> = landmarks
                .iter()
                .map(|l| worlds[l.joint].as_dmat4().transform_point3(l.offset))
                .collect();
            let detections = detect(&rig.cameras, &truth, &BODY_25_PAIRS, &noise, &mut rng);
            let prev = previous
                .as_ref()
                .filter(|(c, _)| *c == f.clip)
                .map(|(_, p)| p);
            let fit = tracker.fit(&detections, prev).unwrap();
            let tracked = kin
                .pose(&skeleton, fit.root_rotation, fit.world_shift, &fit.angles)
                .unwrap();
            let err = mpjpe(&skeleton, &[tracked], std::slice::from_ref(&f.pose)).unwrap()[0];
            if verbose && err > 0.05 {
                eprintln!(
                    "  σ {sigma} px, {cams} cameras: frame of clip {} MPJPE {:.2} cm, {:?}",
                    f.clip,
                    100.0 * err,
                    fit.report
                );
            }
            sum += err;
            worst = worst.max(err);
            count += 1;
            medians.push(fit.report.median_px);
            previous = Some((f.clip, fit));
        }
        medians.sort_by(f64::total_cmp);
        println!(
            "| {sigma} | {cams} | {:.2} | {:.2} | {:.2} | {:.1} |",
            100.0 * sum / count as f64,
            100.0 * worst,
            medians[medians.len() / 2],
            start.elapsed().as_secs_f64()
        );
    }
}
