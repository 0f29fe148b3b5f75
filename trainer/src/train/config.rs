//! Stage-1 training configuration (a JSON file; every field has a default).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::optim::AdamConfig;

/// Loss weights λ of the stage-1 objective.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossWeights {
    /// Silhouette, boundary-vertex term (mean distance in pixels per boundary vertex).
    pub silhouette_boundary: f64,
    /// Silhouette, contour-pixel term (mean distance in pixels per contour pixel).
    pub silhouette_contour: f64,
    /// Laplacian (mean squared norm per vertex, in units of the template's bounding-box
    /// diagonal, squared). Measured relative to the character's size so that the same weight
    /// holds a character modelled in metres and one modelled in centimetres equally: in metres²
    /// (the first version) the term weighed 5,000 times more, relative to the silhouettes, on
    /// the zoo's Fox (a 176-unit diagonal) than on the built-in character (2.48 m), and held its
    /// weights at bone heat (SkinNet 108.7 against bone heat's 123.1, oracle 15.0; 57.3 with the
    /// weight rescaled). 6,130 is the former 1,000 m⁻² at the built-in character's 2.476 m
    /// diagonal, so that character trains as before.
    pub laplacian: f64,
    /// Geodesic skinning regulariser (mean per vertex; Eqs. 7–8). Off by default: the
    /// candidate joints ([`TrainConfig::candidate_joints`]) make its purpose, locality, a hard
    /// constraint, and as a soft term it holds the weights near the initial ones. On the
    /// built-in capture (1,000 image iterations, 8 candidates) switching both regularisers off
    /// took SkinNet from 0.896 to 0.696 cm Chamfer (bone heat 1.003); see docs/experiments/fidelity.md.
    pub skinning: f64,
    /// Part-wise regulariser (mean per rigid skin vertex; off by default, see `skinning`).
    pub partwise: f64,
    /// Prior on the initial weights during the image losses: `KL(w_init ‖ w)` per vertex
    /// (nats), the warm start's objective kept on at a small weight. The silhouettes say
    /// nothing about a vertex they never see (between the legs, in an armpit, a ball centred on
    /// its joint), yet SkinNet moves it with the vertices they do see, because the network is
    /// shared; this term keeps such vertices at their initial weights while the image terms
    /// outweigh it wherever they have something to say.
    pub prior: f64,
    /// The same prior restricted to the vertices no training outline shows
    /// ([`crate::train::hidden`]; which ones: [`TrainConfig::hidden_view_fraction`]): `KL(w_init
    /// ‖ w)` summed over them, divided by the template's vertex count (so at equal weight a
    /// hidden vertex is held as [`Self::prior`] holds every vertex). The silhouettes cannot
    /// correct those vertices, and the shared network would otherwise move them with the
    /// vertices they do see.
    ///
    /// Off by default (measured 2026-12-07, docs/experiments/fidelity.md, "The prior on the
    /// hidden vertices"): it turns silhouettes without the Laplacian from worse than bone heat
    /// into 0.57–0.59 cm on the built-in capture, but added to the defaults it costs 0.024 cm
    /// there, 0.02–0.04 on the held-out phases and 18–38 % on four zoo characters (ours then
    /// above static), while the worst-vertex checks still fail.
    ///
    /// SkinNet only: the static baseline's weights are free per vertex, so nothing carries the
    /// seen vertices' change onto the hidden ones, and its hidden vertices move only with their
    /// neighbours through the Laplacian, which is what they should do (the baseline with the
    /// prior scored 0.739 cm against 0.671 without, the built-in capture's seed 0).
    pub hidden_prior: f64,
    /// A hinge on how far the vertices no training outline shows move from the initial
    /// skinning, beyond [`TrainConfig::hidden_drift_ratio`] times the seen vertices' 99th
    /// percentile in the same batch ([`crate::train::hidden::drift_hinge`]): squared excess
    /// over the squared bounding-box diagonal, per vertex and frame. SkinNet only, as
    /// [`Self::hidden_prior`].
    ///
    /// On by default (1e4; measured 2026-12-07, docs/experiments/fidelity.md, "A hinge on the
    /// hidden vertices' drift"): silhouettes without the Laplacian then score 0.591 / 0.532 /
    /// 0.619 cm on the built-in capture's seed 0 (training seeds 0–2) against bone heat's 1.003
    /// and 1.236 / 0.983 / 1.026 without it, and the full method 0.558 / 0.554 / 0.549 against
    /// 0.555 / 0.562 / 0.557 (captures and training seeds 0–2). At 1e6 it holds the seen
    /// vertices back too (silhouettes alone 0.805 cm on training seed 2).
    pub hidden_drift: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            silhouette_boundary: 1.0,
            silhouette_contour: 1.0,
            laplacian: 6.13e3,
            skinning: 0.0,
            partwise: 0.0,
            prior: 0.0,
            hidden_prior: 0.0,
            hidden_drift: 1e4,
        }
    }
}

