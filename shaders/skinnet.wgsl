// SkinNet per vertex: hidden layers after layer 0, output layer, softmax over joints.
//
// A workgroup of 64 threads owns a tile of 16 vertices. The tile's activations live in
// workgroup memory as `act[row * 4 + quad]`, a vec4 holding one activation row for 4 vertices
// (16 KiB at the widest supported layer, 256: inside WebGPU's default 16 KiB limit). Thread t
// computes outputs t, t + 64, t + 128, t + 192 for all 16 vertices (16 vec4 accumulators in
// registers), streaming the weights from storage (adjacent threads read adjacent outputs) and
// broadcasting activations from workgroup memory; one barrier after the reads lets the
// results overwrite the inputs in place.

const TILE: u32 = 16u;
const QUADS: u32 = 4u;
const MAX_WIDTH: u32 = 256u;
const OUTS_PER_THREAD: u32 = 4u;

var<workgroup> act: array<vec4<f32>, 1024>;

@compute @workgroup_size(64)
fn skinnet_weights(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let first_vertex = group_index(wid, nwg) * TILE;
    let beta = params.beta;
    let h0 = params.term0_width;
    let hs = params.term_skip_width;

    // Layer 0: only constant terms (position part per vertex + pose part per frame).
    for (var e = lid; e < h0 * QUADS; e += THREADS) {
        let o = e / QUADS;
        let q = e % QUADS;
        var z = vec4<f32>(0.0);
        for (var c = 0u; c < 4u; c++) {
            let v = first_vertex + q * 4u + c;
            if v < params.vertex_count {
                z[c] = softplus(term0[v * h0 + o] + pose_terms[o], beta);
            }
        }
        act[o * QUADS + q] = z;
    }
    workgroupBarrier();

    for (var l = 1u; l < params.layer_count; l++) {
        let layer = params.layers[l];
        let in_w = params.layers[l - 1u].out_w;
        let out_w = layer.out_w;
        // Zero-initialised at every iteration (WGSL `var` without initialiser).
        var acc: array<vec4<f32>, 16>;
        let pairs = in_w >> 1u;
        for (var p = 0u; p < pairs; p++) {
            let r0 = 2u * p * QUADS;
            let r1 = r0 + QUADS;
            var a0 = array<vec4<f32>, 4>(act[r0], act[r0 + 1u], act[r0 + 2u], act[r0 + 3u]);
            var a1 = array<vec4<f32>, 4>(act[r1], act[r1 + 1u], act[r1 + 2u], act[r1 + 3u]);
            for (var k = 0u; k < OUTS_PER_THREAD; k++) {
                let o = lid + k * THREADS;
                if o < out_w {
                    let w = weight2(layer, p, o);
                    for (var q = 0u; q < QUADS; q++) {
                        acc[k * QUADS + q] = fma(vec4<f32>(w.x), a0[q], fma(vec4<f32>(w.y), a1[q], acc[k * QUADS + q]));
                    }
                }
            }
        }
        if (in_w & 1u) == 1u {
            let r = (in_w - 1u) * QUADS;
            for (var k = 0u; k < OUTS_PER_THREAD; k++) {
                let o = lid + k * THREADS;
                if o < out_w {
                    let w = weight2(layer, pairs, o).x;
                    for (var q = 0u; q < QUADS; q++) {
                        acc[k * QUADS + q] = fma(vec4<f32>(w), act[r + q], acc[k * QUADS + q]);
                    }
                }
            }
        }
        // Every thread has read its inputs: the outputs may now overwrite them.
        workgroupBarrier();
        let hidden = l + 1u < params.layer_count;
        let skip = l == params.skip_layer;
        for (var k = 0u; k < OUTS_PER_THREAD; k++) {
            let o = lid + k * THREADS;
            if o < out_w {
                for (var q = 0u; q < QUADS; q++) {
                    var z = acc[k * QUADS + q];
                    if skip {
                        z += vec4<f32>(pose_terms[h0 + o]);
                        for (var c = 0u; c < 4u; c++) {
                            let v = first_vertex + q * 4u + c;
                            if v < params.vertex_count {
                                z[c] += term_skip[v * hs + o];
                            }
                        }
                    } else {
                        z += vec4<f32>(biases[layer.b_off + o]);
                    }
                    if hidden {
                        z = softplus4(z, beta);
                    }
                    act[o * QUADS + q] = z;
                }
            }
        }
        workgroupBarrier();
    }

    // Softmax over the joints (the vertex's candidates only, when the model has them), one
    // thread per vertex. Non-candidates weigh exactly zero, as in the CPU path.
    let j_count = params.joint_count;
    let k = params.candidate_k;
    let v = first_vertex + lid;
    if lid < TILE && v < params.vertex_count {
        let q = lid / 4u;
        let c = lid % 4u;
        var m = -3.0e38;
        for (var j = 0u; j < j_count; j++) {
            if is_candidate(v, j, k) {
                m = max(m, act[j * QUADS + q][c]);
            }
        }
        var sum = 0.0;
        for (var j = 0u; j < j_count; j++) {
            if is_candidate(v, j, k) {
                sum += exp(act[j * QUADS + q][c] - m);
            }
        }
        let inv = 1.0 / sum;
        for (var j = 0u; j < j_count; j++) {
            var w = 0.0;
            if is_candidate(v, j, k) {
                w = exp(act[j * QUADS + q][c] - m) * inv;
            }
            skin_weights[v * j_count + j] = w;
        }
    }
}

// Whether joint `j` is among vertex `v`'s `k` candidates (always, with `k` = 0).
fn is_candidate(v: u32, j: u32, k: u32) -> bool {
    if k == 0u {
        return true;
    }
    for (var s = 0u; s < k; s++) {
        if candidates[v * k + s] == j {
            return true;
        }
    }
    return false;
}
