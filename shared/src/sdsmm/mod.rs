//! SDSMM: the state-dependent sensor measurement model (SPEC §6).
//!
//! [`Features`] are what can be predicted about a measurement before it is taken:
//! where the rover will appear in the image, how far it is, how much sun glare the
//! marker reflects into the camera, and the viewing geometry. An [`Sdsmm`] maps
//! them to the measurement noise R on the rover's (x, y).
//!
//! ```
//! use dyfos_shared::params::Params;
//! use dyfos_shared::sdsmm::{Features, Paper, Sdsmm};
//! use dyfos_shared::sensor::{SensorRig, SensorState};
//! use dyfos_shared::world::Sun;
//! use nalgebra::Point3;
//!
//! let params = Params::default();
//! let target = Point3::new(0.0, 0.0, 0.2);
//! let pose = SensorRig::new(&params).pose(&target, &SensorState::new(1.0, 0.0, 0.0, 0.0));
//! // Sun behind the camera (azimuth π, camera looking along +x): no glare.
//! let sun = Sun::new(0.5, std::f64::consts::PI).unwrap().direction();
//! let f = Features::new(&params, &sun, &pose, &target);
//! assert_eq!((f.e, f.s, f.c), (0.0, 0.0, 0.0));
//! let r = Paper.noise(&f);
//! assert!((r.matrix()[(0, 0)] - 2.0 * 0.03f64.powi(2)).abs() < 1e-15); // σ1² + σ2²
//! ```

mod anisotropic;
mod learned;
mod mlp;
mod paper;
mod synthetic;

pub use anisotropic::Anisotropic;
pub use learned::{
    LEARNED_INPUTS, LEARNED_OUTPUTS, LOG_STD_RANGE, Learned, LearnedModelError, LearnedWeights, MAX_HIDDEN,
    learned_input, noise_from_outputs,
};
pub use paper::{Paper, paper_variance};
pub use synthetic::Synthetic;

use crate::math::{Cov2, Point3, Vector3};
use crate::params::{ModelKind, Params};
use crate::sensor::SensorPose;
use std::sync::Arc;

/// The predictable features of one measurement (SPEC §6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Features {
    /// Horizontal image coordinate, −1..1 across the field of view.
    pub u: f64,
    /// Vertical image coordinate, −1..1 across the field of view.
    pub v: f64,
    /// Distance from the image centre, `min(1, max(|u|, |v|))`.
    pub e: f64,
    /// Normalised distance, `clamp((ρ − ρ_min)/(ρ_max − ρ_min), 0, 1)`.
    pub s: f64,
    /// Sun glare, `2·max(0, r·w)^κ` (0 with the sun at or below the horizon).
    pub c: f64,
    /// Unit view direction from the marker to the sensor.
    pub w: Vector3<f64>,
    /// Viewing elevation ε = atan2(w_z, |w_xy|).
    pub elevation: f64,
    /// Bearing β from the sensor to the rover.
    pub bearing: f64,
    /// Distance ρ from the sensor to the marker, m.
    pub rho: f64,
    /// The rover's heading θ, rad: 0 from [`Features::new`], set by
    /// [`Features::with_rover_heading`]. Only the `learned` model (and the synthetic
    /// reference model it is trained against) reads it, as the bearing relative to the
    /// rover, `β − θ`; `paper` and `anisotropic` ignore it.
    pub rover_heading: f64,
}

impl Features {
    /// The features of observing the marker centre `target` from `pose` under a sun
    /// with unit direction `sun` (SPEC §6). ρ is measured, so this also serves the
    /// true states of a simulation.
    #[inline]
    pub fn new(params: &Params, sun: &Vector3<f64>, pose: &SensorPose, target: &Point3<f64>) -> Self {
        Self::with_half_fov_tangents(params, Self::half_fov_tangents(params), sun, pose, target)
    }

    /// `[tan(f_h/2), tan(f_v/2)]`, for [`Features::with_half_fov_tangents`].
    pub fn half_fov_tangents(params: &Params) -> [f64; 2] {
        [(params.f_h / 2.0).tan(), (params.f_v / 2.0).tan()]
    }

