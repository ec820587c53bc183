//! One FMU instance: the FMI 2.0 Co-Simulation call-state machine around a `Controller`.
//! Everything here is safe Rust; `exports.rs` only converts the C arguments.

use quad_controller::{Command, Controller, ControllerConfig, FsmTransition};
use serde::{Deserialize, Serialize};

use crate::budget::max_ticks_per_step;
use crate::ffi::Fmi2Status;
use crate::logger::Logger;
use crate::resources::Resources;
use crate::saved_state::InstanceState;
use crate::variables::{
    check_value, read_input, read_output, read_parameter, write_input, write_parameter, Binding,
    Causality, Inputs, ScalarType, Value, Variable,
};
use crate::FmuError;

/// The FMI 2.0 Co-Simulation states this FMU distinguishes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Phase {
    /// After `fmi2Instantiate` or `fmi2Reset`.
    Instantiated,
    /// Between `fmi2EnterInitializationMode` and `fmi2ExitInitializationMode`.
    InitializationMode,
    /// Ready for `fmi2DoStep`.
    StepComplete,
    /// The controller rejected a step (invalid measured state); only reading, terminating,
    /// resetting and freeing are allowed.
    StepFailed,
    /// After `fmi2Terminate`.
    Terminated,
}

impl Phase {
    /// Name as in the FMI 2.0 state chart.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Instantiated => "instantiated",
            Phase::InitializationMode => "initializationMode",
            Phase::StepComplete => "stepComplete",
            Phase::StepFailed => "stepFailed",
            Phase::Terminated => "terminated",
        }
    }
}

/// Relative tolerance on `currentCommunicationPoint`: a master that accumulates its time in
/// floating point drifts by ~1e-16 per step, a wrong time is off by a whole step.
const TIME_TOLERANCE: f64 = 1e-9;

/// One instance.
pub struct Instance {
    /// Messages to the importer.
    pub logger: Logger,
    phase: Phase,
    resources: Resources,
    config: ControllerConfig,
    inputs: Inputs,
    command: Command,
    controller: Option<Controller>,
    start_time: f64,
    stop_time: Option<f64>,
    time: f64,
    ticks_done: u64,
    max_ticks_per_step: u64,
    last_successful_time: f64,
}

impl Instance {
    /// A fresh instance in state `instantiated`, inputs at their start values, parameters from
    /// `resources/controller.json`.
    pub fn new(resources: Resources, logger: Logger) -> Instance {
        let (state, reference) = resources.table.initial_inputs();
        let command = resources.table.initial_command();
        let config = resources.config.clone();
        Instance {
            logger,
            phase: Phase::Instantiated,
            resources,
            config,
            inputs: Inputs {
                state,
                reference,
                ..Inputs::default()
            },
            command,
            controller: None,
            start_time: 0.0,
            stop_time: None,
            time: 0.0,
            ticks_done: 0,
            max_ticks_per_step: 0,
            last_successful_time: 0.0,
        }
    }

    /// Current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Current simulation time (end of the last completed doStep).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Control ticks run since `fmi2ExitInitializationMode`.
    pub fn ticks_done(&self) -> u64 {
        self.ticks_done
    }

    /// The most control ticks one doStep may run (see [`crate::budget`]); 0 before
    /// `fmi2ExitInitializationMode`.
    pub fn max_ticks_per_step(&self) -> u64 {
        self.max_ticks_per_step
    }

    fn require(&self, function: &'static str, allowed: &[Phase]) -> Result<(), FmuError> {
        if allowed.contains(&self.phase) {
            Ok(())
        } else {
            Err(FmuError::WrongState {
                function,
                phase: self.phase.name(),
            })
        }
    }

    /// `fmi2Reset`: back to `instantiated` with start values.
    pub fn reset(&mut self) {
        let logger = self.logger.clone();
        let resources = self.resources.clone();
        *self = Instance::new(resources, logger);
    }

    /// CRC-32 of the robot description this instance runs (saved states carry it).
    pub fn robot_crc(&self) -> u32 {
        self.resources.robot_crc
    }

    /// The FMU's GUID (saved states carry it).
    pub fn guid(&self) -> &str {
        &self.resources.guid
    }

    /// `fmi2GetFMUstate`: everything the instance carries between calls. Allowed in every
    /// phase.
    pub fn save_state(&self) -> InstanceState {
        InstanceState {
            phase: self.phase,
            config: self.config.clone(),
            inputs: self.inputs,
            command: self.command,
            controller: self.controller.as_ref().map(Controller::save_state),
            start_time: self.start_time,
            stop_time: self.stop_time,
            time: self.time,
            ticks_done: self.ticks_done,
            last_successful_time: self.last_successful_time,
        }
    }

