//! # dyfos-ffi: the C ABI of the dyfos client
//!
//! `libdyfos.so` / `libdyfos.a` with the header `include/dyfos.h` (generated from
//! this crate by cbindgen, checked in, and checked by a test), and the header-only
//! C++17 wrapper `include/dyfos.hpp` over it. Every function wraps the one Rust
//! client, [`dyfos_client::Client`]; nothing of the protocol is re-implemented.
//!
//! The rules, for every function (written out for C users in the header's
//! preamble, `cbindgen.toml`, and `client/ffi/README.md`):
//!
//! - Every fallible function returns a `dyfos_status`: `DYFOS_STATUS_OK` (0), the
//!   daemon's wire status code (1..=21), or a client-side code (1000..). After a
//!   failure, `dyfos_last_error` gives this thread's message; a success clears it.
//! - No panic crosses the boundary: every body runs inside `catch_unwind`, and a
//!   caught panic is `DYFOS_STATUS_PANIC`.
//! - A function on a handle checks the handle first ([`handle::on_handle`]): a NULL,
//!   freed or made-up `dyfos_client *` is `DYFOS_STATUS_NULL_PARAMETER` whatever the
//!   other arguments hold. The handle is a token the library looks up, never memory
//!   it reads. Then a NULL required pointer is `DYFOS_STATUS_NULL_PARAMETER`; other
//!   pointers (strings, structs, buffers) must be valid for the call when not NULL.
//! - Input strings are UTF-8, NUL-terminated, borrowed for the call only. Strings
//!   the library returns (`char **` outputs) belong to the caller, who frees each
//!   exactly once with `dyfos_string_free`. Structs are plain values the caller owns.
//! - A handle may be used from several threads: its calls are serialised (one
//!   request at a time per handle). For parallel queries, connect one handle per
//!   thread. `dyfos_client_free` waits for a call in progress on the handle.
#![allow(unsafe_code)] // The C ABI; every unsafe block says why it is sound.
#![allow(non_camel_case_types)] // C names: dyfos_client, dyfos_answer, ...
#![warn(missing_docs)]

mod handle;
mod status;
mod types;
mod version;

pub use handle::dyfos_client;
pub use status::*;
pub use types::*;
pub use version::*;

use ::dyfos_client::{Client, ClientConfig};
use dyfos_shared::scenario::{Scenario, ScenarioError, params_from_json};
use dyfos_shared::wire::DEFAULT_PREFIX;
use dyfos_shared::wire::map::{decode_bounds, decode_sun};
use dyfos_shared::world::{Bounds, Sun};
use handle::on_handle;
use std::ffi::{CStr, CString, c_char};
use std::time::Duration;

/// Reads a required UTF-8 string argument.
///
/// # Safety
/// `ptr` is NULL or a NUL-terminated string valid for `'a`.
pub(crate) unsafe fn text<'a>(ptr: *const c_char, what: &str) -> Result<&'a str, Failure> {
    // SAFETY: as the caller promises.
    let s = unsafe { c_str(ptr) }.ok_or_else(|| Failure::null(what))?;
    s.to_str().map_err(|e| Failure::invalid(format!("`{what}` is not UTF-8: {e}")))
}

/// Hands `s` to the caller through `out` (freed with `dyfos_string_free`).
fn give_string(out: *mut *mut c_char, what: &str, s: String) -> Result<(), Failure> {
    let c = CString::new(s).map_err(|e| Failure::invalid(format!("{what} holds a NUL byte: {e}")))?;
    let raw = c.into_raw();
    // SAFETY: `out` was checked non-null by the caller of this helper (or is checked
    // here) and points to writable memory for one pointer, as the API documents.
    if let Err(e) = unsafe { write(out, what, raw) } {
        // SAFETY: `raw` came from `CString::into_raw` just above and was not handed out.
        drop(unsafe { CString::from_raw(raw) });
        return Err(e);
    }
    Ok(())
}

/// `replace` and the like: 0 or 1.
fn flag(value: u32, what: &str) -> Result<bool, Failure> {
    match value {
        0 => Ok(false),
        1 => Ok(true),
        v => Err(Failure::invalid(format!("{what} = {v} must be 0 or 1"))),
    }
}

/// Bounds and sun given as arguments, checked as the daemon checks them (same code).
fn bounds_and_sun(bounds: &[f64; 4], elevation: f64, azimuth: f64) -> Result<(Bounds, Sun), Failure> {
    Ok((decode_bounds(*bounds)?, decode_sun([elevation, azimuth])?))
}

/// A JSON value as `dyfos` prints it (`print_json` of the `dyfos` CLI): an object
/// with one `"key": value` line per field, two spaces in; anything else on one line.
pub fn json_text(value: &serde_json::Value) -> String {
    let Some(object) = value.as_object() else {
        return value.to_string();
    };
    let fields: Vec<String> =
        object.iter().map(|(k, v)| format!("  {}: {v}", serde_json::Value::from(k.as_str()))).collect();
    format!("{{\n{}\n}}", fields.join(",\n"))
}

