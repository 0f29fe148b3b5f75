//! The vertices no training outline shows: the gate that restricts the prior on the initial
//! weights to them (`LossWeights::hidden_prior`), and how far a trained model moved them
//! against the vertices the outlines check ([`HiddenDrift`], reported by every training
//! command).
//!
//! A silhouette term moves a vertex's weights only in the views where the vertex lies on the
//! mesh's projected outline (its boundary set and the contour's nearest edges are both made of
//! those vertices, [`crate::losses::silhouette`]). About a third of the built-in character's
//! vertices are on no training view's outline (the legs under the skirt, the crotch, the
//! armpits), yet SkinNet moves them with the vertices the outlines do see, because the network
//! is shared: silhouettes alone raise those vertices' error by 3–29 % while cutting the seen
//! vertices' by 40–46 %, and the zoo's worst vertices off the surface are such hidden vertices
//! (docs/experiments/fidelity.md, "What the silhouettes can see"). A prior on the initial
//! weights over *every* vertex was measured to cost Chamfer everywhere, since it also holds
//! the vertices the images can correct; gated to the hidden ones it leaves those free.
//!
//! Which vertices are hidden is decided once per training template, from the template posed
//! by the initial weights in every training frame (the trained model's outlines differ from
//! them by a fraction of a pixel, and a set that changed during training would make the
//! objective move under the optimiser). A vertex is hidden when it lies on the outline in at
//! most `hidden_view_fraction` of the training views (frames × cameras).

use candle_core::{DType, Tensor};
use glam::Vec3;
use rayon::prelude::*;

use super::data::TrainData;
use super::validation::pose;
use crate::losses::silhouette::EdgeTable;
use crate::losses::silhouette::edges::count_outline_views;

/// How many training views (frame × camera) have each template vertex on the outline of the
/// template posed by `weights` (dense `[V, J]`, one set for every frame), out of how many views.
#[must_use]
pub fn outline_view_counts(
    data: &TrainData,
    weights: &[f32],
    edges: &EdgeTable,
) -> (Vec<u32>, usize) {
    let t = &data.template;
    let v = t.vertex_count();
    let views = data.frames.iter().map(|f| f.views.len()).sum();
    let counts = data
        .frames
        .par_iter()
        .map(|frame| {
            let posed: Vec<Vec3> = pose(&t.positions, weights, &frame.skinning);
            let mut counts = vec![0u32; v];
            let cameras = frame.views.iter().map(|view| &view.camera);
            count_outline_views(&mut counts, cameras, &posed, &t.triangles, edges);
            counts
        })
        .reduce(
            || vec![0u32; v],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        );
    (counts, views)
}

/// The gate: 1 for a vertex on the outline in at most `fraction` of `views`, else 0.
#[must_use]
pub fn hidden_gate(counts: &[u32], views: usize, fraction: f64) -> Vec<f32> {
    let limit = fraction * views as f64;
    counts
        .iter()
        .map(|&c| if f64::from(c) <= limit { 1.0 } else { 0.0 })
        .collect()
}

/// Hidden vertices whose 99th-percentile drift exceeds the seen ones' by more than this factor
/// are reported as unconfirmed ([`HiddenDrift::is_unconfirmed`]). Measured: the default
/// SkinNet and static models of the seven zoo characters and of the built-in captures' three
/// seeds have ratios of 0.05–1.15; the twelve silhouettes-alone models of the built-in
/// captures, whose hidden knees end 10–13 cm further off the true surface than bone heat's worst
/// vertex on novel motions, 1.41–7.8 (docs/experiments/fidelity.md, "How far the hidden
/// vertices move").
pub const UNCONFIRMED_DRIFT_RATIO: f32 = 1.3;

