//! Strided matrix views and one matrix product over them, on the `gemm` crate (the blocked,
//! multi-threaded GEMM candle itself runs on; its AVX-512 kernels are chosen at run time).
//!
//! A view is `(rows, cols, row stride, column stride)` over a slice, so a transpose or a block
//! of columns costs nothing: the backward pass's `dZᵀ·H` and `dZ·W` read the forward pass's
//! buffers in place. Every view is checked to lie inside its slice when it is made; that check
//! is what makes the one `unsafe` call below sound.

/// A read-only strided view of an f32 matrix.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MatRef<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
    row_stride: usize,
    col_stride: usize,
}

/// A writable strided view of an f32 matrix.
#[derive(Debug)]
pub(crate) struct MatMut<'a> {
    data: &'a mut [f32],
    rows: usize,
    cols: usize,
    row_stride: usize,
    col_stride: usize,
}

/// Whether `(rows, cols, row_stride, col_stride)` addresses only elements below `len`.
fn in_bounds(len: usize, rows: usize, cols: usize, row_stride: usize, col_stride: usize) -> bool {
    if rows == 0 || cols == 0 {
        return true;
    }
    (rows - 1)
        .checked_mul(row_stride)
        .and_then(|a| {
            (cols - 1)
                .checked_mul(col_stride)
                .and_then(|b| a.checked_add(b))
        })
        .is_some_and(|last| last < len)
}

impl<'a> MatRef<'a> {
    /// The row-major `rows × cols` matrix stored in `data`.
    pub(crate) fn row_major(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self::strided(data, rows, cols, cols, 1)
    }

    /// A general strided view (panics if it reaches past `data`: an internal invariant).
    pub(crate) fn strided(
        data: &'a [f32],
        rows: usize,
        cols: usize,
        row_stride: usize,
        col_stride: usize,
    ) -> Self {
        assert!(
            in_bounds(data.len(), rows, cols, row_stride, col_stride),
            "matrix view past its slice (internal invariant)"
        );
        Self {
            data,
            rows,
            cols,
            row_stride,
            col_stride,
        }
    }

    /// The transpose (no copy).
    pub(crate) fn t(self) -> Self {
        Self {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
            ..self
        }
    }

    /// Columns `start..start + count` (no copy).
    pub(crate) fn columns(self, start: usize, count: usize) -> Self {
        assert!(
            start + count <= self.cols,
            "column block past the matrix (internal invariant)"
        );
        let offset = if count == 0 || self.rows == 0 {
            0
        } else {
            start * self.col_stride
        };
        Self::strided(
            &self.data[offset.min(self.data.len())..],
            self.rows,
            count,
            self.row_stride,
            self.col_stride,
        )
    }
}

impl<'a> MatMut<'a> {
    /// The row-major `rows × cols` matrix stored in `data`.
    pub(crate) fn row_major(data: &'a mut [f32], rows: usize, cols: usize) -> Self {
        Self::strided(data, rows, cols, cols, 1)
    }

    /// A general strided view (panics if it reaches past `data`: an internal invariant).
    pub(crate) fn strided(
        data: &'a mut [f32],
        rows: usize,
        cols: usize,
        row_stride: usize,
        col_stride: usize,
    ) -> Self {
        assert!(
            in_bounds(data.len(), rows, cols, row_stride, col_stride),
            "matrix view past its slice (internal invariant)"
        );
        Self {
            data,
            rows,
            cols,
            row_stride,
            col_stride,
        }
    }

    /// Columns `start..start + count` (no copy).
    pub(crate) fn columns(self, start: usize, count: usize) -> MatMut<'a> {
        assert!(
            start + count <= self.cols,
            "column block past the matrix (internal invariant)"
        );
        let offset = if count == 0 || self.rows == 0 {
            0
        } else {
            start * self.col_stride
        };
        let len = self.data.len();
        MatMut::strided(
            &mut self.data[offset.min(len)..],
            self.rows,
            count,
            self.row_stride,
            self.col_stride,
        )
    }
}

