//! A robot config resolved the way the controller's loader reads it, as plain data for tools in
//! other languages: the simulation harness builds its physics model from this description (via
//! `pf-robot describe CONFIG`), so the config's keys, defaults and checks live here only.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::package_path::PACKAGE_SCHEME;
use super::{KneeDirection, PackagePath, RobotConfig};
use crate::api::{Leg, ModelError};
use crate::model::{foot_sphere_radius, is_massless_frame, RobotModel};

/// One leg under the controller's leg name, in the URDF's own names.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LegDescription {
    /// FR, FL, RR or RL.
    pub label: &'static str,
    /// Abduction, hip flexion, knee: the actuated joints from the base outwards.
    pub joints: [String; 3],
    /// The link the foot point is given in.
    pub foot_link: String,
    /// Foot point (sphere centre) in `foot_link`'s frame, m.
    pub foot_offset: [f64; 3],
    /// Joint angles a simulation places the robot in before its stand-up, rad (if configured).
    pub crouch: Option<[f64; 3]>,
    /// `backward` or `forward`.
    pub knee_points: &'static str,
    /// Whether the URDF gives `foot_link` a sphere collision centred on the foot point.
    pub has_foot_sphere: bool,
}

/// A robot config and its URDF, resolved and checked by loading the controller's model.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotDescription {
    /// The config file.
    pub config: PathBuf,
    /// The URDF it names, resolved.
    pub urdf: PathBuf,
    /// The floating base link.
    pub base_link: String,
    /// Nominal stand height, m.
    pub stand_height: f64,
    /// The feet's radius (their sphere collisions, else the config's `foot_radius`), m.
    pub foot_radius: f64,
    /// The whole robot's mass as the controller models it (links with mass), kg.
    pub mass: f64,
    /// Frames without mass: the config's `massless_links`, then the URDF's links without
    /// `<inertial>`.
    pub massless_links: Vec<String>,
    /// The config's `limits.effort` (abduction, hip, knee; N·m), overriding the URDF's.
    pub effort_limits: Option<[f64; 3]>,
    /// Legs in the controller's order (FR, FL, RR, RL).
    pub legs: Vec<LegDescription>,
    /// Packages the URDF names by `package://NAME/...`, with the folder each resolves to.
    pub package_dirs: Vec<(String, PathBuf)>,
    /// Files the URDF names (meshes), resolved, sorted.
    pub mesh_files: Vec<PathBuf>,
}

/// Describes the robot config at `path`; `package://` resolves through `packages`. Fails with the
/// loader's error when the controller could not run the robot, and when a file the URDF names
/// cannot be found.
pub fn describe_robot_config(
    path: &Path,
    packages: &PackagePath,
) -> Result<RobotDescription, ModelError> {
    let config = RobotConfig::from_file(path)?;
    let urdf_path = config.urdf_path(path, packages)?;
    let urdf_file = urdf_path.display().to_string();
    let xml = std::fs::read_to_string(&urdf_path).map_err(|e| ModelError::Io {
        path: urdf_file.clone(),
        reason: e.to_string(),
    })?;
    let robot = urdf_rs::read_from_string(&xml)
        .map_err(|e| ModelError::Parse(e.to_string()).in_file(&urdf_file))?;
    let model =
        RobotModel::from_parsed_urdf(&robot, &config, &path.display().to_string(), &urdf_file)?;
    let legs = Leg::ALL
        .into_iter()
        .map(|leg| {
            let leg_config = config.legs.get(leg);
            let foot_offset = leg_config.foot_offset.unwrap_or([0.0; 3]);
            let has_foot_sphere = robot
                .links
                .iter()
                .find(|l| l.name == leg_config.foot_link)
                .and_then(|link| foot_sphere_radius(link, foot_offset))
                .is_some();
            LegDescription {
                label: leg.name(),
                joints: leg_config.joints.clone(),
                foot_link: leg_config.foot_link.clone(),
                foot_offset,
                crouch: leg_config.crouch,
                knee_points: match leg_config.knee_points {
                    KneeDirection::Backward => "backward",
                    KneeDirection::Forward => "forward",
                },
                has_foot_sphere,
            }
        })
        .collect();
    let mut massless_links = config.massless_links.clone();
    for link in &robot.links {
        if is_massless_frame(link) && !massless_links.contains(&link.name) {
            massless_links.push(link.name.clone());
        }
    }
    let urdf_dir = urdf_path.parent().unwrap_or_else(|| Path::new("."));
    let mut meshes = BTreeSet::new();
    let mut package_dirs: Vec<(String, PathBuf)> = Vec::new();
    for reference in mesh_references(&robot) {
        let mesh = packages
            .resolve(reference.trim_start_matches("file://"), urdf_dir)
            .map_err(|reason| {
                ModelError::Missing(format!("a mesh: {reason}")).in_file(&urdf_file)
            })?;
        if let Some(package) = reference
            .strip_prefix(PACKAGE_SCHEME)
            .and_then(|rest| rest.split('/').next())
        {
            if !package_dirs.iter().any(|(name, _)| name == package) {
                if let Some(dir) = packages.package_dir(package) {
                    package_dirs.push((package.to_string(), dir));
                }
            }
        }
        meshes.insert(mesh);
    }
    Ok(RobotDescription {
        config: path.to_path_buf(),
        urdf: urdf_path,
        base_link: config.base_link.clone(),
        stand_height: config.stand_height,
        foot_radius: model.foot_radius(),
        mass: model.total_mass(),
        massless_links,
        effort_limits: config.limits.effort,
        legs,
        package_dirs,
        mesh_files: meshes.into_iter().collect(),
    })
}

/// Every mesh file name of the URDF's visuals and collisions, in document order.
fn mesh_references(robot: &urdf_rs::Robot) -> Vec<&str> {
    let geometries = robot.links.iter().flat_map(|link| {
        link.visual
            .iter()
            .map(|v| &v.geometry)
            .chain(link.collision.iter().map(|c| &c.geometry))
    });
    geometries
        .filter_map(|geometry| match geometry {
            urdf_rs::Geometry::Mesh { filename, .. } => Some(filename.as_str()),
            _ => None,
        })
        .collect()
}
