//! Robot descriptions through a robot config: a small generic 12-DOF URDF and config, and the
//! clear errors of broken descriptions (each names the item and the file, never a panic).
use std::path::{Path, PathBuf};

use quad_controller::{Leg, ModelError, PackagePath, RobotModel};

const LEGS: [(&str, f64, f64); 4] = [
    ("fr", 0.2, -0.1),
    ("fl", 0.2, 0.1),
    ("rr", -0.2, -0.1),
    ("rl", -0.2, 0.1),
];

const LINK_INERTIAL: &str = r#"<inertial><mass value="0.5"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>"#;

/// A generic 12-DOF quadruped: links `body`, `<leg>_l1..l3`, foot link `<leg>_toe` with a
/// 2 cm sphere; joints `<leg>_j1` (x), `<leg>_j2` (y), `<leg>_j3` (y), fixed `<leg>_toe_fix`.
fn tiny_urdf() -> String {
    let mut xml = String::from(
        r#"<robot name="tiny"><link name="body"><inertial><mass value="4.0"/><inertia ixx="0.02" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.05"/></inertial></link>"#,
    );
    for (leg, x, y) in LEGS {
        let side = y.signum() * 0.05;
        xml.push_str(&format!(
            r#"
<joint name="{leg}_j1" type="revolute"><parent link="body"/><child link="{leg}_l1"/><origin xyz="{x} {y} 0" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="20" velocity="20"/></joint>
<link name="{leg}_l1">{LINK_INERTIAL}</link>
<joint name="{leg}_j2" type="revolute"><parent link="{leg}_l1"/><child link="{leg}_l2"/><origin xyz="0 {side} 0" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="3" effort="20" velocity="20"/></joint>
<link name="{leg}_l2">{LINK_INERTIAL}</link>
<joint name="{leg}_j3" type="revolute"><parent link="{leg}_l2"/><child link="{leg}_l3"/><origin xyz="0 0 -0.2" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-2.7" upper="2.7" effort="30" velocity="20"/></joint>
<link name="{leg}_l3">{LINK_INERTIAL}</link>
<joint name="{leg}_toe_fix" type="fixed"><parent link="{leg}_l3"/><child link="{leg}_toe"/><origin xyz="0 0 -0.2" rpy="0 0 0"/></joint>
<link name="{leg}_toe"><inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial><collision><geometry><sphere radius="0.02"/></geometry></collision></link>"#
        ));
    }
    xml.push_str("\n</robot>\n");
    xml
}

fn tiny_config() -> String {
    let mut toml = String::from("urdf = \"tiny.urdf\"\nbase_link = \"body\"\nstand_height = 0.3\n");
    for (ours, (leg, _, _)) in ["FR", "FL", "RR", "RL"].iter().zip(LEGS) {
        let knee = if leg.starts_with('f') {
            "backward"
        } else {
            "forward"
        };
        toml.push_str(&format!(
            "\n[legs.{ours}]\njoints = [\"{leg}_j1\", \"{leg}_j2\", \"{leg}_j3\"]\nfoot_link = \"{leg}_toe\"\nknee_points = \"{knee}\"\n"
        ));
    }
    toml
}

/// The error of loading `config` + `urdf`, as text, with the innermost kind.
fn load_error(config: &str, urdf: &str) -> (String, ModelError) {
    match RobotModel::from_config_str(config, urdf) {
        Ok(_) => panic!("expected an error"),
        Err(e) => {
            let text = e.to_string();
            let kind = match e.innermost() {
                ModelError::Missing(s) => ModelError::Missing(s.clone()),
                ModelError::Structure(s) => ModelError::Structure(s.clone()),
                ModelError::InvalidValue(s) => ModelError::InvalidValue(s.clone()),
                ModelError::Parse(s) => ModelError::Parse(s.clone()),
                ModelError::Config { file, key, reason } => ModelError::Config {
                    file: file.clone(),
                    key: key.clone(),
                    reason: reason.clone(),
                },
                other => panic!("unexpected error kind {other:?}"),
            };
            (text, kind)
        }
    }
}

fn assert_urdf_error(config: &str, urdf: &str, needle: &str) -> ModelError {
    let (text, kind) = load_error(config, urdf);
    assert!(text.starts_with("URDF text: "), "file not named: {text}");
    assert!(text.contains(needle), "`{needle}` not in: {text}");
    kind
}

fn assert_config_error(config: &str, urdf: &str, needle: &str) {
    let (text, kind) = load_error(config, urdf);
    assert!(matches!(kind, ModelError::Config { .. }), "{text}");
    assert!(text.contains("robot config text"), "file not named: {text}");
    assert!(text.contains(needle), "`{needle}` not in: {text}");
}

#[test]
fn tiny_robot_loads_and_bends_its_knees_as_configured() {
    let model = RobotModel::from_config_str(&tiny_config(), &tiny_urdf()).expect("tiny robot");
    assert!((model.total_mass() - (4.0 + 4.0 * 1.55)).abs() < 1e-12);
    assert!((model.foot_radius() - 0.02).abs() < 1e-15);
    assert_eq!(model.stand_height(), 0.3);
    let q = model.stand_joint_positions(0.3).expect("stand");
    for leg in Leg::ALL {
        let knee = q[3 * leg.index() + 2];
        let front = matches!(leg, Leg::FR | Leg::FL);
        assert!(
            if front { knee < -0.1 } else { knee > 0.1 },
            "{leg:?} knee {knee}"
        );
    }
}

