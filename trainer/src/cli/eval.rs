//! `trainer eval --capture DIR --weights SPEC [--weights SPEC …] [--template FILE] [--json]`:
//! scores skinnings against the capture's ground-truth test meshes (M2S, S2M, Chamfer in
//! centimetres). `--template` poses another mesh over the same canonical space instead of the
//! capture's template (e.g. one written by `trainer resample`; SkinNet rows only).
//! `--fast [N]` adds, after every `skf:FILE` row, the runtime's fast path at N nodes (and, per
//! `--top-k K`, its top-k output), scored the same way, and prints their added error against
//! the exact path (docs/experiments/fast-path.md). `--worst-vertices` adds, per row, the
//! worst vertex of every test frame and the joints that move it (method and truth), measured
//! vertex to vertex and off the true surface.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args as ClapArgs, ValueEnum};
use skinfield_formats::capture::load_capture;
use skinfield_runtime::fast::{FastOptions, Interpolation, NodeMetric};
use skinfield_trainer::eval::diagnostics::{WorstMeasure, worst_vertices, worst_vertices_markdown};
use skinfield_trainer::eval::fast::{FastEval, TopKFormat, VsExact, evaluate_fast};
use skinfield_trainer::eval::{
    DEFAULT_SAMPLES, EvalOptions, EvalRow, Skinning, WorstVertexCheck, evaluate_template,
    load_template, off_surface_check, rows_to_json, rows_to_table, worst_vertex_check,
};

/// `--fast-metric`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MetricArg {
    /// Shortest paths along the mesh.
    Mesh,
    /// Straight-line distance (leaks between touching surfaces; for comparison).
    Euclidean,
}

/// `--fast-interp`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InterpArg {
    /// Embedded-deformation-graph weights `(1 − d/d_{k+1})²`.
    Graph,
    /// Inverse squared distance.
    Idw,
}

/// `--top-k-weights`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TopKWeightsArg {
    /// unorm8.
    Unorm8,
    /// unorm16.
    Unorm16,
    /// f32.
    F32,
}

/// Arguments of `trainer eval`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The capture folder (with ground truth for its test frames).
    #[arg(long)]
    pub capture: PathBuf,
    /// Skinning to score, one row each: `initial`, `static:FILE`, `skf:FILE`, `oracle`
    /// (ground-truth weights, LBS) or `oracle-dqs` (ground-truth weights, DQS). Repeatable.
    #[arg(long = "weights", required = true)]
    pub weights: Vec<Skinning>,
    /// Pose this glTF template (any resolution, the capture's canonical space) instead of the
    /// capture's own; only `skf:FILE` rows can pose a mesh with other vertices.
    #[arg(long)]
    pub template: Option<PathBuf>,
    /// Print `{"rows":[…]}` JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Points sampled per surface per test frame (uniform by area).
    #[arg(long, default_value_t = DEFAULT_SAMPLES)]
    pub samples: usize,
    /// Seed of the surface sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also score each `skf:FILE` with the runtime's fast path at N nodes (`--fast` alone: the
    /// runtime's default N).
    #[arg(long, value_name = "N")]
    pub fast: Option<Option<usize>>,
    /// Fast path: nodes each vertex interpolates from.
    #[arg(long, default_value_t = FastOptions::DEFAULT.neighbours)]
    pub fast_neighbours: usize,
    /// Fast path: bind-pose joints kept exactly per vertex (0: interpolate everything).
    #[arg(long, default_value_t = FastOptions::DEFAULT.base_influences)]
    pub fast_base: usize,
    /// Fast path: distance used to pick and weight the nodes.
    #[arg(long, value_enum, default_value_t = MetricArg::Mesh)]
    pub fast_metric: MetricArg,
    /// Fast path: distance-to-weight rule.
    #[arg(long, value_enum, default_value_t = InterpArg::Graph)]
    pub fast_interp: InterpArg,
    /// With `--fast`: also score the top-K output (K joints per vertex, quantised), repeatable.
    #[arg(long = "top-k", value_name = "K", requires = "fast")]
    pub top_k: Vec<usize>,
    /// Weight format of the scored top-k output.
    #[arg(long, value_enum, default_value_t = TopKWeightsArg::Unorm8)]
    pub top_k_weights: TopKWeightsArg,
    /// After the table, each row's worst vertex on every test frame and the joints moving it
    /// (the method's and the ground truth's weights, at most 4 each), vertex to vertex and off
    /// the true surface. Capture template only.
    #[arg(long, conflicts_with_all = ["json", "template"])]
    pub worst_vertices: bool,
}

impl Args {
    fn fast_eval(&self) -> Option<FastEval> {
        let nodes = (*self.fast.as_ref()?).unwrap_or(FastOptions::DEFAULT.nodes);
        Some(FastEval {
            options: FastOptions {
                nodes,
                neighbours: self.fast_neighbours,
                base_influences: self.fast_base,
                metric: match self.fast_metric {
                    MetricArg::Mesh => NodeMetric::AlongMesh,
                    MetricArg::Euclidean => NodeMetric::Euclidean,
                },
                interpolation: match self.fast_interp {
                    InterpArg::Graph => Interpolation::EmbeddedGraph,
                    InterpArg::Idw => Interpolation::InverseDistance,
                },
            },
            top_k: self.top_k.clone(),
            format: match self.top_k_weights {
                TopKWeightsArg::Unorm8 => TopKFormat::Unorm8,
                TopKWeightsArg::Unorm16 => TopKFormat::Unorm16,
                TopKWeightsArg::F32 => TopKFormat::F32,
            },
        })
    }
}

