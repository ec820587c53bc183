//! Soak test of the bundled FMU: many doSteps (default 10^6) and instantiate/free cycles in one
//! process, printing the resident set size so that a leak shows up as growth.
//!
//! ```sh
//! cargo run --release -p quad-controller-fmu --example fmu_soak -- [FMU] [STEPS] [CYCLES]
//! ```
//! Defaults: `target/fmu/QuadController.fmu`, 1_000_000 steps of one 1 ms tick each (set all
//! Real inputs, doStep, get 12 torques), 2000 instantiate/initialise/step/free cycles.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use fmi::fmi2::import::Fmi2Import;
use fmi::fmi2::instance::{CoSimulation, Common, InstanceCS};
use quad_controller::{Controller, ControllerConfig, RobotModel, NUM_JOINTS};
use quad_controller_fmu::bundle::{default_robot_config, repo_root};
use quad_controller_fmu::variables::VariableTable;

fn rss_kib() -> Result<u64> {
    let status =
        std::fs::read_to_string("/proc/self/status").context("reading /proc/self/status")?;
    let line = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .context("no VmRSS line")?;
    line.split_whitespace()
        .nth(1)
        .context("VmRSS value")?
        .parse()
        .context("VmRSS number")
}

fn vr(name: &str) -> Result<u32> {
    static TABLE: std::sync::OnceLock<Result<VariableTable, String>> = std::sync::OnceLock::new();
    let table = TABLE
        .get_or_init(|| {
            VariableTable::for_robot_config(&default_robot_config()).map_err(|e| e.to_string())
        })
        .as_ref()
        .map_err(|e| anyhow::anyhow!("our robot's variable table: {e}"))?;
    Ok(table
        .by_name(name)
        .with_context(|| format!("variable {name}"))?
        .value_reference)
}

fn initialised(import: &Fmi2Import, name: &str) -> Result<InstanceCS> {
    let mut instance = import.instantiate_cs(name, false, false)?;
    instance
        .setup_experiment(None, 0.0, None)
        .map_err(|e| anyhow::anyhow!("setup: {e:?}"))?;
    instance
        .enter_initialization_mode()
        .map_err(|e| anyhow::anyhow!("enter: {e:?}"))?;
    instance
        .exit_initialization_mode()
        .map_err(|e| anyhow::anyhow!("exit: {e:?}"))?;
    Ok(instance)
}

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let fmu = args.next().map(PathBuf::from).unwrap_or_else(|| {
        repo_root()
            .join("target")
            .join("fmu")
            .join("QuadController.fmu")
    });
    let steps: u64 = args
        .next()
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(1_000_000);
    let cycles: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(2000);
    if !fmu.is_file() {
        bail!(
            "{} not found: run `cargo run --release -p quad-controller-fmu --bin bundle-fmu`",
            fmu.display()
        );
    }
    let config = ControllerConfig::default();
    let model = RobotModel::from_config_file(&default_robot_config())?;
    let stand = Controller::new(model, config.clone())?.stand_joint_positions();

    let import: Fmi2Import = fmi::import::from_path(&fmu)?;
    let mut instance = initialised(&import, "soak")?;
    let mut input_vrs = vec![vr("base.pos.z")?, vr("base.vel.z")?];
    let mut values = vec![config.body_height, 0.0];
    for (i, q) in stand.iter().enumerate() {
        input_vrs.push(vr(&format!("joint.q[{}]", i + 1))?);
        values.push(*q);
        input_vrs.push(vr(&format!("joint.dq[{}]", i + 1))?);
        values.push(0.0);
    }
    let torque_vrs = (1..=NUM_JOINTS)
        .map(|i| vr(&format!("joint.tau[{i}]")))
        .collect::<Result<Vec<_>>>()?;
    let mut torques = [0.0; NUM_JOINTS];
    let dt = config.control_dt;
    let report_every = (steps / 10).max(1);
    let started = Instant::now();
    let mut baseline = None;
    println!("step,rss_kib,elapsed_s");
    for k in 0..steps {
        // A small height oscillation keeps the MPC working on a changing state.
        values[0] = config.body_height + 0.005 * (k as f64 * dt * 2.0).sin();
        values[1] = 0.01 * (k as f64 * dt * 2.0).cos();
        instance
            .set_real(&input_vrs, &values)
            .map_err(|e| anyhow::anyhow!("set at {k}: {e:?}"))?;
        instance
            .do_step(k as f64 * dt, dt, true)
            .map_err(|e| anyhow::anyhow!("doStep at {k}: {e:?}"))?;
        instance
            .get_real(&torque_vrs, &mut torques)
            .map_err(|e| anyhow::anyhow!("get: {e:?}"))?;
        if torques.iter().any(|t| !t.is_finite()) {
            bail!("non-finite torque at step {k}");
        }
        if k == 10_000.min(steps - 1) {
            baseline = Some(rss_kib()?);
        }
        if (k + 1) % report_every == 0 {
            println!(
                "{},{},{:.1}",
                k + 1,
                rss_kib()?,
                started.elapsed().as_secs_f64()
            );
        }
    }
    let after_steps = rss_kib()?;
    let step_seconds = started.elapsed().as_secs_f64();
    drop(instance);

    let cycle_start = Instant::now();
    let before_cycles = rss_kib()?;
    for k in 0..cycles {
        let extra = initialised(&import, "cycle")?;
        extra
            .do_step(0.0, 0.01, true)
            .map_err(|e| anyhow::anyhow!("cycle {k}: {e:?}"))?;
    }
    let after_cycles = rss_kib()?;
    println!(
        "summary: {steps} doSteps in {step_seconds:.1} s ({:.2} us/step); RSS after 10k steps {} KiB, after all steps {after_steps} KiB (growth {} KiB); {cycles} instantiate/free cycles in {:.1} s: RSS {before_cycles} -> {after_cycles} KiB",
        step_seconds / steps as f64 * 1e6,
        baseline.unwrap_or(after_steps),
        after_steps as i64 - baseline.unwrap_or(after_steps) as i64,
        cycle_start.elapsed().as_secs_f64(),
    );
    Ok(())
}
