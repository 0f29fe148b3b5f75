//! Result rows and their two renderings: a fixed-width text table and JSON
//! (`{"rows":[{"method":…,"chamfer_cm":…,"m2s_cm":…,"s2m_cm":…,"frames":…}]}`).

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

/// The rows as a text table, in the paper's column order (Chamfer, M2S, S2M), two decimals.
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
        "{:<width$}  {:>12}  {:>8}  {:>8}  {:>6}",
        "method", "Chamfer (cm)", "M2S (cm)", "S2M (cm)", "frames"
    );
    let _ = writeln!(s, "{}", "-".repeat(width + 2 + 12 + 2 + 8 + 2 + 8 + 2 + 6));
    for r in rows {
        let _ = writeln!(
            s,
            "{:<width$}  {:>12.3}  {:>8.3}  {:>8.3}  {:>6}",
            r.method, r.chamfer_cm, r.m2s_cm, r.s2m_cm, r.frames
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows() -> Vec<EvalRow> {
        vec![
            EvalRow {
                method: "initial".into(),
                chamfer_cm: 3.25,
                m2s_cm: 1.5,
                s2m_cm: 1.75,
                frames: 12,
            },
            EvalRow {
                method: "oracle-dqs".into(),
                chamfer_cm: 0.5,
                m2s_cm: 0.25,
                s2m_cm: 0.25,
                frames: 12,
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
        assert_eq!(v["rows"].as_array().unwrap().len(), 2);
        assert_eq!(rows_from_json(&text).unwrap(), rows());
    }

    #[test]
    fn table_aligns_columns() {
        let t = rows_to_table(&rows());
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 4);
        assert!(
            lines[2].starts_with("initial ")
                && lines[2].contains("3.250")
                && lines[2].ends_with("12")
        );
        assert!(lines[3].starts_with("oracle-dqs") && lines[3].contains("0.500"));
        assert!(lines.iter().skip(1).all(|l| l.len() == lines[0].len()));
    }
}
