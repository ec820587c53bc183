//! MPC standing forces, FSM transitions, bad input, determinism and the config file format.
#![allow(clippy::needless_range_loop)] // parallel indexing of joints, axes and legs
use crate::common;

use quad_controller::mpc::{ConvexMpc, MpcInput, MpcParams, MpcStatus};
use quad_controller::{
    Command, Controller, ControllerConfig, ControllerError, FsmState, Leg, ModeRequest, Reference,
    RobotState, GRAVITY,
};

fn controller() -> Controller {
    Controller::new(common::model(), ControllerConfig::default()).expect("default config is valid")
}

/// The robot standing still at the nominal pose, base at `height`.
fn standing_state(controller: &Controller, height: f64) -> RobotState {
    RobotState {
        base_position: [0.0, 0.0, height],
        joint_positions: controller.stand_joint_positions(),
        ..RobotState::default()
    }
}

fn reference(mode: ModeRequest) -> Reference {
    Reference {
        mode,
        body_height: quad_controller::tuning::TUNED_STAND_HEIGHT,
        ..Reference::default()
    }
}

/// MPC set up for the standing robot with the given contact pattern on every step.
fn standing_mpc_forces(contacts: [bool; 4]) -> ([[f64; 3]; 4], f64, ControllerConfig) {
    let ctrl = controller();
    let model = ctrl.model();
    let config = ctrl.config().clone();
    let (inertia, com) = model.composite_inertia(&ctrl.stand_joint_positions());
    let mut mpc = ConvexMpc::new(MpcParams {
        horizon: 10,
        ..MpcParams::from_config(&config, model.total_mass(), inertia)
    })
    .expect("valid MPC");
    let base_z = quad_controller::tuning::TUNED_STAND_HEIGHT;
    let com_world = [com[0], com[1], base_z + com[2]];
    let state = [
        0.0,
        0.0,
        0.0,
        com_world[0],
        com_world[1],
        com_world[2],
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        GRAVITY,
    ];
    let q = ctrl.stand_joint_positions();
    let offsets: [[f64; 3]; 4] = Leg::ALL.map(|leg| {
        let l = leg.index();
        let foot = model.foot_position_body(leg, [q[3 * l], q[3 * l + 1], q[3 * l + 2]]);
        [
            foot[0] - com[0],
            foot[1] - com[1],
            foot[2] + base_z - com_world[2],
        ]
    });
    let reference = vec![state; 10];
    let schedule = vec![contacts; 10];
    let foot_offsets = vec![offsets; 10];
    let solution = mpc.solve(&MpcInput {
        x0: state,
        reference: &reference,
        contacts: &schedule,
        foot_offsets: &foot_offsets,
        terrain_normal: [0.0, 0.0, 1.0],
    });
    assert_eq!(solution.status, MpcStatus::Solved);
    (solution.forces, model.total_mass(), config)
}

#[test]
fn standing_mpc_forces_carry_the_weight_inside_the_friction_pyramid() {
    let (forces, mass, config) = standing_mpc_forces([true; 4]);
    let weight = mass * GRAVITY;
    let total: [f64; 3] = [0, 1, 2].map(|a| forces.iter().map(|f| f[a]).sum());
    assert!(
        (total[2] - weight).abs() < 0.01 * weight,
        "Σfz = {} vs mg = {weight}",
        total[2]
    );
    assert!(total[0].abs() < 0.5 && total[1].abs() < 0.5, "{total:?}");
    for f in &forces {
        assert!(f[0].abs() <= config.mu * f[2] + 1e-6 && f[1].abs() <= config.mu * f[2] + 1e-6);
        assert!(f[2] >= config.f_min - 1e-6 && f[2] <= config.f_max + 1e-6);
        // Symmetric stance: each foot carries roughly a quarter.
        assert!((f[2] - weight / 4.0).abs() < 0.15 * weight, "{f:?}");
    }
}

