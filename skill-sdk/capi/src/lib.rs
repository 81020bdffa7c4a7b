//! # libskillfab — the C ABI of skill-sdk
//!
//! C, C++ and (through `ctypes`) Python programs use this library to be skills and
//! sequencers. The header `include/skillfab.h` is generated from this file by cbindgen (a
//! test keeps it in sync); the message structs are in `include/skillfab_msgs.h`, generated
//! from the Rust message schemas.
//!
//! ## Layout
//! - errors: every call returns a status (`SF_OK` or a negative `SF_ERR_*`) or a null
//!   pointer, and `sf_last_error()` says what went wrong, in words, on the calling thread;
//! - a skill: `sf_skill_new`, `sf_skill_input/output/proposal`, `sf_skill_param_*`,
//!   `sf_skill_compute`, then `sf_skill_run` (registration, cycles, parameter updates and
//!   shutdown are the SDK's);
//! - inside the compute callback: `sf_input`, `sf_output`, `sf_param_*`, `sf_run_cycle`,
//!   `sf_run_fail`;
//! - a sequencer: `sf_client_*` (activate, parameters, queries, monitors and their events);
//! - `sf_log`: a log line on the skill's log stream.
//!
//! Nothing here can crash the process on bad arguments: null pointers, strings that are not
//! UTF-8, unknown message types, wrong sizes and out-of-range indexes are errors, and a
//! panic inside the library is caught at the boundary and reported as `SF_ERR_INTERNAL`.

#![allow(non_camel_case_types)]

use skill_sdk::foreign::{DeclError, ForeignRun, ForeignSkill};
use skill_sdk::params::{ParamKind, ParamSpec, ParamValue};
use skill_sdk::skill::SkillError;
use skillfab_client::{Client, ClientError};
use skillfab_proto::control::MonitorMode;
use skillfab_proto::decl::Mode;
use skillfab_proto::domain::Domain;
use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char, c_void};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Duration;

/// Success.
pub const SF_OK: i32 = 0;
/// A required pointer was NULL.
pub const SF_ERR_NULL: i32 = -1;
/// A name or text that is not allowed (not UTF-8, bad characters, declared twice, ...).
pub const SF_ERR_INVALID: i32 = -2;
/// No shared message type of that name.
pub const SF_ERR_UNKNOWN_TYPE: i32 = -3;
/// A size that does not match the message type.
pub const SF_ERR_SIZE: i32 = -4;
/// An input, output or parameter index that does not exist, or an input with no sample.
pub const SF_ERR_INDEX: i32 = -5;
/// A parameter declaration or value that is refused (bounds, type).
pub const SF_ERR_PARAM: i32 = -6;
/// The fabric failed or refused: no manager, a refused request, a transport error.
pub const SF_ERR_FABRIC: i32 = -7;
/// No answer in time.
pub const SF_ERR_TIMEOUT: i32 = -8;
/// The caller's buffer is too small (the message says how large it must be).
pub const SF_ERR_BUFFER: i32 = -9;
/// A bug in the library, caught at the boundary.
pub const SF_ERR_INTERNAL: i32 = -10;

/// Runs once per cycle when all its inputs for that cycle exist; the cycle waits for it.
pub const SF_SYNC: i32 = 0;
/// Free-running on the latest inputs; the cycle never waits for it.
pub const SF_ASYNC: i32 = 1;

/// Monitor fires the first cycle its condition holds, then is removed.
pub const SF_MONITOR_ONCE: i32 = 0;
/// Monitor fires each cycle its condition becomes true.
pub const SF_MONITOR_EDGE: i32 = 1;
/// Monitor fires every cycle its condition holds.
pub const SF_MONITOR_EVERY: i32 = 2;

/// Log levels of `sf_log`.
pub const SF_LOG_ERROR: i32 = 0;
/// Warning.
pub const SF_LOG_WARN: i32 = 1;
/// Information.
pub const SF_LOG_INFO: i32 = 2;
/// Debugging detail (shown with RUST_LOG=debug or the console's verbose mode).
pub const SF_LOG_DEBUG: i32 = 3;

/// A skill being declared (opaque).
pub struct sf_skill {
    inner: ForeignSkill,
}

/// One run of a skill, valid only during the compute callback (opaque).
pub struct sf_run {
    _private: [u8; 0],
}

/// A sequencer's connection to a domain's manager (opaque).
pub struct sf_client {
    inner: Client,
    /// An event that did not fit the caller's buffer, returned again by the next call.
    pending: Option<CString>,
}

/// The compute callback: return 0 for success, anything else fails the run (its outputs are
/// then not sent). `user` is the pointer given to `sf_skill_compute`.
pub type sf_compute_fn = Option<unsafe extern "C" fn(run: *mut sf_run, user: *mut c_void) -> i32>;

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_error(message: &str) {
    let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = text);
}

/// Records `message` as the thread's last error and returns `code`.
fn fail(code: i32, message: &str) -> i32 {
    set_error(message);
    code
}

