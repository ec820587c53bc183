//! Markdown table of every method × scenario with the shared metrics.

use std::fmt::Write as _;

use pf_planner::metrics::PathMetrics;

/// One cell block of the table: a method's result on a scenario.
#[derive(Debug, Clone)]
pub struct ReportRow {
    /// Scenario name.
    pub scenario: String,
    /// Method label (e.g. "P-F indicator 64²").
    pub method: String,
    /// Whether this row is the reference (graph optimum) the others are compared with.
    pub is_reference: bool,
    /// Metrics and timing, or the error text.
    pub outcome: Result<RowData, String>,
}

/// Numbers of one method on one scenario, over every repeat.
#[derive(Debug, Clone)]
pub struct RowData {
    /// Metrics of the first repeat's path (the methods are deterministic; see `metrics_spread`).
    pub metrics: PathMetrics,
    /// Largest relative difference of ∫p ds between repeats (0 when every repeat gave the same path).
    pub metrics_spread: f64,
    /// Wall-clock time of the method per repeat, seconds (P-F: generator build included).
    pub solve_times_s: Vec<f64>,
    /// P-F only: the generator build per repeat, seconds (part of `solve_times_s`).
    pub generator_times_s: Option<Vec<f64>>,
    /// Graph search only: nodes expanded.
    pub expanded: Option<usize>,
}

/// `min–max` of `values` in milliseconds (`–` when empty).
fn millisecond_range(values: &[f64]) -> String {
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if values.is_empty() {
        "–".to_string()
    } else {
        let digits = if hi < 0.01 { 2 } else { 1 };
        format!("{:.digits$}–{:.digits$}", lo * 1e3, hi * 1e3)
    }
}

/// Renders the rows as a markdown table; `∫p ds / ref` divides by the reference row of the same scenario.
pub fn markdown_table(rows: &[ReportRow]) -> String {
    let mut out = String::from(
        "| scenario | method | ∫p ds | ∫p ds / Dijkstra | length [m] | in obstacles [m] | min clearance [m] | max slope [°] | expanded nodes | solve time [ms] | of which generators [ms] |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for row in rows {
        let reference = rows
            .iter()
            .find(|r| r.scenario == row.scenario && r.is_reference)
            .and_then(|r| r.outcome.as_ref().ok())
            .map(|d| d.metrics.cost_integral);
        match &row.outcome {
            Ok(d) => {
                let m = &d.metrics;
                let ratio =
                    reference.map_or("–".to_string(), |r| format!("{:.3}", m.cost_integral / r));
                let clearance = if m.min_clearance.is_finite() {
                    format!("{:.3}", m.min_clearance)
                } else {
                    "no obstacles".to_string()
                };
                let expanded = d.expanded.map_or("–".to_string(), |n| n.to_string());
                let generators = d
                    .generator_times_s
                    .as_deref()
                    .map_or("–".to_string(), millisecond_range);
                let _ = writeln!(
                    out,
                    "| {} | {} | {:.4} | {} | {:.2} | {:.3} | {} | {:.1} | {} | {} | {} |",
                    row.scenario,
                    row.method,
                    m.cost_integral,
                    ratio,
                    m.length,
                    m.length_in_obstacles,
                    clearance,
                    m.max_slope_deg,
                    expanded,
                    millisecond_range(&d.solve_times_s),
                    generators
                );
            }
            Err(e) => {
                let _ = writeln!(
                    out,
                    "| {} | {} | failed: {} | | | | | | | | |",
                    row.scenario,
                    row.method,
                    e.replace('|', "/")
                );
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(cost: f64) -> Result<RowData, String> {
        Ok(RowData {
            metrics: PathMetrics {
                cost_integral: cost,
                length: 10.0,
                length_in_obstacles: 0.0,
                min_clearance: f64::INFINITY,
                max_slope_deg: 3.0,
            },
            metrics_spread: 0.0,
            solve_times_s: vec![0.5, 0.25, 0.0125],
            generator_times_s: None,
            expanded: Some(12),
        })
    }

    #[test]
    fn ratios_are_relative_to_the_reference_of_the_same_scenario() {
        let rows = vec![
            ReportRow {
                scenario: "a".into(),
                method: "dijkstra".into(),
                is_reference: true,
                outcome: data(2.0),
            },
            ReportRow {
                scenario: "a".into(),
                method: "astar".into(),
                is_reference: false,
                outcome: data(3.0),
            },
            ReportRow {
                scenario: "b".into(),
                method: "pf".into(),
                is_reference: false,
                outcome: Err("stuck | here".into()),
            },
        ];
        let table = markdown_table(&rows);
        assert!(table.contains("| a | astar | 3.0000 | 1.500 |"), "{table}");
        assert!(table.contains("| a | dijkstra | 2.0000 | 1.000 |"));
        // Times as min–max over the repeats, in milliseconds.
        assert!(table.contains("| 12 | 12.5–500.0 | – |"), "{table}");
        assert!(table.contains("failed: stuck / here"));
        assert_eq!(table.lines().count(), 5);
    }
}
