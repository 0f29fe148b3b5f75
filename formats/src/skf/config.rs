//! The CONF section: what the runtime needs to rebuild SkinNet's forward pass.

use glam::Vec3;

use crate::pose::{POSE_FEATURE_ENCODING, UpAxis, pose_feature_count};

use super::{CONF_LEN, MAX_HIDDEN_LAYERS, MAX_LAYER_WIDTH, MAX_PE_FREQUENCIES};
use crate::skeleton::MAX_JOINTS;

/// A network stored in the file; tensor names start with [`Net::prefix`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Net {
    /// Skinning weights `w(x̄, θ̃) ∈ Δ^J`; input `[x̂, γ(x̂), θ̃]`, output `J`, softmax.
    Skin,
    /// Albedo `a(x̄) ∈ R³`; input `[x̂, γ(x̂)]`, output 3.
    Albedo,
    /// Shading `r(x̄, θ̃, n, d) = exp(out)`; input `[x̂, γ(x̂), θ̃, n, d]`, output 1.
    Shadow,
}

impl Net {
    /// Tensor-name prefix.
    #[must_use]
    pub fn prefix(self) -> &'static str {
        match self {
            Net::Skin => "skin",
            Net::Albedo => "albedo",
            Net::Shadow => "shadow",
        }
    }

    /// Bit in [`ModelConfig::nets`].
    #[must_use]
    pub fn bit(self) -> u32 {
        match self {
            Net::Skin => 1,
            Net::Albedo => 2,
            Net::Shadow => 4,
        }
    }
}

/// Why a CONF section is invalid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SkfConfigError {
    /// A field holds an unsupported or out-of-range value.
    #[error("CONF field `{0}` is invalid")]
    BadField(&'static str),
}

/// Network hyper-parameters and input encoding (the CONF section).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelConfig {
    /// Positional-encoding frequencies `L` (NeRF: `sin/cos(2^k π x̂)`, k < L).
    pub pe_frequencies: u32,
    /// Softplus sharpness β: `softplus(x) = log(1 + exp(βx)) / β`.
    pub softplus_beta: f32,
    /// Pose-feature encoding id ([`POSE_FEATURE_ENCODING`]).
    pub pose_encoding: u32,
    /// World up axis for heading removal.
    pub up_axis: UpAxis,
    /// Joint count `J` (SkinNet's output width).
    pub joint_count: u32,
    /// Hidden layer count (≤ [`MAX_HIDDEN_LAYERS`]).
    pub hidden_count: u32,
    /// Hidden layer widths (first `hidden_count` used).
    pub hidden: [u32; MAX_HIDDEN_LAYERS],
    /// Index of the hidden layer whose input is `[h, input]` (the skip connection).
    pub skip_layer: u32,
    /// Canonical bounding-box minimum (maps to -1).
    pub bbox_min: [f32; 3],
    /// Canonical bounding-box maximum (maps to +1).
    pub bbox_max: [f32; 3],
    /// Which nets are stored ([`Net::bit`]s); SkinNet is always present.
    pub nets: u32,
}

impl ModelConfig {
    /// The paper's architecture (supplementary D; see `docs/design.md`, *Network*) for
    /// `joint_count` joints.
    #[must_use]
    pub fn paper_architecture(joint_count: u32, bbox_min: [f32; 3], bbox_max: [f32; 3]) -> Self {
        let mut hidden = [0; MAX_HIDDEN_LAYERS];
        hidden[..5].copy_from_slice(&[256, 256, 128, 256, 256]);
        Self {
            pe_frequencies: 6,
            softplus_beta: 100.0,
            pose_encoding: POSE_FEATURE_ENCODING,
            up_axis: UpAxis::Y,
            joint_count,
            hidden_count: 5,
            hidden,
            skip_layer: 2,
            bbox_min,
            bbox_max,
            nets: Net::Skin.bit(),
        }
    }

    /// Hidden widths in use.
    #[must_use]
    pub fn hidden_widths(&self) -> &[u32] {
        &self.hidden[..(self.hidden_count as usize).min(MAX_HIDDEN_LAYERS)]
    }

    /// Width of `[x̂, γ(x̂)]`: `3 + 6L`.
    #[must_use]
    pub fn position_width(&self) -> usize {
        3 + 6 * self.pe_frequencies as usize
    }

    /// The canonical point `x̄` in the network's input box: `x̂ = 2(x̄ − min)/(max − min) − 1`
    /// with the file's bounding box (f32).
    #[must_use]
    pub fn normalise(&self, x: Vec3) -> Vec3 {
        let lo = Vec3::from_array(self.bbox_min);
        let hi = Vec3::from_array(self.bbox_max);
        2.0 * (x - lo) / (hi - lo) - Vec3::ONE
    }

