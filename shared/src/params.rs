//! The problem's parameters (SPEC §2, §3, §6, §11) with SPEC's defaults.
//!
//! ```
//! use dyfos_shared::params::Params;
//!
//! let p = Params::default();
//! assert_eq!(p.rho_max, 6.0);
//! assert!(p.validate().is_ok());
//! let bad = Params { rho_min: 7.0, ..Params::default() };
//! assert_eq!(bad.validate().unwrap_err().to_string(), "rho_min = 7 must be < rho_max = 6");
//! ```

use crate::codes::codes;
use crate::limits::{MAX_COORDINATE, MAX_PERIMETER_POINTS};
use crate::math::Vector3;
use std::f64::consts::{FRAC_PI_2, PI};

codes! {
    /// Which SDSMM predicts the measurement noise (SPEC §6); the name is the scenario
    /// files' and the code the wire's `params.model`.
    #[derive(Default)]
    pub enum ModelKind("params.model", serde) {
        /// The paper's isotropic linear model.
        #[default]
        Paper = 0, "paper";
        /// `paper`'s variance stretched along the line of sight.
        Anisotropic = 1, "anisotropic";
        /// A trained probabilistic neural network, loaded from a file.
        Learned = 2, "learned";
    }
}

/// Calls macro `$callback` with every parameter of SPEC §11, written once here:
/// its documentation, its place in the wire struct (`#[wire(i)]`: the field's order
/// in [`WireParams`](crate::wire::rendezvous::WireParams) and its bit in `set`), its
/// name (the field, the key in files, the C field), its type and its SPEC default.
/// The list is in the order of [`Params`] and of the files dyfos writes.
///
/// [`Params`] and its `Default`, the wire conversions and `WireParams::FIELDS`, the
/// scenario files' `params` object both ways and the C binding's conversions are
/// generated from it; the C and C++ headers, which must spell the fields out, are
/// checked against it by the binding's tests.
#[macro_export]
macro_rules! spec_params {
    ($callback:ident) => {
        $callback! {
            /// Rover footprint radius, m (SPEC §2).
            #[wire(0)] rover_radius: f64 = 0.75,
            /// Target points on the footprint circle besides the marker centre.
            #[wire(15)] perimeter_points: u32 = 8,
            /// Marker side, m.
            #[wire(1)] marker_size: f64 = 0.2,
            /// Marker height above ground, m.
            #[wire(2)] marker_height: f64 = 0.2,
            /// Viewer body radius, m (SPEC §3).
            #[wire(3)] viewer_radius: f64 = 0.375,
            /// Extra clearance for the collision rays, m (SPEC §5).
            #[wire(4)] safety_margin: f64 = 0.25,
            /// Lowest viewer altitude, m.
            #[wire(5)] z_min: f64 = 0.5,
            /// Highest viewer altitude, m.
            #[wire(6)] z_max: f64 = 8.0,
            /// Downward camera pitch, rad (positive looks down).
            #[wire(7)] camera_pitch: f64 = 45f64.to_radians(),
            /// Camera translation in the level viewer frame, m.
            #[wire(8)] t_vs: $crate::math::Vector3<f64> = $crate::math::Vector3::new(0.1, 0.0, -0.05),
            /// Horizontal field of view, rad.
            #[wire(9)] f_h: f64 = 69.4f64.to_radians(),
            /// Vertical field of view, rad.
            #[wire(10)] f_v: f64 = 42.5f64.to_radians(),
            /// Shortest detection range, m.
            #[wire(11)] rho_min: f64 = 1.0,
            /// Longest detection range, m.
            #[wire(12)] rho_max: f64 = 6.0,
            /// Sun-glare lobe exponent κ.
            #[wire(13)] kappa: f64 = 1.0,
            /// Anisotropy λ of the `anisotropic` model.
            #[wire(14)] lambda: f64 = 3.0,
            /// The SDSMM to use.
            #[wire(16)] model: $crate::params::ModelKind = $crate::params::ModelKind::Paper,
        }
    };
}

