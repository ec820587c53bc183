//! Test support: the robot model and a single-rigid-body simulation with ideal foot forces.
#![allow(dead_code)]
#![allow(clippy::needless_range_loop)] // parallel indexing of joints, axes and legs

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use quad_controller::{
    Command, Controller, ControllerConfig, ImuReading, Leg, RobotModel, RobotState, GRAVITY,
    NUM_JOINTS, NUM_LEGS,
};

pub fn urdf_text() -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.urdf");
    std::fs::read_to_string(path).expect("robot/quadruped.urdf is readable")
}

fn our_config_text() -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    std::fs::read_to_string(path).expect("robot/quadruped.toml is readable")
}

/// Our robot's config applied to `urdf` (an edited copy of our URDF in the error tests).
pub fn our_robot_with_urdf(urdf: &str) -> Result<RobotModel, quad_controller::ModelError> {
    RobotModel::from_config_str(&our_config_text(), urdf)
}

pub fn model() -> RobotModel {
    our_robot_with_urdf(&urdf_text()).expect("the repository robot loads")
}

/// A controller for `model` with `config`, and the simulation standing in its stand pose at
/// `config.body_height`.
pub fn controller_and_standing_sim(
    model: RobotModel,
    config: &ControllerConfig,
) -> (Controller, SrbSim) {
    let controller = Controller::new(model.clone(), config.clone()).expect("controller");
    let sim = SrbSim::standing(
        model,
        controller.stand_joint_positions(),
        config.body_height,
    );
    (controller, sim)
}

/// Single rigid body (total mass, composite inertia at the standing pose) pushed by the
/// controller's desired forces at ideal point feet. Stance feet stay where they touched down;
/// swing feet follow the controller's desired foot positions exactly; joint angles come from IK.
pub struct SrbSim {
    pub model: RobotModel,
    pub mass: f64,
    pub inertia_body: Matrix3<f64>,
    pub com_offset: Vector3<f64>,
    pub com: Vector3<f64>,
    pub velocity: Vector3<f64>,
    pub orientation: UnitQuaternion<f64>,
    pub angular_velocity: Vector3<f64>,
    pub feet: [Vector3<f64>; NUM_LEGS],
    pub in_contact: [bool; NUM_LEGS],
    pub q: [f64; NUM_JOINTS],
    pub dq: [f64; NUM_JOINTS],
    pub mu: f64,
    /// Terrain z = slope_x · x (a plane through the origin).
    pub slope_x: f64,
}

impl SrbSim {
    /// What an ideal IMU on the trunk reads: gyro = Rᵀω, accelerometer = Rᵀ(a + g), with `acceleration`
    /// the base origin's velocity change over the previous tick (a real IMU lags by a sample).
    pub fn imu(&self, acceleration: Vector3<f64>) -> ImuReading {
        let to_body = self.orientation.to_rotation_matrix().inverse();
        ImuReading {
            gyro: (to_body * self.angular_velocity).into(),
            acc: (to_body * (acceleration + Vector3::new(0.0, 0.0, GRAVITY))).into(),
        }
    }

    /// Standing at `base_height` above the terrain at the origin, feet under the hips.
    pub fn standing(model: RobotModel, stand_q: [f64; NUM_JOINTS], base_height: f64) -> Self {
        let (inertia, com) = model.composite_inertia(&stand_q);
        let inertia_body = Matrix3::from_fn(|r, c| inertia[r][c]);
        let com_offset = Vector3::from(com);
        let base = Vector3::new(0.0, 0.0, base_height);
        let mut feet = [Vector3::zeros(); NUM_LEGS];
        for leg in Leg::ALL {
            let l = leg.index();
            let q = [stand_q[3 * l], stand_q[3 * l + 1], stand_q[3 * l + 2]];
            feet[l] = base + Vector3::from(model.foot_position_body(leg, q));
        }
        SrbSim {
            mass: model.total_mass(),
            inertia_body,
            com_offset,
            com: base + com_offset,
            velocity: Vector3::zeros(),
            orientation: UnitQuaternion::identity(),
            angular_velocity: Vector3::zeros(),
            feet,
            in_contact: [true; NUM_LEGS],
            q: stand_q,
            dq: [0.0; NUM_JOINTS],
            mu: 0.8,
            slope_x: 0.0,
            model,
        }
    }

    /// Put the terrain z = slope_x · x under the standing robot: feet move onto the plane.
    pub fn set_slope(&mut self, slope_x: f64, dt: f64) {
        self.slope_x = slope_x;
        for foot in &mut self.feet {
            foot.z = slope_x * foot.x + self.model.foot_radius();
        }
        self.update_joints(dt);
        self.dq = [0.0; NUM_JOINTS];
    }

    pub fn base_position(&self) -> Vector3<f64> {
        self.com - self.orientation * self.com_offset
    }

