//! [`load_capture`]: reads a capture's manifest, template, skeleton, motion and initial
//! weights and validates all of it, naming the file and field of the first error.

use std::path::{Component, Path};

use super::{
    CAPTURE_FORMAT, CAPTURE_VERSION, Capture, CaptureError, CaptureManifest, MANIFEST_FILE,
    MAX_CAMERAS, MAX_FRAMES, MotionFile, SkinFile, TemplateFile, read_json, validate_palette,
};
use crate::camera::CameraRig;
use crate::pose::UpAxis;

/// Checks that a manifest path is relative and stays inside the capture folder.
fn check_relative(file: &Path, field: &str, rel: &str) -> Result<(), CaptureError> {
    let p = Path::new(rel);
    let ok = !rel.is_empty()
        && p.components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    ensure(ok, file, field, || {
        format!("`{rel}` must be a relative path inside the capture")
    })
}

/// `Ok` when `ok`, else the error naming `file` and `field` with `message()`.
fn ensure(
    ok: bool,
    file: &Path,
    field: &str,
    message: impl FnOnce() -> String,
) -> Result<(), CaptureError> {
    if ok {
        Ok(())
    } else {
        Err(CaptureError::invalid(file, field, message()))
    }
}

/// Camera names become folder names: keep them to a portable alphabet.
fn check_name(file: &Path, field: &str, name: &str) -> Result<(), CaptureError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    ensure(ok, file, field, || {
        format!("`{name}` is not a name of [A-Za-z0-9_-], 1 to 64 long")
    })
}

fn check_frames(
    file: &Path,
    field: &str,
    frames: &[usize],
    count: usize,
) -> Result<(), CaptureError> {
    for (i, &f) in frames.iter().enumerate() {
        if f >= count {
            return Err(CaptureError::invalid(
                file,
                format!("{field}[{i}]"),
                format!("frame {f} >= frame_count {count}"),
            ));
        }
        if frames[..i].contains(&f) {
            return Err(CaptureError::invalid(
                file,
                format!("{field}[{i}]"),
                format!("frame {f} listed twice"),
            ));
        }
    }
    Ok(())
}

