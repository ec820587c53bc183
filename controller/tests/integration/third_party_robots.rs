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

/// The `standing` pose of the SRDF shipped next to the URDF (`../srdf/*.srdf` or
/// `../../srdf/*.srdf`), joint name → angle: the package authors' own stand, independent of our
/// configs.
fn srdf_standing_pose(urdf: &Path) -> Vec<(String, f64)> {
    let srdf = [urdf.parent(), urdf.parent().and_then(Path::parent)]
        .into_iter()
        .flatten()
        .filter_map(|dir| std::fs::read_dir(dir.join("../srdf")).ok())
        .flatten()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "srdf"))
        .unwrap_or_else(|| panic!("no SRDF next to {}", urdf.display()));
    let text = std::fs::read_to_string(&srdf).expect("SRDF readable");
    let start = text
        .find("<group_state name=\"standing\"")
        .unwrap_or_else(|| panic!("no standing pose in {}", srdf.display()));
    let end = start
        + text[start..]
            .find("</group_state>")
            .expect("group_state closed");
    text[start..end]
        .split("<joint ")
        .skip(1)
        .filter_map(|element| {
            let attribute = |key: &str| {
                let from = element.find(&format!("{key}=\""))? + key.len() + 2;
                let to = from + element[from..].find('"')?;
                Some(element[from..to].to_string())
            };
            let value = attribute("value")?.trim().parse::<f64>().ok()?;
            Some((attribute("name")?, value))
        })
        .collect()
}

#[test]
fn stand_pose_bends_the_joints_like_the_packages_own_standing_pose() {
    for robot in load_all() {
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
