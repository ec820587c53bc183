//! The integration tests of `lcm_types`, one test binary (each module was a test binary of its own).

// Generated for the whole test schema; each test module uses part of it.
#[allow(dead_code)]
mod test_types {
    include!(concat!(env!("OUT_DIR"), "/codegen_test_types.rs"));
}
mod codegen_schemas;
mod decode_limits;
mod fuzz_decoders;
mod golden_lcm_gen;
