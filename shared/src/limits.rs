//! Capacity limits shared by the scenario parser, the world map and the wire.
//!
//! Every list a client can send has a bound here, so a request can be checked against
//! it before any work is done and the daemon's memory stays bounded.

/// Most obstacles (cylinders and boxes) one map may hold.
pub const MAX_OBSTACLES: usize = 65_536;

/// Most occupied voxel cells one map may hold.
pub const MAX_OCCUPIED_VOXELS: usize = 4_000_000;

/// Most cells of the dense occupancy bitmap spanned by the occupied voxels'
/// bounding box (2^28 cells = 32 MiB of bits).
pub const MAX_VOXEL_GRID_CELLS: u64 = 1 << 28;

/// Largest |index| of a voxel cell on any axis.
pub const MAX_VOXEL_INDEX: i64 = 1 << 20;

/// Most perimeter target points (SPEC §11: `perimeter_points` in [0, 4096]).
pub const MAX_PERIMETER_POINTS: u32 = 4096;

/// Most random or centre samples before `no_feasible_pose` (SPEC §8).
pub const MAX_SAMPLING_TRIES: u64 = 100_000;

/// Largest |coordinate| accepted anywhere in a map, in metres. Keeps every derived
/// quantity (squares, bounding boxes) far from overflow.
pub const MAX_COORDINATE: f64 = 1.0e6;
