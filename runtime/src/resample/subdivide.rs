//! Subdivision to a target vertex or triangle count by adaptive longest-edge bisection.
//!
//! Why this scheme: repeated 1→4 steps only reach counts of about `4^k` times the source's and
//! would need a simplification pass to land on a target; splitting the longest edge one at a
//! time lands on any count, spends the new vertices where the mesh is coarsest (the result is
//! close to uniformly dense), and never makes a triangle's angles worse than half of its
//! parent's. The midpoint stays on the edge — the surface does not move — so positions and
//! attributes of a new vertex are exact barycentric combinations of one source triangle.
//!
//! UV seams: edges are keyed by *position* (vertices at bitwise-equal positions are one welded
//! vertex), so a seam edge and its copy on the other side of the seam are split together, each
//! copy getting its own midpoint vertex with its own attributes at the same position. The seam
//! then stays watertight under any skinning (equal positions get equal SkinNet weights). A split
//! on a seam adds one vertex per copy, so a vertex target can be overshot by one on a seam;
//! elsewhere it is met exactly. Borders need nothing special: a border edge has one triangle.

use std::collections::{BinaryHeap, HashMap};

use core::cmp::Reverse;
use glam::Vec3;
use skinfield_formats::Template;
use skinfield_formats::mesh::MAX_VERTICES;

use super::transfer::{SourcePoint, transfer_attributes};
use super::{ResampleError, Resampled, Target};

/// The growing mesh: triangles, where each corner lies in its source triangle, and the welded
/// edge → triangles map the splits walk.
struct Bisection<'a> {
    source: &'a Template,
    positions: Vec<Vec3>,
    points: Vec<SourcePoint>,
    /// Welded id of every vertex (equal positions, equal id).
    weld: Vec<u32>,
    welded_count: u32,
    triangles: Vec<[u32; 3]>,
    /// Source triangle each triangle lies in, and its corners' barycentrics in that triangle.
    origin: Vec<u32>,
    corners: Vec<[Vec3; 3]>,
    /// Welded edge (low id, high id) → triangles that use it.
    edges: HashMap<(u32, u32), Vec<u32>>,
    /// Longest first: squared length bits (non-negative floats order like their bits), then
    /// the lower edge key, for a deterministic order.
    queue: BinaryHeap<(u32, Reverse<(u32, u32)>)>,
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

impl<'a> Bisection<'a> {
    fn new(source: &'a Template) -> Self {
        let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
        let weld: Vec<u32> = source
            .positions
            .iter()
            .map(|p| {
                let next = ids.len() as u32;
                *ids.entry(p.to_array().map(f32::to_bits)).or_insert(next)
            })
            .collect();
        let mut s = Self {
            source,
            positions: source.positions.clone(),
            points: (0..source.vertex_count() as u32)
                .map(SourcePoint::vertex)
                .collect(),
            weld,
            welded_count: ids.len() as u32,
            triangles: source.triangles.clone(),
            origin: (0..source.triangles.len() as u32).collect(),
            corners: vec![[Vec3::X, Vec3::Y, Vec3::Z]; source.triangles.len()],
            edges: HashMap::new(),
            queue: BinaryHeap::new(),
        };
        for t in 0..s.triangles.len() {
            let tri = s.triangles[t];
            for k in 0..3 {
                s.add_edge(tri[k], tri[(k + 1) % 3], t as u32);
            }
        }
        s
    }

    /// Records that triangle `t` uses the edge `a`–`b`; queues edges seen for the first time.
    fn add_edge(&mut self, a: u32, b: u32, t: u32) {
        let (wa, wb) = (self.weld[a as usize], self.weld[b as usize]);
        if wa == wb {
            return; // zero length: never split
        }
        let k = key(wa, wb);
        let list = self.edges.entry(k).or_default();
        if list.contains(&t) {
            return;
        }
        list.push(t);
        if list.len() == 1 {
            let len2 = (self.positions[a as usize] - self.positions[b as usize]).length_squared();
            self.queue.push((len2.to_bits(), Reverse(k)));
        }
    }

    fn replace_edge_user(&mut self, a: u32, b: u32, old: u32, new: u32) {
        let k = key(self.weld[a as usize], self.weld[b as usize]);
        if let Some(list) = self.edges.get_mut(&k) {
            for t in list.iter_mut().filter(|t| **t == old) {
                *t = new;
            }
        }
    }

    /// Splits the longest edge; `false` when no edge of positive length is left.
    fn split_longest(&mut self) -> bool {
        while let Some((_, Reverse(k))) = self.queue.pop() {
            // Entries of edges split earlier are stale (an edge's length never changes).
            if let Some(users) = self.edges.remove(&k) {
                self.split(k, &users);
                return true;
            }
        }
        false
    }

