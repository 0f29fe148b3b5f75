//! Trainer export → runtime: for random canonical points and poses, the runtime's CPU weights from
//! the exported `.skf` equal candle's forward pass within 1e-3 (the file stores f16 weights).

use glam::{Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::math::Transform;
use skinfield_formats::skf::ModelConfig;
use skinfield_formats::{Pose, Skeleton, pose_features};
use skinfield_runtime::SkinNetModel;
use skinfield_trainer::skinnet::TrainableSkinNet;
use skinfield_trainer::skinnet::export::to_skf_model;

const JOINTS: usize = 6;

fn skeleton() -> Skeleton {
    let names = (0..JOINTS).map(|i| format!("j{i}")).collect();
    // A small tree: 0 → 1 → 2, 0 → 3 → 4, 0 → 5.
    let parents = vec![None, Some(0), Some(1), Some(0), Some(3), Some(0)];
    let offsets = [
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.2, 0.3, 0.0),
        Vec3::new(0.0, 0.3, 0.0),
        Vec3::new(-0.2, 0.3, 0.0),
        Vec3::new(0.0, 0.3, 0.0),
        Vec3::new(0.0, 0.4, 0.05),
    ];
    let bind = offsets
        .iter()
        .map(|&t| Transform {
            translation: t,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        })
        .collect();
    Skeleton::new(names, parents, bind, None, None, Mat4::IDENTITY).unwrap()
}

#[test]
fn runtime_cpu_weights_equal_candle_forward_on_the_exported_file() {
    let skel = skeleton();
    let config = ModelConfig::paper_architecture(JOINTS as u32, [-0.6, 0.0, -0.3], [0.6, 1.9, 0.3]);
    // Output scale 40: far from uniform weights, so a wrong layer would show.
    let (net, _vars) = TrainableSkinNet::seeded(config, 42, 40.0).unwrap();
    let bytes = to_skf_model(&net, &skel).unwrap().to_bytes().unwrap();

    let mut rng = ChaCha8Rng::seed_from_u64(7);
    // Points inside the box and a little outside it (the runtime must extrapolate the same way).
    let points: Vec<Vec3> = (0..300)
        .map(|_| {
            Vec3::new(
                rng.random_range(-0.7..0.7),
                rng.random_range(-0.1..2.0),
                rng.random_range(-0.35..0.35),
            )
        })
        .collect();
    let mut worst = 0.0f32;
    let mut spread = 0.0f32;
    for _ in 0..4 {
        let mut pose = skel.bind_pose();
        for (j, local) in pose.locals.iter_mut().enumerate() {
            let axis = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .normalize();
            local.rotation =
                Quat::from_axis_angle(axis, rng.random_range(-1.2..1.2)) * local.rotation;
            if j == 0 {
                local.translation += Vec3::new(
                    rng.random_range(-1.0..1.0),
                    0.0,
                    rng.random_range(-1.0..1.0),
                );
            }
        }
        let mut feats = vec![0.0; 3 * JOINTS];
        pose_features(&skel, &pose, config.up_axis, &mut feats).unwrap();
        let ours = net.evaluate(&points, &[feats]).unwrap();
        let theirs = SkinNetModel::weights_for_skf(
            &bytes,
            &points,
            &Pose {
                locals: pose.locals.clone(),
            },
        )
        .unwrap();
        assert_eq!(ours.len(), theirs.len());
        for (a, b) in ours.iter().zip(&theirs) {
            worst = worst.max((a - b).abs());
            spread = spread.max((a - 1.0 / JOINTS as f32).abs());
        }
    }
    eprintln!("export → runtime: max |Δw| = {worst:.2e}, max |w − 1/J| = {spread:.3}");
    assert!(worst < 1e-3, "runtime and candle differ by {worst}");
    assert!(
        spread > 0.1,
        "weights too uniform for a meaningful check ({spread})"
    );
}
