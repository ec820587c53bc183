//! Building the model from a URDF document: indexing the link/joint tree, merging fixed-joint
//! clusters into mass properties and extracting the three-joint leg chains. All validation of the
//! input lives here, so a model that was built is known to be well-formed.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use super::{ChainJoint, LegChain, LegGeometry, MassProperties, RobotModel, Transform};
use crate::api::{Leg, ModelError};

fn finite3(v: &[f64; 3], what: &str) -> Result<(), ModelError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ModelError::InvalidValue(format!("{what} is not finite")))
    }
}

fn link_mass_properties(link: &urdf_rs::Link) -> Result<MassProperties, ModelError> {
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
        &format!("inertial origin of `{}`", link.name),
    )?;
    finite3(
        &inertial.origin.rpy,
        &format!("inertial rpy of `{}`", link.name),
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
    let pose = Transform::from_pose(&inertial.origin);
    Ok(MassProperties {
        mass,
        com: pose.translation,
        inertia_com: pose.rotation * inertia * pose.rotation.transpose(),
    })
}

/// Indexed view of the URDF tree.
struct Tree<'a> {
    links: HashMap<&'a str, &'a urdf_rs::Link>,
    parent_joint: HashMap<&'a str, &'a urdf_rs::Joint>,
    child_joints: HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
}

impl<'a> Tree<'a> {
    fn new(robot: &'a urdf_rs::Robot) -> Result<Self, ModelError> {
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
        })
    }

    /// Mass properties of `link` plus everything attached to it through fixed joints, in the
    /// frame of `link`.
    fn rigid_cluster(&self, link: &str, depth: usize) -> Result<MassProperties, ModelError> {
        if depth > 64 {
            return Err(ModelError::Structure(
                "kinematic tree too deep or cyclic".into(),
            ));
        }
        let urdf_link = self
            .links
            .get(link)
            .ok_or_else(|| ModelError::Missing(format!("link `{link}`")))?;
        let mut props = link_mass_properties(urdf_link)?;
        for joint in self.child_joints.get(link).into_iter().flatten() {
            if joint.joint_type == urdf_rs::JointType::Fixed {
                let child = self.rigid_cluster(&joint.child.link, depth + 1)?;
                props.merge(&child, &Transform::from_pose(&joint.origin));
            }
        }
        Ok(props)
    }
}

fn is_unit_axis(axis: &Vector3<f64>, expected: Vector3<f64>) -> bool {
    (axis - expected).norm() < 1e-9
}

fn build_leg(tree: &Tree<'_>, leg: Leg) -> Result<LegChain, ModelError> {
    let prefix = leg.name();
    let joint_names = [
        format!("{prefix}_hip_abd_joint"),
        format!("{prefix}_hip_flex_joint"),
        format!("{prefix}_knee_joint"),
    ];
    let foot_name = format!("{prefix}_foot");
    if !tree.links.contains_key(foot_name.as_str()) {
        return Err(ModelError::Missing(format!("foot link `{foot_name}`")));
    }
    // Walk from the foot up to the base, recording the path (foot-most joint first).
    let mut path: Vec<&urdf_rs::Joint> = Vec::new();
    let mut link = foot_name.as_str();
    while link != "base" {
        let joint = tree.parent_joint.get(link).ok_or_else(|| {
            ModelError::Structure(format!("link `{link}` is not connected to `base`"))
        })?;
        path.push(joint);
        if path.len() > 64 {
            return Err(ModelError::Structure(
                "kinematic tree too deep or cyclic".into(),
            ));
        }
        link = joint.parent.link.as_str();
    }
    path.reverse();
    let moving: Vec<&urdf_rs::Joint> = path
        .iter()
        .copied()
        .filter(|j| j.joint_type != urdf_rs::JointType::Fixed)
        .collect();
    for name in &joint_names {
        if !path.iter().any(|j| &j.name == name) {
            return Err(ModelError::Missing(format!(
                "joint `{name}` between `base` and `{foot_name}`"
            )));
        }
    }
    if moving.len() != 3 || moving.iter().zip(&joint_names).any(|(j, n)| &j.name != n) {
        return Err(ModelError::Structure(format!(
            "leg {prefix}: the joints from `base` to `{foot_name}` must be exactly {joint_names:?} (plus fixed joints), found {:?}",
            moving.iter().map(|j| j.name.as_str()).collect::<Vec<_>>()
        )));
    }
    let mut joints = Vec::with_capacity(3);
    let mut pre = Transform::identity();
    for joint in &path {
        finite3(&joint.origin.xyz, &format!("origin of `{}`", joint.name))?;
        finite3(&joint.origin.rpy, &format!("rpy of `{}`", joint.name))?;
        let origin = Transform::from_pose(&joint.origin);
        if joint.joint_type == urdf_rs::JointType::Fixed {
            pre = pre.then(&origin);
            continue;
        }
        if joint.joint_type != urdf_rs::JointType::Revolute {
            return Err(ModelError::Structure(format!(
                "joint `{}` must be revolute, is {:?}",
                joint.name, joint.joint_type
            )));
        }
        let axis = Vector3::new(joint.axis.xyz[0], joint.axis.xyz[1], joint.axis.xyz[2]);
        let norm = axis.norm();
        if !norm.is_finite() || norm < 1e-9 {
            return Err(ModelError::InvalidValue(format!(
                "axis of `{}`",
                joint.name
            )));
        }
        let limit = &joint.limit;
        if !(limit.lower.is_finite() && limit.upper.is_finite() && limit.lower < limit.upper) {
            return Err(ModelError::InvalidValue(format!(
                "position limits of `{}`: [{}, {}]",
                joint.name, limit.lower, limit.upper
            )));
        }
        if !(limit.effort.is_finite() && limit.effort > 0.0) {
            return Err(ModelError::InvalidValue(format!(
                "effort limit of `{}`: {}",
                joint.name, limit.effort
            )));
        }
        if !(limit.velocity.is_finite() && limit.velocity > 0.0) {
            return Err(ModelError::InvalidValue(format!(
                "velocity limit of `{}`: {}",
                joint.name, limit.velocity
            )));
        }
        joints.push(ChainJoint {
            pre: pre.then(&origin),
            axis: axis / norm,
            body: tree.rigid_cluster(&joint.child.link, 0)?,
            lower: limit.lower,
            upper: limit.upper,
            effort: limit.effort,
            velocity: limit.velocity,
        });
        pre = Transform::identity();
    }
    let foot = pre;
    let joints: [ChainJoint; 3] = joints
        .try_into()
        .map_err(|_| ModelError::Structure(format!("leg {prefix} does not have 3 joints")))?;
    // The rigid cluster of the knee's child already contains the foot (fixed joints), and the
    // clusters never overlap because each stops at the next moving joint.
    if !is_unit_axis(&joints[0].axis, Vector3::x())
        || !is_unit_axis(&joints[1].axis, Vector3::y())
        || !is_unit_axis(&joints[2].axis, Vector3::y())
    {
        return Err(ModelError::Structure(format!(
            "leg {prefix}: expected axes x (abduction), y (hip), y (knee)"
        )));
    }
    let all_rotations_identity = joints
        .iter()
        .map(|j| j.pre.rotation)
        .chain(std::iter::once(foot.rotation))
        .all(|r| (r - Matrix3::identity()).norm() < 1e-9);
    if !all_rotations_identity {
        return Err(ModelError::Structure(format!(
            "leg {prefix}: joint origins must not be rotated (rpy = 0)"
        )));
    }
    let thigh_length = joints[2].pre.translation.norm();
    let calf_length = foot.translation.norm();
    if thigh_length < 1e-3 || calf_length < 1e-3 {
        return Err(ModelError::Structure(format!(
            "leg {prefix}: thigh or calf length is zero"
        )));
    }
    let geometry = LegGeometry {
        abd_origin: joints[0].pre.translation,
        lateral_offset: joints[1].pre.translation.y,
        thigh_length,
        calf_length,
    };
    Ok(LegChain {
        joints,
        foot,
        geometry,
    })
}

