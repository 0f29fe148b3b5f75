// Weights stored as IEEE half pairs (low 16 bits W[o, 2p], high W[o, 2p + 1]), decoded with
// integer operations: `unpack2x16float` needs a downlevel capability (SHADER_F16_IN_F32) that
// not every adapter has (Mesa's llvmpipe only with native f16), so this is the portable form.
@group(0) @binding(1) var<storage, read> weights: array<u32>;

// Exact for zero, subnormal and normal halves; half infinities/NaNs (never written to `.skf`)
// decode to large finite values.
fn half_to_f32(h: u32) -> f32 {
    let magnitude = h & 0x7fffu;
    // Normal: move exponent and mantissa into place and rebias the exponent by 127 - 15.
    let normal = bitcast<f32>((magnitude << 13u) + (112u << 23u));
    // Subnormal: mantissa · 2⁻²⁴ (exact in f32).
    let subnormal = f32(magnitude) * 0x1p-24f;
    let value = select(normal, subnormal, magnitude < 0x400u);
    return bitcast<f32>(((h & 0x8000u) << 16u) | bitcast<u32>(value));
}

fn weight2(layer: Layer, p: u32, o: u32) -> vec2<f32> {
    let packed = weights[layer.w_off + p * layer.out_w + o];
    return vec2<f32>(half_to_f32(packed & 0xffffu), half_to_f32(packed >> 16u));
}
