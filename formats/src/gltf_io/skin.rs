//! One glTF skin as a [`GltfSkin`]: the skeleton (skin joints plus in-between nodes, bind pose
//! from the inverse bind matrices) and the template and weights of every primitive it skins.

use std::collections::HashMap;

use glam::{DMat4, Mat4};
use gltf::accessor::{DataType, Dimensions};

use super::import::Source;
use super::primitive::{append, read_influences, read_primitive};
use super::{GltfError, GltfSkin, PrimitiveInfo};
use crate::math::Transform;
use crate::mesh::Template;
use crate::skeleton::{MAX_JOINTS, Skeleton};
use crate::skin::StaticSkin;

/// Relative error allowed between `IBM⁻¹` and the world matrix rebuilt from the derived TRS
/// bind pose before the bind pose is declared unrepresentable (shear).
const BIND_TOLERANCE: f64 = 1e-3;

/// Skeleton joints for a skin: the skin's joints plus every node between a joint and the
/// joints' lowest common ancestor, ordered depth-first from the roots (topological).
/// Returns the nodes and the ancestors above the roots (outermost first).
fn skeleton_nodes(src: &Source<'_>, joints: &[usize]) -> (Vec<usize>, Vec<usize>) {
    let chains: Vec<Vec<usize>> = joints
        .iter()
        .map(|&j| {
            let mut c = vec![j];
            c.extend(src.ancestors(j));
            c
        })
        .collect();
    // Lowest common ancestor (inclusive of the joints themselves).
    let lca = chains[0]
        .iter()
        .copied()
        .find(|a| chains.iter().all(|c| c.contains(a)));
    let is_joint = |n: usize| joints.contains(&n);
    let mut include = vec![false; src.nodes.len()];
    for c in &chains {
        for &n in c {
            if Some(n) == lca && !is_joint(n) {
                break;
            }
            include[n] = true;
            if Some(n) == lca {
                break;
            }
        }
    }
    let roots: Vec<usize> = (0..src.nodes.len())
        .filter(|&n| include[n] && src.nodes[n].parent.is_none_or(|p| !include[p]))
        .collect();
    let mut order = Vec::new();
    let mut stack: Vec<usize> = roots.iter().rev().copied().collect();
    while let Some(n) = stack.pop() {
        order.push(n);
        let children: Vec<usize> = src.doc.nodes().nth(n).map_or_else(Vec::new, |node| {
            node.children().map(|c| c.index()).collect()
        });
        stack.extend(children.into_iter().rev().filter(|&c| include[c]));
    }
    let mut above = roots.first().map_or_else(Vec::new, |&r| src.ancestors(r));
    above.reverse();
    (order, above)
}

