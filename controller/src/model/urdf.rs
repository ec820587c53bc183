//! Building the model from a URDF document and its robot config: indexing the link/joint tree,
//! merging fixed-joint clusters into mass properties and extracting the three-joint leg chains the
//! config names. All validation of the input lives here, so a model that was built is known to be
//! well-formed; every error names the file it was found in.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::{ChainJoint, LegChain, LegGeometry, MassProperties, RobotModel, Transform};
use crate::api::{Leg, ModelError, NUM_JOINTS};
use crate::robot_config::{KeyProblem, LegConfig, PackagePath, RobotConfig};

/// Principal moments may break the triangle inequality by this relative amount (rounding in
/// published values) before the inertia is refused as physically impossible.
const TRIANGLE_TOLERANCE: f64 = 1e-6;

/// Names of the two descriptions in error messages.
struct Sources<'a> {
    config: &'a str,
    urdf: &'a str,
}

fn finite3(v: &[f64; 3], what: &str) -> Result<(), ModelError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ModelError::InvalidValue(format!(
            "{what} is not finite: {v:?}"
        )))
    }
}

/// A link with zero mass and zero inertia (what a link without `<inertial>` reads as): a frame.
pub(crate) fn is_massless_frame(link: &urdf_rs::Link) -> bool {
    let i = &link.inertial.inertia;
    link.inertial.mass.value == 0.0
        && [i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz]
            .iter()
            .all(|v| *v == 0.0)
}

/// Mass properties of one link. A link with zero mass and zero inertia (or no `<inertial>`) is a
/// massless frame; a link listed in `massless_links` is made one. Anything else needs a positive
/// mass and a positive-definite inertia whose principal moments satisfy the triangle inequality.
fn link_mass_properties(
    link: &urdf_rs::Link,
    massless: bool,
) -> Result<MassProperties, ModelError> {
    let massless_frame = MassProperties {
        mass: 0.0,
        com: Vector3::zeros(),
        inertia_com: Matrix3::zeros(),
    };
    if massless {
        return Ok(massless_frame);
    }
    let inertial = &link.inertial;
    let mass = inertial.mass.value;
    if !mass.is_finite() || mass < 0.0 {
        return Err(ModelError::InvalidValue(format!(
            "mass of link `{}` is {mass}",
            link.name
        )));
    }
    finite3(
        &inertial.origin.xyz,
        &format!("inertial origin of link `{}`", link.name),
    )?;
    finite3(
        &inertial.origin.rpy,
        &format!("inertial rpy of link `{}`", link.name),
    )?;
    let i = &inertial.inertia;
    let inertia = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    if inertia.iter().any(|x| !x.is_finite()) {
        return Err(ModelError::InvalidValue(format!(
            "inertia of link `{}` is not finite",
            link.name
        )));
    }
    if mass == 0.0 {
        if !is_massless_frame(link) {
            return Err(ModelError::InvalidValue(format!(
                "link `{}` has zero mass but a non-zero inertia",
                link.name
            )));
        }
        return Ok(massless_frame);
    }
    check_inertia(&link.name, &inertia)?;
    let pose = Transform::from_pose(&inertial.origin);
    Ok(MassProperties {
        mass,
        com: pose.translation,
        inertia_com: pose.rotation * inertia * pose.rotation.transpose(),
    })
}

/// Every link's inertial checked at once, so a URDF with several placeholder inertials is fixed
/// in one round: the error lists them all and the `massless_links` line that accepts them.
fn check_all_inertials(
    robot: &urdf_rs::Robot,
    tree: &Tree<'_>,
    config: &RobotConfig,
) -> Result<(), ModelError> {
    let problems = inertial_problems(robot, tree);
    let placeholders: Vec<&str> = problems
        .iter()
        .filter(|p| p.placeholder)
        .map(|p| p.link.as_str())
        .collect();
    let text = problems
        .iter()
        .map(|p| p.text.as_str())
        .collect::<Vec<_>>()
        .join("; ");
    match (problems.len(), placeholders.len()) {
        (0, _) => Ok(()),
        (_, 0) => Err(ModelError::InvalidValue(text)),
        (_, n) => {
            let massless: Vec<String> = config
                .massless_links
                .iter()
                .map(String::as_str)
                .chain(placeholders)
                .map(|name| format!("\"{name}\""))
                .collect();
            Err(ModelError::InvalidValue(format!(
                "{text}; if {} placeholder{}, set `massless_links = [{}]` in the robot config (the links become massless frames)",
                if n == 1 { "it is a" } else { "they are" },
                if n == 1 { "" } else { "s" },
                massless.join(", ")
            )))
        }
    }
}

