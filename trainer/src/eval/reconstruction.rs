//! Scoring a reconstructed template against the capture's ground truth (evaluation only: the
//! true surface of the frame it was reconstructed from, and the true part labels).

use glam::Vec3;
use serde::Serialize;
use skinfield_formats::capture::Capture;
use skinfield_formats::{PartLabel, Template};

use super::surface::{Surface, surface_metrics};
use super::{DEFAULT_SAMPLES, EvalError};
use crate::triangle_bvh::TriangleBvh;

/// How close a reconstructed template is to the truth of its frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TemplateScore {
    /// Mean distance from the reconstruction to the true surface (cm).
    pub m2s_cm: f64,
    /// Mean distance from the true surface to the reconstruction (cm).
    pub s2m_cm: f64,
    /// Share of reconstructed vertices whose part label is the label of the nearest true
    /// surface point (the label of the nearest vertex of its triangle); `None` without labels
    /// on either side.
    pub label_accuracy: Option<f64>,
}

/// Scores `reconstruction` (posed as in `frame`) against the ground-truth mesh of `frame`:
/// surface distances from [`DEFAULT_SAMPLES`] area-uniform points on each surface, in cm, and
/// the part labels.
pub fn score_template(
    capture: &Capture,
    frame: usize,
    reconstruction: &Template,
) -> Result<TemplateScore, EvalError> {
    let truth = capture.evaluation_gt_mesh(frame)?;
    let triangles = &capture.template.triangles;
    let metrics = surface_metrics(
        Surface {
            positions: &reconstruction.positions,
            triangles: &reconstruction.triangles,
        },
        Surface {
            positions: &truth,
            triangles,
        },
        DEFAULT_SAMPLES,
        frame as u64,
    )
    .map_err(|source| EvalError::Surface { frame, source })?;
    let label_accuracy = match (&reconstruction.part_labels, &capture.template.part_labels) {
        (Some(ours), Some(true_labels)) => {
            let bvh = TriangleBvh::new(&truth, triangles);
            let right = reconstruction
                .positions
                .iter()
                .zip(ours)
                .filter(|&(&p, &label)| {
                    nearest_label(&bvh, &truth, triangles, true_labels, p) == Some(label)
                })
                .count();
            Some(right as f64 / reconstruction.vertex_count().max(1) as f64)
        }
        _ => None,
    };
    Ok(TemplateScore {
        m2s_cm: metrics.m2s * 100.0,
        s2m_cm: metrics.s2m * 100.0,
        label_accuracy,
    })
}

/// The label of the vertex nearest to `p`'s closest point on the true surface.
fn nearest_label(
    bvh: &TriangleBvh,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    labels: &[PartLabel],
    p: Vec3,
) -> Option<PartLabel> {
    let closest = bvh.closest(p)?;
    let tri = triangles.get(closest.triangle as usize)?;
    let v = tri
        .iter()
        .min_by(|&&a, &&b| {
            let da = positions[a as usize].distance_squared(closest.point);
            let db = positions[b as usize].distance_squared(closest.point);
            da.total_cmp(&db)
        })
        .copied()?;
    labels.get(v as usize).copied()
}
