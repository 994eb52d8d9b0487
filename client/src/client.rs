//! [`Client`]: the connection to one `dyfosd` and its typed requests.

use crate::error::{CallError, ClientOpenError, IpcFailure, MapRequestError, RendezvousError, StatsRequestError};
use dyfos_process::idle::IdleCores;
use dyfos_shared::answer::Answer;
use dyfos_shared::limits::{MAX_DELTAS_PER_MESSAGE, MAX_INLINE_DELTAS, MAX_MAPS};
use dyfos_shared::wire::map::{
    MapId, MapInfo, MapReplyHeader, MapRequest, MapRequestHeader, WireDelta, decode_deltas, world_chunks,
};
use dyfos_shared::wire::rendezvous::{
    Mode, RendezvousCheck, RendezvousReply, RendezvousRequest, RendezvousRequestHeader,
};
use dyfos_shared::wire::services::{self, BadServiceName, InvalidDomain, Ipc, Services};
use dyfos_shared::wire::stats::{DaemonStats, StatsReply, StatsRequest};
use dyfos_shared::wire::{DEFAULT_PREFIX, Rejection, ServiceNames, Status, split_u128};
use dyfos_shared::world::{Bounds, MapDelta, Sun, World};
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::ReceiveError;
use iceoryx2::port::client::Client as ClientPort;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::request_response::RequestResponseOpenError;
use std::fmt::Debug;
use std::time::{Duration, Instant};

type RendezvousPort = ClientPort<Ipc, [WireDelta], RendezvousRequestHeader, RendezvousReply, ()>;
type MapPort = ClientPort<Ipc, [WireDelta], MapRequestHeader, [WireDelta], MapReplyHeader>;
type StatsPort = ClientPort<Ipc, StatsRequest, (), StatsReply, ()>;

/// How long a client polls for a reply without yielding its core, at most, before
/// it polls yielding (`ClientConfig::poll`): long enough for the daemon to answer a
/// check-mode, `stats` or map request (its IPC thread wakes at real-time priority),
/// short enough to cost nothing next to a search (`bench/RESULTS.md`, "Why the
/// scheduling defaults").
pub(crate) const HOT_POLL: Duration = Duration::from_micros(50);

/// How to reach the daemon.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClientConfig {
    /// Service-name prefix the daemon serves (its `--prefix`); default `dyfos/`.
    pub prefix: String,
    /// How long [`Client::connect`] (and a reconnect) waits for the daemon to appear.
    pub connect_timeout: Duration,
    /// How long to poll for a reply (yielding the core between polls) before
    /// sleeping on the reply event; the client sleeps at once, after a 50 µs poll,
    /// while every core is taken (`dyfos_process::idle`). Replies within the window arrive without an event
    /// wake-up, which on a virtual machine goes through the host. The default, 1 ms,
    /// covers a typical `dyfos` query; longer windows cut a lone client's latency a
    /// little more but cost throughput when more clients than cores poll at once
    /// (`bench/RESULTS.md`, "Why the scheduling defaults").
    pub poll: Duration,
    /// iceoryx2 file prefix (its `global.prefix`, default `iox2_`): processes see each
    /// other only within one domain. `None` keeps iceoryx2's default. The daemon's
    /// `--domain`.
    pub domain: Option<String>,
}

impl Default for ClientConfig {
    fn default() -> Self {
        ClientConfig {
            prefix: DEFAULT_PREFIX.to_string(),
            connect_timeout: Duration::from_secs(2),
            poll: Duration::from_millis(1),
            domain: None,
        }
    }
}

/// The iceoryx2 configuration of a domain (`None`: iceoryx2's default), as the
/// client opens its ports; the mission processes open their topics with the same.
pub fn iceoryx_config(domain: Option<&str>) -> Result<iceoryx2::config::Config, ClientOpenError> {
    services::iceoryx_config(domain).map_err(|InvalidDomain(d)| ClientOpenError::InvalidDomain(d))
}

fn ipc(e: impl std::error::Error + Send + Sync + 'static) -> CallError {
    CallError::Ipc(IpcFailure::new(e))
}

