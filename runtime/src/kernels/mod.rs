//! The per-tile MLP kernels: one dense layer over a tile of [`TILE`] vertices with bias,
//! per-vertex precomputed part and activation fused into the store, and the softmax over joints.
//!
//! Layouts (shared by every kernel, so a model expanded once works with any of them):
//! - activations of a tile: `[feature][TILE]` (one row of `TILE` vertices per feature), so the
//!   kernels vectorise over vertices and every layer width is legal;
//! - weights: panels of `MR` output rows, `panel[k][r] = W[MR·p + r][k]`, rows past the
//!   layer's width zero; a panel of a 256-wide layer is 8 KiB and stays in L1 while a tile's
//!   input rows stream through it.
//!
//! The kernel is chosen once ([`Kernel::detect`]) and stored in the model.

use crate::RuntimeError;
use crate::activation::Act;

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod blend;
mod scalar;

pub(crate) use blend::blend;

/// Vertices per tile (the GEMM's N dimension).
pub const TILE: usize = 32;

/// `(start, len)` of the tiles of at most [`TILE`] outputs covering `0..count`.
pub(crate) fn tiles(count: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..count)
        .step_by(TILE)
        .map(move |start| (start, TILE.min(count - start)))
}
/// Output rows per weight panel (the GEMM's M blocking).
pub(crate) const MR: usize = 8;

/// Which implementation evaluates the layers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kernel {
    /// Portable Rust, always compiled (libm activations).
    Scalar,
    /// x86-64 AVX2 + FMA.
    Avx2,
    /// x86-64 AVX-512F.
    Avx512,
}

impl Kernel {
    /// Every kernel, slowest first.
    pub const ALL: [Kernel; 3] = [Kernel::Scalar, Kernel::Avx2, Kernel::Avx512];

    /// Whether this CPU (with `std`: detected at run time; without: the compile-time target
    /// features) and this build (the `scalar` feature forces [`Kernel::Scalar`]) can run it.
    #[must_use]
    pub fn is_available(self) -> bool {
        if cfg!(feature = "scalar") {
            return self == Kernel::Scalar;
        }
        match self {
            Kernel::Scalar => true,
            Kernel::Avx2 => has_avx2(),
            Kernel::Avx512 => has_avx512(),
        }
    }

    /// The fastest available kernel.
    #[must_use]
    pub fn detect() -> Kernel {
        *Self::ALL
            .iter()
            .rev()
            .find(|k| k.is_available())
            .unwrap_or(&Kernel::Scalar)
    }
}

#[cfg(all(target_arch = "x86_64", feature = "std"))]
fn has_avx2() -> bool {
    std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
}
#[cfg(all(target_arch = "x86_64", not(feature = "std")))]
fn has_avx2() -> bool {
    cfg!(all(target_feature = "avx2", target_feature = "fma"))
}
#[cfg(all(target_arch = "x86_64", feature = "std"))]
fn has_avx512() -> bool {
    std::is_x86_feature_detected!("avx512f")
}
#[cfg(all(target_arch = "x86_64", not(feature = "std")))]
fn has_avx512() -> bool {
    cfg!(target_feature = "avx512f")
}
#[cfg(not(target_arch = "x86_64"))]
fn has_avx2() -> bool {
    false
}
#[cfg(not(target_arch = "x86_64"))]
fn has_avx512() -> bool {
    false
}

/// One fused layer over one tile: `out[o][v] = act(Σ_k W[o][k]·input[k][v] + bias[o] + pre[o][v])`
/// for `o < rows_p` (padded rows of `W` and `bias` are zero).
pub(crate) struct LayerArgs<'a> {
    /// `rows_p / MR` panels of `k × MR`.
    pub panels: &'a [f32],
    /// Input width (0: no GEMM, only bias + pre + activation).
    pub k: usize,
    /// `k × TILE`.
    pub input: &'a [f32],
    /// `rows_p`.
    pub bias: &'a [f32],
    /// `rows_p × TILE`, the per-vertex precomputed part, if the layer has one.
    pub pre: Option<&'a [f32]>,
    /// `rows_p × TILE`.
    pub out: &'a mut [f32],
    /// Output rows, a multiple of [`MR`].
    pub rows_p: usize,
    /// Activation.
    pub act: Act,
}

