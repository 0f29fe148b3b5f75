//! The fast path through the C ABI: results equal the Rust fast path's bit for bit (LBS and DQS,
//! whole mesh and a range inside it, triangle mesh and point cloud; the top-k influences in
//! every format, in the model's and in an engine's joint order), the interleaved writes leave
//! other bytes alone, the per-frame calls do not allocate, and every bad argument returns its
//! status with a message naming the function and the field.

#[path = "../../runtime/tests/common/mod.rs"]
mod common;
#[path = "../../runtime/tests/common/counting.rs"]
mod counting;
mod support;

use std::ptr::{null, null_mut};

use glam::{Vec3, Vec4};
use skinfield::*;
use skinfield_runtime::{
    FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, Method, Scratch, SkinNetModel,
    TopKIndices, TopKJob, TopKWeights,
};
use support::{c_pose, fails, ok};

/// A model (no joint map: frames take its own joint order), an ellipsoid bound to it, and the
/// handles of the fast path made through the C ABI (freed on drop).
struct Fast {
    bytes: Vec<u8>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    tangents: Vec<Vec4>,
    triangles: Vec<[u32; 3]>,
    model: *mut SkfModel,
    mesh: *mut SkfMesh,
    fast_mesh: *mut SkfFastMesh,
    nodes: *mut SkfFastNodes,
    frame: *mut SkfFrame,
    scratch: *mut SkfScratch,
    /// Engine joints before the model's when the model is mapped ([`setup_engine`]).
    helpers: usize,
}

impl Drop for Fast {
    fn drop(&mut self) {
        // SAFETY: each handle is live (or null) and freed once.
        unsafe {
            skf_fast_nodes_free(self.nodes);
            skf_fast_mesh_free(self.fast_mesh);
            skf_scratch_free(self.scratch);
            skf_frame_free(self.frame);
            skf_mesh_free(self.mesh);
            skf_model_free(self.model);
        }
    }
}

impl Fast {
    /// Poses the frame from `locals` (the engine's order when mapped); the nodes are then stale.
    fn set_pose(&self, locals: &[SkfTransform]) {
        // SAFETY: live handles, an array of the stated length.
        ok(unsafe { skf_frame_set_pose(self.frame, self.model, locals.as_ptr(), locals.len()) });
    }

    /// Poses the frame from `locals` (the engine's order when mapped) and updates the nodes.
    fn pose(&self, locals: &[SkfTransform]) {
        self.set_pose(locals);
        // SAFETY: live handles.
        unsafe {
            ok(skf_fast_nodes_update(
                self.model,
                self.fast_mesh,
                self.frame,
                self.scratch,
                self.nodes,
            ));
        }
    }

    /// One frame through the C calls: pose, the nodes' update, then vertices `first .. first +
    /// count` skinned by `method` into `out`. Asserts success; allocates nothing then.
    #[allow(clippy::too_many_arguments)]
    fn pose_and_skin(
        &self,
        locals: &[SkfTransform],
        method: u32,
        influences: usize,
        first: usize,
        count: usize,
        out: &mut [u8],
    ) {
        self.pose(locals);
        // SAFETY: live handles, a buffer of the stated length.
        unsafe {
            ok(skf_skin_fast(
                self.fast_mesh,
                self.frame,
                self.nodes,
                method,
                influences,
                first,
                count,
                &LAYOUT,
                out.as_mut_ptr(),
                out.len(),
            ));
        }
    }
}

const OPTIONS: SkfFastOptions = SkfFastOptions {
    nodes: 48,
    neighbours: 4,
    base_influences: 4,
};

/// Two setups of different models and a pose of the first's (seed `seed`), for the
/// bad-argument tests.
fn rivals(seed: u64) -> (Fast, Fast, Vec<SkfTransform>) {
    let f = setup(seed, &OPTIONS, true);
    let other = setup(seed + 1, &OPTIONS, true);
    let net = SkinNetModel::from_skf(&f.bytes).unwrap();
    let pose = common::random_pose(net.skeleton(), &mut common::rng(seed + 2), 0.5);
    (f, other, c_pose(&pose))
}

