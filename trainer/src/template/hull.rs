//! The visual hull of a frame's masks as a signed distance field, meshed by marching
//! tetrahedra.
//!
//! A point belongs to the hull when every camera sees it inside the subject's silhouette. For a
//! mesh with sub-voxel accuracy the inside/outside test is made continuous: each view gives the
//! signed distance (pixels, negative inside) from the point's projection to the 50 % coverage
//! outline of its mask ([`Outline`], the same sub-pixel outline the silhouette loss uses), scaled
//! to metres at the point's depth (`d · z / f`, the distance to the silhouette cone measured
//! across the line of sight), and the field is the largest of them: zero on the hull's surface,
//! negative inside. Marching tetrahedra then place the surface by linear interpolation along
//! each grid edge, which with a distance-like field is accurate to a small fraction of a cell.
//!
//! Every camera is assumed to see the whole subject (as a capture's cameras frame it): a point
//! projecting off an image is outside that view's silhouette. The hull contains the subject and
//! cannot recover concavities that no silhouette reveals (between the legs under a skirt, the
//! armpits of arms held close); how much that costs is measured in `docs/experiments/template.md`.

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use skinfield_formats::Camera;

use crate::losses::silhouette::{Outline, OutlineError};
use crate::marching::marching_tetrahedra;

/// One camera's silhouette: the outline of its mask and the mask's coverage.
#[derive(Clone, Debug)]
pub struct HullView {
    /// The calibrated camera.
    pub camera: Camera,
    /// The mask's 50 % coverage outline.
    outline: Outline,
    /// Coverage in `[0, 1]`, row-major.
    coverage: Vec<f32>,
    /// Metres per pixel at unit depth (`1 / f`, the mean of the two focal lengths).
    metres_per_pixel: f32,
}

impl HullView {
    /// A view from a camera and its mask's coverage (`width × height`, row-major).
    pub fn new(camera: Camera, coverage: Vec<f32>) -> Result<Self, OutlineError> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let outline = Outline::from_coverage(w, h, &coverage)?;
        let metres_per_pixel = 2.0 / (camera.fx + camera.fy);
        Ok(Self {
            camera,
            outline,
            coverage,
            metres_per_pixel,
        })
    }

    /// Bilinear coverage at image point `p` (pixels; centres at `x + 0.5`), 0 off the image.
    fn coverage_at(&self, p: Vec2) -> f32 {
        let (w, h) = (self.outline.width as i64, self.outline.height as i64);
        let (x, y) = (p.x - 0.5, p.y - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = (x - x0, y - y0);
        let at = |xi: i64, yi: i64| {
            if (0..w).contains(&xi) && (0..h).contains(&yi) {
                self.coverage[(yi * w + xi) as usize]
            } else {
                0.0
            }
        };
        let (xi, yi) = (x0 as i64, y0 as i64);
        let top = at(xi, yi) * (1.0 - tx) + at(xi + 1, yi) * tx;
        let bottom = at(xi, yi + 1) * (1.0 - tx) + at(xi + 1, yi + 1) * tx;
        top * (1.0 - ty) + bottom * ty
    }

    /// Signed distance (pixels, negative inside) from image point `p` to the mask's outline.
    #[must_use]
    pub fn signed_pixels(&self, p: Vec2) -> f32 {
        self.signed_pixels_with_gradient(p).0
    }

    /// [`Self::signed_pixels`] and its gradient with respect to `p` (a unit vector away from
    /// the nearest outline point, outwards; zero on the outline).
    #[must_use]
    pub fn signed_pixels_with_gradient(&self, p: Vec2) -> (f32, Vec2) {
        let (d, g) = self.outline.distance(p);
        if self.coverage_at(p) >= 0.5 {
            (-d, -g)
        } else {
            (d, g)
        }
    }

    /// Signed distance (metres, negative inside) from `x` to this view's silhouette cone,
    /// measured across the line of sight at `x`'s depth. Points behind the camera are far
    /// outside.
    #[must_use]
    pub fn signed_distance(&self, x: Vec3) -> f32 {
        let depth = self.camera.to_camera(x).z;
        let Some(p) = self.camera.project(x).filter(|_| depth > 1e-3) else {
            return f32::MAX;
        };
        if !p.is_finite() {
            return f32::MAX;
        }
        self.signed_pixels(p) * depth * self.metres_per_pixel
    }
}

