//! Is the silhouette loss minimised by the truth? On a capture's *test* frames (the only ones with
//! ground-truth meshes), moves the ground-truth posed template along its vertex normals by
//! δ ∈ [−1, 1] px and prints the loss (both terms) and the mean force along the normal per
//! boundary vertex at each δ, the δ where the loss is smallest, and the loss of the initial
//! (bone-heat) posing for comparison. An unbiased loss is smallest at δ = 0 and exerts (almost) no
//! force there.
//!
//! `cargo run --release -p skinfield-trainer --example silhouette_bias -- CAPTURE_DIR [VERTICES]`
//! (`VERTICES`: simplify the template first, as training does; default: full resolution).

use anyhow::Context;
use glam::Vec3;
use skinfield_formats::capture::load_capture;
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_trainer::eval::{PreparedSkinning, Skinning};
use skinfield_trainer::losses::silhouette::{
    DEFAULT_HUBER_PX, SilhouetteTarget, normal_sweep, sweep_minimum,
};
use skinfield_trainer::train::data::simplify_template;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let dir = args
        .get(1)
        .context("usage: silhouette_bias CAPTURE [VERTICES]")?;
    let vertices: usize = args.get(2).map_or(Ok(0), |s| s.parse())?;
    let capture = load_capture(dir)?;
    let (template, source) = simplify_template(&capture.template, vertices);
    let initial = PreparedSkinning::new(&capture, &Skinning::Initial)?;
    let pick = |all: &[Vec3]| -> Vec<Vec3> { source.iter().map(|&i| all[i as usize]).collect() };
    // One pixel in metres at the subject: camera distance / focal length, averaged.
    let centre = capture.template.positions.iter().copied().sum::<Vec3>()
        / capture.template.vertex_count() as f32;
    let cams = &capture.rig.cameras;
    let px = cams
        .iter()
        .map(|c| (c.center() - centre).length() / c.fx)
        .sum::<f32>()
        / cams.len() as f32;
    let steps: Vec<f32> = (-8..=8).map(|k| k as f32 * 0.125).collect();
    let offsets: Vec<f32> = steps.iter().map(|s| s * px).collect();
    println!(
        "{} test frames × {} cameras, template {} vertices, 1 px ≈ {:.2} cm",
        capture.test_frames.len(),
        cams.len(),
        template.vertex_count(),
        100.0 * px
    );
    let mut sums = vec![(0.0f64, 0.0f64, 0.0f64); steps.len()];
    let mut initial_loss = 0.0;
    for &f in &capture.test_frames {
        let views: Vec<_> = cams
            .iter()
            .enumerate()
            .map(|(c, cam)| {
                let m = capture.load_mask(c, f)?;
                let t = SilhouetteTarget::from_coverage(
                    m.width as usize,
                    m.height as usize,
                    &m.coverage,
                )?;
                Ok((cam.clone(), t))
            })
            .collect::<anyhow::Result<_>>()?;
        let truth = pick(&capture.evaluation_gt_mesh(f)?);
        let normals = area_weighted_normals(&truth, &template.triangles);
        let sweep = normal_sweep(
            &views,
            &truth,
            &normals,
            &template.triangles,
            &offsets,
            DEFAULT_HUBER_PX,
        );
        for (s, p) in sums.iter_mut().zip(&sweep) {
            s.0 += p.boundary;
            s.1 += p.contour;
            s.2 += p.normal_force;
        }
        let init = pick(&initial.pose_frame(&capture, f)?);
        let inn = area_weighted_normals(&init, &template.triangles);
        let at_init = normal_sweep(
            &views,
            &init,
            &inn,
            &template.triangles,
            &[0.0],
            DEFAULT_HUBER_PX,
        );
        initial_loss += at_init[0].boundary + at_init[0].contour;
    }
    let n = capture.test_frames.len() as f64;
    println!("δ (px) | boundary | contour | total | mean |force · n| per boundary vertex");
    let mut mean = Vec::new();
    for (k, s) in steps.iter().zip(&sums) {
        println!(
            "{k:+6.3} | {:.4} | {:.4} | {:.4} | {:.3e}",
            s.0 / n,
            s.1 / n,
            (s.0 + s.1) / n,
            s.2 / n
        );
        mean.push(skinfield_trainer::losses::silhouette::SweepPoint {
            offset: *k,
            boundary: s.0 / n,
            contour: s.1 / n,
            normal_force: s.2 / n,
        });
    }
    match sweep_minimum(&mean) {
        Some(m) => println!("loss smallest at δ = {m:+.3} px"),
        None => println!("loss smallest at an end of the sweep"),
    }
    println!(
        "initial (bone-heat) posing: total {:.4} (truth {:.4})",
        initial_loss / n,
        (sums[8].0 + sums[8].1) / n
    );
    Ok(())
}
