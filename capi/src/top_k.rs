//! The fast path's top-k influences behind the C ABI, for an engine that skins on its own (a
//! GPU skinning shader reading glTF-style `JOINTS_0` / `WEIGHTS_0` streams): per frame, the `K`
//! strongest joints of every vertex and their weights, in the engine's joint order once the
//! model is mapped ([`skf_model_map_joints`](crate::model::skf_model_map_joints)).
//!
//! The weights of each vertex sum exactly to one in the chosen format (255, 65535, or 1.0 in
//! any summation order), as the runtime's `TopKJob` writes them.

use std::ffi::c_void;

use skinfield_runtime::fast::MAX_INFLUENCES;
use skinfield_runtime::{TopKIndices, TopKJob, TopKWeights};

use crate::fast::{SkfFastMesh, SkfFastNodes};
use crate::frame::SkfFrame;
use crate::model::SkfModel;
use crate::ptr;
use crate::status::{Failure, SkfStatus, guard};

/// Joint indices as one byte each (skeletons of up to 256 joints).
pub const SKF_TOP_K_INDEX_U8: u32 = 0;
/// Joint indices as two bytes each.
pub const SKF_TOP_K_INDEX_U16: u32 = 1;
/// Weights as unorm8 (255 is one).
pub const SKF_TOP_K_WEIGHT_UNORM8: u32 = 0;
/// Weights as unorm16 (65535 is one).
pub const SKF_TOP_K_WEIGHT_UNORM16: u32 = 1;
/// Weights as f32 (multiples of 2⁻²⁴, summing exactly to 1.0).
pub const SKF_TOP_K_WEIGHT_F32: u32 = 2;

