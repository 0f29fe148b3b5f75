//! The C ABI called as C would call it: results equal the Rust runtime's bit for bit, the
//! interleaved writes leave other bytes alone, and every bad argument (null pointers, wrong
//! lengths, NaN transforms, truncated files, bad settings, handles of another model) returns
//! its status code with a message naming the function and the field.

#[path = "../../runtime/tests/common/mod.rs"]
mod common;
mod support;

use std::ffi::{CStr, CString, c_char};
use std::ptr::{null, null_mut};

use glam::{Vec3, Vec4};
use skinfield::*;
use skinfield_runtime::{
    BoundMesh, FrameState, Method, Pose, Scratch, SkinJob, SkinNetModel, Transform,
};
use support::{c_transform, fails, last_error};

/// Everything a test needs, made through the C ABI (freed on drop).
struct Handles {
    model: *mut SkfModel,
    mesh: *mut SkfMesh,
    frame: *mut SkfFrame,
    scratch: *mut SkfScratch,
}

impl Drop for Handles {
    fn drop(&mut self) {
        // SAFETY: each handle is live (or null) and freed once.
        unsafe {
            skf_scratch_free(self.scratch);
            skf_frame_free(self.frame);
            skf_mesh_free(self.mesh);
            skf_model_free(self.model);
        }
    }
}

const JOINTS: u32 = 7;
const VERTICES: usize = 150;

/// The engine's skeleton: the model's joints reversed, with two helper joints of its own.
fn engine_names(model: &SkinNetModel) -> Vec<CString> {
    let mut names: Vec<CString> = model
        .skeleton()
        .names()
        .iter()
        .rev()
        .map(|n| CString::new(n.as_str()).unwrap())
        .collect();
    names.insert(2, CString::new("ik_target").unwrap());
    names.push(CString::new("weapon_socket").unwrap());
    names
}

/// Engine index of each model joint, for `engine_names`' order.
fn engine_index(model: &SkinNetModel, names: &[CString]) -> Vec<usize> {
    model
        .skeleton()
        .names()
        .iter()
        .map(|n| names.iter().position(|e| e.to_str().unwrap() == n).unwrap())
        .collect()
}

fn engine_parents(model: &SkinNetModel, names: &[CString]) -> Vec<i32> {
    let idx = engine_index(model, names);
    let mut parents = vec![-1i32; names.len()];
    for (j, p) in model.skeleton().parents().iter().enumerate() {
        parents[idx[j]] = p.map_or(-1, |p| idx[p] as i32);
    }
    parents
}

fn setup(bytes: &[u8], positions: &[Vec3], normals: &[Vec3], tangents: &[Vec4]) -> Handles {
    let mut h = Handles {
        model: null_mut(),
        mesh: null_mut(),
        frame: null_mut(),
        scratch: null_mut(),
    };
    let net = SkinNetModel::from_skf(bytes).unwrap();
    let names = engine_names(&net);
    let name_ptrs: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
    let parents = engine_parents(&net, &names);
    // SAFETY: every pointer below points to live data of the stated length.
    unsafe {
        assert_eq!(
            skf_model_load(bytes.as_ptr(), bytes.len(), &mut h.model),
            SkfStatus::Ok
        );
        let s = skf_model_map_joints(h.model, name_ptrs.as_ptr(), names.len(), parents.as_ptr());
        assert_eq!(s, SkfStatus::Ok, "{}", last_error());
        let s = skf_mesh_bind(
            h.model,
            positions.as_ptr().cast(),
            normals.as_ptr().cast(),
            tangents.as_ptr().cast(),
            positions.len(),
            &mut h.mesh,
        );
        assert_eq!(s, SkfStatus::Ok, "{}", last_error());
        assert_eq!(skf_frame_new(h.model, &mut h.frame), SkfStatus::Ok);
        assert_eq!(skf_scratch_new(h.model, &mut h.scratch), SkfStatus::Ok);
    }
    h
}

fn fixture(seed: u64) -> (Vec<u8>, Vec<Vec3>, Vec<Vec3>, Vec<Vec4>) {
    let bytes = common::vinecs_bytes(JOINTS, seed);
    let mut rng = common::rng(seed + 1);
    let positions = common::random_points(VERTICES, &mut rng);
    let (normals, tangents) = common::random_frames(VERTICES, &mut rng);
    (bytes, positions, normals, tangents)
}