/// Runs `f`; a panic becomes `SF_ERR_INTERNAL` (or `on_panic`), never an abort.
fn guard<R>(on_panic: R, f: impl FnOnce() -> R) -> R {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|_| {
        set_error("internal error in libskillfab (a bug: please report it)");
        on_panic
    })
}

/// The text of a C string argument.
///
/// # Safety
/// `p` is NULL or points to a NUL-terminated string.
unsafe fn text<'a>(p: *const c_char, what: &str) -> Result<&'a str, i32> {
    if p.is_null() {
        return Err(fail(SF_ERR_NULL, &format!("{what} is NULL")));
    }
    // SAFETY: non-null and NUL-terminated by the caller's contract.
    unsafe { CStr::from_ptr(p) }
        .to_str()
        .map_err(|_| fail(SF_ERR_INVALID, &format!("{what} is not UTF-8")))
}

fn decl_error(e: &DeclError) -> i32 {
    let code = match e {
        DeclError::UnknownType { .. } => SF_ERR_UNKNOWN_TYPE,
        DeclError::BadParam { .. } => SF_ERR_PARAM,
        _ => SF_ERR_INVALID,
    };
    fail(code, &e.to_string())
}

fn index_result(r: Result<usize, DeclError>) -> i32 {
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

/// Starts declaring a skill of `kind` (also its default instance name), `SF_SYNC` or
/// `SF_ASYNC`. Returns NULL on error (see `sf_last_error`).
///
/// # Safety
/// `kind` is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_new(kind: *const c_char, mode: i32) -> *mut sf_skill {
    guard(std::ptr::null_mut(), || {
        // SAFETY: forwarded caller contract.
        let Ok(kind) = (unsafe { text(kind, "kind") }) else {
            return std::ptr::null_mut();
        };
        let mode = match mode {
            SF_SYNC => Mode::Sync,
            SF_ASYNC => Mode::Async,
            other => {
                fail(
                    SF_ERR_INVALID,
                    &format!("mode {other}: use SF_SYNC or SF_ASYNC"),
                );
                return std::ptr::null_mut();
            }
        };
        match ForeignSkill::new(kind, mode, skillfab_msgs::registry()) {
            Ok(inner) => Box::into_raw(Box::new(sf_skill { inner })),
            Err(e) => {
                decl_error(&e);
                std::ptr::null_mut()
            }
        }
    })
}

/// Frees a skill that was not run. NULL is ignored.
///
/// # Safety
/// `skill` is NULL or a pointer from `sf_skill_new` not yet freed or run.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_free(skill: *mut sf_skill) {
    if !skill.is_null() {
        // SAFETY: made by Box::into_raw in sf_skill_new, not freed before (caller contract).
        drop(unsafe { Box::from_raw(skill) });
    }
}

/// Runs `f` on the skill behind `skill` with the text of `a` and `b`.
///
/// # Safety
/// `skill` is NULL or a live `sf_skill`; `a` and `b` NULL or NUL-terminated strings.
unsafe fn with_skill(
    skill: *mut sf_skill,
    a: (*const c_char, &str),
    b: (*const c_char, &str),
    f: impl FnOnce(&mut ForeignSkill, &str, &str) -> i32,
) -> i32 {
    guard(SF_ERR_INTERNAL, || {
        // SAFETY: live sf_skill or NULL (caller contract).
        let Some(s) = (unsafe { skill.as_mut() }) else {
            return fail(SF_ERR_NULL, "skill is NULL");
        };
        // SAFETY: forwarded caller contract.
        let (x, y) = match unsafe { (text(a.0, a.1), text(b.0, b.1)) } {
            (Ok(x), Ok(y)) => (x, y),
            (Err(e), _) | (_, Err(e)) => return e,
        };
        f(&mut s.inner, x, y)
    })
}

/// Declares input `port` of message type `type_name` (e.g. `SF_TICK_TYPE_NAME`). Returns its
/// index (≥ 0) for `sf_input`, or an error.
///
/// # Safety
/// `skill` is NULL or a live `sf_skill`; the strings NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_input(
    skill: *mut sf_skill,
    port: *const c_char,
    type_name: *const c_char,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_skill(
            skill,
            (port, "port"),
            (type_name, "type name"),
            |s, p, t| index_result(s.input(p, t)),
        )
    }
}

/// Declares output `port` of message type `type_name`. Returns its index for `sf_output`.
///
/// # Safety
/// As `sf_skill_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_output(
    skill: *mut sf_skill,
    port: *const c_char,
    type_name: *const c_char,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_skill(
            skill,
            (port, "port"),
            (type_name, "type name"),
            |s, p, t| index_result(s.output(p, t)),
        )
    }
}

/// Declares a proposal on actuator channel `channel` (arbitrated by priority with the other
/// proposers). Returns its output index for `sf_output`.
///
/// # Safety
/// As `sf_skill_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_proposal(
    skill: *mut sf_skill,
    channel: *const c_char,
    type_name: *const c_char,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_skill(
            skill,
            (channel, "channel"),
            (type_name, "type name"),
            |s, c, t| index_result(s.proposal(c, t)),
        )
    }
}

