//! Attribute transfer from a source mesh to a resampled one: every new vertex is a barycentric
//! combination of (at most three) source vertices on the source surface, recorded as a
//! [`SourcePoint`]. Continuous attributes are interpolated; part labels are categorical and take
//! the label that carries the largest barycentric weight (a vote, never an average).

use core::ops::{Add, Mul};

use glam::Vec3;
use skinfield_formats::mesh::{PartLabel, Template};
use skinfield_formats::skin::StaticSkin;

use super::ResampleError;

/// A point of the source surface: `Σ weights[k] · source[vertices[k]]`, weights ≥ 0 summing to
/// one. A kept vertex is `vertices = [i, i, i]`, `weights = [1, 0, 0]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SourcePoint {
    /// Source vertex indices (a corner may repeat).
    pub vertices: [u32; 3],
    /// Barycentric weights of `vertices`.
    pub weights: [f32; 3],
}

impl SourcePoint {
    /// Exactly source vertex `i`.
    #[must_use]
    pub fn vertex(i: u32) -> Self {
        Self {
            vertices: [i; 3],
            weights: [1.0, 0.0, 0.0],
        }
    }

    /// The attribute `values` (one per source vertex) interpolated at this point.
    ///
    /// # Panics
    /// If a vertex index is out of range for `values`; [`transfer_attributes`] checks the
    /// indices first.
    #[must_use]
    pub fn interpolate<T>(&self, values: &[T]) -> T
    where
        T: Copy + Add<Output = T> + Mul<f32, Output = T>,
    {
        let [a, b, c] = self.vertices.map(|i| values[i as usize]);
        a * self.weights[0] + b * self.weights[1] + c * self.weights[2]
    }

    /// The label with the largest total barycentric weight; on a tie, the label of the
    /// lowest-numbered source vertex among the tied ones (independent of corner order, so the
    /// copies of a seam vertex agree).
    #[must_use]
    pub fn vote(&self, labels: &[PartLabel]) -> PartLabel {
        let mut best: Option<(f32, u32, PartLabel)> = None;
        for k in 0..3 {
            let label = labels[self.vertices[k] as usize];
            let total: f32 = (0..3)
                .filter(|&m| labels[self.vertices[m] as usize] == label)
                .map(|m| self.weights[m])
                .sum();
            let lowest = (0..3)
                .filter(|&m| labels[self.vertices[m] as usize] == label && self.weights[m] > 0.0)
                .map(|m| self.vertices[m])
                .min()
                .unwrap_or(self.vertices[k]);
            let better = match best {
                None => true,
                Some((t, v, _)) => total > t || (total == t && lowest < v),
            };
            if better {
                best = Some((total, lowest, label));
            }
        }
        // Three candidates were examined, so `best` is set.
        best.map_or(labels[self.vertices[0] as usize], |(_, _, l)| l)
    }

    fn check(&self, point: usize, vertices: usize) -> Result<(), ResampleError> {
        match self.vertices.iter().find(|&&v| v as usize >= vertices) {
            Some(&vertex) => Err(ResampleError::SourceIndex {
                point,
                vertex,
                vertices,
            }),
            None => Ok(()),
        }
    }
}

/// A template over `positions` and `triangles` whose UVs, colours and part labels come from
/// `source` at `points` (present where `source` has them). Normals are `normals` when given,
/// else `source`'s interpolated and renormalised (right for a mesh on the same surface).
pub fn transfer_attributes(
    source: &Template,
    points: &[SourcePoint],
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    normals: Option<Vec<Vec3>>,
) -> Result<Template, ResampleError> {
    let n = source.vertex_count();
    for (i, p) in points.iter().enumerate() {
        p.check(i, n)?;
    }
    let normals = normals.unwrap_or_else(|| {
        points
            .iter()
            .map(|p| {
                p.interpolate(&source.normals)
                    .try_normalize()
                    .unwrap_or(Vec3::Y)
            })
            .collect()
    });
    let template = Template {
        positions,
        normals,
        triangles,
        uvs: source
            .uvs
            .as_ref()
            .map(|a| points.iter().map(|p| p.interpolate(a)).collect()),
        colors: source
            .colors
            .as_ref()
            .map(|a| points.iter().map(|p| p.interpolate(a)).collect()),
        part_labels: source
            .part_labels
            .as_ref()
            .map(|a| points.iter().map(|p| p.vote(a)).collect()),
    };
    template.validate()?;
    Ok(template)
}

