use glam::Vec3;

use super::*;
use crate::skinnet::position_inputs_tensor;
use crate::train::tests::{config, scene, scene_with_queries, tube_posed};
use crate::train::{TrainConfig, TrainData};

/// Albedo of the tube: bands along its length and around it (smooth, so images have gradients).
fn albedo(p: Vec3) -> Vec3 {
    Vec3::new(
        0.5 + 0.3 * (9.0 * p.y).sin(),
        0.5 + 0.3 * (2.0 * p.z.atan2(p.x)).cos(),
        0.4,
    )
}

/// Images of the tube posed with the *truth* weights (as in `scene`), coloured by `texture`
/// of the canonical point seen at each pixel; grey background.
fn images(data: &TrainData, truth: &[f32], texture: impl Fn(Vec3) -> Vec3) -> Vec<Vec<RgbTarget>> {
    let t = &data.template;
    data.frames
        .iter()
        .map(|f| {
            let posed = tube_posed(&t.positions, &f.skinning, truth);
            f.views
                .iter()
                .map(|v| {
                    let frags = rasterize(&v.camera, &posed, &t.triangles);
                    let canon = frags.interpolate(&t.triangles, &t.positions);
                    let rgb: Vec<Vec3> = canon
                        .iter()
                        .map(|c| c.map_or(Vec3::splat(0.5), &texture))
                        .collect();
                    RgbTarget::new(v.camera.width as usize, v.camera.height as usize, &rgb).unwrap()
                })
                .collect()
        })
        .collect()
}

fn stage_config(albedo: u64, shadow: u64, refine: u64) -> TrainConfig {
    TrainConfig {
        // A constant rate: the resume tests stop runs by giving them fewer iterations, which
        // would otherwise change the cosine schedule of the iterations that remain.
        lr_final_fraction: 1.0,
        stages: StageConfig {
            albedo_iterations: albedo,
            shadow_iterations: shadow,
            refine_iterations: refine,
            pixels_per_view: 200,
            appearance_lr: 3e-3,
            ..StageConfig::default()
        },
        ..config()
    }
}

fn rows(dir: &Path, stage: &str) -> Vec<(f64, f64)> {
    std::fs::read_to_string(dir.join("stages.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .filter(|l| l.starts_with(stage))
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            (v[2], v[3])
        })
        .collect()
}

/// With full-resolution query cells SkinNet is queried elsewhere, but the appearance nets
/// colour the training vertices the rendering loss rasterises: they read the training
/// template's own encoded positions.
#[test]
fn appearance_reads_the_training_vertices_with_query_cells() {
    let (data, _) = scene_with_queries(1);
    let t = Trainer::new(data.clone(), config(), false).unwrap();
    let config = t.net().unwrap().config();
    let expected = position_inputs_tensor(config, &data.template.positions, &Device::Cpu).unwrap();
    assert_eq!(
        t.encoded().unwrap().to_vec2::<f32>().unwrap(),
        expected.to_vec2::<f32>().unwrap()
    );
}

