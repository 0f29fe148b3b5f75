//! `makehuman::parse_makehuman` on arbitrary bytes split at their first two zero bytes into an
//! OBJ, a `.mhskel` and a `.mhw` (missing parts empty; each read as lossy UTF-8; every OBJ group
//! selected, so a seed is the three files joined by zero bytes): an asset that parses has a
//! valid template, one weight list per template vertex over the skeleton's joints, an OBJ
//! vertex behind every template vertex, and a finite tail for every bone.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use skinfield_formats::makehuman::{MakeHumanOptions, SourceText, parse_makehuman};

fuzz_target!(|data: &[u8]| {
    let mut parts = data.splitn(3, |&b| b == 0);
    let mut next = || String::from_utf8_lossy(parts.next().unwrap_or_default());
    let texts = [next(), next(), next()];
    let source = |k: usize, path: &'static str| SourceText {
        path: Path::new(path),
        text: &texts[k],
    };
    let options = MakeHumanOptions {
        groups: Vec::new(),
        scale: 0.1,
    };
    if let Ok(asset) = parse_makehuman(
        source(0, "fuzz.obj"),
        source(1, "fuzz.mhskel"),
        source(2, "fuzz.mhw"),
        &options,
    ) {
        asset
            .template
            .validate()
            .expect("a parsed template is valid");
        assert_eq!(asset.skin.vertex_count(), asset.template.positions.len());
        assert_eq!(asset.skin.joint_count(), asset.skeleton.len());
        assert_eq!(asset.obj_vertex.len(), asset.template.positions.len());
        assert!(
            asset
                .obj_vertex
                .iter()
                .all(|&v| (v as usize) < asset.obj_vertex_count)
        );
        assert_eq!(asset.bone_tails.len(), asset.skeleton.len());
        assert!(asset.bone_tails.iter().all(|t| t.is_finite()));
    }
});
