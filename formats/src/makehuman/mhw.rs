//! The `.mhw` JSON weights: per bone a list of `[OBJ vertex, weight]` pairs, kept for the
//! template's vertices (`remap`: OBJ vertex → template vertex or `u32::MAX`).

use crate::skeleton::Skeleton;
use crate::skin::StaticSkin;

use super::{MakeHumanError, SourceText, parse_json};

/// The weights of the template's `vertices` for the bones of `skeleton`.
pub(super) fn read_weights(
    source: SourceText<'_>,
    skeleton: &Skeleton,
    remap: &[u32],
    vertices: usize,
) -> Result<StaticSkin, MakeHumanError> {
    let path = source.path;
    let field = |field: String, what: String| MakeHumanError::Field {
        path: path.to_owned(),
        field,
        what,
    };
    let json = parse_json(source)?;
    let weights = json
        .get("weights")
        .and_then(|w| w.as_object())
        .ok_or_else(|| field("weights".into(), "missing or not an object".into()))?;
    let mut per_vertex: Vec<Vec<(u32, f32)>> = vec![Vec::new(); vertices];
    for (bone, list) in weights {
        let at = || format!("weights.{bone}");
        let j = skeleton
            .find(bone)
            .ok_or_else(|| field(at(), "no bone of that name in the skeleton".into()))?;
        let list = list
            .as_array()
            .ok_or_else(|| field(at(), "not an array".into()))?;
        for pair in list {
            let (v, w) = match pair.as_array().map(Vec::as_slice) {
                Some([v, w]) => (v.as_u64(), w.as_f64()),
                _ => (None, None),
            };
            let (Some(v), Some(w)) = (v, w) else {
                return Err(field(
                    at(),
                    format!("`{pair}` is not a [vertex, weight] pair"),
                ));
            };
            let t = *remap.get(v as usize).ok_or_else(|| {
                field(
                    at(),
                    format!("vertex {v} is beyond the OBJ's {}", remap.len()),
                )
            })?;
            if t != u32::MAX {
                per_vertex[t as usize].push((j as u32, w as f32));
            }
        }
    }
    let mut offsets = Vec::with_capacity(vertices + 1);
    offsets.push(0u32);
    let (mut joints, mut ws) = (Vec::new(), Vec::new());
    for mut inf in per_vertex {
        inf.sort_by_key(|&(j, _)| j);
        for (j, w) in inf {
            joints.push(j);
            ws.push(w);
        }
        offsets.push(joints.len() as u32);
    }
    StaticSkin::new(offsets, joints, ws, skeleton.len()).map_err(|source| MakeHumanError::Skin {
        path: path.to_owned(),
        source,
    })
}
