//! Per-vertex attributes of a reconstructed mesh from the views that see each vertex: colours
//! (a weighted mean of the images) and part labels (a weighted vote over label images).
//!
//! A vertex is *seen* by a camera when it faces the camera and the depth buffer of the mesh in
//! that view is not nearer than the vertex (by more than a tolerance of the order of the
//! reconstruction's cell, so a vertex is not hidden by the surface it lies on). Its weight is
//! `cos²` of the angle between its normal and the line of sight: grazing views blur colours
//! across the surface and put boundary labels on the wrong side. Vertices no camera sees (deep
//! in a crease) take the mean colour / the most common label of their seen neighbours, spread
//! ring by ring.

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use skinfield_formats::Camera;
use skinfield_formats::capture::{CaptureImage, LabelImage, NO_LABEL};

use crate::raster::rasterize;

/// Cameras whose line of sight meets the surface more obliquely than this (cosine) do not count.
const MIN_COS: f32 = 0.1;

/// What a camera sees of a mesh: per vertex, its projection and weight, or nothing.
#[derive(Clone, Debug)]
pub struct Visibility {
    /// Per vertex: `(pixel position, cos²)` when the camera sees it.
    pub seen: Vec<Option<(Vec2, f32)>>,
}

impl Visibility {
    /// Which vertices of `positions` / `triangles` (with unit `normals`) `camera` sees, with a
    /// depth tolerance `tolerance` (metres).
    #[must_use]
    pub fn new(
        camera: &Camera,
        positions: &[Vec3],
        normals: &[Vec3],
        triangles: &[[u32; 3]],
        tolerance: f32,
    ) -> Self {
        let frags = rasterize(camera, positions, triangles);
        let (w, h) = (camera.width as usize, camera.height as usize);
        let centre = camera.center();
        let seen = positions
            .par_iter()
            .zip(normals)
            .map(|(&p, &n)| {
                let cos = n.dot((centre - p).normalize_or_zero());
                if cos < MIN_COS {
                    return None;
                }
                let depth = camera.to_camera(p).z;
                let px = camera.project(p)?;
                let (x, y) = (px.x.floor(), px.y.floor());
                if !(x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h) {
                    return None;
                }
                let nearest = frags.depth[y as usize * w + x as usize];
                (nearest >= depth - tolerance).then_some((px, cos * cos))
            })
            .collect();
        Self { seen }
    }
}

