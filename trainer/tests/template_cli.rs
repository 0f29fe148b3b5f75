//! `trainer template` end to end on a small synthetic capture: the copy it writes loads as a
//! capture whose template is the reconstruction (closed, coloured, labelled, with bone heat),
//! `template.glb` holds the same mesh, the report scores it against the ground truth; and the
//! refusals.

mod common;

use std::path::Path;

use common::trainer;
use skinfield_formats::capture::load_capture;
use skinfield_formats::gltf_io::load_gltf;

fn synth(dir: &Path, label_noise: &str) {
    let (code, _, err) = trainer(&[
        "synth",
        "--out",
        dir.to_str().unwrap(),
        "--cameras",
        "8",
        "--resolution",
        "80",
        "--grid",
        "48",
        "--vertices",
        "2500",
        "--train-frames",
        "1",
        "--test-frames",
        "1",
        "--label-noise",
        label_noise,
    ]);
    assert_eq!(code, 0, "{err}");
}

#[test]
fn template_writes_a_trainable_copy_with_a_closed_coloured_labelled_mesh() {
    let tmp = tempfile::tempdir().unwrap();
    let (cap, out) = (tmp.path().join("cap"), tmp.path().join("tpl"));
    synth(&cap, "0");
    let source = load_capture(&cap).unwrap();
    let canonical = source
        .manifest
        .canonical_frame
        .expect("synth writes a canonical frame");
    let (code, stdout, err) = trainer(&[
        "template",
        "--capture",
        cap.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--resolution",
        "64",
        "--vertices",
        "2000",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains(&format!("frame {canonical} from 8 cameras")),
        "{stdout}"
    );

    let copy = load_capture(&out).unwrap();
    let t = &copy.template;
    assert!(
        (1900..2300).contains(&t.vertex_count()),
        "{} vertices",
        t.vertex_count()
    );
    let colors = t.colors.as_ref().expect("vertex colours");
    assert!(
        colors
            .iter()
            .all(|c| c.min_element() >= 0.0 && c.max_element() <= 1.0)
    );
    assert_eq!(t.part_labels.as_ref().map(Vec::len), Some(t.vertex_count()));
    let skin = copy.initial_weights.as_ref().expect("bone heat written");
    assert_eq!(skin.vertex_count(), t.vertex_count());
    assert!(
        copy.manifest.evaluation.is_none(),
        "the copy's ground truth would not fit"
    );
    assert_eq!(copy.poses, source.poses);
    // The canonical frame is the bind pose, so the skeleton is the capture's.
    assert_eq!(copy.skeleton.bind_local(), source.skeleton.bind_local());

    let glb = load_gltf(&out.join("template.glb")).unwrap();
    let skinned = glb.largest_skin().expect("a skinned mesh");
    assert_eq!(skinned.template.positions, t.positions);

    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("template_report.json")).unwrap()).unwrap();
    assert_eq!(report["reconstruction"]["closed"], true, "{report}");
    assert_eq!(
        report["reconstruction"]["euler_characteristic"], 2,
        "{report}"
    );
    // A hull from 8 cameras of 80² pixels (about 2.5 cm each): within a few centimetres, and
    // most labels right (measured: see docs/experiments/template.md for the full-size capture).
    let score = &report["score"];
    let chamfer = score["m2s_cm"].as_f64().unwrap() + score["s2m_cm"].as_f64().unwrap();
    assert!(chamfer < 8.0, "{score}");
    assert!(score["label_accuracy"].as_f64().unwrap() > 0.85, "{score}");
}

#[test]
fn template_refuses_bad_options_and_writing_over_its_input() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    synth(&cap, "0.3");
    let c = cap.to_str().unwrap();
    let out = tmp.path().join("tpl");
    let o = out.to_str().unwrap();
    for (args, needle) in [
        (vec!["--frame", "999"], "`frame`"),
        (vec!["--cameras", "1"], "`cameras`"),
        (vec!["--cameras", "9"], "`cameras`"),
        (vec!["--resolution", "4"], "`resolution`"),
        (vec!["--vertices", "10"], "`vertices`"),
    ] {
        let mut all = vec!["template", "--capture", c, "--out", o];
        all.extend(args);
        let (code, _, err) = trainer(&all);
        assert_eq!(code, 1, "{all:?}");
        assert!(err.contains(needle), "{all:?}: {err}");
        assert!(!out.exists(), "nothing written on error");
    }
    let (code, _, err) = trainer(&["template", "--capture", c, "--out", c]);
    assert_eq!(code, 1);
    assert!(err.contains("--out must differ"), "{err}");
}
