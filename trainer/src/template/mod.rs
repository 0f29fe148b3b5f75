//! `trainer template`: a canonical template (mesh, vertex colours, part labels, the skeleton
//! placed in it) reconstructed from one frame of a capture's own images, so that
//! `video → template → bone heat → SkinNet` needs no artist's mesh (paper §3.1).
//!
//! # Method and why
//!
//! The paper reconstructs the first frame with an implicit surface (NeuS-like) and Marching
//! Cubes. Training such a field takes GPU-hours; on two cores it is out of reach, and its
//! advantage over the masks alone is the concavities. We use what the masks give exactly and
//! cheaply:
//!
//! 1. **Visual hull as a signed distance field** ([`hull`]): the largest over the cameras of the
//!    signed distance to each silhouette cone, from the sub-pixel 50 % coverage outline of each
//!    mask, sampled on a grid of `resolution` cells along the longest side of the occupied box
//!    (found first on a coarse lattice inside a box around the posed skeleton). Distances
//!    rather than 0/1 occupancy let marching place the surface to a fraction of a cell.
//! 2. **Marching tetrahedra** (the synthetic body's mesher; no ambiguous cases, so the surface
//!    is closed), the largest connected piece kept ([`clean`]), simplified to the requested
//!    vertex count with meshoptimizer (the project's one simplifier), area-weighted normals.
//! 3. **Vertex colours** from the images that see each vertex, weighted by `cos²` of the
//!    viewing angle, with a depth test against the mesh ([`attributes`]). The colours keep the
//!    frame's shading (the appearance stages separate albedo from shading later).
//! 4. **Part labels** by a `cos²`-weighted vote over the capture's label images of the frame,
//!    when it has them.
//! 5. **The skeleton** is the capture's, with its bind pose set to the frame's pose, so the mesh
//!    is its own canonical pose: the frame's joint transforms are the bind transforms, and every
//!    other frame's pose (absolute local transforms) is unchanged. When the frame is the
//!    capture's canonical (calibration) frame in the bind pose, nothing moves at all. Joint
//!    limits of Euler DOFs stay as they are, i.e. relative to the new bind pose.
//!
//! What the hull cannot do: recover concavities no silhouette reveals, and separate parts that
//! touch in the frame (arms held against the body); pick a frame with open limbs (`--frame`).

pub mod attributes;
pub mod clean;
pub mod hull;

use std::time::Instant;

use glam::{Mat4, Vec3};
use skinfield_formats::capture::{Capture, CaptureError, CaptureImage, LabelImage, MANIFEST_FILE};
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_formats::{PartLabel, Skeleton, SkeletonError, Template};
use skinfield_runtime::resample::{Target, simplify_subset_locked};

use crate::losses::silhouette::OutlineError;
use attributes::{Visibility, vertex_colors, vote_labels};
use hull::{HullView, mesh_hull, occupied_box};

/// Samples per axis of the coarse lattice that finds the subject's box.
const COARSE_SAMPLES: usize = 48;
/// Depth-test tolerance of the attribute pass, in grid cells.
const DEPTH_TOLERANCE_CELLS: f32 = 1.5;

/// What to reconstruct.
#[derive(Clone, Debug, PartialEq)]
pub struct TemplateOptions {
    /// The frame; `None` takes the capture's canonical frame ([`Capture::canonical_frame`]).
    pub frame: Option<usize>,
    /// Grid cells along the longest side of the subject's box.
    pub resolution: usize,
    /// Vertex count of the simplified mesh (about).
    pub vertices: usize,
    /// Use only this many of the capture's cameras, evenly spread over its list; `None` uses all.
    pub cameras: Option<usize>,
}

impl Default for TemplateOptions {
    fn default() -> Self {
        Self {
            frame: None,
            resolution: 160,
            vertices: 10_000,
            cameras: None,
        }
    }
}

/// Why a template could not be reconstructed.
#[derive(Debug, thiserror::Error)]
pub enum TemplateError {
    /// Reading the capture failed.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// A mask has no outline.
    #[error("camera `{camera}`, frame {frame}: mask: {source}")]
    Mask {
        /// The camera's name.
        camera: String,
        /// The frame.
        frame: usize,
        /// What is wrong.
        source: OutlineError,
    },
    /// No point is inside every silhouette.
    #[error(
        "frame {frame}: no point is inside every camera's silhouette (cameras that do not see the whole subject, or masks of different frames?)"
    )]
    EmptyHull {
        /// The frame.
        frame: usize,
    },
    /// An option is out of range.
    #[error("option `{field}`: {reason}")]
    Option {
        /// The option.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The skeleton could not be re-bound to the frame's pose.
    #[error("skeleton: {0}")]
    Skeleton(#[from] SkeletonError),
}

/// Seconds per step.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StepSeconds {
    /// Reading masks and tracing their outlines.
    pub masks: f64,
    /// The hull field on the grid, marching, the largest piece and simplification.
    pub hull: f64,
    /// Visibility, colours and labels.
    pub attributes: f64,
}

