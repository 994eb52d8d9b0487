//! What a recording holds: its channels (topics, schema names, JSON Schemas). The
//! JSON of each message, written by the recorder and read back by `dyfos replay` bit
//! for bit, is in `exchange.rs` (rendezvous queries) and `map_state.rs` (maps).

use dyfos_shared::params::Params;

/// The channels of a recording: topic, schema name and JSON Schema.
pub mod topics {
    /// The daemon's configuration and build, first message of every file.
    pub const CONFIG: &str = "/dyfosd/config";
    /// The full state of one map, after the configuration in every file.
    pub const MAP_STATE: &str = "/dyfosd/map_state";
    /// A change to a map and the version it produced.
    pub const MAP_CHANGE: &str = "/dyfosd/map_change";
    /// An accepted rendezvous query (solve or check) with its reply.
    pub const RENDEZVOUS: &str = "/dyfosd/rendezvous";
    /// An accepted map request with its reply.
    pub const MAP: &str = "/dyfosd/map";
    /// The recorder's own state: records dropped because the writer fell behind.
    pub const RECORDER: &str = "/dyfosd/recorder";
    /// Every channel, in the order its channel record is written.
    pub const ALL: [&str; 6] = [CONFIG, MAP_STATE, MAP_CHANGE, RENDEZVOUS, MAP, RECORDER];

    /// The schema name of a channel's messages.
    pub fn schema_name(topic: &str) -> &'static str {
        match topic {
            CONFIG => "dyfos.RecordingStart",
            MAP_STATE => "dyfos.MapState",
            MAP_CHANGE => "dyfos.MapChange",
            RENDEZVOUS => "dyfos.RendezvousExchange",
            MAP => "dyfos.MapExchange",
            _ => "dyfos.RecorderStatus",
        }
    }
}

/// What a recording's delta arrays hold.
const DELTAS_DESCRIPTION: &str =
    "map deltas, as in `dyfos map apply` files (docs/deltas.md), e.g. {\"remove_obstacle\": {\"id\": 3}}";

/// The JSON Schema (draft 2020-12) of a channel's messages: the top-level fields
/// and their types, for Foxglove's panels.
pub fn json_schema(topic: &str) -> serde_json::Value {
    use serde_json::json;
    let num = json!({"type": "number"});
    let int = json!({"type": "integer"});
    let nint = json!({"type": ["integer", "null"]});
    let arr = json!({"type": "array"});
    let obj = json!({"type": "object"});
    let str_ = json!({"type": "string"});
    let deltas = json!({"type": "array", "description": DELTAS_DESCRIPTION});
    let properties = match topic {
        topics::CONFIG => json!({
            "build": {"type": "object", "properties": {"name": str_, "version": str_, "profile": str_}},
            "config": obj, "pid": int, "file_index": int, "started_ns": int, "dropped_before": int,
        }),
        topics::MAP_STATE => json!({
            "map": int, "version": int, "bounds": arr, "sun": obj,
            "content": {"type": "array", "description": DELTAS_DESCRIPTION},
        }),
        topics::MAP_CHANGE => json!({
            "map": int, "cause": {"enum": ["create", "apply", "inline", "upload", "delete"]},
            "from_version": nint, "version": int, "deltas": deltas, "state": obj,
        }),
        topics::RENDEZVOUS => json!({
            "mode": {"enum": ["solve", "check"]}, "request_id": int, "received_ns": int, "replied_ns": int,
            "request": {"type": "object", "properties": {
                "map": int, "expected_version": nint, "belief": obj, "deltas": deltas, "algorithm": str_,
                "seed": int, "budget": nint, "deadline_ns": nint, "params": obj}},
            "reply": {"type": "object", "properties": {
                "status": str_, "algorithm": str_, "stop": str_, "map_version": int, "x": arr, "cost": num,
                "sensor_position": arr, "sensor_quaternion": arr, "viewer_position": arr, "viewer_yaw": num,
                "r": arr, "posterior": arr, "evaluations": arr, "micros": int, "daemon_micros": int,
                "error_index": nint, "message": str_}},
        }),
        topics::MAP => json!({
            "kind": {"enum": ["create", "apply", "upload", "snapshot", "delete", "list"]}, "request_id": int, "map": int,
            "received_ns": int, "replied_ns": int, "request": obj,
            "reply": {"type": "object", "properties": {
                "status": str_, "version": int, "chunk_index": int, "chunk_count": int, "map": int}},
        }),
        _ => json!({"dropped_total": int, "dropped_new": int, "reason": str_}),
    };
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": topics::schema_name(topic),
        "type": "object",
        "properties": properties,
    })
}

/// Every SPEC §11 parameter by its scenario name (what
/// [`dyfos_shared::scenario::params_from_json`] reads back, bit for bit).
pub fn params_to_json(p: &Params) -> serde_json::Value {
    dyfos_shared::scenario::params_to_json(p)
}
