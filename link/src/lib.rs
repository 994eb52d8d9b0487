//! # dyfos-link
//!
//! The cross-host link of a mission: the rover's host and the viewer's host each
//! run one [`Link`], which carries the mission's topics between the host's own
//! iceoryx2 shared memory and the other host over [Zenoh](https://zenoh.io) (TCP).
//! The rover and the viewer do not change: their protocol
//! ([`dyfos_mission::mission::presence`]) already tolerates a link that drops, delays
//! or restarts, and the viewer's queries to `dyfosd` stay on its own host.
//!
//! ```no_run
//! use dyfos_mission::mission::topics::TopicsConfig;
//! use dyfos_link::{Link, LinkConfig, Side};
//!
//! let topics = TopicsConfig { prefix: "dyfos/".into(), domain: None, mission: "field-1".into() };
//! let mut config = LinkConfig::new(topics, Side::Rover);
//! config.listen.push("tcp/0.0.0.0:7447".into());
//! config.credentials = Some(std::path::PathBuf::from("/etc/dyfos/field-1.credentials"));
//! let link = Link::start(&config)?;
//! // ... until the mission is over:
//! let stats = link.stop();
//! println!("{} messages out, {} in, {} dropped", stats.sent, stats.received, stats.dropped);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! What crosses, and nothing else (key expressions `dyfos/<mission>/<group>/<topic>`):
//!
//! | from the rover's host | from the viewer's host |
//! |---|---|
//! | `rendezvous`, `estimate`, `rover_presence`, `rover_ack`, `sim/truth` | `measurement`, `viewer_presence`, `viewer_ack`, `evaluation` |
//!
//! Each message travels as a versioned frame ([`LINK_VERSION`], the mission's name,
//! the payload; bincode) and is validated on arrival like any wire input: a frame of
//! another version or mission, or a payload that does not decode into its validated
//! type (NaN, out of range, unknown codes), is dropped and logged through the
//! rate-limited log. Zenoh publishes reliably and blocks rather than drop under a
//! burst, and reconnects by itself after the link comes back.
//!
//! At the goal the rover waits for each reader of its estimates to acknowledge its
//! last sample; across hosts its reader is its link, so the viewer's link
//! acknowledges for the evaluations on its host ([`evaluations`]).
//!
//! Each link announces itself to the other (a Zenoh liveliness token
//! `dyfos/link/v<version>/<mission>/<side>/<zenoh id>`): a peer with the right
//! credentials but another mission, the same side or another link version is
//! named in the log, once. Connections that do not complete Zenoh's handshake
//! within [`HANDSHAKE_TIMEOUT`] are closed, and at most [`PENDING_HANDSHAKES`] may
//! be pending at once, so that a host holding connections open cannot keep the
//! other robot's link out; [`health`] counts and reports them.
//!
//! Security is Zenoh's own: with [`LinkConfig::credentials`] (a file of one
//! `user:password` line, the same on both hosts) each side presents the mission's
//! user and password and accepts only peers that present them (Zenoh user/password
//! authentication: a challenge–response, the password never crosses the link), and
//! access control allows only the mission's key expressions (from the mission's
//! user, on the listening side); anything else is denied. The traffic itself is
//! not encrypted: on an untrusted radio, run the link over a VPN (or add Zenoh's
//! TLS transport, `transport_tls`, not built here).
#![warn(missing_docs)]

pub mod evaluations;
pub mod health;
mod watcher;
mod within;

use dyfos_mission::mission::topics::{MAX_BUFFER, Outbox, TopicOpenError, TopicSendError, Topics, TopicsConfig};
use dyfos_shared::wire::mission::{
    Ack, AckMsg, ESTIMATE_TOPIC, EVALUATION_TOPIC, Estimate, EstimateMsg, EvaluationAckMsg, MEASUREMENT_TOPIC,
    Measurement, MeasurementMsg, Phase, PresenceMsg, RENDEZVOUS_TOPIC, ROVER_ACK_TOPIC, ROVER_PRESENCE_TOPIC,
    RendezvousState, RendezvousStateMsg, TRUTH_TOPIC, TrueState, TrueStateMsg, VIEWER_ACK_TOPIC, VIEWER_PRESENCE_TOPIC,
};
use evaluations::Evaluations;
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize, de::DeserializeOwned};
use std::collections::HashSet;
use std::fmt::Debug;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use within::Outcome;
use zenoh::Wait;

/// Version of the link's frames; a frame of another version is dropped.
pub const LINK_VERSION: u16 = 1;

/// Longest a connection may take to complete Zenoh's handshake (two round trips
/// and the user/password challenge; room for a radio with a few hundred ms of
/// round trip) before it is closed, on both sides: a listener does not keep a
/// silent connection, a connecting side does not wait on a stalled one.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(2);

