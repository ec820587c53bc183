//! Quadruped controller stack: URDF model, gait state machine, convex MPC on ground reaction
//! forces, leg torque control. Pure library: no I/O besides reading the robot config and its URDF
//! on request, no FFI, deterministic.
//!
//! Data flow per tick (`Controller::step`, 1 kHz): measured [`RobotState`] + planner
//! [`Reference`] → FSM (passive / stand-up / stand / locomotion / damping) → gait schedule and
//! Raibert footholds at terrain height → convex MPC on the single rigid body every
//! `mpc_every_ticks` ticks (and on contact changes) → stance legs `τ = Jᵀ Rᵀ(−f) + h`, swing legs
//! joint-space inverse dynamics + PD along the swing trajectory → torques clamped to the URDF
//! effort limits.
//!
//! API notes (the types are in [`api`]; this comment and the item docs are the reference):
//! - [`Command::desired_foot_positions`] (world frame) is reported for the harness and tests.
//! - [`ControllerConfig`]: `Default` is the tuned set, JSON field names = Rust names, unknown
//!   fields are rejected.
//! - [`Reference::body_height`] ≤ 0 selects the configured nominal height.
//! - [`Controller::set_height_map`] takes a local elevation map ([`HeightMap`], 11×11 samples
//!   around the robot; the FMU inputs `terrain.map.*`). With it footholds use the map's height and
//!   avoid edges and steep spots, the swing apex clears the terrain, the base height, pitch and
//!   xy follow the footholds and the friction normal is the ground's under the stance feet.
//! - Leg dynamics take gravity in the base frame: `leg_bias(leg, q, dq, gravity_base)`.
//! - The MPC is exposed as [`mpc::ConvexMpc`] (used by the benchmark and tests); the OSQP
//!   comparison in `benches/mpc.rs` uses the `osqp` crate 0.6 (a dev-dependency), because
//!   `osqp-sys` 1.0 downloads qdldl from GitHub at build time (impossible offline).
//! - Base state velocities must be world-frame; the CoM is taken at the standing-pose composite
//!   CoM offset from the base origin.
//! - [`Controller::step_with_sensors`] also takes the IMU, contact and position-fix readings
//!   ([`SensorReadings`]); with [`ControllerConfig::estimator`] = [`EstimatorKind::Kalman`] the
//!   stages run on the [`estimator`]'s estimate and the base pose of the [`RobotState`] is read at
//!   the first tick only. [`Command::estimate`] reports the estimate and its status bits.
//!
//! Module layout: the pipeline stages of `Controller::step` are private modules (`estimate`,
//! `fsm`, `footholds`, `mpc_schedule`, `leg_control`, `validation`) except [`estimator`], public
//! for its benchmark and its status table; [`math`] holds the shared geometry helpers, so no two
//! modules depend on each other. [`robot_config`] is the robot description (TOML) the [`model`]
//! is built from.
pub mod api;
pub mod config;
pub mod controller;
mod estimate;
pub mod estimator;
mod footholds;
mod fsm;
pub mod gait;
mod leg_control;
pub mod limits;
pub mod math;
pub mod model;
pub mod mpc;
mod mpc_schedule;
mod reference_governor;
pub mod robot_config;
mod statics;
mod steep_ground;
pub mod tuning;
mod validation;

pub use api::*;
pub use config::{ControllerConfig, RobotScale, Scaling};
pub use controller::{Controller, ControllerState};
pub use estimator::{EstimatorStatus, StatusFlag};
pub use fsm::FsmTransition;
pub use leg_control::KNEE_GUARD_BEND;
pub use model::RobotModel;
pub use robot_config::{PackagePath, RobotConfig};
