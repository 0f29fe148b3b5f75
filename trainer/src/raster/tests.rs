use glam::{Vec2, Vec3};
use skinfield_formats::Camera;

use super::*;

fn front_camera(size: u32) -> Camera {
    Camera::look_at(
        "c",
        size,
        size,
        0.8,
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::ZERO,
        Vec3::Y,
    )
}

fn uv_sphere(center: Vec3, r: f32, rings: u32, segments: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for i in 0..=rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let ph = std::f32::consts::TAU * j as f32 / segments as f32;
            p.push(center + r * Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()));
        }
    }
    let mut t = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let a = i * segments + j;
            let b = i * segments + (j + 1) % segments;
            let (c, d) = (a + segments, b + segments);
            t.push([a, c, b]);
            t.push([b, c, d]);
        }
    }
    (p, t)
}

#[test]
fn square_and_triangle_cover_their_projected_area() {
    let cam = front_camera(200);
    // A square of side s at depth 3 projects to a square of side f·s/3 pixels.
    let s = 1.2;
    let pos = [
        Vec3::new(-s / 2.0, -s / 2.0, 0.0),
        Vec3::new(s / 2.0, -s / 2.0, 0.0),
        Vec3::new(s / 2.0, s / 2.0, 0.0),
        Vec3::new(-s / 2.0, s / 2.0, 0.0),
    ];
    let frags = rasterize(&cam, &pos, &[[0, 1, 2], [0, 2, 3]]);
    let side = cam.fx * s / 3.0;
    let cover = frags.coverage() as f32;
    assert!(
        (cover - side * side).abs() <= 4.0 * side,
        "{cover} vs {}",
        side * side
    );
    // A triangle of half that area, drawn with the opposite winding.
    let frags = rasterize(&cam, &pos, &[[0, 2, 1]]);
    let want = 0.5 * side * side;
    let cover = frags.coverage() as f32;
    assert!(
        (cover - want).abs() <= (2.0 + 2f32.sqrt()) * side,
        "{cover} vs {want}"
    );
    assert!((cover - want).abs() > 0.0 || cover > 0.0);
}

#[test]
fn shared_edges_through_pixel_centres_are_covered_exactly_once() {
    // A 10×10 grid of cells, 4 px wide, with every vertex on a pixel centre: every interior edge
    // passes through pixel centres, so any fill-rule slip shows as double or missing coverage.
    let n = 10usize;
    let mut screen = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            screen.push(ScreenVertex {
                xy: Vec2::new(10.5 + 4.0 * i as f32, 10.5 + 4.0 * j as f32),
                depth: 1.0,
            });
        }
    }
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = (j * (n + 1) + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32 + 2);
            // Alternate the diagonal so edges of every direction occur.
            if (i + j) % 2 == 0 {
                tris.extend([[a, b, d], [a, d, c]])
            } else {
                tris.extend([[a, b, c], [b, d, c]])
            }
        }
    }
    let union = rasterize_screen(64, 64, &screen, &tris, false).coverage();
    let sum: usize = tris
        .iter()
        .map(|t| rasterize_screen(64, 64, &screen, &[*t], false).coverage())
        .sum();
    // Pixel centres from 10.5 to 50.5: the top-left rule keeps one of the two boundary lines
    // per axis, so 40 × 40 pixels.
    assert_eq!(union, 1600);
    assert_eq!(sum, 1600, "a pixel centre was claimed by two triangles");
}

#[test]
fn sphere_mask_area_matches_its_projected_disc() {
    let cam = front_camera(256);
    let (r, d) = (0.6f32, 3.0f32);
    let (p, t) = uv_sphere(Vec3::ZERO, r, 64, 128);
    let frags = rasterize(&cam, &p, &t);
    // The silhouette of a sphere centred on the optical axis is a disc of radius
    // f·tan(asin(r/d)) = f·r / sqrt(d² − r²).
    let rp = cam.fx * r / (d * d - r * r).sqrt();
    let want = std::f32::consts::PI * rp * rp;
    let cover = frags.coverage() as f32;
    // Edge pixels (the circumference) plus the polygonal sphere's inscribed shortfall.
    let tol = std::f32::consts::TAU * rp * 0.6
        + want * 2.0 * (1.0 - (std::f32::consts::PI / 128.0).cos());
    assert!((cover - want).abs() <= tol, "{cover} vs {want} ± {tol}");
    // The visible hemisphere is the near one: depth at the centre is d − r.
    let c = (128 * 256 + 128) as usize;
    assert!(
        (frags.depth[c] - (d - r)).abs() < 0.01,
        "{}",
        frags.depth[c]
    );
}