#[test]
fn swing_legs_get_zero_force() {
    let (forces, mass, config) = standing_mpc_forces([true, false, false, true]);
    assert_eq!(forces[Leg::FL.index()], [0.0; 3]);
    assert_eq!(forces[Leg::RR.index()], [0.0; 3]);
    let fz: f64 = forces.iter().map(|f| f[2]).sum();
    assert!(
        (fz - mass * GRAVITY).abs() < 0.05 * mass * GRAVITY,
        "Σfz = {fz}"
    );
    for f in [forces[0], forces[3]] {
        assert!(f[0].abs() <= config.mu * f[2] + 1e-6 && f[1].abs() <= config.mu * f[2] + 1e-6);
    }
}

#[test]
fn mpc_rejects_inconsistent_input_without_panicking() {
    let ctrl = controller();
    let (inertia, _) = ctrl
        .model()
        .composite_inertia(&ctrl.stand_joint_positions());
    let mut mpc = ConvexMpc::new(MpcParams {
        horizon: 10,
        dt: 0.03,
        mass: 12.0,
        inertia_body: inertia,
        q_weights: [1.0; 13],
        r_weight: 1e-5,
        mu: 0.6,
        f_min: 5.0,
        f_max: 150.0,
    })
    .expect("valid");
    let reference = vec![[0.0; 13]; 3];
    let schedule = vec![[true; 4]; 10];
    let offsets = vec![[[0.0; 3]; 4]; 10];
    let solution = mpc.solve(&MpcInput {
        x0: [0.0; 13],
        reference: &reference,
        contacts: &schedule,
        foot_offsets: &offsets,
        terrain_normal: [0.0, 0.0, 1.0],
    });
    assert_eq!(solution.status, MpcStatus::InvalidInput);
    assert!(ConvexMpc::new(MpcParams {
        horizon: 0,
        ..mpc.params().clone()
    })
    .is_err());
    assert!(ConvexMpc::new(MpcParams {
        f_min: 200.0,
        ..mpc.params().clone()
    })
    .is_err());
}

fn step(ctrl: &mut Controller, state: &RobotState, mode: ModeRequest) -> Command {
    ctrl.step(state, &reference(mode), 0.001)
        .expect("valid input")
}

#[test]
fn fsm_walks_through_every_transition() {
    let mut ctrl = controller();
    let state = standing_state(&ctrl, quad_controller::tuning::TUNED_STAND_HEIGHT);
    assert_eq!(ctrl.fsm_state(), FsmState::Passive);
    let cmd = step(&mut ctrl, &state, ModeRequest::Passive);
    assert_eq!(cmd.fsm_state, FsmState::Passive);
    assert_eq!(cmd.joint_torques, [0.0; 12]);

    assert_eq!(
        step(&mut ctrl, &state, ModeRequest::Stand).fsm_state,
        FsmState::StandUp
    );
    // Passive request aborts the stand-up.
    assert_eq!(
        step(&mut ctrl, &state, ModeRequest::Passive).fsm_state,
        FsmState::Passive
    );
    assert_eq!(
        step(&mut ctrl, &state, ModeRequest::Locomotion).fsm_state,
        FsmState::StandUp
    );
    // Stand-up lasts `stand_up_duration` (1 s); locomotion is requested throughout.
    let mut ticks = 1;
    while ctrl.fsm_state() == FsmState::StandUp {
        step(&mut ctrl, &state, ModeRequest::Locomotion);
        ticks += 1;
        assert!(ticks < 1100, "stand-up never finished");
    }
    assert!(
        (1000..=1002).contains(&ticks),
        "stand-up took {ticks} ticks"
    );
    assert_eq!(ctrl.fsm_state(), FsmState::Stand);
    let cmd = step(&mut ctrl, &state, ModeRequest::Locomotion);
    assert_eq!(cmd.fsm_state, FsmState::Locomotion);
    assert!(cmd.mpc_solved);
    assert_eq!(
        step(&mut ctrl, &state, ModeRequest::Stand).fsm_state,
        FsmState::Stand
    );
    let cmd = step(&mut ctrl, &state, ModeRequest::Stand);
    assert_eq!(cmd.contacts, [true; 4]);
    assert!(cmd.mpc_solved);
    let fz: f64 = cmd.desired_forces.iter().map(|f| f[2]).sum();
    assert!(
        (fz - 12.0 * GRAVITY).abs() < 0.05 * 12.0 * GRAVITY,
        "Σfz = {fz}"
    );
    assert_eq!(
        step(&mut ctrl, &state, ModeRequest::Passive).fsm_state,
        FsmState::Passive
    );
}

