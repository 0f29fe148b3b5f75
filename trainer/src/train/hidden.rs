//! The vertices no training outline shows, and the gate that restricts the prior on the initial
//! weights to them (`LossWeights::hidden_prior`).
//!
//! A silhouette term moves a vertex's weights only in the views where the vertex lies on the
//! mesh's projected outline (its boundary set and the contour's nearest edges are both made of
//! those vertices, [`crate::losses::silhouette`]). About a third of the built-in character's
//! vertices are on no training view's outline (the legs under the skirt, the crotch, the
//! armpits), yet SkinNet moves them with the vertices the outlines do see, because the network
//! is shared: silhouettes alone raise those vertices' error by 3–29 % while cutting the seen
//! vertices' by 40–46 %, and the zoo's worst vertices off the surface are such hidden vertices
//! (docs/experiments/fidelity.md, "What the silhouettes can see"). A prior on the initial
//! weights over *every* vertex was measured to cost Chamfer everywhere, since it also holds
//! the vertices the images can correct; gated to the hidden ones it leaves those free.
//!
//! Which vertices are hidden is decided once per training template, from the template posed
//! by the initial weights in every training frame (the trained model's outlines differ from
//! them by a fraction of a pixel, and a set that changed during training would make the
//! objective move under the optimiser). A vertex is hidden when it lies on the outline in at
//! most `hidden_view_fraction` of the training views (frames × cameras).

use glam::Vec3;
use rayon::prelude::*;

use super::data::TrainData;
use super::validation::pose;
use crate::losses::silhouette::EdgeTable;
use crate::losses::silhouette::edges::count_outline_views;

/// How many training views (frame × camera) have each template vertex on the outline of the
/// template posed by `weights` (dense `[V, J]`, one set for every frame), out of how many views.
#[must_use]
pub fn outline_view_counts(
    data: &TrainData,
    weights: &[f32],
    edges: &EdgeTable,
) -> (Vec<u32>, usize) {
    let t = &data.template;
    let v = t.vertex_count();
    let views = data.frames.iter().map(|f| f.views.len()).sum();
    let counts = data
        .frames
        .par_iter()
        .map(|frame| {
            let posed: Vec<Vec3> = pose(&t.positions, weights, &frame.skinning);
            let mut counts = vec![0u32; v];
            let cameras = frame.views.iter().map(|view| &view.camera);
            count_outline_views(&mut counts, cameras, &posed, &t.triangles, edges);
            counts
        })
        .reduce(
            || vec![0u32; v],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        );
    (counts, views)
}

/// The gate: 1 for a vertex on the outline in at most `fraction` of `views`, else 0.
#[must_use]
pub fn hidden_gate(counts: &[u32], views: usize, fraction: f64) -> Vec<f32> {
    let limit = fraction * views as f64;
    counts
        .iter()
        .map(|&c| if f64::from(c) <= limit { 1.0 } else { 0.0 })
        .collect()
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Vec3};
    use skinfield_formats::{Camera, Template};

    use super::*;
    use crate::train::tests::scene;

    #[test]
    fn the_gate_counts_views_up_to_the_fraction() {
        let counts = [0, 1, 2, 5, 10];
        assert_eq!(hidden_gate(&counts, 10, 0.0), [1.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(hidden_gate(&counts, 10, 0.2), [1.0, 1.0, 1.0, 0.0, 0.0]);
        assert_eq!(hidden_gate(&counts, 10, 1.0), [1.0; 5]);
    }

    #[test]
    fn a_sphere_seen_from_one_side_shows_its_rim_and_hides_its_poles() {
        // A UV sphere (poles on ±y) posed by the identity, one camera on the +y axis: the
        // outline is the ring of vertices where the rays from the eye graze the sphere
        // (y = r²/d = 0.2 for radius 1 at distance 5); the caps around the poles face the
        // camera or away from it and are on no outline.
        let (mut data, _) = scene(1);
        let (positions, triangles) =
            crate::losses::silhouette::tests::uv_sphere(12, 24, 1.0, Vec3::ZERO);
        data.template = Template {
            positions: positions.clone(),
            triangles: triangles.clone(),
            ..Default::default()
        };
        let j = data.skeleton.len();
        let weights: Vec<f32> = (0..positions.len())
            .flat_map(|_| (0..j).map(|k| if k == 0 { 1.0 } else { 0.0 }))
            .collect();
        let frame = &mut data.frames[0];
        frame.skinning = vec![Mat4::IDENTITY; j];
        frame.views.truncate(1);
        frame.views[0].camera =
            Camera::look_at("top", 64, 64, 1.0, Vec3::Y * 5.0, Vec3::ZERO, Vec3::Z);
        let edges = EdgeTable::new(positions.len(), &triangles);
        let (counts, views) = outline_view_counts(&data, &weights, &edges);
        assert_eq!(views, 1);
        let seen: Vec<usize> = (0..positions.len()).filter(|&i| counts[i] > 0).collect();
        assert!(!seen.is_empty());
        for &i in &seen {
            // The rings next to the grazing latitude (y = 0.259 and 0 at 12 rings).
            let p = positions[i];
            assert!(
                (p.y - 0.2).abs() < 0.25,
                "vertex {i} at {p} is on the outline"
            );
        }
        for (i, p) in positions.iter().enumerate() {
            if p.y.abs() > 0.7 {
                assert_eq!(counts[i], 0, "vertex {i} at {p} faces the camera or away");
            }
        }
        let gate = hidden_gate(&counts, views, 0.0);
        assert_eq!(
            gate.iter().filter(|&&g| g == 1.0).count(),
            positions.len() - seen.len()
        );
    }
}