#[test]
fn barycentrics_are_perspective_correct() {
    // A plane strongly tilted in depth: screen-linear interpolation would put the interpolated
    // point off the pixel's viewing ray; perspective-correct interpolation puts it on it.
    let cam = front_camera(128);
    let pos = [
        Vec3::new(-1.0, -1.0, 1.5),
        Vec3::new(1.0, -1.0, -3.0),
        Vec3::new(0.0, 1.0, -0.5),
    ];
    let tris = [[0u32, 1, 2]];
    let frags = rasterize(&cam, &pos, &tris);
    let world = frags.interpolate(&tris, &pos);
    let mut checked = 0;
    for (i, w) in world.iter().enumerate() {
        let Some(w) = w else { continue };
        let px = Vec2::new((i % 128) as f32 + 0.5, (i / 128) as f32 + 0.5);
        let back = cam.project(*w).unwrap();
        assert!(
            (back - px).length() < 2e-3,
            "pixel {px} re-projects to {back}"
        );
        assert!((cam.to_camera(*w).z - frags.depth[i]).abs() < 1e-4);
        let b = frags.bary[i];
        assert!((b[0] + b[1] + b[2] - 1.0).abs() < 1e-5 && b.iter().all(|&x| x >= -1e-6));
        checked += 1;
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn nearer_surface_wins_in_any_order() {
    let cam = front_camera(64);
    let quad = |z: f32, s: f32| {
        [
            Vec3::new(-s, -s, z),
            Vec3::new(s, -s, z),
            Vec3::new(s, s, z),
            Vec3::new(-s, s, z),
        ]
    };
    let mut pos = quad(0.0, 0.5).to_vec();
    pos.extend(quad(0.5, 0.2));
    let far = [[0u32, 1, 2], [0, 2, 3]];
    let near = [[4u32, 5, 6], [4, 6, 7]];
    for order in [[far, near], [near, far]] {
        let tris: Vec<[u32; 3]> = order.concat();
        let frags = rasterize(&cam, &pos, &tris);
        let centre = frags.triangle[32 * 64 + 32] as usize;
        assert!(
            tris[centre][0] == 4,
            "the near quad must be visible at the centre"
        );
        let corner = frags.triangle[21 * 64 + 21] as usize;
        assert!(
            tris[corner][0] == 0,
            "the far quad shows around the near one"
        );
    }
    // Behind the camera: nothing is drawn.
    let behind: Vec<Vec3> = quad(4.0, 0.5).to_vec();
    assert_eq!(rasterize(&cam, &behind, &far).coverage(), 0);
}

#[test]
fn shadow_map_shadows_what_lies_under_an_occluder() {
    // Ground plane at y = 0 (4×4 m, all of it in front of the cameras), occluder square at y = 1 from −0.5 to 0.5, light straight down.
    let pos = vec![
        Vec3::new(-2.0, 0.0, -2.0),
        Vec3::new(2.0, 0.0, -2.0),
        Vec3::new(2.0, 0.0, 2.0),
        Vec3::new(-2.0, 0.0, 2.0),
        Vec3::new(-0.5, 1.0, -0.5),
        Vec3::new(0.5, 1.0, -0.5),
        Vec3::new(0.5, 1.0, 0.5),
        Vec3::new(-0.5, 1.0, 0.5),
    ];
    let tris = [[0u32, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]];
    let map = ShadowMap::build(Vec3::NEG_Y, &pos, &tris, 256);
    assert!(map.visibility(Vec3::new(0.0, 0.0, 0.0), Vec3::Y) == 0.0);
    assert!(map.visibility(Vec3::new(0.3, 0.0, -0.2), Vec3::Y) == 0.0);
    assert!(map.visibility(Vec3::new(1.5, 0.0, 0.0), Vec3::Y) == 1.0);
    assert!(
        map.visibility(Vec3::new(0.0, 1.0, 0.0), Vec3::Y) == 1.0,
        "the occluder is not shadowed by itself"
    );
    // Shaded through an oblique camera: ground the occluder hides from the light is darker
    // than ground beside it.
    let light = Light {
        direction: Vec3::NEG_Y,
        ..Light::default()
    };
    let normals = vec![Vec3::Y; 8];
    let cam2 = Camera::look_at(
        "side",
        96,
        96,
        0.9,
        Vec3::new(0.0, 2.0, 4.0),
        Vec3::ZERO,
        Vec3::Y,
    );
    let frags2 = rasterize(&cam2, &pos, &tris);
    let img2 = shade(
        &cam2,
        &frags2,
        &pos,
        &normals,
        None,
        &tris,
        &light,
        Some(&map),
        Vec3::ZERO,
    );
    let px = cam2.project(Vec3::new(0.0, 0.0, 0.45)).unwrap();
    let i = px.y as usize * 96 + px.x as usize;
    assert!(
        tris[frags2.triangle[i] as usize][0] == 0,
        "ground visible there"
    );
    let lit = img2[cam2
        .project(Vec3::new(1.5, 0.0, 0.45))
        .map(|p| p.y as usize * 96 + p.x as usize)
        .unwrap()];
    assert!(
        img2[i].x < 0.5 * lit.x,
        "shadowed {} vs lit {}",
        img2[i],
        lit
    );
}
