// The fast path (runtime/src/fast, docs/experiments/fast-path.md): SkinNet runs at N nodes only (the
// `skinnet_weights` kernel on a node mesh); these kernels turn the nodes' weights into every
// vertex's skinning. With a base (B: bind-pose weights on the vertex's strongest joints,
// a: interpolation weights, L: the nodes' log-weight changes from the bind pose):
//
//   w_vj ∝ B_vj · exp(Σ_i a_vi L_{n_i, j})     over the vertex's base joints, summing to one
//
// and without one (base_count = 0) the convex combination w_v = Σ_i a_vi w_{n_i}.
//
// - `fast_node_residuals` (per node): L_nj = ln max(w_nj, F) − ln max(b_nj, F) with a base;
//   without one the node weights and matrices R_n = Σ_j w_nj M_j;
// - `fast_skin_lbs` (per vertex): M_v = Σ_b w_vb M_{j_b} (with a base), Σ_i a_vi R_{n_i}
//   (without);
// - `fast_skin_dqs` (per vertex): the `dqs_k` strongest joints of w_v, renormalised, DQS;
// - `fast_top_k` (per vertex): the `top_k` strongest joints in engine layouts, weights quantised
//   by largest remainder so they sum exactly to one.
//
// Rust mirror: `FastParams` and `Influence` in runtime/src/gpu/layout.rs (naga-checked layouts).

struct FastParams {
    vertex_count: u32,
    node_count: u32,
    joint_count: u32,
    // Interpolation entries per vertex (k).
    neighbours: u32,
    // Base entries per vertex (stored first, then the k interpolation entries).
    base_count: u32,
    // Joints per vertex for DQS.
    dqs_k: u32,
    // Joints per vertex written by `fast_top_k` (4 or 8).
    top_k: u32,
    // Bytes per written joint index: 1 or 2.
    index_bytes: u32,
    // 0: unorm8, 1: unorm16, 2: f32 (multiples of 2⁻²⁴).
    weight_format: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// A joint (base) or node (interpolation) index and its weight.
struct Influence {
    index: u32,
    weight: f32,
}

@group(0) @binding(13) var<uniform> fast: FastParams;
// SkinNet's exact bind-pose weights at the nodes, `[node][joint]` (zero without a base).
@group(0) @binding(14) var<storage, read> node_base: array<f32>;
// L_n with a base, w_n without, `[node][joint]`.
@group(0) @binding(15) var<storage, read_write> node_residuals: array<f32>;
// R_n per node (without a base).
@group(0) @binding(16) var<storage, read_write> node_mats: array<mat4x4<f32>>;
// Per vertex: `base_count` base entries, then `neighbours` interpolation entries.
@group(0) @binding(17) var<storage, read> vertex_influences: array<Influence>;
// Top-k output: joint indices and weights packed in u32 words, byte layout = the CPU slices'.
@group(0) @binding(18) var<storage, read_write> top_indices: array<u32>;
@group(0) @binding(19) var<storage, read_write> top_weights: array<u32>;

const MAX_K: u32 = 8u;
// `LOG_WEIGHT_FLOOR` (runtime/src/fast/job.rs).
const LOG_WEIGHT_FLOOR: f32 = 1e-12;
// `activation::EXP_TAIL`: below e^-72 of the strongest a weight is exactly zero.
const EXP_TAIL: f32 = 72.0;

@compute @workgroup_size(64)
fn fast_node_residuals(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let n = group_index(wid, nwg) * THREADS + lid;
    if n >= fast.node_count {
        return;
    }
    let j_count = fast.joint_count;
    if fast.base_count > 0u {
        for (var j = 0u; j < j_count; j++) {
            let i = n * j_count + j;
            node_residuals[i] = log(max(skin_weights[i], LOG_WEIGHT_FLOOR))
                - log(max(node_base[i], LOG_WEIGHT_FLOOR));
        }
        return;
    }
    var m = mat4x4<f32>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    for (var j = 0u; j < j_count; j++) {
        let w = skin_weights[n * j_count + j];
        node_residuals[n * j_count + j] = w;
        m += joint_mats[j] * w;
    }
    node_mats[n] = m;
}

fn vertex_stride() -> u32 {
    return fast.base_count + fast.neighbours;
}

struct Base {
    index: array<u32, 8>,
    weight: array<f32, 8>,
}

// The weights of vertex `v` on its base joints (base order; requires a base):
// B_vb · exp(Σ_i a_vi L_{n_i, j_b}), renormalised (as `FastFrame::base_tile` on the CPU).
fn base_weights(v: u32) -> Base {
    var out: Base;
    let first = v * vertex_stride();
    let j_count = fast.joint_count;
    var t: array<f32, 8>;
    var top = -3.0e38;
    for (var b = 0u; b < fast.base_count; b++) {
        let e = vertex_influences[first + b];
        out.index[b] = e.index;
        var change = 0.0;
        for (var i = 0u; i < fast.neighbours; i++) {
            let a = vertex_influences[first + fast.base_count + i];
            change += a.weight * node_residuals[a.index * j_count + e.index];
        }
        // An empty slot (weight 0) stays empty.
        t[b] = select(-3.0e38, log(e.weight) + change, e.weight > 0.0);
        top = max(top, t[b]);
    }
    var sum = 0.0;
    for (var b = 0u; b < fast.base_count; b++) {
        out.weight[b] = select(0.0, exp(t[b] - top), t[b] - top >= -EXP_TAIL);
        sum += out.weight[b];
    }
    for (var b = 0u; b < fast.base_count; b++) {
        out.weight[b] /= sum;
    }
    return out;
}

@compute @workgroup_size(64)
fn fast_skin_lbs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let v = group_index(wid, nwg) * THREADS + lid;
    if v >= fast.vertex_count {
        return;
    }
    var m = mat4x4<f32>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    if fast.base_count > 0u {
        let w = base_weights(v);
        for (var b = 0u; b < fast.base_count; b++) {
            m += joint_mats[w.index[b]] * w.weight[b];
        }
    } else {
        let first = v * vertex_stride();
        for (var i = 0u; i < fast.neighbours; i++) {
            let e = vertex_influences[first + i];
            m += node_mats[e.index] * e.weight;
        }
    }
    skinned[v] = lbs_vertex(m, v);
}

