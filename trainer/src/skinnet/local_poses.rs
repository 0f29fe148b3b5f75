//! A pose input per row, kept in the structure pose locality gives it: each row holds its
//! frame's features for the vertex's relevant joints and one donor pose's features for all the
//! others ([`crate::train::pose_locality`]).
//!
//! Written out, that input is `[B·V, 3J]` floats, and the network's input layers multiply all of
//! it: `3J × out` multiply-adds per row and layer, which on a 163-joint rig is about as much as
//! the rest of the network. Kept structured, the product of row `(b, v)` with donor `d` is
//!
//! ```text
//! pose_row · Wᵀ = pool_d · Wᵀ + Σ_{j relevant to v} Σ_{k<3} (frame_b[3j+k] − pool_d[3j+k]) · W[:, 3j+k]
//! ```
//!
//! one `[D, out]` product for the whole pool plus `3 × (relevant joints) × out` per row (8
//! candidate joints: 24 columns instead of `3J`), and the weight gradient splits the same way.
//! [`LocalPoses::rows`] writes the dense rows for the candle graph and for the tests that check
//! the two forms agree.

use rand::Rng;

/// Why a [`LocalPoses`] cannot be built.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LocalPosesError {
    /// No joints, or `relevant` is not `V × J`.
    #[error("relevant has {len} entries, not a multiple of {joints} joints")]
    Relevant {
        /// Its length.
        len: usize,
        /// Joints.
        joints: usize,
    },
    /// A frame's or a donor's pose is not `3J` long.
    #[error("a pose has {len} features, expected {expected}")]
    PoseWidth {
        /// Its length.
        len: usize,
        /// `3J`.
        expected: usize,
    },
    /// The donor pool is empty.
    #[error("the donor pool is empty")]
    NoDonors,
    /// More donors than a row index can name.
    #[error("{0} donors exceed the cap of {max}", max = u32::MAX)]
    TooManyDonors(usize),
}

/// Each point's joints from a `[V, J]` row-major table, ascending, as compressed rows: pose
/// locality's relevant joints here, the output layer's candidates in the fused op.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct JointLists {
    /// `[V + 1]`: where each point's joints start in `joints`.
    starts: Vec<usize>,
    joints: Vec<u32>,
}

impl JointLists {
    /// The joints `j` of each row of `table` (`width` columns, `width` > 0) with `keep(entry)`.
    pub(crate) fn where_true<T>(table: &[T], width: usize, keep: impl Fn(&T) -> bool) -> Self {
        let mut starts = Vec::with_capacity(table.len() / width + 1);
        let mut joints = Vec::new();
        starts.push(0);
        for row in table.chunks_exact(width) {
            // `width` is a joint count (the width of a `[V, J]` table that was allocated), far
            // below u32::MAX.
            joints.extend((0..width).filter(|&j| keep(&row[j])).map(|j| j as u32));
            starts.push(joints.len());
        }
        Self { starts, joints }
    }

    /// The joints of point `v`.
    pub(crate) fn of(&self, v: usize) -> &[u32] {
        &self.joints[self.starts[v]..self.starts[v + 1]]
    }

    /// The joints of all points together.
    pub(crate) fn total(&self) -> usize {
        self.joints.len()
    }

    /// Whether some point has no joint.
    pub(crate) fn has_empty(&self) -> bool {
        self.starts.windows(2).any(|w| w[0] == w[1])
    }
}

/// The pose input of one image iteration under pose locality, `[B, V, 3J]` in structure.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalPoses {
    joints: usize,
    vertices: usize,
    /// `[B, 3J]`: the frames' own pose features.
    frames: Vec<f32>,
    /// `[D, 3J]`: the donor poses.
    pool: Vec<f32>,
    /// `[B·V]`: the donor of every row, an index into `pool`.
    donor: Vec<u32>,
    /// The relevant joints of every vertex.
    relevant: JointLists,
}

impl LocalPoses {
    /// Draws the donors: row `(b, v)` keeps `poses[b]`'s features for the joints `relevant`
    /// marks for `v` (`[V, J]`, row-major) and takes, for every other joint, those of a donor
    /// from `pool` drawn uniformly per row with `rng` (rows in order, frame-major).
    pub fn draw<R: Rng>(
        poses: &[&[f32]],
        pool: &[&[f32]],
        relevant: &[bool],
        joints: usize,
        rng: &mut R,
    ) -> Result<Self, LocalPosesError> {
        if joints == 0 || !relevant.len().is_multiple_of(joints) {
            return Err(LocalPosesError::Relevant {
                len: relevant.len(),
                joints,
            });
        }
        if pool.is_empty() {
            return Err(LocalPosesError::NoDonors);
        }
        if u32::try_from(pool.len()).is_err() {
            return Err(LocalPosesError::TooManyDonors(pool.len()));
        }
        let q = 3 * joints;
        if let Some(p) = poses.iter().chain(pool).find(|p| p.len() != q) {
            return Err(LocalPosesError::PoseWidth {
                len: p.len(),
                expected: q,
            });
        }
        let vertices = relevant.len() / joints;
        let relevant = JointLists::where_true(relevant, joints, |&keep| keep);
        let donor = (0..poses.len() * vertices)
            .map(|_| rng.random_range(0..pool.len()) as u32)
            .collect();
        Ok(Self {
            joints,
            vertices,
            frames: poses.concat(),
            pool: pool.concat(),
            donor,
            relevant,
        })
    }

    /// Joints `J` (the pose width is `3J`).
    #[must_use]
    pub fn joints(&self) -> usize {
        self.joints
    }

