//! Load-time resampling of a canonical mesh (`resample` feature): one trained SkinNet drives a
//! character at any level of detail, because it is a field over canonical space (paper,
//! supplementary I). Resample the template once at load, then bind the result like any other
//! mesh ([`crate::BoundMesh::bind`] on [`Resampled::template`]'s positions): no retraining, no
//! weight transfer — the network is queried at the new canonical positions.
//!
//! * [`simplify()`] (fewer vertices): meshoptimizer's edge-collapse simplifier. It only removes
//!   vertices, so every kept vertex *is* a source vertex and its attributes carry over exactly.
//!   meshoptimizer treats vertices that share a position but not their attributes (UV seams) as
//!   a seam and collapses both sides together, and border vertices only along the border, so
//!   seams and borders keep their shape.
//! * [`subdivide()`] (more vertices): adaptive longest-edge bisection. The longest edge is split
//!   at its midpoint, again and again, until the target count is reached; each split adds one
//!   vertex (per seam copy of the edge), so the count is reached exactly, and the surface does
//!   not move (no smoothing: the resampled mesh is the same surface, only sampled more densely,
//!   so a comparison with the source's ground truth measures the skinning alone).
//! * [`transfer`]: every new vertex records where it lies on the source surface as a
//!   [`SourcePoint`] (source vertices and barycentric weights); UVs, colours and normals are
//!   interpolated from it, part labels (categorical) take the label with the largest barycentric
//!   weight. Callers transfer their own attributes with [`SourcePoint::interpolate`].
//!
//! [`resample`] picks the one the target needs.

pub mod simplify;
pub mod subdivide;
pub mod transfer;

use skinfield_formats::SkinError;
use skinfield_formats::Template;
use skinfield_formats::mesh::MeshError;

pub use simplify::{simplify, simplify_subset, simplify_subset_locked};
pub use subdivide::subdivide;
pub use transfer::{SourcePoint, transfer_attributes, transfer_skin};

/// The size a resampled mesh should have.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// This many vertices.
    Vertices(usize),
    /// This many triangles.
    Triangles(usize),
}

impl Target {
    /// The requested count.
    #[must_use]
    pub fn count(self) -> usize {
        match self {
            Self::Vertices(n) | Self::Triangles(n) => n,
        }
    }

    /// `"vertices"` or `"triangles"`, for messages.
    #[must_use]
    pub fn unit(self) -> &'static str {
        match self {
            Self::Vertices(_) => "vertices",
            Self::Triangles(_) => "triangles",
        }
    }

    /// The mesh's count in this target's unit.
    #[must_use]
    pub fn of(self, template: &Template) -> usize {
        match self {
            Self::Vertices(_) => template.vertex_count(),
            Self::Triangles(_) => template.triangles.len(),
        }
    }
}

