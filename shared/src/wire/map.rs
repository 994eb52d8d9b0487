//! The map service (`<prefix>map`): create a map, apply a batch of deltas, upload a
//! whole map in chunks, snapshot it back in pages, delete it, list the maps (SPEC §1).
//!
//! Map content travels as a slice of fixed-size [`WireDelta`] records. One
//! [`MapDelta`] is one record, except `SetVoxels`, which is a run header followed
//! by one record per cell, and `SetVoxelBlocks`, a run header followed by one
//! record per 4³ block (up to 64 cells a record: uploads and snapshots of voxel
//! maps use blocks). A batch is applied whole or not at all; its error names
//! the failing delta's index in the batch.
//!
//! A map larger than one message ([`MAX_DELTAS_PER_MESSAGE`] records) is uploaded
//! as numbered chunks `0..chunk_count` of one `upload_id`, each self-contained
//! ([`world_chunks`]); the daemon builds the map only when the last chunk arrives in
//! order. *Interpretation:* an upload replaces the map whole, which counts as one
//! change (version + 1), and a new map starts at version 0, so a scenario uploaded
//! to a fresh id answers with `map_version` 0, as `dyfos solve` does.
//!
//! ```
//! use dyfos_shared::wire::map::{MapRequest, decode_deltas, encode_deltas};
//! use dyfos_shared::world::{MapDelta, Sun};
//!
//! let batch = vec![MapDelta::SetSun(Sun::new(0.5, 1.0).unwrap()), MapDelta::RemoveObstacle { id: 3 }];
//! let records = encode_deltas(&batch);
//! assert_eq!(decode_deltas(&records).unwrap(), batch);
//! let request = MapRequest::Apply { map: 7, expected_version: Some(2), deltas: batch };
//! let header = request.header(1, [0, 0]);
//! assert_eq!(MapRequest::decode(&header, &request.records()).unwrap(), request);
//! ```

use super::{ANY_VERSION, Detail, Rejection, Status};
use crate::limits::{MAX_DELTAS_PER_MESSAGE, MAX_UPLOAD_CHUNKS};
use crate::math::{Point2, Point3};
use crate::world::{
    AxisBox, Bounds, CellIndex, MapDelta, MapDeltaError, MapDeltaErrorKind, Obstacle, Sun, VerticalCylinder,
    VoxelBlock, VoxelError, VoxelGrid, World,
};
use iceoryx2::prelude::ZeroCopySend;

/// A map id, chosen by the client that creates the map.
pub type MapId = u64;