/// Connects to the `dyfosd` serving `prefix` and writes the new handle to `*out`.
///
/// - `prefix`: the daemon's service prefix (its `--prefix`); NULL for `"dyfos/"`.
/// - `domain`: the iceoryx2 domain (the daemon's `--domain`); NULL for the default.
/// - `timeout_ms`: how long to wait for the daemon now, and the default timeout
///   of the calls made with this handle (a call's `timeout_ms` of 0); must be > 0.
/// - `out`: required; receives the handle (NULL on failure). The caller owns it
///   and releases it with `dyfos_client_free`.
///
/// Returns `DYFOS_STATUS_NO_DAEMON` if no daemon serves the prefix in the domain
/// within the timeout. Later, if the daemon goes away, each call tries once to
/// reconnect and answers `DYFOS_STATUS_NO_DAEMON` at once while none serves.
///
/// # Safety
/// `prefix` and `domain` are NULL or NUL-terminated strings; `out` is NULL
/// (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_connect(
    prefix: *const c_char,
    domain: *const c_char,
    timeout_ms: u64,
    out: *mut *mut dyfos_client,
) -> dyfos_status {
    boundary(|| {
        non_null(out, "out")?;
        // SAFETY: `out` is non-null and writable, as the caller promises.
        unsafe { out.write(std::ptr::null_mut()) };
        // SAFETY: NULL or NUL-terminated, as the caller promises.
        let prefix = if prefix.is_null() { DEFAULT_PREFIX } else { unsafe { text(prefix, "prefix")? } };
        // SAFETY: NULL or NUL-terminated, as the caller promises.
        let domain = if domain.is_null() { None } else { Some(unsafe { text(domain, "domain")? }.to_string()) };
        if timeout_ms == 0 {
            return Err(Failure::invalid("timeout_ms = 0: give the time to wait for the daemon's replies, e.g. 1000"));
        }
        let timeout = Duration::from_millis(timeout_ms);
        let config =
            ClientConfig { prefix: prefix.to_string(), connect_timeout: timeout, domain, ..ClientConfig::default() };
        let mut client = Client::connect(&config)?;
        // Once connected, a reconnect (after the daemon went away) tries once: a call
        // answers `no_daemon` at once, as a call on a handle that has not noticed yet.
        client.set_connect_timeout(Duration::ZERO);
        // SAFETY: checked non-null above.
        unsafe { out.write(handle::register(client, timeout)) };
        Ok(())
    })
}

/// Releases a handle and its connection. NULL is a no-op (`DYFOS_STATUS_OK`), as
/// with `free(3)`; a handle freed already is `DYFOS_STATUS_NULL_PARAMETER` (a bug in
/// the caller, detected). A call in progress on the handle in another thread
/// finishes first: this returns after it (and after the connection is closed);
/// calls that were still waiting for the handle then fail with
/// `DYFOS_STATUS_NULL_PARAMETER`.
///
/// # Safety
/// Always safe to call: the handle is never dereferenced.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_free(client: *mut dyfos_client) -> dyfos_status {
    boundary(|| handle::free(client))
}

/// The daemon's health and counters as a JSON object (as `dyfos stats` prints
/// it: `pid`, `uptime_s`, `queries_served`, `maps` (how many it holds),
/// `latency_us`, `errors`, ...).
///
/// `timeout_ms`: the wait for the reply; 0 for the handle's timeout (as for every
/// call on a handle). `json_out`: required; receives a NUL-terminated string the
/// caller owns and frees with `dyfos_string_free`; untouched on failure.
///
/// # Safety
/// `json_out` is NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_stats(
    client: *mut dyfos_client,
    timeout_ms: u64,
    json_out: *mut *mut c_char,
) -> dyfos_status {
    on_handle(client, |handle| {
        non_null(json_out, "json_out")?;
        let stats = handle.call(timeout_ms, |c, timeout| Ok(c.stats(timeout)?))?;
        give_string(json_out, "json_out", json_text(&stats.to_json()))
    })
}

/// Makes sure the daemon holds the map of a scenario (SPEC §11 JSON text, as
/// `dyfos solve` reads) and writes its id to `*map_out` and its version to
/// `*version_out`. The id is the map's content id, so the same scenario reuses
/// its map. If that id holds other content (e.g. the map was changed by deltas
/// since), `replace` 1 replaces it with the scenario's (its version + 1), and
/// `replace` 0 is `DYFOS_STATUS_MAP_EXISTS`; other values are
/// `DYFOS_STATUS_INVALID_ARGUMENT`. A scenario `dyfos solve` would refuse is
/// `DYFOS_STATUS_INVALID_ARGUMENT`, naming the field.
///
/// `map_out` is required; `version_out` may be NULL (not wanted).
///
/// # Safety
/// `scenario_json` is NULL (refused) or NUL-terminated; `map_out` is NULL (refused)
/// or writable; `version_out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_upload_scenario(
    client: *mut dyfos_client,
    timeout_ms: u64,
    scenario_json: *const c_char,
    replace: u32,
    map_out: *mut u64,
    version_out: *mut u64,
) -> dyfos_status {
    on_handle(client, |handle| {
        non_null(map_out, "map_out")?;
        // SAFETY: NULL or NUL-terminated, as the caller promises.
        let scenario = scenario_from(unsafe { text(scenario_json, "scenario_json")? })?;
        let replace = flag(replace, "replace")?;
        let (map, version) =
            handle.call(timeout_ms, |c, t| Ok(c.upload_scenario_map(&scenario.world, None, replace, t)?))?;
        // SAFETY: non-null (checked above) and writable, as the caller promises.
        unsafe { write(map_out, "map_out", map)? };
        // SAFETY: NULL or writable, as the caller promises.
        unsafe { write_optional(version_out, version) };
        Ok(())
    })
}

fn scenario_from(json: &str) -> Result<Scenario, Failure> {
    Scenario::from_json(json).map_err(|e| Failure::invalid(format!("scenario: {e}")))
}

