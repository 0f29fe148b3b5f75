// The constant parts of SkinNet's two input-fed layers (layer 0 and the skip layer):
// - per mesh (`bind_position_terms`): W[:, pos] · [x̂, γ(x̂)] for every vertex;
// - per frame (`frame_pose_terms`): W[:, pose] · θ̃ + b, shared by every vertex.
// What is left per vertex and frame is the dense hidden-to-hidden work in `skinnet.wgsl`.

// Layer and first input column of the constant term `s` (< term0_width + term_skip_width):
// returns (layer index, first column of the `[x̂, γ(x̂), θ̃]` block, output row).
fn term_slot(s: u32) -> vec3<u32> {
    if s < params.term0_width {
        return vec3<u32>(0u, 0u, s);
    }
    let k = params.skip_layer;
    return vec3<u32>(k, params.layers[k - 1u].out_w, s - params.term0_width);
}

@compute @workgroup_size(64)
fn bind_position_terms(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let per_vertex = params.term0_width + params.term_skip_width;
    let g = group_index(wid, nwg) * THREADS + lid;
    let v = g / per_vertex;
    if v >= params.vertex_count {
        return;
    }
    let s = g % per_vertex;
    let slot = term_slot(s);
    let layer = params.layers[slot.x];
    let pw = params.pos_width;
    var acc = 0.0;
    for (var i = 0u; i < pw; i++) {
        acc += weight(layer, slot.y + i, slot.z) * encoding[v * pw + i];
    }
    if slot.x == 0u {
        term0[v * params.term0_width + slot.z] = acc;
    } else {
        term_skip[v * params.term_skip_width + slot.z] = acc;
    }
}

@compute @workgroup_size(64)
fn frame_pose_terms(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let s = group_index(wid, nwg) * THREADS + lid;
    if s >= params.term0_width + params.term_skip_width {
        return;
    }
    let slot = term_slot(s);
    let layer = params.layers[slot.x];
    let first = slot.y + params.pos_width;
    var acc = biases[layer.b_off + slot.z];
    for (var k = 0u; k < params.pose_width; k++) {
        acc += weight(layer, first + k, slot.z) * features[k];
    }
    pose_terms[s] = acc;
}