/// [`OPTIONS`] for the Rust fast path.
fn rust_options() -> FastOptions {
    FastOptions {
        nodes: OPTIONS.nodes,
        neighbours: OPTIONS.neighbours,
        base_influences: OPTIONS.base_influences,
        ..FastOptions::DEFAULT
    }
}

fn setup(seed: u64, options: &SkfFastOptions, triangles: bool) -> Fast {
    setup_engine(seed, options, triangles, 0)
}

/// [`setup`], the model mapped to an engine skeleton when `helpers` > 0: `helpers` joints of
/// the engine's own (`helper_0`, …) first, then the model's joints in reverse order.
fn setup_engine(seed: u64, options: &SkfFastOptions, triangles: bool, helpers: usize) -> Fast {
    let bytes = common::vinecs_bytes(7, seed);
    let (positions, normals, tris) = common::ellipsoid(10, 14);
    let (_, tangents) = common::random_frames(positions.len(), &mut common::rng(seed + 1));
    let mut f = Fast {
        bytes,
        positions,
        normals,
        tangents,
        triangles: if triangles { tris } else { Vec::new() },
        model: null_mut(),
        mesh: null_mut(),
        fast_mesh: null_mut(),
        nodes: null_mut(),
        frame: null_mut(),
        scratch: null_mut(),
        helpers,
    };
    // SAFETY: every pointer below points to live data of the stated length.
    unsafe {
        ok(skf_model_load(
            f.bytes.as_ptr(),
            f.bytes.len(),
            &mut f.model,
        ));
        if helpers > 0 {
            let net = SkinNetModel::from_skf(&f.bytes).unwrap();
            let names: Vec<std::ffi::CString> = (0..helpers)
                .map(|h| format!("helper_{h}"))
                .chain(net.skeleton().names().iter().rev().cloned())
                .map(|n| std::ffi::CString::new(n).unwrap())
                .collect();
            let ptrs: Vec<*const std::ffi::c_char> = names.iter().map(|n| n.as_ptr()).collect();
            ok(skf_model_map_joints(
                f.model,
                ptrs.as_ptr(),
                ptrs.len(),
                null(),
            ));
        }
        ok(skf_mesh_bind(
            f.model,
            f.positions.as_ptr().cast(),
            f.normals.as_ptr().cast(),
            f.tangents.as_ptr().cast(),
            f.positions.len(),
            &mut f.mesh,
        ));
        let tris = if f.triangles.is_empty() {
            null()
        } else {
            f.triangles.as_ptr().cast()
        };
        ok(skf_fast_mesh_bind(
            f.model,
            f.mesh,
            tris,
            f.triangles.len(),
            options,
            &mut f.fast_mesh,
        ));
        ok(skf_fast_nodes_new(f.fast_mesh, &mut f.nodes));
        ok(skf_frame_new(f.model, &mut f.frame));
        ok(skf_scratch_new(f.model, &mut f.scratch));
    }
    f
}

/// A 64-byte vertex: position at 0, 8 bytes the skinning must not touch, normal at 20, tangent
/// at 40, padding after.
const LAYOUT: SkfVertexLayout = SkfVertexLayout {
    stride: 64,
    position_offset: 0,
    normal_offset: 20,
    tangent_offset: 40,
};

fn read_f32s<const N: usize>(bytes: &[u8]) -> [f32; N] {
    core::array::from_fn(|k| f32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap()))
}

