//! The 34 `fmi2*` functions of FMI 2.0 Co-Simulation with their standard C signatures.
//!
//! Every body runs inside `catch_unwind` (a panic crossing `extern "C"` would abort the host)
//! and every failure becomes `fmi2Error` plus a message to the importer's logger. Component
//! pointers are checked against the set of live instances, so NULL, freed or foreign pointers
//! give `fmi2Error` instead of undefined behaviour.

use std::collections::HashSet;
use std::ffi::{c_char, c_int, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Mutex, MutexGuard};

use crate::ffi::{
    status_kind, Fmi2Boolean, Fmi2CallbackFunctions, Fmi2Component, Fmi2FmuState, Fmi2Integer,
    Fmi2Real, Fmi2Status, Fmi2String, Fmi2ValueReference, FMI2_COSIMULATION, FMI2_FALSE, FMI2_TRUE,
};
use crate::instance::Instance;
use crate::logger::Logger;
use crate::variables::{ScalarType, Value};
use crate::{resources, FmuError, GUID};

/// Addresses of the instances created by `fmi2Instantiate` and not yet freed.
static LIVE_INSTANCES: Mutex<Option<HashSet<usize>>> = Mutex::new(None);

fn live_instances() -> MutexGuard<'static, Option<HashSet<usize>>> {
    // A panic while holding the lock cannot leave the set inconsistent (single insert/remove).
    LIVE_INSTANCES
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn is_live(c: Fmi2Component) -> bool {
    live_instances()
        .as_ref()
        .is_some_and(|set| set.contains(&(c as usize)))
}

fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic payload".to_owned())
}

/// Runs `body` on the instance behind `c`; logs failures and maps them to a status.
fn with_instance(
    c: Fmi2Component,
    function: &'static str,
    body: impl FnOnce(&mut Instance) -> Result<Fmi2Status, FmuError>,
) -> Fmi2Status {
    if c.is_null() || !is_live(c) {
        // No instance means no logger to explain this to.
        return Fmi2Status::Error;
    }
    // SAFETY: `c` is in the live set, so it is a `Box<Instance>` leaked by fmi2Instantiate and
    // not yet freed; FMI forbids concurrent calls on one instance.
    let instance = unsafe { &mut *(c as *mut Instance) };
    let result = catch_unwind(AssertUnwindSafe(|| body(instance)));
    match result {
        Ok(Ok(status)) => status,
        Ok(Err(error)) => {
            instance
                .logger
                .log(Fmi2Status::Error, &format!("{function}: {error}"));
            Fmi2Status::Error
        }
        Err(payload) => {
            instance.logger.log(
                Fmi2Status::Error,
                &format!(
                    "{function}: internal panic: {}",
                    panic_text(payload.as_ref())
                ),
            );
            Fmi2Status::Error
        }
    }
}

/// A slice from a C array; NULL is accepted only for an empty array.
///
/// # Safety
/// A non-null `ptr` must point to `len` initialised elements valid for the call's duration.
unsafe fn slice_from<'a, T>(ptr: *const T, len: usize, what: &str) -> Result<&'a [T], FmuError> {
    if len == 0 {
        Ok(&[])
    } else if ptr.is_null() {
        Err(FmuError::InvalidArgument(format!(
            "{what} is NULL but nvr = {len}"
        )))
    } else {
        Ok(std::slice::from_raw_parts(ptr, len))
    }
}

/// Mutable counterpart of [`slice_from`].
///
/// # Safety
/// As for [`slice_from`], and the memory must be writable and not aliased.
unsafe fn slice_from_mut<'a, T>(
    ptr: *mut T,
    len: usize,
    what: &str,
) -> Result<&'a mut [T], FmuError> {
    if len == 0 {
        Ok(&mut [])
    } else if ptr.is_null() {
        Err(FmuError::InvalidArgument(format!(
            "{what} is NULL but nvr = {len}"
        )))
    } else {
        Ok(std::slice::from_raw_parts_mut(ptr, len))
    }
}

/// # Safety
/// `ptr` must be NULL or a NUL-terminated string.
unsafe fn c_str_lossy(ptr: Fmi2String) -> Option<String> {
    (!ptr.is_null()).then(|| CStr::from_ptr(ptr).to_string_lossy().into_owned())
}

fn unsupported(c: Fmi2Component, function: &'static str, capability: &'static str) -> Fmi2Status {
    with_instance(c, function, |_| {
        Err(FmuError::Unsupported {
            function,
            capability,
        })
    })
}

