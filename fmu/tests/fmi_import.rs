//! Loads the bundled FMU with the `fmi` crate (an independent FMI 2.0 importer), steps it and
//! compares with a direct `Controller::step`; checks the exported symbols and misuse handling.

mod support;

use fmi::fmi2::import::Fmi2Import;
use fmi::fmi2::instance::{CoSimulation, Common, InstanceCS};
use fmi::traits::{FmiImport, FmiStatus};
use quad_controller::{Command, Reference, RobotState, NUM_JOINTS};
use support::{
    direct_controller, errors_of, fmu_path, install_logger, log_mark, logged_since, shared_library,
    stand_reference, standing_state, vr,
};

fn set_inputs(instance: &mut InstanceCS, state: &RobotState, reference: &Reference) {
    let mut names = Vec::new();
    let mut values = Vec::new();
    let mut push = |name: String, value: f64| {
        names.push(vr(&name));
        values.push(value);
    };
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        push(format!("base.pos.{axis}"), state.base_position[i]);
        push(format!("base.vel.{axis}"), state.base_linear_velocity[i]);
        push(format!("base.omega.{axis}"), state.base_angular_velocity[i]);
    }
    for (i, c) in ["w", "x", "y", "z"].iter().enumerate() {
        push(format!("base.quat.{c}"), state.base_orientation[i]);
    }
    for i in 0..NUM_JOINTS {
        push(format!("joint.q[{}]", i + 1), state.joint_positions[i]);
        push(format!("joint.dq[{}]", i + 1), state.joint_velocities[i]);
    }
    push("ref.x".into(), reference.x);
    push("ref.y".into(), reference.y);
    push("ref.z".into(), reference.terrain.height);
    push("ref.yaw".into(), reference.yaw);
    push("ref.vx".into(), reference.vx);
    push("ref.vy".into(), reference.vy);
    push("ref.yawRate".into(), reference.yaw_rate);
    push("ref.bodyHeight".into(), reference.body_height);
    push("terrain.dzdx".into(), reference.terrain.slope_x);
    push("terrain.dzdy".into(), reference.terrain.slope_y);
    instance
        .set_real(&names, &values)
        .expect("fmi2SetReal of the inputs");
    instance
        .set_integer(&[vr("cmd.mode")], &[reference.mode.as_code()])
        .expect("fmi2SetInteger cmd.mode");
}

fn torques(instance: &mut InstanceCS) -> [f64; NUM_JOINTS] {
    let vrs: Vec<u32> = (1..=NUM_JOINTS)
        .map(|i| vr(&format!("joint.tau[{i}]")))
        .collect();
    let mut out = [0.0; NUM_JOINTS];
    instance
        .get_real(&vrs, &mut out)
        .expect("fmi2GetReal torques");
    out
}

fn forces(instance: &mut InstanceCS) -> Vec<f64> {
    let vrs: Vec<u32> = (1..=4)
        .flat_map(|leg| ["x", "y", "z"].map(|a| vr(&format!("force[{leg}].{a}"))))
        .collect();
    let mut out = vec![0.0; vrs.len()];
    instance
        .get_real(&vrs, &mut out)
        .expect("fmi2GetReal forces");
    out
}

fn fsm(instance: &mut InstanceCS) -> i32 {
    let mut out = [0];
    instance
        .get_integer(&[vr("fsm.state")], &mut out)
        .expect("fmi2GetInteger fsm.state");
    out[0]
}

fn initialised(import: &Fmi2Import, name: &str) -> InstanceCS {
    let mut instance = import
        .instantiate_cs(name, false, true)
        .expect("fmi2Instantiate");
    instance.setup_experiment(None, 0.0, None).expect("setup");
    instance
        .enter_initialization_mode()
        .expect("enter initialisation");
    instance
        .exit_initialization_mode()
        .expect("exit initialisation");
    instance
}

