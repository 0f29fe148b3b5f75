//! The target outline of a mask at sub-pixel precision, and the exact distance to it.
//!
//! A mask sampled once per pixel places the subject's edge only to within half a pixel: the
//! centres of its inner contour pixels lie 0.5 px (on average) inside the true outline, which is
//! where the previous loss put its zero. Here the outline is the 50 % level of the mask's
//! *coverage* (the fraction of each pixel the subject covers, from an anti-aliased or
//! supersampled render; a binary mask gives 0 and 1), traced by marching squares over the grid of
//! pixel centres with linear interpolation along the cell edges. For a binary mask the crossing
//! falls half-way between an inside and an outside centre, i.e. on the pixel border — unbiased,
//! with ±0.5 px of quantisation noise; with 4 × 4 coverage the noise drops to ~1/16 px.
//!
//! Distances are exact Euclidean distances to that polyline, not samples of a distance image:
//! every pixel centre records its nearest segment (found by two raster sweeps that pass
//! candidates to neighbours, as in 8SSEDT), and a query at any image point measures the exact
//! distance to the segments recorded at the four surrounding centres. The result is continuous,
//! zero exactly on the outline, with the gradient pointing away from the nearest outline point —
//! what the silhouette loss needs to be minimised by the true outline rather than half a pixel
//! inside it.

use glam::Vec2;

/// Why an outline cannot be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OutlineError {
    /// Width or height is zero, or `width × height` overflows.
    #[error("mask is {width}×{height}")]
    BadSize {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
    /// The coverage has a different number of pixels than `width × height`.
    #[error("mask has {len} pixels, expected {expected}")]
    Length {
        /// Given.
        len: usize,
        /// Expected.
        expected: usize,
    },
    /// A coverage value is NaN or infinite.
    #[error("coverage of pixel {0} is not finite")]
    NonFinite(usize),
    /// No pixel is above (or none below) one half: there is no outline.
    #[error("the mask has no outline (empty or full)")]
    Empty,
}

/// No segment recorded at a pixel yet.
const NONE: u32 = u32::MAX;

/// The 50 % coverage outline of a mask as line segments, with each pixel centre's nearest
/// segment.
#[derive(Clone, Debug, PartialEq)]
pub struct Outline {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Segments in pixel coordinates (pixel centres at `x + 0.5`).
    pub segments: Vec<[Vec2; 2]>,
    /// Per pixel, the index of the nearest segment to its centre.
    nearest: Vec<u32>,
    /// Per segment, the segments that share its first and its second end ([`NONE`] at an open
    /// end), so a query can walk along the outline.
    links: Vec<[u32; 2]>,
    /// Per segment, its unit normal pointing out of the mask (towards lower coverage).
    outward: Vec<Vec2>,
}