pub(crate) fn read_skin(src: &Source<'_>, skin: &gltf::Skin<'_>) -> Result<GltfSkin, GltfError> {
    let si = skin.index();
    let field = format!("skins[{si}]");
    let joints: Vec<usize> = skin.joints().map(|n| n.index()).collect();
    if joints.is_empty() {
        return Err(src.field(format!("{field}.joints"), "is empty"));
    }
    if joints.len() > MAX_JOINTS {
        return Err(GltfError::TooLarge {
            file: src.file.to_owned(),
            field: format!("{field}.joints"),
            count: joints.len() as u64,
            cap: MAX_JOINTS as u64,
        });
    }
    for (k, j) in joints.iter().enumerate() {
        if joints[..k].contains(j) {
            return Err(src.field(
                format!("{field}.joints"),
                format!("node {j} is listed twice"),
            ));
        }
    }
    if let Some(acc) = skin.inverse_bind_matrices() {
        src.expect(
            &acc,
            &[Dimensions::Mat4],
            &[DataType::F32],
            &format!("{field}.inverseBindMatrices"),
        )?;
    }
    let ibm: Vec<Mat4> = match skin.reader(src.data()).read_inverse_bind_matrices() {
        Some(it) => it.map(|m| Mat4::from_cols_array_2d(&m)).collect(),
        None if skin.inverse_bind_matrices().is_some() => {
            return Err(src.field(format!("{field}.inverseBindMatrices"), "unreadable"));
        }
        None => vec![Mat4::IDENTITY; joints.len()],
    };
    if ibm.len() < joints.len() {
        return Err(src.field(
            format!("{field}.inverseBindMatrices"),
            format!("{} matrices for {} joints", ibm.len(), joints.len()),
        ));
    }
    for (k, m) in ibm.iter().take(joints.len()).enumerate() {
        if !m.is_finite() || m.as_dmat4().determinant().abs() < 1e-24 {
            return Err(src.field(
                format!("{field}.inverseBindMatrices"),
                format!("matrix {k} is not finite or not invertible"),
            ));
        }
    }

    let (order, above) = skeleton_nodes(src, &joints);
    let base = above
        .iter()
        .fold(DMat4::IDENTITY, |m, &a| m * src.local_matrices[a]);
    let slot: HashMap<usize, usize> = order.iter().enumerate().map(|(k, &n)| (n, k)).collect();
    let skin_index: Vec<Option<usize>> = order
        .iter()
        .map(|n| joints.iter().position(|j| j == n))
        .collect();
    let parents: Vec<Option<usize>> = order
        .iter()
        .map(|&n| src.nodes[n].parent.and_then(|p| slot.get(&p).copied()))
        .collect();

    // Bind pose: skin joints from IBM⁻¹, in-between nodes from their TRS; locals relative to
    // the parent's bind world. In f64 so large scales (RobotExpressive's ×100) lose nothing.
    let mut bind_world = Vec::with_capacity(order.len());
    let mut bind_local = Vec::with_capacity(order.len());
    for (k, &node) in order.iter().enumerate() {
        let parent_world = parents[k].map_or(base, |p| bind_world[p]);
        let world = match skin_index[k] {
            Some(s) => ibm[s].as_dmat4().inverse(),
            None => parent_world * src.local_matrices[node],
        };
        let local = parent_world.inverse() * world;
        let t = Transform::from_mat4(&local.as_mat4());
        // Shear (non-uniform scale under rotation) cannot be a TRS: refuse rather than drift.
        let rebuilt = parent_world * t.to_mat4().as_dmat4();
        let scale = world
            .abs()
            .to_cols_array()
            .iter()
            .fold(1.0f64, |a, b| a.max(*b));
        let err = (rebuilt - world)
            .abs()
            .to_cols_array()
            .iter()
            .fold(0.0f64, |a, b| a.max(*b));
        if !t.is_finite() || err > BIND_TOLERANCE * scale {
            return Err(src.field(
                format!("{field}.inverseBindMatrices"),
                format!("bind pose of node {node} is not a TRS transform (shear?)"),
            ));
        }
        bind_world.push(world);
        bind_local.push(t);
    }
    let inverse_bind: Vec<Mat4> = order
        .iter()
        .enumerate()
        .map(|(k, _)| skin_index[k].map_or_else(|| bind_world[k].inverse().as_mat4(), |s| ibm[s]))
        .collect();
    let mut names: Vec<String> = Vec::with_capacity(order.len());
    for &n in &order {
        let name = &src.nodes[n].name;
        // glTF allows repeated names; a skeleton does not.
        names.push(if names.contains(name) {
            format!("{name}#{n}")
        } else {
            name.clone()
        });
    }
    let skeleton = Skeleton::new(
        names,
        parents,
        bind_local,
        Some(inverse_bind),
        None,
        base.as_mat4(),
    )
    .map_err(|source| GltfError::Skeleton {
        file: src.file.to_owned(),
        skin: si,
        source,
    })?;

    let mut joint_of = vec![0u32; joints.len()];
    for (k, s) in skin_index.iter().enumerate() {
        if let Some(s) = *s {
            joint_of[s] = k as u32;
        }
    }
    // Every primitive of every mesh that a node skins with this skin, in mesh order.
    let mut template = Template::default();
    let mut primitives = Vec::new();
    let (mut offsets, mut wj, mut ww) = (vec![0u32], Vec::new(), Vec::new());
    for mesh in src.doc.meshes() {
        if !src
            .nodes
            .iter()
            .any(|n| n.mesh == Some(mesh.index()) && n.skin == Some(si))
        {
            continue;
        }
        for prim in mesh.primitives() {
            let pf = format!("meshes[{}].primitives[{}]", mesh.index(), prim.index());
            let data = read_primitive(src, &prim, &pf)?;
            let n = data.positions.len();
            let influences = read_influences(src, &prim, &pf, n, joints.len())?;
            primitives.push(PrimitiveInfo {
                mesh: mesh.index(),
                primitive: prim.index(),
                mesh_name: mesh.name().unwrap_or_default().to_owned(),
                material: prim.material().index(),
                first_vertex: template.positions.len(),
                vertex_count: n,
                first_triangle: template.triangles.len(),
                triangle_count: data.triangles.len(),
            });
            append(&mut template, data).map_err(|r| src.field(pf.clone(), r))?;
            for inf in influences {
                for (j, w) in inf {
                    wj.push(joint_of[j]);
                    ww.push(w);
                }
                offsets.push(wj.len() as u32);
            }
        }
    }
    // A skin no mesh node uses is valid glTF: it keeps its skeleton and an empty template.
    let weights =
        StaticSkin::new(offsets, wj, ww, skeleton.len()).map_err(|source| GltfError::Weights {
            file: src.file.to_owned(),
            skin: si,
            source,
        })?;
    Ok(GltfSkin {
        index: si,
        name: skin
            .name()
            .map_or_else(|| format!("skin_{si}"), str::to_owned),
        node_defaults: order.iter().map(|&n| src.nodes[n].local).collect(),
        skeleton,
        template,
        skin: weights,
        primitives,
        joint_nodes: order,
        joint_skin_index: skin_index,
        root_ancestor_defaults: above.iter().map(|&a| src.nodes[a].local).collect(),
        root_ancestors: above,
    })
}
