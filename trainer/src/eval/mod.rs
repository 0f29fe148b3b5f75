//! Evaluation against ground truth (paper §4; see `docs/design.md`, *Evaluation*).
//!
//! For every test frame of a capture, the template is posed with the skinning under test and
//! compared with the ground-truth posed mesh: M2S (recovered → truth), S2M (truth → recovered)
//! and Chamfer = M2S + S2M, each a mean of exact point-to-triangle distances from points sampled
//! uniformly by area with a fixed seed, in centimetres, then averaged over the test frames.
//!
//! # Sample count
//!
//! [`DEFAULT_SAMPLES`] = 20 000 points per surface per frame. Measured on the built-in capture
//! (`trainer synth`, 24 test frames; 5 seeds each, `trainer eval --samples N --seed S`): the
//! standard deviation of the frame-averaged Chamfer between seeds is 0.0020 cm at 5 000 samples,
//! 0.0016 cm at 20 000 and 0.0010 cm at 50 000 for `oracle` (Chamfer ≈ 0.72 cm), and ≤ 0.0002 cm
//! for `oracle-dqs` (≈ 0.06 cm); after the synthetic skirt changed (oracle Chamfer ≈ 0.43 cm)
//! the spread at 20 000 was 0.0015 cm. The seed moves the result by well under 1 %, far below
//! the gaps between methods. Each frame's samples come from the same seed for every method, so
//! rows are compared with common random numbers.
//!
//! # Figures at any scale
//!
//! Centimetres are the model's units × 100 (true centimetres for files in metres, as glTF
//! specifies, but the shared Fox is 155 units long and RobotExpressive's armature scales its
//! mesh by 100). Every row therefore also gives its errors relative to the character's size:
//! [`character_size`] is the **diagonal of the capture template's bounding box** (rest pose),
//! and `chamfer_pct` is the Chamfer distance as a percentage of it. The diagonal rather than
//! the height, because the height misstates quadrupeds and lying characters (the Fox is
//! 79 units tall and 155 long) while the diagonal is defined for any shape; for the built-in
//! 1.75 m character in its T-pose it is 2.48 m, so 1 cm is 0.40 %.
//!
//! # Worst vertex
//!
//! Mean surface distances average a spike away. Each frame therefore also records two worst
//! vertices, and a row keeps both per frame (`per_frame`) and their maxima over the frames:
//!
//! - `max_off_surface_cm`: the largest distance from a vertex of the posed mesh to the
//!   ground-truth **surface**. A spike (a vertex pulled across the body by a far joint) is off
//!   the surface and shows here; a vertex that slides along the true surface does not. Defined
//!   for a mesh of any resolution.
//! - `max_vertex_cm`: the largest **vertex-to-vertex** distance to the ground truth (the same
//!   vertices, so sliding counts too: a ball centred on a joint and carried by the other bone
//!   has the right surface and wrong vertices). Templates of another resolution have no vertex
//!   correspondence and leave it empty.
//!
//! [`off_surface_check`] and [`worst_vertex_check`] compare two rows frame by frame on each
//! figure: "no test frame where any vertex of ours is further from the truth than the worst
//! vertex of bone heat on that frame".
//!
//! # Templates at other resolutions
//!
//! [`evaluate_template`] poses another mesh over the capture's canonical space (e.g. one of
//! `trainer resample`) with SkinNet and compares it with the same ground truth: both surfaces
//! are sampled uniformly by area, so the metrics compare surfaces whatever their vertex counts.
//!
//! # Methods ([`Skinning`])
//!
//! | argument | row | weights | blend |
//! | --- | --- | --- | --- |
//! | `initial` | `initial` | the capture's initial static weights, else bone heat ([`crate::heat::bone_heat`], default options) | LBS |
//! | `static:FILE` | `static` | a [`static_weights`] file | LBS |
//! | `skf:FILE` | `ours` | SkinNet's pose-dependent weights from a `.skf`, by `skinfield_runtime` | LBS |
//! | `oracle` | `oracle` | the ground-truth deformer's own static weights | LBS |
//! | `oracle-dqs` | `oracle-dqs` | the same | DQS |
//! | `bound-static` | `bound-static` | the best static weights for the training frames' ground truth ([`bounds`]) | LBS |
//! | `bound-pose` | `bound-pose` | the best per-frame weights within the candidate joints ([`bounds`]) | LBS |
//!
//! `trainer eval --fast [N]` adds the runtime's fast path of every `skf:FILE` row ([`fast`]).

