//! The rover process: the paper's rover state machine (Fig. 2, SPEC §9) over a
//! simulated body.
//!
//! At each step i the rover
//! 1. plans the leg to waypoint i+1 from its estimate ([`controller::plan_leg`]) and
//!    propagates its belief through the plan: the rendezvous belief;
//! 2. sends that belief to the viewer (`mission/<name>/rendezvous`);
//! 3. drives: every tick the true pose moves by the command plus unseen slip
//!    ([`crate::sim::TrueRover`]) while the EKF predicts with the command
//!    ([`ekf::Ekf::predict`]);
//! 4. waits, at most `measurement_timeout` of wall time, for the viewer's
//!    measurement of step i+1; a measurement updates the EKF, anything else — not
//!    observed, late, or a viewer that is gone — leaves it dead-reckoning, and the
//!    log says which;
//! 5. repeats until the goal, then tells the viewer it has finished (and waits,
//!    at most `linger`, for any evaluation to acknowledge its last sample).
//!
//! The simulation half publishes the true pose on `sim/<name>/truth` (read only by
//! the simulated camera and the evaluation) and the robot half its estimate on
//! `mission/<name>/estimate`, with matching sample numbers.
//!
//! ```no_run
//! use dyfos_client::mission::{Mission, topics::TopicsConfig};
//! use dyfos_client::rover::{RoverConfig, run_rover};
//!
//! let topics = TopicsConfig { prefix: "dyfos/".into(), domain: None, mission: "demo".into() };
//! let config = RoverConfig::new(topics, Mission::builtin(), 1);
//! let report = run_rover(&config, &|| false)?;
//! println!("{} of {} rendezvous measured", report.measured, report.steps);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod controller;
pub mod ekf;

use crate::mission::Mission;
use crate::mission::log::EventLog;
use crate::mission::topics::{Inbox, Outbox, TopicOpenError, TopicSendError, Topics, TopicsConfig};
use crate::sim::{SimClock, TrueRover, standard_normal, stream_seed, streams};
use controller::{DriveConfig, plan_leg};
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::mission::{
    ESTIMATE_TOPIC, EVALUATION_TOPIC, Estimate, EstimateMsg, EvaluationAckMsg, MEASUREMENT_TOPIC, Measurement,
    MeasurementMsg, Observation, Phase, RENDEZVOUS_TOPIC, RendezvousState, RendezvousStateMsg, TRUTH_TOPIC, TrueState,
    TrueStateMsg,
};
use ekf::Ekf;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde_json::json;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How the rover runs.
#[derive(Debug, Clone)]
pub struct RoverConfig {
    /// Where the mission's topics live.
    pub topics: TopicsConfig,
    /// The mission.
    pub mission: Mission,
    /// Seed of the run: true start and slip.
    pub seed: u64,
    /// Simulated seconds per wall second; `None` runs as fast as possible.
    pub time_scale: Option<f64>,
    /// Longest wait for a measurement at a waypoint, wall time.
    pub measurement_timeout: Duration,
    /// Longest wait at the start for a viewer to listen, wall time.
    pub viewer_timeout: Duration,
    /// Drive without a viewer: no rendezvous, no measurements (the baseline).
    pub dead_reckoning: bool,
    /// Drive limits.
    pub drive: DriveConfig,
    /// Publish a truth/estimate sample every this many ticks (and at each waypoint).
    pub sample_every: u32,
    /// JSON-lines event log.
    pub events: Option<PathBuf>,
    /// At the goal, how long to wait for the evaluation (estimate readers, if any)
    /// to acknowledge the last sample before exiting, wall time.
    pub linger: Duration,
}

impl RoverConfig {
    /// Defaults: paced 20× real time, 10 s measurement and viewer timeouts, a
    /// sample every 5 ticks (4 Hz of simulated time).
    pub fn new(topics: TopicsConfig, mission: Mission, seed: u64) -> Self {
        RoverConfig {
            topics,
            mission,
            seed,
            time_scale: Some(20.0),
            measurement_timeout: Duration::from_secs(10),
            viewer_timeout: Duration::from_secs(10),
            dead_reckoning: false,
            drive: DriveConfig::default(),
            sample_every: 5,
            events: None,
            linger: Duration::from_secs(5),
        }
    }
}

