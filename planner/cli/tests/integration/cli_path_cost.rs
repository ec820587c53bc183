//! `pf-plan path-cost`, `pf-plan traversability` and `pf-plan scenario list`: the planner's cost
//! model and scenario list as the harness reads them, and clear errors (never a panic) on bad input.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use pf_planner::io::{load_scenario, parse_path_csv, read_npy, save_scenario};
use pf_planner::metrics::evaluate_path;
use pf_planner::scenarios::{self, SCENARIO_NAMES};
use pf_planner::traversability::TraversabilityField;
use serde_json::Value;

fn pf_plan(args: &[&str], stdin: Option<&str>) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_pf-plan"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("pf-plan runs");
    {
        let mut input = child.stdin.take().expect("stdin");
        if let Some(text) = stdin {
            input.write_all(text.as_bytes()).expect("write stdin");
        }
    }
    child.wait_with_output().expect("pf-plan finishes")
}

fn json_of(output: &Output) -> Value {
    assert!(
        output.status.success(),
        "pf-plan failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("stdout is JSON")
}

/// Asserts a clean failure: non-zero exit, the expected words on stderr, no panic.
fn assert_refused(output: &Output, expected: &str) {
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "accepted; stderr {stderr}");
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains(expected),
        "expected {expected:?} in {stderr}"
    );
}

fn export(name: &str, dir: &Path) -> PathBuf {
    save_scenario(&scenarios::by_name(name).expect("scenario"), dir).expect("export")
}

fn csv(points: &[[f64; 2]]) -> String {
    let mut text = String::from("x,y\n");
    for p in points {
        // `{:?}` prints the shortest representation that reads back to the same f64.
        text.push_str(&format!("{:?},{:?}\n", p[0], p[1]));
    }
    text
}

#[test]
fn path_cost_is_the_library_metric_on_every_scenario_with_and_without_footprint() {
    let dir = tempfile::tempdir().expect("tempdir");
    for name in SCENARIO_NAMES {
        let map_file = export(name, dir.path());
        let scenario = load_scenario(&map_file).expect("load");
        // Start → a corner → goal: crosses the scenario's hills (and c_shape's wall).
        let corner = [
            scenario.map.origin[0] + 0.5 * scenario.map.resolution * scenario.map.width as f64,
            scenario.map.origin[1] + 0.8 * scenario.map.resolution * scenario.map.height as f64,
        ];
        let path = [scenario.start, corner, scenario.goal.center];
        let path_file = dir.path().join(format!("{name}.path.csv"));
        std::fs::write(&path_file, csv(&path)).expect("write csv");
        for radius in [0.0, 0.25] {
            let mut params = scenario.traversability;
            params.footprint_radius_m = radius;
            let field = TraversabilityField::from_map(&scenario.map, &params).expect("field");
            let expected = evaluate_path(&scenario.map, &field, &path);
            let radius_arg = format!("--footprint-radius={radius}");
            let out = json_of(&pf_plan(
                &[
                    "path-cost",
                    "--map",
                    map_file.to_str().expect("utf-8"),
                    &radius_arg,
                    "--path",
                    path_file.to_str().expect("utf-8"),
                ],
                None,
            ));
            // Bit for bit: the same code on the same numbers.
            assert_eq!(out["cost_integral"].as_f64(), Some(expected.cost_integral));
            assert_eq!(out["length"].as_f64(), Some(expected.length));
            assert_eq!(
                out["length_in_obstacles"].as_f64(),
                Some(expected.length_in_obstacles)
            );
            assert_eq!(out["max_slope_deg"].as_f64(), Some(expected.max_slope_deg));
            assert_eq!(out["points"].as_u64(), Some(3));
            assert_eq!(out["footprint_radius_m"].as_f64(), Some(radius));
            assert!(expected.cost_integral > 0.0 && expected.length > 0.0);
        }
    }
}

#[test]
fn a_footprint_raises_the_cost_and_the_built_in_scenario_equals_its_export() {
    let dir = tempfile::tempdir().expect("tempdir");
    let map_file = export("mountain_pass", dir.path());
    let scenario = load_scenario(&map_file).expect("load");
    let text = csv(&[scenario.start, scenario.goal.center]);
    let cost = |args: &[&str]| {
        let mut all = vec!["path-cost", "--path", "-"];
        all.extend_from_slice(args);
        json_of(&pf_plan(&all, Some(&text)))["cost_integral"]
            .as_f64()
            .expect("cost")
    };
    let map = map_file.to_str().expect("utf-8");
    let point = cost(&["--map", map]);
    assert_eq!(point, cost(&["--scenario", "mountain_pass"]));
    let footprint = cost(&["--map", map, "--footprint-radius", "0.25"]);
    assert!(footprint > point, "{footprint} <= {point}");
}

