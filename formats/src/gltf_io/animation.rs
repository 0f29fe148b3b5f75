//! glTF animations as [`Clip`]s and their sampling to [`Pose`]s (LINEAR with quaternion slerp,
//! STEP, CUBICSPLINE), bound to a skin by node index or to any skeleton by joint name.

use std::collections::HashMap;

use glam::{Quat, Vec3, Vec4};

use super::GltfError;
use super::GltfSkin;
use super::import::Source;
use crate::math::Transform;
use crate::pose::Pose;
use crate::skeleton::Skeleton;

/// Most keyframes over all channels of one animation.
pub const MAX_CLIP_KEYS: usize = 1 << 24;

/// Which node property a channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelProperty {
    /// Translation (xyz).
    Translation,
    /// Rotation (unit quaternion xyzw).
    Rotation,
    /// Scale (xyz).
    Scale,
}

/// Keyframe interpolation (glTF `sampler.interpolation`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Piecewise linear; rotations by spherical linear interpolation (shortest arc).
    Linear,
    /// Piecewise constant: the value of the last key at or before `t`.
    Step,
    /// Cubic Hermite spline with in/out tangents stored beside each value.
    CubicSpline,
}

/// One animated property of one node.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    /// Target node index in the file.
    pub node: usize,
    /// Target node's name (for binding by name).
    pub node_name: String,
    /// Animated property.
    pub property: ChannelProperty,
    /// Interpolation.
    pub interpolation: Interpolation,
    /// Key times in seconds, non-decreasing.
    pub times: Vec<f32>,
    /// Values (xyz in `.xyz` for translation/scale, quaternion xyzw for rotation); for
    /// CUBICSPLINE three per key: in-tangent, value, out-tangent.
    pub values: Vec<Vec4>,
}

/// One glTF animation.
#[derive(Clone, Debug, PartialEq)]
pub struct Clip {
    /// The animation's name, or `animation_{index}` when it has none.
    pub name: String,
    /// Time of the last key over all channels (clips play from t = 0).
    pub duration_s: f32,
    /// Number of distinct key times over all channels.
    pub frames: usize,
    /// Node channels (translation, rotation, scale).
    pub channels: Vec<Channel>,
    /// Morph-target weight channels in the file, which poses do not use.
    pub weight_channels: usize,
}

impl Channel {
    fn value(&self, k: usize) -> Vec4 {
        match self.interpolation {
            Interpolation::CubicSpline => self.values[3 * k + 1],
            _ => self.values[k],
        }
    }

    /// The channel's value at time `t` (held before the first and after the last key).
    #[must_use]
    pub fn sample(&self, t: f32) -> Vec4 {
        let n = self.times.len();
        if t.is_nan() || t <= self.times[0] {
            return self.value(0);
        }
        if t >= self.times[n - 1] {
            return self.value(n - 1);
        }
        // First key strictly after t; t is inside (times[0], times[n-1]) so 1 <= k1 <= n-1.
        let k1 = self.times.partition_point(|&x| x <= t);
        let k0 = k1 - 1;
        let dt = self.times[k1] - self.times[k0];
        let u = if dt > 0.0 {
            (t - self.times[k0]) / dt
        } else {
            0.0
        };
        let rotation = self.property == ChannelProperty::Rotation;
        match self.interpolation {
            Interpolation::Step => self.value(k0),
            Interpolation::Linear if rotation => {
                let a = Quat::from_vec4(self.values[k0]);
                let b = Quat::from_vec4(self.values[k1]);
                Vec4::from(a.slerp(b, u))
            }
            Interpolation::Linear => self.values[k0].lerp(self.values[k1], u),
            Interpolation::CubicSpline => {
                let (u2, u3) = (u * u, u * u * u);
                let p0 = self.values[3 * k0 + 1];
                let m0 = self.values[3 * k0 + 2] * dt;
                let p1 = self.values[3 * k1 + 1];
                let m1 = self.values[3 * k1] * dt;
                let v = p0 * (2.0 * u3 - 3.0 * u2 + 1.0)
                    + m0 * (u3 - 2.0 * u2 + u)
                    + p1 * (-2.0 * u3 + 3.0 * u2)
                    + m1 * (u3 - u2);
                if rotation {
                    v.try_normalize().unwrap_or(p0)
                } else {
                    v
                }
            }
        }
    }

    fn apply(&self, t: f32, to: &mut Transform) {
        let v = self.sample(t);
        match self.property {
            ChannelProperty::Translation => to.translation = v.truncate(),
            ChannelProperty::Rotation => to.rotation = Quat::from_vec4(v).normalize(),
            ChannelProperty::Scale => to.scale = v.truncate(),
        }
    }
}

