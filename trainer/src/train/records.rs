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
    /// `KL(w_init ‖ w)` summed over the hidden vertices, per template vertex (nats; 0 without
    /// [`crate::train::LossWeights::hidden_prior`]).
    pub hidden_prior: f64,
    /// The hinge on the hidden vertices' drift (squared excess over the squared diagonal, per
    /// vertex and frame; 0 without [`crate::train::LossWeights::hidden_drift`]).
    pub hidden_drift: f64,
}

impl LossRecord {
    /// CSV header matching [`LossRecord::csv_row`].
    pub const CSV_HEADER: &'static str = concat!(
        "iteration,total,silhouette_boundary,silhouette_contour,laplacian,skinning,partwise,",
        "prior,hidden_prior,hidden_drift"
    );

    /// One CSV row.
    #[must_use]
    pub fn csv_row(&self) -> String {
        format!(
            "{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}",
            self.iteration,
            self.total,
            self.silhouette_boundary,
            self.silhouette_contour,
            self.laplacian,
            self.skinning,
            self.partwise,
            self.prior,
            self.hidden_prior,
            self.hidden_drift
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
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
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
///
/// A run folder written by an earlier version may have other columns (a term added, one
/// dropped): its rows are rewritten under `header` by column name, with an empty field where
/// the old file had no such column, so every row of the log has the header's columns.
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
        let mut lines = text.lines();
        let old_header = lines.next().unwrap_or_default();
        let rows = lines.filter(|l| keep(l));
        if old_header == header {
            kept.extend(rows.map(str::to_string));
        } else {
            let old: Vec<&str> = old_header.split(',').collect();
            let columns: Vec<Option<usize>> = header
                .split(',')
                .map(|name| old.iter().position(|o| *o == name))
                .collect();
            kept.extend(rows.map(|row| {
                let fields: Vec<&str> = row.split(',').collect();
                columns
                    .iter()
                    .map(|c| c.and_then(|i| fields.get(i).copied()).unwrap_or(""))
                    .collect::<Vec<_>>()
                    .join(",")
            }));
        }
    }
    let mut file = std::fs::File::create(path).map_err(io)?;
    writeln!(file, "{}", kept.join("\n")).map_err(io)?;
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_with_other_columns_is_reopened_under_the_new_header() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("warm_start.csv");
        // An earlier version's columns: one dropped since, one not yet there.
        std::fs::write(
            &path,
            "iteration,kl,position_cm2,position_relative\n1,0.5,9,0.01\n2,0.4,8,0.02\n3,0.3,7,0.03\n",
        )
        .unwrap();
        let mut file = reopen_log(&path, "iteration,kl,position_relative,extra", 2).unwrap();
        writeln!(file, "3,0.2,0.04,1").unwrap();
        drop(file);
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "iteration,kl,position_relative,extra\n1,0.5,0.01,\n2,0.4,0.02,\n3,0.2,0.04,1\n"
        );
        // The same header keeps its rows as they are.
        let file = reopen_log(&path, "iteration,kl,position_relative,extra", 1).unwrap();
        drop(file);
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "iteration,kl,position_relative,extra\n1,0.5,0.01,\n"
        );
    }
}