/// A module of `u32` wire codes: one constant per code, plus `ALL`, every code with
/// its constant's name in code order, from which documentation checks and error
/// messages take the valid codes (so a new code cannot be left out of them).
macro_rules! wire_codes {
    ($(#[$m:meta])* $module:ident { $($(#[$doc:meta])* $name:ident = $value:literal;)* }) => {
        $(#[$m])*
        pub mod $module {
            $($(#[$doc])* pub const $name: u32 = $value;)*
            /// Every code and its constant's name, in code order.
            pub const ALL: &[(u32, &str)] = &[$(($name, stringify!($name)),)*];

            /// The valid codes for an error message, e.g. `1 (UPSERT_CYLINDER) ..= 10
            /// (VOXEL_BLOCK)`: the codes are consecutive (a unit test checks it).
            pub fn range() -> String {
                match (ALL.first(), ALL.last()) {
                    (Some((a, first)), Some((b, last))) => format!("{a} ({first}) ..= {b} ({last})"),
                    _ => String::new(),
                }
            }
        }
    };
}

wire_codes! {
    /// Record tags of [`WireDelta`].
    tag {
        /// Upsert a vertical cylinder: `id`, values `[x, y, radius, height]`.
        UPSERT_CYLINDER = 1;
        /// Upsert an axis-aligned box: `id`, values `[min x, y, z, max x, y, z]`.
        UPSERT_BOX = 2;
        /// Remove obstacle `id`.
        REMOVE_OBSTACLE = 3;
        /// Voxel run header: values `[resolution, origin x, y, z]`, `flag` 1 occupied /
        /// 0 free, `cell[0]` the number of [`VOXEL_CELL`] records that follow.
        VOXEL_RUN = 4;
        /// One cell of the preceding run: `cell`.
        VOXEL_CELL = 5;
        /// Set the sun: values `[elevation, azimuth]`.
        SET_SUN = 6;
        /// Set the bounds: values `[x_min, y_min, x_max, y_max]`.
        SET_BOUNDS = 7;
        /// Remove every obstacle and voxel.
        CLEAR = 8;
        /// Voxel block run header: as [`VOXEL_RUN`], `cell[0]` the number of
        /// [`VOXEL_BLOCK`] records that follow.
        VOXEL_BLOCK_RUN = 9;
        /// One 4³ block of the preceding block run: `cell` its minimum cell (each index a
        /// multiple of 4), the 64-bit cell mask in `id` (low half) and `flag` (high half);
        /// cell `cell + (x, y, z)` is bit `16x + 4y + z`.
        VOXEL_BLOCK = 10;
    }
}

/// One map-delta record. Fields a tag does not use are ignored (write zeros);
/// `reserved` must be 0 and `flag` is 0 except in a voxel run header and a voxel
/// block.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("dyfos::WireDelta")]
#[repr(C)]
pub struct WireDelta {
    /// One of [`tag`].
    pub tag: u32,
    /// Voxel run header: 1 occupied, 0 free; voxel block: the mask's high half.
    pub flag: u32,
    /// Obstacle id; voxel block: the mask's low half.
    pub id: u32,
    /// Must be 0.
    pub reserved: u32,
    /// Numbers, by tag.
    pub values: [f64; 6],
    /// Cell index, or the run length in a run header.
    pub cell: [i64; 3],
}

wire_codes! {
    /// Map operations ([`MapRequestHeader::op`]).
    op {
        /// Create an empty map with `bounds` and `sun`.
        CREATE = 1;
        /// Apply the records as one atomic batch.
        APPLY = 2;
        /// One chunk of a whole-map upload.
        UPLOAD = 3;
        /// Page `chunk_index` of the map's content.
        SNAPSHOT = 4;
        /// Delete the map.
        DELETE = 5;
        /// Describe the map with the smallest id at or after `map_id` (a cursor walk,
        /// [`MapInfo`]); no records.
        LIST = 6;
    }
}

/// [`MapRequestHeader::flags`] bit of an upload: replace an existing map.
pub const FLAG_REPLACE: u32 = 1;

/// The fixed part of a map request (the iceoryx2 request user header).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("dyfos::MapRequestHeader")]
#[repr(C)]
pub struct MapRequestHeader {
    /// One of [`op`].
    pub op: u32,
    /// Upload: [`FLAG_REPLACE`]; otherwise 0.
    pub flags: u32,
    /// The map; list: the cursor, the smallest id to describe.
    pub map_id: u64,
    /// Apply, upload-replace, delete: the version the map must have, or [`ANY_VERSION`].
    pub expected_version: u64,
    /// The client's id for this request, echoed in the reply.
    pub request_id: u64,
    /// Upload: the client's id of the whole upload.
    pub upload_id: u64,
    /// Upload: this chunk's number; snapshot: the page wanted.
    pub chunk_index: u32,
    /// Upload: the number of chunks.
    pub chunk_count: u32,
    /// Create and upload: `[x_min, y_min, x_max, y_max]`.
    pub bounds: [f64; 4],
    /// Create and upload: `[elevation, azimuth]`.
    pub sun: [f64; 2],
    /// The client's reply listener id ([`super::split_u128`]).
    pub reply_to: [u64; 2],
}

/// The fixed part of a map reply (the iceoryx2 response user header); a snapshot
/// page's content is the response's record slice.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("dyfos::MapReplyHeader")]
#[repr(C)]
pub struct MapReplyHeader {
    /// A [`Status`] code.
    pub status: u32,
    /// Snapshot: this page's number; upload: the chunk acknowledged.
    pub chunk_index: u32,
    /// Snapshot: the number of pages; list: the number of maps at or after the
    /// cursor (0: none, and no map is described).
    pub chunk_count: u32,
    /// Snapshot and list: the map's generation, a number the daemon picks when the
    /// map is made (created, uploaded or loaded at start). A map deleted and made
    /// again under its id starts again at version 0 but has another generation, so
    /// a client paging a snapshot starts again if a page's generation or version
    /// differs from page 0's. 0 in every other reply.
    pub generation: u32,
    /// The request's id.
    pub request_id: u64,
    /// The map (list: the map described, or the cursor if none).
    pub map_id: u64,
    /// The map's version after the operation (snapshot: the version paged; list:
    /// the described map's).
    pub version: u64,
    /// Snapshot and list: the map's bounds.
    pub bounds: [f64; 4],
    /// Snapshot and list: the map's sun.
    pub sun: [f64; 2],
    /// For delta errors, the failing delta's index, else `u64::MAX`.
    pub error_index: u64,
    /// What went wrong, for people.
    pub detail: Detail,
}

/// A validated map request.
#[derive(Debug, Clone, PartialEq)]
pub enum MapRequest {
    /// Create an empty map at version 0.
    Create {
        /// Its id (must be free).
        map: MapId,
        /// Bounds.
        bounds: Bounds,
        /// Sun.
        sun: Sun,
    },
    /// Apply a batch of deltas atomically.
    Apply {
        /// The map.
        map: MapId,
        /// The version it must have, or `None` for any.
        expected_version: Option<u64>,
        /// The batch.
        deltas: Vec<MapDelta>,
    },
    /// One chunk of a whole-map upload.
    Upload {
        /// The map.
        map: MapId,
        /// The client's id of this upload.
        upload_id: u64,
        /// This chunk's number, from 0.
        chunk_index: u32,
        /// Chunks in the upload, 1..=[`MAX_UPLOAD_CHUNKS`].
        chunk_count: u32,
        /// Whether an existing map may be replaced.
        replace: bool,
        /// When replacing, the version the map must have.
        expected_version: Option<u64>,
        /// The new map's bounds.
        bounds: Bounds,
        /// The new map's sun.
        sun: Sun,
        /// This chunk's content (obstacle upserts and voxel runs).
        deltas: Vec<MapDelta>,
    },
    /// One page of the map's content.
    Snapshot {
        /// The map.
        map: MapId,
        /// The page, from 0.
        page: u32,
    },
    /// Delete the map.
    Delete {
        /// The map.
        map: MapId,
        /// The version it must have, or `None` for any.
        expected_version: Option<u64>,
    },
    /// Describe the map with the smallest id at or after `from`.
    List {
        /// The cursor: 0 first, then the id last described + 1.
        from: MapId,
    },
}

fn version_of(v: u64) -> Option<u64> {
    (v != ANY_VERSION).then_some(v)
}

fn malformed(message: impl Into<String>) -> Rejection {
    Rejection::new(Status::MalformedRequest, message)
}

/// Bounds from the wire, or `invalid_delta` naming the field.
pub fn decode_bounds(b: [f64; 4]) -> Result<Bounds, Rejection> {
    Bounds::new(b).map_err(|e| Rejection::new(Status::InvalidDelta, e.to_string()))
}

/// A sun from the wire, or `invalid_delta` naming the field.
pub fn decode_sun(s: [f64; 2]) -> Result<Sun, Rejection> {
    Sun::new(s[0], s[1]).map_err(|e| Rejection::new(Status::InvalidDelta, e.to_string()))
}

impl MapRequest {
    /// Decodes and checks a request's shape: operation, flags, chunk numbering,
    /// record count and records. Map content is validated when applied.
    pub fn decode(h: &MapRequestHeader, records: &[WireDelta]) -> Result<Self, Rejection> {
        Rejection::at_most(
            records.len(),
            MAX_DELTAS_PER_MESSAGE,
            "records",
            " per message; upload large maps in chunks",
        )?;
        let no_records = |what: &str| {
            if records.is_empty() {
                Ok(())
            } else {
                Err(malformed(format!("{what} carries no records, got {}", records.len())))
            }
        };
        let no_flags = |what: &str| {
            if h.flags == 0 { Ok(()) } else { Err(malformed(format!("{what}: flags = {} must be 0", h.flags))) }
        };
        let map = h.map_id;
        match h.op {
            op::CREATE => {
                no_flags("create")?;
                no_records("create")?;
                Ok(MapRequest::Create { map, bounds: decode_bounds(h.bounds)?, sun: decode_sun(h.sun)? })
            }
            op::APPLY => {
                no_flags("apply")?;
                Ok(MapRequest::Apply {
                    map,
                    expected_version: version_of(h.expected_version),
                    deltas: decode_batch(records)?,
                })
            }
            op::UPLOAD => {
                if h.flags & !FLAG_REPLACE != 0 {
                    return Err(malformed(format!("upload: flags = {} has unknown bits", h.flags)));
                }
                if h.chunk_count == 0 || h.chunk_count > MAX_UPLOAD_CHUNKS {
                    return Err(Rejection::new(
                        Status::OverCapacity,
                        format!("upload: chunk_count = {} must be in 1..={MAX_UPLOAD_CHUNKS}", h.chunk_count),
                    ));
                }
                if h.chunk_index >= h.chunk_count {
                    return Err(Rejection::new(
                        Status::ChunkOutOfOrder,
                        format!("upload: chunk_index = {} is past chunk_count = {}", h.chunk_index, h.chunk_count),
                    ));
                }
                let deltas = decode_deltas(records)?;
                if let Some(i) = deltas.iter().position(|d| {
                    !matches!(
                        d,
                        MapDelta::UpsertObstacle { .. }
                            | MapDelta::SetVoxels { occupied: true, .. }
                            | MapDelta::SetVoxelBlocks { occupied: true, .. }
                    )
                }) {
                    return Err(Rejection::at_delta(
                        Status::MalformedDelta,
                        format!(
                            "upload chunks carry only obstacle upserts and occupied voxel runs; delta #{i} is not one"
                        ),
                        i as u64,
                    ));
                }
                Ok(MapRequest::Upload {
                    map,
                    upload_id: h.upload_id,
                    chunk_index: h.chunk_index,
                    chunk_count: h.chunk_count,
                    replace: h.flags & FLAG_REPLACE != 0,
                    expected_version: version_of(h.expected_version),
                    bounds: decode_bounds(h.bounds)?,
                    sun: decode_sun(h.sun)?,
                    deltas,
                })
            }
            op::SNAPSHOT => {
                no_flags("snapshot")?;
                no_records("snapshot")?;
                Ok(MapRequest::Snapshot { map, page: h.chunk_index })
            }
            op::DELETE => {
                no_flags("delete")?;
                no_records("delete")?;
                Ok(MapRequest::Delete { map, expected_version: version_of(h.expected_version) })
            }
            op::LIST => {
                no_flags("list")?;
                no_records("list")?;
                Ok(MapRequest::List { from: map })
            }
            other => Err(malformed(format!("op = {other} is not a map operation ({})", op::range()))),
        }
    }

    /// The map this request is about (list: the cursor), its header's `map_id`.
    pub fn map(&self) -> MapId {
        match self {
            MapRequest::Create { map, .. }
            | MapRequest::Apply { map, .. }
            | MapRequest::Upload { map, .. }
            | MapRequest::Snapshot { map, .. }
            | MapRequest::Delete { map, .. }
            | MapRequest::List { from: map } => *map,
        }
    }

    /// The header to send.
    pub fn header(&self, request_id: u64, reply_to: [u64; 2]) -> MapRequestHeader {
        let mut h = MapRequestHeader {
            map_id: self.map(),
            request_id,
            reply_to,
            expected_version: ANY_VERSION,
            ..Default::default()
        };
        match self {
            MapRequest::Create { bounds, sun, .. } => {
                h.op = op::CREATE;
                h.bounds = bounds.to_array();
                h.sun = [sun.elevation, sun.azimuth];
            }
            MapRequest::Apply { expected_version, .. } => {
                h.op = op::APPLY;
                h.expected_version = expected_version.unwrap_or(ANY_VERSION);
            }
            MapRequest::Upload {
                upload_id, chunk_index, chunk_count, replace, expected_version, bounds, sun, ..
            } => {
                h.op = op::UPLOAD;
                h.flags = if *replace { FLAG_REPLACE } else { 0 };
                h.upload_id = *upload_id;
                h.chunk_index = *chunk_index;
                h.chunk_count = *chunk_count;
                h.expected_version = expected_version.unwrap_or(ANY_VERSION);
                h.bounds = bounds.to_array();
                h.sun = [sun.elevation, sun.azimuth];
            }
            MapRequest::Snapshot { page, .. } => {
                h.op = op::SNAPSHOT;
                h.chunk_index = *page;
            }
            MapRequest::Delete { expected_version, .. } => {
                h.op = op::DELETE;
                h.expected_version = expected_version.unwrap_or(ANY_VERSION);
            }
            MapRequest::List { .. } => h.op = op::LIST,
        }
        h
    }

    /// The records to send.
    pub fn records(&self) -> Vec<WireDelta> {
        match self {
            MapRequest::Apply { deltas, .. } | MapRequest::Upload { deltas, .. } => encode_deltas(deltas),
            _ => Vec::new(),
        }
    }
}

/// One map as a list reply describes it ([`MapRequest::List`]).
///
/// To list every map, ask from 0, then from the id described + 1, until a reply
/// describes none (at most [`crate::limits::MAX_MAPS`] maps exist at once). The list
/// is not a snapshot of one moment: a map made or deleted while it is walked may or
/// may not be in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapInfo {
    /// The map's id.
    pub id: MapId,
    /// Its version.
    pub version: u64,
    /// Its generation ([`MapReplyHeader::generation`]): another one if the map was
    /// deleted and made again under its id.
    pub generation: u32,
    /// Its bounds.
    pub bounds: Bounds,
    /// Its sun.
    pub sun: Sun,
}

impl MapInfo {
    /// The map a successful reply to a list request from the cursor `from`
    /// describes, or `None` if it says no map is at or after the cursor. The reply
    /// is checked as the daemon checks requests: a map before the cursor, bounds or
    /// a sun that are not valid are errors.
    pub fn from_list_reply(from: MapId, h: &MapReplyHeader) -> Result<Option<MapInfo>, Rejection> {
        if h.chunk_count == 0 {
            return Ok(None);
        }
        if h.map_id < from {
            return Err(malformed(format!(
                "malformed reply: a list from map {from} described map {}, before it",
                h.map_id
            )));
        }
        Ok(Some(MapInfo {
            id: h.map_id,
            version: h.version,
            generation: h.generation,
            bounds: decode_bounds(h.bounds)?,
            sun: decode_sun(h.sun)?,
        }))
    }

    /// As JSON, for `dyfos map list`: `map`, `version`, `generation`, and `bounds`
    /// and `sun` as a scenario writes them.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "map": self.id,
            "version": self.version,
            "generation": self.generation,
            "bounds": self.bounds.to_array(),
            "sun": {"elevation": self.sun.elevation, "azimuth": self.sun.azimuth},
        })
    }
}

