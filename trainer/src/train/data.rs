//! Loading a capture folder into [`TrainData`]: initial weights, the training-resolution
//! template, and per training frame the skinning matrices, pose features and silhouette targets.
//!
//! SkinNet is a field over canonical space, so it is trained on a simplified template (the
//! default keeps about 2,500 of the built-in capture's 10k vertices: one iteration then costs a
//! quarter as much) and evaluated at full resolution. The simplified template keeps a *subset*
//! of the original vertices (meshoptimizer's edge-collapse simplifier only removes vertices), so
//! initial weights and part labels carry over exactly, without interpolation. SkinNet is still
//! queried at every full-resolution vertex over the iterations ([`super::queries`]).
//!
//! Only training frames are read; the capture's evaluation-only ground truth is never touched.

use std::sync::Arc;

use glam::Mat4;
use rayon::prelude::*;
use skinfield_formats::capture::{Capture, CaptureError};
use skinfield_formats::{Camera, Skeleton, StaticSkin, Template, UpAxis, pose_features};
use skinfield_runtime::resample::{SourcePoint, Target, simplify, transfer_attributes};

use super::queries::QueryCells;
use crate::losses::silhouette::SilhouetteTarget;

/// One camera view of a training frame.
#[derive(Clone, Debug)]
pub struct View {
    /// The calibrated camera.
    pub camera: Camera,
    /// The outline of the foreground mask and points along it.
    pub target: SilhouetteTarget,
    /// The mask's coverage (row-major, `[0, 1]`; validation's IoU).
    pub coverage: Arc<[f32]>,
}

/// One training frame.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Skinning matrices (`world · inverse_bind`), one per joint.
    pub skinning: Vec<Mat4>,
    /// Pose features θ̃ (`3J`).
    pub pose_features: Vec<f32>,
    /// The views that see it.
    pub views: Vec<View>,
}

/// Everything stage 1 trains on.
#[derive(Clone, Debug)]
pub struct TrainData {
    /// The skeleton (its joint order is SkinNet's output order).
    pub skeleton: Skeleton,
    /// The (possibly reduced-resolution) template.
    pub template: Template,
    /// Per vertex of `template`, the vertex of the template [`train_data`] was given that it is
    /// (the first copy of its position where a split template was welded): how a mesh posed on
    /// that template is read on this one. ([`static_train_data`] gives `train_data` the weld, so
    /// there it indexes the weld; its [`WeldedTemplate`] maps back to the copies.)
    pub source: Vec<u32>,
    /// Initial weights, dense `[V, J]` row-major (bone heat or the asset's).
    pub init_weights: Vec<f32>,
    /// Training frames.
    pub frames: Vec<Frame>,
    /// Full-resolution query points of the training vertices (`None`: query the training
    /// vertices themselves, e.g. at full resolution); see [`super::queries`].
    pub queries: Option<QueryCells>,
    /// The world's up axis the pose features remove the heading about; recorded in the
    /// exported `.skf` so the runtime computes the same features.
    pub up_axis: UpAxis,
}

/// How a capture is turned into training data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DataOptions {
    /// Vertex count of the training template (about; `0` keeps the full template).
    pub train_vertices: usize,
    /// Use only the first `cameras` cameras (`0` = all).
    pub cameras: usize,
}

impl Default for DataOptions {
    fn default() -> Self {
        Self {
            train_vertices: 2500,
            cameras: 0,
        }
    }
}

/// Why a capture could not be turned into training data.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// A capture file is missing or malformed.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// The initial weights could not be computed.
    #[error("bone heat on the capture's template: {0}")]
    Heat(#[from] crate::heat::HeatError),
    /// The data do not fit together (names the field).
    #[error("{0}")]
    Inconsistent(String),
}

/// The capture's initial weights, or bone heat (default options) on its template when it ships
/// none — the same weights `trainer eval --weights initial` scores.
pub fn initial_weights(capture: &Capture) -> Result<StaticSkin, DataError> {
    match &capture.initial_weights {
        Some(skin) => Ok(skin.clone()),
        None => Ok(crate::heat::bone_heat(
            &capture.template,
            &capture.skeleton,
            &crate::heat::HeatOptions::default(),
        )?
        .skin),
    }
}