impl Clip {
    /// Local transforms of `nodes` at time `t`: `defaults[k]` with node `nodes[k]`'s channels
    /// applied (the general form behind [`Clip::sample`]).
    #[must_use]
    pub fn sample_nodes(&self, nodes: &[usize], defaults: &[Transform], t: f32) -> Vec<Transform> {
        let slot: HashMap<usize, usize> = nodes.iter().enumerate().map(|(k, &n)| (n, k)).collect();
        let mut out = defaults.to_vec();
        for ch in &self.channels {
            if let Some(x) = slot.get(&ch.node).and_then(|&k| out.get_mut(k)) {
                ch.apply(t, x);
            }
        }
        out
    }

    /// The pose of `skin`'s skeleton at time `t`. Joints without channels keep their node's
    /// default TRS (not `bind_local`). If the clip animates nodes above the skeleton roots,
    /// their motion is folded into the roots' locals (the skeleton's `base` is fixed).
    #[must_use]
    pub fn sample(&self, skin: &GltfSkin, t: f32) -> Pose {
        let mut locals = self.sample_nodes(&skin.joint_nodes, &skin.node_defaults, t);
        if self
            .channels
            .iter()
            .any(|c| skin.root_ancestors.contains(&c.node))
        {
            let above = self.sample_nodes(&skin.root_ancestors, &skin.root_ancestor_defaults, t);
            let animated = above
                .iter()
                .fold(glam::Mat4::IDENTITY, |m, x| m * x.to_mat4());
            let fold = skin.skeleton.base().inverse() * animated;
            for (j, p) in skin.skeleton.parents().iter().enumerate() {
                if p.is_none() {
                    locals[j] = Transform::from_mat4(&(fold * locals[j].to_mat4()));
                }
            }
        }
        Pose { locals }
    }

    /// The pose of any skeleton at time `t`, binding channels to joints by node *name*
    /// (animation packs list joints in another order). Joints without channels keep
    /// `defaults` (e.g. the skeleton's bind pose).
    #[must_use]
    pub fn sample_by_name(&self, skeleton: &Skeleton, defaults: &Pose, t: f32) -> Pose {
        let mut locals = defaults.locals.clone();
        for ch in &self.channels {
            if let Some(x) = skeleton.find(&ch.node_name).and_then(|j| locals.get_mut(j)) {
                ch.apply(t, x);
            }
        }
        Pose { locals }
    }

    /// One clip made of several played together (old exporters write one animation per
    /// joint, e.g. CesiumMan_legacy): channels concatenated, duration the longest.
    #[must_use]
    pub fn merged(name: &str, clips: &[Clip]) -> Clip {
        let channels: Vec<Channel> = clips
            .iter()
            .flat_map(|c| c.channels.iter().cloned())
            .collect();
        Clip {
            name: name.to_owned(),
            duration_s: clips.iter().map(|c| c.duration_s).fold(0.0, f32::max),
            frames: distinct_times(channels.iter().map(|c| c.times.as_slice())),
            weight_channels: clips.iter().map(|c| c.weight_channels).sum(),
            channels,
        }
    }
}

fn distinct_times<'a>(lists: impl Iterator<Item = &'a [f32]>) -> usize {
    let mut all: Vec<u32> = lists.flat_map(|l| l.iter().map(|t| t.to_bits())).collect();
    all.sort_unstable();
    all.dedup();
    all.len()
}