/// How far a model moves the vertices no training outline shows from where the initial weights
/// put them, against the vertices the outlines do show: a warning that needs no ground truth.
///
/// Each vertex's drift is its largest distance, over the training frames, between the template
/// posed by the model's weights and by the initial weights. The seen vertices' drift is checked
/// by the images (the validation scores their outlines); the hidden ones' is the network's
/// extrapolation from its neighbours, which no image confirms. Where the hidden vertices move
/// much further than any the images check, the model has carried weights where it cannot know
/// them (silhouettes alone put the built-in character's knees under the skirt on the hips).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HiddenDrift {
    /// Vertices on no training outline when posed by the initial weights.
    pub hidden: usize,
    /// The other vertices.
    pub seen: usize,
    /// The 99th percentile of the hidden vertices' drift (model units).
    pub hidden_p99: f32,
    /// The 99th percentile of the seen vertices' drift (model units).
    pub seen_p99: f32,
    /// The largest drift of a hidden vertex (model units).
    pub hidden_max: f32,
    /// The template's bounding-box diagonal (model units), for figures relative to its size.
    pub diagonal: f32,
}

impl HiddenDrift {
    /// The summary of per-vertex drifts `drift` split by `hidden`; `None` when either group is
    /// empty or the lengths differ.
    #[must_use]
    pub fn from_drifts(drift: &[f32], hidden: &[bool], diagonal: f32) -> Option<Self> {
        if drift.len() != hidden.len() {
            return None;
        }
        let group = |h: bool| -> Vec<f32> {
            drift
                .iter()
                .zip(hidden)
                .filter(|&(_, &x)| x == h)
                .map(|(&d, _)| d)
                .collect()
        };
        let (mut hidden_drift, mut seen_drift) = (group(true), group(false));
        let hidden_max = hidden_drift.iter().copied().reduce(f32::max)?;
        Some(Self {
            hidden: hidden_drift.len(),
            seen: seen_drift.len(),
            hidden_p99: percentile_99(&mut hidden_drift)?,
            seen_p99: percentile_99(&mut seen_drift)?,
            hidden_max,
            diagonal,
        })
    }

    /// Whether the hidden vertices moved further than the images can confirm: their 99th
    /// percentile above [`UNCONFIRMED_DRIFT_RATIO`] times the seen vertices'.
    #[must_use]
    pub fn is_unconfirmed(&self) -> bool {
        self.hidden_p99 > UNCONFIRMED_DRIFT_RATIO * self.seen_p99
    }
}

impl std::fmt::Display for HiddenDrift {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let pct = |x: f32| 100.0 * x / self.diagonal.max(f32::MIN_POSITIVE);
        write!(
            f,
            "the {} vertices on no training outline moved by up to {:.2} % of the size from the \
             initial skinning on the training poses (99th percentile {:.2} %; the {} seen \
             vertices' {:.2} %)",
            self.hidden,
            pct(self.hidden_max),
            pct(self.hidden_p99),
            self.seen,
            pct(self.seen_p99)
        )
    }
}

/// The value at the nearest rank below the 99th percentile of `values` (reordered in place);
/// `None` when empty. The drift report and the hinge share it, so the hinge acts exactly
/// where the report's ratio would warn.
fn percentile_99(values: &mut [f32]) -> Option<f32> {
    let rank = values.len().checked_sub(1)? * 99 / 100;
    Some(*values.select_nth_unstable_by(rank, f32::total_cmp).1)
}

