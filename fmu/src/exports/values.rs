//! `fmi2Get*`/`fmi2Set*`: the C arrays are checked here and the values converted between the
//! FMI C types and [`Value`], so the instance only ever sees typed, in-bounds requests.

use super::{slice_from, slice_from_mut, with_instance};
use crate::ffi::{
    Fmi2Boolean, Fmi2Component, Fmi2Integer, Fmi2Real, Fmi2Status, Fmi2String, Fmi2ValueReference,
    FMI2_FALSE, FMI2_TRUE,
};
use crate::variables::{ScalarType, Value};
use crate::FmuError;

fn get_values<T: Copy>(
    c: Fmi2Component,
    function: &'static str,
    expected: ScalarType,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *mut T,
    convert: fn(Value) -> T,
) -> Fmi2Status {
    with_instance(c, function, |instance| {
        // SAFETY: the importer passes arrays of `nvr` elements (FMI calling convention).
        let vrs = unsafe { slice_from(vr, nvr, "vr") }?;
        let out = unsafe { slice_from_mut(value, nvr, "value") }?;
        instance.get(function, expected, vrs, |k, v| out[k] = convert(v))?;
        Ok(Fmi2Status::Ok)
    })
}

fn set_values<T: Copy>(
    c: Fmi2Component,
    function: &'static str,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *const T,
    convert: fn(T) -> Value,
) -> Fmi2Status {
    with_instance(c, function, |instance| {
        // SAFETY: as in `get_values`.
        let vrs = unsafe { slice_from(vr, nvr, "vr") }?;
        let values = unsafe { slice_from(value, nvr, "value") }?;
        instance.set_with(function, vrs, |k| convert(values[k]))?;
        Ok(Fmi2Status::Ok)
    })
}

fn value_as_real(v: Value) -> Fmi2Real {
    match v {
        Value::Real(x) => x,
        Value::Integer(i) => f64::from(i),
        Value::Boolean(b) => f64::from(u8::from(b)),
    }
}

fn value_as_integer(v: Value) -> Fmi2Integer {
    match v {
        Value::Integer(i) => i,
        Value::Boolean(b) => i32::from(b),
        // Not reachable: get() only returns Integer values for Integer calls.
        Value::Real(x) => x as i32,
    }
}

fn value_as_boolean(v: Value) -> Fmi2Boolean {
    match v {
        Value::Boolean(true) => FMI2_TRUE,
        Value::Boolean(false) => FMI2_FALSE,
        // Not reachable: get() only returns Boolean values for Boolean calls.
        other => Fmi2Boolean::from(value_as_real(other) != 0.0),
    }
}

/// `fmi2GetReal`.
///
/// # Safety
/// `vr` and `value` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetReal(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *mut Fmi2Real,
) -> Fmi2Status {
    get_values(
        c,
        "fmi2GetReal",
        ScalarType::Real,
        vr,
        nvr,
        value,
        value_as_real,
    )
}

/// `fmi2GetInteger`.
///
/// # Safety
/// `vr` and `value` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetInteger(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *mut Fmi2Integer,
) -> Fmi2Status {
    get_values(
        c,
        "fmi2GetInteger",
        ScalarType::Integer,
        vr,
        nvr,
        value,
        value_as_integer,
    )
}

/// `fmi2GetBoolean`.
///
/// # Safety
/// `vr` and `value` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetBoolean(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *mut Fmi2Boolean,
) -> Fmi2Status {
    get_values(
        c,
        "fmi2GetBoolean",
        ScalarType::Boolean,
        vr,
        nvr,
        value,
        value_as_boolean,
    )
}

/// `fmi2GetString`: the FMU has no String variables, so any value reference is unknown.
///
/// # Safety
/// `vr` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetString(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    _value: *mut Fmi2String,
) -> Fmi2Status {
    with_instance(c, "fmi2GetString", |instance| {
        let vrs = slice_from(vr, nvr, "vr")?;
        // Checks the state first, then reports the first (necessarily unknown) reference.
        instance.get("fmi2GetString", ScalarType::Real, &[], |_, _| {})?;
        match vrs.first() {
            Some(&vr) => Err(FmuError::InvalidArgument(format!(
                "valueReference {vr} does not refer to a String variable (this FMU has none)"
            ))),
            None => Ok(Fmi2Status::Ok),
        }
    })
}

/// `fmi2SetReal`.
///
/// # Safety
/// `vr` and `value` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetReal(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *const Fmi2Real,
) -> Fmi2Status {
    set_values(c, "fmi2SetReal", vr, nvr, value, Value::Real)
}

/// `fmi2SetInteger`.
///
/// # Safety
/// `vr` and `value` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetInteger(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *const Fmi2Integer,
) -> Fmi2Status {
    set_values(c, "fmi2SetInteger", vr, nvr, value, Value::Integer)
}

/// `fmi2SetBoolean`.
///
/// # Safety
/// `vr` and `value` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetBoolean(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *const Fmi2Boolean,
) -> Fmi2Status {
    set_values(c, "fmi2SetBoolean", vr, nvr, value, |b| {
        Value::Boolean(b != FMI2_FALSE)
    })
}

/// `fmi2SetString`: no String variables.
///
/// # Safety
/// `vr` must point to `nvr` elements.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetString(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    _value: *const Fmi2String,
) -> Fmi2Status {
    with_instance(c, "fmi2SetString", |instance| {
        let vrs = slice_from(vr, nvr, "vr")?;
        instance.set("fmi2SetString", &[], &[])?;
        match vrs.first() {
            Some(&vr) => Err(FmuError::InvalidArgument(format!(
                "valueReference {vr} does not refer to a String variable (this FMU has none)"
            ))),
            None => Ok(Fmi2Status::Ok),
        }
    })
}
