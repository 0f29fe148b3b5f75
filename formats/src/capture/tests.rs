use std::path::Path;

use glam::{Mat4, Quat, Vec3};

use super::*;
use crate::camera::Camera;
use crate::math::Transform;
use crate::mesh::PartLabel;
use crate::skeleton::{Axis, JointDofs};

fn skeleton() -> Skeleton {
    Skeleton::new(
        vec!["root".into(), "knee".into()],
        vec![None, Some(0)],
        vec![
            Transform::from_rotation_translation(Quat::IDENTITY, Vec3::Y),
            Transform::from_rotation_translation(Quat::from_rotation_z(0.1), Vec3::NEG_Y * 0.5),
        ],
        None,
        Some(vec![
            JointDofs::Free,
            JointDofs::Euler {
                axes: vec![Axis::X],
                limits: vec![[0.0, 2.5]],
            },
        ]),
        Mat4::IDENTITY,
    )
    .unwrap()
}

fn template() -> Template {
    let mut t = Template {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        colors: Some(vec![Vec3::new(0.1, 0.2, 0.3); 4]),
        part_labels: Some(vec![
            PartLabel::Skin,
            PartLabel::Clothing,
            PartLabel::Skin,
            PartLabel::Skin,
        ]),
        ..Default::default()
    };
    t.compute_normals();
    t
}

fn manifest(format: ImageFormat) -> CaptureManifest {
    let cams = [Vec3::new(0.0, 1.0, 3.0), Vec3::new(3.0, 1.0, 0.0)];
    CaptureManifest {
        format: CAPTURE_FORMAT.into(),
        version: CAPTURE_VERSION,
        up_axis: "y".into(),
        cameras: cams
            .iter()
            .enumerate()
            .map(|(i, &e)| {
                CameraEntry::from_camera(&Camera::look_at(
                    &format!("cam{i}"),
                    8,
                    6,
                    0.9,
                    e,
                    Vec3::Y,
                    Vec3::Y,
                ))
            })
            .collect(),
        template: "template.json".into(),
        motion: Some("motion.json".into()),
        initial_weights: Some("initial_weights.json".into()),
        frame_count: 3,
        clips: vec![ClipEntry {
            name: "walk".into(),
            first: 0,
            count: 3,
            split: "train".into(),
        }],
        train_frames: vec![0, 1],
        test_frames: vec![2],
        images: "images".into(),
        masks: "masks".into(),
        image_format: format,
        keypoints: None,
        labels: Some(LabelsEntry {
            folder: "labels".into(),
            palette: vec![[200, 10, 10], [10, 10, 200]],
            frames: vec![0],
        }),
        canonical_frame: None,
        evaluation: Some(EvaluationEntry {
            gt_meshes: "eval/gt".into(),
            true_weights: Some("eval/true_weights.json".into()),
            deformer: "test".into(),
        }),
        source: None,
    }
}

/// Colours and a coverage mask with every level k/17 (0 and 1 included).
fn pixels(frame: usize, cam: usize) -> (Vec<Vec3>, Vec<f32>) {
    let rgb = (0..48)
        .map(|i| Vec3::new(i as f32 / 47.0, (frame as f32) * 0.25, cam as f32 * 0.5))
        .collect();
    let mask = (0..48)
        .map(|i| ((i * 7 + frame * 3 + cam * 5) % 18) as f32 / 17.0)
        .collect();
    (rgb, mask)
}

/// Part labels of camera `cam` (a 8 × 6 image): background, skin and clothing.
fn label_pixels(cam: usize) -> Vec<u8> {
    (0..48).map(|i| [NO_LABEL, 0, 1][(i + cam) % 3]).collect()
}