fn bound(v: f64) -> Option<ParamValue> {
    v.is_finite().then_some(ParamValue::Float(v))
}

/// # Safety
/// As `sf_skill_input`; `doc` NULL or NUL-terminated.
unsafe fn add_param(
    skill: *mut sf_skill,
    name: *const c_char,
    doc: *const c_char,
    spec: impl FnOnce(String, String) -> ParamSpec,
) -> i32 {
    let doc = if doc.is_null() { c"".as_ptr() } else { doc };
    // SAFETY: forwarded caller contract.
    unsafe {
        with_skill(skill, (name, "parameter name"), (doc, "doc"), |s, n, d| {
            index_result(s.param(spec(n.to_string(), d.to_string())))
        })
    }
}

/// Declares a float parameter with its default and inclusive bounds (±INFINITY: unbounded);
/// `doc` may be NULL. Returns its index for `sf_param_float`.
///
/// # Safety
/// As `sf_skill_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_param_float(
    skill: *mut sf_skill,
    name: *const c_char,
    default_value: f64,
    min: f64,
    max: f64,
    doc: *const c_char,
) -> i32 {
    if default_value.is_nan() || min.is_nan() || max.is_nan() {
        return fail(SF_ERR_PARAM, "NaN is not a parameter value or bound");
    }
    // SAFETY: forwarded caller contract.
    unsafe {
        add_param(skill, name, doc, |name, doc| ParamSpec {
            name,
            kind: ParamKind::Float,
            default: ParamValue::Float(default_value),
            min: bound(min),
            max: bound(max),
            doc,
        })
    }
}

/// Declares an integer parameter with its default and inclusive bounds (INT64_MIN /
/// INT64_MAX: unbounded); `doc` may be NULL. Returns its index for `sf_param_int`.
///
/// # Safety
/// As `sf_skill_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_param_int(
    skill: *mut sf_skill,
    name: *const c_char,
    default_value: i64,
    min: i64,
    max: i64,
    doc: *const c_char,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        add_param(skill, name, doc, |name, doc| ParamSpec {
            name,
            kind: ParamKind::Int,
            default: ParamValue::Int(default_value),
            min: (min != i64::MIN).then_some(ParamValue::Int(min)),
            max: (max != i64::MAX).then_some(ParamValue::Int(max)),
            doc,
        })
    }
}

/// Declares a boolean parameter; `doc` may be NULL. Returns its index for `sf_param_bool`.
///
/// # Safety
/// As `sf_skill_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_param_bool(
    skill: *mut sf_skill,
    name: *const c_char,
    default_value: bool,
    doc: *const c_char,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        add_param(skill, name, doc, |name, doc| ParamSpec {
            name,
            kind: ParamKind::Bool,
            default: ParamValue::Bool(default_value),
            min: None,
            max: None,
            doc,
        })
    }
}

/// Sets the default arbitration priority (higher wins; `--priority` overrides it).
///
/// # Safety
/// `skill` is NULL or a live `sf_skill`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_priority(skill: *mut sf_skill, priority: i32) -> i32 {
    // SAFETY: live sf_skill or NULL (caller contract).
    match unsafe { skill.as_mut() } {
        Some(s) => {
            s.inner.set_priority(priority);
            SF_OK
        }
        None => fail(SF_ERR_NULL, "skill is NULL"),
    }
}

/// The callback and its user pointer, moved into the runtime's body.
struct Callback {
    f: unsafe extern "C" fn(*mut sf_run, *mut c_void) -> i32,
    user: *mut c_void,
}

// SAFETY: the runtime calls the body only on the thread that called `sf_skill_run`, the
// thread that gave the user pointer; the value is only moved, never shared.
unsafe impl Send for Callback {}

impl Callback {
    /// Calls the C function.
    ///
    /// # Safety
    /// `run` is valid for the call; the function's contract (`sf_skill_compute`) holds.
    unsafe fn call(&self, run: *mut sf_run) -> i32 {
        // SAFETY: forwarded contract.
        unsafe { (self.f)(run, self.user) }
    }
}

/// Sets the compute callback, called once per run with `user`.
///
/// # Safety
/// `skill` is NULL or a live `sf_skill`; `compute` is NULL or a function that is safe to call
/// with a run and `user` for as long as the skill runs.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_compute(
    skill: *mut sf_skill,
    compute: sf_compute_fn,
    user: *mut c_void,
) -> i32 {
    // SAFETY: live sf_skill or NULL (caller contract).
    let Some(s) = (unsafe { skill.as_mut() }) else {
        return fail(SF_ERR_NULL, "skill is NULL");
    };
    let Some(f) = compute else {
        return fail(SF_ERR_NULL, "compute is NULL");
    };
    let cb = Callback { f, user };
    s.inner.compute(Box::new(move |run: &mut ForeignRun<'_>| {
        let raw = (run as *mut ForeignRun<'_>).cast::<sf_run>();
        // SAFETY: the callback's contract (sf_skill_compute); `raw` is valid for the call.
        let rc = unsafe { cb.call(raw) };
        if rc == 0 {
            Ok(())
        } else {
            Err(SkillError::msg(format!("compute returned {rc}")))
        }
    }));
    SF_OK
}

