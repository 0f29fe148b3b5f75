//! Stage 1 of the paper (§3.4): SkinNet trained from multi-view silhouettes without the
//! rendering loss, plus the static-weights baseline of the ablation (one pose-independent set of
//! per-vertex weights under the same supervision).
//!
//! The loop is library code over [`TrainData`] (template, skeleton, initial weights, per-frame
//! skinning matrices, pose features and silhouette targets); loading a capture into it is the
//! caller's job. Objective per iteration, over a batch of frames `b` and their views `c`:
//!
//! `λ_sb·mean_{b,c} (L_B/|B|) + λ_sc·mean_{b,c} (L_P/|P|) + λ_lap·L_lap/(B·V) + λ_skin·L_skin/(B·V)
//!  + λ_part·L_part/(B·|R∩G|)`
//!
//! The paper sums every term; the means here make the weights independent of the template
//! resolution, the image size and the number of cameras. `L_lap` is taken of the posed mesh
//! minus the same pose under the initial weights by default ([`LaplacianReference`]). Before
//! the image losses a warm start regresses the initial weights (see [`Trainer::warm_step`]), so
//! SkinNet starts from bone heat instead of from a uniform blend. Frame sampling draws from a
//! generator seeded by `(seed, iteration)`, so a
//! resumed run draws the same batches as an uninterrupted one.

pub mod average;
mod candidate_mask;
mod checkpoint;
pub mod config;
pub mod data;
pub mod ensemble;
mod error;
mod export;
pub mod hidden;
pub mod outline_offset;
pub mod plot;
pub mod pose_locality;
pub mod pose_refinement;
pub mod profile;
pub mod queries;
mod records;
mod run;
pub mod stages;
mod step;
pub mod validation;
mod weights;

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use glam::Mat4;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::ModelConfig;

use crate::geodesic::MeshGraph;
use crate::losses::laplacian::UniformLaplacian;
use crate::losses::lbs::{lbs, rest_homogeneous, skinning_tensor};
use crate::losses::partwise::PartwiseReg;
use crate::losses::silhouette::{BatchView, EdgeTable, SilhouetteLoss};
use crate::losses::skinning_reg::GeodesicSkinningReg;
use crate::optim::Adam;
use crate::skinnet::{PREFIX, TrainableSkinNet, position_inputs_tensor, softmax_last};
use candidate_mask::Candidates;
pub(crate) use checkpoint::{
    insert_varmap, load_tensors, read_u64s, restore_varmap, save_tensors, split_u64,
};
pub use config::{
    ConfigError, DEFAULT_REFINE_ITERATIONS, LaplacianReference, LossWeights, TrainConfig,
};
pub use data::{Frame, TrainData, View};
pub use error::TrainError;
pub use pose_refinement::{FrameCorrection, PoseRefinementConfig};
use profile::{IterationKind, Phase, StepProfile, Timer};
use records::reopen_log;
pub(crate) use records::reopen_log_keeping;
pub use records::{LossRecord, WarmRecord, WarmStatus};

/// What is being optimised.
enum Model {
    /// SkinNet with the training vertices' encoded positions `[V, 3 + 6L]`, and with
    /// [`TrainData::queries`] the full-resolution query points' `[N, 3 + 6L]`.
    Net {
        net: TrainableSkinNet,
        encoded: Tensor,
        query_encoded: Option<Tensor>,
    },
    /// Static baseline: per-vertex logits `[V, J]`, weights = softmax.
    Static { logits: Var },
}

