//! The mission's publish-subscribe topics over iceoryx2, each paired with an event
//! so that a waiting reader sleeps instead of polling.
//!
//! Every process opens (or creates) the topics with the same limits, so start
//! order does not matter. Subscribers keep up to [`MAX_BUFFER`] samples; a reader
//! that only needs the latest sample asks for a small buffer and old samples are
//! overwritten (safe overflow), so a slow reader never blocks a writer.
//!
//! ```no_run
//! use dyfos_mission::mission::topics::{Topics, TopicsConfig};
//! use dyfos_shared::wire::mission::{RENDEZVOUS_TOPIC, RendezvousStateMsg};
//! use std::time::Duration;
//!
//! let topics = Topics::open(&TopicsConfig { prefix: "dyfos/".into(), domain: None, mission: "demo".into() })?;
//! let inbox = topics.inbox::<RendezvousStateMsg>("mission", RENDEZVOUS_TOPIC, 16)?;
//! if let Some(msg) = inbox.recv_timeout(Duration::from_secs(1), &|| false) {
//!     println!("rendezvous at waypoint {}", msg.step);
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use dyfos_client::Ipc;
use dyfos_client::iceoryx_config;
use dyfos_process::abandoned::recover;
use dyfos_shared::wire::mission::topic_name;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use std::fmt::Debug;
use std::time::{Duration, Instant};

/// A topic's publish-subscribe service, its event service and its name.
type Pair<T> = (String, PubSubFactory<Ipc, T, ()>, iceoryx2::service::port_factory::event::PortFactory<Ipc>);

/// Largest subscriber buffer of a mission topic (samples).
pub const MAX_BUFFER: usize = 8192;

/// A topic that cannot be opened.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cannot open mission topic `{topic}`: {reason}")]
pub struct TopicOpenError {
    /// The service name.
    pub topic: String,
    /// iceoryx2's reason.
    pub reason: String,
}

/// A message that cannot be sent.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cannot send on `{topic}`: {reason}")]
pub struct TopicSendError {
    /// The service name.
    pub topic: String,
    /// iceoryx2's reason.
    pub reason: String,
}

/// Where the topics live: the daemon's service prefix, the iceoryx2 domain and the
/// mission's name (two missions with different names do not see each other).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicsConfig {
    /// Service-name prefix, e.g. `dyfos/`.
    pub prefix: String,
    /// iceoryx2 domain (`None`: iceoryx2's default).
    pub domain: Option<String>,
    /// Mission name, e.g. `demo-dyfos`.
    pub mission: String,
}

/// One node from which the mission's topics are opened.
pub struct Topics {
    node: Node<Ipc>,
    config: TopicsConfig,
}

impl std::fmt::Debug for Topics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Topics").field("config", &self.config).finish()
    }
}

impl Topics {
    /// Creates the node. Signals are left to the caller (see [`dyfos_process::shutdown`]).
    pub fn open(config: &TopicsConfig) -> Result<Self, TopicOpenError> {
        let err =
            |reason: String| TopicOpenError { topic: format!("{}mission/{}", config.prefix, config.mission), reason };
        let iox = iceoryx_config(config.domain.as_deref()).map_err(|e| err(e.to_string()))?;
        let node = NodeBuilder::new()
            .config(&iox)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| err(format!("{e:?}")))?;
        Ok(Topics { node, config: config.clone() })
    }

    /// Removes what dead processes left behind, so their ports stop counting.
    pub fn cleanup_dead_nodes(&self) {
        self.node.try_cleanup_dead_nodes();
    }

    fn name(&self, group: &str, topic: &str) -> String {
        topic_name(&self.config.prefix, group, &self.config.mission, topic)
    }

    fn open_pair<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        group: &str,
        topic: &str,
    ) -> Result<Pair<T>, TopicOpenError> {
        let name = self.name(group, topic);
        let err = |reason: String| TopicOpenError { topic: name.clone(), reason };
        let service_name = ServiceName::new(&name).map_err(|e| err(format!("{e:?}")))?;
        let event_name = ServiceName::new(&format!("{name}.event")).map_err(|e| err(format!("{e:?}")))?;
        let start = Instant::now();
        let mut abandoned_checked = false;
        // Several processes open the same topics at start; one of them wins the
        // creation and the others retry until it is done. A creation still unfinished
        // after a second may be one its creator died in (see `dyfos_process::abandoned`).
        loop {
            let pubsub = self
                .node
                .service_builder(&service_name)
                .publish_subscribe::<T>()
                .max_publishers(4)
                .max_subscribers(8)
                .max_nodes(16)
                .subscriber_max_buffer_size(MAX_BUFFER)
                .history_size(0)
                .enable_safe_overflow(true)
                .open_or_create();
            let event = self
                .node
                .service_builder(&event_name)
                .event()
                .max_notifiers(4)
                .max_listeners(8)
                .max_nodes(16)
                .open_or_create();
            match (pubsub, event) {
                (Ok(p), Ok(e)) => return Ok((name, p, e)),
                (p, e) if start.elapsed() > Duration::from_secs(3) => {
                    return Err(err(format!("{:?} / {:?}", p.err(), e.err())));
                }
                _ if !abandoned_checked && start.elapsed() > Duration::from_secs(1) => {
                    abandoned_checked = true;
                    for (service, pattern) in
                        [(&service_name, MessagingPattern::PublishSubscribe), (&event_name, MessagingPattern::Event)]
                    {
                        recover(&self.node, service, pattern);
                    }
                }
                _ => std::thread::sleep(Duration::from_millis(10)),
            }
        }
    }

    /// A writer of `topic` in `group` (`mission` or `sim`).
    pub fn outbox<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        group: &str,
        topic: &str,
    ) -> Result<Outbox<T>, TopicOpenError> {
        let (name, service, event) = self.open_pair::<T>(group, topic)?;
        let err = |reason: String| TopicOpenError { topic: name.clone(), reason };
        let publisher = service.publisher_builder().create().map_err(|e| err(format!("{e:?}")))?;
        let notifier = event.notifier_builder().create().map_err(|e| err(format!("{e:?}")))?;
        Ok(Outbox { name, service, publisher, notifier })
    }

    /// A reader of `topic` in `group` keeping up to `buffer` unread samples
    /// (1..=[`MAX_BUFFER`]; older ones are overwritten).
    pub fn inbox<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        group: &str,
        topic: &str,
        buffer: usize,
    ) -> Result<Inbox<T>, TopicOpenError> {
        let (name, service, event) = self.open_pair::<T>(group, topic)?;
        let err = |reason: String| TopicOpenError { topic: name.clone(), reason };
        let subscriber = service
            .subscriber_builder()
            .buffer_size(buffer.clamp(1, MAX_BUFFER))
            .create()
            .map_err(|e| err(format!("{e:?}")))?;
        let listener = event.listener_builder().create().map_err(|e| err(format!("{e:?}")))?;
        Ok(Inbox { name, service, subscriber, listener })
    }
}

