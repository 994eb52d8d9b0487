//! The localization uncertainty prediction pipeline (LUPP): one candidate sensor
//! state in, its feasibility and predicted posterior cost out.
//!
//! For a candidate x the pipeline decodes the sensor and viewer poses (SPEC §4),
//! checks the workspace, collision and occlusion constraints in that order, stopping
//! at the first failure (SPEC §5), predicts the measurement noise R with the SDSMM
//! (SPEC §6) and scores `E = ln det Σ⁺` (SPEC §7). [`Lupp::evaluate`] is the
//! search's hot path and allocates nothing; [`Lupp::predict`] reports everything
//! about one candidate for answers and `dyfos eval`.
//!
//! ```
//! use dyfos_service::lupp::{Evaluation, Lupp};
//! use dyfos_shared::prelude::*;
//!
//! let scenario = Scenario::from_json(include_str!("../../tests/data/example.json")).unwrap();
//! let model = NoiseModel::from_params(&scenario.params).unwrap();
//! let lupp = Lupp::new(&scenario.world, &scenario.belief, &scenario.params, &model);
//! match lupp.evaluate(&SensorState::new(2.0, 0.0, 0.0, 0.3)) {
//!     Evaluation::Feasible { cost } => assert!(cost < scenario.belief.cov.matrix().determinant().ln()),
//!     Evaluation::Rejected(why) => panic!("rejected by {why:?}"),
//! }
//! ```

use dyfos_shared::answer::EvalStats;
use dyfos_shared::math::{Cov2, Matrix3, Point3, Vector3};
use dyfos_shared::params::Params;
use dyfos_shared::posterior::{Belief, CostBound, Prior};
use dyfos_shared::sdsmm::{Features, NoiseModel, Sdsmm};
use dyfos_shared::sensor::{SearchSpace, SensorPose, SensorRig, SensorState};
use dyfos_shared::world::{Blocker, Nearby, Segment, SightFan, Star, World};

/// The constraint that rejected a candidate (SPEC §5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Violation {
    /// Viewer outside the map bounds or the altitude limits.
    Workspace,
    /// A collision ray from the viewer touches an obstacle.
    Collision,
    /// A sight line from the sensor to a target point is blocked.
    Occlusion,
}

impl Violation {
    /// The name used in reports: "workspace", "collision", "occlusion".
    pub fn name(self) -> &'static str {
        match self {
            Violation::Workspace => "workspace",
            Violation::Collision => "collision",
            Violation::Occlusion => "occlusion",
        }
    }
}

/// The verdict on one candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Evaluation {
    /// Passed every constraint; `cost` is E = ln det Σ⁺.
    Feasible {
        /// E = ln det Σ⁺.
        cost: f64,
    },
    /// Rejected by the first failing constraint.
    Rejected(Violation),
}

impl Evaluation {
    /// The cost, if feasible.
    #[inline]
    pub fn cost(&self) -> Option<f64> {
        match self {
            Evaluation::Feasible { cost } => Some(*cost),
            Evaluation::Rejected(_) => None,
        }
    }

    /// Counts this verdict into `stats`.
    #[inline]
    pub fn count(&self, stats: &mut EvalStats) {
        stats.total += 1;
        match self {
            Evaluation::Feasible { .. } => {}
            Evaluation::Rejected(Violation::Workspace) => stats.workspace += 1,
            Evaluation::Rejected(Violation::Collision) => stats.collision += 1,
            Evaluation::Rejected(Violation::Occlusion) => stats.occlusion += 1,
        }
    }
}

/// Everything about one candidate, for answers and reports.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// The candidate.
    pub x: SensorState,
    /// Its sensor and viewer poses.
    pub pose: SensorPose,
    /// The verdict.
    pub evaluation: Evaluation,
    /// What blocked it (empty when feasible or rejected by the workspace).
    pub blockers: Vec<Blocker>,
    /// SDSMM features (computed whether feasible or not).
    pub features: Features,
    /// Predicted measurement noise R.
    pub r: Cov2,
    /// Predicted posterior Σ⁺ by the full Kalman form.
    pub posterior: Matrix3<f64>,
}

/// What a search that makes poses from parts knows about one before it is
/// evaluated ([`Lupp::evaluate_pose_below`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseFacts {
    /// [`Lupp::in_workspace`] of its viewer.
    pub in_workspace: bool,
    /// `viewer_yaw.sin_cos()`, for its collision star's segments.
    pub turn: (f64, f64),
    /// Whether nothing is near its collision star, as proved by an empty
    /// [`World::nearby_within`] list of a box holding [`Lupp::collision_box`]: the
    /// star is not checked.
    pub collision_clear: bool,
    /// Whether nothing solid is near its sight lines, as proved by e.g.
    /// [`World::box_is_clear`] on a box holding [`Lupp::sight_box`]: they are skipped.
    pub sight_clear: bool,
}