/// Most connections whose handshake may be pending at once; more are closed at
/// once. Far above what a mission needs (one peer), so that a host must hold this
/// many connections open, renewing each within [`HANDSHAKE_TIMEOUT`], to keep the
/// other robot out; and below the usual limit of 1024 open files.
pub const PENDING_HANDSHAKES: usize = 512;

/// Largest frame accepted, bytes (the largest message is about 200).
pub const MAX_FRAME: usize = 4096;

/// Longest sleep of a forwarding thread, so that a stop is noticed.
const NAP: Duration = Duration::from_millis(100);

/// How long a stopping link waits for its forwarding threads: a put blocked on a
/// peer that stopped reading must not keep the process from exiting on SIGTERM.
const STOP_GRACE: Duration = Duration::from_secs(3);

/// How long a stopping link waits for the Zenoh session to close. Zenoh bounds
/// its close (10 s), but not while its routing is stalled (a lock held under peer
/// churn): then nothing returns, and the close is left behind on its thread.
const CLOSE_GRACE: Duration = Duration::from_secs(12);

/// Which host a link runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The rover's host: sends the rover's topics, receives the viewer's.
    Rover,
    /// The viewer's host (with `dyfosd`): sends the viewer's topics, receives the rover's.
    Viewer,
}

impl Side {
    /// `rover` or `viewer`.
    pub fn name(self) -> &'static str {
        match self {
            Side::Rover => "rover",
            Side::Viewer => "viewer",
        }
    }
}

/// How a link runs.
#[derive(Debug, Clone)]
pub struct LinkConfig {
    /// This host's iceoryx2 prefix and domain, and the mission's name.
    pub topics: TopicsConfig,
    /// Which host this is.
    pub side: Side,
    /// Zenoh endpoints to listen on, e.g. `tcp/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Zenoh endpoints of the other host to connect to, e.g. `tcp/10.0.0.1:7447`
    /// (retried until it answers, and again after a loss).
    pub connect: Vec<String>,
    /// File with one `user:password` line: the mission's credentials. `None`
    /// runs without authentication or access control (a trusted network only).
    pub credentials: Option<PathBuf>,
    /// Zenoh lease: a peer silent this long is disconnected (and reconnected when it answers).
    pub lease: Duration,
}

impl LinkConfig {
    /// A link for `side` with no endpoints yet, no credentials, a 3 s lease.
    pub fn new(topics: TopicsConfig, side: Side) -> Self {
        LinkConfig {
            topics,
            side,
            listen: Vec::new(),
            connect: Vec::new(),
            credentials: None,
            lease: Duration::from_secs(3),
        }
    }
}

/// Why a link could not start.
#[derive(Debug, thiserror::Error)]
pub enum LinkStartError {
    /// The mission's name cannot be part of a key expression.
    #[error("mission name `{0}` cannot cross the link: use letters, digits, `-`, `_` and `.` only")]
    MissionName(String),
    /// Neither an endpoint to listen on nor one to connect to.
    #[error("give at least one --listen or --connect endpoint (e.g. --listen tcp/0.0.0.0:7447)")]
    NoEndpoint,
    /// The credentials file is unusable.
    #[error("credentials file {path}: {message}")]
    Credentials {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// Zenoh refused the configuration or could not open the session.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A local topic could not be opened.
    #[error(transparent)]
    Open(#[from] TopicOpenError),
}

/// What a link did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkStats {
    /// Messages sent to the other host.
    pub sent: u64,
    /// Valid messages received from the other host and handed to this host's topics.
    pub received: u64,
    /// Frames received and dropped (another version or mission, malformed, invalid).
    pub dropped: u64,
}

/// What a thread carrying one topic needs: this host's topics, the mission, the
/// topic's key on the link and its group and name here, and the link's stop flag,
/// counters and session.
struct Route {
    topics: TopicsConfig,
    mission: String,
    key: String,
    group: String,
    topic: String,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    session: zenoh::Session,
}

#[derive(Debug, Default)]
struct Counters {
    sent: AtomicU64,
    received: AtomicU64,
    dropped: AtomicU64,
}

/// A frame on the link: version, mission and one message.
#[derive(Debug, Serialize, Deserialize)]
struct Frame<T> {
    version: u16,
    mission: String,
    msg: T,
}

fn bincode_config() -> impl bincode::config::Config {
    bincode::config::standard().with_fixed_int_encoding().with_little_endian().with_limit::<MAX_FRAME>()
}

/// Encodes `msg` of `mission` as a frame.
pub fn encode<T: Serialize>(mission: &str, msg: &T) -> Vec<u8> {
    let frame = Frame { version: LINK_VERSION, mission: mission.to_string(), msg };
    bincode::serde::encode_to_vec(&frame, bincode_config()).expect("a frame of plain numbers encodes")
}

/// A frame that was dropped, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// Not a frame.
    #[error("malformed frame: {0}")]
    Malformed(String),
    /// A frame of another link version.
    #[error("frame version {0}, this link speaks version {LINK_VERSION}")]
    Version(u16),
    /// A frame of another mission.
    #[error("frame of unknown mission `{0}`")]
    Mission(String),
    /// The message does not validate.
    #[error("invalid message: {0}")]
    Invalid(String),
}

