//! Bidirectional silhouette loss (paper supplementary E, Eq. 10; DeepCap Eq. 11):
//!
//! `L_silh = Σ_c ( Σ_{i∈B_c} ‖d_c(π_c(x_i))‖ + Σ_{p: d_c(p)=0} ‖π_c(x_p) − p‖ )`
//!
//! `d_c` is the distance transform of the mask contour (exact, [`DistanceImage`]), sampled
//! bilinearly so the first term is differentiable w.r.t. the projected position. `B_c`, the
//! boundary vertices, are the vertices whose projection lies on the contour of the *rendered*
//! silhouette of the posed mesh: triangles are rasterised into a coverage mask (no depth needed
//! for coverage), its contour's distance transform is sampled at each projected vertex, and those
//! within [`BOUNDARY_RADIUS`] pixels are boundary vertices. This excludes contour-generator
//! vertices hidden inside the silhouette (a hand in front of the torso). In the second term `x_p`
//! is the projected *boundary* vertex (of `B_c`) nearest to contour pixel `p`, found exactly with
//! a uniform grid. The paper says "its closest projected vertex"; taken over every vertex in
//! front of the camera, that is often an interior vertex projecting just inside the contour,
//! which the term then drags outwards: at the ground-truth poses of the built-in capture the
//! contour term's mean gradient along the outward normal was −3.8e-3 over all vertices and
//! −2.0e-4 over `B_c` (an unbiased loss has 0 there; `trainer/examples/silhouette_bias.rs`
//! measures it). Both selections are constants of the step; the norms are Euclidean, not
//! squared, as in Eq. 10.

use std::sync::Arc;

use candle_core::{CpuStorage, CustomOp1, Layout, Result, Shape, Tensor, bail};

use crate::distance_transform::{DistanceError, DistanceImage, mask_contour, site_centres};

/// Pixels from the rendered contour within which a projected vertex counts as a boundary vertex.
/// (1.5: a vertex on a concave corner of the rendered silhouette samples the bilinear distance
/// between outside pixel centres, up to √2 px, although it lies on the boundary.)
pub const BOUNDARY_RADIUS: f32 = 1.5;

/// What one camera view contributes: the distance transform of the mask contour and the contour
/// pixel centres.
#[derive(Clone, Debug)]
pub struct SilhouetteTarget {
    /// Distance to the mask contour.
    pub dt: Arc<DistanceImage>,
    /// Centres of the contour pixels.
    pub contour: Vec<[f32; 2]>,
}

impl SilhouetteTarget {
    /// Builds the target from a binary foreground mask (row-major, `width × height`).
    pub fn from_mask(
        width: usize,
        height: usize,
        mask: &[bool],
    ) -> std::result::Result<Self, DistanceError> {
        let sites = mask_contour(width, height, mask)?;
        let dt = DistanceImage::from_sites(width, height, &sites)?;
        Ok(Self {
            dt: Arc::new(dt),
            contour: site_centres(width, &sites),
        })
    }
}

/// Bilinear sample of a distance image at `[N, 2]` image points → `[N]`, with backward.
#[derive(Clone, Debug)]
struct DtSample(Arc<DistanceImage>);

/// `∇d` at `[N, 2]` image points → `[N, 2]` (no backward: the sample is piecewise bilinear and
/// the loss never needs second derivatives).
#[derive(Clone, Debug)]
struct DtGrad(Arc<DistanceImage>);

/// Applies `f` to each `[u, v]` row of a contiguous `[N, 2]` f32/f64 tensor and keeps the first
/// `out_width` outputs (`[N]` when 1, else `[N, out_width]`).
fn map_points(
    storage: &CpuStorage,
    layout: &Layout,
    op: &str,
    f: impl Fn(f64, f64) -> [f64; 2],
    out_width: usize,
) -> Result<(CpuStorage, Shape)> {
    let dims = layout.shape().dims();
    if dims.len() != 2 || dims[1] != 2 {
        bail!("{op}: expected [N, 2] points, got {dims:?}");
    }
    let Some((a, b)) = layout.contiguous_offsets() else {
        bail!("{op} needs a contiguous input")
    };
    let n = dims[0];
    let shape: Shape = if out_width == 1 {
        n.into()
    } else {
        (n, out_width).into()
    };
    let out = match storage {
        CpuStorage::F32(d) => CpuStorage::F32(
            d[a..b]
                .chunks(2)
                .flat_map(|p| {
                    f(f64::from(p[0]), f64::from(p[1]))
                        .into_iter()
                        .take(out_width)
                        .map(|x| x as f32)
                })
                .collect(),
        ),
        CpuStorage::F64(d) => CpuStorage::F64(
            d[a..b]
                .chunks(2)
                .flat_map(|p| f(p[0], p[1]).into_iter().take(out_width))
                .collect(),
        ),
        _ => bail!("{op}: only f32 and f64 are supported"),
    };
    Ok((out, shape))
}

