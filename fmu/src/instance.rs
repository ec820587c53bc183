//! One FMU instance: the FMI 2.0 Co-Simulation call-state machine around a `Controller`.
//! Everything here is safe Rust; `exports.rs` only converts the C arguments.

use quad_controller::{
    Command, Controller, ControllerConfig, FsmTransition, HeightMap, Reference, RobotState,
};

use crate::budget::max_ticks_per_step;
use crate::ffi::Fmi2Status;
use crate::logger::Logger;
use crate::resources::Resources;
use crate::variables::{
    check_value, initial_command, initial_inputs, read_input, read_output, read_parameter, table,
    write_input, write_parameter, Binding, Causality, ScalarType, Value,
};
use crate::FmuError;

/// The FMI 2.0 Co-Simulation states this FMU distinguishes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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
    state: RobotState,
    reference: Reference,
    height_map: HeightMap,
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
        let (state, reference) = initial_inputs();
        let config = resources.config.clone();
        Instance {
            logger,
            phase: Phase::Instantiated,
            resources,
            config,
            state,
            reference,
            height_map: HeightMap::default(),
            command: initial_command(),
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
            let variable = lookup(vr, expected)?;
            let value = match variable.binding {
                Binding::Parameter { field, element } => {
                    Some(read_parameter(field, element, &self.config))
                }
                b => read_output(b, &self.command)
                    .or_else(|| read_input(b, &self.state, &self.reference, &self.height_map)),
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
        self.require(
            function,
            &[
                Phase::Instantiated,
                Phase::InitializationMode,
                Phase::StepComplete,
            ],
        )?;
        let mut checked = Vec::with_capacity(vrs.len());
        for (&vr, &value) in vrs.iter().zip(values) {
            let variable = lookup(vr, value.scalar_type())?;
            if variable.causality == Causality::Output {
                return Err(FmuError::NotSettable {
                    name: variable.name.clone(),
                    reason: "it is an output".to_owned(),
                });
            }
            if self.phase == Phase::StepComplete && !variable.settable_while_running() {
                return Err(FmuError::NotSettable {
                    name: variable.name.clone(),
                    reason: "it is a fixed parameter and the simulation has started".to_owned(),
                });
            }
            check_value(variable, value)?;
            checked.push((variable, value));
        }
        for (variable, value) in checked {
            match variable.binding {
                Binding::Parameter { field, element } => {
                    write_parameter(field, element, &mut self.config, value)
                }
                b => write_input(
                    b,
                    value,
                    &mut self.state,
                    &mut self.reference,
                    &mut self.height_map,
                ),
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
        if let Err(e) = controller.set_height_map(&self.height_map) {
            self.command = controller.safe_command(&self.state);
            self.phase = Phase::StepFailed;
            self.last_successful_time = self.start_time + self.ticks_done as f64 * dt;
            return Err(FmuError::StepRejected {
                time: self.last_successful_time,
                reason: e.to_string(),
            });
        }
        while self.ticks_done < target {
            let before = self.command.fsm_state;
            match controller.step(&self.state, &self.reference, dt) {
                Ok(command) => {
                    self.command = command;
                    self.ticks_done += 1;
                    if self.command.fsm_state != before {
                        let time = self.start_time + self.ticks_done as f64 * dt;
                        log_transition(&self.logger, time, controller.last_transition());
                    }
                }
                Err(e) => {
                    self.command = controller.safe_command(&self.state);
                    self.phase = Phase::StepFailed;
                    self.last_successful_time = self.start_time + self.ticks_done as f64 * dt;
                    return Err(FmuError::StepRejected {
                        time: self.last_successful_time,
                        reason: e.to_string(),
                    });
                }
            }
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
fn lookup(vr: u32, expected: ScalarType) -> Result<&'static crate::variables::Variable, FmuError> {
    table()
        .get(vr as usize)
        .filter(|v| v.scalar_type() == expected)
        .ok_or(FmuError::UnknownValueReference { vr, expected })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::repo_root;
    use crate::variables::by_name;
    use quad_controller::{FsmState, RobotModel};

    fn instance() -> Instance {
        let model = RobotModel::from_urdf_file(&repo_root().join("robot").join("quadruped.urdf"))
            .expect("robot/quadruped.urdf");
        let resources = Resources {
            model,
            config: ControllerConfig::default(),
        };
        Instance::new(
            resources,
            Logger::new(None, std::ptr::null_mut(), "test", false),
        )
    }

    fn running() -> Instance {
        let mut i = instance();
        i.setup_experiment(0.0, None).unwrap();
        i.enter_initialization_mode().unwrap();
        i.exit_initialization_mode().unwrap();
        i
    }

    fn vr(name: &str) -> u32 {
        by_name(name).unwrap().value_reference
    }

    #[test]
    fn do_step_runs_the_ticks_of_the_absolute_grid() {
        let mut i = running();
        // Multiples of the 1 ms tick.
        i.do_step(0.0, 0.01).unwrap();
        assert_eq!(i.ticks_done(), 10);
        i.do_step(0.01, 0.001).unwrap();
        assert_eq!(i.ticks_done(), 11);
        // 1.4 ms steps: ends at 12.4, 13.8, 15.2, 16.6 ticks -> rounded 12, 14, 15, 17.
        let mut t = 0.011;
        let mut ticks = Vec::new();
        for _ in 0..4 {
            i.do_step(t, 0.0014).unwrap();
            t += 0.0014;
            ticks.push(i.ticks_done());
        }
        assert_eq!(ticks, [12, 14, 15, 17]);
        // A step shorter than half a tick runs nothing and keeps the outputs.
        let before = i.command;
        i.do_step(t, 0.0004).unwrap();
        assert_eq!(i.ticks_done(), 17);
        assert_eq!(i.command, before);
        assert!((i.time() - (t + 0.0004)).abs() < 1e-15);
    }

    #[test]
    fn start_time_offsets_the_grid() {
        let mut i = instance();
        i.setup_experiment(100.0, Some(200.0)).unwrap();
        i.enter_initialization_mode().unwrap();
        i.exit_initialization_mode().unwrap();
        assert!(
            i.do_step(0.0, 0.01).is_err(),
            "time must start at startTime"
        );
        i.do_step(100.0, 0.02).unwrap();
        assert_eq!(i.ticks_done(), 20);
    }

    #[test]
    fn calls_out_of_order_are_rejected_and_change_nothing() {
        let mut i = instance();
        assert!(matches!(
            i.do_step(0.0, 0.01),
            Err(FmuError::WrongState { .. })
        ));
        assert!(i.exit_initialization_mode().is_err());
        assert!(i.terminate().is_err());
        assert!(i
            .get("fmi2GetReal", ScalarType::Real, &[0], |_, _| {})
            .is_err());
        assert_eq!(i.phase(), Phase::Instantiated);
        i.enter_initialization_mode().unwrap();
        assert!(i.enter_initialization_mode().is_err());
        assert!(i.setup_experiment(0.0, None).is_err());
        assert!(i.do_step(0.0, 0.01).is_err());
        i.exit_initialization_mode().unwrap();
        assert!(i.enter_initialization_mode().is_err());
        i.terminate().unwrap();
        assert!(i.do_step(0.0, 0.01).is_err());
        assert!(i
            .set("fmi2SetReal", &[vr("ref.x")], &[Value::Real(1.0)])
            .is_err());
        assert_eq!(i.phase(), Phase::Terminated);
        i.reset();
        assert_eq!(i.phase(), Phase::Instantiated);
    }

    #[test]
    fn fixed_parameters_apply_before_initialisation_only() {
        let mut i = instance();
        i.set("fmi2SetReal", &[vr("control.dt")], &[Value::Real(0.002)])
            .unwrap();
        i.set(
            "fmi2SetInteger",
            &[vr("mpc.everyTicks")],
            &[Value::Integer(5)],
        )
        .unwrap();
        i.enter_initialization_mode().unwrap();
        i.exit_initialization_mode().unwrap();
        i.do_step(0.0, 0.01).unwrap();
        assert_eq!(i.ticks_done(), 5, "10 ms at a 2 ms tick");
        let err = i
            .set("fmi2SetReal", &[vr("control.dt")], &[Value::Real(0.001)])
            .unwrap_err();
        assert!(err.to_string().contains("fixed parameter"), "{err}");
    }

    #[test]
    fn invalid_parameters_keep_the_instance_in_initialisation() {
        let mut i = instance();
        // Each value is inside its own range, but f_min must stay below f_max: checked when the
        // controller is built in fmi2ExitInitializationMode.
        i.set(
            "fmi2SetReal",
            &[vr("mpc.fMin"), vr("mpc.fMax")],
            &[Value::Real(500.0), Value::Real(400.0)],
        )
        .unwrap();
        i.enter_initialization_mode().unwrap();
        let err = i.exit_initialization_mode().unwrap_err();
        assert!(matches!(err, FmuError::Config(_)), "{err}");
        assert!(err.to_string().contains("f_min must be < f_max"), "{err}");
        assert_eq!(i.phase(), Phase::InitializationMode);
        i.set("fmi2SetReal", &[vr("mpc.fMax")], &[Value::Real(600.0)])
            .unwrap();
        i.exit_initialization_mode().unwrap();
    }

    #[test]
    fn parameters_outside_their_range_are_refused_at_set_time() {
        let mut i = instance();
        let horizon = vr("mpc.horizon");
        for bad in [9, 41, 0, -1, i32::MIN, i32::MAX] {
            let err = i
                .set("fmi2SetInteger", &[horizon], &[Value::Integer(bad)])
                .unwrap_err();
            assert!(matches!(err, FmuError::InvalidValue { .. }), "{bad}: {err}");
        }
        let every = vr("mpc.everyTicks");
        assert!(i
            .set("fmi2SetInteger", &[every], &[Value::Integer(0)])
            .is_err());
        assert!(i
            .set("fmi2SetInteger", &[every], &[Value::Integer(1001)])
            .is_err());
        // Nothing was stored: the defaults still build a controller.
        i.enter_initialization_mode().unwrap();
        i.exit_initialization_mode().unwrap();
        assert_eq!(i.config, ControllerConfig::default());
    }

    /// The control.dt values of the issue: 1e-12 (first doStep of 1 ms never returned), 1e-9
    /// (3.6 s per step), 10 and 1e300 (no control tick ever ran).
    #[test]
    fn regression_extreme_control_dt_is_refused_at_set_time() {
        let mut i = instance();
        let dt = vr("control.dt");
        for bad in [
            1e-12,
            1e-9,
            10.0,
            1e300,
            0.0,
            -1e-3,
            f64::NAN,
            f64::INFINITY,
        ] {
            let err = i
                .set("fmi2SetReal", &[dt], &[Value::Real(bad)])
                .unwrap_err()
                .to_string();
            assert!(err.starts_with("invalid value for control.dt"), "{err}");
        }
        for good in [1e-4, 0.05] {
            i.set("fmi2SetReal", &[dt], &[Value::Real(good)]).unwrap();
        }
    }

    #[test]
    fn a_step_longer_than_the_tick_cap_is_refused_and_changes_nothing() {
        let mut i = running();
        let max = i.max_ticks_per_step();
        assert_eq!(max, crate::budget::max_ticks_per_step(&i.config));
        let dt = i.config.control_dt;
        let err = i.do_step(0.0, (max + 1) as f64 * dt).unwrap_err();
        assert!(matches!(err, FmuError::StepTooLong { .. }), "{err}");
        assert!(err.to_string().contains("use shorter steps"), "{err}");
        assert_eq!(
            (i.ticks_done(), i.time(), i.phase()),
            (0, 0.0, Phase::StepComplete)
        );
        i.do_step(0.0, max as f64 * dt).unwrap();
        assert_eq!(i.ticks_done(), max);
        // The cap counts the ticks of this step, not since the start.
        let t = i.time();
        i.do_step(t, max as f64 * dt).unwrap();
        assert_eq!(i.ticks_done(), 2 * max);
    }

    /// h = 1e12…1e15 hung and h = 1000 took 27 s: now each is refused before any tick runs.
    #[test]
    fn regression_huge_and_invalid_steps_return_at_once() {
        let mut i = running();
        for h in [
            1e12,
            1e13,
            1e14,
            1e15,
            1000.0,
            1e300,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
            f64::NEG_INFINITY,
            -1.0,
            0.0,
            -0.0,
        ] {
            let start = std::time::Instant::now();
            assert!(i.do_step(0.0, h).is_err(), "h = {h}");
            assert!(start.elapsed().as_secs_f64() < 0.5, "h = {h}");
            assert_eq!(i.ticks_done(), 0, "h = {h}");
        }
        for t in [f64::NAN, f64::INFINITY, -1e300, 1e300] {
            assert!(matches!(
                i.do_step(t, 0.001),
                Err(FmuError::TimeMismatch { .. })
            ));
        }
        // Subnormal and tiny steps run no tick but advance the time exactly.
        let tiny = f64::from_bits(1);
        i.do_step(0.0, tiny).unwrap();
        i.do_step(tiny, 1e-300).unwrap();
        assert_eq!(i.ticks_done(), 0);
        assert_eq!(i.time(), tiny + 1e-300);
        let t = i.time();
        i.do_step(t, 0.01).unwrap();
        assert_eq!(i.ticks_done(), 10);
    }

    #[test]
    fn far_start_times_run_no_ticks_but_do_not_hang() {
        for start in [1e15, 1e300, -1e300] {
            let mut i = instance();
            i.setup_experiment(start, None).unwrap();
            i.enter_initialization_mode().unwrap();
            i.exit_initialization_mode().unwrap();
            let began = std::time::Instant::now();
            let _ = i.do_step(start, 0.5);
            assert!(began.elapsed().as_secs_f64() < 1.0, "start {start}");
        }
    }

    /// With every input at its start value (the robot standing on flat ground, mode Stand) the
    /// controller stands up and holds the stand with finite, non-zero torques.
    #[test]
    fn start_values_stand_up_and_hold_the_stand() {
        let mut i = running();
        let mut reached_stand_at = None;
        for k in 0..300 {
            let t = i.time();
            i.do_step(t, 0.01).unwrap();
            if reached_stand_at.is_none() && i.command.fsm_state == FsmState::Stand {
                reached_stand_at = Some(k);
            }
        }
        assert!(reached_stand_at.is_some(), "never reached Stand");
        assert_eq!(i.command.fsm_state, FsmState::Stand);
        let torques = i.command.joint_torques;
        assert!(torques.iter().all(|t| t.is_finite()), "{torques:?}");
        assert!(torques.iter().any(|t| t.abs() > 0.1), "{torques:?}");
    }

    #[test]
    fn a_rejected_state_switches_to_damping_and_step_failed() {
        let mut i = running();
        let quaternion = ["base.quat.w", "base.quat.x", "base.quat.y", "base.quat.z"].map(vr);
        i.set("fmi2SetReal", &quaternion, &[Value::Real(0.0); 4])
            .unwrap();
        i.set("fmi2SetReal", &[vr("joint.dq[1]")], &[Value::Real(2.0)])
            .unwrap();
        let err = i.do_step(0.0, 0.01).unwrap_err();
        assert!(matches!(err, FmuError::StepRejected { .. }), "{err}");
        assert_eq!(i.phase(), Phase::StepFailed);
        assert_eq!(i.command.fsm_state, FsmState::Damping);
        let kd = ControllerConfig::default().damping_kd;
        assert_eq!(i.command.joint_torques[0], -kd * 2.0);
        assert_eq!(i.last_successful_time().unwrap(), 0.0);
        assert!(i.do_step(0.0, 0.01).is_err());
        i.terminate().unwrap();
    }

    #[test]
    fn a_rejected_set_call_stores_none_of_its_values() {
        let mut i = running();
        let vrs = [vr("ref.x"), vr("ref.y")];
        assert!(i
            .set(
                "fmi2SetReal",
                &vrs,
                &[Value::Real(1.0), Value::Real(f64::NAN)]
            )
            .is_err());
        let mut got = [f64::NAN; 2];
        i.get("fmi2GetReal", ScalarType::Real, &vrs, |k, v| {
            if let Value::Real(x) = v {
                got[k] = x;
            }
        })
        .unwrap();
        assert_eq!(got, [0.0, 0.0]);
    }
}