fn locomoting_controller() -> (Controller, RobotState) {
    let mut ctrl = controller();
    let state = standing_state(&ctrl, quad_controller::tuning::TUNED_STAND_HEIGHT);
    for _ in 0..1002 {
        step(&mut ctrl, &state, ModeRequest::Stand);
    }
    assert_eq!(ctrl.fsm_state(), FsmState::Stand);
    step(&mut ctrl, &state, ModeRequest::Locomotion);
    assert_eq!(ctrl.fsm_state(), FsmState::Locomotion);
    (ctrl, state)
}

/// Gait time at which the push below is measured: the trot's second cycle (a push in the first
/// is not told from the walk's own start), FR and RL a third into their swing.
const PUSHED_AT: f64 = 0.5;

/// Contacts of the 240 ticks after a sideways push is measured at `PUSHED_AT` (FR and RL swing
/// until 0.6 s; FL and RR stand until then and swing until 0.75 s), with the swings cut short
/// `touchdown_time` after a push (0: on the gait's clock).
fn contacts_after_a_push(touchdown_time: f64) -> Vec<[bool; 4]> {
    let config = ControllerConfig {
        recovery_touchdown_time: touchdown_time,
        ..ControllerConfig::default()
    };
    let mut ctrl = Controller::new(common::model(), config).expect("valid config");
    let state = standing_state(&ctrl, quad_controller::tuning::TUNED_STAND_HEIGHT);
    for _ in 0..1002 {
        step(&mut ctrl, &state, ModeRequest::Stand);
    }
    for _ in 0..500 {
        step(&mut ctrl, &state, ModeRequest::Locomotion);
    }
    let pushed = RobotState {
        base_linear_velocity: [0.0, 1.0, 0.0],
        ..state
    };
    (0..240)
        .map(|_| step(&mut ctrl, &pushed, ModeRequest::Locomotion).contacts)
        .collect()
}

#[test]
fn a_push_lands_the_swinging_pair_early_and_the_stance_pair_keeps_its_timing() {
    let [fr, fl, rr, rl] = [0, 1, 2, 3];
    let on_the_clock = contacts_after_a_push(0.0);
    let cut_short = contacts_after_a_push(0.05);
    for (k, (clock, early)) in on_the_clock.iter().zip(&cut_short).enumerate() {
        // Ticks 50 and 100 fall on a phase boundary (0.55 s, 0.6 s) up to rounding.
        if k == 50 || k == 100 {
            continue;
        }
        let t = PUSHED_AT + 0.001 * k as f64;
        // The stance pair lifts off at 0.6 s either way, and its swing is not cut short: the
        // body is still being braked from the same push.
        for leg in [fl, rr] {
            assert_eq!(clock[leg], t < 0.6, "t = {t:.3}, leg {leg}");
            assert_eq!(early[leg], t < 0.6, "t = {t:.3}, leg {leg}");
        }
        for leg in [fr, rl] {
            // On the clock the swing ends at 0.6 s; cut short it ends 0.05 s after the push and
            // the feet stand on into their own stance.
            assert_eq!(clock[leg], t > 0.6, "t = {t:.3}, leg {leg}");
            assert_eq!(early[leg], t > 0.55, "t = {t:.3}, leg {leg}");
        }
    }
}