impl CustomOp1 for DtSample {
    fn name(&self) -> &'static str {
        "dt-sample"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        map_points(
            storage,
            layout,
            "dt-sample",
            |u, v| [self.0.sample64(u, v).0, 0.0],
            1,
        )
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let g = arg
            .contiguous()?
            .apply_op1_no_bwd(&DtGrad(self.0.clone()))?;
        Ok(Some(g.broadcast_mul(&grad_res.unsqueeze(1)?)?))
    }
}

impl CustomOp1 for DtGrad {
    fn name(&self) -> &'static str {
        "dt-grad"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        map_points(
            storage,
            layout,
            "dt-grad",
            |u, v| self.0.sample64(u, v).1,
            2,
        )
    }
}

/// `d(uv)` for image points `[N, 2]` → `[N]`, differentiable w.r.t. `uv`.
pub fn sample_distance(dt: &Arc<DistanceImage>, uv: &Tensor) -> Result<Tensor> {
    uv.contiguous()?.apply_op1(DtSample(dt.clone()))
}

/// Coverage mask of the triangles whose three vertices are `valid`, projected to `uv` (pixel
/// centres at +0.5; a pixel is covered when its centre is inside or on a triangle edge).
#[must_use]
pub fn coverage_mask(
    width: usize,
    height: usize,
    uv: &[[f32; 2]],
    valid: &[bool],
    triangles: &[[u32; 3]],
) -> Vec<bool> {
    let mut mask = vec![false; width * height];
    for t in triangles {
        let idx = t.map(|i| i as usize);
        if idx
            .iter()
            .any(|&i| i >= uv.len() || !valid.get(i).copied().unwrap_or(false))
        {
            continue;
        }
        let [a, b, c] = idx.map(|i| uv[i]);
        let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if area.abs() < 1e-12 || !area.is_finite() {
            continue;
        }
        let lo = |k: usize| a[k].min(b[k]).min(c[k]);
        let hi = |k: usize| a[k].max(b[k]).max(c[k]);
        let x0 = (lo(0) - 0.5).ceil().max(0.0) as usize;
        let y0 = (lo(1) - 0.5).ceil().max(0.0) as usize;
        let x1 = ((hi(0) - 0.5).floor().min(width as f32 - 1.0)).max(-1.0);
        let y1 = ((hi(1) - 0.5).floor().min(height as f32 - 1.0)).max(-1.0);
        if x1 < 0.0 || y1 < 0.0 {
            continue;
        }
        let edge = |p: [f32; 2], q: [f32; 2], x: f32, y: f32| {
            ((q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0])) * area.signum()
        };
        for y in y0..=y1 as usize {
            for x in x0..=x1 as usize {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                if edge(a, b, px, py) >= 0.0
                    && edge(b, c, px, py) >= 0.0
                    && edge(c, a, px, py) >= 0.0
                {
                    mask[y * width + x] = true;
                }
            }
        }
    }
    mask
}

/// Indices of the boundary vertices `B_c` (see the module docs).
#[must_use]
pub fn boundary_vertices(
    width: usize,
    height: usize,
    uv: &[[f32; 2]],
    valid: &[bool],
    triangles: &[[u32; 3]],
) -> Vec<u32> {
    let cover = coverage_mask(width, height, uv, valid, triangles);
    let Ok(rendered) = DistanceImage::of_mask_contour(width, height, &cover) else {
        return Vec::new();
    };
    (0..uv.len())
        .filter(|&i| {
            let [u, v] = uv[i];
            valid[i]
                && (0.0..width as f32).contains(&u)
                && (0.0..height as f32).contains(&v)
                && rendered.sample(u, v).0 <= BOUNDARY_RADIUS
        })
        .map(|i| i as u32)
        .collect()
}

/// Exact nearest-point queries over 2D points with a uniform grid.
struct Grid {
    cell: f32,
    origin: [f32; 2],
    dims: [i64; 2],
    start: Vec<usize>,
    items: Vec<u32>,
}