/// What the Laplacian loss compares the posed mesh's differential coordinates with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LaplacianReference {
    /// Zero, as Eq. 6 writes it: `Σ_i ‖δ_i(x)‖²`. Its minimum is a flat, shrunken mesh, and on
    /// the built-in capture the regularisers alone (no silhouettes) took a warm-started SkinNet
    /// from 1.06 to 5.67 cm Chamfer in 100 iterations.
    Absolute,
    /// The same pose skinned with the initial weights: `Σ_i ‖δ_i(x) − δ_i(x_init)‖²`, which is
    /// zero at the initial skinning and penalises only the roughness that new weights add.
    #[default]
    InitialSkinning,
}

/// Everything a stage-1 run depends on besides the data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Seed of the parameter initialisation and of the frame sampling.
    pub seed: u64,
    /// Image-loss iterations.
    pub iterations: u64,
    /// Frames per iteration (paper: 4).
    pub batch: usize,
    /// Most warm-start iterations (regressing the initial weights before the image losses):
    /// the warm start stops earlier once it has converged (see `warm_start_kl_tolerance`), and
    /// reports when it hit this cap without converging.
    pub warm_start_iterations: u64,
    /// The warm start has converged when, averaged over the last `warm_start_window`
    /// iterations, `KL(w_init ‖ w)` per vertex is at most this (nats)…
    pub warm_start_kl_tolerance: f64,
    /// …and the root-mean-square distance between the vertices skinned with SkinNet's and with
    /// the initial weights is at most this fraction of the template's bounding-box diagonal
    /// (scale-free: 1e-3 is 2 mm on a 2 m character). Measured on the built-in capture: KL 0.016
    /// and 1.3e-3 after 300 iterations, 0.008 and 7e-4 after 600. Tighter (KL 0.002, 3e-4; tried
    /// as the default on 2026-12-06, not kept): the warm start alone then scores below bone heat
    /// on all three demo seeds (0.982 / 0.996 / 0.937 cm Chamfer against 1.003 / 1.024 / 0.970;
    /// at these defaults 1.025 / 1.026 / 0.969), but it takes 780–885 iterations instead of
    /// 237–255, the trained SkinNet ends 0.003–0.011 cm worse on every seed, and the zoo's robot
    /// (43 joints) and Witch (62) stop at the cap unconverged.
    pub warm_start_position_tolerance: f64,
    /// Iterations the convergence test averages over (single batches are noisy).
    pub warm_start_window: u64,
    /// The warm start's learning rate halves every this many iterations (0: constant `adam.lr`).
    /// The rate is a function of the iteration alone, so a resumed run follows the same
    /// schedule. At a constant rate the zoo's robot (43 joints) and Witch (62) stopped at the
    /// cap of 2,000 iterations unconverged, their position error hovering at 1.2–1.7e-3 of the
    /// diagonal from iteration 800 on (tolerance 1e-3), while the characters with 19–24 joints
    /// converge in 236–300 iterations, which this leaves untouched. Halving every 500 made the
    /// robot's warm start converge after 1,451 iterations but left the Witch at the cap (KL
    /// 0.0118, position 1.2e-3); every 1,000 (the default) the robot converges after 1,118 and
    /// the Witch after 2,069 (KL 0.0081, position 9.9e-4), with the same SkinNet scores within
    /// run-to-run noise (robot 0.211 → 0.214 cm, Witch 0.262 → 0.258; zoo, seed 0).
    pub warm_start_lr_halving: u64,
    /// Frames per warm-start iteration. The target (the initial weights) does not depend on the
    /// pose, so one frame per iteration sees as many vertices per step at a quarter of the cost
    /// of four, and the poses still vary from step to step.
    pub warm_start_batch: usize,
    /// Weight of the warm start's posed-position term, whose unit is the squared fraction of the
    /// template's bounding-box diagonal ([`super::Trainer::warm_step`]); 0 (KL alone) by
    /// default. Measured after 300 warm-start iterations on the built-in capture (Chamfer) when
    /// the term was in cm² (its diagonal is 247.6 cm, so 1 per cm² is 61,300 here): 61,300 made
    /// the KL rise to 3.1 by iteration 100 while the position error fell to 62 cm² (stopped);
    /// 613 gave 1.130 cm, against 1.059 cm for KL alone on the previous training template (the
    /// simplifier changed in between, so not a clean comparison).
    pub warm_start_position_weight: f64,
    /// Adam settings (paper: lr 1e-3, gradient values clipped to [−1, 1]).
    pub adam: AdamConfig,
    /// Image-loss iterations over which the learning rate ramps linearly up to `adam.lr` (0:
    /// none). Adam's first steps move every parameter by about lr at once, whatever its gradient
    /// (`m̂/√v̂ = ±1` at step 1); for SkinNet that one step tripled the silhouette error.
    pub lr_warmup: u64,
    /// The image phase's learning rate falls from `adam.lr` (after the warm-up ramp) to this
    /// fraction of it along a half cosine, so the last iterations settle instead of jittering
    /// by a full step around the optimum (1: constant). Stage 4 follows the same shape over its
    /// own iterations. The schedule follows the configured iteration counts: resuming with
    /// different counts changes it for the iterations that remain.
    pub lr_final_fraction: f64,
    /// Half-life, in image iterations, of the exponential moving average of the parameters that
    /// is exported instead of the last iterate (0: export the last iterate). Averaging the
    /// iterates of a noisy optimisation removes most of its run-to-run spread.
    pub ema_half_life: f64,
    /// Learning rate of the static baseline's logits (Adam moves a parameter by about the
    /// learning rate per step, and a logit may need to move by several units).
    pub static_lr: f64,
    /// Pose each training vertex at the canonical position of the full-resolution vertex its
    /// weights are queried at ([`super::queries`]), so that weights and rest position belong to
    /// the same point.
    pub consistent_queries: bool,
    /// Normalise canonical positions for the positional encoding by a cube around the template
    /// (the largest side) instead of its bounding box, so the encoding's frequencies are the
    /// same along every axis.
    pub cubic_normalisation: bool,
    /// Candidate joints per point ([`crate::candidates`]): SkinNet's (and the static
    /// baseline's) softmax ranges over at most this many joints near each point, the rest
    /// weigh exactly zero; 0 turns the restriction off.
    pub candidate_joints: usize,
    /// A skeleton neighbour of a point's bone-heat support joins its candidates only if one of
    /// its bones passes within this many times the point's distance to the support's bones
    /// (`null` in JSON or infinite: no gate; [`crate::candidates::candidate_sets`]).
    #[serde(with = "reach_serde")]
    pub candidate_reach: f32,
    /// With [`LossWeights::hidden_prior`] or [`LossWeights::hidden_drift`]: a vertex counts as
    /// hidden when the template posed by the initial weights has it on its outline in at most
    /// this fraction of the training views (frames × cameras); 0: on none ([`super::hidden`]).
    pub hidden_view_fraction: f64,
    /// With [`LossWeights::hidden_drift`]: how many times the seen vertices' 99th-percentile
    /// drift the hidden ones may move before the hinge acts (by default the ratio above which
    /// [`crate::train::hidden::HiddenDrift`] warns).
    pub hidden_drift_ratio: f64,
    /// Training frames held out for validation from images ([`super::validation`]), spread
    /// evenly; at most a quarter of the frames, none (validate on the training frames) with
    /// fewer than four. 0 turns validation and best-average selection off.
    pub validation_frames: usize,
    /// Validate the parameter average every this many image iterations (and after the last);
    /// the best average is the one exported.
    pub validation_every: u64,
    /// Refuse to export a model that explains the validation silhouettes worse than the
    /// initial weights (`trainer train --allow-worse` turns this off).
    pub refuse_worse_than_initial: bool,
    /// Loss weights.
    pub weights: LossWeights,
    /// The Laplacian loss's reference shape.
    pub laplacian_reference: LaplacianReference,
    /// Geodesic regulariser exponent r (paper: 3).
    pub skinning_r: f32,
    /// Part-wise rigidity threshold u (paper: 0.95).
    pub partwise_u: f32,
    /// Exact geodesic `d_max` up to this many graph nodes (double sweep above).
    pub exact_diameter_limit: usize,
    /// Write a checkpoint every this many iterations (0: only at the end).
    pub checkpoint_every: u64,
    /// Scale of the initial output layer (small: near-uniform weights before the warm start).
    pub output_init_scale: f32,
    /// Static baseline: its logits start at `ln(w_init + ε)`, which moves `Jε/(1 + Jε)` of every
    /// vertex's weight onto all joints, far ones included. Before any training, on the built-in
    /// capture (Chamfer, initial weights 1.003 cm): ε = 0.01 (19 % moved) 2.807 cm, 1e-3 (2.3 %)
    /// 1.173 cm, 1e-4 (the default, 0.24 %) 1.016 cm. The price of a small ε: a zero weight sits
    /// `−ln ε` logit units below the others, out of reach of Adam's ~lr-sized steps, so the
    /// baseline re-blends existing influences but does not add new ones.
    pub static_epsilon: f32,
    /// Query SkinNet, for each training vertex, at a seeded full-resolution template vertex of
    /// its cell instead of at the training vertex itself ([`super::queries`]). Measured on the
    /// built-in capture: see the module docs.
    pub full_resolution_queries: bool,
    /// Positional-encoding frequency count L of SkinNet (and of the appearance nets); default 8
    /// (see `docs/design.md`, *Positional encoding*): the finest period is then 1/128 of the
    /// normalisation cube (2 cm on the built-in character) instead of 1/32 at L = 6. Measured
    /// with pose locality on, the demo's budget and captures of seeds 0–2: Chamfer on the novel
    /// test motions 0.593 ± 0.018 cm against 0.613 ± 0.003 at L = 6, on the held-out phases
    /// 0.497 ± 0.005 against 0.512 ± 0.007 (the static baseline there: 0.506 ± 0.008, so
    /// SkinNet is below it on every seed again); the character zoo (400 image iterations, seed
    /// 0) lower on four characters, higher on the built-in one (0.739 against 0.648), which
    /// converges more slowly at L = 8 (docs/experiments/fidelity.md, *Positional encoding L = 8*).
    /// Earlier (before [`Self::full_resolution_queries`]) L = 4 had beaten L = 6 (1.030 against
    /// 1.166 cm), and L = 8 had cost the robot (1.497 against 1.257 cm) under that day's
    /// bone heat; neither holds with today's trainer.
    pub pe_frequencies: u32,
    /// Store the training poses' feature range in the exported `.skf` (`PRNG`), so the runtime
    /// clamps the pose features of any pose into it ([`skinfield_formats::skf::pose_range`]).
    /// Measured with the same weights scored both ways (docs/experiments/fidelity.md): on the
    /// built-in capture's novel test motions 0.619 ± 0.037 cm Chamfer unclamped, 0.598 ± 0.026
    /// clamped (3 seeds); on the character zoo between −3.6 % and +3.7 %.
    pub clamp_pose_features: bool,
    /// Huber width δ of both silhouette terms, in pixels ([`crate::losses::silhouette`]):
    /// quadratic below, linear (the paper's L1) above.
    pub silhouette_huber_px: f32,
    /// Stages 2–4 (appearance field and rendering loss). By default only stage 4 runs, for
    /// [`DEFAULT_REFINE_ITERATIONS`] iterations on the full-resolution template and without the
    /// rendering term ([`Self::default_stages`]): stage 1's losses continued where every
    /// vertex is trained, which measured 0.057 ± 0.025 cm Chamfer below the same iterations on
    /// the simplified template over three seeds of the built-in capture; the rendering term
    /// (λ_rend = 10, stages 2–3 first) cost 0.053 ± 0.068 cm more there
    /// (`docs/experiments/fidelity.md`, *Stage 4 at full resolution*). A configuration file that names `stages` takes [`StageConfig`]'s own
    /// defaults (the paper's λ_rend, no iterations) for the fields it leaves out.
    ///
    /// [`StageConfig`]: super::stages::StageConfig
    pub stages: super::stages::StageConfig,
    /// Per-frame pose corrections trained with the image losses (off by default; for captures
    /// with tracked motion, [`super::pose_refinement`]).
    pub pose_refinement: super::PoseRefinementConfig,
    /// One outline offset per camera learned with the weights, for masks whose segmentation
    /// grew or shrank every outline (on by default; [`super::outline_offset`]).
    pub outline_offset: super::outline_offset::OutlineOffsetConfig,
    /// Several SkinNets from different seeds, their mean weights distilled into the exported
    /// one ([`super::ensemble`]); one network by default. Not with pose refinement, whose
    /// corrections belong to one run (outline offsets start the student at the members' mean).
    pub ensemble: super::ensemble::EnsembleConfig,
    /// Pose locality ([`super::pose_locality`]): during the image iterations every training
    /// vertex sees its candidate joints' pose features from its own frame and every other
    /// joint's from another training frame drawn at random, so its weights are not taught to
    /// depend on joints that do not move it. It acts through the candidate lists, so it does
    /// nothing when `candidate_joints` is 0. On by default: on the built-in capture (3 seeds,
    /// 1,000 iterations) Chamfer 0.613 ± 0.003 against 0.598 ± 0.030 cm without it, with the
    /// vertex furthest off the true surface beyond bone heat's worst on 4 test frames instead
    /// of 13; on the character zoo CesiumMan and the Fox pass both worst-vertex checks with it
    /// and not without. It costs the poses between the training frames (the held-out-phase
    /// captures): 0.512 ± 0.007 cm against 0.494 ± 0.012 (docs/experiments/fidelity.md).
    pub pose_locality: bool,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            iterations: 300,
            batch: 4,
            warm_start_iterations: 3000,
            warm_start_kl_tolerance: 0.01,
            warm_start_position_tolerance: 1e-3,
            warm_start_window: 50,
            warm_start_lr_halving: 1000,
            warm_start_batch: 4,
            warm_start_position_weight: 0.0,
            adam: AdamConfig::default(),
            lr_warmup: 25,
            lr_final_fraction: 0.05,
            ema_half_life: 50.0,
            static_lr: 1e-2,
            consistent_queries: true,
            cubic_normalisation: true,
            candidate_joints: crate::candidates::DEFAULT_CANDIDATES,
            candidate_reach: crate::candidates::DEFAULT_NEIGHBOUR_REACH,
            hidden_view_fraction: 0.0,
            hidden_drift_ratio: f64::from(crate::train::hidden::UNCONFIRMED_DRIFT_RATIO),
            validation_frames: 4,
            validation_every: 100,
            refuse_worse_than_initial: true,
            weights: LossWeights::default(),
            laplacian_reference: LaplacianReference::default(),
            skinning_r: crate::losses::skinning_reg::PAPER_R,
            partwise_u: crate::losses::partwise::PAPER_U,
            exact_diameter_limit: 4096,
            checkpoint_every: 100,
            output_init_scale: 0.1,
            static_epsilon: 1e-4,
            full_resolution_queries: true,
            pe_frequencies: 8,
            clamp_pose_features: true,
            silhouette_huber_px: crate::losses::silhouette::DEFAULT_HUBER_PX,
            stages: Self::default_stages(),
            pose_refinement: super::PoseRefinementConfig::default(),
            outline_offset: super::outline_offset::OutlineOffsetConfig::default(),
            ensemble: super::ensemble::EnsembleConfig::default(),
            pose_locality: true,
        }
    }
}