/// Fills `*request` for the rover of a scenario (SPEC §11 JSON text) on map `map`:
/// `dyfos_rendezvous_request_init`'s defaults, with the scenario's belief and its
/// parameters (every `set` bit on). Querying it with the seed of
/// `dyfos solve --seed` gives `dyfos solve`'s answer, bit for bit.
///
/// # Safety
/// `scenario_json` is NULL (refused) or NUL-terminated; `request` is NULL (refused)
/// or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_rendezvous_request_from_scenario(
    scenario_json: *const c_char,
    map: u64,
    request: *mut dyfos_rendezvous_request,
) -> dyfos_status {
    boundary(|| {
        non_null(request, "request")?;
        // SAFETY: NULL or NUL-terminated, as the caller promises.
        let scenario = scenario_from(unsafe { text(scenario_json, "scenario_json")? })?;
        let value = dyfos_rendezvous_request {
            map,
            mean: scenario.belief.mean.into(),
            cov: scenario.belief.cov.to_rows(),
            params: dyfos_params::from_params(&scenario.params, DYFOS_PARAMS_ALL_SET),
            ..dyfos_rendezvous_request::defaults()
        };
        // SAFETY: non-null and writable, as the caller promises.
        unsafe { write(request, "request", value) }
    })
}

/// Creates an empty map `map` at version 0 with `bounds` (4 doubles: x_min, y_min,
/// x_max, y_max, m) and the sun (elevation, azimuth, rad); writes the version (0)
/// to `*version_out` unless it is NULL. `DYFOS_STATUS_MAP_EXISTS` if the id is taken;
/// bounds or a sun the daemon would refuse are `DYFOS_STATUS_INVALID_DELTA`, as
/// from the daemon, and nothing is sent.
///
/// # Safety
/// `bounds` is NULL (refused) or points to 4 readable doubles; `version_out` is
/// NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_create_map(
    client: *mut dyfos_client,
    timeout_ms: u64,
    map: u64,
    bounds: *const f64,
    sun_elevation: f64,
    sun_azimuth: f64,
    version_out: *mut u64,
) -> dyfos_status {
    on_handle(client, |handle| {
        // SAFETY: NULL or 4 readable doubles, as the caller promises.
        let b = unsafe { required(bounds.cast::<[f64; 4]>(), "bounds")? };
        let (bounds, sun) = bounds_and_sun(b, sun_elevation, sun_azimuth)?;
        let version = handle.call(timeout_ms, |c, t| Ok(c.create_map(map, bounds, sun, t)?))?;
        // SAFETY: NULL or writable, as the caller promises.
        unsafe { write_optional(version_out, version) };
        Ok(())
    })
}

/// Creates map `map` (or, with `replace` 1, replaces it) from the bytes of an
/// OctoMap `.bt` file (`bt`, `bt_len` bytes): its occupied cells become the map's
/// voxels, OctoMap's cell (0, 0, 0) with its minimum corner at `origin` (3 doubles,
/// m; NULL for (0, 0, 0)), with `bounds` (4 doubles) and the sun; `replace` is 0 or
/// 1 (`DYFOS_STATUS_INVALID_ARGUMENT` otherwise). Writes the version
/// to `*version_out` unless it is NULL. A file that is not a readable `.bt`, bounds
/// or a sun the daemon would refuse are `DYFOS_STATUS_INVALID_DELTA` (the message
/// says what is wrong), too many cells `DYFOS_STATUS_OVER_CAPACITY`; nothing is
/// sent then.
///
/// # Safety
/// `bt` is NULL (refused) or points to `bt_len` readable bytes; `origin` is NULL or
/// 3 readable doubles; `bounds` is NULL (refused) or 4 readable doubles;
/// `version_out` is NULL or writable.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn dyfos_client_upload_octomap(
    client: *mut dyfos_client,
    timeout_ms: u64,
    map: u64,
    bt: *const u8,
    bt_len: usize,
    origin: *const f64,
    bounds: *const f64,
    sun_elevation: f64,
    sun_azimuth: f64,
    replace: u32,
    version_out: *mut u64,
) -> dyfos_status {
    on_handle(client, |handle| {
        if bt.is_null() {
            return Err(Failure::null("bt"));
        }
        // SAFETY: non-null and `bt_len` readable bytes, as the caller promises.
        let bytes = unsafe { std::slice::from_raw_parts(bt, bt_len) };
        // SAFETY: NULL or 3 readable doubles, as the caller promises.
        let origin =
            if origin.is_null() { [0.0; 3] } else { *unsafe { required(origin.cast::<[f64; 3]>(), "origin")? } };
        // SAFETY: NULL or 4 readable doubles, as the caller promises.
        let b = unsafe { required(bounds.cast::<[f64; 4]>(), "bounds")? };
        let (bounds, sun) = bounds_and_sun(b, sun_elevation, sun_azimuth)?;
        let replace = flag(replace, "replace")?;
        let origin = dyfos_shared::math::Point3::from(origin);
        let version =
            handle.call(timeout_ms, |c, t| Ok(c.upload_octomap(map, bytes, origin, bounds, sun, replace, t)?))?;
        // SAFETY: NULL or writable, as the caller promises.
        unsafe { write_optional(version_out, version) };
        Ok(())
    })
}

