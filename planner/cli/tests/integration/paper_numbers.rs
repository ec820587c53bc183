//! `pf-plan paper-numbers`: runs on small grids and writes the page with its tables, the paper's
//! quoted figures beside numbers it computed (functional only: no timing is checked).

use std::process::Command;

#[test]
fn paper_numbers_writes_the_tables() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("paper");
    let output = Command::new(env!("CARGO_BIN_EXE_pf-plan"))
        .args([
            "paper-numbers",
            "--grid",
            "32",
            "--rbf-grid",
            "16",
            "--skip-large",
            "--footprint-radius",
            "0.25",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("pf-plan runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "pf-plan failed: {stderr}");
    let page = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert_eq!(
        String::from_utf8_lossy(&output.stdout),
        page,
        "stdout is the page"
    );
    for heading in [
        "## The paper's figures",
        "### Pits: the density in the obstacles",
        "## The formulation note's prototype figures",
    ] {
        assert!(page.contains(heading), "missing {heading:?} in\n{page}");
    }
    // Every row of the paper's table has its five cells, and ours is a number where the paper
    // has one.
    let row = |prefix: &str| -> Vec<String> {
        let line = page
            .lines()
            .find(|l| l.starts_with(&format!("| {prefix}")))
            .unwrap_or_else(|| panic!("no row {prefix:?} in\n{page}"));
        line.trim_matches('|')
            .split(" | ")
            .map(|c| c.trim().to_string())
            .collect()
    };
    let number = |cell: &str| -> f64 {
        cell.split_whitespace()
            .next()
            .and_then(|t| t.parse().ok())
            .unwrap_or_else(|| panic!("not a number: {cell:?}"))
    };
    let pf = row("c_shape: ∫p ds of the P-F path");
    assert_eq!(pf.len(), 5, "{pf:?}");
    assert_eq!(pf[1], "0.75");
    let astar = row("c_shape: ∫p ds of the A* path");
    assert_eq!(astar[1], "1.03");
    let ratio = row("c_shape: P-F / A*");
    assert_eq!(ratio[1], "0.728");
    let (ours_pf, ours_astar) = (number(&pf[3]), number(&astar[3]));
    assert!(ours_pf > 0.0 && ours_astar > 0.0);
    assert!(
        (number(&ratio[3]) - ours_pf / ours_astar).abs() < 2e-3,
        "ratio row agrees with its rows: {ratio:?}"
    );
    // The floor: the same path without the floor never costs more (on this terrain the road's
    // own p is above the floor, so it costs the same).
    let floored = number(&row("mountain_pass: ∫p ds of the P-F path")[3]);
    let bare = number(&row("mountain_pass: the same path with p_floor → 0")[3]);
    assert!(bare > 0.0 && bare <= floored, "0 < {bare} ≤ {floored}");
    // The obstacle mass: six rows (three bases × two start densities), shares in [0, 1].
    let masses: Vec<&str> = page
        .lines()
        .filter(|l| {
            l.starts_with("| P-F ")
                && (l.contains("| point mass at the start |")
                    || l.contains("| uniform over free space |"))
        })
        .collect();
    assert_eq!(masses.len(), 6, "{masses:?}");
    for line in masses {
        let share = number(line.trim_matches('|').rsplit(" | ").next().expect("cell"));
        assert!((0.0..=1.0).contains(&share), "{line}");
        // Indicators of cells touching an obstacle are not in the basis: no mass there at all.
        if line.starts_with("| P-F indicator") {
            assert_eq!(share, 0.0, "{line}");
        }
    }
    assert!(
        !page.contains("NaN") && !page.contains(" inf"),
        "a number is not finite:\n{page}"
    );
}
