//! Synthetic 2D detections projected from known landmark positions, with the failure modes of
//! a real detector: pixel noise, dropped detections (occlusion or low confidence) and gross
//! outliers (a left/right swap in one view). Seeded, so a run is reproducible.

use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::Camera;

use super::solve::Detection;

/// How synthetic detections are corrupted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectionNoise {
    /// Standard deviation of the Gaussian pixel noise, per axis.
    pub sigma_px: f64,
    /// Probability that a detection is dropped: half of them missing, half reported with a
    /// confidence below the tracker's 0.4 threshold.
    pub drop_rate: f64,
    /// Probability, per view and left/right pair, that the two detections are swapped.
    pub swap_rate: f64,
    /// Seed.
    pub seed: u64,
}

impl DetectionNoise {
    /// The reference corruption: 2 px noise, 10 % dropped, 1 % swapped.
    pub const REFERENCE: Self = Self {
        sigma_px: 2.0,
        drop_rate: 0.1,
        swap_rate: 0.01,
        seed: 0,
    };
}

/// Detections of `points` (world landmark positions) in every camera: `[camera][landmark]`.
/// Points behind a camera or outside its image are missing. `pairs` lists left/right landmark
/// pairs that a swap exchanges. `rng` carries the noise state across frames.
pub fn detect(
    cameras: &[Camera],
    points: &[DVec3],
    pairs: &[(usize, usize)],
    noise: &DetectionNoise,
    rng: &mut ChaCha8Rng,
) -> Vec<Vec<Option<Detection>>> {
    let sigma = noise.sigma_px.max(0.0);
    cameras
        .iter()
        .map(|c| {
            let (w, h) = (f64::from(c.width), f64::from(c.height));
            let mut out: Vec<Option<Detection>> = points
                .iter()
                .map(|p| {
                    let px = c.project_f64(*p)?;
                    if !(0.0..w).contains(&px.x) || !(0.0..h).contains(&px.y) {
                        return None;
                    }
                    let jitter = gaussian_pair(rng) * sigma;
                    let confidence = rng.random_range(0.6..1.0);
                    if rng.random_bool(noise.drop_rate.clamp(0.0, 1.0)) {
                        return rng.random_bool(0.5).then(|| Detection {
                            pixel: px + jitter,
                            confidence: rng.random_range(0.05..0.35),
                        });
                    }
                    Some(Detection {
                        pixel: px + jitter,
                        confidence,
                    })
                })
                .collect();
            for &(a, b) in pairs {
                if rng.random_bool(noise.swap_rate.clamp(0.0, 1.0)) {
                    out.swap(a, b);
                }
            }
            out
        })
        .collect()
}

/// A seeded generator for [`detect`].
#[must_use]
pub fn noise_rng(noise: &DetectionNoise) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(noise.seed)
}

/// Two independent standard normal samples (Box–Muller).
fn gaussian_pair(rng: &mut ChaCha8Rng) -> glam::DVec2 {
    let u: f64 = 1.0 - rng.random::<f64>();
    let v: f64 = rng.random();
    let r = (-2.0 * u.ln()).sqrt();
    let a = core::f64::consts::TAU * v;
    glam::DVec2::new(r * a.cos(), r * a.sin())
}

/// The built-in character's landmarks in OpenPose BODY_25 terms: `(keypoint, joint, offset)`.
/// Face keypoints (nose, eyes, ears) and heels are offsets from the head and ankle joints, as
/// DeepCap attaches its face landmarks to the head. Offsets are in metres in the joint's frame
/// (the built-in skeleton's bind rotations are identity: +Y up, +Z forward, +X the character's
/// left).
pub const BUILT_IN_BODY_25: [(&str, &str, [f32; 3]); 25] = [
    ("Nose", "head", [0.0, 0.08, 0.11]),
    ("Neck", "neck", [0.0, 0.0, 0.0]),
    ("RShoulder", "r_shoulder", [0.0, 0.0, 0.0]),
    ("RElbow", "r_elbow", [0.0, 0.0, 0.0]),
    ("RWrist", "r_wrist", [0.0, 0.0, 0.0]),
    ("LShoulder", "l_shoulder", [0.0, 0.0, 0.0]),
    ("LElbow", "l_elbow", [0.0, 0.0, 0.0]),
    ("LWrist", "l_wrist", [0.0, 0.0, 0.0]),
    ("MidHip", "hips", [0.0, 0.0, 0.0]),
    ("RHip", "r_hip", [0.0, 0.0, 0.0]),
    ("RKnee", "r_knee", [0.0, 0.0, 0.0]),
    ("RAnkle", "r_ankle", [0.0, 0.0, 0.0]),
    ("LHip", "l_hip", [0.0, 0.0, 0.0]),
    ("LKnee", "l_knee", [0.0, 0.0, 0.0]),
    ("LAnkle", "l_ankle", [0.0, 0.0, 0.0]),
    ("REye", "head", [-0.035, 0.11, 0.09]),
    ("LEye", "head", [0.035, 0.11, 0.09]),
    ("REar", "head", [-0.08, 0.09, 0.0]),
    ("LEar", "head", [0.08, 0.09, 0.0]),
    ("LBigToe", "l_toe", [0.0, 0.0, 0.06]),
    ("LSmallToe", "l_toe", [0.04, 0.0, 0.04]),
    ("LHeel", "l_ankle", [0.0, -0.05, -0.06]),
    ("RBigToe", "r_toe", [0.0, 0.0, 0.06]),
    ("RSmallToe", "r_toe", [-0.04, 0.0, 0.04]),
    ("RHeel", "r_ankle", [0.0, -0.05, -0.06]),
];

/// BODY_25's left/right keypoint pairs (indices into its order), the ones a swap exchanges.
pub const BODY_25_PAIRS: [(usize, usize); 11] = [
    (2, 5),
    (3, 6),
    (4, 7),
    (9, 12),
    (10, 13),
    (11, 14),
    (15, 16),
    (17, 18),
    (19, 22),
    (20, 23),
    (21, 24),
];