#[test]
fn the_c_fast_path_skins_exactly_as_the_rust_fast_path() {
    for triangles in [true, false] {
        let f = setup(21, &OPTIONS, triangles);
        let net = SkinNetModel::from_skf(&f.bytes).unwrap();
        let mesh = FastMesh::bind(&net, &f.positions, &f.triangles, &rust_options()).unwrap();
        let mut nodes = FastFrame::new(&mesh);
        let mut frame = FrameState::new(&net);
        let mut scratch = Scratch::new(&net);
        let mut node_count = 0;
        // SAFETY: live handle, writable count.
        ok(unsafe { skf_fast_mesh_node_count(f.fast_mesh, &mut node_count) });
        assert_eq!(node_count, mesh.node_count());
        assert!(node_count > 0 && node_count <= OPTIONS.nodes);

        let n = f.positions.len();
        let mut rng = common::rng(22);
        for (step, method, code, influences, first, count) in [
            (0, Method::Lbs, SKF_METHOD_LBS, 4, 0, n),
            (1, Method::Dqs, SKF_METHOD_DQS, 3, 0, n),
            (2, Method::Lbs, SKF_METHOD_LBS, 4, 37, 90),
        ] {
            let pose = common::random_pose(net.skeleton(), &mut rng, 0.6);
            let locals = c_pose(&pose);
            // SAFETY: a valid layout pointer.
            let len = unsafe { skf_vertex_buffer_len(&LAYOUT, count) };
            let mut vbo = vec![0xABu8; len];
            f.pose_and_skin(&locals, code, influences, first, count, &mut vbo);
            frame.set_pose(&net, &pose).unwrap();
            nodes.update(&net, &mesh, &frame, &mut scratch).unwrap();
            let mut p = vec![Vec3::ZERO; count];
            let mut nn = vec![Vec3::ZERO; count];
            let mut t = vec![Vec4::ZERO; count];
            FastSkinJob {
                mesh: &mesh,
                frame: &frame,
                nodes: &nodes,
                method,
                influences,
                first_vertex: first,
                rest_normals: Some(&f.normals),
                rest_tangents: Some(&f.tangents),
                out_positions: &mut p,
                out_normals: Some(&mut nn),
                out_tangents: Some(&mut t),
                out_weights: None,
            }
            .run()
            .unwrap();
            for v in 0..count {
                let bytes = &vbo[v * 64..];
                let what = format!("step {step}, triangles {triangles}, vertex {}", first + v);
                assert_eq!(read_f32s::<3>(&bytes[0..]), p[v].to_array(), "{what}");
                assert_eq!(read_f32s::<3>(&bytes[20..]), nn[v].to_array(), "{what}");
                assert_eq!(read_f32s::<4>(&bytes[40..]), t[v].to_array(), "{what}");
                assert!(
                    bytes[12..20].iter().all(|&b| b == 0xAB),
                    "{what}: gap written"
                );
            }
        }
    }
}

#[test]
fn per_frame_fast_calls_do_not_allocate() {
    let f = setup(31, &OPTIONS, true);
    let net = SkinNetModel::from_skf(&f.bytes).unwrap();
    let mut rng = common::rng(32);
    let poses: Vec<Vec<SkfTransform>> = (0..3)
        .map(|_| c_pose(&common::random_pose(net.skeleton(), &mut rng, 0.6)))
        .collect();
    let n = f.positions.len();
    // SAFETY: a valid layout pointer.
    let mut vbo = vec![0u8; unsafe { skf_vertex_buffer_len(&LAYOUT, n) }];
    let (mut joints, mut weights) = (vec![0u16; 4 * n], vec![0u16; 4 * n]);
    let count = counting::count_allocations(|| {
        for (k, pose) in poses.iter().enumerate() {
            f.pose_and_skin(pose, (k % 2) as u32, 4, 0, n, &mut vbo);
            let call = TopKCall {
                index_format: SKF_TOP_K_INDEX_U16,
                weight_format: SKF_TOP_K_WEIGHT_UNORM16,
                ..TopKCall::whole(&f, joints.as_mut_ptr(), weights.as_mut_ptr().cast())
            };
            // SAFETY: live handles, buffers of 4n elements.
            ok(unsafe { call.run() });
        }
    });
    assert_eq!(count, 0, "the per-frame fast calls allocated {count} times");
    assert!(vbo.iter().any(|&b| b != 0));
    assert!(weights.iter().any(|&w| w != 0));
}

