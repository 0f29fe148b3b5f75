//! Adam (Kingma & Ba 2015) with gradient values clipped to `[−c, c]` (paper, supplementary F).
//!
//! candle-nn has no plain Adam and no clipping; its `AdamW` with `weight_decay = 0` is the same
//! update, but keeps its moments private, so a checkpoint could not resume it exactly. This one
//! exposes its state ([`Adam::state_tensors`], [`Adam::load_state_tensors`]) and visits its
//! variables in name order, so a run is reproducible bit for bit.

use std::collections::HashMap;

use candle_core::backprop::GradStore;
use candle_core::{Result, Tensor, Var};
use candle_nn::VarMap;

/// Adam hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdamConfig {
    /// Learning rate (paper: 1e-3).
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Denominator epsilon.
    pub eps: f64,
    /// Gradient values are clamped to `[−clip, clip]` before the update (paper: 1); `None` off.
    pub clip: Option<f64>,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            clip: Some(1.0),
        }
    }
}

struct Slot {
    name: String,
    var: Var,
    m: Tensor,
    v: Tensor,
}

/// Adam over a fixed, named set of variables.
pub struct Adam {
    config: AdamConfig,
    slots: Vec<Slot>,
    step: u64,
}

impl Adam {
    /// Optimises `vars` (sorted by name here so the update order never depends on a hash map).
    pub fn new(mut vars: Vec<(String, Var)>, config: AdamConfig) -> Result<Self> {
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        let slots = vars
            .into_iter()
            .map(|(name, var)| {
                let z = var.as_tensor().zeros_like()?;
                Ok(Slot {
                    name,
                    m: z.clone(),
                    v: z,
                    var,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            config,
            slots,
            step: 0,
        })
    }

    /// Optimises every variable of `varmap`.
    pub fn from_varmap(varmap: &VarMap, config: AdamConfig) -> Result<Self> {
        let vars = varmap
            .data()
            .lock()
            .map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
        Self::new(
            vars.iter().map(|(k, v)| (k.clone(), v.clone())).collect(),
            config,
        )
    }

    /// Steps taken so far.
    #[must_use]
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// The hyper-parameters.
    #[must_use]
    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// Sets the learning rate (for schedules).
    pub fn set_lr(&mut self, lr: f64) {
        self.config.lr = lr;
    }

    /// One update from `grads` (clipped first when configured). Variables without a gradient are
    /// left alone and their moments are not decayed.
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.step += 1;
        let c = self.config;
        let t = i32::try_from(self.step).unwrap_or(i32::MAX);
        let bias1 = 1.0 - c.beta1.powi(t);
        let bias2 = 1.0 - c.beta2.powi(t);
        for s in &mut self.slots {
            let Some(g) = grads.get(s.var.as_tensor()) else {
                continue;
            };
            // candle detaches the gradients of intermediate nodes but not those of variables:
            // a variable's gradient still records the ops (and so the activations) of the step
            // that produced it. Kept in the moments, every step's graph would stay alive
            // through the chain m_t → m_{t−1} → …; measured on the demo, +17 MB per iteration.
            let g = g.detach();
            let g = match c.clip {
                Some(l) => g.clamp(-l, l)?,
                None => g,
            };
            s.m = ((&s.m * c.beta1)? + (&g * (1.0 - c.beta1))?)?;
            s.v = ((&s.v * c.beta2)? + (g.sqr()? * (1.0 - c.beta2))?)?;
            let m_hat = (&s.m / bias1)?;
            let denom = ((&s.v / bias2)?.sqrt()? + c.eps)?;
            let next = (s.var.as_tensor() - ((m_hat / denom)? * c.lr)?)?;
            s.var.set(&next)?;
        }
        Ok(())
    }

    /// `loss.backward()` then [`Adam::step`].
    pub fn backward_step(&mut self, loss: &Tensor) -> Result<()> {
        let grads = loss.backward()?;
        self.step(&grads)
    }

    /// The optimiser state as named tensors (`adam.m.NAME`, `adam.v.NAME`, `adam.step`), for a
    /// checkpoint next to the parameters.
    pub fn state_tensors(&self) -> Result<HashMap<String, Tensor>> {
        let mut out = HashMap::new();
        for s in &self.slots {
            out.insert(format!("adam.m.{}", s.name), s.m.clone());
            out.insert(format!("adam.v.{}", s.name), s.v.clone());
        }
        // Two u32 halves: safetensors and candle have no u64 scalar that survives every backend.
        let step = [(self.step & 0xffff_ffff) as u32, (self.step >> 32) as u32];
        out.insert(
            "adam.step".into(),
            Tensor::new(&step, &candle_core::Device::Cpu)?,
        );
        Ok(out)
    }

    /// Restores a state written by [`Adam::state_tensors`]; every variable must be present with
    /// its shape.
    pub fn load_state_tensors(&mut self, state: &HashMap<String, Tensor>) -> Result<()> {
        let get = |k: &str| {
            state
                .get(k)
                .ok_or_else(|| candle_core::Error::Msg(format!("optimiser state lacks `{k}`")))
        };
        for s in &mut self.slots {
            let m = get(&format!("adam.m.{}", s.name))?;
            let v = get(&format!("adam.v.{}", s.name))?;
            if m.shape() != s.var.shape() || v.shape() != s.var.shape() {
                candle_core::bail!("optimiser state for `{}` has the wrong shape", s.name);
            }
            s.m = m.to_dtype(s.var.dtype())?;
            s.v = v.to_dtype(s.var.dtype())?;
        }
        let step = get("adam.step")?.to_vec1::<u32>()?;
        if step.len() != 2 {
            candle_core::bail!(
                "optimiser state `adam.step` has {} entries, expected 2",
                step.len()
            );
        }
        self.step = u64::from(step[0]) | (u64::from(step[1]) << 32);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use candle_nn::Optimizer;

    fn var(v: &[f64]) -> Var {
        Var::from_tensor(&Tensor::new(v, &Device::Cpu).unwrap()).unwrap()
    }

    #[test]
    fn first_steps_match_the_hand_computed_update() {
        // One scalar, loss = 3x: g = 3 is clipped to 1; Adam's first step moves by exactly lr
        // (m̂ = g, v̂ = g²), the second too (constant gradient).
        let x = var(&[2.0, -1.0]);
        let mut opt = Adam::new(vec![("x".into(), x.clone())], AdamConfig::default()).unwrap();
        let w = Tensor::new(&[3.0f64, -0.5], &Device::Cpu).unwrap();
        for k in 1..=2 {
            opt.backward_step(&(x.as_tensor() * &w).unwrap().sum_all().unwrap())
                .unwrap();
            let got = x.as_tensor().to_vec1::<f64>().unwrap();
            let lr = 1e-3 * f64::from(k);
            // Adam's step is lr·sign(g) (up to eps) for a constant gradient: clipping to 1 does
            // not change the first component's direction, and the second is within range.
            assert!((got[0] - (2.0 - lr)).abs() < 1e-9, "{got:?}");
            assert!((got[1] - (-1.0 + lr)).abs() < 1e-9, "{got:?}");
        }
    }

    #[test]
    fn moments_hold_no_graph_of_past_steps() {
        // The gradient of x² is 2x: an op on the variable, which candle leaves recorded on a
        // variable's gradient. The moments must not keep it (and each step's graph) alive.
        let x = var(&[0.5, -2.0]);
        let mut opt = Adam::new(vec![("x".into(), x.clone())], AdamConfig::default()).unwrap();
        for _ in 0..3 {
            let loss = x.as_tensor().sqr().unwrap().sum_all().unwrap();
            let grads = loss.backward().unwrap();
            assert!(grads.get(x.as_tensor()).unwrap().track_op());
            opt.step(&grads).unwrap();
            for (name, t) in opt.state_tensors().unwrap() {
                assert!(!t.track_op(), "`{name}` records ops");
            }
        }
    }

    #[test]
    fn clipping_changes_the_moments() {
        // With g = 3 clipped to 1 and then g = 0.5, v̂₂ = (0.999·1 + 0.001·0.25)/(1 − 0.999²)
        // differs from the unclipped (0.999·9 + …): check the exact second step.
        let x = var(&[0.0]);
        let mut opt = Adam::new(vec![("x".into(), x.clone())], AdamConfig::default()).unwrap();
        opt.backward_step(&(x.as_tensor() * 3.0).unwrap().sum_all().unwrap())
            .unwrap();
        opt.backward_step(&(x.as_tensor() * 0.5).unwrap().sum_all().unwrap())
            .unwrap();
        let (b1, b2, lr) = (0.9f64, 0.999f64, 1e-3);
        let m1 = (1.0 - b1) * 1.0;
        let v1 = (1.0 - b2) * 1.0;
        let x1 = -lr * (m1 / (1.0 - b1)) / ((v1 / (1.0 - b2)).sqrt() + 1e-8);
        let m2 = b1 * m1 + (1.0 - b1) * 0.5;
        let v2 = b2 * v1 + (1.0 - b2) * 0.25;
        let x2 = x1 - lr * (m2 / (1.0 - b1 * b1)) / ((v2 / (1.0 - b2 * b2)).sqrt() + 1e-8);
        let got = x.as_tensor().to_vec1::<f64>().unwrap()[0];
        assert!((got - x2).abs() < 1e-12, "{got} vs {x2}");
    }

    #[test]
    fn equals_candle_adamw_without_decay_when_unclipped() {
        let init = [0.3f32, -0.7, 1.1, 0.05];
        let a = Var::from_tensor(&Tensor::new(&init, &Device::Cpu).unwrap()).unwrap();
        let b = Var::from_tensor(&Tensor::new(&init, &Device::Cpu).unwrap()).unwrap();
        let mut ours = Adam::new(
            vec![("a".into(), a.clone())],
            AdamConfig {
                clip: None,
                ..Default::default()
            },
        )
        .unwrap();
        let params = candle_nn::ParamsAdamW {
            weight_decay: 0.0,
            ..Default::default()
        };
        let mut theirs = candle_nn::AdamW::new(vec![b.clone()], params).unwrap();
        for _ in 0..20 {
            // A non-linear loss so the gradient changes every step.
            let la = a.as_tensor().sqr().unwrap().sum_all().unwrap();
            let lb = b.as_tensor().sqr().unwrap().sum_all().unwrap();
            ours.backward_step(&la).unwrap();
            theirs.backward_step(&lb).unwrap();
        }
        let d = (a.as_tensor() - b.as_tensor())
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_vec0::<f32>()
            .unwrap();
        assert!(d < 1e-6, "{d}");
        assert!(
            (a.as_tensor().to_vec1::<f32>().unwrap()[0] - 0.3).abs() > 0.01,
            "did not move"
        );
    }

    #[test]
    fn state_round_trip_resumes_exactly() {
        let run = |split: Option<usize>| {
            let x = Var::from_tensor(&Tensor::new(&[1.0f32, 2.0, -3.0], &Device::Cpu).unwrap())
                .unwrap();
            let mut opt = Adam::new(vec![("x".into(), x.clone())], AdamConfig::default()).unwrap();
            for i in 0..10 {
                if Some(i) == split {
                    let state = opt.state_tensors().unwrap();
                    let params = x.as_tensor().copy().unwrap();
                    let x2 = Var::from_tensor(&params).unwrap();
                    let mut fresh =
                        Adam::new(vec![("x".into(), x2.clone())], AdamConfig::default()).unwrap();
                    fresh.load_state_tensors(&state).unwrap();
                    assert_eq!(fresh.steps(), i as u64);
                    for _ in i..10 {
                        fresh
                            .backward_step(
                                &x2.as_tensor()
                                    .sqr()
                                    .unwrap()
                                    .sqr()
                                    .unwrap()
                                    .sum_all()
                                    .unwrap(),
                            )
                            .unwrap();
                    }
                    return x2.as_tensor().to_vec1::<f32>().unwrap();
                }
                opt.backward_step(
                    &x.as_tensor()
                        .sqr()
                        .unwrap()
                        .sqr()
                        .unwrap()
                        .sum_all()
                        .unwrap(),
                )
                .unwrap();
            }
            x.as_tensor().to_vec1::<f32>().unwrap()
        };
        assert_eq!(run(None), run(Some(4)));
        let mut opt = Adam::new(vec![("x".into(), var(&[1.0]))], AdamConfig::default()).unwrap();
        assert!(opt.load_state_tensors(&HashMap::new()).is_err());
    }
}