/// Why the rover could not run its mission.
#[derive(Debug, thiserror::Error)]
pub enum RoverRunError {
    /// A topic could not be opened.
    #[error(transparent)]
    Open(#[from] TopicOpenError),
    /// A message could not be sent.
    #[error(transparent)]
    Send(#[from] TopicSendError),
    /// The event log could not be created.
    #[error("cannot create the event log: {0}")]
    Log(#[from] std::io::Error),
    /// No viewer listened in time.
    #[error(
        "no viewer listens on `{topic}` after {waited:?}; start `dyfos-viewer` with the same --prefix and --mission-name, or pass --dead-reckoning"
    )]
    NoViewer {
        /// The rendezvous topic.
        topic: String,
        /// How long the rover waited.
        waited: Duration,
    },
    /// SIGINT or SIGTERM arrived.
    #[error("stopped by a signal at step {step}")]
    Stopped {
        /// The step the rover was on.
        step: u32,
    },
}

/// What the mission came to, as the rover knows it.
#[derive(Debug, Clone, PartialEq)]
pub struct RoverReport {
    /// Waypoints reached (the goal is the last).
    pub steps: u32,
    /// Rendezvous with a measurement used in an update.
    pub measured: u32,
    /// Rendezvous without one (not observed, late, viewer gone).
    pub missed: u32,
    /// The belief at the goal.
    pub final_belief: Belief,
}

/// The rover's ports.
struct Ports {
    topics: Topics,
    rendezvous: Outbox<RendezvousStateMsg>,
    measurement: Inbox<MeasurementMsg>,
    estimate: Outbox<EstimateMsg>,
    truth: Outbox<TrueStateMsg>,
    ack: Inbox<EvaluationAckMsg>,
}

/// The running state.
struct Run<'a> {
    config: &'a RoverConfig,
    ports: Ports,
    log: EventLog,
    clock: SimClock,
    truth: TrueRover,
    ekf: Ekf,
    sample: u64,
    sim_time: f64,
}

/// Why a waypoint passed without a measurement.
enum Missed {
    NotObserved(&'static str),
    Timeout,
    ViewerGone,
}

impl Run<'_> {
    fn publish(&mut self, step: u32, phase: Phase, updated: bool) -> Result<(), TopicSendError> {
        let truth = TrueState { sample: self.sample, step, phase, sim_time: self.sim_time, pose: self.truth.pose() };
        let estimate =
            Estimate { sample: self.sample, step, phase, updated, sim_time: self.sim_time, belief: self.ekf.belief() };
        self.ports.truth.send(TrueStateMsg::from(&truth))?;
        self.ports.estimate.send(EstimateMsg::from(&estimate))?;
        self.sample += 1;
        Ok(())
    }

    /// Waits for the measurement of `step`; stale ones are logged and skipped.
    fn await_measurement(&mut self, step: u32, stop: &impl Fn() -> bool) -> Result<Measurement, Missed> {
        let start = Instant::now();
        let timeout = self.config.measurement_timeout;
        loop {
            let left = timeout.saturating_sub(start.elapsed());
            // Take what arrives within 200 ms; only then ask whether the viewer lives,
            // so that a measurement sent just before it died is still used.
            let mut msg = self.ports.measurement.recv_timeout(left.min(Duration::from_millis(200)), stop);
            if msg.is_none() {
                if stop() || start.elapsed() >= timeout {
                    return Err(Missed::Timeout);
                }
                self.ports.topics.cleanup_dead_nodes();
                if self.ports.measurement.writers() == 0 && self.ports.rendezvous.readers() == 0 {
                    msg = self.ports.measurement.try_recv();
                    if msg.is_none() {
                        return Err(Missed::ViewerGone);
                    }
                }
            }
            let Some(msg) = msg else { continue };
            match Measurement::try_from(&msg) {
                Ok(m) if m.step == step => return Ok(m),
                Ok(m) => self.log.record("measurement_stale", self.sim_time, json!({"step": step, "for_step": m.step})),
                Err(e) => {
                    tracing::warn!("ignoring a malformed measurement: {e}");
                    self.log.record(
                        "measurement_malformed",
                        self.sim_time,
                        json!({"step": step, "error": e.to_string()}),
                    );
                }
            }
        }
    }
}