    /// `fmi2SetFMUstate`: continues from `state`. A state that is not consistent (a controller
    /// before initialization or none after it, parameters the controller rejects, non-finite
    /// times) is refused and the instance is left as it was.
    pub fn restore_state(&mut self, state: &InstanceState) -> Result<(), FmuError> {
        let refuse = |reason: String| Err(FmuError::SavedState(reason));
        let initialized = matches!(
            state.phase,
            Phase::StepComplete | Phase::StepFailed | Phase::Terminated
        );
        if initialized != state.controller.is_some() {
            return refuse(format!(
                "phase {} {} a controller state",
                state.phase.name(),
                if initialized { "without" } else { "with" }
            ));
        }
        let times = [state.start_time, state.time, state.last_successful_time];
        if !times.iter().chain(&state.stop_time).all(|t| t.is_finite()) {
            return refuse("non-finite time".to_owned());
        }
        crate::variables::check_parameters(&self.resources.table, &state.config)
            .map_err(|e| FmuError::SavedState(format!("parameters: {e}")))?;
        let controller = match &state.controller {
            Some(saved) => {
                let mut controller =
                    Controller::new(self.resources.model.clone(), state.config.clone())
                        .map_err(|e| FmuError::SavedState(format!("parameters: {e}")))?;
                controller
                    .restore_state(saved.clone())
                    .map_err(|e| FmuError::SavedState(e.to_string()))?;
                Some(controller)
            }
            None => None,
        };
        // The tick budget follows from the parameters; a saved value is not trusted.
        self.max_ticks_per_step = if controller.is_some() {
            max_ticks_per_step(&state.config)
        } else {
            0
        };
        self.controller = controller;
        self.phase = state.phase;
        self.config = state.config.clone();
        self.inputs = state.inputs;
        self.command = state.command;
        self.start_time = state.start_time;
        self.stop_time = state.stop_time;
        self.time = state.time;
        self.ticks_done = state.ticks_done;
        self.last_successful_time = state.last_successful_time;
        Ok(())
    }

    /// `fmi2SetupExperiment`.
    pub fn setup_experiment(
        &mut self,
        start_time: f64,
        stop_time: Option<f64>,
    ) -> Result<(), FmuError> {
        self.require("fmi2SetupExperiment", &[Phase::Instantiated])?;
        if !start_time.is_finite() {
            return Err(FmuError::InvalidArgument(format!(
                "startTime {start_time} is not finite"
            )));
        }
        if let Some(stop) = stop_time {
            if !(stop.is_finite() && stop >= start_time) {
                return Err(FmuError::InvalidArgument(format!(
                    "stopTime {stop} must be finite and >= startTime {start_time}"
                )));
            }
        }
        self.start_time = start_time;
        self.stop_time = stop_time;
        self.time = start_time;
        self.last_successful_time = start_time;
        Ok(())
    }

