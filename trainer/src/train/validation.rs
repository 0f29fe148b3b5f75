//! Validation from images: how well a weight set explains silhouettes it was not trained on,
//! with no ground-truth geometry.
//!
//! A user cannot tell a broken model from a good one without ground truth, so the trainer holds
//! out a few training frames ([`super::TrainConfig::validation_frames`], spread evenly over the
//! capture's training frames), scores the posed training template against their masks every
//! [`super::TrainConfig::validation_every`] image iterations, keeps the best-scoring parameter
//! average for export, and `trainer train` refuses to write a model that explains the held-out
//! images worse than the initial weights do
//! ([`super::TrainConfig::refuse_worse_than_initial`]).
//!
//! Two figures per score, both from the same views:
//!
//! - the **silhouette distance** (pixels): the mean of the two terms of the image loss without
//!   its Huber robustifier, the boundary vertices' distance to the mask's outline and the
//!   outline's distance to the mesh's silhouette. It is what decides (lower is better): it moves
//!   with sub-pixel changes of the outline, where IoU hardly does;
//! - the **IoU** of the mesh's rasterised coverage (2 × 2 samples per pixel) with the mask's
//!   coverage, `Σ min / Σ max`: a coarse, familiar sanity figure.
//!
//! The training template is usually simplified, so neither figure is zero for perfect weights;
//! both are meant to compare weight sets on the same views.

use std::fmt;

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::{Frame, TrainData};
use crate::losses::silhouette::{EdgeTable, view_terms_with_offset};

/// Sub-pixel samples per axis of the model's coverage in the IoU.
const IOU_SAMPLES: u32 = 2;

/// How well one weight set explains a set of views.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ValidationScore {
    /// Mean distance of the boundary vertices to the mask outline (pixels).
    pub boundary_px: f64,
    /// Mean distance of the mask outline to the mesh silhouette (pixels).
    pub contour_px: f64,
    /// `(boundary_px + contour_px) / 2`: the figure that ranks weight sets.
    pub silhouette_px: f64,
    /// Intersection over union of the rasterised mesh with the mask coverage.
    pub iou: f64,
    /// How far the masks' outlines lie outside the mesh's, on average over their length
    /// (pixels; negative: inside): the masks' area minus the mesh's, over the masks' outline
    /// length. Near zero when the weights explain the masks; a model that cannot follow masks
    /// grown or shrunk by a biased segmentation keeps a share of that bias here.
    pub outline_offset_px: f64,
    /// Views scored.
    pub views: usize,
}

impl ValidationScore {
    /// Whether `self` explains the views worse than `other` (a larger silhouette distance).
    #[must_use]
    pub fn is_worse_than(&self, other: &Self) -> bool {
        self.silhouette_px > other.silhouette_px
    }
}

impl fmt::Display for ValidationScore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "silhouette {:.4} px (boundary {:.4}, contour {:.4}), IoU {:.5}, masks {:+.3} px \
             outside the mesh",
            self.silhouette_px, self.boundary_px, self.contour_px, self.iou, self.outline_offset_px
        )
    }
}

/// Validation scores of a finished run: the initial weights and the exported model, on the same
/// views.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidationReport {
    /// The initial weights (bone heat or the capture's).
    pub initial: ValidationScore,
    /// The weights about to be exported.
    pub model: ValidationScore,
    /// Held-out frames scored (0: too few training frames to hold any out; the training frames
    /// were scored instead).
    pub held_out_frames: usize,
    /// The mean learned outline offset over the cameras (pixels), when the run learned them
    /// ([`super::outline_offset`]); both scores' silhouette distances were measured against
    /// the masks moved by them.
    pub learned_offset_px: Option<f64>,
}

impl ValidationReport {
    /// Whether the model explains the validation views worse than its initialisation.
    #[must_use]
    pub fn model_is_worse(&self) -> bool {
        self.model.is_worse_than(&self.initial)
    }

