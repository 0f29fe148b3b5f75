//! Jobs: vertex ranges, static skinning, caller-memory expansion, and every invalid
//! configuration each job must refuse.

mod common;

use glam::{Mat4, Quat, Vec3, Vec4};
use skinfield_formats::skf::{SkfView, file_checksum};
use skinfield_formats::{Pose, StaticSkin};
use skinfield_runtime::{
    BoundMesh, FrameState, Method, Palette, RuntimeError, Scratch, SkinJob, SkinNet, SkinNetModel,
    StaticSkinJob, WeightsJob, expanded_len,
};

struct Fixture {
    model: SkinNetModel,
    mesh: BoundMesh,
    frame: FrameState,
    normals: Vec<Vec3>,
    tangents: Vec<Vec4>,
    pose: Pose,
}

fn fixture(n: usize, seed: u64) -> Fixture {
    let model = SkinNetModel::from_skf(&common::vinecs_bytes(6, seed)).unwrap();
    let mut rng = common::rng(seed + 1);
    let pts = common::random_points(n, &mut rng);
    let (normals, tangents) = common::random_frames(n, &mut rng);
    let mesh = BoundMesh::bind(&model, &pts).unwrap();
    let pose = common::random_pose(model.skeleton(), &mut rng, 0.6);
    let mut frame = FrameState::new(&model);
    frame.set_pose(&model, &pose).unwrap();
    Fixture {
        model,
        mesh,
        frame,
        normals,
        tangents,
        pose,
    }
}

struct Out {
    p: Vec<Vec3>,
    n: Vec<Vec3>,
    t: Vec<Vec4>,
    w: Vec<f32>,
}

fn run_range(
    f: &Fixture,
    method: Method,
    first: usize,
    count: usize,
    scratch: &mut Scratch,
) -> Out {
    let j = f.model.joint_count();
    let mut o = Out {
        p: vec![Vec3::NAN; count],
        n: vec![Vec3::NAN; count],
        t: vec![Vec4::NAN; count],
        w: vec![f32::NAN; count * j],
    };
    SkinJob {
        model: &f.model,
        mesh: &f.mesh,
        frame: &f.frame,
        method,
        first_vertex: first,
        rest_normals: Some(&f.normals),
        rest_tangents: Some(&f.tangents),
        out_positions: &mut o.p,
        out_normals: Some(&mut o.n),
        out_tangents: Some(&mut o.t),
        out_weights: Some(&mut o.w),
    }
    .run(scratch)
    .unwrap();
    o
}

#[test]
fn sub_ranges_give_the_same_result_as_one_run() {
    let n = 203;
    let f = fixture(n, 1);
    let mut scratch = Scratch::new(&f.model);
    for method in [Method::Lbs, Method::Dqs] {
        let all = run_range(&f, method, 0, n, &mut scratch);
        // Unaligned cuts, including empty and single-vertex ranges.
        let cuts = [0, 0, 1, 17, 32, 33, 95, 160, 202, 203];
        for w in cuts.windows(2) {
            let part = run_range(&f, method, w[0], w[1] - w[0], &mut scratch);
            assert_eq!(part.p, all.p[w[0]..w[1]], "{method:?} {w:?}");
            assert_eq!(part.n, all.n[w[0]..w[1]]);
            assert_eq!(part.t, all.t[w[0]..w[1]]);
            let j = f.model.joint_count();
            assert_eq!(part.w, all.w[w[0] * j..w[1] * j]);
        }
        // Normals and tangents come out unit length, handedness kept.
        assert!(all.n.iter().all(|v| (v.length() - 1.0).abs() < 1e-5));
        assert!(
            all.t
                .iter()
                .zip(&f.tangents)
                .all(|(t, r)| (t.truncate().length() - 1.0).abs() < 1e-5 && t.w == r.w)
        );
    }
    // The weights job returns the same weights.
    let all = run_range(&f, Method::Lbs, 0, n, &mut scratch);
    let mut w = vec![0.0; n * f.model.joint_count()];
    WeightsJob {
        model: &f.model,
        mesh: &f.mesh,
        frame: &f.frame,
        first_vertex: 0,
        out_weights: &mut w,
    }
    .run(&mut scratch)
    .unwrap();
    assert_eq!(w, all.w);
}

