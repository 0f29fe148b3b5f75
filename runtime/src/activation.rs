//! Activation math: Softplus with the file's β and softmax, exact (libm) for the scalar path and
//! as the polynomial approximations the SIMD kernels vectorise.
//!
//! Softplus is evaluated in the numerically stable form
//! `softplus_β(x) = max(x, 0) + log1p(exp(−β|x|)) / β`, which never overflows (the trainer's
//! `log(1 + exp(βx)) / β` overflows for βx > 88). The polynomial versions below use the same
//! constants as the AVX2 and AVX-512 kernels, so their accuracy is tested here, lane by lane,
//! against libm.

/// Lower clamp of the exp argument, `−EXP_TAIL`: callers treat anything below it as zero
/// (see [`EXP_TAIL`]), and `exp(-72) ≈ 5e-32` keeps every intermediate of `exp` and of
/// `log1p` of its result a normal float.
pub const EXP_MIN: f32 = -72.0;
/// Tail cut of softmax: where `max − x` exceeds this, `exp` is below `e^-72 ≈ 5e-32` and the
/// weight is taken as exactly zero. Kept, it would end as a subnormal float within a few more
/// units, and every arithmetic use of a subnormal costs a ~100-cycle microcode assist on Intel
/// cores (the exact MLP ran 60× slower before the tails were cut). Softplus has its own clamp,
/// [`SOFTPLUS_EXP_MIN`].
pub const EXP_TAIL: f32 = 72.0;
/// Upper clamp of the exp argument (only softmax needs positive arguments; it never passes any,
/// because it subtracts the maximum first).
pub const EXP_MAX: f32 = 88.0;
/// Lower clamp of Softplus's exp argument `−β|x|`. Below `e^−60 ≈ 9e-27` the tail
/// `log1p(e)/β` is far below any value that matters, and stopping there keeps every
/// intermediate of the polynomials a normal float: denormal operands cost x86 cores a
/// microcode assist each, which made the SIMD Softplus slower than the matrix products around
/// it when many units sat deep in the negative tail.
pub const SOFTPLUS_EXP_MIN: f32 = -60.0;
/// Lower clamp of `s` where the log1p polynomial squares it (`2^-50`): `s²` stays normal, and
/// the polynomial is exactly 1 in f32 below it either way, so results do not change.
pub const LOG1P_S_MIN: f32 = 8.881_784e-16;
/// `log2(e)`.
pub const LOG2E: f32 = core::f32::consts::LOG2_E;
/// Cody–Waite split of `ln 2`: high part (exact in f32 with 9 bits of mantissa).
pub const LN2_HI: f32 = 0.693_359_4;
/// Cody–Waite split of `ln 2`: low part.
pub const LN2_LO: f32 = -2.121_944_4e-4;
/// Cephes `expf` polynomial on `[-ln2/2, ln2/2]`, highest degree first: `exp(r) ≈ 1 + r + r²·P(r)`.
pub const EXP_P: [f32; 6] = [
    1.987_569_1e-4,
    1.398_199_9e-3,
    8.333_452e-3,
    4.166_579_6e-2,
    1.666_666_5e-1,
    0.5,
];
/// `atanh` series `Σ z^k / (2k+1)`, highest degree first, for `log1p(y) = 2s·Q(s²)` with
/// `s = y / (2 + y) ∈ [0, 1/3]` (truncation error below 1.5e-8 relative).
pub const LOG1P_Q: [f32; 7] = [
    1.0 / 13.0,
    1.0 / 11.0,
    1.0 / 9.0,
    1.0 / 7.0,
    1.0 / 5.0,
    1.0 / 3.0,
    1.0,
];

/// The activation applied after a linear layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Act {
    /// `softplus_β`.
    Softplus {
        /// Sharpness β (> 0, finite).
        beta: f32,
    },
    /// No activation (the output layer; softmax follows over the joints).
    Identity,
}

/// Exact Softplus with sharpness `beta`, stable form (libm).
#[must_use]
pub fn softplus(x: f32, beta: f32) -> f32 {
    x.max(0.0) + libm::log1pf(libm::expf((-beta * x.abs()).max(SOFTPLUS_EXP_MIN))) / beta
}

/// The slope of Softplus, `sigmoid(βx)` (exact, libm), evaluated from `e = exp(−β|x|)` so it
/// neither overflows nor loses the tail: `1/(1 + e)` for `x ≥ 0`, `e/(1 + e)` below.
#[must_use]
pub fn softplus_slope(x: f32, beta: f32) -> f32 {
    let e = libm::expf(-beta * x.abs());
    if x >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    }
}