/// A link whose inertial the model cannot use.
pub(crate) struct InertialProblem {
    pub link: String,
    pub text: String,
    /// Impossible principal moments: what placeholder inertials look like. A negative or
    /// non-finite value is an error in the file, not something to declare massless.
    pub placeholder: bool,
}

fn inertial_problems(robot: &urdf_rs::Robot, tree: &Tree<'_>) -> Vec<InertialProblem> {
    robot
        .links
        .iter()
        .filter_map(|link| {
            let text = match tree.mass_properties(link).err()? {
                ModelError::InvalidValue(text) => text,
                other => other.to_string(),
            };
            Some(InertialProblem {
                link: link.name.clone(),
                placeholder: text.contains("principal moments"),
                text,
            })
        })
        .collect()
}

/// Every link of `robot` whose inertial the model refuses, with `massless` links exempt.
pub(crate) fn unusable_inertials(
    robot: &urdf_rs::Robot,
    massless: &[String],
) -> Result<Vec<InertialProblem>, ModelError> {
    let tree = Tree::new(robot, massless)?;
    Ok(inertial_problems(robot, &tree))
}

fn check_inertia(link: &str, inertia: &Matrix3<f64>) -> Result<(), ModelError> {
    let mut moments: Vec<f64> = SymmetricEigen::new(*inertia)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    moments.sort_by(f64::total_cmp);
    if moments[0] <= moments[2] * 1e-9 || moments[2] <= 0.0 {
        return Err(ModelError::InvalidValue(format!(
            "inertia of link `{link}` is not positive definite (principal moments {})",
            format_moments(&moments)
        )));
    }
    if moments[0] + moments[1] < moments[2] * (1.0 - TRIANGLE_TOLERANCE) {
        return Err(ModelError::InvalidValue(format!(
            "inertia of link `{link}` breaks the triangle inequality (principal moments {})",
            format_moments(&moments)
        )));
    }
    Ok(())
}

fn format_moments(moments: &[f64]) -> String {
    moments
        .iter()
        .map(|m| format!("{m:.3e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Indexed view of the URDF tree.
struct Tree<'a> {
    links: HashMap<&'a str, &'a urdf_rs::Link>,
    parent_joint: HashMap<&'a str, &'a urdf_rs::Joint>,
    child_joints: HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    massless: HashSet<&'a str>,
}

impl<'a> Tree<'a> {
    fn new(robot: &'a urdf_rs::Robot, massless: &'a [String]) -> Result<Self, ModelError> {
        let mut links = HashMap::new();
        for link in &robot.links {
            if links.insert(link.name.as_str(), link).is_some() {
                return Err(ModelError::Structure(format!(
                    "duplicate link `{}`",
                    link.name
                )));
            }
        }
        let mut parent_joint = HashMap::new();
        let mut child_joints: HashMap<&str, Vec<&urdf_rs::Joint>> = HashMap::new();
        for joint in &robot.joints {
            for end in [&joint.parent.link, &joint.child.link] {
                if !links.contains_key(end.as_str()) {
                    return Err(ModelError::Structure(format!(
                        "joint `{}` refers to unknown link `{end}`",
                        joint.name
                    )));
                }
            }
            if parent_joint
                .insert(joint.child.link.as_str(), joint)
                .is_some()
            {
                return Err(ModelError::Structure(format!(
                    "link `{}` has two parent joints",
                    joint.child.link
                )));
            }
            child_joints
                .entry(joint.parent.link.as_str())
                .or_default()
                .push(joint);
        }
        Ok(Tree {
            links,
            parent_joint,
            child_joints,
            massless: massless.iter().map(String::as_str).collect(),
        })
    }

    fn link(&self, name: &str) -> Result<&'a urdf_rs::Link, ModelError> {
        self.links
            .get(name)
            .copied()
            .ok_or_else(|| ModelError::Missing(format!("link `{name}`")))
    }

    fn mass_properties(&self, link: &urdf_rs::Link) -> Result<MassProperties, ModelError> {
        link_mass_properties(link, self.massless.contains(link.name.as_str()))
    }

    /// Mass properties of `link` plus everything attached to it through fixed joints, in the
    /// frame of `link`.
    fn rigid_cluster(&self, link: &str, depth: usize) -> Result<MassProperties, ModelError> {
        if depth > 64 {
            return Err(ModelError::Structure(
                "kinematic tree too deep or cyclic".into(),
            ));
        }
        let mut props = self.mass_properties(self.link(link)?)?;
        for joint in self.child_joints.get(link).into_iter().flatten() {
            if joint.joint_type == urdf_rs::JointType::Fixed {
                check_origin(joint)?;
                let child = self.rigid_cluster(&joint.child.link, depth + 1)?;
                props.merge(&child, &Transform::from_pose(&joint.origin));
            }
        }
        Ok(props)
    }

    /// Joints from `base` down to `tip`, base-most first.
    fn path(&self, base: &str, tip: &str) -> Result<Vec<&'a urdf_rs::Joint>, ModelError> {
        let mut path = Vec::new();
        let mut link = tip;
        while link != base {
            let joint = self.parent_joint.get(link).ok_or_else(|| {
                ModelError::Structure(format!("link `{tip}` is not below the base link `{base}`"))
            })?;
            path.push(*joint);
            if path.len() > 64 {
                return Err(ModelError::Structure(
                    "kinematic tree too deep or cyclic".into(),
                ));
            }
            link = joint.parent.link.as_str();
        }
        path.reverse();
        Ok(path)
    }
}

