//! SkinNet's stage-1 losses (paper §3.4, supplementary E), all differentiable through linear
//! blend skinning into the skinning weights, and the constant data they need.
//!
//! Every loss takes and returns candle tensors of the caller's float type (f32 for training,
//! f64 for the finite-difference tests) and sums over its terms as the paper writes it; the
//! training loop weights and normalises them.

pub mod laplacian;
pub mod lbs;
pub mod partwise;
pub mod prior;
pub mod projection;
pub mod rendering;
pub mod silhouette;
pub mod skinning_reg;

use skinfield_formats::StaticSkin;

/// Dense row-major `[V, J]` copy of sparse skinning weights.
#[must_use]
pub fn dense_weights(skin: &StaticSkin) -> Vec<f32> {
    let j = skin.joint_count();
    let mut out = vec![0.0; skin.vertex_count() * j];
    for v in 0..skin.vertex_count() {
        let (joints, weights) = skin.influences(v);
        for (&jj, &w) in joints.iter().zip(weights) {
            out[v * j + jj as usize] += w;
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod fd {
    //! Central finite differences of a scalar candle loss with respect to one input tensor.

    use candle_core::{Device, Tensor, Var};

    /// Asserts that autodiff and central differences (step `h`) agree within
    /// `abs + rel · |fd|` for every entry of `x0` (f64).
    pub fn check(x0: &Tensor, h: f64, abs: f64, rel: f64, loss: impl Fn(&Tensor) -> Tensor) {
        let x = Var::from_tensor(x0).unwrap();
        let g = loss(x.as_tensor())
            .backward()
            .unwrap()
            .get(&x)
            .map(|g| g.flatten_all().unwrap().to_vec1::<f64>().unwrap());
        let base = x0.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let g = g.unwrap_or_else(|| vec![0.0; base.len()]);
        let mut nonzero = 0;
        for i in 0..base.len() {
            let at = |d: f64| {
                let mut p = base.clone();
                p[i] += d;
                let t = Tensor::from_vec(p, x0.shape().clone(), &Device::Cpu).unwrap();
                loss(&t).to_vec0::<f64>().unwrap()
            };
            let fd = (at(h) - at(-h)) / (2.0 * h);
            assert!(
                (g[i] - fd).abs() <= abs + rel * fd.abs(),
                "entry {i}: autodiff {} vs finite difference {fd}",
                g[i]
            );
            nonzero += usize::from(fd.abs() > abs);
        }
        assert!(
            nonzero > 0,
            "every derivative is zero: the check would pass for any gradient"
        );
    }
}
