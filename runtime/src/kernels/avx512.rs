//! AVX-512F kernel: a panel of 8 output rows × the whole 32-vertex tile (16 zmm accumulators,
//! 2 loads and 8 broadcasts per 16 FMAs), bias + per-vertex part + Softplus fused into the
//! store, polynomial exp/log1p (constants and accuracy in [`crate::activation`]).

use core::arch::x86_64::*;

use super::{LayerArgs, MR, TILE};
use crate::activation::{
    Act, EXP_MAX, EXP_MIN, EXP_P, EXP_TAIL, LN2_HI, LN2_LO, LOG1P_Q, LOG1P_S_MIN, LOG2E,
    SOFTPLUS_EXP_MIN,
};

const NV: usize = TILE / 16;

#[inline]
#[target_feature(enable = "avx512f")]
fn exp_ps(z: __m512) -> __m512 {
    let z = _mm512_min_ps(
        _mm512_max_ps(z, _mm512_set1_ps(EXP_MIN)),
        _mm512_set1_ps(EXP_MAX),
    );
    let t = _mm512_fmadd_ps(z, _mm512_set1_ps(LOG2E), _mm512_set1_ps(0.5));
    let n = _mm512_roundscale_ps::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(t);
    let r = _mm512_fnmadd_ps(n, _mm512_set1_ps(LN2_HI), z);
    let r = _mm512_fnmadd_ps(n, _mm512_set1_ps(LN2_LO), r);
    let mut p = _mm512_set1_ps(EXP_P[0]);
    for &c in &EXP_P[1..] {
        p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(c));
    }
    let y = _mm512_add_ps(
        _mm512_fmadd_ps(p, _mm512_mul_ps(r, r), r),
        _mm512_set1_ps(1.0),
    );
    let e = _mm512_slli_epi32::<23>(_mm512_add_epi32(
        _mm512_cvtps_epi32(n),
        _mm512_set1_epi32(127),
    ));
    _mm512_mul_ps(y, _mm512_castsi512_ps(e))
}

#[inline]
#[target_feature(enable = "avx512f")]
fn log1p_ps(y: __m512) -> __m512 {
    let s = _mm512_div_ps(y, _mm512_add_ps(y, _mm512_set1_ps(2.0)));
    // Clamped before squaring so tiny arguments never underflow (see `LOG1P_S_MIN`).
    let sc = _mm512_max_ps(s, _mm512_set1_ps(LOG1P_S_MIN));
    let z = _mm512_mul_ps(sc, sc);
    let mut q = _mm512_set1_ps(LOG1P_Q[0]);
    for &c in &LOG1P_Q[1..] {
        q = _mm512_fmadd_ps(q, z, _mm512_set1_ps(c));
    }
    _mm512_mul_ps(_mm512_add_ps(s, s), q)
}

/// `exp(max(−β|x|, SOFTPLUS_EXP_MIN))`, Softplus's tail term.
#[inline]
#[target_feature(enable = "avx512f")]
fn tail_exp(x: __m512, beta: __m512) -> __m512 {
    exp_ps(_mm512_max_ps(
        _mm512_sub_ps(_mm512_setzero_ps(), _mm512_mul_ps(beta, _mm512_abs_ps(x))),
        _mm512_set1_ps(SOFTPLUS_EXP_MIN),
    ))
}

#[inline]
#[target_feature(enable = "avx512f")]
fn softplus_ps(x: __m512, beta: __m512, inv_beta: __m512) -> __m512 {
    let e = tail_exp(x, beta);
    _mm512_fmadd_ps(log1p_ps(e), inv_beta, _mm512_max_ps(x, _mm512_setzero_ps()))
}