impl Grid {
    fn new(points: &[[f32; 2]], ids: &[u32]) -> Self {
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for &i in ids {
            for k in 0..2 {
                lo[k] = lo[k].min(points[i as usize][k]);
                hi[k] = hi[k].max(points[i as usize][k]);
            }
        }
        // About two points per cell.
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-3);
        let side = ((ids.len() as f32 / 2.0).sqrt().ceil()).clamp(1.0, 1024.0);
        let cell = extent / side + 1e-6;
        let dims = [
            ((hi[0] - lo[0]) / cell) as i64 + 1,
            ((hi[1] - lo[1]) / cell) as i64 + 1,
        ];
        let cell_of = |p: [f32; 2]| {
            (((p[1] - lo[1]) / cell) as i64 * dims[0] + ((p[0] - lo[0]) / cell) as i64) as usize
        };
        let ncell = (dims[0] * dims[1]) as usize;
        let mut start = vec![0usize; ncell + 1];
        for &i in ids {
            start[cell_of(points[i as usize]) + 1] += 1;
        }
        for c in 0..ncell {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; ids.len()];
        for &i in ids {
            let c = cell_of(points[i as usize]);
            items[fill[c]] = i;
            fill[c] += 1;
        }
        Self {
            cell,
            origin: lo,
            dims,
            start,
            items,
        }
    }

    fn nearest(&self, points: &[[f32; 2]], q: [f32; 2]) -> Option<u32> {
        let cx = ((q[0] - self.origin[0]) / self.cell).floor() as i64;
        let cy = ((q[1] - self.origin[1]) / self.cell).floor() as i64;
        let max_ring = [cx, self.dims[0] - 1 - cx, cy, self.dims[1] - 1 - cy]
            .iter()
            .map(|d| d.abs())
            .max()?;
        let mut best: Option<(f32, u32)> = None;
        for r in 0..=max_ring {
            for y in cy - r..=cy + r {
                for x in cx - r..=cx + r {
                    let on_ring = (y - cy).abs() == r || (x - cx).abs() == r;
                    if !on_ring || x < 0 || y < 0 || x >= self.dims[0] || y >= self.dims[1] {
                        continue;
                    }
                    let c = (y * self.dims[0] + x) as usize;
                    for &i in &self.items[self.start[c]..self.start[c + 1]] {
                        let p = points[i as usize];
                        let d = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
                        if best.is_none_or(|(bd, bi)| d < bd || (d == bd && i < bi)) {
                            best = Some((d, i));
                        }
                    }
                }
            }
            // Every cell of ring r + 1 is at least r cells away from q in x or y.
            if let Some((bd, _)) = best
                && bd.sqrt() <= r as f32 * self.cell
            {
                break;
            }
        }
        best.map(|b| b.1)
    }
}

/// For each query point, the index of the nearest of `points[candidates]` (ties: lowest index);
/// empty when there are no candidates.
#[must_use]
pub fn nearest_points(points: &[[f32; 2]], candidates: &[u32], queries: &[[f32; 2]]) -> Vec<u32> {
    if candidates.is_empty() {
        return Vec::new();
    }
    let grid = Grid::new(points, candidates);
    queries
        .iter()
        .filter_map(|&q| grid.nearest(points, q))
        .collect()
}

/// The two terms of Eq. 10 for one camera and frame, and how many elements each sums.
#[derive(Debug)]
pub struct SilhouetteTerms {
    /// `Σ_{i∈B} d(π(x_i))`.
    pub boundary: Tensor,
    /// `Σ_p ‖π(x_p) − p‖`.
    pub contour: Tensor,
    /// `|B|`.
    pub boundary_count: usize,
    /// Number of contour pixels.
    pub contour_count: usize,
}

/// Eq. 10 for one view: `uv` `[V, 2]` are the projected posed vertices (differentiable),
/// `valid[i]` says whether vertex `i` is in front of the camera; `triangles` the template's.
pub fn silhouette_terms(
    target: &SilhouetteTarget,
    uv: &Tensor,
    valid: &[bool],
    triangles: &[[u32; 3]],
) -> Result<SilhouetteTerms> {
    let (v, two) = uv.dims2()?;
    if two != 2 || valid.len() != v {
        bail!(
            "silhouette: uv is {:?} for {} validity flags",
            uv.dims(),
            valid.len()
        );
    }
    let values: Vec<[f32; 2]> = uv
        .to_dtype(candle_core::DType::F32)?
        .to_vec2::<f32>()?
        .into_iter()
        .map(|r| [r[0], r[1]])
        .collect();
    let (w, h) = (target.dt.width, target.dt.height);
    let dev = uv.device();
    let zero = Tensor::zeros((), uv.dtype(), dev)?;
    let b = boundary_vertices(w, h, &values, valid, triangles);
    let boundary = if b.is_empty() {
        zero.clone()
    } else {
        let sel = uv.index_select(&Tensor::from_vec(b.clone(), b.len(), dev)?, 0)?;
        sample_distance(&target.dt, &sel)?.sum_all()?
    };
    let nearest = nearest_points(&values, &b, &target.contour);
    let contour = if nearest.is_empty() {
        zero
    } else {
        let n = nearest.len();
        let sel = uv.index_select(&Tensor::from_vec(nearest, n, dev)?, 0)?;
        let p: Vec<f32> = target.contour.iter().flatten().copied().collect();
        let p = Tensor::from_vec(p, (n, 2), dev)?.to_dtype(uv.dtype())?;
        // ε inside the root keeps the gradient finite when a vertex sits exactly on its pixel.
        ((sel - p)?.sqr()?.sum(1)? + 1e-12)?.sqrt()?.sum_all()?
    };
    Ok(SilhouetteTerms {
        boundary,
        contour,
        boundary_count: b.len(),
        contour_count: target.contour.len(),
    })
}

#[cfg(test)]
mod tests;
