//! The built-in character's surface: an implicit body (smooth union of round cones around the
//! bones, with flared sleeves) meshed by marching tetrahedra and simplified with meshoptimizer,
//! plus an open, loose skirt (an elliptic cone from the waist); procedural colours and
//! skin / clothing labels.

use glam::{Vec2, Vec3};
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_formats::{PartLabel, Template};
use skinfield_runtime::resample::{Target, simplify_subset};

use super::character::segment_distance;
use crate::marching::marching_tetrahedra;

/// What a vertex of the built-in character belongs to (finer than [`PartLabel`]: colours and
/// the skirt push-out use it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// Pelvis, waist, chest, shoulders (a tight striped top).
    Torso,
    /// Neck and head.
    Head,
    /// Bare arms and hands.
    Arm,
    /// Loose sleeves over the upper arms (clothing).
    Sleeve,
    /// Legs.
    Leg,
    /// Shoes.
    Foot,
    /// The skirt (clothing, open surface).
    Skirt,
}

impl Part {
    /// Skin / clothing label for the part-wise regulariser.
    #[must_use]
    pub fn label(self) -> PartLabel {
        match self {
            Part::Sleeve | Part::Skirt => PartLabel::Clothing,
            _ => PartLabel::Skin,
        }
    }
}

/// A round cone: a capsule whose radius goes linearly from `ra` at `a` to `rb` at `b`.
#[derive(Clone, Copy, Debug)]
struct Cone {
    a: Vec3,
    b: Vec3,
    ra: f32,
    rb: f32,
    part: Part,
}

impl Cone {
    fn sdf(&self, p: Vec3) -> f32 {
        let (d, t) = segment_distance(p, self.a, self.b);
        d - (self.ra + (self.rb - self.ra) * t)
    }
}

/// Polynomial smooth minimum with blend width `k`.
fn smin(a: f32, b: f32, k: f32) -> f32 {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k * 0.25
}

fn c(a: [f32; 3], b: [f32; 3], ra: f32, rb: f32, part: Part) -> Cone {
    Cone {
        a: Vec3::from_array(a),
        b: Vec3::from_array(b),
        ra,
        rb,
        part,
    }
}

/// The shapes, grouped: a torso group blended widely, then each limb (blended narrowly within
/// itself) joined to the torso, so the two legs never melt into each other.
struct Body {
    torso: Vec<Cone>,
    limbs: Vec<Vec<Cone>>,
}

fn body() -> Body {
    let torso = vec![
        c(
            [-0.09, 0.92, 0.0],
            [0.09, 0.92, 0.0],
            0.115,
            0.115,
            Part::Torso,
        ),
        c(
            [-0.05, 1.08, 0.0],
            [0.05, 1.08, 0.0],
            0.105,
            0.105,
            Part::Torso,
        ),
        c(
            [-0.08, 1.27, 0.0],
            [0.08, 1.27, 0.0],
            0.125,
            0.125,
            Part::Torso,
        ),
        c(
            [-0.16, 1.38, 0.0],
            [0.16, 1.38, 0.0],
            0.065,
            0.065,
            Part::Torso,
        ),
        c([0.0, 1.38, 0.0], [0.0, 1.56, 0.01], 0.052, 0.05, Part::Head),
    ];
    let mut limbs = vec![vec![c(
        [0.0, 1.59, 0.015],
        [0.0, 1.67, 0.005],
        0.092,
        0.085,
        Part::Head,
    )]];
    for s in [1.0f32, -1.0] {
        limbs.push(vec![
            c(
                [0.15 * s, 1.39, 0.0],
                [0.45 * s, 1.39, 0.0],
                0.052,
                0.042,
                Part::Arm,
            ),
            c(
                [0.45 * s, 1.39, 0.0],
                [0.70 * s, 1.39, 0.0],
                0.042,
                0.031,
                Part::Arm,
            ),
            c(
                [0.70 * s, 1.39, 0.0],
                [0.80 * s, 1.385, 0.005],
                0.032,
                0.026,
                Part::Arm,
            ),
            c(
                [0.14 * s, 1.39, 0.0],
                [0.33 * s, 1.39, 0.0],
                0.066,
                0.068,
                Part::Sleeve,
            ),
        ]);
        limbs.push(vec![
            c(
                [0.10 * s, 0.93, 0.0],
                [0.10 * s, 0.48, 0.0],
                0.078,
                0.054,
                Part::Leg,
            ),
            c(
                [0.10 * s, 0.48, 0.0],
                [0.10 * s, 0.08, -0.01],
                0.052,
                0.037,
                Part::Leg,
            ),
            c(
                [0.10 * s, 0.06, -0.03],
                [0.10 * s, 0.045, 0.15],
                0.045,
                0.036,
                Part::Foot,
            ),
        ]);
    }
    Body { torso, limbs }
}

impl Body {
    fn sdf(&self, p: Vec3) -> f32 {
        let mut d = self
            .torso
            .iter()
            .map(|s| s.sdf(p))
            .reduce(|a, b| smin(a, b, 0.06))
            .unwrap_or(f32::INFINITY);
        for limb in &self.limbs {
            // Sleeves join their arm with a small blend so their rims stay visible.
            let l = limb
                .iter()
                .map(|s| s.sdf(p))
                .reduce(|a, b| smin(a, b, 0.012))
                .unwrap_or(f32::INFINITY);
            d = smin(d, l, 0.035);
        }
        d
    }