/// Stage-4 iterations of [`TrainConfig::default_stages`].
pub const DEFAULT_REFINE_ITERATIONS: u64 = 100;

impl TrainConfig {
    /// The default [`TrainConfig::stages`]: stage 4 alone, [`DEFAULT_REFINE_ITERATIONS`]
    /// iterations on the full-resolution template, without the rendering term.
    #[must_use]
    pub fn default_stages() -> super::stages::StageConfig {
        super::stages::StageConfig {
            refine_iterations: DEFAULT_REFINE_ITERATIONS,
            rendering_weight: 0.0,
            full_resolution: true,
            ..super::stages::StageConfig::default()
        }
    }
}

/// [`TrainConfig::candidate_reach`] in JSON: a number, or `null` for no gate (JSON has no
/// infinity).
mod reach_serde {
    use serde::{Deserialize, Deserializer, Serializer};

    pub(super) fn serialize<S: Serializer>(reach: &f32, s: S) -> Result<S::Ok, S::Error> {
        if reach.is_finite() {
            s.serialize_f32(*reach)
        } else {
            s.serialize_none()
        }
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::INFINITY))
    }
}

/// Why a configuration file could not be used.
///
/// The cause is named in the message (for callers that print only that) and is also the
/// `source()`, like the project's other errors; `trainer` prints a cause once.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Reading failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// Not valid JSON for a [`TrainConfig`] (serde names the field).
    #[error("{path}: {source}")]
    Parse {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        #[source]
        source: serde_json::Error,
    },
    /// A value out of range.
    #[error("{path}: field `{field}` is invalid")]
    Field {
        /// The file.
        path: std::path::PathBuf,
        /// The field.
        field: &'static str,
    },
}

