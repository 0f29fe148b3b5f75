//! The auxiliary appearance field (paper §3.3, supplementary D): AlbedoNet `a(x̄) ∈ R³` and
//! ShadowNet `r(x̄, θ̃, n, d) = exp(out) ∈ R⁺`, colour `c = a · r` per vertex per view.
//!
//! Both nets share SkinNet's hyper-parameters and input normalisation (the same
//! [`ModelConfig`]: bounding box, `L`, hidden widths 256-256-128-256-256, skip into the third
//! layer, Softplus β, weight normalisation); only their inputs and output widths differ
//! ([`ModelConfig::input_width`]). ShadowNet's input is `[x̂, γ(x̂), θ̃, n, d]` with `n` the unit
//! posed normal and `d` the unit viewing direction from the camera centre to the point, both in
//! world space. Outputs are unprocessed during training (colours may leave [0, 1]); the
//! `*_clipped` helpers clip to [0, 1] for inference, as the paper does.
//!
//! Each net has its own [`VarMap`] so that the training stages can optimise one while the other
//! is frozen. The nets are stored in the `.skf` beside SkinNet (the format reserves
//! [`Net::Albedo`] and [`Net::Shadow`]); [`Appearance::from_skf`] loads them back, and
//! [`appearance_image`] draws them for `trainer render`.

use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Result, Tensor};
use candle_nn::{VarBuilder, VarMap};
use glam::Vec3;
use skinfield_formats::Camera;
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_formats::skf::{ModelConfig, Net, SkfModel, SkfView};

use crate::raster::rasterize;
use crate::skinnet::{
    SkfNetError, WnLinear, init_net_varmap, position_inputs_tensor, softplus, varmap_from_skf,
};

/// A weight-normalised MLP of the file's architecture for [`Net::Albedo`] or [`Net::Shadow`].
#[derive(Clone, Debug)]
pub struct AppearanceNet {
    net: Net,
    config: ModelConfig,
    layers: Vec<WnLinear>,
}

impl AppearanceNet {
    /// Builds the layers from a `VarBuilder` scoped to the net (`l{i}.v`, `l{i}.g`, `l{i}.b`).
    pub fn new(vb: &VarBuilder, config: ModelConfig, net: Net) -> Result<Self> {
        if net == Net::Skin {
            candle_core::bail!("AppearanceNet is for the albedo and shadow nets");
        }
        let layers = config
            .layer_shapes(net)
            .enumerate()
            .map(|(i, (out, inp))| WnLinear::new(&vb.pp(format!("l{i}")), out, inp))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            net,
            config,
            layers,
        })
    }

    /// Which net this is.
    #[must_use]
    pub fn kind(&self) -> Net {
        self.net
    }

    /// The layers, hidden first, then the output layer.
    #[must_use]
    pub fn layers(&self) -> &[WnLinear] {
        &self.layers
    }

    /// Raw outputs `[N, out]` for inputs `[N, input_width]` (no output processing).
    pub fn forward(&self, input: &Tensor) -> Result<Tensor> {
        let (_, width) = input.dims2()?;
        if width != self.config.input_width(self.net) {
            candle_core::bail!(
                "{} net input width {width}, expected {}",
                self.net.prefix(),
                self.config.input_width(self.net)
            );
        }
        let n = self.layers.len() - 1;
        let skip = self.config.skip_layer as usize;
        let mut h = input.clone();
        for (i, layer) in self.layers.iter().enumerate() {
            let x = if i == skip && i > 0 {
                Tensor::cat(&[&h, input], 1)?
            } else {
                h
            };
            let z = x
                .matmul(&layer.weight()?.t()?)?
                .broadcast_add(layer.bias())?;
            h = if i < n {
                softplus(&z, self.config.softplus_beta)?
            } else {
                z
            };
        }
        Ok(h)
    }
}

/// Why the appearance nets could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum AppearanceError {
    /// The file stores no such net.
    #[error("{path}: the file stores no `{net}` net (CONF field `nets`)")]
    Missing {
        /// The file.
        path: PathBuf,
        /// The missing net's prefix.
        net: &'static str,
    },
    /// A stored tensor could not be read.
    #[error("{path}: tensor of `{net}` layer {layer}: {reason}")]
    Tensor {
        /// The file.
        path: PathBuf,
        /// The net's prefix.
        net: &'static str,
        /// Layer index.
        layer: usize,
        /// What is wrong.
        reason: String,
    },
    /// A tensor operation failed.
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
}

/// AlbedoNet and ShadowNet with their parameters.
#[derive(Clone)]
pub struct Appearance {
    config: ModelConfig,
    albedo: AppearanceNet,
    shadow: AppearanceNet,
    albedo_vars: VarMap,
    shadow_vars: VarMap,
}

impl std::fmt::Debug for Appearance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // VarMap has no Debug; the nets show the layers.
        f.debug_struct("Appearance")
            .field("albedo", &self.albedo)
            .field("shadow", &self.shadow)
            .finish_non_exhaustive()
    }
}

