use super::*;
use crate::variables::{by_name, our_table, robot_model};
use quad_controller::FsmState;

pub(super) fn instance() -> Instance {
    let resources = Resources {
        model: robot_model().clone(),
        config: ControllerConfig::default(),
        table: std::sync::Arc::new(our_table().clone()),
        robot_crc: 0x5eed,
        guid: our_table().guid(),
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

pub(super) fn vr(name: &str) -> u32 {
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

fn reals(i: &Instance, names: &[&str]) -> Vec<f64> {
    let vrs: Vec<u32> = names.iter().map(|n| vr(n)).collect();
    let mut values = vec![f64::NAN; vrs.len()];
    i.get("fmi2GetReal", ScalarType::Real, &vrs, |k, v| {
        if let Value::Real(x) = v {
            values[k] = x;
        }
    })
    .unwrap();
    values
}

fn estimator_status(i: &Instance) -> i32 {
    let mut status = -1;
    i.get(
        "fmi2GetInteger",
        ScalarType::Integer,
        &[vr("est.status")],
        |_, v| {
            if let Value::Integer(x) = v {
                status = x;
            }
        },
    )
    .unwrap();
    status
}

const ESTIMATE: [&str; 9] = [
    "est.pos[1]",
    "est.pos[2]",
    "est.pos[3]",
    "est.vel[1]",
    "est.vel[2]",
    "est.vel[3]",
    "est.rpy[1]",
    "est.rpy[2]",
    "est.rpy[3]",
];

fn torques_are_finite(i: &Instance) -> bool {
    let names: Vec<String> = (1..=12).map(|k| format!("joint.tau[{k}]")).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    reals(i, &names).iter().all(|t| t.is_finite())
}

#[test]
fn ground_truth_mode_reports_the_base_inputs_as_the_estimate() {
    let mut i = running();
    i.set(
        "fmi2SetReal",
        &[vr("base.pos.x"), vr("base.vel.y")],
        &[Value::Real(0.1), Value::Real(0.05)],
    )
    .unwrap();
    i.do_step(0.0, 0.01).unwrap();
    let estimate = reals(&i, &ESTIMATE);
    assert_eq!(estimate[0], 0.1);
    assert_eq!(estimate[2], reals(&i, &["base.pos.z"])[0]);
    assert_eq!(estimate[4], 0.05);
    assert_eq!(estimator_status(&i), 0);
}

/// Kalman mode on the inputs of a robot standing still (the start values: standing pose, level
/// IMU at rest): the estimate stays at the truth; NaN IMU samples are reported in est.status and
/// never reach the torques.
#[test]
fn kalman_mode_stands_on_its_estimate_and_survives_nan_imu_samples() {
    let mut i = instance();
    i.set("fmi2SetInteger", &[vr("estimator")], &[Value::Integer(1)])
        .unwrap();
    i.setup_experiment(0.0, None).unwrap();
    i.enter_initialization_mode().unwrap();
    i.exit_initialization_mode().unwrap();
    let truth = reals(&i, &["base.pos.x", "base.pos.y", "base.pos.z"]);
    let mut t = 0.0;
    for _ in 0..200 {
        i.do_step(t, 0.01).unwrap();
        t += 0.01;
    }
    assert_eq!(i.command.fsm_state, FsmState::Stand);
    let estimate = reals(&i, &ESTIMATE);
    for axis in 0..3 {
        assert!((estimate[axis] - truth[axis]).abs() < 1e-3, "{estimate:?}");
        assert!(estimate[3 + axis].abs() < 1e-3, "{estimate:?}");
        assert!(estimate[6 + axis].abs() < 1e-3, "{estimate:?}");
    }
    assert_eq!(estimator_status(&i), 0);

    // A fix at the truth is fused quietly.
    i.set(
        "fmi2SetReal",
        &[vr("fix.pos[1]"), vr("fix.pos[2]"), vr("fix.pos[3]")],
        &[
            Value::Real(truth[0]),
            Value::Real(truth[1]),
            Value::Real(truth[2]),
        ],
    )
    .unwrap();
    i.set(
        "fmi2SetBoolean",
        &[vr("fix.valid")],
        &[Value::Boolean(true)],
    )
    .unwrap();
    i.do_step(t, 0.01).unwrap();
    t += 0.01;
    assert_eq!(estimator_status(&i), 0);

    // A fix 5 m off, still valid for a 10-tick doStep: fused once (refused once, fixRejected
    // alone); fused at every tick it would be refused three times and the filter would relocate
    // to it (covarianceReset, and the estimate 5 m away).
    i.set(
        "fmi2SetReal",
        &[vr("fix.pos[1]")],
        &[Value::Real(truth[0] + 5.0)],
    )
    .unwrap();
    i.do_step(t, 0.01).unwrap();
    t += 0.01;
    assert_eq!(estimator_status(&i), 16);
    assert!((reals(&i, &ESTIMATE)[0] - truth[0]).abs() < 1e-3);
    i.set(
        "fmi2SetBoolean",
        &[vr("fix.valid")],
        &[Value::Boolean(false)],
    )
    .unwrap();

    // NaN gyro and accelerometer samples: accepted, reported, the torques stay finite.
    i.set(
        "fmi2SetReal",
        &[vr("imu.gyro[1]"), vr("imu.acc[3]")],
        &[Value::Real(f64::NAN), Value::Real(f64::NAN)],
    )
    .unwrap();
    for _ in 0..50 {
        i.do_step(t, 0.01).unwrap();
        t += 0.01;
        assert!(torques_are_finite(&i));
        assert!(reals(&i, &ESTIMATE).iter().all(|v| v.is_finite()));
        assert_eq!(estimator_status(&i), 1 | 4);
    }
    // NaN stays refused where it is not a sensor glitch.
    assert!(i
        .set("fmi2SetReal", &[vr("fix.pos[1]")], &[Value::Real(f64::NAN)])
        .is_err());
}

#[test]
fn a_set_with_one_bad_value_stores_none_of_its_values() {
    let mut i = instance();
    let names = ["ref.x", "ref.y", "base.vel.y"];
    let vrs: Vec<u32> = names.iter().map(|n| vr(n)).collect();
    let real = |i: &Instance, name: &str| {
        let mut out = 0.0;
        i.get("fmi2GetReal", ScalarType::Real, &[vr(name)], |_, v| {
            if let Value::Real(x) = v {
                out = x;
            }
        })
        .unwrap();
        out
    };
    i.enter_initialization_mode().unwrap();
    let before: Vec<f64> = names.iter().map(|n| real(&i, n)).collect();
    let bad = [Value::Real(1.5), Value::Real(2.5), Value::Real(f64::NAN)];
    assert!(i.set("fmi2SetReal", &vrs, &bad).is_err());
    assert!(i.set_with("fmi2SetReal", &vrs, |k| bad[k]).is_err());
    let after: Vec<f64> = names.iter().map(|n| real(&i, n)).collect();
    assert_eq!(after, before);
    let good = [Value::Real(1.5), Value::Real(2.5), Value::Real(-0.25)];
    i.set_with("fmi2SetReal", &vrs, |k| good[k]).unwrap();
    let stored: Vec<f64> = names.iter().map(|n| real(&i, n)).collect();
    assert_eq!(stored, vec![1.5, 2.5, -0.25]);
}
