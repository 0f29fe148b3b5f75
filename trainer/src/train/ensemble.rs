//! Several SkinNets trained from different seeds, and their average distilled into one.
//!
//! Once the outline is fitted, the silhouettes no longer pick between weight sets that explain
//! it equally well: on the built-in capture, runs that differ only in their seed fit the
//! held-out masks to within 0.004 px of each other (0.162–0.166 px) yet score 0.598–0.675 cm
//! Chamfer, and each carries spikes of its own (docs/experiments/fidelity.md, *The spread
//! across initialisations*). What a run does along the directions the images cannot see depends
//! on where its network started, so the drift differs from seed to seed while what the images
//! taught is shared; the average of several runs' weights keeps the shared part and cancels
//! much of the rest (three runs, each 0.598–0.649 cm with spikes up to 3.3 cm past bone heat's
//! worst vertex: their average 0.605 cm, at most 0.28 cm past it).
//!
//! The runtime evaluates one network, so the average is distilled: a student starts from the
//! first member's parameters and regresses the members' mean weights (KL divergence from the
//! mean plus the distance between the vertices posed with either, [`EnsembleConfig`]), at the
//! same query points and training poses the warm start uses, with the warm start's loop (its
//! window, learning-rate halving and cap). Starting from a member rather than from a fresh
//! initialisation puts the student a small step from its target. The student must follow the
//! mean far more closely than the warm start follows bone heat: what the ensemble adds is
//! sub-millimetre, and a student 1.2 mm from the mean (the warm start's tolerance) lost it all
//! on the zoo's CesiumMan.

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use serde::{Deserialize, Serialize};

use super::checkpoint::lock_vars;
use super::{Model, TrainError, Trainer};
use crate::skinnet::{PREFIX, TrainableSkinNet};

/// How many SkinNets to train and how closely the exported one must follow their average.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnsembleConfig {
    /// Members trained independently (member `k` with seed `seed + k`, each with the whole
    /// warm start and image schedule); 1 trains a single network and distils nothing. The
    /// static baseline is always a single run: its per-vertex logits share no parameters, so a
    /// vertex the images never see keeps its initial weights there.
    pub members: usize,
    /// The distillation has converged when, over the warm start's window, `KL(mean ‖ student)`
    /// per vertex is at most this (nats)…
    pub kl_tolerance: f64,
    /// …and the RMS distance between the vertices posed with the student's and with the mean
    /// weights is at most this fraction of the template's bounding-box diagonal. It must be
    /// well below the model's own error: on the zoo's CesiumMan (whose SkinNet is 1.3e-3 of
    /// the diagonal from the truth in Chamfer terms) a student that stopped at 6.1e-4 scored
    /// 0.309 cm against its members' 0.243–0.247; at 1e-4 it scored 0.239.
    pub position_tolerance: f64,
    /// Weight of that posed-position term in the distillation's objective (the warm start's
    /// `warm_start_position_weight`, whose unit is the squared fraction of the diagonal). The
    /// KL alone reaches a position error of 1e-4 only slowly (CesiumMan: still 1.1e-4 after the
    /// cap of 3,000 iterations); weighted 1e4 the term gets there after 1,151.
    pub position_weight: f64,
    /// The distillation's learning rate (halved on the warm start's schedule).
    pub lr: f64,
}

impl Default for EnsembleConfig {
    fn default() -> Self {
        Self {
            members: 1,
            kl_tolerance: 2e-3,
            position_tolerance: 1e-4,
            position_weight: 1e4,
            lr: 1e-3,
        }
    }
}

/// Most members a configuration may ask for (each is a whole training run).
pub const MAX_MEMBERS: usize = 16;

impl EnsembleConfig {
    /// Checks ranges; returns the first bad field.
    pub fn validate(&self) -> Result<(), &'static str> {
        if self.members == 0 || self.members > MAX_MEMBERS {
            return Err("ensemble.members");
        }
        if !(self.kl_tolerance.is_finite() && self.kl_tolerance >= 0.0) {
            return Err("ensemble.kl_tolerance");
        }
        if !(self.position_tolerance.is_finite() && self.position_tolerance >= 0.0) {
            return Err("ensemble.position_tolerance");
        }
        if !(self.position_weight.is_finite() && self.position_weight >= 0.0) {
            return Err("ensemble.position_weight");
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return Err("ensemble.lr");
        }
        Ok(())
    }

    /// Whether more than one network is trained.
    #[must_use]
    pub fn is_on(&self) -> bool {
        self.members > 1
    }
}