// ---------------------------------------------------------------------------------------------
// Inquiry, logging, instantiation

/// `fmi2GetTypesPlatform`.
#[no_mangle]
pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
    c"default".as_ptr()
}

/// `fmi2GetVersion`.
#[no_mangle]
pub extern "C" fn fmi2GetVersion() -> *const c_char {
    c"2.0".as_ptr()
}

/// `fmi2SetDebugLogging`.
///
/// # Safety
/// `categories` must hold `n_categories` valid C strings (or be NULL when the count is 0).
#[no_mangle]
pub unsafe extern "C" fn fmi2SetDebugLogging(
    c: Fmi2Component,
    logging_on: Fmi2Boolean,
    n_categories: usize,
    categories: *const Fmi2String,
) -> Fmi2Status {
    with_instance(c, "fmi2SetDebugLogging", |instance| {
        let pointers = slice_from(categories, n_categories, "categories")?;
        let mut names = Vec::with_capacity(pointers.len());
        for &p in pointers {
            names.push(
                c_str_lossy(p)
                    .ok_or_else(|| FmuError::InvalidArgument("a category is NULL".to_owned()))?,
            );
        }
        instance
            .logger
            .set_debug_logging(logging_on != FMI2_FALSE, &names)
            .map_err(|name| FmuError::InvalidArgument(format!("unknown log category {name:?}")))?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2Instantiate`: NULL (with a logged reason) on an empty name, a non-CS type, a wrong GUID
/// or unusable resources.
///
/// # Safety
/// String arguments must be NULL or NUL-terminated; `functions` NULL or a valid struct.
#[no_mangle]
pub unsafe extern "C" fn fmi2Instantiate(
    instance_name: Fmi2String,
    fmu_type: c_int,
    fmu_guid: Fmi2String,
    fmu_resource_location: Fmi2String,
    functions: *const Fmi2CallbackFunctions,
    _visible: Fmi2Boolean,
    logging_on: Fmi2Boolean,
) -> Fmi2Component {
    let result = catch_unwind(AssertUnwindSafe(|| {
        let callbacks = if functions.is_null() {
            None
        } else {
            Some(*functions)
        };
        let name = c_str_lossy(instance_name).unwrap_or_default();
        let logger = Logger::new(
            callbacks.and_then(|f| f.logger),
            callbacks.map_or(std::ptr::null_mut(), |f| f.component_environment),
            &name,
            logging_on != FMI2_FALSE,
        );
        match instantiate(&name, fmu_type, fmu_guid, fmu_resource_location, &logger) {
            Ok(instance) => {
                let pointer = Box::into_raw(Box::new(instance));
                live_instances()
                    .get_or_insert_with(HashSet::new)
                    .insert(pointer as usize);
                pointer as Fmi2Component
            }
            Err(error) => {
                logger.log(Fmi2Status::Error, &format!("fmi2Instantiate: {error}"));
                std::ptr::null_mut()
            }
        }
    }));
    result.unwrap_or(std::ptr::null_mut())
}

/// # Safety
/// As for [`fmi2Instantiate`].
unsafe fn instantiate(
    name: &str,
    fmu_type: c_int,
    fmu_guid: Fmi2String,
    fmu_resource_location: Fmi2String,
    logger: &Logger,
) -> Result<Instance, FmuError> {
    if name.is_empty() {
        return Err(FmuError::Instantiate(
            "instanceName is NULL or empty".to_owned(),
        ));
    }
    if fmu_type != FMI2_COSIMULATION {
        return Err(FmuError::Instantiate(format!(
            "fmuType {fmu_type} requested, but this FMU only supports Co-Simulation ({FMI2_COSIMULATION})"
        )));
    }
    let guid = c_str_lossy(fmu_guid).unwrap_or_default();
    if guid != GUID {
        return Err(FmuError::Instantiate(format!(
            "GUID {guid:?} does not match this FMU's {GUID:?} (modelDescription.xml from a different build?)"
        )));
    }
    let location = c_str_lossy(fmu_resource_location)
        .ok_or_else(|| FmuError::Instantiate("fmuResourceLocation is NULL".to_owned()))?;
    let dir = resources::resource_dir_from_uri(&location)?;
    let loaded = resources::load(&dir)?;
    let instance = Instance::new(loaded, logger.clone());
    logger.log(
        Fmi2Status::Ok,
        &format!("instantiated with resources from {}", dir.display()),
    );
    Ok(instance)
}

/// `fmi2FreeInstance`: unknown or already freed pointers are ignored.
///
/// # Safety
/// `c` must be NULL or a pointer returned by `fmi2Instantiate`.
#[no_mangle]
pub unsafe extern "C" fn fmi2FreeInstance(c: Fmi2Component) {
    let removed = live_instances()
        .as_mut()
        .is_some_and(|set| set.remove(&(c as usize)));
    if removed {
        // Dropping runs no user code that could panic, but keep the FFI boundary panic-free.
        let _ = catch_unwind(AssertUnwindSafe(|| {
            // SAFETY: the pointer came from Box::into_raw in fmi2Instantiate and was live.
            drop(Box::from_raw(c as *mut Instance));
        }));
    }
}

// ---------------------------------------------------------------------------------------------
// Initialisation, termination, reset

/// `fmi2SetupExperiment`.
#[no_mangle]
pub extern "C" fn fmi2SetupExperiment(
    c: Fmi2Component,
    _tolerance_defined: Fmi2Boolean,
    _tolerance: Fmi2Real,
    start_time: Fmi2Real,
    stop_time_defined: Fmi2Boolean,
    stop_time: Fmi2Real,
) -> Fmi2Status {
    with_instance(c, "fmi2SetupExperiment", |instance| {
        let stop = (stop_time_defined != FMI2_FALSE).then_some(stop_time);
        instance.setup_experiment(start_time, stop)?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2EnterInitializationMode`.
#[no_mangle]
pub extern "C" fn fmi2EnterInitializationMode(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, "fmi2EnterInitializationMode", |instance| {
        instance.enter_initialization_mode()?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2ExitInitializationMode`.
#[no_mangle]
pub extern "C" fn fmi2ExitInitializationMode(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, "fmi2ExitInitializationMode", |instance| {
        instance.exit_initialization_mode()?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2Terminate`.
#[no_mangle]
pub extern "C" fn fmi2Terminate(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, "fmi2Terminate", |instance| {
        instance.terminate()?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2Reset`.
#[no_mangle]
pub extern "C" fn fmi2Reset(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, "fmi2Reset", |instance| {
        instance.reset();
        Ok(Fmi2Status::Ok)
    })
}

// ---------------------------------------------------------------------------------------------
// Getting and setting values

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
        let values: Vec<Value> = unsafe { slice_from(value, nvr, "value") }?
            .iter()
            .map(|&v| convert(v))
            .collect();
        instance.set(function, vrs, &values)?;
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

// ---------------------------------------------------------------------------------------------
// FMU state, directional derivatives: declared unsupported in modelDescription.xml

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

// ---------------------------------------------------------------------------------------------
// Co-Simulation

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn null_and_foreign_components_are_rejected() {
        assert_eq!(
            fmi2EnterInitializationMode(std::ptr::null_mut()),
            Fmi2Status::Error
        );
        let mut not_an_instance = 0u64;
        let foreign = (&mut not_an_instance as *mut u64).cast();
        assert_eq!(
            fmi2DoStep(foreign, 0.0, 0.001, FMI2_TRUE),
            Fmi2Status::Error
        );
        // SAFETY: freeing an unknown pointer must be a no-op.
        unsafe { fmi2FreeInstance(foreign) };
    }

    #[test]
    fn wrong_guid_type_or_name_give_null() {
        let resources = c"file:///nonexistent";
        let guid = std::ffi::CString::new(GUID).unwrap();
        // SAFETY: valid C strings, NULL callbacks are allowed.
        unsafe {
            let bad_guid = fmi2Instantiate(
                c"a".as_ptr(),
                1,
                c"{x}".as_ptr(),
                resources.as_ptr(),
                std::ptr::null(),
                0,
                0,
            );
            assert!(bad_guid.is_null());
            let model_exchange = fmi2Instantiate(
                c"a".as_ptr(),
                0,
                guid.as_ptr(),
                resources.as_ptr(),
                std::ptr::null(),
                0,
                0,
            );
            assert!(model_exchange.is_null());
            let empty_name = fmi2Instantiate(
                c"".as_ptr(),
                1,
                guid.as_ptr(),
                resources.as_ptr(),
                std::ptr::null(),
                0,
                0,
            );
            assert!(empty_name.is_null());
            let missing_resources = fmi2Instantiate(
                c"a".as_ptr(),
                1,
                guid.as_ptr(),
                resources.as_ptr(),
                std::ptr::null(),
                0,
                0,
            );
            assert!(missing_resources.is_null());
        }
    }
}
