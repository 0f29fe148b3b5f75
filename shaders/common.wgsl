// Shared declarations of the Skinfield compute kernels. The runtime concatenates this file,
// one of `weights_f16.wgsl` / `weights_f32.wgsl`, and the kernel files into one module, so
// binding numbers are unique across the whole module; each entry point uses a subset.
//
// Rust mirror: `runtime/src/gpu/layout.rs` (`GpuLayer`, `GpuParams`, `SkinnedVertex`); a unit
// test checks sizes and offsets with naga's layouter.

// One linear layer: `W` is `[out_w, in_w]`, stored transposed in column pairs
// (`weight2(layer, p, o)` = `(W[o, 2p], W[o, 2p + 1])`) starting at pair `w_off`;
// its bias starts at `b_off` in `biases`.
struct Layer {
    in_w: u32,
    out_w: u32,
    w_off: u32,
    b_off: u32,
}

// Per-mesh constants (model shape plus the mesh's vertex count).
struct Params {
    vertex_count: u32,
    // Hidden layers plus the output layer (the last one).
    layer_count: u32,
    // Hidden layer whose input is `[h, x̂, γ(x̂), θ̃]`; 0 = no skip connection.
    skip_layer: u32,
    // Width of `[x̂, γ(x̂)]`.
    pos_width: u32,
    // Width of the pose features θ̃ (3 per joint).
    pose_width: u32,
    joint_count: u32,
    // Width of layer 0 (its input is all constant terms).
    term0_width: u32,
    // Width of the skip layer (0 without one).
    term_skip_width: u32,
    // Softplus sharpness β.
    beta: f32,
    // Candidate-list slots per vertex in `candidates` (0: every joint is a candidate).
    candidate_k: u32,
    _pad1: u32,
    _pad2: u32,
    layers: array<Layer, 9>,
}

// A skinned (or rest) vertex; also the layout of the output vertex buffer.
struct Vertex {
    position: vec4<f32>,
    normal: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
// binding 1: `weights`, declared by the weight-format file.
@group(0) @binding(2) var<storage, read> biases: array<f32>;
// `[x̂, γ(x̂)]` per vertex, computed on the CPU in f64 (WGSL's sin/cos are too coarse at 2^k π).
@group(0) @binding(3) var<storage, read> encoding: array<f32>;
// Position part of layer 0, `[vertex][term0_width]`, computed once per mesh.
@group(0) @binding(4) var<storage, read_write> term0: array<f32>;
// Position part of the skip layer, `[vertex][term_skip_width]`, computed once per mesh.
@group(0) @binding(5) var<storage, read_write> term_skip: array<f32>;
// Pose features θ̃ of the current frame.
@group(0) @binding(6) var<storage, read> features: array<f32>;
// Skinning matrices `world · inverse_bind` of the current frame.
@group(0) @binding(7) var<storage, read> joint_mats: array<mat4x4<f32>>;
// Pose part plus bias of layer 0 (first term0_width) and of the skip layer (next term_skip_width).
@group(0) @binding(8) var<storage, read_write> pose_terms: array<f32>;
// Unit dual quaternion per joint: real part at 2j, dual part at 2j + 1 (xyzw).
@group(0) @binding(9) var<storage, read_write> joint_dqs: array<vec4<f32>>;
// SkinNet output (softmax), `[vertex][joint_count]`.
@group(0) @binding(10) var<storage, read_write> skin_weights: array<f32>;
@group(0) @binding(11) var<storage, read> rest: array<Vertex>;
@group(0) @binding(12) var<storage, read_write> skinned: array<Vertex>;
// Candidate joints (a `.skf` with `CAND`): `candidate_k` joint indices per vertex, padded with
// 0xFFFF; the softmax ranges over them only. One unused word without candidates.
@group(0) @binding(20) var<storage, read> candidates: array<u32>;

const THREADS: u32 = 64u;

// Workgroup index of a dispatch split in 2D (each dimension ≤ 65535).
fn group_index(wid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wid.y * nwg.x + wid.x;
}

// `log(1 + exp(βx)) / β` without overflow for large βx.
fn softplus(x: f32, beta: f32) -> f32 {
    return max(x, 0.0) + log(1.0 + exp(-abs(beta * x))) / beta;
}

fn softplus4(x: vec4<f32>, beta: f32) -> vec4<f32> {
    return max(x, vec4<f32>(0.0)) + log(vec4<f32>(1.0) + exp(-abs(beta * x))) / beta;
}

// W[o, i] of `layer`.
fn weight(layer: Layer, i: u32, o: u32) -> f32 {
    let w = weight2(layer, i >> 1u, o);
    return select(w.x, w.y, (i & 1u) == 1u);
}