/// The closest point to `p` on segment `s`, and its parameter along `s`.
#[must_use]
pub fn closest_on_segment(s: [Vec2; 2], p: Vec2) -> (Vec2, f32) {
    let d = s[1] - s[0];
    let len2 = d.length_squared();
    let t = if len2 > 0.0 {
        ((p - s[0]).dot(d) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (s[0] + d * t, t)
}

impl Outline {
    /// Traces the outline of `coverage` (row-major, values in `[0, 1]`; outside the image counts
    /// as uncovered, so the outline closes at the border) and records every pixel's nearest
    /// segment.
    pub fn from_coverage(
        width: usize,
        height: usize,
        coverage: &[f32],
    ) -> Result<Self, OutlineError> {
        let expected = width
            .checked_mul(height)
            .filter(|&n| n > 0 && width < i32::MAX as usize && height < i32::MAX as usize)
            .ok_or(OutlineError::BadSize { width, height })?;
        if coverage.len() != expected {
            return Err(OutlineError::Length {
                len: coverage.len(),
                expected,
            });
        }
        if let Some(i) = coverage.iter().position(|c| !c.is_finite()) {
            return Err(OutlineError::NonFinite(i));
        }
        let segments = march(width, height, coverage);
        if segments.is_empty() {
            return Err(OutlineError::Empty);
        }
        let links = link(&segments);
        let outward = segments
            .iter()
            .map(|&s| outward_normal(width, height, coverage, s))
            .collect();
        let mut outline = Self {
            width,
            height,
            segments,
            nearest: Vec::new(),
            links,
            outward,
        };
        outline.nearest = outline.cached_nearest_segments();
        Ok(outline)
    }

    /// A binary mask's outline (the pixel borders between inside and outside centres).
    pub fn from_mask(width: usize, height: usize, mask: &[bool]) -> Result<Self, OutlineError> {
        let coverage: Vec<f32> = mask.iter().map(|&m| if m { 1.0 } else { 0.0 }).collect();
        Self::from_coverage(width, height, &coverage)
    }

    /// The nearest-segment field built again by the plain sweep, in which every offer measures
    /// both the offered and the held segment and every neighbour is offered: the reference that
    /// the cached sweep of [`Outline::from_coverage`] is tested (equal, bit for bit) and
    /// benchmarked against.
    #[must_use]
    pub fn plain_nearest_segments(&self) -> Vec<u32> {
        self.sweep_nearest::<false>()
    }

    /// Each pixel centre's nearest segment, row-major, by the cached sweep: every segment seeds
    /// the centres around its midpoint, then raster sweeps pass candidates on. What
    /// [`Outline::from_coverage`] records; public for the bench.
    #[must_use]
    pub fn cached_nearest_segments(&self) -> Vec<u32> {
        self.sweep_nearest::<true>()
    }

    fn sweep_nearest<const CACHED: bool>(&self) -> Vec<u32> {
        let mut field = NearestField::<CACHED> {
            width: self.width,
            height: self.height,
            segments: &self.segments,
            nearest: vec![NONE; self.width * self.height],
            best: if CACHED {
                vec![f32::INFINITY; self.width * self.height]
            } else {
                Vec::new()
            },
        };
        field.seed();
        field.sweep();
        field.nearest
    }

    /// The distance from image point `p` (pixels) to the outline, and the unit vector from the
    /// nearest outline point to `p` (the distance's gradient; zero on the outline). Points off
    /// the image use the candidates of the nearest border pixels.
    #[must_use]
    pub fn distance(&self, p: Vec2) -> (f32, Vec2) {
        let (d, q, _) = self.nearest_point(p);
        (d, if d > 0.0 { (p - q) / d } else { Vec2::ZERO })
    }

    /// The signed distance from image point `p` to the outline (pixels; positive outside the
    /// mask, negative inside) and its gradient, the outward unit normal there (zero on the
    /// outline). The side is that of the nearest segment's outward normal.
    #[must_use]
    pub fn signed_distance(&self, p: Vec2) -> (f32, Vec2) {
        let (d, q, segment) = self.nearest_point(p);
        if d <= 0.0 {
            return (0.0, Vec2::ZERO);
        }
        let n = (p - q) / d;
        if n.dot(self.outward[segment as usize]) < 0.0 {
            (-d, -n)
        } else {
            (d, n)
        }
    }

    /// The unit normal of segment `segment` that points out of the mask.
    #[must_use]
    pub fn outward_normal(&self, segment: usize) -> Vec2 {
        self.outward[segment]
    }

    /// The distance from `p` to the outline, the nearest outline point and its segment.
    fn nearest_point(&self, p: Vec2) -> (f32, Vec2, u32) {
        let fx = (p.x - 0.5).floor();
        let fy = (p.y - 0.5).floor();
        let clamp = |v: f32, n: usize| (v.max(0.0) as usize).min(n - 1);
        let dist = |s: u32| {
            let q = closest_on_segment(self.segments[s as usize], p).0;
            ((p - q).length(), q)
        };
        let mut best = (f32::INFINITY, p, 0u32);
        // The segments recorded at the four surrounding centres, then a descent along the
        // outline from each: a point's nearest segment need not be any centre's (inside a bend,
        // neighbouring centres map to outline points more than a segment apart).
        for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let x = clamp(fx + dx, self.width);
            let y = clamp(fy + dy, self.height);
            let start = self.nearest[y * self.width + x];
            if start == NONE {
                continue;
            }
            let (d0, q0) = dist(start);
            if d0 < best.0 {
                best = (d0, q0, start);
            }
            for end in 0..2 {
                let (mut prev, mut cur, mut here) = (start, self.links[start as usize][end], d0);
                for _ in 0..64 {
                    if cur == NONE {
                        break;
                    }
                    let (d, q) = dist(cur);
                    if d >= here {
                        break;
                    }
                    here = d;
                    if d < best.0 {
                        best = (d, q, cur);
                    }
                    let l = self.links[cur as usize];
                    let next = if l[0] == prev { l[1] } else { l[0] };
                    (prev, cur) = (cur, next);
                }
            }
        }
        best
    }

    /// Points along the outline for the contour term: each segment's midpoint with its length
    /// as weight (so the term integrates along the outline, whatever the segments' lengths).
    #[must_use]
    pub fn contour_points(&self) -> (Vec<Vec2>, Vec<f32>) {
        let (points, weights, _) = self.contour_points_with_normals();
        (points, weights)
    }

    /// [`Outline::contour_points`] with each point's outward normal.
    #[must_use]
    pub fn contour_points_with_normals(&self) -> (Vec<Vec2>, Vec<f32>, Vec<Vec2>) {
        let mut out = (Vec::new(), Vec::new(), Vec::new());
        for (s, &n) in self.segments.iter().zip(&self.outward) {
            let length = (s[1] - s[0]).length();
            if length > 0.0 {
                out.0.push((s[0] + s[1]) * 0.5);
                out.1.push(length);
                out.2.push(n);
            }
        }
        out
    }
}

/// The nearest-segment field while it is built: each pixel centre's best segment so far and
/// its squared distance. Keeping the distance (rather than recomputing the held segment's at
/// every offer) and skipping a neighbour that holds the same segment (most of a sweep's offers:
/// whole regions share their nearest segment) leave the same comparisons on the same values,
/// so the field is the one a plain offer-everything sweep builds, bit for bit
/// (`the_cached_sweep_records_what_the_plain_one_does`), at a fraction of the work: this
/// construction was three quarters of `trainer train`'s start-up, 960 masks of 256² on the
/// built-in capture.
///
/// `CACHED = false` is that plain sweep, kept as the reference
/// ([`Outline::plain_nearest_segments`]).
struct NearestField<'a, const CACHED: bool> {
    width: usize,
    height: usize,
    segments: &'a [[Vec2; 2]],
    nearest: Vec<u32>,
    /// The squared distance from each centre to its held segment (cached sweep only).
    best: Vec<f32>,
}

