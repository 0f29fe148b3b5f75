use candle_core::{DType, Device, Tensor};
use glam::Vec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use skinfield_formats::Camera;

use super::*;
use crate::losses::fd;
use crate::raster::rasterize;

const SIZE: u32 = 48;

fn camera() -> Camera {
    Camera::look_at(
        "c",
        SIZE,
        SIZE,
        0.8,
        Vec3::new(0.3, 0.2, 3.0),
        Vec3::ZERO,
        Vec3::Y,
    )
}

/// A tilted quad and a triangle in front of it (so the z-buffer hides part of the quad).
fn scene() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let p = vec![
        Vec3::new(-0.8, -0.7, -0.2),
        Vec3::new(0.7, -0.8, 0.1),
        Vec3::new(0.8, 0.7, 0.2),
        Vec3::new(-0.7, 0.8, -0.1),
        Vec3::new(-0.2, -0.3, 0.6),
        Vec3::new(0.4, -0.1, 0.5),
        Vec3::new(0.0, 0.4, 0.7),
    ];
    (p, vec![[0, 1, 2], [0, 2, 3], [4, 5, 6]])
}

/// A smooth image with values in [0.3, 0.7] on every channel.
fn image() -> RgbTarget {
    let n = SIZE as usize;
    let rgb: Vec<Vec3> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f32, (i / n) as f32);
            Vec3::new(
                0.5 + 0.2 * (0.23 * x).sin() * (0.11 * y).cos(),
                0.5 + 0.2 * (0.17 * y + 0.4).sin(),
                0.5 + 0.2 * (0.07 * (x + y)).cos(),
            )
        })
        .collect();
    RgbTarget::new(n, n, &rgb).unwrap()
}

fn samples(count: usize, seed: u64) -> PixelSamples {
    let (p, t) = scene();
    let frags = rasterize(&camera(), &p, &t);
    sample_visible(&frags, &t, count, &mut ChaCha8Rng::seed_from_u64(seed))
}

fn tensor(rows: &[Vec3]) -> Tensor {
    let v: Vec<f64> = rows
        .iter()
        .flat_map(|r| r.to_array().map(f64::from))
        .collect();
    Tensor::from_vec(v, (rows.len(), 3), &Device::Cpu).unwrap()
}

#[test]
fn projected_surface_points_are_the_pixel_centres() {
    let s = samples(0, 0);
    assert!(s.len() > 200, "only {} visible pixels", s.len());
    let (p, _) = scene();
    let uv = sample_points(&camera(), &s, &tensor(&p))
        .unwrap()
        .to_vec2::<f64>()
        .unwrap();
    for (k, &pixel) in s.pixels.iter().enumerate() {
        let (x, y) = (pixel % SIZE, pixel / SIZE);
        let (du, dv) = (
            uv[k][0] - (f64::from(x) + 0.5),
            uv[k][1] - (f64::from(y) + 0.5),
        );
        assert!(
            du.abs() < 1e-3 && dv.abs() < 1e-3,
            "pixel {pixel}: off by ({du}, {dv})"
        );
    }
    // The front triangle hides part of the quad: some samples see it.
    assert!(s.corners.chunks(3).any(|c| c[0] == 4));
}

#[test]
fn loss_equals_pixel_space_l1_at_the_rasterised_positions() {
    let s = samples(0, 0);
    let (p, _) = scene();
    let colours: Vec<Vec3> = (0..p.len()).map(|i| Vec3::splat(0.1 * i as f32)).collect();
    let corner: Vec<Vec3> = s.corners.iter().map(|&c| colours[c as usize]).collect();
    let loss = rendering_loss(&camera(), &image(), &s, &tensor(&p), &tensor(&corner))
        .unwrap()
        .to_vec0::<f64>()
        .unwrap();
    // Independent reference: the image's own pixels minus the barycentric colour.
    let img = image();
    let mut reference = 0.0;
    for (k, &pixel) in s.pixels.iter().enumerate() {
        let c = &s.corners[3 * k..3 * k + 3];
        let b = s.bary[k];
        let pred = colours[c[0] as usize] * b[0]
            + colours[c[1] as usize] * b[1]
            + colours[c[2] as usize] * b[2];
        for ch in 0..3 {
            let observed = f64::from(img.channels[ch].data[pixel as usize]);
            reference += (observed - f64::from(pred[ch])).abs();
        }
    }
    assert!(
        (loss - reference).abs() < 1e-3 * reference,
        "{loss} vs {reference}"
    );
}

