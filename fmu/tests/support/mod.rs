//! Shared helpers of the FMU integration tests: bundling the FMU from the cdylib cargo built for
//! this test run, capturing the error messages the FMU logs, value references by name, and a
//! standing state for the robot.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use quad_controller::{Controller, ControllerConfig, Reference, RobotModel, RobotState};
use quad_controller_fmu::bundle::{
    default_robot_config, shared_library_next_to, write_fmu, BundleInputs,
};
use quad_controller_fmu::variables::{Variable, VariableTable};

/// Error messages the FMU sent to the importer's logger (the `fmi` crate forwards them to `log`),
/// as `instance: message`.
static LOGGED: Mutex<Vec<String>> = Mutex::new(Vec::new());

struct CaptureLogger;

impl log::Log for CaptureLogger {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }
    fn log(&self, record: &log::Record) {
        // Errors only: the informational messages depend on loggingOn.
        if record.module_path() == Some("logger") && record.level() == log::Level::Error {
            LOGGED
                .lock()
                .unwrap()
                .push(format!("{}: {}", record.target(), record.args()));
        }
    }
    fn flush(&self) {}
}

/// Starts capturing (idempotent).
pub fn install_logger() {
    static LOGGER: CaptureLogger = CaptureLogger;
    let _ = log::set_logger(&LOGGER);
    log::set_max_level(log::LevelFilter::Trace);
}

/// The number of messages captured so far.
pub fn log_mark() -> usize {
    LOGGED.lock().unwrap().len()
}

/// The error messages of `instance` captured since `mark` (see [`log_mark`]).
pub fn logged_since(mark: usize, instance: &str) -> Vec<String> {
    let prefix = format!("{instance}: ");
    LOGGED.lock().unwrap()[mark..]
        .iter()
        .filter(|m| m.starts_with(&prefix))
        .cloned()
        .collect()
}

/// Every error message of `instance` captured.
pub fn errors_of(instance: &str) -> Vec<String> {
    logged_since(0, instance)
}

/// The variable table of the FMU the tests bundle (our robot).
pub fn table() -> &'static [Variable] {
    our_table().rows()
}

fn our_table() -> &'static VariableTable {
    static TABLE: OnceLock<VariableTable> = OnceLock::new();
    TABLE.get_or_init(|| {
        VariableTable::for_robot_config(&default_robot_config()).expect("our robot's table")
    })
}

/// The value reference of the FMU variable `name` (panics when there is none).
pub fn vr(name: &str) -> u32 {
    our_table()
        .by_name(name)
        .unwrap_or_else(|| panic!("variable {name}"))
        .value_reference
}

/// The cdylib of this build (target/<profile>/deps/libquad_controller_fmu.so).
pub fn shared_library() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    shared_library_next_to(&exe).expect("cargo builds the cdylib next to the test executable")
}

/// A `.fmu` bundled once per test process from this build's cdylib.
pub fn fmu_path() -> &'static Path {
    static FMU: OnceLock<PathBuf> = OnceLock::new();
    FMU.get_or_init(|| {
        let out = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("QuadController-{}.fmu", std::process::id()));
        let inputs = BundleInputs::linux64(shared_library());
        write_fmu(&inputs, &out).expect("bundling the test FMU");
        out
    })
}

/// The robot model shipped in the FMU's resources.
pub fn model() -> RobotModel {
    RobotModel::from_config_file(&default_robot_config()).expect("robot/quadruped.toml")
}

/// A direct controller with the FMU's default parameters.
pub fn direct_controller() -> Controller {
    Controller::new(model(), ControllerConfig::default()).expect("default controller")
}

/// The robot standing still on flat ground at z = 0 in the controller's standing pose, yaw `yaw`.
pub fn standing_state(x: f64, yaw: f64) -> RobotState {
    let config = ControllerConfig::default();
    let q = direct_controller().stand_joint_positions();
    RobotState {
        base_position: [x, 0.0, config.body_height],
        base_orientation: [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()],
        joint_positions: q,
        ..RobotState::default()
    }
}

/// A stand request at the state's position.
pub fn stand_reference(state: &RobotState, yaw: f64) -> Reference {
    Reference {
        x: state.base_position[0],
        y: state.base_position[1],
        yaw,
        ..Reference::default()
    }
}
