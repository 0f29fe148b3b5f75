//! `trainer inspect` on every shared glTF asset (counts from their SOURCE.md), on a `.skf`, and
//! on bad input (exit code 1, one stderr line naming the file).

use std::path::Path;
use std::process::Command;

use skinfield_formats::shared_data::shared_data_dir;

fn inspect(path: &Path) -> (i32, serde_json::Value, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .arg("inspect")
        .arg(path)
        .output()
        .unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    let json = serde_json::from_slice(&out.stdout).unwrap_or(serde_json::Value::Null);
    (out.status.code().unwrap_or(-1), json, stderr)
}

#[test]
fn every_shared_gltf_asset() {
    let Some(dir) = shared_data_dir() else { return };
    // file, kind, vertices, triangles, joints, skins, clips, unnormalised weights present
    let cases = [
        (
            "khronos-cesiumman/CesiumMan.glb",
            "glb",
            3273,
            4672,
            19,
            1,
            1,
            false,
        ),
        (
            "khronos-cesiumman/CesiumMan_legacy.glb",
            "glb",
            3273,
            4672,
            19,
            1,
            19,
            true,
        ),
        ("khronos-fox/Fox.glb", "glb", 1728, 576, 24, 1, 3, false),
        (
            "khronos-simpleskin/SimpleSkin.gltf",
            "gltf",
            10,
            8,
            2,
            1,
            1,
            false,
        ),
        (
            "threejs-robotexpressive/RobotExpressive.glb",
            "glb",
            7214,
            3237,
            43,
            2,
            14,
            true,
        ),
        (
            "quaternius-witch/Witch.gltf",
            "gltf",
            13884,
            6872,
            62,
            1,
            24,
            false,
        ),
        (
            "quaternius-female-peasant/Female_Peasant.gltf",
            "gltf",
            10184,
            13568,
            65,
            1,
            0,
            false,
        ),
    ];
    for (file, kind, v, t, j, s, c, unnorm) in cases {
        let (code, json, stderr) = inspect(&dir.join(file));
        assert_eq!(code, 0, "{file}: {stderr}");
        assert_eq!(json["kind"], kind, "{file}");
        assert_eq!(json["vertices"], v, "{file}");
        assert_eq!(json["triangles"], t, "{file}");
        assert_eq!(json["joints"], j, "{file}");
        assert_eq!(json["skins"], s, "{file}");
        assert_eq!(json["clips"].as_array().unwrap().len(), c, "{file}");
        assert_eq!(
            json["unnormalized_weights"].as_u64().unwrap() > 0,
            unnorm,
            "{file}"
        );
        assert!(json["max_influences"].as_u64().unwrap() <= 4, "{file}");
        for clip in json["clips"].as_array().unwrap() {
            assert!(clip["name"].is_string() && clip["duration_s"].as_f64().unwrap() > 0.0);
            assert!(clip["frames"].as_u64().unwrap() >= 2);
        }
    }
    let (_, fox, _) = inspect(&dir.join("khronos-fox/Fox.glb"));
    assert_eq!(fox["clips"][1]["name"], "Walk");
    assert!((fox["clips"][1]["duration_s"].as_f64().unwrap() - 0.708).abs() < 1e-3);
}

#[test]
fn bad_input_exits_1_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8]); 4] = [
        ("short.glb", b"glTF\x02\x00"),
        ("garbage.gltf", b"{ not json"),
        ("empty.skf", b""),
        ("notes.txt", b"hello"),
    ];
    for (name, bytes) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let (code, json, stderr) = inspect(&path);
        assert_eq!(code, 1, "{name}: {stderr}");
        assert!(json.is_null(), "{name}: printed {json}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{name}: {stderr}");
        assert!(stderr.contains(name), "{name}: {stderr}");
    }
    let (code, _, stderr) = inspect(&dir.path().join("missing.glb"));
    assert_eq!(code, 1);
    assert!(stderr.contains("missing.glb"), "{stderr}");
}

#[test]
fn skf_model() {
    use skinfield_formats::skf::{ModelConfig, Net, SkfModel};
    use skinfield_formats::{Skeleton, Transform};
    let skeleton = Skeleton::new(
        vec!["a".into(), "b".into(), "c".into()],
        vec![None, Some(0), Some(1)],
        vec![Transform::IDENTITY; 3],
        None,
        None,
        glam::Mat4::IDENTITY,
    )
    .unwrap();
    let config = ModelConfig::paper_architecture(3, [-1.0; 3], [1.0; 3]);
    let mut model = SkfModel {
        config,
        skeleton,
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    let shapes: Vec<(usize, usize)> = model.config.layer_shapes(Net::Skin).collect();
    for (i, (o, n)) in shapes.into_iter().enumerate() {
        model.push_layer(Net::Skin, i, vec![0.01; o * n], o, n, vec![0.0; o]);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.skf");
    model.write(&path).unwrap();
    let (code, json, stderr) = inspect(&path);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(json["kind"], "skf");
    assert_eq!(json["joints"], 3);
    assert_eq!(json["tensors"], 12);
    assert_eq!(json["version"], "1.0");
    assert_eq!(json["pose_range"], false);
    // With the training range of its 9 pose features the file is version 1.2.
    model.pose_range = Some(skinfield_formats::skf::PoseRange {
        low: vec![-0.5; 9],
        high: vec![0.5; 9],
    });
    model.write(&path).unwrap();
    let (code, json, stderr) = inspect(&path);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(json["version"], "1.2");
    assert_eq!(json["pose_range"], true);
    assert_eq!(json["candidate_anchors"], 0);
}

#[test]
fn every_shared_bvh_clip() {
    let Some(dir) = shared_data_dir() else { return };
    // file, joints without End Sites, frames, duration (SOURCE.md)
    let cases = [
        ("131_01.bvh", 31, 994, 8.28),
        ("131_03.bvh", 31, 1102, 9.18),
        ("02_01.bvh", 31, 343, 2.86),
        ("pirouette.bvh", 43, 592, 4.93),
        ("jumping_jacks.bvh", 31, 125, 4.17),
    ];
    for (file, joints, frames, duration) in cases {
        let (code, json, stderr) = inspect(&dir.join("mocap-cmu").join(file));
        assert_eq!(code, 0, "{file}: {stderr}");
        assert_eq!(json["kind"], "bvh", "{file}");
        assert_eq!(json["joints"], joints, "{file}");
        assert_eq!(json["clips"][0]["frames"], frames, "{file}");
        let d = json["clips"][0]["duration_s"].as_f64().unwrap();
        assert!((d - duration).abs() < 0.01, "{file}: {d}");
    }
}

#[test]
fn capture_folder() {
    let dir = tempfile::tempdir().unwrap();
    let summary = skinfield_trainer::synth::synthesize(
        dir.path(),
        &skinfield_trainer::synth::SynthConfig::tiny(),
    )
    .unwrap();
    let (code, json, stderr) = inspect(dir.path());
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(json["kind"], "capture");
    assert_eq!(json["vertices"], summary.vertices);
    assert_eq!(json["triangles"], summary.triangles);
    assert_eq!(json["joints"], summary.joints);
    assert_eq!(json["train_frames"], summary.train_frames);
    assert_eq!(json["test_frames"], summary.test_frames);
    // A folder without a manifest is bad input naming the folder.
    let empty = tempfile::tempdir().unwrap();
    let (code, _, stderr) = inspect(empty.path());
    assert_eq!(code, 1);
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains(&empty.path().display().to_string()) || stderr.contains("manifest"),
        "{stderr}"
    );
}
