//! FMU states: get at t = 2 s, run 1 s, set back, run the same 1 s: every output is identical to
//! the bit; the same through a serialized state in a second instance; bad serialized states are
//! refused and change nothing.

use super::tests::{instance, vr};
use super::*;
use crate::saved_state::{HEADER_LEN, MAGIC};
use crate::variables::{table, Causality};
use quad_controller::{FsmState, ModeRequest};

/// Inputs as a function of time: stand for 1.5 s, then walk a slow curve; the body "measured"
/// moves with the reference and the joints wiggle, so every tick sees new inputs.
fn set_inputs_at(i: &mut Instance, t: f64) {
    let walk = (t - 1.5).max(0.0);
    let reals = [
        ("base.pos.x", 0.3 * walk),
        ("base.pos.y", 0.02 * walk * walk),
        ("base.vel.x", if walk > 0.0 { 0.3 } else { 0.0 }),
        ("ref.x", 0.3 * walk),
        ("ref.y", 0.02 * walk * walk),
        ("ref.vx", if walk > 0.0 { 0.3 } else { 0.0 }),
        ("imu.gyro[3]", 0.01 * (3.0 * t).sin()),
    ];
    let (names, values): (Vec<u32>, Vec<Value>) = reals
        .iter()
        .map(|(name, value)| (vr(name), Value::Real(*value)))
        .unzip();
    i.set("fmi2SetReal", &names, &values).unwrap();
    let wiggle: Vec<Value> = (0..12)
        .map(|k| {
            let stand = i.controller.as_ref().unwrap().stand_joint_positions()[k];
            Value::Real(stand + 0.01 * (5.0 * t + k as f64).sin())
        })
        .collect();
    let joints: Vec<u32> = (1..=12).map(|k| vr(&format!("joint.q[{k}]"))).collect();
    i.set("fmi2SetReal", &joints, &wiggle).unwrap();
    let mode = if walk > 0.0 {
        ModeRequest::Locomotion
    } else {
        ModeRequest::Stand
    };
    i.set(
        "fmi2SetInteger",
        &[vr("cmd.mode")],
        &[Value::Integer(mode as i32)],
    )
    .unwrap();
}

/// Every output except the MPC's wall-clock solve time (a diagnostic, not deterministic), as bits.
fn output_bits(i: &Instance) -> Vec<u64> {
    let mut bits = Vec::new();
    for v in table() {
        if v.causality != Causality::Output || v.name == "mpc.solveTime" {
            continue;
        }
        i.get("test", v.scalar_type(), &[v.value_reference], |_, value| {
            bits.push(match value {
                Value::Real(x) => x.to_bits(),
                Value::Integer(x) => x as u64,
                Value::Boolean(x) => u64::from(x),
            })
        })
        .unwrap();
    }
    bits
}

const STEP: f64 = 0.01;

/// Runs `steps` doSteps of 10 ms from the instance's time; the outputs after each.
fn run(i: &mut Instance, steps: usize) -> Vec<Vec<u64>> {
    (0..steps)
        .map(|_| {
            let t = i.time();
            set_inputs_at(i, t);
            i.do_step(t, STEP).unwrap();
            output_bits(i)
        })
        .collect()
}

fn started(kalman: bool) -> Instance {
    let mut i = instance();
    if kalman {
        i.set("fmi2SetInteger", &[vr("estimator")], &[Value::Integer(1)])
            .unwrap();
    }
    i.setup_experiment(0.0, None).unwrap();
    i.enter_initialization_mode().unwrap();
    i.exit_initialization_mode().unwrap();
    i
}

fn check_round_trip(kalman: bool) {
    let mut i = started(kalman);
    run(&mut i, 200);
    assert_eq!(i.command.fsm_state, FsmState::Locomotion);
    let saved = i.save_state();
    let first = run(&mut i, 100);

    i.restore_state(&saved).unwrap();
    assert_eq!(i.time(), saved.time);
    let again = run(&mut i, 100);
    assert!(
        first == again,
        "set state: outputs differ from the first run"
    );

    let blob = saved.encode(i.guid(), i.robot_crc()).unwrap();
    let decoded = InstanceState::decode(&blob, i.guid(), i.robot_crc()).unwrap();
    let mut second = instance();
    second.restore_state(&decoded).unwrap();
    assert_eq!(second.phase(), Phase::StepComplete);
    let other = run(&mut second, 100);
    assert!(
        first == other,
        "serialized state in a second instance: outputs differ"
    );
}

