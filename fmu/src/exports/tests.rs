use super::lifecycle::{fmi2EnterInitializationMode, fmi2FreeInstance, fmi2Instantiate};
use super::stepping::fmi2DoStep;
use crate::ffi::{Fmi2Status, FMI2_TRUE};
use crate::GUID;

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