/// Reads and validates the capture in `dir` (see the module docs for the layout).
pub fn load_capture(dir: impl AsRef<Path>) -> Result<Capture, CaptureError> {
    let dir = dir.as_ref().to_owned();
    let mfile = dir.join(MANIFEST_FILE);
    let manifest: CaptureManifest = read_json(&mfile)?;
    let m = &manifest;
    if m.format != CAPTURE_FORMAT {
        return Err(CaptureError::invalid(
            &mfile,
            "format",
            format!("`{}` is not `{CAPTURE_FORMAT}`", m.format),
        ));
    }
    if m.version != CAPTURE_VERSION {
        return Err(CaptureError::invalid(
            &mfile,
            "version",
            format!("version {} is not {CAPTURE_VERSION}", m.version),
        ));
    }
    let up_axis = match m.up_axis.as_str() {
        "y" => UpAxis::Y,
        "z" => UpAxis::Z,
        other => {
            return Err(CaptureError::invalid(
                &mfile,
                "up_axis",
                format!("`{other}` is not `y` or `z`"),
            ));
        }
    };
    if m.cameras.is_empty() || m.cameras.len() > MAX_CAMERAS {
        return Err(CaptureError::invalid(
            &mfile,
            "cameras",
            format!("{} cameras (1 to {MAX_CAMERAS} allowed)", m.cameras.len()),
        ));
    }
    let mut rig = CameraRig::default();
    for (i, c) in m.cameras.iter().enumerate() {
        check_name(&mfile, &format!("cameras[{i}].name"), &c.name)?;
        if m.cameras[..i].iter().any(|o| o.name == c.name) {
            return Err(CaptureError::invalid(
                &mfile,
                format!("cameras[{i}].name"),
                format!("`{}` appears twice", c.name),
            ));
        }
        let cam = c.to_camera();
        cam.validate()
            .map_err(|e| CaptureError::invalid(&mfile, format!("cameras[{i}]"), e))?;
        rig.cameras.push(cam);
    }
    for (field, rel) in [
        ("template", &m.template),
        ("images", &m.images),
        ("masks", &m.masks),
    ] {
        check_relative(&mfile, field, rel)?;
    }
    if let Some(rel) = &m.motion {
        check_relative(&mfile, "motion", rel)?;
    }
    if let Some(rel) = &m.initial_weights {
        check_relative(&mfile, "initial_weights", rel)?;
    }
    if let Some(rel) = &m.keypoints {
        check_relative(&mfile, "keypoints", rel)?;
    }
    if let Some(l) = &m.labels {
        check_relative(&mfile, "labels.folder", &l.folder)?;
        validate_palette(&mfile, "labels.palette", &l.palette)?;
        check_frames(&mfile, "labels.frames", &l.frames, m.frame_count)?;
    }
    if let Some(f) = m.canonical_frame
        && f >= m.frame_count
    {
        return Err(CaptureError::invalid(
            &mfile,
            "canonical_frame",
            format!("frame {f} >= frame_count {}", m.frame_count),
        ));
    }
    if let Some(e) = &m.evaluation {
        check_relative(&mfile, "evaluation.gt_meshes", &e.gt_meshes)?;
        if let Some(rel) = &e.true_weights {
            check_relative(&mfile, "evaluation.true_weights", rel)?;
        }
    }
    if m.frame_count == 0 || m.frame_count > MAX_FRAMES {
        return Err(CaptureError::invalid(
            &mfile,
            "frame_count",
            format!("{} frames (1 to {MAX_FRAMES} allowed)", m.frame_count),
        ));
    }
    check_frames(&mfile, "train_frames", &m.train_frames, m.frame_count)?;
    check_frames(&mfile, "test_frames", &m.test_frames, m.frame_count)?;
    if m.train_frames.is_empty() {
        return Err(CaptureError::invalid(
            &mfile,
            "train_frames",
            "no training frames",
        ));
    }
    if let Some(f) = m.test_frames.iter().find(|f| m.train_frames.contains(f)) {
        return Err(CaptureError::invalid(
            &mfile,
            "test_frames",
            format!("frame {f} is also a training frame"),
        ));
    }
    for (i, clip) in m.clips.iter().enumerate() {
        let end = clip.first.checked_add(clip.count);
        if clip.count == 0 || end.is_none_or(|e| e > m.frame_count) {
            return Err(CaptureError::invalid(
                &mfile,
                format!("clips[{i}]"),
                "frame range empty or past frame_count",
            ));
        }
    }

    let tfile = dir.join(&m.template);
    let tf: TemplateFile = read_json(&tfile)?;
    let template = tf.to_template(&tfile)?;
    let skeleton = tf.skeleton.to_skeleton(&tfile)?;

    let initial_weights = match &m.initial_weights {
        Some(rel) => {
            let path = dir.join(rel);
            let sf: SkinFile = read_json(&path)?;
            Some(sf.to_skin(&path, template.vertex_count(), skeleton.len())?)
        }
        None => None,
    };

    let (poses, motion_fps) = match &m.motion {
        Some(rel) => {
            let motion_file = dir.join(rel);
            let motion: MotionFile = read_json(&motion_file)?;
            let poses = motion.to_poses(&motion_file, &skeleton)?;
            if poses.len() != m.frame_count {
                return Err(CaptureError::invalid(
                    &motion_file,
                    "frames",
                    format!(
                        "{} frames, but the manifest's frame_count is {}",
                        poses.len(),
                        m.frame_count
                    ),
                ));
            }
            (poses, Some(motion.fps))
        }
        None => (vec![skeleton.bind_pose(); m.frame_count], None),
    };

    let capture = Capture {
        train_frames: m.train_frames.clone(),
        test_frames: m.test_frames.clone(),
        dir,
        rig,
        template,
        skeleton,
        up_axis,
        initial_weights,
        poses,
        motion_fps,
        manifest,
    };
    // Every image and mask must exist; reading them stays lazy.
    let used: Vec<usize> = capture
        .train_frames
        .iter()
        .chain(&capture.test_frames)
        .chain(&capture.manifest.canonical_frame)
        .copied()
        .collect();
    let labelled = capture.manifest.labels.as_ref().map(|l| l.frames.clone());
    for cam in 0..capture.rig.cameras.len() {
        let images = used
            .iter()
            .flat_map(|&f| [capture.image_path(cam, f), capture.mask_path(cam, f)]);
        let labels = labelled
            .iter()
            .flatten()
            .filter_map(|&f| capture.label_path(cam, f));
        for path in images.chain(labels) {
            if !path.is_file() {
                return Err(CaptureError::BadFile {
                    file: path,
                    reason: "missing (listed by manifest.json)".into(),
                });
            }
        }
    }
    Ok(capture)
}
