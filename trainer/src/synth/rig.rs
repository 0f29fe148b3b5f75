//! The synthetic camera rig: pinhole cameras on two rings at two heights, all looking at the
//! subject.

use glam::Vec3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use skinfield_formats::{Camera, CameraRig};

/// Ring heights (metres) and radius of the default rig.
pub const RING_HEIGHTS: [f32; 2] = [0.7, 1.7];
/// Distance of the cameras from the vertical axis through the subject (metres).
pub const RING_RADIUS: f32 = 3.4;
/// Point every camera looks at.
pub const TARGET: Vec3 = Vec3::new(0.0, 0.9, 0.0);
/// Vertical field of view (radians), enough for the whole subject with raised arms.
pub const FOV_Y: f32 = 0.78;

/// `count` cameras of `width × height`, alternating between the two rings (the upper ring
/// offset by half a step in azimuth), with ±2° / ±3 cm seeded jitter so no two rigs are
/// exactly symmetric. Names are `cam00`, `cam01`, …
#[must_use]
pub fn camera_rig(count: usize, width: u32, height: u32, seed: u64) -> CameraRig {
    camera_rig_around(count, width, height, seed, TARGET, 1.75)
}

/// The same rig scaled to a subject of height `subject_height` (model units) centred on
/// `target`: ring heights, radius and jitter scale with the subject.
#[must_use]
pub fn camera_rig_around(
    count: usize,
    width: u32,
    height: u32,
    seed: u64,
    target: Vec3,
    subject_height: f32,
) -> CameraRig {
    let scale = subject_height / 1.75;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xC0FF_EE00);
    let per_ring = count.div_ceil(2).max(1);
    let cameras = (0..count)
        .map(|i| {
            let ring = i % 2;
            let k = i / 2;
            let step = std::f32::consts::TAU / per_ring as f32;
            let azimuth = step * (k as f32 + 0.5 * ring as f32) + rng.random_range(-0.035..0.035);
            let y =
                target.y + scale * (RING_HEIGHTS[ring] - TARGET.y + rng.random_range(-0.03..0.03));
            let eye = Vec3::new(
                target.x + scale * RING_RADIUS * azimuth.sin(),
                y,
                target.z + scale * RING_RADIUS * azimuth.cos(),
            );
            Camera::look_at(
                &format!("cam{i:02}"),
                width,
                height,
                FOV_Y,
                eye,
                TARGET,
                Vec3::Y,
            )
        })
        .collect();
    CameraRig { cameras }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_camera_sees_the_whole_subject() {
        let rig = camera_rig(12, 256, 256, 7);
        rig.validate().unwrap();
        assert_eq!(rig.cameras.len(), 12);
        // Corners of the subject's box in the bind pose (arms spread), with a margin.
        for c in &rig.cameras {
            for corner in 0..8 {
                let p = Vec3::new(
                    if corner & 1 == 0 { -0.85 } else { 0.85 },
                    if corner & 2 == 0 { 0.0 } else { 1.78 },
                    if corner & 4 == 0 { -0.3 } else { 0.3 },
                );
                let px = c.project(p).unwrap();
                assert!(
                    px.x > 0.0 && px.y > 0.0 && px.x < 256.0 && px.y < 256.0,
                    "{} sees {p} at {px}",
                    c.name
                );
            }
        }
    }
}
