//! A SkinNet bound to a device: the `.skf`'s weights checked against the configuration and
//! packed for the kernels (f16 pairs or f32), biases, candidate joints.

use half::f16;
use skinfield_formats::skf::{Dtype, ModelConfig, Net, SkfView, TensorView};

use super::GpuError;
use super::layout::{GpuLayer, GpuParams, MAX_GPU_LAYERS, MAX_GPU_WIDTH, WeightFormat};
use super::skinner::GpuSkinner;
use crate::candidates::AnchorSet;

/// Packed weights: `u32` pairs of f16 bits or f32 pairs, transposed to `[in / 2][out]`.
enum Packed {
    Half(Vec<u32>),
    Single(Vec<[f32; 2]>),
}

/// A SkinNet bound to a device: weights and biases in storage buffers.
pub struct GpuModel {
    pub(super) config: ModelConfig,
    pub(super) format: WeightFormat,
    pub(super) params: GpuParams,
    pub(super) weights: wgpu::Buffer,
    pub(super) biases: wgpu::Buffer,
    /// The model's candidate joints (`CAND`), turned into per-vertex lists at bind time.
    pub(super) anchors: Option<AnchorSet>,
}

impl GpuSkinner {
    /// Copies SkinNet out of `view` into GPU buffers, keeping the file's precision: f16 when
    /// every SkinNet weight is stored as f16, else f32.
    pub fn bind_model(
        &self,
        device: &wgpu::Device,
        view: &SkfView<'_>,
    ) -> Result<GpuModel, GpuError> {
        self.bind_model_as(device, view, None)
    }

    /// As [`GpuSkinner::bind_model`] with the GPU storage format chosen by the caller
    /// (`Some(F16)` rounds f32 tensors to half; `Some(F32)` expands f16 exactly).
    pub fn bind_model_as(
        &self,
        device: &wgpu::Device,
        view: &SkfView<'_>,
        format: Option<WeightFormat>,
    ) -> Result<GpuModel, GpuError> {
        let config = *view.config();
        let anchors = view.candidates().map(|c| AnchorSet::from_view(&c));
        let hidden = config.hidden_widths();
        let n = hidden.len();
        for &w in hidden {
            if w as usize > MAX_GPU_WIDTH {
                return Err(GpuError::Unsupported {
                    what: "hidden width",
                    value: w as usize,
                    max: MAX_GPU_WIDTH,
                });
            }
        }
        let joints = config.joint_count as usize;
        if joints > MAX_GPU_WIDTH {
            return Err(GpuError::Unsupported {
                what: "joint_count",
                value: joints,
                max: MAX_GPU_WIDTH,
            });
        }
        let mut tensors = Vec::with_capacity(n + 1);
        for (l, (out, inp)) in config.layer_shapes(Net::Skin).enumerate() {
            let (w, b) = view.layer(Net::Skin, l).ok_or(GpuError::MissingLayer(l))?;
            check_shape(&w, [out as u32, inp as u32])?;
            check_shape(&b, [out as u32, 0])?;
            tensors.push((w, b, out, inp));
        }
        let format = format.unwrap_or(
            if tensors.iter().all(|(w, _, _, _)| w.dtype == Dtype::F16) {
                WeightFormat::F16
            } else {
                WeightFormat::F32
            },
        );
        let mut packed = match format {
            WeightFormat::F16 => Packed::Half(Vec::new()),
            WeightFormat::F32 => Packed::Single(Vec::new()),
        };
        let mut biases = Vec::new();
        let mut layers = [GpuLayer::default(); MAX_GPU_LAYERS];
        for (l, (w, b, out, inp)) in tensors.iter().enumerate() {
            let w_off = match &packed {
                Packed::Half(v) => v.len(),
                Packed::Single(v) => v.len(),
            };
            let too_large = |value: usize| GpuError::TooLarge {
                what: "SkinNet weights",
                value: value as u64,
                limit: u32::MAX.into(),
            };
            layers[l] = GpuLayer {
                in_w: *inp as u32,
                out_w: *out as u32,
                w_off: u32::try_from(w_off).map_err(|_| too_large(w_off))?,
                b_off: u32::try_from(biases.len()).map_err(|_| too_large(biases.len()))?,
            };
            for p in 0..inp.div_ceil(2) {
                for o in 0..*out {
                    let (i0, i1) = (o * inp + 2 * p, o * inp + 2 * p + 1);
                    let has_hi = 2 * p + 1 < *inp;
                    match &mut packed {
                        Packed::Half(v) => {
                            let hi = if has_hi { f16_bits(w, i1) } else { 0 };
                            v.push(u32::from(f16_bits(w, i0)) | (u32::from(hi) << 16));
                        }
                        Packed::Single(v) => {
                            v.push([f32_at(w, i0), if has_hi { f32_at(w, i1) } else { 0.0 }])
                        }
                    }
                }
            }
            biases.extend((0..*out).map(|o| f32_at(b, o)));
        }
        let skip = config.skip_layer as usize;
        let skip = if skip > 0 && skip < n { skip } else { 0 };
        let params = GpuParams {
            vertex_count: 0,
            layer_count: (n + 1) as u32,
            skip_layer: skip as u32,
            pos_width: config.position_width() as u32,
            pose_width: config.pose_width() as u32,
            joint_count: config.joint_count,
            term0_width: hidden[0],
            term_skip_width: if skip > 0 { hidden[skip] } else { 0 },
            beta: config.softplus_beta,
            candidate_k: anchors.as_ref().map_or(0, |a| a.k() as u32),
            layers,
            ..GpuParams::default()
        };
        let weight_bytes: &[u8] = match &packed {
            Packed::Half(v) => bytemuck::cast_slice(v),
            Packed::Single(v) => bytemuck::cast_slice(v),
        };
        Ok(GpuModel {
            config,
            format,
            params,
            weights: self.storage_init(device, "skinnet weights", weight_bytes)?,
            biases: self.storage_init(device, "skinnet biases", bytemuck::cast_slice(&biases))?,
            anchors,
        })
    }
}

impl GpuModel {
    /// The model's configuration.
    #[must_use]
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// How the weights are stored on the GPU.
    #[must_use]
    pub fn weight_format(&self) -> WeightFormat {
        self.format
    }
}

fn check_shape(t: &TensorView<'_>, expected: [u32; 2]) -> Result<(), GpuError> {
    let found = if t.rank == 1 { [t.dims[0], 0] } else { t.dims };
    if found != expected || t.len() != expected[0] as usize * expected[1].max(1) as usize {
        return Err(GpuError::TensorShape {
            name: t.name.as_str().to_string(),
            found,
            expected,
        });
    }
    Ok(())
}

fn f16_bits(t: &TensorView<'_>, i: usize) -> u16 {
    match t.dtype {
        Dtype::F16 => u16::from_le_bytes([t.bytes[2 * i], t.bytes[2 * i + 1]]),
        Dtype::F32 => f16::from_f32(f32_at(t, i)).to_bits(),
    }
}

fn f32_at(t: &TensorView<'_>, i: usize) -> f32 {
    match t.dtype {
        Dtype::F16 => f16::from_bits(f16_bits(t, i)).to_f32(),
        Dtype::F32 => f32::from_le_bytes([
            t.bytes[4 * i],
            t.bytes[4 * i + 1],
            t.bytes[4 * i + 2],
            t.bytes[4 * i + 3],
        ]),
    }
}
