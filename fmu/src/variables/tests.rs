use super::*;
use quad_controller::config::ConfigField;
use quad_controller::{ControllerConfig, HEIGHT_MAP_CELLS};
use std::collections::HashSet;

#[test]
fn names_and_references_are_unique_and_dense() {
    let rows = table();
    let names: HashSet<&str> = rows.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names.len(), rows.len());
    for (i, v) in rows.iter().enumerate() {
        assert_eq!(v.value_reference as usize, i);
    }
}

#[test]
fn table_has_the_documented_signals() {
    let count = |c: Causality| table().iter().filter(|v| v.causality == c).count();
    // 3 pos + 4 quat + 3 vel + 3 omega + 12 q + 12 dq + 10 reference/terrain + cmd.mode
    // + height map (x0, y0, spacing, 121 heights) + 3 gyro + 3 acc + 4 contact + 3 fix + valid
    assert_eq!(count(Causality::Input), 48 + 3 + HEIGHT_MAP_CELLS + 14);
    // 12 tau + 4 stance + fsm + 12 force + solve time + solved + est pos/vel/rpy
    // + est posVar/attVar + est.status
    assert_eq!(count(Causality::Output), 31 + 6 + 10);
    for name in [
        "base.quat.w",
        "joint.q[12]",
        "joint.dq[1]",
        "ref.yawRate",
        "cmd.mode",
        "joint.tau[12]",
        "contact[4]",
        "stance[4]",
        "imu.gyro[3]",
        "imu.acc[1]",
        "fix.pos[3]",
        "fix.valid",
        "est.pos[1]",
        "est.vel[3]",
        "est.rpy[3]",
        "est.posVar[2]",
        "est.attVar[3]",
        "est.status",
        "estimator",
        "est.fixNoise",
        "force[4].z",
        "mpc.solved",
        "gait.period",
        "mpc.q[13]",
        "swing.kd[3]",
    ] {
        assert!(by_name(name).is_some(), "{name}");
    }
    assert_eq!(
        by_name("cmd.mode").unwrap().scalar_type(),
        ScalarType::Integer
    );
    assert_eq!(
        by_name("stance[1]").unwrap().scalar_type(),
        ScalarType::Boolean
    );
    let contact = by_name("contact[1]").unwrap();
    assert_eq!(contact.scalar_type(), ScalarType::Integer);
    assert_eq!(contact.causality, Causality::Input);
    assert_eq!((contact.min, contact.max), (Some(-1.0), Some(1.0)));
    assert_eq!(contact.start, Value::Integer(-1));
    assert_eq!(by_name("imu.acc[3]").unwrap().start, Value::Real(9.81));
    assert_eq!(by_name("fix.valid").unwrap().start, Value::Boolean(false));
    let estimator = by_name("estimator").unwrap();
    assert_eq!(estimator.declared_type, Some(ESTIMATOR_KIND_TYPE));
    assert_eq!(estimator.start, Value::Integer(0));
    let status = &by_name("est.status").unwrap().description;
    for (flag, name, description) in quad_controller::StatusFlag::ALL {
        let bit = format!("{} {name}: {description}", flag.bit());
        assert!(status.contains(&bit), "{status} lacks {bit}");
    }
}

#[test]
fn every_binding_round_trips_through_its_storage() {
    let (state, reference) = initial_inputs();
    let mut inputs = Inputs {
        state,
        reference,
        ..Inputs::default()
    };
    let mut config = ControllerConfig::default();
    for (k, v) in table().iter().enumerate() {
        let probe = match v.start {
            Value::Real(_) => Value::Real(0.5 + k as f64),
            Value::Integer(_) => Value::Integer(1),
            Value::Boolean(b) => Value::Boolean(!b),
        };
        match v.binding {
            Binding::Parameter { field, element } => {
                assert_eq!(
                    read_parameter(field, element, &config),
                    v.start,
                    "{}",
                    v.name
                );
                write_parameter(field, element, &mut config, probe);
                assert_eq!(read_parameter(field, element, &config), probe, "{}", v.name);
            }
            b if v.causality == Causality::Input => {
                assert_eq!(read_input(b, &inputs), Some(v.start), "{}", v.name);
                write_input(b, probe, &mut inputs);
                assert_eq!(read_input(b, &inputs), Some(probe), "{}", v.name);
            }
            b => assert_eq!(
                read_output(b, &initial_command()),
                Some(v.start),
                "{}",
                v.name
            ),
        }
    }
}

