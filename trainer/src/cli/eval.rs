//! `trainer eval --capture DIR --weights SPEC [--weights SPEC …] [--json]`: scores skinnings
//! against the capture's ground-truth test meshes (M2S, S2M, Chamfer in centimetres).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use skinfield_formats::capture::load_capture;
use skinfield_trainer::eval::{
    DEFAULT_SAMPLES, EvalOptions, Skinning, evaluate, rows_to_json, rows_to_table,
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
    let mut rows = Vec::with_capacity(args.weights.len());
    for skinning in &args.weights {
        let row = evaluate(&capture, skinning, &options)
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
