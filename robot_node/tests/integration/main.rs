//! The integration tests of pfnav-robot, one test binary: the node with the controller FMU on a
//! memq bus, a fake body in lockstep and a fake navigator (`support`).

mod faults;
mod lockstep;
mod support;