#[test]
fn a_trajectory_csv_of_pf_plan_plan_is_read_by_its_x_and_y_columns() {
    let path = parse_path_csv(
        "t,x,y,z,yaw,vx,vy,yaw_rate\n0.0,1.0,2.0,0.3,0,0,0,0\n\n0.1,1.5,2.5,0.3,0,0,0,0\n",
        "traj.csv",
    )
    .expect("parses");
    assert_eq!(path, vec![[1.0, 2.0], [1.5, 2.5]]);
    let reordered = parse_path_csv(" y , x \n2,1\n", "p.csv").expect("parses");
    assert_eq!(reordered, vec![[1.0, 2.0]]);
}

#[test]
fn bad_paths_are_refused_with_a_reason() {
    let cases: [(&str, &str); 7] = [
        ("", "empty"),
        ("x,y\n", "no points"),
        ("a,b\n1,2\n", "no column \"x\""),
        ("x,y\n1,2\n3\n", "line 3: 1 fields"),
        ("x,y\n1,abc\n", "y = \"abc\" is not a number"),
        ("x,y\n1,NaN\n", "not finite"),
        ("x,y\ninf,2\n", "not finite"),
    ];
    for (text, expected) in cases {
        let err = parse_path_csv(text, "p.csv").expect_err(text);
        assert!(err.to_string().contains(expected), "{text:?}: {err}");
        let out = pf_plan(
            &["path-cost", "--scenario", "pits", "--path", "-"],
            Some(text),
        );
        assert_refused(&out, expected);
    }
}

#[test]
fn bad_maps_and_options_are_refused_with_a_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path_file = dir.path().join("p.csv");
    std::fs::write(&path_file, "x,y\n1,1\n2,2\n").expect("write");
    let path = path_file.to_str().expect("utf-8");
    assert_refused(
        &pf_plan(
            &["path-cost", "--scenario", "nowhere", "--path", path],
            None,
        ),
        "unknown scenario",
    );
    assert_refused(
        &pf_plan(
            &["path-cost", "--map", "/nonexistent/m.json", "--path", path],
            None,
        ),
        "loading map",
    );
    assert_refused(
        &pf_plan(
            &[
                "path-cost",
                "--scenario",
                "pits",
                "--path",
                "/nonexistent.csv",
            ],
            None,
        ),
        "I/O error",
    );
    for radius in ["-0.1", "NaN", "100"] {
        assert_refused(
            &pf_plan(
                &[
                    "path-cost",
                    "--scenario",
                    "pits",
                    "--footprint-radius",
                    radius,
                    "--path",
                    path,
                ],
                None,
            ),
            "footprint_radius_m",
        );
    }
    let out = dir.path().join("p.npy");
    assert_refused(
        &pf_plan(
            &[
                "traversability",
                "--scenario",
                "pits",
                "--footprint-radius=-1",
                "--out",
                out.to_str().expect("utf-8"),
            ],
            None,
        ),
        "footprint_radius_m",
    );
}

#[test]
fn traversability_writes_the_planners_field() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("p.npy");
    let output = pf_plan(
        &[
            "traversability",
            "--scenario",
            "c_shape",
            "--footprint-radius",
            "0.25",
            "--out",
            out.to_str().expect("utf-8"),
        ],
        None,
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let scenario = scenarios::by_name("c_shape").expect("scenario");
    let mut params = scenario.traversability;
    params.footprint_radius_m = 0.25;
    let field = TraversabilityField::from_map(&scenario.map, &params).expect("field");
    let written = read_npy(&out).expect("npy");
    assert_eq!(written.shape, (scenario.map.height, scenario.map.width));
    assert_eq!(written.values, field.values);
}

#[test]
fn scenario_list_names_every_built_in_scenario_as_exported() {
    let names = pf_plan(&["scenario", "list"], None);
    assert!(names.status.success());
    let listed: Vec<String> = String::from_utf8_lossy(&names.stdout)
        .lines()
        .map(str::to_string)
        .collect();
    assert_eq!(listed, SCENARIO_NAMES);
    let list = json_of(&pf_plan(&["scenario", "list", "--json"], None));
    let entries = list.as_array().expect("array");
    assert_eq!(entries.len(), SCENARIO_NAMES.len());
    for (entry, name) in entries.iter().zip(SCENARIO_NAMES) {
        let s = scenarios::by_name(name).expect("scenario");
        assert_eq!(entry["name"], name);
        assert_eq!(entry["seed"].as_u64(), s.seed);
        assert_eq!(entry["width"].as_u64(), Some(s.map.width as u64));
        assert_eq!(entry["start"][0].as_f64(), Some(s.start[0]));
        assert_eq!(entry["goal"]["radius"].as_f64(), Some(s.goal.radius));
    }
}