/// Seed offsets so the two nets (and SkinNet, seeded with the run's seed) start differently.
const ALBEDO_SEED: u64 = 0xa1be_d0a1;
const SHADOW_SEED: u64 = 0x5ad0_0005;

fn build(config: ModelConfig, albedo_vars: VarMap, shadow_vars: VarMap) -> Result<Appearance> {
    let dev = Device::Cpu;
    let vb = |m: &VarMap, net: Net| VarBuilder::from_varmap(m, DType::F32, &dev).pp(net.prefix());
    Ok(Appearance {
        albedo: AppearanceNet::new(&vb(&albedo_vars, Net::Albedo), config, Net::Albedo)?,
        shadow: AppearanceNet::new(&vb(&shadow_vars, Net::Shadow), config, Net::Shadow)?,
        config,
        albedo_vars,
        shadow_vars,
    })
}

impl Appearance {
    /// Freshly initialised nets for SkinNet's `config` (f32, CPU). The output layers are scaled
    /// by `out_scale`: the albedo starts near 0 and the shading near `exp(0) = 1`.
    pub fn seeded(config: ModelConfig, seed: u64, out_scale: f32) -> Result<Self> {
        let dev = Device::Cpu;
        let (a, s) = (VarMap::new(), VarMap::new());
        init_net_varmap(
            &a,
            &config,
            Net::Albedo,
            Net::Albedo.prefix(),
            seed ^ ALBEDO_SEED,
            out_scale,
            &dev,
        )?;
        init_net_varmap(
            &s,
            &config,
            Net::Shadow,
            Net::Shadow.prefix(),
            seed ^ SHADOW_SEED,
            out_scale,
            &dev,
        )?;
        build(config, a, s)
    }

    /// The shared configuration.
    #[must_use]
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// AlbedoNet.
    #[must_use]
    pub fn albedo_net(&self) -> &AppearanceNet {
        &self.albedo
    }

    /// ShadowNet.
    #[must_use]
    pub fn shadow_net(&self) -> &AppearanceNet {
        &self.shadow
    }

    /// AlbedoNet's parameters (what stage 2 optimises).
    #[must_use]
    pub fn albedo_vars(&self) -> &VarMap {
        &self.albedo_vars
    }

    /// ShadowNet's parameters (what stage 3 optimises).
    #[must_use]
    pub fn shadow_vars(&self) -> &VarMap {
        &self.shadow_vars
    }

    /// Albedo `[N, 3]` of encoded canonical positions `[N, 3 + 6L]` (unclipped).
    pub fn albedo(&self, encoded: &Tensor) -> Result<Tensor> {
        self.albedo.forward(encoded)
    }

    /// Shading `exp(r) > 0`, `[N, 1]`, for ShadowNet inputs `[N, 3 + 6L + 3J + 6]`
    /// ([`shadow_input`]).
    pub fn shading(&self, input: &Tensor) -> Result<Tensor> {
        self.shadow.forward(input)?.exp()
    }

    /// Inference colours of canonical `points` (albedo, shading and their product, each clipped
    /// to [0, 1]) for one pose and one camera centre; `normals` are the posed unit normals and
    /// `posed` the posed positions of the same points.
    pub fn colours_clipped(
        &self,
        points: &[Vec3],
        pose_features: &[f32],
        posed: &[Vec3],
        normals: &[Vec3],
        eye: Vec3,
    ) -> Result<Colours> {
        let dev = Device::Cpu;
        let enc = position_inputs_tensor(&self.config, points, &dev)?;
        let albedo = self.albedo(&enc)?;
        let dirs: Vec<Vec3> = posed
            .iter()
            .map(|&p| (p - eye).normalize_or_zero())
            .collect();
        let input = shadow_input(&enc, pose_features, normals, &dirs)?;
        let shading = self.shading(&input)?;
        let product = albedo.broadcast_mul(&shading)?;
        let rows = |t: &Tensor, w: usize| -> Result<Vec<Vec3>> {
            let v = t.clamp(0.0, 1.0)?.flatten_all()?.to_vec1::<f32>()?;
            Ok(v.chunks(w)
                .map(|c| {
                    if w == 3 {
                        Vec3::from_slice(c)
                    } else {
                        Vec3::splat(c[0])
                    }
                })
                .collect())
        };
        Ok(Colours {
            albedo: rows(&albedo, 3)?,
            shading: rows(&shading, 1)?,
            colour: rows(&product, 3)?,
        })
    }

    /// Adds both nets (weight normalisation folded, as SkinNet's export does) to `model`, whose
    /// configuration must be this one apart from the `nets` bits, which are set.
    pub fn push_to_skf(&self, model: &mut SkfModel) -> Result<()> {
        let mut mine = self.config;
        mine.nets = model.config.nets;
        if mine != model.config {
            candle_core::bail!("the appearance nets were built for another model configuration");
        }
        model.config.nets |= Net::Albedo.bit() | Net::Shadow.bit();
        for net in [&self.albedo, &self.shadow] {
            for (i, layer) in net.layers.iter().enumerate() {
                let w = layer.weight()?;
                let (out, inp) = w.dims2()?;
                model.push_layer(
                    net.net,
                    i,
                    w.flatten_all()?.to_vec1::<f32>()?,
                    out,
                    inp,
                    layer.bias().to_vec1::<f32>()?,
                );
            }
        }
        Ok(())
    }

