//! The 34 `fmi2*` functions of FMI 2.0 Co-Simulation with their standard C signatures.
//!
//! Every body runs inside `catch_unwind` (a panic crossing `extern "C"` would abort the host)
//! and every failure becomes `fmi2Error` plus a message to the importer's logger. Component
//! pointers are checked against the set of live instances, so NULL, freed or foreign pointers
//! give `fmi2Error` instead of undefined behaviour.
//!
//! The shared guard machinery (live-instance set, `with_instance`, pointer checks) lives here;
//! the exports themselves are grouped by the part of the FMI call sequence they belong to.
//! Rust code normally reaches the FMU through `instance`; the functions are public so that Rust
//! callers (the `do_step` benchmark) can go through exactly the C API an importer uses.

use std::collections::HashSet;
use std::ffi::CStr;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Mutex, MutexGuard};

use crate::ffi::{Fmi2Component, Fmi2Status, Fmi2String};
use crate::instance::Instance;
use crate::FmuError;

mod fmu_state;
pub mod lifecycle;
pub mod stepping;
pub mod values;

#[cfg(test)]
mod tests;

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
