//! Initial skinning weights by bone heat (Pinocchio: Baran & Popović 2007), robust on real
//! meshes.
//!
//! For every joint `j`, solve `(−Δ + H) w_j = H p_j` on the template in its bind pose:
//! - `Δ` is the cotangent Laplace–Beltrami operator normalised by mixed Voronoi areas,
//!   `Δ = −M⁻¹K` (the exact discretisation is documented in module `laplacian`); the system
//!   is solved in the equivalent symmetric form `(K + MH) w_j = MH p_j`;
//! - `H_ii = c / d_i²` with `d_i` the distance from vertex `i` to its nearest *visible* bone
//!   segment (module `attach`), `p_ij` the share of joint `j` among the visible segments tied
//!   within a relative `tie_tolerance` of that distance (0 elsewhere);
//! - one sparse Cholesky factorisation (faer, sequential), one solve per joint; the solutions are
//!   clamped to `[0, 1]`, normalised per vertex, weights below `min_weight` dropped, and
//!   normalised again.
//!
//! Which joint owns which segment: module `bones` (glTF/BVH convention; leaves continue their
//! parent's direction).
//!
//! Robustness, so that real assets never fail:
//! - vertices are welded by position (tolerance `weld_tolerance` × bounding-box diagonal) for the
//!   solve and the weights copied back to every file vertex;
//! - collapsed and duplicate triangles are dropped, degenerate (near zero-area) triangles give no
//!   stiffness and no area, interior faces are just more triangles (and more occluders);
//! - each connected component is solved with the heat of the bones visible from it; a component
//!   where no vertex sees any bone, or none sees a bone within `far_visible_ratio` (1.5) times
//!   its distance to the nearest bone, is solved with visibility ignored (heat from the nearest
//!   segments by distance) and counted as a fallback. The second case is a shell in front of
//!   the body whose normals face away from its own bone: the zoo robot's face plate saw only the
//!   IK pole targets, about twice as far as its head's bone, and followed them;
//! - a vertex in no usable triangle, or whose solved weights are all zero, takes its nearest
//!   segment(s) by distance;
//! - a small separate piece (a component under `small_piece_fraction` of the mesh's size:
//!   eyebrows, bolts, buttons) takes the solved weights of the nearest vertex of a larger
//!   component, the surface it sits on (module `pieces`);
//! - should the factorisation still fail (it cannot for the SPD system above, barring floating
//!   point), it is retried with negative cotangent weights clamped to zero, which makes the
//!   matrix diagonally dominant, and that is reported in the stats.
//!
//! Scale invariance: cotangents and `M H = area / d²` are invariant under a uniform scale of mesh
//! and skeleton together, and all tolerances are relative, so the weights are too.

mod attach;
pub(crate) mod bones;
mod laplacian;
mod pieces;
mod solve;
pub(crate) mod weld;

use std::time::Instant;

use faer::Mat;
use glam::{DVec3, Vec3};
use skinfield_formats::{MeshError, Skeleton, SkinError, StaticSkin, Template};

use attach::AttachParams;

/// Settings of [`bone_heat`].
#[derive(Clone, Debug)]
pub struct HeatOptions {
    /// The heat constant `c` in `H_ii = c / d_i²` (1 in Pinocchio).
    pub heat_constant: f64,
    /// Segments within this relative distance of the nearest visible one share the heat.
    pub tie_tolerance: f64,
    /// Cosine of the half-angle of the normal cone a bone must lie in (0.5: Pinocchio's 60°).
    pub cone_cos: f64,
    /// Weights below this (after the first normalisation) are dropped.
    pub min_weight: f32,
    /// Welding tolerance relative to the bounding-box diagonal.
    pub weld_tolerance: f64,
    /// Length of a leaf's segment as a fraction of its parent segment's length.
    pub leaf_fraction: f64,
    /// Explicit bind-pose tail of every joint (world space, joint order), e.g. from MakeHuman or
    /// Blender bones: each joint then owns exactly the segment head → tail.
    pub bone_tails: Option<Vec<Vec3>>,
    /// A component solved with visibility must have a vertex whose nearest visible bone is at
    /// most this many times further than its nearest bone; otherwise it is solved by distance
    /// alone, like a component that sees no bone (see the module docs).
    pub far_visible_ratio: f64,
    /// Components whose bounding-box diagonal is below this fraction of the mesh's take the
    /// weights of the nearest vertex of a larger component (0: off). 0.02 keeps the zoo robot's
    /// limbs (5 % of its size and more) and every skirt and cape apart, and moves its 1–2 %
    /// head details onto the head, where its asset has them.
    pub small_piece_fraction: f64,
}

