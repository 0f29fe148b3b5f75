//! The model handle: a loaded `.skf`, its joint names for C, and the optional map from the
//! engine's joint order.

use std::ffi::{CString, c_char};
use std::path::Path;

use skinfield_runtime::{JointMap, Mat4, RuntimeError, SkinNetModel};
use skinfield_runtime::{SkfFileError, read_skf_file};

use crate::ptr;
use crate::status::{Failure, SkfStatus, guard};

/// A SkinNet model loaded from a `.skf` (opaque). Immutable once its joint map is set, so one
/// model may serve any number of meshes and threads.
pub struct SkfModel {
    pub(crate) net: SkinNetModel,
    names: Vec<CString>,
    pub(crate) map: Option<JointMap>,
}

impl SkfModel {
    fn new(net: SkinNetModel) -> Self {
        // Joint names come from a validated file; an interior NUL is cut rather than refused.
        let names = net
            .skeleton()
            .names()
            .iter()
            .map(|n| CString::new(n.split('\0').next().unwrap_or("")).unwrap_or_default())
            .collect();
        Self {
            net,
            names,
            map: None,
        }
    }

    /// Number of transforms a frame takes: the engine's joints once mapped, else the model's.
    pub(crate) fn frame_joint_count(&self) -> usize {
        self.map
            .as_ref()
            .map_or(self.net.joint_count(), JointMap::engine_joint_count)
    }
}

fn load_error(e: RuntimeError) -> Failure {
    Failure::new(SkfStatus::InvalidFile, e.to_string())
}

/// Loads a model from the bytes of a `.skf` file (copied; the buffer may be freed afterwards).
/// On success `*out_model` owns a model to release with [`skf_model_free`].
///
/// # Safety
/// `bytes` must point to `len` readable bytes; `out_model` must be writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_model_load(
    bytes: *const u8,
    len: usize,
    out_model: *mut *mut SkfModel,
) -> SkfStatus {
    guard("skf_model_load", || {
        // SAFETY: the caller's contract above.
        let bytes = unsafe { ptr::slice(bytes, len, "bytes") }?;
        if out_model.is_null() {
            return Err(crate::status::null("out_model"));
        }
        let net = SkinNetModel::from_skf(bytes).map_err(load_error)?;
        let model = Box::into_raw(Box::new(SkfModel::new(net)));
        // SAFETY: checked non-null above; the caller guarantees it is writable.
        unsafe { ptr::write(out_model, model, "out_model") }
    })
}

/// Loads a model from a `.skf` file (`path` is UTF-8).
///
/// # Safety
/// `path` must be a NUL-terminated string; `out_model` must be writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_model_load_file(
    path: *const c_char,
    out_model: *mut *mut SkfModel,
) -> SkfStatus {
    guard("skf_model_load_file", || {
        // SAFETY: the caller's contract above.
        let path = unsafe { ptr::utf8(path, "path") }?;
        if out_model.is_null() {
            return Err(crate::status::null("out_model"));
        }
        let bytes = read_skf_file(Path::new(path)).map_err(|e| {
            let status = match e {
                SkfFileError::Io { .. } => SkfStatus::Io,
                _ => SkfStatus::InvalidFile,
            };
            Failure::new(status, e.to_string())
        })?;
        let net = SkinNetModel::from_skf(&bytes)
            .map_err(|e| Failure::new(SkfStatus::InvalidFile, format!("{path}: {e}")))?;
        let model = Box::into_raw(Box::new(SkfModel::new(net)));
        // SAFETY: checked non-null above; the caller guarantees it is writable.
        unsafe { ptr::write(out_model, model, "out_model") }
    })
}

/// Releases a model (null is ignored). Meshes, frames and scratches made from it must be
/// released first or never used again.
///
/// # Safety
/// `model` must come from `skf_model_load*` and not have been freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_model_free(model: *mut SkfModel) {
    if !model.is_null() {
        // SAFETY: the caller's contract: a live box from skf_model_load*.
        drop(unsafe { Box::from_raw(model) });
    }
}

/// The number of joints of the model (`*out_count`).
///
/// # Safety
/// `model` must be a live model; `out_count` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_model_joint_count(
    model: *const SkfModel,
    out_count: *mut usize,
) -> SkfStatus {
    guard("skf_model_joint_count", || {
        // SAFETY: the caller's contract above.
        let model = unsafe { ptr::object(model, "model") }?;
        // SAFETY: the caller's contract above.
        unsafe { ptr::write(out_count, model.net.joint_count(), "out_count") }
    })
}

/// The name of model joint `joint` (`*out_name`, NUL-terminated UTF-8, valid while the model
/// lives).
///
/// # Safety
/// `model` must be a live model; `out_name` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_model_joint_name(
    model: *const SkfModel,
    joint: usize,
    out_name: *mut *const c_char,
) -> SkfStatus {
    guard("skf_model_joint_name", || {
        // SAFETY: the caller's contract above.
        let model = unsafe { ptr::object(model, "model") }?;
        let name = model.names.get(joint).ok_or_else(|| {
            Failure::invalid(format!(
                "`joint` = {joint}, but the model has {} joints",
                model.names.len()
            ))
        })?;
        // SAFETY: the caller's contract above.
        unsafe { ptr::write(out_name, name.as_ptr(), "out_name") }
    })
}

