//! Checkpoints: every parameter, Adam's moments, the parameter average, the best-validated average and
//! the counters in one safetensors file, written atomically, and restored bit for bit on resume.

use super::*;

impl Trainer {
    /// Writes parameters, optimiser state and progress to `path` (safetensors, atomically).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), TrainError> {
        save_tensors(&self.checkpoint_tensors("")?, path)
    }

    /// Parameters (`param.NAME`), optimiser state and progress, every name prefixed by `prefix`.
    pub(crate) fn checkpoint_tensors(
        &self,
        prefix: &str,
    ) -> Result<HashMap<String, Tensor>, TrainError> {
        let mut tensors: HashMap<String, Tensor> = self
            .optimiser
            .state_tensors()?
            .into_iter()
            .map(|(k, v)| (format!("{prefix}{k}"), v))
            .collect();
        insert_varmap(&mut tensors, &format!("{prefix}param."), &self.varmap)?;
        if let Some(a) = &self.average {
            for (k, v) in a.state_tensors()? {
                tensors.insert(format!("{prefix}{k}"), v);
            }
        }
        if let Some(r) = &self.pose_refinement {
            for (k, v) in r.state_tensors()? {
                tensors.insert(format!("{prefix}{k}"), v);
            }
        }
        if let Some(o) = &self.outline_offsets {
            for (k, v) in o.state_tensors()? {
                tensors.insert(format!("{prefix}{k}"), v);
            }
        }
        let window: Vec<f64> = self.warm_window.iter().flat_map(|w| [w.0, w.1]).collect();
        let n = self.warm_window.len();
        tensors.insert(
            format!("{prefix}warm.window"),
            Tensor::from_vec(window, (n, 2), &Device::Cpu)?,
        );
        tensors.insert(
            format!("{prefix}warm.converged"),
            Tensor::new(&[u32::from(self.warm_converged)], &Device::Cpu)?,
        );
        let p = [self.warm_done, self.done].map(split_u64).concat();
        tensors.insert(
            format!("{prefix}progress"),
            Tensor::new(p.as_slice(), &Device::Cpu)?,
        );
        // The best-validated average is what a finished run exports: without it a run resumed
        // after its last iteration would export the last average instead.
        if let Some((score, iteration, params)) = &self.best {
            for (name, t) in params {
                tensors.insert(format!("{prefix}best.param.{name}"), t.clone());
            }
            tensors.insert(
                format!("{prefix}best.score"),
                Tensor::new(
                    &[
                        score.boundary_px,
                        score.contour_px,
                        score.silhouette_px,
                        score.iou,
                        score.outline_offset_px,
                    ],
                    &Device::Cpu,
                )?,
            );
            let meta = [*iteration, score.views as u64].map(split_u64).concat();
            tensors.insert(
                format!("{prefix}best.meta"),
                Tensor::new(meta.as_slice(), &Device::Cpu)?,
            );
        }
        Ok(tensors)
    }

    /// The same SkinNet run moved onto other training data of the same capture (another
    /// training template, such as the full-resolution one, for stage 4): parameters, Adam's
    /// moments, the parameter averages, the best-validated average and the progress carry over;
    /// what is derived from the template (rest positions, Laplacian, candidate masks, the
    /// validation frames' scores) is rebuilt for `data`. The static baseline has one logit row
    /// per vertex and cannot move (an error).
    pub fn with_data(self, data: TrainData) -> Result<Self, TrainError> {
        if self.is_static() {
            return Err(TrainError::Data(
                "the static baseline's weights belong to its template's vertices".into(),
            ));
        }
        let tensors = self.checkpoint_tensors("")?;
        let mut moved = Trainer::new(data, self.config.clone(), false)?;
        moved.restore_tensors(
            &tensors,
            "",
            Path::new("(the run moved to other training data)"),
        )?;
        // The timings so far belong to the same run (`profile.csv` is rewritten after stage 4).
        moved.profile = self.profile.clone();
        Ok(moved)
    }

    /// Restores a checkpoint written by [`Trainer::save_checkpoint`] for the same data, config
    /// and model kind; training then continues exactly where it stopped.
    pub fn resume(&mut self, path: &Path) -> Result<(), TrainError> {
        let tensors = load_tensors(path)?;
        self.restore_tensors(&tensors, "", path)
    }

    /// Restores what [`Trainer::checkpoint_tensors`] wrote under `prefix`; errors name `path`.
    pub(crate) fn restore_tensors(
        &mut self,
        tensors: &HashMap<String, Tensor>,
        prefix: &str,
        path: &Path,
    ) -> Result<(), TrainError> {
        let bad = |reason: String| TrainError::Checkpoint {
            path: path.to_owned(),
            reason,
        };
        restore_varmap(tensors, &format!("{prefix}param."), &self.varmap, &bad)?;
        let state: HashMap<String, Tensor> = tensors
            .iter()
            .filter_map(|(k, v)| Some((k.strip_prefix(prefix)?.to_string(), v.clone())))
            .collect();
        self.optimiser
            .load_state_tensors(&state)
            .map_err(|e| bad(e.to_string()))?;
        self.average = if state.contains_key("avg.weight") {
            let mut a = average::ParameterAverage::new(&self.varmap, self.config.ema_half_life)?;
            a.load_state_tensors(&state)
                .map_err(|e| bad(e.to_string()))?;
            Some(a)
        } else {
            None
        };
        if let Some(r) = &mut self.pose_refinement {
            r.load_state_tensors(&state).map_err(&bad)?;
        }
        if let Some(o) = &mut self.outline_offsets {
            o.load_state_tensors(&state).map_err(&bad)?;
        }
        let p = read_u64s(tensors, &format!("{prefix}progress"), 2).map_err(&bad)?;
        self.warm_done = p[0];
        self.done = p[1];
        self.best = match tensors.get(&format!("{prefix}best.score")) {
            None => None,
            Some(score) => {
                let s = score
                    .to_vec1::<f64>()
                    .map_err(|e| bad(format!("`{prefix}best.score`: {e}")))?;
                // Checkpoints written before the outline offset existed hold four values; the
                // offset is then unknown (NaN). Only the silhouette distance ranks checkpoints.
                let (boundary_px, contour_px, silhouette_px, iou, outline_offset_px) = match s[..] {
                    [b, c, s, i] => (b, c, s, i, f64::NAN),
                    [b, c, s, i, o] => (b, c, s, i, o),
                    _ => {
                        return Err(bad(format!(
                            "`{prefix}best.score` has {} values, expected 4 or 5",
                            s.len()
                        )));
                    }
                };
                let meta = read_u64s(tensors, &format!("{prefix}best.meta"), 2).map_err(&bad)?;
                let param_prefix = format!("{prefix}best.param.");
                let mut params: NamedTensors = tensors
                    .iter()
                    .filter_map(|(k, v)| {
                        Some((k.strip_prefix(&param_prefix)?.to_string(), v.clone()))
                    })
                    .collect();
                params.sort_by(|a, b| a.0.cmp(&b.0));
                let views = usize::try_from(meta[1])
                    .map_err(|_| bad(format!("`{prefix}best.meta`: {} views", meta[1])))?;
                Some((
                    validation::ValidationScore {
                        boundary_px,
                        contour_px,
                        silhouette_px,
                        iou,
                        outline_offset_px,
                        views,
                    },
                    meta[0],
                    params,
                ))
            }
        };
        let window = tensors
            .get(&format!("{prefix}warm.window"))
            .ok_or_else(|| bad(format!("`{prefix}warm.window` is missing")))?
            .to_vec2::<f64>()
            .map_err(|e| bad(format!("`{prefix}warm.window`: {e}")))?;
        self.warm_window = window.iter().map(|r| (r[0], r[1])).collect();
        self.warm_converged = tensors
            .get(&format!("{prefix}warm.converged"))
            .ok_or_else(|| bad(format!("`{prefix}warm.converged` is missing")))?
            .to_vec1::<u32>()
            .map_err(|e| bad(format!("`{prefix}warm.converged`: {e}")))?
            .first()
            .is_some_and(|&c| c != 0);
        Ok(())
    }
}

