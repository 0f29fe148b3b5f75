//! Blending skinning matrices over a short influence list, `M += Σ w_i · mats[j_i]`: the inner
//! loop of sparse LBS (the fast path's base joints and node residual matrices, static
//! skinning's influences). A `Mat4` is 16 contiguous floats, so AVX-512 blends one influence
//! with one FMA and AVX2 with two; the portable path uses glam's operators.

use glam::Mat4;

use super::Kernel;

/// Adds `Σ w · mats[j]` over `influences` to `acc`; an index past `mats` is skipped.
#[inline]
pub(crate) fn blend(
    kernel: Kernel,
    acc: &mut Mat4,
    mats: &[Mat4],
    influences: impl Iterator<Item = (usize, f32)>,
) {
    match kernel {
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 if !cfg!(feature = "scalar") => {
            // SAFETY: a stored Avx512 kernel was checked with `is_available` (avx512f).
            unsafe { x86::blend_avx512(acc, mats, influences) }
        }
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 if !cfg!(feature = "scalar") => {
            // SAFETY: a stored Avx2 kernel was checked with `is_available` (avx2 + fma).
            unsafe { x86::blend_avx2(acc, mats, influences) }
        }
        _ => blend_scalar(acc, mats, influences),
    }
}

fn blend_scalar(acc: &mut Mat4, mats: &[Mat4], influences: impl Iterator<Item = (usize, f32)>) {
    for (j, w) in influences {
        if let Some(m) = mats.get(j) {
            *acc += *m * w;
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use core::arch::x86_64::*;

    use glam::Mat4;

    /// # Safety
    /// The CPU must support AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn blend_avx512(
        acc: &mut Mat4,
        mats: &[Mat4],
        influences: impl Iterator<Item = (usize, f32)>,
    ) {
        let out: &mut [f32; 16] = acc.as_mut();
        // SAFETY: `out` is 16 floats; unaligned loads and stores.
        let mut a = unsafe { _mm512_loadu_ps(out.as_ptr()) };
        for (j, w) in influences {
            if let Some(m) = mats.get(j) {
                let m: &[f32; 16] = m.as_ref();
                // SAFETY: `m` is 16 floats.
                let x = unsafe { _mm512_loadu_ps(m.as_ptr()) };
                a = _mm512_fmadd_ps(_mm512_set1_ps(w), x, a);
            }
        }
        // SAFETY: as above.
        unsafe { _mm512_storeu_ps(out.as_mut_ptr(), a) };
    }

    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn blend_avx2(
        acc: &mut Mat4,
        mats: &[Mat4],
        influences: impl Iterator<Item = (usize, f32)>,
    ) {
        let out: &mut [f32; 16] = acc.as_mut();
        // SAFETY: `out` is 16 floats: two 8-float halves; unaligned loads and stores.
        let (mut lo, mut hi) = unsafe {
            (
                _mm256_loadu_ps(out.as_ptr()),
                _mm256_loadu_ps(out.as_ptr().add(8)),
            )
        };
        for (j, w) in influences {
            if let Some(m) = mats.get(j) {
                let m: &[f32; 16] = m.as_ref();
                let w = _mm256_set1_ps(w);
                // SAFETY: `m` is 16 floats.
                let (x0, x1) = unsafe {
                    (
                        _mm256_loadu_ps(m.as_ptr()),
                        _mm256_loadu_ps(m.as_ptr().add(8)),
                    )
                };
                lo = _mm256_fmadd_ps(w, x0, lo);
                hi = _mm256_fmadd_ps(w, x1, hi);
            }
        }
        // SAFETY: as above.
        unsafe {
            _mm256_storeu_ps(out.as_mut_ptr(), lo);
            _mm256_storeu_ps(out.as_mut_ptr().add(8), hi);
        }
    }
}

#[cfg(test)]
mod tests {
    use alloc::vec::Vec;

    use super::*;

    #[test]
    fn every_available_kernel_equals_the_scalar_blend() {
        let mut state = 99u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 23) as f32 - 1.0
        };
        let mats: Vec<Mat4> = (0..20)
            .map(|_| Mat4::from_cols_array(&core::array::from_fn(|_| next())))
            .collect();
        // Includes an out-of-range index (skipped) and a repeated joint.
        let infl: Vec<(usize, f32)> = [0usize, 3, 19, 7, 3, 25, 11, 2]
            .iter()
            .map(|&j| (j, next()))
            .collect();
        let start = Mat4::from_cols_array(&core::array::from_fn(|_| next()));
        let mut want = start;
        blend_scalar(&mut want, &mats, infl.iter().copied());
        for kernel in Kernel::ALL.into_iter().filter(|k| k.is_available()) {
            let mut got = start;
            blend(kernel, &mut got, &mats, infl.iter().copied());
            assert!(got.abs_diff_eq(want, 1e-5), "{kernel:?}: {got} vs {want}");
        }
        // The reference itself: one influence is a plain scaled add.
        let mut one = Mat4::ZERO;
        blend_scalar(&mut one, &mats, [(4usize, 0.5f32)].into_iter());
        assert_eq!(one, mats[4] * 0.5);
    }
}