    /// [`Features::new`] with the tangents of the half fields of view computed once
    /// per request instead of per candidate (the same numbers, bit for bit).
    #[inline]
    pub fn with_half_fov_tangents(
        params: &Params,
        half_fov_tangents: [f64; 2],
        sun: &Vector3<f64>,
        pose: &SensorPose,
        target: &Point3<f64>,
    ) -> Self {
        Self::compute(params, half_fov_tangents, sun, pose, target, true)
    }

    /// The features; with `angles` false, the elevation and bearing (two `atan2`) are
    /// left NaN for a model that reads neither. Every other field is the same.
    #[inline(always)]
    fn compute(
        params: &Params,
        half_fov_tangents: [f64; 2],
        sun: &Vector3<f64>,
        pose: &SensorPose,
        target: &Point3<f64>,
        angles: bool,
    ) -> Self {
        let q = pose.to_sensor(target);
        let u = (q.y / q.x) / half_fov_tangents[0];
        let v = (q.z / q.x) / half_fov_tangents[1];
        let e = u.abs().max(v.abs()).min(1.0);
        let to_sensor = pose.position - target;
        let rho = to_sensor.norm();
        let s = ((rho - params.rho_min) / (params.rho_max - params.rho_min)).clamp(0.0, 1.0);
        let w = to_sensor / rho;
        let c = if sun.z <= 0.0 {
            0.0
        } else {
            let reflected = Vector3::new(-sun.x, -sun.y, sun.z);
            let g = reflected.dot(&w).max(0.0);
            // pow(g, 1) is g exactly (IEEE 754); the default κ skips the call.
            2.0 * if params.kappa == 1.0 { g } else { g.powf(params.kappa) }
        };
        let (elevation, bearing) = if angles {
            (w.z.atan2(w.x.hypot(w.y)), (target.y - pose.position.y).atan2(target.x - pose.position.x))
        } else {
            (f64::NAN, f64::NAN)
        };
        Features { u, v, e, s, c, w, elevation, bearing, rho, rover_heading: 0.0 }
    }

    /// The same features for a rover heading `theta` (rad): the belief's mean heading
    /// when predicting, the true heading when simulating.
    #[inline]
    pub fn with_rover_heading(self, theta: f64) -> Self {
        Features { rover_heading: theta, ..self }
    }

    /// The bearing from the sensor to the rover relative to the rover's heading,
    /// `β − θ` wrapped into [−π, π).
    #[inline]
    pub fn relative_bearing(&self) -> f64 {
        crate::math::wrap_angle(self.bearing - self.rover_heading)
    }
}

/// A state-dependent measurement model: features in, noise covariance R out.
pub trait Sdsmm {
    /// The predicted covariance of the measured rover (x, y), m².
    fn noise(&self, features: &Features) -> Cov2;
}

/// The model a request chose (SPEC §6), dispatched statically. Cheap to clone
/// (learned weights are shared), `Send + Sync`.
#[derive(Debug, Clone, PartialEq)]
pub enum NoiseModel {
    /// The paper's isotropic model.
    Paper(Paper),
    /// The line-of-sight stretched model.
    Anisotropic(Anisotropic),
    /// A trained network, weights loaded from a model file.
    Learned(Arc<Learned>),
    /// The synthetic reference camera the learned model is trained against and judged
    /// by; for experiments only (scenario files cannot name it).
    Synthetic(Synthetic),
}

/// A model that cannot be built from the parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoiseModelError {
    /// `learned` needs weights, which this caller did not load.
    #[error("model `learned` needs trained weights; pass a model file (e.g. `--model model.bin`)")]
    LearnedWithoutWeights,
}

impl NoiseModel {
    /// The model named by `params.model`, with its parameters. `learned` needs
    /// weights: see [`NoiseModel::from_params_and_weights`].
    pub fn from_params(params: &Params) -> Result<Self, NoiseModelError> {
        Self::from_params_and_weights(params, None)
    }