/// The hinge on the hidden vertices' drift (`LossWeights::hidden_drift`): for every frame of
/// the batch and every hidden vertex, `max(0, d − r)²`, where `d` is the vertex's distance
/// between `posed` and `initial` (both `[B, V, 3]`) and `r` is `ratio` times the 99th
/// percentile of the seen vertices' distances in the same batch; summed, divided by `B·V` and
/// the squared `diagonal`. `gate` is the hidden vertices' `[1, V, 1]` indicator, `seen` its
/// complement as a list of vertex indices.
///
/// Why a hinge and not the prior: the prior on the initial weights holds the hidden vertices
/// where bone heat put them, also where the Laplacian would carry the seen vertices'
/// correction onto them, and costs the full method 4–38 %; the hinge leaves them free to move
/// as far as the vertices the images check do, and only stops the network from carrying them
/// further than any image confirms, which is what [`HiddenDrift`] warns about after training.
/// `r` is measured on the batch itself and carries no gradient, so the seen vertices are not
/// pushed to move further to make room.
pub fn drift_hinge(
    posed: &Tensor,
    initial: &Tensor,
    gate: &Tensor,
    seen: &[u32],
    ratio: f64,
    diagonal: f64,
) -> candle_core::Result<Tensor> {
    let (b, v, _) = posed.dims3()?;
    // A floor under the squared distance keeps the square root's gradient finite at zero.
    let floor = (1e-6 * diagonal).powi(2);
    let distance = ((posed - initial)?.sqr()?.sum_keepdim(2)? + floor)?.sqrt()?;
    let d: Vec<Vec<f32>> = distance.squeeze(2)?.to_dtype(DType::F32)?.to_vec2()?;
    let mut seen_distance: Vec<f32> = d
        .iter()
        .flat_map(|row| seen.iter().map(move |&i| row[i as usize]))
        .collect();
    let Some(seen_p99) = percentile_99(&mut seen_distance) else {
        return Tensor::zeros((), posed.dtype(), posed.device());
    };
    let r = ratio * f64::from(seen_p99);
    let excess = (distance - r)?
        .relu()?
        .broadcast_mul(&gate.to_dtype(posed.dtype())?)?;
    excess.sqr()?.sum_all()? / ((b * v) as f64 * diagonal * diagonal)
}

