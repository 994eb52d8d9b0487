//! The viewer's simulated camera: does it see the rover's marker, and what does it
//! measure (SPEC §9).

use super::standard_normal;
use dyfos_shared::math::{Cov2, Point3, Vector2};
use dyfos_shared::params::Params;
use dyfos_shared::sdsmm::{Features, NoiseModel, Sdsmm};
use dyfos_shared::sensor::SensorRig;
use dyfos_shared::world::{Segment, World};
use rand_chacha::ChaCha8Rng;

/// What one look at the rover gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CameraView {
    /// The marker was detected: the measured (x, y) and the noise covariance R the
    /// SDSMM estimates from the true states.
    Seen {
        /// Measured rover (x, y), m.
        position: [f64; 2],
        /// R, m².
        r: Cov2,
        /// The features R was estimated from.
        features: Features,
    },
    /// Part of the marker is outside the field of view (or behind the camera).
    OutOfView,
    /// The marker is nearer than ρ_min or farther than ρ_max.
    OutOfRange,
    /// An obstacle blocks the line of sight to part of the marker.
    Occluded,
}

/// A camera on the viewer, looking at the rover's true pose.
///
/// The marker is detected when its centre and its four corners (side
/// `marker_size`, flat at `marker_height`, turned with the rover) are all inside
/// the field of view, the centre is within `[ρ_min, ρ_max]`, and no obstacle
/// touches the sight line from the sensor to any of the five points (SPEC §5.3's
/// open-ended segments). The SPEC's perimeter points are a *prediction* margin
/// for the search; what the camera needs in reality is the marker. Then the
/// measurement is drawn from `N(true (x, y), R)` with `R` the SDSMM of the true
/// sensor pose, true marker position and sun: the SDSMM's *estimate* (SPEC §9).
#[derive(Debug, Clone)]
pub struct SimCamera {
    params: Params,
    model: NoiseModel,
    rig: SensorRig,
}

impl SimCamera {
    /// A camera with the mission's parameters and noise model.
    pub fn new(params: &Params, model: NoiseModel) -> Self {
        SimCamera { params: *params, model, rig: SensorRig::new(params) }
    }

    /// Looks from the viewer at `viewer_position` with yaw `viewer_yaw` at the rover's
    /// true pose `rover`, in `world`; noise is drawn from `rng`.
    pub fn observe(
        &self,
        world: &World,
        viewer_position: [f64; 3],
        viewer_yaw: f64,
        rover: [f64; 3],
        rng: &mut ChaCha8Rng,
    ) -> CameraView {
        let p = &self.params;
        let pose = self.rig.pose_of_viewer(&Point3::from(viewer_position), viewer_yaw);
        let centre = Point3::new(rover[0], rover[1], p.marker_height);
        let (s, c) = rover[2].sin_cos();
        let h = p.marker_size / 2.0;
        let corner = |a: f64, b: f64| Point3::new(rover[0] + a * c - b * s, rover[1] + a * s + b * c, p.marker_height);
        let points = [centre, corner(h, h), corner(-h, h), corner(-h, -h), corner(h, -h)];
        let (tan_h, tan_v) = ((p.f_h / 2.0).tan(), (p.f_v / 2.0).tan());
        let in_view = points.iter().all(|q| {
            let q = pose.to_sensor(q);
            q.x > 0.0 && (q.y / q.x).abs() <= tan_h && (q.z / q.x).abs() <= tan_v
        });
        if !in_view {
            return CameraView::OutOfView;
        }
        let rho = (centre - pose.position).norm();
        if !(p.rho_min..=p.rho_max).contains(&rho) {
            return CameraView::OutOfRange;
        }
        let mut sight = [Segment::closed(pose.position, nalgebra::Vector3::x(), 0.0); 5];
        for (seg, q) in sight.iter_mut().zip(&points) {
            match Segment::sight_line(&pose.position, q, 1e-6) {
                Some(s) => *seg = s,
                None => return CameraView::OutOfRange,
            }
        }
        if world.any_contact(&sight) {
            return CameraView::Occluded;
        }
        let features = Features::new(p, &world.sun().direction(), &pose, &centre).with_rover_heading(rover[2]);
        let r = self.model.noise(&features);
        let position = match r.matrix().cholesky() {
            Some(ch) => {
                let n = Vector2::new(standard_normal(rng), standard_normal(rng));
                let e = ch.l() * n;
                [rover[0] + e.x, rover[1] + e.y]
            }
            // An SDSMM always returns an SPD R; keep the truth if it ever does not.
            None => [rover[0], rover[1]],
        };
        CameraView::Seen { position, r, features }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::sdsmm::Paper;
    use dyfos_shared::sensor::SensorState;
    use dyfos_shared::world::{Bounds, MapDelta, Obstacle, Sun, VerticalCylinder};
    use nalgebra::Point2;
    use rand::SeedableRng;

    fn world(with_pole: bool) -> World {
        let w = World::empty(Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.6, 2.4).unwrap());
        if !with_pole {
            return w;
        }
        let pole = Obstacle::Cylinder(VerticalCylinder { center: Point2::new(-1.0, 0.0), radius: 0.3, height: 10.0 });
        w.apply(&[MapDelta::UpsertObstacle { id: 1, obstacle: pole }]).unwrap()
    }

