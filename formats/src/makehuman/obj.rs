//! The Wavefront OBJ subset MakeHuman's `base.obj` uses: `v` positions, `g` groups and `f`
//! polygons (any corner count up to a cap, 1-based or negative indices, `v/vt/vn` corners of
//! which only the position index is read). Every count is capped and every line that does not
//! parse is an error naming the file and the line.

use std::path::Path;

use glam::Vec3;

use super::{MAX_POLYGON_CORNERS, MAX_TRIANGLES, MakeHumanError};
use crate::mesh::MAX_VERTICES;

/// Positions, polygons and the group each polygon belongs to.
pub(super) struct ParsedObj {
    pub(super) positions: Vec<Vec3>,
    pub(super) polygons: Vec<Vec<u32>>,
    pub(super) polygon_group: Vec<usize>,
    pub(super) group_names: Vec<String>,
}

pub(super) fn parse_obj(path: &Path, text: &str) -> Result<ParsedObj, MakeHumanError> {
    let err = |line: usize, what: String| MakeHumanError::Obj {
        path: path.to_owned(),
        line: line + 1,
        what,
    };
    let mut positions = Vec::new();
    let mut polygons: Vec<Vec<u32>> = Vec::new();
    let mut polygon_group = Vec::new();
    let mut group_names: Vec<String> = Vec::new();
    let mut current_group: Option<usize> = None;
    let mut triangle_count = 0usize;
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                if positions.len() >= MAX_VERTICES {
                    return Err(err(ln, format!("more than {MAX_VERTICES} vertices")));
                }
                let mut p = [0.0f32; 3];
                for c in &mut p {
                    let s = it
                        .next()
                        .ok_or_else(|| err(ln, "vertex with fewer than 3 coordinates".into()))?;
                    *c = s
                        .parse()
                        .map_err(|_| err(ln, format!("bad coordinate `{s}`")))?;
                    if !c.is_finite() {
                        return Err(err(ln, format!("non-finite coordinate `{s}`")));
                    }
                }
                positions.push(Vec3::from_array(p));
            }
            Some("g") => {
                let name = it.collect::<Vec<_>>().join(" ");
                let g = match group_names.iter().position(|n| *n == name) {
                    Some(g) => g,
                    None => {
                        group_names.push(name);
                        group_names.len() - 1
                    }
                };
                current_group = Some(g);
            }
            Some("f") => {
                let mut poly = Vec::new();
                for corner in it {
                    if poly.len() >= MAX_POLYGON_CORNERS {
                        return Err(err(
                            ln,
                            format!("polygon with more than {MAX_POLYGON_CORNERS} corners"),
                        ));
                    }
                    let first = corner.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| err(ln, format!("bad face index `{corner}`")))?;
                    // OBJ indices are 1-based; negative ones count back from the latest vertex.
                    let n = positions.len() as i64;
                    let v = if i > 0 { i - 1 } else { n + i };
                    if i == 0 || v < 0 || v >= n {
                        return Err(err(ln, format!("face index {i} out of range (1..={n})")));
                    }
                    poly.push(v as u32);
                }
                if poly.len() < 3 {
                    return Err(err(ln, format!("face with {} corners", poly.len())));
                }
                triangle_count += poly.len() - 2;
                if triangle_count > MAX_TRIANGLES {
                    return Err(err(ln, format!("more than {MAX_TRIANGLES} triangles")));
                }
                let g = match current_group {
                    Some(g) => g,
                    None => {
                        // Faces before any `g` line belong to OBJ's implicit group "default".
                        group_names.push("default".to_owned());
                        current_group = Some(group_names.len() - 1);
                        group_names.len() - 1
                    }
                };
                polygons.push(poly);
                polygon_group.push(g);
            }
            _ => {}
        }
    }
    Ok(ParsedObj {
        positions,
        polygons,
        polygon_group,
        group_names,
    })
}