/// Runs the skill as this process's skill until SIGINT/SIGTERM: parses `argv` (the usual
/// skill options `--name`, `--domain`, `--param NAME=VALUE`, `--priority`, `--inactive`,
/// `--remap`), registers with the domain's manager and serves its cycles. Frees `skill`.
/// Returns the process exit code: 0 after a clean shutdown, 1 after an error (printed on
/// stderr and kept in `sf_last_error`), 2 for bad arguments (usage printed).
///
/// # Safety
/// `skill` is NULL or a live `sf_skill` (it is freed here); `argv` is NULL or `argc`
/// pointers to NUL-terminated strings.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_skill_run(
    skill: *mut sf_skill,
    argc: i32,
    argv: *const *const c_char,
) -> i32 {
    guard(1, || {
        if skill.is_null() {
            fail(SF_ERR_NULL, "skill is NULL");
            return 1;
        }
        // SAFETY: made by sf_skill_new, not freed before (caller contract); freed here.
        let s = unsafe { Box::from_raw(skill) }.inner;
        let kind = s.kind.clone();
        let mut args = Vec::new();
        if !argv.is_null() {
            for i in 0..argc.max(0) as usize {
                // SAFETY: argv holds argc pointers (caller contract).
                let a = unsafe { *argv.add(i) };
                if !a.is_null() {
                    // SAFETY: NUL-terminated (caller contract).
                    args.push(unsafe { CStr::from_ptr(a) }.to_string_lossy().into_owned());
                }
            }
        }
        if args.is_empty() {
            args.push(kind.clone());
        }
        match skill_sdk::foreign::run(s, args) {
            Ok(()) => 0,
            Err(skill_sdk::foreign::RunError::Args(usage)) => {
                eprintln!("{usage}");
                set_error(&usage);
                2
            }
            Err(e) => {
                eprintln!("{kind}: error: {e}");
                set_error(&e.to_string());
                1
            }
        }
    })
}

/// The run behind a callback's `sf_run` pointer.
///
/// # Safety
/// `run` is NULL or the pointer the compute callback received, during that call.
unsafe fn run_ref<'a>(run: *const sf_run) -> Option<&'a mut ForeignRun<'a>> {
    // SAFETY: the pointer is a `&mut ForeignRun` cast in sf_skill_compute's body, valid for
    // the callback (caller contract); the runtime does not touch the run meanwhile.
    unsafe { run.cast_mut().cast::<ForeignRun<'a>>().as_mut() }
}

/// The current sample of input `idx`, checked to be `size` bytes (`sizeof` the message
/// struct). NULL if there is none or on error. Valid until the callback returns.
///
/// # Safety
/// `run` is NULL or the callback's run pointer, during the callback.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_input(run: *const sf_run, idx: i32, size: usize) -> *const c_void {
    guard(std::ptr::null(), || {
        // SAFETY: forwarded caller contract.
        unsafe {
            port_bytes(
                run,
                ("input", " (or no sample on it)"),
                idx,
                size,
                |r, i| r.input(i).map(|(bytes, _)| bytes),
            )
        }
        .map_or(std::ptr::null(), |bytes| bytes.as_ptr().cast())
    })
}

/// The cycle input `idx`'s current sample was produced in (0 if none).
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_input_cycle(run: *const sf_run, idx: i32) -> u64 {
    guard(0, || {
        // SAFETY: forwarded caller contract.
        unsafe { run_ref(run) }
            .and_then(|r| usize::try_from(idx).ok().and_then(|i| r.input(i)))
            .map_or(0, |(_, meta)| meta.cycle)
    })
}

/// Port `idx` of the run behind `run` as `get` finds it, checked to be `size` bytes; records
/// why not (NULL run, no such port — `what.0`, with `what.1` added —, wrong size).
///
/// # Safety
/// As `sf_input`.
unsafe fn port_bytes<'a, B: AsRef<[u8]>>(
    run: *const sf_run,
    what: (&str, &str),
    idx: i32,
    size: usize,
    get: impl FnOnce(&'a mut ForeignRun<'a>, usize) -> Option<B>,
) -> Option<B> {
    let (port, missing) = what;
    // SAFETY: forwarded caller contract.
    let Some(r) = (unsafe { run_ref(run) }) else {
        fail(SF_ERR_NULL, "run is NULL");
        return None;
    };
    let Some(bytes) = usize::try_from(idx).ok().and_then(|i| get(r, i)) else {
        fail(SF_ERR_INDEX, &format!("no {port} {idx}{missing}"));
        return None;
    };
    let len = bytes.as_ref().len();
    if len != size {
        fail(
            SF_ERR_SIZE,
            &format!("{port} {idx} is {len} bytes, asked for {size}"),
        );
        return None;
    }
    Some(bytes)
}

