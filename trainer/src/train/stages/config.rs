//! The configuration of stages 2–4: iterations, sampling, the rendering loss's weight and
//! colours, the target images' blur.

use serde::{Deserialize, Serialize};

use super::checkpoint::StageProgress;

/// What colours the rendering loss gives the mesh in stage 4.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ColourSource {
    /// AlbedoNet × ShadowNet (the paper's method).
    #[default]
    Field,
    /// AlbedoNet only (stage 3 skipped).
    AlbedoOnly,
    /// Per-vertex colours averaged from the first training frame's images (no appearance nets).
    FixedVertexColours,
    /// The template's own vertex colours as the albedo (a textured scan's, or a synthetic
    /// capture's true albedo), ShadowNet learned over it in stage 3 (stage 2 skipped). On a
    /// synthetic capture this is the rendering loss with the appearance it was rendered from,
    /// less the shading: what the term can do when the appearance is not what limits it.
    TemplateAlbedo,
}

/// Stages 2–4 (a [`crate::train::TrainConfig`] field; all iterations 0 = stage 1 only).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StageConfig {
    /// Stage 2 (AlbedoNet) iterations.
    pub albedo_iterations: u64,
    /// Stage 3 (ShadowNet) iterations.
    pub shadow_iterations: u64,
    /// Stage 4 (SkinNet refined with the rendering loss) iterations.
    pub refine_iterations: u64,
    /// Visible pixels sampled per view and iteration.
    pub pixels_per_view: usize,
    /// Views rendered per frame and iteration (0 = all).
    pub views_per_frame: usize,
    /// Weight of the rendering loss in stage 4 (per-sample L1 summed over RGB). At 0 stage 4
    /// renders nothing: SkinNet continues with stage 1's losses on stage 4's learning-rate
    /// schedule (the "w/o L_rend" control of the ablation).
    pub rendering_weight: f64,
    /// Colours used by the rendering loss in stages 3 and 4.
    pub colours: ColourSource,
    /// Learning rate of the appearance nets (Adam otherwise as in stage 1).
    pub appearance_lr: f64,
    /// Standard deviation in pixels of the Gaussian that low-passes the target images inside
    /// their masks ([`crate::losses::rendering::blur_within_mask`]; 0 = the images as captured).
    pub image_blur_px: f64,
    /// Run stages 2–4 on the full-resolution template instead of stage 1's simplified training
    /// template (the run moves with [`crate::train::Trainer::with_data`]): stage 1 finds the
    /// weights cheaply on a quarter of the vertices, stage 4 then fits every vertex's outline
    /// and Laplacian where the 2,500-vertex template could only interpolate. See
    /// `docs/experiments/fidelity.md`, *Stage 4 at full resolution*.
    pub full_resolution: bool,
    /// Stage 4's learning rate as a fraction of stage 1's: stage 4 follows stage 1's half
    /// cosine (from `adam.lr` down to `lr_final_fraction` of it, without the warm-up ramp)
    /// over its own iterations, scaled by this. Restarting at the full rate undid part of a
    /// short stage 1 (the zoo's 400 iterations: 0.722 cm against 0.612 at one half, and a
    /// vertex 1.07 cm off the surface beyond bone heat's worst); after the demo's 1,000 it
    /// gained 0.011 cm more than one half does (three seeds). See
    /// `docs/experiments/fidelity.md`, *Stage 4's learning rate*.
    pub refine_lr_fraction: f64,
}

impl Default for StageConfig {
    fn default() -> Self {
        Self {
            albedo_iterations: 0,
            shadow_iterations: 0,
            refine_iterations: 0,
            pixels_per_view: 256,
            views_per_frame: 0,
            rendering_weight: 10.0,
            colours: ColourSource::Field,
            appearance_lr: 1e-3,
            image_blur_px: 2.0,
            full_resolution: false,
            refine_lr_fraction: 0.5,
        }
    }
}

impl StageConfig {
    /// True when any of stages 2–4 runs.
    #[must_use]
    pub fn any(&self) -> bool {
        self.albedo_iterations + self.shadow_iterations + self.refine_iterations > 0
    }

    /// True when any stage renders the colour images (stage 2 or 3 runs, or stage 4 with a
    /// rendering weight): without it stage 4 continues stage 1's losses and needs no images.
    #[must_use]
    pub fn renders(&self) -> bool {
        let s = self.scheduled();
        s.albedo + s.shadow > 0 || (s.refine > 0 && self.rendering_weight > 0.0)
    }

    /// "N stage-4 iterations" (with "at full resolution" where it moves there) for run
    /// summaries; `None` when stage 4 does not run.
    #[must_use]
    pub fn refine_summary(&self) -> Option<String> {
        let n = self.scheduled().refine;
        (n > 0).then(|| {
            let at = if self.full_resolution {
                " at full resolution"
            } else {
                ""
            };
            format!("{n} stage-4 iterations{at}")
        })
    }

    /// True when AlbedoNet is learned (stage 2 runs for these colours), so the appearance nets
    /// are worth storing in the exported model; with fixed colours or the template's albedo they
    /// would show an untrained net's noise in a viewer.
    #[must_use]
    pub fn learns_albedo(&self) -> bool {
        matches!(self.colours, ColourSource::Field | ColourSource::AlbedoOnly)
    }

    /// True when ShadowNet is learned (stage 3 runs for these colours) and shades the albedo in
    /// stage 4.
    #[must_use]
    pub fn learns_shading(&self) -> bool {
        matches!(
            self.colours,
            ColourSource::Field | ColourSource::TemplateAlbedo
        )
    }

    /// The iterations each of stages 2, 3 and 4 runs: the configured counts, less the stages
    /// that `colours` skips (no AlbedoNet with fixed vertex colours, no ShadowNet without the
    /// full field).
    #[must_use]
    pub(super) fn scheduled(&self) -> StageProgress {
        StageProgress {
            albedo: if self.learns_albedo() {
                self.albedo_iterations
            } else {
                0
            },
            shadow: if self.learns_shading() {
                self.shadow_iterations
            } else {
                0
            },
            refine: self.refine_iterations,
        }
    }

    /// Checks ranges; returns the first bad field.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.rendering_weight.is_finite() && self.rendering_weight >= 0.0) {
            return Err("stages.rendering_weight");
        }
        if !(self.refine_lr_fraction.is_finite() && self.refine_lr_fraction > 0.0) {
            return Err("stages.refine_lr_fraction");
        }
        if !(self.appearance_lr.is_finite() && self.appearance_lr > 0.0) {
            return Err("stages.appearance_lr");
        }
        if !(self.image_blur_px.is_finite()
            && (0.0..=MAX_IMAGE_BLUR_PX).contains(&self.image_blur_px))
        {
            return Err("stages.image_blur_px");
        }
        Ok(())
    }
}

/// Largest accepted [`StageConfig::image_blur_px`] (the blur costs `O(σ)` per pixel).
pub const MAX_IMAGE_BLUR_PX: f64 = 16.0;
