//! Fixtures shared by the criterion benches in `benches/`: the same seeded random SkinNet models,
//! canonical points and poses that the runtime's integration tests use (one definition, in
//! `runtime/tests/common`).

#[path = "../../runtime/tests/common/mod.rs"]
mod fixtures;

pub use fixtures::{
    BBOX_MAX, BBOX_MIN, ellipsoid, random_points, random_pose, rng, skeleton, vinecs_bytes,
};