/// The pipeline for one request: world, rendezvous belief, parameters and model,
/// with everything that does not depend on the candidate precomputed.
#[derive(Debug, Clone)]
pub struct Lupp<'a> {
    world: &'a World,
    model: &'a NoiseModel,
    params: Params,
    prior: Prior,
    rig: SensorRig,
    space: SearchSpace,
    sun: Vector3<f64>,
    /// `[tan(f_h/2), tan(f_v/2)]` for the image coordinates.
    half_fov_tangents: [f64; 2],
    /// p_t, then the perimeter points (SPEC §2 order).
    targets: Vec<Point3<f64>>,
    /// The belief's mean heading θ (for the `learned` model's relative bearing).
    heading: f64,
    reach: f64,
    /// The box spanned by `targets`.
    target_box: (Point3<f64>, Point3<f64>),
    /// The obstacles that can block a sight line, by the sensor's azimuth from the marker.
    fan: SightFan,
    /// The obstacles near every collision star of the query.
    nearby: Nearby,
}

impl<'a> Lupp<'a> {
    /// Prepares the pipeline. `params` must be valid (see [`Params::validate`]).
    pub fn new(world: &'a World, belief: &Belief, params: &Params, model: &'a NoiseModel) -> Self {
        debug_assert!(params.validate().is_ok());
        // Here, once per search, not at its first candidate.
        world.build_index();
        let marker = belief.marker(params.marker_height);
        let n = params.perimeter_points;
        let theta = belief.mean.z;
        let mut targets = Vec::with_capacity(n as usize + 1);
        targets.push(marker);
        targets.extend((0..n).map(|k| {
            let a = theta + std::f64::consts::TAU * f64::from(k) / f64::from(n);
            Point3::new(marker.x + params.rover_radius * a.cos(), marker.y + params.rover_radius * a.sin(), marker.z)
        }));
        let target_box = targets.iter().fold((marker, marker), |(lo, hi), q| (lo.inf(q), hi.sup(q)));
        // Sensors lie within ρ_max of the marker; the fan serves them all (a sensor
        // beyond, by rounding, is answered by the BVH, the same verdict).
        let fan = world.sight_fan(&marker, params.rover_radius, params.rho_max * (1.0 + 1e-9));
        // Viewers lie within ρ_max + |t_vs| of the marker, their stars `reach` around
        // them (a star outside the region, by rounding, is answered by the BVH).
        let reach = params.viewer_radius + params.safety_margin;
        let around = Vector3::repeat((params.rho_max + params.t_vs.norm() + reach) * (1.0 + 1e-9));
        let nearby = world.nearby(&(marker - around), &(marker + around));
        Lupp {
            world,
            model,
            params: *params,
            prior: Prior::new(&belief.cov),
            rig: SensorRig::new(params),
            space: SearchSpace::new(params),
            sun: world.sun().direction(),
            half_fov_tangents: Features::half_fov_tangents(params),
            targets,
            heading: theta,
            reach,
            target_box,
            fan,
            nearby,
        }
    }

    /// The candidate box.
    pub fn space(&self) -> &SearchSpace {
        &self.space
    }

    /// The world searched.
    pub fn world(&self) -> &World {
        self.world
    }

    /// The marker centre p_t.
    pub fn marker(&self) -> Point3<f64> {
        self.targets[0]
    }

    /// The viewer's camera mounting.
    pub fn rig(&self) -> &SensorRig {
        &self.rig
    }

    /// Feasibility and cost of `x`: the hot path, no allocation.
    #[inline]
    pub fn evaluate(&self, x: &SensorState) -> Evaluation {
        self.evaluate_pose(&self.rig.pose(&self.targets[0], x), &self.nearby, false)
    }

    /// The obstacles near every collision star of the query: a search whose
    /// candidates share a smaller region narrows it for them
    /// ([`World::nearby_within`]).
    pub fn nearby(&self) -> &Nearby {
        &self.nearby
    }

    /// Feasibility and cost of the candidate whose pose is `pose` (from
    /// [`SensorRig::pose`] or its parts), its collision star checked against
    /// `near`: [`Lupp::nearby`], or a list narrowed from it by
    /// [`World::nearby_within`] (any region: a star outside it is answered by the
    /// BVH). `sight_clear` skips the sight lines: the caller must have proved that
    /// nothing solid is near them, e.g. by [`World::box_is_clear`] on a box holding
    /// [`Lupp::sight_box`]. The verdict is [`Lupp::evaluate`]'s, bit for bit.
    #[inline]
    pub fn evaluate_pose(&self, pose: &SensorPose, near: &Nearby, sight_clear: bool) -> Evaluation {
        if let Some(why) = self.first_violation(pose, near, sight_clear) {
            return Evaluation::Rejected(why);
        }
        Evaluation::Feasible { cost: self.prior.cost(&self.noise(pose)) }
    }

