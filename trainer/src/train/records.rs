//! What a run logs: one record per iteration (image losses, warm-start fit) as CSV rows, the
//! warm start's convergence status, and reopening a log on resume so it continues where the
//! checkpoint left off.

use super::*;

/// The loss values of one iteration (already weighted terms are not stored: raw means).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossRecord {
    /// Iteration (1-based, image-loss phase).
    pub iteration: u64,
    /// Weighted total.
    pub total: f64,
    /// Mean boundary-vertex distance (pixels).
    pub silhouette_boundary: f64,
    /// Mean contour-pixel distance (pixels).
    pub silhouette_contour: f64,
    /// Mean squared Laplacian per vertex, over the squared bounding-box diagonal.
    pub laplacian: f64,
    /// Mean geodesic penalty per vertex.
    pub skinning: f64,
    /// Mean squared deviation per rigid skin vertex.
    pub partwise: f64,
    /// `KL(w_init ‖ w)` per vertex (nats).
    pub prior: f64,
}

impl LossRecord {
    /// CSV header matching [`LossRecord::csv_row`].
    pub const CSV_HEADER: &'static str =
        "iteration,total,silhouette_boundary,silhouette_contour,laplacian,skinning,partwise,prior";

    /// One CSV row.
    #[must_use]
    pub fn csv_row(&self) -> String {
        format!(
            "{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}",
            self.iteration,
            self.total,
            self.silhouette_boundary,
            self.silhouette_contour,
            self.laplacian,
            self.skinning,
            self.partwise,
            self.prior
        )
    }
}

/// The terms of one warm-start iteration (before its step).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WarmRecord {
    /// Warm-start iteration (1-based).
    pub iteration: u64,
    /// `KL(w_init ‖ w)` per vertex.
    pub kl: f64,
    /// The root-mean-square distance between the vertices skinned with SkinNet's and with the
    /// initial weights, over the template's bounding-box diagonal.
    pub position_relative: f64,
}

/// Where the warm start stands.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WarmStatus {
    /// Iterations run.
    pub iterations: u64,
    /// Whether the convergence test passed (then no more iterations run).
    pub converged: bool,
    /// `KL(w_init ‖ w)` per vertex, averaged over the last window.
    pub kl: f64,
    /// Relative root-mean-square position error, averaged over the last window.
    pub position_relative: f64,
}

/// Opens a CSV log for appending after a (re)start: keeps the header and the rows of iterations
/// `1..=keep` already written (a crash may have logged iterations after the last checkpoint,
/// which the resumed run writes again) and drops the rest.
pub(super) fn reopen_log(
    path: &Path,
    header: &str,
    keep: u64,
) -> Result<std::fs::File, TrainError> {
    reopen_log_keeping(path, header, |row| {
        row.split(',')
            .next()
            .and_then(|i| i.parse::<u64>().ok())
            .is_some_and(|i| i <= keep)
    })
}

/// Recreates the CSV log `path` with `header` and the rows of the old file for which `keep`
/// holds (none when there is no old file), and returns it open for appending rows.
pub(crate) fn reopen_log_keeping(
    path: &Path,
    header: &str,
    keep: impl Fn(&str) -> bool,
) -> Result<std::fs::File, TrainError> {
    let io = |source| TrainError::Io {
        path: path.to_owned(),
        source,
    };
    let mut kept = vec![header.to_string()];
    if let Ok(text) = std::fs::read_to_string(path) {
        kept.extend(text.lines().skip(1).filter(|l| keep(l)).map(str::to_string));
    }
    let mut file = std::fs::File::create(path).map_err(io)?;
    writeln!(file, "{}", kept.join("\n")).map_err(io)?;
    Ok(file)
}
