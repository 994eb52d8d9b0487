//! `dyfos._dyfos`: the private extension module behind `import dyfos`.
//!
//! It wraps the one Rust client, [`dyfos_client::Client`]; the public API, its
//! exceptions and docs are the pure-Python package `dyfos` (`python/dyfos/`). A
//! belief's mean and covariance are read here straight from any sequence or numpy
//! array; dicts cross as JSON text and are read with the same
//! functions the `dyfos` command line uses (`params_from_json`, `Scenario::from_json`,
//! `map_json` for map deltas and snapshots), so Python and Rust cannot disagree on a
//! format.
//!
//! Every call releases the GIL while it waits on the daemon. A [`PyClient`] holds
//! its Rust client behind a mutex: several Python threads may share it, and their
//! requests go one at a time (the Rust client has one request in flight); threads
//! that want parallel queries open one client each.
//!
//! Errors: every failure becomes a `(status, detail, retryable, index)` tuple given
//! to the exception factory the Python package registers
//! ([`set_error_factory`]), which picks the `dyfos.DyfosError` subclass; `status` is
//! the wire name (`map_version_mismatch`) or, for failures that never reached the
//! daemon, one of the names listed in [`ErrorInfo`].

use dyfos_client::prelude::*;
use dyfos_shared::wire::map::{decode_bounds, decode_sun};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyList};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

mod defaults;
mod voxels;

/// A failure on its way to Python: the wire status name (or a local one), the
/// sentence saying what to do, whether retrying may help, and the index of the
/// failing delta for delta errors, and for rendezvous errors the version the
/// request left the map at.
///
/// Local names (no wire status): `no_daemon`, `daemon_gone`, `timeout`,
/// `incompatible_daemon`, `ipc_error`, `invalid_prefix`, `invalid_domain`,
/// `invalid_scenario`, `client_closed`.
#[derive(Debug, Clone, PartialEq)]
struct ErrorInfo {
    status: &'static str,
    detail: String,
    retryable: bool,
    index: Option<u64>,
    map_version: Option<u64>,
}

impl ErrorInfo {
    fn new(status: &'static str, detail: impl ToString) -> Self {
        ErrorInfo { status, detail: detail.to_string(), retryable: false, index: None, map_version: None }
    }

    fn rejection(r: &Rejection) -> Self {
        ErrorInfo {
            status: r.status.name(),
            detail: r.message.clone(),
            retryable: r.status.is_retryable(),
            index: r.index,
            map_version: r.map_version,
        }
    }
}

impl From<ClientOpenError> for ErrorInfo {
    fn from(e: ClientOpenError) -> Self {
        let status = match &e {
            ClientOpenError::InvalidPrefix(_) => "invalid_prefix",
            ClientOpenError::InvalidDomain(_) => "invalid_domain",
            ClientOpenError::NoDaemon { .. } => "no_daemon",
            ClientOpenError::Incompatible { .. } => "incompatible_daemon",
            ClientOpenError::Ipc(_) => "ipc_error",
        };
        ErrorInfo { retryable: matches!(e, ClientOpenError::NoDaemon { .. }), ..ErrorInfo::new(status, e) }
    }
}

/// The three request errors have the same variants; one conversion for each.
macro_rules! request_error_info {
    ($($error:ident),*) => {$(
        impl From<$error> for ErrorInfo {
            fn from(e: $error) -> Self {
                let retryable = e.is_retryable();
                let info = match e {
                    $error::Connect(e) => ErrorInfo::from(e),
                    $error::Rejected(r) | $error::Invalid(r) => ErrorInfo::rejection(&r),
                    e @ $error::NoDaemon { .. } => ErrorInfo::new("no_daemon", e),
                    e @ $error::DaemonGone => ErrorInfo::new("daemon_gone", e),
                    e @ $error::Timeout(_) => ErrorInfo::new("timeout", e),
                    e @ $error::Ipc(_) => ErrorInfo::new("ipc_error", e),
                    e @ $error::Interrupted => ErrorInfo::new("interrupted", e),
                };
                ErrorInfo { retryable, ..info }
            }
        }
    )*};
}
request_error_info!(RendezvousError, MapRequestError, StatsRequestError);

