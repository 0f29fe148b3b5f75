//! `trainer demo --ablations`: the rows of the paper's Table 2 that apply to the built-in
//! capture, each trained and scored on the held-out test poses.
//!
//! Rows: initial (bone heat); static weights; stage 1 only; w/o L_rend (stage 4 with λ_rend = 0:
//! stage 1's losses for stage 4's iterations on its learning-rate schedule, so the SkinNet
//! budget is equal; with the default full-resolution stage 4 this is what the plain demo
//! exports); w/ albedo only (stages 1, 2, 4);
//! w/ fixed vertex colours (stage 1, then stage 4 with colours read from the first training
//! frame's images); ours (stages 1–4); ours with fewer cameras (stages 1–4 on the first
//! `--ablation-cameras` cameras); silhouettes only (every regulariser off, the Laplacian and
//! the hinge on the hidden vertices' drift included: stage 1 from the warm start, then stage 4
//! without the rendering term when the configuration runs it at full resolution, otherwise
//! stage 1 for both stages' iterations); silhouettes + drift hinge (the same with the default's
//! hinge on the hidden vertices' drift kept: the only regulariser that leaves the vertices some
//! training outline shows free, so the row says what the images teach where they can see).
//! With the default full-resolution stage 4 every stage-4 row runs on the full template.
//! The rows with every camera but the last share one stage-1 run (its checkpoint), so they
//! differ only in what follows it; the variants continue from that run's last parameter
//! average, the stage-1 row is its best-validated average (as the demo exports it).

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use clap::Args as ClapArgs;
use skinfield_formats::StaticSkin;
use skinfield_formats::capture::Capture;
use skinfield_formats::skf::write_atomic;
use skinfield_trainer::eval::table::{EvalRow, rows_to_json, rows_to_table};
use skinfield_trainer::eval::{EvalOptions, Skinning, evaluate};
use skinfield_trainer::train::data::{DataOptions, TrainData, train_data};
use skinfield_trainer::train::stages::{ColourSource, StageConfig, load_images};
use skinfield_trainer::train::{LossWeights, TrainConfig, Trainer};

use super::train::{full_template_data, train_static, trains_every_vertex};

/// The row every other is compared with: all four stages, every camera.
pub const FULL_METHOD: &str = "ours";

/// The row of stage 1 alone, exported as a run without stages 2–4 exports it.
pub const STAGE1_METHOD: &str = "stage 1 only";

/// Options of `trainer demo --ablations`.
#[derive(ClapArgs, Debug, Clone)]
pub struct AblationArgs {
    /// Produce the ablation table (paper Table 2) instead of the plain demo. The options below
    /// shape its rows and are refused without it (the plain demo trains on the configuration's
    /// stages).
    #[arg(long)]
    pub ablations: bool,
    /// Stage 2 (AlbedoNet) iterations.
    #[arg(long, requires = "ablations", default_value_t = 100)]
    pub albedo_iterations: u64,
    /// Stage 3 (ShadowNet) iterations.
    #[arg(long, requires = "ablations", default_value_t = 100)]
    pub shadow_iterations: u64,
    /// Stage 4 (SkinNet refined with the rendering loss) iterations.
    #[arg(long, requires = "ablations", default_value_t = 100)]
    pub refine_iterations: u64,
    /// Visible pixels sampled per view and iteration.
    #[arg(long, requires = "ablations", default_value_t = StageConfig::default().pixels_per_view)]
    pub pixels_per_view: usize,
    /// Views rendered per frame and iteration in the rendering loss (0 = all).
    #[arg(long, requires = "ablations", default_value_t = 4)]
    pub views_per_frame: usize,
    /// Weight of the rendering loss in stage 4.
    #[arg(long, requires = "ablations", default_value_t = StageConfig::default().rendering_weight)]
    pub rendering_weight: f64,
    /// Gaussian blur (pixels) of the target images inside their masks.
    #[arg(long, requires = "ablations", default_value_t = StageConfig::default().image_blur_px)]
    pub image_blur_px: f64,
    /// Cameras of the "fewer cameras" row.
    #[arg(long, requires = "ablations", default_value_t = 4)]
    pub ablation_cameras: usize,
}

/// One trained variant after stage 1.
struct Variant {
    name: &'static str,
    stages: StageConfig,
}