/// Static skinning weights for the resampled vertices, interpolated from `skin` (the source's).
///
/// SkinNet needs none of this — it is queried at the new positions. This is for the files an
/// engine loads next to the `.skf` (a glTF character must carry some skin), and for comparing
/// static baselines across resolutions.
pub fn transfer_skin(
    skin: &StaticSkin,
    points: &[SourcePoint],
) -> Result<StaticSkin, ResampleError> {
    let n = skin.vertex_count();
    let mut offsets = Vec::with_capacity(points.len() + 1);
    offsets.push(0u32);
    let (mut joints, mut weights) = (Vec::new(), Vec::new());
    let mut row: Vec<(u32, f32)> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        p.check(i, n)?;
        row.clear();
        for k in 0..3 {
            if p.weights[k] == 0.0 {
                continue;
            }
            let (js, ws) = skin.influences(p.vertices[k] as usize);
            for (&j, &w) in js.iter().zip(ws) {
                match row.iter_mut().find(|(jj, _)| *jj == j) {
                    Some(e) => e.1 += p.weights[k] * w,
                    None => row.push((j, p.weights[k] * w)),
                }
            }
        }
        row.sort_unstable_by_key(|&(j, _)| j);
        joints.extend(row.iter().map(|&(j, _)| j));
        weights.extend(row.iter().map(|&(_, w)| w));
        offsets.push(joints.len() as u32);
    }
    // Convex combinations of valid rows are valid: `new` has nothing to refuse.
    Ok(StaticSkin::new(
        offsets,
        joints,
        weights,
        skin.joint_count(),
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn interpolation_is_the_barycentric_combination() {
        let values = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 2.0),
        ];
        let p = SourcePoint {
            vertices: [0, 1, 2],
            weights: [0.5, 0.25, 0.25],
        };
        assert_eq!(p.interpolate(&values), Vec2::new(0.25, 0.5));
        assert_eq!(SourcePoint::vertex(2).interpolate(&values), values[2]);
    }

    #[test]
    fn labels_are_voted_not_averaged() {
        use PartLabel::{Clothing, Skin};
        let labels = [Skin, Clothing, Clothing, Skin];
        let at = |vertices, weights| SourcePoint { vertices, weights }.vote(&labels);
        // The total weight decides: the nearest corner wins over two light ones…
        assert_eq!(at([0, 1, 2], [0.6, 0.2, 0.2]), Skin);
        // …but two clothing corners together outvote the nearest (skin) corner.
        assert_eq!(at([0, 1, 2], [0.4, 0.3, 0.3]), Clothing);
        // Equal totals (skin 0.2 + 0.3, clothing 0.5) go to the lower source vertex (0)…
        assert_eq!(at([0, 1, 3], [0.2, 0.5, 0.3]), Skin);
        // …and so does a midpoint tie, whatever the corner order.
        assert_eq!(at([1, 0, 1], [0.5, 0.5, 0.0]), Skin);
        assert_eq!(at([0, 1, 0], [0.5, 0.5, 0.0]), Skin);
        assert_eq!(at([3, 2, 3], [0.5, 0.5, 0.0]), Clothing);
    }

    #[test]
    fn transfer_rejects_points_outside_the_source() {
        let source = super::super::fixtures::sphere(4, 6);
        let bad = [SourcePoint::vertex(source.vertex_count() as u32)];
        let err = transfer_attributes(&source, &bad, vec![Vec3::ZERO], vec![], None).unwrap_err();
        assert!(
            matches!(err, ResampleError::SourceIndex { point: 0, .. }),
            "{err}"
        );
    }

    #[test]
    fn transferred_skin_is_the_convex_combination_of_the_rows() {
        // Vertex 0: joint 0; vertex 1: joints 1 and 2 half each.
        let skin = StaticSkin::new(vec![0, 1, 3], vec![0, 1, 2], vec![1.0, 0.5, 0.5], 3).unwrap();
        let points = [
            SourcePoint::vertex(1),
            SourcePoint {
                vertices: [0, 1, 1],
                weights: [0.5, 0.5, 0.0],
            },
        ];
        let out = transfer_skin(&skin, &points).unwrap();
        assert_eq!(out.to_dense(), vec![0.0, 0.5, 0.5, 0.5, 0.25, 0.25]);
        assert!(matches!(
            transfer_skin(&skin, &[SourcePoint::vertex(2)]),
            Err(ResampleError::SourceIndex { vertex: 2, .. })
        ));
    }
}
