//! Status codes, the per-thread error message, and the guard every exported function runs its
//! body in, so that no panic unwinds into C and every failure leaves a message.

use std::cell::RefCell;
use std::ffi::{CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};

/// What a call returned. `SKF_STATUS_OK` is zero; on anything else
/// [`skf_last_error`] names the function and the argument or field that was wrong.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SkfStatus {
    /// Success.
    Ok = 0,
    /// A required pointer argument was null.
    NullPointer = 1,
    /// An argument was invalid: a length, an index, a NaN, a setting, a handle of another model.
    InvalidArgument = 2,
    /// The `.skf` bytes are not a valid weight file (truncated, corrupt, unsupported version).
    InvalidFile = 3,
    /// The file could not be read.
    Io = 4,
    /// An internal error (a bug): the call was abandoned without unwinding into the caller.
    Internal = 5,
}

/// A failure: its status and message.
pub(crate) struct Failure {
    status: SkfStatus,
    message: String,
}

impl Failure {
    pub(crate) fn new(status: SkfStatus, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
        }
    }

    pub(crate) fn invalid(message: impl core::fmt::Display) -> Self {
        Self::new(SkfStatus::InvalidArgument, message.to_string())
    }
}

/// A null-pointer failure naming the argument.
pub(crate) fn null(argument: &str) -> Failure {
    Failure::new(SkfStatus::NullPointer, format!("`{argument}` is null"))
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(function: &str, message: &str) {
    // A message with an interior NUL (from a joint name) is cut there rather than lost.
    let text = format!("{function}: {message}");
    let bytes: Vec<u8> = text.bytes().take_while(|&b| b != 0).collect();
    let c = CString::new(bytes).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

/// Runs `body` for the exported function `function`: its failure or panic becomes a status and
/// the thread's last error message. The success path touches neither (no allocation).
pub(crate) fn guard(function: &str, body: impl FnOnce() -> Result<(), Failure>) -> SkfStatus {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => SkfStatus::Ok,
        Ok(Err(f)) => {
            set_last_error(function, &f.message);
            f.status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| String::from("unknown panic"));
            set_last_error(function, &format!("internal error: {what}"));
            SkfStatus::Internal
        }
    }
}

/// The message of the last failed call on this thread (empty before any failure), as a
/// NUL-terminated UTF-8 string that stays valid until the next failing call on the same
/// thread. Never null.
#[unsafe(no_mangle)]
pub extern "C" fn skf_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}