/// Number of records `delta` takes.
pub fn record_count(delta: &MapDelta) -> usize {
    match delta {
        MapDelta::SetVoxels { cells, .. } => 1 + cells.len(),
        MapDelta::SetVoxelBlocks { blocks, .. } => 1 + blocks.len(),
        _ => 1,
    }
}

/// The header of a voxel run (`VOXEL_RUN`) or block run (`VOXEL_BLOCK_RUN`) of `n` records.
fn run_header(tag: u32, resolution: f64, origin: &Point3<f64>, occupied: bool, n: usize) -> WireDelta {
    let mut r = WireDelta { tag, flag: u32::from(occupied), ..Default::default() };
    r.values[..4].copy_from_slice(&[resolution, origin.x, origin.y, origin.z]);
    r.cell[0] = n as i64;
    r
}

fn push_delta(out: &mut Vec<WireDelta>, delta: &MapDelta) {
    let mut r = WireDelta::default();
    match delta {
        MapDelta::UpsertObstacle { id, obstacle: Obstacle::Cylinder(c) } => {
            r.tag = tag::UPSERT_CYLINDER;
            r.id = *id;
            r.values[..4].copy_from_slice(&[c.center.x, c.center.y, c.radius, c.height]);
        }
        MapDelta::UpsertObstacle { id, obstacle: Obstacle::Box(b) } => {
            r.tag = tag::UPSERT_BOX;
            r.id = *id;
            r.values = [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z];
        }
        MapDelta::RemoveObstacle { id } => {
            r.tag = tag::REMOVE_OBSTACLE;
            r.id = *id;
        }
        MapDelta::SetVoxels { resolution, origin, cells, occupied } => {
            out.push(run_header(tag::VOXEL_RUN, *resolution, origin, *occupied, cells.len()));
            out.extend(cells.iter().map(|c| WireDelta { tag: tag::VOXEL_CELL, cell: *c, ..Default::default() }));
            return;
        }
        MapDelta::SetVoxelBlocks { resolution, origin, blocks, occupied } => {
            out.push(run_header(tag::VOXEL_BLOCK_RUN, *resolution, origin, *occupied, blocks.len()));
            out.extend(blocks.iter().map(|b| WireDelta {
                tag: tag::VOXEL_BLOCK,
                id: b.mask as u32,
                flag: (b.mask >> 32) as u32,
                cell: b.min,
                ..Default::default()
            }));
            return;
        }
        MapDelta::SetSun(s) => {
            r.tag = tag::SET_SUN;
            r.values[..2].copy_from_slice(&[s.elevation, s.azimuth]);
        }
        MapDelta::SetBounds(b) => {
            r.tag = tag::SET_BOUNDS;
            r.values[..4].copy_from_slice(&b.to_array());
        }
        MapDelta::Clear => r.tag = tag::CLEAR,
    }
    out.push(r);
}

