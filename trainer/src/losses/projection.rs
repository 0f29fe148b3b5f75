//! Pinhole projection with Brown–Conrady distortion in candle, the same model as
//! [`skinfield_formats::Camera::project`] (OpenCV convention), differentiable w.r.t. the points.

use candle_core::{Result, Tensor};
use skinfield_formats::Camera;

/// Pixel coordinates `[..., 2]` of world points `[..., 3]` seen by `camera`.
///
/// Points at or behind the camera plane have their depth clamped to 1e-6 (their projection is
/// meaningless; callers drop them with [`in_front`] before using the result).
pub fn project(camera: &Camera, points: &Tensor) -> Result<Tensor> {
    let dims = points.dims().to_vec();
    let n: usize = dims[..dims.len() - 1].iter().product();
    let dt = points.dtype();
    let dev = points.device();
    let r = Tensor::from_vec(
        camera.rotation.transpose().to_cols_array().to_vec(),
        (3, 3),
        dev,
    )?
    .to_dtype(dt)?;
    let t = Tensor::from_vec(camera.translation.to_array().to_vec(), (1, 3), dev)?.to_dtype(dt)?;
    // `r` is R row-major (Rᵀ's columns); for row vectors x_camᵀ = xᵀ·Rᵀ + tᵀ.
    let cam = points.reshape((n, 3))?.matmul(&r.t()?)?.broadcast_add(&t)?;
    let z = cam.narrow(1, 2, 1)?.clamp(1e-6, f64::INFINITY)?;
    let mut x = cam.narrow(1, 0, 1)?.div(&z)?;
    let mut y = cam.narrow(1, 1, 1)?.div(&z)?;
    let d = camera.distortion;
    if !d.is_none() {
        let r2 = (x.sqr()? + y.sqr()?)?;
        let poly = ((((&r2 * f64::from(d.k3))? + f64::from(d.k2))? * &r2)? + f64::from(d.k1))?;
        let radial = ((poly * &r2)? + 1.0)?;
        let xy = (&x * &y)?;
        let (p1, p2) = (f64::from(d.p1), f64::from(d.p2));
        let nx = ((&x * &radial)? + (&xy * (2.0 * p1))? + ((&r2 + (x.sqr()? * 2.0)?)? * p2)?)?;
        let ny = ((&y * &radial)? + ((&r2 + (y.sqr()? * 2.0)?)? * p1)? + (&xy * (2.0 * p2))?)?;
        (x, y) = (nx, ny);
    }
    let u = ((x * f64::from(camera.fx))? + f64::from(camera.cx))?;
    let v = ((y * f64::from(camera.fy))? + f64::from(camera.cy))?;
    let mut out = dims;
    if let Some(last) = out.last_mut() {
        *last = 2;
    }
    Tensor::cat(&[u, v], 1)?.reshape(out)
}

/// Pixel coordinates of a world point and the rows `∂u/∂p`, `∂v/∂p` of the projection's
/// Jacobian (the same model as [`Camera::project`]: pinhole, then Brown–Conrady distortion);
/// `None` when the point is not in front of the camera.
#[must_use]
pub fn project_with_jacobian(
    camera: &Camera,
    p: glam::Vec3,
) -> Option<(glam::Vec2, [glam::Vec3; 2])> {
    use glam::{Vec2, Vec3};
    let c = camera.to_camera(p);
    if c.z <= 1e-6 {
        return None;
    }
    let inv_z = 1.0 / c.z;
    let (x, y) = (c.x * inv_z, c.y * inv_z);
    let r = camera.rotation;
    // Rows of R: ∂(x_cam)/∂p.
    let (r0, r1, r2) = (r.row(0), r.row(1), r.row(2));
    let dx = (r0 - r2 * x) * inv_z;
    let dy = (r1 - r2 * y) * inv_z;
    let d = camera.distortion;
    let (xd, yd, j) = if d.is_none() {
        (x, y, [[1.0, 0.0], [0.0, 1.0]])
    } else {
        let rr = x * x + y * y;
        let radial = 1.0 + rr * (d.k1 + rr * (d.k2 + rr * d.k3));
        // ∂radial/∂(r²).
        let dradial = d.k1 + rr * (2.0 * d.k2 + 3.0 * d.k3 * rr);
        let xd = x * radial + 2.0 * d.p1 * x * y + d.p2 * (rr + 2.0 * x * x);
        let yd = y * radial + d.p1 * (rr + 2.0 * y * y) + 2.0 * d.p2 * x * y;
        let j = [
            [
                radial + 2.0 * x * x * dradial + 2.0 * d.p1 * y + 6.0 * d.p2 * x,
                2.0 * x * y * dradial + 2.0 * d.p1 * x + 2.0 * d.p2 * y,
            ],
            [
                2.0 * x * y * dradial + 2.0 * d.p1 * x + 2.0 * d.p2 * y,
                radial + 2.0 * y * y * dradial + 6.0 * d.p1 * y + 2.0 * d.p2 * x,
            ],
        ];
        (xd, yd, j)
    };
    let du: Vec3 = (dx * j[0][0] + dy * j[0][1]) * camera.fx;
    let dv: Vec3 = (dx * j[1][0] + dy * j[1][1]) * camera.fy;
    Some((
        Vec2::new(camera.fx * xd + camera.cx, camera.fy * yd + camera.cy),
        [du, dv],
    ))
}

