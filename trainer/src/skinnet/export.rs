//! Export to `.skf`: weight normalisation folded into plain `[out, in]` weights, stored as f16.

use std::path::Path;

use skinfield_formats::Skeleton;
use skinfield_formats::skf::{Net, SkfFileError, SkfModel};

use super::TrainableSkinNet;

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Reading the parameters out of candle failed.
    #[error("reading SkinNet parameters: {0}")]
    Candle(#[from] candle_core::Error),
    /// The skeleton does not match the network's joint count.
    #[error("skeleton has {skeleton} joints but SkinNet outputs {net}")]
    JointCount {
        /// Skeleton joints.
        skeleton: usize,
        /// Network outputs.
        net: usize,
    },
    /// Serialising or writing the file failed (names the file).
    #[error(transparent)]
    File(#[from] SkfFileError),
}

/// The model as `.skf` content: every layer's folded weight `g ⊙ v/‖v‖` and bias, in f32 (the
/// writer rounds to f16).
pub fn to_skf_model(net: &TrainableSkinNet, skeleton: &Skeleton) -> Result<SkfModel, ExportError> {
    let joints = net.config().joint_count as usize;
    if skeleton.len() != joints {
        return Err(ExportError::JointCount {
            skeleton: skeleton.len(),
            net: joints,
        });
    }
    let mut model = SkfModel {
        config: *net.config(),
        skeleton: skeleton.clone(),
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    for (i, layer) in net.layers().iter().enumerate() {
        let w = layer.weight()?.to_dtype(candle_core::DType::F32)?;
        let (out, inp) = w.dims2()?;
        let weight = w.flatten_all()?.to_vec1::<f32>()?;
        let bias = layer
            .bias()
            .to_dtype(candle_core::DType::F32)?
            .to_vec1::<f32>()?;
        model.push_layer(Net::Skin, i, weight, out, inp, bias);
    }
    Ok(model)
}

/// Writes the model to `path` atomically.
pub fn write_skf(
    net: &TrainableSkinNet,
    skeleton: &Skeleton,
    path: &Path,
) -> Result<(), ExportError> {
    to_skf_model(net, skeleton)?.write(path)?;
    Ok(())
}
