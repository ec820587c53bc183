//! The C types of the FMI 2.0 API (`fmi2TypesPlatform.h`, `fmi2FunctionTypes.h`), written out by
//! hand so that building the FMU needs no C toolchain or libclang.

use std::ffi::{c_char, c_int, c_uint, c_void};

/// `fmi2Component`: the opaque instance pointer handed to the importer.
pub type Fmi2Component = *mut c_void;
/// `fmi2ComponentEnvironment`: the importer's opaque pointer passed back to its callbacks.
pub type Fmi2ComponentEnvironment = *mut c_void;
/// `fmi2FMUstate`: opaque saved state (unsupported here).
pub type Fmi2FmuState = *mut c_void;
/// `fmi2ValueReference`.
pub type Fmi2ValueReference = c_uint;
/// `fmi2Real`.
pub type Fmi2Real = f64;
/// `fmi2Integer`.
pub type Fmi2Integer = c_int;
/// `fmi2Boolean` (`fmi2True` = 1, `fmi2False` = 0).
pub type Fmi2Boolean = c_int;
/// `fmi2String`.
pub type Fmi2String = *const c_char;
/// `fmi2Byte`.
pub type Fmi2Byte = c_char;

/// `fmi2True`.
pub const FMI2_TRUE: Fmi2Boolean = 1;
/// `fmi2False`.
pub const FMI2_FALSE: Fmi2Boolean = 0;

/// `fmi2Status`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fmi2Status {
    /// `fmi2OK`.
    Ok = 0,
    /// `fmi2Warning`.
    Warning = 1,
    /// `fmi2Discard`.
    Discard = 2,
    /// `fmi2Error`.
    Error = 3,
    /// `fmi2Fatal`.
    Fatal = 4,
    /// `fmi2Pending`.
    Pending = 5,
}

impl Fmi2Status {
    /// The `logStatus…` category the FMI standard suggests for a message with this status.
    pub fn log_category(self) -> &'static str {
        match self {
            Fmi2Status::Ok => "logEvents",
            Fmi2Status::Warning => "logStatusWarning",
            Fmi2Status::Discard => "logStatusDiscard",
            Fmi2Status::Error => "logStatusError",
            Fmi2Status::Fatal => "logStatusFatal",
            Fmi2Status::Pending => "logStatusPending",
        }
    }
}

/// `fmi2Type` value of Co-Simulation (`fmi2ModelExchange` is 0).
pub const FMI2_COSIMULATION: c_int = 1;

/// `fmi2StatusKind` values.
pub mod status_kind {
    use std::ffi::c_int;
    /// `fmi2DoStepStatus`.
    pub const DO_STEP_STATUS: c_int = 0;
    /// `fmi2PendingStatus`.
    pub const PENDING_STATUS: c_int = 1;
    /// `fmi2LastSuccessfulTime`.
    pub const LAST_SUCCESSFUL_TIME: c_int = 2;
    /// `fmi2Terminated`.
    pub const TERMINATED: c_int = 3;
}

/// `fmi2CallbackLogger`: printf-style and variadic, hence always called with `"%s"`.
pub type Fmi2CallbackLogger =
    unsafe extern "C" fn(Fmi2ComponentEnvironment, Fmi2String, c_int, Fmi2String, Fmi2String, ...);
/// `fmi2CallbackAllocateMemory`.
pub type Fmi2CallbackAllocateMemory = unsafe extern "C" fn(usize, usize) -> *mut c_void;
/// `fmi2CallbackFreeMemory`.
pub type Fmi2CallbackFreeMemory = unsafe extern "C" fn(*mut c_void);
/// `fmi2StepFinished`.
pub type Fmi2StepFinished = unsafe extern "C" fn(Fmi2ComponentEnvironment, c_int);

/// `fmi2CallbackFunctions`. Function pointers are `Option` because importers may pass NULL.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct Fmi2CallbackFunctions {
    /// Message sink.
    pub logger: Option<Fmi2CallbackLogger>,
    /// Allocator (unused: the FMU allocates with Rust's allocator, see `canNotUseMemoryManagementFunctions`).
    pub allocate_memory: Option<Fmi2CallbackAllocateMemory>,
    /// Deallocator (unused, as above).
    pub free_memory: Option<Fmi2CallbackFreeMemory>,
    /// Asynchronous step completion (unused: `canRunAsynchronuously="false"`).
    pub step_finished: Option<Fmi2StepFinished>,
    /// Passed back as the first argument of `logger`.
    pub component_environment: Fmi2ComponentEnvironment,
}