fn write_capture(dir: &Path, format: ImageFormat) -> (Vec<Pose>, StaticSkin, Vec<Vec3>) {
    let s = skeleton();
    let w = CaptureWriter::new(dir, manifest(format)).unwrap();
    w.write_template(&template(), &s).unwrap();
    let poses: Vec<Pose> = (0..3)
        .map(|f| {
            s.pose_from_angles(
                Quat::from_rotation_y(f as f32 * 0.3),
                Vec3::X * f as f32,
                &[0.1, 0.2, 0.3, f as f32 * 0.5],
            )
            .unwrap()
        })
        .collect();
    w.write_motion(&poses, 30.0).unwrap();
    let skin = StaticSkin::from_dense(&[1.0, 0.0, 0.5, 0.5, 0.25, 0.75, 0.0, 1.0], 2).unwrap();
    w.write_initial_weights(&skin).unwrap();
    w.write_true_weights(&skin).unwrap();
    let gt: Vec<Vec3> = template()
        .positions
        .iter()
        .map(|p| *p * 1.5 + Vec3::Z)
        .collect();
    w.write_gt_mesh(2, &gt).unwrap();
    for f in 0..3 {
        for c in 0..2 {
            let (rgb, mask) = pixels(f, c);
            w.write_image(c, f, &rgb).unwrap();
            w.write_mask(c, f, &mask).unwrap();
        }
    }
    for c in 0..2 {
        w.write_labels(c, 0, &label_pixels(c)).unwrap();
    }
    w.finish().unwrap();
    (poses, skin, gt)
}

#[test]
fn round_trip_write_then_load_gives_equal_data() {
    for format in [ImageFormat::Png, ImageFormat::Exr] {
        let tmp = tempfile::tempdir().unwrap();
        let (poses, skin, gt) = write_capture(tmp.path(), format);
        let c = load_capture(tmp.path()).unwrap();
        assert_eq!(c.manifest, manifest(format));
        assert_eq!(c.template, template());
        assert_eq!(c.skeleton, skeleton());
        assert_eq!(c.poses, poses);
        assert_eq!(c.initial_weights.as_ref(), Some(&skin));
        assert_eq!(c.evaluation_true_weights().unwrap(), Some(skin.clone()));
        assert_eq!(c.evaluation_gt_mesh(2).unwrap(), gt);
        // Training frame 1 has no ground-truth file in this capture: a typed error naming it.
        assert!(
            matches!(c.evaluation_gt_mesh(1), Err(CaptureError::Io { file, .. }) if file.ends_with("00001.bin")),
            "a missing training-frame file"
        );
        // A frame that is neither training nor test is refused by the manifest's rules.
        assert!(matches!(
            c.evaluation_gt_mesh(7),
            Err(CaptureError::Invalid { .. })
        ));
        assert_eq!(
            (c.train_frames.clone(), c.test_frames.clone()),
            (vec![0, 1], vec![2])
        );
        assert_eq!(
            c.rig.cameras[1],
            Camera::look_at(
                "cam1",
                8,
                6,
                0.9,
                Vec3::new(3.0, 1.0, 0.0),
                Vec3::Y,
                Vec3::Y
            )
        );
        for f in 0..3 {
            for cam in 0..2 {
                let (rgb, mask) = pixels(f, cam);
                let img = c.load_image(cam, f).unwrap();
                // PNG quantises to 8-bit sRGB: half a step is at most 1/510 in sRGB, which the
                // transfer function's slope (≤ 1/12.92 near black, ≤ 2.4·x near white) keeps small.
                let tol = if format == ImageFormat::Png {
                    0.006
                } else {
                    0.0
                };
                for (a, b) in img.rgb.iter().zip(&rgb) {
                    assert!((*a - *b).abs().max_element() <= tol, "{a} vs {b}");
                }
                let m = c.load_mask(cam, f).unwrap();
                for (i, (&got, &want)) in m.coverage.iter().zip(&mask).enumerate() {
                    assert!(
                        (got - want).abs() <= 0.5 / 255.0 + 1e-6,
                        "{i}: {got} vs {want}"
                    );
                    assert_eq!(m.inside[i], want > 0.5, "{i}: coverage {want}");
                }
            }
        }
    }
}

fn expect_invalid(dir: &Path, file: &str, field: &str) {
    match load_capture(dir) {
        Err(CaptureError::Invalid {
            file: f, field: fl, ..
        }) => {
            assert!(f.ends_with(file), "file {} instead of {file}", f.display());
            assert!(fl.starts_with(field), "field {fl} instead of {field}");
        }
        other => panic!("expected an invalid `{field}` in {file}, got {other:?}"),
    }
}

fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(path, serde_json::to_vec(&v).unwrap()).unwrap();
}

