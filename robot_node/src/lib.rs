//! `pfnav-robot`: the controller FMU as a real-time LCM node, as it would run on a robot.
//!
//! Every period (1 ms at 1 kHz) on an absolute deadline it takes the newest `low_state_t`,
//! steps the FMU and sends `low_cmd_t` (torque mode: tau = the controller's torques,
//! kp = kd = 0); on a fault it sends damping instead and says why in `robot_status_t`.
//!
//! Modules, one job each: [`model_description`] (names → value references), [`fmu_host`]
//! (unpack, dlopen, the fmi2 calls), [`controller`] (messages ↔ FMU variables), [`inbox`]
//! (decode and check received packets), [`safety`] (torque or damping, and why), [`stats`]
//! (fixed-memory timing histograms), [`clock`] (absolute deadlines, SCHED_FIFO, mlockall),
//! [`node`] (the LCM thread and the control loop).

pub mod clock;
pub mod controller;
pub mod delay;
pub mod fmu_host;
pub mod inbox;
pub mod model_description;
pub mod node;
pub mod platform;
pub mod safety;
pub mod schedule;
pub mod stats;

pub use node::{
    run, LoopTrigger, NodeConfig, RobotChannels, RunReport, DEFAULT_DEADLINE_MARGIN,
    MAX_CATCH_UP_PERIODS, MISS_FACTOR,
};
