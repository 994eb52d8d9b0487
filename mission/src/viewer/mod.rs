//! The viewer process: the paper's viewer state machine (Fig. 2, SPEC §9).
//!
//! The viewer owns the map. At start it uploads the mission's world to the daemon
//! (a chunked batch of map deltas); afterwards a moving sun goes to the daemon as
//! an inline `SetSun` delta with the next query, and a daemon that lost or changed
//! the map (restart without state, another writer) is re-synchronised by a fresh
//! upload. For every rendezvous state from the rover it
//! 1. asks `dyfosd` for the optimal sensor pose with the chosen algorithm
//!    (`dyfos`, `random`, `center`, `brute`), seeded per step;
//! 2. flies there (a straight kinematic flight at 2 m/s and 1 rad/s; simulated
//!    time passes);
//! 3. waits for the rover to stand at the waypoint and looks at its *true* pose
//!    with the simulated camera ([`crate::sim::SimCamera`]): a measurement drawn
//!    from N(true position, R_true), or why there is none;
//! 4. sends the measurement, R and its own pose to the rover, and again every
//!    [`RESEND_INTERVAL`] until the rover acknowledges it (or moves on).
//!
//! Every rendezvous state is acknowledged as it arrives; a repeat of a step already
//! taken is not served twice (idempotent by step). The rover is present while its
//! heartbeats arrive ([`crate::mission::presence`]); the viewer waits for one that
//! went silent (the log says `rover_lost`, then `rover_back`) and gives up only
//! after `rover_timeout`. A restarted viewer takes the mission up at the rover's
//! current rendezvous, which the rover re-sends until acknowledged.
//!
//! When the daemon has no answer (no feasible pose, unreachable) the viewer says
//! so at once, and the rover dead-reckons that step.
//!
//! With [`OutputConfig::mcap`](crate::mission::output::OutputConfig::mcap) of [`ViewerConfig::output`] the viewer keeps its side of the mission — the
//! rendezvous beliefs, the daemon's answers, its measurements and poses — as an
//! MCAP file for Foxglove ([`crate::eval::McapMission`]), written when it exits.
//!
//! ```no_run
//! use dyfos_client::ClientConfig;
//! use dyfos_mission::mission::{Mission, topics::TopicsConfig};
//! use dyfos_mission::viewer::{ViewerConfig, run_viewer};
//! use dyfos_shared::answer::Algorithm;
//!
//! let topics = TopicsConfig { prefix: "dyfos/".into(), domain: None, mission: "demo".into() };
//! let config = ViewerConfig::new(ClientConfig::default(), topics, Mission::builtin(), Algorithm::Dyfos, 1);
//! let report = run_viewer(&config, &|| false)?;
//! println!("{} rendezvous, {} observed", report.rendezvous, report.observed);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::eval::{AnswerRecord, McapMission};
use crate::mission::Mission;
use crate::mission::failure::RunError;
use crate::mission::log::EventLog;
use crate::mission::output::OutputConfig;
use crate::mission::presence::{Heartbeat, Peer, PresenceChange, Reliable, acknowledge, drain_acks};
use crate::mission::topics::{Inbox, Outbox, TopicSendError, Topics, TopicsConfig};
use crate::rover::{MISSION, SIM};
use crate::sim::{CameraView, Flight, FlightLimits, SimCamera, SimClock, stream_seed, streams};
use dyfos_client::{
    Client, ClientConfig, ClientOpenError, MapRequestError, RendezvousError, RendezvousRequest, Status,
};
use dyfos_shared::answer::{Algorithm, Answer};
use dyfos_shared::posterior::Belief;
use dyfos_shared::sdsmm::{Learned, NoiseModel, NoiseModelError};
use dyfos_shared::wire::map::MapId;
use dyfos_shared::wire::mission::{
    AckKind, AckMsg, MEASUREMENT_TOPIC, Measurement, MeasurementMsg, NoMeasurement, Observation, Phase,
    RENDEZVOUS_TOPIC, RESEND_INTERVAL, ROVER_ACK_TOPIC, ROVER_PRESENCE_TOPIC, RendezvousState, RendezvousStateMsg,
    TRUTH_TOPIC, TrueState, TrueStateMsg, VIEWER_ACK_TOPIC, VIEWER_PRESENCE_TOPIC, ViewerPose,
};
use dyfos_shared::world::{MapDelta, Sun, World};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde_json::json;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How the viewer runs.
#[derive(Debug, Clone)]
pub struct ViewerConfig {
    /// How to reach the daemon.
    pub client: ClientConfig,
    /// Where the mission's topics live.
    pub topics: TopicsConfig,
    /// The mission (the viewer uses its world, sun motion, parameters and take-off pose).
    pub mission: Mission,
    /// The daemon map id this viewer owns.
    pub map_id: MapId,
    /// The search algorithm to ask for.
    pub algorithm: Algorithm,
    /// Seed of the run: search seeds and camera noise.
    pub seed: u64,
    /// Simulated seconds per wall second; `None` runs as fast as possible.
    pub time_scale: Option<f64>,
    /// Flight limits.
    pub flight: FlightLimits,
    /// Longest wait for the daemon's answer, wall time.
    pub query_timeout: Duration,
    /// The deadline given to the daemon with each query (best pose so far when it passes).
    pub query_deadline: Option<Duration>,
    /// Longest wait for the rover to reach the rendezvous once the viewer is there, wall time.
    pub observe_timeout: Duration,
    /// Exit after this long without a rendezvous state from the rover, wall time.
    pub idle_timeout: Duration,
    /// A rover without a heartbeat for this long is lost (the viewer still waits), wall time.
    pub presence_timeout: Duration,
    /// Exit (the rover went away) after this long without the rover's heartbeat, wall time.
    pub rover_timeout: Duration,
    /// The event log and the MCAP file of the viewer's side of the mission.
    pub output: OutputConfig,
    /// Weights of the `learned` SDSMM, for missions whose `params.model` is
    /// `learned` (the camera's noise; `dyfosd` needs the same file, its `--model`).
    pub learned: Option<Arc<Learned>>,
}

