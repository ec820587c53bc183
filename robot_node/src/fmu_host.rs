//! Hosting an FMI 2.0 Co-Simulation FMU from its `.fmu` archive: unpacked into a temporary
//! directory, its binary opened with `dlopen` (libloading), and a small safe wrapper over the
//! fmi2 functions the node calls. Every call's status is checked; `fmi2Warning` is logged and
//! accepted, anything else is an error naming the call.

use std::ffi::{c_char, c_int, c_uint, c_void, CStr, CString};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::sync::Arc;

use thiserror::Error;

use crate::model_description::{ModelDescription, ModelDescriptionError};

/// Largest total uncompressed size accepted from an archive: the controller FMU is a few MB,
/// and a corrupt or hostile archive must not fill the disk.
const MAX_UNPACKED_BYTES: u64 = 512 << 20;

#[derive(Debug, Error)]
pub enum FmuError {
    #[error("cannot read the FMU archive {path}: {reason}")]
    Archive { path: PathBuf, reason: String },
    #[error(transparent)]
    ModelDescription(#[from] ModelDescriptionError),
    #[error("cannot load the FMU binary {path}: {reason}")]
    Load { path: PathBuf, reason: String },
    #[error("the FMU binary implements FMI {0:?}, not 2.0")]
    Version(String),
    #[error(
        "fmi2Instantiate returned NULL (GUID, resources or fmuType refused; see the FMU's log)"
    )]
    Instantiate,
    #[error("{call} returned {status}")]
    Call { call: &'static str, status: String },
    #[error("{call}: {reason}")]
    Argument {
        call: &'static str,
        reason: &'static str,
    },
}

/// An FMU archive unpacked into a temporary directory (removed when this is dropped) and its
/// model description.
pub struct UnpackedFmu {
    dir: tempfile::TempDir,
    pub description: ModelDescription,
}

impl UnpackedFmu {
    /// Unpacks `archive` (a `.fmu`) and parses its `modelDescription.xml`.
    pub fn open(archive: &Path) -> Result<Self, FmuError> {
        let fail = |reason: String| FmuError::Archive {
            path: archive.to_path_buf(),
            reason,
        };
        let file = std::fs::File::open(archive).map_err(|e| fail(e.to_string()))?;
        let mut zip = zip::ZipArchive::new(file).map_err(|e| fail(e.to_string()))?;
        let dir = tempfile::Builder::new()
            .prefix("pfnav-robot-fmu-")
            .tempdir()
            .map_err(|e| fail(format!("temporary directory: {e}")))?;
        let mut budget = MAX_UNPACKED_BYTES;
        for index in 0..zip.len() {
            let mut entry = zip.by_index(index).map_err(|e| fail(e.to_string()))?;
            // enclosed_name refuses absolute paths and `..`: nothing lands outside `dir`.
            let Some(relative) = entry.enclosed_name() else {
                return Err(fail(format!("entry {:?} leaves the archive", entry.name())));
            };
            let target = dir.path().join(relative);
            if entry.is_dir() {
                std::fs::create_dir_all(&target).map_err(|e| fail(e.to_string()))?;
                continue;
            }
            if let Some(parent) = target.parent() {
                std::fs::create_dir_all(parent).map_err(|e| fail(e.to_string()))?;
            }
            let mut out = std::fs::File::create(&target).map_err(|e| fail(e.to_string()))?;
            // Read one byte past the budget so that an over-long entry is detected, whatever
            // size its header claims.
            let copied = std::io::copy(&mut (&mut entry).take(budget + 1), &mut out)
                .map_err(|e| fail(e.to_string()))?;
            if copied > budget {
                return Err(fail(format!(
                    "more than {MAX_UNPACKED_BYTES} bytes uncompressed"
                )));
            }
            budget -= copied;
        }
        let xml = std::fs::read_to_string(dir.path().join("modelDescription.xml"))
            .map_err(|e| fail(format!("modelDescription.xml: {e}")))?;
        let description = ModelDescription::parse(&xml)?;
        Ok(Self { dir, description })
    }

    /// The binary for this platform: `binaries/linux64/<modelIdentifier>.so`.
    pub fn binary_path(&self) -> PathBuf {
        self.dir
            .path()
            .join("binaries/linux64")
            .join(format!("{}.so", self.description.model_identifier))
    }

    /// `fmuResourceLocation`: a `file://` URI of the `resources` folder.
    pub fn resources_uri(&self) -> String {
        format!("file://{}/resources", self.dir.path().display())
    }
}

