//! Static (pose-independent) skinning weights, stored sparse with any number of influences.

use alloc::vec::Vec;

/// Why skinning weights are invalid.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SkinError {
    /// `offsets` is not `vertices + 1` long, does not start at 0, decreases, or overruns.
    #[error("skin offsets are malformed at vertex {0}")]
    BadOffsets(usize),
    /// `joints` and `weights` differ in length.
    #[error("skin has {joints} joint indices but {weights} weights")]
    LengthMismatch {
        /// Joint index count.
        joints: usize,
        /// Weight count.
        weights: usize,
    },
    /// A joint index is not below the joint count.
    #[error("vertex {vertex} refers to joint {joint}, but the skeleton has {joint_count}")]
    JointOutOfRange {
        /// The vertex.
        vertex: usize,
        /// The bad joint index.
        joint: u32,
        /// Joint count.
        joint_count: usize,
    },
    /// A weight is negative, NaN or infinite.
    #[error("vertex {vertex} has an invalid weight {weight}")]
    BadWeight {
        /// The vertex.
        vertex: usize,
        /// The weight.
        weight: f32,
    },
    /// A vertex's weights sum to zero.
    #[error("vertex {0} has no influence with a positive weight")]
    NoInfluence(usize),
}

/// Sparse per-vertex skinning weights (CSR layout), normalised to sum to one per vertex.
#[derive(Clone, Debug, PartialEq)]
pub struct StaticSkin {
    offsets: Vec<u32>,
    joints: Vec<u32>,
    weights: Vec<f32>,
    joint_count: usize,
    unnormalized: usize,
}

impl StaticSkin {
    /// Validates and normalises sparse weights: vertex `v`'s influences are
    /// `joints[offsets[v]..offsets[v+1]]` with `weights[..]` alike. Zero weights are kept (they
    /// cost nothing and keep the caller's layout); a vertex whose weights do not sum to one
    /// within 1e-3 is normalised and counted in [`StaticSkin::unnormalized_count`].
    pub fn new(
        offsets: Vec<u32>,
        joints: Vec<u32>,
        mut weights: Vec<f32>,
        joint_count: usize,
    ) -> Result<Self, SkinError> {
        if joints.len() != weights.len() {
            return Err(SkinError::LengthMismatch {
                joints: joints.len(),
                weights: weights.len(),
            });
        }
        if offsets.first() != Some(&0) {
            return Err(SkinError::BadOffsets(0));
        }
        if *offsets.last().unwrap_or(&0) as usize != joints.len() {
            return Err(SkinError::BadOffsets(offsets.len().saturating_sub(1)));
        }
        let mut unnormalized = 0;
        for v in 0..offsets.len() - 1 {
            let (a, b) = (offsets[v] as usize, offsets[v + 1] as usize);
            if b < a || b > joints.len() {
                return Err(SkinError::BadOffsets(v));
            }
            let mut sum = 0.0f64;
            for k in a..b {
                if joints[k] as usize >= joint_count {
                    return Err(SkinError::JointOutOfRange {
                        vertex: v,
                        joint: joints[k],
                        joint_count,
                    });
                }
                let w = weights[k];
                if !(w.is_finite() && w >= 0.0) {
                    return Err(SkinError::BadWeight {
                        vertex: v,
                        weight: w,
                    });
                }
                sum += f64::from(w);
            }
            if sum <= 0.0 {
                return Err(SkinError::NoInfluence(v));
            }
            if (sum - 1.0).abs() > 1e-3 {
                unnormalized += 1;
            }
            for w in &mut weights[a..b] {
                *w = (f64::from(*w) / sum) as f32;
            }
        }
        Ok(Self {
            offsets,
            joints,
            weights,
            joint_count,
            unnormalized,
        })
    }