#[test]
fn every_bad_fast_path_argument_is_a_status_naming_it() {
    use SkfStatus::{InvalidArgument as Invalid, NullPointer as Null};
    let (f, other, pose) = rivals(41);
    let n = f.positions.len();
    // SAFETY: a valid layout pointer.
    let len = unsafe { skf_vertex_buffer_len(&LAYOUT, n) };
    let mut vbo = vec![0u8; len];
    let tris: *const u32 = f.triangles.as_ptr().cast();
    let mut out_mesh: *mut SkfFastMesh = null_mut();
    let mut out_nodes: *mut SkfFastNodes = null_mut();
    let mut count = 0usize;
    // SAFETY: every non-null pointer points to live data of the stated length; the null ones
    // are what is tested.
    unsafe {
        let bind = |model, mesh, tris, tc, options, out| {
            let s = skf_fast_mesh_bind(model, mesh, tris, tc, options, out);
            if s == SkfStatus::Ok {
                skf_fast_mesh_free(*out);
            }
            s
        };
        let (tc, opt) = (f.triangles.len(), &OPTIONS as *const SkfFastOptions);
        let out: *mut *mut SkfFastMesh = &mut out_mesh;
        fails(
            bind(null(), f.mesh, tris, tc, opt, out),
            Null,
            &["skf_fast_mesh_bind", "model"],
        );
        fails(
            bind(f.model, null(), tris, tc, opt, out),
            Null,
            &["skf_fast_mesh_bind", "mesh"],
        );
        fails(
            bind(f.model, f.mesh, null(), tc, opt, out),
            Null,
            &["skf_fast_mesh_bind", "triangles"],
        );
        fails(
            bind(f.model, f.mesh, tris, tc, opt, null_mut()),
            Null,
            &["skf_fast_mesh_bind", "out_fast_mesh"],
        );
        fails(
            bind(f.model, f.mesh, tris, usize::MAX, opt, out),
            Invalid,
            &["skf_fast_mesh_bind", "triangle_count"],
        );
        let mut bad_tris = f.triangles.clone();
        bad_tris[5][1] = n as u32;
        fails(
            bind(f.model, f.mesh, bad_tris.as_ptr().cast(), tc, opt, out),
            Invalid,
            &["skf_fast_mesh_bind", "triangles", &n.to_string()],
        );
        for (options, field) in [
            (
                SkfFastOptions {
                    neighbours: 0,
                    ..OPTIONS
                },
                "neighbours",
            ),
            (
                SkfFastOptions {
                    neighbours: 9,
                    ..OPTIONS
                },
                "neighbours",
            ),
            (
                SkfFastOptions {
                    base_influences: 9,
                    ..OPTIONS
                },
                "base_influences",
            ),
            (
                SkfFastOptions {
                    nodes: 0,
                    ..OPTIONS
                },
                "nodes",
            ),
        ] {
            fails(
                bind(f.model, f.mesh, tris, tc, &options, out),
                Invalid,
                &["skf_fast_mesh_bind", field],
            );
        }
        // Null options take the defaults.
        ok(bind(f.model, f.mesh, tris, tc, null(), out));

        fails(
            skf_fast_mesh_node_count(null(), &mut count),
            Null,
            &["skf_fast_mesh_node_count", "fast_mesh"],
        );
        fails(
            skf_fast_mesh_node_count(f.fast_mesh, null_mut()),
            Null,
            &["skf_fast_mesh_node_count", "out_count"],
        );
        fails(
            skf_fast_nodes_new(null(), &mut out_nodes),
            Null,
            &["skf_fast_nodes_new", "fast_mesh"],
        );
        fails(
            skf_fast_nodes_new(f.fast_mesh, null_mut()),
            Null,
            &["skf_fast_nodes_new", "out_nodes"],
        );

        let update = |model, fast_mesh, frame, scratch, nodes| {
            skf_fast_nodes_update(model, fast_mesh, frame, scratch, nodes)
        };
        let skin = |fast_mesh, frame, nodes, method, influences, first, count, out: &mut [u8]| {
            skf_skin_fast(
                fast_mesh,
                frame,
                nodes,
                method,
                influences,
                first,
                count,
                &LAYOUT,
                out.as_mut_ptr(),
                out.len(),
            )
        };
        // Before any pose.
        fails(
            update(f.model, f.fast_mesh, f.frame, f.scratch, f.nodes),
            Invalid,
            &["skf_fast_nodes_update", "pose"],
        );
        f.set_pose(&pose);
        // Posed, nodes not updated yet.
        fails(
            skin(f.fast_mesh, f.frame, f.nodes, 0, 4, 0, n, &mut vbo),
            Invalid,
            &["skf_skin_fast", "nodes", "another pose"],
        );
        let (model, fast_mesh, frame) = (
            f.model.cast_const(),
            f.fast_mesh.cast_const(),
            f.frame.cast_const(),
        );
        for (i, (model, fast_mesh, frame, scratch, nodes)) in [
            (null(), fast_mesh, frame, f.scratch, f.nodes),
            (model, null(), frame, f.scratch, f.nodes),
            (model, fast_mesh, null(), f.scratch, f.nodes),
            (model, fast_mesh, frame, null_mut(), f.nodes),
            (model, fast_mesh, frame, f.scratch, null_mut()),
        ]
        .into_iter()
        .enumerate()
        {
            let name = ["model", "fast_mesh", "frame", "scratch", "nodes"][i];
            fails(
                update(model, fast_mesh, frame, scratch, nodes),
                Null,
                &["skf_fast_nodes_update", name],
            );
        }
        // Handles of another model or mesh.
        fails(
            update(other.model, f.fast_mesh, f.frame, f.scratch, f.nodes),
            Invalid,
            &["skf_fast_nodes_update", "another model or mesh"],
        );
        fails(
            update(f.model, f.fast_mesh, f.frame, f.scratch, other.nodes),
            Invalid,
            &["skf_fast_nodes_update", "nodes", "another model or mesh"],
        );
        ok(update(f.model, f.fast_mesh, f.frame, f.scratch, f.nodes));
        ok(skin(f.fast_mesh, f.frame, f.nodes, 0, 4, 0, n, &mut vbo));

        fails(
            skin(null(), f.frame, f.nodes, 0, 4, 0, n, &mut vbo),
            Null,
            &["skf_skin_fast", "fast_mesh"],
        );
        fails(
            skin(f.fast_mesh, null(), f.nodes, 0, 4, 0, n, &mut vbo),
            Null,
            &["skf_skin_fast", "frame"],
        );
        fails(
            skin(f.fast_mesh, f.frame, null(), 0, 4, 0, n, &mut vbo),
            Null,
            &["skf_skin_fast", "nodes"],
        );
        fails(
            skin(f.fast_mesh, f.frame, f.nodes, 7, 4, 0, n, &mut vbo),
            Invalid,
            &["skf_skin_fast", "method"],
        );
        fails(
            skin(f.fast_mesh, f.frame, f.nodes, 1, 0, 0, n, &mut vbo),
            Invalid,
            &["skf_skin_fast", "influences"],
        );
        fails(
            skin(f.fast_mesh, f.frame, f.nodes, 1, 9, 0, n, &mut vbo),
            Invalid,
            &["skf_skin_fast", "influences"],
        );
        fails(
            skin(f.fast_mesh, f.frame, f.nodes, 0, 4, 1, n, &mut vbo),
            Invalid,
            &["skf_skin_fast", "vertex range"],
        );
        fails(
            skin(
                f.fast_mesh,
                f.frame,
                f.nodes,
                0,
                4,
                0,
                n,
                &mut vbo[..len - 1],
            ),
            Invalid,
            &["skf_skin_fast", "out"],
        );
        fails(
            skin(other.fast_mesh, f.frame, f.nodes, 0, 4, 0, n, &mut vbo),
            Invalid,
            &["skf_skin_fast", "nodes", "another model or mesh"],
        );
        // A new pose makes the nodes stale until they are updated again.
        f.set_pose(&pose);
        fails(
            skin(f.fast_mesh, f.frame, f.nodes, 0, 4, 0, n, &mut vbo),
            Invalid,
            &["skf_skin_fast", "nodes", "another pose"],
        );
        let null_layout = skf_skin_fast(
            f.fast_mesh,
            f.frame,
            f.nodes,
            0,
            4,
            0,
            n,
            null(),
            vbo.as_mut_ptr(),
            vbo.len(),
        );
        fails(null_layout, Null, &["skf_skin_fast", "layout"]);
        // Null handles are ignored by the free functions.
        skf_fast_mesh_free(null_mut());
        skf_fast_nodes_free(null_mut());
    }
}

