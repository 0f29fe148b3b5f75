//! The tracker's per-frame fit and its skeleton calibration with the chain-rule Jacobian,
//! against the reference measured in the same run: the same solver with central differences of
//! the whole residual (`JacobianMethod::Differences`), the method the chain rule replaced.
//!
//! The built-in skeleton (24 joints) seen by 12 cameras at 256², a joint + side-point detector
//! (a keypoint per joint, one beside it, one at each leaf's tip) at the reference corruption
//! (2 px, 10 % dropped, 1 % swapped); keypoints only (the silhouette term needs a capture on
//! disk, see `docs/experiments/tracking.md` for its wall-clock figures).
//!
//! `cargo bench -p skinfield-benches --bench track`

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{DMat4, DQuat, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::JointDofs;
use skinfield_trainer::synth::character::build_skeleton;
use skinfield_trainer::synth::rig::camera_rig;
use skinfield_trainer::track::landmarks::{joint_side_landmark_map, landmarks_of};
use skinfield_trainer::track::mirror::left_right_pairs;
use skinfield_trainer::track::synthetic::{DetectionNoise, detect, noise_rng};
use skinfield_trainer::track::{
    Detection, JacobianMethod, Kinematics, Landmark, TrackOptions, Tracker,
};

/// Detections of every frame: `[frame][camera][landmark]`.
type Frames = Vec<Vec<Vec<Option<Detection>>>>;

fn bench(c: &mut Criterion) {
    let skeleton = build_skeleton().expect("built-in skeleton");
    let map = joint_side_landmark_map(&skeleton);
    let (keypoints, landmarks): (Vec<usize>, Vec<Landmark>) =
        landmarks_of(&map, &skeleton).into_iter().unzip();
    let pairs: Vec<(usize, usize)> = left_right_pairs(&map, &skeleton)
        .into_iter()
        .filter_map(|(a, b)| {
            let a = keypoints.iter().position(|&k| k == a)?;
            let b = keypoints.iter().position(|&k| k == b)?;
            Some((a, b))
        })
        .collect();
    let rig = camera_rig(12, 256, 256, 1);
    let kinematics = Kinematics::new(&skeleton);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut noise_state = noise_rng(&DetectionNoise::REFERENCE);
    let mut worlds = vec![DMat4::IDENTITY; skeleton.len()];
    let mut points = vec![DVec3::ZERO; landmarks.len()];
    let frames: Frames = (0..8)
        .map(|_| {
            let root = DQuat::from_rotation_y(rng.random_range(-3.0..3.0));
            let angles: Vec<f64> = skeleton
                .dofs()
                .iter()
                .flat_map(|d| match d {
                    JointDofs::Euler { limits, .. } => limits
                        .iter()
                        .map(|l| f64::from(rng.random_range(l[0] * 0.8..=l[1] * 0.8 + 1e-6)))
                        .collect::<Vec<_>>(),
                    other => (0..other.count())
                        .map(|_| rng.random_range(-0.5..0.5))
                        .collect(),
                })
                .collect();
            kinematics.landmarks(root, &angles, &landmarks, &mut worlds, &mut points);
            detect(
                &rig.cameras,
                &points,
                &pairs,
                &DetectionNoise::REFERENCE,
                &mut noise_state,
            )
        })
        .collect();
    let tracker = |jacobian| {
        Tracker::new(
            kinematics.clone(),
            landmarks.clone(),
            &rig.cameras,
            DVec3::Y,
            TrackOptions {
                jacobian,
                ..TrackOptions::default()
            },
        )
    };
    let methods = [
        ("chain_rule", JacobianMethod::ChainRule),
        ("differences", JacobianMethod::Differences),
    ];
    let mut group = c.benchmark_group("track");
    group.sample_size(10);
    for (name, method) in methods {
        let t = tracker(method);
        group.bench_function(format!("fit_first_frame/{name}/builtin_joint_sides"), |b| {
            b.iter(|| t.fit(&frames[0], None).expect("fit"));
        });
    }
    let fits: Vec<_> = {
        let t = tracker(JacobianMethod::ChainRule);
        frames
            .iter()
            .map(|f| t.fit(f, None).expect("fit"))
            .collect()
    };
    for (name, method) in methods {
        let t = tracker(method);
        group.bench_function(format!("fit_next_frame/{name}/builtin_joint_sides"), |b| {
            b.iter(|| t.fit(&frames[1], Some(&fits[0])).expect("fit"));
        });
    }
    let pairs: Vec<_> = frames.iter().map(Vec::as_slice).zip(&fits).collect();
    for (name, method) in methods {
        let t = tracker(method);
        group.bench_function(format!("calibrate_bones/{name}/builtin_8_frames"), |b| {
            b.iter(|| t.calibrate_bones(&pairs).expect("calibration"));
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