pub mod bounds;
pub mod diagnostics;
pub mod distance;
pub mod fast;
pub mod figure;
mod methods;
pub mod posing;
pub mod reconstruction;
pub mod spread;
pub mod static_weights;
pub mod surface;
pub mod table;

use std::path::PathBuf;

use glam::Vec3;
use skinfield_formats::Template;
use skinfield_formats::capture::{Capture, CaptureError};
use skinfield_formats::gltf_io::load_gltf;
use skinfield_formats::skf::SkfFileError;

pub use methods::{ParseSkinningError, PreparedSkinning, Skinning};
pub(crate) use methods::{load_skinnet, sorted_influences};
pub use posing::{Blend, PosingError, pose_static};
pub use static_weights::{StaticWeightsError, read_static_weights, write_static_weights};
pub use surface::{DEFAULT_SAMPLES, Surface, SurfaceError, SurfaceMetrics, surface_metrics};
pub use table::{
    EvalRow, FrameRow, WorstVertexCheck, off_surface_check, rows_from_json, rows_to_json,
    rows_to_table, worst_vertex_check,
};

/// How [`evaluate`] samples the surfaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EvalOptions {
    /// Points sampled per surface per frame.
    pub samples: usize,
    /// Seed of the sampling; frame `f` uses a stream derived from `(seed, f)`.
    pub seed: u64,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            samples: DEFAULT_SAMPLES,
            seed: 0,
        }
    }
}