#[test]
fn gradients_match_finite_differences() {
    let s = samples(40, 7);
    assert_eq!(s.len(), 40);
    let (p, _) = scene();
    // Off the rasterised positions by a fraction of a pixel, so that no sample sits on a node of
    // the bilinear grid (where the sampler's derivative jumps); b and the samples stay fixed.
    let moved: Vec<Vec3> = p
        .iter()
        .enumerate()
        .map(|(i, &x)| x + 0.013 * Vec3::new((i as f32).sin(), (1.7 * i as f32).cos(), 0.3))
        .collect();
    let corner: Vec<Vec3> = s
        .corners
        .iter()
        .map(|&c| Vec3::new(0.05, 0.02 * (c % 3) as f32, 0.08))
        .collect();
    let (cam, img) = (camera(), image());
    let colours = tensor(&corner);
    fd::check(&tensor(&moved), 1e-6, 1e-5, 1e-3, |x| {
        rendering_loss(&cam, &img, &s, x, &colours).unwrap()
    });
    let posed = tensor(&moved);
    fd::check(&colours, 1e-6, 1e-6, 1e-4, |c| {
        rendering_loss(&cam, &img, &s, &posed, c).unwrap()
    });
}

#[test]
fn a_gradient_step_on_positions_recovers_a_shifted_texture() {
    // The image is the scene's own colours rendered at the true positions; the mesh is then
    // shifted sideways. Following −∂L/∂x must bring the loss down.
    let (p, t) = scene();
    let cam = camera();
    let colour = |x: Vec3| {
        Vec3::new(
            0.5 + 0.3 * (4.0 * x.x).sin(),
            0.5 + 0.3 * (3.0 * x.y).cos(),
            0.5,
        )
    };
    let frags = rasterize(&cam, &p, &t);
    let n = SIZE as usize;
    let rgb: Vec<Vec3> = (0..n * n)
        .map(|i| {
            let tri = frags.triangle[i];
            if tri == NO_TRIANGLE {
                return Vec3::splat(0.5);
            }
            let b = frags.bary[i];
            let c = t[tri as usize].map(|v| p[v as usize]);
            colour(c[0] * b[0] + c[1] * b[1] + c[2] * b[2])
        })
        .collect();
    let img = RgbTarget::new(n, n, &rgb).unwrap();
    // Vertex colours cannot reproduce a texture finer than the triangles: use a dense grid of
    // samples on the shifted mesh and colour each sample's corners with its own surface colour.
    let shifted: Vec<Vec3> = p.iter().map(|&x| x + Vec3::new(0.06, 0.0, 0.0)).collect();
    let frags = rasterize(&cam, &shifted, &t);
    let s = sample_visible(&frags, &t, 0, &mut ChaCha8Rng::seed_from_u64(1));
    let corner: Vec<Vec3> = (0..s.len())
        .flat_map(|k| {
            let c = &s.corners[3 * k..3 * k + 3];
            let b = s.bary[k];
            let x = p[c[0] as usize] * b[0] + p[c[1] as usize] * b[1] + p[c[2] as usize] * b[2];
            [colour(x); 3]
        })
        .collect();
    let colours = tensor(&corner);
    let loss = |x: &Tensor| rendering_loss(&cam, &img, &s, x, &colours).unwrap();
    let x0 = candle_core::Var::from_tensor(&tensor(&shifted)).unwrap();
    let l0 = loss(x0.as_tensor());
    let g = l0.backward().unwrap().get(&x0).unwrap().clone();
    // Mean x-gradient over the vertices points back towards −x (the shift was +x).
    let gx = g
        .narrow(1, 0, 1)
        .unwrap()
        .sum_all()
        .unwrap()
        .to_vec0::<f64>()
        .unwrap();
    assert!(gx > 0.0, "x gradient {gx} does not oppose the +x shift");
    let step = (g
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_vec0::<f64>()
        .unwrap())
    .recip()
        * 0.01;
    let l1 = loss(&(x0.as_tensor() - (g * step).unwrap()).unwrap());
    let (l0, l1) = (l0.to_vec0::<f64>().unwrap(), l1.to_vec0::<f64>().unwrap());
    assert!(l1 < l0, "loss {l0} → {l1} after a gradient step");
}

#[test]
fn sampling_is_seeded_distinct_and_visible() {
    let (p, t) = scene();
    let frags = rasterize(&camera(), &p, &t);
    let a = sample_visible(&frags, &t, 25, &mut ChaCha8Rng::seed_from_u64(3));
    let b = sample_visible(&frags, &t, 25, &mut ChaCha8Rng::seed_from_u64(3));
    let c = sample_visible(&frags, &t, 25, &mut ChaCha8Rng::seed_from_u64(4));
    assert_eq!(a, b);
    assert_ne!(a.pixels, c.pixels);
    let mut seen = a.pixels.clone();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), 25);
    assert!(
        a.pixels
            .iter()
            .all(|&q| frags.triangle[q as usize] != NO_TRIANGLE)
    );
    let all = sample_visible(&frags, &t, 1 << 20, &mut ChaCha8Rng::seed_from_u64(3));
    assert_eq!(all.len(), frags.coverage());
    assert!(
        rendering_loss(
            &camera(),
            &image(),
            &PixelSamples::default(),
            &tensor(&p),
            &Tensor::zeros((0, 3), DType::F64, &Device::Cpu).unwrap()
        )
        .unwrap()
        .to_vec0::<f64>()
        .unwrap()
            == 0.0
    );
}