#[test]
fn falling_over_enters_damping_until_reset_to_passive() {
    let (mut ctrl, mut state) = locomoting_controller();
    // Rolled by 60° about x: beyond max_tilt.
    let half = (60f64.to_radians() / 2.0).sin_cos();
    state.base_orientation = [half.1, half.0, 0.0, 0.0];
    state.joint_velocities = [1.0; 12];
    let cmd = step(&mut ctrl, &state, ModeRequest::Locomotion);
    assert_eq!(cmd.fsm_state, FsmState::Damping);
    let kd = ctrl.config().damping_kd;
    for tau in cmd.joint_torques {
        assert!((tau + kd).abs() < 1e-12, "damping torque {tau}");
    }
    assert_eq!(cmd.desired_forces, [[0.0; 3]; 4]);
    // Damping is sticky: neither stand nor locomotion requests leave it.
    let upright = standing_state(&ctrl, quad_controller::tuning::TUNED_STAND_HEIGHT);
    assert_eq!(
        step(&mut ctrl, &upright, ModeRequest::Stand).fsm_state,
        FsmState::Damping
    );
    assert_eq!(
        step(&mut ctrl, &upright, ModeRequest::Locomotion).fsm_state,
        FsmState::Damping
    );
    assert_eq!(
        step(&mut ctrl, &upright, ModeRequest::Passive).fsm_state,
        FsmState::Passive
    );
}

#[test]
fn joint_beyond_its_limit_enters_damping() {
    let mut ctrl = controller();
    let mut state = standing_state(&ctrl, quad_controller::tuning::TUNED_STAND_HEIGHT);
    step(&mut ctrl, &state, ModeRequest::Stand);
    assert_eq!(ctrl.fsm_state(), FsmState::StandUp);
    // Knee limit is −0.5 rad; margin 0.15 rad.
    state.joint_positions[5] = -0.2;
    assert_eq!(
        step(&mut ctrl, &state, ModeRequest::Stand).fsm_state,
        FsmState::Damping
    );
}

#[test]
fn bad_input_is_a_clear_error_and_leaves_the_controller_usable() {
    let (mut ctrl, state) = locomoting_controller();
    let good = reference(ModeRequest::Locomotion);
    for dt in [0.0, -0.001, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(
                ctrl.step(&state, &good, dt),
                Err(ControllerError::InvalidDt(_))
            ),
            "dt {dt}"
        );
    }
    let mut nan_state = state;
    nan_state.joint_positions[4] = f64::NAN;
    let err = ctrl.step(&nan_state, &good, 0.001).expect_err("NaN joint");
    assert!(err.to_string().contains("joint_positions[4]"), "{err}");
    let mut inf_state = state;
    inf_state.base_linear_velocity[2] = f64::INFINITY;
    assert!(matches!(
        ctrl.step(&inf_state, &good, 0.001),
        Err(ControllerError::InvalidState(_))
    ));
    let mut zero_quat = state;
    zero_quat.base_orientation = [0.0; 4];
    assert!(matches!(
        ctrl.step(&zero_quat, &good, 0.001),
        Err(ControllerError::InvalidState(_))
    ));
    let mut bad_ref = good;
    bad_ref.vx = f64::NAN;
    assert!(matches!(
        ctrl.step(&state, &bad_ref, 0.001),
        Err(ControllerError::InvalidReference(_))
    ));
    // The MPC's prediction cannot represent a turn of more than π/2 per step (0.03 s).
    let mut spinning = good;
    spinning.yaw_rate = 60.0;
    let err = ctrl.step(&state, &spinning, 0.001).expect_err("60 rad/s");
    assert!(err.to_string().contains("yaw_rate 60"), "{err}");
    // Errors do not change the FSM; safe torques are finite damping even for NaN velocities.
    assert_eq!(ctrl.fsm_state(), FsmState::Locomotion);
    let mut nan_velocity = state;
    nan_velocity.joint_velocities = [f64::NAN; 12];
    nan_velocity.joint_velocities[0] = 100.0;
    let safe = ctrl.safe_command(&nan_velocity);
    assert_eq!(safe.fsm_state, FsmState::Damping);
    assert_eq!(safe.joint_torques[0], -25.0, "clamped to the effort limit");
    assert!(safe.joint_torques[1..].iter().all(|t| *t == 0.0));
    let cmd = ctrl.step(&state, &good, 0.001).expect("still usable");
    assert_eq!(cmd.fsm_state, FsmState::Locomotion);
    // Locomotion → passive on request.
    assert_eq!(
        step(&mut ctrl, &state, ModeRequest::Passive).fsm_state,
        FsmState::Passive
    );
}

