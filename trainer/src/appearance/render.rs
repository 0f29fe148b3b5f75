//! Pictures of the learned appearance: the posed mesh coloured per vertex by AlbedoNet,
//! ShadowNet's multiplier or their product (clipped to [0, 1], as at inference), interpolated
//! over the visible triangles without further lighting (the shading is what ShadowNet learned).

use glam::Vec3;
use skinfield_formats::Camera;
use skinfield_formats::mesh::area_weighted_normals;

use super::Appearance;
use crate::raster::rasterize;

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

/// Renders `posed` (the template posed for one frame; `canonical` its rest positions, same
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
