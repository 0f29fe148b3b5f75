//! The static-weights file: learned pose-independent weights that `trainer eval
//! --weights static:FILE` scores (the "static learned weights" row of the paper's tables).
//!
//! JSON, joints named so that a file survives a skeleton whose joints are stored in another order:
//!
//! ```json
//! {
//!   "format": "skinfield-static-weights",
//!   "version": 1,
//!   "joints": ["hips", "spine", …],
//!   "vertex_count": 10234,
//!   "offsets": [0, 2, 5, …],
//!   "joint_indices": [0, 1, 0, 1, 4, …],
//!   "weights": [0.7, 0.3, …]
//! }
//! ```
//!
//! `offsets` (`vertex_count + 1` entries) delimit each vertex's influences in `joint_indices`
//! (indices into `joints`) and `weights`, as in [`StaticSkin`]. Weights are normalised on read.

use std::path::{Path, PathBuf};

use skinfield_formats::skf::write_atomic;
use skinfield_formats::{MAX_JOINTS, Skeleton, SkinError, StaticSkin};

/// Value of the `format` field.
pub const STATIC_WEIGHTS_FORMAT: &str = "skinfield-static-weights";
/// The version this reader writes and understands.
pub const STATIC_WEIGHTS_VERSION: u32 = 1;
/// Largest file read (bytes): 16 M vertices × a few influences fits with room.
pub const MAX_STATIC_WEIGHTS_BYTES: u64 = 1 << 30;

#[derive(serde::Serialize, serde::Deserialize)]
struct StaticWeightsFile {
    format: String,
    version: u32,
    joints: Vec<String>,
    vertex_count: usize,
    offsets: Vec<u32>,
    joint_indices: Vec<u32>,
    weights: Vec<f32>,
}

/// Why a static-weights file could not be read or written, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum StaticWeightsError {
    /// The file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not JSON of the expected shape.
    #[error("{}: {source}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// serde_json's message (line and column).
        source: serde_json::Error,
    },
    /// A field has a wrong value.
    #[error("{}: field `{field}`: {reason}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The CSR arrays are inconsistent.
    #[error("{}: fields `offsets`/`joint_indices`/`weights`: {source}", path.display())]
    Skin {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: SkinError,
    },
}