/// Refuses locally (`OverCapacity`, as the daemon would) `n` records of `what` over
/// `limit`; `advice` ends the message.
fn at_most(n: usize, limit: usize, what: &str, advice: &str) -> Result<(), CallError> {
    Rejection::at_most(n, limit, what, advice).map_err(CallError::Local)
}

/// A request just sent: on which service, and how long to wait for its reply.
#[derive(Clone, Copy)]
struct Sent<'a> {
    service: &'a str,
    names: &'a ServiceNames,
    config: &'a ClientConfig,
    timeout: Duration,
}

/// A reply waited for on a [`PendingResponse`].
type Pending<Req, ReqH, Res, ResH> = PendingResponse<Ipc, Req, ReqH, Res, ResH>;

/// Sends `records` under `header` on one of the ports whose request is a header and
/// delta records (rendezvous, map).
fn send_records<H, Res, ResH>(
    port: &ClientPort<Ipc, [WireDelta], H, Res, ResH>,
    header: H,
    records: &[WireDelta],
) -> Result<Pending<[WireDelta], H, Res, ResH>, CallError>
where
    H: Default + Debug + ZeroCopySend,
    Res: Debug + IceoryxSend + ?Sized,
    ResH: Debug + ZeroCopySend,
{
    let mut loan = port.loan_slice_uninit(records.len()).map_err(ipc)?;
    *loan.user_header_mut() = header;
    loan.write_from_slice(records).send().map_err(ipc)
}

fn open_ipc(e: impl std::error::Error + Send + Sync + 'static) -> ClientOpenError {
    ClientOpenError::Ipc(IpcFailure::new(e))
}

/// The ports of one connection. Dropping it closes them.
struct Connection {
    node: Node<Ipc>,
    rendezvous: RendezvousPort,
    map: MapPort,
    stats: StatsPort,
    wake: Notifier<Ipc>,
    reply: Listener<Ipc>,
    reply_to: [u64; 2],
    /// Whether polling for a reply may yield (a core is idle) or should sleep.
    idle: IdleCores,
}

enum Opened {
    Ready(Box<Connection>),
    /// The services are not there (yet): no daemon.
    Missing,
}

impl Connection {
    fn open(config: &ClientConfig, names: &ServiceNames) -> Result<Opened, ClientOpenError> {
        let iox = iceoryx_config(config.domain.as_deref())?;
        // No signal handler: Ctrl-C belongs to the application, not to this library.
        let node = NodeBuilder::new()
            .config(&iox)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(open_ipc)?;
        let services = Services::new(&node, names);
        let named = |e: BadServiceName| ClientOpenError::Ipc(IpcFailure::on(&e.name, e.source));
        let incompatible = |service: &str, e: RequestResponseOpenError| match e {
            RequestResponseOpenError::DoesNotExist => None,
            RequestResponseOpenError::IncompatibleRequestOrResponseType
            | RequestResponseOpenError::IncompatibleMessagingPattern
            | RequestResponseOpenError::IncompatibleAttributes => {
                Some(ClientOpenError::Incompatible { service: service.to_string(), reason: format!("{e:?}") })
            }
            other => Some(ClientOpenError::Ipc(IpcFailure::on(service, other))),
        };
        macro_rules! open_rr {
            ($name:expr, $build:expr) => {
                match $build.map_err(named)?.open() {
                    Ok(s) => s,
                    Err(e) => match incompatible($name, e) {
                        None => return Ok(Opened::Missing),
                        Some(err) => return Err(err),
                    },
                }
            };
        }
        let rendezvous = open_rr!(&names.rendezvous, services.rendezvous());
        let map = open_rr!(&names.map, services.map());
        let stats = open_rr!(&names.stats, services.stats());
        let (Ok(wake), Ok(reply)) = (services.wake().map_err(named)?.open(), services.reply().map_err(named)?.open())
        else {
            return Ok(Opened::Missing);
        };
        use iceoryx2::service::port_factory::PortFactory as _;
        // The daemon creates its servers one after the other: wait for all three.
        let serving = [
            rendezvous.dynamic_config().number_of_servers(),
            map.dynamic_config().number_of_servers(),
            stats.dynamic_config().number_of_servers(),
        ];
        if serving.contains(&0) {
            return Ok(Opened::Missing);
        }
        let reply_listener = reply.listener_builder().create().map_err(open_ipc)?;
        let reply_to = split_u128(reply_listener.id().value());
        Ok(Opened::Ready(Box::new(Connection {
            rendezvous: rendezvous
                .client_builder()
                .initial_max_slice_len(64)
                .allocation_strategy(AllocationStrategy::PowerOfTwo)
                .create()
                .map_err(open_ipc)?,
            map: map
                .client_builder()
                .initial_max_slice_len(1024)
                .allocation_strategy(AllocationStrategy::PowerOfTwo)
                .create()
                .map_err(open_ipc)?,
            stats: stats.client_builder().create().map_err(open_ipc)?,
            wake: wake.notifier_builder().create().map_err(open_ipc)?,
            reply: reply_listener,
            reply_to,
            idle: IdleCores::of_this_machine(),
            node,
        })))
    }

