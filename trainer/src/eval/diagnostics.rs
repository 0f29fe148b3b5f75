//! Diagnostics that explain a run without a debugger, written by `trainer demo` beside its
//! table (`diagnostics.md`):
//!
//! - **per-part errors**: each method's mean and worst per-vertex distance to the ground truth
//!   on the test frames, for the template's skin and clothing vertices separately (a gain on
//!   the skirt and a loss on the arms average out in the table's Chamfer);
//! - **errors where the training outlines see, and where they do not**: the same figures for
//!   the vertices on the outline of the ground-truth mesh in at least one training view and for
//!   the rest, whose weights the silhouettes cannot see;
//! - **the image terms on the truth**: the silhouette distance and IoU of the ground-truth
//!   meshes against the training masks, next to each method's. The truth should score lowest;
//!   a method scoring below the truth is fitting the masks with a wrong shape, and a truth
//!   scoring far from zero says the masks, cameras or the loss itself are off.
//! - **the worst vertex of each test frame** (`trainer eval --worst-vertices`): which vertex
//!   is furthest from its ground-truth position, how far, and which joints move it under the
//!   method and under the ground truth's own weights: a spike names the far joint it follows.

use std::fmt::Write as _;

use glam::Vec3;
use skinfield_formats::capture::Capture;
use skinfield_formats::{Camera, PartLabel};

use super::{EvalError, PreparedSkinning, Skinning, per_vertex_m2s, sorted_influences};
use crate::losses::silhouette::EdgeTable;
use crate::losses::silhouette::edges::count_outline_views;
use crate::train::data::{DataError, DataOptions, TrainData, initial_weights, train_data};
use crate::train::validation::{ValidationScore, score_posed};

/// A diagnostic could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum DiagnosticsError {
    /// Posing or scoring failed.
    #[error(transparent)]
    Eval(#[from] EvalError),
    /// The training frames could not be loaded.
    #[error(transparent)]
    Data(#[from] DataError),
}

/// One part's errors under one method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PartError {
    /// `skin`, `clothing`, or `all` for a template without labels.
    pub part: &'static str,
    /// Vertices of the part.
    pub vertices: usize,
    /// Mean per-vertex distance to the ground-truth surface over the test frames (cm).
    pub mean_cm: f64,
    /// The largest per-vertex distance on any test frame (cm).
    pub worst_cm: f64,
}

/// Per-part errors of `skinning` on the capture's test frames.
pub fn part_errors(capture: &Capture, skinning: &Skinning) -> Result<Vec<PartError>, EvalError> {
    let labels: Vec<&'static str> = match &capture.template.part_labels {
        Some(l) => l
            .iter()
            .map(|p| match p {
                PartLabel::Skin => "skin",
                PartLabel::Clothing => "clothing",
            })
            .collect(),
        None => vec!["all"; capture.template.vertex_count()],
    };
    grouped_errors(capture, skinning, &labels)
}

/// The name of the vertices that lie on a true training outline (see [`truth_outline_views`]).
pub const SEEN: &str = "on a training outline";
/// The name of the vertices that lie on none.
pub const HIDDEN: &str = "on no training outline";

/// Errors of `skinning` on the capture's test frames, split between the vertices that lie on
/// the outline of at least one training view (`views[i] > 0`, [`SEEN`], first) and the rest
/// ([`HIDDEN`]): the silhouettes say something about the first group's weights and nothing
/// about the second's, which rests on the warm start, the regularisers and what the shared
/// network carries over from the vertices it sees.
pub fn outline_errors(
    capture: &Capture,
    skinning: &Skinning,
    views: &[u32],
) -> Result<Vec<PartError>, EvalError> {
    let labels: Vec<&'static str> = views
        .iter()
        .map(|&n| if n > 0 { SEEN } else { HIDDEN })
        .collect();
    let mut rows = grouped_errors(capture, skinning, &labels)?;
    rows.sort_by_key(|p| p.part != SEEN);
    Ok(rows)
}