impl super::Trainer {
    /// The drift of the current weights' hidden vertices against the seen ones
    /// ([`HiddenDrift`]) on the training template and frames; `None` when every vertex is seen
    /// or none is.
    pub fn hidden_drift(&self) -> Result<Option<HiddenDrift>, super::TrainError> {
        let t = &self.data.template;
        let (v, j) = (t.vertex_count(), self.data.skeleton.len());
        let hidden: Vec<bool> = match &self.hidden_gate {
            // The hinge's and the prior's set, counted at set-up, is this one when it admits no
            // outline view.
            Some(gate) if self.config.hidden_view_fraction == 0.0 => {
                gate.gate.iter().map(|&g| g > 0.0).collect()
            }
            _ => {
                let (counts, _) =
                    outline_view_counts(&self.data, &self.data.init_weights, &self.edges);
                counts.iter().map(|&c| c == 0).collect()
            }
        };
        let mut drift = vec![0f32; v];
        let frames: Vec<usize> = (0..self.data.frames.len()).collect();
        // A few frames at a time: the weights of every frame at once are `F·V·J` floats.
        for batch in frames.chunks(8) {
            let w: Vec<f32> = self
                .weights_at(batch, None)?
                .to_dtype(DType::F32)?
                .flatten_all()?
                .to_vec1()?;
            for (b, &f) in batch.iter().enumerate() {
                let skinning = &self.data.frames[f].skinning;
                let model = pose(&t.positions, &w[b * v * j..(b + 1) * v * j], skinning);
                let initial = pose(&t.positions, &self.data.init_weights, skinning);
                for ((d, m), i) in drift.iter_mut().zip(&model).zip(&initial) {
                    *d = d.max(m.distance(*i));
                }
            }
        }
        Ok(HiddenDrift::from_drifts(
            &drift,
            &hidden,
            self.diagonal as f32,
        ))
    }
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Vec3};
    use skinfield_formats::{Camera, Template};

    use super::*;
    use crate::train::TrainConfig;
    use crate::train::tests::scene;

    #[test]
    fn drift_is_unconfirmed_only_where_hidden_vertices_move_further_than_seen_ones() {
        // 200 seen vertices drifting 0..2 (99th percentile at rank 197: 1.97), 100 hidden.
        let seen: Vec<f32> = (0..200).map(|i| i as f32 * 0.01).collect();
        let summary = |hidden_drift: &[f32]| {
            let drift: Vec<f32> = seen.iter().chain(hidden_drift).copied().collect();
            let hidden: Vec<bool> = (0..drift.len()).map(|i| i >= seen.len()).collect();
            HiddenDrift::from_drifts(&drift, &hidden, 10.0).unwrap()
        };
        let like_seen: Vec<f32> = (0..100).map(|i| i as f32 * 0.02).collect();
        let calm = summary(&like_seen);
        assert_eq!((calm.hidden, calm.seen), (100, 200));
        assert!((calm.seen_p99 - 1.97).abs() < 1e-5, "{}", calm.seen_p99);
        assert!((calm.hidden_p99 - 1.96).abs() < 1e-5, "{}", calm.hidden_p99);
        assert!((calm.hidden_max - 1.98).abs() < 1e-5);
        assert!(!calm.is_unconfirmed());
        // Carried 1.2 times as far: within what the default models show; 1.4 times: flagged.
        let scaled = |k: f32| like_seen.iter().map(|d| k * d).collect::<Vec<f32>>();
        assert!(!summary(&scaled(1.2)).is_unconfirmed());
        assert!(summary(&scaled(1.4)).is_unconfirmed());
        // The same hidden vertices carried three times as far: flagged.
        let far = summary(&scaled(3.0));
        assert!(far.is_unconfirmed());
        assert!(far.to_string().contains("59.40 %"), "{far}");
        // Nothing to compare: every vertex seen, or none, or mismatched lengths.
        assert!(HiddenDrift::from_drifts(&seen, &vec![false; seen.len()], 1.0).is_none());
        assert!(HiddenDrift::from_drifts(&seen, &vec![true; seen.len()], 1.0).is_none());
        assert!(HiddenDrift::from_drifts(&seen, &[true], 1.0).is_none());
    }

    #[test]
    fn the_drift_hinge_acts_only_beyond_the_seen_vertices_reach_with_its_analytic_gradient() {
        use candle_core::{Device, Var};
        // Two frames of five vertices: 0–2 seen, 3–4 hidden. Each vertex moves along x only,
        // by these distances from its initial position.
        let moves: [[f64; 5]; 2] = [[0.1, 0.2, 0.3, 0.5, 0.2], [0.4, 0.0, 0.2, 1.0, 0.7]];
        let (ratio, diagonal) = (1.5, 2.0);
        let initial: Vec<f64> = (0..30).map(|i| f64::from(i) * 0.1).collect();
        let mut posed = initial.clone();
        for (f, row) in moves.iter().enumerate() {
            for (v, m) in row.iter().enumerate() {
                posed[(f * 5 + v) * 3] += m;
            }
        }
        let dev = Device::Cpu;
        let posed = Var::from_vec(posed, (2, 5, 3), &dev).unwrap();
        let initial = Tensor::from_vec(initial, (2, 5, 3), &dev).unwrap();
        let gate = Tensor::from_vec(vec![0.0f32, 0.0, 0.0, 1.0, 1.0], (1, 5, 1), &dev).unwrap();
        let hinge =
            |p: &Tensor| drift_hinge(p, &initial, &gate, &[0, 1, 2], ratio, diagonal).unwrap();
        let loss = hinge(posed.as_tensor());
        // The seen distances 0.1 0.2 0.3 0.4 0 0.2: their 99th percentile (nearest rank
        // below) is 0.3, so r = 0.45; beyond it: 0.05, 0.55 and 0.25 (vertex 4 in frame 0,
        // 0.2, is within reach).
        let expected = (0.05f64.powi(2) + 0.55f64.powi(2) + 0.25f64.powi(2)) / (10.0 * 4.0);
        let value = loss.to_scalar::<f64>().unwrap();
        assert!(
            (value - expected).abs() < 1e-9,
            "{value} against {expected}"
        );
        let grads = loss.backward().unwrap();
        let g: Vec<f64> = grads
            .get(&posed)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        // Analytic: 2 (d − r) / (B·V·diag²) along x for a hidden vertex beyond reach, else 0.
        for (f, row) in moves.iter().enumerate() {
            for (v, &m) in row.iter().enumerate() {
                let beyond = v >= 3 && m > 0.45;
                let want = if beyond { 2.0 * (m - 0.45) / 40.0 } else { 0.0 };
                let i = (f * 5 + v) * 3;
                assert!(
                    (g[i] - want).abs() < 1e-9,
                    "frame {f} vertex {v}: {} against {want}",
                    g[i]
                );
                assert!(g[i + 1].abs() < 1e-12 && g[i + 2].abs() < 1e-12);
            }
        }
        // A finite difference on a hidden coordinate agrees (the seen ones fix r).
        let h = 1e-6;
        let mut bumped: Vec<f64> = posed.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
        bumped[(5 + 3) * 3] += h;
        let bumped = Tensor::from_vec(bumped, (2, 5, 3), &dev).unwrap();
        let fd = (hinge(&bumped).to_scalar::<f64>().unwrap() - value) / h;
        assert!(
            (fd - g[(5 + 3) * 3]).abs() < 1e-6,
            "{fd} against {}",
            g[(5 + 3) * 3]
        );
        // No seen vertex: nothing to measure against, no term.
        let none = drift_hinge(posed.as_tensor(), &initial, &gate, &[], ratio, diagonal).unwrap();
        assert_eq!(none.to_scalar::<f64>().unwrap(), 0.0);
    }

    #[test]
    fn weights_that_stay_at_the_initial_ones_do_not_drift() {
        // The static baseline's logits start at the initial weights (to `static_epsilon`), so
        // no vertex moves; the tube seen by one camera has vertices on its outline and others
        // facing the camera or away.
        let (data, _) = scene(2);
        let config = TrainConfig {
            static_epsilon: 1e-7,
            ..crate::train::tests::config()
        };
        let trainer = crate::train::Trainer::new(data, config, true).unwrap();
        let d = trainer
            .hidden_drift()
            .unwrap()
            .expect("seen and hidden vertices");
        assert!(d.hidden > 0 && d.seen > 0);
        assert!(d.hidden_max < 1e-5 * d.diagonal, "{d}");
        assert!(d.seen_p99 < 1e-5 * d.diagonal, "{d}");
    }

    #[test]
    fn the_gate_counts_views_up_to_the_fraction() {
        let counts = [0, 1, 2, 5, 10];
        assert_eq!(hidden_gate(&counts, 10, 0.0), [1.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(hidden_gate(&counts, 10, 0.2), [1.0, 1.0, 1.0, 0.0, 0.0]);
        assert_eq!(hidden_gate(&counts, 10, 1.0), [1.0; 5]);
    }

    #[test]
    fn a_sphere_seen_from_one_side_shows_its_rim_and_hides_its_poles() {
        // A UV sphere (poles on ±y) posed by the identity, one camera on the +y axis: the
        // outline is the ring of vertices where the rays from the eye graze the sphere
        // (y = r²/d = 0.2 for radius 1 at distance 5); the caps around the poles face the
        // camera or away from it and are on no outline.
        let (mut data, _) = scene(1);
        let (positions, triangles) =
            crate::losses::silhouette::tests::uv_sphere(12, 24, 1.0, Vec3::ZERO);
        data.template = Template {
            positions: positions.clone(),
            triangles: triangles.clone(),
            ..Default::default()
        };
        let j = data.skeleton.len();
        let weights: Vec<f32> = (0..positions.len())
            .flat_map(|_| (0..j).map(|k| if k == 0 { 1.0 } else { 0.0 }))
            .collect();
        let frame = &mut data.frames[0];
        frame.skinning = vec![Mat4::IDENTITY; j];
        frame.views.truncate(1);
        frame.views[0].camera =
            Camera::look_at("top", 64, 64, 1.0, Vec3::Y * 5.0, Vec3::ZERO, Vec3::Z);
        let edges = EdgeTable::new(positions.len(), &triangles);
        let (counts, views) = outline_view_counts(&data, &weights, &edges);
        assert_eq!(views, 1);
        let seen: Vec<usize> = (0..positions.len()).filter(|&i| counts[i] > 0).collect();
        assert!(!seen.is_empty());
        for &i in &seen {
            // The rings next to the grazing latitude (y = 0.259 and 0 at 12 rings).
            let p = positions[i];
            assert!(
                (p.y - 0.2).abs() < 0.25,
                "vertex {i} at {p} is on the outline"
            );
        }
        for (i, p) in positions.iter().enumerate() {
            if p.y.abs() > 0.7 {
                assert_eq!(counts[i], 0, "vertex {i} at {p} faces the camera or away");
            }
        }
        let gate = hidden_gate(&counts, views, 0.0);
        assert_eq!(
            gate.iter().filter(|&&g| g == 1.0).count(),
            positions.len() - seen.len()
        );
    }
}