macro_rules! params_struct {
    ($($(#[doc = $doc:literal])* #[wire($slot:literal)] $name:ident: $ty:ty = $default:expr,)*) => {
        /// Rover, viewer, camera and model parameters. [`Params::default`] is SPEC's table.
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct Params {
            $($(#[doc = $doc])* pub $name: $ty,)*
        }

        impl Default for Params {
            fn default() -> Self {
                Params { $($name: $default,)* }
            }
        }
    };
}

spec_params!(params_struct);

/// How a parameter's type is carried on the wire and in files.
pub trait ParamValue: Copy {
    /// Its type in [`WireParams`](crate::wire::rendezvous::WireParams).
    type Wire: Copy;
    /// Its type in the files' `params` object.
    type File;
    /// The wire value.
    fn to_wire(self) -> Self::Wire;
    /// The value from the wire, or what is wrong with the code `field` carries.
    fn from_wire(field: &str, wire: Self::Wire) -> Result<Self, String>;
    /// The value in files.
    fn to_file(self) -> Self::File;
    /// The value from a file.
    fn from_file(file: Self::File) -> Self;
}

macro_rules! plain_param_value {
    ($($ty:ty),*) => {$(
        impl ParamValue for $ty {
            type Wire = $ty;
            type File = $ty;
            fn to_wire(self) -> $ty {
                self
            }
            fn from_wire(_: &str, wire: $ty) -> Result<$ty, String> {
                Ok(wire)
            }
            fn to_file(self) -> $ty {
                self
            }
            fn from_file(file: $ty) -> $ty {
                file
            }
        }
    )*};
}

plain_param_value!(f64, u32);

impl ParamValue for Vector3<f64> {
    type Wire = [f64; 3];
    type File = [f64; 3];
    fn to_wire(self) -> [f64; 3] {
        self.into()
    }
    fn from_wire(_: &str, wire: [f64; 3]) -> Result<Self, String> {
        Ok(Vector3::from(wire))
    }
    fn to_file(self) -> [f64; 3] {
        self.into()
    }
    fn from_file(file: [f64; 3]) -> Self {
        Vector3::from(file)
    }
}

impl ParamValue for ModelKind {
    type Wire = u32;
    type File = ModelKind;
    fn to_wire(self) -> u32 {
        self.code()
    }
    fn from_wire(field: &str, wire: u32) -> Result<Self, String> {
        ModelKind::try_from(wire).map_err(|_| format!("{field} = {wire} is not a model ({})", ModelKind::listing()))
    }
    fn to_file(self) -> ModelKind {
        self
    }
    fn from_file(file: ModelKind) -> Self {
        file
    }
}

/// A parameter outside its meaningful range (SPEC §11). `field` is the scenario name.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} = {value} {rule}")]
pub struct ParamError {
    /// The parameter's name in scenario files, e.g. `rho_min`.
    pub field: &'static str,
    /// The offending value.
    pub value: f64,
    /// What it must satisfy, e.g. `must be > 0`.
    pub rule: String,
}

fn require(field: &'static str, value: f64, ok: bool, rule: impl Into<String>) -> Result<(), ParamError> {
    require_with(field, value, ok, || rule.into())
}

/// [`require`] whose rule is only formatted on failure: `validate` runs for every
/// request, and formatting two numbers on every call cost more than all the checks.
fn require_with(field: &'static str, value: f64, ok: bool, rule: impl FnOnce() -> String) -> Result<(), ParamError> {
    if !value.is_finite() {
        return Err(ParamError { field, value, rule: "must be a finite number".into() });
    }
    if ok { Ok(()) } else { Err(ParamError { field, value, rule: rule() }) }
}

impl Params {
    /// Checks every range of SPEC §11. The first violation is returned.
    ///
    /// SPEC bounds `t_vs` and `rho_max` only by "finite" (and ρ_min < ρ_max); like
    /// every map coordinate they are kept within ±[`MAX_COORDINATE`] (1e6 m), so no
    /// derived position or distance can overflow. Any physically meaningful value
    /// passes.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.validate_given(|_| true)
    }

    /// [`Params::validate`] for parameters of which only those `given(name)` says
    /// were chosen (the others are SPEC defaults): when a pair is out of order
    /// (`z_min < z_max`, `rho_min < rho_max`), the error names the one chosen, not
    /// a default the caller never set. With both chosen, or neither, it names
    /// `z_max` and `rho_min`, as [`Params::validate`] does.
    pub fn validate_given(&self, given: impl Fn(&str) -> bool) -> Result<(), ParamError> {
        let p = self;
        let only = |chosen: &str, default: &str| given(chosen) && !given(default);
        require("rover_radius", p.rover_radius, p.rover_radius > 0.0, "must be > 0")?;
        require("viewer_radius", p.viewer_radius, p.viewer_radius > 0.0, "must be > 0")?;
        require("marker_size", p.marker_size, p.marker_size > 0.0, "must be > 0")?;
        require("marker_height", p.marker_height, p.marker_height >= 0.0, "must be >= 0")?;
        require("safety_margin", p.safety_margin, p.safety_margin >= 0.0, "must be >= 0")?;
        require("f_h", p.f_h, p.f_h > 0.0 && p.f_h < PI, "must be in (0, π)")?;
        require("f_v", p.f_v, p.f_v > 0.0 && p.f_v < PI, "must be in (0, π)")?;
        require("z_min", p.z_min, p.z_min >= 0.0, "must be >= 0")?;
        if only("z_min", "z_max") {
            require_with("z_min", p.z_min, p.z_min < p.z_max, || format!("must be < z_max = {}", p.z_max))?;
        }
        require_with("z_max", p.z_max, p.z_max > p.z_min, || format!("must be > z_min = {}", p.z_min))?;
        require("camera_pitch", p.camera_pitch, p.camera_pitch.abs() <= FRAC_PI_2, "must be in [-π/2, π/2]")?;
        for (i, v) in p.t_vs.iter().enumerate() {
            let field = ["t_vs[0]", "t_vs[1]", "t_vs[2]"][i];
            require(field, *v, v.abs() <= MAX_COORDINATE, "must be within ±1e6 m")?;
        }
        require("rho_min", p.rho_min, p.rho_min > 0.0, "must be > 0")?;
        if only("rho_max", "rho_min") {
            require_with("rho_max", p.rho_max, p.rho_max > p.rho_min, || format!("must be > rho_min = {}", p.rho_min))?;
        }
        require_with("rho_min", p.rho_min, p.rho_min < p.rho_max, || format!("must be < rho_max = {}", p.rho_max))?;
        require("rho_max", p.rho_max, p.rho_max <= MAX_COORDINATE, "must be <= 1e6")?;
        require("kappa", p.kappa, p.kappa > 0.0, "must be > 0")?;
        require("lambda", p.lambda, p.lambda >= 0.0, "must be >= 0")?;
        let n = f64::from(p.perimeter_points);
        require("perimeter_points", n, p.perimeter_points <= MAX_PERIMETER_POINTS, "must be in [0, 4096]")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        Params::default().validate().unwrap();
    }

    /// SPEC §11 gives no upper limit for `t_vs` or `rho_max`: long booms and long
    /// detection ranges are valid (only the ±1e6 m sanity limit of every coordinate
    /// applies).
    #[test]
    fn long_camera_booms_and_ranges_are_valid() {
        let d = Params::default();
        for p in [
            Params { rho_max: 2.0e4, ..d },
            Params { rho_min: 500.0, rho_max: 1.0e6, ..d },
            Params { t_vs: Vector3::new(150.0, -200.0, 1000.0), ..d },
        ] {
            assert_eq!(p.validate(), Ok(()), "{p:?}");
        }
        assert_eq!(Params { rho_max: 1.1e6, ..d }.validate().unwrap_err().field, "rho_max");
        assert_eq!(Params { t_vs: Vector3::new(0.0, 0.0, -2e6), ..d }.validate().unwrap_err().field, "t_vs[2]");
    }

    #[test]
    fn every_range_is_checked() {
        let d = Params::default();
        let cases: Vec<(Params, &str)> = vec![
            (Params { rover_radius: 0.0, ..d }, "rover_radius"),
            (Params { viewer_radius: -1.0, ..d }, "viewer_radius"),
            (Params { marker_size: 0.0, ..d }, "marker_size"),
            (Params { marker_height: -0.1, ..d }, "marker_height"),
            (Params { safety_margin: -0.1, ..d }, "safety_margin"),
            (Params { f_h: PI, ..d }, "f_h"),
            (Params { f_v: 0.0, ..d }, "f_v"),
            (Params { z_min: -0.5, ..d }, "z_min"),
            (Params { z_max: 0.5, ..d }, "z_max"),
            (Params { camera_pitch: 1.6, ..d }, "camera_pitch"),
            (Params { rho_min: 0.0, ..d }, "rho_min"),
            (Params { rho_min: 6.0, ..d }, "rho_min"),
            (Params { kappa: 0.0, ..d }, "kappa"),
            (Params { lambda: -1.0, ..d }, "lambda"),
            (Params { perimeter_points: 4097, ..d }, "perimeter_points"),
            (Params { kappa: f64::NAN, ..d }, "kappa"),
            (Params { t_vs: Vector3::new(f64::INFINITY, 0.0, 0.0), ..d }, "t_vs[0]"),
        ];
        for (p, field) in cases {
            assert_eq!(p.validate().unwrap_err().field, field);
        }
    }
}
