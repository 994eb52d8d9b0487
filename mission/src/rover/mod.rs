//! The rover process: the paper's rover state machine (Fig. 2, SPEC §9) over a
//! simulated body.
//!
//! At each step i the rover
//! 1. plans the leg to waypoint i+1 from its estimate ([`controller::plan_leg`]) and
//!    propagates its belief through the plan: the rendezvous belief;
//! 2. sends that belief to the viewer (`mission/<name>/rendezvous`), and again
//!    every [`RESEND_INTERVAL`] until the viewer acknowledges it;
//! 3. drives: every tick the true pose moves by the command plus unseen slip
//!    ([`crate::sim::TrueRover`]) while the EKF predicts with the command
//!    ([`ekf::Ekf::predict`]);
//! 4. waits, at most `measurement_timeout` of wall time, for the viewer's
//!    measurement of step i+1 (and acknowledges it); a measurement updates the
//!    EKF, anything else — not observed, late, or a viewer that is gone — leaves
//!    it dead-reckoning, and the log says which;
//! 5. repeats until the goal, then tells the viewer it has finished, again every
//!    [`RESEND_INTERVAL`] until the viewer acknowledges it — also while the viewer
//!    counts as gone, since it may come back — and waits for every reader of its
//!    estimates (an evaluation, or the link that carries them to another host) to
//!    acknowledge its last sample; both within [`RoverConfig::linger`] of reaching
//!    the goal.
//!
//! The viewer is present while its heartbeats arrive ([`crate::mission::presence`]);
//! one silent for `presence_timeout` is gone: the rover dead-reckons the steps it
//! misses, keeps re-sending its rendezvous, and resumes with the viewer (or a
//! restarted one) when it comes back. The event log records `viewer_lost` and
//! `viewer_back`.
//!
//! The simulation half publishes the true pose on `sim/<name>/truth` (read only by
//! the simulated camera and the evaluation) and the robot half its estimate on
//! `mission/<name>/estimate`, with matching sample numbers.
//!
//! With [`OutputConfig::mcap`](crate::mission::output::OutputConfig::mcap) of [`RoverConfig::output`] the rover keeps what it knows of the mission — its
//! true and estimated poses, its rendezvous beliefs, the measurements it got (with
//! the viewer's poses) and the APE — as an MCAP file for Foxglove
//! ([`crate::eval::McapMission`]), written when it exits.
//!
//! ```no_run
//! use dyfos_mission::mission::{Mission, topics::TopicsConfig};
//! use dyfos_mission::rover::{RoverConfig, run_rover};
//!
//! let topics = TopicsConfig { prefix: "dyfos/".into(), domain: None, mission: "demo".into() };
//! let config = RoverConfig::new(topics, Mission::builtin(), 1);
//! let report = run_rover(&config, &|| false)?;
//! println!("{} of {} rendezvous measured", report.measured, report.steps);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod controller;
pub mod ekf;

use crate::eval::McapMission;
use crate::mission::Mission;
use crate::mission::failure::RunError;
use crate::mission::log::EventLog;
use crate::mission::output::OutputConfig;
use crate::mission::presence::{Heartbeat, Peer, PresenceChange, Reliable, acknowledge, drain_acks};
use crate::mission::topics::{Inbox, Outbox, TopicSendError, Topics, TopicsConfig};
use crate::sim::{SimClock, TrueRover, standard_normal, stream_seed, streams};
use controller::{DriveConfig, plan_leg};
use dyfos_shared::posterior::Belief;
use dyfos_shared::wire::mission::{
    AckKind, AckMsg, ESTIMATE_TOPIC, EVALUATION_TOPIC, Estimate, EstimateMsg, EvaluationAckMsg, MEASUREMENT_TOPIC,
    Measurement, MeasurementMsg, Observation, Phase, RENDEZVOUS_TOPIC, RESEND_INTERVAL, ROVER_ACK_TOPIC,
    ROVER_PRESENCE_TOPIC, RendezvousState, RendezvousStateMsg, TRUTH_TOPIC, TrueState, TrueStateMsg, VIEWER_ACK_TOPIC,
    VIEWER_PRESENCE_TOPIC,
};
use ekf::Ekf;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde_json::json;
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
    /// Longest wait at the start for a viewer's heartbeat, wall time.
    pub viewer_timeout: Duration,
    /// A viewer without a heartbeat for this long is gone, wall time.
    pub presence_timeout: Duration,
    /// Drive without a viewer: no rendezvous, no measurements (the baseline).
    pub dead_reckoning: bool,
    /// Drive limits.
    pub drive: DriveConfig,
    /// Publish a truth/estimate sample every this many ticks (and at each waypoint).
    pub sample_every: u32,
    /// The event log and the MCAP file of the mission as the rover knows it.
    pub output: OutputConfig,
    /// At the goal, how long at most to keep offering the finish to a viewer that
    /// has not acknowledged it, and to wait for the readers of the estimates (if
    /// any) to acknowledge the last sample, wall time. As long as a viewer waits
    /// for a silent rover by default (its `rover_timeout`), so that a viewer still
    /// waiting when the link comes back hears the finish.
    pub linger: Duration,
}

