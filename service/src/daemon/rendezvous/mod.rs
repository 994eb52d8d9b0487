//! The rendezvous service: validate on the IPC thread ([`on_request`] →
//! [`accept`]), search on a worker ([`worker`]); [`deliver`] records and sends
//! every reply.

mod queue;
mod watch;
mod worker;

pub(crate) use queue::Queue;
pub(crate) use watch::{Connected, Watch};
pub use worker::answer_query;
pub(crate) use worker::worker;

use super::pool::{Pool, lock};
use super::ports::{RendezvousActive, Replies};
use super::record::{ChangeCause, Record, unix_ns, unix_ns_of};
use super::reject::{check_version, guarded, invalid_delta, unknown_map};
use super::state::State;
use dyfos_shared::params::ModelKind;
use dyfos_shared::wire::map::WireDelta;
use dyfos_shared::wire::rendezvous::{Mode, RendezvousReply, RendezvousRequest, RendezvousRequestHeader};
use dyfos_shared::wire::{Rejection, Status, join_u128};
use dyfos_shared::world::World;
use queue::is_heavy;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Instant, SystemTime};
use tracing::{debug, trace};

/// Takes one rendezvous request: a refusal or a check is answered here, a query to
/// solve is queued for a worker.
pub(super) fn on_request(state: &mut State, replies: &Replies, active: RendezvousActive) {
    let received = Instant::now();
    // Copy the header out of shared memory once; validate the copy.
    let header = *active.user_header();
    let request_id = header.request_id;
    let reply_to = join_u128(header.reply_to);
    trace!(request_id, records = active.payload().len(), "rendezvous request");
    match guarded("rendezvous", || accept(state, &header, active.payload())) {
        Err(rejection) => {
            debug!(request_id, status = %rejection.status, "rendezvous request rejected: {}", rejection.message);
            state.pool.stats().failed(rejection.status);
            // Refused before any delta was applied: the map is as it was.
            let map_version = state.maps.get(header.map_id).map(|w| w.version());
            let mut reply = RendezvousReply::rejected(request_id, &Rejection { map_version, ..rejection });
            reply.daemon_micros = micros_since(received);
            deliver(&state.pool, replies, &active, reply_to, reply, None);
        }
        Ok(Accepted::Checked(version, request)) => {
            let mut reply = RendezvousReply::checked(request_id, version);
            reply.daemon_micros = micros_since(received);
            let recorded = request.map(|request| Recorded { received, mode: Mode::Check, request });
            deliver(&state.pool, replies, &active, reply_to, reply, recorded);
        }
        Ok(Accepted::Queued(request, world)) => {
            let client = active.origin().value();
            let heavy = is_heavy(request.algorithm);
            let mut q = lock(&state.pool.queue);
            q.push(client, heavy, Job { active, request: *request, world, received, reply_to, request_id });
            if let Some(thread) = q.hold_for_starved() {
                state.pool.watches[thread].hold.store(true, Ordering::Relaxed);
                trace!(request_id, thread, "every worker searches: holding a search of the busiest client");
            }
            drop(q);
            // One job: one idle thread may take it. Queuing never lets a held search
            // go on, so those are not woken.
            state.pool.work.notify_one();
        }
    }
}

/// What [`accept`] made of a request.
enum Accepted {
    /// Checked: the version the query would search, and the request if recording.
    Checked(u64, Option<Box<RendezvousRequest>>),
    Queued(Box<RendezvousRequest>, Arc<World>),
}

/// Validates a request and commits its inline deltas (a query to solve) or tries
/// them (a check); no port involved.
fn accept(state: &mut State, header: &RendezvousRequestHeader, records: &[WireDelta]) -> Result<Accepted, Rejection> {
    if state.closing {
        return Err(Rejection::new(Status::ShuttingDown, "dyfosd is shutting down; retry when it is back"));
    }
    let (request, mode) = RendezvousRequest::decode(header, records)?;
    if request.params.model == ModelKind::Learned && state.pool.learned.is_none() {
        return Err(Rejection::new(
            Status::UnsupportedModel,
            "params.model = learned needs trained weights, which this daemon has not loaded; start dyfosd with --model FILE (from `dyfos train`), or use paper or anisotropic",
        ));
    }
    let world = state.maps.get(request.map).ok_or_else(|| unknown_map(request.map))?;
    check_version(request.map, &world, request.expected_version)?;
    if mode == Mode::Solve {
        let heavy = is_heavy(request.algorithm);
        let queued = lock(&state.pool.queue).queued_of(heavy);
        if queued >= state.max_queued {
            let class = if heavy { "brute" } else { "non-brute" };
            return Err(Rejection::new(
                Status::Busy,
                format!(
                    "{queued} {class} queries are waiting for a worker; retry shortly or start dyfosd with more --workers"
                ),
            ));
        }
    }
    let world = if request.deltas.is_empty() {
        world
    } else {
        let next = world.apply(&request.deltas).map_err(invalid_delta)?;
        match mode {
            Mode::Check => Arc::new(next),
            Mode::Solve => state.maps.commit_deltas(
                request.map,
                &world,
                &request.deltas,
                next,
                "inline deltas",
                ChangeCause::Inline,
            )?,
        }
    };
    Ok(match mode {
        Mode::Check => Accepted::Checked(world.version(), state.pool.recorder.is_some().then(|| Box::new(request))),
        Mode::Solve => Accepted::Queued(Box::new(request), world),
    })
}

/// An accepted query waiting for (or on) a worker.
pub(crate) struct Job {
    active: RendezvousActive,
    request: RendezvousRequest,
    world: Arc<World>,
    received: Instant,
    reply_to: u128,
    request_id: u64,
}

/// An accepted request, for the recording of its reply.
struct Recorded {
    received: Instant,
    mode: Mode,
    request: Box<RendezvousRequest>,
}

/// Sends `reply` and wakes the client; records it first if `recorded`, so that a
/// query a client sends after this reply is recorded after it, whichever thread
/// answers it. The one way a rendezvous reply leaves the daemon.
fn deliver(
    pool: &Pool,
    replies: &Replies,
    active: &RendezvousActive,
    reply_to: u128,
    reply: RendezvousReply,
    recorded: Option<Recorded>,
) {
    if let (Some(recorder), Some(Recorded { received, mode, request })) = (&pool.recorder, recorded) {
        recorder.record(Record::Rendezvous {
            received: unix_ns_of(received),
            replied: unix_ns(SystemTime::now()),
            mode,
            request_id: reply.request_id,
            request,
            reply: Box::new(reply),
        });
    }
    match active.loan_uninit() {
        Ok(loan) => {
            if let Err(e) = loan.write_payload(reply).send() {
                debug!("rendezvous reply not delivered (client gone?): {e:?}");
            }
        }
        Err(e) => debug!("rendezvous reply not delivered (client gone?): {e:?}"),
    }
    replies.notify(reply_to);
}

/// µs since `received`, as a reply's `daemon_micros`.
fn micros_since(received: Instant) -> u64 {
    u64::try_from(received.elapsed().as_micros()).unwrap_or(u64::MAX)
}

#[cfg(test)]
mod tests;
