//! Building `.skf` bytes and writing them atomically.

use std::io::Write;
use std::path::{Path, PathBuf};

use half::f16;

use super::config::{ModelConfig, Net};
use super::view::{LayerName, SkfView, tensor_name};
use super::*;
use super::{Dtype, SkfError, TensorName};
use crate::skeleton::Skeleton;

/// An owned model ready to be written: configuration, skeleton and f32 tensors (stored as f16).
#[derive(Clone, Debug)]
pub struct SkfModel {
    /// Network configuration.
    pub config: ModelConfig,
    /// Skeleton (its joint order is SkinNet's output order).
    pub skeleton: Skeleton,
    /// `(name, dims, values)`; dims `[n]` or `[out, in]`.
    pub tensors: Vec<(String, Vec<usize>, Vec<f32>)>,
    /// The candidate joints of canonical anchors (the `CAND` section), if any.
    pub candidates: Option<Candidates>,
    /// The training range of the pose features (the `PRNG` section), if any.
    pub pose_range: Option<PoseRange>,
}

/// Per pose feature, the smallest and largest value SkinNet was trained on.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseRange {
    /// Lower bounds, one per pose feature.
    pub low: Vec<f32>,
    /// Upper bounds, one per pose feature.
    pub high: Vec<f32>,
}

impl PoseRange {
    /// The per-feature minimum and maximum over `poses` (each `features` long); `None` without
    /// poses.
    #[must_use]
    pub fn of<'a>(features: usize, poses: impl IntoIterator<Item = &'a [f32]>) -> Option<Self> {
        let mut range: Option<Self> = None;
        for theta in poses {
            let r = range.get_or_insert_with(|| Self {
                low: vec![f32::INFINITY; features],
                high: vec![f32::NEG_INFINITY; features],
            });
            for ((lo, hi), &v) in r.low.iter_mut().zip(&mut r.high).zip(theta) {
                *lo = lo.min(v);
                *hi = hi.max(v);
            }
        }
        range
    }
}

/// Anchors in the canonical space and the joints a point near each may be skinned to.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidates {
    /// Canonical anchor positions.
    pub positions: Vec<[f32; 3]>,
    /// Per anchor, its candidate joints (ascending, at most `k`).
    pub lists: Vec<Vec<u16>>,
    /// List slots per anchor.
    pub k: usize,
}

/// A `.skf` read or write failure, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum SkfFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The bytes are not a valid `.skf`.
    #[error("{path}: {source}")]
    Format {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: SkfError,
    },
    /// The model to write is inconsistent (a tensor name too long, a shape mismatch, …).
    #[error("cannot write .skf: {0}")]
    Invalid(String),
}

impl SkfModel {
    /// Adds the weight and bias of layer `layer` of `net` (`layer == hidden count` is the output
    /// layer); `weight` is row-major `[out, in]`.
    pub fn push_layer(
        &mut self,
        net: Net,
        layer: usize,
        weight: Vec<f32>,
        out: usize,
        inp: usize,
        bias: Vec<f32>,
    ) {
        let n = self.config.hidden_widths().len();
        let l = if layer < n {
            LayerName::Hidden(layer)
        } else {
            LayerName::Out
        };
        self.tensors.push((
            tensor_name(net, l, "weight").as_str().to_string(),
            vec![out, inp],
            weight,
        ));
        self.tensors.push((
            tensor_name(net, l, "bias").as_str().to_string(),
            vec![out],
            bias,
        ));
    }