type Component = *mut c_void;
type Status = c_int;
const FMI2_OK: Status = 0;
const FMI2_WARNING: Status = 1;
const FMI2_TRUE: c_int = 1;
const FMI2_FALSE: c_int = 0;
const FMI2_COSIMULATION: c_int = 1;

fn status_name(status: Status) -> String {
    match status {
        0 => "fmi2OK".to_owned(),
        1 => "fmi2Warning".to_owned(),
        2 => "fmi2Discard".to_owned(),
        3 => "fmi2Error".to_owned(),
        4 => "fmi2Fatal".to_owned(),
        5 => "fmi2Pending".to_owned(),
        other => format!("unknown status {other}"),
    }
}

/// The logger as the FMU calls it. C declares it variadic (printf-style); Rust cannot define a
/// variadic function, so it is declared with one argument after the format. On the Linux
/// x86-64 and AArch64 calling conventions a variadic pointer argument travels in the same
/// register as a fixed one, so this reads the argument of a `"%s"` format, which is how the
/// controller FMU always calls it. Other platforms get no logger (the FMU accepts NULL).
type Logger = unsafe extern "C" fn(
    *mut c_void,
    *const c_char,
    Status,
    *const c_char,
    *const c_char,
    *const c_char,
);

#[repr(C)]
struct CallbackFunctions {
    logger: Option<Logger>,
    allocate_memory: Option<unsafe extern "C" fn(usize, usize) -> *mut c_void>,
    free_memory: Option<unsafe extern "C" fn(*mut c_void)>,
    step_finished: Option<unsafe extern "C" fn(*mut c_void, Status)>,
    component_environment: *mut c_void,
}

fn c_text(pointer: *const c_char) -> String {
    if pointer.is_null() {
        return String::new();
    }
    // SAFETY: the FMU passes NUL-terminated strings valid for the duration of the call.
    unsafe { CStr::from_ptr(pointer) }
        .to_string_lossy()
        .into_owned()
}

unsafe extern "C" fn log_message(
    _environment: *mut c_void,
    instance: *const c_char,
    status: Status,
    category: *const c_char,
    format: *const c_char,
    argument: *const c_char,
) {
    // A panic must not unwind into the FMU's C frames.
    let _ = std::panic::catch_unwind(|| {
        let format = c_text(format);
        let message = if format == "%s" {
            c_text(argument)
        } else {
            format
        };
        let (instance, category) = (c_text(instance), c_text(category));
        match status {
            FMI2_OK => tracing::info!(target: "fmu", %instance, %category, "{message}"),
            FMI2_WARNING => tracing::warn!(target: "fmu", %instance, %category, "{message}"),
            _ => tracing::error!(target: "fmu", %instance, %category, "{message}"),
        }
    });
}

unsafe extern "C" fn allocate(count: usize, size: usize) -> *mut c_void {
    // SAFETY: calloc has no preconditions; NULL on failure is what FMI expects.
    unsafe { libc::calloc(count, size) }
}

unsafe extern "C" fn free(pointer: *mut c_void) {
    // SAFETY: the FMU frees only what `allocate` returned (or NULL).
    unsafe { libc::free(pointer) }
}

type GetVersion = unsafe extern "C" fn() -> *const c_char;
type Instantiate = unsafe extern "C" fn(
    *const c_char,
    c_int,
    *const c_char,
    *const c_char,
    *const CallbackFunctions,
    c_int,
    c_int,
) -> Component;
type FreeInstance = unsafe extern "C" fn(Component);
type SetupExperiment = unsafe extern "C" fn(Component, c_int, f64, f64, c_int, f64) -> Status;
type ComponentCall = unsafe extern "C" fn(Component) -> Status;
type SetReal = unsafe extern "C" fn(Component, *const c_uint, usize, *const f64) -> Status;
type GetReal = unsafe extern "C" fn(Component, *const c_uint, usize, *mut f64) -> Status;
type SetInteger = unsafe extern "C" fn(Component, *const c_uint, usize, *const c_int) -> Status;
type GetInteger = unsafe extern "C" fn(Component, *const c_uint, usize, *mut c_int) -> Status;
type DoStep = unsafe extern "C" fn(Component, f64, f64, c_int) -> Status;

