//! 2D keypoint detections of a capture, in OpenPose's JSON (the de facto exchange format of
//! off-the-shelf detectors), and the map from keypoint names to skeleton landmarks.
//!
//! # Layout
//!
//! ```text
//! {keypoints}/landmarks.json                    LandmarkMapFile: detector format, keypoint names,
//!                                               and which joint (plus a local offset) each one is
//! {keypoints}/{camera}/{frame:05}_keypoints.json  OpenPose output for one image:
//!     {"version": 1.3, "people": [{"pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, …]}]}
//! ```
//!
//! `{keypoints}` is the manifest's optional `keypoints` folder. Pixel coordinates follow the
//! capture's camera convention (pixel centres at integer + 0.5); OpenPose writes `0, 0, 0` for a
//! keypoint it did not find, read here as no detection. When an image holds several people the
//! one with the largest summed confidence is the subject (a capture studio films one person).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::write::write_file;
use super::{Capture, CaptureError, CaptureWriter, MAX_JSON_BYTES, read_json};

/// OpenPose's BODY_25 keypoint names, in its order.
pub const BODY_25: [&str; 25] = [
    "Nose",
    "Neck",
    "RShoulder",
    "RElbow",
    "RWrist",
    "LShoulder",
    "LElbow",
    "LWrist",
    "MidHip",
    "RHip",
    "RKnee",
    "RAnkle",
    "LHip",
    "LKnee",
    "LAnkle",
    "REye",
    "LEye",
    "REar",
    "LEar",
    "LBigToe",
    "LSmallToe",
    "LHeel",
    "RBigToe",
    "RSmallToe",
    "RHeel",
];

/// Most keypoints per person a file may declare (a cap against hostile files; OpenPose's
/// largest model, with hands and face, has 135).
pub const MAX_KEYPOINTS: usize = 1024;
/// Most people per detection file.
pub const MAX_PEOPLE: usize = 256;

/// `{keypoints}/landmarks.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandmarkMapFile {
    /// Always `skinfield-landmarks`.
    pub format: String,
    /// The detector's keypoint layout, e.g. `BODY_25`.
    pub detector: String,
    /// The detector's keypoint names, in its output order.
    pub keypoints: Vec<String>,
    /// The keypoints the tracker uses, each tied to a joint.
    pub landmarks: Vec<LandmarkEntry>,
}

/// One keypoint tied to the skeleton.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandmarkEntry {
    /// Keypoint name (one of [`LandmarkMapFile::keypoints`]).
    pub keypoint: String,
    /// Skeleton joint name.
    pub joint: String,
    /// Offset from the joint in its local frame (skeleton units).
    #[serde(default)]
    pub offset: [f32; 3],
}

/// One detected keypoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keypoint2d {
    /// Pixel x.
    pub x: f32,
    /// Pixel y.
    pub y: f32,
    /// Confidence in `[0, 1]`.
    pub confidence: f32,
}

#[derive(Serialize, Deserialize)]
struct OpenPoseFile {
    #[serde(default)]
    version: Option<f32>,
    people: Vec<OpenPosePerson>,
}

#[derive(Serialize, Deserialize)]
struct OpenPosePerson {
    pose_keypoints_2d: Vec<f32>,
}

/// Path of one image's detections.
#[must_use]
pub fn keypoints_file(dir: &Path, folder: &str, camera: &str, frame: usize) -> PathBuf {
    dir.join(folder)
        .join(camera)
        .join(format!("{frame:05}_keypoints.json"))
}

/// Parses one OpenPose file (`file` names it in errors): the subject's `keypoint_count`
/// keypoints, `None` where it found none. A file without people yields all `None`.
pub fn parse_openpose(
    file: &Path,
    bytes: &[u8],
    keypoint_count: usize,
) -> Result<Vec<Option<Keypoint2d>>, CaptureError> {
    if keypoint_count > MAX_KEYPOINTS {
        return Err(CaptureError::invalid(
            file,
            "keypoints",
            format!("{keypoint_count} keypoints, more than {MAX_KEYPOINTS}"),
        ));
    }
    let parsed: OpenPoseFile =
        serde_json::from_slice(bytes).map_err(|source| CaptureError::Json {
            file: file.to_owned(),
            source,
        })?;
    if parsed.people.len() > MAX_PEOPLE {
        return Err(CaptureError::invalid(
            file,
            "people",
            format!("{} people, more than {MAX_PEOPLE}", parsed.people.len()),
        ));
    }
    let expected = keypoint_count * 3;
    let mut best: Option<(f32, &OpenPosePerson)> = None;
    for (i, p) in parsed.people.iter().enumerate() {
        let field = || format!("people[{i}].pose_keypoints_2d");
        if p.pose_keypoints_2d.len() != expected {
            return Err(CaptureError::invalid(
                file,
                field(),
                format!(
                    "{} numbers, expected {expected} (x, y, confidence for {keypoint_count} keypoints)",
                    p.pose_keypoints_2d.len()
                ),
            ));
        }
        for (k, v) in p.pose_keypoints_2d.chunks_exact(3).enumerate() {
            if !v.iter().all(|x| x.is_finite()) {
                return Err(CaptureError::invalid(
                    file,
                    format!("{}[{}]", field(), 3 * k),
                    "not a finite number",
                ));
            }
            if !(0.0..=1.0).contains(&v[2]) {
                return Err(CaptureError::invalid(
                    file,
                    format!("{}[{}]", field(), 3 * k + 2),
                    format!("confidence {} outside [0, 1]", v[2]),
                ));
            }
        }
        let total: f32 = p.pose_keypoints_2d.chunks_exact(3).map(|v| v[2]).sum();
        if best.is_none_or(|(t, _)| total > t) {
            best = Some((total, p));
        }
    }
    Ok(match best {
        None => vec![None; keypoint_count],
        Some((_, p)) => p
            .pose_keypoints_2d
            .chunks_exact(3)
            .map(|v| {
                (v[2] > 0.0).then_some(Keypoint2d {
                    x: v[0],
                    y: v[1],
                    confidence: v[2],
                })
            })
            .collect(),
    })
}

