//! Robot model loaded from the URDF: per-leg kinematic chains, forward/inverse kinematics, foot
//! Jacobian and per-leg rigid-body dynamics.
//!
//! Legs are found by the naming convention of `robot/README.md`: base link `base`; for each
//! `LEG ∈ {FR, FL, RR, RL}` the revolute joints `LEG_hip_abd_joint`, `LEG_hip_flex_joint`,
//! `LEG_knee_joint` and the foot link `LEG_foot` (with a sphere collision). The chain from `base`
//! to the foot is found by walking the URDF tree from the foot up; fixed joints on the way are
//! merged into the neighbouring moving link. No link name appears anywhere else in the crate.
//!
//! Leg dynamics treat the base as fixed (an inertial frame): `M(q)` and `h(q, q̇)` are those of the
//! 3-link chain hanging from a motionless base, with gravity expressed in the base frame. The
//! coupling with base acceleration is neglected; this is the usual assumption of MIT-style leg
//! controllers, where the legs are ~15 % of the mass and the base moves slowly compared to a
//! swinging leg.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Vector3};

use crate::api::{Leg, ModelError, NUM_JOINTS, NUM_LEGS};
use crate::math::wrap_angle;

/// Rigid transform (rotation, translation) mapping child-frame coordinates to the parent frame.
#[derive(Clone, Copy, Debug)]
struct Transform {
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
}

impl Transform {
    fn identity() -> Self {
        Transform {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    fn from_pose(pose: &urdf_rs::Pose) -> Self {
        let rotation = Rotation3::from_euler_angles(pose.rpy[0], pose.rpy[1], pose.rpy[2]);
        Transform {
            rotation: *rotation.matrix(),
            translation: Vector3::new(pose.xyz[0], pose.xyz[1], pose.xyz[2]),
        }
    }

    fn then(&self, child: &Transform) -> Transform {
        Transform {
            rotation: self.rotation * child.rotation,
            translation: self.translation + self.rotation * child.translation,
        }
    }
}

/// Mass properties of a rigid body: mass, centre of mass and rotational inertia about the CoM,
/// both in the frame of the body it is expressed in.
#[derive(Clone, Copy, Debug)]
struct MassProperties {
    mass: f64,
    com: Vector3<f64>,
    inertia_com: Matrix3<f64>,
}

impl MassProperties {
    /// Merge `other` (expressed in a frame placed at `pose` relative to ours) into `self`.
    fn merge(&mut self, other: &MassProperties, pose: &Transform) {
        let other_com = pose.translation + pose.rotation * other.com;
        let other_inertia = pose.rotation * other.inertia_com * pose.rotation.transpose();
        let total = self.mass + other.mass;
        if total <= 0.0 {
            return;
        }
        let com = (self.com * self.mass + other_com * other.mass) / total;
        let shifted = |inertia: Matrix3<f64>, mass: f64, c: Vector3<f64>| {
            let d = c - com;
            inertia + mass * (Matrix3::identity() * d.dot(&d) - d * d.transpose())
        };
        self.inertia_com = shifted(self.inertia_com, self.mass, self.com)
            + shifted(other_inertia, other.mass, other_com);
        self.com = com;
        self.mass = total;
    }
}

/// One actuated joint of a leg chain.
#[derive(Clone, Debug)]
struct ChainJoint {
    /// Pose of the joint frame (before its rotation) in the previous moving frame (the base for
    /// the first joint), fixed joints in between included.
    pre: Transform,
    /// Unit rotation axis in the joint frame.
    axis: Vector3<f64>,
    /// Everything rigidly attached after this joint, in the joint frame.
    body: MassProperties,
    lower: f64,
    upper: f64,
    effort: f64,
    velocity: f64,
}

/// Geometry used by the closed-form IK initial guess (exact for the reference leg layout: abduction
/// about x, hip and knee about y, thigh offset along y, links along −z at q = 0).
#[derive(Clone, Copy, Debug)]
struct LegGeometry {
    abd_origin: Vector3<f64>,
    /// Signed lateral offset from the abduction axis to the thigh plane.
    lateral_offset: f64,
    thigh_length: f64,
    calf_length: f64,
}

#[derive(Clone, Debug)]
struct LegChain {
    joints: [ChainJoint; 3],
    /// Foot frame (sphere centre) in the knee's moving frame.
    foot: Transform,
    geometry: LegGeometry,
}

/// Per-joint frames of one leg at a configuration, all in the base frame.
#[derive(Clone, Copy, Debug)]
struct LegFrames {
    joint_origin: [Vector3<f64>; 3],
    joint_axis: [Vector3<f64>; 3],
    link_rotation: [Matrix3<f64>; 3],
    foot: Vector3<f64>,
}

/// Robot model for the controller, built from the URDF.
#[derive(Clone, Debug)]
pub struct RobotModel {
    name: String,
    total_mass: f64,
    base_body: MassProperties,
    legs: [LegChain; NUM_LEGS],
    foot_radius: f64,
}

/// Why an IK target was not reached (turned into [`ModelError::Unreachable`] on demand).
#[derive(Clone, Copy, Debug)]
enum IkFailure {
    NotFinite,
    InsideOffset,
    OutOfReach { reach: f64, min: f64, max: f64 },
    NotConverged { residual: f64 },
}

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

fn axis_rotation(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    *Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(*axis), angle).matrix()
}

fn to_array3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn to_array33(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [
        [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
        [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
        [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
    ]
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

    /// Robot name from the URDF.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Sum of all link masses, kg.
    pub fn total_mass(&self) -> f64 {
        self.total_mass
    }

    /// Radius of the foot spheres, m.
    pub fn foot_radius(&self) -> f64 {
        self.foot_radius
    }

    /// URDF effort limits, N·m, index 3·leg + j.
    pub fn effort_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.effort)
    }

    /// URDF velocity limits, rad/s.
    pub fn velocity_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.velocity)
    }