impl ViewerConfig {
    /// Defaults: map id 1, paced 20× real time, 30 s query timeout with a 20 s
    /// deadline, 10 s to wait for the rover at a rendezvous, 120 s idle, a rover
    /// silent for 2 s lost and for 20 s gone.
    pub fn new(client: ClientConfig, topics: TopicsConfig, mission: Mission, algorithm: Algorithm, seed: u64) -> Self {
        ViewerConfig {
            client,
            topics,
            mission,
            map_id: 1,
            algorithm,
            seed,
            time_scale: Some(20.0),
            flight: FlightLimits::default(),
            query_timeout: Duration::from_secs(30),
            query_deadline: Some(Duration::from_secs(20)),
            observe_timeout: Duration::from_secs(10),
            idle_timeout: Duration::from_secs(120),
            presence_timeout: Duration::from_secs(2),
            rover_timeout: Duration::from_secs(20),
            output: OutputConfig::default(),
            learned: None,
        }
    }
}

/// Why the viewer could not run.
pub type ViewerRunError = RunError<ViewerFailure>;

/// What only the viewer fails at.
#[derive(Debug, thiserror::Error)]
pub enum ViewerFailure {
    /// The daemon cannot be reached.
    #[error(transparent)]
    Connect(ClientOpenError),
    /// The map could not be uploaded.
    #[error("cannot upload the mission's map to dyfosd: {0}")]
    Map(MapRequestError),
    /// The mission's noise model cannot run here.
    #[error(transparent)]
    Model(NoiseModelError),
    /// No rover spoke for `idle_timeout`.
    #[error(
        "no word from a rover on `{topic}` for {waited:?}; start `dyfos-rover` with the same --prefix and --mission-name"
    )]
    Idle {
        /// The rendezvous topic.
        topic: String,
        /// How long the viewer waited.
        waited: Duration,
    },
    /// The rover that was being served went away before finishing.
    #[error("the rover on `{topic}` went away before reaching its goal (no heartbeat for {waited:?})")]
    RoverGone {
        /// The rendezvous topic.
        topic: String,
        /// How long the rover was silent.
        waited: Duration,
    },
    /// SIGINT or SIGTERM arrived.
    #[error("stopped by a signal")]
    Stopped,
}