#[test]
fn albedo_stage_learns_the_texture_and_runs_are_deterministic() {
    let (data, truth) = scene(3);
    let imgs = images(&data, &truth, albedo);
    let dir = tempfile::tempdir().unwrap();
    let mut a = Trainer::new(data.clone(), stage_config(40, 0, 0), false).unwrap();
    a.run(&dir.path().join("a"), false).unwrap();
    let app = a
        .run_stages(imgs.clone(), &dir.path().join("a"), false)
        .unwrap();
    let r = rows(&dir.path().join("a"), "2,");
    assert_eq!(r.len(), 40);
    let first: f64 = r[..5].iter().map(|x| x.0).sum::<f64>() / 5.0;
    let last: f64 = r[35..].iter().map(|x| x.0).sum::<f64>() / 5.0;
    assert!(last < 0.5 * first, "L_rend {first} → {last}");
    // The learned albedo approaches the texture on the template (independent of the images).
    let t = &a.data.template;
    let enc = position_inputs_tensor(app.config(), &t.positions, &Device::Cpu).unwrap();
    let learned = app.albedo(&enc).unwrap().to_vec2::<f32>().unwrap();
    let err = |f: &dyn Fn(Vec3) -> Vec3| {
        t.positions
            .iter()
            .zip(&learned)
            .map(|(&p, l)| (Vec3::from_slice(l) - f(p)).abs().element_sum())
            .sum::<f32>()
            / t.positions.len() as f32
    };
    assert!(
        err(&albedo) < 0.6 * err(&|_| Vec3::ZERO),
        "{} vs {}",
        err(&albedo),
        err(&|_| Vec3::ZERO)
    );
    // SkinNet was frozen.
    let mut b = Trainer::new(data, stage_config(40, 0, 0), false).unwrap();
    b.run(&dir.path().join("b"), false).unwrap();
    assert_eq!(
        a.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap(),
        b.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap()
    );
    b.run_stages(imgs, &dir.path().join("b"), false).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.path().join("a/stages.csv")).unwrap(),
        std::fs::read_to_string(dir.path().join("b/stages.csv")).unwrap()
    );
}

#[test]
fn shadow_and_refine_stages_run_and_refine_moves_skinnet_with_the_rendering_term() {
    let (data, truth) = scene(3);
    let imgs = images(&data, &truth, albedo);
    let dir = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(data, stage_config(5, 5, 3), false).unwrap();
    t.run(dir.path(), false).unwrap();
    let before = t.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap();
    let stage1 = std::fs::read_to_string(dir.path().join("profile.csv")).unwrap();
    t.run_stages(imgs, dir.path(), false).unwrap();
    assert_eq!(rows(dir.path(), "3,").len(), 5);
    let refine = rows(dir.path(), "4,");
    assert_eq!(refine.len(), 3);
    // profile.csv is rewritten after stage 4 with its iterations timed apart from stage 1's.
    let image_rows = |csv: &str| -> Vec<String> {
        csv.lines()
            .filter(|l| l.starts_with("image,"))
            .map(|l| l.rsplit_once(',').map_or("", |(k, _)| k).to_owned())
            .collect()
    };
    let profile = std::fs::read_to_string(dir.path().join("profile.csv")).unwrap();
    assert!(stage1.contains("refine,0,total,"), "{stage1}");
    assert!(profile.contains("refine,3,total,"), "{profile}");
    assert_eq!(image_rows(&profile), image_rows(&stage1), "{profile}");
    for &(l, total) in &refine {
        assert!(l > 0.0 && l.is_finite());
        // The step's total includes λ_rend · L_rend.
        assert!(
            total >= t.config.stages.rendering_weight * l,
            "{total} < λ·{l}"
        );
    }
    assert_ne!(
        before,
        t.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap()
    );
    assert!(t.rendering.is_none());
    assert_eq!(t.progress().1, 4 + 3);
}