/// A stage-1 run in progress.
pub struct Trainer {
    config: TrainConfig,
    data: TrainData,
    model: Model,
    varmap: VarMap,
    optimiser: Adam,
    rest: Tensor,
    laplacian: UniformLaplacian,
    skinning: GeodesicSkinningReg,
    partwise: PartwiseReg,
    warm_done: u64,
    done: u64,
    /// Stage 4's rendering term while it runs ([`stages`]).
    rendering: Option<stages::RenderingTerm>,
    /// The initial weights `[1, V, J]`.
    init: Tensor,
    /// With [`TrainData::queries`]: the full-resolution initial weights `[N, J]`.
    query_init: Option<Tensor>,
    /// `Σ_ij w_init ln w_init / V`, the constant that turns the warm start's cross-entropy into
    /// a KL divergence.
    init_entropy: f64,
    /// With [`TrainData::queries`]: `Σ_j w_init ln w_init` of every full-resolution row, so a
    /// batch of query rows sums its constant instead of copying its weights out each step.
    query_neg_entropy: Vec<f64>,
    /// With [`LossWeights::hidden_prior`] or [`LossWeights::hidden_drift`]: the training
    /// vertices no training outline shows.
    hidden_gate: Option<HiddenGate>,
    /// Time per phase of the iterations run so far.
    profile: StepProfile,
    /// The training template's edges (silhouette edges are found among them every view).
    edges: Arc<EdgeTable>,
    /// The training template's triangles, shared with the silhouette op.
    triangles: Arc<[[u32; 3]]>,
    /// With [`TrainConfig::consistent_queries`]: the full-resolution rest positions `[N, 4]`.
    query_rest: Option<Tensor>,
    /// The candidate joints and the masks they make ([`crate::candidates`]).
    candidates: Option<Candidates>,
    /// The running average of the parameters over the image iterations.
    average: Option<average::ParameterAverage>,
    /// The last `warm_start_window` warm-start `(KL, relative position error)` pairs.
    warm_window: std::collections::VecDeque<(f64, f64)>,
    /// Whether the warm start has converged.
    warm_converged: bool,
    /// The template's bounding-box diagonal (the length scale of the warm start's position
    /// error and of the Laplacian term).
    diagonal: f64,
    /// The held-out frames ([`validation`]); empty when too few frames were given (the
    /// training frames are scored instead).
    validation: Vec<Frame>,
    /// The initial weights' validation score (before any candidate restriction).
    initial_score: validation::ValidationScore,
    /// With learned outline offsets: the dense initial weights `initial_score` scored, kept to
    /// score them again against the offsets learned.
    initial_validation_weights: Option<Vec<f32>>,
    /// The best-scoring parameter average so far: `(score, image iteration, parameters)`.
    best: Option<(validation::ValidationScore, u64, NamedTensors)>,
    /// `(image iteration, score)` of every validation so far.
    validation_log: Vec<(u64, validation::ValidationScore)>,
    /// With [`PoseRefinementConfig::enabled`]: the training frames' pose corrections.
    pose_refinement: Option<pose_refinement::PoseRefinement>,
    /// The learned outline offsets, when configured ([`outline_offset`]).
    outline_offsets: Option<outline_offset::OutlineOffsets>,
    /// With [`Trainer::distil_from`]: the ensemble members whose mean weights the warm start
    /// regresses instead of the initial weights.
    teachers: Vec<TrainableSkinNet>,
}

/// The settings of the warm-start loop ([`Trainer::warm_settings`]): the warm start's own, or
/// the distillation's when it regresses an ensemble's mean instead of the initial weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WarmSettings {
    /// Learning rate before the halvings (`warm_start_lr_halving`).
    pub lr: f64,
    /// Converged when the window's mean KL per vertex (nats) is at most this…
    pub kl_tolerance: f64,
    /// …and its RMS posed-position error is at most this fraction of the diagonal.
    pub position_tolerance: f64,
    /// Weight of the posed-position term in the objective.
    pub position_weight: f64,
}

/// The vertices [`LossWeights::hidden_prior`] and [`LossWeights::hidden_drift`] hold
/// ([`hidden`]).
struct HiddenGate {
    /// 1 for each training vertex no training outline shows, else 0, as `[1, V, 1]`.
    tensor: Tensor,
    /// The same as numbers, `[V]`.
    gate: Vec<f32>,
    /// The other training vertices' indices.
    seen: Vec<u32>,
    /// `Σ w_init ln w_init` over the gated vertices' initial weights, divided by `V`: the
    /// constant that turns their cross-entropy into a KL divergence when the batch is the
    /// training vertices themselves (no query rows).
    init_entropy: f64,
}

/// Copies of parameters by name.
type NamedTensors = Vec<(String, Tensor)>;

/// Frame-sampling stream of the warm start (its batches have `warm_start_batch` frames).
const PHASE_WARM: u64 = 1;
/// Frame-sampling stream of the image-loss iterations (stages 2–4 use 12–14).
const PHASE_IMAGE: u64 = 2;
/// Added to a phase for its query-point stream ([`queries`]).
const PHASE_QUERY_OFFSET: u64 = 100;
/// Added to a phase for its pose-locality donor stream ([`pose_locality`]).
const PHASE_POSE_LOCALITY_OFFSET: u64 = 200;

