//! The portable kernel: plain loops over the shared tile layout, exact libm activations. It is
//! the reference every SIMD kernel is tested against, and the path the `scalar` feature forces.

use super::{LayerArgs, MR, TILE};
use crate::activation::softplus_slope as slope_of;
use crate::activation::{Act, EXP_TAIL, softplus};

pub(super) fn layer(a: LayerArgs<'_>) {
    let LayerArgs {
        panels,
        k,
        input,
        bias,
        pre,
        out,
        rows_p,
        act,
    } = a;
    for p in 0..rows_p / MR {
        let mut acc = [[0.0f32; TILE]; MR];
        let panel = &panels[p * k * MR..(p + 1) * k * MR];
        for (w, x) in panel.chunks_exact(MR).zip(input.chunks_exact(TILE)) {
            for (acc_r, &w_r) in acc.iter_mut().zip(w) {
                for (s, &xv) in acc_r.iter_mut().zip(x) {
                    *s += w_r * xv;
                }
            }
        }
        for (r, acc_r) in acc.iter().enumerate() {
            let o = p * MR + r;
            let row = &mut out[o * TILE..(o + 1) * TILE];
            for (v, y) in row.iter_mut().enumerate() {
                let mut x = acc_r[v] + bias[o];
                if let Some(pre) = pre {
                    x += pre[o * TILE + v];
                }
                *y = match act {
                    Act::Softplus { beta } => softplus(x, beta),
                    Act::Identity => x,
                };
            }
        }
    }
}

pub(super) fn softmax_tile(buf: &mut [f32], rows: usize) {
    for v in 0..TILE {
        let mut m = f32::NEG_INFINITY;
        for j in 0..rows {
            m = m.max(buf[j * TILE + v]);
        }
        let mut sum = 0.0;
        for j in 0..rows {
            let z = buf[j * TILE + v] - m;
            // Below the tail the weight would be subnormal (see `EXP_TAIL`): exactly zero.
            let e = if z >= -EXP_TAIL { libm::expf(z) } else { 0.0 };
            buf[j * TILE + v] = e;
            sum += e;
        }
        let inv = 1.0 / sum;
        for j in 0..rows {
            buf[j * TILE + v] *= inv;
        }
    }
}

pub(super) fn softplus_with_slope(x: &mut [f32], slope: &mut [f32], beta: f32) {
    for (v, s) in x.iter_mut().zip(slope) {
        *s = slope_of(*v, beta);
        *v = softplus(*v, beta);
    }
}