fn next_up(x: f64) -> f64 {
    if x == 0.0 {
        f64::from_bits(1)
    } else if x > 0.0 {
        f64::from_bits(x.to_bits() + 1)
    } else {
        f64::from_bits(x.to_bits() - 1)
    }
}

fn next_down(x: f64) -> f64 {
    -next_up(-x)
}

/// Every parameter with its config field and element.
fn parameters() -> impl Iterator<Item = (&'static Variable, &'static ConfigField, usize)> {
    table().iter().filter_map(|v| match v.binding {
        Binding::Parameter { field, element } => {
            Some((v, &ControllerConfig::FIELDS[field], element))
        }
        _ => None,
    })
}

#[test]
fn every_parameter_has_a_range_holding_its_start_value() {
    assert_eq!(parameters().count(), 59);
    for (v, field, _) in parameters() {
        let (min, max) = field.range();
        assert_eq!((v.min, v.max), (Some(min), Some(max)), "{}", v.name);
        assert!(
            min.is_finite() && max.is_finite() && min < max,
            "{}",
            v.name
        );
        check_value(v, v.start).unwrap_or_else(|e| panic!("{e}"));
    }
    check_parameters(our_table(), &ControllerConfig::default()).unwrap();
}

#[test]
fn values_just_outside_a_range_and_non_finite_values_are_refused() {
    for (v, field, _) in parameters() {
        let (min, max) = field.range();
        let (below, above) = match v.start {
            Value::Real(_) => (Value::Real(next_down(min)), Value::Real(next_up(max))),
            _ => (
                Value::Integer(min as i32 - 1),
                Value::Integer(max as i32 + 1),
            ),
        };
        for bad in [below, above] {
            let err = check_value(v, bad).unwrap_err().to_string();
            assert!(
                err.starts_with(&format!("invalid value for {}", v.name)),
                "{err}"
            );
        }
        if let Value::Real(_) = v.start {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300] {
                assert!(
                    check_value(v, Value::Real(bad)).is_err(),
                    "{} {bad}",
                    v.name
                );
            }
        }
        for good in [min, max] {
            let value = match v.start {
                Value::Real(_) => Value::Real(good),
                _ => Value::Integer(good as i32),
            };
            check_value(v, value).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}

/// The ranges are the controller's operating envelope: every end point, with the other
/// parameters at their defaults, builds a controller, except where a parameter is also
/// checked against another one in fmi2ExitInitializationMode (`f_min < f_max`, a standing
/// height the legs reach); those work with a matching partner.
#[test]
fn every_range_end_point_builds_a_controller() {
    use quad_controller::Controller;
    let model = robot_model().clone();
    for (v, field, element) in parameters() {
        let (min, max) = field.range();
        let index = ControllerConfig::FIELDS
            .iter()
            .position(|f| f.name == field.name)
            .unwrap();
        for end in [min, max] {
            let mut config = ControllerConfig::default();
            let value = match v.start {
                Value::Real(_) => Value::Real(end),
                _ => Value::Integer(end as i32),
            };
            write_parameter(index, element, &mut config, value);
            assert_eq!(read_parameter(index, element, &config), value);
            config.check_ranges().unwrap();
            match (field.name, end == max) {
                ("f_min", true) => config.f_max = end + 1.0,
                ("f_max", false) => config.f_min = 0.0,
                _ => {}
            }
            let result = Controller::new(model.clone(), config.clone());
            if field.name == "body_height" && end == max {
                assert!(result.is_err(), "legs of 0.4 m cannot stand 0.5 m high");
            } else {
                result.unwrap_or_else(|e| panic!("{} = {end}: {e}", v.name));
            }
        }
    }
}

#[test]
fn values_are_checked() {
    let x = by_name("base.pos.x").unwrap();
    assert!(check_value(x, Value::Real(f64::NAN))
        .unwrap_err()
        .to_string()
        .contains("base.pos.x"));
    assert!(check_value(x, Value::Real(f64::INFINITY)).is_err());
    assert!(check_value(x, Value::Real(-3.0)).is_ok());
    let mode = by_name("cmd.mode").unwrap();
    assert!(check_value(mode, Value::Integer(3)).is_err());
    assert!(check_value(mode, Value::Integer(-1)).is_err());
    assert!(check_value(mode, Value::Integer(2)).is_ok());
    let dt = by_name("control.dt").unwrap();
    assert!(check_value(dt, Value::Real(0.0)).is_err());
}

/// The start values are the robot standing still on flat ground in its nominal stance: joint
/// angles of the controller's standing pose, inside the URDF ranges, base at the nominal height.
#[test]
fn start_values_are_the_nominal_stance_inside_the_joint_ranges() {
    use quad_controller::{Controller, ModeRequest};
    let config = ControllerConfig::default();
    let stand = Controller::new(robot_model().clone(), config.clone())
        .unwrap()
        .stand_joint_positions();
    let model = robot_model();
    let (lower, upper) = (model.lower_limits(), model.upper_limits());
    for (i, q) in stand.iter().enumerate() {
        let v = by_name(&format!("joint.q[{}]", i + 1)).unwrap();
        assert_eq!(v.start, Value::Real(*q), "{}", v.name);
        assert_eq!(
            (v.min, v.max),
            (Some(lower[i]), Some(upper[i])),
            "{}",
            v.name
        );
        assert!(lower[i] < *q && *q < upper[i], "{} = {q}", v.name);
        let dq = by_name(&format!("joint.dq[{}]", i + 1)).unwrap();
        assert_eq!(dq.start, Value::Real(0.0));
    }
    let start = |name: &str| by_name(name).unwrap().start;
    assert_eq!(start("base.pos.z"), Value::Real(config.body_height));
    assert_eq!(start("base.pos.x"), Value::Real(0.0));
    assert_eq!(start("base.quat.w"), Value::Real(1.0));
    for name in [
        "base.quat.x",
        "base.quat.y",
        "base.quat.z",
        "ref.z",
        "ref.vx",
    ] {
        assert_eq!(start(name), Value::Real(0.0), "{name}");
    }
    assert_eq!(
        start("cmd.mode"),
        Value::Integer(ModeRequest::Stand.as_code())
    );
    // The feet of the start pose touch the flat ground (z = 0) below the hips.
    let (state, _) = initial_inputs();
    for leg in quad_controller::Leg::ALL {
        let l = leg.index();
        let q = [stand[3 * l], stand[3 * l + 1], stand[3 * l + 2]];
        let foot = model.foot_position_body(leg, q);
        let bottom = state.base_position[2] + foot[2] - model.foot_radius();
        assert!(bottom.abs() < 1e-9, "{leg:?}: foot bottom at z = {bottom}");
    }
}

/// Measured joint values outside the URDF range are accepted (the controller's fault check
/// handles them); the declared range is informative for them.
#[test]
fn joint_measurements_outside_their_range_are_accepted() {
    let knee = by_name("joint.q[3]").unwrap();
    assert!(!knee.range_is_enforced());
    check_value(knee, Value::Real(-0.1)).unwrap();
    assert!(check_value(knee, Value::Real(f64::NAN)).is_err());
    assert!(by_name("cmd.mode").unwrap().range_is_enforced());
}

#[test]
fn the_guid_is_the_interface_of_the_table() {
    let ours = our_table();
    let guid = ours.guid();
    assert_eq!(guid.len(), crate::saved_state::GUID_LEN);
    assert!(guid.starts_with('{') && guid.ends_with('}'), "{guid}");
    assert_eq!(guid, ours.clone().guid(), "deterministic");
    // Another robot's numbers (start values, ranges, the robot's name) keep the interface.
    let mut other_robot = ours.clone();
    other_robot.robot_name = "another robot".to_owned();
    for v in &mut other_robot.rows {
        v.min = v.min.map(|m| m - 1.0);
        v.start = match v.start {
            Value::Real(x) => Value::Real(x + 0.25),
            other => other,
        };
    }
    assert_eq!(other_robot.guid(), guid);
    // What an importer relies on changes it.
    type Change = (&'static str, fn(&mut Variable));
    let changes: [Change; 4] = [
        ("name", |v| v.name.push('x')),
        ("value reference", |v| v.value_reference += 1000),
        ("causality", |v| {
            v.causality = if v.causality == Causality::Input {
                Causality::Output
            } else {
                Causality::Input
            }
        }),
        ("unit", |v| {
            v.unit = if v.unit.is_some() {
                None
            } else {
                Some(Unit::Metre)
            }
        }),
    ];
    for (what, change) in changes {
        let mut changed = ours.clone();
        change(&mut changed.rows[3]);
        assert_ne!(changed.guid(), guid, "{what}");
    }
}
