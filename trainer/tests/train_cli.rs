//! `trainer train` with an ensemble: every member trained in its own folder, the student
//! distilled from them and exported, a finished run resumed to the same bytes, and an ensemble
//! with pose refinement refused before anything trains; stage 4 moved to the full-resolution
//! template; the outline offsets learned by default, and not with `--no-outline-offsets`.

mod common;

use common::four_camera_capture;

#[test]
fn an_ensemble_trains_its_members_then_distils_one_model() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = four_camera_capture(tmp.path(), "2");
    let c = cap.to_str().unwrap();
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
    // Each member learns its own outline offsets (on by default); the student goes on from
    // their mean.
    for k in 0..2 {
        assert!(
            out.contains(&format!("member {}: learned outline offsets", k + 1)),
            "{out}"
        );
        assert!(
            work.join(format!("member-{k}/outline_offsets.csv"))
                .exists()
        );
    }
    assert!(work.join("outline_offsets.csv").exists());
    // The student's stage 1 is the distillation alone.
    let distil = std::fs::read_to_string(work.join("warm_start.csv")).unwrap();
    assert!(distil.lines().count() > 1, "{distil}");
    // The iterations reported are every member's and the distillation's, one row each in their
    // logs.
    let rows =
        |path: std::path::PathBuf| std::fs::read_to_string(path).unwrap().lines().count() - 1;
    let warm = rows(work.join("warm_start.csv"))
        + (0..2)
            .map(|k| rows(work.join(format!("member-{k}/warm_start.csv"))))
            .sum::<usize>();
    assert!(
        out.contains(&format!(
            "SkinNet: {warm} warm-start + 12 image iterations before stages 2–4"
        )),
        "{out}"
    );
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

/// With `stages.full_resolution` stage 1 trains on the simplified template and stage 4 on the
/// full one: the exported model's candidate anchors (one per training vertex) are the full
/// template's vertices, and without it the simplified template's.
#[test]
fn stage_four_moves_to_the_full_resolution_template() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = four_camera_capture(tmp.path(), "2");
    let c = cap.to_str().unwrap();
    let full = skinfield_formats::capture::load_capture(&cap)
        .unwrap()
        .template
        .vertex_count();
    let anchors = |full_resolution: bool| {
        let config = tmp.path().join(format!("c{full_resolution}.json"));
        std::fs::write(
            &config,
            format!(
                r#"{{"iterations": 4, "warm_start_iterations": 4, "validation_every": 2,
                    "stages": {{"refine_iterations": 2, "rendering_weight": 0,
                                "full_resolution": {full_resolution}}}}}"#
            ),
        )
        .unwrap();
        let model = tmp.path().join(format!("m{full_resolution}.skf"));
        let (code, _, err) = common::train(
            c,
            model.to_str().unwrap(),
            config.to_str().unwrap(),
            &["--train-vertices", "600"],
        );
        assert_eq!(code, 0, "{err}");
        let bytes = std::fs::read(&model).unwrap();
        let view = skinfield_formats::skf::SkfView::parse(&bytes).unwrap();
        let stages = std::fs::read_to_string(
            tmp.path()
                .join(format!("m{full_resolution}.skf.work/stages.csv")),
        )
        .unwrap();
        assert_eq!(stages.lines().filter(|l| l.starts_with("4,")).count(), 2);
        // The profile rewritten after stage 4 keeps stage 1's timings, also when stage 4
        // moved to the full-resolution template.
        let profile = std::fs::read_to_string(
            tmp.path()
                .join(format!("m{full_resolution}.skf.work/profile.csv")),
        )
        .unwrap();
        for kind in ["image,4,total,", "refine,2,total,"] {
            assert!(profile.contains(kind), "{kind}: {profile}");
        }
        assert!(!profile.contains("warm,0,"), "{profile}");
        view.candidates().map_or(0, |c| c.len())
    };
    let (coarse, fine) = (anchors(false), anchors(true));
    assert!(coarse < full * 2 / 5, "{coarse} of {full}");
    assert_eq!(fine, full);
}

/// By default one outline offset per camera is learned through stage 1 and stage 4 (moved to the
/// full-resolution template), printed and written to the work folder, and a finished run resumed
/// writes the same model; `--no-outline-offsets` learns none.
#[test]
fn outline_offsets_are_learned_printed_and_resumed() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = four_camera_capture(tmp.path(), "2");
    let config = tmp.path().join("c.json");
    std::fs::write(
        &config,
        r#"{"iterations": 4, "warm_start_iterations": 4, "validation_every": 2,
            "stages": {"refine_iterations": 2, "rendering_weight": 0, "full_resolution": true}}"#,
    )
    .unwrap();
    let model = tmp.path().join("m.skf");
    let train = |extra: &[&str]| {
        let mut args = vec!["--train-vertices", "600"];
        args.extend_from_slice(extra);
        common::train(
            cap.to_str().unwrap(),
            model.to_str().unwrap(),
            config.to_str().unwrap(),
            &args,
        )
    };
    let (code, out, err) = train(&[]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("learned outline offsets: the masks lie") && out.contains("over 4 cameras"),
        "{out}"
    );
    // The drift of the vertices the outlines cannot check is reported beside the validation.
    assert!(
        out.contains("vertices on no training outline moved by up to"),
        "{out}"
    );
    let csv_path = tmp.path().join("m.skf.work/outline_offsets.csv");
    let csv = std::fs::read_to_string(&csv_path).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "camera,offset_px");
    assert_eq!(lines.len(), 5, "{csv}");
    let offsets: Vec<f32> = lines[1..]
        .iter()
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    // Six image iterations at up to 1e-2 px each (the schedule's warm-up ramps them in).
    assert!(
        offsets.iter().all(|b| b.is_finite() && b.abs() <= 0.06)
            && offsets.iter().any(|&b| b != 0.0),
        "{offsets:?}"
    );
    let written = std::fs::read(&model).unwrap();
    let (code, _, err) = train(&["--resume"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(&model).unwrap(), written);
    assert_eq!(std::fs::read_to_string(&csv_path).unwrap(), csv);

    std::fs::remove_dir_all(tmp.path().join("m.skf.work")).unwrap();
    let (code, out, err) = train(&["--no-outline-offsets"]);
    assert_eq!(code, 0, "{err}");
    assert!(!out.contains("learned outline offsets"), "{out}");
    assert!(!csv_path.exists());
}
