//! Checking a robot config the way a new user needs it: every problem found in one run, each
//! with the line that fixes it, and the values a config needs (stand height, knee branches,
//! crouch) proposed from the package's own SRDF `standing` pose.
//!
//! The loader ([`RobotModel`]) stops at the first error; the check applies each fix it proposes
//! to a copy of the config and loads again, so later problems surface in the same run.

use std::path::{Path, PathBuf};

use super::foot_mesh::{measure_foot_radius, FootMeshRadius, STANCE_PITCH_RANGE};
use super::srdf::{standing_pose_near, GroupState};
use super::{KneeDirection, PackagePath, RobotConfig};
use crate::api::{Leg, ModelError, NUM_JOINTS};
use crate::model::{unusable_inertials, RobotModel};
use crate::tuning::{swing_speed_share, SWING_SPEED_SHARE, TUNED_STAND_HEIGHT};
use crate::ControllerConfig;

/// Stand height proposals and the configured value may differ by this much before the check
/// reports it, m.
pub const STAND_HEIGHT_TOLERANCE: f64 = 0.01;
/// Limits at or beyond these are placeholders, not an actuator's (URDF exporters write 1000).
const PLACEHOLDER_EFFORT: f64 = 1000.0;
const PLACEHOLDER_VELOCITY: f64 = 1000.0;
/// Loads tried before the check gives up on a config it cannot repair.
const MAX_ROUNDS: usize = 12;
/// Stand heights tried to get a loadable model when the configured one is unreachable, m.
const PROBE_HEIGHTS: std::ops::RangeInclusive<u32> = 4..=60;
const PROBE_STEP: f64 = 0.025;
/// Foot radius assumed to go on checking a robot whose feet are meshes without `foot_radius`, m.
const PROVISIONAL_FOOT_RADIUS: f64 = 0.02;

/// One problem of the config, with the config line that fixes it when the check knows one.
#[derive(Clone, Debug, PartialEq)]
pub struct Finding {
    /// The config key concerned (`stand_height`, `legs.RR.knee_points`, …).
    pub key: String,
    /// What is wrong.
    pub problem: String,
    /// The TOML that fixes it, if known.
    pub fix: Option<String>,
}

/// Values the check proposes for one leg.
#[derive(Clone, Debug, PartialEq)]
pub struct LegProposal {
    /// The leg.
    pub leg: Leg,
    /// Knee branch of the SRDF stand.
    pub knee_points: KneeDirection,
    /// Crouch: the SRDF stand's hip and knee angles, abduction 0, inside the limits.
    pub crouch: [f64; 3],
}

/// Everything the check found.
#[derive(Clone, Debug, Default)]
pub struct RobotCheck {
    /// Problems, in the order found.
    pub findings: Vec<Finding>,
    /// Facts worth knowing that are not problems (how the tuning was adapted, …).
    pub notes: Vec<String>,
    /// The SRDF the proposals come from.
    pub srdf: Option<PathBuf>,
    /// Base origin above the soles in the SRDF stand, m.
    pub stand_height: Option<f64>,
    /// Per-leg proposals from the SRDF stand.
    pub legs: Vec<LegProposal>,
    /// The foot radius measured from the foot meshes, for a config that needs one.
    pub foot_mesh: Option<FootMeshRadius>,
    /// The model loaded from the config with every proposed fix applied.
    pub model: Option<RobotModel>,
}

impl RobotCheck {
    fn find(&mut self, key: impl Into<String>, problem: impl Into<String>, fix: Option<String>) {
        self.findings.push(Finding {
            key: key.into(),
            problem: problem.into(),
            fix,
        });
    }
}

fn knee_name(knee: KneeDirection) -> &'static str {
    match knee {
        KneeDirection::Backward => "backward",
        KneeDirection::Forward => "forward",
    }
}

fn toml_list(names: &[String]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("\"{n}\"")).collect();
    format!("[{}]", quoted.join(", "))
}

