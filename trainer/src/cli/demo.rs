//! `trainer demo`: the README's main job on the built-in default. Synthesise the capture,
//! compute bone-heat initial weights, train SkinNet (stage 1) and the static baseline, export,
//! evaluate on the held-out test poses, print the table and write it with plots and pictures.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Parser;
use skinfield_formats::capture::load_capture;
use skinfield_formats::skf::write_atomic;
use skinfield_trainer::eval::diagnostics::{
    diagnostics_markdown, outline_errors, part_errors, terms_on_truth, truth_outline_views,
};
use skinfield_trainer::eval::figure::{Panel, write_error_figure};
use skinfield_trainer::eval::spread::{spread, spread_table};
use skinfield_trainer::eval::table::{EvalRow, rows_to_json, rows_to_table};
use skinfield_trainer::eval::{EvalOptions, PreparedSkinning, Skinning, evaluate, evaluate_frames};
use skinfield_trainer::synth::{SynthConfig, synthesize};
use skinfield_trainer::train::TrainConfig;
use skinfield_trainer::train::data::{DataOptions, initial_weights};
use skinfield_trainer::train::ensemble::EnsembleConfig;

use super::train::{train_skinnet, train_static};

/// Arguments of `trainer demo`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Output folder (capture, model, results, pictures).
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Seed of the capture and of training (the first one with `--seeds`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Train and evaluate this many seeds (`seed`, `seed + 1`, …, each in `OUT/seed-S`) and
    /// write the table as mean ± standard deviation per row (`OUT/results.md`,
    /// `OUT/results_seeds.json`; with `--ablations`, `OUT/ablations.md` and
    /// `OUT/ablations_seeds.json`).
    #[arg(long, default_value_t = 1)]
    pub seeds: u64,
    /// Training configuration (JSON, `TrainConfig` fields, as `trainer train --config`) that
    /// SkinNet and the static baseline start from instead of the trainer's defaults. `--seed`,
    /// `--iterations` and `--static-iterations` always set their fields; `--warm-start` and
    /// `--ensemble` override the file's only when given.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Cap of SkinNet's warm start (regressing the initial weights; it stops earlier once
    /// converged). Default: the configuration's (the trainer's: 3,000).
    #[arg(long)]
    pub warm_start: Option<u64>,
    /// SkinNet image-loss iterations.
    #[arg(long, default_value_t = 1000)]
    pub iterations: u64,
    /// Static-baseline iterations.
    #[arg(long, default_value_t = 1000)]
    pub static_iterations: u64,
    /// Training-template vertex count for SkinNet.
    #[arg(long, default_value_t = DataOptions::default().train_vertices)]
    pub train_vertices: usize,
    /// SkinNets trained from consecutive seeds (each with the whole warm start and image
    /// schedule) whose mean weights are distilled into the exported one (`ensemble.members`
    /// of the training configuration); 1: a single network. Not used by `--ablations`.
    /// Default: the configuration's (the trainer's: 1).
    #[arg(long)]
    pub ensemble: Option<usize>,
    /// Hide the progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// The ablation table (paper Table 2) instead of the plain demo.
    #[command(flatten)]
    pub ablation: super::ablations::AblationArgs,
}