/// The engine's transforms for a model pose in `Fast::helpers` + reversed model order.
fn engine_locals(f: &Fast, model_locals: &[SkfTransform]) -> Vec<SkfTransform> {
    let j = model_locals.len();
    let identity = support::c_transform(&skinfield_formats::Transform::IDENTITY);
    let mut out = vec![identity; f.helpers + j];
    for (m, t) in model_locals.iter().enumerate() {
        out[f.helpers + j - 1 - m] = *t;
    }
    out
}

#[test]
fn the_c_top_k_influences_equal_the_rust_ones_in_the_engines_joint_order() {
    for helpers in [0, 3] {
        let f = setup_engine(51, &OPTIONS, true, helpers);
        let net = SkinNetModel::from_skf(&f.bytes).unwrap();
        let j = net.joint_count();
        let engine_of = |m: usize| if helpers == 0 { m } else { helpers + j - 1 - m };
        let mesh = FastMesh::bind(&net, &f.positions, &f.triangles, &rust_options()).unwrap();
        let mut nodes = FastFrame::new(&mesh);
        let mut frame = FrameState::new(&net);
        let mut scratch = Scratch::new(&net);
        let pose = common::random_pose(net.skeleton(), &mut common::rng(52), 0.6);
        frame.set_pose(&net, &pose).unwrap();
        nodes.update(&net, &mesh, &frame, &mut scratch).unwrap();
        let model_locals = c_pose(&pose);
        let locals = if helpers == 0 {
            model_locals
        } else {
            engine_locals(&f, &model_locals)
        };
        f.pose(&locals);
        let (k, first, count) = (4, 11, 70);
        let len = k * count;
        let c_top_k = |index_format, indices: *mut u8, weight_format, weights: *mut u8| {
            let call = TopKCall {
                influences: k,
                first,
                count,
                index_format,
                indices,
                indices_len: len,
                weight_format,
                weights,
                weights_len: len,
                ..TopKCall::whole(&f, null_mut(), null_mut())
            };
            // SAFETY: live handles; each buffer holds `len` elements of its format.
            ok(unsafe { call.run() });
        };
        let rust_top_k = |indices: TopKIndices<'_>, weights: TopKWeights<'_>| {
            TopKJob {
                mesh: &mesh,
                frame: &frame,
                nodes: &nodes,
                influences: k,
                first_vertex: first,
                out_indices: indices,
                out_weights: weights,
            }
            .run()
            .unwrap();
        };
        let what = format!("{helpers} helper joints");
        // u8 indices, unorm8 weights.
        let (mut ri, mut rw) = (vec![0u8; len], vec![0u8; len]);
        rust_top_k(TopKIndices::U8(&mut ri), TopKWeights::Unorm8(&mut rw));
        let (mut ci, mut cw) = (vec![0xEEu8; len], vec![0xEEu8; len]);
        c_top_k(
            SKF_TOP_K_INDEX_U8,
            ci.as_mut_ptr(),
            SKF_TOP_K_WEIGHT_UNORM8,
            cw.as_mut_ptr(),
        );
        assert_eq!(cw, rw, "{what}");
        let mapped: Vec<u8> = ri.iter().map(|&m| engine_of(m.into()) as u8).collect();
        assert_eq!(ci, mapped, "{what}");
        // u16 indices, unorm16 and f32 weights.
        let mut ri = vec![0u16; len];
        let mut rw16 = vec![0u16; len];
        rust_top_k(TopKIndices::U16(&mut ri), TopKWeights::Unorm16(&mut rw16));
        let mapped: Vec<u16> = ri.iter().map(|&m| engine_of(m.into()) as u16).collect();
        let (mut ci, mut cw16) = (vec![0xEEEEu16; len], vec![0xEEEEu16; len]);
        c_top_k(
            SKF_TOP_K_INDEX_U16,
            ci.as_mut_ptr().cast(),
            SKF_TOP_K_WEIGHT_UNORM16,
            cw16.as_mut_ptr().cast(),
        );
        assert_eq!((&ci, &cw16), (&mapped, &rw16), "{what}");
        let mut rw32 = vec![0f32; len];
        rust_top_k(TopKIndices::U16(&mut ri), TopKWeights::F32(&mut rw32));
        let mut cw32 = vec![-1f32; len];
        c_top_k(
            SKF_TOP_K_INDEX_U16,
            ci.as_mut_ptr().cast(),
            SKF_TOP_K_WEIGHT_F32,
            cw32.as_mut_ptr().cast(),
        );
        assert_eq!(cw32, rw32, "{what}");
        // Strongest first and summing to one, exactly, in every format.
        for v in 0..count {
            let w = &cw32[v * k..(v + 1) * k];
            assert_eq!(w.iter().sum::<f32>(), 1.0, "{what}, vertex {v}");
            assert!(w.windows(2).all(|p| p[0] >= p[1]), "{what}, vertex {v}");
            let s16: u32 = cw16[v * k..(v + 1) * k].iter().map(|&x| u32::from(x)).sum();
            assert_eq!(s16, 65535, "{what}, vertex {v}");
        }
    }
}