#[test]
fn flipped_axes_are_a_sign_convention_not_an_error() {
    // A joint turning about −y moves the same way for the negated angle: IK must follow.
    let urdf = tiny_urdf().replace(
        r#"<child link="fl_l3"/><origin xyz="0 0 -0.2" rpy="0 0 0"/><axis xyz="0 1 0"/>"#,
        r#"<child link="fl_l3"/><origin xyz="0 0 -0.2" rpy="0 0 0"/><axis xyz="0 -1 0"/>"#,
    );
    assert_ne!(urdf, tiny_urdf());
    let straight = RobotModel::from_config_str(&tiny_config(), &tiny_urdf()).expect("tiny");
    let flipped = RobotModel::from_config_str(&tiny_config(), &urdf).expect("flipped");
    let a = straight.stand_joint_positions(0.3).expect("stand");
    let b = flipped.stand_joint_positions(0.3).expect("stand");
    let fl_knee = 3 * Leg::FL.index() + 2;
    assert!(
        (a[fl_knee] + b[fl_knee]).abs() < 1e-9,
        "{} vs {}",
        a[fl_knee],
        b[fl_knee]
    );
    assert!(a[fl_knee].abs() > 0.1);
}

#[test]
fn missing_joint_and_link_are_named() {
    let config = tiny_config().replace("\"fl_j3\"", "\"fl_knee\"");
    let kind = assert_urdf_error(&config, &tiny_urdf(), "`fl_knee`");
    assert!(matches!(kind, ModelError::Missing(_)));
    let config = tiny_config().replace("\"rl_toe\"", "\"rl_paw\"");
    assert_urdf_error(&config, &tiny_urdf(), "link `rl_paw`");
    let config = tiny_config().replace("base_link = \"body\"", "base_link = \"trunk\"");
    assert_urdf_error(&config, &tiny_urdf(), "base link `trunk`");
    let config = tiny_config().replace("base_link = \"body\"", "base_link = \"fr_l1\"");
    assert_urdf_error(&config, &tiny_urdf(), "must be the root");
}

#[test]
fn ten_and_sixteen_dof_robots_are_refused() {
    // 10 DOF: one leg's knee is fixed.
    let urdf = tiny_urdf().replace(
        r#"<joint name="rr_j3" type="revolute">"#,
        r#"<joint name="rr_j3" type="fixed">"#,
    );
    assert_urdf_error(&tiny_config(), &urdf, "rr_j3");
    // 16 DOF: every leg gets an actuated ankle between the calf and the toe.
    let urdf = tiny_urdf().replace(
        r#"_toe_fix" type="fixed">"#,
        r#"_toe_fix" type="revolute">"#,
    );
    let text = load_error(&tiny_config(), &urdf).0;
    assert!(
        text.contains("exactly the actuated joints") && text.contains("4 movable joints"),
        "{text}"
    );
    // 13 DOF: a movable joint outside the legs (a tail).
    let urdf = tiny_urdf().replace(
        "</robot>",
        r#"<joint name="tail" type="revolute"><parent link="body"/><child link="tail_link"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint><link name="tail_link"/></robot>"#,
    );
    assert_urdf_error(&tiny_config(), &urdf, "joint `tail`");
}

