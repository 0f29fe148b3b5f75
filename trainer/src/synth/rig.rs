//! The synthetic camera rig: pinhole cameras on two rings at two heights, all looking at the
//! subject.

use glam::Vec3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use skinfield_formats::math::Aabb;
use skinfield_formats::{Camera, CameraRig};

/// Ring heights (metres) and radius of the default rig.
pub const RING_HEIGHTS: [f32; 2] = [0.7, 1.7];
/// Distance of the cameras from the vertical axis through the subject (metres).
pub const RING_RADIUS: f32 = 3.4;
/// Point every camera looks at.
pub const TARGET: Vec3 = Vec3::new(0.0, 0.9, 0.0);
/// Vertical field of view (radians), enough for the whole subject with raised arms.
pub const FOV_Y: f32 = 0.78;

/// Where a rig stands: the point every camera looks at and the scale of the reference rig
/// ([`RING_HEIGHTS`], [`RING_RADIUS`] and the jitter, all in metres for a 1.75 m subject centred
/// on [`TARGET`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Framing {
    /// The point every camera looks at; the rings are placed around it.
    pub target: Vec3,
    /// Multiplies every distance of the reference rig (model units per metre of the reference).
    pub scale: f32,
}

/// Fraction of the half-image (in each axis) the subject's bounding box may fill in every
/// camera: 5 % of the image width and height stays free on each side.
pub const FILL: f32 = 0.9;

impl Framing {
    /// The reference rig around the built-in character (1.75 m, feet on y = 0): [`TARGET`],
    /// scale 1. Designed for its motion library; `tests::built_in_rig_frames_every_frame`
    /// checks that every camera sees every vertex of every frame.
    pub const BUILT_IN: Self = Self {
        target: TARGET,
        scale: 1.0,
    };

    /// The smallest rig (the reference rig's ring layout, seeded jitter included) centred on
    /// `bounds` in which every camera of `rig_of(count, width, height, seed)` sees all eight
    /// corners of `bounds` inside [`FILL`] of its half-image. Every vertex inside the box is
    /// then in view (the image rectangle is convex and the box lies in front of each camera),
    /// whatever the box's size, unit or proportions: a 79-unit-tall, 155-unit-long fox gets
    /// the same framing as a 0.79 m one, 100 times smaller. An empty box (a single point) gets
    /// a rig a thousandth of the reference.
    #[must_use]
    pub fn around(bounds: &Aabb, count: usize, width: u32, height: u32, seed: u64) -> Self {
        let target = bounds.center();
        let half = bounds.size() * 0.5;
        // The unit rig: cameras at scale 1 around the origin. Scaling the rig keeps every view
        // direction, so the needed scale is the largest over cameras of the distance each
        // needs along its own direction, divided by its distance in the unit rig.
        let unit = Self {
            target: Vec3::ZERO,
            scale: 1.0,
        };
        let tan_y = (0.5 * FOV_Y).tan() * FILL;
        let tan_x = tan_y * width as f32 / height as f32;
        let mut scale = 0.0f32;
        for camera in camera_rig_framed(count, width, height, seed, &unit).cameras {
            let eye = camera.center();
            let distance = eye.length();
            // Camera axes in world coordinates: rows of the world-to-camera rotation.
            let r = camera.rotation.transpose();
            let (right, down, forward) = (r.x_axis, r.y_axis, r.z_axis);
            for corner in 0..8 {
                let q = Vec3::new(
                    if corner & 1 == 0 { -half.x } else { half.x },
                    if corner & 2 == 0 { -half.y } else { half.y },
                    if corner & 4 == 0 { -half.z } else { half.z },
                );
                // Camera depth of the corner at rig scale s is s·distance + q·forward; it must
                // reach |x| / tan_x and |y| / tan_y (and stay in front of the camera).
                let need = (q.dot(right).abs() / tan_x)
                    .max(q.dot(down).abs() / tan_y)
                    .max(0.5 * q.length())
                    - q.dot(forward);
                scale = scale.max(need / distance);
            }
        }
        Self {
            target,
            scale: if scale > 0.0 && scale.is_finite() {
                scale
            } else {
                1e-3
            },
        }
    }
}