/// Checks the robot config at `path` (URDF through `packages`), proposing values from the SRDF
/// at `srdf` or, when `None`, the first `standing` pose of an SRDF next to the URDF.
pub fn check_robot_config(path: &Path, packages: &PackagePath, srdf: Option<&Path>) -> RobotCheck {
    let mut check = RobotCheck::default();
    let mut config = match RobotConfig::from_file(path) {
        Ok(config) => config,
        Err(e) => {
            check.find("config", e.to_string(), None);
            return check;
        }
    };
    let (urdf_path, robot) = match read_urdf(&config, path, packages) {
        Ok(read) => read,
        Err(problem) => {
            check.find("urdf", problem, None);
            return check;
        }
    };
    let standing = match srdf {
        Some(file) => std::fs::read_to_string(file)
            .ok()
            .and_then(|text| super::srdf::group_state(&text, "standing", file)),
        None => standing_pose_near(&urdf_path),
    };
    check.srdf = standing.as_ref().map(|s| s.file.clone());
    check_base_link(&robot, &mut config, &mut check);
    if !check_inertials(&robot, &mut config, &mut check) {
        return check;
    }
    let urdf = ParsedUrdf {
        robot,
        config_file: path.display().to_string(),
        urdf_file: urdf_path.display().to_string(),
    };
    let configured_radius = config.foot_radius;
    let Some(mut model) = load_repairing(&mut config, &urdf, &mut check) else {
        return check;
    };
    if configured_radius.is_none() && config.foot_radius.is_some() {
        let urdf_dir = urdf_path.parent().unwrap_or_else(|| Path::new("."));
        let feet = MeshFeet {
            urdf: &urdf,
            standing: standing.as_ref(),
            packages,
            urdf_dir,
        };
        match feet.measure(&mut model, &mut config) {
            Ok(measured) => {
                report_foot_radius(&measured, &mut check);
                check.foot_mesh = Some(measured);
            }
            Err(why) => check
                .notes
                .push(format!("the foot radius could not be measured: {why}")),
        }
    }
    check_limits(&model, &config, &mut check);
    let model = match &standing {
        Some(standing) => check_against_srdf(model, &mut config, &urdf, standing, &mut check),
        None => {
            check.notes.push(format!(
                "no SRDF with a `standing` pose next to {}: stand height, knee branches and crouch are not checked (give one with --srdf)",
                urdf_path.display()
            ));
            model
        }
    };
    note_tuning(&model, &mut check);
    check.model = Some(model);
    check
}

/// A robot config's URDF, parsed once for every load the check tries.
struct ParsedUrdf {
    robot: urdf_rs::Robot,
    /// Names the config and the URDF in errors.
    config_file: String,
    urdf_file: String,
}

impl ParsedUrdf {
    fn load(&self, config: &RobotConfig) -> Result<RobotModel, ModelError> {
        RobotModel::from_parsed_urdf(&self.robot, config, &self.config_file, &self.urdf_file)
    }
}

/// The URDF a config names: its path and parsed tree, or why not.
fn read_urdf(
    config: &RobotConfig,
    path: &Path,
    packages: &PackagePath,
) -> Result<(PathBuf, urdf_rs::Robot), String> {
    let urdf_path = config
        .urdf_path(path, packages)
        .map_err(|e| e.to_string())?;
    let xml = std::fs::read_to_string(&urdf_path)
        .map_err(|e| format!("cannot read {}: {e}", urdf_path.display()))?;
    let robot = urdf_rs::read_from_string(&xml)
        .map_err(|e| format!("cannot parse {}: {e}", urdf_path.display()))?;
    Ok((urdf_path, robot))
}

/// The base link must be the URDF tree's root.
fn check_base_link(robot: &urdf_rs::Robot, config: &mut RobotConfig, check: &mut RobotCheck) {
    let children: std::collections::HashSet<&str> =
        robot.joints.iter().map(|j| j.child.link.as_str()).collect();
    let roots: Vec<&str> = robot
        .links
        .iter()
        .map(|l| l.name.as_str())
        .filter(|name| !children.contains(name))
        .collect();
    if let [root] = roots[..] {
        if root != config.base_link {
            check.find(
                "base_link",
                format!(
                    "`{}` is not the root of the URDF tree; the root is `{root}`",
                    config.base_link
                ),
                Some(format!("base_link = \"{root}\"")),
            );
            config.base_link = root.to_string();
        }
    }
}

