//! Part-wise regulariser (paper Eq. 9): `Σ_{i∈R∩G} ‖f_ω(v̄_i, θ̃) − w_init,i‖²`.
//!
//! `G` is the set of vertices whose parsing label is skin; `R = {k | max_t w_init,k,t > u}`
//! (u = 0.95): the rigid vertices, away from joints, where the initial skinning is trusted. A
//! template without part labels is treated as all skin (then `R ∩ G = R`).

use candle_core::{Device, Result, Tensor};
use skinfield_formats::PartLabel;

/// The paper's rigidity threshold u.
pub const PAPER_U: f32 = 0.95;

/// Eq. 9 with the mask `R ∩ G` and the initial weights as constants.
#[derive(Clone, Debug)]
pub struct PartwiseReg {
    mask: Tensor,
    init: Tensor,
    count: usize,
}

impl PartwiseReg {
    /// Builds the regulariser from dense initial weights `[V, J]` and optional part labels.
    pub fn new(
        init: &[f32],
        joints: usize,
        labels: Option<&[PartLabel]>,
        u: f32,
        device: &Device,
    ) -> Result<Self> {
        if joints == 0 || !init.len().is_multiple_of(joints) {
            candle_core::bail!(
                "part-wise regulariser: {} initial weights for {joints} joints",
                init.len()
            );
        }
        let v = init.len() / joints;
        if let Some(l) = labels
            && l.len() != v
        {
            candle_core::bail!("part-wise regulariser: {} labels for {v} vertices", l.len());
        }
        let mask: Vec<f32> = init
            .chunks(joints)
            .enumerate()
            .map(|(i, row)| {
                let skin = labels.is_none_or(|l| l[i] == PartLabel::Skin);
                let rigid = row.iter().copied().fold(f32::NEG_INFINITY, f32::max) > u;
                if skin && rigid { 1.0 } else { 0.0 }
            })
            .collect();
        let count = mask.iter().filter(|&&m| m > 0.0).count();
        Ok(Self {
            mask: Tensor::from_vec(mask, (v, 1), device)?,
            init: Tensor::from_vec(init.to_vec(), (v, joints), device)?,
            count,
        })
    }

    /// `|R ∩ G|`.
    #[must_use]
    pub fn count(&self) -> usize {
        self.count
    }

    /// Eq. 9 summed over frames, for predicted weights `[F, V, J]`.
    pub fn loss(&self, weights: &Tensor) -> Result<Tensor> {
        let dt = weights.dtype();
        weights
            .broadcast_sub(&self.init.to_dtype(dt)?)?
            .sqr()?
            .broadcast_mul(&self.mask.to_dtype(dt)?)?
            .sum_all()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case() -> (Vec<f32>, Vec<PartLabel>) {
        // v0 rigid skin, v1 rigid clothing, v2 skin near a joint (0.6), v3 rigid skin.
        let init = vec![0.97, 0.03, 1.0, 0.0, 0.6, 0.4, 0.02, 0.98];
        (
            init,
            vec![
                PartLabel::Skin,
                PartLabel::Clothing,
                PartLabel::Skin,
                PartLabel::Skin,
            ],
        )
    }

    #[test]
    fn selects_rigid_skin_and_sums_squared_errors() {
        let (init, labels) = case();
        let reg = PartwiseReg::new(&init, 2, Some(&labels), PAPER_U, &Device::Cpu).unwrap();
        assert_eq!(reg.count(), 2);
        assert_eq!(
            PartwiseReg::new(&init, 2, None, PAPER_U, &Device::Cpu)
                .unwrap()
                .count(),
            3
        );
        let w = Tensor::new(
            &[[[0.5f32, 0.5], [0.5, 0.5], [0.5, 0.5], [0.5, 0.5]]],
            &Device::Cpu,
        )
        .unwrap();
        let l = reg.loss(&w).unwrap().to_vec0::<f32>().unwrap();
        let expect = 2.0 * 0.47f32.powi(2) + 2.0 * 0.48f32.powi(2);
        assert!((l - expect).abs() < 1e-6, "{l} vs {expect}");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (init, labels) = case();
        let reg = PartwiseReg::new(&init, 2, Some(&labels), PAPER_U, &Device::Cpu).unwrap();
        let w0 = Tensor::new(
            &[
                [[0.1f64, 0.9], [0.2, 0.8], [0.7, 0.3], [0.4, 0.6]],
                [[0.5, 0.5], [0.0, 1.0], [1.0, 0.0], [0.3, 0.7]],
            ],
            &Device::Cpu,
        )
        .unwrap();
        crate::losses::fd::check(&w0, 1e-6, 1e-8, 1e-6, |w| reg.loss(w).unwrap());
    }

    #[test]
    fn rejects_wrong_label_count() {
        let (init, labels) = case();
        assert!(PartwiseReg::new(&init, 2, Some(&labels[..3]), PAPER_U, &Device::Cpu).is_err());
    }
}
