//! The MakeHuman base body: Wavefront OBJ mesh, `.mhskel` JSON skeleton and `.mhw` JSON
//! weights, read into a [`Template`], a [`Skeleton`] and a [`StaticSkin`].
//!
//! A `.mhskel` stores no joint positions: every bone names a head and a tail *joint*, and a joint
//! is the centroid of a list of OBJ vertex indices (the `joint-*` helper cubes of `base.obj`).
//! A bone's rotation plane names three joints. The OBJ is in decimetres; positions are scaled by
//! [`MakeHumanOptions::scale`] (0.1 by default, giving metres).
//!
//! Choices made here (MakeHuman's own code is AGPL and was not consulted):
//! - Joint `j` of the [`Skeleton`] is bone `j`, placed at the bone's head. Joints are ordered by a
//!   depth-first walk from the roots, children in name order (parents before children).
//! - The bind frame of a bone has local +Y along head → tail (Blender's convention) and local +X
//!   along the rotation plane's normal made orthogonal to +Y; the frame only fixes what "zero
//!   rotation" means for pose angles and has no effect on skinning.
//! - Only the OBJ vertices used by faces of the selected groups become template vertices, in OBJ
//!   order; [`MakeHumanAsset::obj_vertex`] maps them back. Texture coordinates are per face
//!   corner in the OBJ and are not carried (the template's `uvs` is `None`); normals are
//!   area-weighted from the triangles. Polygons are fan-triangulated.
//! - `.mhw` weights are not normalised in the file (sums 0.32–1.67); [`StaticSkin::new`]
//!   normalises them and counts how many were off.

use std::path::Path;

use glam::Vec3;

use crate::mesh::Template;
use crate::skeleton::Skeleton;
use crate::skin::StaticSkin;

mod error;
mod mhskel;
mod mhw;
mod obj;
pub use error::MakeHumanError;
use mhskel::read_skeleton;
use mhw::read_weights;
use obj::parse_obj;

/// Largest file this reader opens (bytes); `base.obj` is about 2 MiB.
pub const MAX_FILE_BYTES: u64 = 256 << 20;
/// Most triangles a read mesh may have.
pub const MAX_TRIANGLES: usize = 1 << 24;
/// Most vertices one OBJ polygon may list.
pub const MAX_POLYGON_CORNERS: usize = 64;

/// What to read.
#[derive(Clone, Debug)]
pub struct MakeHumanOptions {
    /// OBJ groups (`g NAME`) whose faces form the template; empty selects every group.
    pub groups: Vec<String>,
    /// Factor from file units to metres (the hm08 files are in decimetres: 0.1).
    pub scale: f32,
}

impl Default for MakeHumanOptions {
    fn default() -> Self {
        Self {
            groups: vec!["body".to_owned()],
            scale: 0.1,
        }
    }
}

/// A loaded MakeHuman character.
#[derive(Clone, Debug)]
pub struct MakeHumanAsset {
    /// The mesh of the selected groups (metres).
    pub template: Template,
    /// One joint per bone, at the bone's head.
    pub skeleton: Skeleton,
    /// The `.mhw` weights of the template's vertices, normalised.
    pub skin: StaticSkin,
    /// World bind-pose tail of every bone (metres), joint order.
    pub bone_tails: Vec<Vec3>,
    /// OBJ vertex index (0-based) of each template vertex.
    pub obj_vertex: Vec<u32>,
    /// Number of vertices in the whole OBJ.
    pub obj_vertex_count: usize,
    /// Number of polygons in the whole OBJ.
    pub obj_face_count: usize,
    /// Distinct group names in the OBJ, in first-appearance order.
    pub obj_groups: Vec<String>,
}

/// Reads `base.obj`, `default.mhskel` and `default_weights.mhw` from `dir`.
pub fn load_makehuman_dir(
    dir: &Path,
    options: &MakeHumanOptions,
) -> Result<MakeHumanAsset, MakeHumanError> {
    load_makehuman(
        &dir.join("base.obj"),
        &dir.join("default.mhskel"),
        &dir.join("default_weights.mhw"),
        options,
    )
}

/// One file of an asset, already read: its path (named in errors) and its text.
#[derive(Clone, Copy, Debug)]
pub struct SourceText<'a> {
    /// Where the text came from; errors name it.
    pub path: &'a Path,
    /// The file's contents.
    pub text: &'a str,
}

/// Reads a MakeHuman OBJ, skeleton and weights.
pub fn load_makehuman(
    obj: &Path,
    mhskel: &Path,
    mhw: &Path,
    options: &MakeHumanOptions,
) -> Result<MakeHumanAsset, MakeHumanError> {
    let (obj_text, skel_text, mhw_text) = (read_text(obj)?, read_text(mhskel)?, read_text(mhw)?);
    parse_makehuman(
        SourceText {
            path: obj,
            text: &obj_text,
        },
        SourceText {
            path: mhskel,
            text: &skel_text,
        },
        SourceText {
            path: mhw,
            text: &mhw_text,
        },
        options,
    )
}

