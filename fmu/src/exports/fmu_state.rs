//! FMU state and directional derivatives: declared unsupported in modelDescription.xml, but
//! exported all the same because importers resolve every `fmi2*` symbol at load time.

use std::ffi::c_char;

use super::unsupported;
use crate::ffi::{Fmi2Component, Fmi2FmuState, Fmi2Real, Fmi2Status, Fmi2ValueReference};

/// `fmi2GetFMUstate` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2GetFMUstate(c: Fmi2Component, _state: *mut Fmi2FmuState) -> Fmi2Status {
    unsupported(c, "fmi2GetFMUstate", "canGetAndSetFMUstate=\"false\"")
}

/// `fmi2SetFMUstate` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2SetFMUstate(c: Fmi2Component, _state: Fmi2FmuState) -> Fmi2Status {
    unsupported(c, "fmi2SetFMUstate", "canGetAndSetFMUstate=\"false\"")
}

/// `fmi2FreeFMUstate` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2FreeFMUstate(c: Fmi2Component, _state: *mut Fmi2FmuState) -> Fmi2Status {
    unsupported(c, "fmi2FreeFMUstate", "canGetAndSetFMUstate=\"false\"")
}

/// `fmi2SerializedFMUstateSize` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2SerializedFMUstateSize(
    c: Fmi2Component,
    _state: Fmi2FmuState,
    _size: *mut usize,
) -> Fmi2Status {
    unsupported(
        c,
        "fmi2SerializedFMUstateSize",
        "canSerializeFMUstate=\"false\"",
    )
}

/// `fmi2SerializeFMUstate` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2SerializeFMUstate(
    c: Fmi2Component,
    _state: Fmi2FmuState,
    _serialized_state: *mut c_char,
    _size: usize,
) -> Fmi2Status {
    unsupported(c, "fmi2SerializeFMUstate", "canSerializeFMUstate=\"false\"")
}

/// `fmi2DeSerializeFMUstate` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2DeSerializeFMUstate(
    c: Fmi2Component,
    _serialized_state: *const c_char,
    _size: usize,
    _state: *mut Fmi2FmuState,
) -> Fmi2Status {
    unsupported(
        c,
        "fmi2DeSerializeFMUstate",
        "canSerializeFMUstate=\"false\"",
    )
}

/// `fmi2GetDirectionalDerivative` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2GetDirectionalDerivative(
    c: Fmi2Component,
    _v_unknown_ref: *const Fmi2ValueReference,
    _n_unknown: usize,
    _v_known_ref: *const Fmi2ValueReference,
    _n_known: usize,
    _dv_known: *const Fmi2Real,
    _dv_unknown: *mut Fmi2Real,
) -> Fmi2Status {
    unsupported(
        c,
        "fmi2GetDirectionalDerivative",
        "providesDirectionalDerivative=\"false\"",
    )
}