/// Runs `trainer demo`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // Read before anything is synthesised, so a bad file fails at once.
    let base = base_config(&args)?;
    if args.seeds <= 1 {
        return run_seed(&args, &base, args.seed, &args.out).map(|_| ());
    }
    let total = Instant::now();
    let mut runs = Vec::new();
    for seed in args.seed..args.seed + args.seeds {
        println!("== seed {seed}");
        runs.push(run_seed(
            &args,
            &base,
            seed,
            &args.out.join(format!("seed-{seed}")),
        )?);
    }
    // The demo's rows are read against the ceiling and the static baseline; the ablation's
    // against the full method, so a positive difference is what leaving a part out costs.
    let (bound, reference, name, what) = if args.ablation.ablations {
        (
            None,
            Some(super::ablations::FULL_METHOD),
            "ablations",
            "ablation table (paper Table 2)",
        )
    } else {
        (Some(BOUND), Some("static"), "results", "demo results")
    };
    let rows = spread(&runs, bound, reference);
    let table = spread_table(&rows, bound, reference);
    println!("\n{table}");
    let mut md = String::new();
    let _ = writeln!(md, "# Skinfield {what}, {} seeds\n", args.seeds);
    let _ = writeln!(
        md,
        "Built-in capture, seeds {}–{} (each: its own capture and initialisation; per-seed \
         results in `seed-S/`). Mean ± sample standard deviation over the seeds; the paired \
         column is each row's Chamfer distance minus the reference row's on the same seed.\n",
        args.seed,
        args.seed + args.seeds - 1
    );
    let _ = writeln!(md, "{table}");
    let _ = writeln!(md, "{}", config_sentence(&args));
    let _ = writeln!(md, "Total: {:.1} s.", total.elapsed().as_secs_f64());
    let md_path = args.out.join(format!("{name}.md"));
    write_atomic(&md_path, md.as_bytes()).with_context(|| md_path.display().to_string())?;
    let json_path = args.out.join(format!("{name}_seeds.json"));
    let json = serde_json::to_string_pretty(&rows)? + "\n";
    write_atomic(&json_path, json.as_bytes()).with_context(|| json_path.display().to_string())?;
    println!(
        "total {:.1} s; results in {}",
        total.elapsed().as_secs_f64(),
        md_path.display()
    );
    Ok(())
}

/// Every this many training frames are scored for the diagnostics' image terms.
const DIAGNOSTIC_STRIDE: usize = 8;

/// Top of the error pictures' colour scale (cm).
const MAX_ERROR_CM: f32 = 2.0;

/// The ceiling the table's gap shares are measured against.
const BOUND: &str = "bound-pose";

/// The training configuration every seed starts from: `--config` (or the trainer's defaults)
/// with the demo's flags applied; the seed is set per run.
fn base_config(args: &Args) -> anyhow::Result<TrainConfig> {
    let file = TrainConfig::load_or_default(args.config.as_deref())?;
    let config = TrainConfig {
        iterations: args.iterations,
        warm_start_iterations: args.warm_start.unwrap_or(file.warm_start_iterations),
        ensemble: EnsembleConfig {
            members: args.ensemble.unwrap_or(file.ensemble.members),
            ..file.ensemble
        },
        ..file
    };
    config.validate().map_err(|field| {
        anyhow::anyhow!("the arguments make an invalid training configuration: field `{field}`")
    })?;
    Ok(config)
}

/// Where the training configuration came from, for the results files.
fn config_sentence(args: &Args) -> String {
    match &args.config {
        Some(path) => format!(
            "Training configuration: `{}` (with the demo's flags applied).\n",
            path.display()
        ),
        None => "Training configuration: the trainer's defaults.\n".to_string(),
    }
}