    /// The network's position input `[x̂, γ(x̂)]` of the canonical point `x̄`
    /// ([`ModelConfig::position_width`] values): `x̂`, then for `k < L` `sin(2^k π x̂)` (3) and
    /// `cos(2^k π x̂)` (3). The sines are taken in f64 of the f32 `x̂` (libm) and rounded: at
    /// `k = 5` the argument is ~100 rad, where f32 would lose ~1e-5. The one implementation the
    /// trainer, the CPU runtime and the GPU upload share, so their inputs are bit-identical.
    pub fn position_input(&self, x: Vec3) -> impl Iterator<Item = f32> + use<> {
        let xh = self.normalise(x).to_array();
        let waves = (0..self.pe_frequencies as i32).flat_map(move |k| {
            let f = libm::ldexp(core::f64::consts::PI, k);
            let arg = move |c: usize| f * f64::from(xh[c]);
            (0..3)
                .map(move |c| libm::sin(arg(c)) as f32)
                .chain((0..3).map(move |c| libm::cos(arg(c)) as f32))
        });
        xh.into_iter().chain(waves)
    }

    /// Width of the pose features: `3J`.
    #[must_use]
    pub fn pose_width(&self) -> usize {
        pose_feature_count(self.joint_count as usize)
    }

    /// Input width of `net`.
    #[must_use]
    pub fn input_width(&self, net: Net) -> usize {
        match net {
            Net::Skin => self.position_width() + self.pose_width(),
            Net::Albedo => self.position_width(),
            Net::Shadow => self.position_width() + self.pose_width() + 6,
        }
    }

    /// Output width of `net`.
    #[must_use]
    pub fn output_width(&self, net: Net) -> usize {
        match net {
            Net::Skin => self.joint_count as usize,
            Net::Albedo => 3,
            Net::Shadow => 1,
        }
    }