    /// Waits for the reply to `pending` that `receive` keeps: `NoDaemon` if no server
    /// got the request, else as [`Connection::await_reply`].
    fn await_pending<Req, ReqH, Res, ResH, T>(
        &self,
        pending: &Pending<Req, ReqH, Res, ResH>,
        sent: Sent,
        interrupt: &mut Interrupt,
        mut receive: impl FnMut(&Pending<Req, ReqH, Res, ResH>) -> Result<Option<T>, ReceiveError>,
    ) -> Result<T, CallError>
    where
        Req: Debug + IceoryxSend + ?Sized,
        ReqH: Debug + ZeroCopySend,
        Res: Debug + IceoryxSend + ?Sized,
        ResH: Debug + ZeroCopySend,
    {
        if pending.number_of_server_connections() == 0 {
            return Err(CallError::NoDaemon {
                service: sent.service.to_string(),
                prefix: sent.names.prefix.clone(),
                domain: sent.config.domain.clone(),
            });
        }
        self.await_reply(
            sent.config.poll,
            sent.timeout,
            interrupt,
            || receive(pending).map_err(ipc),
            || pending.is_connected(),
        )
    }

    /// Waits for `receive` to yield a reply: busy-polls for `poll`, then sleeps on
    /// the reply event. Notices a daemon that died (its ports go away when the dead
    /// node is cleaned up, which this loop triggers) and the timeout.
    fn await_reply<T>(
        &self,
        poll: Duration,
        timeout: Duration,
        interrupt: &mut Interrupt,
        mut receive: impl FnMut() -> Result<Option<T>, CallError>,
        is_connected: impl Fn() -> bool,
    ) -> Result<T, CallError> {
        let start = Instant::now();
        self.wake.notify().map_err(ipc)?;
        let mut last_cleanup = start;
        loop {
            if let Some(v) = receive()? {
                return Ok(v);
            }
            let now = Instant::now();
            let elapsed = now - start;
            if elapsed >= timeout {
                return Err(CallError::Timeout(timeout));
            }
            if elapsed < poll.min(HOT_POLL) {
                // The first microseconds, poll without yielding: a cheap request's
                // reply comes in that time, and a yield on a busy core hands it to
                // another thread for a whole time slice (milliseconds) first.
                std::hint::spin_loop();
                continue;
            }
            if elapsed < poll && !self.idle.busy() {
                // Yield rather than burn the core: the daemon may need this very core
                // to answer. Only while a core is idle: when every core is taken
                // (the workers search, other clients wait), a thread that yields
                // stays runnable and delays whoever wakes next, e.g. another
                // process's cheap request, by a time slice; sleeping on the reply
                // event costs this wait a wake-up instead. This asks about the
                // moment, not a load that lasts (`busy_lasting`): a wait looks too
                // seldom to tell them apart, and yielding beside searches lengthened
                // the tail of cheap requests (`bench/RESULTS.md`, "Why the scheduling
                // defaults").
                std::thread::yield_now();
                continue;
            }
            if !is_connected() {
                // The reply may have landed just before the server let go.
                return receive()?.ok_or(CallError::DaemonGone);
            }
            if now - last_cleanup >= Duration::from_millis(200) {
                self.node.try_cleanup_dead_nodes();
                last_cleanup = now;
            }
            let nap = (timeout - elapsed).min(Duration::from_millis(100));
            match self.reply.timed_wait(|_| {}, nap) {
                // A signal ended the sleep: the SIGCONT after Ctrl-Z and `fg`, a
                // debugger attaching, a handler of the caller's. It ends the call only
                // if the caller's interrupt check says so (below); else wait on.
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(e) => return Err(ipc(e)),
            }
            if interrupt.requested() {
                return Err(CallError::Interrupted);
            }
        }
    }
}

