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
pub mod config;
pub mod data;
pub mod plot;
pub mod profile;
pub mod queries;
pub mod stages;
pub mod validation;

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use glam::Mat4;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::ModelConfig;
use skinfield_formats::{Camera, Skeleton, Template, UpAxis};

use crate::geodesic::MeshGraph;
use crate::losses::laplacian::UniformLaplacian;
use crate::losses::lbs::{lbs, rest_homogeneous, skinning_tensor};
use crate::losses::partwise::PartwiseReg;
use crate::losses::silhouette::{BatchView, EdgeTable, SilhouetteLoss, SilhouetteTarget};
use crate::losses::skinning_reg::GeodesicSkinningReg;
use crate::optim::Adam;
use crate::skinnet::{PREFIX, SkinNet, encode_positions, softmax_last};
pub use config::{ConfigError, LaplacianReference, LossWeights, TrainConfig};
use profile::{IterationKind, Phase, StepProfile, Timer};

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
    /// Initial weights, dense `[V, J]` row-major (bone heat or the asset's).
    pub init_weights: Vec<f32>,
    /// Training frames.
    pub frames: Vec<Frame>,
    /// Full-resolution query points of the training vertices (`None`: query the training
    /// vertices themselves, e.g. at full resolution); see [`queries`].
    pub queries: Option<queries::QueryCells>,
    /// The world's up axis the pose features remove the heading about; recorded in the
    /// exported `.skf` so the runtime computes the same features.
    pub up_axis: UpAxis,
}

/// Why training cannot start or continue.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The data are inconsistent (names the field).
    #[error("training data: {0}")]
    Data(String),
    /// A tensor operation failed.
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
    /// A file could not be written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Exporting the model failed.
    #[error(transparent)]
    Export(#[from] crate::skinnet::export::ExportError),
    /// A checkpoint does not match this run.
    #[error("{path}: {reason}")]
    Checkpoint {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// The loss values of one iteration (already weighted terms are not stored: raw means).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossRecord {
    /// Iteration (1-based, image-loss phase).
    pub iteration: u64,
    /// Weighted total.
    pub total: f64,
    /// Mean boundary-vertex distance (pixels).
    pub silhouette_boundary: f64,
    /// Mean contour-pixel distance (pixels).
    pub silhouette_contour: f64,
    /// Mean squared Laplacian per vertex.
    pub laplacian: f64,
    /// Mean geodesic penalty per vertex.
    pub skinning: f64,
    /// Mean squared deviation per rigid skin vertex.
    pub partwise: f64,
}

impl LossRecord {
    /// CSV header matching [`LossRecord::csv_row`].
    pub const CSV_HEADER: &'static str =
        "iteration,total,silhouette_boundary,silhouette_contour,laplacian,skinning,partwise";

    /// One CSV row.
    #[must_use]
    pub fn csv_row(&self) -> String {
        format!(
            "{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}",
            self.iteration,
            self.total,
            self.silhouette_boundary,
            self.silhouette_contour,
            self.laplacian,
            self.skinning,
            self.partwise
        )
    }
}

/// The terms of one warm-start iteration (before its step).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WarmRecord {
    /// Warm-start iteration (1-based).
    pub iteration: u64,
    /// `KL(w_init ‖ w)` per vertex.
    pub kl: f64,
    /// Mean squared distance (cm², for metre-scaled templates) between the vertices skinned
    /// with SkinNet's and with the initial weights.
    pub position_cm2: f64,
    /// The root mean square of that distance over the template's bounding-box diagonal.
    pub position_relative: f64,
}

/// Where the warm start stands.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WarmStatus {
    /// Iterations run.
    pub iterations: u64,
    /// Whether the convergence test passed (then no more iterations run).
    pub converged: bool,
    /// `KL(w_init ‖ w)` per vertex, averaged over the last window.
    pub kl: f64,
    /// Relative root-mean-square position error, averaged over the last window.
    pub position_relative: f64,
}