    /// The model named by `params.model`; `learned` uses `weights` (loaded once, shared
    /// by every clone). Weights given for another model are not used.
    pub fn from_params_and_weights(params: &Params, weights: Option<&Arc<Learned>>) -> Result<Self, NoiseModelError> {
        match params.model {
            ModelKind::Paper => Ok(NoiseModel::Paper(Paper)),
            ModelKind::Anisotropic => Ok(NoiseModel::Anisotropic(Anisotropic { lambda: params.lambda })),
            ModelKind::Learned => match weights {
                Some(w) => Ok(NoiseModel::Learned(Arc::clone(w))),
                None => Err(NoiseModelError::LearnedWithoutWeights),
            },
        }
    }
}

impl NoiseModel {
    /// The noise of observing the marker centre `target` from `pose` with the rover's
    /// heading `theta`: [`Sdsmm::noise`] of [`Features::with_half_fov_tangents`] with
    /// that heading, bit for bit, without the viewing angles `paper` and
    /// `anisotropic` do not read (the search's hot path).
    #[inline]
    pub fn noise_at(
        &self,
        params: &Params,
        half_fov_tangents: [f64; 2],
        sun: &Vector3<f64>,
        pose: &SensorPose,
        target: &Point3<f64>,
        theta: f64,
    ) -> Cov2 {
        match self {
            NoiseModel::Paper(m) => m.noise(&Features::compute(params, half_fov_tangents, sun, pose, target, false)),
            NoiseModel::Anisotropic(m) => {
                m.noise(&Features::compute(params, half_fov_tangents, sun, pose, target, false))
            }
            NoiseModel::Learned(_) | NoiseModel::Synthetic(_) => self.noise(
                &Features::with_half_fov_tangents(params, half_fov_tangents, sun, pose, target)
                    .with_rover_heading(theta),
            ),
        }
    }
}

impl Sdsmm for NoiseModel {
    #[inline]
    fn noise(&self, features: &Features) -> Cov2 {
        match self {
            NoiseModel::Paper(m) => m.noise(features),
            NoiseModel::Anisotropic(m) => m.noise(features),
            NoiseModel::Learned(m) => m.noise(features),
            NoiseModel::Synthetic(m) => m.noise(features),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::{SensorRig, SensorState};
    use crate::world::Sun;

    /// The search's shortcut gives every model's noise bit for bit, for suns above and
    /// below the horizon, κ = 1 and not, and views from every side.
    #[test]
    fn noise_at_is_noise_of_the_features_bit_for_bit() {
        let learned = Learned::from_bytes(include_bytes!("../../../tests/data/learned/model.bin")).unwrap();
        let models = [
            NoiseModel::Paper(Paper),
            NoiseModel::Anisotropic(Anisotropic { lambda: 3.0 }),
            NoiseModel::Learned(Arc::new(learned)),
            NoiseModel::Synthetic(Synthetic::default()),
        ];
        let mut k = 0u32;
        for kappa in [1.0, 2.5] {
            let params = Params { kappa, ..Params::default() };
            let rig = SensorRig::new(&params);
            let tangents = Features::half_fov_tangents(&params);
            for (elevation, azimuth) in [(0.7, 2.1), (-0.2, 0.3), (1.2, -2.9)] {
                let sun = Sun::new(elevation, azimuth).unwrap().direction();
                for i in 0..400 {
                    k = k.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                    let r = |j: u32| f64::from((k >> (j * 4)) & 0xffff) / 65_535.0;
                    let x = SensorState::new(
                        1.0 + 5.0 * r(0),
                        (r(1) - 0.5) * params.f_h,
                        (r(2) - 0.5) * params.f_v,
                        f64::from(i) * 0.37,
                    );
                    let target = Point3::new(r(3) * 4.0 - 2.0, r(4) - 0.5, 0.2);
                    let pose = rig.pose(&target, &x);
                    let theta = r(5) * 6.0 - 3.0;
                    for model in &models {
                        let f = Features::with_half_fov_tangents(&params, tangents, &sun, &pose, &target)
                            .with_rover_heading(theta);
                        let want = model.noise(&f);
                        let got = model.noise_at(&params, tangents, &sun, &pose, &target, theta);
                        let bits = |c: &Cov2| c.matrix().map(f64::to_bits);
                        assert_eq!(bits(&got), bits(&want), "{model:?} at {x:?}");
                    }
                }
            }
        }
    }
}