/// The FMU's shared library and the fmi2 functions the node uses, resolved once.
pub struct Fmi2Library {
    instantiate: Instantiate,
    free_instance: FreeInstance,
    setup_experiment: SetupExperiment,
    enter_initialization_mode: ComponentCall,
    exit_initialization_mode: ComponentCall,
    terminate: ComponentCall,
    set_real: SetReal,
    get_real: GetReal,
    set_integer: SetInteger,
    get_integer: GetInteger,
    do_step: DoStep,
    // Last: the function pointers above point into it, so it is dropped after them.
    _library: libloading::Library,
}

impl Fmi2Library {
    /// Opens the shared library at `path` and resolves the functions; checks `fmi2GetVersion`.
    pub fn load(path: &Path) -> Result<Arc<Self>, FmuError> {
        let fail = |reason: String| FmuError::Load {
            path: path.to_path_buf(),
            reason,
        };
        // SAFETY: loading runs the library's initialisers; the FMU binary is the artifact the
        // operator chose to run, and it has no initialisers beyond Rust's runtime ones.
        let library = unsafe { libloading::Library::new(path) }.map_err(|e| fail(e.to_string()))?;
        macro_rules! symbol {
            ($name:literal, $ty:ty) => {{
                // SAFETY: the FMI 2.0 standard fixes each function's C signature; `$ty` is it.
                let function: libloading::Symbol<'_, $ty> = unsafe { library.get($name) }
                    .map_err(|e| fail(format!("{}: {e}", String::from_utf8_lossy($name))))?;
                *function
            }};
        }
        let get_version = symbol!(b"fmi2GetVersion", GetVersion);
        // SAFETY: fmi2GetVersion takes nothing and returns a static string.
        let version = c_text(unsafe { get_version() });
        if version != "2.0" {
            return Err(FmuError::Version(version));
        }
        Ok(Arc::new(Self {
            instantiate: symbol!(b"fmi2Instantiate", Instantiate),
            free_instance: symbol!(b"fmi2FreeInstance", FreeInstance),
            setup_experiment: symbol!(b"fmi2SetupExperiment", SetupExperiment),
            enter_initialization_mode: symbol!(b"fmi2EnterInitializationMode", ComponentCall),
            exit_initialization_mode: symbol!(b"fmi2ExitInitializationMode", ComponentCall),
            terminate: symbol!(b"fmi2Terminate", ComponentCall),
            set_real: symbol!(b"fmi2SetReal", SetReal),
            get_real: symbol!(b"fmi2GetReal", GetReal),
            set_integer: symbol!(b"fmi2SetInteger", SetInteger),
            get_integer: symbol!(b"fmi2GetInteger", GetInteger),
            do_step: symbol!(b"fmi2DoStep", DoStep),
            _library: library,
        }))
    }
}

/// One co-simulation instance. Not `Send`: it is created, stepped and freed on one thread.
pub struct CoSimulation {
    library: Arc<Fmi2Library>,
    component: NonNull<c_void>,
    // The FMU may keep the pointer to its callbacks for its whole life.
    _callbacks: Box<CallbackFunctions>,
    initialized: bool,
    _not_send: std::marker::PhantomData<*const ()>,
}

fn check(call: &'static str, status: Status) -> Result<(), FmuError> {
    match status {
        FMI2_OK => Ok(()),
        FMI2_WARNING => {
            tracing::warn!(call, "fmi2Warning");
            Ok(())
        }
        other => Err(FmuError::Call {
            call,
            status: status_name(other),
        }),
    }
}

impl CoSimulation {
    /// `fmi2Instantiate` of the unpacked FMU as a co-simulation slave.
    pub fn instantiate(
        library: Arc<Fmi2Library>,
        fmu: &UnpackedFmu,
        instance_name: &str,
    ) -> Result<Self, FmuError> {
        let strings = |value: &str| {
            CString::new(value).map_err(|_| FmuError::Argument {
                call: "fmi2Instantiate",
                reason: "a string contains a NUL byte",
            })
        };
        let name = strings(instance_name)?;
        let guid = strings(&fmu.description.guid)?;
        let resources = strings(&fmu.resources_uri())?;
        let logger: Option<Logger> = if cfg!(all(
            target_os = "linux",
            any(target_arch = "x86_64", target_arch = "aarch64")
        )) {
            Some(log_message)
        } else {
            None
        };
        let callbacks = Box::new(CallbackFunctions {
            logger,
            allocate_memory: Some(allocate),
            free_memory: Some(free),
            step_finished: None,
            component_environment: std::ptr::null_mut(),
        });
        // SAFETY: valid C strings and a callbacks struct that outlives the instance (owned by it).
        let component = unsafe {
            (library.instantiate)(
                name.as_ptr(),
                FMI2_COSIMULATION,
                guid.as_ptr(),
                resources.as_ptr(),
                &*callbacks,
                FMI2_FALSE,
                FMI2_FALSE,
            )
        };
        let component = NonNull::new(component).ok_or(FmuError::Instantiate)?;
        Ok(Self {
            library,
            component,
            _callbacks: callbacks,
            initialized: false,
            _not_send: std::marker::PhantomData,
        })
    }

