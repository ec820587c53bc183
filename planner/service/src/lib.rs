//! The P-F planner as an LCM service: a thin adapter between lcm-types messages and pf-planner.
//!
//! Data flow: `terrain_map_t` on `<prefix>MAP` and `plan_request_t` on `<prefix>PLAN_REQUEST`
//! → [`preflight`] (size claims read from the raw bytes, before any allocation) → decode →
//! [`convert`] (validation, defaults) → bounded queue → worker pool → [`planning`] (pf-planner,
//! with P-F generators cached per map + settings) → `plan_reply_t` on `<prefix>PLAN_REPLY`.
//! [`service`] wires it to LCM and publishes `service_status_t` on `<prefix>SERVICE_STATUS`.

pub mod cache;
pub mod convert;
pub mod planning;
pub mod preflight;
pub mod service;

pub use service::{run, Channels, ServiceConfig, ServiceReport, DEFAULT_CHANNEL_PREFIX};
