//! `trainer heat` on CesiumMan: the written glTF reads back with the same mesh and skeleton and
//! the bone-heat weights; the JSON lists them per file vertex; bad input exits 1 naming the file.

use std::process::Command;

use skinfield_formats::gltf_io::load_gltf;
use skinfield_formats::shared_data::shared_data_dir;
use skinfield_trainer::heat::{HeatOptions, bone_heat};

#[test]
fn reweights_cesiumman_and_writes_gltf_and_json() {
    let Some(dir) = shared_data_dir() else { return };
    let asset = dir.join("khronos-cesiumman/CesiumMan.glb");
    let tmp = tempfile::tempdir().unwrap();
    let (out, json) = (tmp.path().join("heat.glb"), tmp.path().join("heat.json"));
    let status = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(["heat", "--asset"])
        .arg(&asset)
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));

    let source = load_gltf(&asset).unwrap();
    let skin = source.largest_skin().unwrap();
    let expected = bone_heat(&skin.template, &skin.skeleton, &HeatOptions::default()).unwrap().skin;
    let written = load_gltf(&out).unwrap();
    let back = written.largest_skin().unwrap();
    assert_eq!(back.template.vertex_count(), skin.template.vertex_count());
    assert_eq!(back.skeleton.names(), skin.skeleton.names());
    // glTF keeps at most 4 influences per vertex set; compare the dominant joint per vertex.
    let n = skin.template.vertex_count();
    let dominant = |s: &skinfield_formats::StaticSkin, v: usize| {
        let (j, w) = s.influences(v);
        j.iter().zip(w).max_by(|a, b| a.1.total_cmp(b.1)).map(|(j, _)| *j).unwrap()
    };
    let same = (0..n).filter(|&v| dominant(&back.skin, v) == dominant(&expected, v)).count();
    assert!(same * 100 >= n * 99, "{same} of {n}");

    let value: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(value["joints"].as_array().unwrap().len(), skin.skeleton.len());
    let weights = value["weights"].as_array().unwrap();
    assert_eq!(weights.len(), n);
    for (v, row) in weights.iter().enumerate() {
        let (j, w) = expected.influences(v);
        let row = row.as_array().unwrap();
        assert_eq!(row.len(), j.len());
        for ((pair, j), w) in row.iter().zip(j).zip(w) {
            assert_eq!(pair[0].as_u64().unwrap(), u64::from(*j));
            assert!((pair[1].as_f64().unwrap() - f64::from(*w)).abs() < 1e-6);
        }
    }

    let bad = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(["heat", "--asset", "/nonexistent/x.glb", "--out"])
        .arg(tmp.path().join("y.glb"))
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("x.glb"));
}
