//! `trainer train`: SkinNet (stage 1 from silhouettes, then stages 2–4 with the appearance field
//! and the rendering loss when the configuration asks for them) or the static-weights baseline.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Parser;
use skinfield_formats::StaticSkin;
use skinfield_formats::capture::{Capture, MotionFile, load_capture, transform_to_array};
use skinfield_trainer::eval::static_weights::write_static_weights;
use skinfield_trainer::train::data::{
    DataOptions, TrainData, full_resolution_vertex_count, initial_weights, static_train_data,
    train_data,
};
use skinfield_trainer::train::plot::plot_log;
use skinfield_trainer::train::stages::load_images;
use skinfield_trainer::train::validation::held_out_indices;
use skinfield_trainer::train::{TrainConfig, Trainer, WarmStatus};

/// Arguments of `trainer train`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Capture folder (manifest.json inside).
    #[arg(long)]
    pub capture: PathBuf,
    /// Output: a `.skf` model, or with `--static` a static-weights JSON file.
    #[arg(long)]
    pub out: PathBuf,
    /// Train the static-weights baseline (one pose-independent weight set) instead of SkinNet.
    #[arg(long = "static")]
    pub static_weights: bool,
    /// Training configuration (JSON, `TrainConfig` fields; missing fields take the defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Folder for losses.csv and checkpoints (default: beside `--out`).
    #[arg(long)]
    pub work: Option<PathBuf>,
    /// Continue from the checkpoints in the work folder (stage 1, then stages 2–4).
    #[arg(long)]
    pub resume: bool,
    /// Training-template vertex count for SkinNet (0 = full resolution).
    #[arg(long, default_value_t = DataOptions::default().train_vertices)]
    pub train_vertices: usize,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Write the model even when it explains the held-out silhouettes worse than the initial
    /// weights (by default that is an error and nothing is written).
    #[arg(long)]
    pub allow_worse: bool,
    /// Correct every training frame's pose together with the weights, from the same images
    /// (`pose_refinement.enabled` in the configuration): for a capture whose motion was tracked
    /// (`trainer track`). The corrected motion is written to `refined_motion.json` in the work
    /// folder.
    #[arg(long)]
    pub refine_poses: bool,
    /// Trust the masks' outlines as they are: learn no outline offsets
    /// (`"outline_offset": {"enabled": false}` in the configuration). By default one offset per
    /// camera is learned with the weights, so that masks from a segmentation whose outlines lie
    /// a fraction of a pixel to a pixel outside or inside the subject's move the offsets instead
    /// of the weights (written to `outline_offsets.csv` in the work folder).
    #[arg(long)]
    pub no_outline_offsets: bool,
}

/// Runs `trainer train`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let capture = load_capture(&args.capture)
        .with_context(|| format!("loading the capture {}", args.capture.display()))?;
    let mut config = TrainConfig::load_or_default(args.config.as_deref())?;
    if args.allow_worse {
        config.refuse_worse_than_initial = false;
    }
    if args.refine_poses {
        config.pose_refinement.enabled = true;
    }
    if args.no_outline_offsets {
        config.outline_offset.enabled = false;
    }
    let work = args
        .work
        .clone()
        .unwrap_or_else(|| default_work_dir(&args.out));
    let initial = initial_weights(&capture)?;
    let options = DataOptions {
        train_vertices: args.train_vertices,
        ..DataOptions::default()
    };
    let seconds = if args.static_weights {
        train_static(
            &capture,
            &initial,
            config,
            &work,
            &args.out,
            args.resume,
            !args.quiet,
        )?
    } else {
        let run = train_skinnet(
            &capture,
            &initial,
            config,
            &options,
            &work,
            &args.out,
            args.resume,
            !args.quiet,
        )?;
        println!(
            "SkinNet: {} warm-start + {} image iterations before stages 2–4",
            run.warm_iterations, run.image_iterations
        );
        run.seconds
    };
    println!(
        "wrote {} ({seconds:.1} s of training; losses in {})",
        args.out.display(),
        work.join("losses.csv").display()
    );
    Ok(())
}

/// `OUT` → `OUT.work/` beside it.
#[must_use]
pub fn default_work_dir(out: &Path) -> PathBuf {
    let mut name = out
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".work");
    out.with_file_name(name)
}

