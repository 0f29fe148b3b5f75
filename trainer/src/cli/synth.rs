//! `trainer synth --out DIR`: writes the built-in synthetic capture, or with
//! `--character FILE --train-clips A,B --test-clips C [--motion OTHER.glb]` a capture of a
//! rigged glTF character.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use skinfield_formats::capture::ImageFormat;
use skinfield_trainer::synth::{
    GltfSource, JointMap, SynthConfig, TestMotions, synthesize, synthesize_gltf,
};

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
    /// Template vertex count after simplification (about; built-in character only).
    #[arg(long, default_value_t = SynthConfig::default().target_vertices)]
    pub vertices: usize,
    /// Write the colour images as linear float EXR instead of 8-bit sRGB PNG.
    #[arg(long)]
    pub exr: bool,
    /// Test poses: `novel` (the test clips, beyond the training ranges) or `held-out-phases`
    /// (the training clips between their training frames; with `--character`, name no
    /// `--test-clips`).
    #[arg(long, value_enum, default_value = "novel")]
    pub test_motions: TestMotionsArg,
    /// A rigged glTF/GLB character instead of the built-in one, or a MakeHuman folder
    /// (`base.obj`, `default.mhskel`, `default_weights.mhw`; clips from `--motion`).
    #[arg(long)]
    pub character: Option<PathBuf>,
    /// A glTF/GLB whose clips drive the character (joints matched by name, or through
    /// `--joint-map`), or BVH motion: a `.bvh` file or a folder of them, one clip per file
    /// named by its stem (with `--joint-map`).
    #[arg(long, requires = "character")]
    pub motion: Option<PathBuf>,
    /// Retarget the motion file's clips through this joint map (JSON: `{"joints":
    /// {"character joint": "motion joint", …}}`), for a motion authored on another rig.
    #[arg(long, requires = "motion")]
    pub joint_map: Option<PathBuf>,
    /// Play the retargeted motion in place: the hips keep their height changes but not their
    /// travel across the floor (clips that walk across a room).
    #[arg(long, requires = "joint_map")]
    pub in_place: bool,
    /// Training clip names (with `--character`).
    #[arg(long, value_delimiter = ',', requires = "character")]
    pub train_clips: Vec<String>,
    /// Test clip names (with `--character`), disjoint from the training clips; none with
    /// `--test-motions held-out-phases`.
    #[arg(long, value_delimiter = ',', requires = "character")]
    pub test_clips: Vec<String>,
    /// Share of the part-label images' boundary pixels that take a neighbouring part's label
    /// (what a human-parsing network gets wrong), 0 to 1.
    #[arg(long, default_value_t = 0.0)]
    pub label_noise: f32,
    /// Pixels by which every mask's outline is moved outwards (negative: inwards), as a
    /// segmentation that over- or under-segments by a constant margin; the images and the
    /// ground truth stay exact.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub mask_offset: f32,
    /// Also write 2D keypoint detections (OpenPose JSON) projected from the motion, for
    /// `trainer track`.
    #[arg(long)]
    pub keypoints: bool,
    /// How the keypoints are corrupted.
    #[command(flatten)]
    pub noise: super::track::NoiseArgs,
}

/// `--test-motions` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum TestMotionsArg {
    /// The test clips, beyond the training ranges.
    Novel,
    /// The training clips at phases between their training frames.
    HeldOutPhases,
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
        image_format: if args.exr {
            ImageFormat::Exr
        } else {
            ImageFormat::Png
        },
        test_motions: match args.test_motions {
            TestMotionsArg::Novel => TestMotions::Novel,
            TestMotionsArg::HeldOutPhases => TestMotions::HeldOutPhases,
        },
        label_noise: args.label_noise,
        mask_offset_px: args.mask_offset,
        seed: args.seed,
        ..SynthConfig::default()
    };
    let s = match &args.character {
        None => synthesize(&args.out, &config),
        Some(character) => {
            let source = GltfSource {
                character: character.clone(),
                motion: args.motion.clone(),
                joint_map: args
                    .joint_map
                    .as_deref()
                    .map(JointMap::read)
                    .transpose()
                    .context("reading --joint-map")?,
                in_place: args.in_place,
                train_clips: args.train_clips.clone(),
                test_clips: args.test_clips.clone(),
            };
            synthesize_gltf(&args.out, &config, &source)
        }
    }
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
    if args.keypoints {
        let capture = skinfield_formats::capture::load_capture(&args.out)
            .with_context(|| format!("loading the capture {}", args.out.display()))?;
        super::track::synthesize_keypoints(&capture, &args.noise)?;
    }
    Ok(())
}
