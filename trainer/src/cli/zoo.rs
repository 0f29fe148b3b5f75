//! `trainer zoo --out DIR [--quick]`: the character zoo. For every shared character with clips
//! and the built-in one: synthesise a capture, compute bone-heat initial weights, train SkinNet
//! and the static baseline with the functions `trainer demo` uses, score initial / static /
//! ours / oracle on the held-out test frames, and write one table (`DIR/zoo.md`, `DIR/zoo.json`,
//! and with `--doc FILE` the Markdown there too, e.g. `docs/zoo.md`).
//!
//! The characters and their clip splits are fixed in [`ZOO`] and named in the table. The
//! training budget is the trainer's defaults (or `--config`), overridden by `--warm-start`,
//! `--iterations`, `--static-iterations`; `--quick` makes each of them 30 unless given (and
//! stage 4 at most 3 iterations).
//! A character that fails (a missing file, a training run the trainer refuses) gets a row
//! saying why; the command then exits with an error after writing the tables.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use serde::Serialize;
use skinfield_formats::capture::load_capture;
use skinfield_trainer::eval::{
    EvalOptions, EvalRow, Skinning, WorstVertexCheck, evaluate, off_surface_check,
    worst_vertex_check,
};
use skinfield_trainer::synth::{
    GltfSource, JointMap, SynthConfig, SynthSummary, TestMotions, synthesize, synthesize_gltf,
};
use skinfield_trainer::train::data::{DataOptions, initial_weights};
use skinfield_trainer::train::{TrainConfig, WarmStatus};

use super::train::{train_skinnet, train_static};

mod table;

use table::write_tables;

/// How a zoo character is tested.
#[derive(Clone, Copy, Debug)]
pub enum TestSplit {
    /// The built-in motion library: five training clips, three novel test clips.
    BuiltIn,
    /// Named clips never trained on.
    Clips(&'static [&'static str]),
    /// The training clips halfway between their training frames.
    HeldOutPhases,
}

/// One character of the zoo.
#[derive(Clone, Copy, Debug)]
pub struct ZooCharacter {
    /// Short name (`--characters`).
    pub name: &'static str,
    /// What it tests.
    pub about: &'static str,
    /// The glTF file under the shared data folder; `None`: the built-in character.
    pub file: Option<&'static str>,
    /// Another file under the shared data folder whose clips drive the character, retargeted
    /// through `joint_map` (a character shipped without animations); `None`: its own clips.
    pub motion: Option<&'static str>,
    /// The joint map from `motion`'s rig to the character's (the JSON of `trainer synth
    /// --joint-map`), built into the program.
    pub joint_map: Option<(&'static str, &'static str)>,
    /// Play the retargeted motion in place (clips that walk across a room).
    pub in_place: bool,
    /// Training clips (empty for the built-in character, whose library fixes them).
    pub train: &'static [&'static str],
    /// Test frames.
    pub test: TestSplit,
}

