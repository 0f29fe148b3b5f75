//! Lab probe for the runtime's fast path (issue 18): where and why it deviates from the exact
//! path on a trained model, and how the additive weight interpolation it replaced did.
//!
//! ```text
//! cargo run -p skinfield-trainer --example fast_path_probe -- CAPTURE_DIR MODEL.skf [log|additive|clamp]
//! ```
//!
//! For every test frame it skins the capture's template with the exact path and with the fast
//! path (LBS; the options of the measurements in docs/experiments/fast-path.md: 256 nodes, 8 base
//! influences), and prints the mean vertex deviation, how many vertex-frames
//! have a negative interpolated weight, and the worst vertices. `log` (the default) is the
//! shipped fast path, which interpolates the nodes' log-weight changes,
//! `w_v ∝ B_v ⊙ exp(Σ a_vi (ln w_n(θ) − ln w_n(bind)))`. `additive` re-skins every vertex with
//! the form it replaced, `B_v + Σ a_vi (w_n(θ) − B_n)` (`B`: the 8 strongest bind-pose joints,
//! renormalised), and `clamp` does the same with negative weights clamped to zero and
//! renormalised. All variants use the exact weights at the nodes, as the fast path does.
use skinfield_formats::capture::load_capture;
use skinfield_runtime::*;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let capture = load_capture(&args[0]).unwrap();
    let model = SkinNetModel::from_skf(&std::fs::read(&args[1]).unwrap()).unwrap();
    let mode = args.get(2).cloned().unwrap_or_default();
    let clamp = mode == "clamp";
    let additive = clamp || mode == "additive";
    let t = &capture.template;
    let n = t.positions.len();
    let j = model.joint_count();
    let mesh = BoundMesh::bind(&model, &t.positions).unwrap();
    // The options the lab notes were measured with (the defaults until 2026-12-03).
    let options = FastOptions {
        nodes: 256,
        base_influences: 8,
        ..FastOptions::DEFAULT
    };
    let fast = FastMesh::bind(&model, &t.positions, &t.triangles, &options).unwrap();
    let mut frame = FrameState::new(&model);
    let mut scratch = Scratch::new(&model);
    let mut nodes = FastFrame::new(&fast);
    let (mut pe, mut pf) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
    let mut we = vec![0.0f32; n * j];
    let mut wf = vec![0.0f32; n * j];
    let mut all = Vec::new();
    let k = fast.options().neighbours;
    let interp = fast.interpolation().to_vec();
    let node_v = fast.node_vertices().to_vec();
    let mut neg_total = 0usize;
    for &f in &capture.test_frames {
        frame.set_pose(&model, &capture.poses[f]).unwrap();
        SkinJob {
            model: &model,
            mesh: &mesh,
            frame: &frame,
            method: Method::Lbs,
            first_vertex: 0,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut pe,
            out_normals: None,
            out_tangents: None,
            out_weights: Some(&mut we),
        }
        .run(&mut scratch)
        .unwrap();
        nodes.update(&model, &fast, &frame, &mut scratch).unwrap();
        FastSkinJob {
            mesh: &fast,
            frame: &frame,
            nodes: &nodes,
            method: Method::Lbs,
            influences: 8,
            first_vertex: 0,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut pf,
            out_normals: None,
            out_tangents: None,
            out_weights: Some(&mut wf),
        }
        .run()
        .unwrap();
        if additive {
            // The replaced form, from the mesh's own base and the nodes' exact weights.
            let mats = frame.palette().matrices();
            let base = fast.base();
            let kb = fast.options().base_influences;
            let wn = nodes.node_weights();
            for v in 0..n {
                let w = &mut wf[v * j..(v + 1) * j];
                w.fill(0.0);
                for b in &base[v * kb..(v + 1) * kb] {
                    w[b.index as usize] += b.weight;
                }
                for e in &interp[v * k..(v + 1) * k] {
                    let node = e.index as usize;
                    let nv = node_v[node] as usize;
                    for (jj, x) in w.iter_mut().enumerate() {
                        *x += e.weight * wn[node * j + jj];
                    }
                    for b in &base[nv * kb..(nv + 1) * kb] {
                        w[b.index as usize] -= e.weight * b.weight;
                    }
                }
                if clamp && w.iter().any(|&x| x < 0.0) {
                    w.iter_mut().for_each(|x| *x = x.max(0.0));
                    let s: f32 = w.iter().sum();
                    w.iter_mut().for_each(|x| *x /= s);
                }
                let m = (0..j).fold(Mat4::ZERO, |a, q| a + mats[q] * w[q]);
                pf[v] = m.transform_point3(t.positions[v]);
            }
        }
        for v in 0..n {
            let d = pe[v].distance(pf[v]);
            let w = &wf[v * j..(v + 1) * j];
            let minw = w.iter().cloned().fold(f32::INFINITY, f32::min);
            if minw < -1e-4 {
                neg_total += 1;
            }
            let l1: f32 = w
                .iter()
                .zip(&we[v * j..(v + 1) * j])
                .map(|(a, b)| (a - b).abs())
                .sum();
            all.push((d, f, v, minw, l1));
        }
    }
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mean: f32 = all.iter().map(|x| x.0).sum::<f32>() / all.len() as f32;
    println!(
        "mean deviation {:.4} cm, vertex-frames with a weight < -1e-4: {} of {}",
        100.0 * mean,
        neg_total,
        all.len()
    );
    for x in &all[..12] {
        println!(
            "dev {:.3} cm frame {} vertex {} min weight {:.4} L1 to exact {:.3}",
            100.0 * x.0,
            x.1,
            x.2,
            x.3,
            x.4
        );
    }
    let neg: Vec<_> = all.iter().filter(|x| x.3 < -1e-4).collect();
    let negmean = neg.iter().map(|x| x.0).sum::<f32>() / neg.len().max(1) as f32;
    println!(
        "mean deviation where a weight is negative: {:.3} cm",
        100.0 * negmean
    );
}