/// `x` as two little-endian `u32` halves (safetensors and candle have no u64 that survives
/// every backend).
pub(crate) fn split_u64(x: u64) -> [u32; 2] {
    [(x & 0xffff_ffff) as u32, (x >> 32) as u32]
}

/// The `count` u64 values stored by [`split_u64`] halves under `name`.
pub(crate) fn read_u64s(
    tensors: &HashMap<String, Tensor>,
    name: &str,
    count: usize,
) -> Result<Vec<u64>, String> {
    let p = tensors
        .get(name)
        .ok_or_else(|| format!("`{name}` is missing"))?
        .to_vec1::<u32>()
        .map_err(|e| format!("`{name}`: {e}"))?;
    if p.len() != 2 * count {
        return Err(format!("`{name}` has the wrong length"));
    }
    Ok(p.chunks_exact(2)
        .map(|h| u64::from(h[0]) | (u64::from(h[1]) << 32))
        .collect())
}

/// Adds every variable `NAME` of `varmap` to `out` as `prefix + NAME`.
pub(crate) fn insert_varmap(
    out: &mut HashMap<String, Tensor>,
    prefix: &str,
    varmap: &VarMap,
) -> Result<(), TrainError> {
    for (k, v) in lock_vars(varmap)?.iter() {
        out.insert(format!("{prefix}{k}"), v.as_tensor().clone());
    }
    Ok(())
}