fn frame_rng(seed: u64, phase: u64, iteration: u64) -> ChaCha8Rng {
    // Distinct, reproducible streams per (seed, phase, iteration).
    ChaCha8Rng::seed_from_u64(
        seed ^ phase.wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ iteration.wrapping_mul(0xbf58_476d_1ce4_e5b9),
    )
}

impl Trainer {
    /// Prepares a run: checks the data, builds the constant loss data (Laplacian, geodesic
    /// penalty, rigid mask) and initialises the model from `config.seed`. `static_weights`
    /// selects the baseline, whose logits start at `ln(w_init + config.static_epsilon)`.
    pub fn new(
        mut data: TrainData,
        config: TrainConfig,
        static_weights: bool,
    ) -> Result<Self, TrainError> {
        config
            .validate()
            .map_err(|f| TrainError::Data(format!("config field `{f}` is invalid")))?;
        let t = &data.template;
        t.validate()
            .map_err(|e| TrainError::Data(format!("template: {e}")))?;
        let (v, j) = (t.vertex_count(), data.skeleton.len());
        if data.init_weights.len() != v * j {
            return Err(TrainError::Data(format!(
                "init_weights has {} entries, expected {v} × {j}",
                data.init_weights.len()
            )));
        }
        if data.frames.is_empty() {
            return Err(TrainError::Data("no training frames".into()));
        }
        for (i, f) in data.frames.iter().enumerate() {
            if f.skinning.len() != j || f.pose_features.len() != 3 * j {
                return Err(TrainError::Data(format!(
                    "frame {i}: skinning/pose_features sized for another skeleton"
                )));
            }
        }
        if let Some(q) = &data.queries
            && (q.training_vertex_count() != v || q.init_weights.len() != q.positions.len() * j)
        {
            return Err(TrainError::Data(format!(
                "queries: {} cells and {} initial weights for {v} training vertices and {} \
                 query points × {j} joints",
                q.training_vertex_count(),
                q.init_weights.len(),
                q.positions.len()
            )));
        }
        let validation = validation::hold_out(&mut data, config.validation_frames);
        let edges = Arc::new(EdgeTable::new(v, &data.template.triangles));
        let (initial_score, initial_validation_weights) = {
            let frames = if validation.is_empty() {
                &data.frames
            } else {
                &validation
            };
            let dense: Vec<f32> = (0..frames.len())
                .flat_map(|_| data.init_weights.iter().copied())
                .collect();
            let score = validation::score(&data, frames, &dense, &edges, None);
            // Scored again against the learned offsets at the end (`validation_report`).
            (score, config.outline_offset.enabled.then_some(dense))
        };
        let candidates =
            Candidates::new(&mut data, config.candidate_joints, config.candidate_reach);
        let t = &data.template;
        let dev = Device::Cpu;
        let bounds = t
            .bounds()
            .ok_or_else(|| TrainError::Data("template has no bounds".into()))?;
        let diagonal = f64::from((bounds.max - bounds.min).length()).max(1e-9);
        let pose_refinement = if config.pose_refinement.enabled {
            let frames: Vec<&[Mat4]> = data.frames.iter().map(|f| f.skinning.as_slice()).collect();
            Some(pose_refinement::PoseRefinement::new(
                &frames,
                data.skeleton.parents(),
                data.skeleton.inverse_bind(),
                diagonal,
                config.pose_refinement,
            )?)
        } else {
            None
        };
        let outline_offsets = if config.outline_offset.enabled {
            let cameras = data.frames.first().map_or(0, |f| f.views.len());
            Some(outline_offset::OutlineOffsets::new(
                cameras,
                config.outline_offset,
            )?)
        } else {
            None
        };
        let (mut lo, mut hi) = (bounds.min, bounds.max);
        if config.cubic_normalisation {
            let (centre, half) = ((lo + hi) * 0.5, (hi - lo).max_element() * 0.5);
            (lo, hi) = (centre - half, centre + half);
        }
        // A margin so points slightly outside the template (other resolutions) stay in [−1, 1].
        let pad = (hi - lo).max_element() * 0.05;
        let mc = ModelConfig {
            pe_frequencies: config.pe_frequencies,
            up_axis: data.up_axis,
            ..ModelConfig::paper_architecture(
                j as u32,
                (lo - pad).to_array(),
                (hi + pad).to_array(),
            )
        };
        let varmap = VarMap::new();
        let model = if static_weights {
            // See `TrainConfig::static_epsilon` for the trade-off.
            let eps = config.static_epsilon;
            let logits: Vec<f32> = data.init_weights.iter().map(|w| (w + eps).ln()).collect();
            let var = Var::from_tensor(&Tensor::from_vec(logits, (v, j), &dev)?)?;
            varmap
                .data()
                .lock()
                .map_err(|_| TrainError::Data("VarMap lock poisoned".into()))?
                .insert("static.logits".into(), var.clone());
            Model::Static { logits: var }
        } else {
            TrainableSkinNet::init_varmap(
                &varmap,
                &mc,
                PREFIX,
                config.seed,
                config.output_init_scale,
                &dev,
            )?;
            let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
            Model::Net {
                net: TrainableSkinNet::new(&vb.pp(PREFIX), mc)?,
                encoded: position_inputs_tensor(&mc, &t.positions, &dev)?,
                query_encoded: match &data.queries {
                    Some(q) => Some(position_inputs_tensor(&mc, &q.positions, &dev)?),
                    None => None,
                },
            }
        };
        let graph = MeshGraph::new(&t.positions, &t.triangles);
        let skinning = GeodesicSkinningReg::new(
            &graph,
            &data.init_weights,
            j,
            config.skinning_r,
            config.exact_diameter_limit,
            &dev,
        )?;
        let partwise = PartwiseReg::new(
            &data.init_weights,
            j,
            t.part_labels.as_deref(),
            config.partwise_u,
            &dev,
        )?;
        let laplacian = UniformLaplacian::new(&t.positions, &t.triangles, &dev)?;
        let triangles: Arc<[[u32; 3]]> = t.triangles.clone().into();
        let rest = rest_homogeneous(&t.positions, &dev)?;
        let init = Tensor::from_vec(data.init_weights.clone(), (1, v, j), &dev)?;
        // SkinNet only (`LossWeights::hidden_prior`, `LossWeights::hidden_drift`).
        let hidden_gate = if (config.weights.hidden_prior > 0.0
            || config.weights.hidden_drift > 0.0)
            && !static_weights
        {
            let (counts, views) = hidden::outline_view_counts(&data, &data.init_weights, &edges);
            let gate = hidden::hidden_gate(&counts, views, config.hidden_view_fraction);
            let entropy: f64 = data
                .init_weights
                .chunks_exact(j.max(1))
                .zip(&gate)
                .filter(|&(_, &g)| g > 0.0)
                .map(|(row, _)| crate::losses::prior::neg_entropy(row))
                .sum();
            let seen = (0u32..)
                .zip(&gate)
                .filter(|&(_, &g)| g == 0.0)
                .map(|(i, _)| i);
            Some(HiddenGate {
                tensor: Tensor::from_vec(gate.clone(), (1, v, 1), &dev)?,
                seen: seen.collect(),
                gate,
                init_entropy: entropy / v.max(1) as f64,
            })
        } else {
            None
        };
        let init_entropy = crate::losses::prior::neg_entropy(&data.init_weights) / v.max(1) as f64;
        let query_init = match &data.queries {
            Some(q) if !static_weights => {
                let n = q.positions.len();
                Some(Tensor::from_vec(q.init_weights.clone(), (n, j), &dev)?)
            }
            _ => None,
        };
        let query_neg_entropy = match &data.queries {
            Some(q) if !static_weights => q
                .init_weights
                .chunks(j)
                .map(crate::losses::prior::neg_entropy)
                .collect(),
            _ => Vec::new(),
        };
        let optimiser = Adam::from_varmap(&varmap, Self::adam_config(&config, static_weights))?;
        let query_rest = match &data.queries {
            Some(q) if config.consistent_queries && !static_weights => {
                Some(rest_homogeneous(&q.positions, &dev)?)
            }
            _ => None,
        };
        Ok(Self {
            config,
            data,
            model,
            varmap,
            optimiser,
            rest,
            laplacian,
            skinning,
            partwise,
            warm_done: 0,
            done: 0,
            rendering: None,
            init,
            query_init,
            init_entropy,
            query_neg_entropy,
            hidden_gate,
            profile: StepProfile::default(),
            edges,
            triangles,
            query_rest,
            candidates,
            average: None,
            warm_window: std::collections::VecDeque::new(),
            warm_converged: false,
            diagonal,
            validation,
            initial_score,
            initial_validation_weights,
            best: None,
            validation_log: Vec::new(),
            pose_refinement,
            outline_offsets,
            teachers: Vec::new(),
        })
    }

