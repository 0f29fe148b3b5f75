//! Bone heat on the real MakeHuman body (13,380 vertices, 163 bones) against its artist weights.

use glam::Vec3;
use skinfield_formats::makehuman::{MakeHumanOptions, load_makehuman_dir};
use skinfield_formats::shared_data::shared_data_dir;
use skinfield_trainer::heat::{HeatOptions, bone_heat};

#[test]
fn makehuman_body_weights_are_valid_and_closer_to_the_artist_than_rigid_binding() {
    let Some(dir) = shared_data_dir() else { return };
    let asset = load_makehuman_dir(&dir.join("makehuman-hm08"), &MakeHumanOptions::default()).unwrap();
    let options = HeatOptions { bone_tails: Some(asset.bone_tails.clone()), ..Default::default() };
    let r = bone_heat(&asset.template, &asset.skeleton, &options).unwrap();
    let n = asset.template.vertex_count();
    let j = asset.skeleton.len();
    assert_eq!(r.skin.vertex_count(), n);
    assert_eq!(r.stats.components, 1, "{:?}", r.stats);
    assert_eq!((r.stats.fallback_components, r.stats.fallback_vertices), (0, 0));
    assert!(r.stats.raw_sum_deviation < 1e-6, "{:?}", r.stats);
    for v in 0..n {
        let (_, w) = r.skin.influences(v);
        assert!(w.iter().all(|w| w.is_finite() && *w > 0.0));
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }
    // An independent rigid binding (each vertex to its nearest head→tail segment) as the yardstick.
    let heads: Vec<Vec3> = asset.skeleton.inverse_bind().iter().map(|m| m.inverse().w_axis.truncate()).collect();
    let mut rigid = vec![0.0f32; n * j];
    for (v, p) in asset.template.positions.iter().enumerate() {
        let dist = |k: usize| {
            let (a, d) = (heads[k], asset.bone_tails[k] - heads[k]);
            let t = if d.length_squared() > 0.0 { ((*p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0) } else { 0.0 };
            p.distance(a + d * t)
        };
        let best = (0..j).min_by(|&x, &y| dist(x).total_cmp(&dist(y))).unwrap();
        rigid[v * j + best] = 1.0;
    }
    let artist = asset.skin.to_dense();
    let l1 = |a: &[f32]| a.iter().zip(&artist).map(|(x, y)| f64::from((x - y).abs())).sum::<f64>() / n as f64;
    let (ours, baseline) = (l1(&r.skin.to_dense()), l1(&rigid));
    assert!(ours < baseline, "heat L1 {ours} vs rigid {baseline}");
}
