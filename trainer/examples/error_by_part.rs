//! Where is a skinning wrong? Per-vertex distance to the ground truth over a capture's test
//! frames (same template, so vertex to vertex), split by the template's part labels (skin,
//! clothing), with the share of vertices beyond 2 cm. Complements `trainer eval`, whose
//! surface Chamfer says how much but not where.
//!
//! `cargo run -p skinfield-trainer --example error_by_part -- CAPTURE_DIR SKINNING...`
//! (skinnings as in `trainer eval --weights`: `initial`, `static:FILE`, `skf:FILE`, `oracle`).

use anyhow::Context;
use skinfield_formats::PartLabel;
use skinfield_formats::capture::load_capture;
use skinfield_trainer::eval::{PreparedSkinning, Skinning};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = args
        .next()
        .context("usage: error_by_part CAPTURE_DIR SKINNING...")?;
    let capture = load_capture(std::path::Path::new(&dir))?;
    let labels = capture
        .template
        .part_labels
        .clone()
        .unwrap_or_else(|| vec![PartLabel::Skin; capture.template.vertex_count()]);
    println!(
        "{:<12} {:>12} {:>12} {:>14} {:>14}",
        "method", "skin (cm)", "cloth (cm)", "skin > 2 cm", "cloth > 2 cm"
    );
    for spec in args {
        let skinning: Skinning = spec.parse().map_err(|e| anyhow::anyhow!("{e}"))?;
        let prepared = PreparedSkinning::new(&capture, &skinning)?;
        // [sum of distances, count, count beyond 2 cm] per label.
        let mut acc = [[0.0f64; 3]; 2];
        for &frame in &capture.test_frames {
            let truth = capture.evaluation_gt_mesh(frame)?;
            let posed = prepared.pose_frame(&capture, frame)?;
            for ((p, t), label) in posed.iter().zip(&truth).zip(&labels) {
                let d = f64::from((*p - *t).length()) * 100.0;
                let a = &mut acc[*label as usize];
                a[0] += d;
                a[1] += 1.0;
                a[2] += f64::from(u8::from(d > 2.0));
            }
        }
        let mean = |a: [f64; 3]| a[0] / a[1].max(1.0);
        let share = |a: [f64; 3]| 100.0 * a[2] / a[1].max(1.0);
        println!(
            "{:<12} {:>12.3} {:>12.3} {:>13.1}% {:>13.1}%",
            prepared.method(),
            mean(acc[0]),
            mean(acc[1]),
            share(acc[0]),
            share(acc[1])
        );
    }
    Ok(())
}