/// The template SkinNet trains on: `template` simplified to about `target` vertices (the
/// runtime's simplifier, so the training template is what an engine's load-time LOD would be;
/// `target` 0 keeps every vertex); returns the new template and, for each of its vertices, the
/// index of the original vertex it is.
///
/// A template split into copies of its positions ([`split_template_weld`]: at its faces, UV
/// charts or materials, as most exported characters are) is welded first, at any target. On the
/// split mesh every seam is an open border: the silhouette loss's outline test then drops or
/// adds copies where a seam meets the outline (of the vertices some true training outline
/// shows, it missed a quarter on the zoo's Fox and added a tenth on CesiumMan), and each copy is
/// one more row of the network for the same point. SkinNet is a function of position, so the copies' weights are the weld's.
///
/// Otherwise, meshoptimizer never collapses a vertex where more than two copies of one position
/// meet (a complex seam), so a mesh with a few such seams may not simplify to its target: when
/// the simplifier ends more than [`SEAM_SLACK`] times the target, the template is welded by
/// exact position first ([`weld_template`]) and that is simplified (or kept, when it is already
/// at or below the target). Welding is not the default for the other meshes because it also
/// joins surfaces a mesh keeps apart on purpose where they touch (the built-in skirt's waistband
/// lies on the body), and where the simplifier copes there is nothing to gain.
#[must_use]
pub fn simplify_template(template: &Template, target: usize) -> (Template, Vec<u32>) {
    simplify_on_weld(template, split_template_weld(template).as_ref(), target)
}

/// [`simplify_template`] given the template's [`split_template_weld`] (`None`: not split).
fn simplify_on_weld(
    template: &Template,
    weld: Option<&WeldedTemplate>,
    target: usize,
) -> (Template, Vec<u32>) {
    let Some(weld) = weld else {
        return simplify_unsplit(template, target);
    };
    let (simplified, source) = simplify_unsplit(&weld.template, target);
    let source = source
        .iter()
        .map(|&w| weld.representative[w as usize])
        .collect();
    (simplified, source)
}

/// The number of vertices SkinNet trains on at full resolution ([`simplify_template`] with
/// target 0): the positions of a split template, every vertex of the others.
#[must_use]
pub fn full_resolution_vertex_count(template: &Template) -> usize {
    vertex_count_on_weld(template, split_template_weld(template).as_ref())
}

/// [`full_resolution_vertex_count`] given the template's [`split_template_weld`].
fn vertex_count_on_weld(template: &Template, weld: Option<&WeldedTemplate>) -> usize {
    weld.map_or(template.vertex_count(), |w| w.template.vertex_count())
}

/// [`simplify_template`] for a template not split into copies of its positions.
fn simplify_unsplit(template: &Template, target: usize) -> (Template, Vec<u32>) {
    let n = template.vertex_count();
    let identity = || (template.clone(), (0..n as u32).collect());
    if target == 0 || target >= n {
        return identity();
    }
    // The capture loader validated the template and the target is below its count, so the
    // simplifier has nothing to refuse; an invalid template trains at full resolution.
    let simplified = |t: &Template| {
        simplify(t, Target::Vertices(target)).ok().map(|r| {
            let source: Vec<u32> = r.source.iter().map(|p| p.vertices[0]).collect();
            (r.template, source)
        })
    };
    let direct = simplified(template).unwrap_or_else(identity);
    if direct.1.len() as f64 <= target as f64 * SEAM_SLACK {
        return direct;
    }
    let Some(WeldedTemplate {
        template: welded,
        representative,
        ..
    }) = weld_template(template)
    else {
        return direct;
    };
    let (simplified, source) = if welded.vertex_count() > target {
        match simplified(&welded) {
            Some(r) => r,
            None => return direct,
        }
    } else {
        let all = (0..welded.vertex_count() as u32).collect();
        (welded, all)
    };
    let source = source.iter().map(|&w| representative[w as usize]).collect();
    (simplified, source)
}

