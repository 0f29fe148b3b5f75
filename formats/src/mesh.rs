//! The template mesh: canonical positions, normals, triangles and optional attributes.

use alloc::vec::Vec;

use glam::{Vec2, Vec3};

use crate::math::Aabb;

/// Largest vertex count the readers accept (a cap against hostile headers).
pub const MAX_VERTICES: usize = 1 << 24;

/// What a vertex belongs to, for the part-wise regulariser (paper Eq. 9).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum PartLabel {
    /// Body skin: should move rigidly with its bones.
    Skin = 0,
    /// Clothing: free to follow pose-dependent skinning.
    Clothing = 1,
}

/// Why a template is invalid.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// No vertices or no triangles.
    #[error("mesh is empty ({vertices} vertices, {triangles} triangles)")]
    Empty {
        /// Vertex count.
        vertices: usize,
        /// Triangle count.
        triangles: usize,
    },
    /// More vertices than [`MAX_VERTICES`].
    #[error("mesh has {0} vertices, more than the cap of {MAX_VERTICES}")]
    TooManyVertices(usize),
    /// A per-vertex attribute has the wrong length.
    #[error("mesh attribute `{field}` has {len} entries, expected {expected}")]
    AttributeLength {
        /// The attribute.
        field: &'static str,
        /// Its length.
        len: usize,
        /// The vertex count.
        expected: usize,
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {vertex}, but the mesh has {vertices}")]
    IndexOutOfRange {
        /// The triangle.
        triangle: usize,
        /// The bad index.
        vertex: u32,
        /// Vertex count.
        vertices: usize,
    },
    /// A position or normal is NaN or infinite.
    #[error("vertex {vertex} has a non-finite `{field}`")]
    NonFinite {
        /// The vertex.
        vertex: usize,
        /// The attribute.
        field: &'static str,
    },
}

/// A template (canonical) mesh.
///
/// Vertex order is the file's order (unwelded meshes stay unwelded) so that every output lines
/// up with the source asset.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Template {
    /// Canonical positions (bind pose, world space, metres).
    pub positions: Vec<Vec3>,
    /// Unit normals, one per vertex.
    pub normals: Vec<Vec3>,
    /// Counter-clockwise triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Texture coordinates, if any.
    pub uvs: Option<Vec<Vec2>>,
    /// Linear RGB colours in [0, 1], if any.
    pub colors: Option<Vec<Vec3>>,
    /// Per-vertex part labels, if any.
    pub part_labels: Option<Vec<PartLabel>>,
}

impl Template {
    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Checks lengths, indices and finiteness.
    pub fn validate(&self) -> Result<(), MeshError> {
        let n = self.positions.len();
        if n == 0 || self.triangles.is_empty() {
            return Err(MeshError::Empty {
                vertices: n,
                triangles: self.triangles.len(),
            });
        }
        if n > MAX_VERTICES {
            return Err(MeshError::TooManyVertices(n));
        }
        let check = |field, len| {
            if len == n {
                Ok(())
            } else {
                Err(MeshError::AttributeLength {
                    field,
                    len,
                    expected: n,
                })
            }
        };
        check("normals", self.normals.len())?;
        if let Some(a) = &self.uvs {
            check("uvs", a.len())?;
        }
        if let Some(a) = &self.colors {
            check("colors", a.len())?;
        }
        if let Some(a) = &self.part_labels {
            check("part_labels", a.len())?;
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            for &v in tri {
                if v as usize >= n {
                    return Err(MeshError::IndexOutOfRange {
                        triangle: t,
                        vertex: v,
                        vertices: n,
                    });
                }
            }
        }
        for (v, (p, nrm)) in self.positions.iter().zip(&self.normals).enumerate() {
            if !p.is_finite() {
                return Err(MeshError::NonFinite {
                    vertex: v,
                    field: "positions",
                });
            }
            if !nrm.is_finite() {
                return Err(MeshError::NonFinite {
                    vertex: v,
                    field: "normals",
                });
            }
        }
        Ok(())
    }

    /// Bounding box of the positions (`None` for an empty or non-finite mesh).
    #[must_use]
    pub fn bounds(&self) -> Option<Aabb> {
        Aabb::from_points(&self.positions)
    }

    /// Area-weighted vertex normals from the triangles; isolated vertices get +Y.
    ///
    /// Triangles with an out-of-range index are skipped (call [`Template::validate`] first).
    pub fn compute_normals(&mut self) {
        self.normals = area_weighted_normals(&self.positions, &self.triangles);
    }
}

/// Area-weighted vertex normals of a triangle soup; vertices touched by no (valid, non-degenerate)
/// triangle get +Y.
#[must_use]
pub fn area_weighted_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut normals = alloc::vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| i as usize);
        if a >= positions.len() || b >= positions.len() || c >= positions.len() {
            continue;
        }
        // The cross product's length is twice the area: this weights by area for free.
        let n = (positions[b] - positions[a]).cross(positions[c] - positions[a]);
        for i in [a, b, c] {
            normals[i] += n;
        }
    }
    for n in &mut normals {
        *n = n.try_normalize().unwrap_or(Vec3::Y);
    }
    normals
}

/// Texture coordinates are optional; this helper returns them or zeros.
#[must_use]
pub fn uvs_or_zero(t: &Template) -> Vec<Vec2> {
    t.uvs
        .clone()
        .unwrap_or_else(|| alloc::vec![Vec2::ZERO; t.positions.len()])
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    fn quad() -> Template {
        let mut t = Template {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0), Vec3::NEG_Z],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        };
        t.compute_normals();
        t
    }

    #[test]
    fn normals_of_a_flat_quad_point_up() {
        let t = quad();
        t.validate().unwrap();
        for n in &t.normals {
            assert!((*n - Vec3::Y).length() < 1e-6);
        }
    }

    #[test]
    fn rejects_every_invalid_configuration() {
        let good = quad();
        let mut t = good.clone();
        t.triangles.clear();
        assert!(matches!(t.validate(), Err(MeshError::Empty { .. })));
        let mut t = good.clone();
        t.normals.pop();
        assert!(matches!(
            t.validate(),
            Err(MeshError::AttributeLength {
                field: "normals",
                ..
            })
        ));
        let mut t = good.clone();
        t.uvs = Some(vec![Vec2::ZERO]);
        assert!(matches!(
            t.validate(),
            Err(MeshError::AttributeLength { field: "uvs", .. })
        ));
        let mut t = good.clone();
        t.colors = Some(vec![]);
        assert!(matches!(
            t.validate(),
            Err(MeshError::AttributeLength {
                field: "colors",
                ..
            })
        ));
        let mut t = good.clone();
        t.part_labels = Some(vec![PartLabel::Skin]);
        assert!(matches!(
            t.validate(),
            Err(MeshError::AttributeLength {
                field: "part_labels",
                ..
            })
        ));
        let mut t = good.clone();
        t.triangles[1][2] = 4;
        assert!(matches!(
            t.validate(),
            Err(MeshError::IndexOutOfRange {
                triangle: 1,
                vertex: 4,
                ..
            })
        ));
        let mut t = good.clone();
        t.positions[2].y = f32::INFINITY;
        assert!(matches!(
            t.validate(),
            Err(MeshError::NonFinite {
                vertex: 2,
                field: "positions"
            })
        ));
        let mut t = good;
        t.normals[3].x = f32::NAN;
        assert!(matches!(
            t.validate(),
            Err(MeshError::NonFinite {
                vertex: 3,
                field: "normals"
            })
        ));
    }
}