// Weight of joint `j` in w_v without a base (the convex combination of its nodes' weights).
fn convex_weight(v: u32, j: u32) -> f32 {
    var w = 0.0;
    let first = v * vertex_stride();
    let j_count = fast.joint_count;
    for (var i = 0u; i < fast.neighbours; i++) {
        let e = vertex_influences[first + i];
        w += e.weight * node_residuals[e.index * j_count + j];
    }
    return w;
}

struct Top {
    index: array<u32, 8>,
    weight: array<f32, 8>,
}

// Offers joint `j` with weight `w` to the `k` strongest kept in `top` (`len` filled, strongest
// first); candidates come in joint order and a later one must be strictly larger to displace an
// earlier one.
fn offer(top: ptr<function, Top>, len: ptr<function, u32>, k: u32, j: u32, w: f32) {
    if *len == k && w <= (*top).weight[k - 1u] {
        return;
    }
    var at = min(*len, k - 1u);
    while at > 0u && (*top).weight[at - 1u] < w {
        (*top).index[at] = (*top).index[at - 1u];
        (*top).weight[at] = (*top).weight[at - 1u];
        at -= 1u;
    }
    (*top).index[at] = j;
    (*top).weight[at] = w;
    *len = min(*len + 1u, k);
}

// The `k` strongest joints of w_v, strongest first (ties: lower joint first), negatives clamped
// to zero, renormalised (as `strongest_influences` on the CPU). With a base only its joints are
// offered (as `strongest_sparse`): the other joints weigh zero and fill any remaining slots in
// joint order, which is what a selection over all joints gives, at the cost of the base.
fn strongest(v: u32, k: u32) -> Top {
    var top: Top;
    var len = 0u;
    if fast.base_count > 0u {
        let base = base_weights(v);
        // The positive base entries in joint order, so ties resolve as over all joints.
        var pj: array<u32, 8>;
        var pw: array<f32, 8>;
        var n = 0u;
        for (var b = 0u; b < fast.base_count; b++) {
            if base.weight[b] > 0.0 {
                var at = n;
                while at > 0u && pj[at - 1u] > base.index[b] {
                    pj[at] = pj[at - 1u];
                    pw[at] = pw[at - 1u];
                    at -= 1u;
                }
                pj[at] = base.index[b];
                pw[at] = base.weight[b];
                n += 1u;
            }
        }
        for (var i = 0u; i < n; i++) {
            offer(&top, &len, k, pj[i], pw[i]);
        }
        var j = 0u;
        while len < k && j < fast.joint_count {
            var taken = false;
            for (var i = 0u; i < n; i++) {
                taken = taken || pj[i] == j;
            }
            if !taken {
                top.index[len] = j;
                top.weight[len] = 0.0;
                len += 1u;
            }
            j += 1u;
        }
    } else {
        for (var j = 0u; j < fast.joint_count; j++) {
            offer(&top, &len, k, j, convex_weight(v, j));
        }
    }
    var sum = 0.0;
    for (var i = 0u; i < k; i++) {
        if i >= len {
            top.index[i] = 0u;
            top.weight[i] = 0.0;
        }
        sum += max(top.weight[i], 0.0);
    }
    for (var i = 0u; i < k; i++) {
        if sum > 0.0 {
            top.weight[i] = max(top.weight[i], 0.0) / sum;
        } else {
            top.weight[i] = select(0.0, 1.0, i == 0u);
        }
    }
    return top;
}