/// How far above its target (as a factor) the simplifier may end before the template is welded
/// first.
pub const SEAM_SLACK: f64 = 1.25;

/// A template welded by exact position ([`weld_template`]).
#[derive(Clone, Debug)]
pub struct WeldedTemplate {
    /// The welded template.
    pub template: Template,
    /// Per welded vertex, the original vertex it copies (the first of its copies).
    pub representative: Vec<u32>,
    /// Per original vertex, the welded vertex it became.
    pub of_input: Vec<u32>,
}

impl WeldedTemplate {
    /// Per-vertex rows of the original template (`joints` each) reduced to the welded vertices:
    /// each takes its representative's row.
    #[must_use]
    pub fn restrict(&self, rows: &[f32], joints: usize) -> Vec<f32> {
        gather_rows(rows, joints, &self.representative)
    }

    /// Per-welded-vertex rows (`joints` each) copied to every original vertex.
    #[must_use]
    pub fn expand(&self, rows: &[f32], joints: usize) -> Vec<f32> {
        gather_rows(rows, joints, &self.of_input)
    }
}

/// Rows `which` of `rows` (`width` floats each), in that order.
fn gather_rows(rows: &[f32], width: usize, which: &[u32]) -> Vec<f32> {
    which
        .iter()
        .flat_map(|&r| {
            rows[r as usize * width..(r as usize + 1) * width]
                .iter()
                .copied()
        })
        .collect()
}

/// `template` with the vertices at equal positions merged into the first of them: its
/// attributes are that vertex's, normals are recomputed from the welded triangles (a split
/// mesh's copies carry one normal per face), and triangles that collapse or repeat are dropped.
/// `None` when the result is not a valid template.
#[must_use]
pub fn weld_template(template: &Template) -> Option<WeldedTemplate> {
    let welded = crate::heat::weld::weld(&template.positions, &template.triangles, 0.0);
    let representative = welded.representative;
    let positions: Vec<glam::Vec3> = representative
        .iter()
        .map(|&i| template.positions[i as usize])
        .collect();
    let normals = skinfield_formats::mesh::area_weighted_normals(&positions, &welded.triangles);
    let points: Vec<SourcePoint> = representative
        .iter()
        .map(|&i| SourcePoint::vertex(i))
        .collect();
    let t = transfer_attributes(
        template,
        &points,
        positions,
        welded.triangles,
        Some(normals),
    );
    Some(WeldedTemplate {
        template: t.ok()?,
        representative,
        of_input: welded.of_input,
    })
}

/// The weld of a template split into copies of its positions (at its faces or UV charts: more
/// than [`SPLIT_COPIES`] vertices per position), which SkinNet ([`simplify_template`]) and the
/// static baseline ([`static_train_data`]) train on. `None` keeps the template.
///
/// Static weights are free per vertex and the Laplacian couples only the vertices of one
/// triangle, so on a mesh split at every face the copies of a position would drift apart and
/// the surface tear wherever that explains a silhouette (the Witch's static baseline ended worse
/// than bone heat); SkinNet, a function of position, gives copies the same weights, but the
/// silhouette loss's outline test sees a seam as an open border. Welding is not used for meshes
/// with a few coincident vertices only (the built-in skirt's waistband lies on the body), for
/// the reason given at [`simplify_template`].
#[must_use]
pub fn split_template_weld(template: &Template) -> Option<WeldedTemplate> {
    let n = template.vertex_count() as f64;
    weld_template(template).filter(|w| w.template.vertex_count() as f64 * SPLIT_COPIES < n)
}

/// Vertices per distinct position above which a template counts as split into copies (a fifth
/// of its vertices or more are copies): the zoo's split meshes have 1.4–6 (CesiumMan, the Fox),
/// the built-in character 1.0.
pub const SPLIT_COPIES: f64 = 1.25;