/// Mean and worst per-vertex distance to the true surface over the test frames, per group of
/// vertices (`labels[i]` names vertex `i`'s group; groups in order of first appearance).
fn grouped_errors(
    capture: &Capture,
    skinning: &Skinning,
    labels: &[&'static str],
) -> Result<Vec<PartError>, EvalError> {
    let prepared = PreparedSkinning::new(capture, skinning)?;
    let mut parts: Vec<&'static str> = Vec::new();
    for &l in labels {
        if !parts.contains(&l) {
            parts.push(l);
        }
    }
    let mut sum = vec![0.0f64; parts.len()];
    let mut worst = vec![0.0f64; parts.len()];
    let mut count = vec![0usize; parts.len()];
    for &f in &capture.test_frames {
        let posed = prepared.pose_frame(capture, f)?;
        let d = per_vertex_m2s(capture, f, &posed)?;
        for (dist, label) in d.iter().zip(labels) {
            let k = parts.iter().position(|p| p == label).unwrap_or(0);
            let cm = 100.0 * f64::from(*dist);
            sum[k] += cm;
            worst[k] = worst[k].max(cm);
            count[k] += 1;
        }
    }
    let frames = capture.test_frames.len().max(1);
    Ok(parts
        .iter()
        .enumerate()
        .map(|(k, &part)| PartError {
            part,
            vertices: count[k] / frames,
            mean_cm: sum[k] / count[k].max(1) as f64,
            worst_cm: worst[k],
        })
        .collect())
}

/// For every template vertex, how many training views (frame × camera) have it on the outline
/// of the ground-truth posed mesh: a silhouette edge's end on the mesh's own projected outline,
/// the silhouette loss's boundary set at the truth (`None` when the capture has no ground truth
/// for its training frames). Only the cameras and the true meshes are read; the set does not
/// depend on the masks. A vertex at 0 is hidden from every training view (under clothing,
/// between the legs) or always faces a camera: the silhouettes cannot see its weights.
///
/// Copies of one rest position (a mesh split at its UV or normal seams) are counted as one
/// vertex and share its count: on the split mesh a seam is an open border, which would count a
/// copy on one side of the outline and not the other. That is what training sees of a split
/// template (it trains on the weld); a template training keeps unwelded (fewer copies than
/// [`crate::train::data::SPLIT_COPIES`] asks, such as the built-in character, 10,000 vertices
/// at 9,982 positions where its skirt's waistband lies on the body) is welded here for the
/// count only.
#[must_use]
pub fn truth_outline_views(capture: &Capture) -> Option<Vec<u32>> {
    let posed = capture
        .train_frames
        .iter()
        .map(|&frame| capture.evaluation_gt_mesh(frame).ok());
    outline_views_by_position(
        &capture.template.positions,
        &capture.template.triangles,
        &capture.rig.cameras,
        posed,
    )
}

/// [`truth_outline_views`] for any posed meshes of a template (`rest` positions, `triangles`):
/// every mesh of `posed` seen by every camera, copies of one rest position counted once (`None`
/// when a mesh is missing).
fn outline_views_by_position(
    rest: &[Vec3],
    triangles: &[[u32; 3]],
    cameras: &[Camera],
    posed: impl IntoIterator<Item = Option<Vec<Vec3>>>,
) -> Option<Vec<u32>> {
    let welded = crate::heat::weld::weld(rest, triangles, 0.0);
    let edges = EdgeTable::new(welded.representative.len(), &welded.triangles);
    let mut views = vec![0u32; welded.representative.len()];
    for mesh in posed {
        let mesh = mesh?;
        let positions: Vec<Vec3> = welded
            .representative
            .iter()
            .map(|&i| mesh.get(i as usize).copied())
            .collect::<Option<_>>()?;
        count_outline_views(&mut views, cameras, &positions, &welded.triangles, &edges);
    }
    Some(welded.of_input.iter().map(|&w| views[w as usize]).collect())
}

/// The ground-truth posed template of each of a list of frames.
type TruthMeshes = Vec<Vec<Vec3>>;

/// Every `stride`-th training frame at full template resolution (masks, cameras, targets) and
/// the ground-truth posed meshes of those frames (`None` where the capture has none).
fn frames_with_truth(
    capture: &Capture,
    stride: usize,
) -> Result<(TrainData, Option<TruthMeshes>), DiagnosticsError> {
    let mut sub = capture.clone();
    sub.train_frames = capture
        .train_frames
        .iter()
        .copied()
        .step_by(stride.max(1))
        .collect();
    let initial = initial_weights(&sub)?;
    let data = train_data(
        &sub,
        &initial,
        &DataOptions {
            train_vertices: 0,
            ..DataOptions::default()
        },
    )?;
    let truth: Result<TruthMeshes, _> = sub
        .train_frames
        .iter()
        .map(|&f| capture.evaluation_gt_mesh(f))
        .collect();
    Ok((data, truth.ok()))
}

/// The vertex of one test frame furthest from its ground-truth position.
#[derive(Clone, Debug, PartialEq)]
pub struct WorstVertex {
    /// The test frame.
    pub frame: usize,
    /// The template vertex.
    pub vertex: usize,
    /// Its distance to the ground truth by the [`WorstMeasure`] asked for (model units × 100:
    /// cm for files in metres).
    pub distance_cm: f64,
    /// The method's influences on that vertex and frame (joint, weight), largest first; empty
    /// where the method has no per-vertex weights (`bound-pose`).
    pub influences: Vec<(u32, f32)>,
    /// The ground truth's own (static) weights on that vertex, largest first; empty where the
    /// capture has none.
    pub true_influences: Vec<(u32, f32)>,
}

/// How [`worst_vertices`] measures a vertex's distance to the truth (the two figures of the
/// zoo's worst-vertex checks).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorstMeasure {
    /// To the same vertex of the ground truth: a vertex sliding along the surface counts.
    VertexToVertex,
    /// To the ground-truth surface: only a vertex off the surface (a spike) counts.
    OffSurface,
}

