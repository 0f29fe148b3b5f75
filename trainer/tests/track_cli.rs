//! A capture that has 2D keypoints but no skeletal motion: everything that poses the skeleton
//! refuses it with a message naming `motion`, and `trainer track` writes a copy that has it.

mod common;

use common::{four_camera_capture, tiny_synth, trainer};
use skinfield_formats::capture::load_capture;
use skinfield_trainer::train::validation::held_out_indices;

/// `trainer track --capture CAPTURE --out OUT EXTRA…`.
fn track(capture: &str, out: &std::path::Path, extra: &[&str]) -> (i32, String, String) {
    let mut args = vec![
        "track",
        "--capture",
        capture,
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    trainer(&args)
}

#[test]
fn a_capture_without_motion_is_tracked_and_only_then_trained() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    let c = cap.to_str().unwrap();
    let (code, _, err) = tiny_synth(
        c,
        "1",
        &["--keypoints", "--cameras", "4", "--resolution", "48"],
    );
    assert_eq!(code, 0, "{err}");
    let truth = load_capture(&cap).unwrap().poses;
    // Drop the motion, as a capture from video and a 2D detector would come.
    let manifest = cap.join("manifest.json");
    let mut m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    m.as_object_mut().unwrap().remove("motion");
    std::fs::write(&manifest, serde_json::to_vec(&m).unwrap()).unwrap();
    std::fs::remove_file(cap.join("motion.json")).unwrap();
    assert!(!load_capture(&cap).unwrap().has_motion());

    let model = tmp.path().join("m.skf");
    for args in [
        vec!["train", "--capture", c, "--out", model.to_str().unwrap()],
        vec!["eval", "--capture", c, "--weights", "initial"],
        vec![
            "template",
            "--capture",
            c,
            "--out",
            tmp.path().join("t").to_str().unwrap(),
        ],
    ] {
        let (code, _, err) = trainer(&args);
        assert_eq!(code, 1, "{args:?}");
        assert!(
            err.contains("`motion`") && err.contains("trainer track"),
            "{args:?}: {err}"
        );
    }
    assert!(!model.exists());

    let tracked = tmp.path().join("tracked");
    let (code, _, err) = track(c, &tracked, &["--calibration-rounds", "1"]);
    assert_eq!(code, 0, "{err}");
    let copy = load_capture(&tracked).unwrap();
    assert!(copy.has_motion());
    // The skeleton calibration's table: a header and one row per joint, the root unmoved.
    let bones = std::fs::read_to_string(tracked.join("bones.csv")).unwrap();
    let rows: Vec<&str> = bones.lines().collect();
    assert_eq!(rows[0], "joint,name,dx,dy,dz,offset,bone_length");
    assert_eq!(rows.len(), 1 + copy.skeleton.len());
    assert!(rows[1].starts_with("0,") && rows[1].contains(",0.000000,0.000000,0.000000,0.000000,"));
    // Fitted to the detections (2 px noise at 48²): the root within a few centimetres.
    for (f, (got, want)) in copy.poses.iter().zip(&truth).enumerate() {
        let d = got.locals[0]
            .translation
            .distance(want.locals[0].translation);
        assert!(d < 0.1, "frame {f}: root {d} m off");
    }
}

#[test]
fn synth_writes_the_detections_of_the_landmark_set_asked_for() {
    use skinfield_trainer::track::landmarks::{joint_ring_landmark_map, joint_side_landmark_map};
    for set in ["joint-sides", "joint-ring"] {
        let tmp = tempfile::tempdir().unwrap();
        let cap = tmp.path().join("cap");
        let (code, _, err) = tiny_synth(
            cap.to_str().unwrap(),
            "1",
            &[
                "--keypoints",
                "--cameras",
                "2",
                "--resolution",
                "32",
                "--landmarks",
                set,
            ],
        );
        assert_eq!(code, 0, "{set}: {err}");
        let capture = load_capture(&cap).unwrap();
        let map = capture.landmark_map().unwrap().unwrap();
        let want = match set {
            "joint-sides" => joint_side_landmark_map(&capture.skeleton),
            _ => joint_ring_landmark_map(&capture.skeleton, &capture.template),
        };
        assert_eq!(map, want, "{set}");
        let detections = capture.keypoints(0, 0, map.keypoints.len()).unwrap();
        assert_eq!(detections.len(), map.keypoints.len());
        assert!(
            detections.iter().filter(|d| d.is_some()).count() > map.keypoints.len() / 2,
            "{set}"
        );
    }
}

#[test]
fn a_bad_filter_setting_is_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = four_camera_capture(tmp.path(), "1");
    let c = cap.to_str().unwrap();
    let tracked = tmp.path().join("tracked");
    for (flag, values) in [
        ("--filter-sigma", ["-1", "NaN", "1e9"]),
        ("--fps", ["0", "-24", "NaN"]),
    ] {
        for value in values {
            let arg = format!("{flag}={value}");
            let (code, _, err) = track(c, &tracked, &["--synthesize", &arg]);
            assert_eq!(code, 1, "{arg}");
            assert!(err.contains(flag), "{arg}: {err}");
            assert!(!tracked.exists(), "{arg}: the copy was written");
        }
    }
    let (code, _, err) = track(
        c,
        &tracked,
        &[
            "--synthesize",
            "--filter-sigma",
            "2",
            "--filter-clips",
            "walk,nope",
        ],
    );
    assert_eq!(code, 1);
    assert!(
        err.contains("--filter-clips") && err.contains("`nope`"),
        "{err}"
    );
    assert!(!tracked.exists(), "the copy was written");
}

