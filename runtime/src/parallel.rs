//! A ready-made parallel run (feature `rayon`): the range is split into one tile-aligned chunk
//! per scratch and the chunks run under `rayon::join`, which needs no heap allocation.

use crate::error::RuntimeError;
use crate::job::{Scratch, SkinJob};
use crate::kernels::TILE;

/// Runs `job` on the current rayon pool with one chunk per entry of `scratches` (give as many
/// as threads). Validates first, so a bad job is refused before any thread starts.
pub fn run_parallel<W: AsRef<[f32]> + Sync>(
    job: SkinJob<'_, W>,
    scratches: &mut [Scratch],
) -> Result<(), RuntimeError> {
    job.validate()?;
    if scratches.is_empty() {
        return Err(RuntimeError::BufferLength {
            field: "scratches",
            len: 0,
            expected: 1,
        });
    }
    go(job, scratches)
}

fn go<W: AsRef<[f32]> + Sync>(
    mut job: SkinJob<'_, W>,
    scratches: &mut [Scratch],
) -> Result<(), RuntimeError> {
    let count = job.out_positions.len();
    if scratches.len() == 1 || count <= TILE {
        return job.run(&mut scratches[0]);
    }
    let (s0, s1) = scratches.split_at_mut(scratches.len() / 2);
    // Split proportionally to the scratches on each side, at a tile boundary of the mesh so no
    // tile's MLP is evaluated twice.
    let target = job.first_vertex + count * s0.len() / (s0.len() + s1.len());
    let at = (target.div_ceil(TILE) * TILE).clamp(job.first_vertex, job.first_vertex + count)
        - job.first_vertex;
    let (head, tail) = job.split_at(at).ok_or(RuntimeError::Mismatch {
        field: "job outputs",
    })?;
    let (a, b) = rayon::join(|| go(head, s0), || go(tail, s1));
    a.and(b)
}