impl Default for HeatOptions {
    fn default() -> Self {
        Self {
            heat_constant: 1.0,
            tie_tolerance: 1e-4,
            cone_cos: 0.5,
            min_weight: 1e-3,
            weld_tolerance: 1e-6,
            leaf_fraction: 0.5,
            bone_tails: None,
            small_piece_fraction: 0.02,
            far_visible_ratio: 1.5,
        }
    }
}

/// What happened during a [`bone_heat`] run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HeatStats {
    /// Vertices in the template.
    pub vertices: usize,
    /// Vertices after welding.
    pub welded_vertices: usize,
    /// Triangles dropped because welding collapsed them.
    pub collapsed_triangles: usize,
    /// Triangles dropped as duplicates of another.
    pub duplicate_triangles: usize,
    /// Degenerate (near zero-area) triangles that got no stiffness.
    pub degenerate_triangles: usize,
    /// Bone segments.
    pub segments: usize,
    /// Connected components (of usable triangles).
    pub components: usize,
    /// Components that saw no bone, or only bones further than `far_visible_ratio` times their
    /// nearest one, and were solved with visibility ignored.
    pub fallback_components: usize,
    /// Welded vertices given their nearest segment(s) directly (no usable triangle, or all
    /// solved weights zero).
    pub fallback_vertices: usize,
    /// Welded vertices of small pieces that took the weights of a larger component.
    pub inherited_vertices: usize,
    /// Welded vertices in solved components that saw no bone (`H_ii = 0`: heat only by diffusion).
    pub unattached_vertices: usize,
    /// Largest `|Σ_j w_ij − 1|` over solved vertices before clamping: the raw heat weights are a
    /// partition of unity (`Σ_j p_ij` is 1 or 0 with `H_ii` 0), so this measures the solve's
    /// round-off.
    pub raw_sum_deviation: f64,
    /// Smallest raw weight before clamping (negative cotangents can undershoot zero).
    pub raw_min: f64,
    /// Whether the factorisation needed negative cotangents clamped to zero.
    pub clamped_negative_cotangents: bool,
    /// Seconds spent welding, building the Laplacian and the BVH.
    pub setup_s: f64,
    /// Seconds spent on visibility (nearest visible segments).
    pub attach_s: f64,
    /// Seconds spent on the Cholesky factorisation.
    pub factor_s: f64,
    /// Seconds spent on the solves (all joints).
    pub solve_s: f64,
    /// Seconds for the whole call.
    pub total_s: f64,
}

/// The weights and how they were obtained.
#[derive(Clone, Debug)]
pub struct HeatResult {
    /// Normalised weights, one row per template vertex (file order).
    pub skin: StaticSkin,
    /// Run statistics.
    pub stats: HeatStats,
}