/// The zoo: every shared character and the built-in one. Splits chosen from the clips each
/// file has (`trainer inspect FILE`): training on ordinary locomotion and gestures, testing on
/// motions never trained on where the file has them. The Female_Peasant has no clips: the
/// Witch's drive it, retargeted from its rig (Quaternius names) to the peasant's (Unreal
/// mannequin names) with the same split as the Witch's. The MakeHuman body has none either:
/// CMU motion capture drives it (a walk with a crouch and jumping jacks for training, hops for
/// testing), in place, since the walk and the hops cross 3 m.
pub static ZOO: [ZooCharacter; 7] = [
    ZooCharacter {
        name: "builtin",
        about: "procedural clothed human, skirt and sleeves, DQS + bulges + skirt push-out",
        file: None,
        motion: None,
        joint_map: None,
        in_place: false,
        train: &[],
        test: TestSplit::BuiltIn,
    },
    ZooCharacter {
        name: "cesiumman",
        about: "one walk clip: tested on held-out phases of it",
        file: Some("khronos-cesiumman/CesiumMan.glb"),
        motion: None,
        joint_map: None,
        in_place: false,
        train: &["animation_0"],
        test: TestSplit::HeldOutPhases,
    },
    ZooCharacter {
        name: "fox",
        about: "quadruped, 155 × 79 units",
        file: Some("khronos-fox/Fox.glb"),
        motion: None,
        joint_map: None,
        in_place: false,
        train: &["Survey", "Walk"],
        test: TestSplit::Clips(&["Run"]),
    },
    ZooCharacter {
        name: "robot",
        about: "rigid robot parts + two skinned hands, mesh scaled ×100 by its armature",
        file: Some("threejs-robotexpressive/RobotExpressive.glb"),
        motion: None,
        joint_map: None,
        in_place: false,
        train: &["Idle", "Walking", "Running", "Dance", "Punch"],
        test: TestSplit::Clips(&["Wave", "ThumbsUp", "Jump"]),
    },
    ZooCharacter {
        name: "witch",
        about: "skirt, 62 joints, unwelded",
        file: Some("quaternius-witch/Witch.gltf"),
        motion: None,
        joint_map: None,
        in_place: false,
        train: &["Idle", "Walk", "Run", "Punch_Left", "Kick_Left"],
        test: TestSplit::Clips(&["Kick_Right", "Punch_Right", "Wave"]),
    },
    ZooCharacter {
        name: "peasant",
        about: "long skirt, 65 joints, no clips of its own: the Witch's, retargeted",
        file: Some("quaternius-female-peasant/Female_Peasant.gltf"),
        motion: Some("quaternius-witch/Witch.gltf"),
        joint_map: Some((
            "trainer/joint-maps/quaternius-to-ue-mannequin.json",
            include_str!("../../joint-maps/quaternius-to-ue-mannequin.json"),
        )),
        in_place: false,
        train: &["Idle", "Walk", "Run", "Punch_Left", "Kick_Left"],
        test: TestSplit::Clips(&["Kick_Right", "Punch_Right", "Wave"]),
    },
    ZooCharacter {
        name: "makehuman",
        about: "MakeHuman body, 163 joints (fingers, toes, face); CMU motion capture (BVH), \
                retargeted and played in place",
        file: Some("makehuman-hm08"),
        motion: Some("mocap-cmu"),
        joint_map: Some((
            "trainer/joint-maps/cmu-bvh-to-makehuman.json",
            include_str!("../../joint-maps/cmu-bvh-to-makehuman.json"),
        )),
        in_place: true,
        train: &["131_01", "jumping_jacks"],
        test: TestSplit::Clips(&["131_03"]),
    },
];

/// Clip names of the built-in library's split, for the table.
const BUILT_IN_TRAIN: &str = "walk, squat, arm_raise_twist, lunge_left, kick_low";
const BUILT_IN_TEST: &str = "high_kick, turn_twist, lunge_right_deep";

/// Arguments of `trainer zoo`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Output folder (one sub-folder per character, `zoo.md`, `zoo.json`).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the Markdown table here (e.g. `docs/zoo.md`; the JSON beside it).
    #[arg(long)]
    pub doc: Option<PathBuf>,
    /// The shared data folder (default: `$SKINFIELD_SHARED_DATA`, else `../shared/data`).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Only these characters (comma-separated names: builtin, cesiumman, fox, robot, witch,
    /// peasant, makehuman).
    #[arg(long, value_delimiter = ',')]
    pub characters: Vec<String>,
    /// A small budget for trying the pipeline: 30 iterations each unless given.
    #[arg(long)]
    pub quick: bool,
    /// Training configuration (JSON, `TrainConfig` fields; default: the trainer's defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// SkinNet warm-start iterations (default: the configuration's).
    #[arg(long)]
    pub warm_start: Option<u64>,
    /// SkinNet image-loss iterations (default: the configuration's).
    #[arg(long)]
    pub iterations: Option<u64>,
    /// Static-baseline iterations (default: the configuration's image iterations).
    #[arg(long)]
    pub static_iterations: Option<u64>,
    /// Seed of the captures and of training.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Cameras per capture.
    #[arg(long, default_value_t = SynthConfig::default().cameras)]
    pub cameras: usize,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = SynthConfig::default().width)]
    pub resolution: u32,
    /// Frames per training clip.
    #[arg(long, default_value_t = SynthConfig::default().train_frames_per_clip)]
    pub train_frames: usize,
    /// Frames per test clip (per training clip for held-out phases).
    #[arg(long, default_value_t = SynthConfig::default().test_frames_per_clip)]
    pub test_frames: usize,
    /// Surface samples per frame in the evaluation.
    #[arg(long, default_value_t = EvalOptions::default().samples)]
    pub samples: usize,
    /// Hide the progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// The training budget every character gets.