/// Whether each world point is in front of the camera (the same test as `Camera::project`).
#[must_use]
pub fn in_front(camera: &Camera, points: &[glam::Vec3]) -> Vec<bool> {
    points
        .iter()
        .map(|&p| camera.to_camera(p).z > 1e-6)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use glam::Vec3;
    use skinfield_formats::Distortion;

    fn camera(distorted: bool) -> Camera {
        let mut c = Camera::look_at(
            "c",
            640,
            480,
            0.9,
            Vec3::new(0.5, 1.2, 3.0),
            Vec3::new(0.0, 0.9, 0.0),
            Vec3::Y,
        );
        c.cx += 7.0;
        c.fy *= 1.1;
        if distorted {
            c.distortion = Distortion {
                k1: -0.2,
                k2: 0.05,
                p1: 0.001,
                p2: -0.002,
                k3: 0.01,
            };
        }
        c
    }

    fn points() -> Vec<Vec3> {
        vec![
            Vec3::new(0.0, 0.9, 0.0),
            Vec3::new(0.3, 1.7, -0.2),
            Vec3::new(-0.4, 0.1, 0.3),
            Vec3::new(0.2, 0.5, 0.5),
        ]
    }

    #[test]
    fn equals_camera_project_with_and_without_distortion() {
        for distorted in [false, true] {
            let c = camera(distorted);
            let p = points();
            let t = Tensor::from_vec(
                p.iter().flat_map(|v| v.to_array()).collect::<Vec<f32>>(),
                (2, 2, 3),
                &Device::Cpu,
            )
            .unwrap();
            let uv = project(&c, &t).unwrap();
            assert_eq!(uv.dims(), &[2, 2, 2]);
            let uv = uv.flatten_all().unwrap().to_vec1::<f32>().unwrap();
            for (i, q) in p.iter().enumerate() {
                let e = c.project(*q).unwrap();
                assert!(
                    (uv[2 * i] - e.x).abs() < 1e-3 && (uv[2 * i + 1] - e.y).abs() < 1e-3,
                    "{i}: {:?} vs {e}",
                    &uv[2 * i..2 * i + 2]
                );
            }
        }
        assert!(
            in_front(&camera(false), &[Vec3::ZERO, Vec3::new(0.0, 0.0, 10.0)]) == vec![true, false]
        );
    }

    #[test]
    fn jacobian_matches_camera_project_and_finite_differences() {
        for distorted in [false, true] {
            let c = camera(distorted);
            for p in points() {
                let (uv, j) = project_with_jacobian(&c, p).unwrap();
                let e = c.project(p).unwrap();
                assert!((uv - e).length() < 1e-4, "{uv} vs {e}");
                // Central differences in f64 around the f32 point (step 1e-3 m).
                let h = 1e-3f32;
                for k in 0..3 {
                    let mut a = p;
                    let mut b = p;
                    a[k] += h;
                    b[k] -= h;
                    let fd = (c.project(a).unwrap() - c.project(b).unwrap()) / (2.0 * h);
                    for (row, fdk) in [(0, fd.x), (1, fd.y)] {
                        let got = j[row][k];
                        assert!(
                            (got - fdk).abs() <= 2e-3 * fdk.abs().max(10.0),
                            "distorted {distorted} row {row} axis {k}: {got} vs {fdk}"
                        );
                    }
                }
            }
        }
        assert!(project_with_jacobian(&camera(false), Vec3::new(0.0, 0.0, 10.0)).is_none());
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let c = camera(true);
        let p: Vec<f64> = points()
            .iter()
            .flat_map(|v| v.to_array())
            .map(f64::from)
            .collect();
        let x0 = Tensor::from_vec(p, (4, 3), &Device::Cpu).unwrap();
        let w = Tensor::new(
            &[[0.3f64, -0.2], [1.0, 0.5], [-0.7, 0.1], [0.2, 0.9]],
            &Device::Cpu,
        )
        .unwrap();
        crate::losses::fd::check(&x0, 1e-6, 1e-5, 1e-6, |x| {
            project(&c, x).unwrap().mul(&w).unwrap().sum_all().unwrap()
        });
    }
}
