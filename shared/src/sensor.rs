//! The viewer's camera and the search space (SPEC §3, §4).
//!
//! A candidate [`SensorState`] `x = (ρ, ψ, φ, ψ_v)` says where the rover's marker
//! appears to the camera — at distance ρ, horizontal angle ψ and vertical angle φ
//! in the sensor frame — and which way the viewer faces. [`SensorRig::pose`] turns
//! it into the sensor and viewer poses in the world.
//!
//! ```
//! use dyfos_shared::params::Params;
//! use dyfos_shared::sensor::{SensorRig, SensorState};
//! use nalgebra::Point3;
//!
//! let rig = SensorRig::new(&Params::default());
//! let target = Point3::new(0.0, 0.0, 0.2);
//! let pose = rig.pose(&target, &SensorState::new(2.0, 0.0, 0.0, 0.0));
//! // Looking 45° down along +x from 2 m away: the sensor is behind and above.
//! assert!((pose.position - Point3::new(-2f64.sqrt(), 0.0, 0.2 + 2f64.sqrt())).norm() < 1e-12);
//! assert!(((pose.position - target).norm() - 2.0).abs() < 1e-12);
//! ```

use crate::math::{Matrix3, Point3, Rotation3, UnitQuaternion, Vector3, canonical_xyzw, rot_y, rot_z, wrap_angle};
use crate::params::Params;
use nalgebra::Quaternion;
use std::f64::consts::PI;

/// A candidate sensor state `x = (ρ, ψ, φ, ψ_v)` (SPEC §4).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SensorState {
    /// Distance from the sensor to the marker centre, m.
    pub rho: f64,
    /// Horizontal angle of the marker in the sensor frame, rad (> 0: left of centre).
    pub psi: f64,
    /// Vertical angle of the marker in the sensor frame, rad (> 0: above centre).
    pub phi: f64,
    /// Viewer yaw ψ_v, rad, in [−π, π).
    pub yaw: f64,
}

impl SensorState {
    /// A state with the yaw wrapped into [−π, π).
    pub fn new(rho: f64, psi: f64, phi: f64, yaw: f64) -> Self {
        SensorState { rho, psi, phi, yaw: wrap_angle(yaw) }
    }

    /// `[ρ, ψ, φ, ψ_v]`.
    pub fn to_array(&self) -> [f64; 4] {
        [self.rho, self.psi, self.phi, self.yaw]
    }

    /// From `[ρ, ψ, φ, ψ_v]`, yaw wrapped.
    pub fn from_array(x: [f64; 4]) -> Self {
        Self::new(x[0], x[1], x[2], x[3])
    }
}

/// The closed box of candidate states (SPEC §4), from the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchSpace {
    /// Lower corner `[ρ_min, −f_h/2, −f_v/2, −π]`.
    pub lo: [f64; 4],
    /// Upper corner `[ρ_max, f_h/2, f_v/2, π]` (yaw π reads as −π).
    pub hi: [f64; 4],
}

impl SearchSpace {
    /// The search space of `params`.
    pub fn new(params: &Params) -> Self {
        SearchSpace {
            lo: [params.rho_min, -params.f_h / 2.0, -params.f_v / 2.0, -PI],
            hi: [params.rho_max, params.f_h / 2.0, params.f_v / 2.0, PI],
        }
    }

    /// The state at unit-cube coordinates `u ∈ [0, 1]⁴`: `lo + u·(hi − lo)`.
    #[inline]
    pub fn from_unit(&self, u: &[f64; 4]) -> SensorState {
        let x: [f64; 4] = std::array::from_fn(|i| self.lo[i] + u[i] * (self.hi[i] - self.lo[i]));
        SensorState::from_array(x)
    }

    /// Whether `x` lies in the box (closed; the yaw is always in range once wrapped).
    pub fn contains(&self, x: &SensorState) -> bool {
        let a = x.to_array();
        (0..3).all(|i| self.lo[i] <= a[i] && a[i] <= self.hi[i]) && a[3].is_finite()
    }
}

/// Where the camera and the viewer are for one candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorPose {
    /// Sensor position p_s, world frame.
    pub position: Point3<f64>,
    /// `R_ws = Rz(ψ_v)·Ry(camera_pitch)`: sensor axes in the world frame.
    pub rotation: Matrix3<f64>,
    /// Viewer position p_v, world frame.
    pub viewer_position: Point3<f64>,
    /// Viewer yaw ψ_v.
    pub viewer_yaw: f64,
}

