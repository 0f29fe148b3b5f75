//! The whole run with a progress bar: warm start to convergence, image iterations, validation
//! every few iterations, checkpoints, logs and plots.

use super::*;

impl Trainer {
    /// Runs the remaining warm-start and image iterations, appending to `dir/losses.csv` and
    /// writing `dir/checkpoint.safetensors` every `checkpoint_every` iterations and at the end.
    /// Shows an indicatif progress bar with the current losses when `progress` is set.
    pub fn run(&mut self, dir: &Path, progress: bool) -> Result<(), TrainError> {
        let io = |path: &Path| {
            let path = path.to_owned();
            move |source: std::io::Error| TrainError::Io {
                path: path.clone(),
                source,
            }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let csv_path = dir.join("losses.csv");
        let mut csv = reopen_log(&csv_path, LossRecord::CSV_HEADER, self.done)?;
        let warm_path = dir.join("warm_start.csv");
        let mut warm_csv =
            reopen_log(&warm_path, "iteration,kl,position_relative", self.warm_done)?;
        let total = self.config.warm_start_iterations + self.config.iterations;
        let bar = if progress {
            indicatif::ProgressBar::new(total)
        } else {
            indicatif::ProgressBar::hidden()
        };
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:30} {pos}/{len} {elapsed_precise} eta {eta} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.set_position(self.warm_done + self.done);
        let ckpt = dir.join("checkpoint.safetensors");
        while self.warm_pending() {
            let r = self.warm_step()?;
            writeln!(
                warm_csv,
                "{},{:.6e},{:.6e}",
                r.iteration, r.kl, r.position_relative
            )
            .map_err(io(&warm_path))?;
            bar.set_message(format!(
                "warm start KL {:.3e}, position {:.1e} of the diagonal",
                r.kl, r.position_relative
            ));
            bar.inc(1);
            if self.config.checkpoint_every > 0
                && self.warm_done.is_multiple_of(self.config.checkpoint_every)
            {
                warm_csv.flush().map_err(io(&warm_path))?;
                self.save_checkpoint(&ckpt)?;
            }
        }
        warm_csv.flush().map_err(io(&warm_path))?;
        if self.warm_converged && self.warm_done < self.config.warm_start_iterations {
            // The skipped warm-start iterations leave the progress bar.
            bar.set_length(self.warm_done + self.config.iterations);
        }
        let validation_path = dir.join("validation.csv");
        let done = self.done;
        // Row 0 is the initial weights' score, rewritten by a run from the start.
        let mut validation_csv = reopen_log_keeping(
            &validation_path,
            "iteration,silhouette_px,boundary_px,contour_px,iou",
            |row| {
                done > 0
                    && row
                        .split(',')
                        .next()
                        .and_then(|i| i.parse::<u64>().ok())
                        .is_some_and(|i| i <= done)
            },
        )?;
        if self.done == 0 && self.config.iterations > 0 {
            let s = self.initial_score;
            writeln!(
                validation_csv,
                "0,{:.6},{:.6},{:.6},{:.6}",
                s.silhouette_px, s.boundary_px, s.contour_px, s.iou
            )
            .map_err(io(&validation_path))?;
        }
        while self.done < self.config.iterations {
            let r = self.step()?;
            writeln!(csv, "{}", r.csv_row()).map_err(io(&csv_path))?;
            let every = self.config.validation_every;
            if self.config.validation_frames > 0
                && (self.done == self.config.iterations
                    || (every > 0 && self.done.is_multiple_of(every)))
            {
                let s = self.validate_average()?;
                writeln!(
                    validation_csv,
                    "{},{:.6},{:.6},{:.6},{:.6}",
                    self.done, s.silhouette_px, s.boundary_px, s.contour_px, s.iou
                )
                .map_err(io(&validation_path))?;
                validation_csv.flush().map_err(io(&validation_path))?;
            }
            bar.set_message(format!(
                "total {:.3} sil {:.2}/{:.2}px lap {:.2e} skin {:.2e} part {:.2e}",
                r.total,
                r.silhouette_boundary,
                r.silhouette_contour,
                r.laplacian,
                r.skinning,
                r.partwise
            ));
            bar.inc(1);
            if self.config.checkpoint_every > 0
                && self.done.is_multiple_of(self.config.checkpoint_every)
            {
                csv.flush().map_err(io(&csv_path))?;
                self.save_checkpoint(&ckpt)?;
            }
        }
        csv.flush().map_err(io(&csv_path))?;
        self.save_checkpoint(&ckpt)?;
        self.write_profile(dir)?;
        self.write_outline_offsets(dir)?;
        if let Some(corrections) = self.pose_corrections()? {
            let path = dir.join("pose_refinement.csv");
            let names = self.data.skeleton.names();
            let mut text = String::from("training_frame,translation");
            for n in names {
                text += &format!(",{}_deg", n.replace([',', '"', '\n'], "_"));
            }
            text.push('\n');
            for (f, c) in corrections.iter().enumerate() {
                text += &format!("{f},{:.6e}", c.translation);
                for a in &c.angles {
                    text += &format!(",{:.4}", a.to_degrees());
                }
                text.push('\n');
            }
            skinfield_formats::skf::write_atomic(&path, text.as_bytes()).map_err(io(&path))?;
        }
        bar.finish();
        Ok(())
    }

    /// Writes `dir/outline_offsets.csv` (`camera,offset_px`) when the run learns outline offsets.
    pub(super) fn write_outline_offsets(&self, dir: &Path) -> Result<(), TrainError> {
        let Some(offsets) = self.outline_offsets()? else {
            return Ok(());
        };
        let mut text = String::from("camera,offset_px\n");
        for (c, b) in offsets.iter().enumerate() {
            text += &format!("{c},{b:.4}\n");
        }
        let path = dir.join("outline_offsets.csv");
        skinfield_formats::skf::write_atomic(&path, text.as_bytes())
            .map_err(|source| TrainError::Io { path, source })
    }

    /// Writes `dir/profile.csv`: the milliseconds per iteration of every phase and kind of
    /// iteration timed by this process ([`profile`]).
    pub(super) fn write_profile(&self, dir: &Path) -> Result<(), TrainError> {
        let path = dir.join("profile.csv");
        skinfield_formats::skf::write_atomic(&path, self.profile.csv().as_bytes())
            .map_err(|source| TrainError::Io { path, source })
    }
}