    fn split(&mut self, k: (u32, u32), users: &[u32]) {
        let welded_mid = self.welded_count;
        self.welded_count += 1;
        // One midpoint per distinct (unwelded) copy of the edge.
        let mut mids: Vec<((u32, u32), u32)> = Vec::new();
        for &t in users {
            let tri = self.triangles[t as usize];
            let Some(c) = (0..3).find(|&c| {
                key(
                    self.weld[tri[c] as usize],
                    self.weld[tri[(c + 1) % 3] as usize],
                ) == k
            }) else {
                continue;
            };
            let (u, v, w) = (tri[c], tri[(c + 1) % 3], tri[(c + 2) % 3]);
            let bary = self.corners[t as usize];
            let (bu, bv, bw) = (bary[c], bary[(c + 1) % 3], bary[(c + 2) % 3]);
            let bm = 0.5 * (bu + bv);
            let m = match mids.iter().find(|(pair, _)| *pair == key(u, v)) {
                Some(&(_, m)) => m,
                None => {
                    let m = self.positions.len() as u32;
                    let o = self.origin[t as usize];
                    self.positions
                        .push(0.5 * (self.positions[u as usize] + self.positions[v as usize]));
                    self.points.push(SourcePoint {
                        vertices: self.source.triangles[o as usize],
                        weights: bm.to_array(),
                    });
                    self.weld.push(welded_mid);
                    mids.push((key(u, v), m));
                    m
                }
            };
            // (u, v, w) → (u, m, w) in place and (m, v, w) appended: orientation is kept.
            let t2 = self.triangles.len() as u32;
            self.triangles[t as usize] = [u, m, w];
            self.corners[t as usize] = [bu, bm, bw];
            self.triangles.push([m, v, w]);
            self.corners.push([bm, bv, bw]);
            self.origin.push(self.origin[t as usize]);
            self.replace_edge_user(v, w, t, t2);
            self.add_edge(u, m, t);
            self.add_edge(m, w, t);
            self.add_edge(m, v, t2);
            self.add_edge(m, w, t2);
        }
    }
}

