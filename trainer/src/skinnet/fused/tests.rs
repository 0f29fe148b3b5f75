//! The fused op against candle's graph: forward values and the gradient of every parameter, on
//! random nets of several shapes and on a trained net read back from a `.skf`.

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::{ModelConfig, SkfView};

use std::sync::Arc;

use super::ParamLayout;
use crate::optim::{Adam, AdamConfig};
use crate::skinnet::export::to_skf_model;
use crate::skinnet::{
    Activation, Backend, LocalPoses, PREFIX, TrainableSkinNet, position_inputs_tensor,
};

fn random_points(n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            Vec3::new(
                rng.random_range(-0.9..0.9),
                rng.random_range(-0.9..0.9),
                rng.random_range(-0.9..0.9),
            )
        })
        .collect()
}

fn random_values(n: usize, scale: f32, seed: u64) -> Vec<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.random_range(-scale..scale)).collect()
}

/// A net of `config` whose variables are a copy of `vars` in `dtype` (so the same parameters can
/// be run through both backends and both precisions).
fn copy_net(config: ModelConfig, vars: &VarMap, dtype: DType) -> (TrainableSkinNet, VarMap) {
    let copy = VarMap::new();
    {
        let src = vars.data().lock().unwrap();
        let mut dst = copy.data().lock().unwrap();
        for (k, v) in src.iter() {
            dst.insert(
                k.clone(),
                Var::from_tensor(&v.as_tensor().to_dtype(dtype).unwrap()).unwrap(),
            );
        }
    }
    let vb = VarBuilder::from_varmap(&copy, dtype, &Device::Cpu);
    (TrainableSkinNet::new(&vb.pp(PREFIX), config).unwrap(), copy)
}

/// A loss that weighs every output differently and is not linear in it, so every path of the
/// backward pass (softmax included) carries a distinct gradient.
fn loss(w: &Tensor, target: &Tensor) -> Tensor {
    let t = target.to_dtype(w.dtype()).unwrap();
    ((w - &t).unwrap().sqr().unwrap() * 3.0)
        .unwrap()
        .add(&(w * &t).unwrap())
        .unwrap()
        .sum_all()
        .unwrap()
}

/// Forward values and per-parameter gradients of the fused op against candle's composite graph
/// evaluated in f64: every element within `1e-4` of the reference tensor's largest magnitude.
fn check_against_candle(
    config: ModelConfig,
    vars: &VarMap,
    frames: usize,
    points: usize,
    seed: u64,
) {
    check_masked(
        config,
        vars,
        frames,
        points,
        seed,
        None,
        &PoseInput::PerFrame,
    );
}

/// How [`check_masked`] feeds the poses.
enum PoseInput {
    /// `[F, Q]`.
    PerFrame,
    /// `[F, V, Q]`, a different pose per row.
    PerRow,
    /// `[F, V, Q]` as [`LocalPoses`] with these relevant joints (`[V, J]`) and five donors;
    /// the reference gets the rows written out.
    Local(Vec<bool>),
}

