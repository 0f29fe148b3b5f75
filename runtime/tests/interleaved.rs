//! `InterleavedJob` writes exactly what the packed jobs write, for each weight source, over
//! ranges that start and end inside chunks and tiles, and touches no other byte; its own
//! fields are validated like every job's.

mod common;

use glam::{Vec3, Vec4};
use skinfield_formats::StaticSkin;
use skinfield_runtime::{
    BoundMesh, CHUNK, FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, InterleavedJob,
    Method, Palette, RuntimeError, Scratch, SkinJob, SkinNetModel, StaticSkinJob, VertexLayout,
    WeightSource,
};

/// 4 bytes of something else, the position, the normal, the tangent, 4 bytes of padding.
const LAYOUT: VertexLayout = VertexLayout {
    stride: 52,
    position: 4,
    normal: Some(16),
    tangent: Some(32),
};
const FILL: u8 = 0x5A;

struct Packed {
    p: Vec<Vec3>,
    n: Vec<Vec3>,
    t: Vec<Vec4>,
}

impl Packed {
    fn new(count: usize) -> Self {
        Self {
            p: vec![Vec3::ZERO; count],
            n: vec![Vec3::ZERO; count],
            t: vec![Vec4::ZERO; count],
        }
    }

    /// Compares with the buffer bit for bit; bytes outside the attributes keep `FILL`.
    fn check(&self, vbo: &[u8]) {
        let read = |at: usize| f32::from_ne_bytes(vbo[at..at + 4].try_into().unwrap());
        for v in 0..self.p.len() {
            let base = v * LAYOUT.stride;
            let attrs: [(usize, &[f32]); 3] = [
                (4, &self.p[v].to_array()),
                (16, &self.n[v].to_array()),
                (32, &self.t[v].to_array()),
            ];
            for (offset, values) in attrs {
                for (k, &x) in values.iter().enumerate() {
                    assert_eq!(
                        read(base + offset + 4 * k).to_bits(),
                        x.to_bits(),
                        "vertex {v}"
                    );
                }
            }
            for b in (0..4).chain(48..52) {
                if base + b < vbo.len() {
                    assert_eq!(vbo[base + b], FILL, "vertex {v} byte {b}");
                }
            }
        }
    }
}

#[test]
fn interleaved_output_equals_the_packed_jobs_for_every_source() {
    let model = SkinNetModel::from_skf(&common::vinecs_bytes(9, 41)).unwrap();
    let mut rng = common::rng(42);
    let (positions, _, triangles) = common::ellipsoid(12, 20);
    let n = positions.len();
    assert!(n > 2 * CHUNK, "the mesh must span several chunks");
    let (normals, tangents) = common::random_frames(n, &mut rng);
    let pose = common::random_pose(model.skeleton(), &mut rng, 0.7);
    let mut frame = FrameState::new(&model);
    frame.set_pose(&model, &pose).unwrap();
    let mut scratch = Scratch::new(&model);
    let mesh = BoundMesh::bind(&model, &positions).unwrap();
    let fast = FastMesh::bind(&model, &positions, &triangles, &FastOptions::DEFAULT).unwrap();
    let mut nodes = FastFrame::new(&fast);
    nodes.update(&model, &fast, &frame, &mut scratch).unwrap();
    let dense: Vec<f32> = (0..n * 9).map(|i| ((i * 7919) % 13) as f32 + 0.5).collect();
    let skin = StaticSkin::from_dense(&dense, 9).unwrap();
    let mut palette = Palette::new(9);
    palette.set_pose(model.skeleton(), &pose).unwrap();

    // Whole mesh; a range inside the first chunk; one crossing chunk and tile boundaries.
    let ranges = [(0, n), (5, 20), (CHUNK - 3, CHUNK + 40)];
    for (first, count) in ranges {
        for method in [Method::Lbs, Method::Dqs] {
            for source in 0..3 {
                let mut want = Packed::new(count);
                let mut vbo = vec![FILL; LAYOUT.buffer_len(count).unwrap()];
                let (rest_normals, rest_tangents) = (Some(&normals[..]), Some(&tangents[..]));
                let weights = match source {
                    0 => {
                        SkinJob {
                            model: &model,
                            mesh: &mesh,
                            frame: &frame,
                            method,
                            first_vertex: first,
                            rest_normals,
                            rest_tangents,
                            out_positions: &mut want.p,
                            out_normals: Some(&mut want.n),
                            out_tangents: Some(&mut want.t),
                            out_weights: None,
                        }
                        .run(&mut scratch)
                        .unwrap();
                        WeightSource::Exact {
                            model: &model,
                            mesh: &mesh,
                            frame: &frame,
                            scratch: &mut scratch,
                        }
                    }
                    1 => {
                        FastSkinJob {
                            mesh: &fast,
                            frame: &frame,
                            nodes: &nodes,
                            method,
                            influences: 6,
                            first_vertex: first,
                            rest_normals,
                            rest_tangents,
                            out_positions: &mut want.p,
                            out_normals: Some(&mut want.n),
                            out_tangents: Some(&mut want.t),
                            out_weights: None,
                        }
                        .run()
                        .unwrap();
                        WeightSource::Fast {
                            mesh: &fast,
                            frame: &frame,
                            nodes: &nodes,
                            influences: 6,
                        }
                    }
                    _ => {
                        StaticSkinJob {
                            skin: &skin,
                            palette: &palette,
                            method,
                            first_vertex: first,
                            rest_positions: &positions,
                            rest_normals,
                            rest_tangents,
                            out_positions: &mut want.p,
                            out_normals: Some(&mut want.n),
                            out_tangents: Some(&mut want.t),
                        }
                        .run()
                        .unwrap();
                        WeightSource::Static {
                            skin: &skin,
                            palette: &palette,
                            rest_positions: &positions,
                        }
                    }
                };
                InterleavedJob {
                    source: weights,
                    method,
                    first_vertex: first,
                    count,
                    rest_normals,
                    rest_tangents,
                    layout: LAYOUT,
                    out: &mut vbo,
                }
                .run()
                .unwrap();
                want.check(&vbo);
            }
        }
    }
}