/// The records of a batch of deltas.
pub fn encode_deltas(deltas: &[MapDelta]) -> Vec<WireDelta> {
    let mut out = Vec::with_capacity(deltas.iter().map(record_count).sum());
    for d in deltas {
        push_delta(&mut out, d);
    }
    out
}

/// Decodes records into deltas. Checks tags, flags, reserved fields and voxel runs;
/// numbers are checked when the deltas are applied ([`World::apply`]). Sun and
/// bounds records are not range-checked here either: the map does that.
pub fn decode_deltas(records: &[WireDelta]) -> Result<Vec<MapDelta>, Rejection> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < records.len() {
        let r = records[i];
        let index = out.len() as u64;
        let bad = |message: String| Rejection::at_delta(Status::MalformedDelta, message, index);
        if r.reserved != 0 {
            return Err(bad(format!("record {i}: reserved = {} must be 0", r.reserved)));
        }
        if r.tag != tag::VOXEL_RUN && r.tag != tag::VOXEL_BLOCK_RUN && r.flag != 0 {
            return Err(bad(format!("record {i}: flag = {} must be 0 for tag {}", r.flag, r.tag)));
        }
        let v = r.values;
        let delta = match r.tag {
            tag::UPSERT_CYLINDER => MapDelta::UpsertObstacle {
                id: r.id,
                obstacle: Obstacle::Cylinder(VerticalCylinder {
                    center: Point2::new(v[0], v[1]),
                    radius: v[2],
                    height: v[3],
                }),
            },
            tag::UPSERT_BOX => MapDelta::UpsertObstacle {
                id: r.id,
                obstacle: Obstacle::Box(AxisBox {
                    min: Point3::new(v[0], v[1], v[2]),
                    max: Point3::new(v[3], v[4], v[5]),
                }),
            },
            tag::REMOVE_OBSTACLE => MapDelta::RemoveObstacle { id: r.id },
            tag::VOXEL_RUN | tag::VOXEL_BLOCK_RUN => {
                let occupied = match r.flag {
                    0 => false,
                    1 => true,
                    f => return Err(bad(format!("record {i}: voxel run flag = {f} must be 0 (free) or 1 (occupied)"))),
                };
                let remaining = (records.len() - i - 1) as i64;
                let n = r.cell[0];
                let (what, item) =
                    if r.tag == tag::VOXEL_RUN { ("cell", tag::VOXEL_CELL) } else { ("block", tag::VOXEL_BLOCK) };
                if !(0..=remaining).contains(&n) {
                    return Err(bad(format!(
                        "record {i}: voxel run of {n} {what}s, but {remaining} records follow (truncated run)"
                    )));
                }
                let items = &records[i + 1..i + 1 + n as usize];
                let stray =
                    |c: &WireDelta| c.tag != item || c.reserved != 0 || (item == tag::VOXEL_CELL && c.flag != 0);
                if let Some(k) = items.iter().position(stray) {
                    return Err(bad(format!("record {}: expected a voxel {what} record of the run at {i}", i + 1 + k)));
                }
                let (resolution, origin) = (v[0], Point3::new(v[1], v[2], v[3]));
                out.push(if item == tag::VOXEL_CELL {
                    MapDelta::SetVoxels { resolution, origin, cells: items.iter().map(|c| c.cell).collect(), occupied }
                } else {
                    let blocks = items
                        .iter()
                        .map(|b| VoxelBlock { min: b.cell, mask: u64::from(b.flag) << 32 | u64::from(b.id) })
                        .collect();
                    MapDelta::SetVoxelBlocks { resolution, origin, blocks, occupied }
                });
                i += 1 + n as usize;
                continue;
            }
            tag::VOXEL_BLOCK => return Err(bad(format!("record {i}: voxel block outside a block run"))),
            tag::VOXEL_CELL => return Err(bad(format!("record {i}: voxel cell outside a run"))),
            tag::SET_SUN => MapDelta::SetSun(Sun { elevation: v[0], azimuth: v[1] }),
            tag::SET_BOUNDS => {
                MapDelta::SetBounds(Bounds { min: Point2::new(v[0], v[1]), max: Point2::new(v[2], v[3]) })
            }
            tag::CLEAR => MapDelta::Clear,
            t => {
                return Err(bad(format!("record {i}: tag = {t} is not a delta record tag ({})", tag::range())));
            }
        };
        out.push(delta);
        i += 1;
    }
    Ok(out)
}

