use super::*;
use crate::skinnet::softplus::softplus_scalar;
use glam::{Mat4, Quat};
use skinfield_formats::Skeleton;
use skinfield_formats::math::Transform;
use skinfield_formats::skf::SkfView;

/// One plain layer: row-major weight `[out, in]`, `out`, `in`, bias.
type Plain = (Vec<f32>, usize, usize, Vec<f32>);

/// Independent reference: the MLP as naive f64 loops over plain weights, one input row at a time,
/// with the input built by concatenation (no position/pose split).
fn naive_forward(config: &ModelConfig, layers: &[Plain], pos: &[f32], pose: &[f32]) -> Vec<f64> {
    let input: Vec<f64> = pos.iter().chain(pose).map(|&x| f64::from(x)).collect();
    let mut h = input.clone();
    let n = layers.len() - 1;
    for (i, (w, out, inp, b)) in layers.iter().enumerate() {
        let x: Vec<f64> = if i == config.skip_layer as usize && i > 0 {
            h.iter().chain(&input).copied().collect()
        } else {
            h.clone()
        };
        assert_eq!(x.len(), *inp);
        let mut y = vec![0.0; *out];
        for (o, yo) in y.iter_mut().enumerate() {
            *yo = f64::from(b[o])
                + (0..*inp)
                    .map(|k| f64::from(w[o * inp + k]) * x[k])
                    .sum::<f64>();
            if i < n {
                *yo = softplus_scalar(*yo, f64::from(config.softplus_beta));
            }
        }
        h = y;
    }
    let m = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let s: f64 = h.iter().map(|x| (x - m).exp()).sum();
    h.iter().map(|x| (x - m).exp() / s).collect()
}

fn plain_layers(net: &TrainableSkinNet) -> Vec<Plain> {
    net.layers()
        .iter()
        .map(|l| {
            let w = l.weight().unwrap();
            let (o, i) = w.dims2().unwrap();
            (
                w.flatten_all().unwrap().to_vec1().unwrap(),
                o,
                i,
                l.bias().to_vec1().unwrap(),
            )
        })
        .collect()
}

fn random_points(n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            Vec3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(0.0..1.8),
                rng.random_range(-0.2..0.2),
            )
        })
        .collect()
}

fn random_poses(f: usize, j: usize, seed: u64) -> Vec<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..f * 3 * j)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect()
}

fn config(j: u32) -> ModelConfig {
    ModelConfig::paper_architecture(j, [-0.5, 0.0, -0.2], [0.5, 1.8, 0.2])
}

#[test]
fn encoding_order_is_x_then_sin_cos_per_frequency() {
    let c = config(2);
    let e = position_inputs(&c, &[Vec3::new(0.25, 0.9, 0.0)]);
    assert_eq!(e.len(), 39);
    // x̂ = (0.5, 0, 0): 0.25 → 2·0.75/1 − 1; 0.9 → 2·0.5 − 1; 0 → 2·0.5 − 1.
    assert!((e[0] - 0.5).abs() < 1e-6 && e[1].abs() < 1e-6 && e[2].abs() < 1e-6);
    for k in 0..6 {
        let f = (1 << k) as f32 * core::f32::consts::PI;
        let base = 3 + 6 * k;
        assert!((e[base] - (f * 0.5).sin()).abs() < 1e-5, "sin x at k={k}");
        assert!(
            (e[base + 3] - (f * 0.5).cos()).abs() < 1e-5,
            "cos x at k={k}"
        );
        assert!((e[base + 4] - 1.0).abs() < 1e-6, "cos y=0 at k={k}");
    }
}

