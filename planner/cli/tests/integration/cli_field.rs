//! `pf-plan plan --field-out/--field-plot`: the feedback law of a P-F plan as a numpy `.npz` and a
//! PNG; numpy reads the archive (checked with the repo's venv Python when it is there).

use std::path::Path;
use std::process::Command;

fn pf_plan(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_pf-plan"))
        .args(args)
        .output()
        .expect("pf-plan runs")
}

/// A P-F plan of c_shape on a 32² grid into `dir`, with `extra` arguments; it must succeed.
fn plan_c_shape(dir: &Path, extra: &[&str]) {
    let mut args = vec![
        "plan",
        "--scenario",
        "c_shape",
        "--method",
        "pf",
        "--grid",
        "32",
        "--out",
        dir.to_str().expect("utf-8 path"),
    ];
    args.extend_from_slice(extra);
    let out = pf_plan(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Runs the Python `check` (which prints "ok") with the repo's venv on `files`; skipped without
/// a venv.
fn numpy_check(check: &str, files: &[&Path]) {
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python");
    if !python.exists() {
        eprintln!("no .venv: numpy check skipped (scripts/setup.sh makes it)");
        return;
    }
    let out = Command::new(python)
        .arg("-c")
        .arg(check)
        .args(files.iter().map(|f| f.as_os_str()))
        .output()
        .expect("python runs");
    assert!(
        out.status.success() && String::from_utf8_lossy(&out.stdout).trim() == "ok",
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn the_field_is_written_as_npz_and_png_and_numpy_reads_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (npz, png) = (dir.path().join("field.npz"), dir.path().join("field.png"));
    plan_c_shape(
        dir.path(),
        &[
            "--field-out",
            npz.to_str().expect("utf-8 path"),
            "--field-plot",
            png.to_str().expect("utf-8 path"),
        ],
    );
    assert!(png.metadata().expect("png written").len() > 10_000);
    let check = r#"
import sys, numpy as np
z = np.load(sys.argv[1])
assert sorted(z.files) == ["cost_to_go", "dir_x", "dir_y", "goal", "origin", "resolution", "speed"], z.files
for k in ("dir_x", "dir_y", "speed", "cost_to_go"):
    assert z[k].shape == (32, 32) and z[k].dtype == np.float64, (k, z[k].shape, z[k].dtype)
assert z["origin"].shape == (2,) and z["resolution"].shape == () and z["goal"].shape == (3,)
assert float(z["resolution"]) == 0.5
c = z["cost_to_go"]
moving = c > 0
assert np.allclose(np.hypot(z["dir_x"], z["dir_y"])[moving], 1.0)
assert np.all(z["speed"][moving] == 0.5) and c.min() >= 0.0
gx, gy, r = z["goal"]
ix, iy = int(gx / 0.5), int(gy / 0.5)
assert c[iy, ix] == 0.0, c[iy, ix]
print("ok")
"#;
    numpy_check(check, &[&npz]);
}

#[test]
fn a_field_without_a_pf_plan_is_refused_with_the_reason() {
    let dir = tempfile::tempdir().expect("temp dir");
    let npz = dir.path().join("field.npz");
    let out = pf_plan(&[
        "plan",
        "--scenario",
        "pits",
        "--method",
        "dijkstra",
        "--grid",
        "16",
        "--out",
        dir.path().to_str().expect("utf-8 path"),
        "--field-out",
        npz.to_str().expect("utf-8 path"),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("need a P-F plan"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!npz.exists());
}

#[test]
fn the_occupation_density_is_written_on_the_planning_grid() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (density, field) = (dir.path().join("density.npz"), dir.path().join("field.npz"));
    plan_c_shape(
        dir.path(),
        &[
            "--field-out",
            field.to_str().expect("utf-8 path"),
            "--density-out",
            density.to_str().expect("utf-8 path"),
        ],
    );
    // The uniform start puts mass on every cell that reaches the goal: ρ > 0 exactly where the
    // field has a cost-to-go > 0, 0 in the goal and where the goal is out of reach.
    let check = r#"
import sys, numpy as np
d, f = np.load(sys.argv[1]), np.load(sys.argv[2])
assert sorted(d.files) == ["density", "origin", "resolution"], d.files
rho = d["density"]
assert rho.shape == (32, 32) and rho.dtype == np.float64, (rho.shape, rho.dtype)
assert np.array_equal(d["origin"], f["origin"]) and float(d["resolution"]) == float(f["resolution"]) == 0.5
c = f["cost_to_go"]
assert np.all(np.isfinite(rho)) and rho.min() >= 0.0
assert np.all(rho[c > 0] > 0.0) and np.all(rho[c <= 0] == 0.0)
print("ok")
"#;
    numpy_check(check, &[&density, &field]);
}
