//! `trainer synth --joint-map`: the flag needs a motion file, and a malformed map is refused
//! with its file named and no capture written.

use skinfield_formats::shared_data::shared_data_dir;

mod common;

fn synth(args: &[&str]) -> (i32, String) {
    let (code, _, err) = common::trainer(&[&["synth"], args].concat());
    (code, err)
}

#[test]
fn a_joint_map_needs_a_motion_and_a_malformed_one_names_its_file() {
    let tmp = tempfile::tempdir().unwrap();
    let map = tmp.path().join("map.json");
    std::fs::write(&map, r#"{"joints": {"pelvis": 7}}"#).unwrap();
    let out = tmp.path().join("capture");
    let (code, err) = synth(&[
        "--out",
        out.to_str().unwrap(),
        "--character",
        "character.glb",
        "--joint-map",
        map.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--motion"), "{err}");
    let Some(data) = shared_data_dir() else {
        return;
    };
    let (code, err) = synth(&[
        "--out",
        out.to_str().unwrap(),
        "--character",
        data.join("quaternius-female-peasant/Female_Peasant.gltf")
            .to_str()
            .unwrap(),
        "--motion",
        data.join("quaternius-witch/Witch.gltf").to_str().unwrap(),
        "--joint-map",
        map.to_str().unwrap(),
        "--train-clips",
        "Walk",
        "--test-clips",
        "Wave",
    ]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("map.json") && err.contains("`joints.pelvis` is not a joint name"),
        "{err}"
    );
    assert!(!out.exists(), "nothing is written");
}
