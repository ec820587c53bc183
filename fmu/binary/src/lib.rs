//! The FMU's shared library. It holds no code of its own: linking `quad-controller-fmu` as a
//! cdylib exports its 34 `#[no_mangle]` `fmi2*` functions. A crate of its own so that its link,
//! and only its link, goes to zig for glibc 2.17 (`fmu/binary/link-gcc.sh`): the FMU binary comes out
//! of the same release build as everything else.

pub use quad_controller_fmu::exports;
