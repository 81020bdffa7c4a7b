use super::*;
use std::ffi::CStr;

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