impl LayerArgs<'_> {
    /// The slice lengths are an internal invariant (sizes come from one layout); checking them
    /// once here is what makes the raw-pointer loops of the SIMD kernels in bounds.
    fn assert_shapes(&self) {
        let ok = self.rows_p.is_multiple_of(MR)
            && self.panels.len() >= self.rows_p * self.k
            && self.input.len() >= self.k * TILE
            && self.bias.len() >= self.rows_p
            && self.pre.is_none_or(|p| p.len() >= self.rows_p * TILE)
            && self.out.len() >= self.rows_p * TILE;
        assert!(
            ok,
            "kernel layer arguments out of shape (internal invariant)"
        );
    }
}

/// Runs one fused layer with `kernel` (which must be available: the model checks at load).
pub(crate) fn layer(kernel: Kernel, args: LayerArgs<'_>) {
    args.assert_shapes();
    match kernel {
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 if !cfg!(feature = "scalar") => {
            // SAFETY: the model only stores Avx512 after `is_available` confirmed avx512f;
            // shapes were checked just above.
            unsafe { avx512::layer(args) }
        }
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 if !cfg!(feature = "scalar") => {
            // SAFETY: the model only stores Avx2 after `is_available` confirmed avx2 + fma;
            // shapes were checked just above.
            unsafe { avx2::layer(args) }
        }
        _ => scalar::layer(args),
    }
}

/// Softmax over the first `rows` rows of a `[row][TILE]` buffer, per vertex column.
pub(crate) fn softmax_tile(kernel: Kernel, buf: &mut [f32], rows: usize) {
    assert!(
        rows >= 1 && buf.len() >= rows * TILE,
        "softmax tile out of shape (internal invariant)"
    );
    match kernel {
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 if !cfg!(feature = "scalar") => {
            // SAFETY: as in `layer`; the shape was checked just above.
            unsafe { avx512::softmax_tile(buf, rows) }
        }
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 if !cfg!(feature = "scalar") => {
            // SAFETY: as in `layer`; the shape was checked just above.
            unsafe { avx2::softmax_tile(buf, rows) }
        }
        _ => scalar::softmax_tile(buf, rows),
    }
}

/// Softplus with sharpness `beta` in place over `x`, and its slope `sigmoid(β·x)` written to
/// `slope`: the activation of a training step's forward pass together with what its backward
/// pass needs (`∂softplus/∂x`), with the same polynomials the runtime's layers use.
///
/// # Errors
/// [`RuntimeError::BufferLength`] (field `slope`) when the slices differ in length, and
/// [`RuntimeError::KernelUnavailable`] for a kernel this CPU or build cannot run.
pub fn softplus_with_slope(
    kernel: Kernel,
    x: &mut [f32],
    slope: &mut [f32],
    beta: f32,
) -> Result<(), RuntimeError> {
    if slope.len() != x.len() {
        return Err(RuntimeError::BufferLength {
            field: "slope",
            len: slope.len(),
            expected: x.len(),
        });
    }
    if !kernel.is_available() {
        return Err(RuntimeError::KernelUnavailable(kernel));
    }
    match kernel {
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 if !cfg!(feature = "scalar") => {
            // SAFETY: availability was checked just above, and the lengths are equal.
            unsafe { avx512::softplus_with_slope(x, slope, beta) }
        }
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 if !cfg!(feature = "scalar") => {
            // SAFETY: availability was checked just above, and the lengths are equal.
            unsafe { avx2::softplus_with_slope(x, slope, beta) }
        }
        _ => scalar::softplus_with_slope(x, slope, beta),
    }
    Ok(())
}

/// Packs a `rows × k` matrix given by `get(row, col)` into `MR`-row panels (`out` holds
/// `round_up(rows, MR) × k` floats), padding rows with zeros; stops at the first error of `get`.
pub(crate) fn pack_panels<E>(
    rows: usize,
    k: usize,
    out: &mut [f32],
    mut get: impl FnMut(usize, usize) -> Result<f32, E>,
) -> Result<(), E> {
    if k == 0 {
        return Ok(());
    }
    for (p, panel) in out
        .chunks_exact_mut(k * MR)
        .enumerate()
        .take(rows.div_ceil(MR))
    {
        for (kk, w) in panel.chunks_exact_mut(MR).enumerate() {
            for (r, slot) in w.iter_mut().enumerate() {
                let o = p * MR + r;
                *slot = if o < rows { get(o, kk)? } else { 0.0 };
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
