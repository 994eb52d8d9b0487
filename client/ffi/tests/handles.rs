//! A handle's life against a real `dyfosd`, through the C ABI as a C program calls
//! it (the `extern "C"` functions, called from Rust): freed while another thread's
//! call runs, and outliving its daemon.
#![allow(unsafe_code)] // Calls the C ABI; every block says why it is sound.

use dyfos::*;
use dyfos_tests::{PATIENCE, Sandbox, data, wait_for};
use std::ffi::{CStr, CString, c_char};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The handle's own timeout in these tests: long, so that a call that waited for it
/// stands out.
const HANDLE_TIMEOUT_MS: u64 = 60_000;

fn last_error() -> String {
    let mut buf = vec![0u8; 1024];
    // SAFETY: `buf` has 1024 writable bytes.
    unsafe { dyfos_last_error(buf.as_mut_ptr().cast(), buf.len()) };
    CStr::from_bytes_until_nul(&buf).expect("NUL-terminated").to_string_lossy().into_owned()
}

fn connect(sandbox: &Sandbox) -> usize {
    let (prefix, domain) =
        (CString::new(sandbox.prefix.as_str()).unwrap(), CString::new(sandbox.domain.as_str()).unwrap());
    let mut handle: *mut dyfos_client = std::ptr::null_mut();
    // SAFETY: C strings and a local output.
    let status = unsafe { dyfos_client_connect(prefix.as_ptr(), domain.as_ptr(), HANDLE_TIMEOUT_MS, &mut handle) };
    assert_eq!(status, DYFOS_STATUS_OK, "{}", last_error());
    handle.addr()
}

/// A handle from its token (handles are tokens: the library never dereferences them).
fn handle(token: usize) -> *mut dyfos_client {
    std::ptr::without_provenance_mut(token)
}

fn stats(token: usize) -> dyfos_status {
    let mut json: *mut c_char = std::ptr::null_mut();
    // SAFETY: a handle token and a local output; the string is freed once.
    unsafe {
        let status = dyfos_client_stats(handle(token), 0, &mut json);
        dyfos_string_free(json);
        status
    }
}

/// The example scenario's map uploaded through `token`, and the request for its rover.
fn example_request(token: usize) -> dyfos_rendezvous_request {
    let scenario = CString::new(std::fs::read_to_string(data("example.json")).expect("example.json")).unwrap();
    let (mut map, mut request) = (0u64, dyfos_rendezvous_request_default());
    // SAFETY: a handle token, a C string and local outputs.
    unsafe {
        let uploaded =
            dyfos_client_upload_scenario(handle(token), 0, scenario.as_ptr(), 0, &mut map, std::ptr::null_mut());
        assert_eq!(uploaded, DYFOS_STATUS_OK, "{}", last_error());
        assert_eq!(dyfos_rendezvous_request_from_scenario(scenario.as_ptr(), map, &mut request), DYFOS_STATUS_OK);
    }
    request
}

fn dyfos_rendezvous_request_default() -> dyfos_rendezvous_request {
    let mut request = std::mem::MaybeUninit::uninit();
    // SAFETY: writes the whole struct, which is then initialised.
    unsafe {
        assert_eq!(dyfos_rendezvous_request_init(request.as_mut_ptr()), DYFOS_STATUS_OK);
        request.assume_init()
    }
}

#[test]
fn free_waits_for_the_call_another_thread_has_in_progress() {
    let sandbox = Sandbox::new("ffi-free");
    let _daemon = sandbox.start_daemon(&[]);
    let token = connect(&sandbox);
    let example = example_request(token);
    // The request holds a pointer, so it is rebuilt in the thread from its numbers.
    let (map, mean, cov, params) = (example.map, example.mean, example.cov, example.params);
    let finished = Arc::new(AtomicBool::new(false));
    let call = {
        let finished = Arc::clone(&finished);
        std::thread::spawn(move || {
            // A call that lasts: an exhaustive search, made slow by many target points
            // per candidate, stopped by a deadline if it has not finished by then (how
            // long it takes depends on the machine and its load).
            let params =
                dyfos_params { perimeter_points: 512, set: params.set | DYFOS_PARAM_PERIMETER_POINTS, ..params };
            let request = dyfos_rendezvous_request {
                map,
                mean,
                cov,
                params,
                algorithm: DYFOS_ALGORITHM_BRUTE,
                deadline_micros: 2_000_000,
                ..dyfos_rendezvous_request_default()
            };
            let mut answer = dyfos_answer::default();
            // SAFETY: a handle token, a request without deltas, a local output.
            let status = unsafe { dyfos_client_rendezvous(handle(token), 0, &request, &mut answer) };
            finished.store(true, Ordering::SeqCst);
            (status, answer.stop)
        })
    };
    // Free only once the daemon searches that query: the call is in progress.
    let mut observer = sandbox.client();
    wait_for("the daemon to run the query", || (observer.stats(PATIENCE).ok()?.running > 0).then_some(()));
    // SAFETY: a handle token.
    assert_eq!(unsafe { dyfos_client_free(handle(token)) }, DYFOS_STATUS_OK, "{}", last_error());
    assert!(finished.load(Ordering::SeqCst), "dyfos_client_free returned while the other thread's call still ran");
    let (status, stop) = call.join().expect("the calling thread");
    assert_eq!(status, DYFOS_STATUS_OK, "the call finished with its answer");
    assert!(matches!(stop, DYFOS_STOP_FINISHED | DYFOS_STOP_DEADLINE), "the search ran to its end or deadline: {stop}");
    assert_eq!(stats(token), DYFOS_STATUS_NULL_PARAMETER, "the handle is freed");
}

#[test]
fn after_the_daemon_went_away_the_next_call_answers_no_daemon_at_once_and_a_new_daemon_is_found() {
    let sandbox = Sandbox::new("ffi-gone");
    let mut daemon = sandbox.start_daemon(&[]);
    let token = connect(&sandbox);
    assert_eq!(stats(token), DYFOS_STATUS_OK);
    daemon.kill9();
    let first = stats(token);
    assert!(first == DYFOS_STATUS_DAEMON_GONE || first == DYFOS_STATUS_NO_DAEMON, "{first}: {}", last_error());
    // Not a speed check: before, this call waited the handle's whole timeout (60 s)
    // for a daemon to come back; now it tries once. Half the timeout tells them apart.
    let start = Instant::now();
    assert_eq!(stats(token), DYFOS_STATUS_NO_DAEMON, "{}", last_error());
    let waited = start.elapsed();
    assert!(waited < Duration::from_millis(HANDLE_TIMEOUT_MS / 2), "waited {waited:?} for a daemon");
    let message = last_error();
    assert!(message.contains(&format!("iceoryx2 domain `{}`", sandbox.domain)), "{message}");
    assert!(message.contains(&format!("--domain {}", sandbox.domain)), "{message}");
    // A daemon serving the prefix again: the same handle reconnects by itself.
    let _again = sandbox.start_daemon(&[]);
    assert_eq!(stats(token), DYFOS_STATUS_OK, "{}", last_error());
    // SAFETY: a handle token, freed once.
    assert_eq!(unsafe { dyfos_client_free(handle(token)) }, DYFOS_STATUS_OK);
}