/// Trains and scores every row; writes `out/ablations.{md,json}` and returns the rows with
/// their training seconds.
pub fn run(
    args: &AblationArgs,
    capture: &Capture,
    initial: &StaticSkin,
    base: TrainConfig,
    train_vertices: usize,
    out: &Path,
    progress: bool,
) -> anyhow::Result<Vec<(EvalRow, f64)>> {
    let eval = |s: &Skinning, name: &str| eval_row(capture, s, name);
    // An ablation reports every variant, a worse one too: no refusal.
    let base = TrainConfig {
        refuse_worse_than_initial: false,
        ..base
    };
    let mut rows = vec![(eval(&Skinning::Initial, "initial weights")?, 0.0)];

    let t = Instant::now();
    let static_file = out.join("static_weights.json");
    train_static(
        capture,
        initial,
        base.clone(),
        &out.join("train-static"),
        &static_file,
        false,
        progress,
    )?;
    rows.push((
        eval(&Skinning::Static(static_file), "static weights")?,
        t.elapsed().as_secs_f64(),
    ));

    let full = StageConfig {
        albedo_iterations: args.albedo_iterations,
        shadow_iterations: args.shadow_iterations,
        refine_iterations: args.refine_iterations,
        pixels_per_view: args.pixels_per_view,
        views_per_frame: args.views_per_frame,
        rendering_weight: args.rendering_weight,
        image_blur_px: args.image_blur_px,
        full_resolution: base.stages.full_resolution,
        ..StageConfig::default()
    };
    let variants = [
        // Stage 4 with λ_rend = 0: the same iterations on the same learning-rate schedule,
        // only without the rendering term (continuing stage 1's schedule instead would give
        // the control 100 steps at the tail of a cosine, next to nothing).
        Variant {
            name: "w/o L_rend",
            stages: StageConfig {
                albedo_iterations: 0,
                shadow_iterations: 0,
                rendering_weight: 0.0,
                ..full
            },
        },
        Variant {
            name: "w/ albedo only",
            stages: StageConfig {
                shadow_iterations: 0,
                colours: ColourSource::AlbedoOnly,
                ..full
            },
        },
        Variant {
            name: "w/ fixed vertex colours",
            stages: StageConfig {
                albedo_iterations: 0,
                shadow_iterations: 0,
                colours: ColourSource::FixedVertexColours,
                ..full
            },
        },
        Variant {
            name: FULL_METHOD,
            stages: full,
        },
    ];

    for cameras in [0, args.ablation_cameras] {
        let options = DataOptions {
            train_vertices,
            cameras,
        };
        let data = train_data(capture, initial, &options)?;
        // Stages 2–4 on the full template: built once (unless stage 1 already trains on it),
        // every variant resumes stage 1 onto it.
        let stage_data = (full.full_resolution
            && !trains_every_vertex(data.template.vertex_count(), capture))
        .then(|| full_template_data(capture, initial, &options))
        .transpose()?;
        let stage_data = stage_data.as_ref().unwrap_or(&data);
        let images = load_images(capture, &options, full.image_blur_px)?;
        let stage1_dir = out.join(format!("ablation-stage1-cams{cameras}"));
        let t = Instant::now();
        let mut stage1 = Trainer::new(data.clone(), base.clone(), false)?;
        stage1.run(&stage1_dir, progress)?;
        let stage1_s = t.elapsed().as_secs_f64();
        println!(
            "stage 1 ({} cameras): {stage1_s:.0} s",
            if cameras == 0 {
                capture.rig.cameras.len()
            } else {
                cameras
            }
        );
        if cameras == 0 {
            // Stage 1 as a run without stages 2–4 exports it (the best-validated average);
            // the demo's SkinNet (stage 4 at full resolution by default) is "w/o L_rend".
            let row = export_best_and_score(&mut stage1, &stage1_dir, capture, STAGE1_METHOD)?;
            rows.push((row, stage1_s));
        }
        drop(stage1);
        let list: Vec<&Variant> = if cameras == 0 {
            variants.iter().collect()
        } else {
            variants.iter().filter(|v| v.name == FULL_METHOD).collect()
        };
        for v in list {
            let name = if cameras == 0 {
                v.name.to_string()
            } else {
                format!("ours, {cameras} cameras")
            };
            let dir = row_dir(out, &name);
            let t = Instant::now();
            let config = TrainConfig {
                stages: v.stages,
                ..base.clone()
            };
            let mut trainer = Trainer::new(stage_data.clone(), config, false)?;
            trainer.resume(&stage1_dir.join("checkpoint.safetensors"))?;
            trainer.run(&dir, progress)?;
            trainer.adopt_average()?;
            let appearance = if v.stages.any() {
                Some(trainer.run_stages(images.clone(), &dir, progress)?)
            } else {
                None
            };
            trainer.adopt_average()?;
            let mut model = trainer.skf_model()?;
            // Untrained appearance nets (fixed colours, or no rendering) are not stored.
            if let Some(a) =
                appearance.filter(|_| v.stages.learns_albedo() && v.stages.rendering_weight > 0.0)
            {
                a.push_to_skf(&mut model)?;
            }
            let path = dir.join("model.skf");
            model.write(&path)?;
            let seconds = stage1_s + t.elapsed().as_secs_f64();
            let row = eval(&Skinning::Skf(path), &name)?;
            println!(
                "{name}: Chamfer {:.3} cm ({seconds:.0} s with stage 1)",
                row.chamfer_cm
            );
            rows.push((row, seconds));
        }
        if cameras == 0 {
            rows.extend(silhouette_rows(
                capture, &data, stage_data, &base, args, out, progress,
            )?);
        }
    }

    let plain: Vec<EvalRow> = rows.iter().map(|(r, _)| r.clone()).collect();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "| method | Chamfer (cm) | M2S (cm) | S2M (cm) | frames | training (s) |"
    );
    let _ = writeln!(md, "| --- | --- | --- | --- | --- | --- |");
    for (r, s) in &rows {
        let _ = writeln!(
            md,
            "| {} | {:.3} | {:.3} | {:.3} | {} | {s:.0} |",
            r.method, r.chamfer_cm, r.m2s_cm, r.s2m_cm, r.frames
        );
    }
    let _ = writeln!(
        md,
        "\nStage 1: {} warm-start + {} iterations; stage 2: {}; stage 3: {}; stage 4: {}{} (λ_rend {}, {} pixels × {} views per frame per iteration, images blurred by {} px); {} training vertices.",
        base.warm_start_iterations,
        base.iterations,
        args.albedo_iterations,
        args.shadow_iterations,
        args.refine_iterations,
        if full.full_resolution {
            " at full resolution"
        } else {
            ""
        },
        args.rendering_weight,
        args.pixels_per_view,
        args.views_per_frame,
        args.image_blur_px,
        train_vertices
    );
    println!("\n{}\n{md}", rows_to_table(&plain));
    let md_path = out.join("ablations.md");
    write_atomic(&md_path, md.as_bytes()).with_context(|| md_path.display().to_string())?;
    let json_path = out.join("ablations.json");
    write_atomic(&json_path, rows_to_json(&plain).as_bytes())
        .with_context(|| json_path.display().to_string())?;
    Ok(rows)
}