/// `dst = a · b` (or `dst += a · b` with `accumulate`), on `threads` threads of the current
/// rayon pool. Shapes must agree (an internal invariant, asserted).
pub(crate) fn matmul(
    dst: MatMut<'_>,
    a: MatRef<'_>,
    b: MatRef<'_>,
    accumulate: bool,
    threads: usize,
) {
    assert!(
        a.rows == dst.rows && b.cols == dst.cols && a.cols == b.rows,
        "matmul shapes {}×{} · {}×{} → {}×{} (internal invariant)",
        a.rows,
        a.cols,
        b.rows,
        b.cols,
        dst.rows,
        dst.cols
    );
    if dst.rows == 0 || dst.cols == 0 {
        return;
    }
    if a.cols == 0 {
        if !accumulate {
            for r in 0..dst.rows {
                for c in 0..dst.cols {
                    dst.data[r * dst.row_stride + c * dst.col_stride] = 0.0;
                }
            }
        }
        return;
    }
    let parallelism = if threads > 1 {
        gemm::Parallelism::Rayon(threads)
    } else {
        gemm::Parallelism::None
    };
    let stride = |s: usize| s as isize;
    // SAFETY: every view was checked at construction to address only elements of its own slice
    // (`in_bounds`), the shapes agree (asserted above), and `dst` is a unique borrow, so it
    // aliases neither `a` nor `b`. gemm reads `m·k` + `k·n` elements and writes `m·n` through
    // exactly these strides.
    unsafe {
        gemm::gemm(
            dst.rows,
            dst.cols,
            a.cols,
            dst.data.as_mut_ptr(),
            stride(dst.col_stride),
            stride(dst.row_stride),
            accumulate,
            a.data.as_ptr(),
            stride(a.col_stride),
            stride(a.row_stride),
            b.data.as_ptr(),
            stride(b.col_stride),
            stride(b.row_stride),
            1.0,
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(a: &[f32], b: &[f32], m: usize, k: usize, n: usize) -> Vec<f32> {
        let mut c = vec![0.0; m * n];
        for i in 0..m {
            for j in 0..n {
                c[i * n + j] = (0..k).map(|l| a[i * k + l] * b[l * n + j]).sum();
            }
        }
        c
    }

    #[test]
    fn transposed_and_column_block_views_multiply_like_the_naive_product() {
        let (m, k, n) = (37, 19, 23);
        let a: Vec<f32> = (0..m * k).map(|i| ((i * 7) % 13) as f32 - 6.0).collect();
        let b: Vec<f32> = (0..k * n).map(|i| ((i * 5) % 11) as f32 - 5.0).collect();
        let want = naive(&a, &b, m, k, n);
        for threads in [1, 2] {
            // Plain product.
            let mut c = vec![f32::NAN; m * n];
            matmul(
                MatMut::row_major(&mut c, m, n),
                MatRef::row_major(&a, m, k),
                MatRef::row_major(&b, k, n),
                false,
                threads,
            );
            assert_eq!(c, want);
            // (bᵀ · aᵀ)ᵀ written through a transposed destination, accumulated onto ones.
            let mut ct = vec![1.0; n * m];
            let dst = MatMut::strided(&mut ct, n, m, 1, n);
            matmul(
                dst,
                MatRef::row_major(&b, k, n).t(),
                MatRef::row_major(&a, m, k).t(),
                true,
                threads,
            );
            for i in 0..m {
                for j in 0..n {
                    assert_eq!(ct[i * n + j], want[i * n + j] + 1.0);
                }
            }
        }
        // A block of columns of a wider matrix: [a | junk] restricted to a's columns.
        let wide: Vec<f32> = (0..m)
            .flat_map(|i| {
                let mut row = vec![99.0; 3];
                row.extend_from_slice(&a[i * k..(i + 1) * k]);
                row
            })
            .collect();
        let mut c = vec![0.0; m * n];
        matmul(
            MatMut::row_major(&mut c, m, n),
            MatRef::row_major(&wide, m, k + 3).columns(3, k),
            MatRef::row_major(&b, k, n),
            false,
            1,
        );
        assert_eq!(c, want);
    }

    #[test]
    fn views_are_bounds_checked() {
        let data = [0.0f32; 6];
        assert!(in_bounds(6, 2, 3, 3, 1));
        assert!(!in_bounds(5, 2, 3, 3, 1));
        assert!(!in_bounds(6, 2, 3, usize::MAX, 1));
        assert!(std::panic::catch_unwind(|| MatRef::strided(&data, 3, 3, 3, 1)).is_err());
    }
}