    /// Serialises the model (tensors as f16) and checks the result with [`SkfView::parse`].
    pub fn to_bytes(&self) -> Result<Vec<u8>, SkfFileError> {
        let invalid = |m: String| SkfFileError::Invalid(m);
        self.config.validate().map_err(|e| invalid(e.to_string()))?;
        if self.skeleton.len() != self.config.joint_count as usize {
            return Err(invalid(format!(
                "skeleton has {} joints, config {}",
                self.skeleton.len(),
                self.config.joint_count
            )));
        }
        // SKEL.
        let mut names = Vec::new();
        let mut records = Vec::new();
        for j in 0..self.skeleton.len() {
            let mut r = [0u8; JOINT_RECORD_LEN];
            let parent = self.skeleton.parents()[j].map_or(u32::MAX, |p| p as u32);
            let name = self.skeleton.names()[j].as_bytes();
            r[0..4].copy_from_slice(&parent.to_le_bytes());
            r[4..8].copy_from_slice(&(names.len() as u32).to_le_bytes());
            r[8..12].copy_from_slice(&(name.len() as u32).to_le_bytes());
            names.extend_from_slice(name);
            let t = self.skeleton.bind_local()[j];
            let floats = t
                .translation
                .to_array()
                .into_iter()
                .chain(t.rotation.to_array())
                .chain(t.scale.to_array());
            for (k, f) in floats
                .chain(self.skeleton.inverse_bind()[j].to_cols_array())
                .enumerate()
            {
                r[16 + 4 * k..20 + 4 * k].copy_from_slice(&f.to_le_bytes());
            }
            records.extend_from_slice(&r);
        }
        let mut skel = Vec::with_capacity(SKEL_HEADER_LEN + records.len() + names.len());
        skel.extend_from_slice(&(self.skeleton.len() as u32).to_le_bytes());
        skel.extend_from_slice(&(names.len() as u32).to_le_bytes());
        skel.extend_from_slice(&[0; 8]);
        for f in self.skeleton.base().to_cols_array() {
            skel.extend_from_slice(&f.to_le_bytes());
        }
        skel.extend_from_slice(&records);
        skel.extend_from_slice(&names);

        // TINF + DATA.
        let mut tinf = Vec::new();
        tinf.extend_from_slice(&(self.tensors.len() as u32).to_le_bytes());
        tinf.extend_from_slice(&[0; 4]);
        let mut data: Vec<u8> = Vec::new();
        for (name, dims, values) in &self.tensors {
            let stored = TensorName::new(name).ok_or_else(|| {
                invalid(format!("tensor name `{name}` is empty or over 24 bytes"))
            })?;
            let elems: usize = dims.iter().product();
            if dims.is_empty() || dims.len() > 2 || elems != values.len() || elems == 0 {
                return Err(invalid(format!(
                    "tensor `{name}` has dims {dims:?} but {} values",
                    values.len()
                )));
            }
            // f16 saturates to infinity above 65504: refuse rather than store a value the
            // runtime would read back as inf.
            if let Some(i) = values
                .iter()
                .position(|v| !(v.is_finite() && v.abs() <= f32::from(f16::MAX)))
            {
                return Err(invalid(format!(
                    "tensor `{name}` has a value at {i} that is not finite in f16"
                )));
            }
            let offset = align_up(data.len()).ok_or_else(|| invalid("DATA too large".into()))?;
            data.resize(offset, 0);
            for v in values {
                data.extend_from_slice(&f16::from_f32(*v).to_le_bytes());
            }
            let mut e = [0u8; TENSOR_ENTRY_LEN];
            e[..24].copy_from_slice(&stored.0);
            e[24..28].copy_from_slice(&Dtype::F16.code().to_le_bytes());
            e[28..32].copy_from_slice(&(dims.len() as u32).to_le_bytes());
            for (k, d) in dims.iter().enumerate() {
                e[32 + 4 * k..36 + 4 * k].copy_from_slice(&(*d as u32).to_le_bytes());
            }
            e[48..56].copy_from_slice(&(offset as u64).to_le_bytes());
            e[56..64].copy_from_slice(&((2 * elems) as u64).to_le_bytes());
            tinf.extend_from_slice(&e);
        }

        let conf = self.config.to_bytes();
        let cand = match &self.candidates {
            Some(c) if c.positions.len() != c.lists.len() => {
                return Err(invalid(format!(
                    "{} anchors but {} candidate lists",
                    c.positions.len(),
                    c.lists.len()
                )));
            }
            Some(c) if c.lists.iter().any(|l| l.len() > c.k) => {
                return Err(invalid(format!(
                    "a candidate list is longer than k = {}",
                    c.k
                )));
            }
            Some(c) => Some(candidates::cand_bytes(&c.positions, &c.lists, c.k)),
            None => None,
        };
        let prng = match &self.pose_range {
            Some(r) if r.low.len() != r.high.len() => {
                return Err(invalid(format!(
                    "pose range has {} lower and {} upper bounds",
                    r.low.len(),
                    r.high.len()
                )));
            }
            Some(r) => Some(pose_range::prng_bytes(&r.low, &r.high)),
            None => None,
        };
        let mut sections: Vec<(&[u8; 4], &[u8])> = vec![
            (&tag::CONF, &conf),
            (&tag::SKEL, &skel),
            (&tag::TINF, &tinf),
            (&tag::DATA, &data),
        ];
        if let Some(c) = &cand {
            sections.push((&tag::CAND, c));
        }
        if let Some(r) = &prng {
            sections.push((&tag::PRNG, r));
        }
        let mut out = vec![0u8; HEADER_LEN + SECTION_ENTRY_LEN * sections.len()];
        for (s, (t, body)) in sections.iter().enumerate() {
            let offset = align_up(out.len()).ok_or_else(|| invalid("file too large".into()))?;
            out.resize(offset, 0);
            out.extend_from_slice(body);
            let e = HEADER_LEN + s * SECTION_ENTRY_LEN;
            out[e..e + 4].copy_from_slice(*t);
            out[e + 8..e + 16].copy_from_slice(&(offset as u64).to_le_bytes());
            out[e + 16..e + 24].copy_from_slice(&(body.len() as u64).to_le_bytes());
        }
        out[..8].copy_from_slice(&MAGIC);
        out[8..10].copy_from_slice(&VERSION_MAJOR.to_le_bytes());
        let minor = match (&cand, &prng) {
            (_, Some(_)) => VERSION_MINOR,
            (Some(_), None) => 1,
            (None, None) => 0,
        };
        out[10..12].copy_from_slice(&minor.to_le_bytes());
        out[12..16].copy_from_slice(&(sections.len() as u32).to_le_bytes());
        let len = out.len() as u64;
        out[16..24].copy_from_slice(&len.to_le_bytes());
        let sum = file_checksum(&out);
        out[24..32].copy_from_slice(&sum.to_le_bytes());
        SkfView::parse(&out)
            .map_err(|e| invalid(format!("written file does not validate: {e}")))?;
        Ok(out)
    }

