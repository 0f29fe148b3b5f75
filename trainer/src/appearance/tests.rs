use candle_core::{Device, Tensor};
use glam::Vec3;
use skinfield_formats::skf::{ModelConfig, Net, SkfModel, SkfView};

use super::*;
use crate::skinnet::export::to_skf_model;
use crate::skinnet::{
    TrainableSkinNet, position_inputs, position_inputs_tensor, softplus::softplus_scalar,
};

fn small_config() -> ModelConfig {
    let mut c = ModelConfig::paper_architecture(3, [-1.0; 3], [1.0; 3]);
    c.pe_frequencies = 2;
    c.hidden_count = 3;
    c.hidden = [0; skinfield_formats::skf::MAX_HIDDEN_LAYERS];
    c.hidden[..3].copy_from_slice(&[16, 8, 16]);
    c.skip_layer = 1;
    c.softplus_beta = 10.0;
    c
}

fn points() -> Vec<Vec3> {
    (0..7)
        .map(|i| {
            let t = i as f32;
            Vec3::new((0.7 * t).sin(), (1.3 * t).cos(), 0.2 * t - 0.6) * 0.9
        })
        .collect()
}

/// Plain f64 reference of the MLP from the effective weights: `[h, input]` at the skip layer.
fn reference(net: &AppearanceNet, cfg: &ModelConfig, input: &[f64]) -> Vec<f64> {
    let n = net.layers().len() - 1;
    let mut h = input.to_vec();
    for (i, layer) in net.layers().iter().enumerate() {
        let w = layer.weight().unwrap().to_vec2::<f32>().unwrap();
        let b = layer.bias().to_vec1::<f32>().unwrap();
        if i == cfg.skip_layer as usize && i > 0 {
            h.extend_from_slice(input);
        }
        h = w
            .iter()
            .zip(&b)
            .map(|(row, &bias)| {
                let z = f64::from(bias)
                    + row
                        .iter()
                        .zip(&h)
                        .map(|(&a, &x)| f64::from(a) * x)
                        .sum::<f64>();
                if i < n {
                    softplus_scalar(z, f64::from(cfg.softplus_beta))
                } else {
                    z
                }
            })
            .collect();
    }
    h
}

#[test]
fn forward_matches_a_scalar_reference_and_shading_is_positive() {
    let cfg = small_config();
    let app = Appearance::seeded(cfg, 5, 1.0).unwrap();
    let pts = points();
    let enc = position_inputs_tensor(&cfg, &pts, &Device::Cpu).unwrap();
    let albedo = app.albedo(&enc).unwrap().to_vec2::<f32>().unwrap();
    let flat = position_inputs(&cfg, &pts);
    let w = cfg.position_width();
    for (k, row) in albedo.iter().enumerate() {
        let x: Vec<f64> = flat[k * w..(k + 1) * w]
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let r = reference(app.albedo_net(), &cfg, &x);
        for c in 0..3 {
            assert!(
                (f64::from(row[c]) - r[c]).abs() < 1e-4,
                "{} vs {}",
                row[c],
                r[c]
            );
        }
    }
    let pose: Vec<f32> = (0..cfg.pose_width())
        .map(|i| 0.1 * i as f32 - 0.3)
        .collect();
    let normals: Vec<Vec3> = pts.iter().map(|p| p.normalize()).collect();
    let dirs: Vec<Vec3> = pts
        .iter()
        .map(|p| (*p - Vec3::Z * 3.0).normalize())
        .collect();
    let input = shadow_input(&enc, &pose, &normals, &dirs).unwrap();
    let shading = app
        .shading(&input)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f32>()
        .unwrap();
    let rows = input.to_vec2::<f32>().unwrap();
    for (k, &s) in shading.iter().enumerate() {
        let x: Vec<f64> = rows[k].iter().map(|&v| f64::from(v)).collect();
        let r = reference(app.shadow_net(), &cfg, &x)[0].exp();
        assert!(
            s > 0.0 && (f64::from(s) - r).abs() < 1e-4 * r.max(1.0),
            "{s} vs {r}"
        );
    }
    let c = app
        .colours_clipped(&pts, &pose, &pts, &normals, Vec3::Z * 3.0)
        .unwrap();
    for v in c.albedo.iter().chain(&c.shading).chain(&c.colour) {
        assert!(v.min_element() >= 0.0 && v.max_element() <= 1.0);
    }
    assert!(shadow_input(&enc, &pose, &normals[1..], &dirs).is_err());
}

#[test]
fn skf_round_trip_keeps_the_outputs_and_missing_nets_are_named() {
    let cfg = small_config();
    let (net, _vars) = TrainableSkinNet::seeded(cfg, 1, 1.0).unwrap();
    let skel = crate::skinnet::tests::skeleton(cfg.joint_count as usize);
    let mut model: SkfModel = to_skf_model(&net, &skel).unwrap();
    let plain = model.to_bytes().unwrap();
    let app = Appearance::seeded(cfg, 2, 1.0).unwrap();
    app.push_to_skf(&mut model).unwrap();
    assert_eq!(
        model.config.nets,
        Net::Skin.bit() | Net::Albedo.bit() | Net::Shadow.bit()
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.skf");
    model.write(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let view = SkfView::parse(&bytes).unwrap();
    let back = Appearance::from_skf(&view, &path).unwrap();
    let pts = points();
    let enc = position_inputs_tensor(&cfg, &pts, &Device::Cpu).unwrap();
    let pose = vec![0.2; cfg.pose_width()];
    let normals = vec![Vec3::Y; pts.len()];
    let input = shadow_input(&enc, &pose, &normals, &normals).unwrap();
    let close = |a: &Tensor, b: &Tensor| {
        let (a, b) = (
            a.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
            b.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
        );
        let scale = a.iter().fold(0f32, |m, x| m.max(x.abs())).max(1.0);
        for (x, y) in a.iter().zip(&b) {
            // f16 storage: about 3 significant digits per weight.
            assert!((x - y).abs() < 2e-2 * scale, "{x} vs {y}");
        }
        assert!(
            a != b || a.is_empty(),
            "identical outputs: the file was not read"
        );
    };
    close(&app.albedo(&enc).unwrap(), &back.albedo(&enc).unwrap());
    close(
        &app.shading(&input).unwrap(),
        &back.shading(&input).unwrap(),
    );
    // SkinNet in the same file is untouched.
    assert_eq!(
        view.layer(Net::Skin, 0).unwrap().0.dims,
        SkfView::parse(&plain)
            .unwrap()
            .layer(Net::Skin, 0)
            .unwrap()
            .0
            .dims
    );
    let e = Appearance::from_skf(&SkfView::parse(&plain).unwrap(), &path).unwrap_err();
    assert!(
        matches!(e, AppearanceError::Missing { net: "albedo", .. }),
        "{e}"
    );
    assert!(e.to_string().contains("m.skf"), "{e}");
}