    /// Builds a skin from a dense `vertices × joint_count` row-major matrix, dropping zeros.
    pub fn from_dense(dense: &[f32], joint_count: usize) -> Result<Self, SkinError> {
        let mut offsets = alloc::vec![0u32];
        let mut joints = Vec::new();
        let mut weights = Vec::new();
        if joint_count == 0 {
            return Err(SkinError::NoInfluence(0));
        }
        for row in dense.chunks(joint_count) {
            for (j, &w) in row.iter().enumerate() {
                if w != 0.0 {
                    joints.push(j as u32);
                    weights.push(w);
                }
            }
            offsets.push(joints.len() as u32);
        }
        Self::new(offsets, joints, weights, joint_count)
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Number of joints the indices refer to.
    #[must_use]
    pub fn joint_count(&self) -> usize {
        self.joint_count
    }

    /// Joint indices and normalised weights of vertex `v`.
    #[must_use]
    pub fn influences(&self, v: usize) -> (&[u32], &[f32]) {
        let (a, b) = (self.offsets[v] as usize, self.offsets[v + 1] as usize);
        (&self.joints[a..b], &self.weights[a..b])
    }

    /// CSR offsets (`vertex_count + 1` entries).
    #[must_use]
    pub fn offsets(&self) -> &[u32] {
        &self.offsets
    }

    /// All joint indices, CSR order.
    #[must_use]
    pub fn joints(&self) -> &[u32] {
        &self.joints
    }

    /// All weights, CSR order.
    #[must_use]
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// Largest number of stored influences on any vertex.
    #[must_use]
    pub fn max_influences(&self) -> usize {
        self.offsets
            .windows(2)
            .map(|w| (w[1] - w[0]) as usize)
            .max()
            .unwrap_or(0)
    }

    /// How many vertices had weights that did not sum to one in the input.
    #[must_use]
    pub fn unnormalized_count(&self) -> usize {
        self.unnormalized
    }

    /// Dense `vertices × joint_count` row-major weights.
    #[must_use]
    pub fn to_dense(&self) -> Vec<f32> {
        let mut d = alloc::vec![0.0; self.vertex_count() * self.joint_count];
        for v in 0..self.vertex_count() {
            let (j, w) = self.influences(v);
            for (&j, &w) in j.iter().zip(w) {
                d[v * self.joint_count + j as usize] += w;
            }
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    #[test]
    fn normalises_and_counts() {
        let s = StaticSkin::new(vec![0, 2, 3], vec![0, 1, 1], vec![1.0, 3.0, 1.0], 2).unwrap();
        assert_eq!(s.influences(0).1, &[0.25, 0.75]);
        assert_eq!(s.unnormalized_count(), 1);
        assert_eq!(s.max_influences(), 2);
        assert_eq!(s.to_dense(), vec![0.25, 0.75, 0.0, 1.0]);
        let back = StaticSkin::from_dense(&s.to_dense(), 2).unwrap();
        assert_eq!(back.to_dense(), s.to_dense());
    }

    #[test]
    fn rejects_every_invalid_configuration() {
        assert!(matches!(
            StaticSkin::new(vec![0, 1], vec![0], vec![], 1),
            Err(SkinError::LengthMismatch { .. })
        ));
        assert!(matches!(
            StaticSkin::new(vec![1, 1], vec![0], vec![1.0], 1),
            Err(SkinError::BadOffsets(0))
        ));
        assert!(matches!(
            StaticSkin::new(vec![0, 2], vec![0], vec![1.0], 1),
            Err(SkinError::BadOffsets(_))
        ));
        assert!(matches!(
            StaticSkin::new(vec![0, 1, 0, 1], vec![0], vec![1.0], 1),
            Err(SkinError::BadOffsets(1))
        ));
        assert!(matches!(
            StaticSkin::new(vec![0, 1], vec![3], vec![1.0], 2),
            Err(SkinError::JointOutOfRange { joint: 3, .. })
        ));
        assert!(matches!(
            StaticSkin::new(vec![0, 1], vec![0], vec![f32::NAN], 1),
            Err(SkinError::BadWeight { .. })
        ));
        assert!(matches!(
            StaticSkin::new(vec![0, 1], vec![0], vec![-1.0], 1),
            Err(SkinError::BadWeight { .. })
        ));
        assert!(matches!(
            StaticSkin::new(vec![0, 1], vec![0], vec![0.0], 1),
            Err(SkinError::NoInfluence(0))
        ));
        assert!(matches!(
            StaticSkin::new(vec![0, 0], vec![], vec![], 1),
            Err(SkinError::NoInfluence(0))
        ));
    }
}
