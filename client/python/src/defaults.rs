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
    let p = Params::default();
    let t_vs: [f64; 3] = p.t_vs.into();
    let json = serde_json::json!({
        "rover_radius": p.rover_radius,
        "perimeter_points": p.perimeter_points,
        "marker_size": p.marker_size,
        "marker_height": p.marker_height,
        "viewer_radius": p.viewer_radius,
        "safety_margin": p.safety_margin,
        "z_min": p.z_min,
        "z_max": p.z_max,
        "camera_pitch": p.camera_pitch,
        "t_vs": t_vs,
        "f_h": p.f_h,
        "f_v": p.f_v,
        "rho_min": p.rho_min,
        "rho_max": p.rho_max,
        "kappa": p.kappa,
        "lambda": p.lambda,
        "model": p.model.name(),
    });
    json_to_py(py, &json)
}
