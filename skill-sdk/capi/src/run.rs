//! Inside the compute callback: inputs, outputs, parameters, the cycle, failing a run; and
//! `sf_log`.

use crate::error::*;
use crate::*;
use skill_sdk::foreign::ForeignRun;
use skill_sdk::params::ParamValue;
use std::ffi::{CStr, c_char, c_void};

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

/// The time of this run's cycle (ns): cycle × period when the manager has a period (lock-step
/// included), the cycle's start stamp when it free-runs; 0 if `run` is NULL. A skill reads
/// this, not a clock, so that a recorded run replays (docs/replay.md).
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_run_time_ns(run: *const sf_run) -> u64 {
    // SAFETY: forwarded caller contract.
    unsafe { run_ref(run) }.map_or(0, |r| r.clock.time.as_nanos() as u64)
}

/// The manager's period (ns); 0 when it free-runs or `run` is NULL.
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_run_period_ns(run: *const sf_run) -> u64 {
    // SAFETY: forwarded caller contract.
    unsafe { run_ref(run) }
        .and_then(|r| r.clock.period)
        .map_or(0, |p| p.as_nanos() as u64)
}

/// Whether the manager runs in lock-step (cycles back to back, simulated time).
///
/// # Safety
/// As `sf_input`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_run_lockstep(run: *const sf_run) -> bool {
    // SAFETY: forwarded caller contract.
    unsafe { run_ref(run) }.is_some_and(|r| r.clock.lockstep)
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
