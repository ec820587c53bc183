//! FMU states (get, set, free, serialize; see [`crate::saved_state`]) and directional
//! derivatives (declared unsupported, but exported all the same because importers resolve every
//! `fmi2*` symbol at load time).
//!
//! An `fmi2FMUstate` is a `Box<InstanceState>` handed out as a pointer. Like components, state
//! pointers are checked against the set of live states, and against the instance that made them:
//! NULL, freed, foreign or another instance's pointers give `fmi2Error`, never undefined
//! behaviour. Freeing an instance frees the states it still owns.

use std::collections::HashMap;
use std::ffi::c_char;
use std::sync::{Mutex, MutexGuard};

use super::{slice_from, unsupported, with_instance};
use crate::ffi::{Fmi2Component, Fmi2FmuState, Fmi2Real, Fmi2Status, Fmi2ValueReference};
use crate::saved_state::InstanceState;
use crate::FmuError;

/// Live state addresses and the component that owns each.
static LIVE_STATES: Mutex<Option<HashMap<usize, usize>>> = Mutex::new(None);

fn live_states() -> MutexGuard<'static, Option<HashMap<usize, usize>>> {
    // A panic while holding the lock cannot leave the map inconsistent (single insert/remove).
    LIVE_STATES
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The state behind `state`, if `c` made it and it is not freed.
fn owned_state<'a>(
    c: Fmi2Component,
    state: Fmi2FmuState,
) -> Result<&'a mut InstanceState, FmuError> {
    let owner = live_states()
        .as_ref()
        .and_then(|map| map.get(&(state as usize)).copied());
    match owner {
        // SAFETY: a live entry is a `Box<InstanceState>` leaked by `store_state` and not yet
        // freed; FMI forbids concurrent calls on its owning instance.
        Some(owner) if owner == c as usize => Ok(unsafe { &mut *(state as *mut InstanceState) }),
        Some(_) => Err(FmuError::InvalidArgument(
            "FMUstate belongs to another instance".to_owned(),
        )),
        None => Err(FmuError::InvalidArgument(
            "FMUstate is not a live state of this FMU (NULL, freed or foreign)".to_owned(),
        )),
    }
}

/// Stores `saved` in `*slot`: into the state already there (one of `c`'s), or a new one.
///
/// # Safety
/// `slot` must be NULL or point to a writable `fmi2FMUstate`.
unsafe fn store_state(
    c: Fmi2Component,
    slot: *mut Fmi2FmuState,
    saved: InstanceState,
) -> Result<(), FmuError> {
    if slot.is_null() {
        return Err(FmuError::InvalidArgument(
            "the FMUstate* argument is NULL".to_owned(),
        ));
    }
    let existing = *slot;
    if existing.is_null() {
        let state = Box::into_raw(Box::new(saved)).cast();
        live_states()
            .get_or_insert_with(HashMap::new)
            .insert(state as usize, c as usize);
        *slot = state;
    } else {
        *owned_state(c, existing)? = saved;
    }
    Ok(())
}

/// Frees every state `c` still owns (from `fmi2FreeInstance`).
pub(super) fn free_states_of(c: Fmi2Component) {
    let mut guard = live_states();
    let Some(map) = guard.as_mut() else { return };
    let owned: Vec<usize> = map
        .iter()
        .filter(|(_, &owner)| owner == c as usize)
        .map(|(&state, _)| state)
        .collect();
    for state in owned {
        map.remove(&state);
        // SAFETY: the entry was live, so the pointer is a leaked `Box<InstanceState>`.
        drop(unsafe { Box::from_raw(state as *mut InstanceState) });
    }
}

