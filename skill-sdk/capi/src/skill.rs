//! Declaring a skill and running it: `sf_skill_*`.

use crate::error::*;
use crate::*;
use skill_sdk::foreign::{DeclError, ForeignRun, ForeignSkill};
use skill_sdk::params::{ParamKind, ParamSpec, ParamValue};
use skill_sdk::skill::SkillError;
use skillfab_proto::decl::Mode;
use std::ffi::{CStr, c_char, c_void};

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
/// Declares a port of `type_name`: a type of the shared catalog, else one of a message package
/// on `SKILLFAB_MSG_PATH` (its layout from the message file).
fn declare(
    s: &mut ForeignSkill,
    port: &str,
    type_name: &str,
    output: bool,
) -> Result<usize, DeclError> {
    let known = if output {
        s.output(port, type_name)
    } else {
        s.input(port, type_name)
    };
    let Err(DeclError::UnknownType { .. }) = known else {
        return known;
    };
    match skillfab_msgs::dynamic::find_schema(type_name) {
        Ok(Some(schema)) if output => s.output_schema(port, schema),
        Ok(Some(schema)) => s.input_schema(port, schema),
        Ok(None) => known,
        Err(e) => Err(DeclError::MessageFile {
            reason: e.to_string(),
        }),
    }
}

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
            |s, p, t| index_result(declare(s, p, t, false)),
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
            |s, p, t| index_result(declare(s, p, t, true)),
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
