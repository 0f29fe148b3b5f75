//! Skinfield trainer: bone-heat initial weights, synthetic captures, SkinNet training with
//! candle, export to `.skf`, and evaluation against ground truth.

pub mod raster;
pub mod synth;
