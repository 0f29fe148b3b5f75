//! `trainer render`: pictures of a posed mesh — over a captured image (`--kind overlay`, paper
//! Fig. 3), coloured by per-vertex M2S error (`--kind error`, paper Fig. 5), or by the learned
//! appearance (`--kind albedo|shading|appearance`, from the nets stored in the `.skf`) — as PNG.
//! With several `--template` files (e.g. from `trainer resample`) the pictures of each, posed in
//! the same frame, are put side by side in one PNG.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args as ClapArgs, ValueEnum};
use glam::Vec3;
use skinfield_formats::Template;
use skinfield_formats::capture::{load_capture, write_image_png};
use skinfield_formats::pose_features;
use skinfield_formats::skf::{SkfView, read_skf_file};
use skinfield_trainer::appearance::{Appearance, AppearanceKind, appearance_image};
use skinfield_trainer::eval::render::{error_image, overlay};
use skinfield_trainer::eval::{PreparedSkinning, Skinning, load_template, per_vertex_m2s};

/// Which picture to draw.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Kind {
    /// The posed mesh over the captured image of the frame.
    Overlay,
    /// The posed mesh coloured by per-vertex distance to the ground truth (test frames only).
    Error,
    /// The learned albedo (needs `--weights skf:FILE` with the appearance nets).
    Albedo,
    /// ShadowNet's shading multiplier, as grey (same file).
    Shading,
    /// Albedo × shading, the learned appearance (same file).
    Appearance,
}

/// Arguments of `trainer render`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The capture folder.
    #[arg(long)]
    pub capture: PathBuf,
    /// Skinning that poses the template (as in `trainer eval`).
    #[arg(long, default_value = "oracle")]
    pub weights: Skinning,
    /// Picture to draw.
    #[arg(long, value_enum, default_value_t = Kind::Overlay)]
    pub kind: Kind,
    /// Frame index (default: the first test frame).
    #[arg(long)]
    pub frame: Option<usize>,
    /// Camera index in the capture's rig.
    #[arg(long, default_value_t = 0)]
    pub camera: usize,
    /// Error mapped to red in `--kind error`, centimetres.
    #[arg(long, default_value_t = 2.0)]
    pub max_error_cm: f32,
    /// Pose these glTF templates instead of the capture's (repeatable; side by side, in order).
    #[arg(long = "template")]
    pub templates: Vec<PathBuf>,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `trainer render`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let capture = load_capture(&args.capture)
        .with_context(|| format!("loading the capture {}", args.capture.display()))?;
    capture.require_motion()?;
    let frame = match args.frame {
        Some(f) => f,
        None => *capture
            .test_frames
            .first()
            .with_context(|| format!("{}: no test frames", args.capture.display()))?,
    };
    let camera = capture.rig.cameras.get(args.camera).with_context(|| {
        format!(
            "--camera {}: the rig has {} cameras",
            args.camera,
            capture.rig.cameras.len()
        )
    })?;
    let skinning = PreparedSkinning::new(&capture, &args.weights)
        .with_context(|| format!("loading `{}`", args.weights.method_name()))?;
    let templates = if args.templates.is_empty() {
        vec![capture.template.clone()]
    } else {
        args.templates
            .iter()
            .map(|p| load_template(p))
            .collect::<Result<Vec<_>, _>>()?
    };
    let panels = templates
        .iter()
        .map(|t| panel(&args, &capture, camera, &skinning, t, frame))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let (w, h) = (camera.width as usize, camera.height as usize);
    // Side by side: row y of the result is row y of every panel in turn.
    let rgb: Vec<Vec3> = (0..h)
        .flat_map(|y| panels.iter().flat_map(move |p| &p[y * w..(y + 1) * w]))
        .copied()
        .collect();
    let width = u32::try_from(w * panels.len()).context("--template: picture too wide")?;
    write_image_png(&args.out, width, camera.height, &rgb)?;
    println!("wrote {}", args.out.display());
    Ok(())
}

/// One picture of `template` posed by `skinning` in `frame`.
fn panel(
    args: &Args,
    capture: &skinfield_formats::capture::Capture,
    camera: &skinfield_formats::Camera,
    skinning: &PreparedSkinning,
    template: &Template,
    frame: usize,
) -> anyhow::Result<Vec<Vec3>> {
    let posed = skinning.pose_rest(capture, &template.positions, frame)?;
    let triangles = &template.triangles;
    Ok(match args.kind {
        Kind::Overlay => {
            let image = capture.load_image(args.camera, frame)?;
            overlay(camera, &image.rgb, &posed, triangles)?
        }
        Kind::Error => {
            let error = per_vertex_m2s(capture, frame, &posed)?;
            let mean_cm = 100.0 * error.iter().map(|&e| f64::from(e)).sum::<f64>()
                / error.len().max(1) as f64;
            println!(
                "frame {frame}, {} vertices: mean per-vertex distance to the ground truth {mean_cm:.3} cm",
                template.vertex_count()
            );
            error_image(
                camera,
                &posed,
                triangles,
                &error,
                args.max_error_cm / 100.0,
                Vec3::ONE,
            )?
        }
        Kind::Albedo | Kind::Shading | Kind::Appearance => {
            let Skinning::Skf(path) = &args.weights else {
                anyhow::bail!("--kind {:?} needs --weights skf:FILE", args.kind);
            };
            let bytes = read_skf_file(path)?;
            let view = SkfView::parse(&bytes).with_context(|| path.display().to_string())?;
            let appearance = Appearance::from_skf(&view, path)?;
            let mut features = vec![0.0; 3 * capture.skeleton.len()];
            pose_features(
                &capture.skeleton,
                &capture.poses[frame],
                capture.up_axis,
                &mut features,
            )?;
            let kind = match args.kind {
                Kind::Albedo => AppearanceKind::Albedo,
                Kind::Shading => AppearanceKind::Shading,
                _ => AppearanceKind::Colour,
            };
            appearance_image(
                &appearance,
                camera,
                &template.positions,
                &posed,
                triangles,
                &features,
                kind,
                Vec3::ZERO,
            )?
        }
    })
}
