//! The `.skf` pose range (`PRNG`): the runtime clamps the pose features SkinNet sees into the
//! training poses' box, and nothing else.

mod common;

use common::{odd_config, random_model, random_points, random_pose, rng};
use skinfield_formats::skf::PoseRange;
use skinfield_formats::{pose_feature_count, pose_features};
use skinfield_runtime::{FrameState, SkinNetModel};

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn pose_features_are_clamped_into_the_files_training_range() {
    let config = odd_config();
    let mut m = random_model(config, 3);
    let mut rng = rng(4);
    let s = m.skeleton.clone();
    let n = pose_feature_count(s.len());
    let features = |pose| {
        let mut f = vec![0.0; n];
        pose_features(&s, pose, config.up_axis, &mut f).unwrap();
        f
    };
    // The training range: five mild poses.
    let training: Vec<_> = (0..5).map(|_| random_pose(&s, &mut rng, 0.3)).collect();
    let training_features: Vec<Vec<f32>> = training.iter().map(features).collect();
    m.pose_range = PoseRange::of(n, training_features.iter().map(|f| &f[..]));
    let range = m.pose_range.clone().unwrap();
    let ranged = SkinNetModel::from_skf(&m.to_bytes().unwrap()).unwrap();
    assert_eq!(ranged.pose_range().len(), n);
    let mut plain_model = m.clone();
    plain_model.pose_range = None;
    let plain = SkinNetModel::from_skf(&plain_model.to_bytes().unwrap()).unwrap();
    assert!(plain.pose_range().is_empty());

    // A wild pose leaves the range; the frame holds its features clamped, feature by feature,
    // and the same skinning matrices as without a range.
    let wild = random_pose(&s, &mut rng, 2.0);
    let raw = features(&wild);
    let outside = (0..n)
        .filter(|&i| raw[i] < range.low[i] || raw[i] > range.high[i])
        .count();
    assert!(outside > n / 4, "only {outside} of {n} features outside");
    let mut frame = FrameState::new(&ranged);
    frame.set_pose(&ranged, &wild).unwrap();
    for (i, (&got, &v)) in frame.features().iter().zip(&raw).enumerate() {
        assert_eq!(got, v.clamp(range.low[i], range.high[i]), "feature {i}");
    }
    let mut plain_frame = FrameState::new(&plain);
    plain_frame.set_pose(&plain, &wild).unwrap();
    assert_eq!(frame.palette().matrices(), plain_frame.palette().matrices());

    // Inside the range nothing changes: at a training pose the weights are the plain model's.
    let points = random_points(64, &mut rng);
    let weights = |model: &SkinNetModel, pose| {
        let mut out = vec![0.0; points.len() * model.joint_count()];
        model.weights_for(&points, pose, &mut out).unwrap();
        out
    };
    assert_eq!(
        weights(&ranged, &training[2]),
        weights(&plain, &training[2])
    );
    // Outside it they differ (the network does depend on the pose) …
    assert!(max_abs_diff(&weights(&ranged, &wild), &weights(&plain, &wild)) > 1e-3);
    // … and a range collapsed onto the bind pose (all features zero) gives every pose the
    // bind pose's weights.
    let mut frozen = m.clone();
    frozen.pose_range = Some(PoseRange {
        low: vec![0.0; n],
        high: vec![0.0; n],
    });
    let frozen = SkinNetModel::from_skf(&frozen.to_bytes().unwrap()).unwrap();
    let bind = s.bind_pose();
    assert!(max_abs_diff(&features(&bind), &vec![0.0; n]) < 1e-6);
    let at_bind = weights(&plain, &bind);
    for pose in [&wild, &training[0]] {
        let d = max_abs_diff(&weights(&frozen, pose), &at_bind);
        assert!(d < 1e-5, "{d}");
    }
}