    /// Loads both nets from a parsed `.skf` (read from `path`, named in errors). The stored
    /// plain weights become `v` with `g = ‖v‖_row`, so the effective weights are the file's.
    pub fn from_skf(view: &SkfView, path: &Path) -> std::result::Result<Self, AppearanceError> {
        let config = *view.config();
        let load = |net: Net| -> std::result::Result<VarMap, AppearanceError> {
            if config.nets & net.bit() == 0 {
                return Err(AppearanceError::Missing {
                    path: path.to_owned(),
                    net: net.prefix(),
                });
            }
            varmap_from_skf(view, net).map_err(|e| match e {
                SkfNetError::Tensor { layer, reason } => AppearanceError::Tensor {
                    path: path.to_owned(),
                    net: net.prefix(),
                    layer,
                    reason,
                },
                SkfNetError::Candle(e) => AppearanceError::from(e),
            })
        };
        let albedo_vars = load(Net::Albedo)?;
        let shadow_vars = load(Net::Shadow)?;
        let mut config = config;
        config.nets = Net::Skin.bit();
        Ok(build(config, albedo_vars, shadow_vars)?)
    }
}

/// Inference colours per point, each clipped to [0, 1] (shading as grey).
#[derive(Clone, Debug, PartialEq)]
pub struct Colours {
    /// AlbedoNet.
    pub albedo: Vec<Vec3>,
    /// ShadowNet's multiplier.
    pub shading: Vec<Vec3>,
    /// Their product (clipped after multiplying).
    pub colour: Vec<Vec3>,
}

/// ShadowNet input rows `[N, 3 + 6L + 3J + 6]`: encoded canonical positions `[N, 3 + 6L]` (any
/// float type; the result has its type), one pose-feature vector shared by every row, and per
/// row the unit normal and viewing direction.
pub fn shadow_input(
    encoded: &Tensor,
    pose_features: &[f32],
    normals: &[Vec3],
    dirs: &[Vec3],
) -> Result<Tensor> {
    let (n, _) = encoded.dims2()?;
    if normals.len() != n || dirs.len() != n {
        candle_core::bail!(
            "shadow_input: {n} rows but {} normals and {} directions",
            normals.len(),
            dirs.len()
        );
    }
    let dev = encoded.device();
    let dt = encoded.dtype();
    let pose = Tensor::from_slice(pose_features, (1, pose_features.len()), dev)?
        .to_dtype(dt)?
        .broadcast_as((n, pose_features.len()))?;
    let nd: Vec<f32> = normals
        .iter()
        .zip(dirs)
        .flat_map(|(a, b)| [a.x, a.y, a.z, b.x, b.y, b.z])
        .collect();
    let nd = Tensor::from_vec(nd, (n, 6), dev)?.to_dtype(dt)?;
    Tensor::cat(&[encoded, &pose, &nd], 1)
}

/// Which appearance quantity a picture shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AppearanceKind {
    /// `clip(a)`.
    Albedo,
    /// `clip(r)` as grey.
    Shading,
    /// `clip(a · r)`.
    Colour,
}

/// A picture of the learned appearance: the posed mesh coloured per vertex by `kind` (clipped,
/// as at inference), interpolated over the visible triangles without further lighting (the
/// shading is what ShadowNet learned). Renders `posed` (the template posed for one frame; `canonical` its rest positions, same
/// order) seen by `camera`, coloured by `kind`; `background` where nothing is visible.
#[allow(clippy::too_many_arguments)]
pub fn appearance_image(
    appearance: &Appearance,
    camera: &Camera,
    canonical: &[Vec3],
    posed: &[Vec3],
    triangles: &[[u32; 3]],
    pose_features: &[f32],
    kind: AppearanceKind,
    background: Vec3,
) -> candle_core::Result<Vec<Vec3>> {
    let normals: Vec<Vec3> = area_weighted_normals(posed, triangles)
        .into_iter()
        .map(|n| n.normalize_or(Vec3::Y))
        .collect();
    let c =
        appearance.colours_clipped(canonical, pose_features, posed, &normals, camera.center())?;
    let per_vertex = match kind {
        AppearanceKind::Albedo => c.albedo,
        AppearanceKind::Shading => c.shading,
        AppearanceKind::Colour => c.colour,
    };
    let frags = rasterize(camera, posed, triangles);
    Ok(frags
        .interpolate(triangles, &per_vertex)
        .into_iter()
        .map(|p| p.unwrap_or(background))
        .collect())
}

#[cfg(test)]
mod tests;