    fn raw(&self) -> Component {
        self.component.as_ptr()
    }

    /// `fmi2SetupExperiment` (start time, no tolerance, no stop time) and
    /// `fmi2EnterInitializationMode`: parameters may be set after this.
    pub fn enter_initialization(&mut self, start_time: f64) -> Result<(), FmuError> {
        // SAFETY: live component of this library.
        let status = unsafe {
            (self.library.setup_experiment)(
                self.raw(),
                FMI2_FALSE,
                0.0,
                start_time,
                FMI2_FALSE,
                0.0,
            )
        };
        check("fmi2SetupExperiment", status)?;
        // SAFETY: as above.
        check("fmi2EnterInitializationMode", unsafe {
            (self.library.enter_initialization_mode)(self.raw())
        })?;
        self.initialized = true;
        Ok(())
    }

    /// `fmi2ExitInitializationMode`.
    pub fn exit_initialization(&mut self) -> Result<(), FmuError> {
        // SAFETY: live component of this library.
        check("fmi2ExitInitializationMode", unsafe {
            (self.library.exit_initialization_mode)(self.raw())
        })
    }

    fn same_length(call: &'static str, a: usize, b: usize) -> Result<(), FmuError> {
        if a == b {
            Ok(())
        } else {
            Err(FmuError::Argument {
                call,
                reason: "value references and values differ in length",
            })
        }
    }

    pub fn set_real(&mut self, references: &[u32], values: &[f64]) -> Result<(), FmuError> {
        Self::same_length("fmi2SetReal", references.len(), values.len())?;
        // SAFETY: both slices hold `len` elements and outlive the call.
        check("fmi2SetReal", unsafe {
            (self.library.set_real)(
                self.raw(),
                references.as_ptr(),
                references.len(),
                values.as_ptr(),
            )
        })
    }

    pub fn get_real(&mut self, references: &[u32], values: &mut [f64]) -> Result<(), FmuError> {
        Self::same_length("fmi2GetReal", references.len(), values.len())?;
        // SAFETY: both slices hold `len` elements; the FMU writes `len` values.
        check("fmi2GetReal", unsafe {
            (self.library.get_real)(
                self.raw(),
                references.as_ptr(),
                references.len(),
                values.as_mut_ptr(),
            )
        })
    }

    pub fn set_integer(&mut self, references: &[u32], values: &[i32]) -> Result<(), FmuError> {
        Self::same_length("fmi2SetInteger", references.len(), values.len())?;
        // SAFETY: both slices hold `len` elements and outlive the call.
        check("fmi2SetInteger", unsafe {
            (self.library.set_integer)(
                self.raw(),
                references.as_ptr(),
                references.len(),
                values.as_ptr(),
            )
        })
    }

    pub fn get_integer(&mut self, references: &[u32], values: &mut [i32]) -> Result<(), FmuError> {
        Self::same_length("fmi2GetInteger", references.len(), values.len())?;
        // SAFETY: both slices hold `len` elements; the FMU writes `len` values.
        check("fmi2GetInteger", unsafe {
            (self.library.get_integer)(
                self.raw(),
                references.as_ptr(),
                references.len(),
                values.as_mut_ptr(),
            )
        })
    }

    /// `fmi2DoStep(time, step)`.
    pub fn do_step(&mut self, time: f64, step: f64) -> Result<(), FmuError> {
        // SAFETY: live component of this library.
        check("fmi2DoStep", unsafe {
            (self.library.do_step)(self.raw(), time, step, FMI2_TRUE)
        })
    }
}

impl Drop for CoSimulation {
    fn drop(&mut self) {
        if self.initialized {
            // SAFETY: live component; terminate is allowed from any state after initialisation
            // (an error here only means the instance was already failed).
            let status = unsafe { (self.library.terminate)(self.raw()) };
            if let Err(e) = check("fmi2Terminate", status) {
                tracing::debug!(error = %e, "terminating the FMU instance");
            }
        }
        // SAFETY: the component came from fmi2Instantiate of this library and is freed once.
        unsafe { (self.library.free_instance)(self.raw()) };
    }
}