/// Maps the engine's skeleton onto the model by joint name: `names[i]` is the engine's joint
/// `i`; from now on `skf_frame_set_pose` takes `count` transforms in the engine's order.
/// `parents` (nullable) holds each engine joint's parent index, `-1` for a root; when given,
/// the hierarchies must agree on the mapped joints. Every model joint must be named exactly
/// once; extra engine joints are ignored. Call at load time, before the model is shared
/// between threads. On failure the previous map is kept.
///
/// # Safety
/// `model` must be a live model no other thread uses; `names` must point to `count` pointers
/// to NUL-terminated strings; `parents`, if not null, to `count` integers.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_model_map_joints(
    model: *mut SkfModel,
    names: *const *const c_char,
    count: usize,
    parents: *const i32,
) -> SkfStatus {
    guard("skf_model_map_joints", || {
        // SAFETY: the caller's contract above.
        let model = unsafe { ptr::object_mut(model, "model") }?;
        // SAFETY: the caller's contract above.
        let raw = unsafe { ptr::slice(names, count, "names") }?;
        let names = raw
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                // SAFETY: the caller's contract: each entry is a NUL-terminated string.
                unsafe { ptr::utf8(p, &format!("names[{i}]")) }
            })
            .collect::<Result<Vec<&str>, Failure>>()?;
        let map = JointMap::new(model.net.skeleton(), &names).map_err(Failure::invalid)?;
        if !parents.is_null() {
            // SAFETY: the caller's contract above.
            let raw = unsafe { ptr::slice(parents, count, "parents") }?;
            let parents = raw
                .iter()
                .enumerate()
                .map(|(i, &p)| match p {
                    -1 => Ok(None),
                    p => usize::try_from(p)
                        .ok()
                        .filter(|&p| p < count)
                        .map(Some)
                        .ok_or_else(|| {
                            Failure::invalid(format!(
                                "`parents[{i}]` = {p}: accepted -1 or 0..{count}"
                            ))
                        }),
                })
                .collect::<Result<Vec<_>, Failure>>()?;
            map.check_parents(model.net.skeleton(), &names, &parents)
                .map_err(Failure::invalid)?;
        }
        model.map = Some(map);
        Ok(())
    })
}

/// The transform from the engine's bind space (where its mesh's rest positions live) to the
/// model's canonical space (where `skf_mesh_bind` wants them), from the engine's inverse bind
/// matrices: `engine_inverse_binds` holds `count` 4×4 matrices, 16 floats each, column-major
/// as glTF stores them, in the engine's joint order once the model is mapped (else the
/// model's). Importers and trainers may re-express the bind space (an armature that scales or
/// turns the character), so an engine binds `M · p`, not `p`. `out_matrix` receives `M` (16
/// floats, column-major); `out_normal_matrix` (nullable) the inverse transpose of its linear
/// part (9 floats, column-major) for the normals, renormalised after it (tangents take `M`'s
/// linear part). Refused, naming the joint, when some joint's bind pose differs from the
/// model's by more than `tolerance` (e.g. 1e-3) relative to the matrices' size after the
/// alignment: positions alone cannot fix that.
///
/// # Safety
/// `model` must be live; `engine_inverse_binds` must point to `16 × count` floats;
/// `out_matrix` to 16 writable floats and `out_normal_matrix`, if not null, to 9.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_model_bind_space(
    model: *const SkfModel,
    engine_inverse_binds: *const f32,
    count: usize,
    tolerance: f32,
    out_matrix: *mut f32,
    out_normal_matrix: *mut f32,
) -> SkfStatus {
    guard("skf_model_bind_space", || {
        // SAFETY: the caller's contract above.
        let model = unsafe { ptr::object(model, "model") }?;
        let len = count
            .checked_mul(16)
            .ok_or_else(|| Failure::invalid(format!("`count` = {count} is absurd")))?;
        // SAFETY: the caller's contract above.
        let raw = unsafe { ptr::slice(engine_inverse_binds, len, "engine_inverse_binds") }?;
        // SAFETY: the caller's contract above.
        let out = unsafe { ptr::slice_mut(out_matrix, 16, "out_matrix") }?;
        let out_normal = if out_normal_matrix.is_null() {
            None
        } else {
            // SAFETY: non-null, the caller's contract above.
            Some(unsafe { ptr::slice_mut(out_normal_matrix, 9, "out_normal_matrix") }?)
        };
        if !(tolerance.is_finite() && tolerance >= 0.0) {
            return Err(Failure::invalid(format!(
                "`tolerance` = {tolerance}: expected a finite value ≥ 0"
            )));
        }
        let binds: Vec<Mat4> = raw.chunks_exact(16).map(Mat4::from_cols_slice).collect();
        let skeleton = model.net.skeleton();
        let identity;
        let map = match &model.map {
            Some(map) => map,
            None => {
                identity = JointMap::identity(skeleton);
                &identity
            }
        };
        let space = map
            .bind_space(skeleton, &binds, tolerance)
            .map_err(Failure::invalid)?;
        out.copy_from_slice(&space.matrix().to_cols_array());
        if let Some(n) = out_normal {
            n.copy_from_slice(&space.normal_matrix().to_cols_array());
        }
        Ok(())
    })
}