/// The demo (or with `--ablations` the ablation table) for one seed in `out`; returns its
/// table.
fn run_seed(
    args: &Args,
    base: &TrainConfig,
    seed: u64,
    out: &std::path::Path,
) -> anyhow::Result<Vec<EvalRow>> {
    let total = Instant::now();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let capture_dir = out.join("capture");
    let mut timings = Vec::new();

    let t = Instant::now();
    let summary = synthesize(
        &capture_dir,
        &SynthConfig {
            seed,
            ..SynthConfig::default()
        },
    )?;
    timings.push(("synthesise the capture", t.elapsed().as_secs_f64()));
    println!(
        "capture: {} vertices, {} joints, {} train / {} test frames → {}",
        summary.vertices,
        summary.joints,
        summary.train_frames,
        summary.test_frames,
        capture_dir.display()
    );
    let capture = load_capture(&capture_dir)?;

    let t = Instant::now();
    let initial = initial_weights(&capture)?;
    timings.push(("bone heat (initial weights)", t.elapsed().as_secs_f64()));

    let model = out.join("model.skf");
    let config = TrainConfig {
        seed,
        ..base.clone()
    };
    let options = DataOptions {
        train_vertices: args.train_vertices,
        ..DataOptions::default()
    };
    if args.ablation.ablations {
        let ablation_out = out.join("ablations");
        let rows = super::ablations::run(
            &args.ablation,
            &capture,
            &initial,
            config,
            args.train_vertices,
            &ablation_out,
            !args.quiet,
        )?;
        println!("total {:.1} s", total.elapsed().as_secs_f64());
        return Ok(rows.into_iter().map(|(row, _)| row).collect());
    }
    let t = Instant::now();
    let skin_work = out.join("train-skinnet");
    let run = train_skinnet(
        &capture,
        &initial,
        config.clone(),
        &options,
        &skin_work,
        &model,
        false,
        !args.quiet,
    )?;
    timings.push((
        "train SkinNet (data + loop + export)",
        t.elapsed().as_secs_f64(),
    ));
    let (warm_ran, image_ran) = (run.warm_iterations, run.image_iterations);
    // Seconds per phase rather than one average: a full-resolution stage-4 iteration costs
    // several times a stage-1 one.
    let stage1_s = run.seconds - run.stage_seconds;

    let static_file = out.join("static_weights.json");
    let static_work = out.join("train-static");
    let t = Instant::now();
    let static_config = TrainConfig {
        iterations: args.static_iterations,
        ..config
    };
    train_static(
        &capture,
        &initial,
        static_config,
        &static_work,
        &static_file,
        false,
        !args.quiet,
    )?;
    timings.push(("train the static baseline", t.elapsed().as_secs_f64()));

    let t = Instant::now();
    let methods = [
        Skinning::Initial,
        Skinning::Static(static_file.clone()),
        Skinning::Skf(model.clone()),
        Skinning::Oracle,
        Skinning::OracleDqs,
        Skinning::BoundStatic,
        Skinning::BoundPose,
    ];
    let options = EvalOptions::default();
    let rows: Vec<EvalRow> = methods
        .iter()
        .map(|m| {
            evaluate(&capture, m, &options)
                .with_context(|| format!("evaluating `{}`", m.method_name()))
        })
        .collect::<anyhow::Result<_>>()?;
    timings.push(("evaluate", t.elapsed().as_secs_f64()));

    // Diagnostics: per-part errors, the same split by what the training outlines see, and the
    // image terms on the truth vs on each method.
    let t = Instant::now();
    let compared = [
        Skinning::Initial,
        Skinning::Static(static_file.clone()),
        Skinning::Skf(model.clone()),
    ];
    let parts = compared
        .iter()
        .map(|m| Ok((m.method_name().to_string(), part_errors(&capture, m)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let outline = match truth_outline_views(&capture) {
        Some(views) => compared
            .iter()
            .map(|m| {
                Ok((
                    m.method_name().to_string(),
                    outline_errors(&capture, m, &views)?,
                ))
            })
            .collect::<anyhow::Result<Vec<_>>>()?,
        None => Vec::new(),
    };
    let terms = terms_on_truth(&capture, &compared, DIAGNOSTIC_STRIDE)?;
    let diagnostics_path = out.join("diagnostics.md");
    write_atomic(
        &diagnostics_path,
        diagnostics_markdown(&parts, &outline, &terms, DIAGNOSTIC_STRIDE).as_bytes(),
    )
    .with_context(|| diagnostics_path.display().to_string())?;
    timings.push(("diagnostics", t.elapsed().as_secs_f64()));

    let table = rows_to_table(&rows);
    println!("\n{table}");
    let json_path = out.join("results.json");
    write_atomic(&json_path, rows_to_json(&rows).as_bytes())
        .with_context(|| json_path.display().to_string())?;

    // Plots (`trainer train` drew them in its work folders) and pictures.
    // An ensemble ran its image iterations in its members' folders: the first member's plots
    // stand for them.
    let skin_plots = if config.ensemble.is_on() {
        skin_work.join("member-0")
    } else {
        skin_work.clone()
    };
    for (work, who) in [(&skin_plots, "skinnet"), (&static_work, "static")] {
        for name in ["losses", "validation"] {
            let from = work.join(format!("{name}.svg"));
            let to = out.join(format!("{name}_{who}.svg"));
            std::fs::copy(&from, &to).with_context(|| format!("copying {}", from.display()))?;
        }
    }
    // The pictures show the test frame bone heat gets most wrong (a frame near the rest pose
    // would show nothing).
    let initial_skinning = PreparedSkinning::new(&capture, &Skinning::Initial)?;
    let frame = evaluate_frames(&capture, &EvalOptions::default(), |f| {
        initial_skinning.pose_frame(&capture, f)
    })?
    .iter()
    .max_by(|a, b| (a.m2s_cm + a.s2m_cm).total_cmp(&(b.m2s_cm + b.s2m_cm)))
    .map(|m| m.frame)
    .context("the capture has no test frames")?;
    for (weights, kind, name) in [
        (
            Skinning::Skf(model.clone()),
            super::render::Kind::Overlay,
            "overlay_ours.png",
        ),
        (
            Skinning::Skf(model.clone()),
            super::render::Kind::Error,
            "error_ours.png",
        ),
        (
            Skinning::Initial,
            super::render::Kind::Error,
            "error_initial.png",
        ),
        (
            Skinning::Static(static_file.clone()),
            super::render::Kind::Error,
            "error_static.png",
        ),
    ] {
        super::render::run(super::render::Args {
            capture: capture_dir.clone(),
            weights,
            kind,
            frame: Some(frame),
            camera: 1,
            max_error_cm: MAX_ERROR_CM,
            templates: Vec::new(),
            out: out.join(name),
        })?;
    }
    // The same frame as the camera saw it, and the error pictures side by side with a scale.
    let seen = capture.load_image(1, frame)?;
    let captured = out.join("captured.png");
    skinfield_formats::capture::write_image_png(&captured, seen.width, seen.height, &seen.rgb)?;
    let panel = |caption: &str, file: &str| Panel {
        caption: caption.to_string(),
        png: out.join(file),
    };
    write_error_figure(
        &out.join("error_panels.svg"),
        &[
            panel("initial (bone heat)", "error_initial.png"),
            panel("static (learned)", "error_static.png"),
            panel("ours (SkinNet)", "error_ours.png"),
            panel("captured image", "captured.png"),
        ],
        &format!(
            "Test frame {frame}, camera 1 (the frame bone heat gets most wrong): per-vertex error"
        ),
        MAX_ERROR_CM,
    )
    .map_err(|e| anyhow::anyhow!("{e}"))?;

    let mut md = String::new();
    let _ = writeln!(md, "# Skinfield demo results\n");
    let _ = writeln!(
        md,
        "Built-in capture (seed {}), {} test frames, {} surface samples per frame.\n",
        seed,
        capture.test_frames.len(),
        options.samples
    );
    let _ = writeln!(md, "```\n{table}```\n");
    let _ = writeln!(md, "{}", config_sentence(args));
    let _ = writeln!(md, "| step | seconds |\n| --- | --- |");
    for (step, s) in &timings {
        let _ = writeln!(md, "| {step} | {s:.1} |");
    }
    let _ = writeln!(
        md,
        "\nSkinNet: {} warm-start + {} image iterations at {} training vertices{} in {:.1} s{}.",
        warm_ran,
        image_ran,
        args.train_vertices,
        if config.ensemble.is_on() {
            format!(
                " ({} ensemble members and the distillation of their mean)",
                config.ensemble.members
            )
        } else {
            String::new()
        },
        stage1_s,
        config
            .stages
            .refine_summary()
            .map_or_else(String::new, |s| {
                format!(", then {s} (stages 2–4: {:.1} s)", run.stage_seconds)
            }),
    );
    let _ = writeln!(md, "Total: {:.1} s.", total.elapsed().as_secs_f64());
    let md_path = out.join("results.md");
    write_atomic(&md_path, md.as_bytes()).with_context(|| md_path.display().to_string())?;
    for (step, s) in &timings {
        println!("{step:40} {s:8.1} s");
    }
    println!(
        "SkinNet: {warm_ran} warm-start + {image_ran} image iterations in {stage1_s:.1} s{}; total {:.1} s; results in {}",
        if run.stage_seconds > 0.0 {
            format!(", stages 2–4 in {:.1} s", run.stage_seconds)
        } else {
            String::new()
        },
        total.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(extra: &[&str]) -> Args {
        Args::try_parse_from(std::iter::once("demo").chain(extra.iter().copied()))
            .expect("valid demo arguments")
    }

    #[test]
    fn the_ablation_options_are_refused_without_ablations() {
        let parse = |extra: &[&str]| {
            Args::try_parse_from(std::iter::once("demo").chain(extra.iter().copied()))
        };
        for flag in [
            "--albedo-iterations",
            "--shadow-iterations",
            "--refine-iterations",
            "--pixels-per-view",
            "--views-per-frame",
            "--rendering-weight",
            "--image-blur-px",
            "--ablation-cameras",
        ] {
            let err = parse(&[flag, "3"]).map(|_| ()).expect_err(flag);
            assert!(err.to_string().contains("--ablations"), "{flag}: {err}");
            let ok = parse(&["--ablations", flag, "3"]).expect(flag);
            assert!(ok.ablation.ablations);
        }
        assert!(!args(&[]).ablation.ablations);
    }

    #[test]
    fn without_a_file_the_demo_trains_on_the_trainers_defaults_at_its_own_budget() {
        let config = base_config(&args(&[])).unwrap();
        assert_eq!(
            config,
            TrainConfig {
                iterations: 1000,
                ..TrainConfig::default()
            }
        );
    }

    #[test]
    fn a_config_file_sets_every_field_but_the_demos_budget() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.json");
        std::fs::write(
            &path,
            r#"{"iterations": 50, "warm_start_iterations": 1234,
                "warm_start_kl_tolerance": 0.002, "ensemble": {"members": 2}}"#,
        )
        .unwrap();
        let p = path.to_str().unwrap();
        let config = base_config(&args(&["--config", p])).unwrap();
        assert_eq!(config.warm_start_kl_tolerance, 0.002);
        assert_eq!(config.warm_start_iterations, 1234);
        assert_eq!(config.ensemble.members, 2);
        // `--iterations` has the demo's default, which the file does not override.
        assert_eq!(config.iterations, 1000);
        let config = base_config(&args(&[
            "--config",
            p,
            "--warm-start",
            "77",
            "--ensemble",
            "1",
            "--iterations",
            "9",
        ]))
        .unwrap();
        assert_eq!(
            (
                config.warm_start_iterations,
                config.ensemble.members,
                config.iterations
            ),
            (77, 1, 9)
        );
        assert_eq!(config.warm_start_kl_tolerance, 0.002);
        assert!(config_sentence(&args(&["--config", p])).contains(p));
    }

    #[test]
    fn a_bad_config_file_is_refused_naming_the_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.json");
        std::fs::write(&path, r#"{"warm_start_kl_tolerance": -1}"#).unwrap();
        let p = path.to_str().unwrap();
        let e = base_config(&args(&["--config", p]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(p) && e.contains("warm_start_kl_tolerance"),
            "{e}"
        );
        std::fs::write(&path, r#"{"no_such_field": 1}"#).unwrap();
        let e = base_config(&args(&["--config", p]))
            .unwrap_err()
            .to_string();
        assert!(e.contains(p) && e.contains("no_such_field"), "{e}");
        let missing = dir.path().join("missing.json");
        let e = base_config(&args(&["--config", missing.to_str().unwrap()])).unwrap_err();
        // The whole chain, as `trainer` prints it, names the file and the cause once.
        let e = crate::one_line(&e);
        assert!(e.contains("missing.json"), "{e}");
        assert_eq!(e.matches("os error").count(), 1, "{e}");
        // Flags that make an invalid configuration are refused too.
        let e = base_config(&args(&["--ensemble", "0"]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("ensemble"), "{e}");
    }
}