#[test]
fn interleaved_fields_are_validated_by_name() {
    let model = SkinNetModel::from_skf(&common::vinecs_bytes(5, 43)).unwrap();
    let mut rng = common::rng(44);
    let positions = common::random_points(70, &mut rng);
    let (normals, _) = common::random_frames(70, &mut rng);
    let mesh = BoundMesh::bind(&model, &positions).unwrap();
    let mut frame = FrameState::new(&model);
    let mut scratch = Scratch::new(&model);
    let mut vbo = vec![0u8; LAYOUT.buffer_len(70).unwrap()];
    let mut run = |frame: &FrameState,
                   first: usize,
                   count: usize,
                   layout: VertexLayout,
                   normals: Option<&[Vec3]>,
                   len: usize| {
        InterleavedJob {
            source: WeightSource::Exact {
                model: &model,
                mesh: &mesh,
                frame,
                scratch: &mut scratch,
            },
            method: Method::Lbs,
            first_vertex: first,
            count,
            rest_normals: normals,
            rest_tangents: None,
            layout,
            out: &mut vbo[..len],
        }
        .run()
    };
    let no_tangent = VertexLayout {
        tangent: None,
        ..LAYOUT
    };
    let full = LAYOUT.buffer_len(70).unwrap();
    assert_eq!(
        run(&frame, 0, 70, no_tangent, Some(&normals), full),
        Err(RuntimeError::NoPose)
    );
    frame
        .set_pose(&model, &model.skeleton().bind_pose())
        .unwrap();
    run(&frame, 0, 70, no_tangent, Some(&normals), full).unwrap();
    assert_eq!(
        run(&frame, 0, 70, LAYOUT, Some(&normals), full),
        Err(RuntimeError::Missing {
            field: "rest_tangents",
            because: "layout.tangent"
        })
    );
    assert_eq!(
        run(&frame, 0, 70, no_tangent, None, full),
        Err(RuntimeError::Missing {
            field: "rest_normals",
            because: "layout.normal"
        })
    );
    let need = no_tangent.buffer_len(70).unwrap();
    assert_eq!(
        run(&frame, 0, 70, no_tangent, Some(&normals), need - 1),
        Err(RuntimeError::BufferLength {
            field: "out",
            len: need - 1,
            expected: need
        })
    );
    assert_eq!(
        run(&frame, 30, 41, no_tangent, Some(&normals), full),
        Err(RuntimeError::Range {
            first: 30,
            count: 41,
            vertex_count: 70
        })
    );
    assert!(matches!(
        run(
            &frame,
            0,
            70,
            VertexLayout {
                stride: 20,
                ..no_tangent
            },
            Some(&normals),
            full
        ),
        Err(RuntimeError::Layout {
            field: "normal",
            ..
        })
    ));
    assert_eq!(
        run(&frame, 0, 70, no_tangent, Some(&normals[1..]), full),
        Err(RuntimeError::BufferLength {
            field: "rest_normals",
            len: 69,
            expected: 70
        })
    );
    // An empty range is fine and writes nothing.
    run(&frame, 70, 0, no_tangent, Some(&normals), 0).unwrap();
}
