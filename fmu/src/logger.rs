//! Messages to the importer through its `fmi2CallbackLogger`.
//!
//! Errors, discards and warnings (a fault that sent the controller to damping) are always passed on (they explain a non-OK return status);
//! informational messages (`logEvents`) only after `loggingOn` / `fmi2SetDebugLogging` enabled them.

use std::ffi::CString;

use crate::ffi::{Fmi2CallbackLogger, Fmi2ComponentEnvironment, Fmi2Status};

/// Log categories declared in `modelDescription.xml`, with their descriptions.
pub const LOG_CATEGORIES: [(&str, &str); 4] = [
    (
        "logEvents",
        "Informational messages: instantiation, FSM state changes, termination.",
    ),
    (
        "logStatusWarning",
        "Warnings: a controller fault (failed check and its value) that dropped the state machine to damping.",
    ),
    (
        "logStatusDiscard",
        "Messages accompanying fmi2Discard (a doStep the controller could not complete).",
    ),
    (
        "logStatusError",
        "Messages accompanying fmi2Error: wrong call order, bad value references, invalid values.",
    ),
];

/// The importer's logger plus the instance's logging switches.
#[derive(Clone)]
pub struct Logger {
    callback: Option<Fmi2CallbackLogger>,
    environment: Fmi2ComponentEnvironment,
    instance_name: CString,
    logging_on: bool,
    enabled: [bool; LOG_CATEGORIES.len()],
}

impl Logger {
    /// A logger that forwards to `callback` (nothing is logged when it is `None`).
    pub fn new(
        callback: Option<Fmi2CallbackLogger>,
        environment: Fmi2ComponentEnvironment,
        instance_name: &str,
        logging_on: bool,
    ) -> Logger {
        Logger {
            callback,
            environment,
            instance_name: to_c_string(instance_name),
            logging_on,
            enabled: [true; LOG_CATEGORIES.len()],
        }
    }

    /// Applies `fmi2SetDebugLogging`: an empty category list enables (or disables) all categories.
    /// Returns the name of the first unknown category, if any (nothing is changed then).
    pub fn set_debug_logging(
        &mut self,
        logging_on: bool,
        categories: &[String],
    ) -> Result<(), String> {
        let mut enabled = if categories.is_empty() {
            [true; LOG_CATEGORIES.len()]
        } else {
            [false; LOG_CATEGORIES.len()]
        };
        for category in categories {
            let index = LOG_CATEGORIES
                .iter()
                .position(|(name, _)| name == category)
                .ok_or_else(|| category.clone())?;
            enabled[index] = true;
        }
        self.logging_on = logging_on;
        self.enabled = enabled;
        Ok(())
    }

    /// Sends `message` with `status`; see the module docs for what is filtered.
    pub fn log(&self, status: Fmi2Status, message: &str) {
        let category = status.log_category();
        if status == Fmi2Status::Ok {
            let enabled = LOG_CATEGORIES
                .iter()
                .position(|(name, _)| *name == category)
                .is_some_and(|index| self.enabled[index]);
            if !self.logging_on || !enabled {
                return;
            }
        }
        let Some(callback) = self.callback else {
            return;
        };
        let category = to_c_string(category);
        let message = to_c_string(message);
        // The logger is printf-style: passing the text as the "%s" argument keeps any '%' in it literal.
        // SAFETY: `callback` was supplied by the importer for exactly this call signature; every
        // pointer argument is a live NUL-terminated string owned by this frame or by `self`.
        unsafe {
            callback(
                self.environment,
                self.instance_name.as_ptr(),
                status as i32,
                category.as_ptr(),
                c"%s".as_ptr(),
                message.as_ptr(),
            );
        }
    }
}

/// A C string of `text` with interior NUL bytes replaced (they cannot cross the C boundary).
fn to_c_string(text: &str) -> CString {
    CString::new(text.replace('\0', "\u{FFFD}")).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_debug_category_is_rejected_and_changes_nothing() {
        let mut logger = Logger::new(None, std::ptr::null_mut(), "x", false);
        let err = logger
            .set_debug_logging(true, &["logEvents".to_owned(), "logBogus".to_owned()])
            .unwrap_err();
        assert_eq!(err, "logBogus");
        assert!(!logger.logging_on);
        assert_eq!(logger.enabled, [true; 4]);
        logger
            .set_debug_logging(true, &["logStatusError".to_owned()])
            .unwrap();
        assert!(logger.logging_on);
        assert_eq!(logger.enabled, [false, false, false, true]);
    }

    #[test]
    fn nul_bytes_are_replaced() {
        assert_eq!(to_c_string("a\0b").to_str().unwrap(), "a\u{FFFD}b");
    }
}
