//! Bone heat on the MakeHuman body (13,380 vertices, 163 bones) against a reference measured in
//! the same run: the linear algebra alone (a sparse Cholesky factorisation of the mesh's
//! uniform graph Laplacian plus the identity, and 163 solves, with faer sequentially), which
//! bounds from below what any bone-heat implementation on this mesh has to spend.
//!
//! `cargo bench -p skinfield-benches --bench heat`

use criterion::{Criterion, criterion_group, criterion_main};
use faer::Mat;
use faer::linalg::solvers::Solve as _;
use faer::sparse::{SparseColMat, Triplet};
use skinfield_formats::makehuman::{MakeHumanOptions, load_makehuman_dir};
use skinfield_formats::shared_data::shared_data_dir;
use skinfield_trainer::heat::{HeatOptions, bone_heat};

fn bench(c: &mut Criterion) {
    let Some(dir) = shared_data_dir() else { return };
    let asset = load_makehuman_dir(&dir.join("makehuman-hm08"), &MakeHumanOptions::default()).expect("MakeHuman body");
    faer::set_global_parallelism(faer::Par::Seq);
    let mut group = c.benchmark_group("heat");
    group.sample_size(10);
    let options = HeatOptions { bone_tails: Some(asset.bone_tails.clone()), ..Default::default() };
    group.bench_function("bone_heat/makehuman_body", |b| {
        b.iter(|| bone_heat(&asset.template, &asset.skeleton, &options).expect("heat"));
    });
    let n = asset.template.vertex_count();
    let mut triplets = Vec::new();
    let mut degree = vec![1.0f64; n];
    for t in &asset.template.triangles {
        for k in 0..3 {
            let (i, j) = (t[k] as usize, t[(k + 1) % 3] as usize);
            triplets.push(Triplet::new(i.max(j), i.min(j), -0.5));
            degree[i] += 0.5;
            degree[j] += 0.5;
        }
    }
    triplets.extend(degree.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
    let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets).expect("matrix");
    let joints = asset.skeleton.len();
    group.bench_function("reference_cholesky_163_solves/makehuman_body", |b| {
        b.iter(|| {
            let llt = a.sp_cholesky(faer::Side::Lower).expect("SPD");
            let rhs = Mat::<f64>::from_fn(n, joints, |i, j| f64::from(u8::from(i % joints == j)));
            llt.solve(rhs)
        });
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
