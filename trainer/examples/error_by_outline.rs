//! Where can the silhouettes see? Counts the training views whose *true* posed mesh has each
//! template vertex on its outline (`eval::diagnostics::truth_outline_views`: the silhouette
//! loss's boundary set at the truth), then splits each skinning's per-vertex errors over the
//! test frames between the vertices some view sees there ("seen") and the rest ("hidden":
//! under clothing, between the legs, facing the cameras in every view). For each
//! split: the mean and the largest distance vertex to vertex and off the true surface, and the
//! worst-vertex checks of `trainer zoo` (frames on which the split's worst vertex is further off
//! than the *initial* skinning's worst vertex of the whole mesh, and by how much at most), and
//! the split's vertex furthest off the surface with the number of training views that had it
//! on their outline. `trainer demo`'s `diagnostics.md` gives the means and worst vertices.
//!
//! A vertex the silhouettes never see gets its weights only from the warm start, the
//! regularisers and whatever the shared network carries over from its neighbours; this tells
//! how much of an error lies there.
//!
//! `cargo run --release -p skinfield-trainer --example error_by_outline -- CAPTURE_DIR SKINNING...`
//! (skinnings as in `trainer eval --weights`; the capture needs ground-truth meshes for its
//! training frames, which `trainer synth` writes).

use anyhow::Context;
use glam::Vec3;
use skinfield_formats::capture::load_capture;
use skinfield_trainer::eval::diagnostics::truth_outline_views;
use skinfield_trainer::eval::{PreparedSkinning, Skinning, per_vertex_m2s};

/// One split's accumulated errors (centimetres).
#[derive(Default)]
struct Split {
    sum_vertex: f64,
    sum_surface: f64,
    count: usize,
    max_vertex: f64,
    max_surface: f64,
    /// The vertex furthest off the true surface, and the training views that saw it.
    worst_surface_vertex: (usize, u32),
    /// Frames whose worst vertex to vertex exceeds the initial skinning's, and the largest excess.
    vertex_fails: (usize, f64),
    /// The same off the true surface.
    surface_fails: (usize, f64),
}

impl Split {
    fn line(&self, name: &str) -> String {
        let n = self.count.max(1) as f64;
        let fails = |(k, by): (usize, f64)| {
            if k == 0 {
                "passes".to_string()
            } else {
                format!("{k} frames, by {by:.2}")
            }
        };
        format!(
            "{name:<7} {:>10.3} {:>10.2} {:>20} {:>10.3} {:>10.2} {:>20} {:>7} {:>6}",
            self.sum_vertex / n,
            self.max_vertex,
            fails(self.vertex_fails),
            self.sum_surface / n,
            self.max_surface,
            fails(self.surface_fails),
            self.worst_surface_vertex.0,
            self.worst_surface_vertex.1,
        )
    }
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = args
        .next()
        .context("usage: error_by_outline CAPTURE_DIR SKINNING...")?;
    let capture = load_capture(std::path::Path::new(&dir))?;
    let seen = truth_outline_views(&capture)
        .context("the capture has no ground truth for its training frames")?;
    let seen_count = seen.iter().filter(|&&s| s > 0).count();
    println!(
        "{seen_count} of {} vertices lie on a true training outline ({} training frames × {} cameras)",
        seen.len(),
        capture.train_frames.len(),
        capture.rig.cameras.len()
    );
    // The reference of the checks: the initial skinning's worst vertex per test frame.
    let initial = PreparedSkinning::new(&capture, &Skinning::Initial)?;
    let mut reference = Vec::new();
    for &frame in &capture.test_frames {
        let (vertex, surface) = errors(&capture, &initial, frame)?;
        reference.push((max(&vertex), max(&surface)));
    }
    println!(
        "{:<7} {:>10} {:>10} {:>20} {:>10} {:>10} {:>20} {:>7} {:>6}",
        "split",
        "v2v mean",
        "v2v max",
        "v2v ≤ initial's",
        "off mean",
        "off max",
        "off ≤ initial's",
        "vertex",
        "views"
    );
    for spec in args {
        let skinning: Skinning = spec.parse().map_err(|e| anyhow::anyhow!("{e}"))?;
        let prepared = PreparedSkinning::new(&capture, &skinning)?;
        let mut splits = [Split::default(), Split::default()];
        for (&frame, &(ref_vertex, ref_surface)) in capture.test_frames.iter().zip(&reference) {
            let (vertex, surface) = errors(&capture, &prepared, frame)?;
            for (k, split) in splits.iter_mut().enumerate() {
                let mine = |values: &[f64]| -> Vec<(usize, f64)> {
                    values
                        .iter()
                        .enumerate()
                        .filter(|&(i, _)| (seen[i] > 0) == (k == 0))
                        .map(|(i, &v)| (i, v))
                        .collect()
                };
                let (v, s) = (mine(&vertex), mine(&surface));
                if let Some(&(i, d)) = s.iter().max_by(|a, b| a.1.total_cmp(&b.1))
                    && d > split.max_surface
                {
                    split.worst_surface_vertex = (i, seen[i]);
                }
                split.sum_vertex += v.iter().map(|p| p.1).sum::<f64>();
                split.sum_surface += s.iter().map(|p| p.1).sum::<f64>();
                split.count += v.len();
                let worst = |values: &[(usize, f64)]| values.iter().fold(0.0, |m, p| p.1.max(m));
                let (worst_v, worst_s) = (worst(&v), worst(&s));
                split.max_vertex = split.max_vertex.max(worst_v);
                split.max_surface = split.max_surface.max(worst_s);
                for (fails, worst, reference) in [
                    (&mut split.vertex_fails, worst_v, ref_vertex),
                    (&mut split.surface_fails, worst_s, ref_surface),
                ] {
                    if worst > reference {
                        fails.0 += 1;
                        fails.1 = fails.1.max(worst - reference);
                    }
                }
            }
        }
        println!("{} (cm)", prepared.method());
        println!("{}", splits[0].line("seen"));
        println!("{}", splits[1].line("hidden"));
    }
    Ok(())
}

/// Per-vertex distances (cm) of one test frame: to the same vertex of the truth, and to the true
/// surface.
fn errors(
    capture: &skinfield_formats::capture::Capture,
    skinning: &PreparedSkinning,
    frame: usize,
) -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
    let truth = capture.evaluation_gt_mesh(frame)?;
    let posed = skinning.pose_frame(capture, frame)?;
    let vertex = posed
        .iter()
        .zip(&truth)
        .map(|(p, t): (&Vec3, &Vec3)| f64::from((*p - *t).length()) * 100.0)
        .collect();
    let surface = per_vertex_m2s(capture, frame, &posed)?
        .into_iter()
        .map(|d| f64::from(d) * 100.0)
        .collect();
    Ok((vertex, surface))
}

fn max(values: &[f64]) -> f64 {
    values.iter().copied().fold(0.0, f64::max)
}