/// What [`reconstruct`] measured along the way.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TemplateReport {
    /// The frame reconstructed.
    pub frame: usize,
    /// Indices of the cameras used.
    pub cameras: Vec<usize>,
    /// Grid cell (metres).
    pub cell: f32,
    /// Vertices marching produced (before simplification).
    pub marched_vertices: usize,
    /// Simplification passes until the mesh was closed (at most `SIMPLIFY_ATTEMPTS`).
    pub simplify_passes: usize,
    /// Whether the final mesh is closed and consistently oriented.
    pub closed: bool,
    /// Euler characteristic of the final mesh (2 for a sphere-like surface).
    pub euler_characteristic: i64,
    /// Vertices no camera sees (colours filled from neighbours).
    pub unseen_vertices: usize,
    /// Vertices no label image voted for (`None` without labels).
    pub unvoted_vertices: Option<usize>,
    /// Seconds per step.
    pub seconds: StepSeconds,
}

/// A reconstructed template with the skeleton bound to it.
#[derive(Clone, Debug)]
pub struct Reconstruction {
    /// The mesh, with colours and (when the capture has label images) part labels.
    pub template: Template,
    /// The capture's skeleton with its bind pose set to the frame's pose.
    pub skeleton: Skeleton,
    /// What was measured.
    pub report: TemplateReport,
}

/// A closed mesh of the visual hull of `views`, searched inside `search`: `resolution` cells
/// along the longest side of the occupied box, simplified to about `vertices`. Returns the
/// template (positions, normals, triangles), the cell size, the marched vertex count and the
/// simplification passes.
pub fn reconstruct_surface(
    views: &[HullView],
    search: (Vec3, Vec3),
    resolution: usize,
    vertices: usize,
) -> Option<(Template, f32, usize, usize)> {
    let (min, max) = occupied_box(views, search, COARSE_SAMPLES)?;
    let cell = (max - min).max_element() / resolution as f32;
    let (positions, triangles) = mesh_hull(views, min, max, cell);
    let (positions, triangles) = clean::largest_component(&positions, &triangles);
    if triangles.is_empty() {
        return None;
    }
    let marched = positions.len();
    let (positions, triangles, passes) =
        simplify_closed(&positions, &triangles, vertices, 3.0 * cell);
    let normals = area_weighted_normals(&positions, &triangles);
    let template = Template {
        positions,
        normals,
        triangles,
        uvs: None,
        colors: None,
        part_labels: None,
    };
    Some((template, cell, marched, passes))
}

/// Simplification attempts before a mesh that is not closed is accepted.
const SIMPLIFY_ATTEMPTS: usize = 8;

/// Simplifies a closed mesh to about `vertices`, keeping it closed. meshoptimizer's edge
/// collapses do not check manifoldness, and in parts about two cells thick (hands, the top of
/// the head) a collapse now and then pinches the two sides onto one edge. After each pass the
/// input vertices within `radius` of a pinched edge are locked and the pass is repeated, so the
/// simplifier keeps those thin parts at the marched resolution; after [`SIMPLIFY_ATTEMPTS`] the
/// last result is kept (the report says whether the mesh is closed).
fn simplify_closed(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    vertices: usize,
    radius: f32,
) -> (Vec<Vec3>, Vec<[u32; 3]>, usize) {
    let mut locked = vec![false; positions.len()];
    let mut result = (Vec::new(), Vec::new());
    let mut passes = 0;
    for _ in 0..SIMPLIFY_ATTEMPTS {
        passes += 1;
        let (source, simplified) =
            simplify_subset_locked(positions, triangles, Target::Vertices(vertices), &locked);
        let pinched = clean::unpaired_edge_vertices(&simplified);
        result = (
            source.iter().map(|&i| positions[i as usize]).collect(),
            simplified,
        );
        if pinched.is_empty() {
            break;
        }
        let centres: Vec<Vec3> = pinched.iter().map(|&v| result.0[v as usize]).collect();
        for (lock, p) in locked.iter_mut().zip(positions) {
            *lock |= centres
                .iter()
                .any(|c| c.distance_squared(*p) < radius * radius);
        }
    }
    (result.0, result.1, passes)
}