/// The hull field at `x`: the largest signed distance over the views (negative inside all).
#[must_use]
pub fn hull_field(views: &[HullView], x: Vec3) -> f32 {
    views
        .iter()
        .map(|v| v.signed_distance(x))
        .fold(f32::MIN, f32::max)
}

/// The box `[min, max]` the subject occupies inside `search` (the box to look in), from the
/// field sampled on a `samples`³ lattice, grown by two lattice steps so that parts thinner than
/// a step are not cut off. `None` when no sample is inside.
#[must_use]
pub fn occupied_box(
    views: &[HullView],
    search: (Vec3, Vec3),
    samples: usize,
) -> Option<(Vec3, Vec3)> {
    let n = samples.max(2);
    let (lo, hi) = search;
    let step = (hi - lo) / (n - 1) as f32;
    let inside: Vec<(Vec3, Vec3)> = (0..n * n * n)
        .into_par_iter()
        .filter_map(|i| {
            let p =
                lo + Vec3::new((i % n) as f32, ((i / n) % n) as f32, (i / (n * n)) as f32) * step;
            (hull_field(views, p) < 0.0).then_some((p, p))
        })
        .collect();
    let (min, max) = inside
        .into_iter()
        .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))?;
    Some(((min - 2.0 * step).max(lo), (max + 2.0 * step).min(hi)))
}

/// Meshes the hull inside `[min, max]` with cubes of side `cell`: positions and outward,
/// counter-clockwise triangles. The box's own faces count as outside, so the surface closes.
#[must_use]
pub fn mesh_hull(
    views: &[HullView],
    min: Vec3,
    max: Vec3,
    cell: f32,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    // The lattice marching_tetrahedra samples ends at `min + (dims - 1)·cell` ≥ `max`.
    let last = min + ((max - min) / cell).ceil() * cell;
    let border = 0.5 * cell;
    // A value within rounding of zero puts the crossings of all the corner's edges on the corner
    // itself: distinct vertices at one position, which meshoptimizer reads as an attribute seam
    // and then opens the surface along. Keeping |f| ≥ 10⁻³ cells keeps them apart.
    let least = 1e-3 * cell;
    marching_tetrahedra(
        |x| {
            let on_face = (x - min).min_element() < border || (last - x).min_element() < border;
            let v = hull_field(views, x);
            if on_face {
                v.max(cell)
            } else if v.abs() < least {
                least.copysign(v)
            } else {
                v
            }
        },
        min,
        max,
        cell,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera looking at the origin from `eye`, 64 × 64, 60° field of view.
    fn camera(eye: Vec3) -> Camera {
        Camera::look_at("c", 64, 64, 60f32.to_radians(), eye, Vec3::ZERO, Vec3::Y)
    }

    #[test]
    fn a_disc_mask_gives_its_cone_distance_to_the_pixel() {
        // The exact coverage of a disc of radius 10 px at the image centre (supersampled).
        let cam = camera(Vec3::new(0.0, 0.0, 3.0));
        let coverage: Vec<f32> = (0..64 * 64)
            .map(|i| {
                let (x, y) = ((i % 64) as f32, (i / 64) as f32);
                let mut n = 0;
                for sy in 0..8 {
                    for sx in 0..8 {
                        let p = Vec2::new(x + (sx as f32 + 0.5) / 8.0, y + (sy as f32 + 0.5) / 8.0);
                        n += u32::from((p - Vec2::splat(32.0)).length() < 10.0);
                    }
                }
                n as f32 / 64.0
            })
            .collect();
        let view = HullView::new(cam.clone(), coverage).unwrap();
        // At the depth of the origin (3 m) the disc is a circle of radius 10 px · 3 / f.
        let r = 10.0 * 3.0 / cam.fx;
        for (x, want) in [(0.0, -r), (0.5 * r, -0.5 * r), (r, 0.0), (1.5 * r, 0.5 * r)] {
            let got = view.signed_distance(Vec3::new(x, 0.0, 0.0));
            assert!((got - want).abs() < 0.02 * r, "x {x}: {got} vs {want}");
        }
        assert_eq!(view.signed_distance(Vec3::new(0.0, 0.0, 4.0)), f32::MAX);
    }
}