/// Tells the starting thread whether a topic's pair of ports opened, and gives the
/// pair back if it did.
fn announce<T>(
    opened: Result<T, LinkStartError>,
    ready: &std::sync::mpsc::Sender<Result<(), LinkStartError>>,
) -> Option<T> {
    match opened {
        Ok(pair) => {
            let _ = ready.send(Ok(()));
            Some(pair)
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            None
        }
    }
}

/// A message type that may cross the link: checked on arrival as on any wire.
pub trait LinkMessage: Debug + Copy + ZeroCopySend + Serialize + DeserializeOwned + Send + 'static {
    /// `Err(why)` when the message must be dropped.
    fn validate(&self) -> Result<(), String>;
}

/// `LinkMessage` for wire messages checked by converting them into their typed form.
macro_rules! checked_by_conversion {
    ($($wire:ty => $typed:ty),* $(,)?) => {
        $(impl LinkMessage for $wire {
            fn validate(&self) -> Result<(), String> {
                <$typed>::try_from(self).map(|_| ()).map_err(|e| e.to_string())
            }
        })*
    };
}

checked_by_conversion! {
    RendezvousStateMsg => RendezvousState,
    MeasurementMsg => Measurement,
    EstimateMsg => Estimate,
    TrueStateMsg => TrueState,
    AckMsg => Ack,
}
impl LinkMessage for PresenceMsg {
    fn validate(&self) -> Result<(), String> {
        if self.reserved == 0 { Ok(()) } else { Err(format!("reserved = {} must be 0", self.reserved)) }
    }
}
impl LinkMessage for EvaluationAckMsg {
    fn validate(&self) -> Result<(), String> {
        Ok(())
    }
}

/// Decodes and validates a frame of `mission`.
pub fn decode<T: LinkMessage>(mission: &str, bytes: &[u8]) -> Result<T, FrameError> {
    let (frame, used): (Frame<T>, usize) = bincode::serde::decode_from_slice(bytes, bincode_config()).map_err(|e| {
        // Tell an old or new link from garbage: the version comes first.
        match bytes.get(..2) {
            Some(v) if u16::from_le_bytes([v[0], v[1]]) != LINK_VERSION => {
                FrameError::Version(u16::from_le_bytes([v[0], v[1]]))
            }
            _ => FrameError::Malformed(e.to_string()),
        }
    })?;
    if used != bytes.len() {
        return Err(FrameError::Malformed(format!("{} bytes after the frame", bytes.len() - used)));
    }
    if frame.version != LINK_VERSION {
        return Err(FrameError::Version(frame.version));
    }
    if frame.mission != mission {
        return Err(FrameError::Mission(frame.mission.chars().take(64).collect()));
    }
    frame.msg.validate().map_err(FrameError::Invalid)?;
    Ok(frame.msg)
}

/// The Zenoh key expression of a mission topic.
pub fn key_expr(mission: &str, group: &str, topic: &str) -> String {
    format!("dyfos/{mission}/{group}/{topic}")
}