#[test]
fn c_abi_skins_exactly_as_the_rust_runtime_into_an_interleaved_buffer() {
    let (bytes, positions, normals, tangents) = fixture(11);
    let h = setup(&bytes, &positions, &normals, &tangents);
    let net = SkinNetModel::from_skf(&bytes).unwrap();
    let names = engine_names(&net);
    let idx = engine_index(&net, &names);
    let bound = BoundMesh::bind(&net, &positions).unwrap();
    let mut frame = FrameState::new(&net);
    let mut scratch = Scratch::new(&net);
    // A 64-byte vertex: position at 0, a UV at 12 the skinning must not touch, normal at 20,
    // tangent at 40, 8 bytes of padding.
    let layout = SkfVertexLayout {
        stride: 64,
        position_offset: 0,
        normal_offset: 20,
        tangent_offset: 40,
    };
    // SAFETY: a valid layout pointer.
    let len = unsafe { skf_vertex_buffer_len(&layout, VERTICES) };
    assert_eq!(len, (VERTICES - 1) * 64 + 56);
    let mut rng = common::rng(12);
    for (f, method, code) in [
        (0, Method::Lbs, SKF_METHOD_LBS),
        (1, Method::Dqs, SKF_METHOD_DQS),
        (2, Method::Lbs, SKF_METHOD_LBS),
    ] {
        let pose = common::random_pose(net.skeleton(), &mut rng, 0.6);
        let mut engine = vec![Transform::IDENTITY; names.len()];
        for (j, &e) in idx.iter().enumerate() {
            engine[e] = pose.locals[j];
        }
        let c_locals: Vec<SkfTransform> = engine.iter().map(c_transform).collect();
        let mut vbo = vec![0xABu8; len];
        // A range that starts and ends inside the network's tiles.
        let (first, count) = (
            if f == 2 { 37 } else { 0 },
            if f == 2 { 90 } else { VERTICES },
        );
        // SAFETY: live handles, arrays of the stated lengths.
        unsafe {
            let s = skf_frame_set_pose(h.frame, h.model, c_locals.as_ptr(), c_locals.len());
            assert_eq!(s, SkfStatus::Ok, "{}", last_error());
            let s = skf_skin(
                h.model,
                h.mesh,
                h.frame,
                h.scratch,
                code,
                first,
                count,
                &layout,
                vbo.as_mut_ptr(),
                vbo.len(),
            );
            assert_eq!(s, SkfStatus::Ok, "{}", last_error());
        }
        frame.set_pose(&net, &pose).unwrap();
        let mut p = vec![Vec3::ZERO; count];
        let mut n = vec![Vec3::ZERO; count];
        let mut t = vec![Vec4::ZERO; count];
        SkinJob {
            model: &net,
            mesh: &bound,
            frame: &frame,
            method,
            first_vertex: first,
            rest_normals: Some(&normals),
            rest_tangents: Some(&tangents),
            out_positions: &mut p,
            out_normals: Some(&mut n),
            out_tangents: Some(&mut t),
            out_weights: None,
        }
        .run(&mut scratch)
        .unwrap();
        let floats = |v: usize, at: usize, k: usize| -> Vec<f32> {
            (0..k)
                .map(|i| {
                    let o = v * 64 + at + 4 * i;
                    f32::from_ne_bytes(vbo[o..o + 4].try_into().unwrap())
                })
                .collect()
        };
        for v in 0..count {
            assert_eq!(floats(v, 0, 3), p[v].to_array(), "position {v}");
            assert_eq!(floats(v, 20, 3), n[v].to_array(), "normal {v}");
            assert_eq!(floats(v, 40, 4), t[v].to_array(), "tangent {v}");
            let untouched = (12..20).chain(56..64).filter(|&b| v * 64 + b < len);
            for b in untouched {
                assert_eq!(vbo[v * 64 + b], 0xAB, "vertex {v} byte {b}");
            }
        }
        let written = (count - 1) * 64 + 56;
        assert!(
            vbo[written..].iter().all(|&b| b == 0xAB),
            "bytes past the range"
        );
    }
}

