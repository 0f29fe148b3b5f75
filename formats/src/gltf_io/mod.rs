//! glTF 2.0 import and export (`std` feature).
//!
//! * [`load_gltf`] / [`load_gltf_slice`] read a `.gltf` (with external or data-URI buffers) or
//!   a `.glb` into a [`GltfDocument`]: one [`GltfSkin`] per skin (skeleton, template mesh and
//!   static weights of every skinned primitive that uses it), the animations as [`Clip`]s, the
//!   unskinned mesh nodes as [`StaticMesh`]es, and counts over every primitive as stored.
//! * [`write_gltf_character`] and [`write_gltf_mesh_sequence`] write skinned characters and
//!   posed mesh sequences that this importer and other glTF tools read back.
//!
//! Untrusted bytes are checked before the gltf crate sees them (GLB container, buffer sources,
//! every accessor's byte range: [`container`]), and the crate's calls run under
//! `catch_unwind` besides, so a malformed file gives a [`GltfError`], never a panic.

mod animation;
pub mod container;
mod export;
mod import;
mod primitive;
mod skin;

use std::path::PathBuf;

use crate::math::Transform;
use crate::mesh::{MeshError, Template};
use crate::skeleton::{Skeleton, SkeletonError};
use crate::skin::{SkinError, StaticSkin};

pub use animation::{Channel, ChannelProperty, Clip, Interpolation};
pub use export::{
    DEFAULT_SEQUENCE_FPS, write_gltf_character, write_gltf_mesh_sequence,
    write_gltf_mesh_sequence_at,
};
pub use import::{load_gltf, load_gltf_slice};

/// Why a glTF file could not be read or written. Every variant names the file; the field or
/// JSON path is named where one is at fault.
#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    /// The file (or an external buffer) could not be read or written.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The GLB container (header, chunk table) is malformed.
    #[error("{file}: {reason}")]
    Container {
        /// The file.
        file: String,
        /// What is wrong.
        reason: String,
    },
    /// The gltf crate refused the JSON (syntax or glTF schema validation).
    #[error("{file}: invalid glTF: {message}")]
    Parse {
        /// The file.
        file: String,
        /// The gltf crate's message (it names the JSON path).
        message: String,
    },
    /// A field holds a value the importer cannot use.
    #[error("{file}: `{field}`: {reason}")]
    Field {
        /// The file.
        file: String,
        /// The JSON path, e.g. `skins[0].inverseBindMatrices`.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// A count exceeds one of the importer's caps.
    #[error("{file}: `{field}` is {count}, more than the cap of {cap}")]
    TooLarge {
        /// The file.
        file: String,
        /// What was counted.
        field: String,
        /// The count.
        count: u64,
        /// The cap.
        cap: u64,
    },
    /// A skin's joints do not form a valid [`Skeleton`].
    #[error("{file}: `skins[{skin}]`: {source}")]
    Skeleton {
        /// The file.
        file: String,
        /// The skin index.
        skin: usize,
        /// The skeleton error.
        source: SkeletonError,
    },
    /// A skin's weights are invalid (e.g. a vertex without any positive weight).
    #[error("{file}: `skins[{skin}]` weights: {source}")]
    Weights {
        /// The file.
        file: String,
        /// The skin index.
        skin: usize,
        /// The weight error.
        source: SkinError,
    },
    /// A mesh handed to an exporter is invalid.
    #[error("{file}: mesh: {source}")]
    Mesh {
        /// The file.
        file: String,
        /// The mesh error.
        source: MeshError,
    },
    /// The gltf crate panicked on this input (caught; defence in depth behind the checks).
    #[error("{file}: the glTF parser failed on malformed input: {message}")]
    Panic {
        /// The file.
        file: String,
        /// The panic message.
        message: String,
    },
    /// The data handed to an exporter cannot be written as glTF.
    #[error("{file}: cannot export: {reason}")]
    Export {
        /// The file.
        file: String,
        /// What is wrong.
        reason: String,
    },
}

/// One node of the file's hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeInfo {
    /// The node's name, or `node_{index}` when it has none.
    pub name: String,
    /// Parent node index.
    pub parent: Option<usize>,
    /// Default local transform (TRS, or the decomposed matrix).
    pub local: Transform,
    /// Mesh index, if the node instances a mesh.
    pub mesh: Option<usize>,
    /// Skin index, if the node's mesh is skinned.
    pub skin: Option<usize>,
}

