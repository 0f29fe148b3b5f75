//! The weights a row of the table is scored with: which ones (`initial`, `oracle`, a static
//! file, a `.skf`, the two bounds), parsed from the command line, and loaded for one capture.

use std::path::PathBuf;
use std::str::FromStr;

use glam::Vec3;
use skinfield_formats::StaticSkin;
use skinfield_formats::capture::{Capture, CaptureError};
use skinfield_formats::skf::read_skf_file;
use skinfield_runtime::SkinNetModel;

use super::posing::{Blend, pose_static};
use super::{EvalError, bounds, posing, read_static_weights};

/// The skinning whose posed meshes are scored.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Skinning {
    /// The capture's initial static weights under LBS; bone heat when the capture ships none.
    Initial,
    /// A static-weights file under LBS.
    Static(PathBuf),
    /// A SkinNet `.skf` (pose-dependent weights) evaluated by the runtime, under LBS.
    Skf(PathBuf),
    /// The ground-truth deformer's static weights under LBS.
    Oracle,
    /// The ground-truth deformer's static weights under DQS.
    OracleDqs,
    /// The best static weights for the training frames' ground truth, under LBS.
    BoundStatic,
    /// The best weights of each test frame within the candidate joints, under LBS.
    BoundPose,
}

impl Skinning {
    /// The row name in the results table.
    #[must_use]
    pub fn method_name(&self) -> &'static str {
        match self {
            Self::Initial => "initial",
            Self::Static(_) => "static",
            Self::Skf(_) => "ours",
            Self::Oracle => "oracle",
            Self::OracleDqs => "oracle-dqs",
            Self::BoundStatic => "bound-static",
            Self::BoundPose => "bound-pose",
        }
    }
}

/// A `--weights` argument that names no skinning method.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "`{0}` is not a skinning: expected initial, static:FILE, skf:FILE, oracle, oracle-dqs, bound-static or bound-pose"
)]
pub struct ParseSkinningError(pub String);

impl FromStr for Skinning {
    type Err = ParseSkinningError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let file = |rest: &str| {
            if rest.is_empty() {
                Err(ParseSkinningError(s.to_string()))
            } else {
                Ok(PathBuf::from(rest))
            }
        };
        match s {
            "initial" => Ok(Self::Initial),
            "oracle" => Ok(Self::Oracle),
            "oracle-dqs" => Ok(Self::OracleDqs),
            "bound-static" => Ok(Self::BoundStatic),
            "bound-pose" => Ok(Self::BoundPose),
            _ => match s.split_once(':') {
                Some(("static", rest)) => Ok(Self::Static(file(rest)?)),
                Some(("skf", rest)) => Ok(Self::Skf(file(rest)?)),
                _ => Err(ParseSkinningError(s.to_string())),
            },
        }
    }
}

/// A skinning made ready for one capture: weights loaded, blend chosen.
#[derive(Clone, Debug)]
pub struct PreparedSkinning {
    method: &'static str,
    weights: Weights,
}

#[derive(Clone, Debug)]
enum Weights {
    Static {
        skin: StaticSkin,
        blend: Blend,
    },
    Net {
        model: Box<SkinNetModel>,
        path: PathBuf,
    },
    /// Fitted per frame to the ground truth within each vertex's candidate joints.
    BestPosed {
        candidates: Vec<Vec<u16>>,
    },
}

impl PreparedSkinning {
    /// Loads what `skinning` needs from `capture` (and from its file, if any).
    pub fn new(capture: &Capture, skinning: &Skinning) -> Result<Self, EvalError> {
        let manifest = capture.dir.join(skinfield_formats::capture::MANIFEST_FILE);
        let initial = || -> Result<StaticSkin, EvalError> {
            Ok(match &capture.initial_weights {
                Some(skin) => skin.clone(),
                None => {
                    crate::heat::bone_heat(
                        &capture.template,
                        &capture.skeleton,
                        &crate::heat::HeatOptions::default(),
                    )
                    .map_err(|source| EvalError::InitialWeights {
                        path: manifest.clone(),
                        source,
                    })?
                    .skin
                }
            })
        };
        let weights = match skinning {
            Skinning::Initial => Weights::Static {
                skin: initial()?,
                blend: Blend::Linear,
            },
            Skinning::BoundStatic => Weights::Static {
                skin: bounds::best_static_weights(capture)?,
                blend: Blend::Linear,
            },
            // The ceiling keeps the generous lists (no gate on the neighbours): a prior of
            // ours should not lower the bound it is measured against.
            Skinning::BoundPose => Weights::BestPosed {
                candidates: crate::candidates::candidate_sets(
                    &crate::losses::dense_weights(&initial()?),
                    &capture.skeleton,
                    &capture.template.positions,
                    crate::candidates::DEFAULT_CANDIDATES,
                    f32::INFINITY,
                ),
            },
            Skinning::Static(path) => Weights::Static {
                skin: read_static_weights(
                    path,
                    &capture.skeleton,
                    capture.template.vertex_count(),
                )?,
                blend: Blend::Linear,
            },
            Skinning::Skf(path) => Weights::Net {
                model: Box::new(load_skinnet(path, capture)?),
                path: path.clone(),
            },
            Skinning::Oracle | Skinning::OracleDqs => {
                let skin = capture
                    .evaluation_true_weights()?
                    .ok_or(EvalError::NoTrueWeights(manifest))?;
                let blend = if *skinning == Skinning::Oracle {
                    Blend::Linear
                } else {
                    Blend::DualQuaternion
                };
                Weights::Static { skin, blend }
            }
        };
        Ok(Self {
            method: skinning.method_name(),
            weights,
        })
    }

