//! Pictures for people: a posed mesh over a captured image (paper Fig. 3) and a posed mesh
//! coloured by per-vertex M2S error (paper Fig. 5). Both use the trainer's software rasteriser;
//! images are linear RGB, row-major from the top-left pixel.

use glam::Vec3;
use skinfield_formats::Camera;
use skinfield_formats::mesh::area_weighted_normals;

use crate::raster::{Light, NO_TRIANGLE, rasterize, shade};

/// Opacity of the mesh drawn over a captured image.
pub const OVERLAY_OPACITY: f32 = 0.6;
/// Colour of the silhouette outline in the overlay (linear RGB, orange).
pub const OUTLINE_COLOR: Vec3 = Vec3::new(1.0, 0.35, 0.0);

/// Why a picture could not be drawn.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// The background image is not the camera's size.
    #[error("image is {got} pixels, the camera's resolution {width}×{height} needs {expected}")]
    ImageSize {
        /// Pixels given.
        got: usize,
        /// Pixels expected.
        expected: usize,
        /// Camera width.
        width: u32,
        /// Camera height.
        height: u32,
    },
    /// The per-vertex values do not match the mesh.
    #[error("{got} per-vertex errors for a mesh of {expected} vertices")]
    ErrorLength {
        /// Values given.
        got: usize,
        /// Vertex count.
        expected: usize,
    },
}

/// The posed mesh shaded in grey at [`OVERLAY_OPACITY`] over `image` as seen by `camera`, with
/// its silhouette outlined in [`OUTLINE_COLOR`]; pixels the mesh does not cover keep the image.
pub fn overlay(
    camera: &Camera,
    image: &[Vec3],
    positions: &[Vec3],
    triangles: &[[u32; 3]],
) -> Result<Vec<Vec3>, RenderError> {
    let expected = camera.width as usize * camera.height as usize;
    if image.len() != expected {
        return Err(RenderError::ImageSize {
            got: image.len(),
            expected,
            width: camera.width,
            height: camera.height,
        });
    }
    let frags = rasterize(camera, positions, triangles);
    let normals = area_weighted_normals(positions, triangles);
    let shaded = shade(
        camera,
        &frags,
        positions,
        &normals,
        None,
        triangles,
        &head_light(camera),
        None,
        Vec3::ZERO,
    );
    let covered = frags.mask();
    let edge = outline(&covered, camera.width as usize, camera.height as usize);
    Ok((0..expected)
        .map(|i| {
            if edge[i] {
                OUTLINE_COLOR
            } else if covered[i] {
                image[i].lerp(shaded[i], OVERLAY_OPACITY)
            } else {
                image[i]
            }
        })
        .collect())
}

/// The posed mesh as seen by `camera`, each vertex coloured by its error through [`error_color`]
/// (0 → blue, `max_error` and above → red), lit from the camera so the shape reads; `background`
/// elsewhere.
pub fn error_image(
    camera: &Camera,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    per_vertex_error: &[f32],
    max_error: f32,
    background: Vec3,
) -> Result<Vec<Vec3>, RenderError> {
    if per_vertex_error.len() != positions.len() {
        return Err(RenderError::ErrorLength {
            got: per_vertex_error.len(),
            expected: positions.len(),
        });
    }
    let scale = if max_error > 0.0 {
        1.0 / max_error
    } else {
        0.0
    };
    let colors: Vec<Vec3> = per_vertex_error
        .iter()
        .map(|&e| error_color(e * scale))
        .collect();
    let frags = rasterize(camera, positions, triangles);
    let normals = area_weighted_normals(positions, triangles);
    let mut light = head_light(camera);
    // Mostly the colour, a little shading: the error is the message, the shape is context.
    light.ambient = 0.55;
    light.intensity = 0.5;
    light.specular = 0.0;
    let shaded = shade(
        camera,
        &frags,
        positions,
        &normals,
        Some(&colors),
        triangles,
        &light,
        None,
        background,
    );
    debug_assert!(
        frags
            .triangle
            .iter()
            .zip(&shaded)
            .all(|(&t, c)| t != NO_TRIANGLE || *c == background)
    );
    Ok(shaded)
}

/// A light travelling along the camera's viewing direction (nothing it lights is in shadow
/// from the camera's point of view).
fn head_light(camera: &Camera) -> Light {
    // The camera looks along +Z of its frame; world direction = Rᵀ·(0, 0, 1).
    let direction = (camera.rotation.transpose() * Vec3::Z)
        .try_normalize()
        .unwrap_or(Vec3::NEG_Z);
    Light {
        direction,
        ..Light::default()
    }
}