fn assert_same_command(fmu_torques: &[f64; NUM_JOINTS], fmu_forces: &[f64], direct: &Command) {
    for (i, (fmu, direct)) in fmu_torques.iter().zip(&direct.joint_torques).enumerate() {
        assert!(
            (fmu - direct).abs() <= 1e-12,
            "torque {i}: FMU {fmu} vs direct {direct}"
        );
    }
    let direct_forces = direct.desired_forces.iter().flatten();
    for (k, (fmu, direct)) in fmu_forces.iter().zip(direct_forces).enumerate() {
        assert!(
            (fmu - direct).abs() <= 1e-12,
            "force {k}: FMU {fmu} vs direct {direct}"
        );
    }
    assert_eq!(fmu_forces.len(), 12);
}

#[test]
fn shared_library_exports_the_34_fmi2_functions() {
    let output = std::process::Command::new("nm")
        .args(["-D", "--defined-only"])
        .arg(shared_library())
        .output()
        .expect("running nm (binutils)");
    assert!(output.status.success());
    let text = String::from_utf8_lossy(&output.stdout);
    let mut exported: Vec<&str> = text
        .lines()
        .filter_map(
            |line| match line.split_whitespace().collect::<Vec<_>>()[..] {
                [_address, "T", name] if name.starts_with("fmi2") => Some(name),
                _ => None,
            },
        )
        .collect();
    exported.sort_unstable();
    let mut expected = vec![
        "fmi2GetTypesPlatform",
        "fmi2GetVersion",
        "fmi2SetDebugLogging",
        "fmi2Instantiate",
        "fmi2FreeInstance",
        "fmi2SetupExperiment",
        "fmi2EnterInitializationMode",
        "fmi2ExitInitializationMode",
        "fmi2Terminate",
        "fmi2Reset",
        "fmi2GetReal",
        "fmi2GetInteger",
        "fmi2GetBoolean",
        "fmi2GetString",
        "fmi2SetReal",
        "fmi2SetInteger",
        "fmi2SetBoolean",
        "fmi2SetString",
        "fmi2GetFMUstate",
        "fmi2SetFMUstate",
        "fmi2FreeFMUstate",
        "fmi2SerializedFMUstateSize",
        "fmi2SerializeFMUstate",
        "fmi2DeSerializeFMUstate",
        "fmi2GetDirectionalDerivative",
        "fmi2SetRealInputDerivatives",
        "fmi2GetRealOutputDerivatives",
        "fmi2DoStep",
        "fmi2CancelStep",
        "fmi2GetStatus",
        "fmi2GetRealStatus",
        "fmi2GetIntegerStatus",
        "fmi2GetBooleanStatus",
        "fmi2GetStringStatus",
    ];
    expected.sort_unstable();
    assert_eq!(expected.len(), 34);
    assert_eq!(exported, expected);
}

#[test]
fn fmi_crate_steps_the_fmu_like_a_direct_controller_call() {
    install_logger();
    let import: Fmi2Import = fmi::import::from_path(fmu_path()).expect("importing the FMU");
    assert_eq!(import.model_description().model_name, "QuadController");
    let mut instance = initialised(&import, "standing");
    let state = standing_state(0.3, 0.2);
    let reference = stand_reference(&state, 0.2);
    set_inputs(&mut instance, &state, &reference);

    // 1.3 s in communication steps of 10 ms (stand-up takes 1 s), then 0.2 s in steps of 1.5 ms
    // (not a multiple of the 1 ms tick): 1500 ticks in all.
    let mut time = 0.0;
    for _ in 0..130 {
        instance.do_step(time, 0.01, true).expect("fmi2DoStep");
        time += 0.01;
    }
    let mut direct = direct_controller();
    let mut command = None;
    for _ in 0..1300 {
        command = Some(direct.step(&state, &reference, 0.001).expect("direct step"));
    }
    assert_same_command(
        &torques(&mut instance),
        &forces(&mut instance),
        command.as_ref().expect("1300 ticks ran"),
    );

    for _ in 0..(0.2f64 / 0.0015).round() as usize {
        instance
            .do_step(time, 0.0015, true)
            .expect("fmi2DoStep 1.5 ms");
        time += 0.0015;
    }
    let ticks_expected = (time / 0.001).round() as usize - 1300;
    for _ in 0..ticks_expected {
        command = Some(direct.step(&state, &reference, 0.001).expect("direct step"));
    }
    let command = command.expect("ticks ran");
    assert_eq!(fsm(&mut instance), 2, "standing after the stand-up");
    assert_same_command(&torques(&mut instance), &forces(&mut instance), &command);
    let weight: f64 = forces(&mut instance).chunks(3).map(|f| f[2]).sum();
    let mg = support::model().total_mass() * quad_controller::GRAVITY;
    assert!(
        (weight - mg).abs() < 0.05 * mg,
        "desired forces carry {weight} N of {mg} N"
    );
    instance.terminate().expect("fmi2Terminate");
}