/// Writes the `influences` (1 to 8) strongest joints of vertices `first_vertex ..
/// first_vertex + count` of `fast_mesh`, strongest first, with the fast path's weights for the
/// frame's pose (`nodes` updated for it by `skf_fast_nodes_update`): `influences` indices per
/// vertex into `out_indices` (format `index_format`, `SKF_TOP_K_INDEX_*`, holding
/// `out_indices_len` elements) and as many weights into `out_weights` (`SKF_TOP_K_WEIGHT_*`,
/// `out_weights_len` elements); both must hold at least `count × influences` elements, aligned
/// for their element type. Indices are the engine's joints when `model` is mapped, else the
/// model's. Does not allocate; ranges of one frame may be written concurrently.
///
/// # Safety
/// All handles must be live; each output must point to its stated number of writable elements
/// of its format, which no other thread writes.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn skf_fast_top_k(
    model: *const SkfModel,
    fast_mesh: *const SkfFastMesh,
    frame: *const SkfFrame,
    nodes: *const SkfFastNodes,
    influences: usize,
    first_vertex: usize,
    count: usize,
    index_format: u32,
    out_indices: *mut c_void,
    out_indices_len: usize,
    weight_format: u32,
    out_weights: *mut c_void,
    out_weights_len: usize,
) -> SkfStatus {
    guard("skf_fast_top_k", || {
        // SAFETY: the caller's contract above (and for the three below).
        let model = unsafe { ptr::object(model, "model") }?;
        // SAFETY: as above.
        let fast_mesh = unsafe { ptr::object(fast_mesh, "fast_mesh") }?;
        // SAFETY: as above.
        let frame = unsafe { ptr::object(frame, "frame") }?;
        // SAFETY: as above.
        let nodes = unsafe { ptr::object(nodes, "nodes") }?;
        if !(1..=MAX_INFLUENCES).contains(&influences) {
            return Err(Failure::invalid(format!(
                "`influences` = {influences}, expected 1..={MAX_INFLUENCES}"
            )));
        }
        if !frame.state.is_for(&model.net) {
            return Err(Failure::invalid(
                "`model` is not the model `frame` was made for".to_string(),
            ));
        }
        let len = count.checked_mul(influences).ok_or_else(|| {
            Failure::invalid(format!("`count` = {count} × `influences` is absurd"))
        })?;
        for (given, name) in [
            (out_indices_len, "out_indices_len"),
            (out_weights_len, "out_weights_len"),
        ] {
            if given < len {
                return Err(Failure::invalid(format!(
                    "`{name}` = {given}, but {count} vertices × {influences} influences need {len}"
                )));
            }
        }
        let engine = model.map.as_ref().map(|m| m.engine_of_model());
        // The largest index written: the engine's once mapped, else the model's.
        let joints = model.frame_joint_count();
        let indices = match index_format {
            SKF_TOP_K_INDEX_U8 if joints > 1 << 8 => {
                return Err(Failure::invalid(format!(
                    "`index_format` u8 holds joints 0..=255, but the skeleton has {joints}"
                )));
            }
            SKF_TOP_K_INDEX_U8 => {
                // SAFETY: the caller's contract above: `out_indices_len` bytes.
                let out = unsafe { ptr::slice_mut(out_indices.cast::<u8>(), len, "out_indices") }?;
                TopKIndices::U8(out)
            }
            SKF_TOP_K_INDEX_U16 if joints > 1 << 16 => {
                return Err(Failure::invalid(format!(
                    "`index_format` u16 holds joints 0..=65535, but the skeleton has {joints}"
                )));
            }
            SKF_TOP_K_INDEX_U16 => {
                // SAFETY: the caller's contract above: `out_indices_len` u16 (alignment checked).
                let out = unsafe { ptr::slice_mut(out_indices.cast::<u16>(), len, "out_indices") }?;
                TopKIndices::U16(out)
            }
            other => {
                return Err(Failure::invalid(format!(
                    "`index_format` = {other}, expected SKF_TOP_K_INDEX_U8 or SKF_TOP_K_INDEX_U16"
                )));
            }
        };
        let weights = match weight_format {
            SKF_TOP_K_WEIGHT_UNORM8 => {
                // SAFETY: the caller's contract above: `out_weights_len` bytes.
                let out = unsafe { ptr::slice_mut(out_weights.cast::<u8>(), len, "out_weights") }?;
                TopKWeights::Unorm8(out)
            }
            SKF_TOP_K_WEIGHT_UNORM16 => {
                // SAFETY: the caller's contract above (alignment checked).
                let out = unsafe { ptr::slice_mut(out_weights.cast::<u16>(), len, "out_weights") }?;
                TopKWeights::Unorm16(out)
            }
            SKF_TOP_K_WEIGHT_F32 => {
                // SAFETY: the caller's contract above (alignment checked).
                let out = unsafe { ptr::slice_mut(out_weights.cast::<f32>(), len, "out_weights") }?;
                TopKWeights::F32(out)
            }
            other => {
                return Err(Failure::invalid(format!(
                    "`weight_format` = {other}, expected SKF_TOP_K_WEIGHT_UNORM8, \
                     SKF_TOP_K_WEIGHT_UNORM16 or SKF_TOP_K_WEIGHT_F32"
                )));
            }
        };
        let mut job = TopKJob {
            mesh: &fast_mesh.fast,
            frame: &frame.state,
            nodes: &nodes.nodes,
            influences,
            first_vertex,
            out_indices: indices,
            out_weights: weights,
        };
        job.run().map_err(Failure::invalid)?;
        // The job writes the model's joints; an engine with its own order reads its own. The
        // casts cannot truncate: every engine index fits the format (checked above).
        if let Some(engine) = engine {
            match &mut job.out_indices {
                TopKIndices::U8(out) => {
                    for i in out.iter_mut() {
                        *i = engine[usize::from(*i)] as u8;
                    }
                }
                TopKIndices::U16(out) => {
                    for i in out.iter_mut() {
                        *i = engine[usize::from(*i)] as u16;
                    }
                }
            }
        }
        Ok(())
    })
}