/// Every unusable inertial at once; placeholders are declared massless to go on. False when an
/// inertial is broken beyond that (negative or non-finite values).
fn check_inertials(
    robot: &urdf_rs::Robot,
    config: &mut RobotConfig,
    check: &mut RobotCheck,
) -> bool {
    let problems = match unusable_inertials(robot, &config.massless_links) {
        Ok(problems) => problems,
        Err(e) => {
            check.find("urdf", e.to_string(), None);
            return false;
        }
    };
    let (placeholders, broken): (Vec<_>, Vec<_>) =
        problems.into_iter().partition(|p| p.placeholder);
    for problem in &broken {
        check.find("urdf", problem.text.clone(), None);
    }
    if !placeholders.is_empty() {
        let texts: Vec<&str> = placeholders.iter().map(|p| p.text.as_str()).collect();
        config
            .massless_links
            .extend(placeholders.iter().map(|p| p.link.clone()));
        check.find(
            "massless_links",
            format!(
                "{} (placeholder inertials: make them massless frames)",
                texts.join("; ")
            ),
            Some(format!(
                "massless_links = {}",
                toml_list(&config.massless_links)
            )),
        );
    }
    broken.is_empty()
}

/// Loads the model, repairing what the check can propose a value for (an unreachable stand
/// height, a crouch outside the limits, a missing foot radius) and recording each problem.
fn load_repairing(
    config: &mut RobotConfig,
    urdf: &ParsedUrdf,
    check: &mut RobotCheck,
) -> Option<RobotModel> {
    let mut probing_height = false;
    for _ in 0..MAX_ROUNDS {
        let error = match urdf.load(config) {
            Ok(model) => return Some(model),
            Err(e) => e,
        };
        let key = error.config_key().unwrap_or("urdf").to_string();
        if key == "stand_height" {
            if !probing_height {
                check.find(key, error.to_string(), None);
                probing_height = true;
            }
            // Any reachable height gives the model the SRDF check proposes the real one from.
            let reachable = PROBE_HEIGHTS.map(|k| f64::from(k) * PROBE_STEP).find(|h| {
                let probe = RobotConfig {
                    stand_height: *h,
                    ..config.clone()
                };
                urdf.load(&probe).is_ok()
            });
            match reachable {
                Some(height) => config.stand_height = height,
                None => return None,
            }
        } else if key.starts_with("legs.") && key.ends_with(".crouch") {
            check.find("legs.*.crouch", error.to_string(), None);
            for leg in Leg::ALL {
                leg_config_mut(config, leg).crouch = None;
            }
        } else if key == "foot_radius" && config.foot_radius.is_none() {
            let fix = "foot_radius = <radius of the foot's sole curvature, m>".to_string();
            check.find(key, error.to_string(), Some(fix));
            config.foot_radius = Some(PROVISIONAL_FOOT_RADIUS);
        } else {
            check.find(key, error.to_string(), None);
            return None;
        }
    }
    None
}

fn leg_config_mut(config: &mut RobotConfig, leg: Leg) -> &mut super::LegConfig {
    match leg {
        Leg::FR => &mut config.legs.FR,
        Leg::FL => &mut config.legs.FL,
        Leg::RR => &mut config.legs.RR,
        Leg::RL => &mut config.legs.RL,
    }
}

/// Leg angles of the stand the foot mesh is measured in: the SRDF's where it names every joint,
/// else the model's own stand.
fn stand_angles(
    model: &RobotModel,
    config: &RobotConfig,
    standing: Option<&GroupState>,
) -> [[f64; 3]; 4] {
    let own = model
        .stand_joint_positions(model.stand_height())
        .unwrap_or([0.0; NUM_JOINTS]);
    Leg::ALL.map(|leg| {
        standing
            .and_then(|s| srdf_leg_angles(config, s, leg))
            .unwrap_or_else(|| {
                let l = 3 * leg.index();
                [own[l], own[l + 1], own[l + 2]]
            })
    })
}

/// Where a config's mesh feet are measured.
struct MeshFeet<'a> {
    urdf: &'a ParsedUrdf,
    standing: Option<&'a GroupState>,
    packages: &'a PackagePath,
    urdf_dir: &'a Path,
}

/// Measurements before the stand pose (which depends on the radius) stops moving.
const FOOT_RADIUS_ROUNDS: usize = 4;