#[test]
fn every_bad_argument_is_a_status_with_a_message_naming_it() {
    use SkfStatus::{InvalidArgument as Invalid, InvalidFile, Io, NullPointer as Null};
    let (bytes, positions, normals, tangents) = fixture(21);
    let h = setup(&bytes, &positions, &normals, &tangents);
    let net = SkinNetModel::from_skf(&bytes).unwrap();
    let names = engine_names(&net);
    let ptrs: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
    let parents = engine_parents(&net, &names);
    let good: Vec<SkfTransform> = vec![c_transform(&Transform::IDENTITY); names.len()];
    let layout = SkfVertexLayout {
        stride: 12,
        position_offset: 0,
        normal_offset: SKF_ABSENT,
        tangent_offset: SKF_ABSENT,
    };
    let mut vbo = vec![0u8; VERTICES * 12];
    let (other_bytes, ..) = fixture(22);
    let other = setup(&other_bytes, &positions, &normals, &tangents);
    let mut out_model = null_mut();
    let mut out_mesh = null_mut();
    let mut out_count = 0usize;
    let mut out_name = null();
    // SAFETY: every non-null pointer below is valid for what the function reads or writes;
    // the null and wrongly sized ones are exactly what is being tested.
    unsafe {
        // Loading.
        fails(
            skf_model_load(null(), 10, &mut out_model),
            Null,
            &["skf_model_load", "`bytes`"],
        );
        fails(
            skf_model_load(bytes.as_ptr(), bytes.len(), null_mut()),
            Null,
            &["`out_model`"],
        );
        for cut in [0, 1, 63, 64, 200, bytes.len() / 2, bytes.len() - 1] {
            fails(
                skf_model_load(bytes.as_ptr(), cut, &mut out_model),
                InvalidFile,
                &["skf"],
            );
            assert!(out_model.is_null());
        }
        let mut corrupt = bytes.clone();
        corrupt[100] ^= 0x40;
        fails(
            skf_model_load(corrupt.as_ptr(), corrupt.len(), &mut out_model),
            InvalidFile,
            &["checksum"],
        );
        fails(
            skf_model_load_file(null(), &mut out_model),
            Null,
            &["`path`"],
        );
        let missing = CString::new("/nonexistent/model.skf").unwrap();
        fails(
            skf_model_load_file(missing.as_ptr(), &mut out_model),
            Io,
            &["/nonexistent/model.skf"],
        );
        let dir = tempfile::tempdir().unwrap();
        let truncated = dir.path().join("truncated.skf");
        std::fs::write(&truncated, &bytes[..bytes.len() - 7]).unwrap();
        let truncated = CString::new(truncated.to_str().unwrap()).unwrap();
        fails(
            skf_model_load_file(truncated.as_ptr(), &mut out_model),
            InvalidFile,
            &["truncated.skf"],
        );
        let not_utf8 = [0xFFu8, 0xFE, 0];
        fails(
            skf_model_load_file(not_utf8.as_ptr().cast(), &mut out_model),
            Invalid,
            &["`path`", "UTF-8"],
        );

        // Model queries.
        fails(
            skf_model_joint_count(null(), &mut out_count),
            Null,
            &["`model`"],
        );
        fails(
            skf_model_joint_count(h.model, null_mut()),
            Null,
            &["`out_count`"],
        );
        fails(
            skf_model_joint_name(h.model, JOINTS as usize, &mut out_name),
            Invalid,
            &["`joint` = 7", "7 joints"],
        );
        fails(
            skf_model_joint_name(h.model, 0, null_mut()),
            Null,
            &["`out_name`"],
        );

        // Joint maps.
        fails(
            skf_model_map_joints(null_mut(), ptrs.as_ptr(), ptrs.len(), null()),
            Null,
            &["`model`"],
        );
        fails(
            skf_model_map_joints(h.model, null(), 3, null()),
            Null,
            &["`names`"],
        );
        let mut with_null = ptrs.clone();
        with_null[4] = null();
        fails(
            skf_model_map_joints(h.model, with_null.as_ptr(), ptrs.len(), null()),
            Null,
            &["`names[4]`"],
        );
        fails(
            skf_model_map_joints(h.model, ptrs.as_ptr(), 3, null()),
            Invalid,
            &["lacks", "joint"],
        );
        let mut dup = ptrs.clone();
        dup.push(ptrs[0]);
        fails(
            skf_model_map_joints(h.model, dup.as_ptr(), dup.len(), null()),
            Invalid,
            &["appears twice"],
        );
        let mut bad_parents = parents.clone();
        bad_parents[1] = 99;
        fails(
            skf_model_map_joints(h.model, ptrs.as_ptr(), ptrs.len(), bad_parents.as_ptr()),
            Invalid,
            &["`parents[1]` = 99"],
        );
        // Re-parent a mapped joint onto the helper joint `ik_target` (engine index 2).
        let child = parents
            .iter()
            .position(|&p| p >= 0 && names[p as usize].to_str().unwrap() != "ik_target")
            .unwrap();
        let mut moved = parents.clone();
        moved[child] = 2;
        fails(
            skf_model_map_joints(h.model, ptrs.as_ptr(), ptrs.len(), moved.as_ptr()),
            Invalid,
            &["parent", "`ik_target`"],
        );

        // Meshes.
        let p = positions.as_ptr().cast::<f32>();
        fails(
            skf_mesh_bind(null(), p, null(), null(), 3, &mut out_mesh),
            Null,
            &["`model`"],
        );
        fails(
            skf_mesh_bind(h.model, null(), null(), null(), 3, &mut out_mesh),
            Null,
            &["`positions`"],
        );
        fails(
            skf_mesh_bind(h.model, p, null(), null(), 0, &mut out_mesh),
            Invalid,
            &["`vertex_count` is 0"],
        );
        fails(
            skf_mesh_bind(h.model, p, null(), null(), usize::MAX / 2, &mut out_mesh),
            Invalid,
            &["`vertex_count`"],
        );
        fails(
            skf_mesh_bind(h.model, p, null(), null(), 3, null_mut()),
            Null,
            &["`out_mesh`"],
        );
        let mut nan = positions.clone();
        nan[5].y = f32::NAN;
        fails(
            skf_mesh_bind(
                h.model,
                nan.as_ptr().cast(),
                null(),
                null(),
                nan.len(),
                &mut out_mesh,
            ),
            Invalid,
            &["`positions`[5]"],
        );
        let mut nan_n = normals.clone();
        nan_n[2].x = f32::INFINITY;
        fails(
            skf_mesh_bind(
                h.model,
                p,
                nan_n.as_ptr().cast(),
                null(),
                VERTICES,
                &mut out_mesh,
            ),
            Invalid,
            &["`normals`[2]"],
        );
        let mut nan_t = tangents.clone();
        nan_t[9].w = f32::NAN;
        fails(
            skf_mesh_bind(
                h.model,
                p,
                null(),
                nan_t.as_ptr().cast(),
                VERTICES,
                &mut out_mesh,
            ),
            Invalid,
            &["`tangents`[9]"],
        );
        assert!(out_mesh.is_null());
        fails(
            skf_mesh_vertex_count(null(), &mut out_count),
            Null,
            &["`mesh`"],
        );

        // Frames.
        let mut out_frame = null_mut();
        fails(skf_frame_new(null(), &mut out_frame), Null, &["`model`"]);
        fails(skf_frame_new(h.model, null_mut()), Null, &["`out_frame`"]);
        fails(
            skf_frame_set_pose(null_mut(), h.model, good.as_ptr(), good.len()),
            Null,
            &["`frame`"],
        );
        fails(
            skf_frame_set_pose(h.frame, null(), good.as_ptr(), good.len()),
            Null,
            &["`model`"],
        );
        fails(
            skf_frame_set_pose(h.frame, h.model, null(), good.len()),
            Null,
            &["`locals`"],
        );
        fails(
            skf_frame_set_pose(h.frame, h.model, good.as_ptr(), good.len() - 1),
            Invalid,
            &["`locals`", "expected 9"],
        );
        fails(
            skf_frame_set_pose(h.frame, other.model, good.as_ptr(), good.len()),
            Invalid,
            &["another model"],
        );
        let mut nan_pose = good.clone();
        nan_pose[3].rotation[1] = f32::NAN;
        fails(
            skf_frame_set_pose(h.frame, h.model, nan_pose.as_ptr(), nan_pose.len()),
            Invalid,
            &["`locals`", "index 3"],
        );
        // A helper joint the model does not use may hold anything.
        let mut helper_nan = good.clone();
        helper_nan[2].translation[0] = f32::NAN;
        assert_eq!(
            skf_frame_set_pose(h.frame, h.model, helper_nan.as_ptr(), helper_nan.len()),
            SkfStatus::Ok
        );

        // Skinning. The frame is posed now.
        let skin = |model,
                    mesh,
                    frame,
                    scratch,
                    method,
                    first,
                    count,
                    layout: *const SkfVertexLayout,
                    out: *mut u8,
                    len| {
            skf_skin(
                model, mesh, frame, scratch, method, first, count, layout, out, len,
            )
        };
        let (m, me, fr, sc) = (
            h.model.cast_const(),
            h.mesh.cast_const(),
            h.frame.cast_const(),
            h.scratch,
        );
        let out = vbo.as_mut_ptr();
        let len = vbo.len();
        fails(
            skin(null(), me, fr, sc, 0, 0, VERTICES, &layout, out, len),
            Null,
            &["skf_skin", "`model`"],
        );
        fails(
            skin(m, null(), fr, sc, 0, 0, VERTICES, &layout, out, len),
            Null,
            &["`mesh`"],
        );
        fails(
            skin(m, me, null(), sc, 0, 0, VERTICES, &layout, out, len),
            Null,
            &["`frame`"],
        );
        fails(
            skin(m, me, fr, null_mut(), 0, 0, VERTICES, &layout, out, len),
            Null,
            &["`scratch`"],
        );
        fails(
            skin(m, me, fr, sc, 0, 0, VERTICES, null(), out, len),
            Null,
            &["`layout`"],
        );
        fails(
            skin(m, me, fr, sc, 0, 0, VERTICES, &layout, null_mut(), len),
            Null,
            &["`out`"],
        );
        fails(
            skin(m, me, fr, sc, 2, 0, VERTICES, &layout, out, len),
            Invalid,
            &["`method` = 2"],
        );
        fails(
            skin(m, me, fr, sc, 0, 0, VERTICES, &layout, out, len - 1),
            Invalid,
            &["`out`", "expected 1800"],
        );
        fails(
            skin(m, me, fr, sc, 0, 10, VERTICES, &layout, out, len),
            Invalid,
            &["vertex range 10..10+150"],
        );
        fails(
            skin(m, me, fr, sc, 0, usize::MAX, 1, &layout, out, len),
            Invalid,
            &["vertex range"],
        );
        let overlap = SkfVertexLayout {
            stride: 24,
            normal_offset: 8,
            ..layout
        };
        fails(
            skin(m, me, fr, sc, 0, 0, 4, &overlap, out, len),
            Invalid,
            &["`normal`", "overlaps"],
        );
        let short = SkfVertexLayout {
            stride: 8,
            ..layout
        };
        fails(
            skin(m, me, fr, sc, 0, 0, 4, &short, out, len),
            Invalid,
            &["`stride`"],
        );
        let past = SkfVertexLayout {
            stride: 24,
            tangent_offset: 12,
            ..layout
        };
        fails(
            skin(m, me, fr, sc, 0, 0, 4, &past, out, len),
            Invalid,
            &["`tangent`", "runs past"],
        );
        // Handles of another model.
        let (om, ome, ofr) = (
            other.model.cast_const(),
            other.mesh.cast_const(),
            other.frame.cast_const(),
        );
        fails(
            skin(m, ome, fr, sc, 0, 0, VERTICES, &layout, out, len),
            Invalid,
            &["`mesh`", "another model"],
        );
        fails(
            skin(m, me, ofr, sc, 0, 0, VERTICES, &layout, out, len),
            Invalid,
            &["`frame`", "another model"],
        );
        let _ = om;
        // A frame whose last pose failed is not skinned.
        assert_eq!(
            skf_frame_set_pose(h.frame, h.model, nan_pose.as_ptr(), nan_pose.len()),
            Invalid
        );
        fails(
            skin(m, me, fr, sc, 0, 0, VERTICES, &layout, out, len),
            Invalid,
            &["no pose"],
        );
        assert_eq!(skf_vertex_buffer_len(null(), 3), 0);
        assert_eq!(skf_vertex_buffer_len(&overlap, 3), 0);

        // The messages are per thread and the free functions ignore null.
        skf_model_free(null_mut());
        skf_mesh_free(null_mut());
        skf_frame_free(null_mut());
        skf_scratch_free(null_mut());
    }
    let message = last_error();
    let other_thread = std::thread::spawn(last_error).join().unwrap();
    assert!(!message.is_empty());
    assert_eq!(other_thread, "");
}

