//! The silhouette loss on the built-in capture is minimised by the truth: the ground-truth posed
//! template of the test frames, moved along its vertex normals by δ, has its smallest loss at
//! δ = 0 (within 0.1 px), and there the force along the normal on each boundary vertex is small
//! (mean of absolute values, so opposite pulls cannot cancel). Bone-heat posing scores worse.

use glam::Vec3;
use skinfield_formats::capture::load_capture;
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_trainer::eval::{PreparedSkinning, Skinning};
use skinfield_trainer::losses::silhouette::{
    DEFAULT_HUBER_PX, SilhouetteTarget, normal_sweep, sweep_minimum,
};
use skinfield_trainer::synth::{SynthConfig, synthesize};
use skinfield_trainer::train::data::simplify_template;

#[test]
fn the_ground_truth_minimises_the_silhouette_loss_on_the_built_in_capture() {
    let dir = tempfile::tempdir().unwrap();
    // The default character, cameras and image size; fewer frames and cameras to stay quick.
    let config = SynthConfig {
        train_frames_per_clip: 1,
        test_frames_per_clip: 1,
        cameras: 4,
        ..SynthConfig::default()
    };
    synthesize(dir.path(), &config).unwrap();
    let capture = load_capture(dir.path()).unwrap();
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
    let initial = PreparedSkinning::new(&capture, &Skinning::Initial).unwrap();
    // The full template and the 2,500-vertex training template.
    for vertices in [0, 2500] {
        let (template, source) = simplify_template(&capture.template, vertices);
        let pick =
            |all: &[Vec3]| -> Vec<Vec3> { source.iter().map(|&i| all[i as usize]).collect() };
        let mut mean = vec![(0.0f64, 0.0f64, 0.0f64); steps.len()];
        let (mut truth_loss, mut initial_loss) = (0.0, 0.0);
        for &f in &capture.test_frames {
            let views: Vec<_> = cams
                .iter()
                .enumerate()
                .map(|(c, cam)| {
                    let m = capture.load_mask(c, f).unwrap();
                    let t = SilhouetteTarget::from_coverage(
                        m.width as usize,
                        m.height as usize,
                        &m.coverage,
                    )
                    .unwrap();
                    (cam.clone(), t)
                })
                .collect();
            let truth = pick(&capture.evaluation_gt_mesh(f).unwrap());
            let normals = area_weighted_normals(&truth, &template.triangles);
            let sweep = normal_sweep(
                &views,
                &truth,
                &normals,
                &template.triangles,
                &offsets,
                DEFAULT_HUBER_PX,
            );
            for (m, p) in mean.iter_mut().zip(&sweep) {
                m.0 += p.boundary;
                m.1 += p.contour;
                m.2 += p.normal_force;
            }
            truth_loss += sweep[8].boundary + sweep[8].contour;
            let init = pick(&initial.pose_frame(&capture, f).unwrap());
            let inn = area_weighted_normals(&init, &template.triangles);
            let at = normal_sweep(
                &views,
                &init,
                &inn,
                &template.triangles,
                &[0.0],
                DEFAULT_HUBER_PX,
            );
            initial_loss += at[0].boundary + at[0].contour;
        }
        let points: Vec<_> = steps
            .iter()
            .zip(&mean)
            .map(
                |(&s, m)| skinfield_trainer::losses::silhouette::SweepPoint {
                    offset: s,
                    boundary: m.0,
                    contour: m.1,
                    normal_force: m.2,
                },
            )
            .collect();
        let minimum = sweep_minimum(&points).expect("minimum inside the sweep");
        assert!(
            minimum.abs() < 0.1,
            "{vertices}: the loss is smallest {minimum:+.3} px off the truth"
        );
        let (force_truth, force_half) = (points[8].normal_force, points[12].normal_force);
        assert!(
            force_truth < 0.3 * force_half,
            "{vertices}: mean |force · n| per boundary vertex {force_truth:.3e} at the truth, \
             {force_half:.3e} half a pixel out"
        );
        assert!(
            initial_loss > 2.0 * truth_loss,
            "{vertices}: bone heat {initial_loss:.4} vs truth {truth_loss:.4}"
        );
    }
}