/// What [`train_skinnet`] reports about a finished run.
#[derive(Clone, Copy, Debug)]
pub struct SkinNetRun {
    /// Seconds spent in the optimisation loops, all stages.
    pub seconds: f64,
    /// Of which stages 2–4 (after stage 1's warm start and image iterations).
    pub stage_seconds: f64,
    /// How the warm start ended (with an ensemble, the distillation of the members' mean).
    pub warm_start: WarmStatus,
    /// Warm-start iterations run before stage 1's image iterations, all of them: with an
    /// ensemble, every member's and the distillation's.
    pub warm_iterations: u64,
    /// Stage 1's image iterations (with an ensemble, the members' together).
    pub image_iterations: u64,
}

/// Trains SkinNet on the capture's training frames (stages 2–4 too when `config.stages` has
/// iterations) and writes the `.skf` (with the appearance nets after stages 2–4).
#[allow(clippy::too_many_arguments)]
pub fn train_skinnet(
    capture: &Capture,
    initial: &StaticSkin,
    config: TrainConfig,
    options: &DataOptions,
    work: &Path,
    out: &Path,
    resume: bool,
    progress: bool,
) -> anyhow::Result<SkinNetRun> {
    let data = train_data(capture, initial, options)?;
    let start = Instant::now();
    let (mut trainer, members) = if config.ensemble.is_on() {
        train_ensemble(data, config, work, resume, progress)?
    } else {
        let mut trainer = Trainer::new(data, config, false)?;
        if resume {
            trainer.resume(&work.join("checkpoint.safetensors"))?;
        }
        trainer.run(work, progress)?;
        report_warm_start(&trainer);
        (trainer, (0, 0))
    };
    let warm_start = trainer.warm_status();
    let (warm_iterations, image_iterations) = {
        let (warm, image) = trainer.progress();
        (members.0 + warm, members.1 + image)
    };
    // The average of stage 1's iterates is the model; stages 2–4 continue from it.
    trainer.adopt_average()?;
    let stages_start = Instant::now();
    let mut trainer = for_stages(trainer, capture, initial, options)?;
    let stages = trainer.config().stages;
    let appearance = if stages.any() {
        let images = if stages.renders() {
            load_images(capture, options, stages.image_blur_px)?
        } else {
            Vec::new()
        };
        Some(if resume {
            trainer.resume_stages(images, work, progress)?
        } else {
            trainer.run_stages(images, work, progress)?
        })
    } else {
        None
    };
    // Stage 4's average, when it ran.
    trainer.adopt_average()?;
    let seconds = start.elapsed().as_secs_f64();
    let stage_seconds = if stages.any() {
        stages_start.elapsed().as_secs_f64()
    } else {
        0.0
    };
    write_refined_motion(capture, &trainer, work)?;
    plot_logs(work, "SkinNet")?;
    check_validation(&trainer)?;
    let mut model = trainer.skf_model()?;
    // Fixed colours leave AlbedoNet untrained: storing it would show noise in a viewer.
    if let Some(a) = appearance.filter(|_| stages.learns_albedo()) {
        a.push_to_skf(&mut model)?;
    }
    model.write(out)?;
    Ok(SkinNetRun {
        seconds,
        stage_seconds,
        warm_start,
        warm_iterations,
        image_iterations,
    })
}

/// `trainer` after stage 1, ready for stages 2–4: with `stages.full_resolution` moved onto the
/// capture's full-resolution template ([`Trainer::with_data`]), unless it already trains on it or
/// no stage runs.
pub fn for_stages(
    trainer: Trainer,
    capture: &Capture,
    initial: &StaticSkin,
    options: &DataOptions,
) -> anyhow::Result<Trainer> {
    let stages = trainer.config().stages;
    if !(stages.any() && stages.full_resolution)
        || trains_every_vertex(trainer.training_vertex_count(), capture)
    {
        return Ok(trainer);
    }
    let data = full_template_data(capture, initial, options)?;
    trainer
        .with_data(data)
        .context("moving SkinNet to the full-resolution template for stages 2–4")
}