/// Parses a MakeHuman OBJ, skeleton and weights from their texts (what [`load_makehuman`] does
/// after reading the files; untrusted text gives a typed error naming the file, never a panic).
pub fn parse_makehuman(
    obj: SourceText<'_>,
    mhskel: SourceText<'_>,
    mhw: SourceText<'_>,
    options: &MakeHumanOptions,
) -> Result<MakeHumanAsset, MakeHumanError> {
    let parsed = parse_obj(obj.path, obj.text)?;
    let selected: Vec<bool> = parsed
        .group_names
        .iter()
        .map(|g| options.groups.is_empty() || options.groups.iter().any(|s| s == g))
        .collect();
    let nv = parsed.positions.len();
    let mut used = vec![false; nv];
    for (poly, &g) in parsed.polygons.iter().zip(&parsed.polygon_group) {
        if selected[g] {
            for &v in poly {
                used[v as usize] = true;
            }
        }
    }
    let obj_vertex: Vec<u32> = (0..nv as u32).filter(|&v| used[v as usize]).collect();
    let mut remap = vec![u32::MAX; nv];
    for (t, &o) in obj_vertex.iter().enumerate() {
        remap[o as usize] = t as u32;
    }
    let mut triangles = Vec::new();
    for (poly, &g) in parsed.polygons.iter().zip(&parsed.polygon_group) {
        if selected[g] {
            for k in 1..poly.len() - 1 {
                triangles.push([poly[0], poly[k], poly[k + 1]].map(|v| remap[v as usize]));
            }
        }
    }
    let mut template = Template {
        positions: obj_vertex
            .iter()
            .map(|&o| parsed.positions[o as usize] * options.scale)
            .collect(),
        triangles,
        ..Default::default()
    };
    template.compute_normals();
    template.validate().map_err(|source| MakeHumanError::Mesh {
        path: obj.path.to_owned(),
        source,
    })?;

    let (skeleton, bone_tails) = read_skeleton(mhskel, &parsed.positions, options.scale)?;
    let skin = read_weights(mhw, &skeleton, &remap, obj_vertex.len())?;
    Ok(MakeHumanAsset {
        template,
        skeleton,
        skin,
        bone_tails,
        obj_vertex,
        obj_vertex_count: nv,
        obj_face_count: parsed.polygons.len(),
        obj_groups: parsed.group_names,
    })
}

fn read_text(path: &Path) -> Result<String, MakeHumanError> {
    let io = |source| MakeHumanError::Io {
        path: path.to_owned(),
        source,
    };
    let bytes = std::fs::metadata(path).map_err(io)?.len();
    if bytes > MAX_FILE_BYTES {
        return Err(MakeHumanError::TooLarge {
            path: path.to_owned(),
            bytes,
        });
    }
    std::fs::read_to_string(path).map_err(io)
}