impl From<ViewerFailure> for ViewerRunError {
    fn from(failure: ViewerFailure) -> Self {
        RunError::Side(failure)
    }
}

/// What the viewer did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ViewerReport {
    /// Rendezvous states received.
    pub rendezvous: u32,
    /// Of those, rendezvous where the rover was measured.
    pub observed: u32,
    /// Mission messages sent to the rover: measurements, their repeats, and
    /// acknowledgements (heartbeats not counted).
    pub messages_sent: u32,
}

struct Viewer<'a> {
    config: &'a ViewerConfig,
    client: Client,
    world: World,
    daemon_version: u64,
    camera: SimCamera,
    clock: SimClock,
    pose: ([f64; 3], f64),
    truth: Inbox<TrueStateMsg>,
    latest_truth: Option<TrueState>,
    log: EventLog,
    topics: Topics,
    rover: Peer,
    rover_acks: Inbox<AckMsg>,
    acks: Outbox<AckMsg>,
    heartbeat: Option<Heartbeat>,
    measurement: Outbox<MeasurementMsg>,
    /// The last measurement, until the rover acknowledges it.
    pending: Option<Reliable<MeasurementMsg>>,
    messages_sent: u32,
}

impl Viewer<'_> {
    /// Uploads the whole map (replacing any copy) and remembers its version.
    fn sync_map(&mut self) -> Result<(), MapRequestError> {
        let timeout = self.config.query_timeout;
        self.daemon_version = self.client.upload_map(self.config.map_id, &self.world, true, timeout)?;
        self.log.record(
            "map_synced",
            self.clock.now(),
            json!({"map": self.config.map_id, "version": self.daemon_version, "obstacles": self.world.obstacles().len()}),
        );
        Ok(())
    }

    /// The deltas that bring the local map to the present (the sun's motion).
    fn due_deltas(&mut self) -> Vec<MapDelta> {
        let m = &self.config.mission;
        if m.sun_azimuth_rate == 0.0 {
            return Vec::new();
        }
        let sun0 = m.world.sun();
        let Ok(sun) = Sun::new(sun0.elevation, sun0.azimuth + m.sun_azimuth_rate * self.clock.now()) else {
            return Vec::new();
        };
        if sun == *self.world.sun() {
            return Vec::new();
        }
        vec![MapDelta::SetSun(sun)]
    }

    /// Asks the daemon, re-synchronising the map once if the daemon's copy is not ours.
    fn query(&mut self, step: u32, belief: &Belief) -> Result<Answer, RendezvousError> {
        let deltas = self.due_deltas();
        if !deltas.is_empty() {
            match self.world.apply(&deltas) {
                Ok(w) => self.world = w,
                Err(e) => tracing::warn!("local map rejected the sun's move: {e}"),
            }
        }
        let mut request = RendezvousRequest {
            expected_version: Some(self.daemon_version),
            deltas,
            algorithm: self.config.algorithm,
            seed: stream_seed(self.config.seed, streams::SEARCH, u64::from(step)),
            deadline: self.config.query_deadline,
            params: self.config.mission.params,
            ..RendezvousRequest::new(self.config.map_id, *belief)
        };
        let mut resynced = false;
        loop {
            match self.client.rendezvous(&request, self.config.query_timeout) {
                Ok(answer) => {
                    self.daemon_version = answer.map_version;
                    return Ok(answer);
                }
                Err(e)
                    if !resynced
                        && (matches!(e.status(), Some(Status::UnknownMap | Status::MapVersionMismatch))
                            || e.is_retryable()) =>
                {
                    tracing::warn!(step, "{e}; re-uploading the map and asking again");
                    self.log.record("resync", self.clock.now(), json!({"step": step, "reason": e.to_string()}));
                    resynced = true;
                    if let Err(m) = self.sync_map() {
                        tracing::warn!("re-upload failed: {m}");
                        return Err(e);
                    }
                    // The upload carries the current sun already.
                    request.deltas.clear();
                    request.expected_version = Some(self.daemon_version);
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Flies to `to`, letting simulated time pass. `false` when stopped.
    fn fly(&mut self, to: ([f64; 3], f64), stop: &impl Fn() -> bool) -> bool {
        let flight = Flight::new(self.pose, to, &self.config.flight);
        let arrive = self.clock.now() + flight.duration;
        let ok = self.clock.advance_to(arrive, stop);
        self.pose = to;
        ok
    }

    /// Keeps the link with the rover: takes in heartbeats and acknowledgements,
    /// logs presence changes, re-sends the measurement not yet acknowledged.
    fn service(&mut self) -> Result<(), TopicSendError> {
        if let Some(change) = self.rover.poll() {
            let step = self.heartbeat_step();
            match change {
                PresenceChange::Appeared { .. } => {}
                PresenceChange::Lost => {
                    tracing::warn!("the rover's heartbeat stopped");
                    self.log.record("rover_lost", self.clock.now(), json!({"step": step}));
                }
                PresenceChange::Returned { instance, silent } => {
                    tracing::info!("the rover is back after {silent:?}");
                    self.log.record(
                        "rover_back",
                        self.clock.now(),
                        json!({"step": step, "instance": instance, "silent_s": silent.as_secs_f64()}),
                    );
                }
                PresenceChange::Restarted { instance } => {
                    tracing::info!("the rover restarted");
                    self.log.record("rover_back", self.clock.now(), json!({"step": step, "instance": instance}));
                }
            }
        }
        let acks = drain_acks(&self.rover_acks);
        if let Some(p) = self.pending.as_mut() {
            for a in &acks {
                p.ack(a);
            }
            if p.service(&self.measurement, self.rover.instance())? {
                self.messages_sent += 1;
                tracing::debug!(step = p.step(), "measurement sent again");
            }
        }
        Ok(())
    }

    fn heartbeat_step(&self) -> u32 {
        self.pending.as_ref().map_or(0, Reliable::step)
    }

    fn acknowledge(&mut self, step: u32, kind: AckKind) {
        let instance = self.heartbeat.as_ref().map_or(0, Heartbeat::instance);
        if acknowledge(&self.acks, instance, step, kind) {
            self.messages_sent += 1;
        }
    }

    fn drain_truth(&mut self) {
        for msg in self.truth.drain() {
            match TrueState::try_from(&msg) {
                Ok(t) if self.latest_truth.is_none_or(|l| t.sample >= l.sample) => self.latest_truth = Some(t),
                Ok(_) => {}
                Err(e) => tracing::warn!("ignoring malformed ground truth: {e}"),
            }
        }
    }

    /// Waits for the rover to stand at waypoint `step`; its true pose, or why not.
    fn rover_at(&mut self, step: u32, stop: &impl Fn() -> bool) -> Result<[f64; 3], NoMeasurement> {
        let start = Instant::now();
        let mut checked = start;
        loop {
            self.drain_truth();
            match self.latest_truth {
                Some(t) if t.step == step && t.phase != Phase::Driving => return Ok(t.pose),
                Some(t) if t.step > step => return Err(NoMeasurement::RoverLeft),
                _ => {}
            }
            if start.elapsed() >= self.config.observe_timeout || stop() {
                return Err(NoMeasurement::RoverLeft);
            }
            // A rover that died or lost the link on the way will not arrive.
            if checked.elapsed() >= RESEND_INTERVAL {
                checked = Instant::now();
                if let Err(e) = self.service() {
                    tracing::warn!("cannot re-send the measurement: {e}");
                }
                if !self.rover.present() {
                    return Err(NoMeasurement::RoverLeft);
                }
            }
            self.truth.wait(self.config.observe_timeout.saturating_sub(start.elapsed()).min(RESEND_INTERVAL));
        }
    }
}

/// Runs until the rover finishes (or goes quiet for `idle_timeout`); then writes
/// [`OutputConfig::mcap`](crate::mission::output::OutputConfig::mcap) of [`ViewerConfig::output`], if asked for.
pub fn run_viewer(config: &ViewerConfig, stop: &impl Fn() -> bool) -> Result<ViewerReport, ViewerRunError> {
    config.output.around(&config.mission, |mcap| serve(config, stop, mcap))
}

fn serve(
    config: &ViewerConfig,
    stop: &impl Fn() -> bool,
    mcap: &mut Option<McapMission>,
) -> Result<ViewerReport, ViewerRunError> {
    let mission = &config.mission;
    let model =
        NoiseModel::from_params_and_weights(&mission.params, config.learned.as_ref()).map_err(ViewerFailure::Model)?;
    let client = Client::connect(&config.client).map_err(ViewerFailure::Connect)?;
    let topics = Topics::open(&config.topics)?;
    let truth = topics.inbox::<TrueStateMsg>(SIM, TRUTH_TOPIC, 64)?;
    let measurement: Outbox<MeasurementMsg> = topics.outbox(MISSION, MEASUREMENT_TOPIC)?;
    let rover = Peer::open(&topics, ROVER_PRESENCE_TOPIC, config.presence_timeout)?;
    let rover_acks = topics.inbox::<AckMsg>(MISSION, ROVER_ACK_TOPIC, 256)?;
    let acks = topics.outbox::<AckMsg>(MISSION, VIEWER_ACK_TOPIC)?;
    let log = config.output.event_log("viewer")?;
    let mut v = Viewer {
        config,
        client,
        world: mission.world.clone(),
        daemon_version: 0,
        camera: SimCamera::new(&mission.params, model),
        clock: SimClock::new(config.time_scale),
        pose: mission.viewer_start,
        truth,
        latest_truth: None,
        log,
        topics,
        rover,
        rover_acks,
        acks,
        heartbeat: None,
        measurement,
        pending: None,
        messages_sent: 0,
    };
    v.sync_map().map_err(ViewerFailure::Map)?;
    // The heartbeat is what tells the rover a viewer is ready, so it comes last.
    let rendezvous = v.topics.inbox::<RendezvousStateMsg>(MISSION, RENDEZVOUS_TOPIC, 64)?;
    v.heartbeat = Some(Heartbeat::start(&config.topics, VIEWER_PRESENCE_TOPIC)?);
    tracing::info!(algorithm = %config.algorithm, map = config.map_id, "viewer ready");
    v.log.record("ready", 0.0, json!({"algorithm": config.algorithm.name(), "map": config.map_id}));

    let mut report = ViewerReport { rendezvous: 0, observed: 0, messages_sent: 0 };
    let mut heard = Instant::now();
    let mut last_step = 0;
    loop {
        if stop() {
            return Err(ViewerFailure::Stopped.into());
        }
        v.service()?;
        let Some(msg) = rendezvous.recv_timeout(RESEND_INTERVAL, stop) else {
            if heard.elapsed() > config.idle_timeout && !v.rover.present() {
                return Err(
                    ViewerFailure::Idle { topic: rendezvous.name().to_string(), waited: config.idle_timeout }.into()
                );
            }
            // A rover that was here and stays silent (crashed, killed, out of
            // reach for good) will not finish.
            if let Some(silent) = v.rover.silent_for()
                && silent > config.rover_timeout
            {
                return Err(ViewerFailure::RoverGone { topic: rendezvous.name().to_string(), waited: silent }.into());
            }
            continue;
        };
        heard = Instant::now();
        let state = match RendezvousState::try_from(&msg) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!("ignoring a malformed rendezvous state: {e}");
                continue;
            }
        };
        let (step, belief) = match state {
            RendezvousState::Finished { step, .. } => {
                v.acknowledge(step, AckKind::Finished);
                v.clock.catch_up();
                v.log.record("finished", v.clock.now(), json!({"step": step}));
                report.messages_sent = v.messages_sent;
                tracing::info!(step, messages = v.messages_sent, "rover finished; viewer done");
                return Ok(report);
            }
            RendezvousState::Rendezvous { step, belief, .. } => (step, belief),
        };
        v.acknowledge(step, AckKind::Rendezvous);
        if step <= last_step {
            // A repeat (our acknowledgement was late or lost): served already; the
            // measurement, if not yet acknowledged, is being re-sent.
            tracing::debug!(step, "repeated rendezvous");
            continue;
        }
        last_step = step;
        // The rover moved on: the last measurement is no longer awaited.
        v.pending = None;
        if let Some(h) = &v.heartbeat {
            h.set_step(step);
        }
        v.clock.catch_up();
        report.rendezvous += 1;
        v.log.record(
            "rendezvous_received",
            v.clock.now(),
            json!({"step": step, "mean": belief.mean.as_slice(), "cov": belief.cov.to_rows()}),
        );
        if let Some(mcap) = mcap.as_mut() {
            mcap.record_request(step, v.clock.now(), &belief);
        }

        let measurement_of = |observation, viewer, predicted_cost, v: &Viewer| Measurement {
            step,
            sim_time: v.clock.now(),
            observation,
            viewer,
            predicted_cost,
        };
        let m = match v.query(step, &belief) {
            Err(e) => {
                let why = if e.status() == Some(Status::NoFeasiblePose) {
                    NoMeasurement::NoFeasiblePose
                } else {
                    NoMeasurement::DaemonUnavailable
                };
                tracing::warn!(step, "no sensor pose: {e}");
                v.log.record(
                    "no_answer",
                    v.clock.now(),
                    json!({"step": step, "reason": why.name(), "error": e.to_string()}),
                );
                measurement_of(Observation::NotObserved(why), None, None, &v)
            }
            Ok(answer) => {
                let target = (<[f64; 3]>::from(answer.viewer_position.coords), answer.viewer_yaw);
                let record = AnswerRecord::new(step, v.clock.now(), &answer);
                v.log.record(
                    "answer",
                    v.clock.now(),
                    json!({"step": step, "viewer_position": target.0, "viewer_yaw": target.1, "cost": answer.cost,
                           "R": answer.r, "evaluations": answer.evaluations.total, "micros": answer.micros,
                           "map_version": answer.map_version, "rendezvous_answer": record}),
                );
                if let Some(mcap) = mcap.as_mut() {
                    mcap.record_answer(record);
                }
                if !v.fly(target, stop) {
                    return Err(ViewerFailure::Stopped.into());
                }
                v.log.record("arrived", v.clock.now(), json!({"step": step}));
                let pose = Some(ViewerPose { position: target.0, yaw: target.1 });
                let observation = match v.rover_at(step, stop) {
                    Err(why) => Observation::NotObserved(why),
                    Ok(rover) => {
                        let mut rng =
                            ChaCha8Rng::seed_from_u64(stream_seed(config.seed, streams::CAMERA, u64::from(step)));
                        match v.camera.observe(&v.world, target.0, target.1, rover, &mut rng) {
                            CameraView::Seen { position, r, .. } => Observation::Observed { position, r },
                            CameraView::OutOfView => Observation::NotObserved(NoMeasurement::OutOfView),
                            CameraView::OutOfRange => Observation::NotObserved(NoMeasurement::OutOfRange),
                            CameraView::Occluded => Observation::NotObserved(NoMeasurement::Occluded),
                        }
                    }
                };
                measurement_of(observation, pose, Some(answer.cost), &v)
            }
        };
        let (status, r) = match &m.observation {
            Observation::Observed { r, .. } => {
                report.observed += 1;
                ("observed", Some(r.to_rows()))
            }
            Observation::NotObserved(why) => (why.name(), None),
        };
        if let Some(mcap) = mcap.as_mut() {
            mcap.record_measurement(&m);
        }
        let (pending, _) = Reliable::send(&v.measurement, MeasurementMsg::from(&m), step, AckKind::Measurement)?;
        v.pending = Some(pending);
        v.messages_sent += 1;
        v.log.record("measurement_sent", v.clock.now(), json!({"step": step, "status": status, "R": r}));
        tracing::info!(step, status, "measurement sent");
    }
}
