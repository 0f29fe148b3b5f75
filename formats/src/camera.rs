//! Calibrated cameras: pinhole intrinsics, optional Brown–Conrady distortion, extrinsics.
//!
//! Conventions (OpenCV): camera space has +X right, +Y down, +Z forward; `x_cam = R·x_world + t`;
//! pixel centres are at integer + 0.5, so pixel `(0, 0)` covers `[0, 1) × [0, 1)`.

use alloc::string::String;
use alloc::vec::Vec;

use glam::{DMat3, DVec2, DVec3, Mat3, Vec2, Vec3};

/// Brown–Conrady lens distortion (OpenCV's `k1, k2, p1, p2, k3`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Distortion {
    /// Radial coefficient r².
    pub k1: f32,
    /// Radial coefficient r⁴.
    pub k2: f32,
    /// Tangential coefficient 1.
    pub p1: f32,
    /// Tangential coefficient 2.
    pub p2: f32,
    /// Radial coefficient r⁶.
    pub k3: f32,
}

impl Distortion {
    /// True when every coefficient is zero.
    #[must_use]
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }

    /// Distorts normalised image coordinates.
    #[must_use]
    pub fn apply(&self, p: Vec2) -> Vec2 {
        if self.is_none() {
            return p;
        }
        self.apply_f64(p.as_dvec2()).as_vec2()
    }

    /// Distorts normalised image coordinates in double precision (the formula; [`Self::apply`]
    /// rounds it).
    #[must_use]
    pub fn apply_f64(&self, p: DVec2) -> DVec2 {
        let [k1, k2, p1, p2, k3] = [self.k1, self.k2, self.p1, self.p2, self.k3].map(f64::from);
        let r2 = p.length_squared();
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xy = p.x * p.y;
        DVec2::new(
            p.x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * p.x * p.x),
            p.y * radial + p1 * (r2 + 2.0 * p.y * p.y) + 2.0 * p2 * xy,
        )
    }

    /// Inverts [`Self::apply_f64`] by fixed-point iteration (OpenCV's `undistortPoints`
    /// scheme: `p ← (d − tangential(p)) / radial(p)`), stopping when the re-distorted point is
    /// within 1e-12 of `d` or after 50 steps; converges for the moderate distortion of
    /// calibrated lenses.
    #[must_use]
    pub fn undistort_f64(&self, d: DVec2) -> DVec2 {
        if self.is_none() {
            return d;
        }
        let [k1, k2, p1, p2, k3] = [self.k1, self.k2, self.p1, self.p2, self.k3].map(f64::from);
        let mut p = d;
        for _ in 0..50 {
            if (self.apply_f64(p) - d).length() < 1e-12 {
                break;
            }
            let r2 = p.length_squared();
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            let xy = p.x * p.y;
            let tangential = DVec2::new(
                2.0 * p1 * xy + p2 * (r2 + 2.0 * p.x * p.x),
                p1 * (r2 + 2.0 * p.y * p.y) + 2.0 * p2 * xy,
            );
            p = (d - tangential) / radial;
        }
        p
    }
}

/// Why a camera is invalid.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// Zero or absurd resolution.
    #[error("camera `{camera}` has resolution {width}×{height}")]
    BadResolution {
        /// Camera name.
        camera: String,
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// A parameter is NaN, infinite, or (focal length) not positive.
    #[error("camera `{camera}` has an invalid `{field}`")]
    BadParameter {
        /// Camera name.
        camera: String,
        /// The field.
        field: &'static str,
    },
    /// The rotation is not orthonormal with determinant +1.
    #[error("camera `{0}` has a rotation that is not a proper rotation matrix")]
    NotARotation(String),
}

/// Largest image side the readers accept.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// A calibrated camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Name (unique in its rig; used for image file names).
    pub name: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length in pixels along x.
    pub fx: f32,
    /// Focal length in pixels along y.
    pub fy: f32,
    /// Principal point x in pixels.
    pub cx: f32,
    /// Principal point y in pixels.
    pub cy: f32,
    /// Lens distortion (zero for an ideal pinhole).
    pub distortion: Distortion,
    /// World-to-camera rotation.
    pub rotation: Mat3,
    /// World-to-camera translation.
    pub translation: Vec3,
}

impl Camera {
    /// A pinhole camera at `eye` looking at `target` with world `up`, vertical field of view
    /// `fov_y` (radians), principal point at the image centre.
    #[must_use]
    pub fn look_at(
        name: &str,
        width: u32,
        height: u32,
        fov_y: f32,
        eye: Vec3,
        target: Vec3,
        up: Vec3,
    ) -> Self {
        let forward = (target - eye).normalize();
        let right = forward.cross(up).normalize();
        let down = forward.cross(right);
        // Rows of R are the camera axes expressed in world coordinates.
        let rotation = Mat3::from_cols(right, down, forward).transpose();
        let f = 0.5 * height as f32 / libm::tanf(0.5 * fov_y);
        Self {
            name: name.into(),
            width,
            height,
            fx: f,
            fy: f,
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
            distortion: Distortion::default(),
            rotation,
            translation: -(rotation * eye),
        }
    }

