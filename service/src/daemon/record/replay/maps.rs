//! Every map version a recording saw, rebuilt from its states and changes.

use crate::daemon::record::MapChange;
use dyfos_shared::wire::map::MapId;
use dyfos_shared::world::World;
use std::collections::HashMap;
use std::sync::Arc;

/// Rebuilds the map version a change produced.
pub(super) fn apply_change(
    json: serde_json::Value,
    worlds: &mut HashMap<(MapId, u64), Arc<World>>,
) -> Result<(), String> {
    let change: MapChange = serde_json::from_value(json).map_err(|e| format!("unreadable map change: {e}"))?;
    let map = change.map;
    if let Some(state) = &change.state {
        let w = state.rebuild().map_err(|e| format!("map {map} version {}: {e}", change.version))?;
        worlds.insert((map, change.version), Arc::new(w));
        return Ok(());
    }
    let Some(from) = change.from_version else {
        // A deletion: the versions stay, queries in flight may need them.
        return Ok(());
    };
    let base = worlds.get(&(map, from)).ok_or_else(|| {
        format!(
            "map {map} version {} cannot be rebuilt: version {from} is not in the recording (records dropped?)",
            change.version
        )
    })?;
    let next = base.apply(&change.deltas).map_err(|e| format!("map {map}: the recorded deltas fail now: {e}"))?;
    if next.version() != change.version {
        return Err(format!("map {map}: the deltas made version {}, the daemon's {}", next.version(), change.version));
    }
    worlds.insert((map, change.version), Arc::new(next));
    Ok(())
}
