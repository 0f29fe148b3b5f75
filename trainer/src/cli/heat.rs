//! `trainer heat`: bone-heat weights for a glTF character, written back as glTF (and JSON).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args as ClapArgs;
use skinfield_formats::gltf_io::{load_gltf, write_gltf_character};
use skinfield_formats::skf::write_atomic;
use skinfield_trainer::heat::{HeatOptions, bone_heat};

/// Arguments of `trainer heat`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// glTF (.gltf or .glb) character; its skin with the most joints is re-weighted.
    #[arg(long)]
    pub asset: PathBuf,
    /// glTF file to write: the same skeleton and mesh with the bone-heat skin.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write per-vertex weights as JSON, `{"joints":[names],"weights":[[[joint, w],…] per
    /// vertex]}`, in the file's vertex order (the skin's primitives concatenated).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let doc = load_gltf(&args.asset)?;
    let skin = doc
        .largest_skin()
        .with_context(|| format!("{}: no skin to re-weight", args.asset.display()))?;
    let result = bone_heat(&skin.template, &skin.skeleton, &HeatOptions::default())
        .with_context(|| format!("{}: bone heat", args.asset.display()))?;
    write_gltf_character(
        &args.out,
        &skin.skeleton,
        &skin.template,
        &result.skin,
        None,
    )?;
    if let Some(path) = &args.json {
        let mut s = String::from("{\"joints\":");
        s.push_str(&serde_json::to_string(skin.skeleton.names())?);
        s.push_str(",\"weights\":[");
        for v in 0..result.skin.vertex_count() {
            if v > 0 {
                s.push(',');
            }
            s.push('[');
            let (js, ws) = result.skin.influences(v);
            for (k, (j, w)) in js.iter().zip(ws).enumerate() {
                if k > 0 {
                    s.push(',');
                }
                write!(s, "[{j},{w}]")?;
            }
            s.push(']');
        }
        s.push_str("]}\n");
        write_atomic(path, s.as_bytes()).with_context(|| format!("{}: writing", path.display()))?;
    }
    let st = &result.stats;
    println!(
        "{}: {} vertices ({} welded), {} joints, {} segments, {} components ({} fallback), {} fallback vertices, {} small-piece vertices; {:.3} s (setup {:.3}, visibility {:.3}, factor {:.3}, solve {:.3})",
        args.asset.display(),
        st.vertices,
        st.welded_vertices,
        skin.skeleton.len(),
        st.segments,
        st.components,
        st.fallback_components,
        st.fallback_vertices,
        st.inherited_vertices,
        st.total_s,
        st.setup_s,
        st.attach_s,
        st.factor_s,
        st.solve_s,
    );
    Ok(())
}
