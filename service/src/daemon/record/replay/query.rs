//! Replaying one recorded query: rebuild the request, answer it with the daemon's
//! own function on the map version it searched, and compare the reply bit for bit.

use super::{ReplayOptions, Tally};
use crate::daemon::answer_query;
use crate::daemon::record::{RecordedReply, RecordedRequest};
use crate::search::SearchControl;
use dyfos_shared::wire::map::MapId;
use dyfos_shared::world::World;
use std::collections::HashMap;
use std::sync::Arc;

/// The request and reply of a `/dyfosd/rendezvous` message.
fn parse_exchange(json: &serde_json::Value) -> Result<(RecordedRequest, RecordedReply), String> {
    let request = serde_json::from_value(json["request"].clone()).map_err(|e| e.to_string())?;
    let reply = serde_json::from_value(json["reply"].clone()).map_err(|e| e.to_string())?;
    Ok((request, reply))
}

fn short(r: &RecordedReply) -> String {
    if r.status == "ok" {
        format!("ok x = {:?}, E = {:?}, evaluations {:?}, stop {}", r.x, r.cost, r.evaluations, r.stop)
    } else {
        format!("{}: {}", r.status, r.message)
    }
}

/// What replaying one query needs of its file.
pub(super) struct Replay<'a> {
    pub(super) name: &'a str,
    pub(super) worlds: &'a HashMap<(MapId, u64), Arc<World>>,
    pub(super) options: &'a ReplayOptions,
    pub(super) learned: Option<&'a Arc<dyfos_shared::sdsmm::Learned>>,
}

impl Replay<'_> {
    /// Replays one `/dyfosd/rendezvous` message and counts the outcome in `t`.
    pub(super) fn query(&self, json: &serde_json::Value, t: &mut Tally, report: &mut dyn FnMut(&str)) {
        let name = self.name;
        let parsed = parse_exchange(json);
        let request_id = json["request_id"].as_u64().unwrap_or(0);
        let (recorded_request, recorded) = match parsed {
            Ok(p) => p,
            Err(e) => {
                report(&format!("{name}: request {request_id}: unreadable ({e}); not replayed"));
                t.unreplayable += 1;
                return;
            }
        };
        let label = format!(
            "request {request_id} (map {} v{}, {}, seed {})",
            recorded_request.map, recorded.map_version, recorded_request.algorithm, recorded_request.seed
        );
        let mut params = recorded_request.params.clone();
        if let Some(p) = params.as_object_mut() {
            p.extend(self.options.set.iter().map(|(k, v)| (k.clone(), v.clone())));
        }
        let request = match recorded_request.rebuild_with(&params) {
            Ok(r) => r,
            Err(e) => {
                report(&format!("{name}: {label}: {e}; not replayed"));
                t.unreplayable += 1;
                return;
            }
        };
        if json["mode"] == "check" {
            t.checks += 1;
            let base = recorded.map_version.checked_sub(request.deltas.len() as u64);
            let checked = base
                .and_then(|b| self.worlds.get(&(request.map, b)))
                .map(|w| w.apply(&request.deltas).map(|n| n.version()).map_err(|e| e.to_string()));
            match checked {
                Some(Ok(v)) if v == recorded.map_version => {}
                Some(Ok(v)) => {
                    report(&format!(
                        "{name}: {label} (check): DIFFERENT: version {v} now, {} recorded",
                        recorded.map_version
                    ));
                    t.different += 1;
                }
                Some(Err(e)) => {
                    report(&format!("{name}: {label} (check): DIFFERENT: the deltas fail now ({e})"));
                    t.different += 1;
                }
                None => {
                    report(&format!("{name}: {label} (check): its map version is not in the recording; not replayed"));
                    t.unreplayable += 1;
                }
            }
            return;
        }
        if recorded.stop == "deadline" || recorded.status == "deadline_exceeded" {
            if !self.options.quiet {
                report(&format!(
                    "{name}: {label}: stopped at its deadline when recorded; not reproducible, not compared"
                ));
            }
            t.deadline += 1;
            return;
        }
        if request.params.model == dyfos_shared::params::ModelKind::Learned && self.learned.is_none() {
            report(&format!("{name}: {label}: uses the learned model; give its file with --model to replay it"));
            t.unreplayable += 1;
            return;
        }
        let Some(world) = self.worlds.get(&(request.map, recorded.map_version)) else {
            report(&format!(
                "{name}: {label}: map {} at version {} is not in the recording; not replayed",
                request.map, recorded.map_version
            ));
            t.unreplayable += 1;
            return;
        };
        // The recorded deadline only ever stopped the search early, and this one did
        // not stop at it: replay without one.
        let control = SearchControl {
            budget: request.budget,
            threads: self.options.threads,
            ..SearchControl::seeded(request.seed)
        };
        let Some(reply) = answer_query(world, &request, request_id, self.learned, &control) else {
            report(&format!("{name}: {label}: the search was abandoned; not replayed"));
            t.unreplayable += 1;
            return;
        };
        let replayed = RecordedReply::of(&reply);
        if recorded.identical(&replayed) {
            t.identical += 1;
            if !self.options.quiet {
                report(&format!("{name}: {label}: identical"));
            }
            return;
        }
        t.different += 1;
        report(&format!("{name}: {label}: DIFFERENT"));
        report(&format!("  recorded: {}", short(&recorded)));
        report(&format!("  replayed: {}", short(&replayed)));
        if recorded.status == "ok" && replayed.status == "ok" {
            report(&format!("  ΔE = replayed − recorded = {:?}", replayed.cost - recorded.cost));
        }
    }
}