#[test]
fn forward_equals_naive_loops_for_every_frame_and_vertex() {
    let c = config(5);
    let (net, _vm) = TrainableSkinNet::seeded(c, 7, 1.0).unwrap();
    let pts = random_points(6, 1);
    let poses = random_poses(3, 5, 2);
    let enc = position_inputs(&c, &pts);
    let w = net
        .forward(
            &position_inputs_tensor(&c, &pts, &Device::Cpu).unwrap(),
            &Tensor::from_vec(poses.clone(), (3, 15), &Device::Cpu).unwrap(),
        )
        .unwrap();
    assert_eq!(w.dims(), &[3, 6, 5]);
    let w = w.to_vec3::<f32>().unwrap();
    let plain = plain_layers(&net);
    let pw = c.position_width();
    let mut spread = 0.0f64;
    for f in 0..3 {
        for v in 0..6 {
            let r = naive_forward(
                &c,
                &plain,
                &enc[v * pw..(v + 1) * pw],
                &poses[f * 15..(f + 1) * 15],
            );
            let s: f32 = w[f][v].iter().sum();
            assert!((s - 1.0).abs() < 1e-5);
            for j in 0..5 {
                assert!(
                    (f64::from(w[f][v][j]) - r[j]).abs() < 2e-5,
                    "f{f} v{v} j{j}: {} vs {}",
                    w[f][v][j],
                    r[j]
                );
                spread = spread.max((r[j] - 0.2).abs());
            }
        }
    }
    // The check is meaningful only if the weights are not all uniform.
    assert!(spread > 1e-3, "{spread}");
}

#[test]
fn composite_activation_gives_the_same_output() {
    let c = config(3);
    let (net, _vm) = TrainableSkinNet::seeded(c, 3, 1.0).unwrap();
    let enc = position_inputs_tensor(&c, &random_points(50, 4), &Device::Cpu).unwrap();
    let poses = Tensor::from_vec(random_poses(2, 3, 5), (2, 9), &Device::Cpu).unwrap();
    let a = net.forward(&enc, &poses).unwrap();
    let b = net
        .clone()
        .with_backend(Backend::Candle(Activation::Composite))
        .forward(&enc, &poses)
        .unwrap();
    let d = (a - b)
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_vec0::<f32>()
        .unwrap();
    assert!(d < 1e-6, "{d}");
}

/// f64 copy of a seeded net, so finite differences are accurate.
fn f64_net(c: ModelConfig, seed: u64) -> (TrainableSkinNet, VarMap) {
    let (_, vm32) = TrainableSkinNet::seeded(c, seed, 1.0).unwrap();
    let vm = VarMap::new();
    {
        let src = vm32.data().lock().unwrap();
        let mut dst = vm.data().lock().unwrap();
        for (k, v) in src.iter() {
            dst.insert(
                k.clone(),
                Var::from_tensor(&v.as_tensor().to_dtype(DType::F64).unwrap()).unwrap(),
            );
        }
    }
    let vb = VarBuilder::from_varmap(&vm, DType::F64, &Device::Cpu);
    (TrainableSkinNet::new(&vb.pp(PREFIX), c).unwrap(), vm)
}

