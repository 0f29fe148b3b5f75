//! The tokenizer and parser behind [`parse_bvh`]: whitespace-separated tokens for the
//! HIERARCHY block (so any line layout works), one frame per line in the MOTION block (so a
//! frame with a missing or extra value is caught on its own line).

use glam::{Mat4, Quat, Vec3};

use super::{
    BvhChannel, BvhEndSite, BvhError, BvhMotion, BvhOptions, MAX_CHANNELS_PER_JOINT, MAX_END_SITES,
    MAX_FRAMES, MAX_POSE_TRANSFORMS,
};
use crate::math::Transform;
use crate::pose::Pose;
use crate::skeleton::{Axis, JointDofs, MAX_JOINTS, Skeleton};

/// Longest excerpt of offending text an error carries.
const SHOWN: usize = 40;

fn shown(s: &str) -> String {
    s.chars().take(SHOWN).collect()
}

fn unexpected(line: usize, expected: &'static str, found: &str) -> BvhError {
    BvhError::Unexpected {
        line,
        expected,
        found: shown(found),
    }
}

/// Whitespace-separated tokens with their 1-based line numbers.
struct Lexer<'a> {
    text: &'a str,
    pos: usize,
    line: usize,
}

impl<'a> Lexer<'a> {
    fn new(text: &'a str) -> Self {
        Self {
            text,
            pos: 0,
            line: 1,
        }
    }

    fn next(&mut self) -> Option<(&'a str, usize)> {
        let b = self.text.as_bytes();
        while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
            if b[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        if self.pos == b.len() {
            return None;
        }
        let start = self.pos;
        while self.pos < b.len() && !b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        // Both ends sit next to ASCII whitespace or at the ends: char boundaries.
        Some((&self.text[start..self.pos], self.line))
    }

    fn token(&mut self, expected: &'static str) -> Result<(&'a str, usize), BvhError> {
        self.next().ok_or(BvhError::UnexpectedEof {
            line: self.line,
            expected,
        })
    }

    fn keyword(&mut self, keyword: &'static str) -> Result<usize, BvhError> {
        let (t, line) = self.token(keyword)?;
        if t.eq_ignore_ascii_case(keyword) {
            Ok(line)
        } else {
            Err(unexpected(line, keyword, t))
        }
    }

    /// A label such as `Frame Time:` however it is split into tokens (`Frame Time:`,
    /// `Frame Time :`); `compact` is the label without spaces.
    fn label(&mut self, compact: &'static str, expected: &'static str) -> Result<(), BvhError> {
        let mut matched = 0;
        while matched < compact.len() {
            let (t, line) = self.token(expected)?;
            let rest = &compact.as_bytes()[matched..];
            if t.len() > rest.len() || !rest[..t.len()].eq_ignore_ascii_case(t.as_bytes()) {
                return Err(unexpected(line, expected, t));
            }
            matched += t.len();
        }
        Ok(())
    }

    fn number(&mut self, field: &'static str) -> Result<f32, BvhError> {
        let (t, line) = self.token(field)?;
        let v: f32 = t.parse().map_err(|_| BvhError::BadNumber {
            line,
            field,
            text: shown(t),
        })?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(BvhError::NonFinite { line, field })
        }
    }

    /// An `OFFSET`'s three numbers, scaled.
    fn offset(&mut self, scale: f32) -> Result<Vec3, BvhError> {
        let v = Vec3::new(
            self.number("OFFSET")?,
            self.number("OFFSET")?,
            self.number("OFFSET")?,
        ) * scale;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(BvhError::NonFinite {
                line: self.line,
                field: "OFFSET",
            })
        }
    }
}

struct JointRec<'a> {
    name: &'a str,
    parent: Option<usize>,
    offset: Option<Vec3>,
    channels: Option<Vec<BvhChannel>>,
}

/// An open `{ … }` block.
#[derive(Clone, Copy)]
enum Open {
    Joint(usize),
    EndSite { parent: usize, offset: Option<Vec3> },
}