/// `fmi2GetFMUstate`: a new state in `*state` when it is NULL, else overwrites that state.
#[no_mangle]
pub extern "C" fn fmi2GetFMUstate(c: Fmi2Component, state: *mut Fmi2FmuState) -> Fmi2Status {
    with_instance(c, "fmi2GetFMUstate", |instance| {
        // SAFETY: FMI passes a pointer to an fmi2FMUstate variable; NULL is checked.
        unsafe { store_state(c, state, instance.save_state())? };
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2SetFMUstate`: the instance continues from `state`.
#[no_mangle]
pub extern "C" fn fmi2SetFMUstate(c: Fmi2Component, state: Fmi2FmuState) -> Fmi2Status {
    with_instance(c, "fmi2SetFMUstate", |instance| {
        instance.restore_state(owned_state(c, state)?)?;
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2FreeFMUstate`: frees `*state` and sets it to NULL (a NULL `*state` is a no-op).
#[no_mangle]
pub extern "C" fn fmi2FreeFMUstate(c: Fmi2Component, state: *mut Fmi2FmuState) -> Fmi2Status {
    with_instance(c, "fmi2FreeFMUstate", |_| {
        if state.is_null() {
            return Err(FmuError::InvalidArgument(
                "the FMUstate* argument is NULL".to_owned(),
            ));
        }
        // SAFETY: FMI passes a pointer to an fmi2FMUstate variable; NULL is checked.
        let existing = unsafe { *state };
        if existing.is_null() {
            return Ok(Fmi2Status::Ok);
        }
        owned_state(c, existing)?;
        if let Some(map) = live_states().as_mut() {
            map.remove(&(existing as usize));
        }
        // SAFETY: `owned_state` found it live and owned by `c`; it is out of the map now.
        drop(unsafe { Box::from_raw(existing as *mut InstanceState) });
        // SAFETY: as above, `state` is a valid pointer.
        unsafe { *state = std::ptr::null_mut() };
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2SerializedFMUstateSize`.
#[no_mangle]
pub extern "C" fn fmi2SerializedFMUstateSize(
    c: Fmi2Component,
    state: Fmi2FmuState,
    size: *mut usize,
) -> Fmi2Status {
    with_instance(c, "fmi2SerializedFMUstateSize", |instance| {
        if size.is_null() {
            return Err(FmuError::InvalidArgument("size is NULL".to_owned()));
        }
        let blob = owned_state(c, state)?.encode(instance.guid(), instance.robot_crc())?;
        // SAFETY: non-NULL pointer to a size_t, per the FMI signature.
        unsafe { *size = blob.len() };
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2SerializeFMUstate`: writes the serialized state into the caller's buffer of `size`
/// bytes (at least `fmi2SerializedFMUstateSize`).
#[no_mangle]
pub extern "C" fn fmi2SerializeFMUstate(
    c: Fmi2Component,
    state: Fmi2FmuState,
    serialized_state: *mut c_char,
    size: usize,
) -> Fmi2Status {
    with_instance(c, "fmi2SerializeFMUstate", |instance| {
        let blob = owned_state(c, state)?.encode(instance.guid(), instance.robot_crc())?;
        if size < blob.len() {
            return Err(FmuError::InvalidArgument(format!(
                "buffer of {size} bytes, the serialized state needs {}",
                blob.len()
            )));
        }
        // SAFETY: the caller provides `size` writable bytes; NULL is refused for size > 0.
        let buffer = unsafe {
            super::slice_from_mut(serialized_state.cast::<u8>(), size, "serializedState")?
        };
        buffer[..blob.len()].copy_from_slice(&blob);
        Ok(Fmi2Status::Ok)
    })
}

/// `fmi2DeSerializeFMUstate`: checks the serialized state and stores it in `*state` (a new
/// state when NULL). A blob of another FMU, version or robot, truncated or corrupted, gives
/// `fmi2Error` and changes nothing.
#[no_mangle]
pub extern "C" fn fmi2DeSerializeFMUstate(
    c: Fmi2Component,
    serialized_state: *const c_char,
    size: usize,
    state: *mut Fmi2FmuState,
) -> Fmi2Status {
    with_instance(c, "fmi2DeSerializeFMUstate", |instance| {
        // SAFETY: the caller provides `size` readable bytes; NULL is refused for size > 0.
        let blob = unsafe { slice_from(serialized_state.cast::<u8>(), size, "serializedState")? };
        let saved = InstanceState::decode(blob, instance.guid(), instance.robot_crc())?;
        // SAFETY: FMI passes a pointer to an fmi2FMUstate variable; NULL is checked.
        unsafe { store_state(c, state, saved)? };
        Ok(Fmi2Status::Ok)
    })
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