/// Whether a SkinNet trained on `training_vertices` vertices already trains on the capture's
/// full-resolution template (the training template was not simplified, only welded if it was
/// split), so stages 2–4 need no full-resolution data of their own.
#[must_use]
pub fn trains_every_vertex(training_vertices: usize, capture: &Capture) -> bool {
    training_vertices == full_resolution_vertex_count(&capture.template)
}

/// The training data of `options` rebuilt on the capture's full-resolution template (every
/// vertex a training vertex): what `stages.full_resolution` trains stages 2–4 on.
pub fn full_template_data(
    capture: &Capture,
    initial: &StaticSkin,
    options: &DataOptions,
) -> anyhow::Result<TrainData> {
    let full = DataOptions {
        train_vertices: 0,
        ..*options
    };
    Ok(train_data(capture, initial, &full)?)
}

/// Stage 1 as an ensemble ([`skinfield_trainer::train::ensemble`]): every member trained in
/// `work/member-K` (seed `seed + K`), then a student in `work` distilled from their mean
/// weights. Returns the student, ready for stages 2–4 and export (its image iterations are the
/// members'), and the warm-start and image iterations the members ran together.
fn train_ensemble(
    data: TrainData,
    config: TrainConfig,
    work: &Path,
    resume: bool,
    progress: bool,
) -> anyhow::Result<(Trainer, (u64, u64))> {
    let members = config.ensemble.members;
    let mut teachers = Vec::with_capacity(members);
    let mut offsets: Vec<Vec<f32>> = Vec::new();
    let mut ran = (0, 0);
    for k in 0..members {
        let member_config = TrainConfig {
            seed: config.seed.wrapping_add(k as u64),
            stages: Default::default(),
            ensemble: Default::default(),
            ..config.clone()
        };
        let dir = work.join(format!("member-{k}"));
        println!(
            "ensemble member {} of {members} (seed {}) in {}",
            k + 1,
            member_config.seed,
            dir.display()
        );
        let mut member = Trainer::new(data.clone(), member_config, false)?;
        let checkpoint = dir.join("checkpoint.safetensors");
        if resume && checkpoint.exists() {
            member.resume(&checkpoint)?;
        }
        member.run(&dir, progress)?;
        report_warm_start(&member);
        let (warm, image) = member.progress();
        ran = (ran.0 + warm, ran.1 + image);
        member.adopt_average()?;
        let report = member.validation_report()?;
        println!("  member {}: validation {}", k + 1, report.model);
        plot_logs(&dir, &format!("SkinNet, ensemble member {}", k + 1))?;
        if let Some(o) = member.outline_offsets()? {
            println!("  member {}: {}", k + 1, describe_outline_offsets(&o));
            offsets.push(o);
        }
        teachers.push(member.frozen_net()?);
    }
    // The student's stage 1 is the distillation; its image iterations were the members'.
    let student_config = TrainConfig {
        iterations: 0,
        ..config
    };
    let mut student = Trainer::new(data, student_config, false)?;
    student.distil_from(teachers)?;
    // The student's outline offsets (for stage 4 and its validation) start at the members'
    // mean: each member estimated the same masks' margins.
    if let Some(mean) = mean_offsets(&offsets) {
        student.set_outline_offsets(&mean)?;
    }
    let checkpoint = work.join("checkpoint.safetensors");
    if resume && checkpoint.exists() {
        student.resume(&checkpoint)?;
    }
    println!("distilling the {members} members' mean weights into one SkinNet");
    student.run(work, progress)?;
    report_warm_start(&student);
    Ok((student, ran))
}

/// Every camera's mean over the members' outline offsets (`None` without any). The members
/// trained on the same data, so each has one offset per camera.
fn mean_offsets(members: &[Vec<f32>]) -> Option<Vec<f32>> {
    let first = members.first()?;
    let n = members.len() as f32;
    Some(
        (0..first.len())
            .map(|c| members.iter().map(|m| m[c]).sum::<f32>() / n)
            .collect(),
    )
}

