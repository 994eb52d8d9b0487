//! Capacity limits shared by the scenario parser, the world map and the wire.
//!
//! Every list a client can send has a bound here, so a request can be checked against
//! it before any work is done and the daemon's memory stays bounded.

/// Most obstacles (cylinders and boxes) one map may hold.
pub const MAX_OBSTACLES: usize = 65_536;

/// Most occupied voxel cells one map may hold (2^26 = 67 108 864: 0.05 m cells
/// covering 20 000 m² of wall and floor twice over). The grid stores them at 1–3
/// bytes each on surfaces (`dyfos-bench octomap` measures it), so a full map is
/// 100–200 MB.
pub const MAX_OCCUPIED_VOXELS: usize = 1 << 26;

/// Most occupied voxel cells of all the maps one daemon holds together (2^27:
/// two full maps, 200–400 MB).
pub const MAX_TOTAL_VOXELS: u64 = 1 << 27;

/// Most 64³-cell blocks the occupied voxels' bounding box may span (2^22: the
/// grid's root index is 4 bytes a block, 16 MiB at most; 6.5 × 6.5 km at 0.05 m
/// in one layer of blocks).
pub const MAX_VOXEL_BLOCKS_SPANNED: u64 = 1 << 22;

/// Largest |index| of a voxel cell on any axis.
pub const MAX_VOXEL_INDEX: i64 = 1 << 20;

/// Most perimeter target points (SPEC §11: `perimeter_points` in [0, 4096]).
pub const MAX_PERIMETER_POINTS: u32 = 4096;

/// Most random or centre samples before `no_feasible_pose` (SPEC §8).
pub const MAX_SAMPLING_TRIES: u64 = 100_000;

/// Largest |coordinate| accepted anywhere in a map, in metres. Keeps every derived
/// quantity (squares, bounding boxes) far from overflow.
pub const MAX_COORDINATE: f64 = 1.0e6;

/// Most [`crate::wire::WireDelta`] records in one message (a map request, one chunk
/// of an upload or snapshot). 4096 records of 88 bytes: 352 KiB.
pub const MAX_DELTAS_PER_MESSAGE: usize = 4096;

/// Most records in one snapshot page the daemon sends (22.5 KiB). Smaller than
/// [`MAX_DELTAS_PER_MESSAGE`] so that the daemon's map replies fit a fixed-size
/// shared-memory segment: with a resizable one, iceoryx2 keeps chunk bookkeeping
/// for 255 segments per connected client (8 MB of `/dev/shm` each, written and swept
/// by the daemon's IPC thread when one connects or leaves).
pub const SNAPSHOT_PAGE_RECORDS: usize = 256;

/// Most delta records carried inline by one rendezvous request.
pub const MAX_INLINE_DELTAS: usize = 1024;

/// Most chunks of one map upload: enough for [`MAX_OBSTACLES`] obstacles plus
/// [`MAX_OCCUPIED_VOXELS`] cells in 4³ blocks of 4 cells or more each (a surface
/// crossing a block holds 4 to 16) at [`MAX_DELTAS_PER_MESSAGE`] records a chunk.
pub const MAX_UPLOAD_CHUNKS: u32 = 1 << 14;

/// Most maps one daemon holds.
pub const MAX_MAPS: usize = 256;

/// Most map uploads in progress at once (each buffers its chunks until complete).
pub const MAX_PENDING_UPLOADS: usize = 8;

/// Longest request deadline accepted, µs (one hour).
pub const MAX_DEADLINE_MICROS: u64 = 3_600_000_000;

/// Longest `--prefix` for the daemon's service names, in bytes.
pub const MAX_PREFIX_LEN: usize = 200;

/// Bytes of the human-readable detail carried by an error reply.
pub const DETAIL_LEN: usize = 240;