/// Colour map for errors: `t` in [0, 1] (clamped) from blue through cyan, green and yellow to
/// red, piecewise linear in linear RGB.
#[must_use]
pub fn error_color(t: f32) -> Vec3 {
    const STOPS: [Vec3; 5] = [
        Vec3::new(0.0, 0.05, 0.6),
        Vec3::new(0.0, 0.6, 0.8),
        Vec3::new(0.1, 0.7, 0.1),
        Vec3::new(0.9, 0.8, 0.0),
        Vec3::new(0.8, 0.0, 0.0),
    ];
    let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x as usize).min(STOPS.len() - 2);
    STOPS[i].lerp(STOPS[i + 1], x - i as f32)
}

/// Covered pixels with at least one uncovered 4-neighbour (or on the image border).
fn outline(covered: &[bool], width: usize, height: usize) -> Vec<bool> {
    let at = |x: isize, y: isize| {
        x >= 0
            && y >= 0
            && (x as usize) < width
            && (y as usize) < height
            && covered[y as usize * width + x as usize]
    };
    (0..width * height)
        .map(|i| {
            let (x, y) = ((i % width) as isize, (i / width) as isize);
            covered[i] && !(at(x - 1, y) && at(x + 1, y) && at(x, y - 1) && at(x, y + 1))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 40×30 camera 2 m in front of the origin looking at it, focal length 40 pixels.
    fn camera() -> Camera {
        let fov_y = 2.0 * (15.0f32 / 40.0).atan();
        Camera::look_at(
            "test",
            40,
            30,
            fov_y,
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::ZERO,
            Vec3::Y,
        )
    }

    /// A square of side `s` at the origin facing +Z (towards the camera).
    fn square(s: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let h = s / 2.0;
        (
            vec![
                Vec3::new(-h, -h, 0.0),
                Vec3::new(h, -h, 0.0),
                Vec3::new(h, h, 0.0),
                Vec3::new(-h, h, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn overlay_changes_only_covered_pixels_and_outlines_them() {
        let cam = camera();
        let (p, t) = square(0.5);
        let bg = Vec3::new(0.2, 0.4, 0.9);
        let image = vec![bg; 40 * 30];
        let out = overlay(&cam, &image, &p, &t).unwrap();
        // The square spans 0.5 m at 2 m: 10 × 10 pixels around the centre (20, 15).
        let changed = out.iter().filter(|c| **c != bg).count();
        assert!((90..=130).contains(&changed), "{changed}");
        assert_eq!(out[0], bg);
        assert_ne!(out[15 * 40 + 20], bg);
        assert_ne!(out[15 * 40 + 20], OUTLINE_COLOR);
        let outlined = out.iter().filter(|c| **c == OUTLINE_COLOR).count();
        assert!((30..=44).contains(&outlined), "{outlined}");
        assert!(overlay(&cam, &image[1..], &p, &t).is_err());
    }

    #[test]
    fn error_image_uses_the_colour_map() {
        let cam = camera();
        let (p, t) = square(0.5);
        let white = Vec3::ONE;
        let low = error_image(&cam, &p, &t, &[0.0; 4], 0.02, white).unwrap();
        let high = error_image(&cam, &p, &t, &[0.05; 4], 0.02, white).unwrap();
        let centre = 15 * 40 + 20;
        assert_eq!(low[0], white);
        // Blue-dominant at zero error, red-dominant above the maximum.
        assert!(low[centre].z > low[centre].x, "{}", low[centre]);
        assert!(high[centre].x > high[centre].z, "{}", high[centre]);
        assert!(error_image(&cam, &p, &t, &[0.0; 3], 0.02, white).is_err());
    }

    #[test]
    fn colour_map_runs_blue_to_red_and_clamps() {
        assert_eq!(error_color(0.0), error_color(-1.0));
        assert_eq!(error_color(1.0), error_color(7.0));
        assert_eq!(error_color(f32::NAN), error_color(1.0));
        assert!(error_color(0.0).z > 0.5 && error_color(1.0).x > 0.5);
        // Continuous: no jump larger than the step between neighbouring stops allows.
        for i in 0..100 {
            let (a, b) = (
                error_color(i as f32 / 100.0),
                error_color((i + 1) as f32 / 100.0),
            );
            assert!((a - b).length() < 0.05, "{i}");
        }
    }
}