#[test]
fn two_instances_in_one_process_are_independent() {
    install_logger();
    let import: Fmi2Import = fmi::import::from_path(fmu_path()).expect("importing the FMU");
    let mut standing = initialised(&import, "a");
    let mut passive = initialised(&import, "b");
    let state = standing_state(0.0, 0.0);
    let reference = stand_reference(&state, 0.0);
    set_inputs(&mut standing, &state, &reference);
    let mut other_state = standing_state(5.0, 1.0);
    other_state.joint_velocities = [0.7; NUM_JOINTS];
    let passive_reference = Reference {
        mode: quad_controller::ModeRequest::Passive,
        ..stand_reference(&other_state, 1.0)
    };
    set_inputs(&mut passive, &other_state, &passive_reference);
    let mut direct = direct_controller();
    let mut command = None;
    for k in 0..60 {
        let t = k as f64 * 0.02;
        standing.do_step(t, 0.02, true).expect("step a");
        passive.do_step(t, 0.02, true).expect("step b");
        for _ in 0..20 {
            command = Some(direct.step(&state, &reference, 0.001).expect("direct"));
        }
    }
    assert_same_command(
        &torques(&mut standing),
        &forces(&mut standing),
        &command.expect("ran"),
    );
    assert_eq!(torques(&mut passive), [0.0; NUM_JOINTS]);
    assert_eq!(fsm(&mut passive), 0);
    assert_eq!(fsm(&mut standing), direct.fsm_state().as_code());
}

#[test]
fn misuse_through_the_fmi_crate_is_rejected_with_a_logged_reason() {
    install_logger();
    let import: Fmi2Import = fmi::import::from_path(fmu_path()).expect("importing the FMU");
    let mut instance = import
        .instantiate_cs("misuse", false, true)
        .expect("fmi2Instantiate");
    let mark = log_mark();
    assert!(
        instance.do_step(0.0, 0.01, true).is_err(),
        "doStep before initialisation"
    );
    let mut one = [0.0];
    assert!(
        instance.get_real(&[vr("joint.tau[1]")], &mut one).is_err(),
        "get before initialisation"
    );
    instance.setup_experiment(None, 0.0, None).expect("setup");
    instance.enter_initialization_mode().expect("enter");
    instance.exit_initialization_mode().expect("exit");
    assert!(
        instance.get_real(&[100_000], &mut one).is_err(),
        "unknown vr"
    );
    assert!(
        instance.get_real(&[vr("cmd.mode")], &mut one).is_err(),
        "Integer vr through GetReal"
    );
    assert!(
        instance.set_real(&[vr("joint.tau[3]")], &[1.0]).is_err(),
        "set an output"
    );
    assert!(
        instance.set_real(&[vr("base.vel.y")], &[f64::NAN]).is_err(),
        "NaN"
    );
    assert!(
        instance
            .set_real(&[vr("joint.dq[2]")], &[f64::NEG_INFINITY])
            .is_err(),
        "-inf"
    );
    assert!(
        instance.set_real(&[vr("control.dt")], &[0.002]).is_err(),
        "fixed parameter after init"
    );
    assert!(instance.do_step(0.0, 0.0, true).is_err(), "h = 0");
    assert!(instance.do_step(0.0, -0.01, true).is_err(), "h < 0");
    assert!(instance.do_step(0.5, 0.01, true).is_err(), "wrong time");
    let messages = logged_since(mark, "misuse");
    let expected = [
        "fmi2DoStep is not allowed in state instantiated",
        "fmi2GetReal is not allowed in state instantiated",
        "valueReference 100000 does not refer to a Real variable",
        "does not refer to a Real variable",
        "cannot set joint.tau[3]: it is an output",
        "invalid value for base.vel.y: NaN is not a finite number",
        "invalid value for joint.dq[2]: -inf is not a finite number",
        "cannot set control.dt: it is a fixed parameter",
        "communicationStepSize 0 must be finite and > 0",
        "communicationStepSize -0.01 must be finite and > 0",
        "currentCommunicationPoint 0.5 does not match the FMU time 0",
    ];
    assert_eq!(messages.len(), expected.len(), "{messages:#?}");
    for (message, fragment) in messages.iter().zip(expected) {
        assert!(
            message.contains(fragment),
            "{message:?} should contain {fragment:?}"
        );
    }
    // The instance is still usable, and the stored inputs are unchanged by the rejected calls.
    instance
        .do_step(0.0, 0.01, true)
        .expect("a correct step after the misuse");
    let mut dq = [1.0];
    instance
        .get_real(&[vr("joint.dq[2]")], &mut dq)
        .expect("get");
    assert_eq!(dq[0], 0.0);
}