fn open_joint<'a>(
    lx: &mut Lexer<'a>,
    joints: &mut Vec<JointRec<'a>>,
    stack: &mut Vec<Open>,
    parent: Option<usize>,
) -> Result<(), BvhError> {
    let (name, line) = lx.token("joint name")?;
    if name == "{" || name == "}" {
        return Err(unexpected(line, "joint name", name));
    }
    if joints.len() >= MAX_JOINTS {
        return Err(BvhError::TooMany {
            line,
            what: "joints",
            max: MAX_JOINTS,
        });
    }
    lx.keyword("{")?;
    stack.push(Open::Joint(joints.len()));
    joints.push(JointRec {
        name,
        parent,
        offset: None,
        channels: None,
    });
    Ok(())
}

/// A `CHANNELS n c₀ … cₙ₋₁` line, after the keyword.
fn channels(lx: &mut Lexer<'_>, joint: &str) -> Result<Vec<BvhChannel>, BvhError> {
    let (t, line) = lx.token("channel count")?;
    let count: u64 = t.parse().map_err(|_| BvhError::BadNumber {
        line,
        field: "CHANNELS",
        text: shown(t),
    })?;
    if count > MAX_CHANNELS_PER_JOINT as u64 {
        return Err(BvhError::ChannelCount {
            line,
            joint: joint.to_owned(),
            count,
        });
    }
    let mut out = Vec::with_capacity(count as usize);
    for _ in 0..count {
        let (t, line) = lx.token("channel name")?;
        let c = BvhChannel::from_name(t).ok_or_else(|| BvhError::UnknownChannel {
            line,
            joint: joint.to_owned(),
            found: shown(t),
        })?;
        if out.contains(&c) {
            return Err(BvhError::DuplicateChannel {
                line,
                joint: joint.to_owned(),
                channel: c,
            });
        }
        out.push(c);
    }
    Ok(out)
}

/// Parses the HIERARCHY block up to and including the `MOTION` keyword.
fn hierarchy<'a>(
    lx: &mut Lexer<'a>,
    scale: f32,
) -> Result<(Vec<JointRec<'a>>, Vec<BvhEndSite>), BvhError> {
    lx.keyword("HIERARCHY")?;
    let mut joints: Vec<JointRec<'a>> = Vec::new();
    let mut end_sites = Vec::new();
    // Depth is bounded by MAX_JOINTS + 1: every open block but an End Site is a joint.
    let mut stack: Vec<Open> = Vec::new();
    loop {
        let Some(&top) = stack.last() else {
            let expected = if joints.is_empty() {
                "ROOT"
            } else {
                "ROOT or MOTION"
            };
            let (t, line) = lx.token(expected)?;
            if t.eq_ignore_ascii_case("ROOT") {
                open_joint(lx, &mut joints, &mut stack, None)?;
            } else if t.eq_ignore_ascii_case("MOTION") && !joints.is_empty() {
                return Ok((joints, end_sites));
            } else {
                return Err(unexpected(line, expected, t));
            }
            continue;
        };
        match top {
            Open::Joint(j) => {
                let (t, line) = lx.token("OFFSET, CHANNELS, JOINT, End Site or }")?;
                let dup = |field| BvhError::DuplicateField {
                    line,
                    joint: joints[j].name.to_owned(),
                    field,
                };
                if t.eq_ignore_ascii_case("OFFSET") {
                    if joints[j].offset.is_some() {
                        return Err(dup("OFFSET"));
                    }
                    joints[j].offset = Some(lx.offset(scale)?);
                } else if t.eq_ignore_ascii_case("CHANNELS") {
                    if joints[j].channels.is_some() {
                        return Err(dup("CHANNELS"));
                    }
                    joints[j].channels = Some(channels(lx, joints[j].name)?);
                } else if t.eq_ignore_ascii_case("JOINT") {
                    open_joint(lx, &mut joints, &mut stack, Some(j))?;
                } else if t.eq_ignore_ascii_case("End") {
                    lx.keyword("Site")?;
                    if end_sites.len() >= MAX_END_SITES {
                        return Err(BvhError::TooMany {
                            line,
                            what: "End Sites",
                            max: MAX_END_SITES,
                        });
                    }
                    lx.keyword("{")?;
                    stack.push(Open::EndSite {
                        parent: j,
                        offset: None,
                    });
                } else if t == "}" {
                    if joints[j].offset.is_none() {
                        return Err(BvhError::MissingOffset {
                            line,
                            joint: joints[j].name.to_owned(),
                        });
                    }
                    stack.pop();
                } else {
                    return Err(unexpected(
                        line,
                        "OFFSET, CHANNELS, JOINT, End Site or }",
                        t,
                    ));
                }
            }
            Open::EndSite { parent, offset } => {
                let (t, line) = lx.token("OFFSET or }")?;
                if t.eq_ignore_ascii_case("OFFSET") {
                    if offset.is_some() {
                        return Err(BvhError::DuplicateField {
                            line,
                            joint: "End Site".into(),
                            field: "OFFSET",
                        });
                    }
                    let offset = Some(lx.offset(scale)?);
                    stack.pop();
                    stack.push(Open::EndSite { parent, offset });
                } else if t == "}" {
                    let offset = offset.ok_or_else(|| BvhError::MissingOffset {
                        line,
                        joint: "End Site".into(),
                    })?;
                    end_sites.push(BvhEndSite { parent, offset });
                    stack.pop();
                } else {
                    return Err(unexpected(line, "OFFSET or }", t));
                }
            }
        }
    }
}

