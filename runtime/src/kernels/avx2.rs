//! AVX2 + FMA kernel: half a panel (4 output rows) × 16 vertices at a time (8 ymm accumulators,
//! 2 loads and 4 broadcasts per 8 FMAs: 16 registers hold no more), bias + per-vertex part +
//! Softplus fused into the store, polynomial exp/log1p (constants in [`crate::activation`]).

use core::arch::x86_64::*;

use super::{LayerArgs, MR, TILE};
use crate::activation::{
    Act, EXP_MAX, EXP_MIN, EXP_P, EXP_TAIL, LN2_HI, LN2_LO, LOG1P_Q, LOG1P_S_MIN, LOG2E,
    SOFTPLUS_EXP_MIN,
};

/// Vectors per vertex block (16 vertices).
const NV: usize = 2;
/// Rows per register block.
const RB: usize = 4;
/// Vertices per vector.
const W: usize = 8;

#[inline]
#[target_feature(enable = "avx2,fma")]
fn exp_ps(z: __m256) -> __m256 {
    let z = _mm256_min_ps(
        _mm256_max_ps(z, _mm256_set1_ps(EXP_MIN)),
        _mm256_set1_ps(EXP_MAX),
    );
    let t = _mm256_fmadd_ps(z, _mm256_set1_ps(LOG2E), _mm256_set1_ps(0.5));
    let n = _mm256_floor_ps(t);
    let r = _mm256_fnmadd_ps(n, _mm256_set1_ps(LN2_HI), z);
    let r = _mm256_fnmadd_ps(n, _mm256_set1_ps(LN2_LO), r);
    let mut p = _mm256_set1_ps(EXP_P[0]);
    for &c in &EXP_P[1..] {
        p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(c));
    }
    let y = _mm256_add_ps(
        _mm256_fmadd_ps(p, _mm256_mul_ps(r, r), r),
        _mm256_set1_ps(1.0),
    );
    let e = _mm256_slli_epi32::<23>(_mm256_add_epi32(
        _mm256_cvtps_epi32(n),
        _mm256_set1_epi32(127),
    ));
    _mm256_mul_ps(y, _mm256_castsi256_ps(e))
}

#[inline]
#[target_feature(enable = "avx2,fma")]
fn log1p_ps(y: __m256) -> __m256 {
    let s = _mm256_div_ps(y, _mm256_add_ps(y, _mm256_set1_ps(2.0)));
    // Clamped before squaring so tiny arguments never underflow (see `LOG1P_S_MIN`).
    let sc = _mm256_max_ps(s, _mm256_set1_ps(LOG1P_S_MIN));
    let z = _mm256_mul_ps(sc, sc);
    let mut q = _mm256_set1_ps(LOG1P_Q[0]);
    for &c in &LOG1P_Q[1..] {
        q = _mm256_fmadd_ps(q, z, _mm256_set1_ps(c));
    }
    _mm256_mul_ps(_mm256_add_ps(s, s), q)
}

/// `exp(max(−β|x|, SOFTPLUS_EXP_MIN))`, Softplus's tail term.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn tail_exp(x: __m256, beta: __m256) -> __m256 {
    exp_ps(_mm256_max_ps(
        _mm256_sub_ps(
            _mm256_setzero_ps(),
            _mm256_mul_ps(beta, _mm256_andnot_ps(_mm256_set1_ps(-0.0), x)),
        ),
        _mm256_set1_ps(SOFTPLUS_EXP_MIN),
    ))
}

#[inline]
#[target_feature(enable = "avx2,fma")]
fn softplus_ps(x: __m256, beta: __m256, inv_beta: __m256) -> __m256 {
    let e = tail_exp(x, beta);
    _mm256_fmadd_ps(log1p_ps(e), inv_beta, _mm256_max_ps(x, _mm256_setzero_ps()))
}

