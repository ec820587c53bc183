//! Co-Simulation stepping and status queries: `fmi2DoStep` is synchronous, so the status calls
//! only report what a finished step left behind.

use std::ffi::c_int;

use super::{slice_from_mut, unsupported, with_instance};
use crate::ffi::{
    status_kind, Fmi2Boolean, Fmi2Component, Fmi2Integer, Fmi2Real, Fmi2Status, Fmi2String,
    Fmi2ValueReference, FMI2_FALSE, FMI2_TRUE,
};
use crate::FmuError;

/// `fmi2SetRealInputDerivatives` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2SetRealInputDerivatives(
    c: Fmi2Component,
    _vr: *const Fmi2ValueReference,
    _nvr: usize,
    _order: *const Fmi2Integer,
    _value: *const Fmi2Real,
) -> Fmi2Status {
    unsupported(
        c,
        "fmi2SetRealInputDerivatives",
        "canInterpolateInputs=\"false\"",
    )
}

/// `fmi2GetRealOutputDerivatives` (unsupported).
#[no_mangle]
pub extern "C" fn fmi2GetRealOutputDerivatives(
    c: Fmi2Component,
    _vr: *const Fmi2ValueReference,
    _nvr: usize,
    _order: *const Fmi2Integer,
    _value: *mut Fmi2Real,
) -> Fmi2Status {
    unsupported(
        c,
        "fmi2GetRealOutputDerivatives",
        "maxOutputDerivativeOrder=\"0\"",
    )
}

/// `fmi2DoStep`: see the crate docs for how steps map to control ticks.
#[no_mangle]
pub extern "C" fn fmi2DoStep(
    c: Fmi2Component,
    current_communication_point: Fmi2Real,
    communication_step_size: Fmi2Real,
    _no_set_fmu_state_prior_to_current_point: Fmi2Boolean,
) -> Fmi2Status {
    with_instance(c, "fmi2DoStep", |instance| {
        instance.do_step(current_communication_point, communication_step_size)?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2CancelStep`: steps are synchronous, there is never one to cancel.
#[no_mangle]
pub extern "C" fn fmi2CancelStep(c: Fmi2Component) -> Fmi2Status {
    unsupported(c, "fmi2CancelStep", "canRunAsynchronuously=\"false\"")
}

/// `fmi2GetStatus`: `fmi2DoStepStatus` only exists for asynchronous steps.
#[no_mangle]
pub extern "C" fn fmi2GetStatus(c: Fmi2Component, kind: c_int, _value: *mut c_int) -> Fmi2Status {
    with_instance(c, "fmi2GetStatus", |instance| {
        instance.check_status_call("fmi2GetStatus")?;
        Err(FmuError::InvalidArgument(format!(
            "status kind {kind}: no fmi2Status is available (steps never return fmi2Pending)"
        )))
    })
}

/// `fmi2GetRealStatus`: `fmi2LastSuccessfulTime`.
///
/// # Safety
/// `value` must be NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealStatus(
    c: Fmi2Component,
    kind: c_int,
    value: *mut Fmi2Real,
) -> Fmi2Status {
    with_instance(c, "fmi2GetRealStatus", |instance| {
        instance.check_status_call("fmi2GetRealStatus")?;
        if kind != status_kind::LAST_SUCCESSFUL_TIME {
            return Err(FmuError::InvalidArgument(format!(
                "status kind {kind}: only fmi2LastSuccessfulTime ({}) is a Real status",
                status_kind::LAST_SUCCESSFUL_TIME
            )));
        }
        let out = slice_from_mut(value, 1, "value")?;
        out[0] = instance.last_successful_time()?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2GetIntegerStatus`: no Integer status kinds exist in FMI 2.0.
#[no_mangle]
pub extern "C" fn fmi2GetIntegerStatus(
    c: Fmi2Component,
    kind: c_int,
    _value: *mut Fmi2Integer,
) -> Fmi2Status {
    with_instance(c, "fmi2GetIntegerStatus", |instance| {
        instance.check_status_call("fmi2GetIntegerStatus")?;
        Err(FmuError::InvalidArgument(format!(
            "status kind {kind}: FMI 2.0 defines no Integer status"
        )))
    })
}

/// `fmi2GetBooleanStatus`: `fmi2Terminated` (always false: the FMU never asks to stop).
///
/// # Safety
/// `value` must be NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetBooleanStatus(
    c: Fmi2Component,
    kind: c_int,
    value: *mut Fmi2Boolean,
) -> Fmi2Status {
    with_instance(c, "fmi2GetBooleanStatus", |instance| {
        instance.check_status_call("fmi2GetBooleanStatus")?;
        if kind != status_kind::TERMINATED {
            return Err(FmuError::InvalidArgument(format!(
                "status kind {kind}: only fmi2Terminated ({}) is a Boolean status",
                status_kind::TERMINATED
            )));
        }
        let out = slice_from_mut(value, 1, "value")?;
        out[0] = if instance.terminated_status()? {
            FMI2_TRUE
        } else {
            FMI2_FALSE
        };
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2GetStringStatus`: `fmi2PendingStatus` only exists for asynchronous steps.
#[no_mangle]
pub extern "C" fn fmi2GetStringStatus(
    c: Fmi2Component,
    kind: c_int,
    _value: *mut Fmi2String,
) -> Fmi2Status {
    with_instance(c, "fmi2GetStringStatus", |instance| {
        instance.check_status_call("fmi2GetStringStatus")?;
        Err(FmuError::InvalidArgument(format!(
            "status kind {kind}: no pending step to describe (steps never return fmi2Pending)"
        )))
    })
}
