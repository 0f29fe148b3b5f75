//! The fast path behind the C ABI: a mesh bound once with a few nodes where SkinNet runs per
//! frame, every other vertex's weights interpolated from them (the runtime's `FastMesh`,
//! `FastFrame` and `FastSkinJob`; measurements in `docs/experiments/fast-path.md`).
//!
//! Per frame: `skf_frame_set_pose`, then [`skf_fast_nodes_update`] once (SkinNet at the
//! nodes: the frame's only network work, whatever the mesh size), then [`skf_skin_fast`] on any
//! vertex ranges, from any threads.

use skinfield_runtime::{
    FastFrame, FastMesh, FastOptions, InterleavedJob, Vec3, Vec4, WeightSource,
};

use crate::frame::SkfFrame;
use crate::mesh::SkfMesh;
use crate::model::SkfModel;
use crate::ptr;
use crate::skin::{SkfScratch, SkfVertexLayout, method_from_code};
use crate::status::{Failure, SkfStatus, guard};

/// Bind-time settings of the fast path ([`skf_fast_options_default`] gives the measured
/// defaults: 128 nodes, 4 neighbours, 4 base joints).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SkfFastOptions {
    /// Nodes at which SkinNet runs per frame (capped at the mesh's welded vertex count).
    pub nodes: usize,
    /// Nodes each vertex interpolates from (1 to 8).
    pub neighbours: usize,
    /// Strongest bind-pose joints kept per vertex as its exact base (0 to 8; 0 interpolates
    /// whole weights from the nodes).
    pub base_influences: usize,
}

impl From<&SkfFastOptions> for FastOptions {
    fn from(o: &SkfFastOptions) -> Self {
        FastOptions {
            nodes: o.nodes,
            neighbours: o.neighbours,
            base_influences: o.base_influences,
            ..FastOptions::DEFAULT
        }
    }
}

/// The default fast-path settings.
#[unsafe(no_mangle)]
pub extern "C" fn skf_fast_options_default() -> SkfFastOptions {
    let d = FastOptions::DEFAULT;
    SkfFastOptions {
        nodes: d.nodes,
        neighbours: d.neighbours,
        base_influences: d.base_influences,
    }
}

/// A mesh bound for the fast path (opaque), with the rest normals and tangents of the mesh it
/// was bound from.
pub struct SkfFastMesh {
    pub(crate) fast: FastMesh,
    normals: Option<Vec<Vec3>>,
    tangents: Option<Vec<Vec4>>,
}

/// SkinNet's weights at a fast mesh's nodes for one posed frame (opaque; one per mesh per
/// frame in flight).
pub struct SkfFastNodes {
    pub(crate) nodes: FastFrame,
}

/// Binds `mesh` (bound to `model` by `skf_mesh_bind`) for the fast path: `triangles` holds
/// `3 × triangle_count` vertex indices (nullable when `triangle_count` is 0: a point cloud,
/// whose nodes are then found by straight-line distance), `options` (nullable: the defaults)
/// the settings. Costs one exact SkinNet evaluation of every vertex and graph searches, once.
/// Release with [`skf_fast_mesh_free`].
///
/// # Safety
/// `model` and `mesh` must be live; `triangles` must hold the stated number of indices;
/// `options` null or readable; `out_fast_mesh` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_fast_mesh_bind(
    model: *const SkfModel,
    mesh: *const SkfMesh,
    triangles: *const u32,
    triangle_count: usize,
    options: *const SkfFastOptions,
    out_fast_mesh: *mut *mut SkfFastMesh,
) -> SkfStatus {
    guard("skf_fast_mesh_bind", || {
        // SAFETY: the caller's contract above.
        let model = unsafe { ptr::object(model, "model") }?;
        // SAFETY: as above.
        let mesh = unsafe { ptr::object(mesh, "mesh") }?;
        if out_fast_mesh.is_null() {
            return Err(crate::status::null("out_fast_mesh"));
        }
        let options = if options.is_null() {
            FastOptions::DEFAULT
        } else {
            // SAFETY: non-null, the caller's contract above.
            FastOptions::from(unsafe { ptr::object(options, "options") }?)
        };
        let triangles: Vec<[u32; 3]> = if triangle_count == 0 {
            Vec::new()
        } else {
            let len = triangle_count.checked_mul(3).ok_or_else(|| {
                Failure::invalid(format!("`triangle_count` = {triangle_count} is absurd"))
            })?;
            // SAFETY: the caller's contract above.
            let t = unsafe { ptr::slice(triangles, len, "triangles") }?;
            t.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
        };
        let fast = FastMesh::bind(
            &model.net,
            mesh.bound.rest_positions(),
            &triangles,
            &options,
        )
        .map_err(Failure::invalid)?;
        let handle = Box::into_raw(Box::new(SkfFastMesh {
            fast,
            normals: mesh.normals.clone(),
            tangents: mesh.tangents.clone(),
        }));
        // SAFETY: checked non-null above; the caller guarantees it is writable.
        unsafe { ptr::write(out_fast_mesh, handle, "out_fast_mesh") }
    })
}

/// Releases a fast mesh (null is ignored).
///
/// # Safety
/// `fast_mesh` must come from [`skf_fast_mesh_bind`] and not have been freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_fast_mesh_free(fast_mesh: *mut SkfFastMesh) {
    if !fast_mesh.is_null() {
        // SAFETY: the caller's contract: a live box from skf_fast_mesh_bind.
        drop(unsafe { Box::from_raw(fast_mesh) });
    }
}