fn check_origin(joint: &urdf_rs::Joint) -> Result<(), ModelError> {
    finite3(
        &joint.origin.xyz,
        &format!("origin xyz of joint `{}`", joint.name),
    )?;
    finite3(
        &joint.origin.rpy,
        &format!("origin rpy of joint `{}`", joint.name),
    )
}

/// How far (rad) an actuated joint's axis, in the base frame at q = 0, may lie from its
/// canonical direction: URDFs round their `rpy` (1.5708 for π/2 leaves 4e-6), and the closed-form
/// IK is only the Newton refinement's starting point, so a near-canonical axis solves exactly.
const AXIS_TOLERANCE: f64 = 1e-3;

/// The axis of an actuated joint, in the base frame at q = 0, must be ± `expected` (the
/// closed-form IK's layout); returns the sign.
fn axis_sign(
    joint: &urdf_rs::Joint,
    axis: &Vector3<f64>,
    expected: Vector3<f64>,
    role: &str,
) -> Result<f64, ModelError> {
    for sign in [1.0, -1.0] {
        if (axis - expected * sign).norm() < AXIS_TOLERANCE {
            return Ok(sign);
        }
    }
    Err(ModelError::Structure(format!(
        "{role} joint `{}` turns about ({:.4}, {:.4}, {:.4}) in the base frame at the zero pose \
         (its axis {:?} through the rotations of the joint origins above it); the controller \
         needs the abduction axis along the base's ±x and the hip and knee axes along ±y \
         (a leg whose axes are tilted out of that layout is not supported)",
        joint.name, axis.x, axis.y, axis.z, joint.axis.xyz
    )))
}

/// Limit of `joint` from the URDF unless overridden; missing (zero) without an override is an
/// error naming the joint.
fn joint_limit(
    joint: &urdf_rs::Joint,
    urdf_value: f64,
    overridden: Option<f64>,
    what: &str,
) -> Result<f64, ModelError> {
    if let Some(value) = overridden {
        return Ok(value);
    }
    if urdf_value.is_finite() && urdf_value > 0.0 {
        Ok(urdf_value)
    } else {
        Err(ModelError::InvalidValue(format!(
            "{what} limit of joint `{}` is {urdf_value} (missing or not positive in <limit>); \
             set `limits.{what}` in the robot config",
            joint.name
        )))
    }
}

const ROLES: [&str; 3] = ["abduction", "hip", "knee"];

