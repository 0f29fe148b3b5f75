//! The target outline's nearest-segment field, built once per training mask when a capture is
//! loaded (960 masks of 256² on the built-in capture), against a reference measured in the same
//! run: the plain sweep that every offer measures twice and every neighbour repeats
//! ([`Outline::plain_nearest_segments`]; the cached sweep records the same field bit for bit,
//! tested in the trainer). Also the whole construction (marching squares plus the cached sweep).
//!
//! The mask is a stick figure of capsules with 4 × 4 supersampled coverage, about the size of a
//! framed person in a 256² view.
//!
//! `cargo bench -p skinfield-benches --bench outline`

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec2;
use skinfield_trainer::losses::silhouette::Outline;

const SIZE: usize = 256;

/// Distance from `p` to the segment `a`–`b`.
fn segment_distance(p: Vec2, a: Vec2, b: Vec2) -> f32 {
    let d = b - a;
    let t = ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
    (p - (a + d * t)).length()
}

/// Coverage of a standing figure: head, torso, arms and legs as capsules (pixels).
fn figure() -> Vec<f32> {
    let c = SIZE as f32 / 256.0;
    let capsules: Vec<(Vec2, Vec2, f32)> = [
        ((128.0, 40.0), (128.0, 48.0), 14.0),
        ((128.0, 70.0), (128.0, 140.0), 24.0),
        ((108.0, 72.0), (80.0, 125.0), 8.0),
        ((80.0, 125.0), (70.0, 170.0), 7.0),
        ((148.0, 72.0), (176.0, 125.0), 8.0),
        ((176.0, 125.0), (186.0, 170.0), 7.0),
        ((116.0, 150.0), (108.0, 200.0), 11.0),
        ((108.0, 200.0), (104.0, 245.0), 9.0),
        ((140.0, 150.0), (148.0, 200.0), 11.0),
        ((148.0, 200.0), (152.0, 245.0), 9.0),
    ]
    .iter()
    .map(|&((ax, ay), (bx, by), r)| (Vec2::new(ax, ay) * c, Vec2::new(bx, by) * c, r * c))
    .collect();
    let mut coverage = vec![0.0f32; SIZE * SIZE];
    for (i, cov) in coverage.iter_mut().enumerate() {
        let (x, y) = ((i % SIZE) as f32, (i / SIZE) as f32);
        let mut hits = 0;
        for sy in 0..4 {
            for sx in 0..4 {
                let p = Vec2::new(x + (sx as f32 + 0.5) / 4.0, y + (sy as f32 + 0.5) / 4.0);
                if capsules
                    .iter()
                    .any(|&(a, b, r)| segment_distance(p, a, b) <= r)
                {
                    hits += 1;
                }
            }
        }
        *cov = hits as f32 / 16.0;
    }
    coverage
}

fn bench(c: &mut Criterion) {
    let coverage = figure();
    let outline = Outline::from_coverage(SIZE, SIZE, &coverage).expect("figure");
    assert_eq!(
        outline.cached_nearest_segments(),
        outline.plain_nearest_segments()
    );
    let mut group = c.benchmark_group("outline_256");
    group.bench_function("nearest_field/plain", |b| {
        b.iter(|| outline.plain_nearest_segments());
    });
    group.bench_function("nearest_field/cached", |b| {
        b.iter(|| outline.cached_nearest_segments());
    });
    group.bench_function("from_coverage", |b| {
        b.iter(|| Outline::from_coverage(SIZE, SIZE, &coverage).expect("figure"));
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
