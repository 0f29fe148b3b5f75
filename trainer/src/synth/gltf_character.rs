//! The character a glTF file shows: every mesh that moves with one skeleton, in one canonical
//! space where the template, the ground truth and the cameras agree.
//!
//! A glTF character is not always one skinned mesh. RobotExpressive has two skins over the same
//! 43 joints (one per hand) and twelve rigid parts (torso, head, limbs), mesh nodes without a
//! skin parented to joints. Its skinned meshes are stored in a space 100 times smaller than the
//! world its animations play in: the armature node above the skeleton scales by 100 and turns
//! the file's Z-up into Y-up, and the inverse bind matrices undo this. `GltfSkin` keeps glTF's
//! meaning exactly (its template is in the skin's bind space, its bind pose comes from the
//! inverse bind matrices), so the bind pose of its root carries a scale of 1/100 that no
//! animation keeps; every posed frame is then 100 times the template, and the ground truth's
//! dual-quaternion skinning, which takes skinning matrices as rigid, drops that scale.
//!
//! [`assemble`] builds the capture's character instead:
//!
//! 1. **Canonical space = the rest scene.** `M = world_r(rest) · IBM_r` for the root-most skin
//!    joint `r` at the nodes' default TRS (the file's rest scene) maps the skin's bind space to
//!    where the character stands at rest. Template positions become `M · x` and the inverse bind
//!    matrices `IBM_j · M⁻¹`: linear blend skinning poses every vertex exactly where glTF puts
//!    it (`world_j · IBM_j · M⁻¹ · M · x`), and the bind pose of the root becomes its rest
//!    transform, so skinning matrices of animated poses stay rigid. Where `M` is the identity
//!    to 1e-6 (CesiumMan, Fox, Witch) nothing changes.
//! 2. **Every skin over the same skeleton.** A skin whose joints are all skeleton joints (matched
//!    by node) adds its meshes: each vertex is posed at the bind pose by its own inverse bind
//!    matrices (exact where its joints agree on the bind pose, as they do in RobotExpressive),
//!    its weights mapped onto the skeleton's joints.
//! 3. **Rigid parts.** A mesh node without a skin below a skeleton joint (the nearest joint among
//!    its ancestors, or the node itself) follows that joint with weight 1, placed at the joint's
//!    bind pose by the node transforms between them.
//!
//! Meshes bound to other skeletons and mesh nodes above or beside the skeleton (props, ground
//! planes) are left out and listed in [`GltfCharacter::left_out`].

use glam::{DMat4, Mat3, Mat4, Vec3};
use skinfield_formats::gltf_io::{GltfDocument, GltfSkin};
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_formats::{Skeleton, StaticSkin, Template, Transform};

use super::SynthError;

/// Relative size of the difference from the identity below which the rest transform is taken
/// as the identity (so files already in world space keep their bytes).
const IDENTITY_TOLERANCE: f64 = 1e-6;
/// Relative error allowed between a re-bound joint's world matrix and its TRS rebuild.
const BIND_TOLERANCE: f64 = 1e-3;

/// How a part of the template moves.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PartSource {
    /// Skinned by the file's skin `skin` (its mesh `mesh`, primitive `primitive`).
    Skinned {
        /// Skin index in the file.
        skin: usize,
        /// Mesh index in the file.
        mesh: usize,
        /// Primitive index within the mesh.
        primitive: usize,
    },
    /// A rigid mesh node following one joint.
    Rigid {
        /// Node index in the file.
        node: usize,
        /// The skeleton joint it follows.
        joint: usize,
    },
}

/// One part of the merged template.
#[derive(Clone, Debug, PartialEq)]
pub struct CharacterPart {
    /// Where it comes from.
    pub source: PartSource,
    /// Mesh or node name.
    pub name: String,
    /// Material index, if the file gives one.
    pub material: Option<usize>,
    /// First template vertex.
    pub first_vertex: usize,
    /// Number of vertices.
    pub vertex_count: usize,
}

/// A glTF character as one template (see the module docs).
#[derive(Clone, Debug)]
pub struct GltfCharacter {
    /// The skeleton, bound in the canonical space (same joints, names and rest nodes as the
    /// file's largest skin; inverse bind matrices re-expressed by the rest transform).
    pub skeleton: Skeleton,
    /// The merged template in the canonical space.
    pub template: Template,
    /// Per-vertex weights on `skeleton`'s joints.
    pub skin: StaticSkin,
    /// The parts of `template`, in order: the largest skin's primitives, then other skins',
    /// then rigid parts in node order.
    pub parts: Vec<CharacterPart>,
    /// The map from the largest skin's bind space to the canonical space (`M` of the module
    /// docs; the identity when the file needs none).
    pub rest_transform: Mat4,
    /// Meshes of the file not in the template, each with the reason.
    pub left_out: Vec<String>,
}

