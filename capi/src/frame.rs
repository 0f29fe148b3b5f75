//! The frame handle: one pose of a model (skinning matrices, pose features, the network's pose
//! terms), set from the engine's local transforms without allocating.

use skinfield_runtime::{FrameState, Pose, Quat, Transform, Vec3};

use crate::model::SkfModel;
use crate::ptr;
use crate::status::{Failure, SkfStatus, guard};

/// A joint's local transform (relative to its parent), applied as translation · rotation ·
/// scale, as in glTF.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkfTransform {
    /// Translation in the parent's frame.
    pub translation: [f32; 3],
    /// Unit quaternion, `x, y, z, w`.
    pub rotation: [f32; 4],
    /// Per-axis scale.
    pub scale: [f32; 3],
}

impl From<&SkfTransform> for Transform {
    fn from(t: &SkfTransform) -> Self {
        Transform {
            translation: Vec3::from_array(t.translation),
            rotation: Quat::from_array(t.rotation),
            scale: Vec3::from_array(t.scale),
        }
    }
}

/// One pose of a model (opaque). One frame per character instance; a frame may be read by any
/// number of concurrent `skf_skin` calls once set.
pub struct SkfFrame {
    model_id: *const SkfModel,
    pub(crate) state: FrameState,
    pose: Pose,
    engine: Vec<Transform>,
}

/// Makes a frame for `model` (not posed until [`skf_frame_set_pose`] succeeds). Release with
/// [`skf_frame_free`].
///
/// # Safety
/// `model` must be a live model; `out_frame` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_frame_new(
    model: *const SkfModel,
    out_frame: *mut *mut SkfFrame,
) -> SkfStatus {
    guard("skf_frame_new", || {
        // SAFETY: the caller's contract above.
        let m = unsafe { ptr::object(model, "model") }?;
        if out_frame.is_null() {
            return Err(crate::status::null("out_frame"));
        }
        let frame = Box::into_raw(Box::new(SkfFrame {
            model_id: model,
            state: FrameState::new(&m.net),
            pose: m.net.skeleton().bind_pose(),
            engine: Vec::with_capacity(m.frame_joint_count()),
        }));
        // SAFETY: checked non-null above; the caller guarantees it is writable.
        unsafe { ptr::write(out_frame, frame, "out_frame") }
    })
}

/// Releases a frame (null is ignored).
///
/// # Safety
/// `frame` must come from [`skf_frame_new`] and not have been freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_frame_free(frame: *mut SkfFrame) {
    if !frame.is_null() {
        // SAFETY: the caller's contract: a live box from skf_frame_new.
        drop(unsafe { Box::from_raw(frame) });
    }
}

/// Poses the frame: `locals` holds `count` local transforms, in the engine's joint order when
/// the model has a joint map (`skf_model_map_joints`), else in the model's. Runs forward
/// kinematics, the pose features and the network's pose terms. Does not allocate (except once
/// after the joint map grew). A wrong count or a NaN transform is refused and leaves the frame
/// unposed.
///
/// # Safety
/// `frame` must be a live frame of `model` that no other thread uses; `locals` must point to
/// `count` transforms.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_frame_set_pose(
    frame: *mut SkfFrame,
    model: *const SkfModel,
    locals: *const SkfTransform,
    count: usize,
) -> SkfStatus {
    guard("skf_frame_set_pose", || {
        // SAFETY: the caller's contract above.
        let frame = unsafe { ptr::object_mut(frame, "frame") }?;
        // SAFETY: the caller's contract above.
        let m = unsafe { ptr::object(model, "model") }?;
        if !std::ptr::eq(frame.model_id, model) {
            return Err(Failure::invalid("`frame` was made for another model"));
        }
        // SAFETY: the caller's contract above.
        let locals = unsafe { ptr::slice(locals, count, "locals") }?;
        let result = match &m.map {
            Some(map) => {
                frame.engine.clear();
                frame.engine.extend(locals.iter().map(Transform::from));
                frame.state.set_engine_pose(&m.net, map, &frame.engine)
            }
            None => {
                if count != frame.pose.locals.len() {
                    return Err(Failure::invalid(format!(
                        "`count` = {count}, but the model has {} joints (map the engine's \
                         skeleton with skf_model_map_joints to pass its own)",
                        frame.pose.locals.len()
                    )));
                }
                for (dst, src) in frame.pose.locals.iter_mut().zip(locals) {
                    *dst = src.into();
                }
                frame.state.set_pose(&m.net, &frame.pose)
            }
        };
        result.map_err(|e| {
            // The runtime names the field after its own argument names.
            Failure::invalid(e.to_string().replace("engine_locals", "locals"))
        })
    })
}
