//! `trainer zoo` end to end on RobotExpressive with a budget of one iteration per phase and a
//! tiny capture: the table and the JSON name the character, its counts and its clip split, and
//! carry the four rows with absolute, relative and worst-vertex figures. Plus the refusals.

use std::path::Path;

use skinfield_formats::shared_data::shared_data_dir;

mod common;

fn zoo(args: &[&str]) -> (i32, String) {
    let (code, _, err) = common::trainer(&[&["zoo"], args].concat());
    (code, err)
}

/// `trainer zoo` of one character with one iteration per phase on a capture of two 40² cameras
/// and one frame per clip, into `out` with the configuration file `config`, plus `extra`.
fn tiny_zoo(
    character: &str,
    out: &Path,
    config: &Path,
    data: &Path,
    extra: &[&str],
) -> (i32, String) {
    let mut args = vec![
        "--out",
        out.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--characters",
        character,
        "--warm-start",
        "1",
        "--iterations",
        "1",
        "--static-iterations",
        "1",
        "--cameras",
        "2",
        "--resolution",
        "40",
        "--train-frames",
        "1",
        "--test-frames",
        "1",
        "--samples",
        "500",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    zoo(&args)
}

#[test]
fn zoo_writes_one_table_with_the_robot() {
    let Some(data) = shared_data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("zoo");
    let doc = tmp.path().join("docs/zoo.md");
    std::fs::create_dir_all(doc.parent().unwrap()).unwrap();
    let config = tmp.path().join("config.json");
    // One iteration per phase cannot beat bone heat: the validation guard would refuse every
    // model, so it is switched off here (its own tests are in the trainer's library).
    std::fs::write(
        &config,
        r#"{"weights": {"skinning": 0, "partwise": 0}, "refuse_worse_than_initial": false}"#,
    )
    .unwrap();
    let (code, err) = tiny_zoo(
        "robot",
        &out,
        &config,
        &data,
        &["--doc", doc.to_str().unwrap()],
    );
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("zoo.json")).unwrap()).unwrap();
    let robot = &json["characters"][0];
    assert_eq!(robot["name"], "robot");
    assert_eq!(robot["joints"], 43);
    assert_eq!(robot["vertices"], 7214);
    assert_eq!(robot["train_clips"], "Idle, Walking, Running, Dance, Punch");
    assert_eq!(robot["frames"], serde_json::json!([5, 3]));
    assert!(robot["error"].is_null());
    let methods: Vec<&str> = robot["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["method"].as_str().unwrap())
        .collect();
    assert_eq!(methods, ["initial", "static", "ours", "oracle"]);
    for row in robot["rows"].as_array().unwrap() {
        let (cm, pct, size) = (
            row["chamfer_cm"].as_f64().unwrap(),
            row["chamfer_pct"].as_f64().unwrap(),
            row["size"].as_f64().unwrap(),
        );
        assert!(cm > 0.0 && (pct - cm / size).abs() < 1e-9, "{row}");
        assert_eq!(row["per_frame"].as_array().unwrap().len(), 3);
        assert!(row["max_vertex_cm"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(robot["worst_vertex_ours"]["frames"], 3);
    // A warm start of one iteration cannot converge (the test averages over 50): the table
    // says it stopped at its cap.
    assert_eq!(robot["warm_start"]["iterations"], 1);
    assert_eq!(robot["warm_start"]["converged"], false);
    let md = std::fs::read_to_string(out.join("zoo.md")).unwrap();
    assert_eq!(std::fs::read_to_string(&doc).unwrap(), md);
    assert!(doc.with_extension("json").is_file());
    assert!(
        md.contains("| **robot** (threejs-robotexpressive/RobotExpressive.glb) | 43 | 7,214 |")
    );
    assert!(md.contains("novel: Wave, ThumbsUp, Jump (3 frames)"));
    assert!(md.contains("Chamfer (% of size)") && md.contains("| oracle |"));
    assert!(
        md.contains("| **no**: stopped at its cap of 1 iteration (KL "),
        "{md}"
    );
    // The configuration and the command that reproduce the table are named in it.
    assert!(
        md.contains(
            r#"`{"refuse_worse_than_initial":false,"weights":{"partwise":0,"skinning":0}}`"#
        ),
        "{md}"
    );
    assert!(md.contains(&format!("--doc {}", doc.display())), "{md}");
    assert!(md.contains("cargo run --release -p skinfield-trainer -- zoo --out"));
    assert!(md.contains("of 1 characters"), "{md}");
    assert_eq!(
        json["budget"]["config"][1]["weights"]["skinning"],
        serde_json::json!(0)
    );
}

#[test]
fn zoo_drives_the_peasant_with_the_witchs_clips_retargeted() {
    let Some(data) = shared_data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("zoo");
    let config = tmp.path().join("config.json");
    std::fs::write(&config, r#"{"refuse_worse_than_initial": false}"#).unwrap();
    let (code, err) = tiny_zoo("peasant", &out, &config, &data, &[]);
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("zoo.json")).unwrap()).unwrap();
    let peasant = &json["characters"][0];
    assert_eq!(peasant["name"], "peasant");
    assert_eq!(
        (&peasant["joints"], &peasant["vertices"]),
        (&65.into(), &10184.into())
    );
    assert_eq!(
        peasant["train_clips"],
        "Idle, Walk, Run, Punch_Left, Kick_Left (quaternius-witch/Witch.gltf's, retargeted)"
    );
    assert_eq!(peasant["frames"], serde_json::json!([5, 3]));
    assert!(peasant["error"].is_null());
}

#[test]
fn zoo_refuses_unknown_characters_and_reports_missing_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("zoo");
    let (code, err) = zoo(&["--out", out.to_str().unwrap(), "--characters", "dragon"]);
    assert_eq!(code, 1);
    assert!(
        err.contains("dragon")
            && err.contains("builtin, cesiumman, fox, robot, witch, peasant, makehuman"),
        "{err}"
    );
    // A missing asset: the table still gets the character's row, with the reason, and the
    // command fails.
    let (code, err) = zoo(&[
        "--out",
        out.to_str().unwrap(),
        "--data",
        tmp.path().join("nowhere").to_str().unwrap(),
        "--characters",
        "fox",
        "--quick",
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("Fox.glb not found"), "{err}");
    let md = std::fs::read_to_string(out.join("zoo.md")).unwrap();
    assert!(
        md.contains("| fox |") && md.contains("Fox.glb not found"),
        "{md}"
    );
}
