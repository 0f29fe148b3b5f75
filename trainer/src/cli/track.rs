//! `trainer track --capture DIR --out DIR`: skeletal motion from the capture's 2D keypoints
//! (DeepCap's kinematics and global alignment layers, robust per-frame fit), written as a copy
//! of the capture whose motion is the tracked one, so `trainer train` runs on it unchanged.
//! `--synthesize` first writes synthetic detections projected from the capture's own motion
//! (as `trainer synth --keypoints` does) into that copy, and tracks the copy; the input capture
//! is never written.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use skinfield_formats::capture::{Capture, CaptureWriter, MANIFEST_FILE, load_capture};
use skinfield_trainer::eval::{PreparedSkinning, Skinning};
use skinfield_trainer::track::TrackOptions;
use skinfield_trainer::track::capture::{
    mean_turn_error_deg, mpjpe, temporal_filter, track_capture, write_synthetic_keypoints,
};
use skinfield_trainer::track::landmarks::{
    default_landmark_map, joint_ring_landmark_map, joint_side_landmark_map,
    joint_surface_landmark_map,
};
use skinfield_trainer::track::synthetic::DetectionNoise;

/// Arguments of `trainer track`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The capture (with keypoints, or `--synthesize`).
    #[arg(long)]
    pub capture: PathBuf,
    /// Output capture folder: the input's files (hard-linked where possible) with the tracked
    /// motion, plus `track.csv` (per-frame residuals).
    #[arg(long)]
    pub out: PathBuf,
    /// First write synthetic detections, projected from the capture's motion, into the copy
    /// (`--out`; the input stays as it was), then track them.
    #[arg(long)]
    pub synthesize: bool,
    /// How the synthetic detections are corrupted.
    #[command(flatten)]
    pub noise: NoiseArgs,
    /// Detections below this confidence are ignored.
    #[arg(long, default_value_t = TrackOptions::default().min_confidence)]
    pub min_confidence: f64,
    /// Weight of the temporal term (px² per rad²).
    #[arg(long, default_value_t = TrackOptions::default().smooth_weight)]
    pub smooth_weight: f64,
    /// Weight of the joint-limit prior (px² per rad²).
    #[arg(long, default_value_t = TrackOptions::default().limit_weight)]
    pub limit_weight: f64,
    /// Final scale of the robust loss (pixels).
    #[arg(long, default_value_t = TrackOptions::default().robust_scale_px)]
    pub robust_px: f64,
    /// Weight of the silhouette refinement (outline vertices of the skinned template against
    /// the masks) relative to the keypoints; 0 turns it off (5.5× faster, less accurate).
    #[arg(long, default_value_t = TrackOptions::default().silhouette_weight)]
    pub silhouette_weight: f64,
    /// Rounds of skeleton calibration before the final fit (each fits the frames to the
    /// keypoints, then every bone's length, shared by all frames, with their poses); 0 keeps the
    /// template's bones. Writes `bones.csv` (each joint's offset along its bone).
    #[arg(long, default_value_t = TrackOptions::default().calibration_rounds)]
    pub calibration_rounds: usize,
    /// Frames the calibration fits, evenly spread (0: every frame); the lengths' noise is
    /// shared by every frame, so a long noisy capture gains from more.
    #[arg(long, default_value_t = TrackOptions::default().calibration_frames)]
    pub calibration_frames: usize,
    /// σ, in frames, of a zero-phase Gaussian filter over each clip's tracked motion (0: off);
    /// for video-rate captures, whose neighbouring frames see nearly the same pose with
    /// independent detection noise, not for sparse frames far apart in time.
    #[arg(long, default_value_t = TrackOptions::default().filter_sigma_frames)]
    pub filter_sigma: f64,
    /// The clips the filter runs on (comma-separated names; default every clip): leave out
    /// clips whose frames are far apart in time, such as a synthetic capture's held-out phases.
    #[arg(long, value_delimiter = ',')]
    pub filter_clips: Vec<String>,
    /// Joints whose local translation is fitted per frame (comma-separated names), for rigs
    /// whose animation translates them, such as inverse-kinematics feet parented to the root.
    #[arg(long, value_delimiter = ',')]
    pub translating_joints: Vec<String>,
    /// Weights of the silhouette term's body: `initial` (the capture's, bone heat when it ships
    /// none), `static:FILE` (`trainer train --static`), `skf:FILE` (SkinNet at the bind pose) or
    /// `oracle` (the capture's true weights; a ceiling for experiments).
    #[arg(long, default_value = "initial")]
    pub body_weights: Skinning,
    /// Frame rate recorded with the tracked motion (frames per second); default: the input
    /// motion's, or 30 for a capture without motion.
    #[arg(long)]
    pub fps: Option<f32>,
}

/// The frame rate `trainer track` records when neither `--fps` nor the input's motion gives one.
pub const DEFAULT_TRACK_FPS: f32 = 30.0;

