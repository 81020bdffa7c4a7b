//! Errors at the boundary: the thread's last error, status codes, panics caught.

use crate::*;
use skill_sdk::foreign::DeclError;
use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

pub(crate) fn set_error(message: &str) {
    let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = text);
}

/// Records `message` as the thread's last error and returns `code`.
pub(crate) fn fail(code: i32, message: &str) -> i32 {
    set_error(message);
    code
}

/// Runs `f`; a panic becomes `SF_ERR_INTERNAL` (or `on_panic`), never an abort.
pub(crate) fn guard<R>(on_panic: R, f: impl FnOnce() -> R) -> R {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|_| {
        set_error("internal error in libskillfab (a bug: please report it)");
        on_panic
    })
}

/// The text of a C string argument.
///
/// # Safety
/// `p` is NULL or points to a NUL-terminated string.
pub(crate) unsafe fn text<'a>(p: *const c_char, what: &str) -> Result<&'a str, i32> {
    if p.is_null() {
        return Err(fail(SF_ERR_NULL, &format!("{what} is NULL")));
    }
    // SAFETY: non-null and NUL-terminated by the caller's contract.
    unsafe { CStr::from_ptr(p) }
        .to_str()
        .map_err(|_| fail(SF_ERR_INVALID, &format!("{what} is not UTF-8")))
}

pub(crate) fn decl_error(e: &DeclError) -> i32 {
    let code = match e {
        DeclError::UnknownType { .. } => SF_ERR_UNKNOWN_TYPE,
        DeclError::BadParam { .. } => SF_ERR_PARAM,
        _ => SF_ERR_INVALID,
    };
    fail(code, &e.to_string())
}

pub(crate) fn index_result(r: Result<usize, DeclError>) -> i32 {
    match r {
        Ok(i) => i as i32,
        Err(e) => decl_error(&e),
    }
}

/// The message of the calling thread's last error ("" if none). Valid until the next call
/// into the library on this thread.
#[unsafe(no_mangle)]
pub extern "C" fn sf_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}