/// With pose refinement: writes `work/refined_motion.json`, the capture's motion with every
/// training frame's pose as the training corrected it (the validation and test frames as they
/// were), in the capture's `motion.json` format, and prints the corrections' size.
pub fn write_refined_motion(
    capture: &Capture,
    trainer: &Trainer,
    work: &Path,
) -> anyhow::Result<()> {
    let (Some(poses), Some(corrections)) = (trainer.refined_poses()?, trainer.pose_corrections()?)
    else {
        return Ok(());
    };
    // The training frames the trainer kept, in its order (`Trainer::new` holds some out).
    let mut frames = capture.train_frames.clone();
    let held = held_out_indices(frames.len(), trainer.config().validation_frames);
    for &i in held.iter().rev() {
        frames.remove(i);
    }
    anyhow::ensure!(
        frames.len() == poses.len(),
        "pose refinement: {} refined poses for {} training frames",
        poses.len(),
        frames.len()
    );
    let mut motion = capture.poses.clone();
    for (&f, pose) in frames.iter().zip(poses) {
        motion[f] = pose;
    }
    let file = MotionFile {
        fps: 30.0,
        frames: motion
            .iter()
            .map(|p| p.locals.iter().map(transform_to_array).collect())
            .collect(),
    };
    let path = work.join("refined_motion.json");
    let json = serde_json::to_vec(&file)?;
    skinfield_formats::skf::write_atomic(&path, &json)
        .with_context(|| format!("writing {}", path.display()))?;
    let angles: Vec<f64> = corrections
        .iter()
        .flat_map(|c| c.angles.iter().copied())
        .collect();
    let mean = angles.iter().sum::<f64>() / angles.len().max(1) as f64;
    let largest = angles.iter().copied().fold(0.0, f64::max);
    println!(
        "pose refinement: {} training frames corrected by {:.2}° per joint on average, at \
         most {largest_deg:.2}°; motion in {}",
        corrections.len(),
        mean.to_degrees(),
        path.display(),
        largest_deg = largest.to_degrees()
    );
    Ok(())
}

/// Plots the stage-1 logs of `work` (`losses.csv`, `validation.csv`, when present) beside them
/// as SVG.
pub fn plot_logs(work: &Path, model: &str) -> anyhow::Result<()> {
    for (name, what) in [
        ("losses", "image-loss terms per iteration"),
        ("validation", "held-out silhouettes (validation)"),
    ] {
        let csv_path = work.join(format!("{name}.csv"));
        let Ok(csv) = std::fs::read_to_string(&csv_path) else {
            continue;
        };
        if csv.lines().filter(|l| !l.trim().is_empty()).count() < 2 {
            continue;
        }
        plot_log(
            &csv,
            &format!("{model}: {what}"),
            &work.join(format!("{name}.svg")),
        )?;
    }
    Ok(())
}

/// Prints the validation scores of the initial weights and of the model about to be written
/// (and which averaged iterate was kept), and refuses a model that explains the validation
/// silhouettes worse than the initial weights unless the configuration allows it.
pub fn check_validation(trainer: &Trainer) -> anyhow::Result<()> {
    let report = trainer.validation_report()?;
    let frames = match report.held_out_frames {
        0 => "the training frames (too few to hold any out)".to_string(),
        n => format!("{n} held-out frames"),
    };
    println!("validation on {frames}, {} views:", report.model.views);
    println!("  initial weights: {}", report.initial);
    println!("  trained model:   {}", report.model);
    if let Some((iteration, _)) = trainer.best_validation() {
        println!("  (the parameter average at image iteration {iteration} scored best)");
    }
    if let Some(offsets) = trainer.outline_offsets()? {
        println!("  {}", describe_outline_offsets(&offsets));
    }
    if let Some((hidden, total)) = trainer.hidden_vertices() {
        println!(
            "  {hidden} of the {total} training vertices are on no training outline when posed \
             by the initial weights (the hidden vertices `weights.hidden_prior` and \
             `weights.hidden_drift` act on)"
        );
    }
    if let Some(margin) = report.mask_margin() {
        eprintln!("warning: {margin}.");
    }
    if let Some(drift) = trainer.hidden_drift()? {
        println!("  {drift}");
        if drift.is_unconfirmed() {
            eprintln!(
                "warning: the vertices no training view shows on its outline moved more than \
                 {}× as far as those the images check (99th percentile); their weights are the \
                 network's guess from their neighbours, which no image confirms. The hinge on \
                 their drift (`weights.hidden_drift`), the Laplacian (`weights.laplacian`) or the \
                 prior on hidden vertices (`weights.hidden_prior`) holds them; more views of \
                 those parts would show them.",
                skinfield_trainer::train::hidden::UNCONFIRMED_DRIFT_RATIO
            );
        }
    }
    if let Some(worse) = report
        .guard(trainer.config().refuse_worse_than_initial)
        .map_err(|e| {
            anyhow::anyhow!(
                "{e}; nothing was written. Check the capture (masks, cameras, motion) and the \
                 training configuration, or pass --allow-worse to write the model anyway."
            )
        })?
    {
        eprintln!(
            "warning: {worse}; written anyway (--allow-worse, or `refuse_worse_than_initial: false` \
             in the configuration)."
        );
    }
    Ok(())
}

