//! Every available kernel against the scalar path on random weights and the real layer shapes.

use alloc::vec;
use alloc::vec::Vec;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::activation::{Act, softplus};

fn random(rng: &mut ChaCha8Rng, n: usize, scale: f32) -> Vec<f32> {
    (0..n)
        .map(|_| rng.random_range(-1.0..1.0) * scale)
        .collect()
}

/// Runs one layer with `kernel`; returns the output.
#[allow(clippy::too_many_arguments)]
fn run(
    kernel: Kernel,
    panels: &[f32],
    k: usize,
    input: &[f32],
    bias: &[f32],
    pre: Option<&[f32]>,
    rows_p: usize,
    act: Act,
) -> Vec<f32> {
    let mut out = vec![f32::NAN; rows_p * TILE];
    layer(
        kernel,
        LayerArgs {
            panels,
            k,
            input,
            bias,
            pre,
            out: &mut out,
            rows_p,
            act,
        },
    );
    out
}

/// `|a − b| ≤ 1e-5 · max(|b|, rms(b))`: relative, with the row's scale as the floor so a value
/// that cancels to ~0 is not held to a relative bound it cannot have.
fn assert_close(a: &[f32], b: &[f32], what: &str) {
    let rms = (b.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>() / b.len() as f64).sqrt();
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let tol = 1e-5 * f64::from(y.abs()).max(rms);
        assert!(
            (f64::from(*x) - f64::from(*y)).abs() <= tol,
            "{what}: element {i}: {x} vs {y} (tol {tol})"
        );
    }
}

#[test]
fn scalar_layer_matches_a_naive_product() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let (rows, k) = (20, 13);
    let w = random(&mut rng, rows * k, 0.3);
    let x = random(&mut rng, k * TILE, 1.0);
    let bias = random(&mut rng, 24, 0.1);
    let mut panels = vec![0.0; 24 * k];
    pack_panels::<()>(rows, k, &mut panels, |o, c| Ok(w[o * k + c])).unwrap();
    let out = run(
        Kernel::Scalar,
        &panels,
        k,
        &x,
        &bias,
        None,
        24,
        Act::Softplus { beta: 3.0 },
    );
    for o in 0..rows {
        for v in 0..TILE {
            let s: f64 = (0..k)
                .map(|c| f64::from(w[o * k + c]) * f64::from(x[c * TILE + v]))
                .sum::<f64>()
                + f64::from(bias[o]);
            let want = softplus(s as f32, 3.0);
            assert!(
                (out[o * TILE + v] - want).abs() <= 1e-5 * want.abs().max(1.0),
                "{o} {v}"
            );
        }
    }
}

#[test]
fn every_kernel_agrees_with_scalar_on_real_shapes() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    // (rows, k, with per-vertex part): the VINECS layers for J = 24 (hidden parts), the
    // bind-time position parts (k = 39) and a layer with no GEMM (layer 0 per frame).
    let shapes: [(usize, usize, bool); 8] = [
        (256, 256, false),
        (128, 256, true),
        (256, 128, false),
        (24, 256, false),
        (256, 39, false),
        (128, 39, false),
        (256, 0, true),
        (5, 7, true),
    ];
    let kernels: Vec<Kernel> = Kernel::ALL
        .iter()
        .copied()
        .filter(|k| k.is_available() && *k != Kernel::Scalar)
        .collect();
    for (rows, k, with_pre) in shapes {
        let rows_p = rows.div_ceil(MR) * MR;
        let w = random(&mut rng, rows * k, (3.0 / k.max(1) as f32).sqrt());
        let mut panels = vec![0.0; rows_p * k];
        pack_panels::<()>(rows, k, &mut panels, |o, c| Ok(w[o * k + c])).unwrap();
        let x = random(&mut rng, k * TILE, 1.0);
        let bias = random(&mut rng, rows_p, 0.5);
        let pre = random(&mut rng, rows_p * TILE, 0.5);
        let pre = with_pre.then_some(&pre[..]);
        for act in [
            Act::Softplus { beta: 100.0 },
            Act::Softplus { beta: 1.0 },
            Act::Identity,
        ] {
            let want = run(Kernel::Scalar, &panels, k, &x, &bias, pre, rows_p, act);
            for &kern in &kernels {
                let got = run(kern, &panels, k, &x, &bias, pre, rows_p, act);
                assert_close(&got, &want, &alloc::format!("{kern:?} {rows}x{k} {act:?}"));
            }
        }
    }
}

#[test]
fn simd_softplus_is_accurate_across_the_range() {
    // A K = 0 layer is pure bias + pre + activation: sweep the activation's argument.
    let kernels: Vec<Kernel> = Kernel::ALL
        .iter()
        .copied()
        .filter(|k| k.is_available())
        .collect();
    let rows_p = 64;
    let pre: Vec<f32> = (0..rows_p * TILE)
        .map(|i| -1.0 + 2.0 * i as f32 / (rows_p * TILE) as f32)
        .collect();
    let bias = vec![0.0; rows_p];
    for beta in [100.0f32, 1.0, 7.5] {
        for &kern in &kernels {
            let got = run(
                kern,
                &[],
                0,
                &[],
                &bias,
                Some(&pre),
                rows_p,
                Act::Softplus { beta },
            );
            for (g, x) in got.iter().zip(&pre) {
                let bx = f64::from(beta) * f64::from(*x);
                let want = (bx.max(0.0) + libm::log1p(libm::exp(-bx.abs()))) / f64::from(beta);
                let err = (f64::from(*g) - want).abs();
                // The tail below e^SOFTPLUS_EXP_MIN / β is clamped there (no subnormals).
                let floor =
                    libm::exp(f64::from(crate::activation::SOFTPLUS_EXP_MIN)) / f64::from(beta);
                assert!(
                    err <= 1e-6 * want.abs() + floor,
                    "{kern:?} β={beta} x={x}: {g} vs {want}"
                );
            }
        }
    }
}

