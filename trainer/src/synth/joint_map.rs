//! The joint map of `trainer synth --joint-map`: which joint of the motion's skeleton drives
//! which joint of the character's, for clips authored on another rig
//! ([`skinfield_formats::Retarget`]).
//!
//! The file is a JSON object with one member, `joints`, itself an object from character joint
//! names to motion joint names:
//!
//! ```json
//! {"joints": {"pelvis": "Body", "spine_01": "Abdomen", "thigh_l": "UpperLeg.L"}}
//! ```
//!
//! Character joints left out keep their rest rotation relative to their parent (fingers of a
//! character whose motion has none, twist helpers). Names are matched exactly.

use std::path::{Path, PathBuf};

use super::SynthError;

/// The largest joint-map file read (a map of a few hundred names is a few kilobytes).
pub const MAX_JOINT_MAP_BYTES: u64 = 1 << 20;

/// A joint map and where it came from (named in errors).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JointMap {
    /// The file, or a description of a map built into the program.
    pub origin: PathBuf,
    /// `(character joint, motion joint)` pairs, in the file's order.
    pub pairs: Vec<(String, String)>,
}

impl JointMap {
    /// Reads a joint map file.
    pub fn read(path: &Path) -> Result<Self, SynthError> {
        let error = |reason: String| SynthError::JointMap {
            path: path.to_path_buf(),
            reason,
        };
        let size = std::fs::metadata(path)
            .map_err(|e| error(e.to_string()))?
            .len();
        if size > MAX_JOINT_MAP_BYTES {
            return Err(error(format!(
                "{size} bytes, more than the {MAX_JOINT_MAP_BYTES} a joint map may have"
            )));
        }
        let text = std::fs::read_to_string(path).map_err(|e| error(e.to_string()))?;
        Self::parse(path.to_path_buf(), &text)
    }

    /// Parses the JSON text of a joint map (see the module docs); `origin` names it in errors.
    pub fn parse(origin: PathBuf, text: &str) -> Result<Self, SynthError> {
        match parse_pairs(text) {
            Ok(pairs) => Ok(Self { origin, pairs }),
            Err(reason) => Err(SynthError::JointMap {
                path: origin,
                reason,
            }),
        }
    }
}

fn parse_pairs(text: &str) -> Result<Vec<(String, String)>, String> {
    let value: serde_json::Value = serde_json::from_str(text).map_err(|e| e.to_string())?;
    let object = value
        .as_object()
        .ok_or("the file is not a JSON object".to_owned())?;
    if let Some(other) = object.keys().find(|k| *k != "joints") {
        return Err(format!("unknown field `{other}` (expected `joints`)"));
    }
    let joints = object
        .get("joints")
        .ok_or("missing field `joints`".to_owned())?
        .as_object()
        .ok_or("field `joints` is not an object of joint names".to_owned())?;
    if joints.is_empty() {
        return Err("field `joints` maps no joint".into());
    }
    joints
        .iter()
        .map(|(target, source)| {
            source
                .as_str()
                .map(|s| (target.clone(), s.to_owned()))
                .ok_or_else(|| format!("field `joints.{target}` is not a joint name (a string)"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_map_parses_into_pairs_and_every_malformed_one_is_named() {
        let pairs =
            parse_pairs(r#"{"joints": {"pelvis": "Body", "thigh_l": "UpperLeg.L"}}"#).unwrap();
        assert_eq!(pairs.len(), 2);
        assert!(pairs.contains(&("pelvis".into(), "Body".into())));
        for (text, says) in [
            ("[1, 2]", "not a JSON object"),
            ("{\"joints\": {}}", "maps no joint"),
            ("{}", "missing field `joints`"),
            ("{\"joints\": [\"a\"]}", "not an object"),
            ("{\"joints\": {\"a\": 1}}", "`joints.a` is not a joint name"),
            (
                "{\"joints\": {\"a\": \"b\"}, \"extra\": 1}",
                "unknown field `extra`",
            ),
            ("{\"joints\": ", "EOF"),
        ] {
            let e = parse_pairs(text).unwrap_err();
            assert!(e.contains(says), "{text}: {e}");
        }
    }

    #[test]
    fn a_missing_or_oversized_file_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("none.json");
        let e = JointMap::read(&missing).unwrap_err().to_string();
        assert!(e.contains("none.json"), "{e}");
        let big = dir.path().join("big.json");
        std::fs::write(&big, vec![b' '; MAX_JOINT_MAP_BYTES as usize + 1]).unwrap();
        let e = JointMap::read(&big).unwrap_err().to_string();
        assert!(e.contains("big.json") && e.contains("more than"), "{e}");
        let bad = dir.path().join("bad.json");
        std::fs::write(&bad, "{\"joints\": 3}").unwrap();
        let e = JointMap::read(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.json") && e.contains("`joints`"), "{e}");
    }
}
