//! A z-buffered software rasteriser: per pixel, the visible triangle, its perspective-correct
//! barycentric coordinates and the camera depth.
//!
//! Used by `trainer synth` to render captures, by the rendering loss (visibility and
//! barycentrics of the posed mesh) and by `trainer render`.
//!
//! Conventions: one sample per pixel at the pixel centre (`x + 0.5, y + 0.5`, the OpenCV
//! convention of [`Camera`]); edges follow the top-left fill rule so that two triangles sharing
//! an edge never both cover (or both miss) a pixel centre on it; the nearest surface wins, ties
//! go to the lower triangle index. Both windings are drawn (the skirt is an open surface seen
//! from both sides). Triangles with a vertex at or behind the near plane (`z ≤ near`) are
//! skipped rather than clipped: every camera of a capture sees the whole subject. With lens
//! distortion the vertices are projected exactly and the edges drawn straight in the image (an
//! approximation that is exact for the pinhole cameras `trainer synth` writes).

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use skinfield_formats::Camera;

mod shade;

pub use shade::{Light, ShadowMap, shade};

/// Triangle id of a pixel that no triangle covers.
pub const NO_TRIANGLE: u32 = u32::MAX;
/// Nearest camera depth drawn (metres).
pub const NEAR: f32 = 1e-3;
/// Rows per parallel band (work unit; results do not depend on it).
const BAND: usize = 16;

/// What the rasteriser found at every pixel (row-major from the top-left).
#[derive(Clone, Debug, PartialEq)]
pub struct Fragments {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Visible triangle per pixel, [`NO_TRIANGLE`] where there is none.
    pub triangle: Vec<u32>,
    /// Perspective-correct barycentric coordinates of the pixel centre in its triangle (sum 1).
    pub bary: Vec<[f32; 3]>,
    /// Depth along the view axis (camera z, or distance along the light for a shadow map);
    /// infinity where there is no triangle.
    pub depth: Vec<f32>,
}

impl Fragments {
    /// Number of pixels.
    #[must_use]
    pub fn len(&self) -> usize {
        self.triangle.len()
    }

    /// True for a 0-pixel image.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.triangle.is_empty()
    }

    /// The silhouette: true where a triangle is visible.
    #[must_use]
    pub fn mask(&self) -> Vec<bool> {
        self.triangle.iter().map(|&t| t != NO_TRIANGLE).collect()
    }

    /// Number of covered pixels.
    #[must_use]
    pub fn coverage(&self) -> usize {
        self.triangle.iter().filter(|&&t| t != NO_TRIANGLE).count()
    }

    /// Interpolates a per-vertex attribute at every covered pixel (`None` elsewhere).
    #[must_use]
    pub fn interpolate(&self, triangles: &[[u32; 3]], attribute: &[Vec3]) -> Vec<Option<Vec3>> {
        self.triangle
            .iter()
            .zip(&self.bary)
            .map(|(&t, b)| {
                let tri = triangles.get(t as usize)?;
                let v = |k: usize| attribute.get(tri[k] as usize).copied();
                Some(v(0)? * b[0] + v(1)? * b[1] + v(2)? * b[2])
            })
            .collect()
    }
}

/// A vertex after projection: image position in pixels and depth along the view axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenVertex {
    /// Pixel coordinates (x right, y down).
    pub xy: Vec2,
    /// Depth (positive in front); non-finite or ≤ [`NEAR`] marks a vertex that cannot be drawn.
    pub depth: f32,
}

/// Projects world positions through a camera.
#[must_use]
pub fn project_vertices(camera: &Camera, positions: &[Vec3]) -> Vec<ScreenVertex> {
    positions
        .iter()
        .map(|&p| {
            let depth = camera.to_camera(p).z;
            match camera.project(p) {
                Some(xy) if depth > NEAR => ScreenVertex { xy, depth },
                _ => ScreenVertex {
                    xy: Vec2::ZERO,
                    depth: f32::NAN,
                },
            }
        })
        .collect()
}

/// Rasterises a mesh seen by `camera` (perspective-correct interpolation).
#[must_use]
pub fn rasterize(camera: &Camera, positions: &[Vec3], triangles: &[[u32; 3]]) -> Fragments {
    let screen = project_vertices(camera, positions);
    rasterize_screen(camera.width, camera.height, &screen, triangles, true)
}