/// The arguments of one `skf_fast_top_k` call, so a test can change one field at a time.
#[derive(Clone, Copy)]
struct TopKCall {
    model: *const SkfModel,
    fast_mesh: *const SkfFastMesh,
    frame: *const SkfFrame,
    nodes: *const SkfFastNodes,
    influences: usize,
    first: usize,
    count: usize,
    index_format: u32,
    indices: *mut u8,
    indices_len: usize,
    weight_format: u32,
    weights: *mut u8,
    weights_len: usize,
}

impl TopKCall {
    /// All of `f`'s vertices, 4 joints each, as u16 indices into `indices` and f32 weights
    /// into `weights` (`4n` elements each).
    fn whole(f: &Fast, indices: *mut u16, weights: *mut f32) -> Self {
        let n = f.positions.len();
        Self {
            model: f.model,
            fast_mesh: f.fast_mesh,
            frame: f.frame,
            nodes: f.nodes,
            influences: 4,
            first: 0,
            count: n,
            index_format: SKF_TOP_K_INDEX_U16,
            indices: indices.cast(),
            indices_len: 4 * n,
            weight_format: SKF_TOP_K_WEIGHT_F32,
            weights: weights.cast(),
            weights_len: 4 * n,
        }
    }

    /// # Safety
    /// As `skf_fast_top_k`'s.
    unsafe fn run(self) -> SkfStatus {
        // SAFETY: the caller's.
        unsafe {
            skf_fast_top_k(
                self.model,
                self.fast_mesh,
                self.frame,
                self.nodes,
                self.influences,
                self.first,
                self.count,
                self.index_format,
                self.indices.cast(),
                self.indices_len,
                self.weight_format,
                self.weights.cast(),
                self.weights_len,
            )
        }
    }
}