/// The Python callable `(status, detail, retryable, index, map_version) -> exception`.
static ERROR_FACTORY: PyOnceLock<Py<PyAny>> = PyOnceLock::new();

/// The Python exception for `e`, made by the registered factory.
fn to_pyerr(py: Python<'_>, e: ErrorInfo) -> PyErr {
    let Some(factory) = ERROR_FACTORY.get(py) else {
        return PyRuntimeError::new_err(format!("{}: {}", e.status, e.detail));
    };
    match factory.call1(py, (e.status, e.detail, e.retryable, e.index, e.map_version)) {
        Ok(exception) => PyErr::from_value(exception.into_bound(py)),
        Err(err) => err,
    }
}

/// Registers the callable that turns a failure into the `dyfos.DyfosError` subclass
/// to raise: `factory(status, detail, retryable, index, map_version)`. Called once by `dyfos`.
#[pyfunction]
fn set_error_factory(py: Python<'_>, factory: Py<PyAny>) {
    let _ = ERROR_FACTORY.set(py, factory);
}

/// Converts a JSON value to the Python object `json.loads` gives for its text:
/// integers stay `int`, every other number is the same `float`, bit for bit.
fn json_to_py<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => {
            if let Some(u) = n.as_u64() {
                u.into_pyobject(py)?.into_any()
            } else if let Some(i) = n.as_i64() {
                i.into_pyobject(py)?.into_any()
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any()
            }
        }
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(json_to_py(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(fields) => {
            let dict = PyDict::new(py);
            for (k, v) in fields {
                dict.set_item(k, json_to_py(py, v)?)?;
            }
            dict.into_any()
        }
    })
}

/// Seconds (a Python float) as a [`Duration`], refusing negative, NaN or huge values.
fn seconds(name: &str, s: f64) -> Result<Duration, ErrorInfo> {
    Duration::try_from_secs_f64(s)
        .map_err(|_| ErrorInfo::new("malformed_request", format!("{name} = {s} s must be a finite number ≥ 0")))
}

/// A belief's mean and covariance from any Python sequences of numbers (lists,
/// tuples, numpy arrays and their rows), read straight into floats.
fn belief_numbers(mean: &Bound<'_, PyAny>, cov: &Bound<'_, PyAny>) -> Result<([f64; 3], [[f64; 3]; 3]), ErrorInfo> {
    let mean = mean.extract::<[f64; 3]>().map_err(|e| {
        ErrorInfo::new("malformed_request", format!("mean must be 3 numbers [x, y, θ] (a list or numpy array): {e}"))
    })?;
    let cov = cov.extract::<[[f64; 3]; 3]>().map_err(|e| {
        ErrorInfo::new(
            "malformed_request",
            format!("cov must be a 3×3 matrix (3 rows of 3 numbers, or a numpy array): {e}"),
        )
    })?;
    Ok((mean, cov))
}

/// The parts of a rendezvous request, as the Python layer passes them.
struct RequestArgs<'a> {
    map_id: u64,
    mean: [f64; 3],
    cov: [[f64; 3]; 3],
    algorithm: &'a str,
    seed: u64,
    params: Option<&'a str>,
    budget: Option<u64>,
    deadline: Option<f64>,
    expected_version: Option<u64>,
    deltas: Option<&'a str>,
}

impl RequestArgs<'_> {
    /// The validated request; errors carry the status the daemon would give.
    fn request(&self) -> Result<RendezvousRequest, ErrorInfo> {
        let belief = Belief::new(self.mean, self.cov).map_err(|e| {
            ErrorInfo::new("invalid_belief", format!("belief: {e}; pass a finite mean and an SPD 3×3 covariance"))
        })?;
        let algorithm = Algorithm::from_name(self.algorithm).ok_or_else(|| {
            ErrorInfo::new(
                "invalid_algorithm",
                format!("algorithm `{}` is not one of dyfos, dyfos-scipy, brute, random, center", self.algorithm),
            )
        })?;
        let params = match self.params {
            None => Params::default(),
            Some(json) => {
                dyfos_shared::scenario::params_from_json(json).map_err(|e| ErrorInfo::new("invalid_params", e))?
            }
        };
        let deltas = match self.deltas {
            None => Vec::new(),
            Some(json) => deltas_from_json(json)?,
        };
        Ok(RendezvousRequest {
            map: self.map_id,
            expected_version: self.expected_version,
            belief,
            deltas,
            algorithm,
            seed: self.seed,
            budget: self.budget,
            deadline: self.deadline.map(|d| seconds("deadline", d)).transpose()?,
            params,
        })
    }
}

