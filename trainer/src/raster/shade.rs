//! Shading of rasterised fragments: Lambert diffuse plus a little Blinn–Phong specular under
//! one directional light, with shadows from a shadow map and a constant ambient term.

use glam::{Vec2, Vec3};
use skinfield_formats::Camera;

use super::{Fragments, NO_TRIANGLE, ScreenVertex, rasterize_screen};

/// A directional light and the material constants shared by the whole subject.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Direction the light travels (unit, world space): a surface facing `-direction` is lit.
    pub direction: Vec3,
    /// Strength of the direct light.
    pub intensity: f32,
    /// Ambient light (unshadowed).
    pub ambient: f32,
    /// Specular strength (white highlight).
    pub specular: f32,
    /// Blinn–Phong exponent.
    pub shininess: f32,
}

impl Default for Light {
    fn default() -> Self {
        Self {
            direction: Vec3::new(-0.4, -1.0, -0.6).normalize(),
            intensity: 0.85,
            ambient: 0.22,
            specular: 0.12,
            shininess: 24.0,
        }
    }
}

/// Depth of the surface nearest to a directional light, on an orthographic grid
/// perpendicular to it.
#[derive(Clone, Debug)]
pub struct ShadowMap {
    u: Vec3,
    v: Vec3,
    d: Vec3,
    origin: Vec2,
    texel: f32,
    size: usize,
    depth: Vec<f32>,
}

impl ShadowMap {
    /// Renders the depth map of a mesh for a light travelling along `direction`, `size × size`
    /// texels covering the mesh's extent across the light (with a margin).
    #[must_use]
    pub fn build(direction: Vec3, positions: &[Vec3], triangles: &[[u32; 3]], size: usize) -> Self {
        let d = direction.normalize();
        let u = d.any_orthonormal_vector();
        let v = d.cross(u);
        let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for p in positions.iter().filter(|p| p.is_finite()) {
            let q = Vec2::new(p.dot(u), p.dot(v));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        if !(lo.is_finite() && hi.is_finite()) {
            (lo, hi) = (Vec2::ZERO, Vec2::ONE);
        }
        let extent = (hi - lo).max_element().max(1e-3) * 1.04;
        let origin = (lo + hi) * 0.5 - Vec2::splat(extent * 0.5);
        let size = size.max(1);
        let texel = extent / size as f32;
        // Depths are measured from the farthest point back, so they stay positive for the
        // rasteriser (which rejects depths ≤ 0 as behind the viewer).
        let back = positions
            .iter()
            .filter(|p| p.is_finite())
            .map(|p| p.dot(d))
            .fold(f32::INFINITY, f32::min)
            - 1.0;
        let screen: Vec<ScreenVertex> = positions
            .iter()
            .map(|&p| ScreenVertex {
                xy: (Vec2::new(p.dot(u), p.dot(v)) - origin) / texel,
                depth: p.dot(d) - back,
            })
            .collect();
        let frags = rasterize_screen(size as u32, size as u32, &screen, triangles, false);
        let depth = frags.depth.iter().map(|&z| z + back).collect();
        Self {
            u,
            v,
            d,
            origin,
            texel,
            size,
            depth,
        }
    }

    /// Size of one texel in metres.
    #[must_use]
    pub fn texel(&self) -> f32 {
        self.texel
    }

    /// Fraction of the light reaching world point `p` with surface normal `n`, in [0, 1]:
    /// 3×3 percentage-closer filtering, with the point offset along the normal and a depth bias
    /// of a few texels so a lit surface does not shadow itself.
    #[must_use]
    pub fn visibility(&self, p: Vec3, n: Vec3) -> f32 {
        let p = p + n * (1.5 * self.texel);
        let q = (Vec2::new(p.dot(self.u), p.dot(self.v)) - self.origin) / self.texel;
        let z = p.dot(self.d) - 1.5 * self.texel;
        let (cx, cy) = (q.x.floor() as isize, q.y.floor() as isize);
        let mut lit = 0u32;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (x, y) = (cx + dx, cy + dy);
                let occluder =
                    if x < 0 || y < 0 || x as usize >= self.size || y as usize >= self.size {
                        f32::INFINITY
                    } else {
                        self.depth[y as usize * self.size + x as usize]
                    };
                if z <= occluder {
                    lit += 1;
                }
            }
        }
        lit as f32 / 9.0
    }
}

/// Shades fragments of a mesh seen by `camera` into linear RGB (row-major), `background` where
/// no triangle is visible. Normals are interpolated per pixel and turned towards the camera
/// (open surfaces are lit on both sides); `colors` are per-vertex albedo (grey 0.7 when
/// `None`).
#[allow(clippy::too_many_arguments)]
#[must_use]
pub fn shade(
    camera: &Camera,
    frags: &Fragments,
    positions: &[Vec3],
    normals: &[Vec3],
    colors: Option<&[Vec3]>,
    triangles: &[[u32; 3]],
    light: &Light,
    shadow: Option<&ShadowMap>,
    background: Vec3,
) -> Vec<Vec3> {
    let eye = camera.center();
    let to_light = -light.direction.normalize();
    let get = |a: &[Vec3], i: u32| a.get(i as usize).copied().unwrap_or(Vec3::ZERO);
    frags
        .triangle
        .iter()
        .zip(&frags.bary)
        .map(|(&t, b)| {
            if t == NO_TRIANGLE {
                return background;
            }
            let Some(tri) = triangles.get(t as usize) else {
                return background;
            };
            let lerp =
                |a: &[Vec3]| get(a, tri[0]) * b[0] + get(a, tri[1]) * b[1] + get(a, tri[2]) * b[2];
            let p = lerp(positions);
            let mut n = lerp(normals).try_normalize().unwrap_or(Vec3::Y);
            let view = (eye - p).try_normalize().unwrap_or(Vec3::Z);
            if n.dot(view) < 0.0 {
                n = -n;
            }
            let albedo = colors.map_or(Vec3::splat(0.7), lerp);
            let diffuse = n.dot(to_light).max(0.0);
            let vis = match shadow {
                Some(s) if diffuse > 0.0 => s.visibility(p, n),
                _ => 1.0,
            };
            let h = (to_light + view).try_normalize().unwrap_or(n);
            let spec = if diffuse > 0.0 {
                light.specular * n.dot(h).max(0.0).powf(light.shininess)
            } else {
                0.0
            };
            albedo * (light.ambient + light.intensity * diffuse * vis)
                + Vec3::splat(spec * vis * light.intensity)
        })
        .collect()
}
