//! `pf-plan import` end to end: a DEM made here becomes a scenario that `pf-plan plan` plans on.

#[path = "../../../core/tests/support/import_fixtures.rs"]
mod fixtures;

use std::path::Path;
use std::process::{Command, Output};

use fixtures::Dem;

fn pf_plan(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pf-plan"))
        .args(args)
        .output()
        .expect("run pf-plan")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A 1 m DEM of 120 x 80 m: a hill in the middle of a gentle slope, nodata in one corner.
fn write_dem(path: &Path) {
    let mut dem = Dem::from_fn(120, 80, 350_000.0, 5_200_000.0, 1.0, |x, y| {
        let (u, v) = (x - 350_060.0, y - 5_200_040.0);
        800.0 + 0.05 * u + 12.0 * (-(u * u + v * v) / 400.0).exp()
    });
    for row in 0..5 {
        for column in 0..5 {
            dem.values[row * 120 + column] = -9999.0;
        }
    }
    dem.write_asc(path, Some(-9999.0));
}

#[test]
fn import_prints_a_summary_and_writes_a_scenario_that_plans() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dem = dir.path().join("hill dem.asc");
    write_dem(&dem);
    let out = dir.path().join("maps");
    let dem_arg = dem.to_str().expect("utf-8 path");
    let out_arg = out.to_str().expect("utf-8 path");
    // A 100 x 70 m crop (with the nodata corner) at 1/20 scale: --cell-size is the written
    // map's, so 0.05 m cells are the source's 1 m cells; the map is 5 x 3.5 m.
    let common = [
        "import",
        dem_arg,
        "--out",
        out_arg,
        "--crop",
        "350000,5200010,350100,5200080",
        "--scale",
        "1/20",
        "--cell-size",
        "0.05",
    ];
    let missing = pf_plan(&common);
    assert!(!missing.status.success());
    let stderr = text(&missing.stderr);
    assert!(stderr.contains("--start X,Y --goal X,Y"), "{stderr}");
    let summary = text(&missing.stdout);
    assert!(
        summary.contains("map:     100 x 70 cells of 0.05 m"),
        "{summary}"
    );

    let mut args = common.to_vec();
    args.extend([
        "--start", "0.3,1.75", "--goal", "4.7,1.75", "--name", "hill",
    ]);
    let ok = pf_plan(&args);
    let stdout = text(&ok.stdout);
    assert!(ok.status.success(), "{stdout}{}", text(&ok.stderr));
    for expected in [
        "source:  ESRI ASCII grid of 120 x 80 cells of 1 x 1, lower-left corner (350000, 5200000)",
        "crop:    100 x 70 cells, lower-left corner (350000, 5200010)",
        "slope:   p50",
        "nodata:  0.36 %",
    ] {
        assert!(stdout.contains(expected), "{expected:?} in\n{stdout}");
    }
    let json = out.join("hill.json");
    assert!(
        stdout.trim_end().ends_with(json.to_str().expect("utf-8")),
        "{stdout}"
    );

    let plans = dir.path().join("plans");
    let plan = pf_plan(&[
        "plan",
        "--map",
        json.to_str().expect("utf-8"),
        "--method",
        "pf",
        "--grid",
        "40",
        "--out",
        plans.to_str().expect("utf-8"),
    ]);
    assert!(
        plan.status.success(),
        "{}{}",
        text(&plan.stdout),
        text(&plan.stderr)
    );
    assert!(plans.join("hill_pf.json").exists());

    // The uncropped DEM has nodata in its north-west corner: a start there is refused.
    let corner = pf_plan(&[
        "import", dem_arg, "--out", out_arg, "--start", "1,78", "--goal", "60,40",
    ]);
    assert!(!corner.status.success());
    let stderr = text(&corner.stderr);
    assert!(stderr.contains("obstacle"), "{stderr}");
    assert!(text(&corner.stdout).contains("nodata:  0.26 %"));
}

#[test]
fn import_flags_are_checked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dem = dir.path().join("dem.asc");
    write_dem(&dem);
    let dem_arg = dem.to_str().expect("utf-8 path");
    let out_arg = dir.path().to_str().expect("utf-8 path");
    for (flags, expected) in [
        (
            vec!["--crop", "1,2,3"],
            "expected 4 comma-separated numbers",
        ),
        (vec!["--size", "10.5,3"], "not a whole number"),
        (vec!["--scale", "-1"], "not a finite factor > 0"),
        (vec!["--scale", "1/0"], "not a finite factor > 0"),
        (
            vec!["--cell-size", "0.1", "--size", "10,10"],
            "cannot be used with",
        ),
        (vec!["--format", "png"], "invalid value"),
    ] {
        let mut args = vec!["import", dem_arg, "--out", out_arg];
        args.extend(flags.iter().copied());
        let result = pf_plan(&args);
        assert!(!result.status.success(), "{flags:?}");
        let stderr = text(&result.stderr);
        assert!(stderr.contains(expected), "{flags:?}: {stderr}");
    }
    let unknown = dir.path().join("dem.xyz");
    std::fs::copy(&dem, &unknown).expect("copy");
    let result = pf_plan(&["import", unknown.to_str().expect("utf-8"), "--out", out_arg]);
    assert!(text(&result.stderr).contains("--format"));
    let forced = pf_plan(&[
        "import",
        unknown.to_str().expect("utf-8"),
        "--out",
        out_arg,
        "--format",
        "asc",
        "--start",
        "50,40",
        "--goal",
        "100,40",
    ]);
    assert!(forced.status.success(), "{}", text(&forced.stderr));
}
