//! Third-party quadrupeds through their robot configs (`robot/third_party/*.toml`): every config
//! loads, the model's mass is the URDF's, the nominal stand puts the feet under the hips at the
//! stand height with the knees bent as configured and inside the joint limits, IK inverts FK, and
//! the controller stands still on the single-rigid-body simulation.
//!
//! The URDFs come from the PyPI package `example-robot-data`, found through the package roots of
//! `PFNAV_PACKAGE_PATH` or else the repository's `.venv`. Without them the tests fail and say how
//! to install the package.
#![allow(clippy::needless_range_loop)] // parallel indexing of joints and legs
use crate::common;

use std::path::{Path, PathBuf};

use quad_controller::robot_config::{KneeDirection, PACKAGE_PATH_ENV};
use quad_controller::{
    ControllerConfig, FsmState, Leg, ModeRequest, PackagePath, Reference, RobotConfig, RobotModel,
    NUM_JOINTS,
};

const INSTALL_HINT: &str = "install the robot models: `.venv/bin/pip install example-robot-data==6.0.0 --no-deps` \
     (puts them in .venv/lib/python3.*/site-packages/cmeel.prefix/share), or set PFNAV_PACKAGE_PATH \
     to the folder that contains `example-robot-data/`";

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The package roots: `PFNAV_PACKAGE_PATH`, else the repository venv's cmeel prefix.
fn package_path() -> PackagePath {
    let from_env = PackagePath::from_env();
    if !from_env.roots().is_empty() {
        return from_env;
    }
    let lib = repo_root().join(".venv/lib");
    let mut roots: Vec<PathBuf> = std::fs::read_dir(&lib)
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| e.path().join("site-packages/cmeel.prefix/share"))
                .filter(|p| p.is_dir())
                .collect()
        })
        .unwrap_or_default();
    roots.sort();
    assert!(
        !roots.is_empty(),
        "{PACKAGE_PATH_ENV} is unset and {} has no python*/site-packages/cmeel.prefix/share: {INSTALL_HINT}",
        lib.display()
    );
    PackagePath::new(roots)
}

/// Every third-party config, sorted by file name.
fn configs() -> Vec<PathBuf> {
    let dir = repo_root().join("robot/third_party");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("robot/third_party exists")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    assert!(
        paths.len() >= 3,
        "expected at least three configs in {}",
        dir.display()
    );
    paths
}

struct Loaded {
    path: PathBuf,
    config: RobotConfig,
    urdf: PathBuf,
    model: RobotModel,
}

fn load_all() -> Vec<Loaded> {
    let packages = package_path();
    configs()
        .into_iter()
        .map(|path| {
            let config = RobotConfig::from_file(&path).expect("config parses");
            let urdf = config
                .urdf_path(&path, &packages)
                .unwrap_or_else(|e| panic!("{e}; {INSTALL_HINT}"));
            let model = RobotModel::from_config_file_with(&path, &packages)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            Loaded {
                path,
                config,
                urdf,
                model,
            }
        })
        .collect()
}

fn leg_q(q: &[f64; NUM_JOINTS], leg: Leg) -> [f64; 3] {
    let l = leg.index();
    [q[3 * l], q[3 * l + 1], q[3 * l + 2]]
}

#[test]
fn total_mass_is_the_urdf_sum_without_the_massless_links() {
    for robot in load_all() {
        let urdf = urdf_rs::read_file(&robot.urdf).expect("URDF parses");
        let sum: f64 = urdf
            .links
            .iter()
            .filter(|l| !robot.config.massless_links.contains(&l.name))
            .map(|l| l.inertial.mass.value)
            .sum();
        assert!(
            sum > 1.0,
            "{}: implausible mass {sum}",
            robot.path.display()
        );
        assert!(
            (robot.model.total_mass() - sum).abs() < 1e-9,
            "{}: model {} kg, URDF {sum} kg",
            robot.path.display(),
            robot.model.total_mass()
        );
    }
}