fn build_leg(
    tree: &Tree<'_>,
    config: &RobotConfig,
    leg: Leg,
    leg_config: &LegConfig,
) -> Result<LegChain, ModelError> {
    let prefix = leg.name();
    let foot_link = leg_config.foot_link.as_str();
    tree.link(foot_link)?;
    let path = tree.path(&config.base_link, foot_link)?;
    for name in &leg_config.joints {
        if !path.iter().any(|j| &j.name == name) {
            let why = if tree.parent_joint.values().any(|j| &j.name == name) {
                "is not"
            } else {
                "does not exist"
            };
            return Err(ModelError::Missing(format!(
                "joint `{name}` of leg {prefix} ({why} on the chain from `{}` to `{foot_link}`)",
                config.base_link
            )));
        }
    }
    let moving: Vec<&str> = path
        .iter()
        .filter(|j| j.joint_type != urdf_rs::JointType::Fixed)
        .map(|j| j.name.as_str())
        .collect();
    if moving
        != leg_config
            .joints
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>()
    {
        return Err(ModelError::Structure(format!(
            "leg {prefix}: the chain from `{}` to `{foot_link}` must have exactly the actuated joints {:?} in that order (plus fixed joints), found {moving:?} ({} movable joints)",
            config.base_link,
            leg_config.joints,
            moving.len()
        )));
    }
    // The chain is stored in frames parallel to the base at q = 0: a joint frame rotated by Q
    // (the product of the origin rotations from the base) turns about Q·axis, and
    // Q·Rot(axis, q)·Qᵀ = Rot(Q·axis, q), so joint angles, limits and kinematics are the URDF's
    // while the closed-form IK sees its canonical layout. URDFs with rotated joint origins
    // (HyQ, ANYmal C) load as published.
    let mut joints = Vec::with_capacity(3);
    let mut orientation = Matrix3::identity();
    let mut translation = Vector3::zeros();
    for joint in &path {
        check_origin(joint)?;
        let origin = Transform::from_pose(&joint.origin);
        translation += orientation * origin.translation;
        orientation *= origin.rotation;
        if joint.joint_type == urdf_rs::JointType::Fixed {
            continue;
        }
        if joint.joint_type != urdf_rs::JointType::Revolute {
            return Err(ModelError::Structure(format!(
                "joint `{}` of leg {prefix} must be revolute, is {:?}",
                joint.name, joint.joint_type
            )));
        }
        finite3(&joint.axis.xyz, &format!("axis of joint `{}`", joint.name))?;
        let axis = Vector3::new(joint.axis.xyz[0], joint.axis.xyz[1], joint.axis.xyz[2]);
        let norm = axis.norm();
        if norm < 1e-9 {
            return Err(ModelError::InvalidValue(format!(
                "axis of joint `{}` is zero",
                joint.name
            )));
        }
        let limit = &joint.limit;
        if !(limit.lower.is_finite() && limit.upper.is_finite() && limit.lower < limit.upper) {
            return Err(ModelError::InvalidValue(format!(
                "position limits of joint `{}`: [{}, {}]",
                joint.name, limit.lower, limit.upper
            )));
        }
        let role = joints.len();
        let effort = joint_limit(
            joint,
            limit.effort,
            config.limits.effort.map(|v| v[role]),
            "effort",
        )?;
        let velocity = joint_limit(
            joint,
            limit.velocity,
            config.limits.velocity.map(|v| v[role]),
            "velocity",
        )?;
        joints.push(ChainJoint {
            pre: Transform {
                rotation: Matrix3::identity(),
                translation,
            },
            axis: orientation * axis / norm,
            body: tree
                .rigid_cluster(&joint.child.link, 0)?
                .rotated(&orientation),
            lower: limit.lower,
            upper: limit.upper,
            effort,
            velocity,
        });
        translation = Vector3::zeros();
    }
    let offset = Vector3::from(leg_config.foot_offset.unwrap_or([0.0; 3]));
    // The foot link's own frame at q = 0 (the rotation the chain's frames were folded by):
    // what its collision meshes are given in.
    let foot = Transform {
        rotation: orientation,
        translation: translation + orientation * offset,
    };
    let joints: [ChainJoint; 3] = joints
        .try_into()
        .map_err(|_| ModelError::Structure(format!("leg {prefix} does not have 3 joints")))?;
    // The rigid cluster of the knee's child already contains the foot (fixed joints), and the
    // clusters never overlap because each stops at the next moving joint.
    let axis_signs = [
        axis_sign(
            path_joint(&path, &leg_config.joints[0])?,
            &joints[0].axis,
            Vector3::x(),
            ROLES[0],
        )?,
        axis_sign(
            path_joint(&path, &leg_config.joints[1])?,
            &joints[1].axis,
            Vector3::y(),
            ROLES[1],
        )?,
        axis_sign(
            path_joint(&path, &leg_config.joints[2])?,
            &joints[2].axis,
            Vector3::y(),
            ROLES[2],
        )?,
    ];
    let thigh = joints[2].pre.translation;
    let calf = foot.translation;
    let thigh_length = thigh.x.hypot(thigh.z);
    let calf_length = calf.x.hypot(calf.z);
    if thigh_length < 1e-3 || calf_length < 1e-3 {
        return Err(ModelError::Structure(format!(
            "leg {prefix}: thigh ({thigh_length} m) or calf ({calf_length} m) length in the sagittal plane is below 1 mm"
        )));
    }
    let hip_origin = joints[1].pre.translation;
    let geometry = LegGeometry {
        abd_origin: joints[0].pre.translation,
        hip_origin,
        lateral_offset: hip_origin.y + thigh.y + calf.y,
        thigh_length,
        calf_length,
        thigh_angle: thigh.x.atan2(-thigh.z),
        calf_angle: calf.x.atan2(-calf.z),
        axis_signs,
        knee: leg_config.knee_points,
    };
    Ok(LegChain {
        joints,
        foot,
        geometry,
    })
}