fn valid_mission(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// Reads `user:password` from the credentials file.
fn read_credentials(path: &std::path::Path) -> Result<(String, String), LinkStartError> {
    let err = |message: String| LinkStartError::Credentials { path: path.display().to_string(), message };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let line = text.lines().map(str::trim).find(|l| !l.is_empty()).ok_or_else(|| err("is empty".into()))?;
    let (user, password) = line.split_once(':').ok_or_else(|| err("must hold one line `user:password`".into()))?;
    if user.is_empty() || password.len() < 8 || user.contains(['"', '\\']) || password.contains(['"', '\\']) {
        return Err(err("needs a user and a password of at least 8 characters, without quotes or backslashes".into()));
    }
    Ok((user.to_string(), password.to_string()))
}

/// The Zenoh configuration of a link: a peer on TCP only, no scouting (the
/// endpoints are given), and with credentials, user/password authentication and
/// access control limited to the mission's key expressions.
pub fn zenoh_config(config: &LinkConfig) -> Result<zenoh::Config, LinkStartError> {
    let mission = &config.topics.mission;
    if !valid_mission(mission) {
        return Err(LinkStartError::MissionName(mission.clone()));
    }
    if config.listen.is_empty() && config.connect.is_empty() {
        return Err(LinkStartError::NoEndpoint);
    }
    let zerr = |e: zenoh::Error| LinkStartError::Zenoh(e.to_string());
    let json = |v: &[String]| serde_json_list(v);
    let mut c = zenoh::Config::default();
    let lease = config.lease.as_millis().clamp(500, 600_000);
    for (key, value) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        // Gossip on but inert (it sends to no one and connects to no one): with it
        // off, Zenoh warns at every start that it cannot de-duplicate data across
        // region gateways, which two peers do not have.
        ("scouting/gossip", "{enabled: true, multihop: false, target: [], autoconnect: []}".into()),
        // Open returns at once; the other host may come later.
        ("open/return_conditions/connect_scouted", "false".into()),
        ("listen/endpoints", json(&config.listen)),
        ("connect/endpoints", json(&config.connect)),
        ("connect/timeout_ms", "-1".into()),
        ("connect/exit_on_failure", "false".into()),
        ("connect/retry", "{period_init_ms: 250, period_max_ms: 1000, period_increase_factor: 2}".into()),
        ("transport/link/tx/lease", lease.to_string()),
        ("transport/unicast/accept_timeout", HANDSHAKE_TIMEOUT.as_millis().to_string()),
        ("transport/unicast/open_timeout", HANDSHAKE_TIMEOUT.as_millis().to_string()),
        ("transport/unicast/accept_pending", PENDING_HANDSHAKES.to_string()),
    ] {
        c.insert_json5(key, &value).map_err(zerr)?;
    }
    if let Some(path) = &config.credentials {
        let (user, password) = read_credentials(path)?;
        let dictionary = std::path::absolute(path).unwrap_or_else(|_| path.clone());
        let usrpwd = format!(
            "{{user: \"{user}\", password: \"{password}\", dictionary_file: {}}}",
            serde_json_list(&[dictionary.display().to_string()]).trim_start_matches('[').trim_end_matches(']')
        );
        c.insert_json5("transport/auth/usrpwd", &usrpwd).map_err(zerr)?;
        let keys = serde_json_list(&[format!("dyfos/{mission}/**")]);
        // User/password authenticates the connecting side to the listening side
        // only: a listener allows the mission's user; a side that connects (to the
        // endpoint it was given) cannot learn the listener's user, so its rule
        // applies to any peer, still for the mission's keys only.
        let subject = if config.connect.is_empty() {
            format!(r#"{{ id: "crew", usernames: ["{user}"] }}"#)
        } else {
            r#"{ id: "crew" }"#.to_string()
        };
        let hello = serde_json_list(&[format!("{HELLO}/**")]);
        let acl = format!(
            r#"{{
                enabled: true,
                default_permission: "deny",
                rules: [{{ id: "mission", messages: ["put", "delete", "declare_subscriber"],
                          flows: ["egress", "ingress"], permission: "allow", key_exprs: {keys} }},
                        {{ id: "hello", messages: ["liveliness_token", "declare_liveliness_subscriber"],
                          flows: ["egress", "ingress"], permission: "allow", key_exprs: {hello} }}],
                subjects: [{subject}],
                policies: [{{ rules: ["mission", "hello"], subjects: ["crew"] }}],
            }}"#
        );
        c.insert_json5("access_control", &acl).map_err(zerr)?;
    }
    Ok(c)
}

/// A JSON list of strings.
fn serde_json_list(v: &[String]) -> String {
    let items: Vec<String> =
        v.iter().map(|s| format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))).collect();
    format!("[{}]", items.join(", "))
}

/// A running link; [`Link::stop`] (or dropping it) ends it.
pub struct Link {
    session: zenoh::Session,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    counters: Arc<Counters>,
    /// Whether the other host is connected, as the watcher thread last saw it.
    peers: Arc<AtomicBool>,
    /// This link's announcement to the other host, and what it hears of the other's.
    hello: Option<(zenoh::liveliness::LivelinessToken, zenoh::pubsub::Subscriber<()>)>,
}

impl Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link").field("zid", &self.session.zid()).field("stats", &self.stats()).finish()
    }
}

const MISSION: &str = "mission";
const SIM: &str = "sim";

/// Where the links announce themselves: `dyfos/link/v<version>/<mission>/<side>/<zenoh id>`.
const HELLO: &str = "dyfos/link";

/// Most mismatched peers a link remembers having named.
const MAX_TOLD: usize = 64;