#[test]
fn stand_pose_puts_the_feet_under_the_hips_at_the_stand_height() {
    for robot in load_all() {
        let model = &robot.model;
        let name = robot.path.display();
        let height = model.stand_height();
        let q = model.stand_joint_positions(height).expect("stand pose");
        let (lower, upper) = (model.lower_limits(), model.upper_limits());
        for leg in Leg::ALL {
            let foot = model.foot_position_body(leg, leg_q(&q, leg));
            let hip = model.hip_position_body(leg);
            let below = -(foot[2] - model.foot_radius());
            assert!(
                (below - height).abs() < 1e-3,
                "{name} {leg:?}: sole {below} m below the base, stand height {height}"
            );
            assert!(
                (foot[0] - hip[0]).abs() < 1e-3,
                "{name} {leg:?}: foot x {} hip x {}",
                foot[0],
                hip[0]
            );
            let lateral = foot[1] - hip[1];
            assert!(
                (lateral - model.hip_lateral_offset(leg)).abs() < 1e-3,
                "{name} {leg:?}: foot {lateral} m beside the abduction joint"
            );
            // Outward, or in the abduction joint's plane (HyQ): never on the other side.
            assert!(
                lateral * hip[1].signum() > -1e-6,
                "{name} {leg:?}: foot on the wrong side"
            );
            // Knee on the configured side of the hip–foot line (which is vertical here).
            let knee = model.joint_positions_body(leg, leg_q(&q, leg))[2];
            let expected = robot.config.legs.get(leg).knee_points;
            let behind = knee[0] < foot[0] - 0.01;
            let ahead = knee[0] > foot[0] + 0.01;
            match expected {
                KneeDirection::Backward => assert!(
                    behind,
                    "{name} {leg:?}: knee x {} foot x {}",
                    knee[0], foot[0]
                ),
                KneeDirection::Forward => assert!(
                    ahead,
                    "{name} {leg:?}: knee x {} foot x {}",
                    knee[0], foot[0]
                ),
            }
            for j in 3 * leg.index()..3 * leg.index() + 3 {
                assert!(
                    q[j] > lower[j] && q[j] < upper[j],
                    "{name}: stand joint {j} = {} outside [{}, {}]",
                    q[j],
                    lower[j],
                    upper[j]
                );
            }
        }
    }
}

/// The `standing` pose of the SRDF shipped next to the URDF, joint name → angle: the package
/// authors' own stand, independent of our configs.
fn srdf_standing_pose(urdf: &Path) -> Vec<(String, f64)> {
    quad_controller::robot_config::srdf::standing_pose_near(urdf)
        .unwrap_or_else(|| panic!("no SRDF standing pose next to {}", urdf.display()))
        .joints
}

/// Robots whose package ships no SRDF (their configs take the stand from the maker's own
/// software, named in the config).
const WITHOUT_SRDF: [&str; 1] = ["laikago"];

#[test]
fn stand_pose_bends_the_joints_like_the_packages_own_standing_pose() {
    for robot in load_all() {
        let stem = robot
            .path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("");
        if WITHOUT_SRDF.contains(&stem) {
            assert!(
                quad_controller::robot_config::srdf::standing_pose_near(&robot.urdf).is_none(),
                "{stem} has an SRDF now: compare it"
            );
            continue;
        }
        let srdf = srdf_standing_pose(&robot.urdf);
        let q = robot
            .model
            .stand_joint_positions(robot.model.stand_height())
            .expect("stand pose");
        let mut compared = 0;
        for leg in Leg::ALL {
            for j in 1..3 {
                let name = &robot.config.legs.get(leg).joints[j];
                let Some((_, reference)) = srdf.iter().find(|(n, _)| n == name) else {
                    continue;
                };
                let ours = q[3 * leg.index() + j];
                assert!(
                    ours * reference > 0.0,
                    "{}: joint `{name}` is {ours:.3} rad at our stand, {reference} in the SRDF standing pose",
                    robot.path.display()
                );
                compared += 1;
            }
        }
        assert_eq!(
            compared,
            8,
            "{}: hip and knee of every leg compared",
            robot.path.display()
        );
    }
}