/// Where one glTF primitive lies inside a [`GltfSkin`]'s template.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PrimitiveInfo {
    /// Mesh index in the file.
    pub mesh: usize,
    /// Primitive index within the mesh.
    pub primitive: usize,
    /// The mesh's name (empty when it has none).
    pub mesh_name: String,
    /// Material index, if any.
    pub material: Option<usize>,
    /// First template vertex of this primitive.
    pub first_vertex: usize,
    /// Number of vertices (the accessor's count: unwelded as stored).
    pub vertex_count: usize,
    /// First template triangle of this primitive.
    pub first_triangle: usize,
    /// Number of triangles (strips and fans converted; points and lines give none).
    pub triangle_count: usize,
}

/// One skin of a glTF file with the geometry that uses it.
#[derive(Clone, Debug)]
pub struct GltfSkin {
    /// Index of the skin in the file.
    pub index: usize,
    /// The skin's name, or `skin_{index}`.
    pub name: String,
    /// Joints: the skin's joints plus the nodes between them that are not in the skin, in
    /// topological order. `bind_local` comes from the inverse bind matrices; `base` is the
    /// world transform of the skeleton roots' parent node.
    pub skeleton: Skeleton,
    /// Every primitive skinned by this skin, concatenated in file order, positions in the
    /// skin's bind space (the mesh node's own transform does not apply, as glTF defines).
    /// Empty when no mesh node uses the skin.
    pub template: Template,
    /// Normalised weights; joint indices refer to `skeleton` joints.
    pub skin: StaticSkin,
    /// The primitives inside `template`, in order.
    pub primitives: Vec<PrimitiveInfo>,
    /// glTF node index of every skeleton joint.
    pub joint_nodes: Vec<usize>,
    /// Index in the skin's `joints` array of every skeleton joint (`None` for in-between nodes).
    pub joint_skin_index: Vec<Option<usize>>,
    /// Default node TRS of every skeleton joint: what a clip leaves on joints it does not
    /// animate (this is not `bind_local`, which comes from the inverse bind matrices).
    pub node_defaults: Vec<Transform>,
    /// Nodes above the skeleton roots, outermost first (their product is `skeleton.base()`
    /// when none is animated).
    pub root_ancestors: Vec<usize>,
    /// Default TRS of each of `root_ancestors`.
    pub root_ancestor_defaults: Vec<Transform>,
}

impl GltfSkin {
    /// Number of joints the skin itself lists (without the in-between nodes).
    #[must_use]
    pub fn skin_joint_count(&self) -> usize {
        self.joint_skin_index.iter().filter(|s| s.is_some()).count()
    }

    /// Skeleton joint of a skin joint index (the numbering of the file's `JOINTS_n`).
    #[must_use]
    pub fn joint_of_skin_index(&self, skin_index: usize) -> Option<usize> {
        self.joint_skin_index
            .iter()
            .position(|&s| s == Some(skin_index))
    }

    /// The pose that leaves every joint at its node's default TRS (the file's rest scene).
    #[must_use]
    pub fn default_pose(&self) -> crate::pose::Pose {
        crate::pose::Pose {
            locals: self.node_defaults.clone(),
        }
    }
}

/// A mesh node without a skin (a rigid part, a static prop, a frame of a mesh sequence).
#[derive(Clone, Debug)]
pub struct StaticMesh {
    /// The node index.
    pub node: usize,
    /// The node's name.
    pub name: String,
    /// Mesh index.
    pub mesh: usize,
    /// All primitives of the mesh concatenated, in the mesh's own space as stored.
    pub template: Template,
    /// The node's default world matrix (mesh space to world space).
    pub world: glam::Mat4,
}

/// Everything Skinfield takes from one glTF file.
#[derive(Clone, Debug)]
pub struct GltfDocument {
    /// One entry per skin, in file order.
    pub skins: Vec<GltfSkin>,
    /// One clip per animation, in file order.
    pub clips: Vec<Clip>,
    /// Every node of the file.
    pub nodes: Vec<NodeInfo>,
    /// Every node that instances a mesh without a skin, in node order.
    pub static_meshes: Vec<StaticMesh>,
    /// Vertices over every primitive of every mesh, as stored (unwelded, each mesh once).
    pub vertex_count: usize,
    /// Triangles over every primitive of every mesh, as stored.
    pub triangle_count: usize,
    /// Number of primitives over every mesh.
    pub primitive_count: usize,
    /// Where the document came from (for messages).
    pub source: PathBuf,
}

impl GltfDocument {
    /// The skin that lists the most joints (the first of equals), if any.
    #[must_use]
    pub fn largest_skin(&self) -> Option<&GltfSkin> {
        self.skins
            .iter()
            .fold(None, |best: Option<&GltfSkin>, s| match best {
                Some(b) if b.skin_joint_count() >= s.skin_joint_count() => Some(b),
                _ => Some(s),
            })
    }

    /// The clip called `name`.
    #[must_use]
    pub fn clip(&self, name: &str) -> Option<&Clip> {
        self.clips.iter().find(|c| c.name == name)
    }
}