#[derive(Clone, Debug, Serialize)]
pub struct Budget {
    /// SkinNet warm-start iterations.
    pub warm_start: u64,
    /// SkinNet image-loss iterations.
    pub iterations: u64,
    /// SkinNets trained per character, their mean distilled into the one scored (the
    /// configuration's `ensemble.members`).
    pub members: usize,
    /// Stage 4 after stage 1, as [`skinfield_trainer::train::stages::StageConfig::refine_summary`]
    /// words it (`None`: no stage 4).
    pub refine: Option<String>,
    /// Static-baseline iterations.
    pub static_iterations: u64,
    /// SkinNet training-template vertices.
    pub train_vertices: usize,
    /// Seed.
    pub seed: u64,
    /// Capture: cameras, resolution, frames per training / test clip.
    pub cameras: usize,
    /// Image side in pixels.
    pub resolution: u32,
    /// Frames per training clip.
    pub train_frames: usize,
    /// Frames per test clip.
    pub test_frames: usize,
    /// The `--config` file and its JSON (overrides of the trainer's defaults), if one was given.
    pub config: Option<(String, serde_json::Value)>,
}

/// Seconds spent per step on one character.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Seconds {
    /// Synthesising the capture.
    pub synth: f64,
    /// Bone heat.
    pub initial: f64,
    /// SkinNet (data, loops, export).
    pub skinnet: f64,
    /// Static baseline.
    pub static_weights: f64,
    /// Evaluation of the four rows.
    pub eval: f64,
}

/// The zoo's result for one character.
#[derive(Clone, Debug, Serialize)]
pub struct ZooResult {
    /// Short name.
    pub name: String,
    /// The file (relative to the shared data folder), or `built-in`.
    pub file: String,
    /// What it tests.
    pub about: String,
    /// Skeleton joints.
    pub joints: usize,
    /// Template vertices.
    pub vertices: usize,
    /// Rest-pose bounding-box diagonal (model units).
    pub size: f64,
    /// Training clips.
    pub train_clips: String,
    /// Test split, named.
    pub test: String,
    /// Training / test frames.
    pub frames: (usize, usize),
    /// initial / static / ours / oracle.
    pub rows: Vec<EvalRow>,
    /// How SkinNet's warm start ended (with an ensemble, the distillation), when it ran.
    pub warm_start: Option<WarmStatus>,
    /// Whether ours < static < initial in Chamfer distance.
    pub ordering_holds: Option<bool>,
    /// Ours' vertex furthest from the true surface against bone heat's, frame by frame.
    pub off_surface_ours: Option<WorstVertexCheck>,
    /// The static baseline's vertex furthest from the true surface against bone heat's.
    pub off_surface_static: Option<WorstVertexCheck>,
    /// Ours' worst vertex-to-vertex distance against bone heat's, frame by frame.
    pub worst_vertex_ours: Option<WorstVertexCheck>,
    /// The static baseline's worst vertex-to-vertex distance against bone heat's.
    pub worst_vertex_static: Option<WorstVertexCheck>,
    /// Seconds per step.
    pub seconds: Seconds,
    /// Why the character has no (or incomplete) rows.
    pub error: Option<String>,
}

/// Runs `trainer zoo`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let total = Instant::now();
    let chosen: Vec<&ZooCharacter> = if args.characters.is_empty() {
        ZOO.iter().collect()
    } else {
        args.characters
            .iter()
            .map(|n| {
                ZOO.iter().find(|c| c.name == n).with_context(|| {
                    format!(
                        "--characters: no character `{n}` (the zoo has: {})",
                        ZOO.map(|c| c.name).join(", ")
                    )
                })
            })
            .collect::<anyhow::Result<_>>()?
    };
    let data = args
        .data
        .clone()
        .or_else(|| std::env::var_os("SKINFIELD_SHARED_DATA").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from("../shared/data"));
    let (mut config, config_json) = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let json: serde_json::Value = serde_json::from_str(&text)
                .with_context(|| format!("{}: not JSON", path.display()))?;
            (
                TrainConfig::parse(&text, path)?,
                Some((path.display().to_string(), json)),
            )
        }
        None => (TrainConfig::default(), None),
    };
    config.seed = args.seed;
    let quick =
        |given: Option<u64>, default: u64| given.unwrap_or(if args.quick { 30 } else { default });
    config.warm_start_iterations = quick(args.warm_start, config.warm_start_iterations);
    config.iterations = quick(args.iterations, config.iterations);
    if args.quick {
        // A smoke run: stage 4 (the default's full-resolution finish) only shows that it runs.
        config.stages.refine_iterations = config.stages.refine_iterations.min(3);
    }
    let budget = Budget {
        warm_start: config.warm_start_iterations,
        iterations: config.iterations,
        members: config.ensemble.members,
        refine: config.stages.refine_summary(),
        static_iterations: quick(args.static_iterations, config.iterations),
        train_vertices: DataOptions::default().train_vertices,
        seed: args.seed,
        cameras: args.cameras,
        resolution: args.resolution,
        train_frames: args.train_frames,
        test_frames: args.test_frames,
        config: config_json,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let command = command_line(&args);
    let mut results = Vec::new();
    for character in chosen {
        println!("== {} ==", character.name);
        let result = run_character(character, &data, &args, &config, &budget);
        if let Some(e) = &result.error {
            eprintln!("{}: {e}", character.name);
        }
        results.push(result);
        // Written after every character, so an interrupted run keeps what it measured.
        write_tables(
            &args,
            &command,
            &budget,
            &results,
            total.elapsed().as_secs_f64(),
        )?;
    }
    let failed: Vec<String> = results
        .iter()
        .filter_map(|r| r.error.as_ref().map(|e| format!("{}: {e}", r.name)))
        .collect();
    println!(
        "zoo: {} characters in {:.1} s; table in {}",
        results.len(),
        total.elapsed().as_secs_f64(),
        args.out.join("zoo.md").display()
    );
    if !failed.is_empty() {
        bail!(
            "{} of {} characters failed ({})",
            failed.len(),
            results.len(),
            failed.join("; ")
        );
    }
    Ok(())
}