/// `count` cameras of `width × height` around the built-in character ([`Framing::BUILT_IN`]).
#[must_use]
pub fn camera_rig(count: usize, width: u32, height: u32, seed: u64) -> CameraRig {
    camera_rig_framed(count, width, height, seed, &Framing::BUILT_IN)
}

/// `count` cameras of `width × height`, alternating between the two rings (the upper ring
/// offset by half a step in azimuth), with ±2° / ±3 cm seeded jitter (×`framing.scale`) so no
/// two rigs are exactly symmetric, all looking at `framing.target`. Names are `cam00`, `cam01`, …
#[must_use]
pub fn camera_rig_framed(
    count: usize,
    width: u32,
    height: u32,
    seed: u64,
    framing: &Framing,
) -> CameraRig {
    let (target, scale) = (framing.target, framing.scale);
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
                target,
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

    fn corners(b: &Aabb) -> Vec<Vec3> {
        (0..8)
            .map(|k| {
                Vec3::new(
                    if k & 1 == 0 { b.min.x } else { b.max.x },
                    if k & 2 == 0 { b.min.y } else { b.max.y },
                    if k & 4 == 0 { b.min.z } else { b.max.z },
                )
            })
            .collect()
    }

    /// Largest offset of a projected corner from the image centre, as a fraction of the half
    /// image, over every camera and corner (≤ FILL when framed, = FILL when tight).
    fn worst_fill(rig: &CameraRig, b: &Aabb) -> f32 {
        let mut worst = 0.0f32;
        for c in &rig.cameras {
            for p in corners(b) {
                assert!(c.to_camera(p).z > 0.0, "{} has a corner behind it", c.name);
                let px = c.project(p).unwrap();
                let fx = (px.x - c.cx).abs() / c.cx;
                let fy = (px.y - c.cy).abs() / c.cy;
                worst = worst.max(fx).max(fy);
            }
        }
        worst
    }

    #[test]
    fn framing_fits_any_box_tightly_and_scales_with_it() {
        // The Fox's proportions (79 tall, 155 long), a thin pole, and a flat wide slab.
        let boxes = [
            Aabb {
                min: Vec3::new(-15.0, 0.0, -77.0),
                max: Vec3::new(15.0, 79.0, 78.0),
            },
            Aabb {
                min: Vec3::new(-0.05, 0.0, -0.05),
                max: Vec3::new(0.05, 2.0, 0.05),
            },
            Aabb {
                min: Vec3::new(-3.0, 1.0, -2.0),
                max: Vec3::new(3.0, 1.2, 2.0),
            },
        ];
        for (w, h) in [(256u32, 256u32), (320, 180)] {
            for b in &boxes {
                let f = Framing::around(b, 12, w, h, 3);
                let rig = camera_rig_framed(12, w, h, 3, &f);
                let fill = worst_fill(&rig, b);
                // Inside the allowed fill, and touching it: no larger than needed.
                assert!(fill <= FILL + 1e-4 && fill > FILL - 1e-3, "{b:?}: {fill}");
                // The same box 100 times larger or smaller, anywhere: the same pictures.
                for (scale, shift) in [(100.0f32, Vec3::new(5.0, -2.0, 1.0)), (0.01, Vec3::ZERO)] {
                    let s = Aabb {
                        min: b.min * scale + shift,
                        max: b.max * scale + shift,
                    };
                    let fs = Framing::around(&s, 12, w, h, 3);
                    assert!((fs.scale / f.scale / scale - 1.0).abs() < 1e-4);
                    let rs = camera_rig_framed(12, w, h, 3, &fs);
                    for (c, cs) in rig.cameras.iter().zip(&rs.cameras) {
                        for (p, ps) in corners(b).into_iter().zip(corners(&s)) {
                            let (a, bb) = (c.project(p).unwrap(), cs.project(ps).unwrap());
                            assert!((a - bb).length() < 0.02, "{a} vs {bb} at scale {scale}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_built_in_framing_is_the_reference_rig() {
        let framed = camera_rig_framed(12, 256, 256, 7, &Framing::BUILT_IN);
        assert_eq!(framed, camera_rig(12, 256, 256, 7));
        // Every camera looks at the target: it projects to the image centre.
        for c in &framed.cameras {
            let px = c.project(TARGET).unwrap();
            assert!((px.x - 128.0).abs() < 1e-3 && (px.y - 128.0).abs() < 1e-3);
        }
    }
}