/// The writing end of a topic.
pub struct Outbox<T: Debug + ZeroCopySend + Copy + 'static> {
    name: String,
    service: PubSubFactory<Ipc, T, ()>,
    publisher: Publisher<Ipc, T, ()>,
    notifier: Notifier<Ipc>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Outbox<T> {
    /// Publishes `msg` and wakes the readers. Returns how many readers got it.
    pub fn send(&self, msg: T) -> Result<usize, TopicSendError> {
        let err = |reason: String| TopicSendError { topic: self.name.clone(), reason };
        let sample = self.publisher.loan_uninit().map_err(|e| err(format!("{e:?}")))?;
        let delivered = sample.write_payload(msg).send().map_err(|e| err(format!("{e:?}")))?;
        self.notifier.notify().map_err(|e| err(format!("{e:?}")))?;
        Ok(delivered)
    }

    /// Readers currently attached to the topic.
    pub fn readers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// The service name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

/// The reading end of a topic.
pub struct Inbox<T: Debug + ZeroCopySend + Copy + 'static> {
    name: String,
    service: PubSubFactory<Ipc, T, ()>,
    subscriber: Subscriber<Ipc, T, ()>,
    listener: Listener<Ipc>,
}

/// Longest single sleep while waiting, so that stop requests are noticed.
const NAP: Duration = Duration::from_millis(50);

impl<T: Debug + ZeroCopySend + Copy + 'static> Inbox<T> {
    /// The next unread sample, if any.
    pub fn try_recv(&self) -> Option<T> {
        match self.subscriber.receive() {
            Ok(Some(sample)) => Some(*sample.payload()),
            Ok(None) => None,
            Err(e) => {
                tracing::warn!(topic = %self.name, "receive failed: {e:?}");
                None
            }
        }
    }

    /// Every unread sample, oldest first.
    pub fn drain(&self) -> Vec<T> {
        std::iter::from_fn(|| self.try_recv()).collect()
    }

    /// The next sample, waiting up to `timeout` (sleeping on the topic's event);
    /// `None` on timeout or when `stop()` turns true.
    pub fn recv_timeout(&self, timeout: Duration, stop: &impl Fn() -> bool) -> Option<T> {
        let start = Instant::now();
        loop {
            if let Some(v) = self.try_recv() {
                return Some(v);
            }
            let elapsed = start.elapsed();
            if elapsed >= timeout || stop() {
                return None;
            }
            // An error here is an interrupting signal; the loop re-checks `stop`.
            let _ = self.listener.timed_wait(|_| {}, (timeout - elapsed).min(NAP));
        }
    }

    /// Sleeps until something may have arrived, at most `timeout`.
    pub fn wait(&self, timeout: Duration) {
        let _ = self.listener.timed_wait(|_| {}, timeout.min(NAP));
    }

    /// Writers currently attached to the topic.
    pub fn writers(&self) -> usize {
        self.service.dynamic_config().number_of_publishers()
    }

    /// The service name.
    pub fn name(&self) -> &str {
        &self.name
    }
}