impl SensorPose {
    /// The sensor orientation as a unit quaternion in SPEC §3's sign: w ≥ 0, and
    /// where w = 0 the first non-zero of x, y, z positive. nalgebra's conversion
    /// gives w < 0 for some yaws; carrying the sign here means every place that
    /// writes the quaternion (JSON answers, wire replies) writes the same numbers.
    pub fn quaternion(&self) -> UnitQuaternion<f64> {
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(self.rotation));
        let [x, y, z, w] = canonical_xyzw(&q);
        UnitQuaternion::new_unchecked(Quaternion::new(w, x, y, z))
    }

    /// The point `p` in the sensor frame: `R_wsᵀ (p − p_s)`.
    #[inline]
    pub fn to_sensor(&self, p: &Point3<f64>) -> Vector3<f64> {
        self.rotation.tr_mul(&(p - self.position))
    }
}

/// What a pose takes from the viewer yaw ψ_v alone ([`SensorRig::yaw_frame`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawFrame {
    /// ψ_v.
    pub yaw: f64,
    /// `R_ws = Rz(ψ_v)·Ry(camera_pitch)`.
    pub rotation: Matrix3<f64>,
    /// `Rz(ψ_v)·t_vs`: the sensor's offset from the viewer, world frame.
    pub offset: Vector3<f64>,
}

/// The camera's mounting on the viewer, precomputed from [`Params`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorRig {
    pitch: Matrix3<f64>,
    t_vs: Vector3<f64>,
}

impl SensorRig {
    /// The rig of `params` (`camera_pitch`, `t_vs`).
    pub fn new(params: &Params) -> Self {
        SensorRig { pitch: rot_y(params.camera_pitch), t_vs: params.t_vs }
    }

    /// Decodes `x` relative to the marker centre `target` (SPEC §4):
    /// `d_s = normalize(1, tan ψ, tan φ)`, `p_s = p_t − ρ·R_ws·d_s`,
    /// `p_v = p_s − Rz(ψ_v)·t_vs`.
    #[inline]
    pub fn pose(&self, target: &Point3<f64>, x: &SensorState) -> SensorPose {
        self.pose_from(target, x.rho, &Self::direction(x.psi, x.phi), &self.yaw_frame(x.yaw))
    }

    /// The marker's direction in the sensor frame, `d_s = normalize(1, tan ψ, tan φ)`:
    /// the part of [`SensorRig::pose`] that depends on ψ and φ alone.
    #[inline]
    pub fn direction(psi: f64, phi: f64) -> Vector3<f64> {
        Vector3::new(1.0, psi.tan(), phi.tan()).normalize()
    }

    /// The part of [`SensorRig::pose`] that depends on the yaw alone.
    #[inline]
    pub fn yaw_frame(&self, yaw: f64) -> YawFrame {
        let turn = rot_z(yaw);
        YawFrame { yaw, rotation: turn * self.pitch, offset: turn * self.t_vs }
    }

    /// [`SensorRig::pose`] from its parts, with the same operations in the same
    /// order (so the same bits): a search over a grid computes each part once per
    /// axis value instead of once per candidate.
    #[inline]
    pub fn pose_from(&self, target: &Point3<f64>, rho: f64, direction: &Vector3<f64>, frame: &YawFrame) -> SensorPose {
        let position = target - frame.rotation * direction * rho;
        let viewer_position = position - frame.offset;
        SensorPose { position, rotation: frame.rotation, viewer_position, viewer_yaw: frame.yaw }
    }