/// Decodes the records of a batch of changes (an apply request, a rendezvous
/// request's inline deltas): [`decode_deltas`], and every voxel run or block run has
/// at least one record. A run of none changes no cell, yet the first one would fix a
/// map without voxels to its resolution and origin, so that a later run at another
/// resolution is refused: that is never what a change means. (A whole map's content,
/// an upload's chunks or a snapshot's pages, may carry one to describe a voxel grid
/// with no cells.)
pub fn decode_batch(records: &[WireDelta]) -> Result<Vec<MapDelta>, Rejection> {
    let deltas = decode_deltas(records)?;
    let empty = deltas.iter().position(|d| match d {
        MapDelta::SetVoxels { cells, .. } => cells.is_empty(),
        MapDelta::SetVoxelBlocks { blocks, .. } => blocks.is_empty(),
        _ => false,
    });
    if let Some(i) = empty {
        return Err(Rejection::at_delta(
            Status::MalformedDelta,
            format!(
                "delta #{i}: a voxel run of 0 cells (or blocks) changes nothing, but would fix the map's voxel grid; send runs of at least one"
            ),
            i as u64,
        ));
    }
    Ok(deltas)
}

/// A map's content (obstacles, then occupied voxels) as self-contained chunks of at
/// most [`MAX_DELTAS_PER_MESSAGE`] records each (an upload's chunks); at least one
/// chunk, maybe empty.
pub fn world_chunks(world: &World) -> Vec<Vec<WireDelta>> {
    world_chunks_of(world, MAX_DELTAS_PER_MESSAGE)
}