/// Bounds and sun given as arguments, checked as the daemon checks them (the same
/// code, `invalid_delta`, as a bad `set_bounds` or `set_sun` delta).
pub(crate) fn bounds_and_sun(bounds: [f64; 4], sun: (f64, f64)) -> Result<(Bounds, Sun), ErrorInfo> {
    let bounds = decode_bounds(bounds).map_err(|r| ErrorInfo::rejection(&r))?;
    let sun = decode_sun([sun.0, sun.1]).map_err(|r| ErrorInfo::rejection(&r))?;
    Ok((bounds, sun))
}

/// A JSON array of map deltas, as in `dyfos map apply` files (`docs/deltas.md`);
/// the error names the field, shows a valid example and gives the delta's index.
fn deltas_from_json(json: &str) -> Result<Vec<MapDelta>, ErrorInfo> {
    dyfos_shared::map_json::deltas_from_json(json)
        .map_err(|e| ErrorInfo { index: e.index().map(|i| i as u64), ..ErrorInfo::new("malformed_delta", &e) })
}

/// The answer to a rendezvous query, as the JSON object `dyfos solve` prints.
/// The Python class `dyfos.Answer` reads it; `to_dict()` is that dict.
#[pyclass(frozen, module = "dyfos._dyfos", name = "RawAnswer")]
struct PyAnswer(Answer);

#[pymethods]
impl PyAnswer {
    /// The answer as the dict `json.loads` makes of `dyfos solve`'s output: the same
    /// keys, and the same numbers bit for bit.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.0.to_json())
    }

    /// The answer as the JSON text `dyfos solve` prints (one line).
    fn to_json(&self) -> String {
        self.0.to_json().to_string()
    }

    /// The search algorithm used.
    #[getter]
    fn algorithm(&self) -> &'static str {
        self.0.algorithm.name()
    }

    /// The sensor state x = [ρ, ψ, φ, ψ_v].
    #[getter]
    fn x(&self) -> [f64; 4] {
        self.0.x.to_array()
    }

    /// E = ln det Σ⁺.
    #[getter]
    fn cost(&self) -> f64 {
        self.0.cost
    }

    /// The predicted measurement noise R, 2×2.
    #[getter(R)]
    fn r(&self) -> [[f64; 2]; 2] {
        self.0.r
    }

    /// The predicted posterior Σ⁺, 3×3 rows.
    #[getter]
    fn posterior(&self) -> [[f64; 3]; 3] {
        dyfos_shared::math::rows3(&self.0.posterior)
    }

    /// The sensor's position [x, y, z].
    #[getter]
    fn sensor_position(&self) -> [f64; 3] {
        self.0.sensor_position.coords.into()
    }

    /// The sensor's orientation [x, y, z, w], as `dyfos solve` prints it.
    #[getter]
    fn sensor_quaternion(&self) -> [f64; 4] {
        dyfos_shared::math::canonical_xyzw(&self.0.sensor_orientation)
    }

    /// The viewer's position [x, y, z].
    #[getter]
    fn viewer_position(&self) -> [f64; 3] {
        self.0.viewer_position.coords.into()
    }

    /// The viewer's yaw ψ_v.
    #[getter]
    fn viewer_yaw(&self) -> f64 {
        self.0.viewer_yaw
    }

    /// Candidates evaluated: {total, workspace, collision, occlusion}.
    #[getter]
    fn evaluations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let e = self.0.evaluations;
        let dict = PyDict::new(py);
        dict.set_item("total", e.total)?;
        dict.set_item("workspace", e.workspace)?;
        dict.set_item("collision", e.collision)?;
        dict.set_item("occlusion", e.occlusion)?;
        Ok(dict)
    }

    /// The map version searched (after the request's deltas, one version each).
    #[getter]
    fn map_version(&self) -> u64 {
        self.0.map_version
    }

    /// Why the search stopped, by its JSON name (`finished`, `deadline`, ...).
    #[getter]
    fn stop(&self) -> String {
        match serde_json::to_value(self.0.stop) {
            Ok(serde_json::Value::String(name)) => name,
            _ => format!("{:?}", self.0.stop),
        }
    }

    /// The search's compute time, µs.
    #[getter]
    fn micros(&self) -> u64 {
        self.0.micros
    }
}