#[test]
fn non_revolute_and_badly_oriented_joints_are_refused() {
    let urdf = tiny_urdf().replace(
        r#"<joint name="fl_j2" type="revolute">"#,
        r#"<joint name="fl_j2" type="prismatic">"#,
    );
    assert_urdf_error(&tiny_config(), &urdf, "`fl_j2` of leg FL must be revolute");
    let urdf = tiny_urdf().replacen(r#"<axis xyz="1 0 0"/>"#, r#"<axis xyz="0 0 1"/>"#, 1);
    assert_urdf_error(&tiny_config(), &urdf, "abduction joint `fr_j1` turns about");
    // A rotated origin that tilts the knee axis out of the sagittal layout: the error says where
    // the axis ends up, not that rotations are forbidden.
    let urdf = tiny_urdf().replacen(
        r#"<origin xyz="0 0 -0.2" rpy="0 0 0"/>"#,
        r#"<origin xyz="0 0 -0.2" rpy="0 0 0.3"/>"#,
        1,
    );
    assert_urdf_error(
        &tiny_config(),
        &urdf,
        "knee joint `fr_j3` turns about (-0.2955, 0.9553, 0.0000)",
    );
}

/// Orientation (roll, pitch, yaw) of each leg's joint origins j1, j2, j3, toe_fix for
/// [`rotated_tiny_urdf`]: quarter turns as HyQ and ANYmal C use, and arbitrary angles.
const ORIGIN_RPY: [[f64; 3]; 4] = [
    [0.0, std::f64::consts::FRAC_PI_2, std::f64::consts::PI],
    [std::f64::consts::FRAC_PI_2, 0.0, 0.0],
    [0.4, -0.7, 1.1],
    [
        std::f64::consts::FRAC_PI_2,
        0.0,
        -std::f64::consts::FRAC_PI_2,
    ],
];

/// Inertial of the three moving links: off-centre, anisotropic, so a frame error shows.
const LINK_COM: [f64; 3] = [0.01, 0.02, -0.05];
const LINK_INERTIA: [f64; 3] = [0.001, 0.002, 0.0025];

fn vector(v: &nalgebra::Vector3<f64>) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

fn rpy(rotation: &nalgebra::Rotation3<f64>) -> String {
    let (r, p, y) = rotation.euler_angles();
    format!("{r} {p} {y}")
}

/// The tiny robot with every leg joint origin rotated by `ORIGIN_RPY` and everything below
/// re-expressed in the rotated frames (translations, axes, inertials), so the robot is the same
/// body with other frames; `rotate = false` gives its unrotated twin.
fn rotated_tiny_urdf(rotate: bool) -> String {
    use nalgebra::{Rotation3, Vector3};
    let mut xml = String::from(
        r#"<robot name="tiny"><link name="body"><inertial><mass value="4.0"/><inertia ixx="0.02" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.05"/></inertial></link>"#,
    );
    for (leg, x, y) in LEGS {
        let side = y.signum() * 0.05;
        let translations = [
            Vector3::new(x, y, 0.0),
            Vector3::new(0.0, side, 0.0),
            Vector3::new(0.0, 0.0, -0.2),
            Vector3::new(0.0, 0.0, -0.2),
        ];
        let axes = [Vector3::x(), Vector3::y(), Vector3::y()];
        let parents = [
            "body",
            &format!("{leg}_l1"),
            &format!("{leg}_l2"),
            &format!("{leg}_l3"),
        ]
        .map(str::to_string);
        let children = [1, 2, 3].map(|i| format!("{leg}_l{i}"));
        // Orientation of the frame reached so far relative to the body, at q = 0.
        let mut orientation = Rotation3::identity();
        for (i, t) in translations.iter().enumerate() {
            let local = if rotate {
                let [r, p, y] = ORIGIN_RPY[i];
                Rotation3::from_euler_angles(r, p, y)
            } else {
                Rotation3::identity()
            };
            let xyz = orientation.inverse() * t;
            orientation *= local;
            let origin = format!(r#"<origin xyz="{}" rpy="{}"/>"#, vector(&xyz), rpy(&local));
            let parent = &parents[i];
            if i == 3 {
                xml.push_str(&format!(
                    r#"<joint name="{leg}_toe_fix" type="fixed"><parent link="{parent}"/><child link="{leg}_toe"/>{origin}</joint>
<link name="{leg}_toe"><inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial><collision><geometry><sphere radius="0.02"/></geometry></collision></link>"#
                ));
                continue;
            }
            let axis = orientation.inverse() * axes[i];
            let com = orientation.inverse() * Vector3::from(LINK_COM);
            let [ixx, iyy, izz] = LINK_INERTIA;
            let child = &children[i];
            xml.push_str(&format!(
                r#"<joint name="{leg}_j{n}" type="revolute"><parent link="{parent}"/><child link="{child}"/>{origin}<axis xyz="{axis}"/><limit lower="-2.7" upper="3" effort="20" velocity="20"/></joint>
<link name="{child}"><inertial><origin xyz="{com}" rpy="{inertial_rpy}"/><mass value="0.5"/><inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial></link>"#,
                n = i + 1,
                axis = vector(&axis),
                com = vector(&com),
                inertial_rpy = rpy(&orientation.inverse()),
            ));
        }
    }
    xml.push_str("\n</robot>\n");
    xml
}

#[test]
fn rotated_joint_origins_give_the_kinematics_and_dynamics_of_the_unrotated_twin() {
    let rotated = RobotModel::from_config_str(&tiny_config(), &rotated_tiny_urdf(true))
        .unwrap_or_else(|e| panic!("the rotated robot must load: {e}"));
    let twin = RobotModel::from_config_str(&tiny_config(), &rotated_tiny_urdf(false))
        .unwrap_or_else(|e| panic!("the unrotated twin must load: {e}"));
    let close = |a: &[f64], b: &[f64], tolerance: f64, what: &str| {
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < tolerance, "{what}: {a:?} vs {b:?}");
        }
    };
    close(&[rotated.total_mass()], &[twin.total_mass()], 1e-12, "mass");
    let stand = rotated.stand_joint_positions(0.3).expect("stand pose");
    close(
        &stand,
        &twin.stand_joint_positions(0.3).expect("twin stand pose"),
        1e-9,
        "stand pose",
    );
    let gravity = [0.3, -0.2, -9.81];
    for leg in Leg::ALL {
        for k in 0..20 {
            let t = f64::from(k) * 0.37;
            let q = [
                0.4 * t.sin(),
                0.8 + 0.6 * (1.3 * t).cos(),
                -1.5 + 0.5 * (0.7 * t).sin(),
            ];
            let dq = [1.1 * t.cos(), -0.7, 2.0 * t.sin()];
            let what = format!("{leg:?} at {q:?}");
            close(
                &rotated.foot_position_body(leg, q),
                &twin.foot_position_body(leg, q),
                1e-12,
                &format!("foot position, {what}"),
            );
            close(
                rotated.foot_jacobian_body(leg, q).as_flattened(),
                twin.foot_jacobian_body(leg, q).as_flattened(),
                1e-12,
                &format!("Jacobian, {what}"),
            );
            close(
                rotated.leg_mass_matrix(leg, q).as_flattened(),
                twin.leg_mass_matrix(leg, q).as_flattened(),
                1e-12,
                &format!("mass matrix, {what}"),
            );
            close(
                &rotated.leg_bias(leg, q, dq, gravity),
                &twin.leg_bias(leg, q, dq, gravity),
                1e-12,
                &format!("bias torques, {what}"),
            );
            let foot = twin.foot_position_body(leg, q);
            let solved = rotated.inverse_kinematics(leg, foot).expect("IK");
            close(
                &rotated.foot_position_body(leg, solved),
                &foot,
                1e-9,
                &format!("IK, {what}"),
            );
        }
    }
    let (inertia, com) = rotated.composite_inertia(&stand);
    let (twin_inertia, twin_com) = twin.composite_inertia(&stand);
    close(
        inertia.as_flattened(),
        twin_inertia.as_flattened(),
        1e-12,
        "composite inertia",
    );
    close(&com, &twin_com, 1e-12, "composite CoM");
}

