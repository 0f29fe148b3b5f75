//! Result rows and their two renderings: a fixed-width text table and JSON
//! (`{"rows":[{"method":…,"chamfer_cm":…,"m2s_cm":…,"s2m_cm":…,"frames":…,"size":…,
//! "chamfer_pct":…,"max_vertex_cm":…,"max_vertex_pct":…,"max_off_surface_cm":…,
//! "max_off_surface_pct":…,"per_frame":[{"frame":…,"m2s_cm":…,"s2m_cm":…,"max_vertex_cm":…,
//! "max_off_surface_cm":…}]}]}`; the fields after `frames` were added later and default when
//! absent, so older files still parse).

use std::fmt::Write as _;

/// One row of the evaluation table: a skinning method averaged over the test frames.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalRow {
    /// Method name: `initial`, `static`, `ours`, `oracle`, `oracle-dqs`.
    pub method: String,
    /// Chamfer distance (M2S + S2M), centimetres.
    pub chamfer_cm: f64,
    /// Recovered-to-ground-truth mean distance, centimetres.
    pub m2s_cm: f64,
    /// Ground-truth-to-recovered mean distance, centimetres.
    pub s2m_cm: f64,
    /// Number of test frames averaged.
    pub frames: usize,
    /// The character's size (rest-pose bounding-box diagonal, model units) the relative
    /// columns are measured against.
    #[serde(default)]
    pub size: f64,
    /// Chamfer distance as a percentage of `size` (0 when the size is 0).
    #[serde(default)]
    pub chamfer_pct: f64,
    /// Largest vertex-to-vertex distance to the ground truth over every test frame (cm);
    /// `None` when the posed mesh is not the capture's template.
    #[serde(default)]
    pub max_vertex_cm: Option<f64>,
    /// `max_vertex_cm` as a percentage of `size`.
    #[serde(default)]
    pub max_vertex_pct: Option<f64>,
    /// Largest distance from a vertex of the posed mesh to the ground-truth surface over every
    /// test frame (cm); `None` in files written before it existed.
    #[serde(default)]
    pub max_off_surface_cm: Option<f64>,
    /// `max_off_surface_cm` as a percentage of `size`.
    #[serde(default)]
    pub max_off_surface_pct: Option<f64>,
    /// Each test frame's figures, in the capture's test-frame order.
    #[serde(default)]
    pub per_frame: Vec<FrameRow>,
}

/// One test frame of an [`EvalRow`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameRow {
    /// The frame index.
    pub frame: usize,
    /// M2S (cm).
    pub m2s_cm: f64,
    /// S2M (cm).
    pub s2m_cm: f64,
    /// Largest vertex-to-vertex distance to the ground truth (cm), if defined.
    pub max_vertex_cm: Option<f64>,
    /// Largest distance from a vertex to the ground-truth surface (cm), if recorded.
    #[serde(default)]
    pub max_off_surface_cm: Option<f64>,
}

/// The outcome of [`worst_vertex_check`] (and [`off_surface_check`]); serialised as is in
/// `trainer zoo`'s JSON.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct WorstVertexCheck {
    /// Frames compared.
    pub frames: usize,
    /// Frames where the candidate's worst vertex is further from the truth than the
    /// reference's: `(frame, candidate cm, reference cm)`.
    pub failures: Vec<(usize, f64, f64)>,
}

impl WorstVertexCheck {
    /// True when no frame failed (and at least one was compared).
    #[must_use]
    pub fn passed(&self) -> bool {
        self.frames > 0 && self.failures.is_empty()
    }

    /// The most by which the candidate's worst vertex exceeded the reference's on a failed
    /// frame (cm; 0 when none failed).
    #[must_use]
    pub fn largest_excess(&self) -> f64 {
        self.failures
            .iter()
            .map(|&(_, candidate, reference)| candidate - reference)
            .fold(0.0, f64::max)
    }

    /// One line: `yes (24 frames)` or `no: 10 of 24 frames (by up to 2.51 cm)`.
    #[must_use]
    pub fn summary(&self) -> String {
        if self.passed() {
            format!("yes ({} frames)", self.frames)
        } else {
            format!(
                "no: {} of {} frames (by up to {:.2} cm)",
                self.failures.len(),
                self.frames,
                self.largest_excess()
            )
        }
    }
}

/// Compares, frame by frame, the worst vertex-to-vertex distance of `candidate` with that of
/// `reference` (e.g. ours against bone heat). `None` when the rows lack per-vertex figures or
/// their frames differ.
#[must_use]
pub fn worst_vertex_check(candidate: &EvalRow, reference: &EvalRow) -> Option<WorstVertexCheck> {
    check_frames(candidate, reference, |f| f.max_vertex_cm)
}

