//! FMI 2.0 Co-Simulation boundary around `quad-controller` (cdylib exporting the fmi2 C API).
//!
//! This crate is only the FMI boundary: all control logic lives in `quad-controller`.
//!
//! * [`exports`] — the 34 `fmi2*` C functions; each checks its pointers, runs inside
//!   `catch_unwind` and turns every failure into `fmi2Error` (or NULL from `fmi2Instantiate`)
//!   with a reason sent to the importer's logger.
//! * [`instance`] — the call-state machine (instantiated → initializationMode → stepComplete ⇄
//!   stepFailed → terminated) around one `Controller`.
//! * [`variables`] — the single variable table (with each parameter's `min`/`max`, taken from
//!   `quad_controller::limits`), built for the robot an FMU carries; [`model_description`] turns
//!   it into `modelDescription.xml` and `documentation/index.html`.
//! * [`budget`] — the most control ticks one `fmi2DoStep` may run (so every call returns within
//!   1 s whatever the parameters and step size).
//! * [`resources`] — `fmuResourceLocation` (file URI) → the robot in `resources/robot/` (config,
//!   URDF) and `resources/controller.json`, checked, with their variable table.
//! * [`saved_state`] — FMU states (`fmi2GetFMUstate` & co.) and their serialized form.
//! * [`bundle`] — writes `QuadController.fmu` for a robot config, its URDF and meshes (used by the
//!   `bundle-fmu` binary).
//!
//! # Timing
#![doc = include_str!("timing.md")]

pub mod budget;
pub mod bundle;
pub mod exports;
pub mod ffi;
pub mod instance;
pub mod logger;
pub mod model_description;
pub mod resources;
pub mod saved_state;
pub mod variables;

use thiserror::Error;

use crate::variables::ScalarType;

/// `modelIdentifier`: the binary is `binaries/linux64/QuadController.so`.
pub const MODEL_IDENTIFIER: &str = "QuadController";

/// `DefaultExperiment` stop time, s.
pub const DEFAULT_STOP_TIME: f64 = 10.0;

/// `DefaultExperiment` step size (suggested communication step), s: one control tick.
pub const DEFAULT_STEP_SIZE: f64 = 0.001;

/// How a doStep maps to control ticks (also shipped in `documentation/index.html`).
pub const TIMING_DOC: &str = include_str!("timing.md");

/// Everything that makes an FMI call fail. The `Display` text is what the importer's logger
/// receives.
#[derive(Debug, Error)]
pub enum FmuError {
    /// The function is not allowed in the instance's current state.
    #[error("{function} is not allowed in state {phase}")]
    WrongState {
        /// The FMI function.
        function: &'static str,
        /// The current state's name.
        phase: &'static str,
    },
    /// No variable of this type has this value reference.
    #[error("valueReference {vr} does not refer to a {expected:?} variable")]
    UnknownValueReference {
        /// The value reference.
        vr: u32,
        /// The type the call was for.
        expected: ScalarType,
    },
    /// The variable exists but cannot be set now.
    #[error("cannot set {name}: {reason}")]
    NotSettable {
        /// Variable name.
        name: String,
        /// Why.
        reason: String,
    },
    /// The value is NaN, infinite or outside the variable's range.
    #[error("invalid value for {name}: {reason}")]
    InvalidValue {
        /// Variable name.
        name: String,
        /// Why.
        reason: String,
    },
    /// A scalar argument or pointer of the call is invalid.
    #[error("{0}")]
    InvalidArgument(String),
    /// `currentCommunicationPoint` is not the FMU's time.
    #[error("currentCommunicationPoint {given} does not match the FMU time {expected}")]
    TimeMismatch {
        /// What the master passed.
        given: f64,
        /// The end of the last completed step.
        expected: f64,
    },
    /// The step would run more control ticks than one doStep may (see [`budget`]).
    #[error("communicationStepSize {step} needs {ticks} control ticks, more than the {max_ticks} one doStep may run with these parameters (h <= {max_step} s); nothing was run: use shorter steps")]
    StepTooLong {
        /// The step size asked for.
        step: f64,
        /// Ticks it would need (may be inf or NaN).
        ticks: f64,
        /// The cap.
        max_ticks: u64,
        /// The longest step the cap allows, s.
        max_step: f64,
    },
    /// The parameters do not make a valid controller.
    #[error("controller rejected the parameters: {0}")]
    Config(String),
    /// The controller rejected a tick; the outputs hold damping torques now.
    #[error("controller step at t = {time} failed ({reason}); outputs switched to damping torques, the instance is in stepFailed (terminate or reset it)")]
    StepRejected {
        /// Time of the last completed tick.
        time: f64,
        /// The controller's reason.
        reason: String,
    },
    /// `fmuResourceLocation` cannot be turned into a local folder.
    #[error("fmuResourceLocation {location:?} is not usable: {reason}")]
    ResourceLocation {
        /// The string passed.
        location: String,
        /// Why.
        reason: String,
    },
    /// A resource file is missing or invalid.
    #[error("resources: {0}")]
    Resources(String),
    /// `fmi2Instantiate` arguments that mean the importer picked the wrong FMU or type.
    #[error("fmi2Instantiate: {0}")]
    Instantiate(String),
    /// An optional FMI capability this FMU declares as unsupported.
    #[error("{function} is not supported ({capability})")]
    Unsupported {
        /// The FMI function.
        function: &'static str,
        /// The capability flag in modelDescription.xml that says so.
        capability: &'static str,
    },
    /// A saved or serialized FMU state that this instance cannot take.
    #[error("FMU state: {0}")]
    SavedState(String),
    /// A broken invariant inside the FMU (a bug); reported instead of panicking.
    #[error("internal error: {0}")]
    Internal(String),
}