#[test]
fn errors_name_the_file_and_field() {
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(&str, &str, &str, Edit)> = vec![
        (
            "manifest.json",
            "manifest.json",
            "cameras[1]",
            Box::new(|v| v["cameras"][1]["fx"] = (-3.0).into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "cameras[0].name",
            Box::new(|v| v["cameras"][0]["name"] = "../x".into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "test_frames[0]",
            Box::new(|v| v["test_frames"][0] = 7.into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "test_frames",
            Box::new(|v| v["test_frames"][0] = 1.into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "template",
            Box::new(|v| v["template"] = "../t.json".into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "version",
            Box::new(|v| v["version"] = 9.into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "clips[0]",
            Box::new(|v| v["clips"][0]["count"] = 9.into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "labels.palette[1]",
            Box::new(|v| v["labels"]["palette"][1] = serde_json::json!([200, 10, 10])),
        ),
        (
            "manifest.json",
            "manifest.json",
            "labels.frames[0]",
            Box::new(|v| v["labels"]["frames"][0] = 3.into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "labels.folder",
            Box::new(|v| v["labels"]["folder"] = "/abs".into()),
        ),
        (
            "manifest.json",
            "manifest.json",
            "canonical_frame",
            Box::new(|v| v["canonical_frame"] = 3.into()),
        ),
        (
            "template.json",
            "template.json",
            "mesh",
            Box::new(|v| v["triangles"][1][2] = 9.into()),
        ),
        (
            "template.json",
            "template.json",
            "part_labels[2]",
            Box::new(|v| v["part_labels"][2] = 5.into()),
        ),
        (
            "template.json",
            "template.json",
            "skeleton",
            Box::new(|v| v["skeleton"]["joints"][0]["parent"] = 1.into()),
        ),
        (
            "template.json",
            "template.json",
            "skeleton.joints[1].dofs",
            Box::new(|v| v["skeleton"]["joints"][1]["dofs"]["euler"]["axes"] = "XQ".into()),
        ),
        (
            "motion.json",
            "motion.json",
            "frames[1]",
            Box::new(|v| v["frames"][1].as_array_mut().unwrap().truncate(1)),
        ),
        (
            "motion.json",
            "motion.json",
            "frames[2][0]",
            Box::new(|v| v["frames"][2][0][6] = 3.0.into()),
        ),
        (
            "motion.json",
            "motion.json",
            "fps",
            Box::new(|v| v["fps"] = 0.0.into()),
        ),
        (
            "motion.json",
            "motion.json",
            "fps",
            Box::new(|v| v["fps"] = (-24.0).into()),
        ),
        (
            "initial_weights.json",
            "initial_weights.json",
            "offsets",
            Box::new(|v| v["offsets"].as_array_mut().unwrap().truncate(2)),
        ),
        (
            "initial_weights.json",
            "initial_weights.json",
            "weights",
            Box::new(|v| v["weights"][0] = (-1.0).into()),
        ),
    ];
    for (target, file, field, edit) in cases {
        let tmp = tempfile::tempdir().unwrap();
        write_capture(tmp.path(), ImageFormat::Png);
        edit_json(&tmp.path().join(target), |v| edit(v));
        expect_invalid(tmp.path(), file, field);
    }
}

#[test]
fn a_capture_without_motion_loads_in_the_bind_pose_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    write_capture(tmp.path(), ImageFormat::Png);
    let with_motion = load_capture(tmp.path()).unwrap();
    assert!(with_motion.require_motion().is_ok());
    assert_eq!(with_motion.motion_fps, Some(30.0));
    edit_json(&tmp.path().join("manifest.json"), |v| {
        v.as_object_mut().unwrap().remove("motion");
    });
    std::fs::remove_file(tmp.path().join("motion.json")).unwrap();
    let c = load_capture(tmp.path()).unwrap();
    assert!(!c.has_motion());
    assert_eq!(c.motion_fps, None);
    assert_eq!(c.poses, vec![c.skeleton.bind_pose(); 3]);
    match c.require_motion() {
        Err(CaptureError::Invalid { field, reason, .. }) => {
            assert_eq!(field, "motion");
            assert!(reason.contains("trainer track"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    // A writer without a motion path refuses to write one.
    let mut m = manifest(ImageFormat::Png);
    m.motion = None;
    let w = CaptureWriter::new(tmp.path().join("other"), m).unwrap();
    assert!(w.write_motion(&c.poses, 30.0).is_err());
}

#[test]
fn labels_and_the_canonical_frame_load_and_missing_ones_are_reported() {
    let tmp = tempfile::tempdir().unwrap();
    write_capture(tmp.path(), ImageFormat::Png);
    let c = load_capture(tmp.path()).unwrap();
    assert_eq!(
        c.canonical_frame(),
        0,
        "the first training frame by default"
    );
    for cam in 0..2 {
        let l = c.load_labels(cam, 0).unwrap().unwrap();
        assert_eq!(l.labels, label_pixels(cam));
    }
    let e = c.load_labels(0, 1).unwrap_err();
    assert!(e.to_string().contains("labels.frames"), "{e}");
    // A label file the manifest lists must exist.
    let label = tmp.path().join("labels/cam1/00000.png");
    std::fs::remove_file(&label).unwrap();
    assert!(
        matches!(load_capture(tmp.path()), Err(CaptureError::BadFile { file, .. }) if file == label)
    );
    // The canonical frame may be outside the train and test frames, but its images must exist.
    let tmp = tempfile::tempdir().unwrap();
    write_capture(tmp.path(), ImageFormat::Png);
    edit_json(&tmp.path().join("manifest.json"), |v| {
        v["train_frames"] = serde_json::json!([0]);
        v["canonical_frame"] = 1.into();
    });
    let c = load_capture(tmp.path()).unwrap();
    assert_eq!(c.canonical_frame(), 1);
    let mask = tmp.path().join("masks/cam0/00001.png");
    std::fs::remove_file(&mask).unwrap();
    assert!(
        matches!(load_capture(tmp.path()), Err(CaptureError::BadFile { file, .. }) if file == mask)
    );
}

#[test]
fn missing_or_malformed_files_are_reported_by_path() {
    let tmp = tempfile::tempdir().unwrap();
    write_capture(tmp.path(), ImageFormat::Png);
    let mask = tmp.path().join("masks/cam1/00002.png");
    std::fs::remove_file(&mask).unwrap();
    assert!(
        matches!(load_capture(tmp.path()), Err(CaptureError::BadFile { file, .. }) if file == mask)
    );

    let tmp = tempfile::tempdir().unwrap();
    write_capture(tmp.path(), ImageFormat::Png);
    let c = load_capture(tmp.path()).unwrap();
    // An image of the wrong size, a truncated PNG, a truncated ground-truth mesh.
    let img = tmp.path().join("images/cam0/00001.png");
    images::write_image_png(&img, 4, 4, &[Vec3::ONE; 16]).unwrap();
    assert!(matches!(c.load_image(0, 1), Err(CaptureError::BadFile { file, .. }) if file == img));
    let bytes = std::fs::read(c.mask_path(1, 0)).unwrap();
    std::fs::write(c.mask_path(1, 0), &bytes[..bytes.len() / 2]).unwrap();
    assert!(matches!(
        c.load_mask(1, 0),
        Err(CaptureError::BadFile { .. })
    ));
    let gt = tmp.path().join("eval/gt/00002.bin");
    let bytes = std::fs::read(&gt).unwrap();
    std::fs::write(&gt, &bytes[..bytes.len() - 1]).unwrap();
    assert!(
        matches!(c.evaluation_gt_mesh(2), Err(CaptureError::BadFile { file, .. }) if file == gt)
    );
    assert!(c.load_image(5, 0).is_err() && c.load_mask(0, 3).is_err());
    let bad_json = tmp.path().join("motion.json");
    std::fs::write(&bad_json, b"{\"fps\": 30, \"frames\": [").unwrap();
    assert!(
        matches!(load_capture(tmp.path()), Err(CaptureError::Json { file, .. }) if file == bad_json)
    );
    assert!(matches!(
        load_capture(tmp.path().join("nowhere")),
        Err(CaptureError::Io { .. })
    ));
}

#[test]
fn srgb_transfer_round_trips() {
    for i in 0..=100 {
        let x = i as f32 / 100.0;
        assert!((srgb_to_linear(linear_to_srgb(x)) - x).abs() < 1e-5);
    }
    // The reference point of the standard: linear 0.5 encodes to ~0.7354.
    assert!((linear_to_srgb(0.5) - 0.735_36).abs() < 1e-4);
}