#[test]
fn invalid_config_is_rejected() {
    let model = common::model();
    let bad = [
        ControllerConfig {
            mpc_horizon: 5,
            ..ControllerConfig::default()
        },
        ControllerConfig {
            mpc_every_ticks: 0,
            ..ControllerConfig::default()
        },
        ControllerConfig {
            control_dt: -1.0,
            ..ControllerConfig::default()
        },
        ControllerConfig {
            mu: f64::NAN,
            ..ControllerConfig::default()
        },
        ControllerConfig {
            body_height: 0.6,
            ..ControllerConfig::default()
        },
    ];
    for config in bad {
        assert!(
            Controller::new(model.clone(), config.clone()).is_err(),
            "{config:?}"
        );
    }
}

/// What a locomotion command must satisfy whatever the gait phase (level ground, base upright):
/// swing legs get no force; the stance forces carry the weight (Σf_z within 35 % of m·g: the MPC
/// also accelerates the base towards the moving reference) inside the friction pyramid and the
/// normal-force bounds; and each stance leg's torques realise its force through the stance law
/// `τ = Jᵀ(−f) + h(q, q̇)` (R = I here) unless the effort clamp changed them.
/// Returns how many stance joint torques were compared with the law.
fn check_stance_forces_and_torques(ctrl: &Controller, state: &RobotState, cmd: &Command) -> usize {
    let mut compared = 0;
    let model = ctrl.model();
    let config = ctrl.config();
    let weight = model.total_mass() * GRAVITY;
    let limits = model.effort_limits();
    let fz: f64 = cmd.desired_forces.iter().map(|f| f[2]).sum();
    assert!(
        (fz - weight).abs() < 0.35 * weight,
        "Σfz = {fz} vs m·g = {weight}"
    );
    for leg in Leg::ALL {
        let l = leg.index();
        let f = cmd.desired_forces[l];
        if !cmd.contacts[l] {
            assert_eq!(f, [0.0; 3], "swing leg {leg:?}");
            continue;
        }
        // The QP is solved to 1e-6 in units of m·g (~1e-4 N): constraints hold to that.
        let tolerance = 1e-3;
        assert!(f[0].abs() <= config.mu * f[2] + tolerance, "{leg:?} {f:?}");
        assert!(f[1].abs() <= config.mu * f[2] + tolerance, "{leg:?} {f:?}");
        assert!(f[2] >= config.f_min - tolerance && f[2] <= config.f_max + tolerance);
        let q = [0, 1, 2].map(|j| state.joint_positions[3 * l + j]);
        let dq = [0, 1, 2].map(|j| state.joint_velocities[3 * l + j]);
        let jacobian = model.foot_jacobian_body(leg, q);
        let bias = model.leg_bias(leg, q, dq, [0.0, 0.0, -GRAVITY]);
        for j in 0..3 {
            let expected: f64 = (0..3).map(|r| jacobian[r][j] * -f[r]).sum::<f64>() + bias[j];
            let limit = limits[3 * l + j];
            if expected.abs() < limit {
                let tau = cmd.joint_torques[3 * l + j];
                assert!(
                    (tau - expected).abs() < 1e-9 * (1.0 + expected.abs()),
                    "{leg:?} joint {j}: τ = {tau}, Jᵀ(−f) + h = {expected}"
                );
                compared += 1;
            }
        }
    }
    compared
}