/// Why bone heat could not run (bad input; a valid mesh and skeleton always get weights).
#[derive(Debug, thiserror::Error)]
pub enum HeatError {
    /// The template is invalid.
    #[error("template: {0}")]
    Mesh(#[from] MeshError),
    /// A joint's inverse bind matrix is singular or not finite.
    #[error("joint {0}: inverse bind matrix is not invertible")]
    SingularBind(usize),
    /// `bone_tails` does not have one finite entry per joint.
    #[error("bone_tails: {len} entries for {joints} joints, or a non-finite tail")]
    BadTails {
        /// Entries given.
        len: usize,
        /// Joint count.
        joints: usize,
    },
    /// An option is out of range.
    #[error("option `{0}` is out of range")]
    BadOption(&'static str),
    /// The weights could not be assembled (a bug: reported, not panicked).
    #[error("assembling the skin: {0}")]
    Skin(#[from] SkinError),
    /// The sparse factorisation failed even after clamping (a bug: reported, not panicked).
    #[error("sparse Cholesky factorisation failed: {0}")]
    Factorization(String),
}

/// Computes bone-heat skinning weights for `template` bound to `skeleton` (see the module docs).
pub fn bone_heat(
    template: &Template,
    skeleton: &Skeleton,
    options: &HeatOptions,
) -> Result<HeatResult, HeatError> {
    let start = Instant::now();
    template.validate()?;
    check_options(options)?;
    let mut stats = HeatStats {
        vertices: template.vertex_count(),
        ..Default::default()
    };

    let heads = bones::joint_heads(skeleton).map_err(HeatError::SingularBind)?;
    let tails: Option<Vec<DVec3>> = match &options.bone_tails {
        None => None,
        Some(t) if t.len() == skeleton.len() && t.iter().all(|v| v.is_finite()) => {
            Some(t.iter().map(|v| v.as_dvec3()).collect())
        }
        Some(t) => {
            return Err(HeatError::BadTails {
                len: t.len(),
                joints: skeleton.len(),
            });
        }
    };
    let segments = bones::bone_segments(skeleton, &heads, tails.as_deref(), options.leaf_fraction);
    stats.segments = segments.len();

    let bounds = template.bounds().ok_or(MeshError::Empty {
        vertices: 0,
        triangles: 0,
    })?;
    // Include the bones in the scale so that a tiny mesh far from its skeleton still has sane
    // tolerances.
    let mut lo = bounds.min.as_dvec3();
    let mut hi = bounds.max.as_dvec3();
    for s in &segments {
        lo = lo.min(s.a).min(s.b);
        hi = hi.max(s.a).max(s.b);
    }
    let diag = (hi - lo).length().max(f64::MIN_POSITIVE);

    let welded = weld::weld(
        &template.positions,
        &template.triangles,
        options.weld_tolerance * diag,
    );
    stats.welded_vertices = welded.positions.len();
    stats.collapsed_triangles = welded.collapsed_triangles;
    stats.duplicate_triangles = welded.duplicate_triangles;
    let n = welded.positions.len();
    let stiffness = laplacian::cotangent_stiffness(&welded.positions, &welded.triangles);
    stats.degenerate_triangles = stiffness.used.iter().filter(|u| !**u).count();
    let (component, n_components) = weld::components(n, &welded.triangles, &stiffness.used);
    stats.components = n_components;
    let used_triangles: Vec<[u32; 3]> = welded
        .triangles
        .iter()
        .zip(&stiffness.used)
        .filter(|(_, u)| **u)
        .map(|(t, _)| *t)
        .collect();
    let bvh = crate::triangle_bvh::TriangleBvh::new_f64(&welded.positions, &used_triangles);
    let normals = attach::cone_normals(&welded.positions, &welded.triangles, &stiffness.used);
    stats.setup_s = start.elapsed().as_secs_f64();

    let t = Instant::now();
    let params = AttachParams {
        tie_tolerance: options.tie_tolerance,
        cone_cos: options.cone_cos,
        ignore_visibility: false,
        min_distance: 1e-9 * diag,
    };
    let in_mesh: Vec<bool> = component.iter().map(|&c| c != u32::MAX).collect();
    let mut attachment = attach::attach(
        &welded.positions,
        &normals,
        &in_mesh,
        &segments,
        &bvh,
        params,
    );
    // The nearest segment(s) of every vertex by distance alone: the yardstick of what a vertex
    // sees, the attachment of components that see nothing near, and the weights of vertices
    // the solve leaves without any (below).
    let nearest = attach::attach(
        &welded.positions,
        &normals,
        &vec![true; n],
        &segments,
        &bvh,
        AttachParams {
            ignore_visibility: true,
            ..params
        },
    );
    // Components where nobody sees a bone, or sees only bones much further than the nearest
    // one: redo them by distance alone.
    let mut sees = vec![false; n_components];
    for ((a, near), &c) in attachment.iter().zip(&nearest).zip(&component) {
        if c != u32::MAX
            && !a.joints.is_empty()
            && a.distance <= options.far_visible_ratio * near.distance
        {
            sees[c as usize] = true;
        }
    }
    stats.fallback_components = sees.iter().filter(|s| !**s).count();
    for ((a, near), &c) in attachment.iter_mut().zip(&nearest).zip(&component) {
        if c != u32::MAX && !sees[c as usize] {
            a.clone_from(near);
        }
    }
    stats.unattached_vertices = attachment
        .iter()
        .zip(&in_mesh)
        .filter(|(a, m)| **m && a.joints.is_empty())
        .count();
    stats.attach_s = t.elapsed().as_secs_f64();

    // Unknowns: welded vertices in a usable triangle (every such component now has heat).
    let mut unknown = vec![u32::MAX; n];
    let mut count = 0u32;
    for v in 0..n {
        if in_mesh[v] {
            unknown[v] = count;
            count += 1;
        }
    }
    let m = count as usize;
    let mh: Vec<f64> = (0..n)
        .filter(|&v| in_mesh[v])
        .map(|v| {
            let a = &attachment[v];
            if a.joints.is_empty() {
                0.0
            } else {
                stiffness.area[v] * options.heat_constant / (a.distance * a.distance)
            }
        })
        .collect();
    let edges: Vec<(u32, u32, f64)> = stiffness
        .edges
        .iter()
        .map(|&(i, j, w)| (unknown[i as usize], unknown[j as usize], w))
        .collect();
    let t = Instant::now();
    let factor = match solve::Factor::new(m, &edges, &mh) {
        Ok(f) => f,
        Err(_) => {
            stats.clamped_negative_cotangents = true;
            let clamped: Vec<(u32, u32, f64)> =
                edges.iter().map(|&(i, j, w)| (i, j, w.max(0.0))).collect();
            solve::Factor::new(m, &clamped, &mh).map_err(|e| HeatError::Factorization(e.0))?
        }
    };
    stats.factor_s = t.elapsed().as_secs_f64();

    // Solve in blocks of joints to bound memory at (unknowns × BLOCK) doubles.
    const BLOCK: usize = 32;
    let joints = skeleton.len();
    let t = Instant::now();
    let mut rows: Vec<Vec<(u32, f32)>> = vec![Vec::new(); n];
    let mesh_vertices: Vec<usize> = (0..n).filter(|&v| in_mesh[v]).collect();
    let mut raw_sum = vec![0.0f64; m];
    let mut raw_min = f64::INFINITY;
    for first in (0..joints).step_by(BLOCK) {
        let width = BLOCK.min(joints - first);
        let mut rhs = Mat::<f64>::zeros(m, width);
        let mut any = vec![false; width];
        for (k, &v) in mesh_vertices.iter().enumerate() {
            for &(j, share) in &attachment[v].joints {
                let j = j as usize;
                if (first..first + width).contains(&j) {
                    rhs[(k, j - first)] = mh[k] * share;
                    any[j - first] = true;
                }
            }
        }
        factor.solve_in_place(&mut rhs);
        for c in 0..width {
            for (k, sum) in raw_sum.iter_mut().enumerate() {
                let w = rhs[(k, c)];
                *sum += w;
                raw_min = raw_min.min(w);
            }
        }
        for (c, _) in any.iter().enumerate().filter(|(_, a)| **a) {
            for (k, &v) in mesh_vertices.iter().enumerate() {
                let w = rhs[(k, c)];
                // Tiny values are noise of the solve; the real threshold is applied after
                // normalisation.
                if w.is_finite() && w > 1e-8 {
                    rows[v].push(((first + c) as u32, w.min(1.0) as f32));
                }
            }
        }
    }
    stats.solve_s = t.elapsed().as_secs_f64();
    stats.raw_sum_deviation = raw_sum.iter().map(|s| (s - 1.0).abs()).fold(0.0, f64::max);
    stats.raw_min = if m > 0 { raw_min } else { 0.0 };

    // Vertices outside any usable triangle, or with nothing left: nearest segment(s) by distance.
    let mut fallback = 0;
    for (row, a) in rows.iter_mut().zip(&nearest) {
        let total: f32 = row.iter().map(|r| r.1).sum();
        if total > 0.0 && total.is_finite() {
            continue;
        }
        fallback += 1;
        *row = a.joints.iter().map(|&(j, s)| (j, s as f32)).collect();
    }
    stats.fallback_vertices = fallback;
    stats.inherited_vertices = pieces::inherit_small_pieces(
        &welded.positions,
        &component,
        n_components,
        &mut rows,
        options.small_piece_fraction,
    );

    for row in &mut rows {
        normalise_and_prune(row, options.min_weight);
    }
    let mut offsets = Vec::with_capacity(template.vertex_count() + 1);
    offsets.push(0u32);
    let (mut js, mut ws) = (Vec::new(), Vec::new());
    for &w in &welded.of_input {
        for &(j, x) in &rows[w as usize] {
            js.push(j);
            ws.push(x);
        }
        offsets.push(js.len() as u32);
    }
    let skin = StaticSkin::new(offsets, js, ws, joints)?;
    stats.total_s = start.elapsed().as_secs_f64();
    Ok(HeatResult { skin, stats })
}

fn check_options(o: &HeatOptions) -> Result<(), HeatError> {
    let ok = |c: bool, name| {
        if c {
            Ok(())
        } else {
            Err(HeatError::BadOption(name))
        }
    };
    ok(
        o.heat_constant.is_finite() && o.heat_constant > 0.0,
        "heat_constant",
    )?;
    ok(
        o.tie_tolerance.is_finite() && o.tie_tolerance >= 0.0,
        "tie_tolerance",
    )?;
    ok((-1.0..=1.0).contains(&o.cone_cos), "cone_cos")?;
    ok((0.0..0.5).contains(&o.min_weight), "min_weight")?;
    ok(
        o.weld_tolerance.is_finite() && o.weld_tolerance >= 0.0,
        "weld_tolerance",
    )?;
    ok(
        o.leaf_fraction.is_finite() && o.leaf_fraction >= 0.0,
        "leaf_fraction",
    )?;
    ok(
        o.far_visible_ratio.is_finite() && o.far_visible_ratio >= 1.0,
        "far_visible_ratio",
    )?;
    ok(
        o.small_piece_fraction.is_finite() && (0.0..1.0).contains(&o.small_piece_fraction),
        "small_piece_fraction",
    )
}

/// Normalises a row, drops weights below `min_weight` and normalises again; the largest weight
/// always survives (`min_weight < 0.5`).
fn normalise_and_prune(row: &mut Vec<(u32, f32)>, min_weight: f32) {
    let sum: f32 = row.iter().map(|r| r.1).sum();
    if sum <= 0.0 {
        return;
    }
    let max = row.iter().map(|r| r.1).fold(0.0f32, f32::max);
    row.retain(|r| r.1 / sum >= min_weight || r.1 == max);
    let sum: f32 = row.iter().map(|r| r.1).sum();
    for r in row.iter_mut() {
        r.1 /= sum;
    }
    row.sort_unstable_by_key(|r| r.0);
}