/// `skinning` scored on the capture's test frames, as the row `name`.
fn eval_row(capture: &Capture, skinning: &Skinning, name: &str) -> anyhow::Result<EvalRow> {
    let mut row = evaluate(capture, skinning, &EvalOptions::default())
        .with_context(|| format!("evaluating `{name}`"))?;
    row.method = name.to_string();
    Ok(row)
}

/// Adopts `trainer`'s best-validated parameter average, writes it as `dir/model.skf` (without
/// appearance nets) and scores it as the row `name`.
fn export_best_and_score(
    trainer: &mut Trainer,
    dir: &Path,
    capture: &Capture,
    name: &str,
) -> anyhow::Result<EvalRow> {
    trainer.adopt_average()?;
    let path = dir.join("model.skf");
    trainer.skf_model()?.write(&path)?;
    eval_row(capture, &Skinning::Skf(path), name)
}

/// The work folder of the row `name` in `out`.
fn row_dir(out: &Path, name: &str) -> std::path::PathBuf {
    out.join(format!(
        "ablation-{}",
        name.replace(['/', ' ', ',', '+'], "_")
    ))
}

/// Which of the two silhouette rows [`silhouette_rows`] trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SilhouetteRow {
    /// Every regulariser off, the hinge on the hidden vertices' drift included.
    Alone,
    /// Every regulariser off but the hinge, at the base configuration's weight.
    WithDriftHinge,
}

impl SilhouetteRow {
    fn name(self) -> &'static str {
        match self {
            Self::Alone => "silhouettes only",
            Self::WithDriftHinge => "silhouettes + drift hinge",
        }
    }

    /// The row's loss weights: `base`'s silhouette terms, every regulariser off but (for
    /// [`Self::WithDriftHinge`]) the hinge at `base`'s weight.
    fn weights(self, base: &LossWeights) -> LossWeights {
        LossWeights {
            laplacian: 0.0,
            skinning: 0.0,
            partwise: 0.0,
            prior: 0.0,
            hidden_prior: 0.0,
            // The hinge is the default's; without it the row measures what the images alone
            // do, with it what they do where an outline sees (docs/experiments/fidelity.md, "A
            // hinge on the hidden vertices' drift").
            hidden_drift: match self {
                Self::Alone => 0.0,
                Self::WithDriftHinge => base.hidden_drift,
            },
            ..*base
        }
    }
}