/// The synthetic detector (`trainer track --synthesize`, `trainer synth --keypoints`): the
/// points it sees and how its detections are corrupted.
#[derive(ClapArgs, Debug, Clone, Copy)]
pub struct NoiseArgs {
    /// Synthetic detections: pixel noise (standard deviation per axis).
    #[arg(long, default_value_t = DetectionNoise::REFERENCE.sigma_px)]
    pub noise_px: f64,
    /// Synthetic detections: share dropped (half missing, half below the confidence threshold).
    #[arg(long, default_value_t = DetectionNoise::REFERENCE.drop_rate)]
    pub drop: f64,
    /// Synthetic detections: probability of a left/right swap per view and pair.
    #[arg(long, default_value_t = DetectionNoise::REFERENCE.swap_rate)]
    pub swap: f64,
    /// Synthetic detections: seed.
    #[arg(long, default_value_t = 0)]
    pub keypoint_seed: u64,
    /// Synthetic detections: which points the detector sees.
    #[arg(long, value_enum, default_value_t = LandmarkSet::Default)]
    pub landmarks: LandmarkSet,
}

/// The points a synthetic detector sees.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum LandmarkSet {
    /// OpenPose BODY_25 on the built-in character's joints, otherwise one keypoint per joint.
    Default,
    /// One keypoint per joint and one beside each joint, off its bone, which sees the limbs'
    /// twists.
    JointSides,
    /// The side points moved out to the template's surface (a marker set or a dense detector),
    /// which sees the turns of short bones (head, feet) that a quarter of the bone cannot.
    JointSurface,
    /// Four surface points around every bone instead of one (a marker set's several markers
    /// per segment), which average the noise of each.
    JointRing,
}

/// Writes synthetic keypoints (the landmark map `args.landmarks` of its skeleton) into `capture`.
pub fn synthesize_keypoints(capture: &Capture, args: &NoiseArgs) -> anyhow::Result<()> {
    let noise = DetectionNoise {
        sigma_px: args.noise_px,
        drop_rate: args.drop,
        swap_rate: args.swap,
        seed: args.keypoint_seed,
    };
    let map = match args.landmarks {
        LandmarkSet::Default => default_landmark_map(&capture.skeleton),
        LandmarkSet::JointSides => joint_side_landmark_map(&capture.skeleton),
        LandmarkSet::JointSurface => {
            joint_surface_landmark_map(&capture.skeleton, &capture.template)
        }
        LandmarkSet::JointRing => joint_ring_landmark_map(&capture.skeleton, &capture.template),
    };
    write_synthetic_keypoints(capture, &map, &noise).context("writing synthetic keypoints")?;
    println!(
        "wrote {} detections per image ({}) into {}",
        map.keypoints.len(),
        map.detector,
        capture.dir.display()
    );
    Ok(())
}

/// `bones.csv` of a calibration (one row per joint: its offset in the parent's frame, its
/// length and the bone's bind-pose length, skeleton units), and the joint with the largest
/// offset.
fn bones_csv(
    skeleton: &skinfield_formats::Skeleton,
    offsets: &[glam::DVec3],
) -> (String, (String, f64)) {
    let mut csv = String::from("joint,name,dx,dy,dz,offset,bone_length\n");
    let mut worst = (String::from("none"), 0.0);
    for (j, (name, o)) in skeleton.names().iter().zip(offsets).enumerate() {
        let bone = f64::from(skeleton.bind_local()[j].translation.length());
        let length = o.length();
        csv += &format!(
            "{j},{name},{:.6},{:.6},{:.6},{length:.6},{bone:.6}\n",
            o.x, o.y, o.z
        );
        if length > worst.1 {
            worst = (name.clone(), length);
        }
    }
    (csv, worst)
}