/// The pose of one frame: `values` holds the frame's channel values in file order.
fn frame_pose(
    skeleton: &Skeleton,
    channels: &[Vec<BvhChannel>],
    values: &[f32],
    scale: f32,
    (line, frame): (usize, usize),
) -> Result<Pose, BvhError> {
    let mut locals = skeleton.bind_local().to_vec();
    let mut k = 0;
    for (j, (local, chans)) in locals.iter_mut().zip(channels).enumerate() {
        let mut rotation = Quat::IDENTITY;
        let mut translation = Vec3::ZERO;
        for &c in chans {
            let v = values[k];
            k += 1;
            if c.is_rotation() {
                rotation *= Quat::from_axis_angle(c.axis().unit(), v.to_radians());
            } else {
                let a = match c.axis() {
                    Axis::X => 0,
                    Axis::Y => 1,
                    Axis::Z => 2,
                };
                translation[a] += v;
            }
        }
        local.rotation = rotation.normalize();
        local.translation += translation * scale;
        if !local.translation.is_finite() {
            return Err(BvhError::NonFiniteTranslation {
                line,
                frame,
                joint: skeleton.names()[j].clone(),
            });
        }
    }
    Ok(Pose { locals })
}

/// Parses BVH text: the hierarchy into a [`Skeleton`], every frame into a [`Pose`].
///
/// Never panics and never allocates from an unchecked count (module docs); every error names
/// the line.
pub fn parse_bvh(text: &str, options: &BvhOptions) -> Result<BvhMotion, BvhError> {
    let scale = options.unit_scale;
    if !(scale.is_finite() && scale > 0.0) {
        return Err(BvhError::BadUnitScale(scale));
    }
    let mut lx = Lexer::new(text);
    let (joints, end_sites) = hierarchy(&mut lx, scale)?;

    lx.label("Frames:", "Frames:")?;
    let (t, count_line) = lx.token("frame count")?;
    let declared: u64 = t.parse().map_err(|_| BvhError::BadNumber {
        line: count_line,
        field: "Frames",
        text: shown(t),
    })?;
    let too_many = || BvhError::TooManyFrames {
        line: count_line,
        frames: declared,
        joints: joints.len(),
    };
    let frames = usize::try_from(declared)
        .ok()
        .filter(|&f| f <= MAX_FRAMES)
        .ok_or_else(too_many)?;
    if frames
        .checked_mul(joints.len())
        .is_none_or(|n| n > MAX_POSE_TRANSFORMS)
    {
        return Err(too_many());
    }
    lx.label("FrameTime:", "Frame Time:")?;
    let (t, line) = lx.token("Frame Time")?;
    let frame_time: f32 = t.parse().map_err(|_| BvhError::BadNumber {
        line,
        field: "Frame Time",
        text: shown(t),
    })?;
    if !(frame_time.is_finite() && frame_time > 0.0) {
        return Err(BvhError::BadFrameTime {
            line,
            value: frame_time,
        });
    }

    let channels: Vec<Vec<BvhChannel>> = joints
        .iter()
        .map(|j| j.channels.clone().unwrap_or_default())
        .collect();
    let channel_count: usize = channels.iter().map(Vec::len).sum();
    // A value takes at least two bytes (a separator and a digit), an empty frame one line
    // break: this bounds every allocation below by the text's own size.
    let rest = &text[lx.pos..];
    let room = if channel_count == 0 {
        rest.len()
    } else {
        rest.len().div_ceil(2)
    };
    if frames
        .checked_mul(channel_count.max(1))
        .is_none_or(|n| n > room)
    {
        return Err(BvhError::FramesExceedData {
            line,
            frames: declared,
            channels: channel_count,
            bytes: rest.len(),
        });
    }

    let dofs = channels
        .iter()
        .map(|c| {
            let axes: Vec<Axis> = c
                .iter()
                .filter(|c| c.is_rotation())
                .map(|c| c.axis())
                .collect();
            if axes.is_empty() {
                JointDofs::Fixed
            } else {
                let limits = vec![[-core::f32::consts::PI, core::f32::consts::PI]; axes.len()];
                JointDofs::Euler { axes, limits }
            }
        })
        .collect();
    let skeleton = Skeleton::new(
        joints.iter().map(|j| j.name.to_owned()).collect(),
        joints.iter().map(|j| j.parent).collect(),
        joints
            .iter()
            .map(|j| Transform::from_translation(j.offset.unwrap_or(Vec3::ZERO)))
            .collect(),
        None,
        Some(dofs),
        Mat4::IDENTITY,
    )?;
    // Which joint and channel each value of a frame belongs to.
    let owners: Vec<(usize, BvhChannel)> = channels
        .iter()
        .enumerate()
        .flat_map(|(j, c)| c.iter().map(move |&c| (j, c)))
        .collect();

    let mut values = Vec::with_capacity(frames * channel_count);
    let mut poses = Vec::with_capacity(frames);
    let mut last_line = lx.line;
    for (k, piece) in rest.split('\n').enumerate() {
        let line = lx.line + k;
        last_line = line;
        if piece.trim_ascii().is_empty() {
            continue;
        }
        if channel_count == 0 || poses.len() == frames {
            return Err(BvhError::TrailingData { line, frames });
        }
        let frame = poses.len();
        let start = values.len();
        let mut found = 0;
        for tok in piece.split_ascii_whitespace() {
            if let Some(&(j, channel)) = owners.get(found) {
                let v = tok
                    .parse::<f32>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| BvhError::BadChannelValue {
                        line,
                        frame,
                        joint: joints[j].name.to_owned(),
                        channel,
                        text: shown(tok),
                    })?;
                values.push(v);
            }
            found += 1;
        }
        if found != channel_count {
            return Err(BvhError::FrameChannelCount {
                line,
                frame,
                expected: channel_count,
                found,
            });
        }
        poses.push(frame_pose(
            &skeleton,
            &channels,
            &values[start..],
            scale,
            (line, frame),
        )?);
    }
    if channel_count == 0 {
        poses.resize(frames, skeleton.bind_pose());
    }
    if poses.len() != frames {
        return Err(BvhError::MissingFrames {
            line: last_line,
            expected: frames,
            found: poses.len(),
        });
    }
    Ok(BvhMotion {
        skeleton,
        frame_time,
        poses,
        channels,
        values,
        end_sites,
    })
}