impl GltfCharacter {
    /// Vertices that come from skinned meshes.
    #[must_use]
    pub fn skinned_vertices(&self) -> usize {
        self.parts
            .iter()
            .filter(|p| matches!(p.source, PartSource::Skinned { .. }))
            .map(|p| p.vertex_count)
            .sum()
    }
}

fn config_error(reason: String) -> SynthError {
    SynthError::Config {
        field: "character",
        reason,
    }
}

/// Normals of a part mapped by `linear` (the inverse transpose of the positions' linear map),
/// or recomputed from the mapped triangles where the file's are missing or degenerate.
fn mapped_normals(part: &Template, positions: &[Vec3], linear: Mat3) -> Vec<Vec3> {
    let usable = part.normals.len() == part.positions.len()
        && part
            .normals
            .iter()
            .all(|n| n.is_finite() && n.length() > 0.5);
    if !usable {
        return area_weighted_normals(positions, &part.triangles);
    }
    if linear == Mat3::IDENTITY {
        return part.normals.clone();
    }
    let normal_map = linear.inverse().transpose();
    part.normals
        .iter()
        .map(|&n| (normal_map * n).try_normalize().unwrap_or(Vec3::Y))
        .collect()
}

/// The merged template under construction: geometry and weights.
#[derive(Default)]
struct Builder {
    template: Template,
    uvs: Vec<Option<Vec<glam::Vec2>>>,
    colors: Vec<Option<Vec<Vec3>>>,
    offsets: Vec<u32>,
    joints: Vec<u32>,
    weights: Vec<f32>,
}

impl Builder {
    /// Appends a part whose mapped positions, normals and influences are given.
    fn push(
        &mut self,
        part: &Template,
        positions: Vec<Vec3>,
        normals: Vec<Vec3>,
        influences: impl Iterator<Item = Vec<(u32, f32)>>,
    ) {
        let base = self.template.positions.len() as u32;
        self.template.positions.extend(positions);
        self.template.normals.extend(normals);
        self.template
            .triangles
            .extend(part.triangles.iter().map(|t| t.map(|i| i + base)));
        self.uvs.push(part.uvs.clone());
        self.colors.push(part.colors.clone());
        if self.offsets.is_empty() {
            self.offsets.push(0);
        }
        for row in influences {
            for (j, w) in row {
                self.joints.push(j);
                self.weights.push(w);
            }
            self.offsets.push(self.joints.len() as u32);
        }
    }

    fn finish(mut self, joint_count: usize) -> Result<(Template, StaticSkin), SynthError> {
        // Attributes only some parts have are dropped (the trainer colours such templates).
        if self.uvs.iter().all(Option::is_some) {
            self.template.uvs = Some(self.uvs.into_iter().flatten().flatten().collect());
        }
        if self.colors.iter().all(Option::is_some) {
            self.template.colors = Some(self.colors.into_iter().flatten().flatten().collect());
        }
        let skin = StaticSkin::new(self.offsets, self.joints, self.weights, joint_count)?;
        Ok((self.template, skin))
    }
}

/// The vertices `first..first + count` of a template as a template of their own.
fn slice_template(t: &Template, first: usize, count: usize, triangles: (usize, usize)) -> Template {
    let range = first..first + count;
    let tri = &t.triangles[triangles.0..triangles.0 + triangles.1];
    Template {
        positions: t.positions[range.clone()].to_vec(),
        normals: t
            .normals
            .get(range.clone())
            .map_or_else(Vec::new, <[Vec3]>::to_vec),
        triangles: tri.iter().map(|tr| tr.map(|i| i - first as u32)).collect(),
        uvs: t
            .uvs
            .as_ref()
            .and_then(|u| u.get(range.clone()).map(<[_]>::to_vec)),
        colors: t
            .colors
            .as_ref()
            .and_then(|c| c.get(range).map(<[_]>::to_vec)),
        part_labels: None,
    }
}

