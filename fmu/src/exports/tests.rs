use super::lifecycle::{fmi2EnterInitializationMode, fmi2FreeInstance, fmi2Instantiate};
use super::stepping::fmi2DoStep;
use crate::ffi::{Fmi2Status, FMI2_TRUE};

/// Our robot's GUID, as `bundle-fmu` writes it into modelDescription.xml.
fn our_guid() -> std::ffi::CString {
    let table =
        crate::variables::VariableTable::for_robot_config(&crate::bundle::default_robot_config())
            .unwrap();
    std::ffi::CString::new(table.guid()).unwrap()
}

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
    let guid = our_guid();
    // Good resources: the GUID alone is wrong (another interface's, or garbage).
    let dir = tempfile::tempdir().unwrap();
    crate::bundle::write_default_resources(dir.path());
    let good_resources =
        std::ffi::CString::new(format!("file://{}", dir.path().display())).unwrap();
    let mut other_interface = guid.clone().into_bytes();
    other_interface[1] = if other_interface[1] == b'0' {
        b'1'
    } else {
        b'0'
    };
    let other_interface = std::ffi::CString::new(other_interface).unwrap();
    // SAFETY: valid C strings, NULL callbacks are allowed.
    unsafe {
        for bad in [c"{x}", other_interface.as_c_str()] {
            let bad_guid = fmi2Instantiate(
                c"a".as_ptr(),
                1,
                bad.as_ptr(),
                good_resources.as_ptr(),
                std::ptr::null(),
                0,
                0,
            );
            assert!(bad_guid.is_null(), "{bad:?}");
        }
        let right = fmi2Instantiate(
            c"a".as_ptr(),
            1,
            guid.as_ptr(),
            good_resources.as_ptr(),
            std::ptr::null(),
            0,
            0,
        );
        assert!(!right.is_null(), "the GUID the table derives is accepted");
        fmi2FreeInstance(right);
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

/// A live instance on the repository's robot, from `fmi2Instantiate` with a resources folder
/// written for the test.
fn instantiate(dir: &std::path::Path, name: &std::ffi::CStr) -> crate::ffi::Fmi2Component {
    crate::bundle::write_default_resources(dir);
    let uri = std::ffi::CString::new(format!("file://{}", dir.display())).unwrap();
    let guid = our_guid();
    // SAFETY: valid C strings, NULL callbacks are allowed.
    let c = unsafe {
        fmi2Instantiate(
            name.as_ptr(),
            1,
            guid.as_ptr(),
            uri.as_ptr(),
            std::ptr::null(),
            0,
            0,
        )
    };
    assert!(!c.is_null(), "fmi2Instantiate");
    c
}

#[test]
fn state_pointers_are_checked_against_their_owner() {
    use super::fmu_state::{
        fmi2DeSerializeFMUstate, fmi2FreeFMUstate, fmi2GetFMUstate, fmi2SerializeFMUstate,
        fmi2SerializedFMUstateSize, fmi2SetFMUstate,
    };
    let dir = tempfile::tempdir().unwrap();
    let a = instantiate(dir.path(), c"a");
    let b = instantiate(dir.path(), c"b");
    let mut state_a: crate::ffi::Fmi2FmuState = std::ptr::null_mut();
    assert_eq!(fmi2GetFMUstate(a, &mut state_a), Fmi2Status::Ok);
    assert!(!state_a.is_null());
    // Overwriting an existing state keeps its pointer.
    let kept = state_a;
    assert_eq!(fmi2GetFMUstate(a, &mut state_a), Fmi2Status::Ok);
    assert_eq!(state_a, kept);
    assert_eq!(fmi2SetFMUstate(a, state_a), Fmi2Status::Ok);
    // Another instance's, a foreign and a NULL state are refused.
    assert_eq!(fmi2SetFMUstate(b, state_a), Fmi2Status::Error);
    let mut not_a_state = 0u64;
    let foreign = (&mut not_a_state as *mut u64).cast();
    assert_eq!(fmi2SetFMUstate(a, foreign), Fmi2Status::Error);
    assert_eq!(fmi2SetFMUstate(a, std::ptr::null_mut()), Fmi2Status::Error);
    let mut foreign_slot = foreign;
    assert_eq!(fmi2GetFMUstate(a, &mut foreign_slot), Fmi2Status::Error);
    assert_eq!(fmi2GetFMUstate(a, std::ptr::null_mut()), Fmi2Status::Error);

    // Serialize: a short buffer is refused; the blob moves to the other instance.
    let mut size = 0usize;
    assert_eq!(
        fmi2SerializedFMUstateSize(a, state_a, &mut size),
        Fmi2Status::Ok
    );
    let mut blob = vec![0u8; size];
    assert_eq!(
        fmi2SerializeFMUstate(a, state_a, blob.as_mut_ptr().cast(), size - 1),
        Fmi2Status::Error
    );
    assert_eq!(
        fmi2SerializeFMUstate(a, state_a, blob.as_mut_ptr().cast(), size),
        Fmi2Status::Ok
    );
    let mut state_b: crate::ffi::Fmi2FmuState = std::ptr::null_mut();
    assert_eq!(
        fmi2DeSerializeFMUstate(b, blob.as_ptr().cast(), size, &mut state_b),
        Fmi2Status::Ok
    );
    assert_eq!(fmi2SetFMUstate(b, state_b), Fmi2Status::Ok);
    let mut refused: crate::ffi::Fmi2FmuState = std::ptr::null_mut();
    assert_eq!(
        fmi2DeSerializeFMUstate(b, blob.as_ptr().cast(), size / 2, &mut refused),
        Fmi2Status::Error
    );
    assert!(refused.is_null());
    assert_eq!(
        fmi2DeSerializeFMUstate(b, std::ptr::null(), size, &mut refused),
        Fmi2Status::Error
    );

    // Freed states are gone; freeing NULL is a no-op; another instance cannot free it.
    assert_eq!(fmi2FreeFMUstate(b, &mut state_a), Fmi2Status::Error);
    let freed = state_a;
    assert_eq!(fmi2FreeFMUstate(a, &mut state_a), Fmi2Status::Ok);
    assert!(state_a.is_null());
    assert_eq!(fmi2FreeFMUstate(a, &mut state_a), Fmi2Status::Ok);
    assert_eq!(fmi2SetFMUstate(a, freed), Fmi2Status::Error);
    // SAFETY: live instances from fmi2Instantiate; b's state is freed with it.
    unsafe {
        fmi2FreeInstance(a);
        fmi2FreeInstance(b);
    }
    assert_eq!(fmi2SetFMUstate(b, state_b), Fmi2Status::Error);
}