/// What the other host's link said of itself, and what is wrong with it for this one.
fn hello_mismatch(key: &str, mission: &str, side: Side) -> Option<(String, String)> {
    let rest = key.strip_prefix(HELLO)?.strip_prefix('/')?;
    let mut parts = rest.split('/');
    let (version, peer_mission, peer_side) = (parts.next()?, parts.next()?, parts.next()?);
    let why = if version != format!("v{LINK_VERSION}") {
        format!(
            "the other host's link speaks link version {}, this one {LINK_VERSION}: nothing crosses between them; run the same dyfos-link on both hosts",
            version.trim_start_matches('v')
        )
    } else if peer_mission != mission {
        format!(
            "the other host's link serves mission `{peer_mission}`, this one `{mission}`: nothing crosses between them; give both links, the rover and the viewer the same --mission-name"
        )
    } else if peer_side == side.name() {
        format!(
            "the other host's link is on the {peer_side}'s side too: start one link with --side rover and the other with --side viewer"
        )
    } else {
        return None;
    };
    Some((format!("{version}/{peer_mission}/{peer_side}"), why))
}

/// How a message read on this host goes onto the link: `None` keeps it here.
type Pass<T> = Box<dyn FnMut(T) -> Option<T> + Send>;

/// How a message from the link is handed to this host's readers; returns how many got it.
type Hand<T> = Box<dyn FnMut(&Outbox<T>, T) -> Result<usize, TopicSendError> + Send>;

impl Link {
    /// Opens the Zenoh session and starts forwarding: one thread per topic and
    /// direction. Returns once every port is open (the other host may come later).
    pub fn start(config: &LinkConfig) -> Result<Self, LinkStartError> {
        let zconfig = zenoh_config(config)?;
        let zerr = |e: zenoh::Error| LinkStartError::Zenoh(e.to_string());
        let session = zenoh::open(zconfig).wait().map_err(zerr)?;
        let mut link = Link {
            session,
            stop: Arc::new(AtomicBool::new(false)),
            threads: Vec::new(),
            counters: Arc::default(),
            peers: Arc::default(),
            hello: None,
        };
        link.hello = Some(link.hello(config).map_err(zerr)?);
        let rover_side = config.side == Side::Rover;
        // Each side sends its own topics: the rover's host rendezvous, estimates,
        // acknowledgements, truth and the rover's heartbeat; the viewer's host
        // measurements, acknowledgements, the evaluations' and the viewer's heartbeat.
        link.forward::<RendezvousStateMsg>(config, rover_side, MISSION, RENDEZVOUS_TOPIC)?;
        link.forward::<AckMsg>(config, rover_side, MISSION, ROVER_ACK_TOPIC)?;
        link.forward::<TrueStateMsg>(config, rover_side, SIM, TRUTH_TOPIC)?;
        link.forward::<MeasurementMsg>(config, !rover_side, MISSION, MEASUREMENT_TOPIC)?;
        link.forward::<AckMsg>(config, !rover_side, MISSION, VIEWER_ACK_TOPIC)?;
        if rover_side {
            link.send_out::<EstimateMsg>(link.route(config, MISSION, ESTIMATE_TOPIC), Box::new(Some))?;
            link.take_in::<EvaluationAckMsg>(
                link.route(config, MISSION, EVALUATION_TOPIC),
                Box::new(|o, m| o.send(m)),
            )?;
        } else {
            // The evaluations on this host: the last estimate's readers, and their
            // acknowledgements, answered for together.
            let evaluations = Arc::new(Mutex::new(Evaluations::default()));
            let key = key_expr(&config.topics.mission, MISSION, EVALUATION_TOPIC);
            let answer = link.session.declare_publisher(key).wait().map_err(zerr)?;
            let (mission, counters, e) = (config.topics.mission.clone(), link.counters.clone(), evaluations.clone());
            let hand: Hand<EstimateMsg> = Box::new(move |outbox, msg| {
                // Held while handing on, so that no acknowledgement comes before the count.
                let mut e = e.lock().unwrap_or_else(|p| p.into_inner());
                let readers = outbox.send(msg)?;
                if Phase::try_from(msg.phase) == Ok(Phase::Finished)
                    && let Some(ack) = e.finished(msg.sample, readers)
                {
                    match answer.put(encode(&mission, &ack)).wait() {
                        Ok(()) => counters.sent.fetch_add(1, Ordering::Relaxed),
                        Err(e) => {
                            tracing::warn!("cannot acknowledge the rover's last sample: {e}");
                            0
                        }
                    };
                }
                Ok(readers)
            });
            link.take_in::<EstimateMsg>(link.route(config, MISSION, ESTIMATE_TOPIC), hand)?;
            let pass: Pass<EvaluationAckMsg> =
                Box::new(move |ack| evaluations.lock().unwrap_or_else(|p| p.into_inner()).acknowledged(ack));
            link.send_out::<EvaluationAckMsg>(link.route(config, MISSION, EVALUATION_TOPIC), pass)?;
        }
        // The heartbeats last: the rover and the viewer start their mission once
        // they hear each other, and by then every other topic crosses.
        link.forward::<PresenceMsg>(config, rover_side, MISSION, ROVER_PRESENCE_TOPIC)?;
        link.forward::<PresenceMsg>(config, !rover_side, MISSION, VIEWER_PRESENCE_TOPIC)?;
        link.watch_peers()?;
        tracing::info!(
            side = config.side.name(),
            mission = %config.topics.mission,
            listen = ?config.listen,
            connect = ?config.connect,
            authenticated = config.credentials.is_some(),
            "link started (zenoh id {})",
            link.session.zid()
        );
        Ok(link)
    }