/// A connection to one `dyfosd`: `dyfos_client::Client` behind a mutex.
#[pyclass(frozen, module = "dyfos._dyfos", name = "RawClient")]
struct PyClient {
    client: Mutex<Option<Client>>,
    timeout: Duration,
    /// What a signal handler raised (`KeyboardInterrupt` on Ctrl-C) while a call
    /// waited: the call ends and raises it.
    raised: Arc<Mutex<Option<PyErr>>>,
}

impl PyClient {
    /// Runs `call` on the client with the GIL released; `timeout` in seconds, or
    /// the client's default.
    fn call<T: Send, E: Into<ErrorInfo>>(
        &self,
        py: Python<'_>,
        timeout: Option<f64>,
        call: impl FnOnce(&mut Client, Duration) -> Result<T, E> + Send,
    ) -> PyResult<T> {
        let timeout = match timeout {
            None => self.timeout,
            Some(t) => seconds("timeout", t).map_err(|e| to_pyerr(py, e))?,
        };
        let result = py.detach(|| {
            let mut guard = self.lock();
            let client = guard.as_mut().ok_or_else(closed)?;
            call(client, timeout).map_err(Into::into)
        });
        let raised = self.raised.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).take();
        match (result, raised) {
            (Err(_), Some(raised)) => Err(raised),
            (result, _) => result.map_err(|e| to_pyerr(py, e)),
        }
    }

    /// The client; a panic in an earlier call (a bug) does not lock it for good.
    fn lock(&self) -> MutexGuard<'_, Option<Client>> {
        self.client.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

fn closed() -> ErrorInfo {
    ErrorInfo::new("client_closed", "this dyfos.Client is closed; open a new one")
}

#[pymethods]
impl PyClient {
    /// Connects to the daemon serving `prefix` (in iceoryx2 `domain`), waiting up to
    /// `connect_timeout` seconds for it; `timeout` is every call's default limit.
    #[new]
    #[pyo3(signature = (prefix, domain, timeout, connect_timeout))]
    fn new(
        py: Python<'_>,
        prefix: String,
        domain: Option<String>,
        timeout: f64,
        connect_timeout: f64,
    ) -> PyResult<Self> {
        let (timeout, connect_timeout) =
            (|| Ok((seconds("timeout", timeout)?, seconds("connect_timeout", connect_timeout)?)))()
                .map_err(|e| to_pyerr(py, e))?;
        let config = ClientConfig { prefix, domain, connect_timeout, ..ClientConfig::default() };
        let mut client = py.detach(|| Client::connect(&config)).map_err(|e| to_pyerr(py, e.into()))?;
        // Python's signal handlers run only when Python code runs: while a call waits
        // (without the GIL) the client asks for them, so that Ctrl-C ends the call
        // (PEP 475). `check_signals` does nothing off the main thread.
        let raised = Arc::new(Mutex::new(None));
        let slot = Arc::clone(&raised);
        client.set_interrupt_check(Some(Box::new(move || {
            Python::attach(|py| match py.check_signals() {
                Ok(()) => false,
                Err(e) => {
                    *slot.lock().unwrap_or_else(|poisoned| poisoned.into_inner()) = Some(e);
                    true
                }
            })
        })));
        Ok(PyClient { client: Mutex::new(Some(client)), timeout, raised })
    }

    /// Closes the connection (idempotent); later calls raise `client_closed`.
    fn close(&self, py: Python<'_>) {
        // Waits for a call in flight on another thread; closing the ports happens
        // without the GIL too.
        py.detach(|| drop(self.lock().take()));
    }

    /// Whether [`PyClient::close`] was called.
    #[getter]
    fn closed(&self, py: Python<'_>) -> bool {
        py.detach(|| self.lock().is_none())
    }