/// The two silhouettes rows, [`SilhouetteRow::Alone`] then [`SilhouetteRow::WithDriftHinge`]:
/// the training as configured with the Laplacian, the skinning
/// regularisers, both priors on the initial weights and (for [`SilhouetteRow::Alone`]) the hinge
/// on the hidden vertices' drift off, so the row says what the silhouette terms alone do to the
/// weights (with the hinge: what they do where some training outline sees). When the base
/// configuration runs stage 4 at full resolution (the default) so does this row, with the same
/// iterations and without the rendering term; otherwise stage 1 runs for as many image
/// iterations as stage 1 and stage 4 together. Stage 1 trains on `data`, stage 4 on
/// `stage_data` (the full template's).
fn silhouette_rows(
    capture: &Capture,
    data: &TrainData,
    stage_data: &TrainData,
    base: &TrainConfig,
    args: &AblationArgs,
    out: &Path,
    progress: bool,
) -> anyhow::Result<Vec<(EvalRow, f64)>> {
    let mut rows = Vec::new();
    for row in [SilhouetteRow::Alone, SilhouetteRow::WithDriftHinge] {
        let name = row.name();
        let dir = row_dir(out, name);
        let weights = row.weights(&base.weights);
        let config = if base.stages.full_resolution {
            TrainConfig {
                weights,
                stages: StageConfig {
                    refine_iterations: args.refine_iterations,
                    rendering_weight: 0.0,
                    full_resolution: true,
                    ..StageConfig::default()
                },
                ..base.clone()
            }
        } else {
            TrainConfig {
                iterations: base.iterations + args.refine_iterations,
                weights,
                stages: StageConfig::default(),
                ..base.clone()
            }
        };
        let t = Instant::now();
        let mut trainer = Trainer::new(data.clone(), config, false)?;
        trainer.run(&dir, progress)?;
        trainer.adopt_average()?;
        if trainer.config().stages.any() {
            trainer = trainer.with_data(stage_data.clone())?;
            trainer.run_stages(Vec::new(), &dir, progress)?;
        }
        let seconds = t.elapsed().as_secs_f64();
        let scored = export_best_and_score(&mut trainer, &dir, capture, name)?;
        println!(
            "{name}: Chamfer {:.3} cm ({seconds:.0} s)",
            scored.chamfer_cm
        );
        rows.push((scored, seconds));
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_silhouette_rows_keep_only_the_image_terms_and_the_second_the_hinge() {
        // Every weight non-zero, so a regulariser left on by mistake shows.
        let base = LossWeights {
            silhouette_boundary: 2.0,
            silhouette_contour: 3.0,
            laplacian: 5.0,
            skinning: 7.0,
            partwise: 11.0,
            prior: 13.0,
            hidden_prior: 17.0,
            hidden_drift: 19.0,
        };
        let images_only = LossWeights {
            silhouette_boundary: 2.0,
            silhouette_contour: 3.0,
            laplacian: 0.0,
            skinning: 0.0,
            partwise: 0.0,
            prior: 0.0,
            hidden_prior: 0.0,
            hidden_drift: 0.0,
        };
        assert_eq!(SilhouetteRow::Alone.weights(&base), images_only);
        assert_eq!(
            SilhouetteRow::WithDriftHinge.weights(&base),
            LossWeights {
                hidden_drift: 19.0,
                ..images_only
            }
        );
        assert_ne!(
            SilhouetteRow::Alone.name(),
            SilhouetteRow::WithDriftHinge.name()
        );
    }

    #[test]
    fn every_row_has_its_own_work_folder_named_after_it() {
        let out = Path::new("abl");
        let names = [
            "w/o L_rend",
            "ours, 4 cameras",
            SilhouetteRow::Alone.name(),
            SilhouetteRow::WithDriftHinge.name(),
        ];
        let dirs: Vec<_> = names.iter().map(|n| row_dir(out, n)).collect();
        assert_eq!(dirs[0], out.join("ablation-w_o_L_rend"));
        assert_eq!(dirs[1], out.join("ablation-ours__4_cameras"));
        assert_eq!(dirs[2], out.join("ablation-silhouettes_only"));
        assert_eq!(dirs[3], out.join("ablation-silhouettes___drift_hinge"));
    }
}
