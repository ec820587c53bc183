//! The integration tests of `transport`, one test binary (each module was a test binary of its own).

mod hostile_udpm;
mod memq;
mod received_size;
mod udpm;
