//! The C ABI's per-frame calls (`skf_frame_set_pose`, `skf_skin`) never touch the heap on
//! success, whatever the joint map and the layout.

#[path = "../../runtime/tests/common/mod.rs"]
mod common;
#[path = "../../runtime/tests/common/counting.rs"]
mod counting;
mod support;

use std::ffi::{CString, c_char};
use std::ptr::null_mut;

use counting::count_allocations;
use skinfield::*;
use skinfield_runtime::SkinNetModel;

#[test]
fn per_frame_c_calls_do_not_allocate() {
    let bytes = common::vinecs_bytes(11, 51);
    let net = SkinNetModel::from_skf(&bytes).unwrap();
    let mut rng = common::rng(52);
    let n = 200;
    let positions = common::random_points(n, &mut rng);
    let (normals, tangents) = common::random_frames(n, &mut rng);
    let mut names: Vec<CString> = net
        .skeleton()
        .names()
        .iter()
        .rev()
        .map(|s| CString::new(s.as_str()).unwrap())
        .collect();
    names.push(CString::new("prop").unwrap());
    let ptrs: Vec<*const c_char> = names.iter().map(|s| s.as_ptr()).collect();
    let poses: Vec<Vec<SkfTransform>> = (0..3)
        .map(|_| {
            let pose = common::random_pose(net.skeleton(), &mut rng, 0.6);
            let mut engine = vec![pose.locals[0]; names.len()];
            for (j, l) in pose.locals.iter().enumerate() {
                engine[names.len() - 2 - j] = *l;
            }
            engine.iter().map(support::c_transform).collect()
        })
        .collect();
    let layout = SkfVertexLayout {
        stride: 48,
        position_offset: 0,
        normal_offset: 12,
        tangent_offset: 24,
    };
    let (mut model, mut mesh, mut frame, mut scratch) =
        (null_mut(), null_mut(), null_mut(), null_mut());
    // SAFETY: live handles and arrays of the stated lengths throughout.
    unsafe {
        assert_eq!(
            skf_model_load(bytes.as_ptr(), bytes.len(), &mut model),
            SkfStatus::Ok
        );
        let s = skf_model_map_joints(model, ptrs.as_ptr(), ptrs.len(), std::ptr::null());
        assert_eq!(s, SkfStatus::Ok);
        let s = skf_mesh_bind(
            model,
            positions.as_ptr().cast(),
            normals.as_ptr().cast(),
            tangents.as_ptr().cast(),
            n,
            &mut mesh,
        );
        assert_eq!(s, SkfStatus::Ok);
        assert_eq!(skf_frame_new(model, &mut frame), SkfStatus::Ok);
        assert_eq!(skf_scratch_new(model, &mut scratch), SkfStatus::Ok);
        let mut vbo = vec![0u8; skf_vertex_buffer_len(&layout, n)];
        let count = count_allocations(|| {
            for (f, pose) in poses.iter().enumerate() {
                let s = skf_frame_set_pose(frame, model, pose.as_ptr(), pose.len());
                assert_eq!(s, SkfStatus::Ok);
                let s = skf_skin(
                    model,
                    mesh,
                    frame,
                    scratch,
                    (f % 2) as u32,
                    0,
                    n,
                    &layout,
                    vbo.as_mut_ptr(),
                    vbo.len(),
                );
                assert_eq!(s, SkfStatus::Ok);
            }
        });
        assert_eq!(count, 0, "the per-frame C calls allocated {count} times");
        assert!(vbo.iter().any(|&b| b != 0));
        skf_scratch_free(scratch);
        skf_frame_free(frame);
        skf_mesh_free(mesh);
        skf_model_free(model);
    }
}
