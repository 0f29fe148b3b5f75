//! The `.mhskel` JSON skeleton: bones named by head and tail joints, a joint the centroid of
//! OBJ helper vertices, a bone's roll fixed by its rotation plane (the conventions are in the
//! parent module's docs).

use std::collections::BTreeMap;

use glam::{Mat3, Quat, Vec3};

use crate::math::Transform;
use crate::skeleton::{MAX_JOINTS, Skeleton, SkeletonError};

use super::{MakeHumanError, SourceText, parse_json};

/// The skeleton of a `.mhskel` (one joint per bone, at the bone's head, parents first) and the
/// world bind-pose tail of every bone, from the OBJ's positions (file units) times `scale`.
pub(super) fn read_skeleton(
    source: SourceText<'_>,
    obj_positions: &[Vec3],
    scale: f32,
) -> Result<(Skeleton, Vec<Vec3>), MakeHumanError> {
    let path = source.path;
    let field = |field: &str, what: String| MakeHumanError::Field {
        path: path.to_owned(),
        field: field.to_owned(),
        what,
    };
    let json = parse_json(source)?;
    let bones = json
        .get("bones")
        .and_then(|b| b.as_object())
        .ok_or_else(|| field("bones", "missing or not an object".into()))?;
    let joints = json
        .get("joints")
        .and_then(|b| b.as_object())
        .ok_or_else(|| field("joints", "missing or not an object".into()))?;
    let planes = json.get("planes").and_then(|b| b.as_object());
    if bones.len() > MAX_JOINTS {
        return Err(MakeHumanError::Skeleton {
            path: path.to_owned(),
            source: SkeletonError::TooManyJoints(bones.len()),
        });
    }
    let joint_pos = |name: &str, at: &str| -> Result<Vec3, MakeHumanError> {
        let list = joints
            .get(name)
            .and_then(|l| l.as_array())
            .ok_or_else(|| field(at, format!("joint `{name}` is not listed in `joints`")))?;
        if list.is_empty() {
            return Err(field(&format!("joints.{name}"), "empty vertex list".into()));
        }
        let mut sum = glam::DVec3::ZERO;
        for v in list {
            let i = v
                .as_u64()
                .filter(|&i| (i as usize) < obj_positions.len())
                .ok_or_else(|| {
                    field(
                        &format!("joints.{name}"),
                        format!("`{v}` is not a vertex index below {}", obj_positions.len()),
                    )
                })?;
            sum += obj_positions[i as usize].as_dvec3();
        }
        Ok((sum / list.len() as f64).as_vec3() * scale)
    };

    // Parent links by name; BTreeMap keeps the walk below deterministic (children in name order).
    let mut children: BTreeMap<Option<&str>, Vec<&str>> = BTreeMap::new();
    for (name, bone) in bones {
        let parent = match bone.get("parent") {
            None | Some(serde_json::Value::Null) => None,
            Some(serde_json::Value::String(p)) => {
                if !bones.contains_key(p) {
                    return Err(field(
                        &format!("bones.{name}.parent"),
                        format!("unknown bone `{p}`"),
                    ));
                }
                Some(p.as_str())
            }
            Some(other) => {
                return Err(field(
                    &format!("bones.{name}.parent"),
                    format!("`{other}` is not a string"),
                ));
            }
        };
        children.entry(parent).or_default().push(name.as_str());
    }
    let mut order: Vec<&str> = Vec::with_capacity(bones.len());
    let mut stack: Vec<&str> = children
        .get(&None)
        .map(|c| c.iter().rev().copied().collect())
        .unwrap_or_default();
    while let Some(b) = stack.pop() {
        order.push(b);
        if let Some(c) = children.get(&Some(b)) {
            stack.extend(c.iter().rev());
        }
    }
    if order.len() != bones.len() {
        return Err(field("bones", "parent links form a cycle".into()));
    }
    let index: BTreeMap<&str, usize> = order.iter().enumerate().map(|(i, &n)| (n, i)).collect();

    let n = order.len();
    let mut heads = Vec::with_capacity(n);
    let mut tails = Vec::with_capacity(n);
    let mut world_rot = Vec::with_capacity(n);
    let mut parents = Vec::with_capacity(n);
    for &name in &order {
        let bone = &bones[name];
        let at = |k: &str| format!("bones.{name}.{k}");
        let jname = |k: &str| {
            bone.get(k)
                .and_then(|v| v.as_str())
                .ok_or_else(|| field(&at(k), "missing or not a string".into()))
        };
        let head = joint_pos(jname("head")?, &at("head"))?;
        let tail = joint_pos(jname("tail")?, &at("tail"))?;
        let y = (tail - head).try_normalize().unwrap_or(Vec3::Y);
        let normal = bone
            .get("rotation_plane")
            .and_then(|p| p.as_str())
            .and_then(|p| planes.and_then(|pl| pl.get(p)))
            .and_then(|p| p.as_array())
            .filter(|p| p.len() == 3)
            .map(|p| -> Result<Vec3, MakeHumanError> {
                let mut q = [Vec3::ZERO; 3];
                for (q, name) in q.iter_mut().zip(p) {
                    let name = name.as_str().ok_or_else(|| {
                        field(&at("rotation_plane"), "plane joint is not a string".into())
                    })?;
                    *q = joint_pos(name, &at("rotation_plane"))?;
                }
                Ok((q[1] - q[0]).cross(q[2] - q[1]))
            })
            .transpose()?
            .unwrap_or(Vec3::ZERO);
        let x = (normal - normal.dot(y) * y)
            .try_normalize()
            .unwrap_or_else(|| y.any_orthonormal_vector());
        let z = x.cross(y);
        world_rot.push(Quat::from_mat3(&Mat3::from_cols(x, y, z)).normalize());
        heads.push(head);
        tails.push(tail);
        parents.push(
            bone.get("parent")
                .and_then(|p| p.as_str())
                .map(|p| index[p]),
        );
    }
    let bind_local = (0..n)
        .map(|j| match parents[j] {
            None => Transform::from_rotation_translation(world_rot[j], heads[j]),
            Some(p) => {
                let inv = world_rot[p].inverse();
                Transform::from_rotation_translation(
                    (inv * world_rot[j]).normalize(),
                    inv * (heads[j] - heads[p]),
                )
            }
        })
        .collect();
    let names = order.iter().map(|s| (*s).to_owned()).collect();
    let skeleton = Skeleton::new(names, parents, bind_local, None, None, glam::Mat4::IDENTITY)
        .map_err(|source| MakeHumanError::Skeleton {
            path: path.to_owned(),
            source,
        })?;
    Ok((skeleton, tails))
}
