//! Skinfield trainer: bone-heat initial weights, synthetic captures, SkinNet training with
//! candle, export to `.skf`, and evaluation against ground truth.

pub mod appearance;
pub mod bilinear;
pub mod candidates;
pub mod eval;
pub mod files;
pub mod geodesic;
pub mod heat;
pub mod losses;
pub mod marching;
pub mod optim;
pub mod raster;
pub mod skinnet;
pub mod synth;
pub mod template;
pub mod track;
pub mod train;
pub mod triangle_bvh;