#[cfg(test)] // the scalar mirror the tests check the SIMD polynomials' constants with
/// `exp(z)` for `z ≤ 0` by the kernels' polynomial (scalar mirror of the SIMD code).
#[must_use]
pub fn exp_poly(z: f32) -> f32 {
    let z = z.clamp(EXP_MIN, EXP_MAX);
    let n = libm::floorf(z * LOG2E + 0.5);
    let r = z - n * LN2_HI - n * LN2_LO;
    let mut p = EXP_P[0];
    for c in &EXP_P[1..] {
        p = p * r + c;
    }
    let y = p * r * r + r + 1.0;
    // n ∈ [-126, 127] after the clamp: a normal power of two.
    y * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

#[cfg(test)] // the scalar mirror the tests check the SIMD polynomials' constants with
/// `log1p(y)` for `y ∈ [0, 1]` by the kernels' polynomial (scalar mirror of the SIMD code).
#[must_use]
pub fn log1p_poly(y: f32) -> f32 {
    let s = y / (2.0 + y);
    let z = s.max(LOG1P_S_MIN) * s.max(LOG1P_S_MIN);
    let mut q = LOG1P_Q[0];
    for c in &LOG1P_Q[1..] {
        q = q * z + c;
    }
    2.0 * s * q
}

#[cfg(test)] // the scalar mirror the tests check the SIMD polynomials' constants with
/// Softplus by the kernels' polynomials.
#[must_use]
pub fn softplus_poly(x: f32, beta: f32) -> f32 {
    x.max(0.0) + log1p_poly(exp_poly((-beta * x.abs()).max(SOFTPLUS_EXP_MIN))) / beta
}

#[cfg(test)] // the scalar mirror the tests check the SIMD polynomials' constants with
/// Softmax in place (exact; max subtracted first, so it never overflows; weights below
/// `e^-72` of the largest are exactly zero, see [`EXP_TAIL`]).
pub fn softmax(x: &mut [f32]) {
    let m = x.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0;
    for v in x.iter_mut() {
        *v = if *v - m >= -EXP_TAIL {
            libm::expf(*v - m)
        } else {
            0.0
        };
        sum += *v;
    }
    let inv = 1.0 / sum;
    for v in x.iter_mut() {
        *v *= inv;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f32, b: f64) -> f64 {
        (f64::from(a) - b).abs() / b.abs().max(1e-300)
    }

    #[test]
    fn exp_poly_is_accurate_over_its_range() {
        let mut worst: f64 = 0.0;
        for i in 0..=200_000 {
            let z = EXP_MIN * i as f32 / 200_000.0;
            worst = worst.max(rel(exp_poly(z), libm::exp(f64::from(z))));
        }
        assert!(worst < 3e-7, "exp_poly worst relative error {worst}");
    }

    #[test]
    fn log1p_poly_is_accurate_on_unit_interval() {
        let mut worst: f64 = 0.0;
        for i in 1..=200_000 {
            // Logarithmic sweep covers tiny arguments, where naive log(1 + y) loses everything.
            let y = libm::powf(10.0, -30.0 + 30.0 * i as f32 / 200_000.0);
            worst = worst.max(rel(log1p_poly(y), libm::log1p(f64::from(y))));
        }
        assert!(worst < 3e-7, "log1p_poly worst relative error {worst}");
    }

    #[test]
    fn softplus_matches_the_defining_formula_in_f64() {
        for beta in [1.0f32, 100.0] {
            for i in -2000..=2000 {
                let x = i as f32 * 0.003;
                let bx = f64::from(beta) * f64::from(x);
                // Defining formula, evaluated where it does not overflow.
                let want = libm::log1p(libm::exp(bx)) / f64::from(beta);
                let tol = 2e-6 * want.abs().max(1e-30) + 1e-12;
                assert!(
                    (f64::from(softplus(x, beta)) - want).abs() <= tol,
                    "libm {x} {beta}"
                );
                assert!(
                    (f64::from(softplus_poly(x, beta)) - want).abs() <= tol,
                    "poly {x} {beta}"
                );
            }
        }
        // Large arguments: no overflow, identity.
        assert_eq!(softplus(1e30, 100.0), 1e30);
        // exp's argument is clamped at −60, so the far negative tail is e^-60/β ≈ 9e-29
        // instead of 0.
        assert!(softplus_poly(-1e30, 100.0).abs() < 1e-28);
        assert!(softplus(-1e30, 100.0).abs() < 1e-28);
    }

    #[test]
    fn no_activation_output_is_subnormal() {
        for beta in [1.0f32, 10.0, 100.0, 1000.0] {
            for i in -100_000..=0 {
                let x = i as f32 * 1e-5 * 100.0 / beta;
                for y in [softplus(x, beta), softplus_poly(x, beta)] {
                    assert!(y == 0.0 || y.is_normal(), "softplus({x}, {beta}) = {y:e}");
                }
            }
        }
        let mut x = [0.0, -70.0, -71.9, -72.1, -80.0, -87.5, -1e30];
        softmax(&mut x);
        assert!(x.iter().all(|v| *v == 0.0 || v.is_normal()), "{x:?}");
        assert_eq!(x[3..], [0.0; 4]);
    }

    #[test]
    fn softmax_sums_to_one_and_survives_large_logits() {
        let mut x = [1000.0, 1001.0, -5.0];
        softmax(&mut x);
        assert!((x.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let e = libm::exp(-1.0f64);
        assert!((f64::from(x[1]) - 1.0 / (1.0 + e)).abs() < 1e-6);
    }
}
