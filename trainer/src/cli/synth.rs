//! `trainer synth --out DIR`: writes the built-in synthetic capture.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use skinfield_trainer::synth::{SynthConfig, synthesize};

/// Arguments of `trainer synth`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Output folder (created; existing files of the same names are replaced).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of every random choice; same seed, same bytes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Number of cameras (two rings at two heights).
    #[arg(long, default_value_t = SynthConfig::default().cameras)]
    pub cameras: usize,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = SynthConfig::default().width)]
    pub resolution: u32,
    /// Frames per training clip (5 clips).
    #[arg(long, default_value_t = SynthConfig::default().train_frames_per_clip)]
    pub train_frames: usize,
    /// Frames per test clip (3 clips).
    #[arg(long, default_value_t = SynthConfig::default().test_frames_per_clip)]
    pub test_frames: usize,
    /// Marching grid cells along the character's height.
    #[arg(long, default_value_t = SynthConfig::default().grid)]
    pub grid: usize,
    /// Template vertex count after simplification (about).
    #[arg(long, default_value_t = SynthConfig::default().target_vertices)]
    pub vertices: usize,
}

/// Runs `trainer synth`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = SynthConfig {
        train_frames_per_clip: args.train_frames,
        test_frames_per_clip: args.test_frames,
        cameras: args.cameras,
        width: args.resolution,
        height: args.resolution,
        grid: args.grid,
        target_vertices: args.vertices,
        seed: args.seed,
        ..SynthConfig::default()
    };
    let s = synthesize(&args.out, &config)
        .with_context(|| format!("writing the capture to {}", args.out.display()))?;
    println!(
        "wrote {}: {} vertices, {} triangles, {} joints; {} train + {} test frames × {} cameras; \
         character {:.2} s, total {:.2} s",
        args.out.display(),
        s.vertices,
        s.triangles,
        s.joints,
        s.train_frames,
        s.test_frames,
        s.cameras,
        s.character_seconds,
        s.total_seconds
    );
    Ok(())
}