/// A connection to `dyfosd`. One request at a time (`&mut self`); open one client
/// per thread that queries concurrently. `Send`, so it can move to a worker thread.
pub struct Client {
    config: ClientConfig,
    names: ServiceNames,
    conn: Option<Box<Connection>>,
    /// The next request's id. Ids start at a random point, not at 1: iceoryx2 can
    /// hand the connection of a client that died to a new client, and a reply the
    /// daemon then sends for the dead client's request arrives at the new one. It
    /// carries the dead client's id, which no other client uses, so it is dropped
    /// like any reply that is not to the request waiting.
    next_id: u64,
    interrupt: Interrupt,
}

/// The caller's interrupt check ([`Client::set_interrupt_check`]), if any.
#[derive(Default)]
struct Interrupt(Option<Box<dyn FnMut() -> bool + Send>>);

impl Interrupt {
    fn requested(&mut self) -> bool {
        self.0.as_mut().is_some_and(|check| check())
    }
}

impl std::fmt::Debug for Client {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client").field("prefix", &self.names.prefix).field("connected", &self.conn.is_some()).finish()
    }
}

impl Client {
    /// Connects to the daemon serving `config.prefix`, waiting up to
    /// `config.connect_timeout` for it to appear.
    pub fn connect(config: &ClientConfig) -> Result<Client, ClientOpenError> {
        let names = ServiceNames::new(&config.prefix)?;
        let mut client = Client {
            config: config.clone(),
            names,
            conn: None,
            next_id: unique_u64(0x7265_7175_6573_7473),
            interrupt: Interrupt::default(),
        };
        client.ensure_connected(config.connect_timeout)?;
        Ok(client)
    }

    /// The configuration this client was made with.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// Sets how long a reconnect, after the daemon went away, waits for a daemon to
    /// appear (`config().connect_timeout`); `Duration::ZERO` tries once and reports
    /// `NoDaemon` at once. The C ABI sets it so, after connecting.
    pub fn set_connect_timeout(&mut self, timeout: Duration) {
        self.config.connect_timeout = timeout;
    }

    /// Lets the caller end a call while it waits for its reply: `check` runs about
    /// every 100 ms of the wait (once it sleeps) and when a signal interrupts it, and
    /// `true` ends the call with `Interrupted`. The Python binding uses it to raise
    /// `KeyboardInterrupt` on Ctrl-C. Without a check, a signal never ends a call:
    /// Ctrl-Z and `fg`, or a debugger attaching, leave the query waiting for its
    /// answer, and only the call's timeout bounds the wait.
    pub fn set_interrupt_check(&mut self, check: Option<Box<dyn FnMut() -> bool + Send>>) {
        self.interrupt = Interrupt(check);
    }

    fn ensure_connected(&mut self, limit: Duration) -> Result<(), ClientOpenError> {
        if self.conn.is_none() {
            let start = Instant::now();
            let waited = limit.min(self.config.connect_timeout);
            loop {
                match Connection::open(&self.config, &self.names)? {
                    Opened::Ready(c) => {
                        self.conn = Some(c);
                        break;
                    }
                    Opened::Missing if start.elapsed() < waited => std::thread::sleep(Duration::from_millis(10)),
                    Opened::Missing => {
                        return Err(ClientOpenError::NoDaemon {
                            service: self.names.rendezvous.clone(),
                            prefix: self.names.prefix.clone(),
                            domain: self.config.domain.clone(),
                            waited,
                        });
                    }
                }
            }
        }
        Ok(())
    }

