// Weights stored as IEEE half pairs: the low 16 bits hold W[o, 2p], the high W[o, 2p + 1].
@group(0) @binding(1) var<storage, read> weights: array<u32>;

fn weight2(layer: Layer, p: u32, o: u32) -> vec2<f32> {
    return unpack2x16float(weights[layer.w_off + p * layer.out_w + o]);
}