/// The JSON of `source`, or an error naming its file.
fn parse_json(source: SourceText<'_>) -> Result<serde_json::Value, MakeHumanError> {
    serde_json::from_str(source.text).map_err(|e| MakeHumanError::Json {
        path: source.path.to_owned(),
        source: e,
    })
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    const OBJ: &str = "v 0 0 0\nv 10 0 0\nv 10 10 0\nv 0 10 0\nv 0 20 0\ng body\nf 1/1 2/2 3/3 4/4\ng other\nf 1 3 5\n";
    const SKEL: &str = r#"{"bones": {
        "root": {"head": "a", "tail": "b", "parent": null, "rotation_plane": "p"},
        "tip": {"head": "b", "tail": "c", "parent": "root", "rotation_plane": "p"}},
      "joints": {"a": [0, 1], "b": [2, 3], "c": [4]},
      "planes": {"p": ["a", "b", "c"]}}"#;
    const MHW: &str = r#"{"weights": {"root": [[0, 1.0], [1, 0.5], [2, 0.25]], "tip": [[2, 0.25], [3, 2.0], [4, 1.0]]}}"#;

    #[test]
    fn reads_a_small_hand_made_asset() {
        let dir = tempfile::tempdir().unwrap();
        let (o, s, w) = (
            write(dir.path(), "a.obj", OBJ),
            write(dir.path(), "a.mhskel", SKEL),
            write(dir.path(), "a.mhw", MHW),
        );
        let a = load_makehuman(&o, &s, &w, &MakeHumanOptions::default()).unwrap();
        assert_eq!(a.obj_vertex, vec![0, 1, 2, 3]);
        assert_eq!(a.template.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(a.obj_groups, vec!["body".to_owned(), "other".to_owned()]);
        assert!((a.template.positions[2] - Vec3::new(1.0, 1.0, 0.0)).length() < 1e-6);
        assert_eq!(a.skeleton.names(), &["root".to_owned(), "tip".to_owned()]);
        // root head = centroid of vertices 0 and 1 = (5, 0, 0) dm; tip head = (5, 10, 0) dm.
        let world = |j: usize| {
            a.skeleton.inverse_bind()[j]
                .inverse()
                .transform_point3(Vec3::ZERO)
        };
        assert!((world(0) - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-5);
        assert!((world(1) - Vec3::new(0.5, 1.0, 0.0)).length() < 1e-5);
        assert!((a.bone_tails[1] - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-5);
        // The bind frame's +Y runs head → tail.
        let y = a.skeleton.inverse_bind()[0]
            .inverse()
            .transform_vector3(Vec3::Y);
        assert!((y - Vec3::Y).length() < 1e-5);
        // Vertex 2: 0.25 + 0.25 → normalised 0.5 / 0.5; vertex 3: only tip; vertex 4 is not in `body`.
        assert_eq!(a.skin.vertex_count(), 4);
        assert_eq!(a.skin.influences(2), (&[0u32, 1][..], &[0.5f32, 0.5][..]));
        assert_eq!(a.skin.influences(3), (&[1u32][..], &[1.0f32][..]));
        assert_eq!(a.skin.unnormalized_count(), 3);
        let all = load_makehuman(
            &o,
            &s,
            &w,
            &MakeHumanOptions {
                groups: vec![],
                scale: 1.0,
            },
        )
        .unwrap();
        assert_eq!(all.template.vertex_count(), 5);
        assert_eq!(all.template.triangles.len(), 3);
    }

    #[test]
    fn bad_inputs_name_the_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let (s, w) = (
            write(dir.path(), "a.mhskel", SKEL),
            write(dir.path(), "a.mhw", MHW),
        );
        let opts = MakeHumanOptions::default();
        let bad_obj = write(dir.path(), "b.obj", "v 0 0 0\ng body\nf 1 2 3\n");
        let e = load_makehuman(&bad_obj, &s, &w, &opts).unwrap_err();
        assert!(matches!(e, MakeHumanError::Obj { line: 3, .. }), "{e}");
        let nan_obj = write(dir.path(), "c.obj", "v 0 nan 0\n");
        assert!(matches!(
            load_makehuman(&nan_obj, &s, &w, &opts),
            Err(MakeHumanError::Obj { line: 1, .. })
        ));
        let o = write(dir.path(), "a.obj", OBJ);
        let bad_skel = write(dir.path(), "b.mhskel", &SKEL.replace("[4]", "[9]"));
        let e = load_makehuman(&o, &bad_skel, &w, &opts).unwrap_err();
        assert!(
            matches!(&e, MakeHumanError::Field { field, .. } if field == "joints.c"),
            "{e}"
        );
        let cyc = write(dir.path(), "c.mhskel", &SKEL.replace("null", "\"tip\""));
        assert!(matches!(
            load_makehuman(&o, &cyc, &w, &opts),
            Err(MakeHumanError::Field { .. })
        ));
        let bad_w = write(dir.path(), "b.mhw", &MHW.replace("\"tip\"", "\"nope\""));
        let e = load_makehuman(&o, &s, &bad_w, &opts).unwrap_err();
        assert!(
            matches!(&e, MakeHumanError::Field { field, .. } if field == "weights.nope"),
            "{e}"
        );
        assert!(e.to_string().contains("b.mhw"));
        let missing = write(dir.path(), "c.mhw", r#"{"weights": {"root": [[0, 1.0]]}}"#);
        assert!(matches!(
            load_makehuman(&o, &s, &missing, &opts),
            Err(MakeHumanError::Skin { .. })
        ));
        let e = load_makehuman(&dir.path().join("none.obj"), &s, &w, &opts).unwrap_err();
        assert!(matches!(e, MakeHumanError::Io { .. }));
    }

    /// Writes the fuzz target's seed (the hand-made asset's three files joined by zero bytes)
    /// to `$SKINFIELD_FUZZ_SEEDS/makehuman/` when that variable is set (`fuzz/README.md`).
    #[test]
    #[ignore = "writes fuzz seeds; run on request"]
    fn write_fuzz_seeds() {
        let Some(dir) = std::env::var_os("SKINFIELD_FUZZ_SEEDS") else {
            return;
        };
        let dir = PathBuf::from(dir).join("makehuman");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("hand_made"), format!("{OBJ}\0{SKEL}\0{MHW}")).unwrap();
    }

    /// meshoptimizer's reader test: every prefix of each file (the other two whole) is read or
    /// refused with an error naming a file, never a panic; a cut JSON file is refused by name.
    #[test]
    fn every_truncated_prefix_is_read_or_refused_naming_a_file() {
        let opts = MakeHumanOptions::default();
        let paths = [
            Path::new("a.obj"),
            Path::new("a.mhskel"),
            Path::new("a.mhw"),
        ];
        let whole = [OBJ, SKEL, MHW];
        let mut read = 0;
        for f in 0..3 {
            for end in (0..whole[f].len()).filter(|&e| whole[f].is_char_boundary(e)) {
                let mut texts = whole;
                texts[f] = &whole[f][..end];
                let source = |k: usize| SourceText {
                    path: paths[k],
                    text: texts[k],
                };
                match parse_makehuman(source(0), source(1), source(2), &opts) {
                    Ok(a) => {
                        assert_eq!(f, 0, "a cut JSON file was read ({end} bytes)");
                        a.template.validate().unwrap();
                        assert_eq!(a.skin.vertex_count(), a.template.positions.len());
                        assert_eq!(a.skin.joint_count(), a.skeleton.len());
                        read += 1;
                    }
                    Err(e) => {
                        let message = e.to_string();
                        let named = if f == 0 { &paths[..] } else { &paths[f..=f] };
                        assert!(
                            named.iter().any(|p| message.contains(p.to_str().unwrap())),
                            "{} cut at {end}: {message}",
                            paths[f].display()
                        );
                    }
                }
            }
        }
        // Cutting the OBJ's trailing group still leaves a valid body.
        assert!(read > 0);
    }
}

#[cfg(test)]
mod shared_asset_tests {
    use std::collections::BTreeMap;

    use super::*;

    /// The counts of `makehuman-hm08/SOURCE.md`, checked against the real files.
    #[test]
    fn hm08_matches_its_source_notes() {
        let Some(data) = crate::shared_data::shared_data_dir() else {
            return;
        };
        let dir = data.join("makehuman-hm08");
        let body = load_makehuman_dir(&dir, &MakeHumanOptions::default()).unwrap();
        assert_eq!(body.obj_vertex_count, 19_158);
        assert_eq!(body.obj_face_count, 18_486);
        // SOURCE.md's "172 groups" counts `g` statements; the eyelash helpers and the tights are
        // split over several statements of the same name, leaving 139 distinct groups.
        let text = std::fs::read_to_string(dir.join("base.obj")).unwrap();
        assert_eq!(text.lines().filter(|l| l.starts_with("g ")).count(), 172);
        assert_eq!(body.obj_groups.len(), 139);
        assert_eq!(
            body.obj_groups
                .iter()
                .filter(|g| g.starts_with("joint-"))
                .count(),
            125
        );
        assert_eq!(body.template.vertex_count(), 13_380);
        assert_eq!(body.template.triangles.len(), 2 * 13_378);
        assert_eq!(body.skeleton.len(), 163);
        assert_eq!(
            body.skeleton
                .parents()
                .iter()
                .filter(|p| p.is_none())
                .count(),
            1
        );
        assert_eq!(body.skeleton.names()[0], "root");
        // Decimetres became metres: the body is about 1.67 m tall.
        let b = body.template.bounds().unwrap();
        assert!((1.6..1.75).contains(&b.size().y), "{b:?}");

        let all = load_makehuman_dir(
            &dir,
            &MakeHumanOptions {
                groups: vec![],
                scale: 0.1,
            },
        )
        .unwrap();
        assert_eq!(all.template.vertex_count(), 19_158);
        // SOURCE.md: y from -8.45 to 8.50 decimetres over all vertices.
        let ab = all.template.bounds().unwrap();
        assert!(
            (ab.min.y + 0.845).abs() < 0.001 && (ab.max.y - 0.850).abs() < 0.001,
            "{ab:?}"
        );
        let mut weighted_joints = vec![false; all.skeleton.len()];
        let mut histogram = BTreeMap::new();
        for v in 0..all.skin.vertex_count() {
            let (j, _) = all.skin.influences(v);
            *histogram.entry(j.len()).or_insert(0) += 1;
            for &j in j {
                weighted_joints[j as usize] = true;
            }
        }
        assert_eq!(weighted_joints.iter().filter(|&&w| w).count(), 139);
        let expected: BTreeMap<usize, usize> = [
            (1, 4101),
            (2, 5321),
            (3, 3813),
            (4, 2258),
            (5, 1661),
            (6, 968),
            (7, 627),
            (8, 358),
            (9, 23),
            (10, 8),
            (12, 20),
        ]
        .into_iter()
        .collect();
        assert_eq!(histogram, expected);
        // Every child's head sits where MakeHuman's rig puts it: inside the body's bounding box.
        for m in body.skeleton.inverse_bind() {
            let head = m.inverse().transform_point3(Vec3::ZERO);
            assert!(
                head.cmpge(b.min - 0.05).all() && head.cmple(b.max + 0.05).all(),
                "{head}"
            );
        }
    }
}