#[test]
fn set_state_continues_bit_for_bit_ground_truth() {
    check_round_trip(false);
}

#[test]
fn set_state_continues_bit_for_bit_kalman() {
    check_round_trip(true);
}

#[test]
fn states_of_every_phase_restore_the_phase_and_its_rules() {
    let mut i = instance();
    let instantiated = i.save_state();
    i.enter_initialization_mode().unwrap();
    i.set("fmi2SetReal", &[vr("control.dt")], &[Value::Real(0.002)])
        .unwrap();
    let initializing = i.save_state();
    i.exit_initialization_mode().unwrap();
    i.do_step(0.0, 0.01).unwrap();
    assert_eq!(i.ticks_done(), 5);

    i.restore_state(&instantiated).unwrap();
    assert_eq!(i.phase(), Phase::Instantiated);
    assert!(
        i.do_step(0.0, 0.01).is_err(),
        "no doStep before initialization"
    );
    i.restore_state(&initializing).unwrap();
    assert_eq!(i.phase(), Phase::InitializationMode);
    assert_eq!(i.max_ticks_per_step(), 0);
    i.exit_initialization_mode().unwrap();
    i.do_step(0.0, 0.01).unwrap();
    assert_eq!(
        i.ticks_done(),
        5,
        "the parameter set before the state was taken holds"
    );
}

#[test]
fn bad_serialized_states_are_refused_and_change_nothing() {
    let mut i = started(false);
    run(&mut i, 50);
    let crc = i.robot_crc();
    let blob = i.save_state().encode(i.guid(), crc).unwrap();
    let before = output_bits(&i);
    let time = i.time();

    let mut cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", Vec::new(), "shorter than"),
        ("truncated header", blob[..HEADER_LEN - 3].to_vec(), "shorter than"),
        ("truncated payload", blob[..blob.len() - 1].to_vec(), "truncated"),
        ("padded", [blob.as_slice(), &[0]].concat(), "truncated or padded"),
        ("not ours", b"%PDF-1.7 and then some more bytes to pass the header length check of the state................................".to_vec(), "magic"),
    ];
    let mut layout = blob.clone();
    layout[MAGIC.len()] ^= 0x01;
    cases.push(("other state types", layout, "other state types"));
    let mut guid = blob.clone();
    let digit = MAGIC.len() + 4 + 1;
    guid[digit] = if guid[digit] == b'0' { b'1' } else { b'0' };
    cases.push(("other FMU", guid, "GUID"));
    let mut corrupted = blob.clone();
    let last = corrupted.len() - 1;
    corrupted[last] ^= 0x40;
    cases.push(("corrupted", corrupted, "checksum"));
    for (what, bytes, expected) in &cases {
        let err = InstanceState::decode(bytes, i.guid(), crc).expect_err(what);
        assert!(err.to_string().contains(expected), "{what}: {err}");
    }
    let err = InstanceState::decode(&blob, i.guid(), crc ^ 1).expect_err("other robot");
    assert!(err.to_string().contains("robot description"), "{err}");

    // A well-formed state that is not consistent: a controller state with a phase that has none.
    let mut state = i.save_state();
    state.phase = Phase::Instantiated;
    let err = i
        .restore_state(&state)
        .expect_err("phase without controller");
    assert!(
        err.to_string().contains("instantiated with a controller"),
        "{err}"
    );
    let mut state = i.save_state();
    state.config.f_min = state.config.f_max + 1.0;
    assert!(
        i.restore_state(&state).is_err(),
        "parameters the controller rejects"
    );

    assert_eq!(output_bits(&i), before);
    assert_eq!(i.time(), time);
    i.do_step(time, STEP).unwrap();
}