    /// Runs `call`; a daemon that went away drops the connection, so the next call
    /// reconnects.
    fn with_connection<T>(
        &mut self,
        timeout: Duration,
        call: impl FnOnce(&Connection, u64, &ClientConfig, &ServiceNames, &mut Interrupt) -> Result<T, CallError>,
    ) -> Result<T, CallError> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        let result = match self.ensure_connected(timeout) {
            Ok(()) => {
                call(self.conn.as_deref().expect("connected above"), id, &self.config, &self.names, &mut self.interrupt)
            }
            Err(e) => Err(CallError::Connect(e)),
        };
        if matches!(result, Err(CallError::DaemonGone | CallError::NoDaemon { .. } | CallError::Ipc(_))) {
            self.conn = None;
        }
        result
    }

    fn rendezvous_call(
        &mut self,
        request: &RendezvousRequest,
        mode: Mode,
        timeout: Duration,
    ) -> Result<RendezvousReply, CallError> {
        if request.budget == Some(0) {
            return Err(CallError::Local(Rejection::new(
                Status::MalformedRequest,
                "a budget of 0 evaluations can find nothing; use None for the algorithm's own limits",
            )));
        }
        let records = request.records();
        at_most(records.len(), MAX_INLINE_DELTAS, "inline delta records", "; apply them with Client::apply first")?;
        self.with_connection(timeout, |conn, id, config, names, interrupt| {
            let pending = send_records(&conn.rendezvous, request.header(mode, id, conn.reply_to), &records)?;
            let sent = Sent { service: &names.rendezvous, names, config, timeout };
            conn.await_pending(&pending, sent, interrupt, |p| {
                Ok(p.receive()?.map(|r| *r.payload()).filter(|r| r.request_id == id))
            })
        })
    }

    /// Asks the daemon for the optimal sensor pose. Waits at most `timeout`; give the
    /// request a `deadline` shorter than that to get the best pose found in time.
    pub fn rendezvous(&mut self, request: &RendezvousRequest, timeout: Duration) -> Result<Answer, RendezvousError> {
        let reply = self.rendezvous_call(request, Mode::Solve, timeout)?;
        reply.decode_answer().map_err(RendezvousError::Rejected)
    }

    /// Sends `request` in check mode: the daemon validates everything (map id and
    /// version, belief, parameters, inline deltas on a copy of the map) and answers
    /// at once, without searching or changing the map. The round-trip floor.
    pub fn check(
        &mut self,
        request: &RendezvousRequest,
        timeout: Duration,
    ) -> Result<RendezvousCheck, RendezvousError> {
        let reply = self.rendezvous_call(request, Mode::Check, timeout)?;
        reply.decode_check().map_err(RendezvousError::Rejected)
    }

    /// One map request and its reply header and records.
    fn map_call(
        &mut self,
        request: &MapRequest,
        timeout: Duration,
    ) -> Result<(MapReplyHeader, Vec<WireDelta>), CallError> {
        let records = request.records();
        let advice = " per message; split the batch or upload the whole map";
        at_most(records.len(), MAX_DELTAS_PER_MESSAGE, "delta records", advice)?;
        let (reply, records) = self.with_connection(timeout, |conn, id, config, names, interrupt| {
            let pending = send_records(&conn.map, request.header(id, conn.reply_to), &records)?;
            let sent = Sent { service: &names.map, names, config, timeout };
            conn.await_pending(&pending, sent, interrupt, |p| {
                let Some(r) = p.receive()? else { return Ok(None) };
                let header = *r.user_header();
                Ok((header.request_id == id).then(|| (header, r.payload().to_vec())))
            })
        })?;
        if reply.status != Status::Ok as u32 {
            return Err(CallError::Rejected(Rejection::from_wire(reply.status, &reply.detail, reply.error_index)));
        }
        Ok((reply, records))
    }

    /// Creates an empty map at version 0; `map_exists` if the id is taken.
    pub fn create_map(
        &mut self,
        map: MapId,
        bounds: Bounds,
        sun: Sun,
        timeout: Duration,
    ) -> Result<u64, MapRequestError> {
        Ok(self.map_call(&MapRequest::Create { map, bounds, sun }, timeout)?.0.version)
    }

    /// Applies `deltas` to the map as one atomic batch (SPEC §1) and returns the new
    /// version. With `expected_version`, the map must be at that version first.
    pub fn apply(
        &mut self,
        map: MapId,
        expected_version: Option<u64>,
        deltas: &[MapDelta],
        timeout: Duration,
    ) -> Result<u64, MapRequestError> {
        let request = MapRequest::Apply { map, expected_version, deltas: deltas.to_vec() };
        Ok(self.map_call(&request, timeout)?.0.version)
    }

    /// Uploads `world`'s bounds, sun, obstacles and voxels as map `map`, in as many
    /// chunks as it takes; the daemon swaps it in atomically when the last arrives.
    /// A new map starts at version 0; with `replace`, an existing map is replaced
    /// whole (one change: version + 1), else `map_exists`. Returns the version.
    pub fn upload_map(
        &mut self,
        map: MapId,
        world: &World,
        replace: bool,
        timeout: Duration,
    ) -> Result<u64, MapRequestError> {
        let start = Instant::now();
        let chunks = world_chunks(world);
        let upload_id = upload_id(map);
        let chunk_count = u32::try_from(chunks.len()).unwrap_or(u32::MAX);
        let mut version = 0;
        for (i, chunk) in chunks.iter().enumerate() {
            let deltas = decode_deltas(chunk).map_err(MapRequestError::Invalid)?;
            let request = MapRequest::Upload {
                map,
                upload_id,
                chunk_index: i as u32,
                chunk_count,
                replace,
                expected_version: None,
                bounds: *world.bounds(),
                sun: *world.sun(),
                deltas,
            };
            let left = timeout.saturating_sub(start.elapsed());
            version = self.map_call(&request, left)?.0.version;
        }
        Ok(version)
    }

    /// Uploads an OctoMap `.bt` file's occupied cells as map `map` (bounds and sun
    /// given, OctoMap's cell (0, 0, 0) with its minimum corner at `origin`: see
    /// [`dyfos_shared::world::octomap::world_from_bt`]), as [`Client::upload_map`]
    /// does; returns the version. A file that cannot be read as an OctoMap, or whose
    /// cells do not fit a map, is refused before anything is sent (`Invalid`, with
    /// `invalid_delta` or `over_capacity`).
    #[allow(clippy::too_many_arguments)]
    pub fn upload_octomap(
        &mut self,
        map: MapId,
        bt: &[u8],
        origin: dyfos_shared::math::Point3<f64>,
        bounds: dyfos_shared::world::Bounds,
        sun: dyfos_shared::world::Sun,
        replace: bool,
        timeout: Duration,
    ) -> Result<u64, MapRequestError> {
        use dyfos_shared::world::{VoxelError, octomap::OctomapError};
        let world = dyfos_shared::world::octomap::world_from_bt(bt, origin, bounds, sun).map_err(|e| {
            let status = match e {
                OctomapError::Map(VoxelError::TooManyCells { .. } | VoxelError::GridTooLarge { .. }) => {
                    Status::OverCapacity
                }
                _ => Status::InvalidDelta,
            };
            MapRequestError::Invalid(Rejection::new(status, format!("OctoMap: {e}")))
        })?;
        self.upload_map(map, &world, replace, timeout)
    }

    /// Makes sure the daemon holds `world` (a scenario's map) and returns its id and
    /// version: the map is uploaded under `map` (default: [`World::content_id`], so
    /// the same scenario reuses its map); if that id holds the same content already,
    /// it is reused as it is; if it holds other content, `replace` replaces it, else
    /// the error is `map_exists`.
    pub fn upload_scenario_map(
        &mut self,
        world: &World,
        map: Option<MapId>,
        replace: bool,
        timeout: Duration,
    ) -> Result<(MapId, u64), MapRequestError> {
        let start = Instant::now();
        let map = map.unwrap_or_else(|| world.content_id());
        match self.upload_map(map, world, false, timeout) {
            Ok(version) => Ok((map, version)),
            Err(e) if e.status() == Some(Status::MapExists) => {
                let existing = self.snapshot(map, timeout.saturating_sub(start.elapsed()))?;
                if existing.same_content(world) {
                    Ok((map, existing.version()))
                } else if replace {
                    Ok((map, self.upload_map(map, world, true, timeout.saturating_sub(start.elapsed()))?))
                } else {
                    Err(MapRequestError::Rejected(Rejection::new(
                        Status::MapExists,
                        format!("map {map} exists in the daemon with other content; replace it, or use another map id"),
                    )))
                }
            }
            Err(e) => Err(e),
        }
    }

    /// The map as it is now, read in pages; retried if it changes while paging.
    pub fn snapshot(&mut self, map: MapId, timeout: Duration) -> Result<World, MapRequestError> {
        let start = Instant::now();
        'attempt: for _ in 0..4 {
            let left = timeout.saturating_sub(start.elapsed());
            let (first, records) = self.map_call(&MapRequest::Snapshot { map, page: 0 }, left)?;
            let mut deltas = decode_deltas(&records).map_err(MapRequestError::Invalid)?;
            for page in 1..first.chunk_count {
                let left = timeout.saturating_sub(start.elapsed());
                let (h, records) = self.map_call(&MapRequest::Snapshot { map, page }, left)?;
                // A map deleted and made again meanwhile may be at the same version.
                if h.version != first.version || h.generation != first.generation {
                    continue 'attempt;
                }
                deltas.extend(decode_deltas(&records).map_err(MapRequestError::Invalid)?);
            }
            let bounds = dyfos_shared::wire::map::decode_bounds(first.bounds).map_err(MapRequestError::Invalid)?;
            let sun = dyfos_shared::wire::map::decode_sun(first.sun).map_err(MapRequestError::Invalid)?;
            return dyfos_shared::wire::map::world_from_content(first.version, bounds, sun, &deltas)
                .map_err(|e| MapRequestError::Invalid(Rejection::new(Status::InvalidDelta, format!("snapshot: {e}"))));
        }
        Err(MapRequestError::Rejected(Rejection::new(
            Status::MapVersionMismatch,
            "the map kept changing while it was read; retry",
        )))
    }

    /// Deletes the map (and its file in the daemon's state directory).
    pub fn delete_map(
        &mut self,
        map: MapId,
        expected_version: Option<u64>,
        timeout: Duration,
    ) -> Result<(), MapRequestError> {
        self.map_call(&MapRequest::Delete { map, expected_version }, timeout)?;
        Ok(())
    }

    /// Every map the daemon holds, in id order: one request per map, each asking
    /// for the first map after the last one described (docs/wire.md §9), all within
    /// `timeout`. Not a snapshot of one moment: a map made or deleted meanwhile may
    /// or may not be in the list. A listing that goes on past [`MAX_MAPS`] maps
    /// (maps made faster than they are listed) is refused with
    /// `map_version_mismatch`: retry.
    pub fn list_maps(&mut self, timeout: Duration) -> Result<Vec<MapInfo>, MapRequestError> {
        let start = Instant::now();
        let mut maps: Vec<MapInfo> = Vec::new();
        let mut from: MapId = 0;
        // One more request than maps: the last says there are no more.
        for _ in 0..=MAX_MAPS {
            let left = timeout.saturating_sub(start.elapsed());
            let (reply, _) = self.map_call(&MapRequest::List { from }, left)?;
            let Some(info) = MapInfo::from_list_reply(from, &reply).map_err(MapRequestError::Invalid)? else {
                return Ok(maps);
            };
            maps.push(info);
            match info.id.checked_add(1) {
                Some(next) => from = next,
                None => return Ok(maps),
            }
        }
        Err(MapRequestError::Rejected(Rejection::new(
            Status::MapVersionMismatch,
            format!("the daemon's maps kept changing while they were listed (more than {MAX_MAPS} seen); retry"),
        )))
    }

    /// The daemon's health and counters.
    pub fn stats(&mut self, timeout: Duration) -> Result<DaemonStats, StatsRequestError> {
        let reply = self.with_connection(timeout, |conn, id, config, names, interrupt| {
            let request = StatsRequest { request_id: id, reply_to: conn.reply_to };
            let pending = conn.stats.send_copy(request).map_err(ipc)?;
            let sent = Sent { service: &names.stats, names, config, timeout };
            conn.await_pending(&pending, sent, interrupt, |p| {
                Ok(p.receive()?.map(|r| *r.payload()).filter(|r| r.request_id == id))
            })
        })?;
        Ok(DaemonStats::from(&reply))
    }
}