    /// The sensor pose of a viewer at `viewer_position` with yaw `viewer_yaw` (the
    /// inverse of the last step of [`SensorRig::pose`]).
    pub fn pose_of_viewer(&self, viewer_position: &Point3<f64>, viewer_yaw: f64) -> SensorPose {
        let yaw = rot_z(viewer_yaw);
        SensorPose {
            position: viewer_position + yaw * self.t_vs,
            rotation: yaw * self.pitch,
            viewer_position: *viewer_position,
            viewer_yaw,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoded_pose_sees_the_target_at_x() {
        let params = Params { camera_pitch: 0.6, ..Params::default() };
        let rig = SensorRig::new(&params);
        let target = Point3::new(1.0, -2.0, 0.2);
        for x in [
            SensorState::new(1.0, 0.0, 0.0, 0.0),
            SensorState::new(3.7, 0.5, -0.3, 2.5),
            SensorState::new(6.0, -0.6, 0.37, -3.0),
        ] {
            let pose = rig.pose(&target, &x);
            let q = pose.to_sensor(&target);
            assert!((q.norm() - x.rho).abs() < 1e-12);
            assert!((q.y.atan2(q.x) - x.psi).abs() < 1e-12);
            assert!((q.z.atan2(q.x) - x.phi).abs() < 1e-12);
            let back = rig.pose_of_viewer(&pose.viewer_position, pose.viewer_yaw);
            assert!((back.position - pose.position).norm() < 1e-12);
        }
    }

    /// SPEC §3: quaternions are written with w ≥ 0. The orientation itself carries
    /// that sign, so the wire reply (which copies it) agrees with the JSON answer.
    #[test]
    fn orientation_quaternion_has_the_spec_sign() {
        for pitch in [-1.2, 0.0, 0.6, std::f64::consts::FRAC_PI_2] {
            let rig = SensorRig::new(&Params { camera_pitch: pitch, ..Params::default() });
            for k in 0..72 {
                let yaw = -PI + 2.0 * PI * f64::from(k) / 72.0;
                let pose = rig.pose_of_viewer(&Point3::new(1.0, 2.0, 3.0), yaw);
                let q = pose.quaternion();
                assert!(q.w >= 0.0, "pitch {pitch}, yaw {yaw}: {q:?}");
                assert!((q.to_rotation_matrix().matrix() - pose.rotation).norm() < 1e-14);
                assert_eq!(crate::math::canonical_xyzw(&q), [q.i, q.j, q.k, q.w].map(|v| v + 0.0));
            }
        }
    }

    /// The pose from precomputed parts is SPEC §4's formula evaluated in one go, bit
    /// for bit: a grid search relies on it to give the answers of one candidate at
    /// a time.
    #[test]
    fn pose_from_parts_is_the_pose_bit_for_bit() {
        let bits = |p: &SensorPose| {
            let mut v: Vec<u64> = p.position.iter().chain(p.viewer_position.iter()).map(|x| x.to_bits()).collect();
            v.extend(p.rotation.iter().map(|x| x.to_bits()));
            v.push(p.viewer_yaw.to_bits());
            v
        };
        for params in
            [Params::default(), Params { camera_pitch: -0.3, t_vs: Vector3::new(0.2, -0.1, 0.3), ..Params::default() }]
        {
            let rig = SensorRig::new(&params);
            let space = SearchSpace::new(&params);
            let formula = |target: &Point3<f64>, x: &SensorState| {
                let yaw = rot_z(x.yaw);
                let rotation = yaw * rot_y(params.camera_pitch);
                let d_s = Vector3::new(1.0, x.psi.tan(), x.phi.tan()).normalize();
                let position = target - rotation * d_s * x.rho;
                SensorPose { position, rotation, viewer_position: position - yaw * params.t_vs, viewer_yaw: x.yaw }
            };
            let target = Point3::new(3.7, -8.1, 0.2);
            for i in 0..7 {
                let rho = space.lo[0] + f64::from(i) * (space.hi[0] - space.lo[0]) / 6.0;
                for j in 0..9 {
                    let psi = space.lo[1] + f64::from(j) * (space.hi[1] - space.lo[1]) / 8.0;
                    for k in 0..9 {
                        let phi = space.lo[2] + f64::from(k) * (space.hi[2] - space.lo[2]) / 8.0;
                        let direction = SensorRig::direction(psi, phi);
                        for m in 0..72 {
                            let x = SensorState::new(rho, psi, phi, -PI + 2.0 * PI * f64::from(m) / 72.0);
                            let parts = rig.pose_from(&target, rho, &direction, &rig.yaw_frame(x.yaw));
                            assert_eq!(bits(&parts), bits(&formula(&target, &x)), "{x:?}");
                            assert_eq!(bits(&rig.pose(&target, &x)), bits(&parts));
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn positive_pitch_looks_down() {
        let pose = SensorRig::new(&Params::default()).pose_of_viewer(&Point3::new(0.0, 0.0, 5.0), 0.0);
        let axis = pose.rotation * Vector3::x();
        assert!(axis.z < 0.0 && axis.x > 0.0);
    }

    #[test]
    fn unit_cube_maps_to_the_closed_box() {
        let s = SearchSpace::new(&Params::default());
        assert_eq!(s.from_unit(&[0.0; 4]).to_array(), s.lo);
        let top = s.from_unit(&[1.0; 4]);
        assert_eq!(top.rho, 6.0);
        assert_eq!(top.yaw, -PI); // π reads as −π
        assert!(s.contains(&top));
    }
}