/// One line on the learned outline offsets: their mean and range over the cameras.
#[must_use]
pub fn describe_outline_offsets(offsets: &[f32]) -> String {
    let n = offsets.len().max(1) as f64;
    let mean = offsets.iter().map(|&b| f64::from(b)).sum::<f64>() / n;
    let lo = offsets.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = offsets.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    format!(
        "learned outline offsets: the masks lie {mean:+.3} px outside the model's outline on \
         average ({lo:+.3} to {hi:+.3} over {} cameras; outline_offsets.csv)",
        offsets.len()
    )
}

/// Says how the warm start ended: converged, or stopped at its cap (a warning on stderr: the
/// image losses then start from weights that differ from the initial ones).
fn report_warm_start(trainer: &Trainer) {
    let w = trainer.warm_status();
    if w.iterations == 0 {
        return;
    }
    let (what, consequence) = if trainer.is_distilling() {
        (
            "the distillation",
            "the exported SkinNet differs from the ensemble's mean weights",
        )
    } else {
        (
            "the warm start",
            "SkinNet starts away from the initial weights",
        )
    };
    if w.converged {
        println!(
            "{what} converged after {} iterations (KL {:.4}, position error {:.1e} of the \
             template's diagonal)",
            w.iterations, w.kl, w.position_relative
        );
    } else {
        eprintln!(
            "warning: {what} stopped at its cap of {} iterations without converging: \
             KL {:.4} (tolerance {}), position error {:.1e} of the template's diagonal \
             (tolerance {:.1e}). {consequence}; raise \
             `warm_start_iterations` in the training configuration.",
            w.iterations,
            w.kl,
            trainer.warm_settings().kl_tolerance,
            w.position_relative,
            trainer.warm_settings().position_tolerance
        );
    }
}

/// Trains the static baseline at full template resolution (it has one weight set per vertex, so
/// it cannot be evaluated at another resolution; a template split into copies of its positions
/// trains welded, one weight set per position: `train::data::static_train_data`) and writes the
/// static-weights file.
pub fn train_static(
    capture: &Capture,
    initial: &StaticSkin,
    mut config: TrainConfig,
    work: &Path,
    out: &Path,
    resume: bool,
    progress: bool,
) -> anyhow::Result<f64> {
    // The logits start at the initial weights: regressing them first would be a no-op.
    config.warm_start_iterations = 0;
    let (data, welded) = static_train_data(capture, initial)?;
    if let (Some(w), true) = (&welded, progress) {
        println!(
            "static baseline: the template's {} vertices lie at {} positions; one weight set per \
             position",
            capture.template.vertex_count(),
            w.template.vertex_count()
        );
    }
    let skeleton = data.skeleton.clone();
    let joints = skeleton.len();
    let mut trainer = Trainer::new(data, config, true)?;
    if resume {
        trainer.resume(&work.join("checkpoint.safetensors"))?;
    }
    let start = Instant::now();
    trainer.run(work, progress)?;
    trainer.adopt_average()?;
    let seconds = start.elapsed().as_secs_f64();
    write_refined_motion(capture, &trainer, work)?;
    plot_logs(work, "Static baseline")?;
    check_validation(&trainer)?;
    let mut dense = trainer
        .static_weights()?
        .context("the trainer holds no static weights")?;
    if let Some(w) = &welded {
        // Every copy of a position takes its welded vertex's weights.
        dense = w.expand(&dense, joints);
    }
    let skin = StaticSkin::from_dense(&dense, joints)?;
    write_static_weights(out, &skeleton, &skin)?;
    Ok(seconds)
}