/// SplitMix64: explicit-seed offsets around the stand pose.
fn splitmix(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

#[test]
fn inverse_kinematics_inverts_forward_kinematics() {
    for robot in load_all() {
        let model = &robot.model;
        let stand = model
            .stand_joint_positions(model.stand_height())
            .expect("stand");
        let mut seed = 19u64;
        for _ in 0..200 {
            for leg in Leg::ALL {
                let mut q = leg_q(&stand, leg);
                for v in &mut q {
                    *v += 0.6 * (splitmix(&mut seed) - 0.5);
                }
                let p = model.foot_position_body(leg, q);
                let solved = model
                    .inverse_kinematics(leg, p)
                    .unwrap_or_else(|e| panic!("{}: {e} for q {q:?}", robot.path.display()));
                let back = model.foot_position_body(leg, solved);
                for i in 0..3 {
                    assert!(
                        (back[i] - p[i]).abs() < 1e-9,
                        "{}: FK(IK(p)) ≠ p",
                        robot.path.display()
                    );
                    assert!(
                        (solved[i] - q[i]).abs() < 1e-6,
                        "{} {leg:?}: IK gave {solved:?} for {q:?}",
                        robot.path.display()
                    );
                }
            }
        }
    }
}

#[test]
fn controller_stands_still_on_the_rigid_body_simulation() {
    for robot in load_all() {
        let model = robot.model.clone();
        // The tuning an FMU bundled for the robot ships: the default scaled to its size.
        let config = ControllerConfig::for_robot(&model);
        let dt = config.control_dt;
        let (mut controller, mut sim) = common::controller_and_standing_sim(model, &config);
        let reference = Reference {
            body_height: config.body_height,
            mode: ModeRequest::Stand,
            ..Reference::default()
        };
        let mut worst_height_error = 0.0f64;
        // The stand-up and the stand's first moments move the base to put the centre of mass over
        // the feet (about 1 cm on the A1, settled by 1.7 s); standing still is judged over the
        // last 0.3 s.
        let mut settled = None;
        for tick in 0..(2.0 / dt) as usize {
            let command = controller
                .step(&sim.state(), &reference, dt)
                .expect("valid input");
            let balancing = matches!(command.fsm_state, FsmState::Stand | FsmState::Locomotion);
            sim.apply_torques(&command, dt, balancing);
            if tick as f64 * dt > 1.0 {
                let base = sim.base_position();
                if tick as f64 * dt >= 1.7 {
                    settled.get_or_insert(base);
                }
                worst_height_error = worst_height_error.max((base.z - config.body_height).abs());
            }
        }
        let settled = settled.expect("the loop runs past 1.7 s");
        let drift = sim.base_position() - settled;
        let tilt = sim.orientation.angle();
        eprintln!(
            "{}: {:.3} kg, stand {:.3} m: worst height error {worst_height_error:.2e} m, drift {:.2e} m, tilt {tilt:.2e} rad",
            robot.path.display(),
            robot.model.total_mass(),
            config.body_height,
            drift.x.hypot(drift.y)
        );
        assert_eq!(
            controller.fsm_state(),
            FsmState::Stand,
            "{}",
            robot.path.display()
        );
        assert!(
            worst_height_error < 0.01 && drift.x.hypot(drift.y) < 0.001 && tilt < 0.02,
            "{}: height error {worst_height_error:.4} m, drift ({:.4}, {:.4}) m, tilt {tilt:.4} rad",
            robot.path.display(),
            drift.x,
            drift.y
        );
    }
}

#[test]
fn default_tuning_lowers_the_swing_of_robots_whose_joints_cannot_follow_it() {
    use quad_controller::tuning::{swing_speed_share, SWING_SPEED_SHARE, TUNED_STAND_HEIGHT};
    let defaults = ControllerConfig::default();
    let mut lowered = Vec::new();
    for robot in load_all() {
        let name = robot.path.display();
        let tuned = ControllerConfig::for_robot(&robot.model);
        let length = robot.model.stand_height() / TUNED_STAND_HEIGHT;
        let scaled = ControllerConfig {
            swing_height: defaults.swing_height * length,
            ..tuned.clone()
        };
        // Only the swing height changes, and only down.
        assert_eq!(
            tuned.gait_period,
            defaults.gait_period * length.sqrt(),
            "{name}"
        );
        assert!(tuned.swing_height <= scaled.swing_height + 1e-12, "{name}");
        let share = swing_speed_share(&robot.model, &tuned);
        if tuned.swing_height < scaled.swing_height - 1e-12 {
            lowered.push(robot.config.urdf.clone());
            // Lowered to the limit, or as low as it goes (40 % of the scaled swing).
            let at_limit = (share - SWING_SPEED_SHARE).abs() < 1e-6;
            let lowest = (tuned.swing_height - 0.4 * scaled.swing_height).abs() < 1e-12;
            assert!(
                at_limit || lowest,
                "{name}: share {share:.3}, swing {}",
                tuned.swing_height
            );
            assert!(share < swing_speed_share(&robot.model, &scaled), "{name}");
        } else {
            assert!(share <= SWING_SPEED_SHARE, "{name}: {share:.3}");
        }
    }
    // ANYmal C's 7.5 rad/s knees cannot follow the scaled 0.15 m swing; HyQ's 12 rad/s neither.
    for needle in ["anymal_c", "hyq"] {
        assert!(
            lowered.iter().any(|urdf| urdf.contains(needle)),
            "{needle} not lowered: {lowered:?}"
        );
    }
}

#[test]
fn check_finds_every_fault_of_a_broken_config_in_one_run_and_proposes_the_srdf_stand() {
    use quad_controller::robot_config::check::{check_robot_config, STAND_HEIGHT_TOLERANCE};
    let packages = package_path();
    let source = repo_root().join("robot/third_party/hyq.toml");
    let good = std::fs::read_to_string(&source).expect("hyq.toml");
    // What a new user writes first: the body link as base, no massless links, one knee wrong,
    // a guessed stand height, no crouch.
    let broken: String = good
        .lines()
        .filter(|line| !line.starts_with("massless_links") && !line.starts_with("crouch"))
        .collect::<Vec<_>>()
        .join("\n")
        .replace("base_link = \"base_link\"", "base_link = \"trunk\"")
        .replace("stand_height = 0.60", "stand_height = 0.5")
        .replacen("knee_points = \"forward\"", "knee_points = \"backward\"", 1);
    let dir = std::env::temp_dir().join(format!("pf-robot-check-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("hyq_broken.toml");
    std::fs::write(&path, broken).expect("write config");
    let check = check_robot_config(&path, &packages, None);
    let keys: Vec<&str> = check.findings.iter().map(|f| f.key.as_str()).collect();
    for (key, fix) in [
        ("base_link", "base_link = \"base_link\""),
        ("massless_links", "\"lf_foot\""),
        ("legs.RR.knee_points", "knee_points = \"forward\""),
        ("stand_height", "stand_height = 0.599"),
        ("legs.FR.crouch", "crouch = [0.000, 0.750, -1.500]"),
    ] {
        let finding = check
            .findings
            .iter()
            .find(|f| f.key == key)
            .unwrap_or_else(|| panic!("no finding for `{key}` in {keys:?}"));
        let proposed = finding.fix.as_deref().unwrap_or("");
        assert!(
            proposed.contains(fix),
            "`{key}`: fix `{proposed}`, expected `{fix}`"
        );
    }
    // The proposals stand the robot where the SRDF stands it.
    let model = check.model.as_ref().expect("the repaired config loads");
    let srdf = srdf_standing_pose(&model_urdf(&packages, &source));
    let srdf_height = srdf_base_height(
        model,
        &RobotConfig::from_file(&source).expect("config"),
        &srdf,
    );
    let proposed = check.stand_height.expect("stand height proposed");
    assert!(
        (proposed - srdf_height).abs() < STAND_HEIGHT_TOLERANCE,
        "{proposed} vs {srdf_height}"
    );
    let stand = model.stand_joint_positions(proposed).expect("stand pose");
    for leg in Leg::ALL {
        let foot = model.foot_position_body(leg, leg_q(&stand, leg));
        let below = model.foot_radius() - foot[2];
        assert!(
            (below - srdf_height).abs() < STAND_HEIGHT_TOLERANCE,
            "{leg:?}: {below}"
        );
    }
    // The shipped configs have nothing to fix.
    for robot in load_all() {
        let check = check_robot_config(&robot.path, &packages, None);
        assert!(
            check.findings.is_empty(),
            "{}: {:?}",
            robot.path.display(),
            check.findings
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

fn model_urdf(packages: &PackagePath, config: &Path) -> PathBuf {
    RobotConfig::from_file(config)
        .expect("config")
        .urdf_path(config, packages)
        .expect("urdf")
}

/// Base origin above the soles at the SRDF stand, by the model's forward kinematics.
fn srdf_base_height(model: &RobotModel, config: &RobotConfig, srdf: &[(String, f64)]) -> f64 {
    let angle = |name: &str| {
        srdf.iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| *v)
            .unwrap_or_else(|| panic!("{name} not in the SRDF stand"))
    };
    let heights: Vec<f64> = Leg::ALL
        .iter()
        .map(|&leg| {
            let joints = &config.legs.get(leg).joints;
            let q = [angle(&joints[0]), angle(&joints[1]), angle(&joints[2])];
            model.foot_radius() - model.foot_position_body(leg, q)[2]
        })
        .collect();
    heights.iter().sum::<f64>() / heights.len() as f64
}

#[test]
fn check_measures_the_foot_radius_of_mesh_feet_as_the_shipped_configs_give_it() {
    use quad_controller::robot_config::check::check_robot_config;
    let packages = package_path();
    let dir = std::env::temp_dir().join(format!("pf-robot-feet-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    // Go2 and Solo-12 have mesh feet; their configs give the radius measured by hand.
    for name in ["go2", "solo12"] {
        let source = repo_root().join(format!("robot/third_party/{name}.toml"));
        let text = std::fs::read_to_string(&source).expect("config");
        let by_hand = RobotConfig::from_file(&source)
            .expect("config")
            .foot_radius
            .expect("mesh-footed configs give foot_radius");
        let without: String = text
            .lines()
            .filter(|line| !line.starts_with("foot_radius"))
            .collect::<Vec<_>>()
            .join("\n");
        let path = dir.join(format!("{name}.toml"));
        std::fs::write(&path, without).expect("write config");
        let check = check_robot_config(&path, &packages, None);
        let finding = check
            .findings
            .iter()
            .find(|f| f.key == "foot_radius")
            .unwrap_or_else(|| panic!("{name}: no foot_radius finding in {:?}", check.findings));
        let measured = check.foot_mesh.as_ref().expect("foot mesh measured");
        assert!(
            (measured.radius - by_hand).abs() < 0.001,
            "{name}: measured {} vs {by_hand} by hand",
            measured.radius
        );
        let fix = finding.fix.as_deref().unwrap_or("");
        assert!(
            fix.starts_with(&format!("foot_radius = {:.4}", measured.radius)),
            "{name}: {fix}"
        );
        let model = check.model.as_ref().expect("the repaired config loads");
        assert!((model.foot_radius() - measured.radius).abs() < 1e-4);
        assert_eq!(check.findings.len(), 1, "{name}: {:?}", check.findings);
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn knee_bend_is_zero_where_the_leg_is_straight_and_every_stand_is_clear_of_the_knee_guard() {
    use quad_controller::KNEE_GUARD_BEND;
    let mut robots = load_all();
    let ours = repo_root().join("robot/quadruped.toml");
    robots.push(Loaded {
        config: RobotConfig::from_file(&ours).expect("config"),
        urdf: ours.clone(),
        model: RobotModel::from_config_file(&ours).expect("our robot"),
        path: ours,
    });
    for robot in robots {
        let model = &robot.model;
        let stand = model
            .stand_joint_positions(model.stand_height())
            .expect("stand pose");
        for leg in Leg::ALL {
            let q = leg_q(&stand, leg);
            let bend = model.knee_bend(leg, q);
            assert!(
                bend > 2.0 * KNEE_GUARD_BEND,
                "{} {leg:?}: stand knee bent only {bend} rad",
                robot.path.display()
            );
            // The hip-to-foot distance peaks where the bend is zero.
            let straight = q[2] - bend / model.knee_bend_per_angle(leg);
            let reach = |knee: f64| {
                let at = [q[0], q[1], knee];
                let hip = model.joint_positions_body(leg, at)[1];
                let foot = model.foot_position_body(leg, at);
                (0..3)
                    .map(|i| (foot[i] - hip[i]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            };
            for delta in [-0.05, 0.05] {
                assert!(
                    reach(straight + delta) < reach(straight) - 1e-6,
                    "{} {leg:?}: the leg is longer {delta} rad away from `straight`",
                    robot.path.display()
                );
            }
        }
    }
}

#[test]
fn describe_resolves_every_config_as_the_model_loads_it() {
    use quad_controller::robot_config::describe::describe_robot_config;
    let packages = package_path();
    for robot in load_all() {
        let described = describe_robot_config(&robot.path, &packages)
            .unwrap_or_else(|e| panic!("{}: {e}", robot.path.display()));
        let name = robot.path.display();
        assert_eq!(described.urdf, robot.urdf, "{name}");
        assert_eq!(described.foot_radius, robot.model.foot_radius(), "{name}");
        assert_eq!(described.stand_height, robot.config.stand_height, "{name}");
        let labels: Vec<&str> = described.legs.iter().map(|l| l.label).collect();
        assert_eq!(labels, ["FR", "FL", "RR", "RL"], "{name}");
        for (leg, described_leg) in Leg::ALL.iter().zip(&described.legs) {
            assert_eq!(
                described_leg.joints,
                robot.config.legs.get(*leg).joints,
                "{name}"
            );
        }
        assert!(
            robot
                .config
                .massless_links
                .iter()
                .all(|l| described.massless_links.contains(l)),
            "{name}"
        );
        assert!(
            !described.mesh_files.is_empty(),
            "{name}: the package URDFs name meshes"
        );
        assert!(described.mesh_files.iter().all(|m| m.is_file()), "{name}");
        assert!(
            described
                .package_dirs
                .iter()
                .any(|(package, dir)| package == "example-robot-data" && dir.is_dir()),
            "{name}"
        );
    }
}