/// The static baseline's training data: [`train_data`] at full resolution, on the weld of a
/// template split into copies of its positions ([`split_template_weld`]; the initial weights
/// of each position are its first copy's), with that weld, whose [`WeldedTemplate::expand`]
/// gives the trained weights back to every copy.
pub fn static_train_data(
    capture: &Capture,
    initial: &StaticSkin,
) -> Result<(TrainData, Option<WeldedTemplate>), DataError> {
    let options = DataOptions {
        train_vertices: 0,
        ..DataOptions::default()
    };
    let Some(welded) = split_template_weld(&capture.template) else {
        return Ok((train_data(capture, initial, &options)?, None));
    };
    // The weld reads the initial weights by vertex before `train_data` would check them.
    check_initial(capture, initial)?;
    let j = capture.skeleton.len();
    let first_copies = welded.restrict(&initial.to_dense(), j);
    let initial = StaticSkin::from_dense(&first_copies, j)
        .map_err(|e| DataError::Inconsistent(format!("initial weights of the weld: {e}")))?;
    let capture = Capture {
        template: welded.template.clone(),
        initial_weights: Some(initial.clone()),
        ..capture.clone()
    };
    Ok((train_data(&capture, &initial, &options)?, Some(welded)))
}

/// Initial weights must cover `capture`'s template and skeleton.
fn check_initial(capture: &Capture, initial: &StaticSkin) -> Result<(), DataError> {
    let (n, j) = (capture.template.vertex_count(), capture.skeleton.len());
    if initial.vertex_count() != n || initial.joint_count() != j {
        return Err(DataError::Inconsistent(format!(
            "initial weights are {} vertices × {} joints, the template has {n} vertices and the \
             skeleton {j} joints",
            initial.vertex_count(),
            initial.joint_count()
        )));
    }
    Ok(())
}