/// [`world_chunks`] with at most `max_records` records a chunk (at least 2: a voxel
/// run's header and one block); the daemon's snapshot pages use
/// [`crate::limits::SNAPSHOT_PAGE_RECORDS`].
pub fn world_chunks_of(world: &World, max_records: usize) -> Vec<Vec<WireDelta>> {
    let max_records = max_records.clamp(2, MAX_DELTAS_PER_MESSAGE);
    let mut chunks: Vec<Vec<WireDelta>> = vec![Vec::new()];
    let room = |chunks: &mut Vec<Vec<WireDelta>>, need: usize| {
        if chunks.last().is_some_and(|c| c.len() + need > max_records) {
            chunks.push(Vec::new());
        }
    };
    for (id, obstacle) in world.obstacles() {
        room(&mut chunks, 1);
        push_delta(chunks.last_mut().expect("one chunk"), &MapDelta::UpsertObstacle { id: *id, obstacle: *obstacle });
    }
    if let Some(grid) = world.voxels() {
        let mut blocks = grid.blocks().peekable();
        // A grid with no cells still carries its resolution and origin.
        loop {
            room(&mut chunks, 2.min(1 + usize::from(blocks.peek().is_some())));
            let chunk = chunks.last_mut().expect("one chunk");
            let take = max_records - chunk.len() - 1;
            let run = MapDelta::SetVoxelBlocks {
                resolution: grid.resolution(),
                origin: grid.origin(),
                blocks: blocks.by_ref().take(take).collect(),
                occupied: true,
            };
            push_delta(chunk, &run);
            if blocks.peek().is_none() {
                break;
            }
        }
    }
    chunks
}

/// The map with `bounds`, `sun` and the content `deltas` (obstacle upserts and
/// occupied voxel runs, as [`world_chunks`] makes them, in any order), at `version`.
///
/// A map's content is a set of obstacles and occupied cells, so the order of its
/// deltas does not matter (an id upserted twice keeps the later obstacle): every
/// voxel run, whatever its place or kind, goes into one build of the grid, as
/// applying runs one by one would rebuild it once per run. Other deltas (not made by
/// [`world_chunks`]) are applied in their order, before the voxels. An error names
/// the failing delta's index in `deltas`; for the cells together past a limit, the
/// first voxel run's.
pub fn world_from_content(version: u64, bounds: Bounds, sun: Sun, deltas: &[MapDelta]) -> Result<World, MapDeltaError> {
    /// The voxel runs gathered, and the grid they name.
    struct Grid {
        first: usize,
        resolution: f64,
        origin: Point3<f64>,
        cells: Option<Vec<CellIndex>>,
        blocks: Option<Vec<VoxelBlock>>,
    }
    let at = |index: usize| move |kind: MapDeltaErrorKind| MapDeltaError { index, kind };
    let mut rest: Vec<MapDelta> = Vec::new();
    let mut rest_index: Vec<usize> = Vec::new();
    let mut grid: Option<Grid> = None;
    for (i, d) in deltas.iter().enumerate() {
        let (resolution, origin) = match d {
            MapDelta::SetVoxels { resolution, origin, occupied: true, .. }
            | MapDelta::SetVoxelBlocks { resolution, origin, occupied: true, .. } => (*resolution, *origin),
            other => {
                rest.push(other.clone());
                rest_index.push(i);
                continue;
            }
        };
        let g = match &mut grid {
            None => {
                VoxelGrid::empty(resolution, origin).map_err(|e| at(i)(e.into()))?;
                grid.insert(Grid { first: i, resolution, origin, cells: None, blocks: None })
            }
            Some(g) if g.resolution == resolution && g.origin == origin => g,
            Some(g) => {
                return Err(at(i)(MapDeltaErrorKind::VoxelGridMismatch {
                    have_resolution: g.resolution,
                    have_origin: g.origin.coords.into(),
                    resolution,
                    origin: origin.coords.into(),
                }));
            }
        };
        match d {
            MapDelta::SetVoxels { cells, .. } => g.cells.get_or_insert_with(Vec::new).extend_from_slice(cells),
            MapDelta::SetVoxelBlocks { blocks, .. } => g.blocks.get_or_insert_with(Vec::new).extend_from_slice(blocks),
            _ => {}
        }
    }
    let world = World::empty(bounds, sun)
        .apply(&rest)
        .map_err(|e| MapDeltaError { index: rest_index.get(e.index).copied().unwrap_or(e.index), kind: e.kind })?;
    let Some(g) = grid else { return Ok(world.at_version(version)) };
    let (resolution, origin) = (g.resolution, g.origin);
    let mut runs = Vec::new();
    if let Some(cells) = g.cells {
        runs.push(MapDelta::SetVoxels { resolution, origin, cells, occupied: true });
    }
    if let Some(blocks) = g.blocks {
        runs.push(MapDelta::SetVoxelBlocks { resolution, origin, blocks, occupied: true });
    }
    let world = world
        .apply(&runs)
        .map_err(|e| MapDeltaError { index: run_at_fault(deltas, &e.kind).unwrap_or(g.first), kind: e.kind })?;
    Ok(world.at_version(version))
}

