//! Proof that the per-frame path never touches the heap: a counting global allocator, armed
//! only on this test's thread, around pose → frame → every job kind.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use glam::{Vec3, Vec4};
use skinfield_formats::StaticSkin;
use skinfield_runtime::{
    BoundMesh, FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, Method, Palette, Scratch,
    SkinJob, SkinNetModel, StaticSkinJob, TopKIndices, TopKJob, TopKWeights, WeightsJob,
};

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

fn note() {
    // `try_with`: the allocator also runs while thread locals are being torn down.
    let armed = ARMED.try_with(Cell::get).unwrap_or(false);
    if armed {
        let _ = COUNT.try_with(|c| c.set(c.get() + 1));
    }
}

// SAFETY: forwards every call unchanged to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn count_allocations(f: impl FnOnce()) -> usize {
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    f();
    ARMED.with(|a| a.set(false));
    COUNT.with(Cell::get)
}

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
        // Error paths do not allocate either.
        assert!(frame.set_pose(&model, &bad).is_err());
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
