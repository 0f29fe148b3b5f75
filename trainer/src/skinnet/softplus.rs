//! Fused Softplus and softmax ops with their own backward passes.
//!
//! candle has no Softplus; the composite `relu(x) + log1p(exp(-|βx|))/β` allocates five
//! intermediate tensors forward and as many again backward, which costs about half of a SkinNet
//! training step on the CPU. The fused op does one pass forward and one pass backward
//! (`∂/∂x = sigmoid(βx)`). candle-nn's `softmax_last_dim` has no backward at all, so the fused
//! softmax here carries one (`∂x = s ⊙ (g − ⟨g, s⟩)`).

use candle_core::{CpuStorage, CustomOp1, CustomOp2, DType, Layout, Result, Shape, Tensor, bail};

/// `softplus(x) = log(1 + exp(βx)) / β`, evaluated stably as `max(x, 0) + log1p(exp(−|βx|))/β`.
#[must_use]
pub fn softplus_scalar(x: f64, beta: f64) -> f64 {
    x.max(0.0) + (-(beta * x).abs()).exp().ln_1p() / beta
}

/// `sigmoid(βx)`, the derivative of [`softplus_scalar`].
#[must_use]
pub fn softplus_grad_scalar(x: f64, beta: f64) -> f64 {
    let z = beta * x;
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

fn softplus_f32(x: f32, beta: f32) -> f32 {
    x.max(0.0) + (-(beta * x).abs()).exp().ln_1p() / beta
}

fn sigmoid_f32(z: f32) -> f32 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// The contiguous slice a layout covers (the fused ops only take contiguous inputs; every tensor
/// that reaches them is a matmul or add output, which candle stores contiguously).
fn contiguous<'a, T>(data: &'a [T], layout: &Layout, op: &str) -> Result<&'a [T]> {
    match layout.contiguous_offsets() {
        Some((a, b)) => Ok(&data[a..b]),
        None => bail!("{op} needs a contiguous input"),
    }
}

/// Fused Softplus with sharpness β.
#[derive(Clone, Copy, Debug)]
pub struct Softplus {
    /// Sharpness β (IGR and the paper: 100).
    pub beta: f32,
}

impl CustomOp1 for Softplus {
    fn name(&self) -> &'static str {
        "softplus"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let out = match storage {
            CpuStorage::F32(d) => {
                let b = self.beta;
                CpuStorage::F32(
                    contiguous(d, layout, "softplus")?
                        .iter()
                        .map(|&x| softplus_f32(x, b))
                        .collect(),
                )
            }
            CpuStorage::F64(d) => {
                let b = f64::from(self.beta);
                CpuStorage::F64(
                    contiguous(d, layout, "softplus")?
                        .iter()
                        .map(|&x| softplus_scalar(x, b))
                        .collect(),
                )
            }
            _ => bail!("softplus: only f32 and f64 are supported"),
        };
        Ok((out, layout.shape().clone()))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let g = grad_res.contiguous()?;
        Ok(Some(
            arg.contiguous()?
                .apply_op2_no_bwd(&g, &SoftplusGrad { beta: self.beta })?,
        ))
    }
}

/// `sigmoid(β·x) ⊙ g`: Softplus's backward, fused (first argument x, second g).
#[derive(Clone, Copy, Debug)]
struct SoftplusGrad {
    beta: f32,
}

impl CustomOp2 for SoftplusGrad {
    fn name(&self) -> &'static str {
        "softplus-grad"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        if l1.shape() != l2.shape() {
            bail!(
                "softplus-grad: shapes {:?} and {:?} differ",
                l1.shape(),
                l2.shape()
            );
        }
        let out = match (s1, s2) {
            (CpuStorage::F32(x), CpuStorage::F32(g)) => {
                let (x, g) = (
                    contiguous(x, l1, "softplus-grad")?,
                    contiguous(g, l2, "softplus-grad")?,
                );
                let b = self.beta;
                CpuStorage::F32(
                    x.iter()
                        .zip(g)
                        .map(|(&x, &g)| sigmoid_f32(b * x) * g)
                        .collect(),
                )
            }
            (CpuStorage::F64(x), CpuStorage::F64(g)) => {
                let (x, g) = (
                    contiguous(x, l1, "softplus-grad")?,
                    contiguous(g, l2, "softplus-grad")?,
                );
                let b = f64::from(self.beta);
                CpuStorage::F64(
                    x.iter()
                        .zip(g)
                        .map(|(&x, &g)| softplus_grad_scalar(x, b) * g)
                        .collect(),
                )
            }
            _ => bail!("softplus-grad: only f32 and f64 are supported"),
        };
        Ok((out, l1.shape().clone()))
    }
}

