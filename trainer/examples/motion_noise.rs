//! How accurate must a tracked motion be? A copy of a capture whose training frames' motion is
//! perturbed by random joint turns of a known size, to train SkinNet on and score at the true
//! test poses (`docs/experiments/tracking.md`, "How accurate the motion must be").
//!
//! ```sh
//! cargo run --release -p skinfield-trainer --example motion_noise -- CAPTURE OUT SIGMA_RAD [iid|shared] [SEED]
//! ```
//!
//! Every joint's local rotation of every training frame is followed by a turn `exp(r)`,
//! `r ~ N(0, σ² I₃)` (radians), and every root's translation moves by `N(0, (0.3 σ)² I₃)` in
//! file units (0.3 m per radian: a hip's turn of σ moves the pelvis about as far as a turn of
//! the trunk). `iid` draws anew for each frame (the part of a tracker's error that more frames
//! average out); `shared` draws once and applies the same turns to every training frame (the
//! part they share, such as a skeleton that is not the template's). Test frames and the
//! canonical frame keep their motion, so `trainer eval --capture CAPTURE` of a model trained on
//! OUT scores it at the true test poses. Prints the mean per-joint position error (MPJPE) of the
//! perturbed training frames against the input, in file units.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use glam::{Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::capture::{CaptureWriter, MANIFEST_FILE, load_capture};
use skinfield_trainer::files::copy_tree;
use skinfield_trainer::track::capture::mpjpe;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: motion_noise CAPTURE OUT SIGMA_RAD [iid|shared] [SEED]";
    let (Some(input), Some(out), Some(sigma)) = (args.get(1), args.get(2), args.get(3)) else {
        bail!("{usage}");
    };
    let sigma: f32 = sigma.parse().context("SIGMA_RAD")?;
    if !(sigma.is_finite() && sigma >= 0.0) {
        bail!("SIGMA_RAD must be a finite number ≥ 0, not {sigma}");
    }
    let shared = match args.get(4).map(String::as_str) {
        None | Some("iid") => false,
        Some("shared") => true,
        Some(other) => bail!("noise mode `{other}`: iid or shared; {usage}"),
    };
    let seed: u64 = args.get(5).map_or(Ok(0), |s| s.parse()).context("SEED")?;
    let (input, out) = (PathBuf::from(input), PathBuf::from(out));
    if out.canonicalize().ok() == input.canonicalize().ok() {
        bail!("OUT must differ from CAPTURE (the input keeps its motion)");
    }
    let capture = load_capture(&input).with_context(|| format!("loading {}", input.display()))?;
    if !capture.has_motion() {
        bail!("{} has no motion to perturb", input.display());
    }
    let skeleton = &capture.skeleton;
    let roots: Vec<bool> = skeleton.parents().iter().map(Option::is_none).collect();

    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut draw = || -> Vec<(Vec3, Vec3)> {
        (0..skeleton.len())
            .map(|_| {
                (
                    gaussian3(&mut rng) * sigma,
                    gaussian3(&mut rng) * (0.3 * sigma),
                )
            })
            .collect()
    };
    let once = draw();
    let mut poses = capture.poses.clone();
    for &f in &capture.train_frames {
        let turns = if shared { once.clone() } else { draw() };
        for (j, (local, (turn, shift))) in poses[f].locals.iter_mut().zip(turns).enumerate() {
            local.rotation = (local.rotation * Quat::from_scaled_axis(turn)).normalize();
            if roots[j] {
                local.translation += shift;
            }
        }
    }
    let train_errors = {
        let pick = |p: &[skinfield_formats::Pose]| -> Vec<skinfield_formats::Pose> {
            capture.train_frames.iter().map(|&f| p[f].clone()).collect()
        };
        mpjpe(skeleton, &pick(&poses), &pick(&capture.poses))?
    };

    let manifest = capture.manifest.clone();
    let motion = manifest
        .motion
        .clone()
        .context("the manifest's motion path")?;
    copy_tree(
        &capture.dir,
        &out,
        &[capture.dir.join(MANIFEST_FILE), capture.dir.join(&motion)],
    )?;
    let writer = CaptureWriter::new(&out, manifest)?;
    writer.write_motion(&poses, 30.0)?;
    writer.finish()?;
    let mean = train_errors.iter().sum::<f64>() / train_errors.len().max(1) as f64;
    println!(
        "{} training frames perturbed ({}, σ = {sigma} rad, seed {seed}): MPJPE {mean:.5} (file units), worst frame {:.5}; written to {}",
        train_errors.len(),
        if shared { "shared" } else { "iid" },
        train_errors.iter().copied().fold(0.0, f64::max),
        out.display()
    );
    Ok(())
}

/// Three independent standard normal numbers (Box–Muller).
fn gaussian3(rng: &mut ChaCha8Rng) -> Vec3 {
    let mut pair = || {
        let u: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
        let v: f64 = rng.random();
        let r = (-2.0 * u.ln()).sqrt();
        let a = std::f64::consts::TAU * v;
        (r * a.cos(), r * a.sin())
    };
    let (x, y) = pair();
    let (z, _) = pair();
    Vec3::new(x as f32, y as f32, z as f32)
}