    /// The guard every command that trains applies before writing a model: a model worse than
    /// its initialisation is refused (`refuse`), or let through with the refusal's message as a
    /// warning (`Ok(Some(..))`).
    pub fn guard(&self, refuse: bool) -> Result<Option<WorseThanInitial>, WorseThanInitial> {
        if !self.model_is_worse() {
            return Ok(None);
        }
        let worse = WorseThanInitial {
            model_px: self.model.silhouette_px,
            initial_px: self.initial.silhouette_px,
            held_out_frames: self.held_out_frames,
        };
        if refuse { Err(worse) } else { Ok(Some(worse)) }
    }

    /// The masks' margin over the trained model's outline when it exceeds
    /// [`MASK_MARGIN_WARNING_PX`] either way: the sign of masks grown or shrunk by their
    /// segmentation, which the silhouette loss (unbiased at the masks' 50 % outline) makes the
    /// weights follow at the truth's expense, and which the guard cannot see, being scored
    /// against the same masks. `None` when the model explains the masks' extent, or with
    /// learned outline offsets when those explain the margin to within the same tolerance.
    #[must_use]
    pub fn mask_margin(&self) -> Option<MaskMargin> {
        let px = self.model.outline_offset_px;
        let unexplained = px - self.learned_offset_px.unwrap_or(0.0);
        (unexplained.abs() > MASK_MARGIN_WARNING_PX).then_some(MaskMargin {
            model_px: px,
            initial_px: self.initial.outline_offset_px,
        })
    }
}

/// The margin of the masks over a trained model's outline above which training warns
/// ([`ValidationReport::mask_margin`]), in pixels. Models trained on exact masks leave
/// 0.02–0.06 px (the five zoo characters); masks grown or shrunk by one pixel leave about 0.7 px
/// (the built-in capture; `docs/experiments/fidelity.md`).
pub const MASK_MARGIN_WARNING_PX: f64 = 0.25;

/// The masks lie further outside (or inside) the trained model's outline than exact masks would
/// leave them ([`ValidationReport::mask_margin`]).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error(
    "the masks lie {model_px:+.2} px outside the trained model's outline on average (bone heat: \
     {initial_px:+.2} px; exact masks leave less than {MASK_MARGIN_WARNING_PX} px): masks that \
     their segmentation grew (or shrank) by a margin do this, and the weights then follow the \
     margin instead of the body; check the masks"
)]
pub struct MaskMargin {
    /// The margin over the trained model (pixels; negative: the masks lie inside).
    pub model_px: f64,
    /// The margin over the initial weights' outline.
    pub initial_px: f64,
}

/// A trained model explains the validation silhouettes worse than its initial weights.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error(
    "the trained model explains the validation silhouettes ({held_out_frames} held-out frames; \
     0: the training frames) worse than its initial weights: {model_px:.4} px against \
     {initial_px:.4} px mean distance to the mask outlines"
)]
pub struct WorseThanInitial {
    /// The model's silhouette distance (pixels).
    pub model_px: f64,
    /// The initial weights' silhouette distance (pixels).
    pub initial_px: f64,
    /// Held-out frames scored.
    pub held_out_frames: usize,
}

/// Which of `n` training frames `hold_out` takes for `count` validation frames: the middle
/// of each of `count` equal spans; none when fewer than four frames per held-out frame remain.
#[must_use]
pub fn held_out_indices(n: usize, count: usize) -> Vec<usize> {
    let count = count.min(n / 4);
    (0..count).map(|i| (2 * i + 1) * n / (2 * count)).collect()
}

/// Moves the frames [`held_out_indices`] picks out of `data.frames` and returns them (none:
/// the caller validates on the training frames).
pub(crate) fn hold_out(data: &mut TrainData, count: usize) -> Vec<Frame> {
    take_held_out(&mut data.frames, count)
}

/// Removes the items [`held_out_indices`] picks for `count` out of `items` and returns them in
/// order: what [`hold_out`] does to the frames, for anything listed per training frame (the
/// colour images of stages 2–4).
pub(crate) fn take_held_out<T>(items: &mut Vec<T>, count: usize) -> Vec<T> {
    let picked = held_out_indices(items.len(), count);
    let mut held: Vec<T> = picked.iter().rev().map(|&i| items.remove(i)).collect();
    held.reverse();
    held
}