#[test]
fn bind_pose_returns_the_rest_mesh() {
    let n = 40;
    let mut f = fixture(n, 2);
    let bind = f.model.skeleton().bind_pose();
    f.frame.set_pose(&f.model, &bind).unwrap();
    let mut scratch = Scratch::new(&f.model);
    for method in [Method::Lbs, Method::Dqs] {
        let o = run_range(&f, method, 0, n, &mut scratch);
        for v in 0..n {
            assert!(
                (o.p[v] - f.mesh.rest_positions()[v]).length() < 1e-5,
                "{method:?} {v}"
            );
            assert!((o.n[v] - f.normals[v]).length() < 1e-5);
        }
    }
}

#[test]
fn static_skin_with_the_nets_weights_skins_the_same() {
    let n = 70;
    let f = fixture(n, 3);
    let mut scratch = Scratch::new(&f.model);
    for method in [Method::Lbs, Method::Dqs] {
        let net = run_range(&f, method, 0, n, &mut scratch);
        let skin = StaticSkin::from_dense(&net.w, f.model.joint_count()).unwrap();
        let (mut p, mut nn, mut t) = (
            vec![Vec3::ZERO; n - 10],
            vec![Vec3::ZERO; n - 10],
            vec![Vec4::ZERO; n - 10],
        );
        StaticSkinJob {
            skin: &skin,
            palette: f.frame.palette(),
            method,
            first_vertex: 10,
            rest_positions: f.mesh.rest_positions(),
            rest_normals: Some(&f.normals),
            rest_tangents: Some(&f.tangents),
            out_positions: &mut p,
            out_normals: Some(&mut nn),
            out_tangents: Some(&mut t),
        }
        .run()
        .unwrap();
        for i in 0..n - 10 {
            assert!((p[i] - net.p[i + 10]).length() < 1e-5, "{method:?} {i}");
            assert!((nn[i] - net.n[i + 10]).length() < 1e-5);
            assert!((t[i] - net.t[i + 10]).length() < 1e-5);
        }
    }
}

#[test]
fn static_skin_rotated_bone_is_analytic() {
    // Two joints: root at the origin, child 1 m up; the child bends 90° about Z.
    let s = skinfield_formats::Skeleton::new(
        vec!["root".into(), "child".into()],
        vec![None, Some(0)],
        vec![
            skinfield_formats::Transform::IDENTITY,
            skinfield_formats::Transform::from_translation(Vec3::Y),
        ],
        None,
        None,
        Mat4::IDENTITY,
    )
    .unwrap();
    let mut pose = s.bind_pose();
    pose.locals[1].rotation = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
    let mut palette = Palette::new(2);
    palette.set_pose(&s, &pose).unwrap();
    // Vertex 0 rigid on the child, 1 m above it; vertex 1 rigid on the root.
    let skin = StaticSkin::new(vec![0, 1, 2], vec![1, 0], vec![1.0, 1.0], 2).unwrap();
    let rest = [Vec3::new(0.0, 2.0, 0.0), Vec3::new(0.3, 0.5, 0.0)];
    for method in [Method::Lbs, Method::Dqs] {
        let mut out = [Vec3::ZERO; 2];
        StaticSkinJob {
            skin: &skin,
            palette: &palette,
            method,
            first_vertex: 0,
            rest_positions: &rest,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut out,
            out_normals: None,
            out_tangents: None,
        }
        .run()
        .unwrap();
        assert!(
            (out[0] - Vec3::new(-1.0, 1.0, 0.0)).length() < 1e-6,
            "{method:?} {out:?}"
        );
        assert!((out[1] - rest[1]).length() < 1e-6);
    }
}

#[test]
fn caller_memory_model_equals_owning_model() {
    let bytes = common::vinecs_bytes(6, 4);
    let view = SkfView::parse(&bytes).unwrap();
    let len = expanded_len(view.config());
    let mut small = vec![0.0; len - 1];
    assert_eq!(
        SkinNet::expand_into(&view, &mut small).err(),
        Some(RuntimeError::BufferLength {
            field: "buf",
            len: len - 1,
            expected: len
        })
    );
    let mut buf = vec![0.0; len + 5];
    let borrowed = SkinNet::expand_into(&view, &mut buf).unwrap();
    let owned = SkinNetModel::from_view(&view).unwrap();
    let mut rng = common::rng(5);
    let pts = common::random_points(50, &mut rng);
    let pose = common::random_pose(owned.skeleton(), &mut rng, 0.5);
    let (mut a, mut b) = (vec![0.0; 50 * 6], vec![0.0; 50 * 6]);
    borrowed.weights_for(&pts, &pose, &mut a).unwrap();
    owned.weights_for(&pts, &pose, &mut b).unwrap();
    assert_eq!(a, b);
    assert_eq!(
        SkinNetModel::weights_for_skf(&bytes, &pts, &pose).unwrap(),
        b
    );
}