/// The command as typed, for the table's header.
fn command_line(args: &Args) -> String {
    let mut s = String::from("trainer zoo");
    let mut flag = |name: &str, value: Option<String>| {
        let _ = match value {
            Some(v) => write!(s, " --{name} {v}"),
            None => write!(s, " --{name}"),
        };
    };
    flag("out", Some(args.out.display().to_string()));
    if let Some(doc) = &args.doc {
        flag("doc", Some(doc.display().to_string()));
    }
    if let Some(data) = &args.data {
        flag("data", Some(data.display().to_string()));
    }
    if args.quick {
        flag("quick", None);
    }
    if !args.characters.is_empty() {
        flag("characters", Some(args.characters.join(",")));
    }
    if let Some(c) = &args.config {
        flag("config", Some(c.display().to_string()));
    }
    for (name, v) in [
        ("warm-start", args.warm_start),
        ("iterations", args.iterations),
        ("static-iterations", args.static_iterations),
    ] {
        if let Some(v) = v {
            flag(name, Some(v.to_string()));
        }
    }
    let defaults = SynthConfig::default();
    if args.seed != 0 {
        flag("seed", Some(args.seed.to_string()));
    }
    if args.cameras != defaults.cameras {
        flag("cameras", Some(args.cameras.to_string()));
    }
    if args.resolution != defaults.width {
        flag("resolution", Some(args.resolution.to_string()));
    }
    if args.train_frames != defaults.train_frames_per_clip {
        flag("train-frames", Some(args.train_frames.to_string()));
    }
    if args.test_frames != defaults.test_frames_per_clip {
        flag("test-frames", Some(args.test_frames.to_string()));
    }
    if args.samples != EvalOptions::default().samples {
        flag("samples", Some(args.samples.to_string()));
    }
    s
}

fn run_character(
    character: &ZooCharacter,
    data: &Path,
    args: &Args,
    config: &TrainConfig,
    budget: &Budget,
) -> ZooResult {
    let (train_clips, test) = match character.test {
        TestSplit::BuiltIn => (
            BUILT_IN_TRAIN.to_string(),
            format!("novel: {BUILT_IN_TEST}"),
        ),
        TestSplit::Clips(clips) => (
            character.train.join(", "),
            format!("novel: {}", clips.join(", ")),
        ),
        TestSplit::HeldOutPhases => (
            character.train.join(", "),
            "held-out phases of the training clip".to_string(),
        ),
    };
    let train_clips = match character.motion {
        Some(m) => format!("{train_clips} ({m}'s, retargeted)"),
        None => train_clips,
    };
    let mut result = ZooResult {
        name: character.name.into(),
        file: character.file.unwrap_or("built-in").into(),
        about: character.about.into(),
        joints: 0,
        vertices: 0,
        size: 0.0,
        train_clips,
        test,
        frames: (0, 0),
        rows: Vec::new(),
        warm_start: None,
        ordering_holds: None,
        off_surface_ours: None,
        off_surface_static: None,
        worst_vertex_ours: None,
        worst_vertex_static: None,
        seconds: Seconds::default(),
        error: None,
    };
    if let Err(e) = fill_character(&mut result, character, data, args, config, budget) {
        result.error = Some(format!("{e:#}"));
    }
    result
}