/// The variables of `varmap` (locked for the caller).
pub(crate) fn lock_vars(
    varmap: &VarMap,
) -> Result<std::sync::MutexGuard<'_, HashMap<String, candle_core::Var>>, TrainError> {
    varmap
        .data()
        .lock()
        .map_err(|_| TrainError::Data("VarMap lock poisoned".into()))
}

/// Sets every variable `NAME` of `varmap` from `tensors[prefix + NAME]`, which must exist with
/// the variable's shape (`bad` turns a reason into the caller's error).
pub(crate) fn restore_varmap(
    tensors: &HashMap<String, Tensor>,
    prefix: &str,
    varmap: &VarMap,
    bad: &dyn Fn(String) -> TrainError,
) -> Result<(), TrainError> {
    for (k, v) in lock_vars(varmap)?.iter() {
        let t = tensors
            .get(&format!("{prefix}{k}"))
            .ok_or_else(|| bad(format!("`{prefix}{k}` is missing")))?;
        if t.shape() != v.shape() {
            return Err(bad(format!(
                "`{prefix}{k}` has shape {:?}, expected {:?}",
                t.dims(),
                v.dims()
            )));
        }
        v.set(t)?;
    }
    Ok(())
}

/// Writes `tensors` to `path` atomically (a temporary file renamed over it).
pub(crate) fn save_tensors(
    tensors: &HashMap<String, Tensor>,
    path: &Path,
) -> Result<(), TrainError> {
    let tmp = path.with_extension("tmp");
    candle_core::safetensors::save(tensors, &tmp)?;
    std::fs::rename(&tmp, path).map_err(|source| TrainError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Reads a safetensors checkpoint; a file that cannot be read is a [`TrainError::Checkpoint`].
pub(crate) fn load_tensors(path: &Path) -> Result<HashMap<String, Tensor>, TrainError> {
    candle_core::safetensors::load(path, &Device::Cpu).map_err(|e| TrainError::Checkpoint {
        path: path.to_owned(),
        reason: e.to_string(),
    })
}