/// # Safety
/// As `sf_input`.
unsafe fn output(run: *mut sf_run, idx: i32, size: usize, clear: bool) -> *mut c_void {
    guard(std::ptr::null_mut(), || {
        // SAFETY: forwarded caller contract.
        unsafe { port_bytes(run, ("output", ""), idx, size, |r, i| r.output(i, clear)) }
            .map_or(std::ptr::null_mut(), |bytes| bytes.as_mut_ptr().cast())
    })
}

/// The message of output `idx` to fill, zeroed, checked to be `size` bytes; asking for it
/// marks the output written (sent if the callback returns 0). NULL on error. The memory is
/// the shared-memory sample itself: no copy is made.
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_output(run: *mut sf_run, idx: i32, size: usize) -> *mut c_void {
    // SAFETY: forwarded caller contract.
    unsafe { output(run, idx, size, true) }
}

/// As `sf_output` but not cleared: fields not written hold what this output held in some
/// earlier cycle (zeros at first). For large messages overwritten in place.
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_output_in_place(
    run: *mut sf_run,
    idx: i32,
    size: usize,
) -> *mut c_void {
    // SAFETY: forwarded caller contract.
    unsafe { output(run, idx, size, false) }
}

/// # Safety
/// As `sf_input`.
unsafe fn param(run: *const sf_run, idx: i32) -> Option<ParamValue> {
    guard(None, || {
        // SAFETY: forwarded caller contract.
        let v = unsafe { run_ref(run) }
            .and_then(|r| usize::try_from(idx).ok().and_then(|i| r.param(i)));
        if v.is_none() {
            fail(SF_ERR_INDEX, &format!("no parameter {idx}"));
        }
        v
    })
}

/// The current value of parameter `idx` as a double (NaN on error).
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_param_float(run: *const sf_run, idx: i32) -> f64 {
    // SAFETY: forwarded caller contract.
    unsafe { param(run, idx) }.map_or(f64::NAN, |v| v.as_f64())
}

/// The current value of parameter `idx` as an integer (floats truncated; 0 on error).
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_param_int(run: *const sf_run, idx: i32) -> i64 {
    // SAFETY: forwarded caller contract.
    match unsafe { param(run, idx) } {
        Some(ParamValue::Int(i)) => i,
        Some(ParamValue::UInt(u)) => i64::try_from(u).unwrap_or(i64::MAX),
        Some(ParamValue::Bool(b)) => i64::from(b),
        Some(ParamValue::Float(f)) => f as i64,
        None => 0,
    }
}

/// The current value of parameter `idx` as a bool (non-zero numbers are true; false on error).
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_param_bool(run: *const sf_run, idx: i32) -> bool {
    // SAFETY: forwarded caller contract.
    unsafe { param(run, idx) }.is_some_and(|v| v.as_f64() != 0.0)
}

/// The cycle of this run (0 if `run` is NULL).
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_run_cycle(run: *const sf_run) -> u64 {
    // SAFETY: forwarded caller contract.
    unsafe { run_ref(run) }.map_or(0, |r| r.cycle)
}

/// Fails this run with `reason` (logged; its outputs are not sent), whatever the callback
/// returns.
///
/// # Safety
/// As `sf_input`; `reason` NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_run_fail(run: *mut sf_run, reason: *const c_char) -> i32 {
    guard(SF_ERR_INTERNAL, || {
        // SAFETY: forwarded caller contract.
        let Some(r) = (unsafe { run_ref(run) }) else {
            return fail(SF_ERR_NULL, "run is NULL");
        };
        let reason = if reason.is_null() {
            "failed".to_string()
        } else {
            // SAFETY: NUL-terminated (caller contract).
            unsafe { CStr::from_ptr(reason) }
                .to_string_lossy()
                .into_owned()
        };
        r.fail(&reason);
        SF_OK
    })
}

/// A log line at `level` (`SF_LOG_*`): on stderr and the skill's log stream (console, `ctl
/// logs`), rate limited like a Rust skill's.
///
/// # Safety
/// `message` is NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_log(level: i32, message: *const c_char) -> i32 {
    guard(SF_ERR_INTERNAL, || {
        // SAFETY: forwarded caller contract.
        let m = match unsafe { text(message, "message") } {
            Ok(m) => m,
            Err(e) => return e,
        };
        match level {
            SF_LOG_ERROR => tracing::error!(target: "skill", "{m}"),
            SF_LOG_WARN => tracing::warn!(target: "skill", "{m}"),
            SF_LOG_INFO => tracing::info!(target: "skill", "{m}"),
            SF_LOG_DEBUG => tracing::debug!(target: "skill", "{m}"),
            other => return fail(SF_ERR_INVALID, &format!("log level {other}")),
        }
        SF_OK
    })
}

// ---- sequencer client ----

fn client_error(e: &ClientError) -> i32 {
    let code = match e {
        ClientError::Timeout(_) => SF_ERR_TIMEOUT,
        _ => SF_ERR_FABRIC,
    };
    fail(code, &e.to_string())
}

