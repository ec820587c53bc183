//! The integration tests of `controller`, one test binary (each module was a test binary of its own).

mod closed_loop;
mod closed_loop_estimator;
mod command_stream;
#[path = "../common/mod.rs"]
mod common;
mod controller;
mod model;
mod mpc;
mod robot_config;
mod state_restore;
mod terrain;
mod third_party_robots;
