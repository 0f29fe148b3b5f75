//! The prior on the initial weights: `KL(w_init ‖ w)`, the warm start's objective, which the
//! image-loss phase may keep on at a small weight ([`crate::train::LossWeights::prior`]).
//!
//! Why KL and not the squared error of the weights (the part-wise regulariser's form): its
//! gradient with respect to SkinNet's logits is `w − w_init`, which does not vanish where the
//! softmax saturates, while the squared error's passes through the softmax Jacobian.

use candle_core::{Result, Tensor};

/// `−Σ_j w_init,j ln w_j` summed over every frame and vertex, for predicted weights `[F, V, J]`
/// and initial weights `[1, V, J]` (or `[F, V, J]`). Weights below 1e-12 count as 1e-12, so a
/// joint SkinNet rules out (a candidate mask's zero) costs a finite penalty where the initial
/// weights use it.
///
/// Its minimum over `w` is at `w = w_init`; minus [`neg_entropy`] of the same vertices it is
/// the KL divergence, which is zero there.
pub fn cross_entropy(weights: &Tensor, init: &Tensor) -> Result<Tensor> {
    weights
        .clamp(1e-12, 1.0)?
        .log()?
        .broadcast_mul(init)?
        .sum_all()?
        .neg()
}

/// `Σ_j w_j ln w_j` summed over the rows of dense weights `w` (zero weights add nothing): the
/// constant that turns [`cross_entropy`] into the KL divergence.
#[must_use]
pub fn neg_entropy(w: &[f32]) -> f64 {
    w.iter()
        .filter(|&&x| x > 0.0)
        .map(|&x| f64::from(x) * f64::from(x).ln())
        .sum()
}

#[cfg(test)]
mod tests {
    use candle_core::{D, Device};

    use super::*;

    fn init() -> Tensor {
        // Three vertices, three joints: a rigid vertex, a blend, a vertex with a zero weight.
        Tensor::new(
            &[[[1.0f64, 0.0, 0.0], [0.5, 0.3, 0.2], [0.0, 0.6, 0.4]]],
            &Device::Cpu,
        )
        .unwrap()
    }

    fn kl(w: &Tensor, init: &Tensor) -> f64 {
        let h: f64 = init
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap()
            .iter()
            .filter(|&&x| x > 0.0)
            .map(|&x| x * x.ln())
            .sum();
        cross_entropy(w, init).unwrap().to_vec0::<f64>().unwrap() + h
    }

    #[test]
    fn is_zero_at_the_initial_weights_and_positive_elsewhere() {
        let init = init();
        assert!(kl(&init, &init).abs() < 1e-12);
        let other = Tensor::new(
            &[[[0.9f64, 0.05, 0.05], [0.5, 0.3, 0.2], [0.1, 0.5, 0.4]]],
            &Device::Cpu,
        )
        .unwrap();
        // By hand: −ln 0.9 + (0.6 ln(0.6/0.5) + 0.4 ln(0.4/0.4)).
        let expect = -(0.9f64.ln()) + 0.6 * (0.6f64 / 0.5).ln();
        assert!((kl(&other, &init) - expect).abs() < 1e-12);
        let h32 = neg_entropy(&[1.0, 0.0, 0.0, 0.5, 0.3, 0.2, 0.0, 0.6, 0.4]);
        let h64 = 0.5 * 0.5f64.ln()
            + 0.3 * 0.3f64.ln()
            + 0.2 * 0.2f64.ln()
            + 0.6 * 0.6f64.ln()
            + 0.4 * 0.4f64.ln();
        assert!((h32 - h64).abs() < 1e-6, "{h32} vs {h64}");
    }

    #[test]
    fn gradient_matches_finite_differences_and_is_w_minus_init_in_the_logits() {
        let init = init();
        let logits = Tensor::new(
            &[
                [[0.3f64, -0.2, 0.1], [1.0, 0.5, -1.0], [-0.4, 0.2, 0.9]],
                [[2.0, 0.0, -2.0], [0.0, 0.0, 0.0], [0.1, -0.3, 0.2]],
            ],
            &Device::Cpu,
        )
        .unwrap();
        let loss =
            |z: &Tensor| cross_entropy(&candle_nn::ops::softmax(z, D::Minus1).unwrap(), &init);
        crate::losses::fd::check(&logits, 1e-6, 1e-8, 1e-6, |z| loss(z).unwrap());
        let z = candle_core::Var::from_tensor(&logits).unwrap();
        let g = loss(z.as_tensor()).unwrap().backward().unwrap();
        let g = g
            .get(&z)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let w = candle_nn::ops::softmax(&logits, D::Minus1).unwrap();
        let expect = w
            .broadcast_sub(&init)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        for (a, b) in g.iter().zip(&expect) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }
}