/// Applies map deltas (a JSON array, the format of `dyfos map apply` files) to map
/// `map` as one atomic batch (all or none) and writes the new version to
/// `*version_out` unless it is NULL. The version counts deltas, not batches: each
/// delta adds 1, so a batch of 5 deltas moves version 3 to 8 (a voxel run with its
/// cells is one delta; an empty batch changes nothing). With `expected_version`
/// other than `DYFOS_ANY_VERSION`, the map must be at that version first (else
/// `DYFOS_STATUS_MAP_VERSION_MISMATCH`, nothing applied). At most
/// `DYFOS_MAX_BATCH_RECORDS` records (else `DYFOS_STATUS_OVER_CAPACITY`, nothing
/// sent): split larger changes into several batches. Text that is not a JSON array
/// of deltas is `DYFOS_STATUS_MALFORMED_DELTA`; a delta the map refuses,
/// `DYFOS_STATUS_INVALID_DELTA`.
///
/// The format (`docs/deltas.md`): each delta is an object with one key, its kind; an
/// obstacle, voxels, sun or bounds are written as in a scenario file (SPEC §11):
/// `{"upsert_obstacle": {"id": 1, "cylinder": {"x": 2.0, "y": 1.0, "radius": 0.5, "height": 10.0}}}`,
/// `{"upsert_obstacle": {"id": 2, "box": {"min": [4.0, 4.0, 0.0], "max": [5.0, 6.0, 3.0]}}}`,
/// `{"remove_obstacle": {"id": 2}}`,
/// `{"set_voxels": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "occupied": [[1, 2, 3]]}}`
/// (`"free"` in place of `"occupied"` frees the cells),
/// `{"set_voxel_blocks": {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "occupied": [{"min": [0, 0, 4], "mask": 7}]}}`,
/// `{"set_sun": {"elevation": 0.5, "azimuth": 1.0}}`, `{"set_bounds": [-20.0, -20.0, 20.0, 20.0]}`,
/// `{"clear": {}}`. A document not of this form is `DYFOS_STATUS_MALFORMED_DELTA`, and
/// `dyfos_last_error` names the field and shows a valid example of its kind.
///
/// # Safety
/// `deltas_json` is NULL (refused) or NUL-terminated; `version_out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_apply(
    client: *mut dyfos_client,
    timeout_ms: u64,
    map: u64,
    deltas_json: *const c_char,
    expected_version: u64,
    version_out: *mut u64,
) -> dyfos_status {
    on_handle(client, |handle| {
        // SAFETY: NULL or NUL-terminated, as the caller promises.
        let deltas = deltas_from_json(unsafe { text(deltas_json, "deltas_json")? })?;
        let expected = (expected_version != DYFOS_ANY_VERSION).then_some(expected_version);
        let version = handle.call(timeout_ms, |c, t| Ok(c.apply(map, expected, &deltas, t)?))?;
        // SAFETY: NULL or writable, as the caller promises.
        unsafe { write_optional(version_out, version) };
        Ok(())
    })
}

/// The map as it is now, as a JSON object (`version`, `bounds`, `sun`,
/// `obstacles` in scenario form, `voxels` if any: `dyfos map snapshot` without its
/// `map` field), printed as `dyfos` prints it.
///
/// `json_out`: required; receives a NUL-terminated string the caller owns and
/// frees with `dyfos_string_free`; untouched on failure.
///
/// # Safety
/// `json_out` is NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_snapshot(
    client: *mut dyfos_client,
    timeout_ms: u64,
    map: u64,
    json_out: *mut *mut c_char,
) -> dyfos_status {
    on_handle(client, |handle| {
        non_null(json_out, "json_out")?;
        let world = handle.call(timeout_ms, |c, t| Ok(c.snapshot(map, t)?))?;
        give_string(json_out, "json_out", json_text(&world.to_json()))
    })
}

/// Deletes map `map` (and its file in the daemon's state directory). With
/// `expected_version` other than `DYFOS_ANY_VERSION`, the map must be at that
/// version (else `DYFOS_STATUS_MAP_VERSION_MISMATCH`, nothing deleted);
/// `DYFOS_STATUS_UNKNOWN_MAP` if no map has the id. The id is free again after:
/// e.g. upload a scenario again after deleting its content-id map
/// (`dyfos_client_list_maps` finds the ids the daemon holds).
///
/// # Safety
/// Always safe to call: no pointer but the handle, which is never dereferenced.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_delete_map(
    client: *mut dyfos_client,
    timeout_ms: u64,
    map: u64,
    expected_version: u64,
) -> dyfos_status {
    on_handle(client, |handle| {
        let expected = (expected_version != DYFOS_ANY_VERSION).then_some(expected_version);
        handle.call(timeout_ms, |c, t| Ok(c.delete_map(map, expected, t)?))
    })
}

/// Lists the maps the daemon holds, in id order: writes the first `capacity` of
/// them to `maps_out[0 .. capacity]` and their number to `*count_out`. If that
/// number is larger than `capacity`, only the first `capacity` maps were written
/// (ask again with a larger array); an array of `DYFOS_MAX_MAPS` entries always
/// holds every map. `maps_out` may be NULL when `capacity` is 0, to ask the number
/// only. On failure nothing is written.
///
/// The daemon describes one map per request (docs/wire.md §9), so this call makes
/// one request per map, all within the call's timeout. The list is not a snapshot
/// of one moment: a map made or deleted while it is walked may or may not be in it.
/// A walk that meets more than `DYFOS_MAX_MAPS` maps (maps made faster than they
/// are listed) is `DYFOS_STATUS_MAP_VERSION_MISMATCH`: call again.
///
/// # Safety
/// `maps_out` is NULL (refused unless `capacity` is 0) or points to `capacity`
/// writable `dyfos_map_info`; `count_out` is NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_list_maps(
    client: *mut dyfos_client,
    timeout_ms: u64,
    maps_out: *mut dyfos_map_info,
    capacity: usize,
    count_out: *mut usize,
) -> dyfos_status {
    on_handle(client, |handle| {
        non_null(count_out, "count_out")?;
        if capacity > 0 {
            non_null(maps_out, "maps_out")?;
        }
        let maps = handle.call(timeout_ms, |c, t| Ok(c.list_maps(t)?))?;
        for (i, map) in maps.iter().take(capacity).enumerate() {
            // SAFETY: `maps_out` is non-null (checked above, as `capacity` > 0) and
            // points to `capacity` writable entries, as the caller promises; i < capacity.
            unsafe { maps_out.add(i).write(dyfos_map_info::from(map)) };
        }
        // SAFETY: non-null (checked above) and writable, as the caller promises.
        unsafe { write(count_out, "count_out", maps.len()) }
    })
}