impl MeshFeet<'_> {
    /// Measures the feet in the stand pose, sets the radius in `config` and reloads `model`
    /// with it, until the stand (which depends on the radius) and the radius agree.
    fn measure(
        &self,
        model: &mut RobotModel,
        config: &mut RobotConfig,
    ) -> Result<FootMeshRadius, String> {
        let mut round = 1;
        loop {
            let stand = stand_angles(model, config, self.standing);
            let feet = measure_foot_radius(
                &self.urdf.robot,
                config,
                model,
                &stand,
                self.packages,
                self.urdf_dir,
            )?;
            // A tenth of a millimetre: finer than any sole is made to.
            let radius = (feet.radius * 1e4).round() / 1e4;
            let settled = config.foot_radius == Some(radius);
            config.foot_radius = Some(radius);
            if let Ok(reloaded) = self.urdf.load(config) {
                *model = reloaded;
            }
            if settled || round == FOOT_RADIUS_ROUNDS {
                return Ok(feet);
            }
            round += 1;
        }
    }
}

/// Makes the measured radius the fix of the missing-radius finding.
fn report_foot_radius(measured: &FootMeshRadius, check: &mut RobotCheck) {
    if let Some(finding) = check.findings.iter_mut().find(|f| f.key == "foot_radius") {
        finding.fix = Some(format!(
            "foot_radius = {:.4}  # lowest point of {} below the foot point in the stand",
            measured.radius,
            measured.meshes.join(", ")
        ));
    }
    let (low, high) = measured.stance_range;
    check.notes.push(format!(
        "foot meshes reach {:.1}–{:.1} mm below the foot point while the foot pitches ±{:.0}° about the stand{}",
        1e3 * low,
        1e3 * high,
        STANCE_PITCH_RANGE.to_degrees(),
        if measured.legs_differ() {
            ": the legs' feet differ by more than 1 mm, the largest is proposed"
        } else {
            ""
        }
    ));
}

/// Placeholder effort and velocity limits (exporters write 1000): the controller would clamp
/// nothing and the tuning would not respect the real motors.
fn check_limits(model: &RobotModel, config: &RobotConfig, check: &mut RobotCheck) {
    for (what, values, placeholder, set) in [
        (
            "effort",
            model.effort_limits(),
            PLACEHOLDER_EFFORT,
            config.limits.effort.is_some(),
        ),
        (
            "velocity",
            model.velocity_limits(),
            PLACEHOLDER_VELOCITY,
            config.limits.velocity.is_some(),
        ),
    ] {
        if !set && values.iter().any(|v| *v >= placeholder) {
            check.find(
                format!("limits.{what}"),
                format!(
                    "the URDF's {what} limits ({:?}) look like placeholders",
                    &values[..3]
                ),
                Some(format!(
                    "[limits] {what} = [<abduction>, <hip>, <knee>] from the actuators' data sheet"
                )),
            );
        }
    }
}

/// Leg angles of the SRDF stand in the controller's order, if the state names every joint.
fn srdf_leg_angles(config: &RobotConfig, standing: &GroupState, leg: Leg) -> Option<[f64; 3]> {
    let joints = &config.legs.get(leg).joints;
    Some([
        standing.angle(&joints[0])?,
        standing.angle(&joints[1])?,
        standing.angle(&joints[2])?,
    ])
}

/// Knee side of the hip–foot line at `q`: the knee joint's x against the line's x at its height.
fn knee_side(model: &RobotModel, leg: Leg, q: [f64; 3]) -> KneeDirection {
    let [_, hip, knee] = model.joint_positions_body(leg, q);
    let foot = model.foot_position_body(leg, q);
    let along = if (foot[2] - hip[2]).abs() > 1e-9 {
        (knee[2] - hip[2]) / (foot[2] - hip[2])
    } else {
        0.5
    };
    let line_x = hip[0] + (foot[0] - hip[0]) * along;
    if knee[0] < line_x {
        KneeDirection::Backward
    } else {
        KneeDirection::Forward
    }
}