/// Applies the fused Softplus (differentiable).
pub fn softplus(x: &Tensor, beta: f32) -> Result<Tensor> {
    x.contiguous()?.apply_op1(Softplus { beta })
}

/// The composite Softplus from candle primitives, `relu(x) + log1p(exp(−|βx|))/β` (candle has no
/// `log1p`, so `log(1 + ·)`): the reference the fused op is tested and benchmarked against.
pub fn softplus_composite(x: &Tensor, beta: f32) -> Result<Tensor> {
    let b = f64::from(beta);
    let tail = ((x.abs()? * (-b))?.exp()? + 1.0)?.log()?;
    x.relu()? + (tail / b)?
}

/// Fused softmax over the last dimension, with backward.
#[derive(Clone, Copy, Debug)]
pub struct SoftmaxLast;

impl CustomOp1 for SoftmaxLast {
    fn name(&self) -> &'static str {
        "softmax-last-bwd"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let n = layout.shape().dims().last().copied().unwrap_or(1).max(1);
        fn rows<T: num_like::Float>(d: &[T], n: usize) -> Vec<T> {
            let mut out = d.to_vec();
            for row in out.chunks_mut(n) {
                let m = row.iter().copied().fold(T::NEG_INF, T::max);
                let mut s = T::ZERO;
                for v in row.iter_mut() {
                    *v = (*v - m).exp();
                    s = s + *v;
                }
                for v in row.iter_mut() {
                    *v = *v / s;
                }
            }
            out
        }
        let out = match storage {
            CpuStorage::F32(d) => CpuStorage::F32(rows(contiguous(d, layout, "softmax")?, n)),
            CpuStorage::F64(d) => CpuStorage::F64(rows(contiguous(d, layout, "softmax")?, n)),
            _ => bail!("softmax: only f32 and f64 are supported"),
        };
        Ok((out, layout.shape().clone()))
    }

    fn bwd(&self, _arg: &Tensor, res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let dot = (grad_res * res)?.sum_keepdim(candle_core::D::Minus1)?;
        Ok(Some((res * grad_res.broadcast_sub(&dot)?)?))
    }
}

/// Softmax over the last dimension (differentiable).
pub fn softmax_last(x: &Tensor) -> Result<Tensor> {
    match x.dtype() {
        DType::F32 | DType::F64 => x.contiguous()?.apply_op1(SoftmaxLast),
        d => bail!("softmax: dtype {d:?} is not supported"),
    }
}

/// The two float types the fused ops run on.
mod num_like {
    pub trait Float:
        Copy
        + core::ops::Sub<Output = Self>
        + core::ops::Add<Output = Self>
        + core::ops::Div<Output = Self>
    {
        const ZERO: Self;
        const NEG_INF: Self;
        fn exp(self) -> Self;
        fn max(self, o: Self) -> Self;
    }
    macro_rules! imp {
        ($t:ty) => {
            impl Float for $t {
                const ZERO: Self = 0.0;
                const NEG_INF: Self = <$t>::NEG_INFINITY;
                fn exp(self) -> Self {
                    <$t>::exp(self)
                }
                fn max(self, o: Self) -> Self {
                    <$t>::max(self, o)
                }
            }
        };
    }
    imp!(f32);
    imp!(f64);
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random(n: usize, scale: f64, seed: u64, dtype: DType) -> Tensor {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let v: Vec<f64> = (0..n).map(|_| rng.random_range(-scale..scale)).collect();
        Tensor::from_vec(v, n, &Device::Cpu)
            .unwrap()
            .to_dtype(dtype)
            .unwrap()
    }

