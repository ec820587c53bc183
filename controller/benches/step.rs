//! `Controller::step` without an MPC solve: trotting with two legs in swing (IK, inverse
//! dynamics) and two in stance (Jᵀf), the gait period stretched so no contact change (and hence
//! no MPC re-solve) happens during the measurement.
use criterion::{criterion_group, criterion_main, Criterion};
use quad_controller::{
    Controller, ControllerConfig, FsmState, ModeRequest, Reference, RobotModel, RobotState,
};

fn bench_step(c: &mut Criterion) {
    let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    let model = RobotModel::from_config_file(&robot).expect("URDF");
    let config = ControllerConfig {
        gait_period: 1.0e4,
        mpc_every_ticks: usize::MAX,
        stand_up_duration: 0.01,
        ..ControllerConfig::default()
    };
    let mut ctrl = Controller::new(model, config).expect("controller");
    let state = RobotState {
        base_position: [0.0, 0.0, quad_controller::tuning::TUNED_STAND_HEIGHT],
        joint_positions: ctrl.stand_joint_positions(),
        ..RobotState::default()
    };
    let mut reference = Reference {
        body_height: quad_controller::tuning::TUNED_STAND_HEIGHT,
        ..Reference::default()
    };
    for _ in 0..20 {
        ctrl.step(&state, &reference, 0.001).expect("step");
    }
    reference.mode = ModeRequest::Locomotion;
    reference.vx = 0.5;
    // First locomotion tick solves the MPC once; later ticks reuse its forces.
    for _ in 0..200 {
        ctrl.step(&state, &reference, 0.001).expect("step");
    }
    assert_eq!(ctrl.fsm_state(), FsmState::Locomotion);
    let mut solves_during_bench = 0usize;
    let mut last_time = ctrl
        .step(&state, &reference, 0.001)
        .expect("step")
        .mpc_solve_time_s;
    c.bench_function("step_without_mpc_trot", |b| {
        b.iter(|| {
            let cmd = ctrl.step(&state, &reference, 0.001).expect("step");
            if cmd.mpc_solve_time_s.to_bits() != last_time.to_bits() {
                solves_during_bench += 1;
                last_time = cmd.mpc_solve_time_s;
            }
            cmd.joint_torques[0]
        })
    });
    println!("MPC solves during the step benchmark: {solves_during_bench}");
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