#[test]
fn parameter_gradients_match_finite_differences() {
    let c = config(4);
    let (net, vm) = f64_net(c, 11);
    let enc = position_inputs_tensor(&c, &random_points(8, 6), &Device::Cpu)
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap();
    let poses = Tensor::from_vec(random_poses(2, 4, 7), (2, 12), &Device::Cpu)
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let r: Vec<f64> = (0..2 * 8 * 4)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let r = Tensor::from_vec(r, (2, 8, 4), &Device::Cpu).unwrap();
    let loss = |net: &TrainableSkinNet| {
        net.forward(&enc, &poses)
            .unwrap()
            .mul(&r)
            .unwrap()
            .sum_all()
            .unwrap()
    };
    let grads = loss(&net).backward().unwrap();
    let h = 1e-6;
    let mut checked = 0;
    for name in [
        "skin.l0.v",
        "skin.l0.g",
        "skin.l2.v",
        "skin.l2.b",
        "skin.l4.g",
        "skin.l5.v",
        "skin.l5.b",
    ] {
        let var = vm.data().lock().unwrap().get(name).unwrap().clone();
        let g = grads
            .get(&var)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let base = var
            .as_tensor()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let shape = var.shape().clone();
        for idx in [0, base.len() / 3, base.len() - 1] {
            let eval = |d: f64| {
                let mut p = base.clone();
                p[idx] += d;
                var.set(&Tensor::from_vec(p, shape.clone(), &Device::Cpu).unwrap())
                    .unwrap();
                let v = loss(&net).to_vec0::<f64>().unwrap();
                var.set(&Tensor::from_vec(base.clone(), shape.clone(), &Device::Cpu).unwrap())
                    .unwrap();
                v
            };
            let fd = (eval(h) - eval(-h)) / (2.0 * h);
            let tol = 1e-6 + 1e-4 * fd.abs();
            assert!(
                (g[idx] - fd).abs() < tol,
                "{name}[{idx}]: autodiff {} fd {fd}",
                g[idx]
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 21);
}

/// A chain of `j` joints 0.3 m apart (shared by the appearance-net export tests).
pub(crate) fn skeleton(j: usize) -> Skeleton {
    let names = (0..j).map(|i| format!("j{i}")).collect();
    let parents = (0..j).map(|i| i.checked_sub(1)).collect();
    let bind = (0..j)
        .map(|i| Transform {
            translation: Vec3::new(0.0, 0.3 * i as f32, 0.0),
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        })
        .collect();
    Skeleton::new(names, parents, bind, None, None, Mat4::IDENTITY).unwrap()
}

#[test]
fn exported_skf_evaluates_like_candle() {
    let c = config(6);
    // A larger output scale so the softmax is far from uniform and errors would show.
    let (net, _vm) = TrainableSkinNet::seeded(c, 21, 4.0).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.skf");
    export::write_skf(&net, &skeleton(6), &path).unwrap();
    let bytes = skinfield_formats::skf::read_skf_file(&path).unwrap();
    let view = SkfView::parse(&bytes).unwrap();
    assert_eq!(view.config(), &c);
    let layers: Vec<Plain> = (0..=c.hidden_widths().len())
        .map(|i| {
            let (w, b) = view.layer(Net::Skin, i).unwrap();
            let mut wv = vec![0.0; w.len()];
            w.to_f32(&mut wv).unwrap();
            let mut bv = vec![0.0; b.len()];
            b.to_f32(&mut bv).unwrap();
            let out = bv.len();
            (wv, out, w.len() / out, bv)
        })
        .collect();
    let pts = random_points(40, 9);
    let poses = random_poses(3, 6, 10);
    let w = net
        .forward(
            &position_inputs_tensor(&c, &pts, &Device::Cpu).unwrap(),
            &Tensor::from_vec(poses.clone(), (3, 18), &Device::Cpu).unwrap(),
        )
        .unwrap()
        .to_vec3::<f32>()
        .unwrap();
    let enc = position_inputs(&c, &pts);
    let pw = c.position_width();
    let mut worst = 0.0f64;
    let mut spread = 0.0f64;
    for f in 0..3 {
        for v in 0..40 {
            let r = naive_forward(
                &c,
                &layers,
                &enc[v * pw..(v + 1) * pw],
                &poses[f * 18..(f + 1) * 18],
            );
            for j in 0..6 {
                worst = worst.max((f64::from(w[f][v][j]) - r[j]).abs());
                spread = spread.max((r[j] - 1.0 / 6.0).abs());
            }
        }
    }
    assert!(worst < 1e-3, "f16 export deviates by {worst}");
    assert!(
        spread > 0.05,
        "weights too uniform for a meaningful check: {spread}"
    );
    // The skeleton round-trips too.
    assert_eq!(view.skeleton().to_skeleton().unwrap(), skeleton(6));
}

#[test]
fn export_rejects_a_skeleton_of_the_wrong_size() {
    let (net, _vm) = TrainableSkinNet::seeded(config(3), 1, 1.0).unwrap();
    assert!(matches!(
        export::to_skf_model(&net, &skeleton(4)),
        Err(export::ExportError::JointCount {
            skeleton: 4,
            net: 3
        })
    ));
}
