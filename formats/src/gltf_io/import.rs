//! glTF import entry points: container and JSON checks, buffers, the node table, then skins
//! ([`super::skin`]), static mesh nodes and animations.

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};

use glam::{DMat4, Mat4, Vec3};
use gltf::accessor::{DataType, Dimensions};

use super::animation::read_clip;
use super::container::{check_accessors, check_container, load_buffers, read_capped};
use super::primitive::{append, read_primitive, triangles_in};
use super::skin::read_skin;
use super::{GltfDocument, GltfError, NodeInfo, StaticMesh};
use crate::math::Transform;
use crate::mesh::Template;

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
    pub fn ancestors(&self, node: usize) -> Vec<usize> {
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