#[derive(serde::Serialize)]
struct JsonOut<'a> {
    rows: &'a [EvalRow],
    #[serde(skip_serializing_if = "<[VsExact]>::is_empty")]
    fast_vs_exact: &'a [VsExact],
}

/// Runs `trainer eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let capture = load_capture(&args.capture)
        .with_context(|| format!("loading the capture {}", args.capture.display()))?;
    let options = EvalOptions {
        samples: args.samples,
        seed: args.seed,
    };
    let template = match &args.template {
        Some(path) => load_template(path)?,
        None => capture.template.clone(),
    };
    let fast = args.fast_eval();
    let mut rows = Vec::with_capacity(args.weights.len());
    let mut vs_exact = Vec::new();
    for skinning in &args.weights {
        let row = evaluate_template(&capture, &template, skinning, &options)
            .with_context(|| format!("evaluating `{}`", skinning.method_name()))?;
        rows.push(row);
        if let (Some(fast), Skinning::Skf(path)) = (&fast, skinning) {
            let (r, e) = evaluate_fast(&capture, &template, path, fast, &options)
                .with_context(|| format!("evaluating the fast path of {}", path.display()))?;
            rows.extend(r);
            vs_exact.extend(e);
        }
    }
    if args.json {
        if vs_exact.is_empty() {
            print!("{}", rows_to_json(&rows));
        } else {
            let out = JsonOut {
                rows: &rows,
                fast_vs_exact: &vs_exact,
            };
            println!("{}", serde_json::to_string_pretty(&out)?);
        }
    } else {
        print!("{}", rows_to_table(&rows));
        print!("{}", checks_against_initial(&rows));
        if !vs_exact.is_empty() {
            println!(
                "\nfast path vs exact (same frames): vertex distance mean / max (cm), weights L1"
            );
            for e in &vs_exact {
                println!(
                    "{:<32} {:>9.5} {:>9.4} {:>9.5}   (N = {}, bind {:.0} ms)",
                    e.method, e.mean_cm, e.max_cm, e.weights_l1, e.nodes, e.bind_ms
                );
            }
        }
        if args.worst_vertices {
            for measure in [WorstMeasure::VertexToVertex, WorstMeasure::OffSurface] {
                for skinning in &args.weights {
                    let worst = worst_vertices(&capture, skinning, measure).with_context(|| {
                        format!("worst vertices of `{}`", skinning.method_name())
                    })?;
                    println!(
                        "\n{}",
                        worst_vertices_markdown(
                            &capture,
                            skinning.method_name(),
                            measure,
                            &worst,
                            4
                        )
                    );
                }
            }
        }
    }
    Ok(())
}

/// The zoo's two worst-vertex checks of every row against the `initial` row (bone heat), frame
/// by frame, as lines to print under the table; empty without an `initial` row. A fast-path row
/// is compared too.
fn checks_against_initial(rows: &[EvalRow]) -> String {
    let Some(initial) = rows.iter().find(|r| r.method == "initial") else {
        return String::new();
    };
    let mut out = String::from(
        "\nworst vertex ≤ initial's on every test frame (a row's furthest vertex against bone heat's):\n",
    );
    for row in rows.iter().filter(|r| r.method != "initial") {
        let cell =
            |check: Option<WorstVertexCheck>| check.map_or_else(|| "–".to_owned(), |c| c.summary());
        out.push_str(&format!(
            "{:<13} off surface: {}; vertex to vertex: {}\n",
            row.method,
            cell(off_surface_check(row, initial)),
            cell(worst_vertex_check(row, initial))
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinfield_trainer::eval::FrameRow;

    fn row(method: &str, worst: &[(f64, f64)]) -> EvalRow {
        EvalRow {
            method: method.into(),
            chamfer_cm: 1.0,
            m2s_cm: 0.5,
            s2m_cm: 0.5,
            frames: worst.len(),
            size: 2.0,
            chamfer_pct: 0.5,
            max_vertex_cm: None,
            max_vertex_pct: None,
            max_off_surface_cm: None,
            max_off_surface_pct: None,
            per_frame: worst
                .iter()
                .enumerate()
                .map(|(frame, &(vertex, surface))| FrameRow {
                    frame,
                    m2s_cm: 0.5,
                    s2m_cm: 0.5,
                    max_vertex_cm: Some(vertex),
                    max_off_surface_cm: Some(surface),
                })
                .collect(),
        }
    }

    #[test]
    fn every_row_is_checked_against_initial() {
        let rows = [
            row("initial", &[(3.0, 1.0), (4.0, 2.0)]),
            row("ours", &[(3.5, 1.0), (4.0, 1.5)]),
            row("oracle", &[(1.0, 0.5), (1.0, 0.5)]),
        ];
        let text = checks_against_initial(&rows);
        let lines: Vec<&str> = text.lines().skip(2).collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(
            lines[0].starts_with("ours ")
                && lines[0].ends_with(
                    "off surface: yes (2 frames); vertex to vertex: no: 1 of 2 frames (by up to 0.50 cm)"
                ),
            "{text}"
        );
        assert!(lines[1].starts_with("oracle "), "{text}");
        assert!(
            lines[1].contains("vertex to vertex: yes (2 frames)"),
            "{text}"
        );
        // Rows without per-frame figures get a dash; without an initial row, nothing.
        let mut bare = row("static", &[]);
        bare.per_frame.clear();
        let text = checks_against_initial(&[rows[0].clone(), bare]);
        assert!(
            text.contains("off surface: –; vertex to vertex: –"),
            "{text}"
        );
        assert_eq!(checks_against_initial(&rows[1..]), "");
    }
}
