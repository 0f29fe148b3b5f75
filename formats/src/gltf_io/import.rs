//! glTF import: nodes, skins (skeleton from the inverse bind matrices), skinned primitives
//! (every `JOINTS_n`/`WEIGHTS_n` set) and static mesh nodes.

use std::collections::HashMap;
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};

use glam::{DMat4, Mat4, Vec2, Vec3};
use gltf::accessor::{DataType, Dimensions};

use super::animation::read_clip;
use super::container::{check_accessors, check_container, load_buffers, read_capped};
use super::{GltfDocument, GltfError, GltfSkin, NodeInfo, PrimitiveInfo, StaticMesh};
use crate::math::Transform;
use crate::mesh::{MAX_VERTICES, Template, area_weighted_normals};
use crate::skeleton::{MAX_JOINTS, Skeleton};
use crate::skin::StaticSkin;

/// Most `JOINTS_n`/`WEIGHTS_n` sets read per primitive (32 influences).
const MAX_INFLUENCE_SETS: u32 = 8;
/// Relative error allowed between `IBM⁻¹` and the world matrix rebuilt from the derived TRS
/// bind pose before the bind pose is declared unrepresentable (shear).
const BIND_TOLERANCE: f64 = 1e-3;

/// Reads a `.gltf` (external buffers relative to its folder, or data URIs) or a `.glb`.
pub fn load_gltf(path: &Path) -> Result<GltfDocument, GltfError> {
    let file = path.display().to_string();
    let bytes = read_capped(path, &file)?;
    let mut doc = load_named(&bytes, path.parent(), &file)?;
    doc.source = path.to_owned();
    Ok(doc)
}

/// Reads glTF or GLB bytes; external buffers are resolved against `base_dir` (refused when
/// `None`).
pub fn load_gltf_slice(bytes: &[u8], base_dir: Option<&Path>) -> Result<GltfDocument, GltfError> {
    load_named(bytes, base_dir, "<memory>")
}

fn load_named(
    bytes: &[u8],
    base_dir: Option<&Path>,
    file: &str,
) -> Result<GltfDocument, GltfError> {
    check_container(bytes, file)?;
    // The checks above and in `check_accessors` keep the gltf crate inside its contract; this
    // catches whatever they missed so that no panic leaves our API.
    match std::panic::catch_unwind(AssertUnwindSafe(|| import(bytes, base_dir, file))) {
        Ok(result) => result,
        Err(payload) => {
            let message = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(GltfError::Panic {
                file: file.to_owned(),
                message,
            })
        }
    }
}

/// Parsed file with its buffers; shared by the skin, static-mesh and animation readers.
pub(crate) struct Source<'a> {
    pub doc: &'a gltf::Document,
    pub buffers: &'a [Vec<u8>],
    pub file: &'a str,
    pub nodes: &'a [NodeInfo],
    /// Each node's default local matrix, kept exact (matrix nodes may not decompose).
    pub local_matrices: &'a [DMat4],
}

impl<'a> Source<'a> {
    pub fn field(&self, field: String, reason: impl Into<String>) -> GltfError {
        GltfError::Field {
            file: self.file.to_owned(),
            field,
            reason: reason.into(),
        }
    }

    pub fn data(&self) -> impl Clone + Fn(gltf::Buffer<'_>) -> Option<&'a [u8]> + 'a {
        let buffers = self.buffers;
        move |b| buffers.get(b.index()).map(Vec::as_slice)
    }

    /// Checks an accessor's element type before a gltf reader trusts it (the readers pick the
    /// element size from the component type alone and assume the dimensions).
    pub fn expect(
        &self,
        acc: &gltf::Accessor<'_>,
        dims: &[Dimensions],
        types: &[DataType],
        field: &str,
    ) -> Result<(), GltfError> {
        if dims.contains(&acc.dimensions()) && types.contains(&acc.data_type()) {
            Ok(())
        } else {
            Err(self.field(
                format!("{field} (accessors[{}])", acc.index()),
                format!(
                    "{:?} of {:?} is not a valid type here",
                    acc.dimensions(),
                    acc.data_type()
                ),
            ))
        }
    }