#[test]
fn fixed_colours_come_from_the_images_and_mismatched_images_are_rejected() {
    let (data, truth) = scene(2);
    let dir = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(data.clone(), stage_config(1, 0, 0), false).unwrap();
    t.run(dir.path(), false).unwrap();
    // An image linear in x: a vertex seen by the camera gets about the colour at its own
    // projection (a barycentric mean of the pixels around it); unseen ones get the mean.
    let camera = &data.frames[0].views[0].camera;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let ramp = |x: f32| 0.2 + 0.6 * x / w as f32;
    let rgb: Vec<Vec3> = (0..w * h)
        .map(|i| Vec3::splat(ramp((i % w) as f32 + 0.5)))
        .collect();
    let imgs = vec![vec![RgbTarget::new(w, h, &rgb).unwrap()]; data.frames.len()];
    let colours = t.canonical_vertex_colours(&imgs).unwrap();
    let posed = t
        .posed(&[0])
        .unwrap()
        .get(0)
        .unwrap()
        .to_vec2::<f32>()
        .unwrap();
    let near = colours
        .iter()
        .zip(&posed)
        .filter(|(c, p)| {
            let u = camera.project(Vec3::from_slice(p)).unwrap().x;
            (c.x - ramp(u)).abs() < 0.03 && c.x == c.y && c.y == c.z
        })
        .count();
    assert!(near > colours.len() * 2 / 5, "{near} of {}", colours.len());
    assert!(colours.iter().all(|c| c.x >= 0.2 && c.x <= 0.8));
    let mut short = images(&data, &truth, albedo);
    short.pop();
    assert!(matches!(
        t.run_stages(short, dir.path(), false),
        Err(TrainError::Data(_))
    ));
    // Stage 4 without the rendering term reads no image: none need be given.
    let mut config = stage_config(0, 0, 2);
    config.stages.rendering_weight = 0.0;
    assert!(!config.stages.renders() && stage_config(1, 0, 0).stages.renders());
    let mut u = Trainer::new(data, config, false).unwrap();
    u.run(&dir.path().join("u"), false).unwrap();
    u.run_stages(Vec::new(), &dir.path().join("u"), false)
        .unwrap();
    assert_eq!(rows(&dir.path().join("u"), "4,").len(), 2);
}