/// Runs `trainer track`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let input = load_capture(&args.capture)
        .with_context(|| format!("loading the capture {}", args.capture.display()))?;
    if args.out.canonicalize().ok() == args.capture.canonicalize().ok() {
        anyhow::bail!("--out must differ from --capture (the input keeps its motion)");
    }
    let options = TrackOptions {
        min_confidence: args.min_confidence,
        smooth_weight: args.smooth_weight,
        limit_weight: args.limit_weight,
        robust_scale_px: args.robust_px,
        silhouette_weight: args.silhouette_weight,
        calibration_rounds: args.calibration_rounds,
        calibration_frames: args.calibration_frames,
        filter_sigma_frames: args.filter_sigma,
        filter_clips: args.filter_clips.clone(),
        translating_joints: args.translating_joints.clone(),
        ..TrackOptions::default()
    };
    // Refused before anything is written (`--synthesize` writes the copy first).
    let fps = args.fps.or(input.motion_fps).unwrap_or(DEFAULT_TRACK_FPS);
    if !(fps.is_finite() && fps > 0.0) {
        anyhow::bail!("--fps {fps} is not a positive frame rate");
    }
    temporal_filter(&options, &input.manifest.clips).context("--filter-sigma / --filter-clips")?;
    // Synthetic detections go into the copy, which is then tracked: the input stays as it was.
    let capture = if args.synthesize {
        let skip: Vec<_> = input
            .manifest
            .keypoints
            .iter()
            .map(|k| input.dir.join(k))
            .collect();
        skinfield_trainer::files::copy_tree(&input.dir, &args.out, &skip)?;
        let reload = || {
            load_capture(&args.out)
                .with_context(|| format!("loading the copy {}", args.out.display()))
        };
        synthesize_keypoints(&reload()?, &args.noise)?;
        reload()?
    } else {
        input
    };
    let body_skin = match &args.body_weights {
        Skinning::Initial => None,
        other => Some(
            PreparedSkinning::new(&capture, other)
                .and_then(|s| s.bind_skin(&capture))
                .context("--body-weights")?,
        ),
    };
    let bar = indicatif::ProgressBar::new(capture.frame_count() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("track {bar:30} {pos}/{len} {elapsed_precise}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let start = std::time::Instant::now();
    let tracked = track_capture(&capture, &options, body_skin.as_ref(), |_| bar.inc(1))
        .with_context(|| format!("tracking {}", args.capture.display()))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();

    // A capture without motion gets one; one with motion keeps its path.
    let mut manifest = capture.manifest.clone();
    let motion_rel = manifest
        .motion
        .get_or_insert_with(|| "motion.json".into())
        .clone();
    if !args.synthesize {
        skinfield_trainer::files::copy_tree(
            &capture.dir,
            &args.out,
            &[
                capture.dir.join(MANIFEST_FILE),
                capture.dir.join(&motion_rel),
            ],
        )?;
    }
    let writer = CaptureWriter::new(&args.out, manifest)?;
    writer.write_motion(&tracked.poses, fps)?;
    writer.finish()?;

    // Against the input's motion, when it has one (a synthetic capture's ground truth).
    let errors = if capture.has_motion() {
        Some((
            mpjpe(&capture.skeleton, &tracked.poses, &capture.poses)?,
            mean_turn_error_deg(&capture.skeleton, &tracked.poses, &capture.poses)?,
        ))
    } else {
        None
    };
    let csv_path = args.out.join("track.csv");
    let mut csv = String::from(
        "frame,detections,inliers,far,rms_inlier_px,median_px,limit_excess_rad,iterations,mpjpe_vs_input,turn_deg_vs_input\n",
    );
    for (f, fit) in tracked.fits.iter().enumerate() {
        let r = &fit.report;
        let e = errors
            .as_ref()
            .map(|(e, t)| format!("{:.6},{:.3}", e[f], t[f]))
            .unwrap_or_else(|| ",".into());
        csv += &format!(
            "{f},{},{},{},{:.4},{:.4},{:.5},{},{e}\n",
            r.detections,
            r.inliers,
            r.far,
            r.rms_inlier_px,
            r.median_px,
            r.limit_excess,
            r.iterations,
        );
    }
    skinfield_formats::skf::write_atomic(&csv_path, csv.as_bytes())
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let mut out = std::io::stdout().lock();
    if let Some(calibration) = &tracked.calibration {
        let bones_path = args.out.join("bones.csv");
        let (csv, worst) = bones_csv(&capture.skeleton, &calibration.offsets);
        skinfield_formats::skf::write_atomic(&bones_path, csv.as_bytes())
            .with_context(|| format!("writing {}", bones_path.display()))?;
        writeln!(
            out,
            "skeleton calibrated on {} frames in {:.1} s: keypoint RMS {:.3} → {:.3} px; \
             largest bone offset {:.3} skeleton units ({}); per joint: {}",
            calibration.frames,
            calibration.seconds,
            calibration.rms_before_px,
            calibration.rms_after_px,
            worst.1,
            worst.0,
            bones_path.display()
        )?;
    }
    writeln!(
        out,
        "tracked {} frames in {seconds:.1} s → {} at {fps} fps (per-frame residuals of the fit: \
         {})",
        tracked.poses.len(),
        args.out.display(),
        csv_path.display()
    )?;
    if options.filter_sigma_frames > 0.0 {
        let clips = if options.filter_clips.is_empty() {
            "every clip".to_owned()
        } else {
            options.filter_clips.join(", ")
        };
        writeln!(
            out,
            "then filtered over time: a zero-phase Gaussian of σ = {} frames on {clips}",
            options.filter_sigma_frames
        )?;
    }
    if let Some((errors, turns)) = &errors {
        let mean = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
        let worst = errors.iter().copied().fold(0.0, f64::max);
        let turn = turns.iter().sum::<f64>() / turns.len().max(1) as f64;
        writeln!(
            out,
            "mean per-joint position error against the input's motion: {mean:.3} (worst frame \
             {worst:.3}) skeleton units; mean joint turn error {turn:.2}°"
        )?;
    }
    writeln!(
        out,
        "train on it with `trainer train --capture {} --refine-poses …`: the tracked poses are \
         corrected together with the weights",
        args.out.display()
    )?;
    Ok(())
}