impl RoverConfig {
    /// Defaults: paced 20× real time, 10 s measurement and viewer timeouts, a
    /// viewer silent for 2 s is gone, a sample every 5 ticks (4 Hz of simulated
    /// time), a linger of [`LINGER`].
    pub fn new(topics: TopicsConfig, mission: Mission, seed: u64) -> Self {
        RoverConfig {
            topics,
            mission,
            seed,
            time_scale: Some(20.0),
            measurement_timeout: Duration::from_secs(10),
            viewer_timeout: Duration::from_secs(10),
            presence_timeout: Duration::from_secs(2),
            dead_reckoning: false,
            drive: DriveConfig::default(),
            sample_every: 5,
            output: OutputConfig::default(),
            linger: LINGER,
        }
    }
}

/// The default [`RoverConfig::linger`]: the viewer's default `rover_timeout`.
pub const LINGER: Duration = Duration::from_secs(20);

/// Why the rover could not run its mission.
pub type RoverRunError = RunError<RoverFailure>;

/// What only the rover fails at.
#[derive(Debug, thiserror::Error)]
pub enum RoverFailure {
    /// No viewer's heartbeat arrived in time.
    #[error(
        "no viewer's heartbeat on `{topic}` after {waited:?}; start `dyfos-viewer` with the same --prefix and --mission-name (and, across hosts, `dyfos-link` on both), or pass --dead-reckoning"
    )]
    NoViewer {
        /// The viewer's heartbeat topic.
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

impl From<RoverFailure> for RoverRunError {
    fn from(failure: RoverFailure) -> Self {
        RunError::Side(failure)
    }
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
    /// Mission messages the rover sent to the viewer: rendezvous and finish, their
    /// repeats, and acknowledgements (heartbeats and simulation samples not counted).
    pub messages_sent: u32,
}

/// The rover's ports.
struct Ports {
    _topics: Topics,
    rendezvous: Outbox<RendezvousStateMsg>,
    measurement: Inbox<MeasurementMsg>,
    estimate: Outbox<EstimateMsg>,
    truth: Outbox<TrueStateMsg>,
    ack: Inbox<EvaluationAckMsg>,
    viewer: Peer,
    viewer_acks: Inbox<AckMsg>,
    acks: Outbox<AckMsg>,
    heartbeat: Heartbeat,
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
    /// The rendezvous (or finish) not yet known to be acknowledged.
    pending: Option<Reliable<RendezvousStateMsg>>,
    /// Steps whose measurement has been used or given up on.
    done: u32,
    messages_sent: u32,
    /// Whether presence changes go to the event log (not after the finish).
    log_presence: bool,
    /// The mission file being recorded, if asked for.
    mcap: &'a mut Option<McapMission>,
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
        if let Some(mcap) = self.mcap.as_mut() {
            mcap.record_truth(&truth);
            mcap.record_estimate(&estimate);
        }
        self.sample += 1;
        Ok(())
    }

    /// Keeps the link with the viewer: takes in heartbeats and acknowledgements,
    /// logs presence changes, re-sends what is not acknowledged, acknowledges late
    /// duplicates of measurements already dealt with.
    fn service(&mut self) -> Result<(), TopicSendError> {
        if let Some(change) = self.ports.viewer.poll()
            && self.log_presence
        {
            match change {
                PresenceChange::Appeared { .. } => {}
                PresenceChange::Lost => {
                    tracing::warn!("the viewer's heartbeat stopped");
                    self.log.record("viewer_lost", self.sim_time, json!({"step": self.done + 1}));
                }
                PresenceChange::Returned { instance, silent } => {
                    tracing::info!("the viewer is back after {silent:?}");
                    self.log.record(
                        "viewer_back",
                        self.sim_time,
                        json!({"step": self.done + 1, "instance": instance, "silent_s": silent.as_secs_f64()}),
                    );
                }
                PresenceChange::Restarted { instance } => {
                    tracing::info!("the viewer restarted");
                    self.log.record("viewer_back", self.sim_time, json!({"step": self.done + 1, "instance": instance}));
                }
            }
        }
        let acks = drain_acks(&self.ports.viewer_acks);
        if let Some(p) = self.pending.as_mut() {
            for a in &acks {
                p.ack(a);
            }
            if p.service(&self.ports.rendezvous, self.ports.viewer.instance())? {
                self.messages_sent += 1;
                tracing::debug!(step = p.step(), "rendezvous sent again");
            }
        }
        Ok(())
    }

    /// Sends `state` reliably (replacing what was pending); returns how many readers got it.
    fn send_reliably(&mut self, state: &RendezvousState) -> Result<usize, TopicSendError> {
        let (step, kind) = match state {
            RendezvousState::Rendezvous { step, .. } => (*step, AckKind::Rendezvous),
            RendezvousState::Finished { step, .. } => (*step, AckKind::Finished),
        };
        let (pending, readers) = Reliable::send(&self.ports.rendezvous, RendezvousStateMsg::from(state), step, kind)?;
        self.pending = Some(pending);
        self.messages_sent += 1;
        Ok(readers)
    }

    fn acknowledge(&mut self, step: u32) {
        if acknowledge(&self.ports.acks, self.ports.heartbeat.instance(), step, AckKind::Measurement) {
            self.messages_sent += 1;
        }
    }

    /// Waits for the measurement of `step`. Each measurement received is
    /// acknowledged; repeats of earlier steps are dropped.
    fn await_measurement(&mut self, step: u32, stop: &impl Fn() -> bool) -> Result<Measurement, Missed> {
        let start = Instant::now();
        let timeout = self.config.measurement_timeout;
        loop {
            if self.service().is_err() {
                tracing::warn!(step, "cannot re-send the rendezvous");
            }
            let left = timeout.saturating_sub(start.elapsed());
            // Take what arrives within a resend interval; only then ask whether the
            // viewer lives, so that a measurement sent just before it died is used.
            let mut msg = self.ports.measurement.recv_timeout(left.min(RESEND_INTERVAL), stop);
            if msg.is_none() {
                if stop() || start.elapsed() >= timeout {
                    return Err(Missed::Timeout);
                }
                if !self.ports.viewer.present() {
                    msg = self.ports.measurement.try_recv();
                    if msg.is_none() {
                        return Err(Missed::ViewerGone);
                    }
                }
            }
            let Some(msg) = msg else { continue };
            match Measurement::try_from(&msg) {
                Ok(m) if m.step == step => {
                    self.acknowledge(m.step);
                    return Ok(m);
                }
                Ok(m) if m.step < step => {
                    // A repeat of a step already dealt with: the viewer missed our
                    // acknowledgement.
                    self.acknowledge(m.step);
                    tracing::debug!(step, for_step = m.step, "repeated measurement");
                }
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

/// Runs the mission to the goal, then writes [`OutputConfig::mcap`](crate::mission::output::OutputConfig::mcap) of [`RoverConfig::output`] if asked for.
/// `stop` is polled (e.g. [`dyfos_process::shutdown::requested`]).
pub fn run_rover(config: &RoverConfig, stop: &impl Fn() -> bool) -> Result<RoverReport, RoverRunError> {
    config.output.around(&config.mission, |mcap| drive(config, stop, mcap))
}

fn drive(
    config: &RoverConfig,
    stop: &impl Fn() -> bool,
    mcap: &mut Option<McapMission>,
) -> Result<RoverReport, RoverRunError> {
    let topics = Topics::open(&config.topics)?;
    let ports = Ports {
        viewer: Peer::open(&topics, VIEWER_PRESENCE_TOPIC, config.presence_timeout)?,
        viewer_acks: topics.inbox(MISSION, VIEWER_ACK_TOPIC, 256)?,
        acks: topics.outbox(MISSION, ROVER_ACK_TOPIC)?,
        heartbeat: Heartbeat::start(&config.topics, ROVER_PRESENCE_TOPIC)?,
        rendezvous: topics.outbox(MISSION, RENDEZVOUS_TOPIC)?,
        measurement: topics.inbox(MISSION, MEASUREMENT_TOPIC, 64)?,
        estimate: topics.outbox(MISSION, ESTIMATE_TOPIC)?,
        truth: topics.outbox(SIM, TRUTH_TOPIC)?,
        ack: topics.inbox(MISSION, EVALUATION_TOPIC, 16)?,
        _topics: topics,
    };
    let log = config.output.event_log("rover")?;
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
        pending: None,
        done: 0,
        messages_sent: 0,
        log_presence: true,
        mcap,
        ports,
    };

    if !config.dead_reckoning {
        let waited = Instant::now();
        loop {
            run.ports.viewer.poll();
            if run.ports.viewer.present() {
                break;
            }
            if stop() {
                return Err(RoverFailure::Stopped { step: 0 }.into());
            }
            if waited.elapsed() > config.viewer_timeout {
                return Err(RoverFailure::NoViewer {
                    topic: topic_name(&config.topics, VIEWER_PRESENCE_TOPIC),
                    waited: config.viewer_timeout,
                }
                .into());
            }
            run.ports.viewer.wait(Duration::from_millis(10));
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
        run.ports.heartbeat.set_step(step);
        let plan = plan_leg(run.ekf.mean(), *goal, &config.drive);
        let mut predicted = run.ekf.clone();
        for m in &plan {
            predicted.predict(m, &mission.odometry);
        }
        let rendezvous = predicted.belief();
        if !config.dead_reckoning {
            let msg = RendezvousState::Rendezvous { step, sim_time: run.sim_time, belief: rendezvous };
            let readers = run.send_reliably(&msg)?;
            if let Some(mcap) = run.mcap.as_mut() {
                mcap.record_request(step, run.sim_time, &rendezvous);
            }
            run.log.record(
                "rendezvous_sent",
                run.sim_time,
                json!({"step": step, "mean": rendezvous.mean.as_slice(), "cov": rendezvous.cov.to_rows(), "readers": readers}),
            );
        }
        let mut serviced = Instant::now();
        for (k, m) in plan.iter().enumerate() {
            if !config.dead_reckoning && serviced.elapsed() >= RESEND_INTERVAL {
                serviced = Instant::now();
                run.service()?;
            }
            run.truth.drive(m);
            run.ekf.predict(m, &mission.odometry);
            run.sim_time += dt;
            if !run.clock.advance_to(run.sim_time, stop) {
                return Err(RoverFailure::Stopped { step }.into());
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
            return Err(RoverFailure::Stopped { step }.into());
        }
        run.clock.catch_up();
        run.sim_time = run.sim_time.max(run.clock.now());
        if let (Ok(m), Some(mcap)) = (&outcome, run.mcap.as_mut()) {
            mcap.record_measurement(m);
        }
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
        run.done = step;
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
    let deadline = Instant::now() + config.linger;
    if !config.dead_reckoning {
        run.send_reliably(&RendezvousState::Finished { step: steps, sim_time: run.sim_time })?;
        // Until the viewer acknowledges or the linger time is up: a viewer that
        // counts as gone may be back (a link that faded at the goal).
        run.log_presence = false;
        let acked = |run: &Run| run.pending.as_ref().is_some_and(|p| p.acked(run.ports.viewer.instance()));
        while !acked(&run) && Instant::now() < deadline && !stop() {
            run.service()?;
            run.ports.viewer_acks.wait(Duration::from_millis(20));
        }
        if !acked(&run) && !stop() {
            tracing::warn!("the viewer did not acknowledge the finish within {:?}", config.linger);
            run.log.record("finish_unacknowledged", run.sim_time, json!({"step": steps}));
        }
    }
    linger(&run, deadline, stop);
    run.log.record(
        "finished",
        run.sim_time,
        json!({"steps": steps, "measured": measured, "missed": missed, "belief": run.ekf.mean()}),
    );
    tracing::info!(steps, measured, missed, messages = run.messages_sent, "rover reached the goal");
    Ok(RoverReport { steps, measured, missed, final_belief: run.ekf.belief(), messages_sent: run.messages_sent })
}

/// Waits until `deadline` for every reader of the estimates (each one
/// acknowledges once) to confirm it holds the last sample: a reader that had not
/// yet taken the samples when the rover's ports closed would lose them. Across
/// hosts the reader is the link, whose other end acknowledges for the evaluations
/// on its host.
fn linger(run: &Run, deadline: Instant, stop: &impl Fn() -> bool) {
    let last = run.sample.saturating_sub(1);
    let mut acks = 0;
    loop {
        // What arrived already counts, however late it is.
        acks += run.ports.ack.drain().iter().filter(|a| a.sample >= last).count();
        if run.ports.estimate.readers() <= acks {
            return;
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() || stop() {
            tracing::warn!(
                "{} of {} readers of the estimates did not acknowledge the last sample within {:?}",
                run.ports.estimate.readers().saturating_sub(acks),
                run.ports.estimate.readers(),
                run.config.linger
            );
            return;
        }
        run.ports.ack.wait(left);
    }
}

/// The full name of a mission topic, for messages.
fn topic_name(config: &TopicsConfig, topic: &str) -> String {
    dyfos_shared::wire::mission::topic_name(&config.prefix, MISSION, &config.mission, topic)
}

/// Topic group of the robots' own topics.
pub(crate) const MISSION: &str = "mission";
/// Topic group of simulation-only topics.
pub(crate) const SIM: &str = "sim";