    /// Where the warm start stands (averages over its last window of iterations).
    #[must_use]
    pub fn warm_status(&self) -> WarmStatus {
        let n = self.warm_window.len().max(1) as f64;
        WarmStatus {
            iterations: self.warm_done,
            converged: self.warm_converged,
            kl: self.warm_window.iter().map(|w| w.0).sum::<f64>() / n,
            position_relative: self.warm_window.iter().map(|w| w.1).sum::<f64>() / n,
        }
    }

    /// With [`LossWeights::hidden_prior`] or [`LossWeights::hidden_drift`]: how many of the
    /// training template's vertices they act on (on no training outline, [`hidden`]), and the
    /// template's vertex count.
    #[must_use]
    pub fn hidden_vertices(&self) -> Option<(usize, usize)> {
        self.hidden_gate
            .as_ref()
            .map(|h| (h.gate.iter().filter(|&&g| g > 0.0).count(), h.gate.len()))
    }

    /// Whether the warm start still has iterations to run.
    fn warm_pending(&self) -> bool {
        !self.is_static()
            && !self.warm_converged
            && self.warm_done < self.config.warm_start_iterations
    }

    /// Records one warm-start iteration in the convergence window and applies the test.
    fn note_warm(&mut self, r: &WarmRecord) {
        self.warm_window.push_back((r.kl, r.position_relative));
        while self.warm_window.len() as u64 > self.config.warm_start_window {
            self.warm_window.pop_front();
        }
        let s = self.warm_status();
        let settings = self.warm_settings();
        self.warm_converged = self.warm_window.len() as u64 == self.config.warm_start_window
            && s.kl <= settings.kl_tolerance
            && s.position_relative <= settings.position_tolerance;
    }

