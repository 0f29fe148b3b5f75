//! `trainer eval --capture DIR --weights SPEC [--weights SPEC …] [--template FILE] [--json]`:
//! scores skinnings against the capture's ground-truth test meshes (M2S, S2M, Chamfer in
//! centimetres). `--template` poses another mesh over the same canonical space instead of the
//! capture's template (e.g. one written by `trainer resample`; SkinNet rows only).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use skinfield_formats::capture::load_capture;
use skinfield_trainer::eval::{
    DEFAULT_SAMPLES, EvalOptions, Skinning, evaluate_template, load_template, rows_to_json,
    rows_to_table,
};

/// Arguments of `trainer eval`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The capture folder (with ground truth for its test frames).
    #[arg(long)]
    pub capture: PathBuf,
    /// Skinning to score, one row each: `initial`, `static:FILE`, `skf:FILE`, `oracle`
    /// (ground-truth weights, LBS) or `oracle-dqs` (ground-truth weights, DQS). Repeatable.
    #[arg(long = "weights", required = true)]
    pub weights: Vec<Skinning>,
    /// Pose this glTF template (any resolution, the capture's canonical space) instead of the
    /// capture's own; only `skf:FILE` rows can pose a mesh with other vertices.
    #[arg(long)]
    pub template: Option<PathBuf>,
    /// Print `{"rows":[…]}` JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Points sampled per surface per test frame (uniform by area).
    #[arg(long, default_value_t = DEFAULT_SAMPLES)]
    pub samples: usize,
    /// Seed of the surface sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Runs `trainer eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let capture = load_capture(&args.capture)
        .with_context(|| format!("loading the capture {}", args.capture.display()))?;
    let options = EvalOptions {
        samples: args.samples,
        seed: args.seed,
    };
    let template = match &args.template {
        Some(path) => load_template(path)?,
        None => capture.template.clone(),
    };
    let mut rows = Vec::with_capacity(args.weights.len());
    for skinning in &args.weights {
        let row = evaluate_template(&capture, &template, skinning, &options)
            .with_context(|| format!("evaluating `{}`", skinning.method_name()))?;
        rows.push(row);
    }
    if args.json {
        print!("{}", rows_to_json(&rows));
    } else {
        print!("{}", rows_to_table(&rows));
    }
    Ok(())
}
