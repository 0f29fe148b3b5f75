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
//!
//! The paired difference of a row is its Chamfer distance minus a reference row's *of the same
//! seed*, then averaged. Two rows trained on the same capture share most of their seed-to-seed
//! variation (the capture's motion amplitudes, colours and cameras move both), so whether one
//! method beats another is read from the spread of the per-seed differences, not from the two
//! rows' spreads.

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
    /// Chamfer minus the reference row's, per seed (cm; `None` without a reference row).
    pub paired_delta_cm: Option<MeanStd>,
    /// Seeds that had this row.
    pub seeds: usize,
}

/// Groups `runs` (one table per seed) by method, in the order of first appearance, with the gap
/// share against the row named `bound` (and `initial`) of the same seed, and the paired
/// difference to the row named `reference`.
#[must_use]
pub fn spread(
    runs: &[Vec<EvalRow>],
    bound: Option<&str>,
    reference: Option<&str>,
) -> Vec<SpreadRow> {
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
                        (find(rows, "initial")?, find(rows, bound?)?, find(rows, m)?);
                    let gap = initial - bound;
                    (gap.abs() > 1e-12).then(|| (initial - row) / gap)
                })
                .collect();
            let deltas: Vec<f64> = runs
                .iter()
                .filter_map(|rows| Some(find(rows, m)? - find(rows, reference?)?))
                .collect();
            SpreadRow {
                method: m.to_string(),
                chamfer_cm: of(|r| r.chamfer_cm),
                m2s_cm: of(|r| r.m2s_cm),
                s2m_cm: of(|r| r.s2m_cm),
                gap_share: (!shares.is_empty()).then(|| MeanStd::of(&shares)),
                paired_delta_cm: (!deltas.is_empty()).then(|| MeanStd::of(&deltas)),
                seeds: rows.len(),
            }
        })
        .collect()
}

/// The rows as a Markdown table (`mean ± std`): the gap share in per cent when `bound` is
/// given, the paired difference when `reference` is.
#[must_use]
pub fn spread_table(rows: &[SpreadRow], bound: Option<&str>, reference: Option<&str>) -> String {
    let mut s = String::new();
    let mut header = "| method | Chamfer (cm) | M2S (cm) | S2M (cm) |".to_string();
    if let Some(bound) = bound {
        let _ = write!(header, " share of the initial → {bound} gap |");
    }
    if let Some(reference) = reference {
        let _ = write!(header, " Chamfer − {reference}'s, paired (cm) |");
    }
    header.push_str(" seeds |");
    let columns = header.matches('|').count() - 1;
    let _ = writeln!(s, "{header}");
    let _ = writeln!(s, "|{}", " --- |".repeat(columns));
    let pm = |m: MeanStd| format!("{:.3} ± {:.3}", m.mean, m.std);
    for r in rows {
        let _ = write!(
            s,
            "| {} | {} | {} | {} |",
            r.method,
            pm(r.chamfer_cm),
            pm(r.m2s_cm),
            pm(r.s2m_cm)
        );
        if bound.is_some() {
            let share = r.gap_share.map_or_else(
                || "—".to_string(),
                |g| format!("{:.0} ± {:.0} %", 100.0 * g.mean, 100.0 * g.std),
            );
            let _ = write!(s, " {share} |");
        }
        if reference.is_some() {
            let delta = r.paired_delta_cm.map_or_else(
                || "—".to_string(),
                |d| format!("{:+.3} ± {:.3}", d.mean, d.std),
            );
            let _ = write!(s, " {delta} |");
        }
        let _ = writeln!(s, " {} |", r.seeds);
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
            max_off_surface_cm: None,
            max_off_surface_pct: None,
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
        let s = spread(&runs, Some("bound-pose"), Some("initial"));
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
        // Paired against the initial row: −0.2, −0.5, −0.35 (the spread of the rows themselves
        // is 0.1 and 0.05; the differences' is 0.15).
        let d = ours.paired_delta_cm.unwrap();
        assert!((d.mean + 0.35).abs() < 1e-12, "{d:?}");
        assert!((d.std - 0.15).abs() < 1e-12, "{d:?}");
        assert_eq!(s[0].paired_delta_cm.unwrap(), MeanStd::default());
        let table = spread_table(&s, Some("bound-pose"), Some("initial"));
        assert!(table.contains("| ours | 0.750 ± 0.050 |"), "{table}");
        assert!(
            table.contains("38 ± 18 % | -0.350 ± 0.150 | 3 |"),
            "{table}"
        );
        assert_eq!(
            table.lines().nth(1),
            Some("| --- | --- | --- | --- | --- | --- | --- |")
        );
        // Without a bound or a reference the table has neither column.
        let plain = spread_table(&spread(&runs, None, None), None, None);
        assert_eq!(
            plain.lines().nth(1),
            Some("| --- | --- | --- | --- | --- |")
        );
        assert!(
            plain.contains("| ours | 0.750 ± 0.050 | 0.375 ± 0.025 | 0.375 ± 0.025 | 3 |"),
            "{plain}"
        );
    }
}
