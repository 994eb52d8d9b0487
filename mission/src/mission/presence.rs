//! Presence by heartbeat, and messages re-sent until acknowledged: what makes the
//! mission protocol independent of the transport under it (one host's shared
//! memory, or a cross-host link whose own ports would count as readers).
//!
//! Each mission process runs a [`Heartbeat`]: a thread publishing a
//! [`PresenceMsg`] every [`HEARTBEAT_PERIOD`] with a random instance number drawn
//! at start. The other side follows it with a [`Peer`]: present while heartbeats
//! come within the presence timeout; a new instance number is a restarted process.
//! A message the other side must act on is kept in a [`Reliable`] and sent again
//! every [`RESEND_INTERVAL`] until an [`Ack`] for its (step, kind) arrives from the
//! peer's current instance.
//!
//! ```no_run
//! use dyfos_mission::mission::presence::{Heartbeat, Peer};
//! use dyfos_mission::mission::topics::{Topics, TopicsConfig};
//! use dyfos_shared::wire::mission::{ROVER_PRESENCE_TOPIC, VIEWER_PRESENCE_TOPIC};
//! use std::time::Duration;
//!
//! let config = TopicsConfig { prefix: "dyfos/".into(), domain: None, mission: "demo".into() };
//! let _me = Heartbeat::start(&config, ROVER_PRESENCE_TOPIC)?;
//! let topics = Topics::open(&config)?;
//! let mut viewer = Peer::open(&topics, VIEWER_PRESENCE_TOPIC, Duration::from_secs(2))?;
//! viewer.poll();
//! println!("viewer present: {}", viewer.present());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::mission::topics::{Inbox, Outbox, TopicOpenError, TopicSendError, Topics, TopicsConfig};
use dyfos_shared::wire::mission::{Ack, AckKind, AckMsg, HEARTBEAT_PERIOD, PresenceMsg, RESEND_INTERVAL};
use std::fmt::Debug;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Topic group of the robots' own topics.
const MISSION: &str = "mission";

/// A random instance number for this process (time and pid mixed; never 0).
pub fn new_instance() -> u64 {
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let mut x = (nanos as u64) ^ (u64::from(std::process::id()) << 32) ^ 0x9e37_79b9_7f4a_7c15;
    // splitmix64 finaliser
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (x ^ (x >> 31)).max(1)
}

/// This process's heartbeat, published from its own thread until dropped.
#[derive(Debug)]
pub struct Heartbeat {
    instance: u64,
    step: Arc<AtomicU32>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Heartbeat {
    /// Starts publishing on `topic` (e.g. `ROVER_PRESENCE_TOPIC`) of the mission.
    pub fn start(config: &TopicsConfig, topic: &str) -> Result<Self, TopicOpenError> {
        let instance = new_instance();
        let step = Arc::new(AtomicU32::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        // The port is opened here so that an error reaches the caller; the thread
        // gets its own node (ports stay on the thread that made them).
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let (config, topic) = (config.clone(), topic.to_string());
        let (s, st) = (step.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("heartbeat".into())
            .spawn(move || {
                let opened = Topics::open(&config).and_then(|t| Ok((t.outbox::<PresenceMsg>(MISSION, &topic)?, t)));
                let (outbox, _topics) = match opened {
                    Ok(o) => {
                        let _ = ready_tx.send(Ok(()));
                        o
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                while !st.load(Ordering::Relaxed) {
                    let msg = PresenceMsg { instance, step: s.load(Ordering::Relaxed), reserved: 0 };
                    if let Err(e) = outbox.send(msg) {
                        tracing::warn!("heartbeat not sent: {e}");
                    }
                    std::thread::sleep(HEARTBEAT_PERIOD);
                }
            })
            .map_err(|e| TopicOpenError { topic: "heartbeat thread".into(), reason: e.to_string() })?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Heartbeat { instance, step, stop, thread: Some(thread) }),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(TopicOpenError { topic: "heartbeat thread".into(), reason: "it ended at start".into() }),
        }
    }

    /// This process's instance number.
    pub fn instance(&self) -> u64 {
        self.instance
    }

    /// Tells the peer which waypoint this process is on.
    pub fn set_step(&self, step: u32) {
        self.step.store(step, Ordering::Relaxed);
    }
}

impl Drop for Heartbeat {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A change in the peer's presence, as seen by [`Peer::poll`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PresenceChange {
    /// First heartbeat ever.
    Appeared {
        /// Its instance.
        instance: u64,
    },
    /// Heartbeats again after the presence timeout passed without any.
    Returned {
        /// Its instance (another one than before: the process restarted).
        instance: u64,
        /// How long it was silent.
        silent: Duration,
    },
    /// A heartbeat from another instance than before, without a gap (a fast restart).
    Restarted {
        /// The new instance.
        instance: u64,
    },
    /// Silent for longer than the presence timeout.
    Lost,
}

/// The other side's presence, from its heartbeats.
pub struct Peer {
    inbox: Inbox<PresenceMsg>,
    timeout: Duration,
    last: Option<(Instant, u64, u32)>,
    lost: bool,
}

impl Debug for Peer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Peer").field("topic", &self.inbox.name()).field("last", &self.last).finish()
    }
}

impl Peer {
    /// Follows the heartbeats on `topic`; a peer silent for `timeout` is gone.
    pub fn open(topics: &Topics, topic: &str, timeout: Duration) -> Result<Self, TopicOpenError> {
        Ok(Peer { inbox: topics.inbox(MISSION, topic, 64)?, timeout, last: None, lost: false })
    }