#[test]
fn a_model_without_a_joint_map_takes_transforms_in_its_own_order() {
    let (bytes, positions, ..) = fixture(31);
    let net = SkinNetModel::from_skf(&bytes).unwrap();
    let mut model = null_mut();
    let mut frame = null_mut();
    let pose: Pose = common::random_pose(net.skeleton(), &mut common::rng(32), 0.5);
    let locals: Vec<SkfTransform> = pose.locals.iter().map(c_transform).collect();
    // SAFETY: live handles and arrays of the stated lengths.
    unsafe {
        assert_eq!(
            skf_model_load(bytes.as_ptr(), bytes.len(), &mut model),
            SkfStatus::Ok
        );
        let mut joints = 0;
        assert_eq!(skf_model_joint_count(model, &mut joints), SkfStatus::Ok);
        assert_eq!(joints, JOINTS as usize);
        for j in 0..joints {
            let mut name = null();
            assert_eq!(skf_model_joint_name(model, j, &mut name), SkfStatus::Ok);
            assert_eq!(
                CStr::from_ptr(name).to_str().unwrap(),
                net.skeleton().names()[j]
            );
        }
        assert_eq!(skf_frame_new(model, &mut frame), SkfStatus::Ok);
        fails(
            skf_frame_set_pose(frame, model, locals.as_ptr(), locals.len() + 1),
            SkfStatus::InvalidArgument,
            &["`count` = 8", "skf_model_map_joints"],
        );
        assert_eq!(
            skf_frame_set_pose(frame, model, locals.as_ptr(), locals.len()),
            SkfStatus::Ok
        );
        let mut mesh = null_mut();
        assert_eq!(
            skf_mesh_bind(
                model,
                positions.as_ptr().cast(),
                null(),
                null(),
                positions.len(),
                &mut mesh
            ),
            SkfStatus::Ok
        );
        let mut count = 0;
        assert_eq!(skf_mesh_vertex_count(mesh, &mut count), SkfStatus::Ok);
        assert_eq!(count, VERTICES);
        skf_mesh_free(mesh);
        skf_frame_free(frame);
        skf_model_free(model);
    }
}