    /// The part of the shape nearest to `p` (smallest signed distance).
    fn part(&self, p: Vec3) -> Part {
        self.torso
            .iter()
            .chain(self.limbs.iter().flatten())
            .map(|s| (s.sdf(p), s.part))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(Part::Torso, |(_, part)| part)
    }
}

/// The built-in character's mesh and per-vertex parts.
#[derive(Clone, Debug)]
pub struct CharacterMesh {
    /// Template with normals, colours and part labels.
    pub template: Template,
    /// Fine part per vertex.
    pub parts: Vec<Part>,
}

/// Skirt geometry: an elliptic cone from the waist to the hem (radii along X and Z).
pub const SKIRT_TOP: (f32, Vec2) = (1.00, Vec2::new(0.222, 0.140));
/// Hem height and radii.
pub const SKIRT_HEM: (f32, Vec2) = (0.50, Vec2::new(0.36, 0.30));

fn skirt(rings: usize, segments: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut p = Vec::with_capacity((rings + 1) * segments);
    for i in 0..=rings {
        let t = i as f32 / rings as f32;
        let y = SKIRT_TOP.0 + (SKIRT_HEM.0 - SKIRT_TOP.0) * t;
        let r = SKIRT_TOP.1.lerp(SKIRT_HEM.1, t);
        for j in 0..segments {
            let a = std::f32::consts::TAU * j as f32 / segments as f32;
            p.push(Vec3::new(r.x * a.cos(), y, r.y * a.sin()));
        }
    }
    let mut t = Vec::with_capacity(rings * segments * 2);
    for i in 0..rings {
        for j in 0..segments {
            let a = (i * segments + j) as u32;
            let b = (i * segments + (j + 1) % segments) as u32;
            let (c, d) = (a + segments as u32, b + segments as u32);
            // Counter-clockwise seen from outside (normals point away from the axis).
            t.push([a, b, c]);
            t.push([b, d, c]);
        }
    }
    (p, t)
}

/// Builds the character mesh: the implicit body meshed on a grid of `grid` cells along the
/// height, simplified to about `target_vertices` (body and skirt together), plus the skirt.
/// `seed` varies the colour noise.
#[must_use]
pub fn build_mesh(grid: usize, target_vertices: usize, seed: u64) -> CharacterMesh {
    let body = body();
    let (min, max) = (Vec3::new(-0.86, -0.01, -0.16), Vec3::new(0.86, 1.79, 0.22));
    let cell = (max.y - min.y) / grid.max(8) as f32;
    let (raw_p, raw_t) = marching_tetrahedra(|p| body.sdf(p), min, max, cell);
    let (skirt_rings, skirt_segments) = (16usize, 96usize);
    let skirt_vertices = (skirt_rings + 1) * skirt_segments;
    let body_target = target_vertices.saturating_sub(skirt_vertices).max(500);
    let (mut positions, mut triangles) = simplify(&raw_p, &raw_t, body_target);
    let mut parts: Vec<Part> = positions.iter().map(|&p| body.part(p)).collect();
    let (sp, st) = skirt(skirt_rings, skirt_segments);
    let offset = positions.len() as u32;
    positions.extend(sp);
    parts.extend(std::iter::repeat_n(Part::Skirt, skirt_vertices));
    triangles.extend(st.iter().map(|t| t.map(|i| i + offset)));
    let normals = area_weighted_normals(&positions, &triangles);
    let colors = positions
        .iter()
        .zip(&parts)
        .map(|(&p, &part)| super::texture::color(p, part, seed))
        .collect();
    let part_labels = Some(parts.iter().map(|p| p.label()).collect());
    let template = Template {
        positions,
        normals,
        triangles,
        uvs: None,
        colors: Some(colors),
        part_labels,
    };
    CharacterMesh { template, parts }
}

/// Simplifies a closed mesh to about `target_vertices` with meshoptimizer and drops unused
/// vertices (first-use order, so the result is deterministic).
fn simplify(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    target_vertices: usize,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let (source, triangles) =
        simplify_subset(positions, triangles, Target::Vertices(target_vertices));
    (
        source.iter().map(|&i| positions[i as usize]).collect(),
        triangles,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_character_mesh_is_valid_and_labelled() {
        let m = build_mesh(48, 3000, 1);
        m.template.validate().unwrap();
        let n = m.template.vertex_count();
        assert!((1500..6000).contains(&n), "{n} vertices");
        let b = m.template.bounds().unwrap();
        assert!((1.65..1.85).contains(&b.size().y), "height {}", b.size().y);
        let labels = m.template.part_labels.as_ref().unwrap();
        assert!(labels.iter().filter(|l| **l == PartLabel::Clothing).count() > 1000);
        assert!(
            m.parts.contains(&Part::Sleeve)
                && m.parts.contains(&Part::Head)
                && m.parts.contains(&Part::Foot)
        );
        // The skirt clears the thighs in the bind pose (the push-out acts only under motion).
        let thigh = |p: Vec3, s: f32| {
            segment_distance(
                p,
                Vec3::new(0.1 * s, 0.93, 0.0),
                Vec3::new(0.1 * s, 0.48, 0.0),
            )
            .0
        };
        for (p, part) in m.template.positions.iter().zip(&m.parts) {
            if *part == Part::Skirt {
                assert!(thigh(*p, 1.0) > 0.08 && thigh(*p, -1.0) > 0.08, "{p}");
            }
        }
    }
}