impl WorstMeasure {
    /// The figure's name in tables.
    #[must_use]
    pub fn label(self) -> &'static str {
        match self {
            Self::VertexToVertex => "vertex to vertex",
            Self::OffSurface => "off the true surface",
        }
    }
}

/// The worst vertex of every test frame under `skinning`, by `measure`.
pub fn worst_vertices(
    capture: &Capture,
    skinning: &Skinning,
    measure: WorstMeasure,
) -> Result<Vec<WorstVertex>, EvalError> {
    let prepared = PreparedSkinning::new(capture, skinning)?;
    let truth_weights = capture.evaluation_true_weights()?;
    let mut out = Vec::with_capacity(capture.test_frames.len());
    for &f in &capture.test_frames {
        let posed = prepared.pose_frame(capture, f)?;
        let distances: Vec<f32> = match measure {
            WorstMeasure::VertexToVertex => {
                let truth = capture.evaluation_gt_mesh(f)?;
                posed
                    .iter()
                    .zip(&truth)
                    .map(|(a, b)| (*a - *b).length())
                    .collect()
            }
            WorstMeasure::OffSurface => super::per_vertex_m2s(capture, f, &posed)?,
        };
        let Some((vertex, &distance)) = distances
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
        else {
            continue;
        };
        let true_influences = match &truth_weights {
            Some(skin) if vertex < skin.vertex_count() => sorted_influences(skin, vertex),
            _ => Vec::new(),
        };
        out.push(WorstVertex {
            frame: f,
            vertex,
            distance_cm: 100.0 * f64::from(distance),
            influences: prepared
                .vertex_influences(capture, f, vertex)?
                .unwrap_or_default(),
            true_influences,
        });
    }
    Ok(out)
}