impl TrainConfig {
    /// Reads and validates a JSON configuration.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// A configuration from the JSON text of the file `path` (named in the errors), checked
    /// as [`TrainConfig::load`] checks it: for a caller that also keeps the text.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let c: Self = serde_json::from_str(text).map_err(|source| ConfigError::Parse {
            path: path.to_owned(),
            source,
        })?;
        c.validate().map_err(|field| ConfigError::Field {
            path: path.to_owned(),
            field,
        })?;
        Ok(c)
    }

    /// [`TrainConfig::load`] of `path` when one is given, otherwise the defaults: what `trainer
    /// train` and `trainer demo` start from.
    pub fn load_or_default(path: Option<&Path>) -> Result<Self, ConfigError> {
        path.map_or_else(|| Ok(Self::default()), Self::load)
    }

    /// Checks ranges; returns the first bad field.
    pub fn validate(&self) -> Result<(), &'static str> {
        if self.batch == 0 || self.batch > 64 {
            return Err("batch");
        }
        if !(self.silhouette_huber_px.is_finite() && self.silhouette_huber_px > 0.0) {
            return Err("silhouette_huber_px");
        }
        if self.warm_start_batch == 0 || self.warm_start_batch > 64 {
            return Err("warm_start_batch");
        }
        if !(self.warm_start_position_weight.is_finite() && self.warm_start_position_weight >= 0.0)
        {
            return Err("warm_start_position_weight");
        }
        if !(self.adam.lr.is_finite() && self.adam.lr > 0.0) {
            return Err("adam.lr");
        }
        if !(self.warm_start_kl_tolerance.is_finite() && self.warm_start_kl_tolerance >= 0.0) {
            return Err("warm_start_kl_tolerance");
        }
        if !(self.warm_start_position_tolerance.is_finite()
            && self.warm_start_position_tolerance >= 0.0)
        {
            return Err("warm_start_position_tolerance");
        }
        if self.warm_start_window == 0 || self.warm_start_window > 10_000 {
            return Err("warm_start_window");
        }
        if !(self.lr_final_fraction > 0.0 && self.lr_final_fraction <= 1.0) {
            return Err("lr_final_fraction");
        }
        if !(self.ema_half_life.is_finite() && self.ema_half_life >= 0.0) {
            return Err("ema_half_life");
        }
        if !(self.static_lr.is_finite() && self.static_lr > 0.0) {
            return Err("static_lr");
        }
        if self.candidate_joints > skinfield_formats::skf::candidates::MAX_CANDIDATES {
            return Err("candidate_joints");
        }
        if self.candidate_reach.is_nan() || self.candidate_reach <= 0.0 {
            return Err("candidate_reach");
        }
        self.pose_refinement.validate()?;
        self.outline_offset.validate()?;
        if !(0.0..=1.0).contains(&self.hidden_view_fraction) {
            return Err("hidden_view_fraction");
        }
        if !(self.hidden_drift_ratio.is_finite() && self.hidden_drift_ratio > 0.0) {
            return Err("hidden_drift_ratio");
        }
        if self.validation_frames > 0 && self.validation_every == 0 {
            return Err("validation_every");
        }
        if self.adam.clip.is_some_and(|c| !(c.is_finite() && c > 0.0)) {
            return Err("adam.clip");
        }
        let w = self.weights;
        for (v, f) in [
            (w.silhouette_boundary, "weights.silhouette_boundary"),
            (w.silhouette_contour, "weights.silhouette_contour"),
            (w.laplacian, "weights.laplacian"),
            (w.skinning, "weights.skinning"),
            (w.partwise, "weights.partwise"),
            (w.prior, "weights.prior"),
            (w.hidden_prior, "weights.hidden_prior"),
            (w.hidden_drift, "weights.hidden_drift"),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(f);
            }
        }
        if !(self.skinning_r.is_finite() && self.skinning_r > 0.0) {
            return Err("skinning_r");
        }
        if !(0.0..1.0).contains(&self.partwise_u) {
            return Err("partwise_u");
        }
        if !(self.output_init_scale.is_finite() && self.output_init_scale > 0.0) {
            return Err("output_init_scale");
        }
        if !(self.static_epsilon.is_finite() && self.static_epsilon > 0.0) {
            return Err("static_epsilon");
        }
        if self.pe_frequencies > skinfield_formats::skf::MAX_PE_FREQUENCIES {
            return Err("pe_frequencies");
        }
        self.stages.validate()?;
        self.ensemble.validate()?;
        // Pose corrections belong to one run: the distilled student would start its own from
        // zero in stage 4. (Outline offsets are one number per camera: the student starts from
        // the members' mean.)
        if self.ensemble.is_on() && self.pose_refinement.enabled {
            return Err("ensemble.members");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_and_bad_fields_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.json");
        std::fs::write(&p, serde_json::to_string(&TrainConfig::default()).unwrap()).unwrap();
        assert_eq!(TrainConfig::load(&p).unwrap(), TrainConfig::default());
        std::fs::write(&p, r#"{"batch": 0}"#).unwrap();
        assert!(matches!(
            TrainConfig::load(&p),
            Err(ConfigError::Field { field: "batch", .. })
        ));
        std::fs::write(&p, r#"{"pe_frequencies": 17}"#).unwrap();
        assert!(matches!(
            TrainConfig::load(&p),
            Err(ConfigError::Field {
                field: "pe_frequencies",
                ..
            })
        ));
        std::fs::write(&p, r#"{"iterations": 5, "bogus": 1}"#).unwrap();
        let e = TrainConfig::load(&p).unwrap_err().to_string();
        assert!(e.contains("bogus") && e.contains("c.json"), "{e}");
        std::fs::write(&p, r#"{"iterations": 5}"#).unwrap();
        assert_eq!(TrainConfig::load(&p).unwrap().iterations, 5);
        // No file: the defaults; a file: what `load` reads, errors included.
        assert_eq!(
            TrainConfig::load_or_default(None).unwrap(),
            TrainConfig::default()
        );
        assert_eq!(
            TrainConfig::load_or_default(Some(&p)).unwrap().iterations,
            5
        );
        std::fs::write(&p, r#"{"batch": 0}"#).unwrap();
        assert!(matches!(
            TrainConfig::load_or_default(Some(&p)),
            Err(ConfigError::Field { field: "batch", .. })
        ));
        // Text already read: what `load` makes of the same file, the path named in errors.
        let named = Path::new("named.json");
        assert_eq!(
            TrainConfig::parse(r#"{"iterations": 7}"#, named)
                .unwrap()
                .iterations,
            7
        );
        let e = TrainConfig::parse(r#"{"batch": 0}"#, named).unwrap_err();
        assert!(matches!(&e, ConfigError::Field { field: "batch", .. }));
        assert!(e.to_string().contains("named.json"), "{e}");
        assert!(matches!(
            TrainConfig::parse("{", named),
            Err(ConfigError::Parse { .. })
        ));
    }

    #[test]
    fn the_candidate_reach_is_a_number_or_null_and_positive() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.json");
        let load = |text: &str| {
            std::fs::write(&p, text).unwrap();
            TrainConfig::load(&p)
        };
        // JSON has no infinity: the default (no gate) is written as null and read back.
        let text = serde_json::to_string(&TrainConfig::default()).unwrap();
        assert!(text.contains(r#""candidate_reach":null"#), "{text}");
        assert_eq!(
            load(r#"{"candidate_reach": null}"#)
                .unwrap()
                .candidate_reach,
            f32::INFINITY
        );
        assert_eq!(
            load(r#"{"candidate_reach": 2.0}"#).unwrap().candidate_reach,
            2.0
        );
        assert!(matches!(
            load(r#"{"candidate_reach": 0}"#),
            Err(ConfigError::Field {
                field: "candidate_reach",
                ..
            })
        ));
    }

    #[test]
    fn an_ensemble_has_one_to_max_members_and_no_pose_refinement() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.json");
        let field = |text: &str| {
            std::fs::write(&p, text).unwrap();
            match TrainConfig::load(&p) {
                Ok(c) => Ok(c.ensemble.members),
                Err(ConfigError::Field { field, .. }) => Err(field),
                Err(e) => panic!("{e}"),
            }
        };
        assert_eq!(field("{}"), Ok(1));
        assert_eq!(field(r#"{"ensemble": {"members": 3}}"#), Ok(3));
        let max = super::super::ensemble::MAX_MEMBERS;
        assert_eq!(
            field(&format!(r#"{{"ensemble": {{"members": {max}}}}}"#)),
            Ok(max)
        );
        for bad in [
            r#"{"ensemble": {"members": 0}}"#.to_string(),
            format!(r#"{{"ensemble": {{"members": {}}}}}"#, max + 1),
            r#"{"ensemble": {"members": 2}, "pose_refinement": {"enabled": true}}"#.to_string(),
        ] {
            assert_eq!(field(&bad), Err("ensemble.members"), "{bad}");
        }
        assert_eq!(
            field(r#"{"ensemble": {"kl_tolerance": -1}}"#),
            Err("ensemble.kl_tolerance")
        );
        // One network with pose refinement stays valid.
        assert_eq!(field(r#"{"pose_refinement": {"enabled": true}}"#), Ok(1));
        assert_eq!(field(r#"{"outline_offset": {"enabled": true}}"#), Ok(1));
        // Outline offsets (on by default) go with an ensemble.
        assert_eq!(
            field(r#"{"ensemble": {"members": 2}, "outline_offset": {"enabled": true}}"#),
            Ok(2)
        );
        assert_eq!(
            field(r#"{"outline_offset": {"enabled": true, "lr": 0}}"#),
            Err("outline_offset.lr")
        );
    }
}