/// What is being optimised.
enum Model {
    /// SkinNet with the training vertices' encoded positions `[V, 3 + 6L]`, and with
    /// [`TrainData::queries`] the full-resolution query points' `[N, 3 + 6L]`.
    Net {
        net: SkinNet,
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
    /// The template's bounding-box diagonal (the warm start's position scale).
    diagonal: f64,
    /// The held-out frames ([`validation`]); empty when too few frames were given (the
    /// training frames are scored instead).
    validation: Vec<Frame>,
    /// The initial weights' validation score (before any candidate restriction).
    initial_score: validation::ValidationScore,
    /// The best-scoring parameter average so far: `(score, image iteration, parameters)`.
    best: Option<(validation::ValidationScore, u64, NamedTensors)>,
    /// `(image iteration, score)` of every validation so far.
    validation_log: Vec<(u64, validation::ValidationScore)>,
}

/// Copies of parameters by name.
type NamedTensors = Vec<(String, Tensor)>;

/// The candidate joints of a run and the masks they make.
struct Candidates {
    /// Per training vertex, its candidate joints (ascending).
    lists: Vec<Vec<u16>>,
    /// Additive mask `[V, J]` of the training vertices (0 or −∞).
    mask: Tensor,
    /// Additive mask `[N, J]` of the full-resolution query points (their nearest training
    /// vertex's list, the runtime's rule), or a copy of `mask` without query cells.
    query_mask: Tensor,
}

impl Candidates {
    /// The candidates of `data`'s training vertices ([`crate::candidates::candidate_sets`] with
    /// `k` joints; `None` when `k` is 0), and the initial weights of `data` — the warm start's
    /// target and the regularisers' reference — restricted to them and renormalised, since
    /// weights outside the candidates cannot be represented.
    fn new(data: &mut TrainData, k: usize) -> Option<Self> {
        if k == 0 {
            return None;
        }
        let j = data.skeleton.len();
        let lists = crate::candidates::candidate_sets(&data.init_weights, &data.skeleton, k);
        restrict(&mut data.init_weights, j, &lists, |i| i);
        let mask_values = crate::candidates::additive_mask(&lists, j);
        let v = lists.len();
        let mask = Tensor::from_vec(mask_values.clone(), (v, j), &Device::Cpu).ok()?;
        let query_mask = match &mut data.queries {
            Some(q) => {
                let anchor = skinfield_runtime::candidates::nearest_anchors(
                    &data.template.positions,
                    &q.positions,
                );
                restrict(&mut q.init_weights, j, &lists, |i| anchor[i] as usize);
                let rows: Vec<f32> = anchor
                    .iter()
                    .flat_map(|&a| {
                        mask_values[a as usize * j..(a as usize + 1) * j]
                            .iter()
                            .copied()
                    })
                    .collect();
                Tensor::from_vec(rows, (anchor.len(), j), &Device::Cpu).ok()?
            }
            None => mask.clone(),
        };
        Some(Self {
            lists,
            mask,
            query_mask,
        })
    }
}

/// Zeroes each row's weights outside `lists[list_of(row)]` and renormalises the row (a row
/// left with no weight gets its candidates' uniform blend).
fn restrict(weights: &mut [f32], j: usize, lists: &[Vec<u16>], list_of: impl Fn(usize) -> usize) {
    for (i, row) in weights.chunks_mut(j.max(1)).enumerate() {
        let list = &lists[list_of(i)];
        let mut keep = vec![false; j];
        for &c in list {
            keep[c as usize] = true;
        }
        for (w, k) in row.iter_mut().zip(&keep) {
            if !k {
                *w = 0.0;
            }
        }
        let sum: f32 = row.iter().sum();
        if sum > 0.0 {
            row.iter_mut().for_each(|w| *w /= sum);
        } else {
            for &c in list {
                row[c as usize] = 1.0 / list.len() as f32;
            }
        }
    }
}

/// Frame-sampling stream of the warm start (its batches have `warm_start_batch` frames).
const PHASE_WARM: u64 = 1;
/// Frame-sampling stream of the image-loss iterations (stages 2–4 use 12–14).
const PHASE_IMAGE: u64 = 2;
/// Added to a phase for its query-point stream ([`queries`]).
const PHASE_QUERY_OFFSET: u64 = 100;

/// `Σ_ij w ln w / v` of dense weights `w`: with the cross-entropy, the KL divergence.
fn mean_neg_entropy(w: &[f32], v: usize) -> f64 {
    w.iter()
        .filter(|&&x| x > 0.0)
        .map(|&x| f64::from(x) * f64::from(x).ln())
        .sum::<f64>()
        / v.max(1) as f64
}

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
        let initial_score = {
            let frames = if validation.is_empty() {
                &data.frames
            } else {
                &validation
            };
            let dense: Vec<f32> = (0..frames.len())
                .flat_map(|_| data.init_weights.iter().copied())
                .collect();
            validation::score(&data, frames, &dense, &edges)
        };
        let candidates = Candidates::new(&mut data, config.candidate_joints);
        let t = &data.template;
        let dev = Device::Cpu;
        let bounds = t
            .bounds()
            .ok_or_else(|| TrainError::Data("template has no bounds".into()))?;
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
            ..ModelConfig::vinecs(j as u32, (lo - pad).to_array(), (hi + pad).to_array())
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
            SkinNet::init_varmap(
                &varmap,
                &mc,
                PREFIX,
                config.seed,
                config.output_init_scale,
                &dev,
            )?;
            let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
            Model::Net {
                net: SkinNet::new(&vb.pp(PREFIX), mc)?,
                encoded: encode_positions(&mc, &t.positions, &dev)?,
                query_encoded: match &data.queries {
                    Some(q) => Some(encode_positions(&mc, &q.positions, &dev)?),
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
        let init_entropy = mean_neg_entropy(&data.init_weights, v);
        let query_init = match &data.queries {
            Some(q) if !static_weights => {
                let n = q.positions.len();
                Some(Tensor::from_vec(q.init_weights.clone(), (n, j), &dev)?)
            }
            _ => None,
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
            profile: StepProfile::default(),
            edges,
            triangles,
            query_rest,
            candidates,
            average: None,
            warm_window: std::collections::VecDeque::new(),
            warm_converged: false,
            diagonal: f64::from((bounds.max - bounds.min).length()).max(1e-9),
            validation,
            initial_score,
            best: None,
            validation_log: Vec::new(),
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
        self.warm_converged = self.warm_window.len() as u64 == self.config.warm_start_window
            && s.kl <= self.config.warm_start_kl_tolerance
            && s.position_relative <= self.config.warm_start_position_tolerance;
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

    /// The learning rate of image iteration `done` (0-based). Stage 1: a linear ramp over
    /// `lr_warmup` iterations, then a half cosine from the full rate down to `lr_final_fraction`
    /// of it at its last iteration. Stage 4 (iterations past stage 1's) follows the same
    /// cosine over its own iterations, without the ramp.
    fn image_lr(&self, done: u64) -> f64 {
        let base = Self::adam_config(&self.config, self.is_static()).lr;
        let (ramp, start, len) = if done < self.config.iterations {
            (self.config.lr_warmup, 0, self.config.iterations)
        } else {
            (
                0,
                self.config.iterations,
                self.config.stages.refine_iterations,
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
        base * warm * cosine
    }

    fn is_static(&self) -> bool {
        matches!(self.model, Model::Static { .. })
    }

    /// Replaces the parameters by their running average over the image iterations so far
    /// ([`TrainConfig::ema_half_life`]) and drops the average: what is exported, and where the
    /// later stages continue from (stage 4 starts an average of its own). A no-op without one.
    ///
    /// With validation snapshots ([`Trainer::validate_average`]), the best-scoring one is
    /// adopted instead; it is one of the averages, so the rule is "the best average seen".
    pub fn adopt_average(&mut self) -> Result<(), TrainError> {
        if let Some(mut a) = self.average.take() {
            a.swap()?;
        }
        if let Some((_, _, params)) = self.best.take() {
            let vars = self
                .varmap
                .data()
                .lock()
                .map_err(|_| TrainError::Data("VarMap lock poisoned".into()))?;
            for (name, value) in &params {
                if let Some(var) = vars.get(name) {
                    var.set(value)?;
                }
            }
        }
        Ok(())
    }

    /// Scores the current parameters on the validation frames (the training frames when none
    /// are held out).
    pub fn validate(&self) -> Result<validation::ValidationScore, TrainError> {
        let frames = if self.validation.is_empty() {
            &self.data.frames
        } else {
            &self.validation
        };
        let poses: Vec<f32> = frames
            .iter()
            .flat_map(|f| f.pose_features.iter().copied())
            .collect();
        let w = self.weights_for_poses(poses, frames.len(), None)?;
        let dense: Vec<f32> = w.flatten_all()?.to_vec1()?;
        Ok(validation::score(&self.data, frames, &dense, &self.edges))
    }

    /// Scores the running parameter average (the current parameters without one), logs the
    /// score and keeps a copy of the parameters when they are the best so far; returns the
    /// score.
    pub fn validate_average(&mut self) -> Result<validation::ValidationScore, TrainError> {
        if let Some(a) = &mut self.average {
            a.swap()?;
        }
        // Scored and copied while the average is in place; swapped back whatever happened.
        let scored = self.validate().and_then(|score| {
            let better = self
                .best
                .as_ref()
                .is_none_or(|(best, _, _)| !score.is_worse_than(best));
            let params = if better {
                Some(self.parameter_copies()?)
            } else {
                None
            };
            Ok((score, params))
        });
        if let Some(a) = &mut self.average {
            a.swap()?;
        }
        let (score, params) = scored?;
        self.validation_log.push((self.done, score));
        if let Some(params) = params {
            self.best = Some((score, self.done, params));
        }
        Ok(score)
    }

    /// Copies of every parameter, by name.
    fn parameter_copies(&self) -> Result<NamedTensors, TrainError> {
        let vars = self
            .varmap
            .data()
            .lock()
            .map_err(|_| TrainError::Data("VarMap lock poisoned".into()))?;
        vars.iter()
            .map(|(name, var)| Ok((name.clone(), var.as_tensor().copy()?)))
            .collect()
    }

    /// The initial weights' validation score and the number of held-out frames.
    #[must_use]
    pub fn initial_validation(&self) -> (validation::ValidationScore, usize) {
        (self.initial_score, self.validation.len())
    }

    /// Every validation so far: `(image iteration, score)`.
    #[must_use]
    pub fn validation_log(&self) -> &[(u64, validation::ValidationScore)] {
        &self.validation_log
    }

    /// The iteration and score of the best average so far (what [`Trainer::adopt_average`]
    /// exports).
    #[must_use]
    pub fn best_validation(&self) -> Option<(u64, validation::ValidationScore)> {
        self.best.as_ref().map(|(s, i, _)| (*i, *s))
    }

    /// The validation report of the current parameters against the initial weights.
    pub fn validation_report(&self) -> Result<validation::ValidationReport, TrainError> {
        Ok(validation::ValidationReport {
            initial: self.initial_score,
            model: self.validate()?,
            held_out_frames: self.validation.len(),
        })
    }

    /// The homogeneous rest positions `[V, 4]` the batch is skinned from: the query rows' own
    /// positions with [`TrainConfig::consistent_queries`], else the training vertices'.
    fn rest_at(&self, query: Option<&Tensor>) -> Result<Tensor, TrainError> {
        match (&self.query_rest, query) {
            (Some(rest), Some(q)) => Ok(rest.index_select(q, 0)?),
            _ => Ok(self.rest.clone()),
        }
    }

    /// Where the iterations run so far spent their time ([`profile`]).
    #[must_use]
    pub fn profile(&self) -> &StepProfile {
        &self.profile
    }

    /// The network as `.skf` content with its candidate joints (the `CAND` section): what
    /// `trainer train` writes. Exporting the network alone would let every joint back into a
    /// softmax that was trained over the candidates only.
    pub fn skf_model(&self) -> Result<skinfield_formats::skf::SkfModel, TrainError> {
        let net = self
            .net()
            .ok_or_else(|| TrainError::Data("the static baseline has no network".into()))?;
        let mut model = crate::skinnet::export::to_skf_model(net, &self.data.skeleton)?;
        model.candidates = self.export_candidates();
        Ok(model)
    }

    /// The network (`None` for the static baseline).
    #[must_use]
    pub fn net(&self) -> Option<&SkinNet> {
        match &self.model {
            Model::Net { net, .. } => Some(net),
            Model::Static { .. } => None,
        }
    }

    /// The static baseline's weights `[V, J]` (`None` for SkinNet).
    pub fn static_weights(&self) -> Result<Option<Vec<f32>>, TrainError> {
        match &self.model {
            Model::Static { .. } => Ok(Some(self.weights(&[0])?.flatten_all()?.to_vec1()?)),
            Model::Net { .. } => Ok(None),
        }
    }

    /// The anchors and candidate joints to store in the exported `.skf` (the training template's
    /// vertices and their lists), or `None` when candidates are off.
    #[must_use]
    pub fn export_candidates(&self) -> Option<skinfield_formats::skf::Candidates> {
        self.candidates
            .as_ref()
            .map(|c| skinfield_formats::skf::Candidates {
                positions: self
                    .data
                    .template
                    .positions
                    .iter()
                    .map(|p| p.to_array())
                    .collect(),
                lists: c.lists.clone(),
                k: self.config.candidate_joints,
            })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// `(warm-start iterations done, image iterations done)`.
    #[must_use]
    pub fn progress(&self) -> (u64, u64) {
        (self.warm_done, self.done)
    }

    /// Weights `[B, V, J]` for the given frames, queried at the training vertices.
    pub fn weights(&self, frames: &[usize]) -> Result<Tensor, TrainError> {
        self.weights_at(frames, None)
    }

    /// Weights `[B, V, J]` for the given frames, SkinNet queried at rows `query` (`[V]`) of the
    /// full-resolution query points, or at the training vertices themselves (`None`).
    fn weights_at(&self, frames: &[usize], query: Option<&Tensor>) -> Result<Tensor, TrainError> {
        let poses: Vec<f32> = frames
            .iter()
            .flat_map(|&f| self.data.frames[f].pose_features.iter().copied())
            .collect();
        self.weights_for_poses(poses, frames.len(), query)
    }

    /// Weights `[B, V, J]` for `b` poses given by their concatenated pose features.
    fn weights_for_poses(
        &self,
        poses: Vec<f32>,
        b: usize,
        query: Option<&Tensor>,
    ) -> Result<Tensor, TrainError> {
        let j = self.data.skeleton.len();
        Ok(match &self.model {
            Model::Net {
                net,
                encoded,
                query_encoded,
            } => {
                let (rows, mask) = match (query, query_encoded) {
                    (Some(q), Some(points)) => (
                        points.index_select(q, 0)?,
                        self.candidates
                            .as_ref()
                            .map(|c| c.query_mask.index_select(q, 0))
                            .transpose()?,
                    ),
                    _ => (
                        encoded.clone(),
                        self.candidates.as_ref().map(|c| c.mask.clone()),
                    ),
                };
                net.forward_masked(
                    &rows,
                    &Tensor::from_vec(poses, (b, 3 * j), &Device::Cpu)?,
                    mask.as_ref(),
                )?
            }
            Model::Static { logits } => {
                let logits = match &self.candidates {
                    Some(c) => logits.as_tensor().broadcast_add(&c.mask)?,
                    None => logits.as_tensor().clone(),
                };
                let w = softmax_last(&logits)?;
                let (v, _) = w.dims2()?;
                w.unsqueeze(0)?.broadcast_as((b, v, j))?.contiguous()?
            }
        })
    }

    /// The query rows of one iteration of `phase`: a seeded member of every training vertex's
    /// cell ([`queries::QueryCells::draw`]), or `None` (query the training vertices) without
    /// query cells or with `full_resolution_queries` off.
    fn draw_queries(&self, phase: u64, iteration: u64) -> Result<Option<Tensor>, TrainError> {
        match (&self.data.queries, &self.query_init) {
            (Some(q), Some(_)) if self.config.full_resolution_queries => {
                let mut rng = frame_rng(self.config.seed, PHASE_QUERY_OFFSET + phase, iteration);
                let rows = q.draw(&mut rng);
                let v = rows.len();
                Ok(Some(Tensor::from_vec(rows, v, &Device::Cpu)?))
            }
            _ => Ok(None),
        }
    }

    /// The initial weights `[1, V, J]` at query rows `query`, or at the training vertices
    /// (`None`).
    fn init_at(&self, query: Option<&Tensor>) -> Result<Tensor, TrainError> {
        match (&self.query_init, query) {
            (Some(full), Some(q)) => Ok(full.index_select(q, 0)?.unsqueeze(0)?),
            _ => Ok(self.init.clone()),
        }
    }

    /// Skinning matrices of `frames` as `[B, J, 4, 4]`-shaped data for [`lbs`].
    fn frame_skinning(&self, frames: &[usize]) -> Result<Tensor, TrainError> {
        let mats: Vec<Vec<Mat4>> = frames
            .iter()
            .map(|&f| self.data.frames[f].skinning.clone())
            .collect();
        Ok(skinning_tensor(&mats, &Device::Cpu)?)
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

    /// One warm-start iteration on a random batch of frames; returns the objective's terms
    /// before the step. A no-op for the static baseline.
    ///
    /// The objective is `KL(w_init ‖ w) + λ_pos · ‖x(w) − x(w_init)‖²`, both averaged over the
    /// batch's vertices: the Kullback–Leibler divergence from the initial weights to SkinNet's,
    /// plus the squared distance (cm²) between the vertex skinned with SkinNet's weights and with
    /// the initial ones in the batch's poses (`warm_start_position_weight` = λ_pos).
    ///
    /// Why these: the squared error of the weights (the first version) has a gradient that
    /// passes through the softmax Jacobian and vanishes as the weights saturate; KL's gradient
    /// with respect to the logits is `w − w_init`. But KL ignores the joints a vertex has no
    /// initial weight on, and a small leak onto a far joint moves the vertex by centimetres; the
    /// position term weighs every weight error by how far it moves the vertex (off by default:
    /// it did not help in the runs measured, see `TrainConfig::warm_start_position_weight`). On
    /// the built-in capture (Chamfer after the warm start alone; bone heat 1.003 cm): 300
    /// squared-error iterations 1.161 cm, 300 KL iterations 1.059 cm.
    pub fn warm_step(&mut self) -> Result<WarmRecord, TrainError> {
        if matches!(self.model, Model::Static { .. }) {
            self.warm_done += 1;
            return Ok(WarmRecord::default());
        }
        const KIND: IterationKind = IterationKind::Warm;
        let mut timer = Timer::start();
        let frames = self.sample(PHASE_WARM, self.warm_done);
        let query = self.draw_queries(PHASE_WARM, self.warm_done)?;
        let w = self.weights_at(&frames, query.as_ref())?;
        timer.lap(&mut self.profile, KIND, Phase::Forward);
        let init = self.init_at(query.as_ref())?;
        let v = self.data.template.vertex_count();
        let b = frames.len();
        let cross = (w
            .clamp(1e-12, 1.0)?
            .log()?
            .broadcast_mul(&init)?
            .sum_all()?
            / (-((b * v) as f64)))?;
        let init_entropy = if query.is_some() {
            mean_neg_entropy(&init.flatten_all()?.to_vec1::<f32>()?, v)
        } else {
            self.init_entropy
        };
        timer.lap(&mut self.profile, KIND, Phase::Regularisers);
        let skinning = self.frame_skinning(&frames)?;
        let rest = self.rest_at(query.as_ref())?;
        let offset =
            (lbs(&w, &skinning, &rest)? - self.initial_posing(&init, &skinning, &rest, b)?)?;
        // m² → cm².
        let position = (offset.sqr()?.sum_all()? * (1e4 / (b * v) as f64))?;
        let total = (&cross + (&position * self.config.warm_start_position_weight)?)?;
        let kl = f64::from(cross.to_vec0::<f32>()?) + init_entropy;
        let position_cm2 = f64::from(position.to_vec0::<f32>()?);
        // cm² back to m², then relative to the diagonal.
        let position_relative = (position_cm2 * 1e-4).sqrt() / self.diagonal;
        timer.lap(&mut self.profile, KIND, Phase::Skinning);
        let grads = total.backward()?;
        timer.lap(&mut self.profile, KIND, Phase::Backward);
        self.optimiser.step(&grads)?;
        timer.lap(&mut self.profile, KIND, Phase::Optimiser);
        self.profile.finish_iteration(KIND);
        self.warm_done += 1;
        let record = WarmRecord {
            iteration: self.warm_done,
            kl,
            position_cm2,
            position_relative,
        };
        self.note_warm(&record);
        Ok(record)
    }

    /// One image-loss iteration on a seeded batch; returns its losses (before the step).
    ///
    /// The first image iteration starts a fresh Adam state, and the learning rate ramps up over
    /// `config.lr_warmup` iterations. The warm start's moments belong to another objective
    /// whose gradients are much smaller: carried over, the first image-loss step quadrupled the
    /// mean boundary-vertex distance on the built-in capture (0.76 → 2.88 px); with a fresh
    /// state and no ramp it still rose to 1.86 px, since Adam's first step moves every
    /// parameter by lr at once.
    pub fn step(&mut self) -> Result<LossRecord, TrainError> {
        if self.done == 0 {
            self.optimiser = Adam::from_varmap(
                &self.varmap,
                Self::adam_config(&self.config, self.is_static()),
            )?;
        }
        if self.average.is_none() && self.config.ema_half_life > 0.0 {
            self.average = Some(average::ParameterAverage::new(
                &self.varmap,
                self.config.ema_half_life,
            )?);
        }
        self.optimiser.set_lr(self.image_lr(self.done));
        const KIND: IterationKind = IterationKind::Image;
        let mut timer = Timer::start();
        let frames = self.sample(PHASE_IMAGE, self.done);
        let query = self.draw_queries(PHASE_IMAGE, self.done)?;
        let w = self.weights_at(&frames, query.as_ref())?;
        timer.lap(&mut self.profile, KIND, Phase::Forward);
        let b = frames.len();
        let skinning = self.frame_skinning(&frames)?;
        let rest = self.rest_at(query.as_ref())?;
        let posed = lbs(&w, &skinning, &rest)?;
        timer.lap(&mut self.profile, KIND, Phase::Skinning);
        let views: Vec<BatchView> = frames
            .iter()
            .enumerate()
            .flat_map(|(k, &f)| {
                self.data.frames[f].views.iter().map(move |view| BatchView {
                    frame: k,
                    camera: view.camera.clone(),
                    target: view.target.clone(),
                })
            })
            .collect();
        let silhouette = SilhouetteLoss::new(
            views,
            self.triangles.clone(),
            self.edges.clone(),
            self.config.silhouette_huber_px,
        )
        .apply(&posed)?;
        let sb = silhouette.get(0)?;
        let sc = silhouette.get(1)?;
        let (sb_px, sc_px) = (silhouette.get(2)?, silhouette.get(3)?);
        timer.lap(&mut self.profile, KIND, Phase::Silhouette);
        let v = self.data.template.vertex_count() as f64;
        let lap_input = match self.config.laplacian_reference {
            LaplacianReference::Absolute => posed.clone(),
            // The operator is linear: δ(x) − δ(x_init) = δ(x − x_init).
            LaplacianReference::InitialSkinning => {
                let init = self.init_at(query.as_ref())?;
                (&posed - self.initial_posing(&init, &skinning, &rest, b)?)?
            }
        };
        let lap = (self.laplacian.loss(&lap_input)? / (b as f64 * v))?;
        let skin = (self.skinning.loss(&w)? / (b as f64 * v))?;
        let part = (self.partwise.loss(&w)? / (b * self.partwise.count().max(1)) as f64)?;
        let lw = self.config.weights;
        let terms = [
            (&sb * lw.silhouette_boundary)?,
            (&sc * lw.silhouette_contour)?,
            (&lap * lw.laplacian)?,
            (&skin * lw.skinning)?,
            (&part * lw.partwise)?,
        ];
        let mut terms = terms.to_vec();
        timer.lap(&mut self.profile, KIND, Phase::Regularisers);
        terms.extend(self.rendering_term(&frames, &posed)?);
        timer.lap(&mut self.profile, KIND, Phase::Rendering);
        let total = Tensor::stack(&terms, 0)?.sum_all()?;
        let val = |t: &Tensor| -> Result<f64, TrainError> { Ok(f64::from(t.to_vec0::<f32>()?)) };
        self.done += 1;
        let record = LossRecord {
            iteration: self.done,
            total: val(&total)?,
            silhouette_boundary: val(&sb_px)?,
            silhouette_contour: val(&sc_px)?,
            laplacian: val(&lap)?,
            skinning: val(&skin)?,
            partwise: val(&part)?,
        };
        let grads = total.backward()?;
        timer.lap(&mut self.profile, KIND, Phase::Backward);
        self.optimiser.step(&grads)?;
        if let Some(a) = &mut self.average {
            a.update()?;
        }
        timer.lap(&mut self.profile, KIND, Phase::Optimiser);
        self.profile.finish_iteration(KIND);
        Ok(record)
    }

    /// Writes parameters, optimiser state and progress to `path` (safetensors, atomically).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), TrainError> {
        save_tensors(&self.checkpoint_tensors("")?, path)
    }

    /// Parameters (`param.NAME`), optimiser state and progress, every name prefixed by `prefix`.
    pub(crate) fn checkpoint_tensors(
        &self,
        prefix: &str,
    ) -> Result<HashMap<String, Tensor>, TrainError> {
        let mut tensors: HashMap<String, Tensor> = self
            .optimiser
            .state_tensors()?
            .into_iter()
            .map(|(k, v)| (format!("{prefix}{k}"), v))
            .collect();
        insert_varmap(&mut tensors, &format!("{prefix}param."), &self.varmap)?;
        if let Some(a) = &self.average {
            for (k, v) in a.state_tensors()? {
                tensors.insert(format!("{prefix}{k}"), v);
            }
        }
        let window: Vec<f64> = self.warm_window.iter().flat_map(|w| [w.0, w.1]).collect();
        let n = self.warm_window.len();
        tensors.insert(
            format!("{prefix}warm.window"),
            Tensor::from_vec(window, (n, 2), &Device::Cpu)?,
        );
        tensors.insert(
            format!("{prefix}warm.converged"),
            Tensor::new(&[u32::from(self.warm_converged)], &Device::Cpu)?,
        );
        let p = [self.warm_done, self.done].map(split_u64).concat();
        tensors.insert(
            format!("{prefix}progress"),
            Tensor::new(p.as_slice(), &Device::Cpu)?,
        );
        Ok(tensors)
    }

    /// Restores a checkpoint written by [`Trainer::save_checkpoint`] for the same data, config
    /// and model kind; training then continues exactly where it stopped.
    pub fn resume(&mut self, path: &Path) -> Result<(), TrainError> {
        let tensors = load_tensors(path)?;
        self.restore_tensors(&tensors, "", path)
    }

    /// Restores what [`Trainer::checkpoint_tensors`] wrote under `prefix`; errors name `path`.
    pub(crate) fn restore_tensors(
        &mut self,
        tensors: &HashMap<String, Tensor>,
        prefix: &str,
        path: &Path,
    ) -> Result<(), TrainError> {
        let bad = |reason: String| TrainError::Checkpoint {
            path: path.to_owned(),
            reason,
        };
        restore_varmap(tensors, &format!("{prefix}param."), &self.varmap, &bad)?;
        let state: HashMap<String, Tensor> = tensors
            .iter()
            .filter_map(|(k, v)| Some((k.strip_prefix(prefix)?.to_string(), v.clone())))
            .collect();
        self.optimiser
            .load_state_tensors(&state)
            .map_err(|e| bad(e.to_string()))?;
        self.average = if state.contains_key("avg.weight") {
            let mut a = average::ParameterAverage::new(&self.varmap, self.config.ema_half_life)?;
            a.load_state_tensors(&state)
                .map_err(|e| bad(e.to_string()))?;
            Some(a)
        } else {
            None
        };
        let p = read_u64s(tensors, &format!("{prefix}progress"), 2).map_err(bad)?;
        self.warm_done = p[0];
        self.done = p[1];
        let window = tensors
            .get(&format!("{prefix}warm.window"))
            .ok_or_else(|| bad(format!("`{prefix}warm.window` is missing")))?
            .to_vec2::<f64>()
            .map_err(|e| bad(format!("`{prefix}warm.window`: {e}")))?;
        self.warm_window = window.iter().map(|r| (r[0], r[1])).collect();
        self.warm_converged = tensors
            .get(&format!("{prefix}warm.converged"))
            .ok_or_else(|| bad(format!("`{prefix}warm.converged` is missing")))?
            .to_vec1::<u32>()
            .map_err(|e| bad(format!("`{prefix}warm.converged`: {e}")))?
            .first()
            .is_some_and(|&c| c != 0);
        Ok(())
    }

    /// Runs the remaining warm-start and image iterations, appending to `dir/losses.csv` and
    /// writing `dir/checkpoint.safetensors` every `checkpoint_every` iterations and at the end.
    /// Shows an indicatif progress bar with the current losses when `progress` is set.
    pub fn run(&mut self, dir: &Path, progress: bool) -> Result<(), TrainError> {
        let io = |path: &Path| {
            let path = path.to_owned();
            move |source: std::io::Error| TrainError::Io {
                path: path.clone(),
                source,
            }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let csv_path = dir.join("losses.csv");
        let mut csv = reopen_log(&csv_path, LossRecord::CSV_HEADER, self.done)?;
        let warm_path = dir.join("warm_start.csv");
        let mut warm_csv = reopen_log(
            &warm_path,
            "iteration,kl,position_cm2,position_relative",
            self.warm_done,
        )?;
        let total = self.config.warm_start_iterations + self.config.iterations;
        let bar = if progress {
            indicatif::ProgressBar::new(total)
        } else {
            indicatif::ProgressBar::hidden()
        };
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:30} {pos}/{len} {elapsed_precise} eta {eta} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.set_position(self.warm_done + self.done);
        let ckpt = dir.join("checkpoint.safetensors");
        while self.warm_pending() {
            let r = self.warm_step()?;
            writeln!(
                warm_csv,
                "{},{:.6e},{:.6e},{:.6e}",
                r.iteration, r.kl, r.position_cm2, r.position_relative
            )
            .map_err(io(&warm_path))?;
            bar.set_message(format!(
                "warm start KL {:.3e}, {:.3e} cm²",
                r.kl, r.position_cm2
            ));
            bar.inc(1);
            if self.config.checkpoint_every > 0
                && self.warm_done.is_multiple_of(self.config.checkpoint_every)
            {
                warm_csv.flush().map_err(io(&warm_path))?;
                self.save_checkpoint(&ckpt)?;
            }
        }
        warm_csv.flush().map_err(io(&warm_path))?;
        if self.warm_converged && self.warm_done < self.config.warm_start_iterations {
            // The skipped warm-start iterations leave the progress bar.
            bar.set_length(self.warm_done + self.config.iterations);
        }
        let validation_path = dir.join("validation.csv");
        let done = self.done;
        // Row 0 is the initial weights' score, rewritten by a run from the start.
        let mut validation_csv = reopen_log_keeping(
            &validation_path,
            "iteration,silhouette_px,boundary_px,contour_px,iou",
            |row| {
                done > 0
                    && row
                        .split(',')
                        .next()
                        .and_then(|i| i.parse::<u64>().ok())
                        .is_some_and(|i| i <= done)
            },
        )?;
        if self.done == 0 && self.config.iterations > 0 {
            let s = self.initial_score;
            writeln!(
                validation_csv,
                "0,{:.6},{:.6},{:.6},{:.6}",
                s.silhouette_px, s.boundary_px, s.contour_px, s.iou
            )
            .map_err(io(&validation_path))?;
        }
        while self.done < self.config.iterations {
            let r = self.step()?;
            writeln!(csv, "{}", r.csv_row()).map_err(io(&csv_path))?;
            let every = self.config.validation_every;
            if self.config.validation_frames > 0
                && (self.done == self.config.iterations
                    || (every > 0 && self.done.is_multiple_of(every)))
            {
                let s = self.validate_average()?;
                writeln!(
                    validation_csv,
                    "{},{:.6},{:.6},{:.6},{:.6}",
                    self.done, s.silhouette_px, s.boundary_px, s.contour_px, s.iou
                )
                .map_err(io(&validation_path))?;
                validation_csv.flush().map_err(io(&validation_path))?;
            }
            bar.set_message(format!(
                "total {:.3} sil {:.2}/{:.2}px lap {:.2e} skin {:.2e} part {:.2e}",
                r.total,
                r.silhouette_boundary,
                r.silhouette_contour,
                r.laplacian,
                r.skinning,
                r.partwise
            ));
            bar.inc(1);
            if self.config.checkpoint_every > 0
                && self.done.is_multiple_of(self.config.checkpoint_every)
            {
                csv.flush().map_err(io(&csv_path))?;
                self.save_checkpoint(&ckpt)?;
            }
        }
        csv.flush().map_err(io(&csv_path))?;
        self.save_checkpoint(&ckpt)?;
        let profile_path = dir.join("profile.csv");
        std::fs::write(&profile_path, self.profile.csv()).map_err(io(&profile_path))?;
        bar.finish();
        Ok(())
    }
}

/// `x` as two little-endian `u32` halves (safetensors and candle have no u64 that survives
/// every backend).
pub(crate) fn split_u64(x: u64) -> [u32; 2] {
    [(x & 0xffff_ffff) as u32, (x >> 32) as u32]
}

/// The `count` u64 values stored by [`split_u64`] halves under `name`.
pub(crate) fn read_u64s(
    tensors: &HashMap<String, Tensor>,
    name: &str,
    count: usize,
) -> Result<Vec<u64>, String> {
    let p = tensors
        .get(name)
        .ok_or_else(|| format!("`{name}` is missing"))?
        .to_vec1::<u32>()
        .map_err(|e| format!("`{name}`: {e}"))?;
    if p.len() != 2 * count {
        return Err(format!("`{name}` has the wrong length"));
    }
    Ok(p.chunks_exact(2)
        .map(|h| u64::from(h[0]) | (u64::from(h[1]) << 32))
        .collect())
}

/// Adds every variable `NAME` of `varmap` to `out` as `prefix + NAME`.
pub(crate) fn insert_varmap(
    out: &mut HashMap<String, Tensor>,
    prefix: &str,
    varmap: &VarMap,
) -> Result<(), TrainError> {
    for (k, v) in lock_vars(varmap)?.iter() {
        out.insert(format!("{prefix}{k}"), v.as_tensor().clone());
    }
    Ok(())
}

/// The variables of `varmap` (locked for the caller).
pub(crate) fn lock_vars(
    varmap: &VarMap,
) -> Result<std::sync::MutexGuard<'_, HashMap<String, candle_core::Var>>, TrainError> {
    varmap
        .data()
        .lock()
        .map_err(|_| TrainError::Data("VarMap lock poisoned".into()))
}

/// Sets every variable `NAME` of `varmap` from `tensors[prefix + NAME]`, which must exist with
/// the variable's shape (`bad` turns a reason into the caller's error).
pub(crate) fn restore_varmap(
    tensors: &HashMap<String, Tensor>,
    prefix: &str,
    varmap: &VarMap,
    bad: &dyn Fn(String) -> TrainError,
) -> Result<(), TrainError> {
    for (k, v) in lock_vars(varmap)?.iter() {
        let t = tensors
            .get(&format!("{prefix}{k}"))
            .ok_or_else(|| bad(format!("`{prefix}{k}` is missing")))?;
        if t.shape() != v.shape() {
            return Err(bad(format!(
                "`{prefix}{k}` has shape {:?}, expected {:?}",
                t.dims(),
                v.dims()
            )));
        }
        v.set(t)?;
    }
    Ok(())
}

/// Writes `tensors` to `path` atomically (a temporary file renamed over it).
pub(crate) fn save_tensors(
    tensors: &HashMap<String, Tensor>,
    path: &Path,
) -> Result<(), TrainError> {
    let tmp = path.with_extension("tmp");
    candle_core::safetensors::save(tensors, &tmp)?;
    std::fs::rename(&tmp, path).map_err(|source| TrainError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Reads a safetensors checkpoint; a file that cannot be read is a [`TrainError::Checkpoint`].
pub(crate) fn load_tensors(path: &Path) -> Result<HashMap<String, Tensor>, TrainError> {
    candle_core::safetensors::load(path, &Device::Cpu).map_err(|e| TrainError::Checkpoint {
        path: path.to_owned(),
        reason: e.to_string(),
    })
}

/// Opens a CSV log for appending after a (re)start: keeps the header and the rows of iterations
/// `1..=keep` already written (a crash may have logged iterations after the last checkpoint,
/// which the resumed run writes again) and drops the rest.
fn reopen_log(path: &Path, header: &str, keep: u64) -> Result<std::fs::File, TrainError> {
    reopen_log_keeping(path, header, |row| {
        row.split(',')
            .next()
            .and_then(|i| i.parse::<u64>().ok())
            .is_some_and(|i| i <= keep)
    })
}

/// Recreates the CSV log `path` with `header` and the rows of the old file for which `keep`
/// holds (none when there is no old file), and returns it open for appending rows.
pub(crate) fn reopen_log_keeping(
    path: &Path,
    header: &str,
    keep: impl Fn(&str) -> bool,
) -> Result<std::fs::File, TrainError> {
    let io = |source| TrainError::Io {
        path: path.to_owned(),
        source,
    };
    let mut kept = vec![header.to_string()];
    if let Ok(text) = std::fs::read_to_string(path) {
        kept.extend(text.lines().skip(1).filter(|l| keep(l)).map(str::to_string));
    }
    let mut file = std::fs::File::create(path).map_err(io)?;
    writeln!(file, "{}", kept.join("\n")).map_err(io)?;
    Ok(file)
}

#[cfg(test)]
mod tests;