    /// Takes in the heartbeats received; returns the change they (or their
    /// absence) make, if any.
    pub fn poll(&mut self) -> Option<PresenceChange> {
        let mut change = None;
        for msg in self.inbox.drain() {
            let now = Instant::now();
            change = match self.last {
                None => Some(PresenceChange::Appeared { instance: msg.instance }),
                Some((at, _, _)) if self.lost => {
                    Some(PresenceChange::Returned { instance: msg.instance, silent: now - at })
                }
                Some((_, old, _)) if old != msg.instance => Some(PresenceChange::Restarted { instance: msg.instance }),
                _ => change,
            };
            self.lost = false;
            self.last = Some((now, msg.instance, msg.step));
        }
        if change.is_none() && !self.lost && self.last.is_some_and(|(at, _, _)| at.elapsed() > self.timeout) {
            self.lost = true;
            return Some(PresenceChange::Lost);
        }
        change
    }

    /// Whether a heartbeat came within the presence timeout (as of the last poll).
    pub fn present(&self) -> bool {
        !self.lost && self.last.is_some_and(|(at, _, _)| at.elapsed() <= self.timeout)
    }

    /// Whether any heartbeat was ever received.
    pub fn ever_seen(&self) -> bool {
        self.last.is_some()
    }

    /// The peer's current instance, if it was ever heard.
    pub fn instance(&self) -> Option<u64> {
        self.last.map(|(_, i, _)| i)
    }

    /// How long since the last heartbeat (`None`: never heard).
    pub fn silent_for(&self) -> Option<Duration> {
        self.last.map(|(at, _, _)| at.elapsed())
    }

    /// Sleeps until a heartbeat may have arrived, at most `timeout`.
    pub fn wait(&self, timeout: Duration) {
        self.inbox.wait(timeout);
    }
}

/// A message sent again every [`RESEND_INTERVAL`] until the peer's current
/// instance acknowledges its (step, kind).
#[derive(Debug)]
pub struct Reliable<T> {
    msg: T,
    step: u32,
    kind: AckKind,
    sent_at: Instant,
    acked_by: Option<u64>,
    /// Times sent, the first included.
    pub sends: u32,
}

impl<T: Debug + Copy + iceoryx2::prelude::ZeroCopySend + 'static> Reliable<T> {
    /// Sends `msg` for the first time; returns it with how many readers got it.
    pub fn send(outbox: &Outbox<T>, msg: T, step: u32, kind: AckKind) -> Result<(Self, usize), TopicSendError> {
        let readers = outbox.send(msg)?;
        Ok((Reliable { msg, step, kind, sent_at: Instant::now(), acked_by: None, sends: 1 }, readers))
    }

    /// The step.
    pub fn step(&self) -> u32 {
        self.step
    }

    /// Takes in an acknowledgement.
    pub fn ack(&mut self, ack: &Ack) {
        if ack.step == self.step && ack.kind == self.kind {
            self.acked_by = Some(ack.instance);
        }
    }

    /// Whether `peer` (its current instance) has acknowledged.
    pub fn acked(&self, peer: Option<u64>) -> bool {
        self.acked_by.is_some() && self.acked_by == peer
    }

    /// Sends again if the peer's current instance has not acknowledged and the
    /// interval has passed (a new instance is sent to at once). Returns whether it sent.
    pub fn service(&mut self, outbox: &Outbox<T>, peer: Option<u64>) -> Result<bool, TopicSendError> {
        let new_peer = self.acked_by.is_some() && self.acked_by != peer;
        if self.acked(peer) || (!new_peer && self.sent_at.elapsed() < RESEND_INTERVAL) {
            return Ok(false);
        }
        if new_peer {
            self.acked_by = None;
        }
        outbox.send(self.msg)?;
        self.sent_at = Instant::now();
        self.sends += 1;
        Ok(true)
    }
}

/// Sends an acknowledgement (failures are logged: the peer will send again).
pub fn acknowledge(outbox: &Outbox<AckMsg>, instance: u64, step: u32, kind: AckKind) -> bool {
    match outbox.send(AckMsg::from(&Ack { instance, step, kind })) {
        Ok(_) => true,
        Err(e) => {
            tracing::warn!("acknowledgement not sent: {e}");
            false
        }
    }
}

/// Every valid acknowledgement received on `inbox` (malformed ones are logged
/// and dropped).
pub fn drain_acks(inbox: &Inbox<AckMsg>) -> Vec<Ack> {
    inbox
        .drain()
        .iter()
        .filter_map(|m| match Ack::try_from(m) {
            Ok(a) => Some(a),
            Err(e) => {
                tracing::warn!(topic = inbox.name(), "ignoring a malformed acknowledgement: {e}");
                None
            }
        })
        .collect()
}