#[test]
fn the_bind_space_through_the_c_abi_is_the_rust_one() {
    use SkfStatus::{InvalidArgument as Invalid, NullPointer as Null};
    let (bytes, positions, normals, tangents) = fixture(71);
    let h = setup(&bytes, &positions, &normals, &tangents);
    let net = SkinNetModel::from_skf(&bytes).unwrap();
    let names = engine_names(&net);
    let idx = engine_index(&net, &names);
    // An engine whose bind space is the model's scaled to centimetres, turned Z-up and moved:
    // its inverse bind matrices are the model's times M.
    let m = glam::Mat4::from_scale_rotation_translation(
        Vec3::splat(0.01),
        glam::Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
        Vec3::new(0.1, -0.2, 0.3),
    );
    let mut binds = vec![glam::Mat4::IDENTITY; names.len()];
    for (j, &e) in idx.iter().enumerate() {
        binds[e] = net.skeleton().inverse_bind()[j] * m;
    }
    let flat: Vec<f32> = binds.iter().flat_map(|b| b.to_cols_array()).collect();
    let (mut out, mut normal) = ([0f32; 16], [0f32; 9]);
    let n = names.len();
    // SAFETY: live handle, arrays of the stated lengths; the null ones are what is tested.
    unsafe {
        assert_eq!(
            skf_model_bind_space(
                h.model,
                flat.as_ptr(),
                n,
                1e-4,
                out.as_mut_ptr(),
                normal.as_mut_ptr()
            ),
            SkfStatus::Ok,
            "{}",
            last_error()
        );
        let got = glam::Mat4::from_cols_array(&out);
        assert!(got.abs_diff_eq(m, 1e-6), "{got} vs {m}");
        // The same numbers as the Rust runtime's.
        let engine: Vec<&str> = names.iter().map(|c| c.to_str().unwrap()).collect();
        let space = skinfield_runtime::JointMap::new(net.skeleton(), &engine)
            .unwrap()
            .bind_space(net.skeleton(), &binds, 1e-4)
            .unwrap();
        assert_eq!(out, space.matrix().to_cols_array());
        assert_eq!(normal, space.normal_matrix().to_cols_array());
        // Unmapped, the matrices come in the model's joint order.
        let mut plain = null_mut();
        assert_eq!(
            skf_model_load(bytes.as_ptr(), bytes.len(), &mut plain),
            SkfStatus::Ok
        );
        let model_order: Vec<f32> = net
            .skeleton()
            .inverse_bind()
            .iter()
            .flat_map(|b| (*b * m).to_cols_array())
            .collect();
        let mut unmapped = [0f32; 16];
        let status = skf_model_bind_space(
            plain,
            model_order.as_ptr(),
            net.joint_count(),
            1e-4,
            unmapped.as_mut_ptr(),
            null_mut(),
        );
        skf_model_free(plain);
        assert_eq!(status, SkfStatus::Ok, "{}", last_error());
        assert_eq!(unmapped, out);
        // A normal matrix is optional.
        assert_eq!(
            skf_model_bind_space(
                h.model,
                flat.as_ptr(),
                n,
                1e-4,
                out.as_mut_ptr(),
                null_mut()
            ),
            SkfStatus::Ok
        );
        // One joint's bind pose moved by 5 % of the size: the bind poses differ.
        let moved = idx[3];
        let mut bad = flat.clone();
        bad[16 * moved + 12] += 0.05
            * bad[16 * moved..16 * moved + 16]
                .iter()
                .fold(0f32, |a, b| a.max(b.abs()));
        let normal_ptr = normal.as_mut_ptr();
        let call = |binds: *const f32, count, tolerance, out: *mut f32| {
            skf_model_bind_space(h.model, binds, count, tolerance, out, normal_ptr)
        };
        let joint = net.skeleton().names()[3].clone();
        let (bp, fp, op) = (bad.as_ptr(), flat.as_ptr(), out.as_mut_ptr());
        let nn = n.to_string();
        // Each call runs right before its message is read: the message is the last failure's.
        type Case<'a> = (SkfStatus, Box<dyn Fn() -> SkfStatus + 'a>, Vec<&'a str>);
        let cases: [Case; 8] = [
            (
                Invalid,
                Box::new(|| call(bp, n, 1e-4, op)),
                vec![&joint, "bind pose"],
            ),
            (
                Null,
                Box::new(|| skf_model_bind_space(null(), fp, n, 1e-4, op, null_mut())),
                vec!["model"],
            ),
            (
                Null,
                Box::new(|| call(null(), n, 1e-4, op)),
                vec!["engine_inverse_binds"],
            ),
            (
                Null,
                Box::new(|| call(fp, n, 1e-4, null_mut())),
                vec!["out_matrix"],
            ),
            (
                Invalid,
                Box::new(|| call(fp, n - 1, 1e-4, op)),
                vec!["engine_inverse_binds", &nn],
            ),
            (
                Invalid,
                Box::new(|| call(fp, usize::MAX, 1e-4, op)),
                vec!["count"],
            ),
            (
                Invalid,
                Box::new(|| call(fp, n, f32::NAN, op)),
                vec!["tolerance"],
            ),
            (
                Invalid,
                Box::new(|| call(fp, n, -1.0, op)),
                vec!["tolerance"],
            ),
        ];
        for (status, run, words) in cases {
            support::fails(
                run(),
                status,
                &[&["skf_model_bind_space"][..], &words].concat(),
            );
        }
        let mut nan = flat.clone();
        nan[16 * idx[1] + 5] = f32::NAN;
        support::fails(
            call(nan.as_ptr(), n, 1e-4, out.as_mut_ptr()),
            Invalid,
            &["skf_model_bind_space", "engine_inverse_binds", "non-finite"],
        );
    }
}