/// Bilinear sample of an image at pixel position `p` (centres at `x + 0.5`), clamped to the edge.
fn sample(image: &CaptureImage, p: Vec2) -> Vec3 {
    let (w, h) = (image.width as i64, image.height as i64);
    let (x, y) = (p.x - 0.5, p.y - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (tx, ty) = (x - x0, y - y0);
    let at = |xi: i64, yi: i64| image.rgb[(yi.clamp(0, h - 1) * w + xi.clamp(0, w - 1)) as usize];
    let (xi, yi) = (x0 as i64, y0 as i64);
    let top = at(xi, yi).lerp(at(xi + 1, yi), tx);
    let bottom = at(xi, yi + 1).lerp(at(xi + 1, yi + 1), tx);
    top.lerp(bottom, ty)
}

/// Vertex colours: the `cos²`-weighted mean of the images that see each vertex (linear RGB), and
/// how many vertices no image sees (filled from their neighbours).
#[must_use]
pub fn vertex_colors(
    visibility: &[Visibility],
    images: &[CaptureImage],
    vertex_count: usize,
    triangles: &[[u32; 3]],
) -> (Vec<Vec3>, usize) {
    let mut sum = vec![Vec3::ZERO; vertex_count];
    let mut weight = vec![0.0f32; vertex_count];
    for (vis, image) in visibility.iter().zip(images) {
        for (v, s) in vis.seen.iter().enumerate() {
            if let Some((px, w)) = *s {
                sum[v] += sample(image, px) * w;
                weight[v] += w;
            }
        }
    }
    let mut colors: Vec<Option<Vec3>> = sum
        .iter()
        .zip(&weight)
        .map(|(&s, &w)| (w > 0.0).then(|| s / w))
        .collect();
    let unseen = colors.iter().filter(|c| c.is_none()).count();
    fill_from_neighbours(&mut colors, triangles, |values| {
        values.iter().copied().sum::<Vec3>() / values.len() as f32
    });
    (
        colors
            .into_iter()
            .map(|c| c.unwrap_or(Vec3::splat(0.5)))
            .collect(),
        unseen,
    )
}

/// Part labels: per vertex the label with the largest summed `cos²` over the label images that
/// see it (the pixel under its projection; unlabelled pixels do not vote), and how many
/// vertices got no vote (filled from their neighbours).
#[must_use]
pub fn vote_labels(
    visibility: &[Visibility],
    labels: &[LabelImage],
    parts: usize,
    vertex_count: usize,
    triangles: &[[u32; 3]],
) -> (Vec<u8>, usize) {
    let mut votes = vec![0.0f32; vertex_count * parts];
    for (vis, image) in visibility.iter().zip(labels) {
        let w = image.width as usize;
        for (v, s) in vis.seen.iter().enumerate() {
            if let Some((px, weight)) = *s {
                let i = px.y as usize * w + px.x as usize;
                match image.labels.get(i) {
                    Some(&l) if l != NO_LABEL && usize::from(l) < parts => {
                        votes[v * parts + usize::from(l)] += weight;
                    }
                    _ => {}
                }
            }
        }
    }
    let mut winners: Vec<Option<u8>> = votes
        .chunks(parts.max(1))
        .map(|row| {
            let (best, &w) = row
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)))?;
            (w > 0.0).then_some(best as u8)
        })
        .collect();
    let unvoted = winners.iter().filter(|l| l.is_none()).count();
    fill_from_neighbours(&mut winners, triangles, |values| {
        let mut count = [0usize; 256];
        for &l in values {
            count[usize::from(l)] += 1;
        }
        (0..=255u8)
            .max_by_key(|&l| (count[usize::from(l)], std::cmp::Reverse(l)))
            .unwrap_or(0)
    });
    (
        winners.into_iter().map(|l| l.unwrap_or(0)).collect(),
        unvoted,
    )
}

/// Gives every `None` the `combine` of its known neighbours' values, ring by ring inwards from
/// the known region (values found in one ring are used only from the next, so the result does
/// not depend on vertex order). Vertices of a piece with no known value stay `None`.
fn fill_from_neighbours<T: Copy>(
    values: &mut [Option<T>],
    triangles: &[[u32; 3]],
    combine: impl Fn(&[T]) -> T,
) {
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); values.len()];
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3]);
            if !neighbours[a].contains(&b) {
                neighbours[a].push(b);
                neighbours[b as usize].push(a as u32);
            }
        }
    }
    loop {
        let ring: Vec<(usize, T)> = (0..values.len())
            .filter(|&v| values[v].is_none())
            .filter_map(|v| {
                let known: Vec<T> = neighbours[v]
                    .iter()
                    .filter_map(|&n| values[n as usize])
                    .collect();
                (!known.is_empty()).then(|| (v, combine(&known)))
            })
            .collect();
        if ring.is_empty() {
            return;
        }
        for (v, x) in ring {
            values[v] = Some(x);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_values_fill_ring_by_ring_from_their_neighbours() {
        // A strip of triangles 0-1-2-3-4-5: only the ends are known.
        let triangles = [[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]];
        let mut values = [Some(1.0f32), None, None, None, None, Some(5.0)];
        fill_from_neighbours(&mut values, &triangles, |v| {
            v.iter().sum::<f32>() / v.len() as f32
        });
        // Ring 1: vertex 1 (neighbours 0, 2, 3 → 1), 2 (0, 1, 3, 4 → 1), 3 (1, 2, 4, 5 → 5),
        // 4 (2, 3, 5 → 5).
        assert_eq!(values, [1.0, 1.0, 1.0, 5.0, 5.0, 5.0].map(Some));
        let mut lonely = [None::<f32>; 3];
        fill_from_neighbours(&mut lonely, &[[0, 1, 2]], |v| v[0]);
        assert_eq!(lonely, [None; 3]);
    }
}