/// [`check_against_candle`] with an optional additive mask `[points, J]` on the logits and the
/// poses fed as `input` says.
fn check_masked(
    config: ModelConfig,
    vars: &VarMap,
    frames: usize,
    points: usize,
    seed: u64,
    mask: Option<&Tensor>,
    input: &PoseInput,
) {
    let dev = Device::Cpu;
    let enc = position_inputs_tensor(&config, &random_points(points, seed), &dev).unwrap();
    let q = config.pose_width();
    let j = config.joint_count as usize;
    let local = match input {
        PoseInput::Local(relevant) => {
            let own = random_values(frames * q, 1.5, seed + 1);
            let donors = random_values(5 * q, 1.5, seed + 3);
            let own: Vec<&[f32]> = own.chunks_exact(q).collect();
            let donors: Vec<&[f32]> = donors.chunks_exact(q).collect();
            let mut rng = ChaCha8Rng::seed_from_u64(seed + 4);
            Some(Arc::new(
                LocalPoses::draw(&own, &donors, relevant, j, &mut rng).unwrap(),
            ))
        }
        _ => None,
    };
    let poses = match (input, &local) {
        (_, Some(local)) => Tensor::from_vec(local.rows(), (frames, points, q), &dev),
        (PoseInput::PerRow, _) => Tensor::from_vec(
            random_values(frames * points * q, 1.5, seed + 1),
            (frames, points, q),
            &dev,
        ),
        _ => Tensor::from_vec(random_values(frames * q, 1.5, seed + 1), (frames, q), &dev),
    }
    .unwrap();
    let target = Tensor::from_vec(
        random_values(frames * points * j, 1.0, seed + 2),
        (frames, points, j),
        &dev,
    )
    .unwrap();

    let (fused, fused_vars) = copy_net(config, vars, DType::F32);
    let w_fused = match &local {
        Some(local) => fused.forward_local(&enc, local, mask).unwrap(),
        None => fused.forward_masked(&enc, &poses, mask).unwrap(),
    };
    let g_fused = loss(&w_fused, &target).backward().unwrap();

    let (reference, ref_vars) = copy_net(config, vars, DType::F64);
    let reference = reference.with_backend(Backend::Candle(Activation::Composite));
    let w_ref = reference
        .forward_masked(
            &enc.to_dtype(DType::F64).unwrap(),
            &poses.to_dtype(DType::F64).unwrap(),
            mask,
        )
        .unwrap();
    let g_ref = loss(&w_ref, &target).backward().unwrap();

    let a = w_fused.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let b = w_ref.flatten_all().unwrap().to_vec1::<f64>().unwrap();
    if let Some(m) = mask {
        // Masked joints weigh exactly zero, every frame.
        let m = m.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        for (i, w) in a.iter().enumerate() {
            if m[i % m.len()] == f32::NEG_INFINITY {
                assert_eq!(*w, 0.0, "masked weight {i}");
            }
        }
    }
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (f64::from(*x) - y).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "weights differ by {worst}");

    let fused_map = fused_vars.data().lock().unwrap();
    let ref_map = ref_vars.data().lock().unwrap();
    let mut checked = 0;
    for (name, var) in fused_map.iter() {
        let got = g_fused
            .get(var.as_tensor())
            .unwrap_or_else(|| panic!("no fused gradient for {name}"))
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let want = g_ref
            .get(ref_map[name].as_tensor())
            .unwrap_or_else(|| panic!("no reference gradient for {name}"))
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0, "{name}: reference gradient is zero");
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            let err = (f64::from(*g) - w).abs() / scale;
            assert!(
                err <= 1e-4,
                "{name}[{i}]: fused {g} vs candle {w} (rel {err:.2e})"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 3 * fused.layers().len());
}

/// The gradient of `l` with respect to every variable of `varmap`, flattened and concatenated
/// in the order of the variables' names.
fn sorted_gradients(l: &Tensor, varmap: &VarMap) -> Vec<f32> {
    let g = l.backward().unwrap();
    let vars = varmap.data().lock().unwrap();
    let mut names: Vec<_> = vars.keys().cloned().collect();
    names.sort();
    names
        .iter()
        .flat_map(|n| {
            g.get(vars[n].as_tensor())
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
        })
        .collect()
}

fn seeded_vars(config: ModelConfig, seed: u64) -> VarMap {
    TrainableSkinNet::seeded(config, seed, 1.0).unwrap().1
}

/// The paper's architecture for 5 joints, and a narrow net with the skip into the second layer.
fn paper_and_narrow() -> (ModelConfig, ModelConfig) {
    let paper = ModelConfig::paper_architecture(5, [-1.0; 3], [1.0; 3]);
    let mut narrow = paper;
    narrow.hidden_count = 3;
    narrow.hidden = [0; skinfield_formats::skf::MAX_HIDDEN_LAYERS];
    narrow.hidden[..3].copy_from_slice(&[24, 16, 20]);
    narrow.skip_layer = 1;
    narrow.pe_frequencies = 2;
    (paper, narrow)
}