    /// Camera centre in world coordinates.
    #[must_use]
    pub fn center(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// World point to camera space.
    #[must_use]
    pub fn to_camera(&self, world: Vec3) -> Vec3 {
        self.rotation * world + self.translation
    }

    /// Projects a world point to pixel coordinates; `None` when it is not in front of the camera.
    #[must_use]
    pub fn project(&self, world: Vec3) -> Option<Vec2> {
        let c = self.to_camera(world);
        if c.z <= 1e-6 {
            return None;
        }
        let n = self.distortion.apply(Vec2::new(c.x / c.z, c.y / c.z));
        Some(Vec2::new(self.fx * n.x + self.cx, self.fy * n.y + self.cy))
    }

    /// [`Self::project`] in double precision (the camera's parameters widened).
    #[must_use]
    pub fn project_f64(&self, world: DVec3) -> Option<DVec2> {
        let c = self.rotation.as_dmat3() * world + self.translation.as_dvec3();
        if c.z <= 1e-9 {
            return None;
        }
        let n = self.distortion.apply_f64(DVec2::new(c.x / c.z, c.y / c.z));
        Some(DVec2::new(
            f64::from(self.fx) * n.x + f64::from(self.cx),
            f64::from(self.fy) * n.y + f64::from(self.cy),
        ))
    }

    /// The ray through a pixel (undistorted): the camera centre and the unit direction, in world
    /// coordinates, double precision.
    #[must_use]
    pub fn ray_f64(&self, pixel: DVec2) -> (DVec3, DVec3) {
        let d = DVec2::new(
            (pixel.x - f64::from(self.cx)) / f64::from(self.fx),
            (pixel.y - f64::from(self.cy)) / f64::from(self.fy),
        );
        let n = self.distortion.undistort_f64(d);
        // The inverse, not the transpose: a rotation stored in f32 is orthonormal only to about
        // 1e-7, and rays must invert `project_f64` exactly.
        let inv: DMat3 = self.rotation.as_dmat3().inverse();
        let origin = -(inv * self.translation.as_dvec3());
        (origin, (inv * n.extend(1.0)).normalize())
    }

    /// Checks resolution, intrinsics and that the rotation is a rotation.
    pub fn validate(&self) -> Result<(), CameraError> {
        let bad = |field| CameraError::BadParameter {
            camera: self.name.clone(),
            field,
        };
        if self.width == 0
            || self.height == 0
            || self.width > MAX_IMAGE_SIDE
            || self.height > MAX_IMAGE_SIDE
        {
            return Err(CameraError::BadResolution {
                camera: self.name.clone(),
                width: self.width,
                height: self.height,
            });
        }
        for (v, field) in [(self.fx, "fx"), (self.fy, "fy")] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field));
            }
        }
        for (v, field) in [(self.cx, "cx"), (self.cy, "cy")] {
            if !v.is_finite() {
                return Err(bad(field));
            }
        }
        let d = self.distortion;
        if ![d.k1, d.k2, d.p1, d.p2, d.k3].iter().all(|v| v.is_finite()) {
            return Err(bad("distortion"));
        }
        if !self.translation.is_finite() {
            return Err(bad("translation"));
        }
        let r = self.rotation;
        if !r.is_finite()
            || !(r * r.transpose()).abs_diff_eq(Mat3::IDENTITY, 1e-3)
            || (r.determinant() - 1.0).abs() > 1e-3
        {
            return Err(CameraError::NotARotation(self.name.clone()));
        }
        Ok(())
    }
}

/// A set of calibrated cameras.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraRig {
    /// The cameras, in capture order.
    pub cameras: Vec<Camera>,
}

impl CameraRig {
    /// Validates every camera.
    pub fn validate(&self) -> Result<(), CameraError> {
        self.cameras.iter().try_for_each(Camera::validate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_projects_target_to_centre_and_up_to_smaller_y() {
        let c = Camera::look_at(
            "c",
            200,
            100,
            1.0,
            Vec3::new(0.0, 1.0, 3.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::Y,
        );
        c.validate().unwrap();
        let p = c.project(Vec3::new(0.0, 1.0, 0.0)).unwrap();
        assert!((p - Vec2::new(100.0, 50.0)).length() < 1e-4);
        let up = c.project(Vec3::new(0.0, 1.5, 0.0)).unwrap();
        assert!(up.y < 50.0);
        let right = c.project(Vec3::new(0.5, 1.0, 0.0)).unwrap();
        assert!(
            right.x > 100.0,
            "world +X is to the right when looking down -Z"
        );
        assert!((c.center() - Vec3::new(0.0, 1.0, 3.0)).length() < 1e-5);
        assert!(c.project(Vec3::new(0.0, 1.0, 4.0)).is_none());
    }

    #[test]
    fn rejects_bad_cameras() {
        let good = Camera::look_at("c", 64, 64, 1.0, Vec3::Z * 3.0, Vec3::ZERO, Vec3::Y);
        let mut c = good.clone();
        c.width = 0;
        assert!(matches!(
            c.validate(),
            Err(CameraError::BadResolution { .. })
        ));
        let mut c = good.clone();
        c.fx = -1.0;
        assert!(matches!(
            c.validate(),
            Err(CameraError::BadParameter { field: "fx", .. })
        ));
        let mut c = good.clone();
        c.distortion.k1 = f32::NAN;
        assert!(matches!(
            c.validate(),
            Err(CameraError::BadParameter {
                field: "distortion",
                ..
            })
        ));
        let mut c = good;
        c.rotation = Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0));
        assert!(matches!(c.validate(), Err(CameraError::NotARotation(_))));
    }
}
