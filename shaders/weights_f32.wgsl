// Weights stored as f32 pairs (W[o, 2p], W[o, 2p + 1]).
@group(0) @binding(1) var<storage, read> weights: array<vec2<f32>>;

fn weight2(layer: Layer, p: u32, o: u32) -> vec2<f32> {
    return weights[layer.w_off + p * layer.out_w + o];
}