    #[test]
    fn sees_what_the_search_space_promises_and_nothing_else() {
        let params = Params::default();
        let cam = SimCamera::new(&params, NoiseModel::Paper(Paper));
        let rig = SensorRig::new(&params);
        let rover = [0.0, 0.0, 0.4];
        let target = Point3::new(0.0, 0.0, params.marker_height);
        // Rover in the image centre, 2.5 m away, viewer looking along +x.
        let pose = rig.pose(&target, &SensorState::new(2.5, 0.0, 0.0, 0.0));
        let vp: [f64; 3] = pose.viewer_position.coords.into();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let seen = cam.observe(&world(false), vp, 0.0, rover, &mut rng);
        let CameraView::Seen { position, r, features } = seen else { panic!("{seen:?}") };
        assert!(features.e < 1e-9 && (features.rho - 2.5).abs() < 1e-9);
        assert!((r.matrix()[(0, 0)] - dyfos_shared::sdsmm::paper_variance(&features)).abs() < 1e-15);
        assert!((position[0] - rover[0]).hypot(position[1] - rover[1]) < 5.0 * r.matrix()[(0, 0)].sqrt());
        // The same pose with a pole between them.
        assert_eq!(cam.observe(&world(true), vp, 0.0, rover, &mut rng), CameraView::Occluded);
        // Looking away.
        assert_eq!(cam.observe(&world(false), vp, 2.0, rover, &mut rng), CameraView::OutOfView);
        // Too far.
        let far = rig.pose(&target, &SensorState::new(6.5, 0.0, 0.0, 0.0));
        let fp: [f64; 3] = far.viewer_position.coords.into();
        assert_eq!(cam.observe(&world(false), fp, 0.0, rover, &mut rng), CameraView::OutOfRange);
    }

    #[test]
    fn measurements_scatter_with_r() {
        let params = Params::default();
        let cam = SimCamera::new(&params, NoiseModel::Paper(Paper));
        let rig = SensorRig::new(&params);
        let target = Point3::new(1.0, 2.0, params.marker_height);
        // Off-centre and far, so R is large enough to measure.
        let pose = rig.pose(&target, &SensorState::new(5.0, 0.4, 0.2, 1.0));
        let vp: [f64; 3] = pose.viewer_position.coords.into();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut sx, mut sxx, n) = (0.0, 0.0, 4000);
        let mut var = 0.0;
        for _ in 0..n {
            let CameraView::Seen { position, r, .. } = cam.observe(&world(false), vp, 1.0, [1.0, 2.0, 0.0], &mut rng)
            else {
                panic!("not seen")
            };
            var = r.matrix()[(0, 0)];
            sx += position[0] - 1.0;
            sxx += (position[0] - 1.0).powi(2);
        }
        let mean = sx / n as f64;
        let v = sxx / n as f64 - mean * mean;
        assert!(mean.abs() < 4.0 * (var / n as f64).sqrt(), "mean error {mean}");
        assert!((v / var - 1.0).abs() < 0.1, "variance {v} vs R {var}");
    }
}