impl RobotModel {
    /// Parse a URDF document.
    pub fn from_urdf_str(xml: &str) -> Result<Self, ModelError> {
        let robot = urdf_rs::read_from_string(xml).map_err(|e| ModelError::Parse(e.to_string()))?;
        Self::from_urdf_robot(&robot)
    }

    /// Read and parse a URDF file.
    pub fn from_urdf_file(path: &Path) -> Result<Self, ModelError> {
        let xml = std::fs::read_to_string(path).map_err(|e| ModelError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::from_urdf_str(&xml)
    }

    fn from_urdf_robot(robot: &urdf_rs::Robot) -> Result<Self, ModelError> {
        let tree = Tree::new(robot)?;
        if !tree.links.contains_key("base") {
            return Err(ModelError::Missing("base link `base`".into()));
        }
        if tree.parent_joint.contains_key("base") {
            return Err(ModelError::Structure("link `base` must be the root".into()));
        }
        let base_body = tree.rigid_cluster("base", 0)?;
        let legs = [
            build_leg(&tree, Leg::FR)?,
            build_leg(&tree, Leg::FL)?,
            build_leg(&tree, Leg::RR)?,
            build_leg(&tree, Leg::RL)?,
        ];
        let mut total_mass = 0.0;
        for link in &robot.links {
            total_mass += link_mass_properties(link)?.mass;
        }
        if total_mass <= 0.0 {
            return Err(ModelError::InvalidValue("total mass is zero".into()));
        }
        let mut foot_radius = None;
        for leg in Leg::ALL {
            let foot_name = format!("{}_foot", leg.name());
            let link = tree
                .links
                .get(foot_name.as_str())
                .ok_or_else(|| ModelError::Missing(format!("foot link `{foot_name}`")))?;
            let radius = link
                .collision
                .iter()
                .find_map(|c| match c.geometry {
                    urdf_rs::Geometry::Sphere { radius } => Some(radius),
                    _ => None,
                })
                .ok_or_else(|| {
                    ModelError::Structure(format!(
                        "foot link `{foot_name}` has no sphere collision"
                    ))
                })?;
            if !(radius.is_finite() && radius > 0.0) {
                return Err(ModelError::InvalidValue(format!("foot radius {radius}")));
            }
            foot_radius = Some(radius);
        }
        let foot_radius =
            foot_radius.ok_or_else(|| ModelError::Missing("foot sphere collision".into()))?;
        Ok(RobotModel {
            name: robot.name.clone(),
            total_mass,
            base_body,
            legs,
            foot_radius,
        })
    }
}