#[test]
fn every_kernel_softmax_agrees_with_scalar() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for rows in [1, 3, 24, 57] {
        let mut logits = random(&mut rng, rows * TILE, 20.0);
        logits[5] = 80.0;
        let mut want = logits.clone();
        softmax_tile(Kernel::Scalar, &mut want, rows);
        for v in 0..TILE {
            let s: f32 = (0..rows).map(|j| want[j * TILE + v]).sum();
            assert!((s - 1.0).abs() < 1e-5);
        }
        for kern in Kernel::ALL.into_iter().filter(|k| k.is_available()) {
            let mut got = logits.clone();
            softmax_tile(kern, &mut got, rows);
            for (g, w) in got.iter().zip(&want) {
                assert!(
                    (g - w).abs() <= 1e-5 * w.max(1e-3),
                    "{kern:?} rows {rows}: {g} vs {w}"
                );
            }
        }
    }
}

#[test]
fn detection_respects_the_scalar_feature() {
    let k = Kernel::detect();
    assert!(k.is_available());
    if cfg!(feature = "scalar") {
        assert_eq!(k, Kernel::Scalar);
        assert!(!Kernel::Avx2.is_available() && !Kernel::Avx512.is_available());
    }
}

/// Subnormal floats cost a ~100-cycle microcode assist per use on Intel cores (the exact MLP
/// ran 60× slower before the tails were cut): no kernel may emit one from Softplus or softmax.
#[test]
fn no_kernel_emits_subnormal_activations_or_weights() {
    let rows_p = 64;
    let pre: Vec<f32> = (0..rows_p * TILE)
        .map(|i| -3.0 + 3.0 * i as f32 / (rows_p * TILE) as f32)
        .collect();
    let bias = vec![0.0; rows_p];
    for kern in Kernel::ALL.into_iter().filter(|k| k.is_available()) {
        for beta in [1.0f32, 100.0, 1000.0] {
            let got = run(
                kern,
                &[],
                0,
                &[],
                &bias,
                Some(&pre),
                rows_p,
                Act::Softplus { beta },
            );
            for (g, x) in got.iter().zip(&pre) {
                assert!(*g == 0.0 || g.is_normal(), "{kern:?} β={beta} x={x}: {g:e}");
            }
        }
        // Logit gaps from 0 to 200 below the maximum: far joints get exactly zero.
        let rows = 40;
        let mut logits: Vec<f32> = (0..rows * TILE)
            .map(|i| -5.0 * (i / TILE) as f32 - 0.01 * (i % TILE) as f32)
            .collect();
        softmax_tile(kern, &mut logits, rows);
        assert!(
            logits.iter().all(|w| *w == 0.0 || w.is_normal()),
            "{kern:?} softmax"
        );
        assert!(logits[39 * TILE] == 0.0 && logits[TILE] > 0.0);
    }
}

#[test]
fn every_kernel_softplus_with_slope_agrees_with_the_f64_definition() {
    // Lengths that leave a tail for every vector width; |βx| up to 40 covers both branches, the
    // curved part and the far tail where the slope is ~e^-40.
    let beta = 100.0f32;
    for n in [0usize, 1, 7, 8, 15, 16, 17, 1000] {
        let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
        let x0 = random(&mut rng, n, 0.4);
        for kernel in Kernel::ALL.into_iter().filter(|k| k.is_available()) {
            let mut x = x0.clone();
            let mut slope = vec![f32::NAN; n];
            softplus_with_slope(kernel, &mut x, &mut slope, beta).unwrap();
            for i in 0..n {
                let bx = f64::from(beta) * f64::from(x0[i]);
                let want_h = (libm::log1p(libm::exp(-bx.abs())) + bx.max(0.0)) / f64::from(beta);
                let want_s = 1.0 / (1.0 + libm::exp(-bx));
                // exp amplifies the f32 rounding of βx (relative 6e-8) by |βx|.
                let rel = 1e-6 + 1.2e-7 * bx.abs();
                let tol_h = rel * want_h.abs() + 1e-12;
                let tol_s = rel * want_s.abs() + 1e-30;
                assert!(
                    (f64::from(x[i]) - want_h).abs() <= tol_h,
                    "{kernel:?} n={n} softplus({}) = {} vs {want_h}",
                    x0[i],
                    x[i]
                );
                assert!(
                    (f64::from(slope[i]) - want_s).abs() <= tol_s,
                    "{kernel:?} n={n} slope({}) = {} vs {want_s}",
                    x0[i],
                    slope[i]
                );
            }
        }
    }
}

#[test]
fn softplus_with_slope_rejects_mismatched_slices() {
    let mut x = vec![0.0f32; 4];
    let mut slope = vec![0.0f32; 3];
    let e = softplus_with_slope(Kernel::Scalar, &mut x, &mut slope, 100.0).unwrap_err();
    assert_eq!(
        e,
        RuntimeError::BufferLength {
            field: "slope",
            len: 3,
            expected: 4
        }
    );
}
