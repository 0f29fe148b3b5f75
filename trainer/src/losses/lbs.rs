//! Linear blend skinning in candle: `x_v = Σ_j w_vj · G_j · x̄_v`, differentiable w.r.t. `w`.
//!
//! The per-vertex blended matrix `Σ_j w_vj G_j` is a batched `[F, V, J] × [F, J, 12]` matmul;
//! applying it to `[x̄, 1]` is an elementwise product and a sum. That keeps the graph small (two
//! ops) instead of materialising all `J` transformed copies of the mesh.

use candle_core::{Device, Result, Tensor};
use glam::{Mat4, Vec3};

/// Skinning matrices (`world · inverse_bind`) of `F` frames, `J` each, as an f32 tensor
/// `[F, J, 12]`: the top three rows of each matrix, row-major.
pub fn skinning_tensor(frames: &[Vec<Mat4>], device: &Device) -> Result<Tensor> {
    let j = frames.first().map_or(0, Vec::len);
    if frames.iter().any(|f| f.len() != j) {
        candle_core::bail!("skinning matrices: frames have different joint counts");
    }
    let mut data = Vec::with_capacity(frames.len() * j * 12);
    for m in frames.iter().flatten() {
        let r = m.transpose().to_cols_array(); // rows of m
        data.extend_from_slice(&r[..12]);
    }
    Tensor::from_vec(data, (frames.len(), j, 12), device)
}

/// Homogeneous rest positions `[V, 4]` (`[x, y, z, 1]`).
pub fn rest_homogeneous(positions: &[Vec3], device: &Device) -> Result<Tensor> {
    let data: Vec<f32> = positions
        .iter()
        .flat_map(|p| [p.x, p.y, p.z, 1.0])
        .collect();
    Tensor::from_vec(data, (positions.len(), 4), device)
}

/// Posed positions `[F, V, 3]` from weights `[F, V, J]`, skinning matrices `[F, J, 12]`
/// ([`skinning_tensor`]) and homogeneous rest positions `[V, 4]` ([`rest_homogeneous`]).
pub fn lbs(weights: &Tensor, skinning: &Tensor, rest: &Tensor) -> Result<Tensor> {
    let (f, v, _j) = weights.dims3()?;
    let blended = weights
        .matmul(&skinning.to_dtype(weights.dtype())?)?
        .reshape((f, v, 3, 4))?;
    let x = rest.to_dtype(weights.dtype())?.reshape((1, v, 1, 4))?;
    blended.broadcast_mul(&x)?.sum(3)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::DType;
    use glam::Quat;

    #[test]
    fn blends_two_rigid_transforms() {
        // Joint 0: identity; joint 1: 90° about z then +1 in x. Vertex (1, 0, 0) with weights
        // (0.25, 0.75) → 0.25·(1,0,0) + 0.75·(1,1,0) = (1, 0.75, 0).
        let g1 = Mat4::from_rotation_translation(
            Quat::from_rotation_z(core::f32::consts::FRAC_PI_2),
            Vec3::X,
        );
        let s = skinning_tensor(&[vec![Mat4::IDENTITY, g1]], &Device::Cpu).unwrap();
        let rest = rest_homogeneous(&[Vec3::X, Vec3::new(0.0, 2.0, 0.0)], &Device::Cpu).unwrap();
        let w = Tensor::new(&[[[0.25f32, 0.75], [0.0, 1.0]]], &Device::Cpu).unwrap();
        let x = lbs(&w, &s, &rest).unwrap().to_vec3::<f32>().unwrap();
        let expect = [[1.0, 0.75, 0.0], [-1.0, 0.0, 0.0]];
        for (got, e) in x[0].iter().zip(expect) {
            for k in 0..3 {
                assert!((got[k] - e[k]).abs() < 1e-6, "{got:?} vs {e:?}");
            }
        }
    }

    #[test]
    fn gradient_with_respect_to_weights_matches_finite_differences() {
        let g = |a: f32, t: Vec3| Mat4::from_rotation_translation(Quat::from_rotation_y(a), t);
        let frames = vec![
            vec![g(0.3, Vec3::X), g(-1.0, Vec3::Y), g(2.0, Vec3::Z)],
            vec![g(0.1, Vec3::ZERO), g(0.5, Vec3::ONE), g(-0.2, Vec3::X)],
        ];
        let s = skinning_tensor(&frames, &Device::Cpu)
            .unwrap()
            .to_dtype(DType::F64)
            .unwrap();
        let rest = rest_homogeneous(
            &[Vec3::new(0.1, 0.2, 0.3), Vec3::new(-1.0, 0.5, 2.0)],
            &Device::Cpu,
        )
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap();
        let w0 = Tensor::new(
            &[
                [[0.2f64, 0.3, 0.5], [0.6, 0.1, 0.3]],
                [[1.0, 0.0, 0.0], [0.3, 0.3, 0.4]],
            ],
            &Device::Cpu,
        )
        .unwrap();
        // A non-linear function of the posed positions so the gradient depends on them.
        crate::losses::fd::check(&w0, 1e-6, 1e-7, 1e-6, |w| {
            lbs(w, &s, &rest).unwrap().sqr().unwrap().sum_all().unwrap()
        });
    }

    /// The differentiable twin of the runtime's LBS: on random affine joints and random
    /// weights, equal to `StaticSkinJob` (what ships) up to float rounding.
    #[test]
    fn equals_the_runtimes_static_skinning() {
        use rand::{Rng, SeedableRng};
        use skinfield_formats::StaticSkin;
        use skinfield_runtime::{Method, Palette, StaticSkinJob};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (v, j) = (40, 5);
        let mats: Vec<Mat4> = (0..j)
            .map(|_| {
                Mat4::from_scale_rotation_translation(
                    Vec3::splat(rng.random_range(0.8..1.2)),
                    Quat::from_rotation_arc(
                        Vec3::Y,
                        Vec3::new(rng.random(), rng.random(), rng.random()).normalize(),
                    ),
                    Vec3::new(rng.random(), rng.random(), rng.random()),
                )
            })
            .collect();
        let rest: Vec<Vec3> = (0..v)
            .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - Vec3::ONE)
            .collect();
        let mut dense = vec![0.0f32; v * j];
        for row in dense.chunks_mut(j) {
            row.iter_mut().for_each(|w| *w = rng.random_range(0.0..1.0));
            let sum: f32 = row.iter().sum();
            row.iter_mut().for_each(|w| *w /= sum);
        }
        let dev = Device::Cpu;
        let w = Tensor::from_vec(dense.clone(), (1, v, j), &dev).unwrap();
        let s = skinning_tensor(std::slice::from_ref(&mats), &dev).unwrap();
        let ours = lbs(&w, &s, &rest_homogeneous(&rest, &dev).unwrap())
            .unwrap()
            .to_vec3::<f32>()
            .unwrap();
        let skin = StaticSkin::from_dense(&dense, j).unwrap();
        let mut palette = Palette::new(j);
        palette.set_matrices(&mats).unwrap();
        let mut shipped = vec![Vec3::ZERO; v];
        StaticSkinJob {
            skin: &skin,
            palette: &palette,
            method: Method::Lbs,
            first_vertex: 0,
            rest_positions: &rest,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut shipped,
            out_normals: None,
            out_tangents: None,
        }
        .run()
        .unwrap();
        for (a, b) in ours[0].iter().zip(&shipped) {
            assert!((Vec3::from_slice(a) - *b).length() < 1e-5, "{a:?} vs {b}");
        }
    }
}