/// Builds the stage-1 training data from `capture`'s training frames.
pub fn train_data(
    capture: &Capture,
    initial: &StaticSkin,
    options: &DataOptions,
) -> Result<TrainData, DataError> {
    capture.require_motion()?;
    let skeleton = capture.skeleton.clone();
    let j = skeleton.len();
    check_initial(capture, initial)?;
    let full = &capture.template;
    // Welded once: the simplification and the full-resolution count both need it.
    let weld = split_template_weld(full);
    let (template, source) = simplify_on_weld(full, weld.as_ref(), options.train_vertices);
    let full_count = vertex_count_on_weld(full, weld.as_ref());
    let dense = initial.to_dense();
    // Query cells stand in for the vertices a simplification removed; a weld removed none.
    let queries = if template.vertex_count() < full_count {
        let normals = if full.normals.len() == full.vertex_count() {
            full.normals.clone()
        } else {
            skinfield_formats::mesh::area_weighted_normals(&full.positions, &full.triangles)
        };
        QueryCells::new(&full.positions, &normals, &dense, &source)
    } else {
        None
    };
    let init_weights = source
        .iter()
        .flat_map(|&v| dense[v as usize * j..(v as usize + 1) * j].iter().copied())
        .collect();
    let cameras = match options.cameras {
        0 => capture.rig.cameras.len(),
        c => c.min(capture.rig.cameras.len()),
    };
    let mut frames = Vec::with_capacity(capture.train_frames.len());
    for &f in &capture.train_frames {
        let pose = &capture.poses[f];
        let mut skinning = vec![Mat4::IDENTITY; j];
        skeleton
            .skinning_matrices(pose, &mut skinning)
            .map_err(|e| DataError::Inconsistent(format!("motion frame {f}: {e}")))?;
        let mut features = vec![0.0; 3 * j];
        pose_features(&skeleton, pose, capture.up_axis, &mut features)
            .map_err(|e| DataError::Inconsistent(format!("motion frame {f}: {e}")))?;
        // Each view's outline is traced from its mask's coverage (sub-pixel; binary masks work
        // too), in parallel.
        let views = capture.rig.cameras[..cameras]
            .par_iter()
            .enumerate()
            .map(|(c, camera)| -> Result<View, DataError> {
                let mask = capture.load_mask(c, f)?;
                let target = SilhouetteTarget::from_coverage(
                    mask.width as usize,
                    mask.height as usize,
                    &mask.coverage,
                )
                .map_err(|e| {
                    DataError::Inconsistent(format!("{}: {e}", capture.mask_path(c, f).display()))
                })?;
                Ok(View {
                    camera: camera.clone(),
                    target,
                    coverage: mask.coverage.into(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        frames.push(Frame {
            skinning,
            pose_features: features,
            views,
        });
    }
    Ok(TrainData {
        skeleton,
        template,
        source,
        init_weights,
        frames,
        queries,
        up_axis: capture.up_axis,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A tiny synthetic capture (its folder kept alive by the returned guard) and its bone heat.
    fn tiny_capture() -> (tempfile::TempDir, Capture, StaticSkin) {
        let dir = tempfile::tempdir().unwrap();
        crate::synth::synthesize(dir.path(), &crate::synth::SynthConfig::tiny()).unwrap();
        let capture = skinfield_formats::capture::load_capture(dir.path()).unwrap();
        let initial = initial_weights(&capture).unwrap();
        (dir, capture, initial)
    }

    /// `capture` with its template split at every face ([`split_at_every_face`]), the initial
    /// weights carried to every copy, and the vertex of the original each copy is.
    pub(crate) fn split_capture(
        capture: &Capture,
        initial: &StaticSkin,
    ) -> (Capture, StaticSkin, Vec<u32>) {
        let j = capture.skeleton.len();
        let (split, corners) = split_at_every_face(&capture.template);
        let split_initial =
            StaticSkin::from_dense(&gather_rows(&initial.to_dense(), j, &corners), j).unwrap();
        let split_capture = Capture {
            template: split,
            ..capture.clone()
        };
        (split_capture, split_initial, corners)
    }

    /// `t` split at every face (each triangle its own three vertices, as exporters write
    /// flat-shaded or per-material meshes), and the vertex of `t` each split vertex copies.
    fn split_at_every_face(t: &Template) -> (Template, Vec<u32>) {
        let corners: Vec<u32> = t.triangles.iter().flatten().copied().collect();
        let pick = |i: &u32| *i as usize;
        let split = Template {
            positions: corners.iter().map(|i| t.positions[pick(i)]).collect(),
            normals: corners.iter().map(|i| t.normals[pick(i)]).collect(),
            triangles: (0..t.triangles.len() as u32)
                .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
                .collect(),
            uvs: t
                .uvs
                .as_ref()
                .map(|a| corners.iter().map(|i| a[pick(i)]).collect()),
            colors: t
                .colors
                .as_ref()
                .map(|a| corners.iter().map(|i| a[pick(i)]).collect()),
            part_labels: t
                .part_labels
                .as_ref()
                .map(|a| corners.iter().map(|i| a[pick(i)]).collect()),
        };
        split.validate().unwrap();
        (split, corners)
    }

    /// `simplified`'s vertex `k` is `original`'s vertex `source[k]`: same position, same part.
    fn assert_subset_of(simplified: &Template, source: &[u32], original: &Template) {
        assert_eq!(source.len(), simplified.vertex_count());
        for (k, &s) in source.iter().enumerate() {
            assert_eq!(simplified.positions[k], original.positions[s as usize]);
            assert_eq!(
                simplified.part_labels.as_ref().unwrap()[k],
                original.part_labels.as_ref().unwrap()[s as usize]
            );
        }
    }

    #[test]
    fn simplified_template_is_a_subset_with_its_attributes() {
        let cfg = crate::synth::SynthConfig::tiny();
        let character = crate::synth::build_character(&cfg).unwrap();
        let t = &character.template;
        let (r, source) = simplify_template(t, t.vertex_count() / 3);
        r.validate().unwrap();
        assert!(
            r.vertex_count() < t.vertex_count() / 2,
            "{} of {}",
            r.vertex_count(),
            t.vertex_count()
        );
        assert_subset_of(&r, &source, t);
        let (same, identity) = simplify_template(t, 0);
        assert_eq!(same, *t);
        assert_eq!(identity.len(), t.vertex_count());
    }

    /// A mesh split at every face (each triangle its own three vertices, as exporters write
    /// flat-shaded or per-material meshes) defeats meshoptimizer; the training template must
    /// still reach its target, as a subset of vertices at the original positions.
    #[test]
    fn a_mesh_split_at_every_face_is_welded_then_simplified() {
        let cfg = crate::synth::SynthConfig::tiny();
        let t = crate::synth::build_character(&cfg).unwrap().template;
        let (split, _) = split_at_every_face(&t);
        let target = t.vertex_count() / 3;
        let stuck = simplify(&split, Target::Vertices(target)).unwrap();
        assert!(
            stuck.template.vertex_count() as f64 > SEAM_SLACK * target as f64,
            "the direct simplifier was expected to be stuck: {} for a target of {target}",
            stuck.template.vertex_count()
        );
        let (r, source) = simplify_template(&split, target);
        r.validate().unwrap();
        assert!(
            r.vertex_count() as f64 <= SEAM_SLACK * target as f64,
            "{} vertices for a target of {target}",
            r.vertex_count()
        );
        assert_subset_of(&r, &source, &split);
        // Welded, the split mesh is the original one again: as many vertices and triangles.
        let welded = weld_template(&split).unwrap();
        assert_eq!(welded.template.vertex_count(), t.vertex_count());
        assert_eq!(welded.template.triangles.len(), t.triangles.len());
        assert!(
            welded
                .representative
                .iter()
                .all(|&i| (i as usize) < split.vertex_count())
        );
        // Every copy maps to the welded vertex at its position, which copies one of them.
        for (o, &w) in welded.of_input.iter().enumerate() {
            let w = w as usize;
            assert_eq!(welded.template.positions[w], split.positions[o]);
            assert_eq!(
                welded.of_input[welded.representative[w] as usize] as usize,
                w
            );
        }
        // The static baseline trains on the weld of a split mesh, and on the mesh itself
        // otherwise.
        let for_static = split_template_weld(&split).unwrap();
        assert_eq!(for_static.template.vertex_count(), t.vertex_count());
        assert!(split_template_weld(&t).is_none());
    }

    #[test]
    fn a_simplified_training_template_gets_query_cells_over_the_full_template() {
        let (_dir, capture, initial) = tiny_capture();
        let (n, j) = (capture.template.vertex_count(), capture.skeleton.len());
        let options = |train_vertices| DataOptions {
            train_vertices,
            ..DataOptions::default()
        };
        let data = train_data(&capture, &initial, &options(n / 3)).unwrap();
        let q = data.queries.as_ref().unwrap();
        assert_eq!(q.training_vertex_count(), data.template.vertex_count());
        assert_eq!(q.positions, capture.template.positions);
        let mut all = q.members.clone();
        all.sort_unstable();
        assert_eq!(all, (0..n as u32).collect::<Vec<_>>());
        assert_eq!(data.source, q.source);
        for (i, &s) in q.source.iter().enumerate() {
            let s = s as usize;
            assert_eq!(data.template.positions[i], capture.template.positions[s]);
            assert!(q.cell(i).contains(&(s as u32)));
            assert_eq!(
                q.init_weights[s * j..(s + 1) * j],
                data.init_weights[i * j..(i + 1) * j]
            );
        }
        // At full resolution every vertex is a training vertex: no cells.
        assert!(
            train_data(&capture, &initial, &options(0))
                .unwrap()
                .queries
                .is_none()
        );
    }

    /// The static baseline of a capture whose template is split at every face trains on the
    /// weld (the unsplit vertex count, each position starting from its first copy's weights) and
    /// gives every copy of a position the same weights back; an unsplit template trains as it is.
    #[test]
    fn the_static_baseline_of_a_split_template_trains_one_weight_set_per_position() {
        let (_dir, capture, initial) = tiny_capture();
        let (n, j) = (capture.template.vertex_count(), capture.skeleton.len());
        let (same, none) = static_train_data(&capture, &initial).unwrap();
        assert!(none.is_none());
        assert_eq!(same.template.vertex_count(), n);

        let dense = initial.to_dense();
        let (split_capture, split_initial, corners) = split_capture(&capture, &initial);
        let split = &split_capture.template;
        // Initial weights of another template: a typed error (they are read before
        // `train_data` would check them).
        assert!(matches!(
            static_train_data(&split_capture, &initial),
            Err(DataError::Inconsistent(_))
        ));
        let (data, welded) = static_train_data(&split_capture, &split_initial).unwrap();
        let welded = welded.unwrap();
        assert_eq!(data.template.vertex_count(), n);
        for (w, &first) in welded.representative.iter().enumerate() {
            let original = corners[first as usize] as usize;
            assert_eq!(
                data.template.positions[w],
                capture.template.positions[original]
            );
            // (The sparse skin renormalises: equal up to rounding.)
            let rows = data.init_weights[w * j..(w + 1) * j]
                .iter()
                .zip(&dense[original * j..(original + 1) * j]);
            for (got, want) in rows {
                assert!((got - want).abs() < 1e-6, "vertex {w}: {got} vs {want}");
            }
        }
        // Distinct rows per welded vertex: every copy gets its own position's row.
        let trained: Vec<f32> = (0..n * j).map(|i| i as f32).collect();
        let back = welded.expand(&trained, j);
        assert_eq!(back.len(), split.vertex_count() * j);
        for (copy, row) in back.chunks_exact(j).enumerate() {
            let w = row[0] as usize / j;
            assert_eq!(row, &trained[w * j..(w + 1) * j]);
            assert_eq!(data.template.positions[w], split.positions[copy]);
        }
    }

    /// SkinNet's training data of a capture whose template is split at every face: the weld at
    /// full resolution (no query cells: a weld removes no point of the surface), each position
    /// at its first copy's initial weights, and a simplification of the weld below it.
    #[test]
    fn skinnet_trains_a_split_template_on_its_weld() {
        let (_dir, capture, initial) = tiny_capture();
        let (n, j) = (capture.template.vertex_count(), capture.skeleton.len());
        let dense = initial.to_dense();
        let (split_capture, split_initial, corners) = split_capture(&capture, &initial);
        let split = &split_capture.template;
        assert_eq!(full_resolution_vertex_count(split), n);
        assert_eq!(full_resolution_vertex_count(&capture.template), n);
        let options = |train_vertices| DataOptions {
            train_vertices,
            ..DataOptions::default()
        };
        let full = train_data(&split_capture, &split_initial, &options(0)).unwrap();
        assert_eq!(full.template.vertex_count(), n);
        assert_eq!(
            full.template.triangles.len(),
            capture.template.triangles.len()
        );
        assert!(full.queries.is_none());
        // The data's own map to the split template is the weld's, as the simplifier gives it.
        let (_, source) = simplify_template(split, 0);
        assert_eq!(full.source, source);
        for (w, &copy) in full.source.iter().enumerate() {
            assert_eq!(full.template.positions[w], split.positions[copy as usize]);
            let original = corners[copy as usize] as usize;
            let rows = full.init_weights[w * j..(w + 1) * j]
                .iter()
                .zip(&dense[original * j..(original + 1) * j]);
            for (got, want) in rows {
                assert!((got - want).abs() < 1e-6, "vertex {w}: {got} vs {want}");
            }
        }
        // Simplified below the weld: query cells over every copy of the split mesh.
        let coarse = train_data(&split_capture, &split_initial, &options(n / 3)).unwrap();
        assert!(coarse.template.vertex_count() < n / 2);
        let q = coarse.queries.as_ref().unwrap();
        assert_eq!(q.positions.len(), split.vertex_count());
        assert_eq!(q.training_vertex_count(), coarse.template.vertex_count());
        assert_eq!(coarse.source, q.source);
        for (k, &copy) in coarse.source.iter().enumerate() {
            assert_eq!(coarse.template.positions[k], split.positions[copy as usize]);
        }
    }
}
