//! `trainer resample --capture DIR|--asset FILE --vertices 1000,5000,50000 --out DIR [--skf F]`:
//! writes the template resampled to each vertex count as a glTF character (simplified below the
//! source's count, subdivided above it: `skinfield_runtime::resample`), and prints what each
//! costs at load time — resampling, and with `--skf` binding the result to the model.
//!
//! Each file carries the source's skeleton and a static skin interpolated from the source's
//! (a glTF character must have one; a capture's initial weights, or bone heat when it ships
//! none). SkinNet does not use it: `trainer eval --template F --weights skf:M` queries the
//! network at the new canonical positions.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use clap::Args as ClapArgs;
use skinfield_formats::capture::load_capture;
use skinfield_formats::gltf_io::{load_gltf, write_gltf_character};
use skinfield_formats::skf::read_skf_file;
use skinfield_formats::{Skeleton, StaticSkin, Template};
use skinfield_runtime::resample::{Target, resample, transfer_skin};
use skinfield_runtime::{BoundMesh, SkinNetModel};
use skinfield_trainer::train::data::initial_weights;

/// Arguments of `trainer resample`.
#[derive(ClapArgs, Debug)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["capture", "asset"])))]
pub struct Args {
    /// Resample a capture's template (its skeleton and initial weights go with it).
    #[arg(long)]
    pub capture: Option<PathBuf>,
    /// Resample a glTF character (its skin with the most joints).
    #[arg(long)]
    pub asset: Option<PathBuf>,
    /// Vertex counts to resample to, comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub vertices: Vec<usize>,
    /// Output folder: `template_{N}.glb` per count.
    #[arg(long)]
    pub out: PathBuf,
    /// Also bind each resampled mesh to this model and time it (the other half of load time).
    #[arg(long)]
    pub skf: Option<PathBuf>,
}

/// Runs `trainer resample`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (name, skeleton, template, skin) = source(&args)?;
    let model = match &args.skf {
        Some(path) => {
            let bytes = read_skf_file(path)?;
            let model = SkinNetModel::from_skf(&bytes)
                .with_context(|| format!("{}: loading the model", path.display()))?;
            Some(model)
        }
        None => None,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: creating the folder", args.out.display()))?;
    println!(
        "{name}: {} vertices, {} triangles",
        template.vertex_count(),
        template.triangles.len()
    );
    println!("| target | vertices | triangles | resample (ms) | bind (ms) | file |");
    println!("| --- | --- | --- | --- | --- | --- |");
    for &n in &args.vertices {
        let start = Instant::now();
        let r = resample(&template, Target::Vertices(n))
            .with_context(|| format!("{name}: resampling to {n} vertices (`--vertices`)"))?;
        let resample_ms = start.elapsed().as_secs_f64() * 1e3;
        let bind_ms = match &model {
            Some(m) => {
                let start = Instant::now();
                let bound = BoundMesh::bind(m, &r.template.positions)?;
                let ms = start.elapsed().as_secs_f64() * 1e3;
                std::hint::black_box(bound);
                format!("{ms:.1}")
            }
            None => "–".into(),
        };
        let out_skin = transfer_skin(&skin, &r.source)?;
        let path = args.out.join(format!("template_{n}.glb"));
        write_gltf_character(&path, &skeleton, &r.template, &out_skin, None)?;
        println!(
            "| {n} | {} | {} | {resample_ms:.1} | {bind_ms} | {} |",
            r.template.vertex_count(),
            r.template.triangles.len(),
            path.display()
        );
    }
    Ok(())
}

/// The source's name (for messages), skeleton, template and static skin.
fn source(args: &Args) -> anyhow::Result<(String, Skeleton, Template, StaticSkin)> {
    if let Some(dir) = &args.capture {
        let capture =
            load_capture(dir).with_context(|| format!("loading the capture {}", dir.display()))?;
        let skin = initial_weights(&capture)
            .with_context(|| format!("{}: initial weights", dir.display()))?;
        return Ok((
            dir.display().to_string(),
            capture.skeleton,
            capture.template,
            skin,
        ));
    }
    // clap's group makes one of the two present.
    let path = args
        .asset
        .as_ref()
        .context("--capture or --asset is required")?;
    let doc = load_gltf(path)?;
    let skin = doc
        .largest_skin()
        .with_context(|| format!("{}: no skinned mesh to resample", path.display()))?;
    Ok((
        path.display().to_string(),
        skin.skeleton.clone(),
        skin.template.clone(),
        skin.skin.clone(),
    ))
}