/// `worst` as Markdown: one line per frame, joints by name with their weights (at most
/// `max_joints` each).
#[must_use]
pub fn worst_vertices_markdown(
    capture: &Capture,
    method: &str,
    measure: WorstMeasure,
    worst: &[WorstVertex],
    max_joints: usize,
) -> String {
    let names = |inf: &[(u32, f32)]| -> String {
        if inf.is_empty() {
            return "–".into();
        }
        inf.iter()
            .take(max_joints)
            .map(|&(j, w)| {
                let name = capture
                    .skeleton
                    .names()
                    .get(j as usize)
                    .map_or("?", String::as_str);
                format!("{name} {w:.2}")
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut s = String::new();
    let _ = writeln!(
        s,
        "### Worst vertex per test frame, {}: {method}\n",
        measure.label()
    );
    let _ = writeln!(
        s,
        "| frame | vertex | distance (cm) | joints (method) | joints (truth) |"
    );
    let _ = writeln!(s, "| --- | --- | --- | --- | --- |");
    for w in worst {
        let _ = writeln!(
            s,
            "| {} | {} | {:.3} | {} | {} |",
            w.frame,
            w.vertex,
            w.distance_cm,
            names(&w.influences),
            names(&w.true_influences)
        );
    }
    s
}

/// The image terms of the ground truth and of each method (row name, score) on every
/// `stride`-th training frame, all views, at full template resolution. The truth row is
/// `truth`; it is left out when the capture has no ground truth for its training frames.
///
/// A template split into copies of its positions is scored on its weld, as training sees it
/// ([`split_template_weld`](crate::train::data::split_template_weld)): on the split mesh every
/// seam is an open border, which the outline test would take for the surface's edge.
pub fn terms_on_truth(
    capture: &Capture,
    methods: &[Skinning],
    stride: usize,
) -> Result<Vec<(String, ValidationScore)>, DiagnosticsError> {
    // At full resolution the training template is the weld of a split template and the
    // template itself otherwise; each posed copy of the capture's template is read on it.
    let (data, truth) = frames_with_truth(capture, stride)?;
    let triangles = &data.template.triangles;
    let on_training_template = |posed: Vec<Vec3>| -> Vec<Vec3> {
        data.source.iter().map(|&i| posed[i as usize]).collect()
    };
    let edges = EdgeTable::new(data.template.vertex_count(), triangles);
    let mut rows = Vec::new();
    if let Some(truth) = truth {
        let truth: Vec<Vec<Vec3>> = truth.into_iter().map(on_training_template).collect();
        rows.push((
            "truth".to_string(),
            score_posed(&data.frames, &truth, triangles, &edges, None),
        ));
    }
    for m in methods {
        let prepared = PreparedSkinning::new(capture, m)?;
        let posed = (capture.train_frames.iter().step_by(stride.max(1)))
            .map(|&f| prepared.pose_frame(capture, f).map(on_training_template))
            .collect::<Result<Vec<_>, _>>()?;
        rows.push((
            m.method_name().to_string(),
            score_posed(&data.frames, &posed, triangles, &edges, None),
        ));
    }
    Ok(rows)
}

/// The diagnostics as Markdown: per-part errors, the same split by what the training outlines
/// see (`outline`, left out when empty), and the image terms.
#[must_use]
pub fn diagnostics_markdown(
    parts: &[(String, Vec<PartError>)],
    outline: &[(String, Vec<PartError>)],
    terms: &[(String, ValidationScore)],
    stride: usize,
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "## Per-part errors on the test frames\n");
    let _ = writeln!(
        s,
        "Mean and worst per-vertex distance to the ground-truth surface (cm).\n"
    );
    part_table(&mut s, parts);
    if !outline.is_empty() {
        let _ = writeln!(
            s,
            "\n## Errors where the training outlines see, and where they do not\n\n\
             The same figures for the vertices that lie on the outline of the ground-truth mesh \
             in at least one training view and for those that lie on none (under clothing, \
             between the legs): the silhouettes cannot see the second group's weights, which \
             rest on the warm start, the regularisers and what the network carries over from \
             the vertices it sees.\n"
        );
        part_table(&mut s, outline);
    }
    let _ = writeln!(
        s,
        "\n## Image terms on the truth and on each method\n\nEvery {stride}th training frame, \
         all views, full template resolution: the mean distance between mesh silhouette and \
         mask outline (pixels; no Huber), the IoU of the rasterised mesh with the mask, and how \
         far the masks lie outside the mesh on average (their area minus the mesh's over their \
         outline length, pixels; near zero on the truth unless the masks are biased). The truth \
         should score lowest.\n"
    );
    let _ = writeln!(
        s,
        "| mesh | silhouette (px) | boundary (px) | contour (px) | IoU | masks outside the mesh (px) |"
    );
    let _ = writeln!(s, "| --- | --- | --- | --- | --- | --- |");
    for (name, t) in terms {
        let _ = writeln!(
            s,
            "| {name} | {:.4} | {:.4} | {:.4} | {:.5} | {:+.3} |",
            t.silhouette_px, t.boundary_px, t.contour_px, t.iou, t.outline_offset_px
        );
    }
    s
}

/// One Markdown table of per-group errors, a row per method and group.
fn part_table(s: &mut String, parts: &[(String, Vec<PartError>)]) {
    let _ = writeln!(s, "| method | part | vertices | mean (cm) | worst (cm) |");
    let _ = writeln!(s, "| --- | --- | --- | --- | --- |");
    for (method, rows) in parts {
        for p in rows {
            let _ = writeln!(
                s,
                "| {method} | {} | {} | {:.3} | {:.2} |",
                p.part, p.vertices, p.mean_cm, p.worst_cm
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinfield_formats::capture::load_capture;

    /// The tiny synthetic capture, loaded (its folder kept alive by the returned guard).
    fn tiny_capture() -> (tempfile::TempDir, Capture) {
        let dir = tempfile::tempdir().unwrap();
        crate::synth::synthesize(dir.path(), &crate::synth::SynthConfig::tiny()).unwrap();
        let capture = load_capture(dir.path()).unwrap();
        (dir, capture)
    }

    #[test]
    fn parts_partition_the_vertices_and_average_to_the_per_vertex_mean() {
        let (_dir, capture) = tiny_capture();
        let parts = part_errors(&capture, &Skinning::Initial).unwrap();
        let v = capture.template.vertex_count();
        assert_eq!(parts.iter().map(|p| p.vertices).sum::<usize>(), v);
        assert_eq!(
            parts.iter().map(|p| p.part).collect::<Vec<_>>(),
            ["skin", "clothing"]
        );
        // The vertex-weighted mean of the parts is the plain per-vertex mean, computed here
        // independently.
        let prepared = PreparedSkinning::new(&capture, &Skinning::Initial).unwrap();
        let (mut sum, mut worst) = (0.0f64, 0.0f64);
        for &f in &capture.test_frames {
            let posed = prepared.pose_frame(&capture, f).unwrap();
            for d in per_vertex_m2s(&capture, f, &posed).unwrap() {
                sum += 100.0 * f64::from(d);
                worst = worst.max(100.0 * f64::from(d));
            }
        }
        let mean = sum / (v * capture.test_frames.len()) as f64;
        let combined = parts
            .iter()
            .map(|p| p.mean_cm * p.vertices as f64)
            .sum::<f64>()
            / v as f64;
        assert!(
            (combined - mean).abs() < 1e-9 * mean.max(1.0),
            "{combined} vs {mean}"
        );
        assert_eq!(parts.iter().map(|p| p.worst_cm).fold(0.0, f64::max), worst);
        // The oracle's error is smaller than bone heat's on every part.
        let oracle = part_errors(&capture, &Skinning::Oracle).unwrap();
        for (o, i) in oracle.iter().zip(&parts) {
            assert!(o.mean_cm < i.mean_cm, "{o:?} vs {i:?}");
        }
    }

    #[test]
    fn worst_vertices_are_the_frames_largest_distances_with_their_joints() {
        let (_dir, capture) = tiny_capture();
        let worst =
            worst_vertices(&capture, &Skinning::Initial, WorstMeasure::VertexToVertex).unwrap();
        assert_eq!(worst.len(), capture.test_frames.len());
        let prepared = PreparedSkinning::new(&capture, &Skinning::Initial).unwrap();
        let heat = crate::heat::bone_heat(
            &capture.template,
            &capture.skeleton,
            &crate::heat::HeatOptions::default(),
        )
        .unwrap()
        .skin;
        for (w, &f) in worst.iter().zip(&capture.test_frames) {
            assert_eq!(w.frame, f);
            let posed = prepared.pose_frame(&capture, f).unwrap();
            let truth = capture.evaluation_gt_mesh(f).unwrap();
            let max = crate::eval::max_vertex_distance(&posed, &truth).unwrap();
            assert!((w.distance_cm - 100.0 * max).abs() < 1e-9, "{w:?} vs {max}");
            // The reported influences are bone heat's at that vertex, largest first.
            let (j, wt) = heat.influences(w.vertex);
            let total: f32 = w.influences.iter().map(|i| i.1).sum();
            assert!((total - 1.0).abs() < 1e-4, "{w:?}");
            assert!(w.influences.windows(2).all(|p| p[0].1 >= p[1].1));
            for &(joint, weight) in &w.influences {
                let k = j.iter().position(|&x| x == joint).unwrap();
                assert_eq!(wt[k], weight);
            }
            assert!(!w.true_influences.is_empty());
        }
        // Under the oracle the method's joints are the truth's.
        for w in worst_vertices(&capture, &Skinning::Oracle, WorstMeasure::VertexToVertex).unwrap()
        {
            assert_eq!(w.influences, w.true_influences);
        }
        let md =
            worst_vertices_markdown(&capture, "initial", WorstMeasure::VertexToVertex, &worst, 2);
        assert_eq!(
            md.lines().filter(|l| l.starts_with("| ")).count(),
            worst.len() + 2
        );
        // Off the surface: the frame's largest distance to the true surface, which is the
        // evaluation's per-frame figure, and never more than the vertex-to-vertex one.
        let off = worst_vertices(&capture, &Skinning::Initial, WorstMeasure::OffSurface).unwrap();
        let frames =
            crate::eval::evaluate_frames(&capture, &crate::eval::EvalOptions::default(), |f| {
                prepared.pose_frame(&capture, f)
            })
            .unwrap();
        for ((o, w), f) in off.iter().zip(&worst).zip(&frames) {
            assert!(
                (o.distance_cm - f.max_off_surface_cm).abs() < 1e-6,
                "{o:?} vs {f:?}"
            );
            assert!(o.distance_cm <= w.distance_cm + 1e-6, "{o:?} vs {w:?}");
        }
        assert!(
            worst_vertices_markdown(&capture, "initial", WorstMeasure::OffSurface, &off, 2)
                .contains("off the true surface: initial")
        );
    }

    #[test]
    fn the_truth_scores_lower_than_bone_heat_on_its_own_masks() {
        let (_dir, capture) = tiny_capture();
        let rows = terms_on_truth(&capture, &[Skinning::Initial], 1).unwrap();
        assert_eq!(rows[0].0, "truth");
        assert_eq!(rows[1].0, "initial");
        let (truth, initial) = (rows[0].1, rows[1].1);
        assert!(truth.views > 0 && truth.views == initial.views);
        assert!(
            truth.silhouette_px < initial.silhouette_px && truth.iou > initial.iou,
            "{truth} vs {initial}"
        );
        let md = diagnostics_markdown(&[], &[], &rows, 1);
        assert!(md.contains("| truth |") && md.contains("| initial |"));
        // The truth leaves its exact masks no margin; masks grown by a pixel lie a pixel
        // outside it.
        assert!(truth.outline_offset_px.abs() < 0.2, "{truth}");
        let grown = tempfile::tempdir().unwrap();
        let config = crate::synth::SynthConfig {
            mask_offset_px: 1.0,
            ..crate::synth::SynthConfig::tiny()
        };
        crate::synth::synthesize(grown.path(), &config).unwrap();
        let rows = terms_on_truth(&load_capture(grown.path()).unwrap(), &[], 1).unwrap();
        let margin = rows[0].1.outline_offset_px;
        assert!((margin - 1.0).abs() < 0.25, "{}", rows[0].1);
    }
    #[test]
    fn a_template_split_at_every_face_scores_as_the_unsplit_one() {
        // Cut at every face, every edge of the mesh is a seam: scored on the split mesh, every
        // vertex would lie on an open border and count for the outline.
        let (_dir, capture) = tiny_capture();
        let initial = initial_weights(&capture).unwrap();
        let (split, split_initial, _) =
            crate::train::data::tests::split_capture(&capture, &initial);
        let split = Capture {
            initial_weights: Some(split_initial),
            ..split
        };
        let whole = terms_on_truth(&capture, &[Skinning::Initial], 1).unwrap();
        let cut = terms_on_truth(&split, &[Skinning::Initial], 1).unwrap();
        // The capture's ground truth is for the unsplit vertices, so the split one has no truth
        // row.
        assert_eq!(cut.len(), 1);
        let (whole, cut) = (whole[1].1, cut[0].1);
        assert_eq!(whole.views, cut.views);
        for (a, b) in [
            (whole.silhouette_px, cut.silhouette_px),
            (whole.boundary_px, cut.boundary_px),
            (whole.contour_px, cut.contour_px),
            (whole.iou, cut.iou),
        ] {
            assert!((a - b).abs() < 1e-3 * a.abs().max(1.0), "{whole} vs {cut}");
        }
    }

    #[test]
    fn copies_of_a_position_share_the_count_of_the_welded_vertex() {
        // A UV sphere seen from its side, and the same sphere split into one copy of each
        // corner per triangle (a mesh cut at every face, as glTF files cut at their seams):
        // every copy gets the count of the sphere's vertex at its position.
        let (positions, triangles) =
            crate::losses::silhouette::tests::uv_sphere(12, 24, 1.0, Vec3::ZERO);
        let cameras = [
            Camera::look_at("side", 64, 64, 1.0, Vec3::X * 5.0, Vec3::ZERO, Vec3::Y),
            Camera::look_at("top", 64, 64, 1.0, Vec3::Y * 5.0, Vec3::ZERO, Vec3::Z),
        ];
        let whole =
            outline_views_by_position(&positions, &triangles, &cameras, [Some(positions.clone())])
                .unwrap();
        let (mut split_positions, mut split_triangles, mut of_split) = (vec![], vec![], vec![]);
        for t in &triangles {
            let base = split_positions.len() as u32;
            for &i in t {
                split_positions.push(positions[i as usize]);
                of_split.push(i as usize);
            }
            split_triangles.push([base, base + 1, base + 2]);
        }
        let split = outline_views_by_position(
            &split_positions,
            &split_triangles,
            &cameras,
            [Some(split_positions.clone())],
        )
        .unwrap();
        assert!(whole.iter().filter(|&&n| n > 0).count() > 24, "{whole:?}");
        for (k, &i) in of_split.iter().enumerate() {
            assert_eq!(split[k], whole[i], "copy {k} of vertex {i}");
        }
        // A missing mesh gives no counts.
        assert!(outline_views_by_position(&positions, &triangles, &cameras, [None]).is_none());
    }

    #[test]
    fn outline_views_count_vertices_on_a_true_outline_and_split_the_errors() {
        let (_dir, capture) = tiny_capture();
        let views = truth_outline_views(&capture).unwrap();
        let v = capture.template.vertex_count();
        assert_eq!(views.len(), v);
        let total = (capture.train_frames.len() * capture.rig.cameras.len()) as u32;
        assert!(views.iter().all(|&n| n <= total));
        // Independently of the mesh's contour generators: a counted vertex projects onto the
        // mask's outline (within a pixel) in at least one training view.
        let (data, truth) = frames_with_truth(&capture, 1).unwrap();
        let truth = truth.unwrap();
        for (i, _) in views.iter().enumerate().filter(|&(_, &n)| n > 0) {
            let nearest = data
                .frames
                .iter()
                .zip(&truth)
                .flat_map(|(frame, posed)| {
                    frame.views.iter().filter_map(move |view| {
                        let uv = view.camera.project(posed[i])?;
                        Some(view.target.outline.distance(uv).0)
                    })
                })
                .fold(f32::INFINITY, f32::min);
            assert!(nearest < 1.0, "vertex {i}: {nearest} px from every outline");
        }
        // The skirt hides part of the legs from every view, and the body's outline shows the
        // rest: both groups are there.
        let seen = views.iter().filter(|&&n| n > 0).count();
        assert!(seen > v / 10 && seen < v, "{seen} of {v}");
        // The two groups partition the vertices, and their vertex-weighted mean is the mean
        // over every vertex (the per-part split's, which partitions them too).
        let split = outline_errors(&capture, &Skinning::Initial, &views).unwrap();
        let names: Vec<_> = split.iter().map(|p| p.part).collect();
        assert_eq!(names, [SEEN, HIDDEN], "{split:?}");
        assert_eq!(split.iter().map(|p| p.vertices).sum::<usize>(), v);
        let mean = |rows: &[PartError]| {
            rows.iter()
                .map(|p| p.mean_cm * p.vertices as f64)
                .sum::<f64>()
                / v as f64
        };
        let parts = part_errors(&capture, &Skinning::Initial).unwrap();
        assert!(
            (mean(&split) - mean(&parts)).abs() < 1e-9,
            "{split:?} vs {parts:?}"
        );
        let md = diagnostics_markdown(&[], &[("initial".into(), split)], &[], 1);
        assert!(md.contains(SEEN) && md.contains(HIDDEN), "{md}");
    }
}