/// Copies `s` with its NUL into `buf` of `len` bytes.
///
/// # Safety
/// `buf` is NULL or `len` writable bytes.
unsafe fn copy_out(s: &CStr, buf: *mut c_char, len: usize) -> i32 {
    let bytes = s.to_bytes_with_nul();
    if buf.is_null() {
        return fail(SF_ERR_NULL, "buffer is NULL");
    }
    if bytes.len() > len {
        return fail(
            SF_ERR_BUFFER,
            &format!("the buffer holds {len} bytes, {} needed", bytes.len()),
        );
    }
    // SAFETY: `buf` has `len` ≥ bytes.len() writable bytes (caller contract).
    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf.cast::<u8>(), bytes.len()) };
    SF_OK
}

/// Copies JSON text into `buf`.
///
/// # Safety
/// As `copy_out`.
unsafe fn json_out(v: &serde_json::Value, buf: *mut c_char, len: usize) -> i32 {
    let text = CString::new(v.to_string()).unwrap_or_default();
    // SAFETY: forwarded caller contract.
    unsafe { copy_out(&text, buf, len) }
}

/// Connects to the manager of `domain` (NULL: `$SKILLFAB_DOMAIN`, else "default") and
/// subscribes to its events (every event from now on can be read with
/// `sf_client_next_event`). NULL on error (no manager, bad domain name).
///
/// # Safety
/// `domain` is NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_connect(domain: *const c_char) -> *mut sf_client {
    guard(std::ptr::null_mut(), || {
        let name = if domain.is_null() {
            std::env::var(skillfab_proto::domain::DOMAIN_ENV).unwrap_or_else(|_| "default".into())
        } else {
            // SAFETY: forwarded caller contract.
            match unsafe { text(domain, "domain") } {
                Ok(d) => d.to_string(),
                Err(_) => return std::ptr::null_mut(),
            }
        };
        let d = match Domain::new(&name) {
            Ok(d) => d,
            Err(e) => {
                fail(SF_ERR_INVALID, &e.to_string());
                return std::ptr::null_mut();
            }
        };
        // Subscribed at once: a monitor installed next may fire before the first
        // sf_client_next_event, and its event must not be lost.
        match Client::connect(&d).and_then(|mut inner| inner.subscribe().map(|()| inner)) {
            Ok(inner) => Box::into_raw(Box::new(sf_client {
                inner,
                pending: None,
            })),
            Err(e) => {
                client_error(&e);
                std::ptr::null_mut()
            }
        }
    })
}

/// Closes a client (its monitors stay until removed). NULL is ignored.
///
/// # Safety
/// `client` is NULL or a pointer from `sf_client_connect` not yet freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_free(client: *mut sf_client) {
    if !client.is_null() {
        // SAFETY: made by Box::into_raw in sf_client_connect (caller contract).
        drop(unsafe { Box::from_raw(client) });
    }
}

/// Runs `f` on the client with the text of the given string arguments.
///
/// # Safety
/// `client` NULL or live; every string NULL or NUL-terminated.
unsafe fn with_client<const N: usize>(
    client: *mut sf_client,
    strings: [(*const c_char, &str); N],
    f: impl FnOnce(&mut sf_client, [&str; N]) -> i32,
) -> i32 {
    guard(SF_ERR_INTERNAL, || {
        // SAFETY: live or NULL (caller contract).
        let Some(c) = (unsafe { client.as_mut() }) else {
            return fail(SF_ERR_NULL, "client is NULL");
        };
        let mut texts = [""; N];
        for (i, (p, what)) in strings.iter().enumerate() {
            // SAFETY: forwarded caller contract.
            match unsafe { text(*p, what) } {
                Ok(t) => texts[i] = t,
                Err(e) => return e,
            }
        }
        f(c, texts)
    })
}

fn status(r: Result<(), ClientError>) -> i32 {
    match r {
        Ok(()) => SF_OK,
        Err(e) => client_error(&e),
    }
}

/// Activates skill `skill`.
///
/// # Safety
/// `client` NULL or live; `skill` NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_activate(client: *mut sf_client, skill: *const c_char) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [(skill, "skill")], |c, [s]| {
            status(c.inner.activate(&[s]))
        })
    }
}

/// Deactivates skill `skill`.
///
/// # Safety
/// As `sf_client_activate`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_deactivate(client: *mut sf_client, skill: *const c_char) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [(skill, "skill")], |c, [s]| {
            status(c.inner.deactivate(&[s]))
        })
    }
}

/// Sets `skill`'s parameter `param` from text (parsed and bound-checked by its declared
/// type; a refusal says why); applied from the next cycle.
///
/// # Safety
/// `client` NULL or live; the strings NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_set_param(
    client: *mut sf_client,
    skill: *const c_char,
    param: *const c_char,
    value: *const c_char,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(
            client,
            [(skill, "skill"), (param, "param"), (value, "value")],
            |c, [s, p, v]| status(c.inner.set_param(s, p, v)),
        )
    }
}