    /// The weights of the capture's template in the bind pose, as a static skin: what a
    /// pose-independent consumer (the tracker's silhouette body) can use. SkinNet is queried at
    /// the skeleton's bind pose; `bound-pose` has no weights outside its test frames.
    pub fn bind_skin(&self, capture: &Capture) -> Result<StaticSkin, EvalError> {
        match &self.weights {
            Weights::Static { skin, .. } => Ok(skin.clone()),
            Weights::Net { model, path } => posing::skinnet_weights(
                model,
                &capture.template.positions,
                &capture.skeleton.bind_pose(),
            )
            .map_err(|e| EvalError::Skf {
                path: path.clone(),
                reason: format!("bind pose: {e}"),
            }),
            Weights::BestPosed { .. } => Err(EvalError::NoBindWeights(self.method)),
        }
    }

    /// The row name.
    #[must_use]
    pub fn method(&self) -> &'static str {
        self.method
    }

    /// The influences (joint, weight) of the template's vertex `vertex` on `frame`, largest
    /// first, zero weights left out; `None` for `bound-pose` (whose weights are fitted per frame
    /// to the truth) and for a vertex or frame out of range.
    pub fn vertex_influences(
        &self,
        capture: &Capture,
        frame: usize,
        vertex: usize,
    ) -> Result<Option<Vec<(u32, f32)>>, EvalError> {
        Ok(Some(match &self.weights {
            Weights::Static { skin, .. } if vertex < skin.vertex_count() => {
                sorted_influences(skin, vertex)
            }
            Weights::Net { model, path } => {
                let (Some(pose), Some(&p)) = (
                    capture.poses.get(frame),
                    capture.template.positions.get(vertex),
                ) else {
                    return Ok(None);
                };
                let skin =
                    posing::skinnet_weights(model, &[p], pose).map_err(|e| EvalError::Skf {
                        path: path.clone(),
                        reason: format!("frame {frame}: {e}"),
                    })?;
                sorted_influences(&skin, 0)
            }
            _ => return Ok(None),
        }))
    }

    /// The template's positions posed for `frame`.
    pub fn pose_frame(&self, capture: &Capture, frame: usize) -> Result<Vec<Vec3>, EvalError> {
        self.pose_rest(capture, &capture.template.positions, frame)
    }

    /// Canonical positions `rest` (the capture's template, or any mesh over the same canonical
    /// space, e.g. a resampled one: SkinNet is queried at these positions) posed for `frame`.
    /// Static weights pose only the capture's own template.
    pub fn pose_rest(
        &self,
        capture: &Capture,
        rest: &[Vec3],
        frame: usize,
    ) -> Result<Vec<Vec3>, EvalError> {
        let pose = capture.poses.get(frame).ok_or_else(|| {
            EvalError::Capture(CaptureError::Invalid {
                file: capture.dir.join(skinfield_formats::capture::MANIFEST_FILE),
                field: "frame_count".into(),
                reason: format!("frame {frame} out of range"),
            })
        })?;
        match &self.weights {
            Weights::Static { skin, .. } if skin.vertex_count() != rest.len() => {
                Err(EvalError::TemplateMismatch {
                    method: self.method,
                    weights: skin.vertex_count(),
                    vertices: rest.len(),
                })
            }
            Weights::Static { skin, blend } => {
                pose_static(&capture.skeleton, skin, rest, pose, *blend)
                    .map_err(|source| EvalError::Posing { frame, source })
            }
            Weights::BestPosed { candidates } if candidates.len() != rest.len() => {
                Err(EvalError::TemplateMismatch {
                    method: self.method,
                    weights: candidates.len(),
                    vertices: rest.len(),
                })
            }
            Weights::BestPosed { candidates } => {
                bounds::best_posed_weights(capture, candidates, frame)
            }
            Weights::Net { model, path } => {
                posing::pose_skinnet(model, rest, pose).map_err(|e| EvalError::Skf {
                    path: path.clone(),
                    reason: format!("frame {frame}: {e}"),
                })
            }
        }
    }
}

/// Vertex `v`'s influences in `skin` (joint, weight), largest first, zero weights left out.
pub(crate) fn sorted_influences(skin: &StaticSkin, v: usize) -> Vec<(u32, f32)> {
    let (joints, weights) = skin.influences(v);
    let mut out: Vec<(u32, f32)> = joints
        .iter()
        .copied()
        .zip(weights.iter().copied())
        .filter(|&(_, w)| w > 0.0)
        .collect();
    out.sort_by(|a, b| b.1.total_cmp(&a.1));
    out
}

/// Reads a `.skf` and checks that its skeleton is the capture's (same joint names, same order:
/// SkinNet's outputs and pose features are per joint in file order).
pub(crate) fn load_skinnet(
    path: &std::path::Path,
    capture: &Capture,
) -> Result<SkinNetModel, EvalError> {
    let bytes = read_skf_file(path)?;
    let model = SkinNetModel::from_skf(&bytes).map_err(|e| EvalError::Skf {
        path: path.to_owned(),
        reason: e.to_string(),
    })?;
    if model.skeleton().names() != capture.skeleton.names() {
        return Err(EvalError::Skf {
            path: path.to_owned(),
            reason: format!(
                "skeleton joints {:?} differ from the capture's {:?}",
                model.skeleton().names(),
                capture.skeleton.names()
            ),
        });
    }
    Ok(model)
}