/// `source` subdivided to `target` (above its count) by longest-edge bisection: the same
/// surface, more densely sampled; attributes and normals interpolated from the source triangle
/// each new vertex lies in.
pub fn subdivide(source: &Template, target: Target) -> Result<Resampled, ResampleError> {
    source.validate()?;
    let have = target.of(source);
    let err = |reason| ResampleError::Target {
        target: target.count(),
        unit: target.unit(),
        source_count: have,
        reason,
    };
    if target.count() <= have {
        return Err(err("must be above the source's count to subdivide"));
    }
    // A closed mesh has about two triangles per vertex.
    let cap = match target {
        Target::Vertices(_) => MAX_VERTICES,
        Target::Triangles(_) => 2 * MAX_VERTICES,
    };
    if target.count() > cap {
        return Err(err("exceeds the cap of 2^24 vertices"));
    }
    let mut b = Bisection::new(source);
    let reached = |b: &Bisection<'_>| match target {
        Target::Vertices(n) => b.positions.len() >= n,
        Target::Triangles(n) => b.triangles.len() >= n,
    };
    while !reached(&b) {
        if !b.split_longest() {
            return Err(err("cannot be reached: no edge of positive length is left"));
        }
    }
    let template = transfer_attributes(source, &b.points, b.positions, b.triangles, None)?;
    Ok(Resampled {
        template,
        source: b.points,
    })
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{
        closed_when_welded, color_of, label_of, seam_sphere, sphere, uv_of, with_affine_attributes,
    };
    use super::*;
    use skinfield_formats::mesh::PartLabel;

    #[test]
    fn vertex_targets_are_met_exactly_on_a_welded_mesh() {
        let s = sphere(8, 10);
        for n in [s.vertex_count() + 1, 500, 5_001] {
            let t = subdivide(&s, Target::Vertices(n)).unwrap().template;
            assert_eq!(t.vertex_count(), n);
            // Every split of a closed mesh's edge adds one vertex and two triangles.
            assert_eq!(
                t.triangles.len(),
                s.triangles.len() + 2 * (n - s.vertex_count())
            );
        }
        let t = subdivide(&s, Target::Triangles(1001)).unwrap().template;
        assert!((1001..=1002).contains(&t.triangles.len()));
    }

    #[test]
    fn new_vertices_lie_on_the_source_triangle_and_carry_its_attributes() {
        // An affine field is reproduced exactly by barycentric interpolation, so every
        // transferred UV and colour must equal the field at the new vertex's position.
        let s = sphere(6, 8);
        let r = subdivide(&s, Target::Vertices(2_000)).unwrap();
        let t = &r.template;
        for (v, p) in r.source.iter().enumerate() {
            let x = t.positions[v];
            assert!((p.interpolate(&s.positions) - x).length() < 1e-5, "{v}");
            assert!((p.weights.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            assert!(p.weights.iter().all(|&w| w >= 0.0));
            assert!(
                (t.uvs.as_ref().unwrap()[v] - uv_of(x)).length() < 1e-5,
                "{v}"
            );
            assert!((t.colors.as_ref().unwrap()[v] - color_of(x)).length() < 1e-5);
            assert!((t.normals[v].length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn labels_are_never_averaged() {
        // Source labels split at the equator; a new vertex well inside either half (all its
        // corners agree) must keep that half's label.
        let s = sphere(6, 8);
        let r = subdivide(&s, Target::Vertices(1_500)).unwrap();
        let labels = r.template.part_labels.as_ref().unwrap();
        for (v, p) in r.source.iter().enumerate() {
            let corner_labels: Vec<PartLabel> = p
                .vertices
                .iter()
                .map(|&i| label_of(s.positions[i as usize]))
                .collect();
            if corner_labels.iter().all(|&l| l == corner_labels[0]) {
                assert_eq!(labels[v], corner_labels[0], "{v}");
            }
        }
        assert!(labels.contains(&PartLabel::Skin) && labels.contains(&PartLabel::Clothing));
    }

    #[test]
    fn the_longest_edge_goes_first_and_the_surface_stays_closed() {
        let s = sphere(8, 10);
        let longest = |t: &Template| {
            t.triangles
                .iter()
                .flat_map(|tri| (0..3).map(move |k| (tri[k], tri[(k + 1) % 3])))
                .map(|(a, b)| (t.positions[a as usize] - t.positions[b as usize]).length())
                .fold(0.0f32, f32::max)
        };
        let t = subdivide(&s, Target::Vertices(3_000)).unwrap().template;
        // Bisection until the count, longest first: no edge is longer than half the source's
        // longest once every source edge has been split (3,000 ≫ the source's edge count).
        assert!(longest(&t) <= 0.5 * longest(&s) + 1e-6);
        let mut directed = std::collections::HashSet::new();
        for tri in &t.triangles {
            for k in 0..3 {
                assert!(
                    directed.insert((tri[k], tri[(k + 1) % 3])),
                    "edge used twice"
                );
            }
        }
        assert!(directed.iter().all(|&(a, b)| directed.contains(&(b, a))));
    }

    #[test]
    fn seams_are_split_on_both_sides_together() {
        // Two triangles sharing an edge, unwelded: the shared edge exists twice with different
        // UVs. Splitting it must give a midpoint on each side at the same position.
        let positions = vec![
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
        ];
        let mut s = with_affine_attributes(positions, vec![[0, 1, 2], [4, 3, 5]]);
        s.uvs.as_mut().unwrap()[3..]
            .iter_mut()
            .for_each(|uv| uv.x += 10.0);
        let r = subdivide(&s, Target::Vertices(7)).unwrap();
        let t = &r.template;
        assert_eq!(t.vertex_count(), 8, "one midpoint per side of the seam");
        let (m1, m2) = (t.positions[6], t.positions[7]);
        assert_eq!(m1, Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(m1, m2);
        let uvs = t.uvs.as_ref().unwrap();
        assert!(
            (uvs[6].x - uvs[7].x).abs() > 9.0,
            "each side keeps its own UVs"
        );
        assert_eq!(t.triangles.len(), 4);
    }

    #[test]
    fn a_uv_sphere_seam_stays_closed() {
        let s = seam_sphere(8, 10);
        let t = subdivide(&s, Target::Vertices(2_000)).unwrap().template;
        assert!(closed_when_welded(&t), "the seam opened");
        assert!((2_000..=2_001).contains(&t.vertex_count()));
    }

    #[test]
    fn unreachable_targets_are_typed_errors() {
        let s = sphere(4, 6);
        let err = subdivide(&s, Target::Vertices(s.vertex_count())).unwrap_err();
        assert!(matches!(err, ResampleError::Target { .. }), "{err}");
        let err = subdivide(&s, Target::Vertices(MAX_VERTICES + 1)).unwrap_err();
        assert!(err.to_string().contains("cap"), "{err}");
        // A mesh whose only triangle has zero area and zero-length edges cannot grow.
        let flat = with_affine_attributes(vec![Vec3::ONE; 3], vec![[0, 1, 2]]);
        let err = subdivide(&flat, Target::Vertices(10)).unwrap_err();
        assert!(err.to_string().contains("no edge"), "{err}");
    }
}