impl Trainer {
    /// A copy of the network whose parameters no later step of this trainer changes (what a
    /// finished ensemble member hands to the distillation).
    pub fn frozen_net(&self) -> Result<TrainableSkinNet, TrainError> {
        let net = self
            .net()
            .ok_or_else(|| TrainError::Data("the static baseline has no network".into()))?;
        let copy = VarMap::new();
        {
            let vars = lock_vars(&self.varmap)?;
            let mut out = lock_vars(&copy)?;
            let prefix = format!("{PREFIX}.");
            for (name, var) in vars.iter().filter(|(n, _)| n.starts_with(&prefix)) {
                out.insert(name.clone(), Var::from_tensor(&var.as_tensor().copy()?)?);
            }
        }
        let vb = VarBuilder::from_varmap(&copy, DType::F32, &Device::Cpu);
        Ok(TrainableSkinNet::new(&vb.pp(PREFIX), *net.config())?.with_backend(net.backend()))
    }

    /// Turns the warm start into a distillation: its target becomes the mean of `teachers`'
    /// weights (in each batch's poses, at its query points) instead of the initial weights, its
    /// KL tolerance [`EnsembleConfig::kl_tolerance`], and the network starts from the first
    /// teacher's parameters. Call before [`Trainer::run`] (and before [`Trainer::resume`], which
    /// then restores the student's own progress). The teachers must have been trained on the
    /// same data and architecture.
    pub fn distil_from(&mut self, teachers: Vec<TrainableSkinNet>) -> Result<(), TrainError> {
        let Model::Net { net, .. } = &self.model else {
            return Err(TrainError::Data(
                "the static baseline cannot be distilled into".into(),
            ));
        };
        let Some(first) = teachers.first() else {
            return Err(TrainError::Data(
                "distillation needs at least one teacher".into(),
            ));
        };
        if teachers.iter().any(|t| t.config() != net.config()) {
            return Err(TrainError::Data(
                "a teacher's architecture differs from the student's".into(),
            ));
        }
        {
            let vars = lock_vars(&self.varmap)?;
            for (i, layer) in first.layers().iter().enumerate() {
                let (v, g, b) = layer.parts();
                for (suffix, value) in [("v", v), ("g", g), ("b", b)] {
                    let name = format!("{PREFIX}.l{i}.{suffix}");
                    vars.get(&name)
                        .ok_or_else(|| {
                            TrainError::Data(format!("the student has no parameter `{name}`"))
                        })?
                        .set(value)?;
                }
            }
        }
        self.teachers = teachers;
        self.warm_done = 0;
        self.warm_converged = false;
        self.warm_window.clear();
        Ok(())
    }

    /// Whether the warm start regresses teachers' mean weights ([`Trainer::distil_from`]).
    #[must_use]
    pub fn is_distilling(&self) -> bool {
        !self.teachers.is_empty()
    }

    /// The teachers' mean weights `[B, V, J]` in `frames`' poses at query rows `query` (or at
    /// the training vertices), outside the autograd graph.
    pub(super) fn teacher_mean(
        &self,
        frames: &[usize],
        query: Option<&Tensor>,
    ) -> Result<Tensor, TrainError> {
        let (rows, mask) = self.net_rows(query)?;
        let poses = self.pose_tensor(frames)?;
        let mut sum: Option<Tensor> = None;
        for teacher in &self.teachers {
            let w = teacher
                .forward_masked(&rows, &poses, mask.as_ref())?
                .detach();
            sum = Some(match sum {
                Some(s) => (s + w)?,
                None => w,
            });
        }
        let sum = sum.ok_or_else(|| TrainError::Data("no teachers".into()))?;
        Ok((sum / self.teachers.len() as f64)?)
    }
}
