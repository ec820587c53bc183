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

/// Numbers of one successful plan.
#[derive(Debug, Clone, Copy)]
pub struct RowData {
    pub metrics: PathMetrics,
    /// Wall-clock time of the method, seconds.
    pub solve_time_s: f64,
}

/// Renders the rows as a markdown table; `∫p ds / ref` divides by the reference row of the same scenario.
pub fn markdown_table(rows: &[ReportRow]) -> String {
    let mut out = String::from(
        "| scenario | method | ∫p ds | ∫p ds / Dijkstra | length [m] | in obstacles [m] | min clearance [m] | max slope [°] | time [s] |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|\n",
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
                let _ = writeln!(
                    out,
                    "| {} | {} | {:.4} | {} | {:.2} | {:.3} | {} | {:.1} | {:.3} |",
                    row.scenario,
                    row.method,
                    m.cost_integral,
                    ratio,
                    m.length,
                    m.length_in_obstacles,
                    clearance,
                    m.max_slope_deg,
                    d.solve_time_s
                );
            }
            Err(e) => {
                let _ = writeln!(
                    out,
                    "| {} | {} | failed: {} | | | | | | |",
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
            solve_time_s: 0.5,
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
        assert!(table.contains("failed: stuck / here"));
        assert_eq!(table.lines().count(), 5);
    }
}