#[test]
fn bad_masses_and_inertias_are_refused() {
    let body = r#"<mass value="4.0"/>"#;
    for (bad, needle) in [
        (r#"<mass value="-4.0"/>"#, "mass of link `body` is -4"),
        (r#"<mass value="nan"/>"#, "mass of link `body` is NaN"),
        (
            r#"<mass value="0"/>"#,
            "link `body` has zero mass but a non-zero inertia",
        ),
    ] {
        let kind = assert_urdf_error(&tiny_config(), &tiny_urdf().replace(body, bad), needle);
        assert!(matches!(kind, ModelError::InvalidValue(_)));
    }
    let inertia = r#"ixx="0.02" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.05""#;
    for (bad, needle) in [
        (
            r#"ixx="-0.02" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.05""#,
            "not positive definite",
        ),
        (
            r#"ixx="0.01" ixy="0.01" ixz="0.01" iyy="0.01" iyz="0.01" izz="0.01""#,
            "not positive definite",
        ),
        (
            r#"ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.05""#,
            "triangle inequality",
        ),
        (
            r#"ixx="inf" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.05""#,
            "not finite",
        ),
    ] {
        let text = load_error(&tiny_config(), &tiny_urdf().replace(inertia, bad)).0;
        assert!(text.contains(needle) && text.contains("`body`"), "{text}");
        let physical = needle != "not finite";
        assert_eq!(
            text.contains("massless_links"),
            physical,
            "remedy hint: {text}"
        );
    }
    // Every placeholder at once, with the config line that accepts them all.
    let two = tiny_urdf()
        .replace(
            inertia,
            r#"ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.05""#,
        )
        .replacen(
            r#"<inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/>"#,
            r#"<inertia ixx="1e-6" ixy="1e-6" ixz="1e-6" iyy="1e-6" iyz="1e-6" izz="1e-6"/>"#,
            1,
        );
    let text = load_error(&tiny_config(), &two).0;
    for needle in [
        "`body` breaks the triangle inequality",
        "`fr_toe` is not positive definite",
        r#"set `massless_links = ["body", "fr_toe"]`"#,
    ] {
        assert!(text.contains(needle), "{needle} in {text}");
    }
    // The remedy the message names: a placeholder inertial declared massless is accepted.
    let singular = tiny_urdf().replace(
        inertia,
        r#"ixx="0.01" ixy="0.01" ixz="0.01" iyy="0.01" iyz="0.01" izz="0.01""#,
    );
    let config = format!("massless_links = [\"body\"]\n{}", tiny_config());
    let model = RobotModel::from_config_str(&config, &singular).expect("massless body");
    assert!((model.total_mass() - 4.0 * 1.55).abs() < 1e-12);
    // A link without <inertial> is a massless frame.
    let frame = tiny_urdf().replace("</robot>", r#"<joint name="cam" type="fixed"><parent link="body"/><child link="cam_link"/></joint><link name="cam_link"/></robot>"#);
    RobotModel::from_config_str(&tiny_config(), &frame).expect("massless frame link");
    let config = format!("massless_links = [\"nothing\"]\n{}", tiny_config());
    assert_config_error(&config, &tiny_urdf(), "`nothing`");
}

#[test]
fn non_finite_origins_and_axes_are_refused() {
    let urdf = tiny_urdf().replacen(
        r#"<origin xyz="0 0 -0.2" rpy="0 0 0"/>"#,
        r#"<origin xyz="0 nan -0.2" rpy="0 0 0"/>"#,
        1,
    );
    assert_urdf_error(
        &tiny_config(),
        &urdf,
        "origin xyz of joint `fr_j3` is not finite",
    );
    let urdf = tiny_urdf().replacen(r#"<axis xyz="1 0 0"/>"#, r#"<axis xyz="inf 0 0"/>"#, 1);
    assert_urdf_error(&tiny_config(), &urdf, "axis of joint `fr_j1` is not finite");
    let urdf = tiny_urdf().replacen(
        r#"<origin xyz="0 0 -0.2" rpy="0 0 0"/></joint>"#,
        r#"<origin xyz="0 0 -0.2" rpy="0 inf 0"/></joint>"#,
        1,
    );
    assert_urdf_error(
        &tiny_config(),
        &urdf,
        "origin rpy of joint `fr_toe_fix` is not finite",
    );
}

#[test]
fn foot_radius_comes_from_the_sphere_or_the_config() {
    let no_spheres = tiny_urdf().replace(
        r#"<collision><geometry><sphere radius="0.02"/></geometry></collision>"#,
        "",
    );
    assert_config_error(&tiny_config(), &no_spheres, "no foot radius");
    let config = format!("foot_radius = 0.015\n{}", tiny_config());
    let model = RobotModel::from_config_str(&config, &no_spheres).expect("radius from config");
    assert!((model.foot_radius() - 0.015).abs() < 1e-15);
    assert_config_error(&config, &tiny_urdf(), "contradicts the sphere collision");
    // Foot offset on the last link instead of a foot link.
    let config = tiny_config()
        .replace(
            "foot_link = \"fr_toe\"",
            "foot_link = \"fr_l3\"\nfoot_offset = [0.0, 0.0, -0.2]",
        )
        .replace(
            "foot_link = \"fl_toe\"",
            "foot_link = \"fl_l3\"\nfoot_offset = [0.0, 0.0, -0.2]",
        );
    let offset = RobotModel::from_config_str(&config, &tiny_urdf()).expect("foot offset");
    let linked = RobotModel::from_config_str(&tiny_config(), &tiny_urdf()).expect("tiny");
    let q = [0.1, 0.5, -1.0];
    for leg in [Leg::FR, Leg::FL] {
        let (a, b) = (
            offset.foot_position_body(leg, q),
            linked.foot_position_body(leg, q),
        );
        assert!(
            (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12),
            "{a:?} vs {b:?}"
        );
    }
}

#[test]
fn missing_or_zero_limits_need_an_override() {
    let urdf = tiny_urdf().replacen(
        r#"effort="20" velocity="20""#,
        r#"effort="0" velocity="20""#,
        1,
    );
    assert_urdf_error(&tiny_config(), &urdf, "effort limit of joint `fr_j1` is 0");
    let config = format!("{}\n[limits]\neffort = [5.0, 6.0, 7.0]\n", tiny_config());
    let model = RobotModel::from_config_str(&config, &urdf).expect("override");
    assert_eq!(&model.effort_limits()[..3], &[5.0, 6.0, 7.0]);
    assert_eq!(&model.velocity_limits()[..3], &[20.0, 20.0, 20.0]);
}

#[test]
fn toml_and_urdf_syntax_errors_name_the_file() {
    let (text, _) = load_error("urdf = \"x.urdf\"\nbase_link = \n", &tiny_urdf());
    assert!(
        text.contains("robot config text") && text.contains("line 2"),
        "{text}"
    );
    let (text, kind) = load_error(&tiny_config(), "<robot");
    assert!(
        matches!(kind, ModelError::Parse(_)) && text.starts_with("URDF text: "),
        "{text}"
    );
    assert_config_error(
        &tiny_config().replace("stand_height = 0.3", "stand_height = 0.9"),
        &tiny_urdf(),
        "stand_height",
    );
}

/// A scratch folder with the tiny robot's files.
fn scratch(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("pfnav-robot-config-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

#[test]
fn config_file_names_its_urdf_relative_to_itself_or_by_package() {
    let dir = scratch("files");
    std::fs::write(dir.join("tiny.urdf"), tiny_urdf()).expect("write");
    std::fs::write(dir.join("tiny.toml"), tiny_config()).expect("write");
    let model = RobotModel::from_config_file(&dir.join("tiny.toml")).expect("relative URDF");
    assert_eq!(model.name(), "tiny");
    // package://NAME/PATH through explicit roots.
    let package = dir.join("share/tiny_pkg/urdf");
    std::fs::create_dir_all(&package).expect("mkdir");
    std::fs::write(package.join("tiny.urdf"), tiny_urdf()).expect("write");
    let config = tiny_config().replace("\"tiny.urdf\"", "\"package://tiny_pkg/urdf/tiny.urdf\"");
    std::fs::write(dir.join("pkg.toml"), config).expect("write");
    let roots = PackagePath::new(vec![dir.join("share")]);
    RobotModel::from_config_file_with(&dir.join("pkg.toml"), &roots).expect("package URDF");
    let error = RobotModel::from_config_file_with(&dir.join("pkg.toml"), &PackagePath::default())
        .expect_err("no roots")
        .to_string();
    assert!(
        error.contains("pkg.toml") && error.contains("package `tiny_pkg`"),
        "{error}"
    );
    // URDF errors name the URDF file.
    std::fs::write(
        dir.join("tiny.urdf"),
        tiny_urdf().replace(r#"<mass value="4.0"/>"#, r#"<mass value="-1"/>"#),
    )
    .expect("write");
    let error = RobotModel::from_config_file(&dir.join("tiny.toml"))
        .expect_err("bad mass")
        .to_string();
    let urdf_path = dir.join("tiny.urdf");
    assert!(
        error.starts_with(&format!("{}: ", urdf_path.display())),
        "{error}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
    assert!(RobotModel::from_config_file(Path::new("/nonexistent/r.toml")).is_err());
}

#[test]
fn inverse_kinematics_handles_offset_hips_and_slanted_links() {
    // FR: hip joint off the abduction axis in x and z, knee ahead of the hip at q = 0, foot
    // behind and beside the knee: the closed-form guess must account for all of them.
    let urdf = tiny_urdf()
        .replace(
            r#"<child link="fr_l2"/><origin xyz="0 -0.05 0" rpy="0 0 0"/>"#,
            r#"<child link="fr_l2"/><origin xyz="0.01 -0.05 -0.02" rpy="0 0 0"/>"#,
        )
        .replace(
            r#"<child link="fr_l3"/><origin xyz="0 0 -0.2" rpy="0 0 0"/>"#,
            r#"<child link="fr_l3"/><origin xyz="0.03 -0.01 -0.2" rpy="0 0 0"/>"#,
        )
        .replace(
            r#"<child link="fr_toe"/><origin xyz="0 0 -0.2" rpy="0 0 0"/>"#,
            r#"<child link="fr_toe"/><origin xyz="-0.02 -0.008 -0.19" rpy="0 0 0"/>"#,
        );
    assert_eq!(
        urdf.matches("-0.008 -0.19").count(),
        1,
        "the FR leg was modified"
    );
    let model = RobotModel::from_config_str(&tiny_config(), &urdf).expect("offset leg");
    let mut state = 7u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..200 {
        let q = [
            0.6 * (next() - 0.5),
            0.4 + 0.8 * next(),
            -0.6 - 1.2 * next(),
        ];
        let p = model.foot_position_body(Leg::FR, q);
        let solved = model.inverse_kinematics(Leg::FR, p).expect("reachable");
        for i in 0..3 {
            assert!((solved[i] - q[i]).abs() < 1e-6, "IK {solved:?} for {q:?}");
        }
    }
    let stand = model.stand_joint_positions(0.3).expect("stand");
    let foot = model.foot_position_body(Leg::FR, [stand[0], stand[1], stand[2]]);
    let nominal = model.nominal_foot_position(Leg::FR, 0.3);
    assert!(
        (0..3).all(|i| (foot[i] - nominal[i]).abs() < 1e-9),
        "{foot:?} vs {nominal:?}"
    );
}

#[test]
fn the_crouch_is_all_four_legs_or_none_and_inside_the_joint_limits() {
    let urdf = tiny_urdf();
    let model = RobotModel::from_config_str(&tiny_config(), &urdf).expect("tiny robot");
    assert_eq!(model.crouch_joint_positions(), None);
    let with_crouch = |crouch: &[&str; 4]| {
        let mut config = tiny_config();
        for (leg, angles) in ["FR", "FL", "RR", "RL"].iter().zip(crouch) {
            let header = format!("[legs.{leg}]\n");
            if !angles.is_empty() {
                config = config.replace(&header, &format!("{header}crouch = [{angles}]\n"));
            }
        }
        config
    };
    let crouch = [
        "0.1, 0.8, -1.6",
        "-0.1, 0.8, -1.6",
        "0, -0.8, 1.6",
        "0, -0.8, 1.6",
    ];
    let model =
        RobotModel::from_config_str(&with_crouch(&crouch), &urdf).expect("crouch on four legs");
    let pose = model.crouch_joint_positions().expect("crouch");
    assert_eq!(&pose[..6], &[0.1, 0.8, -1.6, -0.1, 0.8, -1.6]);
    assert_eq!(&pose[6..], &[0.0, -0.8, 1.6, 0.0, -0.8, 1.6]);
    assert_config_error(
        &with_crouch(&["0, 0.8, -1.6", "", "", ""]),
        &urdf,
        "`legs.FL.crouch` is missing",
    );
    assert_config_error(
        &with_crouch(&[
            "0, 0.8, -1.6",
            "0, 0.8, -1.6",
            "0, 0.8, -2.9",
            "0, 0.8, -1.6",
        ]),
        &urdf,
        "`legs.RR.crouch`: -2.9 rad for joint `rr_j3` is outside its limits",
    );
    assert_config_error(
        &with_crouch(&[
            "0, 0.8, nan",
            "0, 0.8, -1.6",
            "0, 0.8, -1.6",
            "0, 0.8, -1.6",
        ]),
        &urdf,
        "`legs.FR.crouch` is not finite",
    );
    assert_config_error(
        &with_crouch(&["0, 0.8", "0, 0.8, -1.6", "0, 0.8, -1.6", "0, 0.8, -1.6"]),
        &urdf,
        "expected exactly 3 values",
    );
}

#[test]
fn the_tuning_table_overrides_the_scaled_tuning_and_names_its_keys_in_errors() {
    use quad_controller::{ControllerConfig, RobotScale};
    let with_tuning = |table: &str| format!("{}\n[tuning]\n{table}\n", tiny_config());
    let plain = RobotModel::from_config_str(&tiny_config(), &tiny_urdf()).expect("tiny robot");
    assert!(plain.configured_tuning().is_none());
    let scaled = ControllerConfig::for_robot(&plain);
    let model = RobotModel::from_config_str(
        &with_tuning("kp_stand = [100, 110, 120]\ngait_period = 0.4\ngait = \"Walk\""),
        &tiny_urdf(),
    )
    .expect("tuned robot");
    let tuned = ControllerConfig::for_robot(&model);
    assert_eq!(tuned.kp_stand, [100.0, 110.0, 120.0]);
    assert_eq!(tuned.gait_period, 0.4);
    assert_ne!(tuned.gait, scaled.gait);
    // Everything not named keeps the robot's scaled default.
    assert_eq!(
        ControllerConfig {
            kp_stand: scaled.kp_stand,
            gait_period: scaled.gait_period,
            gait: scaled.gait,
            ..tuned
        },
        scaled
    );
    let scale = RobotScale::of(&plain);
    let (_, kp_max) = ControllerConfig::field("kp_stand")
        .expect("field")
        .range_for(scale);
    for (table, needle) in [
        (
            "kp_stnd = [1, 1, 1]",
            "key `tuning.kp_stnd` is not a controller config field",
        ),
        (
            &format!("kp_stand = [1, {}, 1]", kp_max * 2.0) as &str,
            "key `tuning.kp_stand[1] = ",
        ),
        ("gait_period = \"slow\"", "table `tuning`"),
        ("f_min = 200.0\nf_max = 100.0", "f_min must be < f_max"),
        ("kp_stand = [1, 1]", "table `tuning`"),
    ] {
        assert_config_error(&with_tuning(table), &tiny_urdf(), needle);
    }
}

/// A UV sphere of `radius` around `centre` as triangles (every vertex on the sphere).
fn sphere_triangles(centre: [f64; 3], radius: f64) -> Vec<[[f64; 3]; 3]> {
    let (rings, sectors) = (32, 64);
    let point = |i: usize, j: usize| {
        let polar = std::f64::consts::PI * i as f64 / rings as f64;
        let azimuth = 2.0 * std::f64::consts::PI * j as f64 / sectors as f64;
        [
            centre[0] + radius * polar.sin() * azimuth.cos(),
            centre[1] + radius * polar.sin() * azimuth.sin(),
            centre[2] + radius * polar.cos(),
        ]
    };
    let mut triangles = Vec::new();
    for i in 0..rings {
        for j in 0..sectors {
            let (a, b) = (point(i, j), point(i + 1, j));
            let (c, d) = (point(i + 1, j + 1), point(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    triangles
}

fn binary_stl(triangles: &[[[f64; 3]; 3]]) -> Vec<u8> {
    let mut bytes = vec![0u8; 80];
    bytes.extend((triangles.len() as u32).to_le_bytes());
    for triangle in triangles {
        bytes.extend([0u8; 12]);
        for v in triangle {
            for x in v {
                bytes.extend((*x as f32).to_le_bytes());
            }
        }
        bytes.extend([0u8; 2]);
    }
    bytes
}

fn ascii_stl(triangles: &[[[f64; 3]; 3]]) -> String {
    let mut text = String::from("solid foot\n");
    for triangle in triangles {
        text.push_str("facet normal 0 0 0\nouter loop\n");
        for v in triangle {
            text.push_str(&format!("vertex {} {} {}\n", v[0], v[1], v[2]));
        }
        text.push_str("endloop\nendfacet\n");
    }
    text.push_str("endsolid foot\n");
    text
}

fn obj(triangles: &[[[f64; 3]; 3]]) -> String {
    let mut text = String::new();
    for (k, triangle) in triangles.iter().enumerate() {
        for v in triangle {
            text.push_str(&format!("v {} {} {}\n", v[0], v[1], v[2]));
        }
        text.push_str(&format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3));
    }
    text
}

#[test]
fn check_measures_mesh_feet_in_stl_and_obj_and_says_what_it_cannot_read() {
    use quad_controller::robot_config::check::check_robot_config;
    let dir = scratch("foot-mesh");
    // The foot sphere in millimetres, off the mesh origin; the collision origin (shifted and
    // turned) and the scale put it back around the foot point: the radius is 25 mm whatever the
    // leg's pose.
    let in_mm = sphere_triangles([0.0, 0.0, 10.0], 25.0);
    std::fs::write(dir.join("foot.stl"), binary_stl(&in_mm)).expect("write");
    std::fs::write(dir.join("foot_ascii.stl"), ascii_stl(&in_mm)).expect("write");
    std::fs::write(dir.join("foot.obj"), obj(&in_mm)).expect("write");
    std::fs::write(dir.join("foot.dae"), "<COLLADA/>").expect("write");
    std::fs::write(dir.join("broken.stl"), b"solid x\nfacet normal nonsense").expect("write");
    std::fs::write(dir.join("tiny.toml"), tiny_config()).expect("write");
    let shift = nalgebra::Rotation3::from_euler_angles(0.3, 0.2, 0.1)
        * nalgebra::Vector3::new(0.0, 0.0, 0.01);
    for mesh in [
        "foot.stl",
        "foot_ascii.stl",
        "foot.obj",
        "foot.dae",
        "broken.stl",
    ] {
        let collision = format!(
            r#"<collision><origin xyz="{} {} {}" rpy="0.3 0.2 0.1"/><geometry><mesh filename="{mesh}" scale="0.001 0.001 0.001"/></geometry></collision>"#,
            -shift[0], -shift[1], -shift[2]
        );
        let urdf = tiny_urdf().replace(
            r#"<collision><geometry><sphere radius="0.02"/></geometry></collision>"#,
            &collision,
        );
        std::fs::write(dir.join("tiny.urdf"), urdf).expect("write");
        let check = check_robot_config(&dir.join("tiny.toml"), &PackagePath::default(), None);
        let finding = check
            .findings
            .iter()
            .find(|f| f.key == "foot_radius")
            .unwrap_or_else(|| panic!("{mesh}: no foot_radius finding: {:?}", check.findings));
        let fix = finding.fix.as_deref().unwrap_or("");
        match mesh {
            "foot.dae" | "broken.stl" => {
                assert!(check.foot_mesh.is_none(), "{mesh}");
                assert!(fix.contains("<radius"), "{mesh}: {fix}");
                let why = if mesh == "foot.dae" {
                    "cannot read `.dae` meshes"
                } else {
                    "is not a readable STL"
                };
                assert!(
                    check.notes.iter().any(|n| n.contains(why)),
                    "{mesh}: {:?}",
                    check.notes
                );
            }
            _ => {
                let measured = check.foot_mesh.as_ref().expect("measured");
                assert!(
                    (measured.radius - 0.025).abs() < 5e-5,
                    "{mesh}: {}",
                    measured.radius
                );
                assert!(fix.starts_with("foot_radius = 0.0250"), "{mesh}: {fix}");
                let model = check.model.as_ref().expect("loads with the radius");
                assert!((model.foot_radius() - 0.025).abs() < 1e-4);
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn check_measures_a_mesh_foot_in_the_pose_the_leg_stands_in() {
    use quad_controller::robot_config::check::check_robot_config;
    let dir = scratch("foot-spike");
    // A spike 30 mm straight down from the foot point: how deep it reaches depends on how the
    // lower leg is turned in the stand.
    let length = 0.03;
    let spike = [[[0.0, 0.0, -length], [0.001, 0.0, 0.0], [-0.001, 0.0, 0.0]]];
    std::fs::write(dir.join("spike.stl"), binary_stl(&spike)).expect("write");
    std::fs::write(dir.join("tiny.toml"), tiny_config()).expect("write");
    let urdf = tiny_urdf().replace(
        r#"<collision><geometry><sphere radius="0.02"/></geometry></collision>"#,
        r#"<collision><geometry><mesh filename="spike.stl"/></geometry></collision>"#,
    );
    std::fs::write(dir.join("tiny.urdf"), urdf).expect("write");
    let check = check_robot_config(&dir.join("tiny.toml"), &PackagePath::default(), None);
    let measured = check.foot_mesh.as_ref().expect("measured");
    let model = check.model.as_ref().expect("loads");
    let q = model
        .stand_joint_positions(model.stand_height())
        .expect("stand");
    for (leg, depth) in &measured.per_leg {
        let l = 3 * leg.index();
        let expected = length * (q[l + 1] + q[l + 2]).cos() * q[l].cos();
        assert!(
            (depth - expected).abs() < 1e-4,
            "{leg:?}: {depth} vs {expected} (lower leg pitched {} rad)",
            q[l + 1] + q[l + 2]
        );
    }
    assert!(
        (measured.radius - length).abs() > 1e-3,
        "the stand turns the lower leg, the spike must not reach its full length"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn config_errors_carry_the_key_they_are_about() {
    let key_of = |config: &str, urdf: &str| {
        RobotModel::from_config_str(config, urdf)
            .expect_err("must fail")
            .config_key()
            .map(str::to_string)
    };
    let no_spheres = tiny_urdf().replace(
        r#"<collision><geometry><sphere radius="0.02"/></geometry></collision>"#,
        "",
    );
    let crouch = tiny_config().replace(
        "foot_link = \"fr_toe\"",
        "foot_link = \"fr_toe\"\ncrouch = [0.0, 9.0, -1.0]",
    );
    let cases: [(String, String, Option<&str>); 6] = [
        (
            tiny_config().replace("stand_height = 0.3", "stand_height = 0.9"),
            tiny_urdf(),
            Some("stand_height"),
        ),
        (tiny_config(), no_spheres, Some("foot_radius")),
        (crouch, tiny_urdf(), Some("legs.FR.crouch")),
        (
            format!("{}\n[tuning]\nswing_height = 50.0\n", tiny_config()),
            tiny_urdf(),
            Some("tuning.swing_height"),
        ),
        (
            format!("{}\n[tuning]\nno_such_gain = 1.0\n", tiny_config()),
            tiny_urdf(),
            Some("tuning.no_such_gain"),
        ),
        (
            "urdf = \"x.urdf\"\nbase_link = \n".into(),
            tiny_urdf(),
            None,
        ),
    ];
    for (config, urdf, key) in cases {
        assert_eq!(key_of(&config, &urdf).as_deref(), key, "{config}");
    }
}