/// The index of the first voxel run in `deltas` holding the cell or block a
/// grid error names, if it names one.
fn run_at_fault(deltas: &[MapDelta], kind: &MapDeltaErrorKind) -> Option<usize> {
    let holds = |d: &MapDelta| match (kind, d) {
        (MapDeltaErrorKind::Voxels(VoxelError::IndexOutOfRange { index }), MapDelta::SetVoxels { cells, .. }) => {
            cells.contains(index)
        }
        (MapDeltaErrorKind::Voxels(VoxelError::IndexOutOfRange { index }), MapDelta::SetVoxelBlocks { blocks, .. }) => {
            blocks.iter().any(|b| b.min == *index || b.cells().any(|c| c == *index))
        }
        (MapDeltaErrorKind::Voxels(VoxelError::MisalignedBlock { min }), MapDelta::SetVoxelBlocks { blocks, .. }) => {
            blocks.iter().any(|b| b.min == *min)
        }
        _ => false,
    };
    deltas.iter().position(holds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::VoxelGrid;

    fn sample_world(cells: usize, obstacles: u32) -> World {
        let voxels =
            VoxelGrid::new(0.25, Point3::new(-1.0, -2.0, 0.0), (0..cells as i64).map(|i| [i % 97, i / 97, i % 5]))
                .unwrap();
        let obs = (0..obstacles).map(|i| {
            (
                i * 2 + 1,
                Obstacle::Cylinder(VerticalCylinder {
                    center: Point2::new(f64::from(i), 0.5),
                    radius: 0.3,
                    height: 2.0,
                }),
            )
        });
        World::new(4, Bounds::new([-10.0, -10.0, 10.0, 10.0]).unwrap(), Sun::new(0.3, 1.0).unwrap(), obs, Some(voxels))
            .unwrap()
    }

    #[test]
    fn world_round_trips_through_chunks() {
        for (cells, obstacles) in [(0, 0), (3, 2), (MAX_DELTAS_PER_MESSAGE * 2 + 7, 5000)] {
            let world = sample_world(cells, obstacles);
            for max in [MAX_DELTAS_PER_MESSAGE, crate::limits::SNAPSHOT_PAGE_RECORDS, 2] {
                let chunks = world_chunks_of(&world, max);
                assert!(chunks.iter().all(|c| c.len() <= max), "max {max}");
                if max == MAX_DELTAS_PER_MESSAGE {
                    assert_eq!(chunks, world_chunks(&world));
                }
                let deltas: Vec<MapDelta> = chunks.iter().flat_map(|c| decode_deltas(c).unwrap()).collect();
                let back = world_from_content(4, *world.bounds(), *world.sun(), &deltas).unwrap();
                assert_eq!(back, world, "{cells} cells, {obstacles} obstacles, pages of {max}");
            }
        }
    }

    #[test]
    fn malformed_records_are_rejected_with_their_index() {
        let good = encode_deltas(&[
            MapDelta::Clear,
            MapDelta::SetVoxels { resolution: 1.0, origin: Point3::origin(), cells: vec![[1, 2, 3]], occupied: true },
        ]);
        let cases: Vec<(Vec<WireDelta>, u64)> = vec![
            (vec![WireDelta { tag: 99, ..good[0] }], 0),
            (vec![good[0], WireDelta { reserved: 1, ..good[1] }], 1),
            (vec![good[0], WireDelta { flag: 2, ..good[1] }], 1),
            (vec![good[0], WireDelta { flag: 1, ..good[0] }], 1),
            (good[..2].to_vec(), 1),     // run truncated
            (vec![good[0], good[2]], 1), // cell outside a run
            (vec![good[0], WireDelta { cell: [-1, 0, 0], ..good[1] }, good[2]], 1),
        ];
        for (records, index) in cases {
            let err = decode_deltas(&records).unwrap_err();
            assert_eq!(err.status, Status::MalformedDelta, "{records:?}");
            assert_eq!(err.index, Some(index), "{err}");
        }
    }

    #[test]
    fn codes_are_consecutive_and_unknown_ones_are_told_the_real_range() {
        for all in [tag::ALL, op::ALL] {
            assert!(all.windows(2).all(|w| w[1].0 == w[0].0 + 1), "{all:?}");
        }
        assert_eq!(tag::ALL.last(), Some(&(tag::VOXEL_BLOCK, "VOXEL_BLOCK")));
        let (last, _) = *tag::ALL.last().unwrap();
        let err = decode_deltas(&[WireDelta { tag: last + 1, ..Default::default() }]).unwrap_err();
        assert!(err.message.contains("1 (UPSERT_CYLINDER) ..= 10 (VOXEL_BLOCK)"), "{err}");
        let h = MapRequestHeader { op: op::LIST + 1, ..Default::default() };
        let err = MapRequest::decode(&h, &[]).unwrap_err();
        assert!(err.message.contains("1 (CREATE) ..= 6 (LIST)"), "{err}");
    }

    /// Chunk 0 of `chunk_count` of upload `upload_id` of map 1: the unit square, a
    /// low sun, no expected version.
    fn upload(upload_id: u64, chunk_count: u32, replace: bool, deltas: Vec<MapDelta>) -> MapRequest {
        let (bounds, sun) = (Bounds::new([0.0, 0.0, 1.0, 1.0]).unwrap(), Sun::new(0.1, 0.0).unwrap());
        MapRequest::Upload {
            map: 1,
            upload_id,
            chunk_index: 0,
            chunk_count,
            replace,
            expected_version: None,
            bounds,
            sun,
            deltas,
        }
    }

    #[test]
    fn a_batch_refuses_voxel_runs_of_nothing_an_upload_takes_them() {
        let empty =
            |occupied| MapDelta::SetVoxels { resolution: 1.0, origin: Point3::origin(), cells: vec![], occupied };
        let no_blocks =
            MapDelta::SetVoxelBlocks { resolution: 1.0, origin: Point3::origin(), blocks: vec![], occupied: true };
        for run in [empty(true), empty(false), no_blocks.clone()] {
            let records = encode_deltas(&[MapDelta::Clear, run]);
            assert_eq!(decode_deltas(&records).unwrap().len(), 2);
            let err = decode_batch(&records).unwrap_err();
            assert_eq!((err.status, err.index), (Status::MalformedDelta, Some(1)), "{err}");
            let apply = MapRequest::Apply { map: 1, expected_version: None, deltas: vec![] }.header(1, [0, 0]);
            assert_eq!(MapRequest::decode(&apply, &records).unwrap_err().status, Status::MalformedDelta);
        }
        // An upload's run of nothing describes a grid with no cells.
        let up = upload(1, 1, false, vec![no_blocks]);
        assert_eq!(MapRequest::decode(&up.header(1, [0, 0]), &up.records()).unwrap(), up);
    }

    #[test]
    fn content_makes_the_same_map_in_any_order() {
        let world = sample_world(MAX_DELTAS_PER_MESSAGE + 300, 40);
        let grid = world.voxels().unwrap();
        let mut deltas: Vec<MapDelta> =
            world_chunks_of(&world, 64).iter().flat_map(|c| decode_deltas(c).unwrap()).collect();
        // Obstacles last, block runs interleaved with upserts and with runs of single cells.
        deltas.reverse();
        let cells: Vec<CellIndex> = grid.cells().take(50).collect();
        for (k, c) in cells.iter().enumerate() {
            let run = MapDelta::SetVoxels {
                resolution: grid.resolution(),
                origin: grid.origin(),
                cells: vec![*c],
                occupied: true,
            };
            deltas.insert((k * 7) % deltas.len(), run);
        }
        let back = world_from_content(4, *world.bounds(), *world.sun(), &deltas).unwrap();
        assert_eq!(back, world);

        // Errors name the delta at fault in the content as given.
        let at = |mut deltas: Vec<MapDelta>, i: usize, d: MapDelta| {
            deltas.insert(i, d);
            world_from_content(0, *world.bounds(), *world.sun(), &deltas).unwrap_err()
        };
        let other_grid =
            MapDelta::SetVoxels { resolution: 0.5, origin: grid.origin(), cells: vec![[0, 0, 0]], occupied: true };
        let e = at(deltas.clone(), 30, other_grid);
        assert!(matches!(e.kind, MapDeltaErrorKind::VoxelGridMismatch { .. }) && e.index == 30, "{e}");
        let far = MapDelta::SetVoxels {
            resolution: grid.resolution(),
            origin: grid.origin(),
            cells: vec![[1 << 21, 0, 0]],
            occupied: true,
        };
        let e = at(deltas.clone(), 40, far);
        assert!(
            matches!(e.kind, MapDeltaErrorKind::Voxels(VoxelError::IndexOutOfRange { .. })) && e.index == 40,
            "{e}"
        );
        let bad_pole = MapDelta::UpsertObstacle {
            id: 999,
            obstacle: Obstacle::Cylinder(VerticalCylinder { center: Point2::new(0.0, 0.0), radius: 0.0, height: 1.0 }),
        };
        let e = at(deltas, 55, bad_pole);
        assert!(matches!(e.kind, MapDeltaErrorKind::InvalidObstacle { id: 999, .. }) && e.index == 55, "{e}");
    }

    #[test]
    fn headers_are_checked() {
        let up = upload(9, 2, true, vec![]);
        let h = up.header(5, [1, 2]);
        assert_eq!(MapRequest::decode(&h, &[]).unwrap(), up);
        let status = |h: MapRequestHeader| MapRequest::decode(&h, &[]).unwrap_err().status;
        assert_eq!(status(MapRequestHeader { op: 0, ..h }), Status::MalformedRequest);
        assert_eq!(status(MapRequestHeader { flags: 2, ..h }), Status::MalformedRequest);
        assert_eq!(status(MapRequestHeader { chunk_count: 0, ..h }), Status::OverCapacity);
        assert_eq!(status(MapRequestHeader { chunk_index: 2, ..h }), Status::ChunkOutOfOrder);
        assert_eq!(status(MapRequestHeader { bounds: [0.0, 0.0, f64::NAN, 1.0], ..h }), Status::InvalidDelta);
        let too_many = vec![WireDelta { tag: tag::CLEAR, ..Default::default() }; MAX_DELTAS_PER_MESSAGE + 1];
        assert_eq!(
            MapRequest::decode(&MapRequestHeader { op: op::APPLY, ..h }, &too_many).unwrap_err().status,
            Status::OverCapacity
        );
    }

    #[test]
    fn a_list_request_carries_only_its_cursor_and_its_reply_is_checked() {
        let list = MapRequest::List { from: u64::MAX - 1 };
        let h = list.header(3, [0, 0]);
        assert_eq!((h.op, h.map_id, h.flags), (op::LIST, u64::MAX - 1, 0));
        assert_eq!(MapRequest::decode(&h, &[]).unwrap(), list);
        assert_eq!(list.map(), u64::MAX - 1);
        let status = |h: MapRequestHeader, records: &[WireDelta]| MapRequest::decode(&h, records).unwrap_err().status;
        assert_eq!(status(MapRequestHeader { flags: FLAG_REPLACE, ..h }, &[]), Status::MalformedRequest);
        let clear = encode_deltas(&[MapDelta::Clear]);
        assert_eq!(status(h, &clear), Status::MalformedRequest);

        let described = MapReplyHeader {
            chunk_count: 2,
            generation: 9,
            map_id: 40,
            version: 3,
            bounds: [-1.0, -2.0, 3.0, 4.0],
            sun: [0.5, 1.0],
            ..Default::default()
        };
        let info = MapInfo::from_list_reply(40, &described).unwrap().unwrap();
        assert_eq!((info.id, info.version, info.generation), (40, 3, 9));
        assert_eq!((info.bounds.to_array(), info.sun), (described.bounds, Sun::new(0.5, 1.0).unwrap()));
        assert_eq!(info.to_json()["sun"]["azimuth"], 1.0);
        // None at or after the cursor; a map before it, or bad numbers: refused.
        assert_eq!(MapInfo::from_list_reply(41, &MapReplyHeader { chunk_count: 0, ..described }), Ok(None));
        let refused = |from, h: MapReplyHeader| MapInfo::from_list_reply(from, &h).unwrap_err().status;
        assert_eq!(refused(41, described), Status::MalformedRequest);
        assert_eq!(refused(0, MapReplyHeader { bounds: [1.0, 0.0, 0.0, 1.0], ..described }), Status::InvalidDelta);
        assert_eq!(refused(0, MapReplyHeader { sun: [f64::NAN, 0.0], ..described }), Status::InvalidDelta);
    }
}
