//! Candidate joints end to end: a SkinNet exported with anchors and candidate lists (`CAND`)
//! evaluates in the runtime exactly as the trainer's masked forward pass does for the same
//! points (each point with its nearest anchor's list), and every non-candidate weight is zero.

use candle_core::{Device, Tensor};
use glam::{Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::math::Transform;
use skinfield_formats::skf::{Candidates, ModelConfig, SkfView};
use skinfield_formats::{Skeleton, UpAxis, pose_features};
use skinfield_runtime::SkinNetModel;
use skinfield_runtime::candidates::nearest_anchors;
use skinfield_trainer::candidates::additive_mask;
use skinfield_trainer::skinnet::export::to_skf_model;
use skinfield_trainer::skinnet::{TrainableSkinNet, position_inputs_tensor};

fn chain(j: usize) -> Skeleton {
    let t = Transform {
        translation: Vec3::new(0.0, 0.3, 0.0),
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    };
    Skeleton::new(
        (0..j).map(|i| format!("j{i}")).collect(),
        (0..j).map(|i| i.checked_sub(1)).collect(),
        vec![t; j],
        None,
        None,
        Mat4::IDENTITY,
    )
    .unwrap()
}

#[test]
fn runtime_masked_weights_equal_the_trainers() {
    let j = 6;
    let config = ModelConfig::paper_architecture(j as u32, [-1.0; 3], [1.0; 3]);
    let (net, _vars) = TrainableSkinNet::seeded(config, 4, 3.0).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut point = || {
        Vec3::new(
            rng.random_range(-0.9..0.9),
            rng.random_range(-0.9..0.9),
            rng.random_range(-0.9..0.9),
        )
    };
    let anchors: Vec<Vec3> = (0..25).map(|_| point()).collect();
    let lists: Vec<Vec<u16>> = (0..25)
        .map(|a| {
            let first = (a % (j - 1)) as u16;
            if a % 3 == 0 {
                vec![first]
            } else {
                vec![first, first + 1]
            }
        })
        .collect();
    let points: Vec<Vec3> = (0..60).map(|_| point()).collect();
    let skeleton = chain(j);
    let mut model = to_skf_model(&net, &skeleton).unwrap();
    model.candidates = Some(Candidates {
        positions: anchors.iter().map(|p| p.to_array()).collect(),
        lists: lists.clone(),
        k: 3,
    });
    let bytes = model.to_bytes().unwrap();
    assert_eq!(SkfView::parse(&bytes).unwrap().minor_version(), 1);
    let runtime = SkinNetModel::from_skf(&bytes).unwrap();

    let angles: Vec<f32> = (0..skeleton.angle_count())
        .map(|i| 0.2 * (i % 5) as f32 - 0.4)
        .collect();
    let pose = skeleton
        .pose_from_angles(Quat::from_rotation_z(0.3), Vec3::ZERO, &angles)
        .unwrap();
    let mut got = vec![0.0f32; points.len() * j];
    runtime.weights_for(&points, &pose, &mut got).unwrap();

    let nearest = nearest_anchors(&anchors, &points);
    let rows: Vec<Vec<u16>> = nearest.iter().map(|&a| lists[a as usize].clone()).collect();
    let mask = Tensor::from_vec(additive_mask(&rows, j), (points.len(), j), &Device::Cpu).unwrap();
    let mut features = vec![0.0f32; 3 * j];
    pose_features(&skeleton, &pose, UpAxis::Y, &mut features).unwrap();
    let want = net
        .forward_masked(
            &position_inputs_tensor(&config, &points, &Device::Cpu).unwrap(),
            &Tensor::from_vec(features, (1, 3 * j), &Device::Cpu).unwrap(),
            Some(&mask),
        )
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f32>()
        .unwrap();
    let mut spread = 0.0f32;
    for (v, row) in rows.iter().enumerate() {
        let sum: f32 = got[v * j..(v + 1) * j].iter().sum();
        assert!((sum - 1.0).abs() < 1e-5, "vertex {v}: weights sum to {sum}");
        for k in 0..j {
            let (g, w) = (got[v * j + k], want[v * j + k]);
            if !row.contains(&(k as u16)) {
                assert_eq!(g, 0.0, "vertex {v} joint {k} is not a candidate");
            }
            // f16 storage of the weights: ~1e-3.
            assert!(
                (g - w).abs() < 2e-3,
                "vertex {v} joint {k}: runtime {g}, trainer {w}"
            );
            spread = spread.max((w - 0.5).abs());
        }
    }
    assert!(
        spread > 0.1,
        "weights too uniform for the check to mean anything"
    );
}
