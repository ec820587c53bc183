//! Runs `quad_controller::Controller` directly, without the FMU, for the same inputs a test
//! feeds the FMU, and prints the commands as JSON. The FMU tests compare against it to 1e-12.
//!
//! Reads from stdin:
//! `{"segments": [{"state": RobotState, "reference": Reference, "ticks": n, "comm_step": h},
//! ...]}` (serde layout of the controller types; `comm_step`, optional, is the communication step
//! of the FMU run being mirrored: the controller then gets the FMU's input period max(h, control
//! dt); without it, a fresh state every tick) and prints
//! `{"total_mass": m, "stand_joint_positions": [..12], "control_dt": dt,
//! "commands": [Command after each segment, ...]}` (an empty segment list gives the model data only).
//! Options: `--robot PATH` (a robot config; default `robot/quadruped.toml`), `--config PATH` (JSON
//! `ControllerConfig`; default `ControllerConfig::for_robot`, what `bundle-fmu --robot` ships as
//! the FMU's `resources/controller.json`).

use std::io::Read;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use quad_controller::{
    Command, Controller, ControllerConfig, Reference, RobotModel, RobotState, NUM_JOINTS,
};
use quad_controller_fmu::bundle::default_robot_config;
use serde::{Deserialize, Serialize};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Segment {
    state: RobotState,
    reference: Reference,
    ticks: u64,
    #[serde(default)]
    comm_step: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Request {
    segments: Vec<Segment>,
}

#[derive(Serialize)]
struct Response {
    total_mass: f64,
    stand_joint_positions: [f64; NUM_JOINTS],
    control_dt: f64,
    commands: Vec<Command>,
}

/// Run the controller directly (no FMU) on the segments read from stdin and print its commands
/// as JSON (the reference the FMU tests compare against).
#[derive(Parser)]
#[command(name = "fmu-direct-reference")]
struct Args {
    /// The robot config [default: <repo>/robot/quadruped.toml].
    #[arg(long)]
    robot: Option<PathBuf>,
    /// A JSON `ControllerConfig` [default: `ControllerConfig::for_robot`, the FMU's
    /// resources/controller.json].
    #[arg(long = "config")]
    config_path: Option<PathBuf>,
}

fn main() -> Result<()> {
    let Args { robot, config_path } = Args::parse();
    let robot = robot.unwrap_or_else(default_robot_config);
    let model = RobotModel::from_config_file(&robot)
        .with_context(|| format!("loading {}", robot.display()))?;
    let config = match config_path {
        Some(path) => {
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?
        }
        None => ControllerConfig::for_robot(&model),
    };
    let mut input = String::new();
    std::io::stdin()
        .read_to_string(&mut input)
        .context("reading the request from stdin")?;
    let request: Request = serde_json::from_str(&input).context("parsing the request")?;

    let total_mass = model.total_mass();
    let dt = config.control_dt;
    let mut controller = Controller::new(model, config).context("building the controller")?;
    let mut commands = Vec::with_capacity(request.segments.len());
    for (index, segment) in request.segments.iter().enumerate() {
        let mut last = None;
        controller
            .set_input_period(segment.comm_step.map_or(0.0, |h| h.max(dt)))
            .with_context(|| format!("segment {index}"))?;
        for tick in 0..segment.ticks {
            let command = controller
                .step(&segment.state, &segment.reference, dt)
                .with_context(|| format!("segment {index}, tick {tick}"))?;
            last = Some(command);
        }
        commands.push(last.with_context(|| format!("segment {index} has no ticks"))?);
    }
    let response = Response {
        total_mass,
        stand_joint_positions: controller.stand_joint_positions(),
        control_dt: dt,
        commands,
    };
    println!("{}", serde_json::to_string(&response)?);
    Ok(())
}