#[test]
fn gradients_equal_candle_on_random_nets() {
    // The paper's architecture, a narrow net with the skip into the second layer, and a net
    // without a skip layer.
    let (paper, narrow) = paper_and_narrow();
    let mut no_skip = narrow;
    no_skip.skip_layer = 0;
    no_skip.joint_count = 3;
    for (k, config) in [paper, narrow, no_skip].into_iter().enumerate() {
        check_against_candle(config, &seeded_vars(config, 10 + k as u64), 3, 37, k as u64);
    }
}

#[test]
fn masked_gradients_equal_candle() {
    // Each point keeps 1–4 of 7 joints (a seeded pattern), as candidate masks do: the output
    // layer is dense and masked. Then 1–3 of 16: few enough that it computes the candidates
    // alone.
    for (joints, most, sparse) in [(7u16, 4, false), (16, 3, true)] {
        let config = ModelConfig::paper_architecture(joints.into(), [-1.0; 3], [1.0; 3]);
        let j = joints as usize;
        let points = 29;
        let mut rng = ChaCha8Rng::seed_from_u64(17 + j as u64);
        let lists: Vec<Vec<u16>> = (0..points)
            .map(|_| {
                let n = rng.random_range(1..=most);
                let mut l: Vec<u16> = (0..joints).collect();
                for i in 0..n {
                    let k = rng.random_range(i..j);
                    l.swap(i, k);
                }
                let mut l = l[..n].to_vec();
                l.sort_unstable();
                l
            })
            .collect();
        let values = crate::candidates::additive_mask(&lists, j);
        assert_eq!(
            super::sparse::LogitMask::new(values.clone(), j).is_sparse(),
            sparse
        );
        let mask = Tensor::from_vec(values, (points, j), &Device::Cpu).unwrap();
        for (k, input) in [PoseInput::PerFrame, PoseInput::PerRow].iter().enumerate() {
            let seed = 33 + j as u64 + k as u64;
            let vars = seeded_vars(config, seed);
            check_masked(config, &vars, 3 - k, points, seed + 8, Some(&mask), input);
        }
    }
}

#[test]
fn a_pose_per_row_gives_the_gradients_of_candle() {
    let (paper, narrow) = paper_and_narrow();
    for (k, config) in [paper, narrow].into_iter().enumerate() {
        let vars = seeded_vars(config, 40 + k as u64);
        check_masked(
            config,
            &vars,
            3,
            23,
            50 + k as u64,
            None,
            &PoseInput::PerRow,
        );
    }
}

#[test]
fn local_poses_give_the_gradients_of_candle_on_their_rows() {
    // Pose locality's structured input against candle's graph fed the same rows written out:
    // points relevant to no joint, to one, to several and to all, with the candidate mask that
    // goes with them and without a mask; both architectures at 16 joints; few relevant joints
    // (the structure is multiplied, and the masked output layer computes the candidates alone)
    // and many (the rows are written out and the output layer is dense).
    let (paper, narrow) = paper_and_narrow();
    for (k, mut config) in [paper, narrow].into_iter().enumerate() {
        config.joint_count = 16;
        let j = 16;
        let points = 36;
        for (share, structured) in [(0.08, true), (0.5, false)] {
            let seed = 70 + 10 * k as u64 + u64::from(structured);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let relevant: Vec<bool> = (0..points)
                .flat_map(|p| match p % 18 {
                    0 => vec![false; j],
                    1 => vec![true; j],
                    2 => (0..j).map(|i| i == p % j).collect(),
                    _ => (0..j).map(|_| rng.random_bool(share)).collect(),
                })
                .collect();
            let own = random_values(config.pose_width(), 1.0, 1);
            let probe = LocalPoses::draw(&[&own], &[&own], &relevant, j, &mut rng).unwrap();
            assert_eq!(probe.worth_structure(), structured);
            // The mask of the relevant joints (a point relevant to none keeps one).
            let lists: Vec<Vec<u16>> = relevant
                .chunks_exact(j)
                .enumerate()
                .map(|(p, r)| {
                    let l: Vec<u16> = (0..j as u16).filter(|&i| r[i as usize]).collect();
                    if l.is_empty() {
                        vec![(p % j) as u16]
                    } else {
                        l
                    }
                })
                .collect();
            let values = crate::candidates::additive_mask(&lists, j);
            assert_eq!(
                super::sparse::LogitMask::new(values.clone(), j).is_sparse(),
                structured
            );
            let mask = Tensor::from_vec(values, (points, j), &Device::Cpu).unwrap();
            let vars = seeded_vars(config, seed + 100);
            let input = PoseInput::Local(relevant.clone());
            check_masked(config, &vars, 3, points, seed + 200, None, &input);
            check_masked(config, &vars, 2, points, seed + 300, Some(&mask), &input);
        }
    }
}