#[cfg(feature = "rayon")]
#[test]
fn parallel_run_equals_sequential() {
    let n = 301;
    let f = fixture(n, 6);
    let mut scratch = Scratch::new(&f.model);
    let want = run_range(&f, Method::Dqs, 5, n - 5, &mut scratch);
    for threads in [1, 2, 3, 8] {
        let mut scratches: Vec<Scratch> = (0..threads).map(|_| Scratch::new(&f.model)).collect();
        let mut p = vec![Vec3::NAN; n - 5];
        let mut w = vec![f32::NAN; (n - 5) * f.model.joint_count()];
        let job = SkinJob {
            model: &f.model,
            mesh: &f.mesh,
            frame: &f.frame,
            method: Method::Dqs,
            first_vertex: 5,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut p,
            out_normals: None,
            out_tangents: None,
            out_weights: Some(&mut w),
        };
        skinfield_runtime::parallel::run_parallel(job, &mut scratches).unwrap();
        assert_eq!(p, want.p, "{threads} threads");
        assert_eq!(w, want.w);
    }
}

fn full_job<'a>(
    f: &'a Fixture,
    p: &'a mut [Vec3],
    n: &'a mut [Vec3],
    t: &'a mut [Vec4],
    w: &'a mut [f32],
) -> SkinJob<'a, Vec<f32>> {
    SkinJob {
        model: &f.model,
        mesh: &f.mesh,
        frame: &f.frame,
        method: Method::Lbs,
        first_vertex: 0,
        rest_normals: Some(&f.normals),
        rest_tangents: Some(&f.tangents),
        out_positions: p,
        out_normals: Some(n),
        out_tangents: Some(t),
        out_weights: Some(w),
    }
}