/// Writes `skill`'s parameter `param` as JSON text (a number or true/false) into `buf`.
///
/// # Safety
/// `client` NULL or live; the strings NULL or NUL-terminated; `buf` NULL or `len` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_get_param(
    client: *mut sf_client,
    skill: *const c_char,
    param: *const c_char,
    buf: *mut c_char,
    len: usize,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(
            client,
            [(skill, "skill"), (param, "param")],
            |c, [s, p]| match c.inner.get_param(s, p) {
                Ok(v) => json_out(&skillfab_client::json::param_json(&v), buf, len),
                Err(e) => client_error(&e),
            },
        )
    }
}

/// Writes the latest value at `path` (`skill.output[.field][index]`, or `channel.NAME...`)
/// as JSON `{"value": ..., "cycle": n}` into `buf`.
///
/// # Safety
/// As `sf_client_get_param`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_query(
    client: *mut sf_client,
    path: *const c_char,
    buf: *mut c_char,
    len: usize,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [(path, "path")], |c, [p]| match c.inner.query(p) {
            Ok((v, cycle)) => json_out(
                &serde_json::json!({"value": skillfab_client::json::value_json(&v), "cycle": cycle}),
                buf,
                len,
            ),
            Err(e) => client_error(&e),
        })
    }
}

/// Installs a monitor on condition `expr` (e.g. `"avoid.drive.translate < 0.1"`), firing
/// `SF_MONITOR_ONCE`, `_EDGE` or `_EVERY`, after the condition held `hold` cycles (0 or 1:
/// at once). Returns its id (≥ 0) or an error; firings arrive as events.
///
/// # Safety
/// `client` NULL or live; `expr` NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_add_monitor(
    client: *mut sf_client,
    expr: *const c_char,
    mode: i32,
    hold: u32,
) -> i64 {
    let mode = match mode {
        SF_MONITOR_ONCE => MonitorMode::Once,
        SF_MONITOR_EDGE => MonitorMode::Edge,
        SF_MONITOR_EVERY => MonitorMode::Every,
        other => return i64::from(fail(SF_ERR_INVALID, &format!("monitor mode {other}"))),
    };
    let mut id = 0i64;
    // SAFETY: forwarded caller contract.
    let rc = unsafe {
        with_client(client, [(expr, "expr")], |c, [e]| {
            match c.inner.add_monitor(e, mode, hold) {
                Ok(i) => {
                    id = i64::try_from(i).unwrap_or(i64::MAX);
                    SF_OK
                }
                Err(e) => client_error(&e),
            }
        })
    };
    if rc == SF_OK { id } else { i64::from(rc) }
}

/// Removes monitor `id`.
///
/// # Safety
/// `client` NULL or live.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_remove_monitor(client: *mut sf_client, id: i64) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [], |c, []| match u64::try_from(id) {
            Ok(id) => status(c.inner.remove_monitor(id)),
            Err(_) => fail(SF_ERR_INVALID, "monitor ids are not negative"),
        })
    }
}

/// Waits up to `timeout_ms` for the next event and writes it as one JSON object
/// (`{"seq", "cycle", "time_ns", "event": "monitor_fired" | "skill_died" | ..., ...}`, as
/// `skillfab ctl --json events` prints) into `buf`. Returns 1 if an event was written, 0 on
/// timeout, or an error; an event too large for `buf` is kept for the next call.
///
/// # Safety
/// `client` NULL or live; `buf` NULL or `len` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_next_event(
    client: *mut sf_client,
    timeout_ms: u32,
    buf: *mut c_char,
    len: usize,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [], |c, []| {
            let text = match c.pending.take() {
                Some(t) => t,
                None => match c
                    .inner
                    .next_event(Duration::from_millis(u64::from(timeout_ms)))
                {
                    Ok(Some(ev)) => {
                        CString::new(skillfab_client::json::event_json(&ev).to_string())
                            .unwrap_or_default()
                    }
                    Ok(None) => return 0,
                    Err(e) => return client_error(&e),
                },
            };
            let rc = copy_out(&text, buf, len);
            if rc == SF_OK {
                1
            } else {
                c.pending = Some(text);
                rc
            }
        })
    }
}

/// Sets `skill`'s arbitration priority from the next cycle.
///
/// # Safety
/// `client` NULL or live; `skill` NULL or NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_set_priority(
    client: *mut sf_client,
    skill: *const c_char,
    priority: i32,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [(skill, "skill")], |c, [s]| {
            status(c.inner.set_priority(s, priority))
        })
    }
}