/// With `template_albedo` the template's vertex colours are the albedo: stage 2 is skipped,
/// ShadowNet (stage 3) and stage 4 shade those colours, and a template without colours is a
/// typed error naming the setting. Images that are red everywhere are explained by a red
/// template (shading starts near 1) far better than by a grey one. (Red everywhere, background
/// included, because the short stage 1 here leaves the tube's pose off the truth: a texture or
/// an outline would be compared misaligned.)
#[test]
fn template_albedo_colours_the_mesh_with_the_templates_own_colours() {
    let red = Vec3::new(0.9, 0.2, 0.1);
    let (mut data, _) = scene(3);
    let imgs: Vec<Vec<RgbTarget>> = data
        .frames
        .iter()
        .map(|f| {
            f.views
                .iter()
                .map(|v| {
                    let (w, h) = (v.camera.width as usize, v.camera.height as usize);
                    RgbTarget::new(w, h, &vec![red; w * h]).unwrap()
                })
                .collect()
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let run = |data: &TrainData, name: &str| {
        let mut config = stage_config(5, 6, 2);
        config.stages.colours = ColourSource::TemplateAlbedo;
        let mut t = Trainer::new(data.clone(), config, false).unwrap();
        t.run(&dir.path().join(name), false).unwrap();
        t.run_stages(imgs.clone(), &dir.path().join(name), false)
            .map(|_| ())
    };
    data.template.colors = None;
    match run(&data, "none") {
        Err(TrainError::Data(m)) => assert!(m.contains("template_albedo"), "{m}"),
        other => panic!("{other:?}"),
    }
    let n = data.template.vertex_count();
    data.template.colors = Some(vec![red; n]);
    run(&data, "red").unwrap();
    let red_dir = dir.path().join("red");
    assert!(rows(&red_dir, "2,").is_empty());
    assert_eq!(rows(&red_dir, "4,").len(), 2);
    data.template.colors = Some(vec![Vec3::splat(0.5); n]);
    run(&data, "grey").unwrap();
    let mean = |name: &str| {
        let r = rows(&dir.path().join(name), "3,");
        assert_eq!(r.len(), 6, "{name}");
        r.iter().map(|x| x.0).sum::<f64>() / r.len() as f64
    };
    let (with_red, with_grey) = (mean("red"), mean("grey"));
    assert!(
        with_red < 0.5 * with_grey,
        "L_rend {with_red} with the true colour, {with_grey} with grey"
    );
}

/// `load_images` reads every training frame; with frames held out for validation the stages
/// take the images of the frames they train on.
#[test]
fn stages_run_with_frames_held_out_for_validation() {
    let (data, truth) = scene(8);
    let imgs = images(&data, &truth, albedo);
    let dir = tempfile::tempdir().unwrap();
    let config = TrainConfig {
        validation_frames: 2,
        validation_every: 2,
        ..stage_config(3, 0, 2)
    };
    let mut t = Trainer::new(data, config, false).unwrap();
    t.run(dir.path(), false).unwrap();
    let mut short = imgs.clone();
    short.pop();
    assert!(matches!(
        t.run_stages(short, dir.path(), false),
        Err(TrainError::Data(_))
    ));
    t.run_stages(imgs, dir.path(), false).unwrap();
    assert_eq!(rows(dir.path(), "2,").len(), 3);
    assert_eq!(rows(dir.path(), "4,").len(), 2);
}

#[test]
fn stage_config_reads_from_json_and_names_bad_fields() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.json");
    std::fs::write(
        &p,
        r#"{"stages": {"albedo_iterations": 5, "colours": "albedo_only",
             "image_blur_px": 1.5}}"#,
    )
    .unwrap();
    let c = TrainConfig::load(&p).unwrap();
    assert_eq!(c.stages.albedo_iterations, 5);
    assert_eq!(c.stages.colours, ColourSource::AlbedoOnly);
    assert_eq!(c.stages.image_blur_px, 1.5);
    for bad in ["-1", "1e9"] {
        std::fs::write(&p, format!(r#"{{"stages": {{"image_blur_px": {bad}}}}}"#)).unwrap();
        assert!(matches!(
            TrainConfig::load(&p),
            Err(crate::train::ConfigError::Field {
                field: "stages.image_blur_px",
                ..
            })
        ));
    }
    assert!(c.stages.any());
    // The default runs stage 4 alone, at full resolution, without rendering anything.
    let d = TrainConfig::default().stages;
    assert!(d.any() && d.full_resolution && !d.renders());
    assert_eq!(
        d.refine_summary().as_deref(),
        Some("100 stage-4 iterations at full resolution")
    );
    assert_eq!(StageConfig::default().refine_summary(), None);
    for (json, bad) in [
        (
            r#"{"stages": {"rendering_weight": -1}}"#,
            "stages.rendering_weight",
        ),
        (
            r#"{"stages": {"refine_lr_fraction": 0}}"#,
            "stages.refine_lr_fraction",
        ),
        (
            r#"{"stages": {"refine_lr_fraction": -0.5}}"#,
            "stages.refine_lr_fraction",
        ),
    ] {
        std::fs::write(&p, json).unwrap();
        assert!(
            matches!(
                TrainConfig::load(&p),
                Err(crate::train::ConfigError::Field { field, .. }) if field == bad
            ),
            "{json}"
        );
    }
    std::fs::write(&p, r#"{"stages": {"refine_lr_fraction": 0.25}}"#).unwrap();
    assert_eq!(
        TrainConfig::load(&p).unwrap().stages.refine_lr_fraction,
        0.25
    );
}

/// `load_images` returns the capture's images as they are without blur, and with blur changes
/// only the masked pixels, towards their masked neighbours ([`blur_within_mask`]).
#[test]
fn loaded_images_are_blurred_inside_their_masks_only() {
    use skinfield_formats::capture::load_capture;
    let dir = tempfile::tempdir().unwrap();
    crate::synth::synthesize(dir.path(), &crate::synth::SynthConfig::tiny()).unwrap();
    let capture = load_capture(dir.path()).unwrap();
    let options = DataOptions {
        train_vertices: 0,
        cameras: 1,
    };
    let sharp = load_images(&capture, &options, 0.0).unwrap();
    let soft = load_images(&capture, &options, 1.5).unwrap();
    assert_eq!(sharp.len(), capture.train_frames.len());
    assert!(sharp.iter().chain(&soft).all(|views| views.len() == 1));
    let (f, img) = (
        capture.train_frames[0],
        capture.load_image(0, capture.train_frames[0]).unwrap(),
    );
    let mask = capture.load_mask(0, f).unwrap();
    let (w, h) = (img.width as usize, img.height as usize);
    let expected = blur_within_mask(w, h, &img.rgb, &mask.inside, 1.5).unwrap();
    let uv: Vec<f32> = (0..w * h)
        .flat_map(|p| [(p % w) as f32 + 0.5, (p / w) as f32 + 0.5])
        .collect();
    let uv = Tensor::from_vec(uv, (w * h, 2), &Device::Cpu).unwrap();
    let read = |t: &RgbTarget| t.sample(&uv).unwrap().to_vec2::<f32>().unwrap();
    let (a, b) = (read(&sharp[0][0]), read(&soft[0][0]));
    let mut changed = 0;
    for p in 0..w * h {
        assert!((Vec3::from_slice(&a[p]) - img.rgb[p]).length() < 1e-6);
        assert!((Vec3::from_slice(&b[p]) - expected[p]).length() < 1e-6);
        if mask.inside[p] {
            changed += usize::from(expected[p] != img.rgb[p]);
        } else {
            assert_eq!(expected[p], img.rgb[p]);
        }
    }
    assert!(changed > 0, "the blur changed no foreground pixel");
    // A mask of another size is a typed error naming the file, not read out of bounds.
    let path = capture.mask_path(0, f);
    skinfield_formats::capture::write_mask_png(&path, 3, 2, &[1.0; 6]).unwrap();
    match load_images(&capture, &options, 1.5) {
        Err(e @ DataError::Capture(_)) => {
            let m = e.to_string();
            assert!(
                m.contains(&*path.to_string_lossy()) && m.contains("3×2"),
                "{m}"
            );
        }
        other => panic!("{other:?}"),
    }
    // Without blur the masks are not read.
    assert!(load_images(&capture, &options, 0.0).is_ok());
}

/// Runs stages 1–4 in `dir` with `stages` iterations, resuming whatever `dir` holds; returns
/// the trainer and its appearance.
fn run_to(
    data: &TrainData,
    imgs: &[Vec<RgbTarget>],
    dir: &Path,
    (albedo, shadow, refine): (u64, u64, u64),
    colours: ColourSource,
) -> (Trainer, Appearance) {
    let mut config = stage_config(albedo, shadow, refine);
    config.stages.colours = colours;
    config.checkpoint_every = 3;
    let mut t = Trainer::new(data.clone(), config, false).unwrap();
    let ckpt = dir.join("checkpoint.safetensors");
    if ckpt.exists() {
        t.resume(&ckpt).unwrap();
    }
    t.run(dir, false).unwrap();
    let app = t.resume_stages(imgs.to_vec(), dir, false).unwrap();
    (t, app)
}

/// A run stopped inside stage 2, inside stage 3 and inside stage 4 and resumed each time ends
/// exactly where an uninterrupted one does: same log, same SkinNet, same appearance.
#[test]
fn stages_resume_exactly_after_stops_in_each_stage() {
    let (data, truth) = scene(3);
    let imgs = images(&data, &truth, albedo);
    let dir = tempfile::tempdir().unwrap();
    let (a, a_app) = run_to(
        &data,
        &imgs,
        &dir.path().join("a"),
        (5, 5, 4),
        ColourSource::Field,
    );
    let b_dir = dir.path().join("b");
    for stop in [(2, 0, 0), (5, 4, 0), (5, 5, 2), (5, 5, 4)] {
        run_to(&data, &imgs, &b_dir, stop, ColourSource::Field);
    }
    let (b, b_app) = run_to(&data, &imgs, &b_dir, (5, 5, 4), ColourSource::Field);
    let log = |d: &Path| std::fs::read_to_string(d.join("stages.csv")).unwrap();
    assert_eq!(log(&dir.path().join("a")), log(&b_dir));
    assert_eq!(log(&b_dir).lines().count(), 1 + 5 + 5 + 4);
    assert_eq!(
        a.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap(),
        b.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap()
    );
    let enc = a.encoded().unwrap();
    assert_eq!(
        a_app.albedo(enc).unwrap().to_vec2::<f32>().unwrap(),
        b_app.albedo(enc).unwrap().to_vec2::<f32>().unwrap()
    );
    assert_eq!(b.progress().1, 4 + 4);
    // Without `resume_stages` the same folder starts stages 2–4 over.
    let mut c = Trainer::new(data.clone(), stage_config(1, 0, 0), false).unwrap();
    c.run(&dir.path().join("c"), false).unwrap();
    c.run_stages(imgs.clone(), &b_dir, false).unwrap();
    assert_eq!(log(&b_dir).lines().count(), 2);
}

/// Fixed vertex colours are part of the checkpoint: they were read through the SkinNet of stage
/// 4's first iteration, which a resumed stage 4 no longer has. The appearance iterations the
/// config asks for are skipped with fixed colours, and the resume knows it.
#[test]
fn fixed_colour_stage_resumes_exactly() {
    let (data, truth) = scene(3);
    let imgs = images(&data, &truth, albedo);
    let dir = tempfile::tempdir().unwrap();
    let fixed = ColourSource::FixedVertexColours;
    let (a, _) = run_to(&data, &imgs, &dir.path().join("a"), (3, 3, 4), fixed);
    run_to(&data, &imgs, &dir.path().join("b"), (3, 3, 1), fixed);
    let (b, _) = run_to(&data, &imgs, &dir.path().join("b"), (3, 3, 4), fixed);
    assert_eq!(
        a.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap(),
        b.weights(&[0, 1]).unwrap().to_vec3::<f32>().unwrap()
    );
}

/// A checkpoint that does not fit is a typed error naming the file: unreadable bytes, a stage
/// resumed after a later one started, and SkinNet progress that disagrees with stage 4's.
#[test]
fn unusable_stage_checkpoints_are_named_errors() {
    let (data, truth) = scene(3);
    let imgs = images(&data, &truth, albedo);
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("a");
    run_to(&data, &imgs, &d, (2, 2, 0), ColourSource::Field);
    let ckpt = d.join(checkpoint::STAGES_CHECKPOINT);
    let resume = |stages: (u64, u64, u64)| {
        let mut t = Trainer::new(
            data.clone(),
            stage_config(stages.0, stages.1, stages.2),
            false,
        )
        .unwrap();
        t.resume(&d.join("checkpoint.safetensors")).unwrap();
        t.resume_stages(imgs.clone(), &d, false)
    };
    // Stage 3 has started: stage 2 cannot grow.
    match resume((4, 2, 0)) {
        Err(TrainError::Checkpoint { path, reason }) => {
            assert_eq!(path, ckpt);
            assert!(reason.contains("stage 3 has started"), "{reason}");
        }
        other => panic!("{:?}", other.err()),
    }
    // Stage-4 progress that SkinNet's own progress in the file contradicts.
    let good = std::fs::read(&ckpt).unwrap();
    let mut tensors = candle_core::safetensors::load(&ckpt, &Device::Cpu).unwrap();
    tensors.insert(
        "stages.progress".into(),
        Tensor::new(&[2u32, 0, 2, 0, 1, 0], &Device::Cpu).unwrap(),
    );
    candle_core::safetensors::save(&tensors, &ckpt).unwrap();
    match resume((2, 2, 2)) {
        Err(TrainError::Checkpoint { reason, .. }) => {
            assert!(reason.contains("image iterations"), "{reason}")
        }
        other => panic!("{:?}", other.err()),
    }
    std::fs::write(&ckpt, &good[..good.len() / 2]).unwrap();
    assert!(matches!(
        resume((2, 2, 0)),
        Err(TrainError::Checkpoint { path, .. }) if path == ckpt
    ));
}