    /// Ancestors of `node`, nearest first.
    fn ancestors(&self, node: usize) -> Vec<usize> {
        let mut out = Vec::new();
        let mut at = self.nodes[node].parent;
        while let Some(p) = at {
            out.push(p);
            at = self.nodes[p].parent;
        }
        out
    }

    /// Default world matrix of `node`.
    fn world(&self, node: usize) -> DMat4 {
        let mut m = self.local_matrices[node];
        for a in self.ancestors(node) {
            m = self.local_matrices[a] * m;
        }
        m
    }
}

fn import(bytes: &[u8], base_dir: Option<&Path>, file: &str) -> Result<GltfDocument, GltfError> {
    let parse = |e: gltf::Error| GltfError::Parse {
        file: file.to_owned(),
        message: e.to_string(),
    };
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(parse)?;
    let root = document.into_json();
    // gltf-json's POSITION min/max hook indexes `accessors` before the index checks run.
    for (mi, mesh) in root.meshes.iter().enumerate() {
        for (pi, prim) in mesh.primitives.iter().enumerate() {
            if let Some((_, idx)) = prim
                .attributes
                .iter()
                .find(|(_, i)| i.value() >= root.accessors.len())
            {
                return Err(GltfError::Field {
                    file: file.to_owned(),
                    field: format!("meshes[{mi}].primitives[{pi}].attributes"),
                    reason: format!("accessor {} does not exist", idx.value()),
                });
            }
        }
    }
    // gltf-json does not validate animation channel targets at all.
    for (ai, anim) in root.animations.iter().enumerate() {
        for (ci, ch) in anim.channels.iter().enumerate() {
            if ch.target.node.value() >= root.nodes.len() {
                return Err(GltfError::Field {
                    file: file.to_owned(),
                    field: format!("animations[{ai}].channels[{ci}].target.node"),
                    reason: format!("node {} does not exist", ch.target.node.value()),
                });
            }
        }
    }
    let document = gltf::Document::from_json(root).map_err(parse)?;
    // gltf-json's validation lets some unrecognised enum values through (e.g. an animation
    // target `path`) and the accessors later unwrap them; serialising finds every such value.
    if let Err(e) = serde_json::to_writer(std::io::sink(), document.as_json()) {
        return Err(GltfError::Field {
            file: file.to_owned(),
            field: "(an enum field: path, interpolation, mode, type or componentType)".into(),
            reason: format!("holds an unrecognised value: {e}"),
        });
    }
    let buffers = load_buffers(&document, blob, base_dir, file)?;
    check_accessors(&document, &buffers, file)?;
    let (nodes, local_matrices) = read_nodes(&document, file)?;
    let src = Source {
        doc: &document,
        buffers: &buffers,
        file,
        nodes: &nodes,
        local_matrices: &local_matrices,
    };

    let (mut vertex_count, mut triangle_count, mut primitive_count) = (0usize, 0usize, 0usize);
    for mesh in document.meshes() {
        for prim in mesh.primitives() {
            let field = format!("meshes[{}].primitives[{}]", mesh.index(), prim.index());
            let positions = prim
                .get(&gltf::Semantic::Positions)
                .ok_or_else(|| src.field(field.clone(), "has no POSITION"))?;
            let n = positions.count();
            let idx = prim.indices().map_or(n, |a| a.count());
            vertex_count = vertex_count.saturating_add(n);
            triangle_count = triangle_count.saturating_add(triangles_in(prim.mode(), idx));
            primitive_count += 1;
        }
    }
    let skins = document
        .skins()
        .map(|s| read_skin(&src, &s))
        .collect::<Result<Vec<_>, _>>()?;
    let static_meshes = read_static_meshes(&src)?;
    let clips = document
        .animations()
        .map(|a| read_clip(&src, &a))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(GltfDocument {
        skins,
        clips,
        nodes,
        static_meshes,
        vertex_count,
        triangle_count,
        primitive_count,
        source: PathBuf::from(file),
    })
}