fn path_joint<'a>(
    path: &[&'a urdf_rs::Joint],
    name: &str,
) -> Result<&'a urdf_rs::Joint, ModelError> {
    path.iter()
        .copied()
        .find(|j| j.name == name)
        .ok_or_else(|| ModelError::Missing(format!("joint `{name}`")))
}

/// Radius of the sphere collision of the foot link centred on the foot point, if there is one.
pub(crate) fn foot_sphere_radius(link: &urdf_rs::Link, offset: [f64; 3]) -> Option<f64> {
    link.collision.iter().find_map(|c| match c.geometry {
        urdf_rs::Geometry::Sphere { radius }
            if (Vector3::from(*c.origin.xyz) - Vector3::from(offset)).norm() < 1e-6 =>
        {
            Some(radius)
        }
        _ => None,
    })
}

/// Foot radius: the feet's sphere collisions, else the config's `foot_radius`. Errors are the
/// config's (`Ok(Err)`) or the URDF's (`Err`).
fn foot_radius(
    tree: &Tree<'_>,
    config: &RobotConfig,
) -> Result<Result<f64, KeyProblem>, ModelError> {
    let mut from_urdf: Option<(f64, &str)> = None;
    for leg in Leg::ALL {
        let leg_config = config.legs.get(leg);
        let link = tree.link(&leg_config.foot_link)?;
        let Some(radius) = foot_sphere_radius(link, leg_config.foot_offset.unwrap_or([0.0; 3]))
        else {
            continue;
        };
        if !(radius.is_finite() && radius > 0.0) {
            return Err(ModelError::InvalidValue(format!(
                "sphere radius {radius} of foot link `{}`",
                link.name
            )));
        }
        match from_urdf {
            Some((other, other_link)) if (other - radius).abs() > 1e-9 => {
                return Err(ModelError::Structure(format!(
                    "foot spheres differ: `{other_link}` has radius {other}, `{}` {radius}",
                    link.name
                )));
            }
            _ => from_urdf = Some((radius, link.name.as_str())),
        }
    }
    Ok(match (from_urdf, config.foot_radius) {
        (Some((radius, _)), None) => Ok(radius),
        (Some((radius, link)), Some(configured)) if (radius - configured).abs() > 1e-9 => Err(
            KeyProblem::of("foot_radius", format!("key `foot_radius` = {configured} contradicts the sphere collision of `{link}` (radius {radius}); remove the key")),
        ),
        (Some((radius, _)), Some(_)) => Ok(radius),
        (None, Some(configured)) => Ok(configured),
        (None, None) => Err(KeyProblem::of("foot_radius", format!(
            "no foot radius: the foot links ({}) have no sphere collision at the foot point and key `foot_radius` is not set",
            Leg::ALL
                .iter()
                .map(|leg| format!("`{}`", config.legs.get(*leg).foot_link))
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    })
}

/// The config's crouch as 12 joint angles: all four legs or none, inside the joint limits.
fn crouch_pose(
    config: &RobotConfig,
    lower: &[f64; NUM_JOINTS],
    upper: &[f64; NUM_JOINTS],
) -> Result<Option<[f64; NUM_JOINTS]>, KeyProblem> {
    let given: Vec<Leg> = Leg::ALL
        .into_iter()
        .filter(|leg| config.legs.get(*leg).crouch.is_some())
        .collect();
    if given.is_empty() {
        return Ok(None);
    }
    let mut pose = [0.0; NUM_JOINTS];
    for leg in Leg::ALL {
        let leg_config = config.legs.get(leg);
        let key = format!("legs.{}.crouch", leg.name());
        let Some(angles) = leg_config.crouch else {
            return Err(KeyProblem {
                reason: format!(
                    "key `{key}` is missing while other legs give one; give all four or none"
                ),
                key: Some(key),
            });
        };
        for (j, angle) in angles.into_iter().enumerate() {
            let i = 3 * leg.index() + j;
            if !(lower[i]..=upper[i]).contains(&angle) {
                return Err(KeyProblem {
                    reason: format!(
                        "key `{key}`: {angle} rad for joint `{}` is outside its limits [{}, {}]",
                        leg_config.joints[j], lower[i], upper[i]
                    ),
                    key: Some(key),
                });
            }
            pose[i] = angle;
        }
    }
    Ok(Some(pose))
}

impl RobotModel {
    /// Load a robot config file and the URDF it names; `package://` URIs resolve through
    /// [`PackagePath::from_env`].
    pub fn from_config_file(path: &Path) -> Result<Self, ModelError> {
        Self::from_config_file_with(path, &PackagePath::from_env())
    }

    /// [`RobotModel::from_config_file`] with explicit package roots.
    pub fn from_config_file_with(path: &Path, packages: &PackagePath) -> Result<Self, ModelError> {
        let config = RobotConfig::from_file(path)?;
        let urdf_path = config.urdf_path(path, packages)?;
        let xml = std::fs::read_to_string(&urdf_path).map_err(|e| ModelError::Io {
            path: urdf_path.display().to_string(),
            reason: e.to_string(),
        })?;
        let sources = Sources {
            config: &path.display().to_string(),
            urdf: &urdf_path.display().to_string(),
        };
        Self::build(&config, &xml, &sources)
    }

    /// A model from the texts of a robot config and of its URDF (the config's `urdf` key is not
    /// read: the caller already has the document, e.g. from the FMU's resources).
    pub fn from_config_str(config_toml: &str, urdf_xml: &str) -> Result<Self, ModelError> {
        Self::from_named_texts(config_toml, "robot config text", urdf_xml, "URDF text")
    }

    /// [`RobotModel::from_config_str`] with the names error messages give the two texts (e.g.
    /// the files they were read from).
    pub fn from_named_texts(
        config_toml: &str,
        config_origin: &str,
        urdf_xml: &str,
        urdf_origin: &str,
    ) -> Result<Self, ModelError> {
        let sources = Sources {
            config: config_origin,
            urdf: urdf_origin,
        };
        let config = RobotConfig::from_toml_str(config_toml, sources.config)?;
        Self::build(&config, urdf_xml, &sources)
    }

    /// A model from an already parsed config and the URDF text it describes.
    pub fn from_config(config: &RobotConfig, urdf_xml: &str) -> Result<Self, ModelError> {
        let sources = Sources {
            config: "robot config",
            urdf: "URDF text",
        };
        Self::build(config, urdf_xml, &sources)
    }

    /// [`RobotModel::from_config`] for a URDF already parsed (a tool loading one robot under
    /// several configs parses it once); errors name `config_file` and `urdf_file`.
    pub fn from_parsed_urdf(
        robot: &urdf_rs::Robot,
        config: &RobotConfig,
        config_file: &str,
        urdf_file: &str,
    ) -> Result<Self, ModelError> {
        let sources = Sources {
            config: config_file,
            urdf: urdf_file,
        };
        Self::from_urdf_robot(robot, config, &sources)
    }

    fn build(config: &RobotConfig, xml: &str, sources: &Sources<'_>) -> Result<Self, ModelError> {
        let robot = urdf_rs::read_from_string(xml)
            .map_err(|e| ModelError::Parse(e.to_string()).in_file(sources.urdf))?;
        Self::from_urdf_robot(&robot, config, sources)
    }

    fn from_urdf_robot(
        robot: &urdf_rs::Robot,
        config: &RobotConfig,
        sources: &Sources<'_>,
    ) -> Result<Self, ModelError> {
        let in_urdf = |e: ModelError| e.in_file(sources.urdf);
        let in_config = |problem: KeyProblem| problem.in_file(sources.config);
        let tree = Tree::new(robot, &config.massless_links).map_err(in_urdf)?;
        for link in &config.massless_links {
            if !tree.links.contains_key(link.as_str()) {
                return Err(in_config(KeyProblem::of(
                    "massless_links",
                    format!(
                        "key `massless_links` names `{link}`, which is not a link of {}",
                        sources.urdf
                    ),
                )));
            }
        }
        let base = config.base_link.as_str();
        tree.link(base)
            .map_err(|_| ModelError::Missing(format!("base link `{base}`")))
            .map_err(in_urdf)?;
        if let Some(joint) = tree.parent_joint.get(base) {
            return Err(in_urdf(ModelError::Structure(format!(
                "base link `{base}` must be the root of the tree, but joint `{}` attaches it to `{}`",
                joint.name, joint.parent.link
            ))));
        }
        if let Some(root) = robot
            .links
            .iter()
            .find(|l| l.name != base && !tree.parent_joint.contains_key(l.name.as_str()))
        {
            return Err(in_urdf(ModelError::Structure(format!(
                "link `{}` is not attached to the base link `{base}` (a second root)",
                root.name
            ))));
        }
        check_all_inertials(robot, &tree, config).map_err(in_urdf)?;
        let base_body = tree.rigid_cluster(base, 0).map_err(in_urdf)?;
        let mut legs = Vec::with_capacity(4);
        for leg in Leg::ALL {
            legs.push(build_leg(&tree, config, leg, config.legs.get(leg)).map_err(in_urdf)?);
        }
        let legs: [LegChain; 4] = legs
            .try_into()
            .map_err(|_| in_urdf(ModelError::Structure("not four legs".into())))?;
        let leg_joints: HashSet<&str> = Leg::ALL
            .iter()
            .flat_map(|leg| config.legs.get(*leg).joints.iter().map(String::as_str))
            .collect();
        if let Some(extra) = robot.joints.iter().find(|j| {
            j.joint_type != urdf_rs::JointType::Fixed && !leg_joints.contains(j.name.as_str())
        }) {
            return Err(in_urdf(ModelError::Structure(format!(
                "joint `{}` ({:?}) is movable but is none of the legs' 12 actuated joints; only 12-DOF quadrupeds are supported",
                extra.name, extra.joint_type
            ))));
        }
        let mut total_mass = 0.0;
        for link in &robot.links {
            total_mass += tree.mass_properties(link).map_err(in_urdf)?.mass;
        }
        if total_mass <= 0.0 {
            return Err(in_urdf(ModelError::InvalidValue(
                "total mass is zero".into(),
            )));
        }
        let foot_radius = foot_radius(&tree, config)
            .map_err(in_urdf)?
            .map_err(in_config)?;
        let model = RobotModel {
            name: robot.name.clone(),
            total_mass,
            base_body,
            legs,
            foot_radius,
            stand_height: config.stand_height,
            crouch: None,
            tuning: None,
        };
        let model = RobotModel {
            crouch: crouch_pose(config, &model.lower_limits(), &model.upper_limits())
                .map_err(in_config)?,
            ..model
        };
        if config.stand_height <= foot_radius {
            return Err(in_config(KeyProblem::of(
                "stand_height",
                format!(
                    "key `stand_height` = {} m is not above the foot radius {foot_radius} m",
                    config.stand_height
                ),
            )));
        }
        model
            .stand_joint_positions(config.stand_height)
            .map_err(|e| {
                in_config(KeyProblem::of(
                    "stand_height",
                    format!("key `stand_height` = {} m: {e}", config.stand_height),
                ))
            })?;
        let tuning = if config.tuning.is_empty() {
            None
        } else {
            let tuned =
                crate::tuning::tuned_for_robot(&model, &config.tuning).map_err(in_config)?;
            Some(Box::new(tuned))
        };
        Ok(RobotModel { tuning, ..model })
    }
}