pub(crate) fn read_clip(src: &Source<'_>, anim: &gltf::Animation<'_>) -> Result<Clip, GltfError> {
    use gltf::animation::util::ReadOutputs;
    let ai = anim.index();
    let mut channels = Vec::new();
    let mut weight_channels = 0;
    let mut all_times: Vec<Vec<f32>> = Vec::new();
    let mut keys = 0usize;
    for ch in anim.channels() {
        let field = format!("animations[{ai}].channels[{}]", ch.index());
        {
            use gltf::accessor::{DataType as D, Dimensions as M};
            use gltf::animation::Property as P;
            let (input, output) = (ch.sampler().input(), ch.sampler().output());
            src.expect(
                &input,
                &[M::Scalar],
                &[D::F32],
                &format!("{field}.sampler.input"),
            )?;
            let of = format!("{field}.sampler.output");
            match ch.target().property() {
                P::Translation | P::Scale => src.expect(&output, &[M::Vec3], &[D::F32], &of)?,
                P::Rotation => src.expect(
                    &output,
                    &[M::Vec4],
                    &[D::F32, D::I8, D::U8, D::I16, D::U16],
                    &of,
                )?,
                P::MorphTargetWeights => src.expect(
                    &output,
                    &[M::Scalar],
                    &[D::F32, D::I8, D::U8, D::I16, D::U16],
                    &of,
                )?,
            }
        }
        let reader = ch.reader(src.data());
        let times: Vec<f32> = reader
            .read_inputs()
            .ok_or_else(|| src.field(format!("{field}.sampler.input"), "unreadable"))?
            .collect();
        keys = keys.saturating_add(times.len());
        if keys > MAX_CLIP_KEYS {
            return Err(GltfError::TooLarge {
                file: src.file.to_owned(),
                field: format!("animations[{ai}] keys"),
                count: keys as u64,
                cap: MAX_CLIP_KEYS as u64,
            });
        }
        if times.is_empty()
            || times.iter().any(|t| !t.is_finite())
            || times.windows(2).any(|w| w[1] < w[0])
        {
            return Err(src.field(
                format!("{field}.sampler.input"),
                "key times must be finite and non-decreasing",
            ));
        }
        let outputs = reader
            .read_outputs()
            .ok_or_else(|| src.field(format!("{field}.sampler.output"), "unreadable"))?;
        let (property, values): (ChannelProperty, Vec<Vec4>) = match outputs {
            ReadOutputs::Translations(it) => (
                ChannelProperty::Translation,
                it.map(|v| Vec3::from(v).extend(0.0)).collect(),
            ),
            ReadOutputs::Scales(it) => (
                ChannelProperty::Scale,
                it.map(|v| Vec3::from(v).extend(0.0)).collect(),
            ),
            ReadOutputs::Rotations(it) => (
                ChannelProperty::Rotation,
                it.into_f32().map(Vec4::from).collect(),
            ),
            ReadOutputs::MorphTargetWeights(_) => {
                weight_channels += 1;
                all_times.push(times);
                continue;
            }
        };
        let interpolation = match ch.sampler().interpolation() {
            gltf::animation::Interpolation::Linear => Interpolation::Linear,
            gltf::animation::Interpolation::Step => Interpolation::Step,
            gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
        };
        let per_key = if interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        if values.len() != times.len() * per_key {
            return Err(src.field(
                format!("{field}.sampler.output"),
                format!(
                    "{} values for {} keys ({per_key} per key expected)",
                    values.len(),
                    times.len()
                ),
            ));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(src.field(
                format!("{field}.sampler.output"),
                "holds a non-finite value",
            ));
        }
        if property == ChannelProperty::Rotation
            && (0..times.len()).any(|k| values[k * per_key + per_key / 2].length() < 1e-6)
        {
            return Err(src.field(
                format!("{field}.sampler.output"),
                "a rotation key is a zero quaternion",
            ));
        }
        let node = ch.target().node().index();
        all_times.push(times.clone());
        channels.push(Channel {
            node,
            node_name: src.nodes[node].name.clone(),
            property,
            interpolation,
            times,
            values,
        });
    }
    Ok(Clip {
        name: anim
            .name()
            .map_or_else(|| format!("animation_{ai}"), str::to_owned),
        duration_s: all_times
            .iter()
            .filter_map(|t| t.last().copied())
            .fold(0.0, f32::max),
        frames: distinct_times(all_times.iter().map(Vec::as_slice)),
        channels,
        weight_channels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(
        property: ChannelProperty,
        interpolation: Interpolation,
        times: &[f32],
        values: &[Vec4],
    ) -> Channel {
        Channel {
            node: 0,
            node_name: "n".into(),
            property,
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
        }
    }

    #[test]
    fn linear_step_and_holds() {
        let c = channel(
            ChannelProperty::Translation,
            Interpolation::Linear,
            &[1.0, 3.0],
            &[Vec4::ZERO, Vec4::new(2.0, 4.0, 6.0, 0.0)],
        );
        assert_eq!(c.sample(0.0), Vec4::ZERO);
        assert_eq!(c.sample(2.0), Vec4::new(1.0, 2.0, 3.0, 0.0));
        assert_eq!(c.sample(9.0), Vec4::new(2.0, 4.0, 6.0, 0.0));
        let s = Channel {
            interpolation: Interpolation::Step,
            ..c
        };
        assert_eq!(s.sample(2.9), Vec4::ZERO);
        assert_eq!(s.sample(3.0), Vec4::new(2.0, 4.0, 6.0, 0.0));
    }

    #[test]
    fn rotation_slerp_takes_the_short_arc_at_constant_speed() {
        let a = Quat::IDENTITY;
        // The same 90° turn about Z stored with a negative sign: slerp must not go the long way.
        let b = -Quat::from_rotation_z(core::f32::consts::FRAC_PI_2);
        let c = channel(
            ChannelProperty::Rotation,
            Interpolation::Linear,
            &[0.0, 1.0],
            &[Vec4::from(a), Vec4::from(b)],
        );
        let q = Quat::from_vec4(c.sample(0.25));
        let want = Quat::from_rotation_z(core::f32::consts::FRAC_PI_8);
        assert!(q.dot(want).abs() > 1.0 - 1e-6, "{q:?}");
    }

    #[test]
    fn cubic_spline_matches_the_hermite_basis() {
        // x(t) = t³ on [0, 2]: values 0 and 8, derivatives 0 and 12 (tangents are per second).
        let v = |x: f32| Vec4::new(x, 0.0, 0.0, 0.0);
        let c = channel(
            ChannelProperty::Translation,
            Interpolation::CubicSpline,
            &[0.0, 2.0],
            &[v(0.0), v(0.0), v(0.0), v(12.0), v(8.0), v(0.0)],
        );
        for t in [0.3f32, 1.0, 1.7] {
            assert!((c.sample(t).x - t * t * t).abs() < 1e-4, "t={t}");
        }
    }
}