/// Writes `skin` (whose joint indices follow `skeleton`) atomically.
pub fn write_static_weights(
    path: &Path,
    skeleton: &Skeleton,
    skin: &StaticSkin,
) -> Result<(), StaticWeightsError> {
    if skin.joint_count() != skeleton.len() {
        return Err(StaticWeightsError::Invalid {
            path: path.to_owned(),
            field: "joints",
            reason: format!(
                "skin has {} joints, skeleton {}",
                skin.joint_count(),
                skeleton.len()
            ),
        });
    }
    let file = StaticWeightsFile {
        format: STATIC_WEIGHTS_FORMAT.into(),
        version: STATIC_WEIGHTS_VERSION,
        joints: skeleton.names().to_vec(),
        vertex_count: skin.vertex_count(),
        offsets: skin.offsets().to_vec(),
        joint_indices: skin.joints().to_vec(),
        weights: skin.weights().to_vec(),
    };
    let bytes = serde_json::to_vec(&file).map_err(|source| StaticWeightsError::Json {
        path: path.to_owned(),
        source,
    })?;
    write_atomic(path, &bytes).map_err(|source| StaticWeightsError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Reads a static-weights file for a mesh of `vertex_count` vertices and re-indexes its joints
/// into `skeleton`'s order by name. Joints of the skeleton that the file does not name get no
/// weight; a file joint the skeleton lacks is an error.
pub fn read_static_weights(
    path: &Path,
    skeleton: &Skeleton,
    vertex_count: usize,
) -> Result<StaticSkin, StaticWeightsError> {
    let io = |source| StaticWeightsError::Io {
        path: path.to_owned(),
        source,
    };
    let invalid = |field, reason: String| StaticWeightsError::Invalid {
        path: path.to_owned(),
        field,
        reason,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_STATIC_WEIGHTS_BYTES {
        return Err(invalid(
            "(file)",
            format!("{len} bytes, more than {MAX_STATIC_WEIGHTS_BYTES}"),
        ));
    }
    let bytes = std::fs::read(path).map_err(io)?;
    let file: StaticWeightsFile =
        serde_json::from_slice(&bytes).map_err(|source| StaticWeightsError::Json {
            path: path.to_owned(),
            source,
        })?;
    if file.format != STATIC_WEIGHTS_FORMAT {
        return Err(invalid(
            "format",
            format!("`{}`, expected `{STATIC_WEIGHTS_FORMAT}`", file.format),
        ));
    }
    if file.version != STATIC_WEIGHTS_VERSION {
        return Err(invalid(
            "version",
            format!(
                "{}, this reader understands {STATIC_WEIGHTS_VERSION}",
                file.version
            ),
        ));
    }
    if file.joints.is_empty() || file.joints.len() > MAX_JOINTS {
        return Err(invalid(
            "joints",
            format!("{} joints, expected 1 to {MAX_JOINTS}", file.joints.len()),
        ));
    }
    if file.vertex_count != vertex_count {
        return Err(invalid(
            "vertex_count",
            format!("{}, the template has {vertex_count}", file.vertex_count),
        ));
    }
    if file.offsets.len() != vertex_count + 1 {
        return Err(invalid(
            "offsets",
            format!(
                "{} entries, expected vertex_count + 1 = {}",
                file.offsets.len(),
                vertex_count + 1
            ),
        ));
    }
    let mut remap = Vec::with_capacity(file.joints.len());
    for name in &file.joints {
        let j = skeleton
            .find(name)
            .ok_or_else(|| invalid("joints", format!("joint `{name}` is not in the skeleton")))?;
        if remap.contains(&(j as u32)) {
            return Err(invalid("joints", format!("joint `{name}` listed twice")));
        }
        remap.push(j as u32);
    }
    let mut joints = Vec::with_capacity(file.joint_indices.len());
    for &k in &file.joint_indices {
        let j = remap.get(k as usize).ok_or_else(|| {
            invalid(
                "joint_indices",
                format!("index {k} but only {} joints are named", remap.len()),
            )
        })?;
        joints.push(*j);
    }
    StaticSkin::new(file.offsets, joints, file.weights, skeleton.len()).map_err(|source| {
        StaticWeightsError::Skin {
            path: path.to_owned(),
            source,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat4;
    use skinfield_formats::Transform;

    fn skeleton(names: &[&str]) -> Skeleton {
        let n = names.len();
        Skeleton::new(
            names.iter().map(|s| (*s).to_string()).collect(),
            (0..n).map(|j| j.checked_sub(1)).collect(),
            vec![Transform::IDENTITY; n],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap()
    }

    #[test]
    fn round_trips_and_remaps_joints_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.json");
        let a = skeleton(&["a", "b", "c"]);
        let skin = StaticSkin::from_dense(&[0.25, 0.75, 0.0, 0.0, 0.0, 1.0], 3).unwrap();
        write_static_weights(&path, &a, &skin).unwrap();
        assert_eq!(
            read_static_weights(&path, &a, 2).unwrap().to_dense(),
            skin.to_dense()
        );
        // The same joints stored in another order (still topological: all are chains here, so
        // just the names move): weights follow the names, not the indices.
        let b = skeleton(&["c", "a", "b"]);
        let back = read_static_weights(&path, &b, 2).unwrap();
        assert_eq!(back.to_dense(), vec![0.0, 0.25, 0.75, 1.0, 0.0, 0.0]);
    }

    #[test]
    fn names_the_file_and_field_of_every_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.json");
        let a = skeleton(&["a", "b"]);
        let write = |s: &str| std::fs::write(&path, s).unwrap();
        let base = |joints: &str, vc: usize, off: &str, ji: &str, w: &str| {
            format!(
                r#"{{"format":"skinfield-static-weights","version":1,"joints":{joints},"vertex_count":{vc},"offsets":{off},"joint_indices":{ji},"weights":{w}}}"#
            )
        };
        let cases = [
            (
                base(r#"["a"]"#, 2, "[0,1,2]", "[0,0]", "[1,1]"),
                "vertex_count",
            ),
            (base(r#"["a"]"#, 1, "[0,1,2]", "[0,0]", "[1,1]"), "offsets"),
            (base(r#"["z"]"#, 1, "[0,1]", "[0]", "[1]"), "joints"),
            (base(r#"["a","a"]"#, 1, "[0,1]", "[0]", "[1]"), "joints"),
            (base("[]", 1, "[0,1]", "[0]", "[1]"), "joints"),
            (base(r#"["a"]"#, 1, "[0,1]", "[3]", "[1]"), "joint_indices"),
            (base(r#"["a"]"#, 1, "[0,1]", "[0]", "[-1]"), "weights"),
            (
                base(r#"["a"]"#, 1, "[0,1]", "[0]", "[1]")
                    .replace("skinfield-static-weights", "other"),
                "format",
            ),
        ];
        for (text, field) in cases {
            write(&text);
            let e = read_static_weights(&path, &a, 1).unwrap_err().to_string();
            assert!(e.contains("w.json") && e.contains(field), "{field}: {e}");
        }
        write("{not json");
        assert!(matches!(
            read_static_weights(&path, &a, 1),
            Err(StaticWeightsError::Json { .. })
        ));
        assert!(matches!(
            read_static_weights(&dir.path().join("missing"), &a, 1),
            Err(StaticWeightsError::Io { .. })
        ));
    }
}
