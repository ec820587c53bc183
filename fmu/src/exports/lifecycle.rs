//! Inquiry, logging, instantiation, initialisation, termination and reset: the calls that
//! create an instance and move it through its states, where a wrong GUID, type or resource
//! folder must be refused before any controller exists.

use std::collections::HashSet;
use std::ffi::{c_char, c_int};
use std::panic::{catch_unwind, AssertUnwindSafe};

use super::{c_str_lossy, live_instances, slice_from, with_instance};
use crate::ffi::{
    Fmi2Boolean, Fmi2CallbackFunctions, Fmi2Component, Fmi2Real, Fmi2Status, Fmi2String,
    FMI2_COSIMULATION, FMI2_FALSE,
};
use crate::instance::Instance;
use crate::logger::Logger;
use crate::{resources, FmuError};

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
    let location = c_str_lossy(fmu_resource_location)
        .ok_or_else(|| FmuError::Instantiate("fmuResourceLocation is NULL".to_owned()))?;
    let dir = resources::resource_dir_from_uri(&location)?;
    let loaded = resources::load(&dir)?;
    // The GUID is the interface of the variable table the resources give this binary.
    if guid != loaded.guid {
        return Err(FmuError::Instantiate(format!(
            "GUID {guid:?} does not match this FMU's {:?} (modelDescription.xml from a different build?)",
            loaded.guid
        )));
    }
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
            super::fmu_state::free_states_of(c);
            // SAFETY: the pointer came from Box::into_raw in fmi2Instantiate and was live.
            drop(Box::from_raw(c as *mut Instance));
        }));
    }
}

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