#[test]
fn every_bad_top_k_argument_is_a_status_naming_it() {
    use SkfStatus::{InvalidArgument as Invalid, NullPointer as Null};
    let (f, other, pose) = rivals(61);
    let net = SkinNetModel::from_skf(&f.bytes).unwrap();
    let len = 4 * f.positions.len();
    let mut indices = vec![0u16; len + 1];
    let mut weights = vec![0f32; len + 1];
    let good = TopKCall::whole(&f, indices.as_mut_ptr(), weights.as_mut_ptr());
    // SAFETY: every non-null pointer points to live data of at least the stated length; the
    // null and misaligned ones are what is tested.
    unsafe {
        f.set_pose(&pose);
        // Posed, nodes not updated yet.
        fails(
            good.run(),
            Invalid,
            &["skf_fast_top_k", "nodes", "another pose"],
        );
        ok(skf_fast_nodes_update(
            f.model,
            f.fast_mesh,
            f.frame,
            f.scratch,
            f.nodes,
        ));
        ok(good.run());
        let cases: [(TopKCall, SkfStatus, &[&str]); 20] = [
            (
                TopKCall {
                    model: null(),
                    ..good
                },
                Null,
                &["model"],
            ),
            (
                TopKCall {
                    fast_mesh: null(),
                    ..good
                },
                Null,
                &["fast_mesh"],
            ),
            (
                TopKCall {
                    frame: null(),
                    ..good
                },
                Null,
                &["frame"],
            ),
            (
                TopKCall {
                    nodes: null(),
                    ..good
                },
                Null,
                &["nodes"],
            ),
            (
                TopKCall {
                    model: other.model,
                    ..good
                },
                Invalid,
                &["model", "frame"],
            ),
            (
                TopKCall {
                    fast_mesh: other.fast_mesh,
                    ..good
                },
                Invalid,
                &["nodes"],
            ),
            (
                TopKCall {
                    frame: other.frame,
                    ..good
                },
                Invalid,
                &["model", "frame"],
            ),
            (
                TopKCall {
                    nodes: other.nodes,
                    ..good
                },
                Invalid,
                &["nodes"],
            ),
            (
                TopKCall {
                    influences: 0,
                    ..good
                },
                Invalid,
                &["influences"],
            ),
            (
                TopKCall {
                    influences: 9,
                    ..good
                },
                Invalid,
                &["influences"],
            ),
            (
                TopKCall {
                    count: usize::MAX,
                    ..good
                },
                Invalid,
                &["count"],
            ),
            (
                TopKCall {
                    indices_len: len - 1,
                    ..good
                },
                Invalid,
                &["out_indices_len"],
            ),
            (
                TopKCall {
                    weights_len: len - 1,
                    ..good
                },
                Invalid,
                &["out_weights_len"],
            ),
            (TopKCall { first: 1, ..good }, Invalid, &["range"]),
            (
                TopKCall {
                    index_format: 7,
                    ..good
                },
                Invalid,
                &["index_format"],
            ),
            (
                TopKCall {
                    weight_format: 7,
                    ..good
                },
                Invalid,
                &["weight_format"],
            ),
            (
                TopKCall {
                    indices: null_mut(),
                    ..good
                },
                Null,
                &["out_indices"],
            ),
            (
                TopKCall {
                    weights: null_mut(),
                    ..good
                },
                Null,
                &["out_weights"],
            ),
            (
                TopKCall {
                    indices: good.indices.add(1),
                    ..good
                },
                Invalid,
                &["out_indices", "aligned"],
            ),
            (
                TopKCall {
                    weights: good.weights.add(2),
                    ..good
                },
                Invalid,
                &["out_weights", "aligned"],
            ),
        ];
        for (call, status, words) in cases {
            fails(
                call.run(),
                status,
                &[&["skf_fast_top_k"][..], words].concat(),
            );
        }
    }
    // More engine joints than a byte can index.
    let wide = setup_engine(64, &OPTIONS, true, 300);
    let locals = engine_locals(&wide, &pose);
    let mut bytes = vec![0u8; len];
    let call = TopKCall::whole(&wide, indices.as_mut_ptr(), weights.as_mut_ptr());
    wide.pose(&locals);
    // SAFETY: live handles, arrays of the stated lengths.
    unsafe {
        let joints = (300 + net.joint_count()).to_string();
        let as_bytes = TopKCall {
            index_format: SKF_TOP_K_INDEX_U8,
            indices: bytes.as_mut_ptr(),
            ..call
        };
        fails(
            as_bytes.run(),
            Invalid,
            &["skf_fast_top_k", "index_format", &joints],
        );
        ok(call.run());
    }
    assert!(indices[..len].iter().all(|&e| usize::from(e) >= 300));
}