/// # Safety
/// The CPU must support AVX2 and FMA, and `a.assert_shapes()` must have passed.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn layer(a: LayerArgs<'_>) {
    let LayerArgs {
        panels,
        k,
        input,
        bias,
        pre,
        out,
        rows_p,
        act,
    } = a;
    let (beta, inv_beta, softplus) = match act {
        Act::Softplus { beta } => (beta, 1.0 / beta, true),
        Act::Identity => (1.0, 1.0, false),
    };
    let (beta, inv_beta) = (_mm256_set1_ps(beta), _mm256_set1_ps(inv_beta));
    let x = input.as_ptr();
    let out = out.as_mut_ptr();
    for p in 0..rows_p / MR {
        for rb in 0..MR / RB {
            for vb in 0..TILE / (NV * W) {
                let mut acc = [[_mm256_setzero_ps(); NV]; RB];
                // SAFETY: the panel p spans `k·MR` floats from `p·k·MR`, inside `panels` because
                // `panels.len() ≥ rows_p·k`.
                let w = unsafe { panels.as_ptr().add(p * k * MR + rb * RB) };
                for kk in 0..k {
                    // SAFETY: `kk < k` and `input.len() ≥ k·TILE`: the vertex block
                    // `vb·NV·W + [0, NV·W)` of row `kk` is in bounds; `kk·MR + rb·RB + r` with
                    // `r < RB` stays inside the panel.
                    unsafe {
                        let xr = x.add(kk * TILE + vb * NV * W);
                        let mut xv = [_mm256_setzero_ps(); NV];
                        for (c, xc) in xv.iter_mut().enumerate() {
                            *xc = _mm256_loadu_ps(xr.add(W * c));
                        }
                        let wr = w.add(kk * MR);
                        for (r, acc_r) in acc.iter_mut().enumerate() {
                            let b = _mm256_set1_ps(*wr.add(r));
                            for (a, &xc) in acc_r.iter_mut().zip(&xv) {
                                *a = _mm256_fmadd_ps(b, xc, *a);
                            }
                        }
                    }
                }
                for (r, acc_r) in acc.iter().enumerate() {
                    let o = p * MR + rb * RB + r;
                    let b = _mm256_set1_ps(bias[o]);
                    for (c, &acc_rc) in acc_r.iter().enumerate() {
                        let at = o * TILE + vb * NV * W + W * c;
                        let mut v = _mm256_add_ps(acc_rc, b);
                        if let Some(pre) = pre {
                            // SAFETY: `o < rows_p` and `pre.len() ≥ rows_p·TILE`.
                            v = _mm256_add_ps(v, unsafe { _mm256_loadu_ps(pre.as_ptr().add(at)) });
                        }
                        if softplus {
                            v = softplus_ps(v, beta, inv_beta);
                        }
                        // SAFETY: `o < rows_p` and `out.len() ≥ rows_p·TILE`.
                        unsafe { _mm256_storeu_ps(out.add(at), v) };
                    }
                }
            }
        }
    }
}

/// # Safety
/// The CPU must support AVX2 and FMA, `buf.len() ≥ rows·TILE` and `rows ≥ 1`.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn softmax_tile(buf: &mut [f32], rows: usize) {
    let b = buf.as_mut_ptr();
    // SAFETY: every pointer is `b + j·TILE + W·c + [0, W)` with `j < rows` and `c < TILE/W`, inside
    // `buf` because `buf.len() ≥ rows·TILE`.
    unsafe {
        for c in 0..TILE / W {
            let mut m = _mm256_set1_ps(f32::NEG_INFINITY);
            for j in 0..rows {
                m = _mm256_max_ps(m, _mm256_loadu_ps(b.add(j * TILE + W * c)));
            }
            let mut sum = _mm256_setzero_ps();
            for j in 0..rows {
                let at = b.add(j * TILE + W * c);
                let z = _mm256_sub_ps(_mm256_loadu_ps(at), m);
                let keep = _mm256_cmp_ps::<_CMP_GE_OQ>(z, _mm256_set1_ps(-EXP_TAIL));
                let e = _mm256_and_ps(keep, exp_ps(z));
                sum = _mm256_add_ps(sum, e);
                _mm256_storeu_ps(at, e);
            }
            let inv = _mm256_div_ps(_mm256_set1_ps(1.0), sum);
            for j in 0..rows {
                let at = b.add(j * TILE + W * c);
                _mm256_storeu_ps(at, _mm256_mul_ps(_mm256_loadu_ps(at), inv));
            }
        }
    }
}

/// Softplus in place over `x` and its slope `sigmoid(β·x)` into `slope` (the trainer's forward
/// pass keeps the slope for its backward pass), 8 lanes at a time; the tail goes through the
/// scalar path.
///
/// # Safety
/// The CPU must support avx2,fma, and `slope.len() == x.len()`.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn softplus_with_slope(x: &mut [f32], slope: &mut [f32], beta: f32) {
    let n = x.len() - x.len() % 8;
    let (b, ib) = (_mm256_set1_ps(beta), _mm256_set1_ps(1.0 / beta));
    let (xp, sp) = (x.as_mut_ptr(), slope.as_mut_ptr());
    for i in (0..n).step_by(8) {
        // SAFETY: `i + 8 ≤ n ≤ x.len() = slope.len()`.
        unsafe {
            let x = _mm256_loadu_ps(xp.add(i));
            let e = tail_exp(x, b);
            let h = _mm256_fmadd_ps(log1p_ps(e), ib, _mm256_max_ps(x, _mm256_setzero_ps()));
            let inv = _mm256_div_ps(_mm256_set1_ps(1.0), _mm256_add_ps(e, _mm256_set1_ps(1.0)));
            let ge = _mm256_cmp_ps::<_CMP_GE_OQ>(x, _mm256_setzero_ps());
            let s = _mm256_blendv_ps(_mm256_mul_ps(e, inv), inv, ge);
            _mm256_storeu_ps(xp.add(i), h);
            _mm256_storeu_ps(sp.add(i), s);
        }
    }
    super::scalar::softplus_with_slope(&mut x[n..], &mut slope[n..], beta);
}