/// Stand height, knee branches and crouch against the SRDF stand; the returned model has the
/// proposals applied.
fn check_against_srdf(
    model: RobotModel,
    config: &mut RobotConfig,
    urdf: &ParsedUrdf,
    standing: &GroupState,
    check: &mut RobotCheck,
) -> RobotModel {
    let (lower, upper) = (model.lower_limits(), model.upper_limits());
    let mut heights = Vec::new();
    for leg in Leg::ALL {
        let Some(q) = srdf_leg_angles(config, standing, leg) else {
            check.notes.push(format!(
                "{} has no angle for every joint of leg {}: not compared",
                standing.file.display(),
                leg.name()
            ));
            continue;
        };
        heights.push(model.foot_radius() - model.foot_position_body(leg, q)[2]);
        let knee_points = knee_side(&model, leg, q);
        let l = 3 * leg.index();
        let clamp = |j: usize, v: f64| v.clamp(lower[l + j], upper[l + j]);
        let crouch = [clamp(0, 0.0), clamp(1, q[1]), clamp(2, q[2])];
        let leg_config = leg_config_mut(config, leg);
        if leg_config.knee_points != knee_points {
            check.find(
                format!("legs.{}.knee_points", leg.name()),
                format!(
                    "the SRDF stand bends the knee {} of the hip–foot line, the config says `{}`",
                    knee_name(knee_points),
                    knee_name(leg_config.knee_points)
                ),
                Some(format!("knee_points = \"{}\"", knee_name(knee_points))),
            );
            leg_config.knee_points = knee_points;
        }
        if leg_config.crouch.is_none() {
            check.find(
                format!("legs.{}.crouch", leg.name()),
                "no crouch: a simulation (the DART harness) has no pose to place the robot in before its stand-up",
                Some(format!("crouch = [{:.3}, {:.3}, {:.3}]", crouch[0], crouch[1], crouch[2])),
            );
            leg_config.crouch = Some(crouch);
        }
        check.legs.push(LegProposal {
            leg,
            knee_points,
            crouch,
        });
    }
    if heights.len() == NUM_JOINTS / 3 {
        let height = heights.iter().sum::<f64>() / heights.len() as f64;
        check.stand_height = Some(height);
        if (config.stand_height - height).abs() > STAND_HEIGHT_TOLERANCE {
            check.find(
                "stand_height",
                format!(
                    "{:.3} m, but the SRDF stand puts the base origin {height:.3} m above the soles",
                    config.stand_height
                ),
                Some(format!("stand_height = {height:.3}")),
            );
            config.stand_height = height;
        }
    }
    match urdf.load(config) {
        Ok(repaired) => repaired,
        Err(e) => {
            check.find(
                e.config_key().unwrap_or("urdf"),
                format!("with the proposals applied: {e}"),
                None,
            );
            model
        }
    }
}

/// How the default tuning carries over to this robot.
fn note_tuning(model: &RobotModel, check: &mut RobotCheck) {
    let tuning = ControllerConfig::for_robot(model);
    let length = model.stand_height() / TUNED_STAND_HEIGHT;
    let defaults = ControllerConfig::default();
    check.notes.push(format!(
        "{:.3} kg standing {:.3} m: default tuning scaled by mass × {:.2}, length × {:.2}; swing {:.3} m every {:.3} s at {:.0} % of the joints' velocity limits (aimed at ≤ {:.0} %)",
        model.total_mass(),
        model.stand_height(),
        model.total_mass() / crate::tuning::TUNED_MASS,
        length,
        tuning.swing_height,
        tuning.gait_period,
        100.0 * swing_speed_share(model, &tuning),
        100.0 * SWING_SPEED_SHARE
    ));
    if tuning.swing_height < defaults.swing_height * length - 1e-9 {
        check.notes.push(format!(
            "the swing was lowered from {:.3} m so the joints stay within their velocity limits",
            defaults.swing_height * length
        ));
    }
    let share = swing_speed_share(model, &tuning);
    if share > SWING_SPEED_SHARE + 1e-9 {
        check.notes.push(format!(
            "even the lowest swing asks {:.0} % of a joint's velocity limit: the stride at {} m/s does; the swing feet will lag, and the contact detector ignores a leg whose joint is at its limit",
            100.0 * share,
            crate::tuning::SWING_CHECK_SPEED
        ));
    }
}
