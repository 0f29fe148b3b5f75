//! `trainer template --capture DIR --out DIR2 [--frame F] [--resolution R] [--vertices N]
//! [--cameras K]`: the canonical template reconstructed from one frame's masks, images and
//! label images ([`skinfield_trainer::template`]), with bone heat on the new mesh, written as a
//! copy of the capture (so `trainer train` runs on it unchanged) plus `template.glb` (the mesh
//! skinned with bone heat, for `trainer eval --template` and DCC tools) and
//! `template_report.json`.
//!
//! When the capture has ground truth, the reconstruction is also scored against the true
//! surface of its frame and the true part labels; the copy has no `evaluation` entry (its
//! ground-truth meshes belong to the original template): score models trained on it with
//! `trainer eval --capture DIR --weights skf:M --template DIR2/template.glb`.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args as ClapArgs;
use serde::Serialize;
use skinfield_formats::capture::{CaptureWriter, MANIFEST_FILE, load_capture};
use skinfield_formats::gltf_io::write_gltf_character;
use skinfield_trainer::eval::reconstruction::{TemplateScore, score_template};
use skinfield_trainer::heat::{HeatOptions, bone_heat};
use skinfield_trainer::template::{TemplateOptions, TemplateReport, reconstruct};

/// Arguments of `trainer template`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The capture (masks and images of the frame; label images if it has them).
    #[arg(long)]
    pub capture: PathBuf,
    /// Output capture folder: the input's files (hard-linked where possible) with the
    /// reconstructed template, bone-heat initial weights, `template.glb` and
    /// `template_report.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// The frame to reconstruct (default: the capture's canonical frame, else its first
    /// training frame).
    #[arg(long)]
    pub frame: Option<usize>,
    /// Grid cells along the longest side of the subject.
    #[arg(long, default_value_t = TemplateOptions::default().resolution)]
    pub resolution: usize,
    /// Vertex count of the template (about).
    #[arg(long, default_value_t = TemplateOptions::default().vertices)]
    pub vertices: usize,
    /// Use only this many of the capture's cameras (evenly spread over its list).
    #[arg(long)]
    pub cameras: Option<usize>,
}

/// What `template_report.json` holds.
#[derive(Serialize)]
struct Report<'a> {
    vertices: usize,
    triangles: usize,
    reconstruction: &'a TemplateReport,
    bone_heat_seconds: f64,
    total_seconds: f64,
    /// Against the ground truth, when the capture has it.
    score: Option<TemplateScore>,
}

/// Runs `trainer template`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let capture = load_capture(&args.capture)
        .with_context(|| format!("loading the capture {}", args.capture.display()))?;
    if args.out.canonicalize().ok() == args.capture.canonicalize().ok() {
        anyhow::bail!("--out must differ from --capture (the input keeps its template)");
    }
    let options = TemplateOptions {
        frame: args.frame,
        resolution: args.resolution,
        vertices: args.vertices,
        cameras: args.cameras,
    };
    let start = Instant::now();
    let r = reconstruct(&capture, &options)
        .with_context(|| format!("reconstructing a template from {}", args.capture.display()))?;
    let heat_start = Instant::now();
    let heat = bone_heat(&r.template, &r.skeleton, &HeatOptions::default())
        .context("bone heat on the reconstructed template")?;
    let bone_heat_seconds = heat_start.elapsed().as_secs_f64();
    let total_seconds = start.elapsed().as_secs_f64();

    let mut manifest = capture.manifest.clone();
    manifest.initial_weights = Some("initial_weights.json".into());
    manifest.evaluation = None;
    let mut skip = vec![
        capture.dir.join(MANIFEST_FILE),
        capture.dir.join(&capture.manifest.template),
    ];
    skip.extend(
        capture
            .manifest
            .initial_weights
            .iter()
            .map(|p| capture.dir.join(p)),
    );
    if let Some(e) = &capture.manifest.evaluation {
        skip.push(capture.dir.join(&e.gt_meshes));
        skip.extend(e.true_weights.iter().map(|p| capture.dir.join(p)));
    }
    skinfield_trainer::files::copy_tree(&capture.dir, &args.out, &skip)?;
    let writer = CaptureWriter::new(&args.out, manifest)?;
    writer.write_template(&r.template, &r.skeleton)?;
    writer.write_initial_weights(&heat.skin)?;
    writer.finish()?;
    let glb = args.out.join("template.glb");
    write_gltf_character(&glb, &r.skeleton, &r.template, &heat.skin, None)
        .with_context(|| format!("writing {}", glb.display()))?;

    let score = match capture.manifest.evaluation {
        Some(_) => Some(score_template(&capture, r.report.frame, &r.template)?),
        None => None,
    };
    let report = Report {
        vertices: r.template.vertex_count(),
        triangles: r.template.triangles.len(),
        reconstruction: &r.report,
        bone_heat_seconds,
        total_seconds,
        score,
    };
    let json_path = args.out.join("template_report.json");
    let mut json = serde_json::to_vec_pretty(&report)?;
    json.push(b'\n');
    skinfield_formats::skf::write_atomic(&json_path, &json)
        .with_context(|| format!("writing {}", json_path.display()))?;

    let rep = &r.report;
    let s = &rep.seconds;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "frame {} from {} cameras: {} vertices ({} marched, cell {:.2} cm, {} simplification \
         passes), {}closed, Euler characteristic {}, {} unseen vertices{}",
        rep.frame,
        rep.cameras.len(),
        r.template.vertex_count(),
        rep.marched_vertices,
        rep.cell * 100.0,
        rep.simplify_passes,
        if rep.closed { "" } else { "NOT " },
        rep.euler_characteristic,
        rep.unseen_vertices,
        rep.unvoted_vertices
            .map(|n| format!(", {n} without a label vote"))
            .unwrap_or_default(),
    )?;
    writeln!(
        out,
        "seconds: masks {:.1}, hull and simplification {:.1}, colours and labels {:.1}, bone \
         heat {:.1}, total {:.1}",
        s.masks, s.hull, s.attributes, bone_heat_seconds, total_seconds
    )?;
    if let Some(sc) = score {
        writeln!(
            out,
            "against the true surface of frame {}: M2S {:.3} cm, S2M {:.3} cm, Chamfer {:.3} cm{}",
            rep.frame,
            sc.m2s_cm,
            sc.s2m_cm,
            sc.m2s_cm + sc.s2m_cm,
            sc.label_accuracy
                .map(|a| format!(", labels right on {:.1} % of vertices", 100.0 * a))
                .unwrap_or_default(),
        )?;
    }
    writeln!(out, "wrote {} (and {})", args.out.display(), glb.display())?;
    Ok(())
}
