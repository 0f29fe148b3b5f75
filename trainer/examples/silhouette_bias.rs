//! Is the silhouette loss minimised by the truth? On a capture's *test* frames (the only ones
//! with ground-truth meshes), compares the stage-1 silhouette terms of the ground-truth posed
//! training template with those of the initial (bone-heat) posing, and measures the loss's
//! gradient at the ground truth along the outward surface normal: an unbiased loss has a mean
//! normal force near zero there; a positive one means descent shrinks the silhouette.
//!
//! `cargo run -p skinfield-trainer --example silhouette_bias -- CAPTURE_DIR [TRAIN_VERTICES]`
//! (`SILHOUETTE_TERM=boundary|contour` differentiates one term of Eq. 10 alone).

use anyhow::Context;
use candle_core::{DType, Device, Tensor, Var};
use glam::Vec3;
use skinfield_formats::capture::load_capture;
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_trainer::eval::{PreparedSkinning, Skinning};
use skinfield_trainer::losses::projection::{in_front, project};
use skinfield_trainer::losses::silhouette::{SilhouetteTarget, silhouette_terms};
use skinfield_trainer::train::data::simplify_template;

struct Terms {
    boundary: f64,
    contour: f64,
    normal_force: f64,
}

fn terms(
    points: &[Vec3],
    normals: &[Vec3],
    triangles: &[[u32; 3]],
    views: &[(skinfield_formats::Camera, SilhouetteTarget)],
) -> anyhow::Result<Terms> {
    let flat: Vec<f32> = points.iter().flat_map(|p| p.to_array()).collect();
    let x = Var::from_tensor(&Tensor::from_vec(flat, (points.len(), 3), &Device::Cpu)?)?;
    let (mut b, mut c) = (Vec::new(), Vec::new());
    for (camera, target) in views {
        let uv = project(camera, x.as_tensor())?;
        let t = silhouette_terms(target, &uv, &in_front(camera, points), triangles)?;
        b.push((t.boundary / t.boundary_count.max(1) as f64)?);
        c.push((t.contour / t.contour_count.max(1) as f64)?);
    }
    let n = views.len() as f64;
    let sb = (Tensor::stack(&b, 0)?.sum_all()? / n)?;
    let sc = (Tensor::stack(&c, 0)?.sum_all()? / n)?;
    // `SILHOUETTE_TERM=boundary|contour` differentiates one term alone.
    let total = match std::env::var("SILHOUETTE_TERM").as_deref() {
        Ok("boundary") => sb.clone(),
        Ok("contour") => sc.clone(),
        _ => (&sb + &sc)?,
    };
    let grads = total.backward()?;
    let g = grads.get(&x).context("no gradient")?.to_vec2::<f32>()?;
    let (mut force, mut count) = (0.0f64, 0usize);
    for (gi, ni) in g.iter().zip(normals) {
        let gv = Vec3::new(gi[0], gi[1], gi[2]);
        if gv.length_squared() > 0.0 {
            force += f64::from(gv.dot(*ni));
            count += 1;
        }
    }
    Ok(Terms {
        boundary: f64::from(sb.to_dtype(DType::F32)?.to_vec0::<f32>()?),
        contour: f64::from(sc.to_dtype(DType::F32)?.to_vec0::<f32>()?),
        normal_force: force / count.max(1) as f64,
    })
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let dir = args
        .get(1)
        .context("usage: silhouette_bias CAPTURE [VERTICES]")?;
    let vertices: usize = args.get(2).map_or(Ok(2500), |s| s.parse())?;
    let capture = load_capture(dir)?;
    let (template, source) = simplify_template(&capture.template, vertices);
    let initial = PreparedSkinning::new(&capture, &Skinning::Initial)?;
    let pick = |all: &[Vec3]| -> Vec<Vec3> { source.iter().map(|&i| all[i as usize]).collect() };
    println!(
        "frame | initial boundary/contour px | truth boundary/contour px | truth normal force"
    );
    let mut sums = [0.0f64; 5];
    for &f in &capture.test_frames {
        let views: Vec<_> = capture
            .rig
            .cameras
            .iter()
            .enumerate()
            .map(|(c, cam)| {
                let m = capture.load_mask(c, f)?;
                let t =
                    SilhouetteTarget::from_mask(m.width as usize, m.height as usize, &m.inside)?;
                Ok((cam.clone(), t))
            })
            .collect::<anyhow::Result<_>>()?;
        let truth = pick(&capture.evaluation_gt_mesh(f)?);
        let init = pick(&initial.pose_frame(&capture, f)?);
        let tn = area_weighted_normals(&truth, &template.triangles);
        if f == capture.test_frames[0] {
            // Outward normals: positive mean n · (x − centroid).
            let c = truth.iter().copied().sum::<Vec3>() / truth.len() as f32;
            let out: f32 = truth.iter().zip(&tn).map(|(p, n)| n.dot(*p - c)).sum();
            println!(
                "normals point {}",
                if out > 0.0 { "outwards" } else { "inwards" }
            );
        }
        let inn = area_weighted_normals(&init, &template.triangles);
        let a = terms(&init, &inn, &template.triangles, &views)?;
        let b = terms(&truth, &tn, &template.triangles, &views)?;
        println!(
            "{f:5} | {:.3} / {:.3} | {:.3} / {:.3} | {:+.4e}",
            a.boundary, a.contour, b.boundary, b.contour, b.normal_force
        );
        for (s, v) in
            sums.iter_mut()
                .zip([a.boundary, a.contour, b.boundary, b.contour, b.normal_force])
        {
            *s += v;
        }
    }
    let n = capture.test_frames.len() as f64;
    println!(
        "mean  | {:.3} / {:.3} | {:.3} / {:.3} | {:+.4e}",
        sums[0] / n,
        sums[1] / n,
        sums[2] / n,
        sums[3] / n,
        sums[4] / n
    );
    Ok(())
}