impl<const CACHED: bool> NearestField<'_, CACHED> {
    fn centre(&self, i: usize) -> Vec2 {
        Vec2::new((i % self.width) as f32 + 0.5, (i / self.width) as f32 + 0.5)
    }

    fn squared_distance(&self, s: u32, c: Vec2) -> f32 {
        (closest_on_segment(self.segments[s as usize], c).0 - c).length_squared()
    }

    fn offer(&mut self, i: usize, s: u32) {
        let cur = self.nearest[i];
        if CACHED {
            if cur == s {
                return;
            }
            let d = self.squared_distance(s, self.centre(i));
            if cur == NONE || d < self.best[i] {
                self.nearest[i] = s;
                self.best[i] = d;
            }
        } else {
            let c = self.centre(i);
            if cur == NONE || self.squared_distance(s, c) < self.squared_distance(cur, c) {
                self.nearest[i] = s;
            }
        }
    }

    /// Every segment is offered to the (up to four) pixel centres at the corners of its cell.
    fn seed(&mut self) {
        for s in 0..self.segments.len() {
            let mid = (self.segments[s][0] + self.segments[s][1]) * 0.5;
            // The cell's top-left centre is at (cx + 0.5, cy + 0.5).
            let cx = (mid.x - 0.5).floor() as i64;
            let cy = (mid.y - 0.5).floor() as i64;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (cx + dx, cy + dy);
                if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
                    self.offer(y as usize * self.width + x as usize, s as u32);
                }
            }
        }
    }

    /// Two raster sweeps (down, then up), each passing every pixel's candidate to the
    /// neighbours not yet visited; run twice, which propagates around any concavity of a
    /// silhouette at this scale.
    fn sweep(&mut self) {
        let (w, h) = (self.width, self.height);
        // Offers neighbour `j`'s segment to pixel `i`; the callers keep `j` on the image.
        let pull = |o: &mut Self, i: usize, j: usize| {
            let s = o.nearest[j];
            if s != NONE {
                o.offer(i, s);
            }
        };
        for _ in 0..2 {
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    if x > 0 {
                        pull(self, i, i - 1);
                    }
                    if y > 0 {
                        if x > 0 {
                            pull(self, i, i - w - 1);
                        }
                        pull(self, i, i - w);
                        if x + 1 < w {
                            pull(self, i, i - w + 1);
                        }
                    }
                }
                for x in (0..w - 1).rev() {
                    pull(self, y * w + x, y * w + x + 1);
                }
            }
            for y in (0..h).rev() {
                for x in (0..w).rev() {
                    let i = y * w + x;
                    if x + 1 < w {
                        pull(self, i, i + 1);
                    }
                    if y + 1 < h {
                        if x + 1 < w {
                            pull(self, i, i + w + 1);
                        }
                        pull(self, i, i + w);
                        if x > 0 {
                            pull(self, i, i + w - 1);
                        }
                    }
                }
                for x in 1..w {
                    pull(self, y * w + x, y * w + x - 1);
                }
            }
        }
    }
}

