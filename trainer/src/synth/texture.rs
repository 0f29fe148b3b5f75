//! Procedural textures of the built-in character, as per-vertex linear RGB (the template is
//! dense enough): stripes on the top and sleeves, checks on the skirt, value noise on the skin,
//! so that every view carries colour gradients for the rendering loss.

use glam::Vec3;

use super::body::Part;

/// Integer hash → [0, 1) (a 64-bit mix; deterministic across platforms).
fn hash(x: i64, y: i64, z: i64, seed: u64) -> f32 {
    let mut h = seed ^ 0x9E37_79B9_7F4A_7C15;
    for v in [x, y, z] {
        h ^= v as u64;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 31;
    }
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Trilinear value noise in [0, 1) with cells of side `scale` metres.
#[must_use]
pub fn value_noise(p: Vec3, scale: f32, seed: u64) -> f32 {
    let q = p / scale;
    let f = q.floor();
    let t = q - f;
    let s = t * t * (Vec3::splat(3.0) - 2.0 * t);
    let (x, y, z) = (f.x as i64, f.y as i64, f.z as i64);
    let mut acc = 0.0;
    for c in 0..8 {
        let (dx, dy, dz) = (c & 1, (c >> 1) & 1, c >> 2);
        let w = (if dx == 1 { s.x } else { 1.0 - s.x })
            * (if dy == 1 { s.y } else { 1.0 - s.y })
            * (if dz == 1 { s.z } else { 1.0 - s.z });
        acc += w * hash(x + dx, y + dy, z + dz, seed);
    }
    acc
}

/// A soft square wave in [0, 1] with the given period (smooth edges, so colours have gradients).
fn soft_wave(x: f32, period: f32) -> f32 {
    let s = (std::f32::consts::TAU * x / period).sin();
    0.5 + 0.5 * (3.0 * s).tanh() / 3f32.tanh()
}

/// Colour (linear RGB in [0, 1]) of a template point of the given part.
#[must_use]
pub fn color(p: Vec3, part: Part, seed: u64) -> Vec3 {
    let n = value_noise(p, 0.05, seed) - 0.5;
    let skin = Vec3::new(0.62, 0.38, 0.27) * (1.0 + 0.25 * n);
    let c = match part {
        Part::Head => {
            // Hair on the top and back of the head.
            if p.y > 1.64 || (p.y > 1.57 && p.z < -0.02) {
                Vec3::new(0.09, 0.05, 0.03) * (1.0 + 0.6 * n)
            } else {
                skin
            }
        }
        Part::Arm => skin,
        Part::Torso | Part::Sleeve => {
            let a = Vec3::new(0.06, 0.16, 0.50);
            let b = Vec3::new(0.85, 0.82, 0.72);
            a.lerp(b, soft_wave(p.y, 0.07)) * (1.0 + 0.15 * n)
        }
        Part::Leg => Vec3::new(0.20, 0.12, 0.10).lerp(skin, 0.5) * (1.0 + 0.3 * n),
        Part::Foot => Vec3::new(0.05, 0.05, 0.06) + Vec3::splat(0.05 * n),
        Part::Skirt => {
            let angle = p.z.atan2(p.x);
            let u = soft_wave(angle, std::f32::consts::TAU / 12.0);
            let v = soft_wave(p.y, 0.1);
            let check = u * v + (1.0 - u) * (1.0 - v);
            Vec3::new(0.55, 0.06, 0.08).lerp(Vec3::new(0.95, 0.72, 0.15), check) * (1.0 + 0.2 * n)
        }
    };
    c.clamp(Vec3::ZERO, Vec3::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_continuous_bounded_and_seeded() {
        let p = Vec3::new(0.31, 1.2, -0.07);
        let a = value_noise(p, 0.05, 3);
        assert!((0.0..1.0).contains(&a));
        assert!((value_noise(p + Vec3::splat(1e-4), 0.05, 3) - a).abs() < 0.02);
        assert_ne!(value_noise(p, 0.05, 4), a);
        let stripes: Vec<f32> = (0..20)
            .map(|i| color(Vec3::new(0.0, 1.1 + i as f32 * 0.005, 0.1), Part::Torso, 1).x)
            .collect();
        let spread = stripes.iter().cloned().fold(f32::MIN, f32::max)
            - stripes.iter().cloned().fold(f32::MAX, f32::min);
        assert!(spread > 0.3, "stripes vary across the top: {spread}");
    }
}
