//! Stages 2–4 of the paper's schedule (§3.4, supplementary F), after stage 1 ([`Trainer::run`]):
//!
//! 2. AlbedoNet from the rendering loss alone, SkinNet frozen (colour `c = a`: ShadowNet is not
//!    trained yet);
//! 3. ShadowNet from the rendering loss, SkinNet and AlbedoNet frozen (`c = a · r`);
//! 4. SkinNet refined with every stage-1 loss plus `λ_rend · L_rend`, the appearance frozen.
//!
//! Every stage draws frames from the same seeded batches as stage 1 (a stream per stage and
//! iteration). Per frame and view the posed mesh is rasterised once; `pixels_per_view` visible
//! pixels are sampled from a generator seeded by `(seed, stage, iteration)` and, where
//! `views_per_frame` is set, only that many seeded views of each frame are rendered. The loss per
//! view is the mean over its samples of the L1 colour difference (summed over RGB), averaged
//! over the views of the batch ([`crate::losses::rendering`] documents what is differentiated).
//! The target images are low-passed inside their masks first (`image_blur_px`, default 2 px;
//! [`blur_within_mask`] says why): the rendered colours are interpolated from the training
//! template's vertices, about 3.6 px apart on the built-in capture, a tent filter whose
//! equivalent Gaussian has σ = 3.6/√6 ≈ 1.5 px; 2 px rounds that up, since nets fitted in a
//! hundred iterations are smoother than their vertices allow. On the built-in capture the
//! appearance then explains its targets to 0.079 per sample after stage 3, against 0.151 for
//! the sharp images; what that does to stage 4 is in the README's ablation section.
//! ShadowNet's normal and viewing-direction inputs are constants of the step (stage 4 moves the
//! vertices through the projected sample points only).
//!
//! The ablations of the paper's Table 2 are [`ColourSource`]s: without ShadowNet (stage 3
//! skipped, `c = a` in stage 4) and with fixed per-vertex colours read from the images of the
//! first training frame instead of the appearance field; [`ColourSource::TemplateAlbedo`]
//! takes the template's own vertex colours as the albedo (stage 2 skipped, ShadowNet learned
//! over it), which on a synthetic capture measures what the term can do when the appearance does
//! not limit it. Stages 2–4 write their own checkpoint
//! ([`checkpoint`]); `trainer train --resume` continues from it.

use std::io::Write;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use glam::Vec3;
use rand::seq::index::sample;
use skinfield_formats::capture::{Capture, CaptureImage};
use skinfield_formats::mesh::area_weighted_normals;

use super::data::{DataError, DataOptions};
use super::{Model, TrainError, Trainer, frame_rng, reopen_log_keeping};
use crate::appearance::{Appearance, shadow_input};
use crate::losses::lbs::lbs;
use crate::losses::rendering::{RgbTarget, blur_within_mask, rendering_loss, sample_visible};
use crate::raster::rasterize;
use checkpoint::{STAGES_CHECKPOINT, StageProgress, StageState};
pub use config::{ColourSource, MAX_IMAGE_BLUR_PX, StageConfig};

/// The colour images of the training frames, `[frame][view]` in [`super::data::train_data`]'s
/// order (the capture's training frames, its first `options.cameras` cameras), blurred inside
/// their masks by `blur_px` pixels ([`StageConfig::image_blur_px`]; masks are read only then).
pub fn load_images(
    capture: &Capture,
    options: &DataOptions,
    blur_px: f64,
) -> Result<Vec<Vec<RgbTarget>>, DataError> {
    let cameras = match options.cameras {
        0 => capture.rig.cameras.len(),
        c => c.min(capture.rig.cameras.len()),
    };
    capture
        .train_frames
        .iter()
        .map(|&f| {
            (0..cameras)
                .map(|c| {
                    let img = capture.load_image(c, f)?;
                    let (w, h) = (img.width as usize, img.height as usize);
                    let rgb = if blur_px > 0.0 {
                        blurred(capture, (c, f), &img, blur_px)?
                    } else {
                        img.rgb
                    };
                    RgbTarget::new(w, h, &rgb).map_err(|e| {
                        DataError::Inconsistent(format!(
                            "{}: {e}",
                            capture.image_path(c, f).display()
                        ))
                    })
                })
                .collect()
        })
        .collect()
}

