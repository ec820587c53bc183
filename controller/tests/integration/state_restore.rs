//! A saved controller state, restored, continues bit for bit: the controller trots on the
//! single-rigid-body simulation of `common`; at a tick in mid-walk (MPC solver cache warm, feet in
//! swing and stance) its state is saved, and the inputs of the following ticks are recorded with
//! the commands they gave. Replayed into the same controller after a restore, and into a fresh
//! controller restored from the state's CBOR encoding, the inputs give the same commands, every
//! float to the bit (except the MPC's wall-clock solve time, a diagnostic).
#![allow(clippy::needless_range_loop)] // the shared simulation indexes joints and axes in parallel
use crate::common;

use nalgebra::Vector3;
use quad_controller::{
    Command, Controller, ControllerConfig, ControllerState, EstimatorKind, FsmState, ModeRequest,
    Reference, RobotState, SensorReadings,
};

/// One tick's inputs.
type TickInputs = (RobotState, SensorReadings, Reference);

/// Every value of a command as bits, the solve time left out.
fn command_bits(command: &Command) -> Vec<u64> {
    let mut bits: Vec<u64> = command.joint_torques.iter().map(|v| v.to_bits()).collect();
    for vector in command
        .desired_forces
        .iter()
        .chain(&command.desired_foot_positions)
        .chain([
            &command.estimate.position,
            &command.estimate.velocity,
            &command.estimate.rpy,
        ])
    {
        bits.extend(vector.iter().map(|v| v.to_bits()));
    }
    bits.extend(command.contacts.iter().map(|&c| u64::from(c)));
    bits.push(command.fsm_state as u64);
    bits.push(u64::from(command.mpc_solved));
    bits.push(u64::from(command.estimate.status));
    bits
}

/// Trots for `save_after` s (1.5 s standing first), saves the state, then records `record` s of
/// inputs and commands.
fn trot_and_record(
    config: &ControllerConfig,
    save_after: f64,
    record: f64,
) -> (Controller, ControllerState, Vec<TickInputs>, Vec<Vec<u64>>) {
    let model = common::model();
    let dt = config.control_dt;
    let (mut controller, mut sim) = common::controller_and_standing_sim(model, config);
    let stand_ticks = (1.5 / dt) as usize;
    let save_tick = stand_ticks + (save_after / dt) as usize;
    let end_tick = save_tick + (record / dt) as usize;
    let speed = 0.4;
    let mut previous_velocity = Vector3::from(sim.state().base_linear_velocity);
    let mut acceleration = Vector3::zeros();
    let mut saved = None;
    let (mut inputs, mut commands) = (Vec::new(), Vec::new());
    for tick in 0..end_tick {
        if tick == save_tick {
            saved = Some(controller.save_state());
        }
        let walking = tick >= stand_ticks;
        let t = (tick as f64 - stand_ticks as f64).max(0.0) * dt;
        let sensors = SensorReadings {
            imu: sim.imu(acceleration),
            ..SensorReadings::default()
        };
        let reference = Reference {
            x: speed * t,
            y: 0.05 * t * t,
            yaw: 0.1 * t,
            vx: if walking { speed } else { 0.0 },
            yaw_rate: if walking { 0.1 } else { 0.0 },
            body_height: config.body_height,
            mode: if walking {
                ModeRequest::Locomotion
            } else {
                ModeRequest::Stand
            },
            ..Reference::default()
        };
        let state = sim.state();
        let command = controller
            .step_with_sensors(&state, &sensors, &reference, dt)
            .expect("valid input");
        if tick >= save_tick {
            inputs.push((state, sensors, reference));
            commands.push(command_bits(&command));
        }
        let balancing = matches!(command.fsm_state, FsmState::Stand | FsmState::Locomotion);
        sim.apply_torques(&command, dt, balancing);
        let velocity = Vector3::from(sim.state().base_linear_velocity);
        acceleration = (velocity - previous_velocity) / dt;
        previous_velocity = velocity;
    }
    assert_eq!(controller.fsm_state(), FsmState::Locomotion);
    (
        controller,
        saved.expect("the save tick is inside the run"),
        inputs,
        commands,
    )
}

fn replay(controller: &mut Controller, inputs: &[TickInputs], dt: f64) -> Vec<Vec<u64>> {
    inputs
        .iter()
        .map(|(state, sensors, reference)| {
            let command = controller
                .step_with_sensors(state, sensors, reference, dt)
                .expect("valid input");
            command_bits(&command)
        })
        .collect()
}

fn first_difference(expected: &[Vec<u64>], got: &[Vec<u64>]) -> Option<usize> {
    expected.iter().zip(got).position(|(a, b)| a != b)
}

fn check_restore(config: ControllerConfig) {
    let dt = config.control_dt;
    let (mut controller, state, inputs, expected) = trot_and_record(&config, 1.2, 0.8);

    controller.restore_state(state.clone()).expect("own state");
    let again = replay(&mut controller, &inputs, dt);
    assert_eq!(
        first_difference(&expected, &again),
        None,
        "restored into the same controller: first differing tick"
    );

    let mut blob = Vec::new();
    ciborium::into_writer(&state, &mut blob).expect("encode");
    let decoded: ControllerState = ciborium::from_reader(blob.as_slice()).expect("decode");
    let mut fresh = Controller::new(common::model(), config).expect("controller");
    fresh.restore_state(decoded).expect("decoded state");
    let from_blob = replay(&mut fresh, &inputs, dt);
    assert_eq!(
        first_difference(&expected, &from_blob),
        None,
        "restored from CBOR into a fresh controller: first differing tick"
    );
}

#[test]
fn ground_truth_controller_continues_bit_for_bit_after_restore() {
    check_restore(ControllerConfig::default());
}

#[test]
fn kalman_controller_continues_bit_for_bit_after_restore() {
    check_restore(ControllerConfig {
        estimator: EstimatorKind::Kalman,
        est_foot_rolling: 0.0,
        ..ControllerConfig::default()
    });
}

#[test]
fn state_of_another_horizon_is_refused_and_changes_nothing() {
    let config = ControllerConfig::default();
    let (_, state, inputs, _) = trot_and_record(&config, 0.3, 0.2);
    let other = ControllerConfig {
        mpc_horizon: config.mpc_horizon + 2,
        ..config.clone()
    };
    let mut controller = Controller::new(common::model(), other).expect("controller");
    let error = controller
        .restore_state(state)
        .expect_err("a state of another horizon");
    assert!(error.to_string().contains("horizon"), "{error}");
    // The refused controller is the fresh one it was: it stands up from the passive state.
    let command = controller
        .step(&inputs[0].0, &inputs[0].2, config.control_dt)
        .expect("valid input");
    assert_ne!(command.fsm_state, FsmState::Locomotion);
}