/// `m` when it differs from the identity by more than [`IDENTITY_TOLERANCE`] of its size,
/// else the identity exactly.
fn snap_identity(m: DMat4) -> DMat4 {
    let size = m.to_cols_array().iter().fold(1.0f64, |a, b| a.max(b.abs()));
    let diff = (m - DMat4::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, b| a.max(b.abs()));
    if diff <= IDENTITY_TOLERANCE * size {
        DMat4::IDENTITY
    } else {
        m
    }
}

/// The skin's skeleton with its inverse bind matrices re-expressed by `rest` (`IBM · rest⁻¹`)
/// and the bind pose derived from them, as the importer derives it.
fn rebind(skin: &GltfSkin, rest: DMat4) -> Result<Skeleton, SynthError> {
    let sk = &skin.skeleton;
    if rest == DMat4::IDENTITY {
        return Ok(sk.clone());
    }
    let rest_inv = rest.inverse();
    let base = sk.base().as_dmat4();
    let mut bind_world: Vec<DMat4> = Vec::with_capacity(sk.len());
    let mut bind_local = Vec::with_capacity(sk.len());
    let mut inverse_bind = Vec::with_capacity(sk.len());
    for j in 0..sk.len() {
        let ibm = sk.inverse_bind()[j].as_dmat4() * rest_inv;
        let world = ibm.inverse();
        let parent_world = sk.parents()[j].map_or(base, |p| bind_world[p]);
        let local = parent_world.inverse() * world;
        let t = Transform::from_mat4(&local.as_mat4());
        let rebuilt = parent_world * t.to_mat4().as_dmat4();
        let scale = world
            .to_cols_array()
            .iter()
            .fold(1.0f64, |a, b| a.max(b.abs()));
        let err = (rebuilt - world)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |a, b| a.max(b.abs()));
        if !t.is_finite() || err > BIND_TOLERANCE * scale {
            return Err(config_error(format!(
                "joint `{}`: its bind pose in the rest scene is not a TRS transform (shear?)",
                sk.names()[j]
            )));
        }
        bind_world.push(world);
        bind_local.push(t);
        inverse_bind.push(ibm.as_mat4());
    }
    Ok(Skeleton::new(
        sk.names().to_vec(),
        sk.parents().to_vec(),
        bind_local,
        Some(inverse_bind),
        Some(sk.dofs().to_vec()),
        sk.base(),
    )?)
}

