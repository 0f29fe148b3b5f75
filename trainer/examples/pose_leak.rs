//! How much a SkinNet model's weights follow joints that cannot move the vertex.
//!
//! For every test frame of a capture and every donor frame (training frames spread over the
//! clips), each template vertex's pose is the test frame's for its candidate joints (the
//! `.skf`'s `CAND` lists, bound as the runtime binds them) and the donor's for every other
//! joint; the figure is `Σ_j |Δw_j|` of the vertex's weights against the unmixed pose, mean and
//! largest over (vertex, test frame, donor). Zero for a model whose weights depend only on the
//! pose of their candidate joints. Used for the pose-locality measurements in
//! `docs/experiments/fidelity.md`:
//!
//! ```sh
//! cargo run --release -p skinfield-trainer --example pose_leak -- CAPTURE_DIR MODEL.skf [DONORS]
//! ```
//!
//! `DONORS` (default 5) training frames serve as donors, evenly spaced.

use std::collections::HashMap;

use anyhow::{Context, Result, bail};
use skinfield_formats::Pose;
use skinfield_runtime::{BoundMesh, SkinNetModel};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(capture), Some(skf)) = (args.get(1), args.get(2)) else {
        bail!("usage: pose_leak CAPTURE_DIR MODEL.skf [DONORS]");
    };
    let donors: usize = match args.get(3) {
        Some(d) => d.parse().context("DONORS")?,
        None => 5,
    };
    let capture = skinfield_formats::capture::load_capture(capture)?;
    let bytes = std::fs::read(skf).with_context(|| format!("reading {skf}"))?;
    let model = SkinNetModel::from_skf(&bytes).with_context(|| skf.clone())?;
    let joints = model.joint_count();
    if joints != capture.skeleton.len() {
        bail!(
            "{skf} has {joints} joints, the capture {}",
            capture.skeleton.len()
        );
    }
    let points = &capture.template.positions;
    let mesh = BoundMesh::bind(&model, points)?;
    // Vertices grouped by candidate list: one evaluation per group and pose.
    let mut groups: HashMap<Vec<u16>, Vec<usize>> = HashMap::new();
    for v in 0..points.len() {
        let Some(list) = mesh.candidates(v) else {
            bail!("{skf} has no candidate joints: every joint may move every vertex");
        };
        let list = list.iter().copied().filter(|&c| (c as usize) < joints);
        groups.entry(list.collect()).or_default().push(v);
    }
    let train = &capture.train_frames;
    let donors: Vec<usize> = (0..donors.max(1))
        .map(|k| train[k * train.len() / donors.max(1)])
        .collect();
    let mut base = vec![0.0f32; points.len() * joints];
    let (mut sum, mut count, mut largest) = (0.0f64, 0usize, 0.0f32);
    for &f in &capture.test_frames {
        let own = &capture.poses[f];
        model.weights_for(points, own, &mut base)?;
        for &d in &donors {
            for (list, members) in &groups {
                let mut mixed: Pose = capture.poses[d].clone();
                for &c in list {
                    mixed.locals[c as usize] = own.locals[c as usize];
                }
                let sub: Vec<_> = members.iter().map(|&v| points[v]).collect();
                let mut w = vec![0.0f32; sub.len() * joints];
                model.weights_for(&sub, &mixed, &mut w)?;
                for (row, &v) in w.chunks_exact(joints).zip(members) {
                    let change: f32 = row
                        .iter()
                        .zip(&base[v * joints..(v + 1) * joints])
                        .map(|(a, b)| (a - b).abs())
                        .sum();
                    sum += f64::from(change);
                    count += 1;
                    largest = largest.max(change);
                }
            }
        }
    }
    println!(
        "{skf}: Σ|Δw| from non-candidate joints, mean {:.4}, largest {:.3}, over {count} \
         (vertex, test frame, donor) of {} test frames and donors {donors:?}",
        sum / count.max(1) as f64,
        largest,
        capture.test_frames.len()
    );
    Ok(())
}