/// The number of nodes SkinNet runs at per frame for `fast_mesh` (`*out_count`).
///
/// # Safety
/// `fast_mesh` must be live; `out_count` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_fast_mesh_node_count(
    fast_mesh: *const SkfFastMesh,
    out_count: *mut usize,
) -> SkfStatus {
    guard("skf_fast_mesh_node_count", || {
        // SAFETY: the caller's contract above.
        let fast_mesh = unsafe { ptr::object(fast_mesh, "fast_mesh") }?;
        // SAFETY: the caller's contract above.
        unsafe { ptr::write(out_count, fast_mesh.fast.node_count(), "out_count") }
    })
}

/// Makes the node buffers of `fast_mesh`. Release with [`skf_fast_nodes_free`].
///
/// # Safety
/// `fast_mesh` must be live; `out_nodes` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_fast_nodes_new(
    fast_mesh: *const SkfFastMesh,
    out_nodes: *mut *mut SkfFastNodes,
) -> SkfStatus {
    guard("skf_fast_nodes_new", || {
        // SAFETY: the caller's contract above.
        let fast_mesh = unsafe { ptr::object(fast_mesh, "fast_mesh") }?;
        if out_nodes.is_null() {
            return Err(crate::status::null("out_nodes"));
        }
        let handle = Box::into_raw(Box::new(SkfFastNodes {
            nodes: FastFrame::new(&fast_mesh.fast),
        }));
        // SAFETY: checked non-null above; the caller guarantees it is writable.
        unsafe { ptr::write(out_nodes, handle, "out_nodes") }
    })
}

/// Releases node buffers (null is ignored).
///
/// # Safety
/// `nodes` must come from [`skf_fast_nodes_new`] and not have been freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_fast_nodes_free(nodes: *mut SkfFastNodes) {
    if !nodes.is_null() {
        // SAFETY: the caller's contract: a live box from skf_fast_nodes_new.
        drop(unsafe { Box::from_raw(nodes) });
    }
}

/// Runs SkinNet at `fast_mesh`'s nodes for the frame's pose into `nodes`: once per frame, after
/// `skf_frame_set_pose` and before [`skf_skin_fast`]. Does not allocate.
///
/// # Safety
/// All handles must be live; `nodes` and `scratch` used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_fast_nodes_update(
    model: *const SkfModel,
    fast_mesh: *const SkfFastMesh,
    frame: *const SkfFrame,
    scratch: *mut SkfScratch,
    nodes: *mut SkfFastNodes,
) -> SkfStatus {
    guard("skf_fast_nodes_update", || {
        // SAFETY: the caller's contract above (and for the four below).
        let model = unsafe { ptr::object(model, "model") }?;
        // SAFETY: as above.
        let fast_mesh = unsafe { ptr::object(fast_mesh, "fast_mesh") }?;
        // SAFETY: as above.
        let frame = unsafe { ptr::object(frame, "frame") }?;
        // SAFETY: as above.
        let scratch = unsafe { ptr::object_mut(scratch, "scratch") }?;
        // SAFETY: as above.
        let nodes = unsafe { ptr::object_mut(nodes, "nodes") }?;
        nodes
            .nodes
            .update(
                &model.net,
                &fast_mesh.fast,
                &frame.state,
                &mut scratch.scratch,
            )
            .map_err(Failure::invalid)
    })
}

/// Skins vertices `first_vertex .. first_vertex + count` of `fast_mesh` with the fast path's
/// weights for the frame's pose (`nodes` updated for it by [`skf_fast_nodes_update`]) into
/// `out`, laid out as for `skf_skin`. `method` is `SKF_METHOD_LBS` or `SKF_METHOD_DQS`;
/// `influences` (1 to 8) is the number of strongest joints DQS keeps per vertex (LBS ignores
/// it). Does not allocate; ranges of one frame may be skinned concurrently.
///
/// # Safety
/// All handles must be live; `out` must point to `out_len` writable bytes no other thread
/// writes.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn skf_skin_fast(
    fast_mesh: *const SkfFastMesh,
    frame: *const SkfFrame,
    nodes: *const SkfFastNodes,
    method: u32,
    influences: usize,
    first_vertex: usize,
    count: usize,
    layout: *const SkfVertexLayout,
    out: *mut u8,
    out_len: usize,
) -> SkfStatus {
    guard("skf_skin_fast", || {
        // SAFETY: the caller's contract above (and for the three below).
        let fast_mesh = unsafe { ptr::object(fast_mesh, "fast_mesh") }?;
        // SAFETY: as above.
        let frame = unsafe { ptr::object(frame, "frame") }?;
        // SAFETY: as above.
        let nodes = unsafe { ptr::object(nodes, "nodes") }?;
        // SAFETY: as above.
        let layout = unsafe { ptr::object(layout, "layout") }?;
        let method = method_from_code(method)?;
        // SAFETY: the caller's contract above.
        let out = unsafe { ptr::slice_mut(out, out_len, "out") }?;
        InterleavedJob::<'_, Vec<f32>> {
            source: WeightSource::Fast {
                mesh: &fast_mesh.fast,
                frame: &frame.state,
                nodes: &nodes.nodes,
                influences,
            },
            method,
            first_vertex,
            count,
            rest_normals: fast_mesh.normals.as_deref(),
            rest_tangents: fast_mesh.tangents.as_deref(),
            layout: layout.into(),
            out,
        }
        .run()
        .map_err(Failure::invalid)
    })
}