/// Scores dense weights `weights` (`[frames.len()][V][J]`, one set per frame, row-major) on
/// every view of `frames`, posing `data`'s template by linear blend skinning; with learned
/// outline offsets (one per camera, [`super::outline_offset`]) the silhouette distances are
/// measured to the masks' outlines moved by them.
pub(crate) fn score(
    data: &TrainData,
    frames: &[Frame],
    weights: &[f32],
    edges: &EdgeTable,
    offsets: Option<&[f32]>,
) -> ValidationScore {
    let t = &data.template;
    let (v, j) = (t.vertex_count(), data.skeleton.len());
    debug_assert_eq!(weights.len(), frames.len() * v * j);
    let posed: Vec<Vec<Vec3>> = frames
        .par_iter()
        .enumerate()
        .map(|(b, frame)| {
            pose(
                &t.positions,
                &weights[b * v * j..(b + 1) * v * j],
                &frame.skinning,
            )
        })
        .collect();
    score_posed(frames, &posed, &t.triangles, edges, offsets)
}

/// Scores already posed meshes (`posed[b]` for `frames[b]`, triangles `triangles`, edge table
/// `edges`) on every view of `frames`: the same figures for any mesh, e.g. the ground truth.
/// `offsets` (one per camera, in the frames' view order) moves the mask outlines that the
/// silhouette distances are measured to ([`crate::losses::silhouette::view_terms_with_offset`]);
/// the IoU and the masks' margin always take the masks as they are.
#[must_use]
pub fn score_posed(
    frames: &[Frame],
    posed: &[Vec<Vec3>],
    triangles: &[[u32; 3]],
    edges: &EdgeTable,
    offsets: Option<&[f32]>,
) -> ValidationScore {
    struct ViewScore {
        boundary: f64,
        boundary_count: usize,
        contour: f64,
        contour_weight: f64,
        intersection: f64,
        union: f64,
        mask_area: f64,
        mesh_area: f64,
        outline_length: f64,
    }
    let per_view: Vec<ViewScore> = frames
        .par_iter()
        .enumerate()
        .flat_map(|(b, frame)| {
            let posed = &posed[b];
            frame
                .views
                .par_iter()
                .enumerate()
                .map(move |(c, view)| {
                    let offset = offsets.and_then(|o| o.get(c).copied()).unwrap_or(0.0);
                    let terms = view_terms_with_offset(
                        &view.camera,
                        &view.target,
                        posed,
                        triangles,
                        edges,
                        1.0,
                        offset,
                    );
                    let mesh = crate::raster::coverage(&view.camera, posed, triangles, IOU_SAMPLES);
                    let (mut intersection, mut union) = (0.0f64, 0.0f64);
                    let (mut mesh_area, mut mask_area) = (0.0f64, 0.0f64);
                    for (&a, &b) in mesh.iter().zip(view.coverage.iter()) {
                        intersection += f64::from(a.min(b));
                        union += f64::from(a.max(b));
                        mesh_area += f64::from(a);
                        mask_area += f64::from(b);
                    }
                    ViewScore {
                        boundary: terms.boundary_distance,
                        boundary_count: terms.boundary_count,
                        contour: terms.contour_distance,
                        contour_weight: terms.contour_weight,
                        intersection,
                        union,
                        mask_area,
                        mesh_area,
                        outline_length: view
                            .target
                            .contour_weights
                            .iter()
                            .map(|&w| f64::from(w))
                            .sum(),
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let sum = |f: fn(&ViewScore) -> f64| per_view.iter().map(f).sum::<f64>();
    let count = per_view.iter().map(|s| s.boundary_count).sum::<usize>();
    let boundary_px = sum(|s| s.boundary) / count.max(1) as f64;
    let contour_px = sum(|s| s.contour) / sum(|s| s.contour_weight).max(1e-12);
    ValidationScore {
        boundary_px,
        contour_px,
        silhouette_px: 0.5 * (boundary_px + contour_px),
        iou: sum(|s| s.intersection) / sum(|s| s.union).max(1e-12),
        outline_offset_px: (sum(|s| s.mask_area) - sum(|s| s.mesh_area))
            / sum(|s| s.outline_length).max(1e-12),
        views: per_view.len(),
    }
}

/// Linear blend skinning of `rest` with weights `w` (`[V][J]`) and `skinning` matrices.
pub(crate) fn pose(rest: &[Vec3], w: &[f32], skinning: &[Mat4]) -> Vec<Vec3> {
    let j = skinning.len();
    rest.iter()
        .zip(w.chunks_exact(j.max(1)))
        .map(|(&p, row)| {
            row.iter()
                .zip(skinning)
                .filter(|(w, _)| **w != 0.0)
                .map(|(&w, m)| m.transform_point3(p) * w)
                .sum()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::tests::{scene, tube_posed};

    #[test]
    fn pose_blends_the_transformed_points() {
        let rest = [Vec3::new(1.0, 2.0, 3.0)];
        let skinning = [
            Mat4::from_translation(Vec3::X),
            Mat4::from_rotation_z(std::f32::consts::FRAC_PI_2),
        ];
        let got = pose(&rest, &[0.25, 0.75], &skinning);
        let want = Vec3::new(2.0, 2.0, 3.0) * 0.25 + Vec3::new(-2.0, 1.0, 3.0) * 0.75;
        assert!((got[0] - want).length() < 1e-6, "{got:?} vs {want}");
    }

    #[test]
    fn worse_means_a_larger_silhouette_distance() {
        let a = ValidationScore {
            silhouette_px: 0.3,
            iou: 0.9,
            ..ValidationScore::default()
        };
        let b = ValidationScore {
            silhouette_px: 0.4,
            iou: 0.95,
            ..ValidationScore::default()
        };
        assert!(b.is_worse_than(&a) && !a.is_worse_than(&b) && !a.is_worse_than(&a));
    }

    /// The tube of the training tests posed with its true weights, its cross-section scaled by
    /// `radial` about the tube's axis (`radial` > 1: the mesh is wider than the masks).
    fn scored(radial: f32) -> ValidationScore {
        let (data, truth) = scene(2);
        let t = &data.template;
        let posed: Vec<Vec<Vec3>> = data
            .frames
            .iter()
            .map(|f| {
                let rest: Vec<Vec3> = t
                    .positions
                    .iter()
                    .map(|p| Vec3::new(p.x * radial, p.y, p.z * radial))
                    .collect();
                tube_posed(&rest, &f.skinning, &truth)
            })
            .collect();
        let edges = EdgeTable::new(t.vertex_count(), &t.triangles);
        score_posed(&data.frames, &posed, &t.triangles, &edges, None)
    }

    #[test]
    fn the_outline_offset_is_the_masks_margin_over_the_mesh() {
        // The truth explains its own masks: no margin, but for the difference between the
        // mesh's coverage, sampled 2 × 2, and the masks', 4 × 4 (0.06 px on this tube a few
        // pixels wide).
        let exact = scored(1.0);
        assert!(exact.outline_offset_px.abs() < 0.1, "{exact}");
        // A mesh 20 % thinner than the masks leaves them outside it, by a fifth of the tube's
        // radius in pixels (0.61 px here); one 20 % wider leaves them as far inside.
        let (thin, wide) = (scored(0.8), scored(1.2));
        assert!(thin.outline_offset_px > 0.2, "{thin}");
        assert!(wide.outline_offset_px < -0.2, "{wide}");
        assert!(
            (thin.outline_offset_px + wide.outline_offset_px).abs() < 0.25 * thin.outline_offset_px,
            "{thin} / {wide}"
        );
        // Training warns about the thin and the wide model, not about the exact one.
        let report = |model: ValidationScore| ValidationReport {
            initial: exact,
            model,
            held_out_frames: 2,
            learned_offset_px: None,
        };
        assert_eq!(report(exact).mask_margin(), None);
        let warned = report(thin).mask_margin().expect("a margin");
        assert_eq!(warned.model_px, thin.outline_offset_px);
        assert!(warned.to_string().contains("+0.61 px outside"), "{warned}");
        assert!(report(wide).mask_margin().is_some());
        // Learned outline offsets that took the margin up silence the warning; offsets that
        // explain only part of it do not.
        let learned = |offset: f64| ValidationReport {
            learned_offset_px: Some(offset),
            ..report(thin)
        };
        assert_eq!(learned(thin.outline_offset_px - 0.1).mask_margin(), None);
        assert!(
            learned(thin.outline_offset_px - 0.4)
                .mask_margin()
                .is_some()
        );
    }
}