/// # Safety
/// The CPU must support AVX-512F, and `a.assert_shapes()` must have passed.
#[target_feature(enable = "avx512f")]
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
    let (beta, inv_beta) = (_mm512_set1_ps(beta), _mm512_set1_ps(inv_beta));
    let x = input.as_ptr();
    let out = out.as_mut_ptr();
    for p in 0..rows_p / MR {
        let mut acc = [[_mm512_setzero_ps(); NV]; MR];
        // SAFETY: the panel p spans `k·MR` floats from `p·k·MR` and `panels.len() ≥ rows_p·k`.
        let w = unsafe { panels.as_ptr().add(p * k * MR) };
        for kk in 0..k {
            // SAFETY: `kk < k` and `input.len() ≥ k·TILE`, so row `kk` (TILE floats) is in
            // bounds; `kk·MR + r < k·MR` stays inside the panel.
            unsafe {
                let xr = x.add(kk * TILE);
                let mut xv = [_mm512_setzero_ps(); NV];
                for (c, xc) in xv.iter_mut().enumerate() {
                    *xc = _mm512_loadu_ps(xr.add(16 * c));
                }
                let wr = w.add(kk * MR);
                for (r, acc_r) in acc.iter_mut().enumerate() {
                    let b = _mm512_set1_ps(*wr.add(r));
                    for (a, &xc) in acc_r.iter_mut().zip(&xv) {
                        *a = _mm512_fmadd_ps(b, xc, *a);
                    }
                }
            }
        }
        for (r, acc_r) in acc.iter().enumerate() {
            let o = p * MR + r;
            let b = _mm512_set1_ps(bias[o]);
            for (c, &acc_rc) in acc_r.iter().enumerate() {
                let mut v = _mm512_add_ps(acc_rc, b);
                if let Some(pre) = pre {
                    // SAFETY: `o < rows_p` and `pre.len() ≥ rows_p·TILE`.
                    v = _mm512_add_ps(v, unsafe {
                        _mm512_loadu_ps(pre.as_ptr().add(o * TILE + 16 * c))
                    });
                }
                if softplus {
                    v = softplus_ps(v, beta, inv_beta);
                }
                // SAFETY: `o < rows_p` and `out.len() ≥ rows_p·TILE`.
                unsafe { _mm512_storeu_ps(out.add(o * TILE + 16 * c), v) };
            }
        }
    }
}

/// # Safety
/// The CPU must support AVX-512F, `buf.len() ≥ rows·TILE` and `rows ≥ 1`.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn softmax_tile(buf: &mut [f32], rows: usize) {
    let b = buf.as_mut_ptr();
    // SAFETY: every pointer is `b + j·TILE + 16·c + [0, 16)` with `j < rows` and `c < NV`, inside
    // `buf` because `buf.len() ≥ rows·TILE`.
    unsafe {
        for c in 0..NV {
            let mut m = _mm512_set1_ps(f32::NEG_INFINITY);
            for j in 0..rows {
                m = _mm512_max_ps(m, _mm512_loadu_ps(b.add(j * TILE + 16 * c)));
            }
            let mut sum = _mm512_setzero_ps();
            for j in 0..rows {
                let at = b.add(j * TILE + 16 * c);
                let z = _mm512_sub_ps(_mm512_loadu_ps(at), m);
                let keep = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(z, _mm512_set1_ps(-EXP_TAIL));
                let e = _mm512_maskz_mov_ps(keep, exp_ps(z));
                sum = _mm512_add_ps(sum, e);
                _mm512_storeu_ps(at, e);
            }
            let inv = _mm512_div_ps(_mm512_set1_ps(1.0), sum);
            for j in 0..rows {
                let at = b.add(j * TILE + 16 * c);
                _mm512_storeu_ps(at, _mm512_mul_ps(_mm512_loadu_ps(at), inv));
            }
        }
    }
}

/// Softplus in place over `x` and its slope `sigmoid(β·x)` into `slope` (the trainer's forward
/// pass keeps the slope for its backward pass), 16 lanes at a time; the tail goes through the
/// scalar path.
///
/// # Safety
/// The CPU must support avx512f, and `slope.len() == x.len()`.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn softplus_with_slope(x: &mut [f32], slope: &mut [f32], beta: f32) {
    let n = x.len() - x.len() % 16;
    let (b, ib) = (_mm512_set1_ps(beta), _mm512_set1_ps(1.0 / beta));
    let (xp, sp) = (x.as_mut_ptr(), slope.as_mut_ptr());
    for i in (0..n).step_by(16) {
        // SAFETY: `i + 16 ≤ n ≤ x.len() = slope.len()`.
        unsafe {
            let x = _mm512_loadu_ps(xp.add(i));
            let e = tail_exp(x, b);
            let h = _mm512_fmadd_ps(log1p_ps(e), ib, _mm512_max_ps(x, _mm512_setzero_ps()));
            let inv = _mm512_div_ps(_mm512_set1_ps(1.0), _mm512_add_ps(e, _mm512_set1_ps(1.0)));
            let ge = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(x, _mm512_setzero_ps());
            let s = _mm512_mask_blend_ps(ge, _mm512_mul_ps(e, inv), inv);
            _mm512_storeu_ps(xp.add(i), h);
            _mm512_storeu_ps(sp.add(i), s);
        }
    }
    super::scalar::softplus_with_slope(&mut x[n..], &mut slope[n..], beta);
}