    /// Announces this link to the other host and names, once each, the ways in
    /// which the other host's link does not match it.
    fn hello(
        &self,
        config: &LinkConfig,
    ) -> zenoh::Result<(zenoh::liveliness::LivelinessToken, zenoh::pubsub::Subscriber<()>)> {
        let (mission, side, zid) = (config.topics.mission.clone(), config.side, self.session.zid().to_string());
        let me = format!("{HELLO}/v{LINK_VERSION}/{mission}/{}/{zid}", side.name());
        let token = self.session.liveliness().declare_token(me).wait()?;
        let told = Mutex::new(HashSet::new());
        let heard = self
            .session
            .liveliness()
            .declare_subscriber(format!("{HELLO}/**"))
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                if sample.kind() != zenoh::sample::SampleKind::Put || key.ends_with(&format!("/{zid}")) {
                    return;
                }
                let Some((what, why)) = hello_mismatch(key, &mission, side) else { return };
                let mut told = told.lock().unwrap_or_else(|p| p.into_inner());
                // Bounded: without credentials anyone may announce anything.
                if told.len() < MAX_TOLD && told.insert(what) {
                    tracing::warn!("{why}");
                }
            })
            .wait()?;
        Ok((token, heard))
    }

    /// Starts the thread carrying `group/topic` outwards (`out`) or inwards, as is.
    fn forward<T: LinkMessage>(
        &mut self,
        config: &LinkConfig,
        out: bool,
        group: &str,
        topic: &str,
    ) -> Result<(), LinkStartError> {
        let route = self.route(config, group, topic);
        if out {
            self.send_out::<T>(route, Box::new(Some))
        } else {
            self.take_in::<T>(route, Box::new(|outbox, msg| outbox.send(msg)))
        }
    }

    /// What the thread carrying `group/topic` needs of `config` and of the link.
    fn route(&self, config: &LinkConfig, group: &str, topic: &str) -> Route {
        let mission = config.topics.mission.clone();
        Route {
            topics: config.topics.clone(),
            key: key_expr(&mission, group, topic),
            mission,
            group: group.to_string(),
            topic: topic.to_string(),
            stop: self.stop.clone(),
            counters: self.counters.clone(),
            session: self.session.clone(),
        }
    }

    /// Starts the thread reading `group/topic` on this host and putting what `pass`
    /// lets through on the link.
    fn send_out<T: LinkMessage>(&mut self, route: Route, mut pass: Pass<T>) -> Result<(), LinkStartError> {
        let Route { topics: config, mission, key, group, topic, stop, counters, session } = route;
        self.spawn(config, &format!("link->{topic}"), move |topics, ready| {
            let opened =
                topics.inbox::<T>(&group, &topic, MAX_BUFFER).map_err(LinkStartError::from).and_then(|inbox| {
                    session
                        .declare_publisher(key.clone())
                        .congestion_control(zenoh::qos::CongestionControl::Block)
                        .express(true)
                        .wait()
                        .map(|p| (inbox, p))
                        .map_err(|e| LinkStartError::Zenoh(e.to_string()))
                });
            let Some((inbox, publisher)) = announce(opened, ready) else { return };
            while !stop.load(Ordering::Relaxed) {
                let Some(msg) = inbox.recv_timeout(NAP, &|| stop.load(Ordering::Relaxed)) else { continue };
                let Some(msg) = pass(msg) else { continue };
                match publisher.put(encode(&mission, &msg)).wait() {
                    Ok(()) => {
                        counters.sent.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(e) => tracing::warn!(key = %key, "not sent: {e}"),
                }
            }
        })
    }

    /// Starts the thread taking `group/topic` from the link and handing each valid
    /// message to this host with `hand`.
    fn take_in<T: LinkMessage>(&mut self, route: Route, mut hand: Hand<T>) -> Result<(), LinkStartError> {
        let Route { topics: config, mission, key, group, topic, stop, counters, session } = route;
        self.spawn(config, &format!("link-<{topic}"), move |topics, ready| {
            let opened = topics.outbox::<T>(&group, &topic).map_err(LinkStartError::from).and_then(|outbox| {
                session
                    .declare_subscriber(key.clone())
                    .with(zenoh::handlers::FifoChannel::new(MAX_BUFFER))
                    .wait()
                    .map(|s| (outbox, s))
                    .map_err(|e| LinkStartError::Zenoh(e.to_string()))
            });
            let Some((outbox, subscriber)) = announce(opened, ready) else { return };
            while !stop.load(Ordering::Relaxed) {
                let sample = match subscriber.recv_timeout(NAP) {
                    Ok(Some(s)) => s,
                    Ok(None) => continue,
                    Err(_) => break,
                };
                match decode::<T>(&mission, &sample.payload().to_bytes()) {
                    Ok(msg) => match hand(&outbox, msg) {
                        Ok(_) => {
                            counters.received.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => tracing::warn!("cannot hand on a message from the link: {e}"),
                    },
                    Err(e) => {
                        counters.dropped.fetch_add(1, Ordering::Relaxed);
                        tracing::warn!(key = %key, "dropped a message from the link: {e}");
                    }
                }
            }
        })
    }

    /// Runs `body` on a thread of its own with this host's topics (iceoryx2 ports
    /// stay on the thread that made them); returns once it said whether its ports
    /// opened.
    fn spawn(
        &mut self,
        topics_config: TopicsConfig,
        name: &str,
        body: impl FnOnce(Topics, &std::sync::mpsc::Sender<Result<(), LinkStartError>>) + Send + 'static,
    ) -> Result<(), LinkStartError> {
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), LinkStartError>>();
        let thread = std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || match Topics::open(&topics_config) {
                Ok(topics) => body(topics, &ready_tx),
                Err(e) => {
                    let _ = ready_tx.send(Err(e.into()));
                }
            })
            .map_err(|e| LinkStartError::Zenoh(format!("cannot start a thread: {e}")))?;
        self.threads.push(thread);
        ready_rx.recv().unwrap_or_else(|_| Err(LinkStartError::Zenoh("a link thread ended at start".into())))
    }

    /// What the link has done so far.
    pub fn stats(&self) -> LinkStats {
        LinkStats {
            sent: self.counters.sent.load(Ordering::Relaxed),
            received: self.counters.received.load(Ordering::Relaxed),
            dropped: self.counters.dropped.load(Ordering::Relaxed),
        }
    }

    /// Whether the other host is connected, as seen at most one nap ago. It never
    /// waits on Zenoh, so a process polling it still notices SIGTERM when Zenoh
    /// stalls ([`Link::watch_peers`]).
    pub fn connected(&self) -> bool {
        self.peers.load(Ordering::Relaxed)
    }

    /// Keeps [`Link::connected`] current from a thread of its own: asking Zenoh
    /// for its peers blocks while its routing is stalled.
    fn watch_peers(&mut self) -> Result<(), LinkStartError> {
        let session = self.session.clone();
        let thread = watcher::watch("link-peers", self.peers.clone(), self.stop.clone(), NAP, move || {
            session.info().peers_zid().wait().next().is_some()
        })
        .map_err(|e| LinkStartError::Zenoh(format!("cannot start a thread: {e}")))?;
        self.threads.push(thread);
        Ok(())
    }

    /// Stops forwarding, closes the session; returns the final counts.
    pub fn stop(mut self) -> LinkStats {
        self.shutdown();
        self.stats()
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let stuck = dyfos_process::shutdown::join_within(std::mem::take(&mut self.threads), STOP_GRACE);
        if !stuck.is_empty() {
            tracing::warn!("stopping: {} did not stop within {STOP_GRACE:?}; left behind", stuck.join(", "));
        }
        // The announcement's undeclaring and the close wait on Zenoh: on a thread
        // of their own, so that a stalled Zenoh cannot keep the process from exiting.
        let (session, hello) = (self.session.clone(), self.hello.take());
        let closed = within::run_within("link-close", CLOSE_GRACE, move || {
            drop(hello);
            session.close().wait()
        });
        match closed {
            Outcome::Finished(Ok(())) => {}
            Outcome::Finished(Err(e)) => tracing::warn!("stopping: the Zenoh session did not close cleanly: {e}"),
            Outcome::Panicked(why) => tracing::warn!("stopping: closing the Zenoh session panicked: {why}"),
            Outcome::LeftBehind => {
                tracing::warn!("stopping: the Zenoh session did not close within {CLOSE_GRACE:?}; left behind")
            }
        }
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        if !self.threads.is_empty() {
            self.shutdown();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::posterior::Belief;

    fn rendezvous() -> RendezvousStateMsg {
        let belief = Belief::new([1.0, 2.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]]).unwrap();
        RendezvousStateMsg::from(&RendezvousState::Rendezvous { step: 3, sim_time: 1.5, belief })
    }

    #[test]
    fn frames_round_trip_and_bad_ones_are_dropped_with_the_reason() {
        let msg = rendezvous();
        let bytes = encode("m1", &msg);
        assert_eq!(decode::<RendezvousStateMsg>("m1", &bytes).unwrap(), msg);
        assert!(matches!(decode::<RendezvousStateMsg>("m2", &bytes), Err(FrameError::Mission(m)) if m == "m1"));
        let mut old = bytes.clone();
        old[0] = 9;
        assert_eq!(decode::<RendezvousStateMsg>("m1", &old), Err(FrameError::Version(9)));
        assert!(matches!(decode::<RendezvousStateMsg>("m1", &bytes[..bytes.len() - 3]), Err(FrameError::Malformed(_))));
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(matches!(decode::<RendezvousStateMsg>("m1", &longer), Err(FrameError::Malformed(_))));
        let mut nan = msg;
        nan.mean[0] = f64::NAN;
        assert!(matches!(decode::<RendezvousStateMsg>("m1", &encode("m1", &nan)), Err(FrameError::Invalid(_))));
        let far = MeasurementMsg { position: [1e9, 0.0], ..MeasurementMsg::from(&measurement()) };
        assert!(matches!(decode::<MeasurementMsg>("m1", &encode("m1", &far)), Err(FrameError::Invalid(_))));
        let bad_ack = AckMsg { instance: 1, step: 1, kind: 7 };
        assert!(matches!(decode::<AckMsg>("m1", &encode("m1", &bad_ack)), Err(FrameError::Invalid(_))));
        // A huge length prefix is refused by the size limit, not allocated.
        let mut huge = bytes.clone();
        huge[2..10].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(decode::<RendezvousStateMsg>("m1", &huge).is_err());
    }

    fn measurement() -> Measurement {
        use dyfos_shared::wire::mission::Observation;
        Measurement {
            step: 1,
            sim_time: 0.0,
            observation: Observation::Observed {
                position: [0.0, 0.0],
                r: dyfos_shared::math::Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.01]]).unwrap(),
            },
            viewer: None,
            predicted_cost: None,
        }
    }

    #[test]
    fn a_peer_of_another_mission_side_or_version_is_told_apart() {
        let hello = |v: &str, m: &str, side: &str| format!("{HELLO}/{v}/{m}/{side}/0123abcd");
        let v = format!("v{LINK_VERSION}");
        assert_eq!(hello_mismatch(&hello(&v, "m1", "viewer"), "m1", Side::Rover), None);
        let (what, why) = hello_mismatch(&hello(&v, "m2", "viewer"), "m1", Side::Rover).unwrap();
        assert!(why.contains("serves mission `m2`, this one `m1`"), "{why}");
        assert_eq!(what, format!("{v}/m2/viewer"));
        let (_, why) = hello_mismatch(&hello(&v, "m1", "rover"), "m1", Side::Rover).unwrap();
        assert!(why.contains("on the rover's side too"), "{why}");
        let (_, why) = hello_mismatch(&hello("v9", "m1", "viewer"), "m1", Side::Rover).unwrap();
        assert!(why.contains("link version 9"), "{why}");
        assert_eq!(hello_mismatch("dyfos/linked/v1/m1/viewer/x", "m1", Side::Rover), None);
        assert_eq!(hello_mismatch(&format!("{HELLO}/{v}/m1"), "m1", Side::Rover), None);
    }

    #[test]
    fn config_needs_a_safe_mission_name_an_endpoint_and_real_credentials() {
        let topics = TopicsConfig { prefix: "p/".into(), domain: None, mission: "a/b".into() };
        let mut c = LinkConfig::new(topics, Side::Rover);
        c.listen.push("tcp/127.0.0.1:0".into());
        assert!(matches!(zenoh_config(&c), Err(LinkStartError::MissionName(_))));
        c.topics.mission = "m-1".into();
        assert!(zenoh_config(&c).is_ok());
        c.listen.clear();
        assert!(matches!(zenoh_config(&c), Err(LinkStartError::NoEndpoint)));
        c.listen.push("tcp/127.0.0.1:0".into());
        let file = std::env::temp_dir().join(format!("dyfos-link-cred-{}", std::process::id()));
        std::fs::write(&file, "crew:short\n").unwrap();
        c.credentials = Some(file.clone());
        assert!(matches!(zenoh_config(&c), Err(LinkStartError::Credentials { .. })));
        std::fs::write(&file, "crew:a-long-secret\n").unwrap();
        assert!(zenoh_config(&c).is_ok(), "{:?}", zenoh_config(&c).err());
        let _ = std::fs::remove_file(&file);
    }
}