/// Serialises one person's keypoints as an OpenPose file (`None`: `0, 0, 0`).
pub fn openpose_json(keypoints: &[Option<Keypoint2d>]) -> Vec<u8> {
    let values = keypoints
        .iter()
        .flat_map(|k| match k {
            Some(k) => [k.x, k.y, k.confidence],
            None => [0.0; 3],
        })
        .collect();
    let file = OpenPoseFile {
        version: Some(1.3),
        people: vec![OpenPosePerson {
            pose_keypoints_2d: values,
        }],
    };
    serde_json::to_vec(&file).expect("plain numbers serialise")
}

/// Checks a landmark map against the skeleton's joint names (`file` names it in errors).
pub fn validate_landmarks(
    file: &Path,
    map: &LandmarkMapFile,
    joints: &[String],
) -> Result<(), CaptureError> {
    if map.format != "skinfield-landmarks" {
        return Err(CaptureError::invalid(
            file,
            "format",
            format!("`{}`, expected `skinfield-landmarks`", map.format),
        ));
    }
    if map.keypoints.is_empty() || map.keypoints.len() > MAX_KEYPOINTS {
        return Err(CaptureError::invalid(
            file,
            "keypoints",
            format!(
                "{} names, expected 1..={MAX_KEYPOINTS}",
                map.keypoints.len()
            ),
        ));
    }
    for (i, l) in map.landmarks.iter().enumerate() {
        if !map.keypoints.contains(&l.keypoint) {
            return Err(CaptureError::invalid(
                file,
                format!("landmarks[{i}].keypoint"),
                format!("`{}` is not one of the detector's keypoints", l.keypoint),
            ));
        }
        if !joints.contains(&l.joint) {
            return Err(CaptureError::invalid(
                file,
                format!("landmarks[{i}].joint"),
                format!("`{}` is not a joint of the skeleton", l.joint),
            ));
        }
        if !l.offset.iter().all(|x| x.is_finite()) {
            return Err(CaptureError::invalid(
                file,
                format!("landmarks[{i}].offset"),
                "not finite",
            ));
        }
    }
    Ok(())
}

/// File name of the landmark map inside the keypoints folder.
pub const LANDMARKS_FILE: &str = "landmarks.json";

impl Capture {
    /// The capture's landmark map, validated against its skeleton; `None` when the capture has
    /// no keypoints.
    pub fn landmark_map(&self) -> Result<Option<LandmarkMapFile>, CaptureError> {
        let Some(folder) = &self.manifest.keypoints else {
            return Ok(None);
        };
        let file = self.dir.join(folder).join(LANDMARKS_FILE);
        let map: LandmarkMapFile = read_json(&file)?;
        validate_landmarks(&file, &map, self.skeleton.names())?;
        Ok(Some(map))
    }

    /// The detections of camera `cam` at `frame` (`keypoint_count` = the map's keypoints);
    /// a missing file means nothing was detected in that image.
    pub fn keypoints(
        &self,
        cam: usize,
        frame: usize,
        keypoint_count: usize,
    ) -> Result<Vec<Option<Keypoint2d>>, CaptureError> {
        let folder = self.manifest.keypoints.as_deref().ok_or_else(|| {
            CaptureError::invalid(
                &self.dir.join(super::MANIFEST_FILE),
                "keypoints",
                "the capture has no keypoints",
            )
        })?;
        let camera = &self
            .rig
            .cameras
            .get(cam)
            .ok_or_else(|| {
                CaptureError::invalid(
                    &self.dir.join(super::MANIFEST_FILE),
                    "cameras",
                    format!("camera index {cam} out of range"),
                )
            })?
            .name;
        let file = keypoints_file(&self.dir, folder, camera, frame);
        let io = |source| CaptureError::Io {
            file: file.clone(),
            source,
        };
        let len = match std::fs::metadata(&file) {
            Ok(m) => m.len(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(vec![None; keypoint_count]);
            }
            Err(e) => return Err(io(e)),
        };
        if len > MAX_JSON_BYTES {
            return Err(CaptureError::BadFile {
                file,
                reason: format!("{len} bytes, more than {MAX_JSON_BYTES}"),
            });
        }
        let bytes = std::fs::read(&file).map_err(io)?;
        parse_openpose(&file, &bytes, keypoint_count)
    }
}

