//! Proof that the per-frame path never touches the heap: a counting global allocator, armed
//! only on this test's thread, around pose → frame → every job kind.

mod common;
#[path = "common/counting.rs"]
mod counting;

use counting::count_allocations;

use glam::{Vec3, Vec4};
use skinfield_formats::StaticSkin;
use skinfield_runtime::{
    BoundMesh, FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, InterleavedJob, JointMap,
    Method, Palette, Scratch, SkinJob, SkinNetModel, StaticSkinJob, TopKIndices, TopKJob,
    TopKWeights, Transform, VertexLayout, WeightSource, WeightsJob,
};

#[test]
fn per_frame_path_does_not_allocate() {
    let n = 150;
    let model = SkinNetModel::from_skf(&common::vinecs_bytes(24, 21)).unwrap();
    let mut rng = common::rng(22);
    let pts = common::random_points(n, &mut rng);
    let (normals, tangents) = common::random_frames(n, &mut rng);
    let mesh = BoundMesh::bind(&model, &pts).unwrap();
    let poses: Vec<_> = (0..3)
        .map(|_| common::random_pose(model.skeleton(), &mut rng, 0.8))
        .collect();
    let mut frame = FrameState::new(&model);
    let mut scratch = Scratch::new(&model);
    let mut palette = Palette::new(24);
    let skin = StaticSkin::from_dense(&vec![1.0 / 24.0; n * 24], 24).unwrap();
    let (mut p, mut nn, mut t, mut w) = (
        vec![Vec3::ZERO; n - 7],
        vec![Vec3::ZERO; n - 7],
        vec![Vec4::ZERO; n - 7],
        vec![0.0; (n - 7) * 24],
    );
    let mut bad = poses[0].clone();
    bad.locals[4].translation.x = f32::NAN;
    // The fast path on a closed mesh (bind allocates; frames must not).
    let (fp, fnrm, ftri) = common::ellipsoid(8, 12);
    let fast = FastMesh::bind(
        &model,
        &fp,
        &ftri,
        &FastOptions {
            nodes: 40,
            ..FastOptions::DEFAULT
        },
    )
    .unwrap();
    let mut nodes = FastFrame::new(&fast);
    let fnv = fp.len();
    let (mut fpos, mut fn_out) = (vec![Vec3::ZERO; fnv], vec![Vec3::ZERO; fnv]);
    let (mut tj, mut tw) = (vec![0u8; fnv * 8], vec![0u16; fnv * 8]);
    // An engine skeleton in reverse order with one helper joint, and its vertex buffer.
    let mut names: Vec<String> = model.skeleton().names().iter().rev().cloned().collect();
    names.push(String::from("socket"));
    let map = JointMap::new(model.skeleton(), &names).unwrap();
    let mut engine = vec![Transform::IDENTITY; names.len()];
    let layout = VertexLayout::POSITION_NORMAL_TANGENT;
    let mut vbo = vec![0u8; layout.buffer_len(n).unwrap()];

    let count = count_allocations(|| {
        for pose in &poses {
            frame.set_pose(&model, pose).unwrap();
            for method in [Method::Lbs, Method::Dqs] {
                SkinJob {
                    model: &model,
                    mesh: &mesh,
                    frame: &frame,
                    method,
                    first_vertex: 7,
                    rest_normals: Some(&normals),
                    rest_tangents: Some(&tangents),
                    out_positions: &mut p,
                    out_normals: Some(&mut nn),
                    out_tangents: Some(&mut t),
                    out_weights: Some(&mut w),
                }
                .run(&mut scratch)
                .unwrap();
            }
            WeightsJob {
                model: &model,
                mesh: &mesh,
                frame: &frame,
                first_vertex: 0,
                out_weights: &mut w,
            }
            .run(&mut scratch)
            .unwrap();
            palette.set_pose(model.skeleton(), pose).unwrap();
            StaticSkinJob {
                skin: &skin,
                palette: &palette,
                method: Method::Dqs,
                first_vertex: 7,
                rest_positions: mesh.rest_positions(),
                rest_normals: Some(&normals),
                rest_tangents: None,
                out_positions: &mut p,
                out_normals: Some(&mut nn),
                out_tangents: None,
            }
            .run()
            .unwrap();
            nodes.update(&model, &fast, &frame, &mut scratch).unwrap();
            for method in [Method::Lbs, Method::Dqs] {
                FastSkinJob {
                    mesh: &fast,
                    frame: &frame,
                    nodes: &nodes,
                    method,
                    influences: 8,
                    first_vertex: 0,
                    rest_normals: Some(&fnrm),
                    rest_tangents: None,
                    out_positions: &mut fpos,
                    out_normals: Some(&mut fn_out),
                    out_tangents: None,
                    out_weights: None,
                }
                .run()
                .unwrap();
            }
            TopKJob {
                mesh: &fast,
                frame: &frame,
                nodes: &nodes,
                influences: 8,
                first_vertex: 0,
                out_indices: TopKIndices::U8(&mut tj),
                out_weights: TopKWeights::Unorm16(&mut tw),
            }
            .run()
            .unwrap();
        }
        for pose in &poses {
            for (j, &e) in map.engine_of_model().iter().enumerate() {
                engine[e] = pose.locals[j];
            }
            frame.set_engine_pose(&model, &map, &engine).unwrap();
            InterleavedJob {
                source: WeightSource::Exact {
                    model: &model,
                    mesh: &mesh,
                    frame: &frame,
                    scratch: &mut scratch,
                },
                method: Method::Dqs,
                first_vertex: 0,
                count: n,
                rest_normals: Some(&normals),
                rest_tangents: Some(&tangents),
                layout,
                out: &mut vbo,
            }
            .run()
            .unwrap();
        }
        // Error paths do not allocate either.
        assert!(frame.set_pose(&model, &bad).is_err());
        assert!(frame.set_engine_pose(&model, &map, &engine[1..]).is_err());
    });
    assert_eq!(count, 0, "the per-frame path allocated {count} times");
    // The counter works: a Vec allocates.
    assert_eq!(
        count_allocations(|| drop(std::hint::black_box(vec![1u8; 10]))),
        1
    );
    assert!(p.iter().all(|v| v.is_finite()));
    assert!(fpos.iter().all(|v| v.is_finite()));
}