fn triangles_in(mode: gltf::mesh::Mode, indices: usize) -> usize {
    use gltf::mesh::Mode;
    match mode {
        Mode::Triangles => indices / 3,
        Mode::TriangleStrip | Mode::TriangleFan => indices.saturating_sub(2),
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => 0,
    }
}

fn read_nodes(doc: &gltf::Document, file: &str) -> Result<(Vec<NodeInfo>, Vec<DMat4>), GltfError> {
    let n = doc.nodes().len();
    let mut parent = vec![None; n];
    for node in doc.nodes() {
        for child in node.children() {
            let c = child.index();
            if parent[c].is_some() || c == node.index() {
                return Err(GltfError::Field {
                    file: file.to_owned(),
                    field: format!("nodes[{}].children", node.index()),
                    reason: format!("node {c} has more than one parent"),
                });
            }
            parent[c] = Some(node.index());
        }
    }
    // One parent each; a cycle would make some walk longer than the node count.
    for start in 0..n {
        let (mut at, mut steps) = (parent[start], 0usize);
        while let Some(p) = at {
            steps += 1;
            if steps > n {
                return Err(GltfError::Field {
                    file: file.to_owned(),
                    field: format!("nodes[{start}]"),
                    reason: "the node hierarchy has a cycle".into(),
                });
            }
            at = parent[p];
        }
    }
    let mut infos = Vec::with_capacity(n);
    let mut mats = Vec::with_capacity(n);
    for node in doc.nodes() {
        let m = Mat4::from_cols_array_2d(&node.transform().matrix());
        let (t, r, s) = node.transform().decomposed();
        let local = Transform {
            translation: Vec3::from(t),
            rotation: glam::Quat::from_array(r).normalize(),
            scale: Vec3::from(s),
        };
        if !m.is_finite() || !local.is_finite() {
            return Err(GltfError::Field {
                file: file.to_owned(),
                field: format!("nodes[{}]", node.index()),
                reason: "transform is not finite".into(),
            });
        }
        mats.push(m.as_dmat4());
        infos.push(NodeInfo {
            name: node
                .name()
                .map_or_else(|| format!("node_{}", node.index()), str::to_owned),
            parent: parent[node.index()],
            local,
            mesh: node.mesh().map(|m| m.index()),
            skin: node.skin().map(|s| s.index()),
        });
    }
    Ok((infos, mats))
}

/// Geometry of one primitive as stored.
struct PrimitiveData {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uvs: Option<Vec<Vec2>>,
    colors: Option<Vec<Vec3>>,
    triangles: Vec<[u32; 3]>,
}