/// Compares, frame by frame, the vertex furthest from the true surface of `candidate` with
/// that of `reference`. `None` when the rows lack the figure or their frames differ.
#[must_use]
pub fn off_surface_check(candidate: &EvalRow, reference: &EvalRow) -> Option<WorstVertexCheck> {
    check_frames(candidate, reference, |f| f.max_off_surface_cm)
}

fn check_frames(
    candidate: &EvalRow,
    reference: &EvalRow,
    figure: impl Fn(&FrameRow) -> Option<f64>,
) -> Option<WorstVertexCheck> {
    if candidate.per_frame.len() != reference.per_frame.len() || candidate.per_frame.is_empty() {
        return None;
    }
    let mut failures = Vec::new();
    for (c, r) in candidate.per_frame.iter().zip(&reference.per_frame) {
        if c.frame != r.frame {
            return None;
        }
        let (cv, rv) = (figure(c)?, figure(r)?);
        if cv > rv {
            failures.push((c.frame, cv, rv));
        }
    }
    Some(WorstVertexCheck {
        frames: candidate.per_frame.len(),
        failures,
    })
}

#[derive(serde::Serialize, serde::Deserialize)]
struct Rows<'a> {
    #[serde(borrow)]
    rows: std::borrow::Cow<'a, [EvalRow]>,
}

/// The rows as JSON (`{"rows":[…]}`), pretty-printed, ending in a newline.
#[must_use]
pub fn rows_to_json(rows: &[EvalRow]) -> String {
    let mut s = serde_json::to_string_pretty(&Rows {
        rows: std::borrow::Cow::Borrowed(rows),
    })
    .unwrap_or_else(|_| String::from("{\"rows\":[]}"));
    s.push('\n');
    s
}

/// Parses what [`rows_to_json`] writes.
pub fn rows_from_json(text: &str) -> Result<Vec<EvalRow>, serde_json::Error> {
    let r: Rows<'_> = serde_json::from_str(text)?;
    Ok(r.rows.into_owned())
}