    /// What the warm-start loop runs with: the warm start's settings, or while distilling
    /// ([`Trainer::distil_from`]) the ensemble's.
    #[must_use]
    pub fn warm_settings(&self) -> WarmSettings {
        let c = &self.config;
        if self.is_distilling() {
            let e = &c.ensemble;
            WarmSettings {
                lr: e.lr,
                kl_tolerance: e.kl_tolerance,
                position_tolerance: e.position_tolerance,
                position_weight: e.position_weight,
            }
        } else {
            WarmSettings {
                lr: c.adam.lr,
                kl_tolerance: c.warm_start_kl_tolerance,
                position_tolerance: c.warm_start_position_tolerance,
                position_weight: c.warm_start_position_weight,
            }
        }
    }

    /// Adam's settings: the configured ones, with [`TrainConfig::static_lr`] for the static
    /// baseline's logits.
    fn adam_config(config: &TrainConfig, static_weights: bool) -> crate::optim::AdamConfig {
        let mut adam = config.adam;
        if static_weights {
            adam.lr = config.static_lr;
        }
        adam
    }

    /// The learning rate of warm-start iteration `done` (0-based): `adam.lr` (while distilling
    /// `ensemble.lr`) halved every `warm_start_lr_halving` iterations.
    fn warm_lr(&self, done: u64) -> f64 {
        let halvings = done
            .checked_div(self.config.warm_start_lr_halving)
            .unwrap_or(0)
            .min(64);
        self.warm_settings().lr * 0.5f64.powi(halvings as i32)
    }

    /// Whether the image iteration after `done` belongs to stage 1 (stage 4's iterations follow
    /// stage 1's, numbered on).
    fn in_stage_one(&self, done: u64) -> bool {
        done < self.config.iterations
    }

    /// The learning rate of image iteration `done` (0-based). Stage 1: a linear ramp over
    /// `lr_warmup` iterations, then a half cosine from the full rate down to `lr_final_fraction`
    /// of it at its last iteration. Stage 4 (iterations past stage 1's) follows the same
    /// cosine over its own iterations, without the ramp, scaled by
    /// [`StageConfig::refine_lr_fraction`](stages::StageConfig::refine_lr_fraction).
    fn image_lr(&self, done: u64) -> f64 {
        let base = Self::adam_config(&self.config, self.is_static()).lr;
        let (ramp, start, len, peak) = if self.in_stage_one(done) {
            (self.config.lr_warmup, 0, self.config.iterations, 1.0)
        } else {
            let s = &self.config.stages;
            (
                0,
                self.config.iterations,
                s.refine_iterations,
                s.refine_lr_fraction,
            )
        };
        let k = done - start;
        let warm = if ramp == 0 {
            1.0
        } else {
            ((k + 1) as f64 / ramp as f64).min(1.0)
        };
        let span = len.saturating_sub(ramp).max(1) as f64;
        let t = (k.saturating_sub(ramp) as f64 / span).min(1.0);
        let f = self.config.lr_final_fraction;
        let cosine = f + (1.0 - f) * 0.5 * (1.0 + (core::f64::consts::PI * t).cos());
        base * peak * warm * cosine
    }