    /// [`Lupp::evaluate_pose`] for a search that knows `facts` of the pose and
    /// only wants costs below `bound` ([`Prior::cost_bound`] of [`Lupp::prior`]):
    /// the same verdict, and the same cost bit for bit, but that a feasible
    /// candidate whose cost is sure to be at least the bound reports +∞ (its
    /// logarithms are not taken).
    #[inline]
    pub fn evaluate_pose_below(
        &self,
        pose: &SensorPose,
        facts: &PoseFacts,
        near: &Nearby,
        bound: &CostBound,
    ) -> Evaluation {
        let why = if !facts.in_workspace {
            Some(Violation::Workspace)
        } else if !facts.collision_clear && self.world.star_contact_near_turned(near, &self.star(pose), facts.turn) {
            Some(Violation::Collision)
        } else if self.occluded(pose, facts.sight_clear) {
            Some(Violation::Occlusion)
        } else {
            None
        };
        if let Some(why) = why {
            return Evaluation::Rejected(why);
        }
        Evaluation::Feasible { cost: self.prior.cost_below(&self.noise(pose), bound).unwrap_or(f64::INFINITY) }
    }

    /// The rendezvous prior, with what the cost needs precomputed.
    pub fn prior(&self) -> &Prior {
        &self.prior
    }

    /// Whether a viewer at `p_v` is inside the map bounds and altitude limits (SPEC §5.1).
    #[inline]
    pub fn in_workspace(&self, p_v: &Point3<f64>) -> bool {
        self.world.bounds().contains(p_v.x, p_v.y) && self.params.z_min <= p_v.z && p_v.z <= self.params.z_max
    }

    /// A box holding every collision segment of `pose` (SPEC §5.2): the cube of
    /// half-side `viewer_radius + safety_margin` around the viewer.
    #[inline]
    pub fn collision_box(&self, pose: &SensorPose) -> (Point3<f64>, Point3<f64>) {
        self.star(pose).bounds()
    }

    /// A box holding every sight line of `pose` (SPEC §5.3): the sensor and the targets.
    #[inline]
    pub fn sight_box(&self, pose: &SensorPose) -> (Point3<f64>, Point3<f64>) {
        (self.target_box.0.inf(&pose.position), self.target_box.1.sup(&pose.position))
    }

    #[inline]
    fn noise(&self, pose: &SensorPose) -> Cov2 {
        self.model.noise_at(&self.params, self.half_fov_tangents, &self.sun, pose, &self.targets[0], self.heading)
    }

    /// The SDSMM features of observing the rover from `pose` (SPEC §6), with the
    /// belief's mean heading.
    #[inline]
    pub fn features(&self, pose: &SensorPose) -> Features {
        Features::with_half_fov_tangents(&self.params, self.half_fov_tangents, &self.sun, pose, &self.targets[0])
            .with_rover_heading(self.heading)
    }

    #[inline]
    fn first_violation(&self, pose: &SensorPose, near: &Nearby, sight_clear: bool) -> Option<Violation> {
        if !self.in_workspace(&pose.viewer_position) {
            return Some(Violation::Workspace);
        }
        if self.world.star_contact_near(near, &self.star(pose)) {
            return Some(Violation::Collision);
        }
        self.occluded(pose, sight_clear).then_some(Violation::Occlusion)
    }

    /// Whether a sight line of `pose` is blocked (SPEC §5.3); `sight_clear` as in
    /// [`Lupp::evaluate_pose`].
    #[inline]
    fn occluded(&self, pose: &SensorPose, sight_clear: bool) -> bool {
        if sight_clear {
            return false;
        }
        let (lo, hi) = self.sight_box(pose);
        self.world.any_sight_line_contact(&self.fan, &pose.position, &self.targets, 1e-6, &lo, &hi)
    }

    /// The collision star of `pose` (SPEC §5.2).
    #[inline]
    fn star(&self, pose: &SensorPose) -> Star {
        Star { center: pose.viewer_position, yaw: pose.viewer_yaw, reach: self.reach }
    }

    /// Everything about `x`, listing every blocker of the first failing constraint.
    pub fn predict(&self, x: &SensorState) -> Prediction {
        let pose = self.rig.pose(&self.targets[0], x);
        let evaluation = self.evaluate(x);
        let blockers = match evaluation {
            Evaluation::Rejected(Violation::Collision) => self.blockers(&self.star(&pose).segments()),
            Evaluation::Rejected(Violation::Occlusion) => {
                let sights: Vec<Segment> =
                    self.targets.iter().filter_map(|q| Segment::sight_line(&pose.position, q, 1e-6)).collect();
                self.blockers(&sights)
            }
            _ => Vec::new(),
        };
        let features = self.features(&pose);
        let r = self.model.noise(&features);
        Prediction { x: *x, pose, evaluation, blockers, features, r, posterior: self.prior.posterior(&r) }
    }

    fn blockers(&self, segments: &[Segment]) -> Vec<Blocker> {
        let mut all: Vec<Blocker> = segments.iter().flat_map(|s| self.world.contacts(s)).map(|(b, _)| b).collect();
        all.sort();
        all.dedup();
        all
    }
}
