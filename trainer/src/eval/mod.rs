//! Evaluation against ground truth (paper §4, `DESIGN.md` "Evaluation").

pub mod bvh;
pub mod distance;
pub mod posing;
pub mod static_weights;
pub mod surface;
pub mod table;