    /// The daemon's health and counters, as the dict `dyfos stats` prints.
    #[pyo3(signature = (timeout=None))]
    fn stats<'py>(&self, py: Python<'py>, timeout: Option<f64>) -> PyResult<Bound<'py, PyAny>> {
        let stats = self.call(py, timeout, |c, t| c.stats(t))?;
        json_to_py(py, &stats.to_json())
    }

    /// Makes sure the daemon holds the map of a scenario, or of a map as `snapshot`
    /// gives it (JSON text); returns `(map_id, version)`.
    #[pyo3(signature = (scenario_json, map_id=None, replace=false, timeout=None))]
    fn upload_scenario(
        &self,
        py: Python<'_>,
        scenario_json: &str,
        map_id: Option<u64>,
        replace: bool,
        timeout: Option<f64>,
    ) -> PyResult<(u64, u64)> {
        let world = dyfos_shared::map_json::world_from_json_with_files(scenario_json, |path| {
            Err(format!("cannot read `{path}`: an OctoMap scenario is uploaded with upload_octomap"))
        })
        .map_err(|e| to_pyerr(py, ErrorInfo::new("invalid_scenario", format!("scenario: {e}"))))?;
        self.call(py, timeout, |c, t| c.upload_scenario_map(&world, map_id, replace, t))
    }

    /// Uploads an OctoMap `.bt` file's bytes as map `map_id`; returns the version.
    #[pyo3(signature = (map_id, bt, bounds, sun, origin=[0.0, 0.0, 0.0], replace=false, timeout=None))]
    #[allow(clippy::too_many_arguments)]
    fn upload_octomap(
        &self,
        py: Python<'_>,
        map_id: u64,
        bt: Vec<u8>,
        bounds: [f64; 4],
        sun: (f64, f64),
        origin: [f64; 3],
        replace: bool,
        timeout: Option<f64>,
    ) -> PyResult<u64> {
        let (bounds, sun) = bounds_and_sun(bounds, sun).map_err(|e| to_pyerr(py, e))?;
        let origin = dyfos_shared::math::Point3::from(origin);
        self.call(py, timeout, |c, t| c.upload_octomap(map_id, &bt, origin, bounds, sun, replace, t))
    }

    /// Creates an empty map at version 0; returns the version.
    #[pyo3(signature = (map_id, bounds, sun, timeout=None))]
    fn create_map(
        &self,
        py: Python<'_>,
        map_id: u64,
        bounds: [f64; 4],
        sun: (f64, f64),
        timeout: Option<f64>,
    ) -> PyResult<u64> {
        let (bounds, sun) = bounds_and_sun(bounds, sun).map_err(|e| to_pyerr(py, e))?;
        self.call(py, timeout, |c, t| c.create_map(map_id, bounds, sun, t))
    }

    /// Applies a JSON array of map deltas atomically; returns the new version (the old
    /// one plus the number of deltas: the version counts deltas, not batches).
    #[pyo3(signature = (map_id, deltas_json, expected_version=None, timeout=None))]
    fn apply(
        &self,
        py: Python<'_>,
        map_id: u64,
        deltas_json: &str,
        expected_version: Option<u64>,
        timeout: Option<f64>,
    ) -> PyResult<u64> {
        let deltas = deltas_from_json(deltas_json).map_err(|e| to_pyerr(py, e))?;
        self.call(py, timeout, |c, t| c.apply(map_id, expected_version, &deltas, t))
    }

    /// The map as it is now: the dict `dyfos map snapshot` prints.
    #[pyo3(signature = (map_id, timeout=None))]
    fn snapshot<'py>(&self, py: Python<'py>, map_id: u64, timeout: Option<f64>) -> PyResult<Bound<'py, PyAny>> {
        let world = self.call(py, timeout, |c, t| c.snapshot(map_id, t))?;
        json_to_py(py, &dyfos_shared::map_json::map_to_json(Some(map_id), &world))
    }

    /// Deletes the map.
    #[pyo3(signature = (map_id, expected_version=None, timeout=None))]
    fn delete_map(
        &self,
        py: Python<'_>,
        map_id: u64,
        expected_version: Option<u64>,
        timeout: Option<f64>,
    ) -> PyResult<()> {
        self.call(py, timeout, |c, t| c.delete_map(map_id, expected_version, t))
    }

    /// Every map the daemon holds, in id order: a list of the dicts `dyfos map list`
    /// prints, one a map.
    #[pyo3(signature = (timeout=None))]
    fn list_maps<'py>(&self, py: Python<'py>, timeout: Option<f64>) -> PyResult<Vec<Bound<'py, PyAny>>> {
        let maps = self.call(py, timeout, |c, t| c.list_maps(t))?;
        maps.iter().map(|m| json_to_py(py, &m.to_json())).collect()
    }

    /// A rendezvous query: with `check` false the answer (see
    /// `dyfos.Client.rendezvous`), with `check` true the same request in check mode,
    /// validated by the daemon and not searched: the map version it would search.
    #[pyo3(signature = (check, map_id, mean, cov, algorithm, seed, params, budget, deadline, expected_version, deltas, timeout))]
    #[allow(clippy::too_many_arguments)]
    fn rendezvous<'py>(
        &self,
        py: Python<'py>,
        check: bool,
        map_id: u64,
        mean: &Bound<'_, PyAny>,
        cov: &Bound<'_, PyAny>,
        algorithm: &str,
        seed: u64,
        params: Option<&str>,
        budget: Option<u64>,
        deadline: Option<f64>,
        expected_version: Option<u64>,
        deltas: Option<&str>,
        timeout: Option<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (mean, cov) = belief_numbers(mean, cov).map_err(|e| to_pyerr(py, e))?;
        let args =
            RequestArgs { map_id, mean, cov, algorithm, seed, params, budget, deadline, expected_version, deltas };
        let request = args.request().map_err(|e| to_pyerr(py, e))?;
        if check {
            let checked = self.call(py, timeout, |c, t| c.check(&request, t))?;
            Ok(checked.map_version.into_pyobject(py)?.into_any())
        } else {
            let answer = self.call(py, timeout, |c, t| c.rendezvous(&request, t))?;
            Ok(Bound::new(py, PyAnswer(answer))?.into_any())
        }
    }

    /// Benchmark baseline: sends the same `dyfos` query (`check` true: in check mode)
    /// `count` times from Rust, with no Python in the loop, and returns each round
    /// trip in seconds. `bench.py` compares it with the same calls made from Python.
    #[pyo3(signature = (map_id, mean, cov, check, count, timeout=None))]
    #[allow(clippy::too_many_arguments)]
    fn _rust_round_trips(
        &self,
        py: Python<'_>,
        map_id: u64,
        mean: [f64; 3],
        cov: [[f64; 3]; 3],
        check: bool,
        count: usize,
        timeout: Option<f64>,
    ) -> PyResult<Vec<f64>> {
        let args = RequestArgs {
            map_id,
            mean,
            cov,
            algorithm: "dyfos",
            seed: 0,
            params: None,
            budget: None,
            deadline: None,
            expected_version: None,
            deltas: None,
        };
        let request = args.request().map_err(|e| to_pyerr(py, e))?;
        self.call(py, timeout, |c, t| {
            let mut times = Vec::with_capacity(count);
            for _ in 0..count {
                let start = Instant::now();
                if check {
                    std::hint::black_box(c.check(&request, t)?);
                } else {
                    std::hint::black_box(c.rendezvous(&request, t)?);
                }
                times.push(start.elapsed().as_secs_f64());
            }
            Ok::<_, RendezvousError>(times)
        })
    }
}

/// The private extension module of `dyfos`: use `import dyfos`, not this.
#[pymodule]
fn _dyfos(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyClient>()?;
    m.add_class::<PyAnswer>()?;
    m.add_function(wrap_pyfunction!(set_error_factory, m)?)?;
    m.add_class::<voxels::PyVoxels>()?;
    m.add_function(wrap_pyfunction!(voxels::upload_voxels, m)?)?;
    m.add_function(wrap_pyfunction!(voxels::update_voxels, m)?)?;
    m.add_function(wrap_pyfunction!(defaults::default_params, m)?)?;
    m.add("MAX_DELTAS_PER_BATCH", dyfos_shared::limits::MAX_DELTAS_PER_MESSAGE)?;
    m.add("DEFAULT_PREFIX", dyfos_client::DEFAULT_PREFIX)?;
    Ok(())
}