/// The unit normal of segment `s` that points towards lower coverage: the coverage's bilinear
/// interpolant (outside the image 0, as [`march`] takes it) compared a tenth of a pixel to
/// either side of the segment's midpoint. A zero-length segment (the outline passing through a
/// pixel centre of exactly 50 %) takes the direction in which the interpolant falls fastest.
fn outward_normal(width: usize, height: usize, coverage: &[f32], s: [Vec2; 2]) -> Vec2 {
    let at = |x: i64, y: i64| -> f32 {
        if x < 0 || y < 0 || x >= width as i64 || y >= height as i64 {
            0.0
        } else {
            coverage[y as usize * width + x as usize]
        }
    };
    let sample = |p: Vec2| -> f32 {
        let (u, v) = (p.x - 0.5, p.y - 0.5);
        let (x0, y0) = (u.floor(), v.floor());
        let (fx, fy) = (u - x0, v - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
        let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    };
    let mid = (s[0] + s[1]) * 0.5;
    let d = s[1] - s[0];
    let length = d.length();
    if length <= 0.0 {
        let h = 0.1;
        let fall = Vec2::new(
            sample(mid - Vec2::X * h) - sample(mid + Vec2::X * h),
            sample(mid - Vec2::Y * h) - sample(mid + Vec2::Y * h),
        );
        return fall.try_normalize().unwrap_or(Vec2::X);
    }
    let n = Vec2::new(d.y, -d.x) / length;
    if sample(mid + n * 0.1) <= sample(mid - n * 0.1) {
        n
    } else {
        -n
    }
}

/// For each segment, the other segment sharing each of its ends. Marching squares computes a
/// crossing on a cell edge identically from both cells, so shared ends are bit-identical.
fn link(segments: &[[Vec2; 2]]) -> Vec<[u32; 2]> {
    let key = |p: Vec2| (p.x.to_bits(), p.y.to_bits());
    let mut ends: Vec<((u32, u32), u32, usize)> = segments
        .iter()
        .enumerate()
        .flat_map(|(i, s)| [(key(s[0]), i as u32, 0), (key(s[1]), i as u32, 1)])
        .collect();
    ends.sort_unstable();
    let mut links = vec![[NONE; 2]; segments.len()];
    for run in ends.chunk_by(|a, b| a.0 == b.0) {
        if let [(_, a, ea), (_, b, eb)] = run {
            links[*a as usize][*ea] = *b;
            links[*b as usize][*eb] = *a;
        }
    }
    links
}

/// Marching squares over the grid of pixel centres at level ½, with a ring of uncovered samples
/// around the image.
fn march(width: usize, height: usize, coverage: &[f32]) -> Vec<[Vec2; 2]> {
    let f = |x: i64, y: i64| -> f32 {
        if x < 0 || y < 0 || x >= width as i64 || y >= height as i64 {
            -0.5
        } else {
            coverage[y as usize * width + x as usize] - 0.5
        }
    };
    let mut segments = Vec::new();
    for cy in -1..height as i64 {
        for cx in -1..width as i64 {
            // Corners a (top-left), b (top-right), c (bottom-right), d (bottom-left).
            let corners = [(cx, cy), (cx + 1, cy), (cx + 1, cy + 1), (cx, cy + 1)];
            let v = corners.map(|(x, y)| f(x, y));
            let inside = v.map(|x| x > 0.0);
            if inside.iter().all(|&i| i) || inside.iter().all(|&i| !i) {
                continue;
            }
            let pos = |k: usize| {
                let (x, y) = corners[k];
                Vec2::new(x as f32 + 0.5, y as f32 + 0.5)
            };
            // Crossing on edge k (between corners k and k + 1): top, right, bottom, left.
            let cross = |k: usize| -> Option<Vec2> {
                let (i, j) = (k, (k + 1) % 4);
                if inside[i] == inside[j] {
                    return None;
                }
                // Interpolate from the corner that comes first in (y, x) order, so the cell on
                // the other side of this edge computes the bit-identical point (`link` relies
                // on it).
                let (i, j) = if (corners[i].1, corners[i].0) < (corners[j].1, corners[j].0) {
                    (i, j)
                } else {
                    (j, i)
                };
                let t = v[i] / (v[i] - v[j]);
                Some(pos(i) + (pos(j) - pos(i)) * t)
            };
            let e: Vec<(usize, Vec2)> = (0..4).filter_map(|k| cross(k).map(|p| (k, p))).collect();
            match e.len() {
                2 => segments.push([e[0].1, e[1].1]),
                4 => {
                    // Saddle: the cell centre's average decides which diagonal is connected.
                    let centre_inside = v.iter().sum::<f32>() > 0.0;
                    let p = |k: usize| e[k].1;
                    // Pair each edge with a neighbouring one: (top, right) + (bottom, left) cuts
                    // off corners b and d; (left, top) + (right, bottom) cuts off a and c.
                    let cut_b_and_d = centre_inside == inside[0];
                    if cut_b_and_d {
                        segments.push([p(0), p(1)]);
                        segments.push([p(2), p(3)]);
                    } else {
                        segments.push([p(3), p(0)]);
                        segments.push([p(1), p(2)]);
                    }
                }
                _ => {}
            }
        }
    }
    segments
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Coverage of a disc by `n × n` sub-samples per pixel.
    fn disc(w: usize, h: usize, centre: Vec2, r: f32, n: usize) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let mut k = 0;
                for a in 0..n {
                    for b in 0..n {
                        let p = Vec2::new(
                            x + (a as f32 + 0.5) / n as f32,
                            y + (b as f32 + 0.5) / n as f32,
                        );
                        k += usize::from((p - centre).length() < r);
                    }
                }
                k as f32 / (n * n) as f32
            })
            .collect()
    }

    fn brute(o: &Outline, p: Vec2) -> f32 {
        o.segments
            .iter()
            .map(|&s| (closest_on_segment(s, p).0 - p).length())
            .fold(f32::INFINITY, f32::min)
    }

    #[test]
    fn a_binary_square_traces_its_pixel_borders() {
        // Pixels 3..7 × 2..6 inside: the outline is the rectangle x ∈ [3, 7], y ∈ [2, 6]
        // (pixel borders), cut at the corners by the marching-squares diagonals.
        let (w, h) = (10, 9);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| (3..7).contains(&(i % w)) && (2..6).contains(&(i / w)))
            .collect();
        let o = Outline::from_mask(w, h, &mask).unwrap();
        for s in &o.segments {
            for p in s {
                let on_x = (p.x - 3.0).abs() < 1e-6 || (p.x - 7.0).abs() < 1e-6;
                let on_y = (p.y - 2.0).abs() < 1e-6 || (p.y - 6.0).abs() < 1e-6;
                assert!(on_x || on_y, "{p} is not on the pixel border");
            }
        }
        // Mid-edge points are at distance 0; a pixel centre next to the edge at 0.5.
        assert!(o.distance(Vec2::new(3.0, 4.0)).0 < 1e-6);
        let (d, g) = o.distance(Vec2::new(2.5, 4.0));
        assert!((d - 0.5).abs() < 1e-6 && (g - Vec2::new(-1.0, 0.0)).length() < 1e-6);
        let (d, g) = o.distance(Vec2::new(5.0, 4.5));
        assert!(
            (d - 1.5).abs() < 1e-6 && (g - Vec2::new(0.0, -1.0)).length() < 1e-6,
            "{d} {g}"
        );
    }

    #[test]
    fn a_supersampled_disc_is_traced_to_a_small_fraction_of_a_pixel() {
        let centre = Vec2::new(31.3, 28.6);
        let r = 17.4;
        let cov = disc(64, 60, centre, r, 8);
        let o = Outline::from_coverage(64, 60, &cov).unwrap();
        let mut worst: f32 = 0.0;
        let mut sum = 0.0;
        for s in &o.segments {
            for p in s {
                let e = (p - centre).length() - r;
                worst = worst.max(e.abs());
                sum += e;
            }
        }
        let mean = sum / (2 * o.segments.len()) as f32;
        // Linear interpolation of coverage between centres is off by up to ~0.13 px where an
        // edge crosses a pixel obliquely, but the errors average out: no bias.
        assert!(worst < 0.15, "worst radial error {worst} px");
        assert!(mean.abs() < 0.01, "mean radial error {mean} px (bias)");
        // The binary mask of the same disc: unbiased on average, noisier.
        let bin: Vec<bool> = disc(64, 60, centre, r, 1)
            .iter()
            .map(|&c| c > 0.5)
            .collect();
        let ob = Outline::from_mask(64, 60, &bin).unwrap();
        let errs: Vec<f32> = ob
            .segments
            .iter()
            .flatten()
            .map(|p| (*p - centre).length() - r)
            .collect();
        let mean_b = errs.iter().sum::<f32>() / errs.len() as f32;
        assert!(mean_b.abs() < 0.15, "binary mean radial error {mean_b} px");
        assert!(errs.iter().all(|e| e.abs() < 0.75));
    }

    #[test]
    fn signed_distances_are_negative_inside_a_ring_and_positive_outside() {
        // A ring: a disc with a hole, so the inner outline's outward normals point at the
        // centre and the outer one's away from it.
        let centre = Vec2::new(30.3, 27.8);
        let outer = disc(64, 60, centre, 22.0, 4);
        let inner = disc(64, 60, centre, 9.0, 4);
        let cov: Vec<f32> = outer.iter().zip(&inner).map(|(a, b)| a - b).collect();
        let o = Outline::from_coverage(64, 60, &cov).unwrap();
        for (k, s) in o.segments.iter().enumerate() {
            let mid = (s[0] + s[1]) * 0.5;
            let away = (mid - centre).normalize();
            let n = o.outward_normal(k);
            let on_outer = (mid - centre).length() > 15.0;
            let expected = if on_outer { away } else { -away };
            assert!(n.dot(expected) > 0.8, "segment {k} at {mid}: {n}");
        }
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..2000 {
            let p = Vec2::new(rng.random_range(2.0..62.0), rng.random_range(2.0..58.0));
            let r = (p - centre).length();
            let (s, g) = o.signed_distance(p);
            let (d, n) = o.distance(p);
            assert!((s.abs() - d).abs() < 1e-6, "{p}: {s} vs {d}");
            // Away from the outlines (0.3 px: the 4 × 4 coverage's noise) the sign is the
            // side; the gradient is the unsigned one turned outwards.
            if (r - 22.0).abs() > 0.3 && (r - 9.0).abs() > 0.3 {
                let inside = r < 22.0 && r > 9.0;
                assert_eq!(s < 0.0, inside, "{p} (radius {r}): {s}");
            }
            assert!(g == n || g == -n, "{p}: {g} vs {n}");
            if s != 0.0 {
                assert!((g * s.signum()).dot(n) > 0.99);
            }
        }
    }

    #[test]
    fn the_cached_sweep_records_what_the_plain_one_does() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut masks = vec![
            (48, 40, disc(48, 40, Vec2::new(20.2, 19.7), 11.3, 4)),
            (33, 57, disc(33, 57, Vec2::new(3.0, 50.0), 20.0, 1)),
        ];
        // Random blobs: many components, holes and concavities.
        let noise: Vec<f32> = (0..64 * 48)
            .map(|_| {
                if rng.random_bool(0.45) {
                    1.0
                } else {
                    rng.random_range(0.0..1.0)
                }
            })
            .collect();
        masks.push((64, 48, noise));
        for (w, h, cov) in masks {
            let o = Outline::from_coverage(w, h, &cov).unwrap();
            assert!(o.nearest.iter().all(|&s| s != NONE));
            assert_eq!(o.nearest, o.plain_nearest_segments(), "{w}×{h}");
        }
    }

    #[test]
    fn distances_equal_brute_force_near_and_far() {
        let cov = disc(48, 40, Vec2::new(20.2, 19.7), 11.3, 4);
        let mut cov2 = cov.clone();
        // A second blob and a thin gap make the outline non-convex with several components.
        for (i, c) in disc(48, 40, Vec2::new(38.0, 10.0), 5.0, 4)
            .iter()
            .enumerate()
        {
            cov2[i] = cov2[i].max(*c);
        }
        let o = Outline::from_coverage(48, 40, &cov2).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut close, mut compared) = (0usize, 0usize);
        for _ in 0..3000 {
            let p = Vec2::new(rng.random_range(-5.0..53.0), rng.random_range(-5.0..45.0));
            let want = brute(&o, p);
            let (got, g) = o.distance(p);
            let inside = p.x > 0.0 && p.y > 0.0 && p.x < 48.0 && p.y < 40.0;
            if inside && want < 3.0 {
                assert!((got - want).abs() < 1e-4, "{p}: {got} vs {want}");
            } else {
                // Far from the outline the walk may stop at a near-nearest segment, and off the
                // image only the border pixels' records are seen: an upper bound, by little.
                let tol = if inside { 0.05 } else { 0.15 };
                assert!(
                    got >= want - 1e-4 && got - want < tol * want.max(1.0),
                    "{p}: {got} vs {want}"
                );
            }
            if got > 1e-3 {
                // The gradient is the unit direction away from the nearest point.
                let h = 1e-2;
                let fd = Vec2::new(
                    o.distance(p + Vec2::X * h).0 - o.distance(p - Vec2::X * h).0,
                    o.distance(p + Vec2::Y * h).0 - o.distance(p - Vec2::Y * h).0,
                ) / (2.0 * h);
                assert!((g.length() - 1.0).abs() < 1e-4);
                // The polyline's corners put kinks into the distance along their bisectors,
                // which a difference step may straddle: almost every point agrees closely, none
                // far off.
                if got > 0.05 && inside && want < 1.0 {
                    let e = (fd - g).length();
                    assert!(e < 0.5, "{p}: fd {fd} vs {g}");
                    close += usize::from(e < 0.05);
                    compared += 1;
                }
            }
        }
        assert!(
            compared > 100 && close * 100 >= compared * 95,
            "{close} of {compared}"
        );
    }

    #[test]
    fn the_outline_closes_at_the_border_and_bad_input_is_refused() {
        // Everything covered but one pixel: the outline runs along the image border too.
        let mut cov = vec![1.0; 16];
        cov[5] = 0.0;
        let o = Outline::from_coverage(4, 4, &cov).unwrap();
        assert!(
            o.distance(Vec2::new(0.0, 2.0)).0 < 1e-6,
            "border is outline"
        );
        // The hole's outline is the diamond through the mid-points to its covered neighbours.
        assert!((o.distance(Vec2::new(1.5, 1.5)).0 - 0.5 / 2f32.sqrt()).abs() < 1e-5);
        assert_eq!(
            Outline::from_coverage(4, 4, &[0.0; 16]),
            Err(OutlineError::Empty)
        );
        assert_eq!(
            Outline::from_coverage(0, 4, &[]),
            Err(OutlineError::BadSize {
                width: 0,
                height: 4
            })
        );
        assert_eq!(
            Outline::from_coverage(2, 2, &[0.0; 3]),
            Err(OutlineError::Length {
                len: 3,
                expected: 4
            })
        );
        assert_eq!(
            Outline::from_coverage(2, 2, &[0.0, f32::NAN, 1.0, 0.0]),
            Err(OutlineError::NonFinite(1))
        );
        // A full mask has an outline: the image border.
        assert!(Outline::from_coverage(2, 2, &[1.0; 4]).is_ok());
        let (pts, w) = o.contour_points();
        assert_eq!(pts.len(), w.len());
        assert!(w.iter().all(|&l| l > 0.0));
    }
}