/// The rows as a text table, in the paper's column order (Chamfer, M2S, S2M), three decimals,
/// then the frame count, the Chamfer relative to the character's size and the two worst
/// vertices, off the true surface and vertex to vertex (`-` where undefined).
#[must_use]
pub fn rows_to_table(rows: &[EvalRow]) -> String {
    let width = rows
        .iter()
        .map(|r| r.method.len())
        .max()
        .unwrap_or(0)
        .max("method".len());
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<width$}  {:>12}  {:>8}  {:>8}  {:>6}  {:>11}  {:>16}  {:>15}",
        "method",
        "Chamfer (cm)",
        "M2S (cm)",
        "S2M (cm)",
        "frames",
        "Chamfer (%)",
        "off surface (cm)",
        "max vertex (cm)"
    );
    let _ = writeln!(
        s,
        "{}",
        "-".repeat(width + 2 + 12 + 2 + 8 + 2 + 8 + 2 + 6 + 2 + 11 + 2 + 16 + 2 + 15)
    );
    let cell = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{v:.3}"));
    for r in rows {
        let _ = writeln!(
            s,
            "{:<width$}  {:>12.3}  {:>8.3}  {:>8.3}  {:>6}  {:>11.4}  {:>16}  {:>15}",
            r.method,
            r.chamfer_cm,
            r.m2s_cm,
            r.s2m_cm,
            r.frames,
            r.chamfer_pct,
            cell(r.max_off_surface_cm),
            cell(r.max_vertex_cm)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(frame: usize, max_vertex_cm: Option<f64>) -> FrameRow {
        FrameRow {
            frame,
            m2s_cm: 1.0,
            s2m_cm: 1.0,
            max_vertex_cm,
            max_off_surface_cm: max_vertex_cm.map(|v| v / 2.0),
        }
    }

    fn rows() -> Vec<EvalRow> {
        vec![
            EvalRow {
                method: "initial".into(),
                chamfer_cm: 3.25,
                m2s_cm: 1.5,
                s2m_cm: 1.75,
                frames: 12,
                size: 2.5,
                chamfer_pct: 1.3,
                max_vertex_cm: Some(7.5),
                max_vertex_pct: Some(3.0),
                max_off_surface_cm: Some(3.75),
                max_off_surface_pct: Some(1.5),
                per_frame: vec![frame(4, Some(7.5)), frame(9, Some(2.0))],
            },
            EvalRow {
                method: "oracle-dqs".into(),
                chamfer_cm: 0.5,
                m2s_cm: 0.25,
                s2m_cm: 0.25,
                frames: 12,
                size: 2.5,
                chamfer_pct: 0.2,
                max_vertex_cm: None,
                max_vertex_pct: None,
                max_off_surface_cm: None,
                max_off_surface_pct: None,
                per_frame: Vec::new(),
            },
        ]
    }

    #[test]
    fn json_has_the_documented_shape_and_round_trips() {
        let text = rows_to_json(&rows());
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let first = &v["rows"][0];
        assert_eq!(first["method"], "initial");
        assert_eq!(first["chamfer_cm"], 3.25);
        assert_eq!(first["m2s_cm"], 1.5);
        assert_eq!(first["s2m_cm"], 1.75);
        assert_eq!(first["frames"], 12);
        assert_eq!(first["size"], 2.5);
        assert_eq!(first["chamfer_pct"], 1.3);
        assert_eq!(first["max_vertex_cm"], 7.5);
        assert_eq!(first["per_frame"][1]["frame"], 9);
        assert_eq!(first["per_frame"][1]["max_vertex_cm"], 2.0);
        assert_eq!(first["max_off_surface_cm"], 3.75);
        assert_eq!(first["per_frame"][1]["max_off_surface_cm"], 1.0);
        assert!(v["rows"][1]["max_vertex_cm"].is_null());
        assert_eq!(v["rows"].as_array().unwrap().len(), 2);
        assert_eq!(rows_from_json(&text).unwrap(), rows());
        // A file written before the relative and per-frame fields existed still parses.
        let old =
            r#"{"rows":[{"method":"ours","chamfer_cm":1.0,"m2s_cm":0.5,"s2m_cm":0.5,"frames":3}]}"#;
        let r = rows_from_json(old).unwrap();
        assert_eq!(
            (r[0].frames, r[0].max_vertex_cm, r[0].per_frame.len()),
            (3, None, 0)
        );
    }

    #[test]
    fn table_aligns_columns() {
        let t = rows_to_table(&rows());
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 4);
        assert!(
            lines[2].starts_with("initial ")
                && lines[2].contains("3.250")
                && lines[2].contains(" 12 ")
                && lines[2].contains("1.3000")
                && lines[2].contains(" 3.750 ")
                && lines[2].ends_with("7.500")
        );
        assert!(lines[3].starts_with("oracle-dqs") && lines[3].contains("0.500"));
        assert!(lines[3].ends_with(" -"));
        assert!(lines.iter().skip(1).all(|l| l.len() == lines[0].len()));
    }

    #[test]
    fn worst_vertex_check_names_the_frames_where_the_candidate_is_worse() {
        let reference = rows().remove(0);
        let mut candidate = reference.clone();
        // Equal worst vertices pass; one frame worse fails with both figures named.
        assert!(worst_vertex_check(&candidate, &reference).unwrap().passed());
        candidate.per_frame[1].max_vertex_cm = Some(2.5);
        let check = worst_vertex_check(&candidate, &reference).unwrap();
        assert_eq!(
            (check.frames, check.failures.clone()),
            (2, vec![(9, 2.5, 2.0)])
        );
        assert!(!check.passed());
        assert!((check.largest_excess() - 0.5).abs() < 1e-12);
        assert_eq!(check.summary(), "no: 1 of 2 frames (by up to 0.50 cm)");
        let pass = worst_vertex_check(&reference, &reference).unwrap();
        assert_eq!(
            (pass.largest_excess(), pass.summary()),
            (0.0, "yes (2 frames)".into())
        );
        // Rows on other frames, or without per-vertex figures, cannot be compared.
        candidate.per_frame[1].frame = 10;
        assert!(worst_vertex_check(&candidate, &reference).is_none());
        candidate.per_frame[1] = frame(9, None);
        assert!(worst_vertex_check(&candidate, &reference).is_none());
        assert!(worst_vertex_check(&rows()[1], &rows()[1]).is_none());
    }

    #[test]
    fn the_off_surface_check_compares_its_own_figure() {
        let reference = rows().remove(0);
        let mut candidate = reference.clone();
        assert!(off_surface_check(&candidate, &reference).unwrap().passed());
        // Worse vertex to vertex only (a part sliding along the surface): the off-surface
        // check still passes.
        candidate.per_frame[1].max_vertex_cm = Some(2.5);
        assert!(off_surface_check(&candidate, &reference).unwrap().passed());
        assert!(!worst_vertex_check(&candidate, &reference).unwrap().passed());
        // Off the surface (a spike): it fails, naming the frame and both figures.
        candidate.per_frame[0].max_off_surface_cm = Some(4.0);
        let check = off_surface_check(&candidate, &reference).unwrap();
        assert_eq!(check.failures, vec![(4, 4.0, 3.75)]);
        // A row from a file written before the figure existed cannot be compared.
        candidate.per_frame[0].max_off_surface_cm = None;
        assert!(off_surface_check(&candidate, &reference).is_none());
    }
}