/// Fraction of each pixel that the mesh covers, from `samples × samples` sub-pixel samples per
/// pixel (a regular grid at `(x + (i + ½)/s, y + (j + ½)/s)`): the anti-aliased mask a camera
/// records, whose 50 % level places the outline to `1/samples` of a pixel. `samples = 1` is the
/// binary mask of [`rasterize`].
#[must_use]
pub fn coverage(
    camera: &Camera,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    samples: u32,
) -> Vec<f32> {
    let s = samples.max(1);
    // Pixel u maps to s·u on the fine grid, whose pixel centres are the sub-pixel samples.
    let screen: Vec<ScreenVertex> = project_vertices(camera, positions)
        .into_iter()
        .map(|v| ScreenVertex {
            xy: v.xy * s as f32,
            ..v
        })
        .collect();
    let fine = rasterize_screen(
        camera.width * s,
        camera.height * s,
        &screen,
        triangles,
        true,
    );
    let (w, h, s) = (camera.width as usize, camera.height as usize, s as usize);
    let scale = 1.0 / (s * s) as f32;
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, c) in row.iter_mut().enumerate() {
            let mut n = 0u32;
            for j in 0..s {
                let base = (y * s + j) * w * s + x * s;
                n += fine.triangle[base..base + s]
                    .iter()
                    .filter(|&&t| t != NO_TRIANGLE)
                    .count() as u32;
            }
            *c = n as f32 * scale;
        }
    });
    out
}

/// Rasterises already projected vertices. With `perspective`, attributes are interpolated
/// linearly in 1/depth (a pinhole projection); without, linearly in the image (orthographic).
/// Triangles with an out-of-range index or an undrawable vertex are skipped.
#[must_use]
pub fn rasterize_screen(
    width: u32,
    height: u32,
    screen: &[ScreenVertex],
    triangles: &[[u32; 3]],
    perspective: bool,
) -> Fragments {
    let (w, h) = (width as usize, height as usize);
    let n = w * h;
    let mut triangle = vec![NO_TRIANGLE; n];
    let mut bary = vec![[0.0f32; 3]; n];
    let mut depth = vec![f32::INFINITY; n];
    // Set-up once per triangle: pixel bounds and edge data; bands then scan what overlaps them.
    let setups: Vec<Option<Setup>> = triangles
        .iter()
        .map(|t| Setup::new(t, screen, w, h))
        .collect();
    triangle
        .par_chunks_mut(BAND * w.max(1))
        .zip(bary.par_chunks_mut(BAND * w.max(1)))
        .zip(depth.par_chunks_mut(BAND * w.max(1)))
        .enumerate()
        .for_each(|(band, ((tri_out, bary_out), depth_out))| {
            let y0 = band * BAND;
            let y1 = (y0 + BAND).min(h);
            for (t, s) in setups.iter().enumerate() {
                let Some(s) = s else { continue };
                if s.y1 < y0 || s.y0 >= y1 {
                    continue;
                }
                for y in s.y0.max(y0)..=s.y1.min(y1 - 1) {
                    let py = y as f32 + 0.5;
                    for x in s.x0..=s.x1 {
                        let p = Vec2::new(x as f32 + 0.5, py);
                        let Some(l) = s.barycentric(p) else { continue };
                        let (b, z) = if perspective {
                            let q = [l[0] * s.inv_z[0], l[1] * s.inv_z[1], l[2] * s.inv_z[2]];
                            let sum = q[0] + q[1] + q[2];
                            ([q[0] / sum, q[1] / sum, q[2] / sum], 1.0 / sum)
                        } else {
                            (l, l[0] * s.z[0] + l[1] * s.z[1] + l[2] * s.z[2])
                        };
                        let b = if s.swapped { [b[0], b[2], b[1]] } else { b };
                        let i = (y - y0) * w + x;
                        // Strictly nearer wins, so among equal depths the first triangle stays.
                        if z < depth_out[i] {
                            depth_out[i] = z;
                            tri_out[i] = t as u32;
                            bary_out[i] = b;
                        }
                    }
                }
            }
        });
    Fragments {
        width,
        height,
        triangle,
        bary,
        depth,
    }
}

