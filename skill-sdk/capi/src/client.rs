//! The sequencer's link: `sf_client_*`.

use crate::error::*;
use crate::*;
use skillfab_client::{Client, ClientError};
use skillfab_proto::control::MonitorMode;
use skillfab_proto::domain::Domain;
use std::ffi::{CStr, CString, c_char};
use std::time::Duration;

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
        match Client::connect(&d).and_then(|inner| inner.subscribe().map(|()| inner)) {
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

/// Wants skill `skill`: activates it with every skill it reads from, transitively (the
/// producers that were inactive are activated on demand). Refused, with nothing changed, when
/// an input has no producer or producers read each other (the error says which).
///
/// # Safety
/// As `sf_client_activate`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_want(client: *mut sf_client, skill: *const c_char) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [(skill, "skill")], |c, [s]| {
            status(c.inner.want(&[s]))
        })
    }
}

/// Releases wanted skill `skill`: deactivates it and every skill activated on demand that no
/// wanted skill still reads from. A skill activated by `sf_client_activate` stays active.
///
/// # Safety
/// As `sf_client_activate`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sf_client_release(client: *mut sf_client, skill: *const c_char) -> i32 {
    // SAFETY: forwarded caller contract.
    unsafe {
        with_client(client, [(skill, "skill")], |c, [s]| {
            status(c.inner.release(&[s]))
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