    /// `(out, in)` of every linear layer of `net`, hidden layers first, then the output layer.
    pub fn layer_shapes(&self, net: Net) -> impl Iterator<Item = (usize, usize)> + '_ {
        let input = self.input_width(net);
        let widths = self.hidden_widths();
        let n = widths.len();
        (0..=n).map(move |i| {
            let out = if i < n {
                widths[i] as usize
            } else {
                self.output_width(net)
            };
            let prev = if i == 0 {
                input
            } else {
                widths[i - 1] as usize
            };
            let inp = if i == self.skip_layer as usize && i > 0 {
                prev + input
            } else {
                prev
            };
            (out, inp)
        })
    }

    /// Multiply-adds per vertex of `net` (pose terms and position terms included).
    #[must_use]
    pub fn macs_per_vertex(&self, net: Net) -> usize {
        self.layer_shapes(net).map(|(o, i)| o * i).sum()
    }

    /// Checks every field against the caps.
    pub fn validate(&self) -> Result<(), SkfConfigError> {
        let bad = |f| Err(SkfConfigError::BadField(f));
        if self.pe_frequencies > MAX_PE_FREQUENCIES {
            return bad("pe_frequencies");
        }
        if !(self.softplus_beta.is_finite() && self.softplus_beta > 0.0) {
            return bad("softplus_beta");
        }
        if self.pose_encoding != POSE_FEATURE_ENCODING {
            return bad("pose_encoding");
        }
        if self.joint_count == 0 || self.joint_count as usize > MAX_JOINTS {
            return bad("joint_count");
        }
        if self.hidden_count == 0 || self.hidden_count as usize > MAX_HIDDEN_LAYERS {
            return bad("hidden_count");
        }
        let n = self.hidden_count as usize;
        if self.hidden[..n]
            .iter()
            .any(|&w| w == 0 || w > MAX_LAYER_WIDTH)
            || self.hidden[n..].iter().any(|&w| w != 0)
        {
            return bad("hidden");
        }
        if self.skip_layer as usize >= n {
            return bad("skip_layer");
        }
        for k in 0..3 {
            let (lo, hi) = (self.bbox_min[k], self.bbox_max[k]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return bad("bbox");
            }
        }
        if self.nets & Net::Skin.bit() == 0 || self.nets & !7 != 0 {
            return bad("nets");
        }
        Ok(())
    }

    /// Serialises to the 128-byte CONF section.
    #[must_use]
    pub fn to_bytes(&self) -> [u8; CONF_LEN] {
        let mut b = [0u8; CONF_LEN];
        let mut put = |at: usize, v: [u8; 4]| b[at..at + 4].copy_from_slice(&v);
        put(0, self.pe_frequencies.to_le_bytes());
        put(4, self.softplus_beta.to_le_bytes());
        put(8, self.pose_encoding.to_le_bytes());
        put(12, self.up_axis.code().to_le_bytes());
        put(16, self.joint_count.to_le_bytes());
        put(20, self.hidden_count.to_le_bytes());
        for (k, w) in self.hidden.iter().enumerate() {
            put(24 + 4 * k, w.to_le_bytes());
        }
        put(56, self.skip_layer.to_le_bytes());
        for k in 0..3 {
            put(60 + 4 * k, self.bbox_min[k].to_le_bytes());
            put(72 + 4 * k, self.bbox_max[k].to_le_bytes());
        }
        put(84, self.nets.to_le_bytes());
        b
    }

    /// Parses and validates a CONF section (exactly [`CONF_LEN`] bytes; bytes 88.. must be zero).
    pub fn from_bytes(b: &[u8]) -> Result<Self, SkfConfigError> {
        if b.len() != CONF_LEN {
            return Err(SkfConfigError::BadField("length"));
        }
        let u = |at: usize| u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        let f = |at: usize| f32::from_bits(u(at));
        let mut hidden = [0; MAX_HIDDEN_LAYERS];
        for (k, w) in hidden.iter_mut().enumerate() {
            *w = u(24 + 4 * k);
        }
        if b[88..].iter().any(|&x| x != 0) {
            return Err(SkfConfigError::BadField("reserved"));
        }
        let c = Self {
            pe_frequencies: u(0),
            softplus_beta: f(4),
            pose_encoding: u(8),
            up_axis: UpAxis::from_code(u(12)).ok_or(SkfConfigError::BadField("up_axis"))?,
            joint_count: u(16),
            hidden_count: u(20),
            hidden,
            skip_layer: u(56),
            bbox_min: [f(60), f(64), f(68)],
            bbox_max: [f(72), f(76), f(80)],
            nets: u(84),
        };
        c.validate()?;
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vinecs_architecture_matches_design_flop_count() {
        let c = ModelConfig::paper_architecture(24, [-1.0; 3], [1.0; 3]);
        c.validate().unwrap();
        let shapes: alloc::vec::Vec<_> = c.layer_shapes(Net::Skin).collect();
        assert_eq!(
            shapes,
            [
                (256, 111),
                (256, 256),
                (128, 367),
                (256, 128),
                (256, 256),
                (24, 256)
            ]
        );
        // `docs/design.md`, *Network*: ≈ 0.49 MFLOP per vertex for J = 24, L = 6.
        let mflop = 2.0 * c.macs_per_vertex(Net::Skin) as f64 / 1e6;
        assert!((mflop - 0.49).abs() < 0.01, "{mflop}");
        assert_eq!(ModelConfig::from_bytes(&c.to_bytes()), Ok(c));
    }

    type Mutation = (fn(&mut ModelConfig), &'static str);

    #[test]
    fn rejects_each_bad_field() {
        let good = ModelConfig::paper_architecture(24, [-1.0; 3], [1.0; 3]);
        let cases: [Mutation; 9] = [
            (|c| c.pe_frequencies = 99, "pe_frequencies"),
            (|c| c.softplus_beta = f32::NAN, "softplus_beta"),
            (|c| c.pose_encoding = 7, "pose_encoding"),
            (|c| c.joint_count = 0, "joint_count"),
            (|c| c.hidden_count = 9, "hidden_count"),
            (|c| c.hidden[1] = 0, "hidden"),
            (|c| c.skip_layer = 5, "skip_layer"),
            (|c| c.bbox_max[1] = -2.0, "bbox"),
            (|c| c.nets = 2, "nets"),
        ];
        for (mutate, field) in cases {
            let mut c = good;
            mutate(&mut c);
            assert_eq!(c.validate(), Err(SkfConfigError::BadField(field)));
            assert_eq!(
                ModelConfig::from_bytes(&c.to_bytes()),
                Err(SkfConfigError::BadField(field))
            );
        }
        let mut b = good.to_bytes();
        b[12] = 9;
        assert_eq!(
            ModelConfig::from_bytes(&b),
            Err(SkfConfigError::BadField("up_axis"))
        );
        let mut b = good.to_bytes();
        b[100] = 1;
        assert_eq!(
            ModelConfig::from_bytes(&b),
            Err(SkfConfigError::BadField("reserved"))
        );
    }
}
