//! `trainer pose` on CesiumMan's walk against an independent glTF skinning reference written
//! straight on the gltf crate (`formats/tests/gltf_reference`: its own buffer loading, node TRS
//! sampled in f64, joint world × inverse bind, every JOINTS_n/WEIGHTS_n set), plus the
//! `--model` and `--dqs` paths and bad input.

use std::path::Path;
use std::process::Command;

use glam::{DMat4, DVec3, Mat4};
use skinfield_formats::shared_data::shared_data_dir;

// The independent glTF skinning reference shared with the formats crate's asset tests (it shares
// no code with `skinfield_formats::gltf_io` or the runtime).
#[path = "../../formats/tests/gltf_reference/mod.rs"]
mod gltf_reference;
use gltf_reference::Reference;

fn trainer(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .arg("pose")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stderr).unwrap(),
    )
}

fn read_frames(path: &Path) -> Vec<(f64, Vec<DVec3>)> {
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    v["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let pos = f["positions"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| {
                    DVec3::new(
                        p[0].as_f64().unwrap(),
                        p[1].as_f64().unwrap(),
                        p[2].as_f64().unwrap(),
                    )
                })
                .collect();
            (f["time"].as_f64().unwrap(), pos)
        })
        .collect()
}

#[test]
fn cesium_man_walk_matches_the_gltf_reference() {
    let Some(dir) = shared_data_dir() else { return };
    let asset = dir.join("khronos-cesiumman/CesiumMan.glb");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("pose.json");
    let (code, err) = trainer(&[
        "--asset",
        asset.to_str().unwrap(),
        "--clip",
        "0",
        "--times",
        "0,0.37,1.0,1.5,100",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let frames = read_frames(&out);
    assert_eq!(frames.len(), 5);
    let r = Reference::open(&asset);
    let mut moved = 0.0f64;
    for (t, got) in &frames {
        let want = r.skinned(0, &r.worlds(&r.locals(&[0], *t)));
        assert_eq!(got.len(), want.len());
        assert_eq!(got.len(), 3273, "CesiumMan has 3273 vertices");
        let worst = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        assert!(worst < 1e-4, "t = {t}: worst vertex off by {worst} m");
        moved = moved.max(
            got.iter()
                .zip(&frames[0].1)
                .map(|(a, b)| (*a - *b).length())
                .fold(0.0, f64::max),
        );
    }
    // The walk moves the mesh (the comparison is not between rest poses), and a time past the
    // end holds the last key.
    assert!(moved > 0.05, "{moved}");
    let end = r.skinned(0, &r.worlds(&r.locals(&[0], 1e9)));
    assert!(
        frames[4]
            .1
            .iter()
            .zip(&end)
            .all(|(a, b)| (*a - *b).length() < 1e-4)
    );

    // DQS: same vertex count, close to LBS for this mildly twisting walk, but not identical.
    let out_dqs = tmp.path().join("dqs.json");
    let (code, err) = trainer(&[
        "--asset",
        asset.to_str().unwrap(),
        "--clip",
        "0",
        "--times",
        "0.37",
        "--dqs",
        "--out",
        out_dqs.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let dqs = read_frames(&out_dqs);
    let d = dqs[0]
        .1
        .iter()
        .zip(&frames[1].1)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    assert!(d > 1e-6 && d < 0.05, "DQS vs LBS max difference {d}");
}

#[test]
fn model_weights_drive_the_matching_skin() {
    use skinfield_formats::gltf_io::load_gltf;
    use skinfield_formats::skf::{ModelConfig, Net, SkfModel, write_atomic};
    let Some(dir) = shared_data_dir() else { return };
    let asset = dir.join("khronos-cesiumman/CesiumMan.glb");
    let doc = load_gltf(&asset).unwrap();
    let skin = &doc.skins[0];
    let bb = skinfield_formats::Aabb::from_points(&skin.template.positions).unwrap();
    let j = skin.skeleton.len();
    let mut config =
        ModelConfig::paper_architecture(j as u32, bb.min.to_array(), bb.max.to_array());
    config.hidden_count = 2;
    config.hidden = [16, 16, 0, 0, 0, 0, 0, 0];
    config.skip_layer = 1;
    let mut m = SkfModel {
        config,
        skeleton: skin.skeleton.clone(),
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    let shapes: Vec<_> = config.layer_shapes(Net::Skin).collect();
    for (i, (o, k)) in shapes.into_iter().enumerate() {
        // Deterministic, varied weights.
        let w = (0..o * k)
            .map(|x| (((x * 7919 + i * 31) % 200) as f32 - 100.0) / (100.0 * (k as f32).sqrt()))
            .collect();
        m.push_layer(Net::Skin, i, w, o, k, vec![0.0; o]);
    }
    let bytes = m.to_bytes().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let model_path = tmp.path().join("m.skf");
    write_atomic(&model_path, &bytes).unwrap();
    let out = tmp.path().join("pose.json");
    let (code, err) = trainer(&[
        "--asset",
        asset.to_str().unwrap(),
        "--clip",
        "0",
        "--times",
        "0.6",
        "--model",
        model_path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let got = &read_frames(&out)[0].1;
    // Reference: the reference's joint matrices, blended with the runtime's SkinNet weights
    // (checked against an f64 forward pass in the runtime's own tests) in f64. The glTF skin's
    // joint list and the importer's skeleton order can differ: map through joint names.
    let r = Reference::open(&asset);
    let worlds = r.worlds(&r.locals(&[0], 0.6));
    let gskin = r.doc.skins().next().unwrap();
    let data = |b: gltf::Buffer<'_>| Some(&r.buffers[b.index()].0[..]);
    let ibm: Vec<DMat4> = gskin
        .reader(data)
        .read_inverse_bind_matrices()
        .unwrap()
        .map(|m| Mat4::from_cols_array_2d(&m).as_dmat4())
        .collect();
    let by_name: std::collections::HashMap<String, DMat4> = gskin
        .joints()
        .zip(&ibm)
        .map(|(n, b)| {
            (
                n.name()
                    .map_or(format!("node_{}", n.index()), str::to_string),
                worlds[n.index()] * *b,
            )
        })
        .collect();
    let pose = skinfield_formats::gltf_io::Clip::sample(&doc.clips[0], skin, 0.6);
    let w =
        skinfield_runtime::SkinNetModel::weights_for_skf(&bytes, &skin.template.positions, &pose)
            .unwrap();
    let mut worst = 0.0f64;
    for (v, p) in skin.template.positions.iter().enumerate() {
        let mut x = DVec3::ZERO;
        for (k, name) in skin.skeleton.names().iter().enumerate() {
            if let Some(m) = by_name.get(name) {
                x += f64::from(w[v * j + k]) * m.transform_point3(p.as_dvec3());
            }
        }
        worst = worst.max((x - got[v]).length());
    }
    assert!(worst < 1e-3, "worst {worst}");
}

#[test]
fn bad_input_is_one_line_naming_the_field() {
    let Some(dir) = shared_data_dir() else { return };
    let asset = dir.join("khronos-cesiumman/CesiumMan.glb");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("x.json");
    let (code, err) = trainer(&[
        "--asset",
        asset.to_str().unwrap(),
        "--clip",
        "nope",
        "--times",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("--clip") && err.contains("nope"), "{err}");
    let (code, err) = trainer(&[
        "--asset",
        asset.to_str().unwrap(),
        "--clip",
        "0",
        "--times",
        "0,NaN",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("--times"), "{err}");
    let (code, err) = trainer(&[
        "--asset",
        "/nonexistent.glb",
        "--clip",
        "0",
        "--times",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("nonexistent.glb"), "{err}");
    assert!(!out.exists());
}