/// The true start: the mission's, or a draw from the initial belief.
fn true_start(mission: &Mission, seed: u64) -> [f64; 3] {
    if let Some(s) = mission.true_start {
        return s;
    }
    let b = &mission.initial_belief;
    let l = b.cov.matrix().cholesky().map(|c| c.l()).unwrap_or_else(nalgebra::Matrix3::zeros);
    let mut rng = ChaCha8Rng::seed_from_u64(stream_seed(seed, streams::START, 0));
    let n = nalgebra::Vector3::new(standard_normal(&mut rng), standard_normal(&mut rng), standard_normal(&mut rng));
    let s = b.mean + l * n;
    [s.x, s.y, dyfos_shared::math::wrap_angle(s.z)]
}

/// Runs the mission to the goal. `stop` is polled (e.g. [`crate::shutdown::requested`]).
pub fn run_rover(config: &RoverConfig, stop: &impl Fn() -> bool) -> Result<RoverReport, RoverRunError> {
    let topics = Topics::open(&config.topics)?;
    let ports = Ports {
        rendezvous: topics.outbox(MISSION, RENDEZVOUS_TOPIC)?,
        measurement: topics.inbox(MISSION, MEASUREMENT_TOPIC, 64)?,
        estimate: topics.outbox(MISSION, ESTIMATE_TOPIC)?,
        truth: topics.outbox(SIM, TRUTH_TOPIC)?,
        ack: topics.inbox(MISSION, EVALUATION_TOPIC, 16)?,
        topics,
    };
    let log = EventLog::create(config.events.as_deref(), "rover")?;
    let mission = &config.mission;
    let start = true_start(mission, config.seed);
    let mut run = Run {
        config,
        log,
        clock: SimClock::new(config.time_scale),
        truth: TrueRover::new(start, mission.odometry, stream_seed(config.seed, streams::SLIP, 0)),
        ekf: Ekf::new(&mission.initial_belief),
        sample: 0,
        sim_time: 0.0,
        ports,
    };

    if !config.dead_reckoning {
        let waited = Instant::now();
        while run.ports.rendezvous.readers() == 0 {
            if stop() {
                return Err(RoverRunError::Stopped { step: 0 });
            }
            if waited.elapsed() > config.viewer_timeout {
                return Err(RoverRunError::NoViewer {
                    topic: run.ports.rendezvous.name().to_string(),
                    waited: config.viewer_timeout,
                });
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
    run.log.record(
        "start",
        0.0,
        json!({"waypoints": mission.waypoints.len(), "seed": config.seed, "dead_reckoning": config.dead_reckoning,
               "belief": run.ekf.mean()}),
    );
    tracing::info!(
        waypoints = mission.waypoints.len(),
        dead_reckoning = config.dead_reckoning,
        "rover starting at {:?} (believed {:?})",
        start,
        run.ekf.mean()
    );
    run.publish(0, Phase::AtWaypoint, false)?;

    let (mut measured, mut missed) = (0, 0);
    let dt = config.drive.dt;
    for (i, goal) in mission.waypoints.iter().enumerate() {
        let step = i as u32 + 1;
        let plan = plan_leg(run.ekf.mean(), *goal, &config.drive);
        let mut predicted = run.ekf.clone();
        for m in &plan {
            predicted.predict(m, &mission.odometry);
        }
        let rendezvous = predicted.belief();
        if !config.dead_reckoning {
            let msg = RendezvousState::Rendezvous { step, sim_time: run.sim_time, belief: rendezvous };
            let readers = run.ports.rendezvous.send(RendezvousStateMsg::from(&msg))?;
            run.log.record(
                "rendezvous_sent",
                run.sim_time,
                json!({"step": step, "mean": rendezvous.mean.as_slice(), "cov": rendezvous.cov.to_rows(), "readers": readers}),
            );
        }
        for (k, m) in plan.iter().enumerate() {
            run.truth.drive(m);
            run.ekf.predict(m, &mission.odometry);
            run.sim_time += dt;
            if !run.clock.advance_to(run.sim_time, stop) {
                return Err(RoverRunError::Stopped { step });
            }
            if (k + 1) % config.sample_every.max(1) as usize == 0 && k + 1 < plan.len() {
                run.publish(step, Phase::Driving, false)?;
            }
        }
        debug_assert_eq!(run.ekf, predicted, "the plan predicts the arrival belief exactly");
        run.publish(step, Phase::AtWaypoint, false)?;
        run.log.record("arrived", run.sim_time, json!({"step": step, "belief": run.ekf.mean()}));

        let outcome = if config.dead_reckoning {
            Err(Missed::NotObserved("dead_reckoning"))
        } else {
            run.await_measurement(step, stop)
        };
        if stop() {
            return Err(RoverRunError::Stopped { step });
        }
        run.clock.catch_up();
        run.sim_time = run.sim_time.max(run.clock.now());
        let reason = match outcome {
            Ok(m) => match m.observation {
                Observation::Observed { position, r } => match run.ekf.update(position, &r) {
                    Ok(innovation) => {
                        measured += 1;
                        run.log.record(
                            "updated",
                            run.sim_time,
                            json!({"step": step, "z": position, "R": r.to_rows(), "residual": innovation.residual,
                                   "mahalanobis2": innovation.mahalanobis2, "belief": run.ekf.mean()}),
                        );
                        tracing::info!(step, "measured: residual {:?}", innovation.residual);
                        None
                    }
                    Err(e) => Some(format!("update_failed: {e}")),
                },
                Observation::NotObserved(why) => Some(format!("not_observed: {}", why.name())),
            },
            Err(Missed::NotObserved(why)) => Some(why.to_string()),
            Err(Missed::Timeout) => Some(format!("no measurement within {:?}", config.measurement_timeout)),
            Err(Missed::ViewerGone) => Some("viewer gone".to_string()),
        };
        let updated = reason.is_none();
        if let Some(reason) = reason {
            missed += 1;
            run.log.record("dead_reckoning", run.sim_time, json!({"step": step, "reason": reason}));
            if !config.dead_reckoning {
                tracing::warn!(step, "no measurement ({reason}); dead-reckoning");
            }
        }
        let last = step as usize == mission.waypoints.len();
        run.publish(step, if last { Phase::Finished } else { Phase::AtWaypoint }, updated)?;
    }
    let steps = mission.waypoints.len() as u32;
    if !config.dead_reckoning {
        run.ports
            .rendezvous
            .send(RendezvousStateMsg::from(&RendezvousState::Finished { step: steps, sim_time: run.sim_time }))?;
    }
    linger(&run, config.linger, stop);
    run.log.record(
        "finished",
        run.sim_time,
        json!({"steps": steps, "measured": measured, "missed": missed, "belief": run.ekf.mean()}),
    );
    tracing::info!(steps, measured, missed, "rover reached the goal");
    Ok(RoverReport { steps, measured, missed, final_belief: run.ekf.belief() })
}

/// Waits up to `limit` for every evaluation listening to the estimates (each one
/// acknowledges once) to confirm it holds the last sample: a reader that had not
/// yet connected when the rover's ports closed would lose the samples.
fn linger(run: &Run, limit: Duration, stop: &impl Fn() -> bool) {
    let last = run.sample.saturating_sub(1);
    let start = Instant::now();
    let mut acks = 0;
    while run.ports.estimate.readers() > acks {
        let left = limit.saturating_sub(start.elapsed());
        if left.is_zero() || stop() {
            tracing::warn!("an evaluation did not acknowledge the last sample within {limit:?}");
            return;
        }
        if run.ports.ack.recv_timeout(left, stop).is_some_and(|a| a.sample >= last) {
            acks += 1;
        }
    }
}

/// Topic group of the robots' own topics.
pub(crate) const MISSION: &str = "mission";
/// Topic group of simulation-only topics.
pub(crate) const SIM: &str = "sim";