/// The `fps` of a capture's `motion.json`.
fn motion_fps(capture: &std::path::Path) -> f64 {
    let motion: serde_json::Value =
        serde_json::from_slice(&std::fs::read(capture.join("motion.json")).unwrap()).unwrap();
    motion["fps"].as_f64().unwrap()
}

#[test]
fn the_tracked_motion_keeps_the_input_frame_rate_unless_told_otherwise() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = four_camera_capture(tmp.path(), "1");
    // A video at 80 frames per second.
    let path = cap.join("motion.json");
    let mut motion: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    motion["fps"] = 80.0.into();
    std::fs::write(&path, serde_json::to_vec(&motion).unwrap()).unwrap();
    let c = cap.to_str().unwrap();
    let fast = ["--synthesize", "--silhouette-weight", "0"];
    let kept = tmp.path().join("kept");
    let (code, out, err) = track(c, &kept, &fast);
    assert_eq!(code, 0, "{err}");
    assert_eq!(motion_fps(&kept), 80.0);
    assert!(out.contains("at 80 fps"), "{out}");
    let told = tmp.path().join("told");
    let (code, _, err) = track(c, &told, &[&fast[..], &["--fps", "24"]].concat());
    assert_eq!(code, 0, "{err}");
    assert_eq!(motion_fps(&told), 24.0);
}

#[test]
fn track_synthesize_writes_the_detections_into_the_copy_and_leaves_the_input_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = four_camera_capture(tmp.path(), "1");
    let c = cap.to_str().unwrap();
    let manifest_before = std::fs::read(cap.join("manifest.json")).unwrap();
    let tracked = tmp.path().join("tracked");
    let (code, _, err) = track(
        c,
        &tracked,
        &[
            "--synthesize",
            "--landmarks",
            "joint-ring",
            "--silhouette-weight",
            "0",
        ],
    );
    assert_eq!(code, 0, "{err}");
    // The input: no keypoints, the same manifest byte for byte.
    assert!(!cap.join("keypoints").exists());
    assert_eq!(
        std::fs::read(cap.join("manifest.json")).unwrap(),
        manifest_before
    );
    assert!(load_capture(&cap).unwrap().manifest.keypoints.is_none());
    // The copy: the ring's detections and the tracked motion, close to the input's.
    let copy = load_capture(&tracked).unwrap();
    let map = copy.landmark_map().unwrap().unwrap();
    assert_eq!(map.detector, "joints+ring");
    let truth = load_capture(&cap).unwrap().poses;
    for (f, (got, want)) in copy.poses.iter().zip(&truth).enumerate() {
        let d = got.locals[0]
            .translation
            .distance(want.locals[0].translation);
        assert!(d < 0.1, "frame {f}: root {d} m off");
    }
}

#[test]
fn train_refine_poses_writes_the_corrected_training_motion() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = four_camera_capture(tmp.path(), "2");
    let c = cap.to_str().unwrap();
    let capture = load_capture(&cap).unwrap();
    let config = tmp.path().join("c.json");
    std::fs::write(
        &config,
        r#"{"iterations": 16, "warm_start_iterations": 4, "validation_every": 8,
            "pose_refinement": {"lr": 0.01}}"#,
    )
    .unwrap();
    // `trainer train` into `out` with the configuration above, plus `extra`.
    let train = |out: &str, extra: &[&str]| common::train(c, out, config.to_str().unwrap(), extra);
    let model = tmp.path().join("m.skf");
    let (code, out, err) = train(model.to_str().unwrap(), &["--refine-poses"]);
    assert_eq!(code, 0, "{err}");
    // The validation frames (`held_out_indices`) and the test frames keep their poses; every
    // other training frame was corrected.
    let held: Vec<usize> = held_out_indices(capture.train_frames.len(), 4)
        .into_iter()
        .map(|i| capture.train_frames[i])
        .collect();
    assert!(!held.is_empty());
    let corrected = capture.train_frames.len() - held.len();
    assert!(
        out.contains(&format!("pose refinement: {corrected} training frames")),
        "{out}"
    );
    let path = tmp.path().join("m.skf.work/refined_motion.json");
    let refined: skinfield_formats::capture::MotionFile =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(refined.frames.len(), capture.frame_count());
    for (f, (got, pose)) in refined.frames.iter().zip(&capture.poses).enumerate() {
        let moved = got.iter().zip(&pose.locals).any(|(g, l)| {
            let l = skinfield_formats::capture::transform_to_array(l);
            g.iter().zip(l).any(|(a, b)| (a - b).abs() > 1e-5)
        });
        let trained = capture.train_frames.contains(&f) && !held.contains(&f);
        assert_eq!(moved, trained, "frame {f}");
    }
    // Without the flag there is no such file.
    let plain = tmp.path().join("p.skf");
    let (code, out, err) = train(plain.to_str().unwrap(), &[]);
    assert_eq!(code, 0, "{err}");
    assert!(!out.contains("pose refinement"), "{out}");
    assert!(!tmp.path().join("p.skf.work/refined_motion.json").exists());
}
