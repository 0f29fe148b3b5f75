//! Bone heat on the MakeHuman body: timing and agreement with the artist weights.
//!
//! `cargo run --release --example heat_report -p skinfield-trainer [-- RUNS]`
//!
//! Prints one table row per mesh (the 13,380-vertex body and its 1→4 midpoint subdivision, with
//! the artist weights interpolated the same way) and per bone convention: median wall time of
//! `bone_heat` over RUNS runs (default 3) with its phases, the mean per-vertex L1 difference to
//! the artist weights, and the mean vertex distance (cm) between LBS with our weights and LBS with
//! the artist's over 20 seeded random poses (every joint rotated by a rotation vector with
//! components uniform in ±0.35 rad). A rigid nearest-segment skin is printed as a baseline.
//! Then the same for the glTF humanoids (CesiumMan, Witch, Female_Peasant; largest skin, glTF
//! convention), the LBS distance over every clip of the file sampled at 10 instants each.

use std::collections::HashMap;

use glam::{Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::gltf_io::load_gltf;
use skinfield_formats::makehuman::{MakeHumanOptions, load_makehuman_dir};
use skinfield_formats::shared_data::shared_data_dir;
use skinfield_formats::{Skeleton, Template};
use skinfield_trainer::heat::{HeatOptions, HeatResult, bone_heat};

fn main() -> anyhow::Result<()> {
    let runs: usize = std::env::args().nth(1).map(|s| s.parse()).transpose()?.unwrap_or(3);
    let dir = shared_data_dir().ok_or_else(|| anyhow::anyhow!("shared data not found"))?.join("makehuman-hm08");
    let asset = load_makehuman_dir(&dir, &MakeHumanOptions::default())?;
    let artist = asset.skin.to_dense();
    let (sub, sub_artist) = subdivide(&asset.template, &artist, asset.skeleton.len());
    let poses = random_poses(&asset.skeleton, 20, 0.35);
    println!("| mesh | vertices | bones | convention | time s (median of {runs}) | setup / visibility / factor / solve s | fallbacks | L1 to artist | LBS cm to artist |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, mesh, art) in [("MakeHuman body", &asset.template, &artist), ("body subdivided 1→4", &sub, &sub_artist)] {
        for (convention, tails) in [("head→tail (MakeHuman bones)", Some(asset.bone_tails.clone())), ("to child (glTF)", None)] {
            let options = HeatOptions { bone_tails: tails, ..Default::default() };
            let mut results: Vec<HeatResult> = (0..runs).map(|_| bone_heat(mesh, &asset.skeleton, &options)).collect::<Result<_, _>>()?;
            results.sort_by(|a, b| a.stats.total_s.total_cmp(&b.stats.total_s));
            let r = &results[runs / 2];
            let s = &r.stats;
            let ours = r.skin.to_dense();
            println!(
                "| {name} | {} | {} | {convention} | {:.3} | {:.3} / {:.3} / {:.3} / {:.3} | {} comp, {} vert | {:.3} | {:.2} |",
                mesh.vertex_count(),
                asset.skeleton.len(),
                s.total_s,
                s.setup_s,
                s.attach_s,
                s.factor_s,
                s.solve_s,
                s.fallback_components,
                s.fallback_vertices,
                l1(&ours, art, asset.skeleton.len()),
                lbs_distance_cm(mesh, &asset.skeleton, &poses, &ours, art),
            );
        }
        let rigid = nearest_segment_skin(mesh, &asset.skeleton, &asset.bone_tails);
        println!(
            "| {name} | {} | {} | baseline: rigid nearest head→tail segment | – | – | – | {:.3} | {:.2} |",
            mesh.vertex_count(),
            asset.skeleton.len(),
            l1(&rigid, art, asset.skeleton.len()),
            lbs_distance_cm(mesh, &asset.skeleton, &poses, &rigid, art),
        );
    }
    for file in ["khronos-cesiumman/CesiumMan.glb", "quaternius-witch/Witch.gltf", "quaternius-female-peasant/Female_Peasant.gltf"] {
        let doc = load_gltf(&dir.join("..").join(file))?;
        let Some(skin) = doc.largest_skin() else { continue };
        let mut results: Vec<HeatResult> =
            (0..runs).map(|_| bone_heat(&skin.template, &skin.skeleton, &HeatOptions::default())).collect::<Result<_, _>>()?;
        results.sort_by(|a, b| a.stats.total_s.total_cmp(&b.stats.total_s));
        let r = &results[runs / 2];
        let s = &r.stats;
        let poses: Vec<Vec<Mat4>> = doc
            .clips
            .iter()
            .flat_map(|c| (0..10).map(move |k| c.duration_s * k as f32 / 9.0).map(move |t| c.sample(skin, t)))
            .map(|pose| {
                let mut m = vec![Mat4::IDENTITY; skin.skeleton.len()];
                skin.skeleton.skinning_matrices(&pose, &mut m).expect("pose");
                m
            })
            .collect();
        let (ours, art) = (r.skin.to_dense(), skin.skin.to_dense());
        println!(
            "| {file} ({} welded, {} clips) | {} | {} | to child (glTF) | {:.3} | {:.3} / {:.3} / {:.3} / {:.3} | {} comp of {}, {} vert | {:.3} | {:.2} |",
            s.welded_vertices,
            doc.clips.len(),
            skin.template.vertex_count(),
            skin.skeleton.len(),
            s.total_s,
            s.setup_s,
            s.attach_s,
            s.factor_s,
            s.solve_s,
            s.fallback_components,
            s.components,
            s.fallback_vertices,
            l1(&ours, &art, skin.skeleton.len()),
            if poses.is_empty() { f64::NAN } else { lbs_distance_cm(&skin.template, &skin.skeleton, &poses, &ours, &art) },
        );
    }
    Ok(())
}

/// Mean over vertices of `Σ_j |a_vj − b_vj|` (dense rows of `joints`).
fn l1(a: &[f32], b: &[f32], joints: usize) -> f64 {
    let rows = a.len() / joints;
    a.iter().zip(b).map(|(x, y)| f64::from((x - y).abs())).sum::<f64>() / rows as f64
}

fn random_poses(skeleton: &Skeleton, count: usize, max_angle: f32) -> Vec<Vec<Mat4>> {
    let mut rng = ChaCha8Rng::seed_from_u64(2007);
    (0..count)
        .map(|_| {
            let angles: Vec<f32> = (0..skeleton.angle_count()).map(|_| rng.random_range(-max_angle..max_angle)).collect();
            let pose = skeleton.pose_from_angles(Quat::IDENTITY, Vec3::ZERO, &angles).expect("angle count");
            let mut m = vec![Mat4::IDENTITY; skeleton.len()];
            skeleton.skinning_matrices(&pose, &mut m).expect("pose");
            m
        })
        .collect()
}

fn lbs(p: Vec3, row: &[f32], m: &[Mat4]) -> Vec3 {
    row.iter().zip(m).filter(|(w, _)| **w != 0.0).map(|(w, m)| m.transform_point3(p) * *w).sum()
}

fn lbs_distance_cm(mesh: &Template, skeleton: &Skeleton, poses: &[Vec<Mat4>], a: &[f32], b: &[f32]) -> f64 {
    let j = skeleton.len();
    let mut total = 0.0;
    for m in poses {
        for (v, p) in mesh.positions.iter().enumerate() {
            let row = v * j..(v + 1) * j;
            total += f64::from(lbs(*p, &a[row.clone()], m).distance(lbs(*p, &b[row], m)));
        }
    }
    100.0 * total / (poses.len() * mesh.vertex_count()) as f64
}

fn nearest_segment_skin(mesh: &Template, skeleton: &Skeleton, tails: &[Vec3]) -> Vec<f32> {
    let heads: Vec<Vec3> = skeleton.inverse_bind().iter().map(|m| m.inverse().w_axis.truncate()).collect();
    let j = skeleton.len();
    let mut dense = vec![0.0; mesh.vertex_count() * j];
    for (v, p) in mesh.positions.iter().enumerate() {
        let dist = |k: usize| {
            let (a, b) = (heads[k], tails[k]);
            let d = b - a;
            let t = if d.length_squared() > 0.0 { ((*p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0) } else { 0.0 };
            p.distance(a + d * t)
        };
        let best = (0..j).min_by(|&x, &y| dist(x).total_cmp(&dist(y))).unwrap_or(0);
        dense[v * j + best] = 1.0;
    }
    dense
}

/// Midpoint subdivision (every triangle into four); new vertices average their edge's positions
/// and weights.
fn subdivide(mesh: &Template, weights: &[f32], joints: usize) -> (Template, Vec<f32>) {
    let mut positions = mesh.positions.clone();
    let mut w = weights.to_vec();
    let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
    let mut triangles = Vec::with_capacity(mesh.triangles.len() * 4);
    let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>, w: &mut Vec<f32>| -> u32 {
        *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
            positions.push((positions[a as usize] + positions[b as usize]) * 0.5);
            for k in 0..joints {
                let x = 0.5 * (w[a as usize * joints + k] + w[b as usize * joints + k]);
                w.push(x);
            }
            positions.len() as u32 - 1
        })
    };
    for &[a, b, c] in &mesh.triangles {
        let ab = midpoint(a, b, &mut positions, &mut w);
        let bc = midpoint(b, c, &mut positions, &mut w);
        let ca = midpoint(c, a, &mut positions, &mut w);
        triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    let mut t = Template { positions, triangles, ..Default::default() };
    t.compute_normals();
    (t, w)
}