/// Asks the daemon for the optimal sensor pose for `*request` and writes it to
/// `*answer_out` (a struct the caller owns; nothing to free). Waits at most the
/// call's timeout (`timeout_ms`, 0 for the handle's); give the request a
/// `deadline_micros` shorter than that to get the best pose found in time.
///
/// # Safety
/// `request` is NULL (refused) or points to an initialised request whose
/// `deltas_json` is NULL or NUL-terminated; `answer_out` is NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_rendezvous(
    client: *mut dyfos_client,
    timeout_ms: u64,
    request: *const dyfos_rendezvous_request,
    answer_out: *mut dyfos_answer,
) -> dyfos_status {
    on_handle(client, |handle| {
        non_null(answer_out, "answer_out")?;
        // SAFETY: NULL or a valid request with a valid `deltas_json`, as the caller promises.
        let request = unsafe { required(request, "request")?.decode()? };
        let answer = handle.call(timeout_ms, |c, t| Ok(c.rendezvous(&request, t)?))?;
        // SAFETY: non-null and writable, as the caller promises.
        unsafe { write(answer_out, "answer_out", dyfos_answer::from(&answer)) }
    })
}

/// Sends `*request` in check mode: the daemon validates everything (map id and
/// version, belief, parameters, deltas on a copy of the map) and answers at once
/// without searching or changing the map; writes the version the query would
/// search to `*map_version_out` unless it is NULL. The round-trip floor, for
/// latency and health checks.
///
/// # Safety
/// As `dyfos_client_rendezvous`; `map_version_out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_client_check(
    client: *mut dyfos_client,
    timeout_ms: u64,
    request: *const dyfos_rendezvous_request,
    map_version_out: *mut u64,
) -> dyfos_status {
    on_handle(client, |handle| {
        // SAFETY: NULL or a valid request with a valid `deltas_json`, as the caller promises.
        let request = unsafe { required(request, "request")?.decode()? };
        let checked = handle.call(timeout_ms, |c, t| Ok(c.check(&request, t)?))?;
        // SAFETY: NULL or writable, as the caller promises.
        unsafe { write_optional(map_version_out, checked.map_version) };
        Ok(())
    })
}

/// The answer as the JSON text `dyfos solve` prints (same keys, same numbers, same
/// layout; without the final newline).
///
/// `json_out`: required; receives a NUL-terminated string the caller owns and
/// frees with `dyfos_string_free`; untouched on failure.
///
/// # Safety
/// `answer` is NULL (refused) or points to an initialised answer; `json_out` is
/// NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_answer_to_json(answer: *const dyfos_answer, json_out: *mut *mut c_char) -> dyfos_status {
    boundary(|| {
        non_null(json_out, "json_out")?;
        // SAFETY: NULL or a valid answer, as the caller promises.
        let answer = unsafe { required(answer, "answer")? }.decode()?;
        give_string(json_out, "json_out", json_text(&answer.to_json()))
    })
}

/// Writes `dyfos_rendezvous_request`'s defaults to `*request`: what a zeroed
/// request means (map 0, any version, a zero belief to set, algorithm dyfos, seed
/// 0, no budget, deadline or deltas, every parameter at its SPEC default with
/// `params.set` = 0), with the parameter fields holding their default values so
/// they can be read. Calling it is optional: `= {0}` gives the same request.
///
/// # Safety
/// `request` is NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_rendezvous_request_init(request: *mut dyfos_rendezvous_request) -> dyfos_status {
    // SAFETY: NULL or writable, as the caller promises.
    boundary(|| unsafe { write(request, "request", dyfos_rendezvous_request::defaults()) })
}

/// Writes the SPEC §11 defaults to `*params` with `set` = 0 (every field default).
///
/// # Safety
/// `params` is NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_params_init(params: *mut dyfos_params) -> dyfos_status {
    // SAFETY: NULL or writable, as the caller promises.
    boundary(|| unsafe { write(params, "params", dyfos_params::from_params(&Default::default(), 0)) })
}

/// Parses parameters given as a JSON object of SPEC §11 names (e.g.
/// `{"lambda": 2.0, "model": "anisotropic"}`; anything left out is the default) into
/// `*params`, with every `set` bit on. Text that is not such an object, or has an
/// unknown field, is `DYFOS_STATUS_INVALID_ARGUMENT`; a value out of its range is
/// `DYFOS_STATUS_INVALID_PARAMS`, as in a request. The message names the field.
///
/// # Safety
/// `json` is NULL (refused) or NUL-terminated; `params` is NULL (refused) or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_params_from_json(json: *const c_char, params: *mut dyfos_params) -> dyfos_status {
    boundary(|| {
        non_null(params, "params")?;
        // SAFETY: NULL or NUL-terminated, as the caller promises.
        let parsed = params_from_json(unsafe { text(json, "json")? }).map_err(|e| {
            let code = match e {
                ScenarioError::Malformed { .. } => DYFOS_STATUS_INVALID_ARGUMENT,
                ScenarioError::Invalid { .. } => DYFOS_STATUS_INVALID_PARAMS,
            };
            Failure::new(code, format!("params: {e}"))
        })?;
        // SAFETY: non-null and writable, as the caller promises.
        unsafe { write(params, "params", dyfos_params::from_params(&parsed, DYFOS_PARAMS_ALL_SET)) }
    })
}

