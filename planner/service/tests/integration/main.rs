//! The integration tests of `service`, one test binary (each module was a test binary of its own).

#[path = "../common/mod.rs"]
mod common;
mod hostile_packets;
mod map_updates;
mod oversize_map;
mod realtime;
mod rejected_maps;
mod service_memq;
