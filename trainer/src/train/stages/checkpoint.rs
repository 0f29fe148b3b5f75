//! Checkpoints of stages 2–4, `dir/stages.safetensors`, so that a stopped run resumes where it
//! stopped instead of redoing the appearance ([`Trainer::resume_stages`]).
//!
//! One file holds everything the remaining iterations depend on: both appearance nets
//! (`albedo.param.*`, `shadow.param.*`), the Adam state of the appearance stage that ran last
//! and which stage it belongs to (`appearance.adam.*`, `appearance.stage`), SkinNet with its
//! optimiser and progress as in the stage-1 checkpoint (`skin.*`: stage 4 changes them), the
//! fixed vertex colours when that ablation runs (`fixed_colours`: they are read through the
//! SkinNet of stage 4's first iteration) and the iterations done per stage
//! (`stages.progress`). Every draw of stages 2–4 is seeded by its iteration, so a resumed run
//! repeats an uninterrupted one exactly.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use candle_nn::VarMap;

use super::super::{
    TrainError, Trainer, insert_varmap, load_tensors, read_u64s, restore_varmap, save_tensors,
    split_u64,
};
use crate::appearance::Appearance;
use crate::optim::Adam;

/// File name of the stages checkpoint inside the work folder.
pub const STAGES_CHECKPOINT: &str = "stages.safetensors";

/// Iterations done in stages 2, 3 and 4.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct StageProgress {
    /// Stage 2 (AlbedoNet).
    pub albedo: u64,
    /// Stage 3 (ShadowNet).
    pub shadow: u64,
    /// Stage 4 (SkinNet refined).
    pub refine: u64,
}

impl StageProgress {
    /// The counter of appearance stage 2 (AlbedoNet) or, for any other value, 3 (ShadowNet).
    pub fn of_appearance_stage(&mut self, stage: u64) -> &mut u64 {
        if stage == 2 {
            &mut self.albedo
        } else {
            &mut self.shadow
        }
    }
}

/// What a stages checkpoint restores besides the parameters.
#[derive(Default)]
pub(super) struct StageState {
    /// Iterations done.
    pub progress: StageProgress,
    /// The Adam state of the appearance stage (2 or 3) that ran last.
    pub appearance_optimiser: Option<(u64, HashMap<String, Tensor>)>,
    /// Stage 4's fixed vertex colours `[V, 3]`, once computed.
    pub fixed: Option<Tensor>,
}

impl Trainer {
    /// Writes the stages checkpoint to `path` (atomically).
    pub(super) fn save_stages(
        &self,
        path: &Path,
        appearance: &Appearance,
        state: &StageState,
    ) -> Result<(), TrainError> {
        let mut tensors = self.checkpoint_tensors("skin.")?;
        insert_varmap(&mut tensors, "albedo.param.", appearance.albedo_vars())?;
        insert_varmap(&mut tensors, "shadow.param.", appearance.shadow_vars())?;
        if let Some((stage, adam)) = &state.appearance_optimiser {
            for (k, v) in adam {
                tensors.insert(format!("appearance.{k}"), v.clone());
            }
            tensors.insert(
                "appearance.stage".into(),
                Tensor::new(&split_u64(*stage), &Device::Cpu)?,
            );
        }
        if let Some(fixed) = &state.fixed {
            tensors.insert("fixed_colours".into(), fixed.clone());
        }
        let p = state.progress;
        let p = [p.albedo, p.shadow, p.refine].map(split_u64).concat();
        tensors.insert(
            "stages.progress".into(),
            Tensor::new(p.as_slice(), &Device::Cpu)?,
        );
        save_tensors(&tensors, path)
    }

    /// Restores a stages checkpoint into `appearance` and this trainer's SkinNet; checks that
    /// its progress fits the configuration (a later stage may not have started while an earlier
    /// one still has iterations to run).
    pub(super) fn load_stages(
        &mut self,
        path: &Path,
        appearance: &Appearance,
    ) -> Result<StageState, TrainError> {
        let bad = |reason: String| TrainError::Checkpoint {
            path: path.to_owned(),
            reason,
        };
        let tensors = load_tensors(path)?;
        self.restore_tensors(&tensors, "skin.", path)?;
        restore_varmap(&tensors, "albedo.param.", appearance.albedo_vars(), &bad)?;
        restore_varmap(&tensors, "shadow.param.", appearance.shadow_vars(), &bad)?;
        let p = read_u64s(&tensors, "stages.progress", 3).map_err(bad)?;
        let progress = StageProgress {
            albedo: p[0],
            shadow: p[1],
            refine: p[2],
        };
        let appearance_optimiser = match tensors.get("appearance.stage") {
            None => None,
            Some(_) => {
                let stage = read_u64s(&tensors, "appearance.stage", 1).map_err(bad)?[0];
                let adam = tensors
                    .iter()
                    .filter_map(|(k, v)| {
                        Some((k.strip_prefix("appearance.")?.to_string(), v.clone()))
                    })
                    .filter(|(k, _)| k.starts_with("adam."))
                    .collect();
                Some((stage, adam))
            }
        };
        let c = self.config.stages.scheduled();
        let pending = [
            (2, progress.albedo < c.albedo),
            (3, progress.shadow < c.shadow),
        ];
        let started = [(3, progress.shadow > 0), (4, progress.refine > 0)];
        for (earlier, open) in pending {
            if let Some((later, _)) = started.iter().find(|(s, on)| *on && *s > earlier)
                && open
            {
                return Err(bad(format!(
                    "stage {later} has started but stage {earlier} has iterations left"
                )));
            }
        }
        if self.done != self.config.iterations + progress.refine {
            return Err(bad(format!(
                "SkinNet has done {} image iterations, expected {} of stage 1 and {} of stage 4",
                self.done, self.config.iterations, progress.refine
            )));
        }
        Ok(StageState {
            progress,
            appearance_optimiser,
            fixed: tensors.get("fixed_colours").cloned(),
        })
    }
}

/// An Adam state for `stage` from a restored checkpoint, or a fresh one when the stage has not
/// started (`done == 0`).
pub(super) fn stage_optimiser(
    vars: &VarMap,
    config: crate::optim::AdamConfig,
    stage: u64,
    done: u64,
    saved: &Option<(u64, HashMap<String, Tensor>)>,
    path: &Path,
) -> Result<Adam, TrainError> {
    let mut adam = Adam::from_varmap(vars, config)?;
    if done > 0 {
        let bad = |reason: String| TrainError::Checkpoint {
            path: path.to_owned(),
            reason,
        };
        match saved {
            Some((s, state)) if *s == stage => adam
                .load_state_tensors(state)
                .map_err(|e| bad(e.to_string()))?,
            _ => return Err(bad(format!("no optimiser state for stage {stage}"))),
        }
    }
    Ok(adam)
}