/// An upload id unlikely to collide with another client's: time, process and map.
fn upload_id(map: MapId) -> u64 {
    unique_u64(map)
}

/// A number unlikely to be drawn by any other client, in this process or another,
/// now or earlier: time, process id, a per-process counter and `salt`, mixed.
fn unique_u64(salt: u64) -> u64 {
    static DRAWN: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64);
    let count = DRAWN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut x = nanos
        ^ (u64::from(std::process::id()) << 32)
        ^ salt.rotate_left(17)
        ^ count.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    // splitmix64 finalizer
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d049bb133111eb);
    x ^ (x >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_many_records_are_refused_locally_with_advice() {
        assert_eq!(at_most(3, 3, "delta records", ""), Ok(()));
        let Err(CallError::Local(r)) = at_most(4, 3, "inline delta records", "; apply them first") else {
            panic!("four records over a limit of three were not refused")
        };
        assert_eq!(r.status, Status::OverCapacity);
        assert_eq!(r.message, "4 inline delta records exceed the limit of 3; apply them first");
    }

    #[test]
    fn request_ids_of_two_clients_do_not_start_alike() {
        let (a, b) = (unique_u64(1), unique_u64(1));
        assert_ne!(a, b);
        assert_ne!(unique_u64(0x7265_7175_6573_7473), 1);
    }

    #[test]
    fn client_is_send() {
        fn send<T: Send>() {}
        send::<Client>();
    }

    #[test]
    fn bad_prefix_and_domain_are_refused_before_any_ipc() {
        let err =
            Client::connect(&ClientConfig { prefix: "no spaces/".into(), ..ClientConfig::default() }).unwrap_err();
        assert!(matches!(err, ClientOpenError::InvalidPrefix(_)), "{err}");
        assert!(iceoryx_config(Some("a/b")).is_err());
        assert!(iceoryx_config(Some("dyfos_test_1")).is_ok());
    }

    #[test]
    fn no_daemon_is_reported_after_the_connect_timeout() {
        let config = ClientConfig {
            prefix: format!("dyfos-client-unit-{}/", std::process::id()),
            connect_timeout: Duration::from_millis(50),
            ..ClientConfig::default()
        };
        let err = Client::connect(&config).unwrap_err();
        assert!(matches!(err, ClientOpenError::NoDaemon { .. }), "{err}");
        assert!(err.to_string().contains("dyfosd --prefix dyfos-client-unit-"), "{err}");
        assert!(err.to_string().contains("the default iceoryx2 domain"), "{err}");
    }

    #[test]
    fn no_daemon_messages_name_the_domain() {
        let domain = Some("dyt_robot_".to_string());
        let open = ClientOpenError::NoDaemon {
            service: "p/rendezvous".into(),
            prefix: "p/".into(),
            domain: domain.clone(),
            waited: Duration::ZERO,
        };
        let request = crate::RendezvousError::NoDaemon { service: "p/rendezvous".into(), prefix: "p/".into(), domain };
        for message in [open.to_string(), request.to_string()] {
            assert!(message.contains("in iceoryx2 domain `dyt_robot_`"), "{message}");
            assert!(message.contains("`dyfosd --prefix p/ --domain dyt_robot_`"), "{message}");
        }
        // Word for word, as the two messages have always read.
        assert_eq!(
            open.to_string(),
            "no dyfosd serves `p/rendezvous` in iceoryx2 domain `dyt_robot_` (waited 0ns); start one with \
             `dyfosd --prefix p/ --domain dyt_robot_`, or pass the prefix and domain it uses"
        );
        assert_eq!(
            request.to_string(),
            "no dyfosd serves `p/rendezvous` in iceoryx2 domain `dyt_robot_`; start one with \
             `dyfosd --prefix p/ --domain dyt_robot_` (retryable)"
        );
    }
}
