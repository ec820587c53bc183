//! Hostile parameter values and step sizes through the C API of the bundled FMU (loaded with the
//! `fmi` crate): each is refused with fmi2Error and a logged reason, every call returns well
//! within 1 s, and the instance stays usable afterwards.

mod support;

use std::time::Instant;

use fmi::fmi2::import::Fmi2Import;
use fmi::fmi2::instance::{CoSimulation, Common, InstanceCS};
use quad_controller::{ControllerConfig, GaitKind};
use quad_controller_fmu::budget::max_ticks_per_step;
use quad_controller_fmu::variables::{Binding, Value};

use support::{errors_of, fmu_path, install_logger, table, vr};

/// Longest any call may take, s.
const CALL_LIMIT_S: f64 = 1.0;

/// Runs `call`, asserts it took less than [`CALL_LIMIT_S`] and returns whether it succeeded.
fn timed<T, E>(what: &str, call: impl FnOnce() -> Result<T, E>) -> bool {
    let start = Instant::now();
    let ok = call().is_ok();
    let elapsed = start.elapsed().as_secs_f64();
    assert!(elapsed < CALL_LIMIT_S, "{what} took {elapsed} s");
    ok
}

fn next_up(x: f64) -> f64 {
    match x {
        0.0 => f64::from_bits(1),
        x if x > 0.0 => f64::from_bits(x.to_bits() + 1),
        x => f64::from_bits(x.to_bits() - 1),
    }
}

fn next_down(x: f64) -> f64 {
    -next_up(-x)
}

fn initialise(instance: &mut InstanceCS) {
    assert!(timed("setup", || instance.setup_experiment(None, 0.0, None)));
    assert!(timed("enter", || instance.enter_initialization_mode()));
    assert!(timed("exit", || instance.exit_initialization_mode()));
}

#[test]
fn every_parameter_refuses_values_outside_its_range_with_a_reason() {
    install_logger();
    let import: Fmi2Import = fmi::import::from_path(fmu_path()).expect("importing the FMU");
    let name = "ranges";
    let mut instance = import
        .instantiate_cs(name, false, true)
        .expect("fmi2Instantiate");
    let mut refused = 0;
    for v in table() {
        let Binding::Parameter { .. } = v.binding else {
            continue;
        };
        let (min, max) = (v.min.expect("min"), v.max.expect("max"));
        let what = |x: &dyn std::fmt::Debug| format!("{} = {x:?}", v.name);
        match v.start {
            Value::Real(start) => {
                for bad in [
                    next_down(min),
                    next_up(max),
                    f64::NAN,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    1e300,
                    -1e300,
                ] {
                    let ok = timed(&what(&bad), || {
                        instance.set_real(&[v.value_reference], &[bad])
                    });
                    assert!(!ok, "{}", what(&bad));
                    refused += 1;
                }
                for good in [min, max, start] {
                    let ok = timed(&what(&good), || {
                        instance.set_real(&[v.value_reference], &[good])
                    });
                    assert!(ok, "{}", what(&good));
                }
            }
            _ => {
                for bad in [min as i32 - 1, max as i32 + 1, i32::MIN, i32::MAX] {
                    let ok = timed(&what(&bad), || {
                        instance.set_integer(&[v.value_reference], &[bad])
                    });
                    assert!(!ok, "{}", what(&bad));
                    refused += 1;
                }
            }
        }
    }
    let errors = errors_of(name);
    assert_eq!(errors.len(), refused, "{errors:#?}");
    assert!(errors
        .iter()
        .all(|m| m.contains("fmi2Set") && m.contains("invalid value for ")));
    assert!(errors.iter().any(|m| m.contains(
        "invalid value for control.dt: 0.00009999999999999999 is below the minimum 0.0001"
    )));
    // Nothing out of range was stored: the instance initialises and runs.
    initialise(&mut instance);
    assert!(timed("doStep", || instance.do_step(0.0, 0.01, true)));
}

/// The hangs of the issue, through the C API.
#[test]
fn regression_hangs_are_refused_at_once() {
    install_logger();
    let import: Fmi2Import = fmi::import::from_path(fmu_path()).expect("importing the FMU");
    let name = "hangs";
    let mut instance = import
        .instantiate_cs(name, false, true)
        .expect("fmi2Instantiate");
    for dt in [1e-12, 1e-9, 10.0, 1e300] {
        assert!(!timed("control.dt", || instance
            .set_real(&[vr("control.dt")], &[dt])));
    }
    initialise(&mut instance);
    for h in [1e12, 1e13, 1e14, 1e15, 1000.0, 1e300, f64::NAN, -1.0] {
        assert!(!timed(&format!("h = {h}"), || instance.do_step(0.0, h, true)));
    }
    let errors = errors_of(name);
    assert_eq!(errors.len(), 12, "{errors:#?}");
    for message in &errors[4..9] {
        assert!(message.contains("use shorter steps"), "{message}");
    }
    assert!(timed("doStep", || instance.do_step(0.0, 0.01, true)));
}

#[test]
fn the_tick_cap_of_the_most_expensive_parameters_holds_through_the_c_api() {
    install_logger();
    let import: Fmi2Import = fmi::import::from_path(fmu_path()).expect("importing the FMU");
    let name = "cap";
    let mut instance = import
        .instantiate_cs(name, false, true)
        .expect("fmi2Instantiate");
    let config = ControllerConfig {
        control_dt: 1e-4,
        mpc_every_ticks: 1,
        mpc_horizon: 40,
        gait: GaitKind::Walk,
        gait_period: 0.05,
        stand_up_duration: 0.01,
        ..ControllerConfig::default()
    };
    instance
        .set_real(
            &[vr("control.dt"), vr("gait.period"), vr("stand.upDuration")],
            &[
                config.control_dt,
                config.gait_period,
                config.stand_up_duration,
            ],
        )
        .expect("worst reals");
    instance
        .set_integer(
            &[vr("mpc.everyTicks"), vr("mpc.horizon"), vr("gait.kind")],
            &[1, 40, 1],
        )
        .expect("worst integers");
    let stand = support::direct_controller().stand_joint_positions();
    let q: Vec<u32> = (1..=12).map(|i| vr(&format!("joint.q[{i}]"))).collect();
    instance.set_real(&q, &stand).expect("joints");
    instance
        .set_real(&[vr("base.pos.z"), vr("ref.vx")], &[0.28, 0.3])
        .expect("height");
    instance
        .set_integer(&[vr("cmd.mode")], &[2])
        .expect("locomotion");
    initialise(&mut instance);
    let max = max_ticks_per_step(&config);
    assert_eq!(max, 8);
    let h = max as f64 * config.control_dt;
    assert!(!timed("one tick over", || instance.do_step(
        0.0,
        (max + 1) as f64 * config.control_dt,
        true
    )));
    let mut t = 0.0;
    let mut worst: f64 = 0.0;
    for _ in 0..60 {
        let start = Instant::now();
        assert!(timed("capped step", || instance.do_step(t, h, true)));
        worst = worst.max(start.elapsed().as_secs_f64());
        t += h;
    }
    let mut fsm = [0];
    instance
        .get_integer(&[vr("fsm.state")], &mut fsm)
        .expect("fsm");
    assert_eq!(fsm[0], 3, "locomotion: the MPC ran on every tick");
    eprintln!("slowest capped step: {:.1} ms", worst * 1e3);
    assert_eq!(errors_of(name).len(), 1);
}
