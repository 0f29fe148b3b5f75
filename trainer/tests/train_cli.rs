//! `trainer train` with an ensemble: every member trained in its own folder, the student
//! distilled from them and exported, a finished run resumed to the same bytes, and an ensemble
//! with pose refinement refused before anything trains.

mod common;

use common::tiny_synth;

#[test]
fn an_ensemble_trains_its_members_then_distils_one_model() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    let c = cap.to_str().unwrap();
    let (code, _, err) = tiny_synth(c, "2", &["--cameras", "4", "--resolution", "48"]);
    assert_eq!(code, 0, "{err}");
    let config = tmp.path().join("c.json");
    std::fs::write(
        &config,
        r#"{"iterations": 6, "warm_start_iterations": 4, "validation_every": 3,
            "ensemble": {"members": 2}}"#,
    )
    .unwrap();
    let model = tmp.path().join("m.skf");
    let train =
        |extra: &[&str]| common::train(c, model.to_str().unwrap(), config.to_str().unwrap(), extra);
    let (code, out, err) = train(&[]);
    assert_eq!(code, 0, "{err}");
    let work = tmp.path().join("m.skf.work");
    for k in 0..2 {
        assert!(
            out.contains(&format!("ensemble member {} of 2 (seed {k})", k + 1)),
            "{out}"
        );
        // A header and one row per image iteration.
        let losses = std::fs::read_to_string(work.join(format!("member-{k}/losses.csv"))).unwrap();
        assert_eq!(losses.lines().count(), 7, "member {k}: {losses}");
    }
    assert!(
        out.contains("distilling the 2 members' mean weights"),
        "{out}"
    );
    // The student's stage 1 is the distillation alone.
    let distil = std::fs::read_to_string(work.join("warm_start.csv")).unwrap();
    assert!(distil.lines().count() > 1, "{distil}");
    let written = std::fs::read(&model).unwrap();
    assert!(skinfield_formats::skf::SkfView::parse(&written).is_ok());

    // Everything has run: resuming changes nothing.
    let (code, _, err) = train(&["--resume"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(&model).unwrap(), written);

    std::fs::write(
        &config,
        r#"{"ensemble": {"members": 2}, "pose_refinement": {"enabled": true}}"#,
    )
    .unwrap();
    std::fs::remove_file(&model).unwrap();
    let (code, _, err) = train(&[]);
    assert_ne!(code, 0);
    assert!(err.contains("ensemble.members"), "{err}");
    assert!(!model.exists());
}