/// Builds the character of `doc` around its largest skin (see the module docs).
pub fn assemble(doc: &GltfDocument) -> Result<GltfCharacter, SynthError> {
    let main = doc
        .largest_skin()
        .ok_or_else(|| config_error(format!("{} has no skin", doc.source.display())))?;
    let sk = &main.skeleton;
    let mut rest_world = vec![Mat4::IDENTITY; sk.len()];
    sk.world_matrices(&main.default_pose(), &mut rest_world)?;
    // Root-most skin joint: the first in topological order that the skin lists.
    let root = (0..sk.len())
        .find(|&j| main.joint_skin_index[j].is_some())
        .ok_or_else(|| config_error("the largest skin lists no joint".into()))?;
    let rest = snap_identity(rest_world[root].as_dmat4() * sk.inverse_bind()[root].as_dmat4());
    let skeleton = rebind(main, rest)?;
    let bind_world: Vec<DMat4> = skeleton
        .inverse_bind()
        .iter()
        .map(|m| m.as_dmat4().inverse())
        .collect();
    let joint_of_node = |node: usize| main.joint_nodes.iter().position(|&n| n == node);

    let mut builder = Builder::default();
    let mut parts = Vec::new();
    let mut left_out = Vec::new();
    // Skins: the largest first, then every other skin over the same joints.
    let mut skins: Vec<&GltfSkin> = vec![main];
    skins.extend(doc.skins.iter().filter(|s| s.index != main.index));
    for s in skins {
        // Skeleton joint of each of this skin's joints, by node.
        let map: Option<Vec<usize>> = s.joint_nodes.iter().map(|&n| joint_of_node(n)).collect();
        let Some(map) = map else {
            for p in &s.primitives {
                left_out.push(format!(
                    "mesh `{}` (skin {}): its skeleton is not the character's",
                    p.mesh_name, s.index
                ));
            }
            continue;
        };
        // Each of this skin's joints: the map from its bind space to the canonical one (`M`
        // itself for the largest skin, by construction).
        let to_rest: Vec<DMat4> = if s.index == main.index {
            vec![rest; s.skeleton.len()]
        } else {
            (0..s.skeleton.len())
                .map(|k| bind_world[map[k]] * s.skeleton.inverse_bind()[k].as_dmat4())
                .collect()
        };
        for p in &s.primitives {
            let part = slice_template(
                &s.template,
                p.first_vertex,
                p.vertex_count,
                (p.first_triangle, p.triangle_count),
            );
            let mut positions = Vec::with_capacity(p.vertex_count);
            let mut rows = Vec::with_capacity(p.vertex_count);
            for (i, &x) in part.positions.iter().enumerate() {
                let (js, ws) = s.skin.influences(p.first_vertex + i);
                let x = x.as_dvec3();
                let first = js.first().map_or(rest, |&k| to_rest[k as usize]);
                // Joints that agree on the bind pose need no blend (and the identity then
                // keeps the file's bits).
                let y = if js.iter().all(|&k| to_rest[k as usize] == first) {
                    first.transform_point3(x)
                } else {
                    js.iter()
                        .zip(ws)
                        .map(|(&k, &w)| to_rest[k as usize].transform_point3(x) * f64::from(w))
                        .sum()
                };
                positions.push(y.as_vec3());
                rows.push(
                    js.iter()
                        .zip(ws)
                        .map(|(&k, &w)| (map[k as usize] as u32, w))
                        .collect::<Vec<_>>(),
                );
            }
            // The part's linear map for normals: its heaviest joint's (exact for the usual
            // case, where every joint of the skin agrees).
            let linear = Mat3::from_mat4(to_rest[heaviest_joint(s, p.first_vertex)].as_mat4());
            let normals = mapped_normals(&part, &positions, linear);
            parts.push(CharacterPart {
                source: PartSource::Skinned {
                    skin: s.index,
                    mesh: p.mesh,
                    primitive: p.primitive,
                },
                name: p.mesh_name.clone(),
                material: p.material,
                first_vertex: builder.template.positions.len(),
                vertex_count: p.vertex_count,
            });
            builder.push(&part, positions, normals, rows.into_iter());
        }
    }
    // Rigid parts: mesh nodes below (or at) a skeleton joint.
    for mesh in &doc.static_meshes {
        let mut at = Some(mesh.node);
        let joint = loop {
            match at {
                None => break None,
                Some(n) => match joint_of_node(n) {
                    Some(j) => break Some(j),
                    None => at = doc.nodes.get(n).and_then(|i| i.parent),
                },
            }
        };
        let Some(joint) = joint else {
            left_out.push(format!(
                "mesh node `{}`: no joint of the character above it",
                mesh.name
            ));
            continue;
        };
        if mesh.template.positions.is_empty() || mesh.template.triangles.is_empty() {
            continue;
        }
        // Node space → the joint's space at rest → the joint's bind pose in the canonical space.
        let to_rest =
            bind_world[joint] * rest_world[joint].as_dmat4().inverse() * mesh.world.as_dmat4();
        let positions: Vec<Vec3> = mesh
            .template
            .positions
            .iter()
            .map(|p| to_rest.transform_point3(p.as_dvec3()).as_vec3())
            .collect();
        let normals = mapped_normals(
            &mesh.template,
            &positions,
            Mat3::from_mat4(to_rest.as_mat4()),
        );
        parts.push(CharacterPart {
            source: PartSource::Rigid {
                node: mesh.node,
                joint,
            },
            name: mesh.name.clone(),
            material: None,
            first_vertex: builder.template.positions.len(),
            vertex_count: positions.len(),
        });
        let n = positions.len();
        builder.push(
            &mesh.template,
            positions,
            normals,
            std::iter::repeat_n(vec![(joint as u32, 1.0f32)], n),
        );
    }
    if builder.template.positions.is_empty() {
        return Err(config_error(format!(
            "{}: no mesh moves with the skeleton of skin {}",
            doc.source.display(),
            main.index
        )));
    }
    let (template, skin) = builder.finish(skeleton.len())?;
    Ok(GltfCharacter {
        skeleton,
        template,
        skin,
        parts,
        rest_transform: rest.as_mat4(),
        left_out,
    })
}

/// The skin joint with the largest weight on vertex `v` of skin `s`.
fn heaviest_joint(s: &GltfSkin, v: usize) -> usize {
    let (js, ws) = s.skin.influences(v);
    js.iter()
        .zip(ws)
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(&j, _)| j as usize)
}
