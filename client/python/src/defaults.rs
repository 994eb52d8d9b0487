//! SPEC's default parameters, by the names scenario files and requests use, so that
//! a caller can show them (a ROS node declares its parameters with them) without a
//! second copy of the numbers.

use super::json_to_py;
use dyfos_shared::params::Params;
use pyo3::prelude::*;

/// Every SPEC §11 parameter at its default, as the dict `params` takes: floats,
/// `perimeter_points` an int, `t_vs` three floats, `model` a name.
#[pyfunction]
pub(crate) fn default_params(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let json = dyfos_shared::scenario::params_to_json(&Params::default());
    json_to_py(py, &json)
}
