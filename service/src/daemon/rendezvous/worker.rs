//! A worker thread: takes an accepted query from the [`Queue`](super::Queue),
//! searches, and replies to the client itself.

use super::{Job, Recorded, deliver, micros_since};
use crate::daemon::cpu::{CoreShare, WorkerCheckpoint};
use crate::daemon::pool::{Pool, lock};
use crate::daemon::ports::Replies;
use crate::daemon::reject::guarded;
use crate::search::{Checkpoint, SearchControl};
use crate::{SearchError, solve};
use dyfos_shared::answer::StopReason;
use dyfos_shared::sdsmm::NoiseModel;
use dyfos_shared::wire::rendezvous::{Mode, RendezvousReply, RendezvousRequest};
use dyfos_shared::wire::{Rejection, Status};
use dyfos_shared::world::World;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;
use tracing::{debug, error, info};

/// Thread `index` of the pool: takes jobs until the queue is closed. `index` names
/// its [`Watch`](super::Watch) in `pool.watches`.
pub(crate) fn worker(pool: &Pool, replies: &Replies, index: usize) {
    let watch = &pool.watches[index];
    loop {
        let (job, heavy) = {
            let mut q = lock(&pool.queue);
            loop {
                if let Some(taken) = q.take(index) {
                    // A hold asked of this thread's last search, which ended before its
                    // next checkpoint, is not for this one (cleared under the lock the
                    // IPC thread asks under).
                    watch.hold.store(false, Ordering::Relaxed);
                    break taken;
                }
                if q.is_closed() {
                    return;
                }
                q = pool.work.wait(q).unwrap_or_else(|poisoned| poisoned.into_inner());
            }
        };
        // A bug in a search must not take the thread (and the shutdown's count of
        // queries in flight) with it; `run` answers `internal_error` for a panic in
        // the search itself, this catches the rest.
        let checkpoint = WorkerCheckpoint::new(pool, index, !heavy && pool.spares > 0);
        let checkpoint = checkpoint.wanted().then_some(&checkpoint as &dyn Checkpoint);
        CoreShare::resume();
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(pool, replies, index, job, checkpoint)))
            .is_err()
        {
            error!("a search panicked; its query was dropped");
        }
        let mut q = lock(&pool.queue);
        q.finish(index);
        let held = q.held() > 0;
        drop(q);
        // A core is free: a held search may go on, or a query start. This thread
        // takes the query itself (the loop above), so only held searches are woken.
        if held {
            pool.resume.notify_all();
        }
    }
}

/// Searches for `job` and replies, unless its client goes away first: a query whose
/// client left while it waited for a worker is skipped, one whose client leaves during
/// the search (seen by the IPC thread through the thread's watch) abandons the search.
/// Neither gets a reply, as nobody is there to receive it. Both count as abandoned in
/// the stats, so that every accepted query shows there as served, failed or abandoned.
fn run(pool: &Pool, replies: &Replies, index: usize, job: Job, checkpoint: Option<&dyn Checkpoint>) {
    let watch = &pool.watches[index];
    let Job { active, request, world, received, reply_to, request_id } = job;
    let deadline = request.deadline.map(|d| received + d);
    if !active.is_connected() {
        pool.stats().abandoned();
        info!(
            request_id,
            algorithm = request.algorithm.name(),
            "query skipped: its client left while it waited for a worker"
        );
        return;
    }
    let (mut reply, active) = if deadline.is_some_and(|d| Instant::now() >= d) {
        let reply = RendezvousReply::rejected(
            request_id,
            &Rejection {
                map_version: Some(world.version()),
                ..Rejection::new(
                    Status::DeadlineExceeded,
                    format!(
                        "the deadline of {:?} passed while the query waited for a worker; give it more time or ask for less (a budget, a cheaper algorithm)",
                        request.deadline.unwrap_or_default()
                    ),
                )
            },
        );
        (reply, active)
    } else {
        watch.lend(request_id, active);
        let control = SearchControl {
            seed: request.seed,
            budget: request.budget,
            deadline,
            threads: pool.workers,
            abandon: Some(&watch.abandon),
            checkpoint,
        };
        let reply = answer_query(&world, &request, request_id, pool.learned.as_ref(), &control);
        let Some(active) = watch.take_back() else {
            error!(request_id, "a running query's request went missing; it gets no reply");
            return;
        };
        let Some(reply) = reply else {
            pool.stats().abandoned();
            let micros = micros_since(received);
            info!(request_id, micros, algorithm = request.algorithm.name(), "query abandoned: its client has gone");
            return;
        };
        (reply, active)
    };
    let micros = micros_since(received);
    reply.daemon_micros = micros;
    {
        let mut stats = pool.stats();
        match Status::try_from(reply.status) {
            Ok(Status::Ok) => stats.served(micros),
            Ok(s) => stats.failed(s),
            Err(_) => {}
        }
    }
    debug!(request_id, status = reply.status, micros, map = request.map, version = world.version(), "query answered");
    let recorded =
        pool.recorder.is_some().then(|| Recorded { received, mode: Mode::Solve, request: Box::new(request) });
    deliver(pool, replies, &active, reply_to, reply, recorded);
}

/// Searches for an accepted query's answer in `world` (the map after the query's
/// inline deltas) and makes the reply the daemon sends, without its timing
/// (`daemon_micros` 0): the one function from a request to a reply, used by the
/// daemon's workers and by `dyfos replay`. `None` when the search was abandoned
/// (`control.abandon` raised), as nobody wants its answer. A panic in the search
/// becomes `internal_error`.
pub fn answer_query(
    world: &World,
    request: &RendezvousRequest,
    request_id: u64,
    learned: Option<&Arc<dyfos_shared::sdsmm::Learned>>,
    control: &SearchControl,
) -> Option<RendezvousReply> {
    let searched = guarded("rendezvous", || {
        let model = NoiseModel::from_params_and_weights(&request.params, learned)
            .map_err(|e| Rejection::new(Status::UnsupportedModel, e.to_string()))?;
        Ok(solve(world, &request.belief, &request.params, &model, request.algorithm, control))
    });
    let stop = match &searched {
        Ok(Ok(answer)) => Some(answer.stop),
        Ok(Err(SearchError::NoFeasiblePose { stop, .. })) => Some(*stop),
        Err(_) => None,
    };
    if stop == Some(StopReason::Abandoned) {
        return None;
    }
    Some(
        match searched.and_then(|solved| {
            solved.map_err(|e @ SearchError::NoFeasiblePose { stop, .. }| {
                let status =
                    if stop == StopReason::Deadline { Status::DeadlineExceeded } else { Status::NoFeasiblePose };
                Rejection::new(status, e.to_string())
            })
        }) {
            Ok(answer) => RendezvousReply::answer(request_id, &answer),
            // The inline deltas (if any) were committed on accepting the query: the
            // reply says which version they made, whatever the search found.
            Err(rejection) => {
                RendezvousReply::rejected(request_id, &Rejection { map_version: Some(world.version()), ..rejection })
            }
        },
    )
}