/// Frees a string this library returned. NULL is a no-op. Leaves this thread's
/// last error message as it was.
///
/// # Safety
/// `s` is NULL or a string returned by this library and not freed yet; freeing
/// anything else (or twice) is undefined behaviour, as with `free(3)`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_string_free(s: *mut c_char) {
    boundary_quiet(|| {
        if !s.is_null() {
            // SAFETY: `s` came from `CString::into_raw` in this library and is freed
            // once, as the caller promises.
            drop(unsafe { CString::from_raw(s) });
        }
    });
}

/// Copies this thread's last error message (the failure of the last call on this
/// thread that returned a `dyfos_status`; empty after a success) into `buf` as a
/// NUL-terminated UTF-8 string and returns the message's full length in bytes,
/// without the NUL. If that is ≥ `len`, the copy was truncated (at a character
/// boundary) to fit: call again with a buffer of the returned length + 1. `buf`
/// may be NULL when `len` is 0, to ask the length. The message of a wire error is
/// the daemon's sentence.
///
/// # Safety
/// `buf` is NULL or points to `len` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dyfos_last_error(buf: *mut c_char, len: usize) -> usize {
    let copy = |message: &str| {
        if !buf.is_null() && len > 0 {
            let mut end = message.len().min(len - 1);
            while !message.is_char_boundary(end) {
                end -= 1;
            }
            // SAFETY: `buf` has `len` writable bytes (caller's promise); we write
            // `end + 1 <= len` of them, from a distinct Rust string.
            unsafe {
                std::ptr::copy_nonoverlapping(message.as_ptr(), buf.cast::<u8>(), end);
                buf.add(end).write(0);
            }
        }
        message.len()
    };
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| with_last_error(copy).unwrap_or(0))).unwrap_or(0)
}

/// The snake_case name of a status code (`"ok"`, `"map_version_mismatch"`,
/// `"null_parameter"`, ...), or `"unknown_status"`. A static string: do not free it.
#[unsafe(no_mangle)]
pub extern "C" fn dyfos_status_name(status: dyfos_status) -> *const c_char {
    let name = std::panic::catch_unwind(|| match status_name(status) {
        Some(n) => STATUS_C_NAMES.iter().find(|c| c.to_bytes() == n.as_bytes()).copied(),
        None => None,
    });
    name.ok().flatten().unwrap_or(c"unknown_status").as_ptr()
}

/// The ABI version this library implements (`DYFOS_ABI_VERSION` of the header it
/// was built with). A program may compare it with the `DYFOS_ABI_VERSION` it was
/// compiled with; the SONAME already keeps a library of another ABI from loading.
#[unsafe(no_mangle)]
pub extern "C" fn dyfos_abi_version() -> u32 {
    DYFOS_ABI_VERSION
}

/// This library's release version, `"MAJOR.MINOR.PATCH"`. A static string: do not
/// free it.
#[unsafe(no_mangle)]
pub extern "C" fn dyfos_version() -> *const c_char {
    VERSION.as_ptr()
}

const VERSION: &CStr = match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
    Ok(v) => v,
    Err(_) => panic!("the package version holds a NUL byte"),
};