fn fill_character(
    result: &mut ZooResult,
    character: &ZooCharacter,
    data: &Path,
    args: &Args,
    config: &TrainConfig,
    budget: &Budget,
) -> anyhow::Result<()> {
    let dir = args.out.join(character.name);
    let capture_dir = dir.join("capture");
    let synth = SynthConfig {
        seed: args.seed,
        cameras: args.cameras,
        width: args.resolution,
        height: args.resolution,
        train_frames_per_clip: args.train_frames,
        test_frames_per_clip: args.test_frames,
        test_motions: match character.test {
            TestSplit::HeldOutPhases => TestMotions::HeldOutPhases,
            _ => TestMotions::Novel,
        },
        ..SynthConfig::default()
    };
    let t = Instant::now();
    let summary: SynthSummary = match (character.file, character.test) {
        (None, _) => synthesize(&capture_dir, &synth)?,
        (Some(file), test) => {
            let path = data.join(file);
            if !path.exists() {
                bail!(
                    "{} not found (set --data or SKINFIELD_SHARED_DATA)",
                    path.display()
                );
            }
            let source = GltfSource {
                character: path,
                motion: character.motion.map(|m| data.join(m)),
                joint_map: character
                    .joint_map
                    .map(|(origin, json)| JointMap::parse(origin.into(), json))
                    .transpose()?,
                in_place: character.in_place,
                train_clips: character.train.iter().map(|c| c.to_string()).collect(),
                test_clips: match test {
                    TestSplit::Clips(c) => c.iter().map(|c| c.to_string()).collect(),
                    _ => Vec::new(),
                },
            };
            synthesize_gltf(&capture_dir, &synth, &source)?
        }
    };
    result.seconds.synth = t.elapsed().as_secs_f64();
    result.joints = summary.joints;
    result.vertices = summary.vertices;
    result.frames = (summary.train_frames, summary.test_frames);
    let capture = load_capture(&capture_dir)?;
    result.size = skinfield_trainer::eval::character_size(&capture.template);
    println!(
        "capture: {} vertices, {} joints, {} train / {} test frames ({:.1} s)",
        summary.vertices,
        summary.joints,
        summary.train_frames,
        summary.test_frames,
        result.seconds.synth
    );

    let t = Instant::now();
    let initial = initial_weights(&capture)?;
    result.seconds.initial = t.elapsed().as_secs_f64();
    let options = EvalOptions {
        samples: args.samples,
        seed: 0,
    };
    let eval = |s: &Skinning| {
        evaluate(&capture, s, &options).with_context(|| format!("evaluating `{}`", s.method_name()))
    };
    let t = Instant::now();
    let mut rows = vec![eval(&Skinning::Initial)?];
    let mut eval_seconds = t.elapsed().as_secs_f64();

    let static_file = dir.join("static_weights.json");
    let t = Instant::now();
    let static_config = TrainConfig {
        iterations: budget.static_iterations,
        ..config.clone()
    };
    train_static(
        &capture,
        &initial,
        static_config,
        &dir.join("train-static"),
        &static_file,
        false,
        !args.quiet,
    )
    .context("training the static baseline")?;
    result.seconds.static_weights = t.elapsed().as_secs_f64();
    let t = Instant::now();
    rows.push(eval(&Skinning::Static(static_file))?);
    eval_seconds += t.elapsed().as_secs_f64();

    let model = dir.join("model.skf");
    let t = Instant::now();
    let skinnet = train_skinnet(
        &capture,
        &initial,
        config.clone(),
        &DataOptions::default(),
        &dir.join("train-skinnet"),
        &model,
        false,
        !args.quiet,
    )
    .context("training SkinNet");
    result.seconds.skinnet = t.elapsed().as_secs_f64();
    let oracle_seconds = Instant::now();
    let oracle = eval(&Skinning::Oracle)?;
    eval_seconds += oracle_seconds.elapsed().as_secs_f64();
    let skinnet = match skinnet {
        Ok(run) => run,
        Err(e) => {
            rows.push(oracle);
            result.rows = rows;
            result.seconds.eval = eval_seconds;
            return Err(e);
        }
    };
    result.warm_start = Some(skinnet.warm_start);
    let t = Instant::now();
    rows.push(eval(&Skinning::Skf(model))?);
    rows.push(oracle);
    result.seconds.eval = eval_seconds + t.elapsed().as_secs_f64();
    let (initial_row, static_row, ours) = (&rows[0], &rows[1], &rows[2]);
    result.ordering_holds = Some(
        ours.chamfer_cm < static_row.chamfer_cm && static_row.chamfer_cm < initial_row.chamfer_cm,
    );
    result.off_surface_ours = off_surface_check(ours, initial_row);
    result.off_surface_static = off_surface_check(static_row, initial_row);
    result.worst_vertex_ours = worst_vertex_check(ours, initial_row);
    result.worst_vertex_static = worst_vertex_check(static_row, initial_row);
    result.rows = rows;
    Ok(())
}