fn read_primitive(
    src: &Source<'_>,
    prim: &gltf::Primitive<'_>,
    field: &str,
) -> Result<PrimitiveData, GltfError> {
    use gltf::mesh::Mode;
    check_attributes(src, prim, field)?;
    let reader = prim.reader(src.data());
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| {
            src.field(
                format!("{field}.attributes.POSITION"),
                "missing or unreadable",
            )
        })?
        .map(Vec3::from)
        .collect();
    let n = positions.len();
    if positions.iter().any(|p| !p.is_finite()) {
        return Err(src.field(
            format!("{field}.attributes.POSITION"),
            "holds a non-finite value",
        ));
    }
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(src.field(
            format!("{field}.indices"),
            format!("index {bad} but the primitive has {n} vertices"),
        ));
    }
    let triangles: Vec<[u32; 3]> = match prim.mode() {
        Mode::Triangles => indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
        // Strips alternate winding so every triangle stays counter-clockwise.
        Mode::TriangleStrip => indices
            .windows(3)
            .enumerate()
            .map(|(k, w)| {
                if k % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[1], w[0], w[2]]
                }
            })
            .collect(),
        Mode::TriangleFan => indices
            .windows(2)
            .skip(1)
            .map(|w| [indices[0], w[0], w[1]])
            .collect(),
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => Vec::new(),
    };
    let normals = match reader.read_normals() {
        Some(it) => {
            let v: Vec<Vec3> = it.map(Vec3::from).collect();
            if v.len() != n || v.iter().any(|x| !x.is_finite()) {
                return Err(src.field(
                    format!("{field}.attributes.NORMAL"),
                    "count differs from POSITION or not finite",
                ));
            }
            v
        }
        None => area_weighted_normals(&positions, &triangles),
    };
    let uvs = match reader.read_tex_coords(0) {
        Some(it) => {
            let v: Vec<Vec2> = it.into_f32().map(Vec2::from).collect();
            if v.len() != n {
                return Err(src.field(
                    format!("{field}.attributes.TEXCOORD_0"),
                    "count differs from POSITION",
                ));
            }
            Some(v)
        }
        None => None,
    };
    let colors = match reader.read_colors(0) {
        Some(it) => {
            let v: Vec<Vec3> = it.into_rgb_f32().map(Vec3::from).collect();
            if v.len() != n {
                return Err(src.field(
                    format!("{field}.attributes.COLOR_0"),
                    "count differs from POSITION",
                ));
            }
            Some(v)
        }
        None => None,
    };
    Ok(PrimitiveData {
        positions,
        normals,
        uvs,
        colors,
        triangles,
    })
}

/// Element types the glTF spec allows for the attributes we read.
fn check_attributes(
    src: &Source<'_>,
    prim: &gltf::Primitive<'_>,
    field: &str,
) -> Result<(), GltfError> {
    use DataType::{F32, U8, U16, U32};
    use gltf::Semantic as S;
    for (semantic, acc) in prim.attributes() {
        let f = format!("{field}.attributes.{}", semantic.to_string());
        match semantic {
            S::Positions | S::Normals => src.expect(&acc, &[Dimensions::Vec3], &[F32], &f)?,
            S::TexCoords(_) => src.expect(&acc, &[Dimensions::Vec2], &[F32, U8, U16], &f)?,
            S::Colors(_) => src.expect(
                &acc,
                &[Dimensions::Vec3, Dimensions::Vec4],
                &[F32, U8, U16],
                &f,
            )?,
            S::Joints(_) => src.expect(&acc, &[Dimensions::Vec4], &[U8, U16], &f)?,
            S::Weights(_) => src.expect(&acc, &[Dimensions::Vec4], &[F32, U8, U16], &f)?,
            S::Tangents => src.expect(&acc, &[Dimensions::Vec4], &[F32], &f)?,
        }
    }
    if let Some(acc) = prim.indices() {
        src.expect(
            &acc,
            &[Dimensions::Scalar],
            &[U8, U16, U32],
            &format!("{field}.indices"),
        )?;
    }
    Ok(())
}