#[test]
fn a_pose_per_row_that_repeats_the_frames_pose_gives_the_frames_weights() {
    // Both backends: `[F, V, Q]` rows all equal to frame f's pose must give exactly what
    // `[F, Q]` gives, values and gradients (up to summation order).
    let config = ModelConfig::paper_architecture(6, [-1.0; 3], [1.0; 3]);
    let dev = Device::Cpu;
    let (frames, points) = (2, 31);
    let enc = position_inputs_tensor(&config, &random_points(points, 61), &dev).unwrap();
    let q = config.pose_width();
    let poses = Tensor::from_vec(random_values(frames * q, 1.5, 62), (frames, q), &dev).unwrap();
    let rows = poses
        .unsqueeze(1)
        .unwrap()
        .broadcast_as((frames, points, q))
        .unwrap()
        .contiguous()
        .unwrap();
    let target = Tensor::from_vec(
        random_values(frames * points * 6, 1.0, 63),
        (frames, points, 6),
        &dev,
    )
    .unwrap();
    for backend in [Backend::Fused, Backend::Candle(Activation::Composite)] {
        let (net, varmap) = TrainableSkinNet::seeded(config, 64, 1.0).unwrap();
        let net = net.with_backend(backend);
        let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let gradient = |w: &Tensor| sorted_gradients(&loss(w, &target), &varmap);
        let per_frame = net.forward(&enc, &poses).unwrap();
        let per_row = net.forward(&enc, &rows).unwrap();
        let close = |a: &[f32], b: &[f32], what: &str| {
            let scale = b.iter().fold(0.0f32, |m, x| m.max(x.abs()));
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-5 * scale.max(1.0),
                    "{backend:?} {what}[{i}]: per row {x} vs per frame {y}"
                );
            }
        };
        close(&flat(&per_row), &flat(&per_frame), "weights");
        close(&gradient(&per_row), &gradient(&per_frame), "gradient");
    }
}

#[test]
fn a_pose_input_of_another_shape_is_an_error() {
    let config = ModelConfig::paper_architecture(3, [-1.0; 3], [1.0; 3]);
    let dev = Device::Cpu;
    let enc = position_inputs_tensor(&config, &random_points(5, 1), &dev).unwrap();
    let q = config.pose_width();
    for backend in [Backend::Fused, Backend::Candle(Activation::Composite)] {
        let net = TrainableSkinNet::seeded(config, 2, 1.0)
            .unwrap()
            .0
            .with_backend(backend);
        // Four rows per frame where the positions have five.
        let wrong = Tensor::zeros((2, 4, q), DType::F32, &dev).unwrap();
        assert!(net.forward(&enc, &wrong).is_err(), "{backend:?}");
    }
}