/// Why an evaluation failed.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The capture's files are missing or malformed.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// The capture lists no test frames.
    #[error("{}: field `test_frames` is empty: nothing to evaluate", .0.display())]
    NoTestFrames(PathBuf),
    /// `initial` was asked for, the capture ships no initial weights and bone heat failed.
    #[error("{}: no `initial_weights` and bone heat failed: {source}", path.display())]
    InitialWeights {
        /// The capture's manifest.
        path: PathBuf,
        /// Why bone heat failed.
        source: crate::heat::HeatError,
    },
    /// `oracle` was asked for but the capture has no ground-truth weights.
    #[error("{}: field `evaluation.true_weights` is absent: the capture has no ground-truth weights", .0.display())]
    NoTrueWeights(PathBuf),
    /// The static-weights file is unreadable or does not fit the capture.
    #[error(transparent)]
    StaticWeights(#[from] StaticWeightsError),
    /// The `.skf` file is unreadable or malformed.
    #[error(transparent)]
    SkfFile(#[from] SkfFileError),
    /// The `.skf` does not fit the capture, or the runtime refused it.
    #[error("{}: {reason}", path.display())]
    Skf {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A static skinning was asked to pose a template other than the capture's (its weights are
    /// per vertex of the capture's template; only SkinNet poses any mesh).
    #[error(
        "`{method}` has weights for the capture's {weights} vertices, the template has {vertices}: only `skf:FILE` (SkinNet) poses another template"
    )]
    TemplateMismatch {
        /// The row.
        method: &'static str,
        /// Vertices the weights cover.
        weights: usize,
        /// Vertices of the template.
        vertices: usize,
    },
    /// The skinning has no weights outside the test frames (`bound-pose`).
    #[error("`{0}` is fitted per test frame and has no bind-pose weights")]
    NoBindWeights(&'static str),
    /// A template file is unreadable or holds no mesh.
    #[error("{}: {reason}", path.display())]
    Template {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The weights do not fit the template or the pose the skeleton.
    #[error("frame {frame}: {source}")]
    Posing {
        /// The frame.
        frame: usize,
        /// The cause.
        source: PosingError,
    },
    /// A surface cannot be measured.
    #[error("frame {frame}: {source}")]
    Surface {
        /// The frame.
        frame: usize,
        /// The cause.
        source: SurfaceError,
    },
}

/// One test frame's metrics, in centimetres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameMetrics {
    /// The frame index.
    pub frame: usize,
    /// M2S (cm).
    pub m2s_cm: f64,
    /// S2M (cm).
    pub s2m_cm: f64,
    /// Largest vertex-to-vertex distance to the ground truth (cm), when the posed mesh has the
    /// capture template's vertices (`None` for a template of another resolution).
    pub max_vertex_cm: Option<f64>,
    /// Largest distance from a vertex of the posed mesh to the ground-truth surface (cm).
    pub max_off_surface_cm: f64,
}

/// The sampling seed of one frame: distinct streams per frame, identical across methods.
#[must_use]
pub fn frame_seed(seed: u64, frame: usize) -> u64 {
    seed ^ (frame as u64)
        .wrapping_add(1)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// Scores the posed meshes of `positions_for(frame)` (the capture's template posed) against the
/// ground truth of every test frame.
pub fn evaluate_frames(
    capture: &Capture,
    options: &EvalOptions,
    positions_for: impl FnMut(usize) -> Result<Vec<Vec3>, EvalError>,
) -> Result<Vec<FrameMetrics>, EvalError> {
    evaluate_mesh_frames(capture, &capture.template.triangles, options, positions_for)
}

/// [`evaluate_frames`] for a posed mesh with its own `triangles` (any resolution: both
/// surfaces are sampled by area, so the metrics compare surfaces, not vertex lists).
pub fn evaluate_mesh_frames(
    capture: &Capture,
    triangles: &[[u32; 3]],
    options: &EvalOptions,
    mut positions_for: impl FnMut(usize) -> Result<Vec<Vec3>, EvalError>,
) -> Result<Vec<FrameMetrics>, EvalError> {
    capture.require_motion()?;
    if capture.test_frames.is_empty() {
        return Err(EvalError::NoTestFrames(
            capture.dir.join(skinfield_formats::capture::MANIFEST_FILE),
        ));
    }
    // Vertex i of the posed mesh is vertex i of the truth only for the capture's own mesh; another
    // template (resampled, reconstructed) may have the same count by chance.
    let corresponds = triangles == capture.template.triangles.as_slice();
    let mut out = Vec::with_capacity(capture.test_frames.len());
    for &frame in &capture.test_frames {
        let truth = capture.evaluation_gt_mesh(frame)?;
        let posed = positions_for(frame)?;
        let m = surface_metrics(
            Surface {
                positions: &posed,
                triangles,
            },
            Surface {
                positions: &truth,
                triangles: &capture.template.triangles,
            },
            options.samples,
            frame_seed(options.seed, frame),
        )
        .map_err(|source| EvalError::Surface { frame, source })?;
        out.push(FrameMetrics {
            frame,
            m2s_cm: m.m2s * 100.0,
            s2m_cm: m.s2m * 100.0,
            max_vertex_cm: max_vertex_distance(&posed, &truth)
                .filter(|_| corresponds)
                .map(|d| d * 100.0),
            max_off_surface_cm: m.max_vertex_off * 100.0,
        });
    }
    Ok(out)
}

/// The largest distance between corresponding vertices (model units), or `None` when the two
/// lists differ in length (meshes of different resolutions have no vertex correspondence).
#[must_use]
pub fn max_vertex_distance(posed: &[Vec3], truth: &[Vec3]) -> Option<f64> {
    (posed.len() == truth.len()).then(|| {
        posed
            .iter()
            .zip(truth)
            .map(|(a, b)| f64::from((*a - *b).length()))
            .fold(0.0f64, f64::max)
    })
}

/// The character's size that relative errors are measured against: the diagonal of the
/// capture template's bounding box (rest pose), in model units; 0 for an empty template.
#[must_use]
pub fn character_size(template: &Template) -> f64 {
    template
        .bounds()
        .map_or(0.0, |b| f64::from(b.size().length()))
}

/// `cm` as a percentage of a character of `size` model units ([`character_size`]); 0 for a
/// character without size. Model units are taken as metres (cm → units is ÷ 100, a percentage
/// is × 100: the two cancel), the convention of every `cm` column.
#[must_use]
pub fn percent_of_size(cm: f64, size: f64) -> f64 {
    if size > 0.0 { cm / size } else { 0.0 }
}

/// Averages per-frame metrics into a table row; `size` is the character's size
/// ([`character_size`], model units) for the relative columns.
#[must_use]
pub fn average(method: &str, frames: &[FrameMetrics], size: f64) -> EvalRow {
    let n = frames.len().max(1) as f64;
    let m2s = frames.iter().map(|f| f.m2s_cm).sum::<f64>() / n;
    let s2m = frames.iter().map(|f| f.s2m_cm).sum::<f64>() / n;
    let max_vertex = frames
        .iter()
        .map(|f| f.max_vertex_cm)
        .collect::<Option<Vec<f64>>>()
        .map(|v| v.into_iter().fold(0.0f64, f64::max));
    let off_surface = (!frames.is_empty()).then(|| {
        frames
            .iter()
            .map(|f| f.max_off_surface_cm)
            .fold(0.0f64, f64::max)
    });
    let percent = |cm: f64| percent_of_size(cm, size);
    EvalRow {
        method: method.to_string(),
        chamfer_cm: m2s + s2m,
        m2s_cm: m2s,
        s2m_cm: s2m,
        frames: frames.len(),
        size,
        chamfer_pct: percent(m2s + s2m),
        max_vertex_cm: max_vertex,
        max_vertex_pct: max_vertex.map(percent),
        max_off_surface_cm: off_surface,
        max_off_surface_pct: off_surface.map(percent),
        per_frame: frames
            .iter()
            .map(|f| FrameRow {
                frame: f.frame,
                m2s_cm: f.m2s_cm,
                s2m_cm: f.s2m_cm,
                max_vertex_cm: f.max_vertex_cm,
                max_off_surface_cm: Some(f.max_off_surface_cm),
            })
            .collect(),
    }
}

/// Poses the template for every test frame of `capture` with `skinning` and reports M2S, S2M and
/// Chamfer in centimetres averaged over the test frames.
pub fn evaluate(
    capture: &Capture,
    skinning: &Skinning,
    options: &EvalOptions,
) -> Result<EvalRow, EvalError> {
    evaluate_template(capture, &capture.template, skinning, options)
}

/// [`evaluate`] with `template` posed instead of the capture's own: a mesh over the same
/// canonical space at any resolution (`trainer eval --template`). Only SkinNet (`skf:FILE`)
/// poses a template whose vertices are not the capture's.
pub fn evaluate_template(
    capture: &Capture,
    template: &Template,
    skinning: &Skinning,
    options: &EvalOptions,
) -> Result<EvalRow, EvalError> {
    let prepared = PreparedSkinning::new(capture, skinning)?;
    let frames = evaluate_mesh_frames(capture, &template.triangles, options, |frame| {
        prepared.pose_rest(capture, &template.positions, frame)
    })?;
    Ok(average(
        prepared.method(),
        &frames,
        character_size(&capture.template),
    ))
}

/// The template of a glTF/GLB file: the mesh of its largest skin, else its first unskinned
/// mesh (positions as stored). This is what `trainer resample` writes.
pub fn load_template(path: &std::path::Path) -> Result<Template, EvalError> {
    let doc = load_gltf(path).map_err(|e| EvalError::Template {
        path: path.to_owned(),
        reason: e.to_string(),
    })?;
    let template = match doc.largest_skin() {
        Some(skin) if skin.template.vertex_count() > 0 => skin.template.clone(),
        _ => doc
            .static_meshes
            .first()
            .map(|m| m.template.clone())
            .ok_or_else(|| EvalError::Template {
                path: path.to_owned(),
                reason: "no mesh: expected a skinned character or a mesh node".into(),
            })?,
    };
    template.validate().map_err(|e| EvalError::Template {
        path: path.to_owned(),
        reason: format!("`meshes`: {e}"),
    })?;
    Ok(template)
}

/// Distance (metres) from each vertex of a posed mesh to the ground-truth surface of `frame`:
/// the per-vertex M2S error that `trainer render` colours.
pub fn per_vertex_m2s(
    capture: &Capture,
    frame: usize,
    posed: &[Vec3],
) -> Result<Vec<f32>, EvalError> {
    let truth = capture.evaluation_gt_mesh(frame)?;
    let bvh = crate::triangle_bvh::TriangleBvh::new(&truth, &capture.template.triangles);
    Ok(surface::distances_to(posed, &bvh))
}
pub mod render;
#[cfg(test)]
mod template_tests;
#[cfg(test)]
mod tests;