    /// `fmi2EnterInitializationMode`.
    pub fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.require("fmi2EnterInitializationMode", &[Phase::Instantiated])?;
        self.phase = Phase::InitializationMode;
        Ok(())
    }

    /// `fmi2ExitInitializationMode`: builds the controller from the (possibly overridden)
    /// parameters. A rejected configuration leaves the instance in initialization mode.
    pub fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.require("fmi2ExitInitializationMode", &[Phase::InitializationMode])?;
        let controller = Controller::new(self.resources.model.clone(), self.config.clone())
            .map_err(|e| FmuError::Config(e.to_string()))?;
        self.controller = Some(controller);
        self.time = self.start_time;
        self.last_successful_time = self.start_time;
        self.ticks_done = 0;
        self.max_ticks_per_step = max_ticks_per_step(&self.config);
        self.phase = Phase::StepComplete;
        self.logger.log(
            Fmi2Status::Ok,
            &format!(
                "initialised at t = {}: control dt {} s, MPC every {} ticks, at most {} control ticks per doStep (h <= {} s)",
                self.start_time,
                self.config.control_dt,
                self.config.mpc_every_ticks,
                self.max_ticks_per_step,
                self.max_ticks_per_step as f64 * self.config.control_dt
            ),
        );
        Ok(())
    }

    /// `fmi2Terminate`.
    pub fn terminate(&mut self) -> Result<(), FmuError> {
        self.require("fmi2Terminate", &[Phase::StepComplete, Phase::StepFailed])?;
        self.phase = Phase::Terminated;
        self.logger
            .log(Fmi2Status::Ok, &format!("terminated at t = {}", self.time));
        Ok(())
    }

    /// Reads variables of type `expected` into `values` (same length as `vrs`).
    pub fn get(
        &self,
        function: &'static str,
        expected: ScalarType,
        vrs: &[u32],
        mut store: impl FnMut(usize, Value),
    ) -> Result<(), FmuError> {
        self.require(
            function,
            &[
                Phase::InitializationMode,
                Phase::StepComplete,
                Phase::StepFailed,
                Phase::Terminated,
            ],
        )?;
        for (k, &vr) in vrs.iter().enumerate() {
            let variable = lookup(&self.resources.table, vr, expected)?;
            let value = match variable.binding {
                Binding::Parameter { field, element } => {
                    Some(read_parameter(field, element, &self.config))
                }
                b => read_output(b, &self.command).or_else(|| read_input(b, &self.inputs)),
            };
            // Every binding is either a parameter, an input or an output (see the table tests).
            let value = value.ok_or(FmuError::UnknownValueReference { vr, expected })?;
            store(k, value);
        }
        Ok(())
    }

    /// Writes variables of one type. All values are checked before any is stored, so a
    /// rejected call changes nothing.
    pub fn set(
        &mut self,
        function: &'static str,
        vrs: &[u32],
        values: &[Value],
    ) -> Result<(), FmuError> {
        let n = vrs.len().min(values.len());
        self.set_with(function, &vrs[..n], |k| values[k])
    }

    /// [`Instance::set`] with the value of `vrs[k]` given by `value_at(k)`: the exports read
    /// the importer's array through it, so a call allocates nothing (the master sets ~50 inputs
    /// every millisecond). Each value is checked in a first pass and stored in a second.
    pub fn set_with(
        &mut self,
        function: &'static str,
        vrs: &[u32],
        value_at: impl Fn(usize) -> Value,
    ) -> Result<(), FmuError> {
        self.require(
            function,
            &[
                Phase::Instantiated,
                Phase::InitializationMode,
                Phase::StepComplete,
            ],
        )?;
        let running = self.phase == Phase::StepComplete;
        for (k, &vr) in vrs.iter().enumerate() {
            let value = value_at(k);
            let variable = lookup(&self.resources.table, vr, value.scalar_type())?;
            if variable.causality == Causality::Output {
                return Err(FmuError::NotSettable {
                    name: variable.name.clone(),
                    reason: "it is an output".to_owned(),
                });
            }
            if running && !variable.settable_while_running() {
                return Err(FmuError::NotSettable {
                    name: variable.name.clone(),
                    reason: "it is a fixed parameter and the simulation has started".to_owned(),
                });
            }
            check_value(variable, value)?;
        }
        let table = &self.resources.table;
        for (k, &vr) in vrs.iter().enumerate() {
            // Found and checked in the first pass.
            let Some(variable) = table.get(vr) else {
                continue;
            };
            let value = value_at(k);
            match variable.binding {
                Binding::Parameter { field, element } => {
                    write_parameter(field, element, &mut self.config, value)
                }
                b => write_input(b, value, &mut self.inputs),
            }
        }
        Ok(())
    }

    /// `fmi2DoStep`: runs the control ticks of the absolute grid `start + k·control_dt` that fall
    /// into `(t, t + h]` (k rounded to the nearest integer), holding the inputs constant.
    /// A controller error returns `Err` after switching the outputs to damping torques and the
    /// phase to `stepFailed`.
    pub fn do_step(&mut self, current_time: f64, step: f64) -> Result<(), FmuError> {
        self.require("fmi2DoStep", &[Phase::StepComplete])?;
        if !(step.is_finite() && step > 0.0) {
            return Err(FmuError::InvalidArgument(format!(
                "communicationStepSize {step} must be finite and > 0"
            )));
        }
        let tolerance = TIME_TOLERANCE * (1.0 + self.time.abs());
        if !(current_time.is_finite() && (current_time - self.time).abs() <= tolerance) {
            return Err(FmuError::TimeMismatch {
                given: current_time,
                expected: self.time,
            });
        }
        let dt = self.config.control_dt;
        let end = current_time + step;
        let target = ((end - self.start_time) / dt).round();
        // Refused before anything runs (NaN and inf included), so the instance stays usable.
        let ticks = target - self.ticks_done as f64;
        let within_cap = ticks <= self.max_ticks_per_step as f64; // false for NaN
        if !within_cap {
            return Err(FmuError::StepTooLong {
                step,
                ticks,
                max_ticks: self.max_ticks_per_step,
                max_step: self.max_ticks_per_step as f64 * dt,
            });
        }
        // `target` is an integer in [0, ticks_done + max_ticks_per_step] here (the FMU time
        // never runs behind the ticks done), so the cast is exact.
        let target = target.max(0.0) as u64;
        let Some(controller) = self.controller.as_mut() else {
            return Err(FmuError::Internal(
                "no controller in state stepComplete".to_owned(),
            ));
        };
        // The inputs stay in force for the whole step and the outputs for the next one.
        controller
            .set_input_period(step.max(dt))
            .map_err(|e| FmuError::InvalidArgument(e.to_string()))?;
        let Inputs {
            state,
            reference,
            height_map,
            sensors,
        } = &self.inputs;
        if let Err(e) = controller.set_height_map(height_map) {
            self.command = controller.safe_command(state);
            self.phase = Phase::StepFailed;
            self.last_successful_time = self.start_time + self.ticks_done as f64 * dt;
            return Err(FmuError::StepRejected {
                time: self.last_successful_time,
                reason: e.to_string(),
            });
        }
        // A fix arrives once per doStep: only the first tick fuses it. The status bits of every
        // tick of the step are reported (a rejected fix on the first tick must not be lost).
        let mut tick_sensors = *sensors;
        let mut status = None;
        while self.ticks_done < target {
            let before = self.command.fsm_state;
            match controller.step_with_sensors(state, &tick_sensors, reference, dt) {
                Ok(command) => {
                    self.command = command;
                    status = Some(status.unwrap_or(0) | command.estimate.status);
                    tick_sensors.fix.valid = false;
                    self.ticks_done += 1;
                    if self.command.fsm_state != before {
                        let time = self.start_time + self.ticks_done as f64 * dt;
                        log_transition(&self.logger, time, controller.last_transition());
                    }
                }
                Err(e) => {
                    self.command = controller.safe_command(state);
                    self.phase = Phase::StepFailed;
                    self.last_successful_time = self.start_time + self.ticks_done as f64 * dt;
                    return Err(FmuError::StepRejected {
                        time: self.last_successful_time,
                        reason: e.to_string(),
                    });
                }
            }
        }
        if let Some(status) = status {
            self.command.estimate.status = status;
        }
        self.time = end;
        self.last_successful_time = end;
        Ok(())
    }

    /// `fmi2GetRealStatus(fmi2LastSuccessfulTime)`.
    pub fn last_successful_time(&self) -> Result<f64, FmuError> {
        self.require_status("fmi2GetRealStatus")?;
        Ok(self.last_successful_time)
    }

    /// `fmi2GetBooleanStatus(fmi2Terminated)`: the FMU never asks the master to stop.
    pub fn terminated_status(&self) -> Result<bool, FmuError> {
        self.require_status("fmi2GetBooleanStatus")?;
        Ok(false)
    }

    fn require_status(&self, function: &'static str) -> Result<(), FmuError> {
        self.require(
            function,
            &[Phase::StepComplete, Phase::StepFailed, Phase::Terminated],
        )
    }

    /// Checks that a status function is called in a state where one is allowed (for the
    /// unsupported kinds, so that the error names the real problem).
    pub fn check_status_call(&self, function: &'static str) -> Result<(), FmuError> {
        self.require_status(function)
    }
}

/// Logs a state change of the controller at `time` (the end of the tick that made it). A drop
/// to damping is a warning, always passed on, with the failed check and its value; the other
/// changes are `logEvents` messages.
fn log_transition(logger: &Logger, time: f64, transition: Option<&FsmTransition>) {
    let Some(FsmTransition { from, to, reason }) = transition else {
        return;
    };
    match reason {
        Some(reason) => logger.log(
            Fmi2Status::Warning,
            &format!("t = {time}: controller state {from:?} -> {to:?}: {reason}"),
        ),
        None => logger.log(
            Fmi2Status::Ok,
            &format!("t = {time}: controller state {from:?} -> {to:?}"),
        ),
    }
}

/// The table row of `vr` if it exists and has type `expected`.
fn lookup(
    table: &crate::variables::VariableTable,
    vr: u32,
    expected: ScalarType,
) -> Result<&Variable, FmuError> {
    table
        .get(vr)
        .filter(|v| v.scalar_type() == expected)
        .ok_or(FmuError::UnknownValueReference { vr, expected })
}

#[cfg(test)]
mod state_tests;
#[cfg(test)]
mod tests;