    #[test]
    fn fused_forward_equals_composite_and_definition() {
        // Inputs spread over |βx| up to 30 so both the linear tail and the curved part are hit.
        let x = random(4096, 0.3, 1, DType::F32);
        let fused = softplus(&x, 100.0).unwrap().to_vec1::<f32>().unwrap();
        let comp = softplus_composite(&x, 100.0)
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let xs = x.to_vec1::<f32>().unwrap();
        for ((f, c), x) in fused.iter().zip(&comp).zip(&xs) {
            let exact = (1.0 + (100.0 * f64::from(*x)).exp()).ln() / 100.0;
            assert!((f - c).abs() < 1e-6, "{x}: fused {f} composite {c}");
            assert!(
                (f64::from(*f) - exact).abs() < 1e-6,
                "{x}: fused {f} exact {exact}"
            );
        }
    }

    #[test]
    fn fused_backward_matches_finite_differences() {
        // f64 so the central difference (step 1e-6, error O(h²β²)) is accurate to ~1e-8.
        let x0 = random(257, 0.05, 2, DType::F64);
        let w = random(257, 1.0, 3, DType::F64);
        let x = Var::from_tensor(&x0).unwrap();
        let loss = (softplus(x.as_tensor(), 100.0).unwrap() * &w)
            .unwrap()
            .sum_all()
            .unwrap();
        let g = loss
            .backward()
            .unwrap()
            .get(&x)
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let (xs, ws) = (x0.to_vec1::<f64>().unwrap(), w.to_vec1::<f64>().unwrap());
        let h = 1e-6;
        for i in 0..xs.len() {
            let fd = ws[i]
                * (softplus_scalar(xs[i] + h, 100.0) - softplus_scalar(xs[i] - h, 100.0))
                / (2.0 * h);
            assert!((g[i] - fd).abs() < 1e-6, "{i}: {} vs {fd}", g[i]);
        }
        // And the same gradient as candle's autodiff of the composite.
        let x2 = Var::from_tensor(&x0).unwrap();
        let loss2 = (softplus_composite(x2.as_tensor(), 100.0).unwrap() * &w)
            .unwrap()
            .sum_all()
            .unwrap();
        let g2 = loss2
            .backward()
            .unwrap()
            .get(&x2)
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        for (a, b) in g.iter().zip(&g2) {
            assert!((a - b).abs() < 1e-9);
        }
    }

    #[test]
    fn softmax_forward_and_backward() {
        let x0 = random(5 * 7, 3.0, 4, DType::F64).reshape((5, 7)).unwrap();
        let w = random(5 * 7, 1.0, 5, DType::F64).reshape((5, 7)).unwrap();
        let x = Var::from_tensor(&x0).unwrap();
        let s = softmax_last(x.as_tensor()).unwrap();
        let reference = candle_nn::ops::softmax(&x0, candle_core::D::Minus1).unwrap();
        let diff = (&s - &reference)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_vec0::<f64>()
            .unwrap();
        assert!(diff < 1e-12);
        let grads = (s * &w).unwrap().sum_all().unwrap().backward().unwrap();
        let g = grads
            .get(&x)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let f = |xs: &Tensor| {
            candle_nn::ops::softmax(xs, candle_core::D::Minus1)
                .unwrap()
                .mul(&w)
                .unwrap()
                .sum_all()
                .unwrap()
                .to_vec0::<f64>()
                .unwrap()
        };
        let flat = x0.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let h = 1e-6;
        for i in 0..flat.len() {
            let mut p = flat.clone();
            p[i] += h;
            let mut m = flat.clone();
            m[i] -= h;
            let tp = Tensor::from_vec(p, (5, 7), &Device::Cpu).unwrap();
            let tm = Tensor::from_vec(m, (5, 7), &Device::Cpu).unwrap();
            let fd = (f(&tp) - f(&tm)) / (2.0 * h);
            assert!((g[i] - fd).abs() < 1e-8, "{i}: {} vs {fd}", g[i]);
        }
    }
}