    /// Vertices `V` per frame.
    #[must_use]
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Frames `B`.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.frames.len() / (3 * self.joints)
    }

    /// Donor poses `D`.
    #[must_use]
    pub fn donor_count(&self) -> usize {
        self.pool.len() / (3 * self.joints)
    }

    /// The frames' own pose features, `[B, 3J]`.
    #[must_use]
    pub fn frames(&self) -> &[f32] {
        &self.frames
    }

    /// The donor poses, `[D, 3J]`.
    #[must_use]
    pub fn pool(&self) -> &[f32] {
        &self.pool
    }

    /// The donor of row `b·V + v`.
    #[must_use]
    pub fn donor(&self, row: usize) -> usize {
        self.donor[row] as usize
    }

    /// The joints relevant to vertex `v`, ascending.
    #[must_use]
    pub fn relevant(&self, v: usize) -> &[u32] {
        self.relevant.of(v)
    }

    /// The features of row `b·V + v` where it differs from its donor: `(feature, row's value −
    /// donor's value)` over the relevant joints' features, zero differences skipped. The row is
    /// its donor's pose plus these.
    pub fn differences(&self, row: usize) -> impl Iterator<Item = (usize, f32)> + '_ {
        let q = 3 * self.joints;
        let b = row / self.vertices;
        let frame = &self.frames[b * q..(b + 1) * q];
        let d = self.donor(row);
        let donor = &self.pool[d * q..(d + 1) * q];
        self.relevant(row % self.vertices)
            .iter()
            .flat_map(|&j| 3 * j as usize..3 * j as usize + 3)
            .map(move |c| (c, frame[c] - donor[c]))
            .filter(|&(_, diff)| diff != 0.0)
    }

    /// Whether multiplying the structure pays against multiplying the rows written out: the
    /// relevant joints are at most a quarter of all (`fused::worth_sparse`; at 8 of 24 joints
    /// the two cost the same, and the rows keep small rigs' results what they were).
    #[must_use]
    pub fn worth_structure(&self) -> bool {
        super::fused::worth_sparse(self.relevant.total(), self.vertices * self.joints)
    }

    /// The dense input `[B, V, 3J]`, row-major: what the structure stands for.
    #[must_use]
    pub fn rows(&self) -> Vec<f32> {
        let q = 3 * self.joints;
        let mut rows = Vec::with_capacity(self.donor.len() * q);
        for (b, frame) in self.frames.chunks_exact(q).enumerate() {
            for v in 0..self.vertices {
                let d = self.donor(b * self.vertices + v);
                let start = rows.len();
                rows.extend_from_slice(&self.pool[d * q..(d + 1) * q]);
                for &j in self.relevant(v) {
                    let c = 3 * j as usize;
                    rows[start + c..start + c + 3].copy_from_slice(&frame[c..c + 3]);
                }
            }
        }
        rows
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;

    #[test]
    fn relevant_joints_keep_the_frames_features_and_the_others_come_from_one_donor() {
        let joints = 3;
        let frame: Vec<f32> = (0..9).map(|i| i as f32).collect();
        let donors: Vec<Vec<f32>> = (1..=4)
            .map(|d| (0..9).map(|i| (100 * d + i) as f32).collect())
            .collect();
        let pool: Vec<&[f32]> = donors.iter().map(Vec::as_slice).collect();
        // Vertex 0 moves with joints 0 and 2, vertex 1 with joint 1, vertex 2 with all three,
        // vertex 3 with none.
        let relevant = [
            true, false, true, //
            false, true, false, //
            true, true, true, //
            false, false, false,
        ];
        let draw = |seed| {
            LocalPoses::draw(
                &[&frame, &frame],
                &pool,
                &relevant,
                joints,
                &mut ChaCha8Rng::seed_from_u64(seed),
            )
            .unwrap()
        };
        let local = draw(7);
        assert_eq!((local.frame_count(), local.vertices()), (2, 4));
        assert_eq!(local.donor_count(), 4);
        assert_eq!(local.relevant(0), &[0, 2]);
        assert!(local.relevant(3).is_empty());
        let rows = local.rows();
        assert_eq!(rows.len(), 2 * 4 * 9);
        for (r, row) in rows.chunks_exact(9).enumerate() {
            let keep = &relevant[(r % 4) * 3..(r % 4) * 3 + 3];
            let d = local.donor(r) + 1;
            for j in 0..joints {
                for a in 0..3 {
                    let want = if keep[j] {
                        (3 * j + a) as f32
                    } else {
                        // The row's donor's feature of the same joint and axis.
                        (100 * d + 3 * j + a) as f32
                    };
                    assert_eq!(row[3 * j + a], want, "row {r} joint {j}");
                }
            }
        }
        // The same seed draws the same donors; another seed other donors somewhere.
        assert_eq!(draw(7), local);
        assert!((8..40u64).any(|s| draw(s).rows() != rows));
    }

    #[test]
    fn malformed_inputs_are_refused() {
        let pose = [0.0f32; 6];
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut draw = |poses: &[&[f32]], pool: &[&[f32]], relevant: &[bool], joints| {
            LocalPoses::draw(poses, pool, relevant, joints, &mut rng)
        };
        assert_eq!(
            draw(&[&pose], &[&pose], &[true; 3], 2),
            Err(LocalPosesError::Relevant { len: 3, joints: 2 })
        );
        assert_eq!(
            draw(&[&pose], &[&pose], &[], 0),
            Err(LocalPosesError::Relevant { len: 0, joints: 0 })
        );
        assert_eq!(
            draw(&[&pose], &[], &[true; 2], 2),
            Err(LocalPosesError::NoDonors)
        );
        assert_eq!(
            draw(&[&pose[..5]], &[&pose], &[true; 2], 2),
            Err(LocalPosesError::PoseWidth {
                len: 5,
                expected: 6
            })
        );
    }
}