/// Every way a job, a frame, a palette, a bind or a file can be wrong, and the error that names it.
#[test]
fn every_invalid_configuration_is_refused_by_name() {
    let n = 20;
    let f = fixture(n, 7);
    let j = f.model.joint_count();
    let other = fixture(n, 8);
    let mut scratch = Scratch::new(&f.model);
    let unposed = FrameState::new(&f.model);
    let short_normals = vec![Vec3::Y; n - 1];
    let short_tangents = vec![Vec4::X; n + 1];

    let cases: [(&str, RuntimeError); 9] = [
        (
            "mesh of another model",
            RuntimeError::Mismatch { field: "mesh" },
        ),
        (
            "frame of another model",
            RuntimeError::Mismatch { field: "frame" },
        ),
        ("frame without pose", RuntimeError::NoPose),
        (
            "range past the end",
            RuntimeError::Range {
                first: 1,
                count: n,
                vertex_count: n,
            },
        ),
        (
            "overflowing range",
            RuntimeError::Range {
                first: usize::MAX,
                count: n,
                vertex_count: n,
            },
        ),
        (
            "normals out without rest normals",
            RuntimeError::Missing {
                field: "rest_normals",
                because: "out_normals",
            },
        ),
        (
            "rest normals too short",
            RuntimeError::BufferLength {
                field: "rest_normals",
                len: n - 1,
                expected: n,
            },
        ),
        (
            "tangents out without rest tangents",
            RuntimeError::Missing {
                field: "rest_tangents",
                because: "out_tangents",
            },
        ),
        (
            "rest tangents too long",
            RuntimeError::BufferLength {
                field: "rest_tangents",
                len: n + 1,
                expected: n,
            },
        ),
    ];
    for (k, (what, want)) in cases.into_iter().enumerate() {
        let (mut pos, mut nrm, mut tan, mut wts) = (
            vec![Vec3::ZERO; n],
            vec![Vec3::ZERO; n],
            vec![Vec4::ZERO; n],
            vec![0.0; n * j],
        );
        let mut job = full_job(&f, &mut pos, &mut nrm, &mut tan, &mut wts);
        assert!(job.validate().is_ok());
        match k {
            0 => job.mesh = &other.mesh,
            1 => job.frame = &other.frame,
            2 => job.frame = &unposed,
            3 => job.first_vertex = 1,
            4 => job.first_vertex = usize::MAX,
            5 => job.rest_normals = None,
            6 => job.rest_normals = Some(&short_normals),
            7 => job.rest_tangents = None,
            _ => job.rest_tangents = Some(&short_tangents),
        }
        assert_eq!(job.validate(), Err(want.clone()), "{what}");
        assert_eq!(
            job.run(&mut scratch),
            Err(want),
            "{what}: run validates too"
        );
    }
    let mut pos = vec![Vec3::ZERO; n];
    let mut nrm = vec![Vec3::ZERO; n];
    // Output slices of the wrong length (the range length is out_positions').
    let mut short = vec![Vec3::ZERO; n - 1];
    let mut short4 = vec![Vec4::ZERO; n - 1];
    let mut short_w = vec![0.0; n * j - 1];
    fn base<'a>(f: &'a Fixture, p: &'a mut [Vec3]) -> SkinJob<'a, Vec<f32>> {
        SkinJob {
            model: &f.model,
            mesh: &f.mesh,
            frame: &f.frame,
            method: Method::Dqs,
            first_vertex: 0,
            rest_normals: Some(&f.normals),
            rest_tangents: Some(&f.tangents),
            out_positions: p,
            out_normals: None,
            out_tangents: None,
            out_weights: None,
        }
    }
    let mut job = base(&f, &mut pos);
    job.out_normals = Some(&mut short);
    assert_eq!(
        job.validate(),
        Err(RuntimeError::BufferLength {
            field: "out_normals",
            len: n - 1,
            expected: n
        })
    );
    let mut job = base(&f, &mut pos);
    job.out_tangents = Some(&mut short4);
    assert_eq!(
        job.validate(),
        Err(RuntimeError::BufferLength {
            field: "out_tangents",
            len: n - 1,
            expected: n
        })
    );
    let mut job = base(&f, &mut pos);
    job.out_weights = Some(&mut short_w);
    assert_eq!(
        job.validate(),
        Err(RuntimeError::BufferLength {
            field: "out_weights",
            len: n * j - 1,
            expected: n * j
        })
    );
    // Scratch made for a narrower model.
    let tiny = SkinNetModel::from_skf(
        &common::random_model(common::no_skip_config(), 9)
            .to_bytes()
            .unwrap(),
    )
    .unwrap();
    let mut tiny_scratch = Scratch::new(&tiny);
    let mut job = base(&f, &mut pos);
    assert!(matches!(
        job.run(&mut tiny_scratch),
        Err(RuntimeError::BufferLength {
            field: "scratch",
            ..
        })
    ));

    // Weights job.
    let mut w = vec![0.0; 3 * j + 1];
    let wj = WeightsJob {
        model: &f.model,
        mesh: &f.mesh,
        frame: &f.frame,
        first_vertex: 0,
        out_weights: &mut w,
    };
    assert!(matches!(
        wj.validate(),
        Err(RuntimeError::BufferLength {
            field: "out_weights",
            ..
        })
    ));
    let mut w = vec![0.0; 3 * j];
    let wj = WeightsJob {
        model: &f.model,
        mesh: &f.mesh,
        frame: &f.frame,
        first_vertex: n - 2,
        out_weights: &mut w,
    };
    assert_eq!(
        wj.validate(),
        Err(RuntimeError::Range {
            first: n - 2,
            count: 3,
            vertex_count: n
        })
    );

    // Frame state: NaN, wrong joint count, zero quaternion, another model.
    let mut frame = FrameState::new(&f.model);
    let mut nan = f.pose.clone();
    nan.locals[2].rotation.x = f32::NAN;
    assert!(matches!(
        frame.set_pose(&f.model, &nan),
        Err(RuntimeError::Skeleton(_))
    ));
    assert!(!frame.is_ready());
    let mut inf = f.pose.clone();
    inf.locals[0].translation.y = f32::INFINITY;
    assert!(matches!(
        frame.set_pose(&f.model, &inf),
        Err(RuntimeError::Skeleton(_))
    ));
    let mut short_pose = f.pose.clone();
    short_pose.locals.pop();
    assert!(matches!(
        frame.set_pose(&f.model, &short_pose),
        Err(RuntimeError::Skeleton(_))
    ));
    let mut zero_q = f.pose.clone();
    zero_q.locals[3].rotation = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    assert!(
        frame.set_pose(&f.model, &zero_q).is_err(),
        "a zero quaternion has no rotation"
    );
    assert_eq!(
        frame.set_pose(&other.model, &other.pose),
        Err(RuntimeError::Mismatch { field: "frame" })
    );
    frame.set_pose(&f.model, &f.pose).unwrap();
    assert!(frame.is_ready());

    // Palette.
    let mut palette = Palette::new(j);
    assert_eq!(
        palette.set_matrices(&[Mat4::IDENTITY]),
        Err(RuntimeError::BufferLength {
            field: "matrices",
            len: 1,
            expected: j
        })
    );
    let mut mats = vec![Mat4::IDENTITY; j];
    mats[1].w_axis.x = f32::NAN;
    assert_eq!(
        palette.set_matrices(&mats),
        Err(RuntimeError::NonFinite {
            field: "matrices",
            index: 1
        })
    );

    // Static skin job.
    let skin = StaticSkin::from_dense(&vec![1.0 / j as f32; n * j], j).unwrap();
    let rest = f.mesh.rest_positions();
    let unready = Palette::new(j);
    let small_palette = {
        let mut p = Palette::new(j - 1);
        p.set_matrices(&vec![Mat4::IDENTITY; j - 1]).unwrap();
        p
    };
    let mut p = vec![Vec3::ZERO; n];
    fn static_job<'a>(
        skin: &'a StaticSkin,
        palette: &'a Palette,
        rest_positions: &'a [Vec3],
        first_vertex: usize,
        out: &'a mut [Vec3],
    ) -> StaticSkinJob<'a> {
        StaticSkinJob {
            skin,
            palette,
            method: Method::Lbs,
            first_vertex,
            rest_positions,
            rest_normals: None,
            rest_tangents: None,
            out_positions: out,
            out_normals: None,
            out_tangents: None,
        }
    }
    assert!(
        static_job(&skin, f.frame.palette(), rest, 0, &mut p)
            .validate()
            .is_ok()
    );
    assert_eq!(
        static_job(&skin, &unready, rest, 0, &mut p).validate(),
        Err(RuntimeError::NoPose)
    );
    assert_eq!(
        static_job(&skin, &small_palette, rest, 0, &mut p).validate(),
        Err(RuntimeError::BufferLength {
            field: "palette",
            len: j - 1,
            expected: j
        })
    );
    assert_eq!(
        static_job(&skin, f.frame.palette(), &rest[1..], 0, &mut p).validate(),
        Err(RuntimeError::BufferLength {
            field: "rest_positions",
            len: n - 1,
            expected: n
        })
    );
    assert_eq!(
        static_job(&skin, f.frame.palette(), rest, 3, &mut p).validate(),
        Err(RuntimeError::Range {
            first: 3,
            count: n,
            vertex_count: n
        })
    );
    let mut job = static_job(&skin, f.frame.palette(), rest, 0, &mut p);
    job.out_normals = Some(&mut nrm);
    assert_eq!(
        job.validate(),
        Err(RuntimeError::Missing {
            field: "rest_normals",
            because: "out_normals"
        })
    );

    // Bind.
    assert_eq!(
        BoundMesh::bind(&f.model, &[]).err(),
        Some(RuntimeError::VertexCount(0))
    );
    let bad = [Vec3::ZERO, Vec3::new(0.0, f32::NAN, 0.0)];
    assert_eq!(
        BoundMesh::bind(&f.model, &bad).err(),
        Some(RuntimeError::NonFinite {
            field: "positions",
            index: 1
        })
    );
    let mut w = vec![0.0; 5];
    assert_eq!(
        f.model.weights_for(&[Vec3::ZERO], &f.pose, &mut w),
        Err(RuntimeError::BufferLength {
            field: "out",
            len: 5,
            expected: j
        })
    );
}

#[test]
fn corrupt_or_non_finite_files_are_refused() {
    let mut bytes = common::vinecs_bytes(6, 10);
    assert!(matches!(
        SkinNetModel::from_skf(&bytes[..100]),
        Err(RuntimeError::Skf(_))
    ));
    // A NaN f16 in layer 3's weights, with the checksum fixed so only the value is wrong.
    let at = {
        let view = SkfView::parse(&bytes).unwrap();
        let t = view.tensor("skin.l3.weight").unwrap();
        t.bytes.as_ptr() as usize - bytes.as_ptr() as usize + 2 * 7
    };
    bytes[at..at + 2].copy_from_slice(&0x7e00u16.to_le_bytes());
    let sum = file_checksum(&bytes);
    bytes[24..32].copy_from_slice(&sum.to_le_bytes());
    assert_eq!(
        SkinNetModel::from_skf(&bytes).err(),
        Some(RuntimeError::NonFiniteWeight {
            tensor: skinfield_formats::skf::TensorName::new("skin.l3.weight").unwrap(),
            index: 7
        })
    );
}
