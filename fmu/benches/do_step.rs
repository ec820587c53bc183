//! Cost of one control tick driven three ways: a direct `Controller::step`, and `fmi2DoStep` of
//! one tick through the `fmi` crate importer, with and without writing all 47 Real inputs and
//! reading the 12 torques around it (what a co-simulation master does every step).
//!
//! The FMU is bundled from this build's cdylib into the cargo target's tmp folder.
//! Run: `cargo bench -p quad-controller-fmu --bench do_step -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use fmi::fmi2::import::Fmi2Import;
use fmi::fmi2::instance::{CoSimulation, Common, InstanceCS};
use quad_controller::{
    Controller, ControllerConfig, Reference, RobotModel, RobotState, NUM_JOINTS,
};
use quad_controller_fmu::bundle::{
    default_robot_config, shared_library_next_to, write_fmu, BundleInputs,
};
use quad_controller_fmu::variables::{Causality, ScalarType, VariableTable};

const DT: f64 = 0.001;
/// Ticks until the robot stands (stand-up takes 1 s), so every variant measures the MPC stance.
const WARM_UP_TICKS: usize = 1500;

fn standing(model: &RobotModel) -> (RobotState, Reference) {
    let config = ControllerConfig::default();
    let controller = Controller::new(model.clone(), config.clone()).expect("default controller");
    let state = RobotState {
        base_position: [0.0, 0.0, config.body_height],
        joint_positions: controller.stand_joint_positions(),
        ..RobotState::default()
    };
    (state, Reference::default())
}

fn real_inputs(
    table: &VariableTable,
    state: &RobotState,
    reference: &Reference,
) -> (Vec<u32>, Vec<f64>) {
    let mut vrs = Vec::new();
    let mut values = Vec::new();
    let mut fields: Vec<(String, f64)> = Vec::new();
    for (i, a) in ["x", "y", "z"].iter().enumerate() {
        fields.push((format!("base.pos.{a}"), state.base_position[i]));
        fields.push((format!("base.vel.{a}"), state.base_linear_velocity[i]));
        fields.push((format!("base.omega.{a}"), state.base_angular_velocity[i]));
    }
    for (i, c) in ["w", "x", "y", "z"].iter().enumerate() {
        fields.push((format!("base.quat.{c}"), state.base_orientation[i]));
    }
    for i in 0..NUM_JOINTS {
        fields.push((format!("joint.q[{}]", i + 1), state.joint_positions[i]));
        fields.push((format!("joint.dq[{}]", i + 1), state.joint_velocities[i]));
    }
    fields.push(("ref.x".into(), reference.x));
    fields.push(("ref.y".into(), reference.y));
    for (name, value) in fields {
        vrs.push(table.by_name(&name).expect("input name").value_reference);
        values.push(value);
    }
    (vrs, values)
}

fn bench(c: &mut Criterion) {
    let model = RobotModel::from_config_file(&default_robot_config()).expect("robot config");
    let table = VariableTable::new(&model, &ControllerConfig::for_robot(&model)).expect("table");
    let (state, reference) = standing(&model);

    let mut direct =
        Controller::new(model.clone(), ControllerConfig::default()).expect("controller");
    for _ in 0..WARM_UP_TICKS {
        direct.step(&state, &reference, DT).expect("warm-up");
    }
    let mut group = c.benchmark_group("one_tick");
    group.bench_function("direct Controller::step", |b| {
        b.iter(|| {
            black_box(
                direct
                    .step(black_box(&state), black_box(&reference), DT)
                    .expect("step"),
            )
        })
    });

    let exe = std::env::current_exe().expect("bench executable");
    let library = shared_library_next_to(&exe).expect("cdylib next to the bench executable");
    let fmu = Path::new(env!("CARGO_TARGET_TMPDIR")).join("QuadController-bench.fmu");
    write_fmu(&BundleInputs::linux64(library), &fmu).expect("bundle");
    let import: Fmi2Import = fmi::import::from_path(&fmu).expect("import");
    let mut instance: InstanceCS = import
        .instantiate_cs("bench", false, false)
        .expect("instantiate");
    instance.setup_experiment(None, 0.0, None).expect("setup");
    instance.enter_initialization_mode().expect("enter");
    instance.exit_initialization_mode().expect("exit");
    let (vrs, values) = real_inputs(&table, &state, &reference);
    instance.set_real(&vrs, &values).expect("set");
    let mut time = 0.0;
    for _ in 0..WARM_UP_TICKS {
        instance.do_step(time, DT, true).expect("warm-up");
        time += DT;
    }
    let torque_vrs: Vec<u32> = table
        .rows()
        .iter()
        .filter(|v| v.causality == Causality::Output && v.scalar_type() == ScalarType::Real)
        .take(NUM_JOINTS)
        .map(|v| v.value_reference)
        .collect();
    let mut torques = [0.0; NUM_JOINTS];
    group.bench_function("fmi crate fmi2DoStep", |b| {
        b.iter(|| {
            instance.do_step(time, DT, true).expect("step");
            time += DT;
        })
    });
    group.bench_function(
        "fmi crate set 47 inputs + fmi2DoStep + get 12 torques",
        |b| {
            b.iter(|| {
                instance.set_real(&vrs, black_box(&values)).expect("set");
                instance.do_step(time, DT, true).expect("step");
                time += DT;
                instance.get_real(&torque_vrs, &mut torques).expect("get");
                black_box(&torques);
            })
        },
    );
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
