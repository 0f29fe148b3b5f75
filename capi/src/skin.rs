//! Skinning a vertex range into the engine's interleaved vertex buffer, and the per-thread
//! scratch memory it needs.

use skinfield_runtime::{InterleavedJob, Method, Scratch, VertexLayout, WeightSource};

use crate::frame::SkfFrame;
use crate::mesh::SkfMesh;
use crate::model::SkfModel;
use crate::ptr;
use crate::status::{Failure, SkfStatus, guard};

/// [`SkfVertexLayout`] offset of an attribute the buffer does not have (all bits set, i.e.
/// `SIZE_MAX`).
pub const SKF_ABSENT: usize = !0;
/// Linear blend skinning.
pub const SKF_METHOD_LBS: u32 = 0;
/// Dual-quaternion skinning (scale dropped).
pub const SKF_METHOD_DQS: u32 = 1;

/// Where each skinned attribute goes in one vertex of an interleaved buffer: byte offsets
/// within a vertex of `stride` bytes. Positions and normals are 3 floats, tangents 4 (x, y, z,
/// handedness); [`SKF_ABSENT`] for an attribute not written. Other bytes are left untouched.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SkfVertexLayout {
    /// Bytes from one vertex to the next.
    pub stride: usize,
    /// Byte offset of the position.
    pub position_offset: usize,
    /// Byte offset of the normal, or `SKF_ABSENT`.
    pub normal_offset: usize,
    /// Byte offset of the tangent, or `SKF_ABSENT`.
    pub tangent_offset: usize,
}

impl From<&SkfVertexLayout> for VertexLayout {
    fn from(l: &SkfVertexLayout) -> Self {
        let opt = |o: usize| (o != SKF_ABSENT).then_some(o);
        VertexLayout {
            stride: l.stride,
            position: l.position_offset,
            normal: opt(l.normal_offset),
            tangent: opt(l.tangent_offset),
        }
    }
}

/// The skinning method a C caller names by `SKF_METHOD_*`.
pub(crate) fn method_from_code(method: u32) -> Result<Method, Failure> {
    match method {
        SKF_METHOD_LBS => Ok(Method::Lbs),
        SKF_METHOD_DQS => Ok(Method::Dqs),
        m => Err(Failure::invalid(format!(
            "`method` = {m}: accepted SKF_METHOD_LBS (0) or SKF_METHOD_DQS (1)"
        ))),
    }
}

/// Per-thread working memory of the network (opaque): one per thread that skins.
pub struct SkfScratch {
    pub(crate) scratch: Scratch,
}

/// Makes scratch memory for `model`'s network. Release with [`skf_scratch_free`].
///
/// # Safety
/// `model` must be a live model; `out_scratch` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_scratch_new(
    model: *const SkfModel,
    out_scratch: *mut *mut SkfScratch,
) -> SkfStatus {
    guard("skf_scratch_new", || {
        // SAFETY: the caller's contract above.
        let model = unsafe { ptr::object(model, "model") }?;
        if out_scratch.is_null() {
            return Err(crate::status::null("out_scratch"));
        }
        let scratch = Box::into_raw(Box::new(SkfScratch {
            scratch: Scratch::new(&model.net),
        }));
        // SAFETY: checked non-null above; the caller guarantees it is writable.
        unsafe { ptr::write(out_scratch, scratch, "out_scratch") }
    })
}

/// Releases scratch memory (null is ignored).
///
/// # Safety
/// `scratch` must come from [`skf_scratch_new`] and not have been freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_scratch_free(scratch: *mut SkfScratch) {
    if !scratch.is_null() {
        // SAFETY: the caller's contract: a live box from skf_scratch_new.
        drop(unsafe { Box::from_raw(scratch) });
    }
}

/// Bytes an interleaved buffer needs for `count` vertices with `layout`
/// (`(count − 1) · stride` plus the end of the last attribute); 0 on a layout that does not
/// fit its stride or on overflow.
///
/// # Safety
/// `layout` must point to a layout (null gives 0).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_vertex_buffer_len(
    layout: *const SkfVertexLayout,
    count: usize,
) -> usize {
    // SAFETY: the caller's contract above.
    let Ok(layout) = (unsafe { ptr::object(layout, "layout") }) else {
        return 0;
    };
    let layout = VertexLayout::from(layout);
    if layout.validate().is_err() {
        return 0;
    }
    layout.buffer_len(count).unwrap_or(0)
}

/// Skins vertices `first_vertex .. first_vertex + count` of `mesh` with SkinNet's weights for
/// the frame's pose, writing positions (and normals and tangents where `layout` has them) into
/// `out`, which starts at vertex `first_vertex` and holds `out_len` bytes (at least
/// [`skf_vertex_buffer_len`]). `method` is [`SKF_METHOD_LBS`] or [`SKF_METHOD_DQS`]. Does not
/// allocate; ranges of one frame may be skinned concurrently, each thread with its own scratch.
///
/// # Safety
/// All handles must be live and belong to `model`; `scratch` used by no other thread; `out`
/// must point to `out_len` writable bytes no other thread writes.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn skf_skin(
    model: *const SkfModel,
    mesh: *const SkfMesh,
    frame: *const SkfFrame,
    scratch: *mut SkfScratch,
    method: u32,
    first_vertex: usize,
    count: usize,
    layout: *const SkfVertexLayout,
    out: *mut u8,
    out_len: usize,
) -> SkfStatus {
    guard("skf_skin", || {
        // SAFETY: the caller's contract above (and for the four below).
        let model = unsafe { ptr::object(model, "model") }?;
        // SAFETY: as above.
        let mesh = unsafe { ptr::object(mesh, "mesh") }?;
        // SAFETY: as above.
        let frame = unsafe { ptr::object(frame, "frame") }?;
        // SAFETY: as above.
        let scratch = unsafe { ptr::object_mut(scratch, "scratch") }?;
        // SAFETY: as above.
        let layout = unsafe { ptr::object(layout, "layout") }?;
        let method = method_from_code(method)?;
        // SAFETY: the caller's contract above.
        let out = unsafe { ptr::slice_mut(out, out_len, "out") }?;
        InterleavedJob {
            source: WeightSource::Exact {
                model: &model.net,
                mesh: &mesh.bound,
                frame: &frame.state,
                scratch: &mut scratch.scratch,
            },
            method,
            first_vertex,
            count,
            rest_normals: mesh.normals.as_deref(),
            rest_tangents: mesh.tangents.as_deref(),
            layout: layout.into(),
            out,
        }
        .run()
        .map_err(Failure::invalid)
    })
}