    fn is_static(&self) -> bool {
        matches!(self.model, Model::Static { .. })
    }

    /// With [`PoseRefinementConfig::enabled`]: each training frame's pose as corrected so far (in
    /// the training frames' order, the validation frames left out), as local transforms.
    pub fn refined_poses(&self) -> Result<Option<Vec<skinfield_formats::Pose>>, TrainError> {
        if self.pose_refinement.is_none() {
            return Ok(None);
        }
        let skeleton = &self.data.skeleton;
        let bind: Vec<Mat4> = skeleton
            .inverse_bind()
            .iter()
            .map(|m| m.inverse())
            .collect();
        let all: Vec<usize> = (0..self.data.frames.len()).collect();
        let rows = self.frame_skinning(&all)?.flatten_all()?.to_vec1::<f32>()?;
        let poses = rows
            .chunks_exact(12 * bind.len().max(1))
            .map(|frame| {
                let world: Vec<Mat4> = frame
                    .chunks_exact(12)
                    .zip(&bind)
                    .map(|(r, b)| {
                        let mut m = [0.0; 16];
                        m[..12].copy_from_slice(r);
                        m[15] = 1.0;
                        // `r` holds the top three rows, row-major.
                        Mat4::from_cols_array(&m).transpose() * *b
                    })
                    .collect();
                pose_refinement::pose_from_world(skeleton, &world)
            })
            .collect();
        Ok(Some(poses))
    }

    /// With [`outline_offset::OutlineOffsetConfig::enabled`]: every camera's learned outline
    /// offset so far (pixels; positive: the masks lie outside the mesh's outline).
    pub fn outline_offsets(&self) -> Result<Option<Vec<f32>>, TrainError> {
        Ok(match &self.outline_offsets {
            Some(o) => Some(o.values()?),
            None => None,
        })
    }

    /// With [`outline_offset::OutlineOffsetConfig::enabled`]: starts every camera's outline
    /// offset at `values` (pixels) instead of zero: what an ensemble's student takes from its
    /// members before stage 4. An error when offsets are not learned or the count differs from
    /// the cameras'.
    pub fn set_outline_offsets(&mut self, values: &[f32]) -> Result<(), TrainError> {
        let offsets = self
            .outline_offsets
            .as_mut()
            .ok_or_else(|| TrainError::Data("this run learns no outline offsets to set".into()))?;
        offsets.set_values(values).map_err(TrainError::Data)
    }

    /// With [`PoseRefinementConfig::enabled`]: each training frame's pose correction so far
    /// (in the training frames' order, the validation frames left out).
    pub fn pose_corrections(&self) -> Result<Option<Vec<FrameCorrection>>, TrainError> {
        Ok(match &self.pose_refinement {
            Some(r) => Some(r.summary()?),
            None => None,
        })
    }

    /// The template posed with initial weights `init` (`[1, V, J]`) under `skinning` (`B`
    /// frames) → `[B, V, 3]`.
    fn initial_posing(
        &self,
        init: &Tensor,
        skinning: &Tensor,
        rest: &Tensor,
        b: usize,
    ) -> Result<Tensor, TrainError> {
        let (v, j) = (self.data.template.vertex_count(), self.data.skeleton.len());
        let init = init.broadcast_as((b, v, j))?.contiguous()?;
        Ok(lbs(&init, skinning, rest)?)
    }

    fn sample(&self, phase: u64, iteration: u64) -> Vec<usize> {
        let mut rng = frame_rng(self.config.seed, phase, iteration);
        let n = self.data.frames.len();
        let batch = if phase == PHASE_WARM {
            self.config.warm_start_batch
        } else {
            self.config.batch
        };
        (0..batch).map(|_| rng.random_range(0..n)).collect()
    }
}

#[cfg(test)]
mod tests;