#[test]
fn step_is_deterministic_and_torques_respect_effort_limits() {
    let run = || {
        let (mut ctrl, state) = locomoting_controller();
        let limits = ctrl.model().effort_limits();
        let mut reference = reference(ModeRequest::Locomotion);
        reference.vx = 0.4;
        reference.yaw_rate = 0.3;
        let mut outputs = Vec::new();
        let mut compared = 0;
        for tick in 0..400 {
            let mut s = state;
            s.base_linear_velocity[0] = 0.001 * tick as f64;
            let cmd = ctrl.step(&s, &reference, 0.001).expect("valid");
            for (tau, limit) in cmd.joint_torques.iter().zip(limits) {
                assert!(tau.abs() <= limit);
            }
            compared += check_stance_forces_and_torques(&ctrl, &s, &cmd);
            outputs.push((cmd.joint_torques, cmd.desired_forces, cmd.contacts));
        }
        // Two stance legs of three joints on every tick, unless the clamp was active.
        assert!(
            compared > 400 * 6 / 2,
            "only {compared} stance torques compared"
        );
        outputs
    };
    let (a, b) = (run(), run());
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.0.map(f64::to_bits), y.0.map(f64::to_bits));
        assert_eq!(
            x.1.map(|f| f.map(f64::to_bits)),
            y.1.map(|f| f.map(f64::to_bits))
        );
        assert_eq!(x.2, y.2);
    }
    // The gait actually alternates contacts.
    assert!(a.iter().any(|o| o.2 == [true, false, false, true]));
    assert!(a.iter().any(|o| o.2 == [false, true, true, false]));
}

#[test]
fn config_round_trips_through_json() {
    let config = ControllerConfig::default();
    let text = serde_json::to_string_pretty(&config).expect("serialise");
    let back: ControllerConfig = serde_json::from_str(&text).expect("deserialise");
    assert_eq!(back, config);
    assert!(serde_json::from_str::<ControllerConfig>("{\"control_dt\": 0.001}").is_err());
    assert_eq!(
        FsmState::from_code(FsmState::Damping.as_code()),
        Some(FsmState::Damping)
    );
    assert_eq!(FsmState::from_code(7), None);
}

/// Stand-up torques of the first tick with every joint moving at `velocity` rad/s.
fn stand_up_torques(ctrl: &mut Controller, velocity: f64) -> [f64; 12] {
    let mut state = standing_state(ctrl, quad_controller::tuning::TUNED_STAND_HEIGHT);
    state.joint_velocities = [velocity; 12];
    step(ctrl, &state, ModeRequest::Stand).joint_torques
}

#[test]
fn joint_feedback_is_capped_for_a_held_input_period() {
    let baseline = stand_up_torques(&mut controller(), 0.5);
    for period in [0.0, 0.001] {
        let mut ctrl = controller();
        ctrl.set_input_period(period).expect("valid period");
        // At the controller's own rate no default gain reaches its cap: bit for bit the same.
        assert_eq!(
            stand_up_torques(&mut ctrl, 0.5),
            baseline,
            "period {period}"
        );
    }
    let period = 0.005;
    let damping = |ctrl_of: &dyn Fn() -> Controller| {
        let plus = stand_up_torques(&mut ctrl_of(), 0.5);
        let minus = stand_up_torques(&mut ctrl_of(), -0.5);
        let mut kd = [0.0; 12];
        for i in 0..12 {
            kd[i] = (minus[i] - plus[i]) / (2.0 * 0.5); // τ = … − k_d q̇
        }
        kd
    };
    let fresh = damping(&controller);
    let held = damping(&|| {
        let mut ctrl = controller();
        ctrl.set_input_period(period).expect("valid period");
        ctrl
    });
    let ctrl = controller();
    let q = ctrl.stand_joint_positions();
    for leg in Leg::ALL {
        let l = leg.index();
        let mass = ctrl
            .model()
            .leg_mass_matrix(leg, [q[3 * l], q[3 * l + 1], q[3 * l + 2]]);
        for j in 0..3 {
            let i = 3 * l + j;
            let cap = mass[j][j] / period;
            assert!(
                held[i] <= cap * (1.0 + 1e-9),
                "joint {i}: k_d {} > {cap}",
                held[i]
            );
            assert!(held[i] <= fresh[i] + 1e-9, "joint {i}");
        }
    }
    // The knee (lightest joint) is the one the cap lowers at 5 ms.
    assert!(
        held[2] < 0.5 * fresh[2],
        "knee k_d {} vs {}",
        held[2],
        fresh[2]
    );
    let mut ctrl = controller();
    for bad in [-0.001, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            ctrl.set_input_period(bad),
            Err(ControllerError::Config(_))
        ));
    }
}