#[test]
fn gradients_equal_candle_on_a_trained_net_read_from_a_skf() {
    // Train a small paper-shaped net towards peaked, position-dependent weights (so its
    // softmax saturates as a trained SkinNet's does), export it, read it back and compare.
    let config = ModelConfig::paper_architecture(4, [-1.0; 3], [1.0; 3]);
    let (net, varmap) = TrainableSkinNet::seeded(config, 3, 0.1).unwrap();
    let dev = Device::Cpu;
    let pts = random_points(64, 9);
    let enc = position_inputs_tensor(&config, &pts, &dev).unwrap();
    let poses = Tensor::zeros((1, config.pose_width()), DType::F32, &dev).unwrap();
    let target: Vec<f32> = pts
        .iter()
        .flat_map(|p| {
            let k = usize::from(p.x > 0.0) + 2 * usize::from(p.y > 0.0);
            (0..4).map(move |j| if j == k { 0.97 } else { 0.01 })
        })
        .collect();
    let target = Tensor::from_vec(target, (1, 64, 4), &dev).unwrap();
    let mut opt = Adam::from_varmap(
        &varmap,
        AdamConfig {
            lr: 1e-2,
            ..AdamConfig::default()
        },
    )
    .unwrap();
    for _ in 0..40 {
        let w = net.forward(&enc, &poses).unwrap();
        opt.backward_step(&(w - &target).unwrap().sqr().unwrap().sum_all().unwrap())
            .unwrap();
    }
    let skeleton = crate::skinnet::tests::skeleton(4);
    let bytes = to_skf_model(&net, &skeleton).unwrap().to_bytes().unwrap();
    let view = SkfView::parse(&bytes).unwrap();
    let (loaded, vars) = TrainableSkinNet::from_skf(&view).unwrap();
    check_against_candle(*loaded.config(), &vars, 4, 50, 21);
}

#[test]
fn a_step_is_deterministic_and_a_second_backward_recomputes() {
    let config = ModelConfig::paper_architecture(6, [-1.0; 3], [1.0; 3]);
    let (net, varmap) = TrainableSkinNet::seeded(config, 5, 1.0).unwrap();
    let dev = Device::Cpu;
    let enc = position_inputs_tensor(&config, &random_points(40, 2), &dev).unwrap();
    let q = config.pose_width();
    let poses = Tensor::from_vec(random_values(2 * q, 1.0, 3), (2, q), &dev).unwrap();
    let target = Tensor::from_vec(random_values(2 * 40 * 6, 1.0, 4), (2, 40, 6), &dev).unwrap();
    let grads = |l: &Tensor| sorted_gradients(l, &varmap);
    let l1 = loss(&net.forward(&enc, &poses).unwrap(), &target);
    let first = grads(&l1);
    // The same graph again: its saved activations were consumed, so the op recomputes them.
    let again = grads(&l1);
    let l2 = loss(&net.forward(&enc, &poses).unwrap(), &target);
    let second = grads(&l2);
    assert_eq!(first, second, "two identical steps differ");
    assert_eq!(first, again, "the recomputing backward differs");
}

#[test]
fn the_layout_matches_the_packed_parameters() {
    let config = ModelConfig::paper_architecture(7, [-1.0; 3], [1.0; 3]);
    let (net, _vars) = TrainableSkinNet::seeded(config, 1, 1.0).unwrap();
    let layout = ParamLayout::new(&config);
    let packed = net.packed_parameters().unwrap().to_vec1::<f32>().unwrap();
    assert_eq!(packed.len(), layout.len());
    for (i, layer) in net.layers().iter().enumerate() {
        let [rv, rg, rb] = layout.ranges(i);
        let (v, g, b) = layer.parts();
        assert_eq!(
            &packed[rv],
            v.flatten_all().unwrap().to_vec1::<f32>().unwrap()
        );
        assert_eq!(&packed[rg], g.to_vec1::<f32>().unwrap());
        assert_eq!(&packed[rb], b.to_vec1::<f32>().unwrap());
    }
}

#[test]
fn the_buffer_pool_reuses_allocations() {
    let pool = super::BufferPool::default();
    let a = pool.take(1000);
    assert_eq!(a.len(), 1000);
    let ptr = a.as_ptr();
    pool.give([a]);
    let b = pool.take(800);
    assert_eq!(b.as_ptr(), ptr, "the pooled allocation was not reused");
    assert_eq!(b.len(), 800);
    // The pool is empty again: a new allocation, and a larger request grows.
    let c = pool.take(10);
    assert_ne!(c.as_ptr(), ptr);
    pool.give([b, c]);
    assert_eq!(pool.take(5000).len(), 5000);
}