/// Torques and forces after each of `steps` doSteps of 20 ms from `t`, the robot walking in place
/// with a reference that moves, as bits.
fn walk(instance: &mut InstanceCS, t: f64, steps: usize) -> Vec<Vec<u64>> {
    (0..steps)
        .map(|k| {
            let t = t + k as f64 * 0.02;
            let state = standing_state(0.01 * t, 0.0);
            let reference = Reference {
                vx: 0.2,
                mode: quad_controller::ModeRequest::Locomotion,
                ..stand_reference(&state, 0.0)
            };
            set_inputs(instance, &state, &reference);
            instance.do_step(t, 0.02, true).expect("doStep");
            let mut bits: Vec<u64> = torques(instance).iter().map(|v| v.to_bits()).collect();
            bits.extend(forces(instance).iter().map(|v| v.to_bits()));
            bits.push(fsm(instance) as u64);
            bits
        })
        .collect()
}

#[test]
fn fmu_state_get_set_and_serialize_through_the_c_api() {
    install_logger();
    let import: Fmi2Import = fmi::import::from_path(fmu_path()).expect("importing the FMU");
    let mut first = initialised(&import, "state-a");
    walk(&mut first, 0.0, 100);
    let saved = first.get_fmu_state().expect("fmi2GetFMUstate at t = 2 s");
    let run_1 = walk(&mut first, 2.0, 50);
    first.set_fmu_state(&saved).ok().expect("fmi2SetFMUstate");
    let run_2 = walk(&mut first, 2.0, 50);
    assert!(run_1 == run_2, "after fmi2SetFMUstate the outputs differ");

    let blob = first.serialize_fmu_state(&saved).expect("serialize");
    let mut second = import
        .instantiate_cs("state-b", false, true)
        .expect("fmi2Instantiate");
    let restored = second.deserialize_fmu_state(&blob).expect("deserialize");
    second
        .set_fmu_state(&restored)
        .ok()
        .expect("set in a second instance");
    let run_3 = walk(&mut second, 2.0, 50);
    assert!(
        run_1 == run_3,
        "a deserialized state in another instance differs"
    );

    let mut truncated = blob.clone();
    truncated.truncate(blob.len() / 2);
    assert!(second.deserialize_fmu_state(&truncated).is_err());
    let errors = errors_of("state-b");
    assert!(
        errors
            .iter()
            .any(|e| e.contains("fmi2DeSerializeFMUstate") && e.contains("truncated")),
        "{errors:?}"
    );
}
