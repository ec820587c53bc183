//! Cost of one control tick driven three ways: a direct `Controller::step`, and `fmi2DoStep` of
//! one tick through the FMU's exported C functions (the calls an importer makes), with and
//! without writing the 47 Real state and reference inputs and reading the 12 torques around it
//! (what a co-simulation master does every step).
//!
//! The instance loads its robot from a resources folder written into the cargo target's tmp folder.
//! Run: `cargo bench -p quad-controller-fmu --bench do_step -- --warm-up-time 1 --measurement-time 3`

use std::ffi::CString;
use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use quad_controller::{
    Controller, ControllerConfig, PackagePath, Reference, RobotModel, RobotState, NUM_JOINTS,
};
use quad_controller_fmu::bundle::{default_robot_config, write_resources};
use quad_controller_fmu::exports::lifecycle::{
    fmi2EnterInitializationMode, fmi2ExitInitializationMode, fmi2FreeInstance, fmi2Instantiate,
    fmi2SetupExperiment,
};
use quad_controller_fmu::exports::stepping::fmi2DoStep;
use quad_controller_fmu::exports::values::{fmi2GetReal, fmi2SetReal};
use quad_controller_fmu::ffi::{Fmi2Component, Fmi2Status, FMI2_FALSE, FMI2_TRUE};
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

/// An initialised instance of our robot's FMU, created through `fmi2Instantiate`.
fn instantiate(resources: &Path, guid: &str) -> Fmi2Component {
    write_resources(&default_robot_config(), &PackagePath::default(), resources)
        .expect("resources");
    let uri = CString::new(format!("file://{}", resources.display())).expect("uri");
    let guid = CString::new(guid).expect("guid");
    // SAFETY: valid C strings; NULL callbacks are allowed by the FMU.
    let c = unsafe {
        fmi2Instantiate(
            c"bench".as_ptr(),
            1,
            guid.as_ptr(),
            uri.as_ptr(),
            std::ptr::null(),
            FMI2_FALSE,
            FMI2_FALSE,
        )
    };
    assert!(!c.is_null(), "fmi2Instantiate");
    let ok = |status: Fmi2Status, what: &str| assert_eq!(status, Fmi2Status::Ok, "{what}");
    ok(
        fmi2SetupExperiment(c, FMI2_FALSE, 0.0, 0.0, FMI2_FALSE, 0.0),
        "setup",
    );
    ok(fmi2EnterInitializationMode(c), "enter");
    ok(fmi2ExitInitializationMode(c), "exit");
    c
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

    let resources = Path::new(env!("CARGO_TARGET_TMPDIR")).join("do_step_bench_resources");
    let instance = instantiate(&resources, &table.guid());
    let (vrs, values) = real_inputs(&table, &state, &reference);
    // SAFETY (every call below): `instance` is live; the slices outlive the calls and their
    // lengths are passed with them.
    let set_inputs = |values: &[f64]| {
        let status = unsafe { fmi2SetReal(instance, vrs.as_ptr(), vrs.len(), values.as_ptr()) };
        assert_eq!(status, Fmi2Status::Ok, "fmi2SetReal");
    };
    set_inputs(&values);
    let mut time = 0.0;
    let step = |time: &mut f64| {
        assert_eq!(
            fmi2DoStep(instance, *time, DT, FMI2_TRUE),
            Fmi2Status::Ok,
            "fmi2DoStep"
        );
        *time += DT;
    };
    for _ in 0..WARM_UP_TICKS {
        step(&mut time);
    }
    let torque_vrs: Vec<u32> = table
        .rows()
        .iter()
        .filter(|v| v.causality == Causality::Output && v.scalar_type() == ScalarType::Real)
        .take(NUM_JOINTS)
        .map(|v| v.value_reference)
        .collect();
    let mut torques = [0.0; NUM_JOINTS];
    group.bench_function("C API fmi2DoStep", |b| b.iter(|| step(&mut time)));
    group.bench_function("C API set 47 inputs + fmi2DoStep + get 12 torques", |b| {
        b.iter(|| {
            set_inputs(black_box(&values));
            step(&mut time);
            let status = unsafe {
                fmi2GetReal(
                    instance,
                    torque_vrs.as_ptr(),
                    torque_vrs.len(),
                    torques.as_mut_ptr(),
                )
            };
            assert_eq!(status, Fmi2Status::Ok, "fmi2GetReal");
            black_box(&torques);
        })
    });
    group.finish();
    // SAFETY: `instance` came from fmi2Instantiate and is freed once.
    unsafe { fmi2FreeInstance(instance) };
}

criterion_group!(benches, bench);
criterion_main!(benches);