@compute @workgroup_size(64)
fn fast_skin_dqs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let v = group_index(wid, nwg) * THREADS + lid;
    if v >= fast.vertex_count {
        return;
    }
    let k = fast.dqs_k;
    let top = strongest(v, k);
    // Antipodality against the strongest joint (the first).
    let qp = joint_dqs[2u * top.index[0]];
    var br = vec4<f32>(0.0);
    var bd = vec4<f32>(0.0);
    for (var i = 0u; i < k; i++) {
        let j = top.index[i];
        let r = joint_dqs[2u * j];
        let w = select(top.weight[i], -top.weight[i], dot(r, qp) < 0.0);
        br += w * r;
        bd += w * joint_dqs[2u * j + 1u];
    }
    let len = length(br);
    if !(len > 1e-8) {
        // Rotations that cancel: LBS of the same influences (as the CPU).
        var m = mat4x4<f32>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
        for (var i = 0u; i < k; i++) {
            m += joint_mats[top.index[i]] * top.weight[i];
        }
        skinned[v] = lbs_vertex(m, v);
        return;
    }
    br /= len;
    bd /= len;
    let t = 2.0 * (br.w * bd.xyz - bd.w * br.xyz + cross(br.xyz, bd.xyz));
    let p = quat_rotate(br, rest[v].position.xyz) + t;
    let nrm = unit_or_zero(quat_rotate(br, rest[v].normal.xyz));
    skinned[v] = Vertex(vec4<f32>(p, 1.0), vec4<f32>(nrm, 0.0));
}

@compute @workgroup_size(64)
fn fast_top_k(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let v = group_index(wid, nwg) * THREADS + lid;
    if v >= fast.vertex_count {
        return;
    }
    let k = fast.top_k;
    let top = strongest(v, k);
    // Largest remainder: floor(w · one) each, then one unit to each of the largest fractions
    // (ties: the earlier slot) until the sum is `one`.
    var one = 255u;
    if fast.weight_format == 1u {
        one = 65535u;
    } else if fast.weight_format == 2u {
        one = 16777216u;
    }
    var q: array<u32, 8>;
    var frac: array<f32, 8>;
    var given = 0u;
    for (var i = 0u; i < k; i++) {
        let x = top.weight[i] * f32(one);
        let f = floor(x);
        q[i] = u32(f);
        frac[i] = x - f;
        given += q[i];
    }
    // f32 rounding can push the floors' sum one unit past `one`: take it back from the
    // smallest fraction among the nonzero slots.
    while given > one {
        var worst = MAX_K;
        for (var i = 0u; i < k; i++) {
            if q[i] > 0u && (worst == MAX_K || frac[i] < frac[worst]) {
                worst = i;
            }
        }
        q[worst] -= 1u;
        frac[worst] = 2.0;
        given -= 1u;
    }
    while given < one {
        var best = 0u;
        for (var i = 1u; i < k; i++) {
            if frac[i] > frac[best] {
                best = i;
            }
        }
        q[best] += 1u;
        frac[best] = -1.0;
        given += 1u;
    }
    // Pack little-endian into u32 words: the byte layout of the CPU's `[u8]` / `[u16]` slices.
    let per_index_word = 4u / fast.index_bytes;
    let index_words = k / per_index_word;
    for (var w = 0u; w < index_words; w++) {
        var word = 0u;
        for (var c = 0u; c < per_index_word; c++) {
            word |= top.index[w * per_index_word + c] << (c * 8u * fast.index_bytes);
        }
        top_indices[v * index_words + w] = word;
    }
    if fast.weight_format == 2u {
        for (var i = 0u; i < k; i++) {
            top_weights[v * k + i] = bitcast<u32>(f32(q[i]) * 0x1p-24f);
        }
    } else {
        let bytes = fast.weight_format + 1u;
        let per_word = 4u / bytes;
        let words = k / per_word;
        for (var w = 0u; w < words; w++) {
            var word = 0u;
            for (var c = 0u; c < per_word; c++) {
                word |= q[w * per_word + c] << (c * 8u * bytes);
            }
            top_weights[v * words + w] = word;
        }
    }
}