/// The image of camera `c`, frame `f` blurred by `blur_px` inside its mask.
fn blurred(
    capture: &Capture,
    (c, f): (usize, usize),
    img: &CaptureImage,
    blur_px: f64,
) -> Result<Vec<Vec3>, DataError> {
    let mask = capture.load_mask(c, f)?;
    let mismatch = || {
        DataError::Inconsistent(format!(
            "{}: {}×{} mask for a {}×{} image",
            capture.mask_path(c, f).display(),
            mask.width,
            mask.height,
            img.width,
            img.height
        ))
    };
    if (mask.width, mask.height) != (img.width, img.height) {
        return Err(mismatch());
    }
    let (w, h) = (img.width as usize, img.height as usize);
    blur_within_mask(w, h, &img.rgb, &mask.inside, blur_px as f32).ok_or_else(mismatch)
}

/// How corner colours are produced in one rendering-loss evaluation.
#[derive(Clone, Copy)]
enum Colouring<'a> {
    /// `a`, trainable (stage 2).
    Albedo(&'a Appearance),
    /// `a.detach() · r`, `r` trainable (stage 3).
    Shadow(&'a Appearance),
    /// Everything frozen (stage 4): the field (`true`) or the albedo alone (`false`).
    Frozen(&'a Appearance, bool),
    /// Fixed per-vertex colours `[V, 3]`.
    Fixed(&'a Tensor),
}

/// The stage-4 rendering term held by the [`Trainer`] while it refines SkinNet.
pub(crate) struct RenderingTerm {
    images: Vec<Vec<RgbTarget>>,
    appearance: Appearance,
    fixed: Option<Tensor>,
    /// The template's colours as the albedo ([`ColourSource::TemplateAlbedo`]).
    albedo: Option<Tensor>,
    config: StageConfig,
    /// Unweighted value of the last evaluation.
    last: f64,
}

/// Stage identifiers for the seeded streams (stage 1 uses phases 1 and 2).
const PHASE_ALBEDO: u64 = 12;
const PHASE_SHADOW: u64 = 13;
const PHASE_REFINE: u64 = 14;

impl Trainer {
    fn encoded(&self) -> Result<&Tensor, TrainError> {
        match &self.model {
            Model::Net { encoded, .. } => Ok(encoded),
            Model::Static { .. } => Err(TrainError::Data(
                "stages 2–4 need SkinNet, not the static baseline".into(),
            )),
        }
    }

    /// Posed training vertices `[B, V, 3]` of `frames`.
    ///
    /// With pose refinement, at the poses corrected so far (stage 4's iterations keep
    /// correcting them, stages 2–3 do not).
    fn posed(&self, frames: &[usize]) -> Result<Tensor, TrainError> {
        let w = self.weights(frames)?;
        let skinning = self.frame_skinning(frames)?.detach();
        Ok(lbs(&w, &skinning, &self.rest)?)
    }

    /// The training template's vertex colours `[V, 3]` as the albedo of
    /// [`ColourSource::TemplateAlbedo`] (`None` for the other sources).
    fn template_albedo(&self, config: &StageConfig) -> Result<Option<Tensor>, TrainError> {
        if config.colours != ColourSource::TemplateAlbedo {
            return Ok(None);
        }
        let colours = self.data.template.colors.as_ref().ok_or_else(|| {
            TrainError::Data(
                "stages.colours = template_albedo needs a template with vertex colours".into(),
            )
        })?;
        let flat: Vec<f32> = colours.iter().flat_map(|c| c.to_array()).collect();
        Ok(Some(Tensor::from_vec(
            flat,
            (colours.len(), 3),
            &Device::Cpu,
        )?))
    }

    /// Mean rendering loss over the views of `frames` for posed vertices `[B, V, 3]`, samples
    /// drawn from the stream `(phase, iteration)`; `albedo` replaces AlbedoNet's output where
    /// given ([`ColourSource::TemplateAlbedo`]).
    #[allow(clippy::too_many_arguments)]
    fn rendering_mean(
        &self,
        images: &[Vec<RgbTarget>],
        frames: &[usize],
        posed: &Tensor,
        colouring: Colouring,
        albedo: Option<&Tensor>,
        config: &StageConfig,
        (phase, iteration): (u64, u64),
    ) -> Result<Tensor, TrainError> {
        let mut rng = frame_rng(self.config.seed, phase, iteration);
        let encoded = self.encoded()?;
        let triangles = &self.data.template.triangles;
        let albedo_all = match (colouring, albedo) {
            (Colouring::Fixed(_), _) => None,
            (_, Some(t)) => Some(t.clone()),
            (Colouring::Albedo(a), None) => Some(a.albedo(encoded)?),
            (Colouring::Shadow(a) | Colouring::Frozen(a, _), None) => {
                Some(a.albedo(encoded)?.detach())
            }
        };
        let posed_values = posed.to_vec3::<f32>()?;
        let mut terms = Vec::new();
        for (k, &f) in frames.iter().enumerate() {
            let frame = &self.data.frames[f];
            let pts: Vec<Vec3> = posed_values[k]
                .iter()
                .map(|p| Vec3::from_slice(p))
                .collect();
            let normals: Vec<Vec3> = area_weighted_normals(&pts, triangles)
                .into_iter()
                .map(|n| n.normalize_or(Vec3::Y))
                .collect();
            let xk = posed.get(k)?;
            let n_views = frame.views.len().min(images[f].len());
            let views: Vec<usize> = match config.views_per_frame {
                0 => (0..n_views).collect(),
                m if m >= n_views => (0..n_views).collect(),
                m => sample(&mut rng, n_views, m).into_vec(),
            };
            for c in views {
                let camera = &frame.views[c].camera;
                let frags = rasterize(camera, &pts, triangles);
                let s = sample_visible(&frags, triangles, config.pixels_per_view, &mut rng);
                if s.is_empty() {
                    continue;
                }
                let idx = Tensor::from_slice(&s.corners, s.corners.len(), &Device::Cpu)?;
                let shade = |a: &Appearance| -> Result<Tensor, TrainError> {
                    let eye = camera.center();
                    let corner_n: Vec<Vec3> =
                        s.corners.iter().map(|&v| normals[v as usize]).collect();
                    let dirs: Vec<Vec3> = s
                        .corners
                        .iter()
                        .map(|&v| (pts[v as usize] - eye).normalize_or_zero())
                        .collect();
                    let input = shadow_input(
                        &encoded.index_select(&idx, 0)?,
                        &frame.pose_features,
                        &corner_n,
                        &dirs,
                    )?;
                    Ok(a.shading(&input)?)
                };
                let albedo = |t: &Option<Tensor>| -> Result<Tensor, TrainError> {
                    match t {
                        Some(t) => Ok(t.index_select(&idx, 0)?),
                        None => Err(TrainError::Data("no albedo".into())),
                    }
                };
                let colours = match colouring {
                    Colouring::Albedo(_) | Colouring::Frozen(_, false) => albedo(&albedo_all)?,
                    Colouring::Shadow(a) => albedo(&albedo_all)?.broadcast_mul(&shade(a)?)?,
                    Colouring::Frozen(a, true) => {
                        albedo(&albedo_all)?.broadcast_mul(&shade(a)?.detach())?
                    }
                    Colouring::Fixed(t) => t.index_select(&idx, 0)?,
                };
                let l = rendering_loss(camera, &images[f][c], &s, &xk, &colours)?;
                terms.push((l / s.len() as f64)?);
            }
        }
        Ok(if terms.is_empty() {
            Tensor::zeros((), DType::F32, &Device::Cpu)?
        } else {
            (Tensor::stack(&terms, 0)?.sum_all()? / terms.len() as f64)?
        })
    }

    /// The stage-4 term for [`Trainer::step`]: `λ_rend · L_rend` on the step's posed vertices
    /// (`None` outside stage 4).
    pub(super) fn rendering_term(
        &mut self,
        frames: &[usize],
        posed: &Tensor,
    ) -> Result<Option<Tensor>, TrainError> {
        let Some(mut term) = self.rendering.take() else {
            return Ok(None);
        };
        let colouring = match &term.fixed {
            Some(t) => Colouring::Fixed(t),
            None => Colouring::Frozen(&term.appearance, term.config.learns_shading()),
        };
        let result = self.rendering_mean(
            &term.images,
            frames,
            posed,
            colouring,
            term.albedo.as_ref(),
            &term.config,
            (PHASE_REFINE, self.done),
        );
        let out = result.and_then(|l| {
            term.last = f64::from(l.to_vec0::<f32>()?);
            Ok((l * term.config.rendering_weight)?)
        });
        self.rendering = Some(term);
        out.map(Some)
    }

    /// Per-vertex colours of the training template from the images of training frame 0: every
    /// visible pixel adds its colour to its triangle's corners with barycentric weights, over
    /// all views; unseen vertices get the mean colour. Shading is baked in, as in a texture
    /// reconstructed from the capture (the paper's "NeuS texture" ablation).
    pub fn canonical_vertex_colours(
        &self,
        images: &[Vec<RgbTarget>],
    ) -> Result<Vec<Vec3>, TrainError> {
        let posed = self.posed(&[0])?.get(0)?.to_vec2::<f32>()?;
        let pts: Vec<Vec3> = posed.iter().map(|p| Vec3::from_slice(p)).collect();
        let triangles = &self.data.template.triangles;
        let mut sum = vec![Vec3::ZERO; pts.len()];
        let mut weight = vec![0f32; pts.len()];
        for (view, image) in self.data.frames[0].views.iter().zip(&images[0]) {
            let frags = rasterize(&view.camera, &pts, triangles);
            let all = sample_visible(&frags, triangles, 0, &mut frame_rng(0, 0, 0));
            let uv = (0..all.len()).map(|k| {
                let p = all.pixels[k] as usize;
                [
                    (p % image.width()) as f32 + 0.5,
                    (p / image.width()) as f32 + 0.5,
                ]
            });
            let uv: Vec<f32> = uv.flatten().collect();
            let rgb = image
                .sample(&Tensor::from_vec(uv, (all.len(), 2), &Device::Cpu)?)?
                .to_vec2::<f32>()?;
            for (k, c) in rgb.iter().enumerate() {
                for m in 0..3 {
                    let v = all.corners[3 * k + m] as usize;
                    sum[v] += Vec3::from_slice(c) * all.bary[k][m];
                    weight[v] += all.bary[k][m];
                }
            }
        }
        let seen: Vec<Vec3> = (0..pts.len())
            .filter(|&v| weight[v] > 0.0)
            .map(|v| sum[v] / weight[v])
            .collect();
        let mean = seen.iter().copied().sum::<Vec3>() / seen.len().max(1) as f32;
        Ok((0..pts.len())
            .map(|v| {
                if weight[v] > 0.0 {
                    sum[v] / weight[v]
                } else {
                    mean
                }
            })
            .collect())
    }

    /// Runs stages 2–4 of `config.stages` after stage 1 on the training frames' colour `images`
    /// ([`load_images`]), writing `stage,iteration,rendering,total` rows to `dir/stages.csv`
    /// and a checkpoint to `dir/stages.safetensors` every `checkpoint_every` iterations and at
    /// the end of each stage ([`checkpoint`]). Returns the appearance nets (untrained where their
    /// stage did not run).
    pub fn run_stages(
        &mut self,
        images: Vec<Vec<RgbTarget>>,
        dir: &Path,
        progress: bool,
    ) -> Result<Appearance, TrainError> {
        self.stages_from(images, dir, progress, false)
    }

    /// [`Trainer::run_stages`] continued from `dir/stages.safetensors` where it exists (after
    /// [`Trainer::resume`] and [`Trainer::run`] have finished stage 1); otherwise the same as
    /// `run_stages`. The configuration may add iterations to the stage that ran last or to
    /// later ones.
    pub fn resume_stages(
        &mut self,
        images: Vec<Vec<RgbTarget>>,
        dir: &Path,
        progress: bool,
    ) -> Result<Appearance, TrainError> {
        self.stages_from(images, dir, progress, true)
    }

    fn stages_from(
        &mut self,
        mut images: Vec<Vec<RgbTarget>>,
        dir: &Path,
        progress: bool,
        resume: bool,
    ) -> Result<Appearance, TrainError> {
        let config = self.config.stages;
        if !config.renders() {
            // Stage 4 without the rendering term reads no image.
            images.clear();
        } else {
            if !self.validation.is_empty()
                && images.len() == self.data.frames.len() + self.validation.len()
            {
                // Images of every training frame, as `load_images` reads them: the frames held
                // out for validation take no part in stages 2–4.
                super::validation::take_held_out(&mut images, self.config.validation_frames);
            }
            if images.len() != self.data.frames.len()
                || images
                    .iter()
                    .zip(&self.data.frames)
                    .any(|(i, f)| i.len() != f.views.len())
            {
                return Err(TrainError::Data(
                    "colour images do not match the training frames and views".into(),
                ));
            }
        }
        let net_config = *self
            .net()
            .ok_or_else(|| TrainError::Data("stages 2–4 need SkinNet".into()))?
            .config();
        let appearance =
            Appearance::seeded(net_config, self.config.seed, self.config.output_init_scale)?;
        let io = |source: std::io::Error| TrainError::Io {
            path: dir.join("stages.csv"),
            source,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let ckpt = dir.join(STAGES_CHECKPOINT);
        let mut state = if resume && ckpt.exists() {
            self.load_stages(&ckpt, &appearance)?
        } else {
            StageState::default()
        };
        let mut csv = reopen_stage_log(&dir.join("stages.csv"), state.progress, self.done)?;
        let bar = |n: u64, done: u64, name: &str| {
            let b = if progress {
                indicatif::ProgressBar::new(n)
            } else {
                indicatif::ProgressBar::hidden()
            };
            b.set_prefix(name.to_string());
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{prefix} {bar:30} {pos}/{len} {elapsed_precise} {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            b.set_position(done.min(n));
            b
        };
        let adam = crate::optim::AdamConfig {
            lr: config.appearance_lr,
            ..self.config.adam
        };
        let every = self.config.checkpoint_every;
        let use_nets = config.colours != ColourSource::FixedVertexColours;
        let template_albedo = self.template_albedo(&config)?;
        let scheduled = config.scheduled();
        for (stage, iterations, phase) in [
            (2u64, scheduled.albedo, PHASE_ALBEDO),
            (3, scheduled.shadow, PHASE_SHADOW),
        ] {
            let start = *state.progress.of_appearance_stage(stage);
            if start >= iterations {
                continue;
            }
            let vars = if stage == 2 {
                appearance.albedo_vars()
            } else {
                appearance.shadow_vars()
            };
            let mut optimiser = checkpoint::stage_optimiser(
                vars,
                adam,
                stage,
                start,
                &state.appearance_optimiser,
                &ckpt,
            )?;
            let b = bar(
                iterations,
                start,
                if stage == 2 { "albedo" } else { "shadow" },
            );
            for it in start..iterations {
                let frames = self.sample(phase, it);
                let posed = self.posed(&frames)?.detach();
                let colouring = if stage == 2 {
                    Colouring::Albedo(&appearance)
                } else {
                    Colouring::Shadow(&appearance)
                };
                let loss = self.rendering_mean(
                    &images,
                    &frames,
                    &posed,
                    colouring,
                    template_albedo.as_ref(),
                    &config,
                    (phase, it),
                )?;
                let value = f64::from(loss.to_vec0::<f32>()?);
                writeln!(csv, "{stage},{},{value:.6e},{value:.6e}", it + 1).map_err(io)?;
                optimiser.backward_step(&loss)?;
                *state.progress.of_appearance_stage(stage) = it + 1;
                b.set_message(format!("L_rend {value:.4}"));
                b.inc(1);
                if (every > 0 && (it + 1).is_multiple_of(every)) || it + 1 == iterations {
                    csv.flush().map_err(io)?;
                    state.appearance_optimiser = Some((stage, optimiser.state_tensors()?));
                    self.save_stages(&ckpt, &appearance, &state)?;
                }
            }
            b.finish();
        }
        // λ_rend = 0 is stage 1's losses on stage 4's schedule: the ablation's control, which
        // renders nothing.
        let rendered = config.rendering_weight > 0.0;
        if state.progress.refine < config.refine_iterations {
            if rendered && !use_nets && state.fixed.is_none() {
                let c = self.canonical_vertex_colours(&images)?;
                let flat: Vec<f32> = c.iter().flat_map(|v| v.to_array()).collect();
                state.fixed = Some(Tensor::from_vec(flat, (c.len(), 3), &Device::Cpu)?);
            }
            self.rendering = rendered.then(|| RenderingTerm {
                images,
                appearance: appearance.clone(),
                fixed: state.fixed.clone(),
                albedo: template_albedo,
                config,
                last: 0.0,
            });
            let b = bar(config.refine_iterations, state.progress.refine, "refine");
            let result = (|| -> Result<(), TrainError> {
                while state.progress.refine < config.refine_iterations {
                    let r = self.step()?;
                    state.progress.refine += 1;
                    let l = self.rendering.as_ref().map_or(0.0, |t| t.last);
                    writeln!(csv, "4,{},{l:.6e},{:.6e}", r.iteration, r.total).map_err(io)?;
                    b.set_message(format!(
                        "total {:.3} sil {:.2}/{:.2}px L_rend {l:.4}",
                        r.total, r.silhouette_boundary, r.silhouette_contour
                    ));
                    b.inc(1);
                    let n = state.progress.refine;
                    if (every > 0 && n.is_multiple_of(every)) || n == config.refine_iterations {
                        csv.flush().map_err(io)?;
                        self.save_stages(&ckpt, &appearance, &state)?;
                    }
                }
                Ok(())
            })();
            self.rendering = None;
            result?;
            b.finish();
        }
        csv.flush().map_err(io)?;
        self.write_profile(dir)?;
        self.write_outline_offsets(dir)?;
        Ok(appearance)
    }
}

/// Opens `stages.csv` for a (re)start: keeps the header and the rows of the iterations in
/// `done` (stage-4 rows are numbered by SkinNet's image iteration, `skin_done` after the
/// restore) and drops rows a crash logged after the last checkpoint, or every row of an old
/// run when nothing is resumed.
fn reopen_stage_log(
    path: &Path,
    done: StageProgress,
    skin_done: u64,
) -> Result<std::fs::File, TrainError> {
    let resumed = done != StageProgress::default();
    reopen_log_keeping(path, "stage,iteration,rendering,total", |row| {
        let mut f = row.split(',').map(|x| x.parse::<u64>().ok());
        resumed
            && match (f.next().flatten(), f.next().flatten()) {
                (Some(2), Some(i)) => i <= done.albedo,
                (Some(3), Some(i)) => i <= done.shadow,
                (Some(4), Some(i)) => i <= skin_done,
                _ => false,
            }
    })
}

pub mod checkpoint;
mod config;
#[cfg(test)]
mod tests;