/// Why a mesh could not be resampled.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ResampleError {
    /// The source template is invalid.
    #[error("source template: {0}")]
    Mesh(#[from] MeshError),
    /// The target cannot be reached by the requested operation.
    #[error("`target`: {target} {unit} {reason} (the source has {source_count})")]
    Target {
        /// The requested count.
        target: usize,
        /// `"vertices"` or `"triangles"`.
        unit: &'static str,
        /// The source's count in the same unit.
        source_count: usize,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A source point refers to a vertex the source does not have.
    #[error("`source[{point}]` refers to vertex {vertex}, but the source has {vertices}")]
    SourceIndex {
        /// The offending point.
        point: usize,
        /// The bad vertex index.
        vertex: u32,
        /// The source's vertex count.
        vertices: usize,
    },
    /// The transferred skin is invalid.
    #[error("`skin`: {0}")]
    Skin(#[from] SkinError),
}

/// A resampled template and, for each of its vertices, where it lies on the source surface.
#[derive(Clone, Debug, PartialEq)]
pub struct Resampled {
    /// The new template (valid; UVs, colours and part labels present where the source has them).
    pub template: Template,
    /// One entry per vertex of `template`.
    pub source: Vec<SourcePoint>,
}

/// Simplifies (target below the source's count), subdivides (above) or copies (equal) `source`.
pub fn resample(source: &Template, target: Target) -> Result<Resampled, ResampleError> {
    source.validate()?;
    let have = target.of(source);
    match target.count().cmp(&have) {
        core::cmp::Ordering::Less => simplify(source, target),
        core::cmp::Ordering::Greater => subdivide(source, target),
        core::cmp::Ordering::Equal => Ok(Resampled {
            template: source.clone(),
            source: (0..source.vertex_count() as u32)
                .map(SourcePoint::vertex)
                .collect(),
        }),
    }
}

#[cfg(test)]
pub(crate) mod fixtures {
    //! Meshes with known answers for the resampling tests.

    use glam::{Vec2, Vec3};
    use skinfield_formats::Template;
    use skinfield_formats::mesh::PartLabel;

    /// The triangles of a UV sphere with the north pole at vertex 0, the south pole at `south`
    /// and ring `r` (1..rings), longitude `s` (0..=segments) at vertex `at(r, s)`.
    fn sphere_triangles(
        rings: u32,
        segments: u32,
        south: u32,
        at: impl Fn(u32, u32) -> u32,
    ) -> Vec<[u32; 3]> {
        let mut triangles = Vec::new();
        for s in 0..segments {
            triangles.push([0, at(1, s + 1), at(1, s)]);
            triangles.push([south, at(rings - 1, s), at(rings - 1, s + 1)]);
            for r in 1..rings - 1 {
                let (a, b, c, d) = (at(r, s), at(r, s + 1), at(r + 1, s), at(r + 1, s + 1));
                triangles.push([a, b, d]);
                triangles.push([a, d, c]);
            }
        }
        triangles
    }

    /// A UV sphere of radius 1 (closed, welded): `rings` latitude bands, `segments` longitudes.
    /// Colours and UVs are affine in the position, so any barycentric transfer is exact.
    pub fn sphere(rings: u32, segments: u32) -> Template {
        let mut positions = vec![Vec3::Y];
        for r in 1..rings {
            let phi = core::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segments {
                let theta = core::f32::consts::TAU * s as f32 / segments as f32;
                positions.push(Vec3::new(
                    phi.sin() * theta.cos(),
                    phi.cos(),
                    phi.sin() * theta.sin(),
                ));
            }
        }
        positions.push(Vec3::NEG_Y);
        let south = positions.len() as u32 - 1;
        let at = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
        let triangles = sphere_triangles(rings, segments, south, at);
        with_affine_attributes(positions, triangles)
    }

    /// The same sphere with a UV seam: the meridian at longitude 0 is duplicated (`u` = 0 on one
    /// copy, 1 on the other), as texture-mapped meshes store it.
    pub fn seam_sphere(rings: u32, segments: u32) -> Template {
        let mut positions = vec![Vec3::Y];
        let mut uvs = vec![Vec2::new(0.5, 0.0)];
        for r in 1..rings {
            let phi = core::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let theta = core::f32::consts::TAU * (s % segments) as f32 / segments as f32;
                positions.push(Vec3::new(
                    phi.sin() * theta.cos(),
                    phi.cos(),
                    phi.sin() * theta.sin(),
                ));
                uvs.push(Vec2::new(
                    s as f32 / segments as f32,
                    r as f32 / rings as f32,
                ));
            }
        }
        positions.push(Vec3::NEG_Y);
        uvs.push(Vec2::new(0.5, 1.0));
        let south = positions.len() as u32 - 1;
        let at = |r: u32, s: u32| 1 + (r - 1) * (segments + 1) + s;
        let triangles = sphere_triangles(rings, segments, south, at);
        let mut t = with_affine_attributes(positions, triangles);
        t.uvs = Some(uvs);
        t
    }

    /// Whether the mesh is closed once vertices at equal positions are welded: every welded
    /// edge used exactly once in each direction (a seam that opened would leave edges used once).
    pub fn closed_when_welded(t: &Template) -> bool {
        let mut ids = std::collections::HashMap::new();
        let weld: Vec<usize> = t
            .positions
            .iter()
            .map(|p| {
                let next = ids.len();
                *ids.entry(p.to_array().map(f32::to_bits)).or_insert(next)
            })
            .collect();
        let mut directed = std::collections::HashMap::new();
        for tri in &t.triangles {
            for k in 0..3 {
                let e = (weld[tri[k] as usize], weld[tri[(k + 1) % 3] as usize]);
                *directed.entry(e).or_insert(0) += 1;
            }
        }
        directed
            .iter()
            .all(|(&(a, b), &c)| c == 1 && directed.get(&(b, a)) == Some(&1))
    }

    /// Attributes that are affine functions of the position (so interpolation reproduces them).
    pub fn with_affine_attributes(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Template {
        let mut t = Template {
            uvs: Some(positions.iter().map(|&p| uv_of(p)).collect()),
            colors: Some(positions.iter().map(|&p| color_of(p)).collect()),
            part_labels: Some(positions.iter().map(|&p| label_of(p)).collect()),
            positions,
            triangles,
            ..Default::default()
        };
        t.compute_normals();
        t
    }

    /// The UV field of the fixtures.
    pub fn uv_of(p: Vec3) -> Vec2 {
        Vec2::new(0.5 + 0.25 * p.x - 0.1 * p.z, 0.5 + 0.5 * p.y)
    }

    /// The colour field of the fixtures.
    pub fn color_of(p: Vec3) -> Vec3 {
        Vec3::new(0.5, 0.5, 0.5) + 0.2 * p
    }

    /// Clothing above the equator, skin below it (strictly: the equator itself is skin).
    pub fn label_of(p: Vec3) -> PartLabel {
        if p.y > 1e-6 {
            PartLabel::Clothing
        } else {
            PartLabel::Skin
        }
    }
}