/// Every status name as a C string (`dyfos_status_name` hands these out).
const STATUS_C_NAMES: [&std::ffi::CStr; 30] = [
    c"ok",
    c"malformed_request",
    c"invalid_algorithm",
    c"invalid_belief",
    c"invalid_params",
    c"unsupported_model",
    c"invalid_deadline",
    c"malformed_delta",
    c"invalid_delta",
    c"unknown_map",
    c"map_version_mismatch",
    c"map_exists",
    c"over_capacity",
    c"chunk_out_of_order",
    c"chunk_duplicate",
    c"chunk_incomplete",
    c"no_feasible_pose",
    c"deadline_exceeded",
    c"busy",
    c"storage_failed",
    c"shutting_down",
    c"internal_error",
    c"null_parameter",
    c"invalid_argument",
    c"no_daemon",
    c"daemon_gone",
    c"timeout",
    c"ipc",
    c"panic",
    c"incompatible_daemon",
];

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::CStr;

    fn last_error() -> String {
        // SAFETY: NULL with length 0 asks the length only.
        let n = unsafe { dyfos_last_error(std::ptr::null_mut(), 0) };
        let mut buf = vec![0u8; n + 1];
        // SAFETY: `buf` has n + 1 writable bytes.
        assert_eq!(unsafe { dyfos_last_error(buf.as_mut_ptr().cast(), buf.len()) }, n);
        CStr::from_bytes_until_nul(&buf).unwrap().to_str().unwrap().to_string()
    }

    #[test]
    fn every_status_has_its_c_name() {
        for code in (0..=21).chain(CLIENT_CODES.iter().map(|(c, _)| *c)) {
            // SAFETY: a static NUL-terminated string.
            let name = unsafe { CStr::from_ptr(dyfos_status_name(code)) }.to_str().unwrap();
            assert_eq!(Some(name), status_name(code));
        }
        // SAFETY: as above.
        assert_eq!(unsafe { CStr::from_ptr(dyfos_status_name(77)) }, c"unknown_status");
    }

    #[test]
    fn null_and_stale_handles_are_refused_with_the_null_parameter_code() {
        let mut json: *mut c_char = std::ptr::null_mut();
        let mut version = 0u64;
        // SAFETY (all calls below): every pointer is NULL, a made-up handle token
        // (never dereferenced by the library), or points to a local.
        unsafe {
            assert_eq!(dyfos_client_stats(std::ptr::null_mut(), 0, &mut json), DYFOS_STATUS_NULL_PARAMETER);
            assert!(last_error().contains("`client` is NULL"), "{}", last_error());
            let made_up = std::ptr::without_provenance_mut::<dyfos_client>(0xdead_0000);
            assert_eq!(dyfos_client_stats(made_up, 0, &mut json), DYFOS_STATUS_NULL_PARAMETER);
            assert!(last_error().contains("not a live handle"), "{}", last_error());
            assert_eq!(dyfos_client_free(made_up), DYFOS_STATUS_NULL_PARAMETER);
            assert_eq!(dyfos_client_free(std::ptr::null_mut()), DYFOS_STATUS_OK);
            assert_eq!(last_error(), "");
            let bounds = [0.0, 0.0, 1.0, 1.0];
            assert_eq!(
                dyfos_client_create_map(made_up, 0, 1, bounds.as_ptr(), 0.5, 0.5, &mut version),
                DYFOS_STATUS_NULL_PARAMETER
            );
            assert_eq!(dyfos_rendezvous_request_init(std::ptr::null_mut()), DYFOS_STATUS_NULL_PARAMETER);
            assert_eq!(dyfos_params_init(std::ptr::null_mut()), DYFOS_STATUS_NULL_PARAMETER);
            assert_eq!(dyfos_answer_to_json(std::ptr::null(), &mut json), DYFOS_STATUS_NULL_PARAMETER);
            assert_eq!(
                dyfos_client_connect(std::ptr::null(), std::ptr::null(), 10, std::ptr::null_mut()),
                DYFOS_STATUS_NULL_PARAMETER
            );
        }
        assert!(json.is_null(), "no string handed out on failure");
    }

    /// Every function on a handle, given a NULL or made-up handle together with bad
    /// inputs, reports the handle: the handle is checked before anything else.
    #[test]
    fn a_bad_handle_is_reported_before_any_bad_input() {
        let made_up = std::ptr::without_provenance_mut::<dyfos_client>(0xdead_0010);
        let bad_request = dyfos_rendezvous_request {
            mean: [f64::NAN; 3],
            algorithm: 99,
            has_expected_version: 7,
            deltas_json: c"[not json".as_ptr(),
            ..dyfos_rendezvous_request::defaults()
        };
        let inverted = [1.0, 1.0, -1.0, -1.0];
        let garbage = [0u8; 3];
        let mut answer = dyfos_answer::default();
        for handle in [std::ptr::null_mut(), made_up] {
            // SAFETY (all calls): NULL, a made-up token (never dereferenced), C string
            // literals, or locals.
            let codes = unsafe {
                [
                    dyfos_client_stats(handle, 0, std::ptr::null_mut()),
                    dyfos_client_upload_scenario(
                        handle,
                        0,
                        c"{}".as_ptr(),
                        9,
                        std::ptr::null_mut(),
                        std::ptr::null_mut(),
                    ),
                    dyfos_client_upload_scenario(
                        handle,
                        0,
                        std::ptr::null(),
                        0,
                        std::ptr::null_mut(),
                        std::ptr::null_mut(),
                    ),
                    dyfos_client_create_map(handle, 0, 1, inverted.as_ptr(), f64::NAN, 0.0, std::ptr::null_mut()),
                    dyfos_client_create_map(handle, 0, 1, std::ptr::null(), 0.5, 0.0, std::ptr::null_mut()),
                    dyfos_client_upload_octomap(
                        handle,
                        0,
                        1,
                        garbage.as_ptr(),
                        garbage.len(),
                        std::ptr::null(),
                        inverted.as_ptr(),
                        9.0,
                        0.0,
                        5,
                        std::ptr::null_mut(),
                    ),
                    dyfos_client_apply(handle, 0, 1, c"[not json".as_ptr(), 0, std::ptr::null_mut()),
                    dyfos_client_apply(handle, 0, 1, std::ptr::null(), 0, std::ptr::null_mut()),
                    dyfos_client_snapshot(handle, 0, 1, std::ptr::null_mut()),
                    dyfos_client_delete_map(handle, 0, 1, 0),
                    dyfos_client_list_maps(handle, 0, std::ptr::null_mut(), 5, std::ptr::null_mut()),
                    dyfos_client_rendezvous(handle, 0, &bad_request, &mut answer),
                    dyfos_client_rendezvous(handle, 0, std::ptr::null(), std::ptr::null_mut()),
                    dyfos_client_check(handle, 0, &bad_request, std::ptr::null_mut()),
                    dyfos_client_check(handle, 0, std::ptr::null(), std::ptr::null_mut()),
                ]
            };
            for (i, code) in codes.into_iter().enumerate() {
                assert_eq!(code, DYFOS_STATUS_NULL_PARAMETER, "call {i} with handle {handle:?}: {}", last_error());
                assert!(last_error().contains("`client`"), "call {i}: {}", last_error());
            }
        }
    }

    #[test]
    fn string_free_leaves_the_last_error_as_it_was() {
        // SAFETY: a NULL handle and a local output.
        let code = unsafe { dyfos_client_stats(std::ptr::null_mut(), 0, &mut std::ptr::null_mut()) };
        assert_eq!(code, DYFOS_STATUS_NULL_PARAMETER);
        let message = last_error();
        assert!(!message.is_empty());
        // SAFETY: NULL is a no-op.
        unsafe { dyfos_string_free(std::ptr::null_mut()) };
        assert_eq!(last_error(), message);
        let mut json: *mut c_char = std::ptr::null_mut();
        let answer = dyfos_answer::default();
        // SAFETY: a valid answer and a local output.
        assert_eq!(unsafe { dyfos_answer_to_json(&answer, &mut json) }, DYFOS_STATUS_OK);
        // SAFETY: NULL handle and a local output.
        unsafe { dyfos_client_stats(std::ptr::null_mut(), 0, &mut std::ptr::null_mut()) };
        // SAFETY: a string this library returned, freed once.
        unsafe { dyfos_string_free(json) };
        assert_eq!(last_error(), message, "freeing a string is not a call that clears the message");
    }

    #[test]
    fn bad_arguments_are_refused_before_any_ipc() {
        let mut handle: *mut dyfos_client = std::ptr::null_mut();
        // SAFETY: valid C strings and a local output.
        unsafe {
            assert_eq!(dyfos_client_connect(c"bad prefix".as_ptr(), std::ptr::null(), 10, &mut handle), 1001);
            assert!(last_error().contains("bad prefix"), "{}", last_error());
            assert_eq!(dyfos_client_connect(std::ptr::null(), c"a/b".as_ptr(), 10, &mut handle), 1001);
            assert_eq!(dyfos_client_connect(std::ptr::null(), std::ptr::null(), 0, &mut handle), 1001);
            let not_utf8 = [0xffu8, 0];
            assert_eq!(dyfos_client_connect(not_utf8.as_ptr().cast(), std::ptr::null(), 10, &mut handle), 1001);
            assert!(last_error().contains("UTF-8"), "{}", last_error());
        }
        assert!(handle.is_null());
    }

    /// Bounds and sun given as arguments get the code the daemon gives the same
    /// values in a map request (`invalid_delta`), not a client-side code.
    #[test]
    fn bounds_and_sun_arguments_get_the_daemons_code() {
        let inverted = bounds_and_sun(&[1.0, 1.0, -1.0, -1.0], 0.5, 0.5).unwrap_err();
        assert_eq!(inverted.code, DYFOS_STATUS_INVALID_DELTA, "{}", inverted.message);
        let overhead = bounds_and_sun(&[0.0, 0.0, 1.0, 1.0], 5.0, 0.5).unwrap_err();
        assert_eq!(overhead.code, DYFOS_STATUS_INVALID_DELTA, "{}", overhead.message);
        assert!(overhead.message.contains("elevation"), "{}", overhead.message);
        assert_eq!(
            decode_bounds([1.0, 1.0, -1.0, -1.0]).unwrap_err().status as u32,
            inverted.code,
            "the daemon's own check"
        );
        assert!(bounds_and_sun(&[0.0, 0.0, 1.0, 1.0], 0.5, 0.5).is_ok());
    }

    #[test]
    fn last_error_truncates_at_a_character_boundary_and_reports_the_full_length() {
        let message = "é".repeat(10); // 20 bytes
        assert_eq!(boundary(|| Err(Failure::invalid(message.clone()))), DYFOS_STATUS_INVALID_ARGUMENT);
        let mut buf = [0x55u8; 6];
        // SAFETY: `buf` has 6 writable bytes.
        assert_eq!(unsafe { dyfos_last_error(buf.as_mut_ptr().cast(), buf.len()) }, 20);
        // 5 bytes fit; the boundary is at 4: "éé" and the NUL.
        assert_eq!(CStr::from_bytes_until_nul(&buf).unwrap().to_str().unwrap(), "éé");
        assert_eq!(last_error(), message);
    }

    #[test]
    fn params_from_json_sets_every_bit_and_names_bad_fields() {
        let mut p = dyfos_params::default();
        // SAFETY: valid C strings and a local output.
        unsafe {
            assert_eq!(dyfos_params_from_json(cr#"{"lambda": 2.0}"#.as_ptr(), &mut p), DYFOS_STATUS_OK);
            assert_eq!((p.lambda, p.set), (2.0, DYFOS_PARAMS_ALL_SET));
            assert_eq!(dyfos_params_from_json(cr#"{"rho_mim": 2}"#.as_ptr(), &mut p), DYFOS_STATUS_INVALID_ARGUMENT);
            assert!(last_error().contains("rho_min"), "{}", last_error());
            assert_eq!(dyfos_params_from_json(c"[1,".as_ptr(), &mut p), DYFOS_STATUS_INVALID_ARGUMENT);
            // A value out of range: the code a request with it gets.
            assert_eq!(dyfos_params_from_json(cr#"{"rho_min": 9}"#.as_ptr(), &mut p), DYFOS_STATUS_INVALID_PARAMS);
            assert!(last_error().contains("rho_min"), "{}", last_error());
            assert_eq!(dyfos_params_init(&mut p), DYFOS_STATUS_OK);
        }
        assert_eq!((p.set, p.to_params().unwrap()), (0, dyfos_shared::params::Params::default()));
        let out_of_range = dyfos_params { rho_min: 9.0, set: DYFOS_PARAM_RHO_MIN, ..p };
        assert_eq!(out_of_range.to_params().unwrap_err().code, DYFOS_STATUS_INVALID_PARAMS);
    }

    #[test]
    fn the_version_is_the_packages() {
        // SAFETY: a static NUL-terminated string.
        let version = unsafe { CStr::from_ptr(dyfos_version()) }.to_str().unwrap();
        assert_eq!(version, env!("CARGO_PKG_VERSION"));
        assert_eq!(version, format!("{DYFOS_VERSION_MAJOR}.{DYFOS_VERSION_MINOR}.{DYFOS_VERSION_PATCH}"));
        assert_eq!(dyfos_abi_version(), DYFOS_ABI_VERSION);
    }

    #[test]
    fn json_text_prints_like_the_cli() {
        let v = serde_json::json!({"a": 1, "b": [0.1, 2.0], "c": "x"});
        assert_eq!(json_text(&v), "{\n  \"a\": 1,\n  \"b\": [0.1,2.0],\n  \"c\": \"x\"\n}");
        assert_eq!(json_text(&serde_json::json!([1])), "[1]");
    }
}