/// Per-triangle set-up: pixel bounding box, vertices, edge tie-break flags.
struct Setup {
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
    v: [Vec2; 3],
    /// Twice the signed area (non-zero).
    area2: f32,
    z: [f32; 3],
    inv_z: [f32; 3],
    /// Whether a pixel centre exactly on edge `k` (opposite vertex `k`) belongs to this triangle.
    owns_edge: [bool; 3],
    /// Vertices 1 and 2 were swapped to make the area positive (undone in the output).
    swapped: bool,
}

fn edge(a: Vec2, b: Vec2, p: Vec2) -> f32 {
    (b - a).perp_dot(p - a)
}

/// The edge function with its end points in a canonical order, so that the two triangles
/// sharing an edge compute exactly opposite values (no cracks from rounding).
fn edge_canonical(a: Vec2, b: Vec2, p: Vec2) -> f32 {
    if (a.x, a.y) < (b.x, b.y) {
        edge(a, b, p)
    } else {
        -edge(b, a, p)
    }
}

impl Setup {
    fn new(t: &[u32; 3], screen: &[ScreenVertex], w: usize, h: usize) -> Option<Self> {
        let sv = [
            screen.get(t[0] as usize)?,
            screen.get(t[1] as usize)?,
            screen.get(t[2] as usize)?,
        ];
        if sv
            .iter()
            .any(|s| !(s.depth.is_finite() && s.depth > 0.0 && s.xy.is_finite()))
        {
            return None;
        }
        let mut v = [sv[0].xy, sv[1].xy, sv[2].xy];
        let mut z = [sv[0].depth, sv[1].depth, sv[2].depth];
        let mut area2 = edge(v[0], v[1], v[2]);
        if area2 == 0.0 || !area2.is_finite() {
            return None;
        }
        // Draw both windings: reorder to a positive area so one set of rules applies.
        let swapped = area2 < 0.0;
        if swapped {
            v.swap(1, 2);
            z.swap(1, 2);
            area2 = -area2;
        }
        let min = v[0].min(v[1]).min(v[2]);
        let max = v[0].max(v[1]).max(v[2]);
        if max.x < 0.0 || max.y < 0.0 || min.x > w as f32 || min.y > h as f32 {
            return None;
        }
        // Pixel x covers centre x + 0.5: the first centre ≥ min is ceil(min − 0.5).
        let lo = |m: f32| (m - 0.5).ceil().max(0.0) as usize;
        let hi = |m: f32, n: usize| ((m - 0.5).floor().min(n as f32 - 1.0)).max(-1.0) as isize;
        let (x0, y0) = (lo(min.x), lo(min.y));
        let (x1, y1) = (hi(max.x, w), hi(max.y, h));
        if x1 < x0 as isize || y1 < y0 as isize {
            return None;
        }
        // Top-left rule in an image with y down and positive (clockwise-on-screen) area:
        // an edge a→b is "top" when horizontal and going right, "left" when going up.
        let owns = |a: Vec2, b: Vec2| {
            let d = b - a;
            (d.y == 0.0 && d.x > 0.0) || d.y < 0.0
        };
        let owns_edge = [owns(v[1], v[2]), owns(v[2], v[0]), owns(v[0], v[1])];
        let inv_z = z.map(|z| 1.0 / z);
        Some(Self {
            x0,
            x1: x1 as usize,
            y0,
            y1: y1 as usize,
            v,
            area2,
            z,
            inv_z,
            owns_edge,
            swapped,
        })
    }

    /// Screen-space barycentrics of `p`, or `None` when the pixel centre is outside.
    fn barycentric(&self, p: Vec2) -> Option<[f32; 3]> {
        let e = [
            edge_canonical(self.v[1], self.v[2], p),
            edge_canonical(self.v[2], self.v[0], p),
            edge_canonical(self.v[0], self.v[1], p),
        ];
        for (&ek, &owns) in e.iter().zip(&self.owns_edge) {
            if ek < 0.0 || (ek == 0.0 && !owns) {
                return None;
            }
        }
        Some([e[0] / self.area2, e[1] / self.area2, e[2] / self.area2])
    }
}

#[cfg(test)]
mod tests;