    /// Writes the model to `path` atomically.
    pub fn write(&self, path: &Path) -> Result<(), SkfFileError> {
        let bytes = self.to_bytes()?;
        write_atomic(path, &bytes).map_err(|source| SkfFileError::Io {
            path: path.to_owned(),
            source,
        })
    }
}

/// Reads a whole `.skf` file and validates it, returning its bytes (parse them again with
/// [`SkfView::parse`] to borrow; validation is cheap next to any use of the model).
pub fn read_skf_file(path: &Path) -> Result<Vec<u8>, SkfFileError> {
    let bytes = std::fs::read(path).map_err(|source| SkfFileError::Io {
        path: path.to_owned(),
        source,
    })?;
    SkfView::parse(&bytes).map_err(|source| SkfFileError::Format {
        path: path.to_owned(),
        source,
    })?;
    Ok(bytes)
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so a
/// reader never sees a partial file and a failure leaves any previous file intact.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .ok_or_else(|| std::io::Error::other("path has no file name"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(".{}.tmp", std::process::id()));
    let tmp = dir.join(tmp_name);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Transform;
    use glam::Mat4;

    #[test]
    fn refuses_values_that_overflow_f16() {
        let skeleton = Skeleton::new(
            vec!["root".into()],
            vec![None],
            vec![Transform::IDENTITY],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap();
        let mut config = ModelConfig::paper_architecture(1, [-1.0; 3], [1.0; 3]);
        config.hidden_count = 1;
        config.hidden = [4, 0, 0, 0, 0, 0, 0, 0];
        config.skip_layer = 0;
        let mut model = SkfModel {
            config,
            skeleton,
            tensors: Vec::new(),
            candidates: None,
            pose_range: None,
        };
        for (i, (out, inp)) in config.layer_shapes(Net::Skin).enumerate() {
            model.push_layer(Net::Skin, i, vec![0.5; out * inp], out, inp, vec![0.0; out]);
        }
        model.to_bytes().unwrap();
        model.tensors[0].2[3] = 70000.0;
        assert!(matches!(model.to_bytes(), Err(SkfFileError::Invalid(m)) if m.contains("f16")));
    }
}