    /// URDF lower position limits, rad.
    pub fn lower_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.lower)
    }

    /// URDF upper position limits, rad.
    pub fn upper_limits(&self) -> [f64; NUM_JOINTS] {
        self.per_joint(|j| j.upper)
    }

    fn per_joint(&self, f: impl Fn(&ChainJoint) -> f64) -> [f64; NUM_JOINTS] {
        let mut out = [0.0; NUM_JOINTS];
        for (l, leg) in self.legs.iter().enumerate() {
            for (j, joint) in leg.joints.iter().enumerate() {
                out[3 * l + j] = f(joint);
            }
        }
        out
    }

    /// Position of the hip-abduction joint in the base frame, m.
    pub fn hip_position_body(&self, leg: Leg) -> [f64; 3] {
        to_array3(&self.legs[leg.index()].geometry.abd_origin)
    }

    /// Signed lateral offset from the abduction axis to the leg's sagittal plane, m (positive to
    /// the left).
    pub fn hip_lateral_offset(&self, leg: Leg) -> f64 {
        self.legs[leg.index()].geometry.lateral_offset
    }

    /// Thigh and calf lengths, m.
    pub fn link_lengths(&self, leg: Leg) -> (f64, f64) {
        let g = &self.legs[leg.index()].geometry;
        (g.thigh_length, g.calf_length)
    }

    fn frames(&self, leg: Leg, q: [f64; 3]) -> LegFrames {
        let chain = &self.legs[leg.index()];
        let mut current = Transform::identity();
        let mut joint_origin = [Vector3::zeros(); 3];
        let mut joint_axis = [Vector3::zeros(); 3];
        let mut link_rotation = [Matrix3::identity(); 3];
        for (i, joint) in chain.joints.iter().enumerate() {
            current = current.then(&joint.pre);
            joint_origin[i] = current.translation;
            joint_axis[i] = current.rotation * joint.axis;
            current.rotation *= axis_rotation(&joint.axis, q[i]);
            link_rotation[i] = current.rotation;
        }
        let foot = current.then(&chain.foot).translation;
        LegFrames {
            joint_origin,
            joint_axis,
            link_rotation,
            foot,
        }
    }

    /// Forward kinematics: foot (sphere centre) position in the base frame, m.
    pub fn foot_position_body(&self, leg: Leg, q_leg: [f64; 3]) -> [f64; 3] {
        to_array3(&self.frames(leg, q_leg).foot)
    }

    /// Foot Jacobian ∂p_foot/∂q in the base frame (row = Cartesian axis, column = joint).
    pub fn foot_jacobian_body(&self, leg: Leg, q_leg: [f64; 3]) -> [[f64; 3]; 3] {
        to_array33(&self.jacobian(leg, q_leg))
    }

    fn jacobian(&self, leg: Leg, q: [f64; 3]) -> Matrix3<f64> {
        let frames = self.frames(leg, q);
        let mut jac = Matrix3::zeros();
        for i in 0..3 {
            let column = frames.joint_axis[i].cross(&(frames.foot - frames.joint_origin[i]));
            jac.set_column(i, &column);
        }
        jac
    }

    /// Inverse kinematics: joint angles placing the foot at `p_body` (base frame), knee-backward
    /// branch (knee angle < 0), foot below the hip axis in the leg plane. Closed-form for the nominal layout, refined by Newton steps on
    /// the full URDF kinematics. Joint limits are not enforced here (callers clamp).
    pub fn inverse_kinematics(&self, leg: Leg, p_body: [f64; 3]) -> Result<[f64; 3], ModelError> {
        self.solve_ik(leg, p_body)
            .map_err(|failure| ModelError::Unreachable {
                leg,
                reason: match failure {
                    IkFailure::NotFinite => "target is not finite".into(),
                    IkFailure::InsideOffset => "target inside the abduction offset".into(),
                    IkFailure::OutOfReach { reach, min, max } => {
                        format!("distance {reach:.4} m outside [{min:.4}, {max:.4}] m")
                    }
                    IkFailure::NotConverged { residual } => {
                        format!("IK did not converge (residual {residual:.2e} m)")
                    }
                },
            })
    }

    /// [`RobotModel::inverse_kinematics`] without building an error message: for callers that
    /// retry or fall back on failure every control tick (formatting the message's floats cost
    /// more than the IK itself).
    pub(crate) fn try_inverse_kinematics(&self, leg: Leg, p_body: [f64; 3]) -> Option<[f64; 3]> {
        self.solve_ik(leg, p_body).ok()
    }

    fn solve_ik(&self, leg: Leg, p_body: [f64; 3]) -> Result<[f64; 3], IkFailure> {
        if p_body.iter().any(|v| !v.is_finite()) {
            return Err(IkFailure::NotFinite);
        }
        let g = &self.legs[leg.index()].geometry;
        let rel = Vector3::new(p_body[0], p_body[1], p_body[2]) - g.abd_origin;
        let d = g.lateral_offset;
        let (l1, l2) = (g.thigh_length, g.calf_length);
        let yz_sq = rel.y * rel.y + rel.z * rel.z;
        if yz_sq < d * d + 1e-12 {
            return Err(IkFailure::InsideOffset);
        }
        let z_plane = -(yz_sq - d * d).sqrt();
        let q0 = rel.z.atan2(rel.y) - z_plane.atan2(d);
        let x_plane = rel.x;
        let reach_sq = x_plane * x_plane + z_plane * z_plane;
        let reach = reach_sq.sqrt();
        if reach > l1 + l2 - 1e-9 || reach < (l1 - l2).abs() + 1e-9 {
            return Err(IkFailure::OutOfReach {
                reach,
                min: (l1 - l2).abs(),
                max: l1 + l2,
            });
        }
        let cos_knee = ((reach_sq - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)).clamp(-1.0, 1.0);
        let q2 = -cos_knee.acos();
        let direction = (-x_plane).atan2(-z_plane);
        let q1 = direction - (l2 * q2.sin()).atan2(l1 + l2 * q2.cos());
        let mut q = [wrap_angle(q0), wrap_angle(q1), q2];
        let target = Vector3::new(p_body[0], p_body[1], p_body[2]);
        for _ in 0..20 {
            let error = target - self.frames(leg, q).foot;
            if error.norm() < 1e-12 {
                break;
            }
            let Some(inverse) = self.jacobian(leg, q).try_inverse() else {
                break;
            };
            let dq = inverse * error;
            for i in 0..3 {
                q[i] += dq[i];
            }
        }
        let residual = (target - self.frames(leg, q).foot).norm();
        if residual > 1e-6 {
            return Err(IkFailure::NotConverged { residual });
        }
        Ok(q)
    }

    /// Recursive Newton–Euler on the fixed-base leg chain: joint torques for (q, q̇, q̈) with the
    /// base frame taken as inertial and `gravity_base` the gravity acceleration in the base frame.
    fn rnea(
        &self,
        leg: Leg,
        q: [f64; 3],
        dq: [f64; 3],
        ddq: [f64; 3],
        gravity_base: Vector3<f64>,
    ) -> Vector3<f64> {
        let chain = &self.legs[leg.index()];
        let frames = self.frames(leg, q);
        let mut omega = [Vector3::zeros(); 3];
        let mut alpha = [Vector3::zeros(); 3];
        let mut accel_origin = [Vector3::zeros(); 3];
        let mut com = [Vector3::zeros(); 3];
        let mut inertia = [Matrix3::zeros(); 3];
        let (mut prev_omega, mut prev_alpha) = (Vector3::zeros(), Vector3::zeros());
        // Gravity enters as an upward acceleration of the (fixed) base.
        let (mut prev_accel, mut prev_origin) = (-gravity_base, frames.joint_origin[0]);
        for i in 0..3 {
            let z = frames.joint_axis[i];
            let lever = frames.joint_origin[i] - prev_origin;
            accel_origin[i] =
                prev_accel + prev_alpha.cross(&lever) + prev_omega.cross(&prev_omega.cross(&lever));
            omega[i] = prev_omega + z * dq[i];
            alpha[i] = prev_alpha + z * ddq[i] + prev_omega.cross(&(z * dq[i]));
            let r = frames.link_rotation[i];
            com[i] = frames.joint_origin[i] + r * chain.joints[i].body.com;
            inertia[i] = r * chain.joints[i].body.inertia_com * r.transpose();
            prev_omega = omega[i];
            prev_alpha = alpha[i];
            prev_accel = accel_origin[i];
            prev_origin = frames.joint_origin[i];
        }
        let mut tau = Vector3::zeros();
        let (mut f_next, mut n_next) = (Vector3::zeros(), Vector3::zeros());
        for i in (0..3).rev() {
            let body = &chain.joints[i].body;
            let c = com[i] - frames.joint_origin[i];
            let accel_com =
                accel_origin[i] + alpha[i].cross(&c) + omega[i].cross(&omega[i].cross(&c));
            let force = accel_com * body.mass;
            let moment = inertia[i] * alpha[i] + omega[i].cross(&(inertia[i] * omega[i]));
            let next_lever = if i < 2 {
                frames.joint_origin[i + 1] - frames.joint_origin[i]
            } else {
                Vector3::zeros()
            };
            let f = force + f_next;
            let n = moment + c.cross(&force) + n_next + next_lever.cross(&f_next);
            tau[i] = frames.joint_axis[i].dot(&n);
            f_next = f;
            n_next = n;
        }
        tau
    }

    /// Joint-space inertia matrix M(q) of one leg (fixed base), kg·m².
    pub fn leg_mass_matrix(&self, leg: Leg, q_leg: [f64; 3]) -> [[f64; 3]; 3] {
        to_array33(&self.mass_matrix(leg, q_leg))
    }

    pub(crate) fn mass_matrix(&self, leg: Leg, q: [f64; 3]) -> Matrix3<f64> {
        let mut m = Matrix3::zeros();
        for j in 0..3 {
            let mut unit = [0.0; 3];
            unit[j] = 1.0;
            let column = self.rnea(leg, q, [0.0; 3], unit, Vector3::zeros());
            m.set_column(j, &column);
        }
        // RNEA columns are symmetric up to rounding; symmetrise so callers get an exact SPD matrix.
        (m + m.transpose()) * 0.5
    }

    /// Bias torques h(q, q̇) = C(q, q̇)q̇ + g(q) of one leg (fixed base), N·m, with
    /// `gravity_base` the gravity acceleration expressed in the base frame (e.g. Rᵀ(0, 0, −9.81)).
    pub fn leg_bias(
        &self,
        leg: Leg,
        q_leg: [f64; 3],
        dq_leg: [f64; 3],
        gravity_base: [f64; 3],
    ) -> [f64; 3] {
        let g = Vector3::new(gravity_base[0], gravity_base[1], gravity_base[2]);
        to_array3(&self.rnea(leg, q_leg, dq_leg, [0.0; 3], g))
    }

    /// Inertia of the whole robot about its centre of mass in the base frame, with all legs at
    /// `joint_positions`, and the CoM offset from the base origin (base frame). Used as the
    /// single-rigid-body inertia of the MPC.
    pub fn composite_inertia(
        &self,
        joint_positions: &[f64; NUM_JOINTS],
    ) -> ([[f64; 3]; 3], [f64; 3]) {
        let mut total = self.base_body;
        for leg in Leg::ALL {
            let l = leg.index();
            let q = [
                joint_positions[3 * l],
                joint_positions[3 * l + 1],
                joint_positions[3 * l + 2],
            ];
            let frames = self.frames(leg, q);
            for (i, joint) in self.legs[l].joints.iter().enumerate() {
                let pose = Transform {
                    rotation: frames.link_rotation[i],
                    translation: frames.joint_origin[i],
                };
                total.merge(&joint.body, &pose);
            }
        }
        (to_array33(&total.inertia_com), to_array3(&total.com))
    }

    /// Masses of the base cluster and of the moving links of one leg (hip, thigh, calf+foot), kg.
    pub fn link_masses(&self, leg: Leg) -> (f64, [f64; 3]) {
        let chain = &self.legs[leg.index()];
        (
            self.base_body.mass,
            [
                chain.joints[0].body.mass,
                chain.joints[1].body.mass,
                chain.joints[2].body.mass,
            ],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_mass_properties_merge_is_identity() {
        let mut a = MassProperties {
            mass: 0.0,
            com: Vector3::zeros(),
            inertia_com: Matrix3::zeros(),
        };
        let b = MassProperties {
            mass: 2.0,
            com: Vector3::new(0.1, 0.0, 0.0),
            inertia_com: Matrix3::identity() * 0.01,
        };
        a.merge(&b, &Transform::identity());
        assert!((a.mass - 2.0).abs() < 1e-15);
        assert!((a.com.x - 0.1).abs() < 1e-15);
        assert!((a.inertia_com[(0, 0)] - 0.01).abs() < 1e-15);
    }
}