/// Writes every registered skill as a JSON array (as `skillfab ctl --json ls`) into `buf`.
///
/// # Safety
/// `client` NULL or live; `buf` NULL or `len` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_list(
    client: *mut sf_client,
    buf: *mut c_char,
    len: usize,
) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [], |c, []| match c.inner.list() {
            Ok(skills) => json_out(
                &serde_json::Value::Array(
                    skills
                        .iter()
                        .map(skillfab_client::json::skill_json)
                        .collect(),
                ),
                buf,
                len,
            ),
            Err(e) => client_error(&e),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn last_error() -> String {
        // SAFETY: sf_last_error returns a valid NUL-terminated string.
        unsafe { CStr::from_ptr(sf_last_error()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn bad_arguments_are_errors_not_crashes() {
        unsafe {
            assert!(sf_skill_new(std::ptr::null(), SF_SYNC).is_null());
            assert!(last_error().contains("NULL"));
            assert!(sf_skill_new(c"x".as_ptr(), 7).is_null());
            let s = sf_skill_new(c"c_scale".as_ptr(), SF_SYNC);
            assert!(!s.is_null());
            assert_eq!(
                sf_skill_input(s, c"tick".as_ptr(), c"skillfab.Tick".as_ptr()),
                0
            );
            assert_eq!(
                sf_skill_input(s, c"x".as_ptr(), c"skillfab.NoSuch".as_ptr()),
                SF_ERR_UNKNOWN_TYPE
            );
            assert!(last_error().contains("skillfab.NoSuch"), "{}", last_error());
            assert_eq!(
                sf_skill_output(
                    std::ptr::null_mut(),
                    c"a".as_ptr(),
                    c"skillfab.Tick".as_ptr()
                ),
                SF_ERR_NULL
            );
            assert_eq!(
                sf_skill_output(s, std::ptr::null(), c"skillfab.Tick".as_ptr()),
                SF_ERR_NULL
            );
            let not_utf8 = [0xffu8, 0];
            assert_eq!(
                sf_skill_output(s, not_utf8.as_ptr().cast(), c"skillfab.Tick".as_ptr()),
                SF_ERR_INVALID
            );
            assert_eq!(
                sf_skill_param_float(s, c"gain".as_ptr(), 2.0, -1.0, 1.0, std::ptr::null()),
                SF_ERR_PARAM
            );
            assert_eq!(
                sf_skill_param_float(
                    s,
                    c"gain".as_ptr(),
                    0.5,
                    -1.0,
                    f64::INFINITY,
                    c"doc".as_ptr()
                ),
                0
            );
            assert_eq!(
                sf_skill_param_int(s, c"n".as_ptr(), 3, i64::MIN, i64::MAX, std::ptr::null()),
                1
            );
            assert_eq!(sf_skill_compute(s, None, std::ptr::null_mut()), SF_ERR_NULL);
            // Run accessors with no run.
            assert!(sf_input(std::ptr::null(), 0, 8).is_null());
            assert!(sf_output(std::ptr::null_mut(), 0, 8).is_null());
            assert!(sf_param_float(std::ptr::null(), 0).is_nan());
            assert_eq!(sf_run_cycle(std::ptr::null()), 0);
            assert_eq!(sf_log(9, c"x".as_ptr()), SF_ERR_INVALID);
            assert_eq!(sf_log(SF_LOG_INFO, std::ptr::null()), SF_ERR_NULL);
            // A skill without a body does not run.
            assert_eq!(sf_skill_run(s, 0, std::ptr::null()), 1);
            assert!(last_error().contains("no compute body"), "{}", last_error());
            assert_eq!(sf_skill_run(std::ptr::null_mut(), 0, std::ptr::null()), 1);
            // Client calls on NULL.
            assert_eq!(
                sf_client_activate(std::ptr::null_mut(), c"a".as_ptr()),
                SF_ERR_NULL
            );
            assert_eq!(
                sf_client_next_event(std::ptr::null_mut(), 0, std::ptr::null_mut(), 0),
                SF_ERR_NULL
            );
            assert!(sf_client_connect(c"bad domain!".as_ptr()).is_null());
            assert_eq!(
                sf_client_add_monitor(std::ptr::null_mut(), c"a.b.c > 1".as_ptr(), 9, 0),
                i64::from(SF_ERR_INVALID)
            );
        }
    }

    /// The committed header is what cbindgen makes of this file.
    #[test]
    fn the_header_is_in_sync() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
        let mut out = Vec::new();
        cbindgen::Builder::new()
            .with_config(config)
            .with_src(dir.join("src/lib.rs"))
            .generate()
            .unwrap()
            .write(&mut out);
        let generated = String::from_utf8(out).unwrap();
        let path = dir.join("include/skillfab.h");
        if std::env::var_os("SKILLFAB_BLESS").is_some() {
            std::fs::write(&path, &generated).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            committed == generated,
            "include/skillfab.h is out of date: run `SKILLFAB_BLESS=1 cargo test -p skillfab-capi`"
        );
    }

    /// The committed message header is what the schema generator writes.
    #[test]
    fn the_message_header_is_in_sync() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let generated = skillfab_codegen::c_header(&skillfab_codegen::shared_schemas());
        let path = dir.join("include/skillfab_msgs.h");
        if std::env::var_os("SKILLFAB_BLESS").is_some() {
            std::fs::write(&path, &generated).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            committed == generated,
            "include/skillfab_msgs.h is out of date: run `SKILLFAB_BLESS=1 cargo test -p skillfab-capi`"
        );
    }
}