/// Gives `template` (posed as in `frame`) vertex colours from the images of `cameras` at
/// `frame`, and part labels from their label images when the capture has them for that frame
/// (see [`attributes`]); `tolerance` is the depth test's, in metres. Returns how many vertices no
/// camera sees and (with labels) how many got no vote.
pub fn paint(
    capture: &Capture,
    frame: usize,
    cameras: &[usize],
    template: &mut Template,
    tolerance: f32,
) -> Result<(usize, Option<usize>), CaptureError> {
    let visibility = cameras
        .iter()
        .map(|&c| {
            let camera = capture
                .rig
                .cameras
                .get(c)
                .ok_or_else(|| CaptureError::Invalid {
                    file: capture.dir.join(MANIFEST_FILE),
                    field: "cameras".into(),
                    reason: format!("camera index {c} out of range"),
                })?;
            Ok(Visibility::new(
                camera,
                &template.positions,
                &template.normals,
                &template.triangles,
                tolerance,
            ))
        })
        .collect::<Result<Vec<_>, CaptureError>>()?;
    let images = cameras
        .iter()
        .map(|&c| capture.load_image(c, frame))
        .collect::<Result<Vec<CaptureImage>, _>>()?;
    let n = template.vertex_count();
    let (colors, unseen) = vertex_colors(&visibility, &images, n, &template.triangles);
    template.colors = Some(colors);
    let Some(entry) = capture
        .manifest
        .labels
        .as_ref()
        .filter(|e| e.frames.contains(&frame))
    else {
        return Ok((unseen, None));
    };
    let labels = cameras
        .iter()
        .map(|&c| {
            capture
                .load_labels(c, frame)?
                .ok_or_else(|| CaptureError::Invalid {
                    file: capture.dir.join(MANIFEST_FILE),
                    field: "labels".into(),
                    reason: "the capture has no labels".into(),
                })
        })
        .collect::<Result<Vec<LabelImage>, CaptureError>>()?;
    // The template knows two parts (0 = skin, 1 = clothing); further labels do not vote.
    let parts = entry.palette.len().min(2);
    let (votes, unvoted) = vote_labels(&visibility, &labels, parts, n, &template.triangles);
    template.part_labels = Some(
        votes
            .into_iter()
            .map(|l| {
                if l == 1 {
                    PartLabel::Clothing
                } else {
                    PartLabel::Skin
                }
            })
            .collect(),
    );
    Ok((unseen, Some(unvoted)))
}

fn check(
    options: &TemplateOptions,
    capture: &Capture,
) -> Result<(usize, Vec<usize>), TemplateError> {
    let bad = |field, reason: String| Err(TemplateError::Option { field, reason });
    let frame = options.frame.unwrap_or_else(|| capture.canonical_frame());
    if frame >= capture.frame_count() {
        return bad(
            "frame",
            format!("{frame} >= the capture's {} frames", capture.frame_count()),
        );
    }
    if !(8..=1024).contains(&options.resolution) {
        return bad(
            "resolution",
            format!("{} (8 to 1024 cells)", options.resolution),
        );
    }
    if !(100..=1_000_000).contains(&options.vertices) {
        return bad(
            "vertices",
            format!("{} (100 to 1,000,000)", options.vertices),
        );
    }
    let n = capture.rig.cameras.len();
    let k = options.cameras.unwrap_or(n);
    if !(2..=n).contains(&k) {
        return bad("cameras", format!("{k} (2 to the capture's {n})"));
    }
    // Evenly spread over the list: the rigs list cameras ring by ring, around each ring.
    let cameras = (0..k).map(|i| i * n / k).collect();
    Ok((frame, cameras))
}

/// Reconstructs the template of `capture` (see the module docs).
pub fn reconstruct(
    capture: &Capture,
    options: &TemplateOptions,
) -> Result<Reconstruction, TemplateError> {
    capture.require_motion()?;
    let (frame, cameras) = check(options, capture)?;
    let mut seconds = StepSeconds::default();
    let start = Instant::now();
    let views = cameras
        .iter()
        .map(|&c| {
            let camera = capture.rig.cameras[c].clone();
            let mask = capture.load_mask(c, frame)?;
            HullView::new(camera.clone(), mask.coverage).map_err(|source| TemplateError::Mask {
                camera: camera.name,
                frame,
                source,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    seconds.masks = start.elapsed().as_secs_f64();

    let pose = &capture.poses[frame];
    let mut world = vec![Mat4::IDENTITY; capture.skeleton.len()];
    capture.skeleton.world_matrices(pose, &mut world)?;
    let joints: Vec<Vec3> = world.iter().map(|m| m.w_axis.truncate()).collect();
    let (lo, hi) = joints
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), &p| {
            (a.min(p), b.max(p))
        });
    // The mesh reaches past the joints (head, hands, feet, a skirt): search half the skeleton's
    // diagonal beyond them on every side, at least a metre-scale margin for a one-joint rig.
    let margin = 0.5 * (hi - lo).length().max(1e-3);
    let start = Instant::now();
    let (mut template, cell, marched, simplify_passes) = reconstruct_surface(
        &views,
        (lo - margin, hi + margin),
        options.resolution,
        options.vertices,
    )
    .ok_or(TemplateError::EmptyHull { frame })?;
    seconds.hull = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let (unseen_vertices, unvoted_vertices) = paint(
        capture,
        frame,
        &cameras,
        &mut template,
        DEPTH_TOLERANCE_CELLS * cell,
    )?;
    seconds.attributes = start.elapsed().as_secs_f64();

    let s = &capture.skeleton;
    let skeleton = Skeleton::new(
        s.names().to_vec(),
        s.parents().to_vec(),
        pose.locals.clone(),
        None,
        Some(s.dofs().to_vec()),
        s.base(),
    )?;
    let report = TemplateReport {
        frame,
        cameras,
        cell,
        marched_vertices: marched,
        simplify_passes,
        closed: clean::is_closed(&template.triangles),
        euler_characteristic: clean::euler_characteristic(&template.triangles),
        unseen_vertices,
        unvoted_vertices,
        seconds,
    };
    Ok(Reconstruction {
        template,
        skeleton,
        report,
    })
}

#[cfg(test)]
mod tests;