    pub fn state(&self) -> RobotState {
        let base = self.base_position();
        let lever = self.orientation * self.com_offset;
        let v_base = self.velocity - self.angular_velocity.cross(&lever);
        let q = self.orientation.quaternion();
        RobotState {
            base_position: [base.x, base.y, base.z],
            base_orientation: [q.w, q.i, q.j, q.k],
            base_linear_velocity: [v_base.x, v_base.y, v_base.z],
            base_angular_velocity: [
                self.angular_velocity.x,
                self.angular_velocity.y,
                self.angular_velocity.z,
            ],
            joint_positions: self.q,
            joint_velocities: self.dq,
        }
    }

    fn update_joints(&mut self, dt: f64) {
        let base = self.base_position();
        let rt = self.orientation.inverse();
        for leg in Leg::ALL {
            let l = leg.index();
            let p = rt * (self.feet[l] - base);
            if let Ok(q) = self.model.inverse_kinematics(leg, [p.x, p.y, p.z]) {
                for j in 0..3 {
                    let i = 3 * l + j;
                    self.dq[i] = (q[j] - self.q[i]) / dt;
                    self.q[i] = q[j];
                }
            }
        }
    }

    /// Ground reaction force on the robot at the foot of a stance leg that the command's joint
    /// torques produce, world frame: the foot is fixed, so the leg is static and
    /// `τ = Jᵀ f_foot + h(q, q̇)` with `f_foot` the force the foot exerts on the ground (base
    /// frame); the robot receives `−R f_foot`. This inverts the controller's stance law, so it
    /// returns the MPC's force exactly when the law is right and the torques are not clamped.
    pub fn stance_force_from_torques(&self, leg: Leg, torques: &[f64; NUM_JOINTS]) -> Vector3<f64> {
        let l = leg.index();
        let q = [self.q[3 * l], self.q[3 * l + 1], self.q[3 * l + 2]];
        let dq = [self.dq[3 * l], self.dq[3 * l + 1], self.dq[3 * l + 2]];
        let rotation = self.orientation.to_rotation_matrix();
        let gravity_body = rotation.inverse() * Vector3::new(0.0, 0.0, -GRAVITY);
        let bias =
            self.model
                .leg_bias(leg, q, dq, [gravity_body.x, gravity_body.y, gravity_body.z]);
        let jacobian = Matrix3::from_fn(|r, c| self.model.foot_jacobian_body(leg, q)[r][c]);
        let tau = Vector3::new(
            torques[3 * l] - bias[0],
            torques[3 * l + 1] - bias[1],
            torques[3 * l + 2] - bias[2],
        );
        let foot_force_body = jacobian
            .transpose()
            .try_inverse()
            .expect("stance leg away from a singular pose")
            * tau;
        -(rotation * foot_force_body)
    }

    /// Apply one command for `dt`, the stance forces being the ones the joint torques produce
    /// (see [`SrbSim::stance_force_from_torques`]) instead of the command's desired forces.
    pub fn apply_torques(&mut self, command: &Command, dt: f64, dynamics: bool) {
        let mut from_torques = *command;
        for leg in Leg::ALL {
            let l = leg.index();
            if command.contacts[l] && self.in_contact[l] {
                let f = self.stance_force_from_torques(leg, &command.joint_torques);
                from_torques.desired_forces[l] = [f.x, f.y, f.z];
            }
        }
        self.apply(&from_torques, dt, dynamics);
    }

    /// Apply one command for `dt`. The body is held while the controller is not balancing
    /// (passive, stand-up), as if lying on a support.
    pub fn apply(&mut self, command: &Command, dt: f64, dynamics: bool) {
        let mut force = Vector3::zeros();
        let mut torque = Vector3::zeros();
        for l in 0..NUM_LEGS {
            if command.contacts[l] {
                if !self.in_contact[l] {
                    let mut p = Vector3::from(command.desired_foot_positions[l]);
                    p.z = self.slope_x * p.x + self.model.foot_radius();
                    self.feet[l] = p;
                    self.in_contact[l] = true;
                }
                let mut f = Vector3::from(command.desired_forces[l]);
                f.z = f.z.max(0.0);
                let tangential = (f.x * f.x + f.y * f.y).sqrt();
                if tangential > self.mu * f.z && tangential > 0.0 {
                    let scale = self.mu * f.z / tangential;
                    f.x *= scale;
                    f.y *= scale;
                }
                force += f;
                torque += (self.feet[l] - self.com).cross(&f);
            } else {
                self.in_contact[l] = false;
                self.feet[l] = Vector3::from(command.desired_foot_positions[l]);
            }
        }
        if dynamics {
            let r = self.orientation.to_rotation_matrix();
            let inertia_world = r.matrix() * self.inertia_body * r.matrix().transpose();
            let inv = inertia_world.try_inverse().expect("inertia is invertible");
            let acceleration = force / self.mass - Vector3::new(0.0, 0.0, GRAVITY);
            let omega = self.angular_velocity;
            let angular_acceleration = inv * (torque - omega.cross(&(inertia_world * omega)));
            self.velocity += acceleration * dt;
            self.com += self.velocity * dt;
            self.angular_velocity += angular_acceleration * dt;
            self.orientation =
                UnitQuaternion::from_scaled_axis(self.angular_velocity * dt) * self.orientation;
        }
        self.update_joints(dt);
    }
}