impl CaptureWriter {
    /// Writes the landmark map into the manifest's `keypoints` folder (which must be set).
    pub fn write_landmark_map(&self, map: &LandmarkMapFile) -> Result<(), CaptureError> {
        let folder = self.keypoints_folder()?;
        let path = self.dir().join(folder).join(LANDMARKS_FILE);
        let bytes = serde_json::to_vec_pretty(map).map_err(|source| CaptureError::Json {
            file: path.clone(),
            source,
        })?;
        write_file(&path, &bytes)
    }

    /// Writes the detections of camera `cam` at `frame` as an OpenPose file.
    pub fn write_keypoints(
        &self,
        cam: usize,
        frame: usize,
        keypoints: &[Option<Keypoint2d>],
    ) -> Result<(), CaptureError> {
        let folder = self.keypoints_folder()?;
        let camera = &self.camera(cam)?.name;
        write_file(
            &keypoints_file(self.dir(), folder, camera, frame),
            &openpose_json(keypoints),
        )
    }

    fn keypoints_folder(&self) -> Result<&str, CaptureError> {
        self.manifest().keypoints.as_deref().ok_or_else(|| {
            CaptureError::invalid(
                &self.dir().join(super::MANIFEST_FILE),
                "keypoints",
                "not set in the manifest given to the writer",
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<Option<Keypoint2d>> {
        vec![
            Some(Keypoint2d {
                x: 10.5,
                y: 20.25,
                confidence: 0.9,
            }),
            None,
            Some(Keypoint2d {
                x: 1.0,
                y: 2.0,
                confidence: 0.3,
            }),
        ]
    }

    #[test]
    fn round_trip_and_subject_choice() {
        let bytes = openpose_json(&sample());
        let f = Path::new("a.json");
        assert_eq!(parse_openpose(f, &bytes, 3).unwrap(), sample());
        // Two people: the more confident one is the subject.
        let two = br#"{"people":[{"pose_keypoints_2d":[1,1,0.1,2,2,0.1,3,3,0.1]},
                       {"pose_keypoints_2d":[4,4,0.9,0,0,0,6,6,0.8]}]}"#;
        let got = parse_openpose(f, two, 3).unwrap();
        assert_eq!(got[0].unwrap().x, 4.0);
        assert!(got[1].is_none());
        assert_eq!(
            parse_openpose(f, br#"{"people":[]}"#, 3).unwrap(),
            vec![None; 3]
        );
    }

    #[test]
    fn every_bad_file_is_a_typed_error_naming_the_field() {
        let f = Path::new("cam00/00003_keypoints.json");
        let field_of = |bytes: &[u8], n: usize| match parse_openpose(f, bytes, n) {
            Err(CaptureError::Invalid { field, file, .. }) => {
                assert_eq!(file, f);
                field
            }
            other => panic!("{other:?}"),
        };
        assert_eq!(
            field_of(br#"{"people":[{"pose_keypoints_2d":[1,2,0.5,1]}]}"#, 1),
            "people[0].pose_keypoints_2d"
        );
        assert_eq!(
            field_of(br#"{"people":[{"pose_keypoints_2d":[1,2,1.5]}]}"#, 1),
            "people[0].pose_keypoints_2d[2]"
        );
        assert_eq!(field_of(b"{\"people\":[]}", MAX_KEYPOINTS + 1), "keypoints");
        assert!(matches!(
            parse_openpose(f, b"{\"people\":", 1),
            Err(CaptureError::Json { .. })
        ));
        // Every truncated prefix of a valid file is an error, never a panic.
        let bytes = openpose_json(&sample());
        for n in 0..bytes.len() {
            assert!(parse_openpose(f, &bytes[..n], 3).is_err(), "prefix {n}");
        }
    }

    #[test]
    fn landmark_maps_are_checked_against_the_skeleton() {
        let f = Path::new("landmarks.json");
        let joints = vec!["pelvis".to_owned(), "head".to_owned()];
        let mut map = LandmarkMapFile {
            format: "skinfield-landmarks".into(),
            detector: "BODY_25".into(),
            keypoints: BODY_25.iter().map(|s| (*s).to_owned()).collect(),
            landmarks: vec![LandmarkEntry {
                keypoint: "MidHip".into(),
                joint: "pelvis".into(),
                offset: [0.0; 3],
            }],
        };
        validate_landmarks(f, &map, &joints).unwrap();
        map.landmarks[0].joint = "tail".into();
        assert!(matches!(
            validate_landmarks(f, &map, &joints),
            Err(CaptureError::Invalid { field, .. }) if field == "landmarks[0].joint"
        ));
        map.landmarks[0].joint = "pelvis".into();
        map.landmarks[0].keypoint = "Tail".into();
        assert!(matches!(
            validate_landmarks(f, &map, &joints),
            Err(CaptureError::Invalid { field, .. }) if field == "landmarks[0].keypoint"
        ));
    }
}
