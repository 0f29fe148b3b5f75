//! Spread over seeds: the same table trained and evaluated with several seeds, each row as mean
//! ± standard deviation, and the share of the gap between the initial weights and a bound that
//! each row closes.
//!
//! Single runs of the built-in demo differ by a few hundredths of a centimetre when only the
//! seed changes, as much as some effects being measured; a table of means with their spread
//! says which differences are real. The standard deviation is the sample one (`n − 1`), 0 for a
//! single seed.
//!
//! The gap share of a row is `(initial − row) / (initial − bound)` on the Chamfer distance,
//! per seed, then averaged: 0 for the initial weights, 1 for the bound. The bound is the best
//! any per-frame weights can do ([`super::Skinning::BoundPose`]) when it was evaluated.

use std::fmt::Write as _;

use super::table::EvalRow;

/// Mean and sample standard deviation.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct MeanStd {
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (`n − 1`; 0 for one value).
    pub std: f64,
}

impl MeanStd {
    /// Of `values` (empty: zeros).
    #[must_use]
    pub fn of(values: &[f64]) -> Self {
        let n = values.len();
        if n == 0 {
            return Self::default();
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let std = if n > 1 {
            (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        Self { mean, std }
    }
}

/// One method over every seed.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SpreadRow {
    /// Method name (as in [`EvalRow::method`]).
    pub method: String,
    /// Chamfer distance (cm).
    pub chamfer_cm: MeanStd,
    /// Model-to-scan distance (cm).
    pub m2s_cm: MeanStd,
    /// Scan-to-model distance (cm).
    pub s2m_cm: MeanStd,
    /// Share of the initial → bound Chamfer gap closed (`None` without both rows).
    pub gap_share: Option<MeanStd>,
    /// Seeds that had this row.
    pub seeds: usize,
}

/// Groups `runs` (one table per seed) by method, in the order of first appearance, with the gap
/// share against the row named `bound` (and `initial`) of the same seed.
#[must_use]
pub fn spread(runs: &[Vec<EvalRow>], bound: &str) -> Vec<SpreadRow> {
    let mut methods: Vec<&str> = Vec::new();
    for rows in runs {
        for r in rows {
            if !methods.contains(&r.method.as_str()) {
                methods.push(&r.method);
            }
        }
    }
    let find =
        |rows: &[EvalRow], m: &str| rows.iter().find(|r| r.method == m).map(|r| r.chamfer_cm);
    methods
        .iter()
        .map(|&m| {
            let rows: Vec<&EvalRow> = runs
                .iter()
                .filter_map(|rows| rows.iter().find(|r| r.method == m))
                .collect();
            let of = |f: fn(&EvalRow) -> f64| {
                MeanStd::of(&rows.iter().map(|r| f(r)).collect::<Vec<_>>())
            };
            let shares: Vec<f64> = runs
                .iter()
                .filter_map(|rows| {
                    let (initial, bound, row) =
                        (find(rows, "initial")?, find(rows, bound)?, find(rows, m)?);
                    let gap = initial - bound;
                    (gap.abs() > 1e-12).then(|| (initial - row) / gap)
                })
                .collect();
            SpreadRow {
                method: m.to_string(),
                chamfer_cm: of(|r| r.chamfer_cm),
                m2s_cm: of(|r| r.m2s_cm),
                s2m_cm: of(|r| r.s2m_cm),
                gap_share: (!shares.is_empty()).then(|| MeanStd::of(&shares)),
                seeds: rows.len(),
            }
        })
        .collect()
}

/// The rows as a Markdown table (`mean ± std`; the gap share in per cent).
#[must_use]
pub fn spread_table(rows: &[SpreadRow], bound: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| method | Chamfer (cm) | M2S (cm) | S2M (cm) | share of the initial → {bound} gap | seeds |"
    );
    let _ = writeln!(s, "| --- | --- | --- | --- | --- | --- |");
    let pm = |m: MeanStd| format!("{:.3} ± {:.3}", m.mean, m.std);
    for r in rows {
        let share = r.gap_share.map_or_else(
            || "—".to_string(),
            |g| format!("{:.0} ± {:.0} %", 100.0 * g.mean, 100.0 * g.std),
        );
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {share} | {} |",
            r.method,
            pm(r.chamfer_cm),
            pm(r.m2s_cm),
            pm(r.s2m_cm),
            r.seeds
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: &str, chamfer: f64) -> EvalRow {
        EvalRow {
            method: method.into(),
            chamfer_cm: chamfer,
            m2s_cm: chamfer / 2.0,
            s2m_cm: chamfer / 2.0,
            frames: 3,
            size: 0.0,
            chamfer_pct: 0.0,
            max_vertex_cm: None,
            max_vertex_pct: None,
            per_frame: Vec::new(),
        }
    }

    #[test]
    fn mean_and_sample_deviation() {
        let m = MeanStd::of(&[1.0, 2.0, 3.0, 4.0]);
        assert!((m.mean - 2.5).abs() < 1e-12);
        // Σ(x − 2.5)² = 5, / 3.
        assert!((m.std - (5.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(
            MeanStd::of(&[7.0]),
            MeanStd {
                mean: 7.0,
                std: 0.0
            }
        );
        assert_eq!(MeanStd::of(&[]), MeanStd::default());
    }

    #[test]
    fn rows_group_by_method_and_close_their_share_of_the_gap() {
        let runs = vec![
            vec![
                row("initial", 1.0),
                row("ours", 0.8),
                row("bound-pose", 0.2),
            ],
            vec![
                row("initial", 1.2),
                row("ours", 0.7),
                row("bound-pose", 0.2),
            ],
            vec![row("initial", 1.1), row("ours", 0.75)],
        ];
        let s = spread(&runs, "bound-pose");
        let names: Vec<&str> = s.iter().map(|r| r.method.as_str()).collect();
        assert_eq!(names, ["initial", "ours", "bound-pose"]);
        let ours = &s[1];
        assert_eq!(ours.seeds, 3);
        assert!((ours.chamfer_cm.mean - 0.75).abs() < 1e-12);
        // Seed 0: 0.2 / 0.8 = 25 %; seed 1: 0.5 / 1.0 = 50 %; seed 2 has no bound.
        let g = ours.gap_share.unwrap();
        assert!((g.mean - 0.375).abs() < 1e-12, "{g:?}");
        assert_eq!(s[0].gap_share.unwrap().mean, 0.0);
        assert!((s[2].gap_share.unwrap().mean - 1.0).abs() < 1e-12);
        let table = spread_table(&s, "bound-pose");
        assert!(table.contains("| ours | 0.750 ± 0.050 |"), "{table}");
        assert!(table.contains("38 ± 18 %"), "{table}");
    }
}