/// Per-vertex `(skin joint, weight)` pairs over every `JOINTS_n`/`WEIGHTS_n` set, zero
/// weights dropped and repeated joints merged.
fn read_influences(
    src: &Source<'_>,
    prim: &gltf::Primitive<'_>,
    field: &str,
    vertices: usize,
    skin_joints: usize,
) -> Result<Vec<Vec<(usize, f32)>>, GltfError> {
    let reader = prim.reader(src.data());
    let mut out = vec![Vec::<(usize, f32)>::with_capacity(4); vertices];
    let mut set = 0u32;
    while let Some(joints) = reader.read_joints(set) {
        if set >= MAX_INFLUENCE_SETS {
            return Err(GltfError::TooLarge {
                file: src.file.to_owned(),
                field: format!("{field}: JOINTS_n sets"),
                count: u64::from(set) + 1,
                cap: u64::from(MAX_INFLUENCE_SETS),
            });
        }
        let wfield = format!("{field}.attributes.WEIGHTS_{set}");
        let weights = reader
            .read_weights(set)
            .ok_or_else(|| src.field(wfield.clone(), "missing beside JOINTS"))?;
        let joints: Vec<[u16; 4]> = joints.into_u16().collect();
        let weights: Vec<[f32; 4]> = weights.into_f32().collect();
        if joints.len() != vertices || weights.len() != vertices {
            return Err(src.field(
                wfield,
                format!(
                    "JOINTS/WEIGHTS counts {}/{} differ from {vertices} vertices",
                    joints.len(),
                    weights.len()
                ),
            ));
        }
        for (v, (js, ws)) in joints.iter().zip(&weights).enumerate() {
            for (&j, &w) in js.iter().zip(ws) {
                if !(w.is_finite() && w >= 0.0) {
                    return Err(src.field(wfield, format!("vertex {v} has weight {w}")));
                }
                if w == 0.0 {
                    continue;
                }
                let j = usize::from(j);
                if j >= skin_joints {
                    return Err(src.field(
                        format!("{field}.attributes.JOINTS_{set}"),
                        format!("vertex {v} refers to joint {j}, the skin has {skin_joints}"),
                    ));
                }
                match out[v].iter_mut().find(|(k, _)| *k == j) {
                    Some((_, acc)) => *acc += w,
                    None => out[v].push((j, w)),
                }
            }
        }
        set += 1;
    }
    if set == 0 {
        return Err(src.field(
            format!("{field}.attributes.JOINTS_0"),
            "skinned primitive without joints",
        ));
    }
    Ok(out)
}

/// Appends a primitive's geometry to `t` (attribute options stay aligned: a primitive
/// without UVs or colours gets zeros or white where others have them).
fn append(t: &mut Template, p: PrimitiveData) -> Result<(), String> {
    let base = t.positions.len();
    let n = p.positions.len();
    if base.checked_add(n).is_none_or(|total| total > MAX_VERTICES) {
        return Err(format!("more than {MAX_VERTICES} vertices"));
    }
    let b = base as u32;
    t.triangles
        .extend(p.triangles.iter().map(|tri| tri.map(|i| i + b)));
    match (&mut t.uvs, p.uvs) {
        (Some(a), Some(b)) => a.extend(b),
        (Some(a), None) => a.extend(std::iter::repeat_n(Vec2::ZERO, n)),
        (None, Some(b)) => {
            let mut a = vec![Vec2::ZERO; base];
            a.extend(b);
            t.uvs = Some(a);
        }
        (None, None) => {}
    }
    match (&mut t.colors, p.colors) {
        (Some(a), Some(b)) => a.extend(b),
        (Some(a), None) => a.extend(std::iter::repeat_n(Vec3::ONE, n)),
        (None, Some(b)) => {
            let mut a = vec![Vec3::ONE; base];
            a.extend(b);
            t.colors = Some(a);
        }
        (None, None) => {}
    }
    t.positions.extend(p.positions);
    t.normals.extend(p.normals);
    Ok(())
}

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

fn read_skin(src: &Source<'_>, skin: &gltf::Skin<'_>) -> Result<GltfSkin, GltfError> {
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
    if template.positions.is_empty() {
        return Err(src.field(field, "no mesh node uses this skin"));
    }
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

fn read_static_meshes(src: &Source<'_>) -> Result<Vec<StaticMesh>, GltfError> {
    let mut out = Vec::new();
    for (i, node) in src.nodes.iter().enumerate() {
        let (Some(mi), None) = (node.mesh, node.skin) else {
            continue;
        };
        let Some(mesh) = src.doc.meshes().nth(mi) else {
            continue;
        };
        let mut template = Template::default();
        for prim in mesh.primitives() {
            let pf = format!("meshes[{mi}].primitives[{}]", prim.index());
            let data = read_primitive(src, &prim, &pf)?;
            append(&mut template, data).map_err(|r| src.field(pf.clone(), r))?;
        }
        out.push(StaticMesh {
            node: i,
            name: node.name.clone(),
            mesh: mi,
            template,
            world: src.world(i).as_mat4(),
        });
    }
    Ok(out)
}
