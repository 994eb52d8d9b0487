//! Voxel maps as a robot's mapping stack sends them, and the map changes from one
//! to the next: what keeps a daemon's map in step with octomap_server (`dyfos_ros`).
//!
//! A [`PyVoxels`] is the occupied cells of one map (a [`VoxelGrid`]), read from an
//! OctoMap `.bt` file, from the tree of an `octomap_msgs/Octomap` message, or from
//! occupied-cell centres (octomap_server's point cloud). [`upload_voxels`] sends one
//! as a whole map; [`update_voxels`] sends only the cells that changed since the
//! previous one, as two `SetVoxelBlocks` deltas (freed, then occupied) in one atomic
//! batch. Typed all the way: no map delta crosses as JSON.

use super::{ErrorInfo, PyClient, to_pyerr};
use dyfos_shared::limits::MAX_DELTAS_PER_MESSAGE;
use dyfos_shared::math::Point3;
use dyfos_shared::world::octomap::{Octomap, OctomapError};
use dyfos_shared::world::{CellIndex, MapDelta, VoxelBlock, VoxelError, VoxelGrid, World};
use pyo3::prelude::*;
use std::collections::HashMap;

/// The first line of OctoMap's binary files.
const BT_MAGIC: &str = "# Octomap OcTree binary file";

/// The occupied cells of a voxel map, with its resolution and origin.
#[pyclass(frozen, module = "dyfos._dyfos", name = "RawVoxels")]
pub(crate) struct PyVoxels(VoxelGrid);

/// The status of a map that cannot be read: `over_capacity` for one too large for
/// the daemon, `invalid_delta` otherwise (as `Client::upload_octomap` reports it).
fn octomap_error(e: OctomapError) -> ErrorInfo {
    match e {
        OctomapError::Map(VoxelError::TooManyCells { .. } | VoxelError::GridTooLarge { .. }) => {
            ErrorInfo::new("over_capacity", format!("OctoMap: {e}"))
        }
        e => ErrorInfo::new("invalid_delta", format!("OctoMap: {e}")),
    }
}

fn voxel_error(what: &str, e: VoxelError) -> ErrorInfo {
    match e {
        VoxelError::TooManyCells { .. } | VoxelError::GridTooLarge { .. } => {
            ErrorInfo::new("over_capacity", format!("{what}: {e}"))
        }
        e => ErrorInfo::new("invalid_delta", format!("{what}: {e}")),
    }
}

/// Nodes of an OctoMap tree stream (what `OcTree::writeBinaryData` writes and an
/// `octomap_msgs/Octomap` carries, without the file's header): the root plus one
/// for every non-zero 2-bit child code. Only the `size` line a `.bt` header needs;
/// the reader still checks the stream itself (truncated, trailing bytes, ...).
fn tree_nodes(data: &[u8]) -> u64 {
    if data.is_empty() {
        return 0;
    }
    let children: u64 =
        data.iter().map(|b| u64::from((0..4).filter(|i| (b >> (2 * i)) & 0b11 != 0).count() as u8)).sum();
    1 + children
}

#[pymethods]
impl PyVoxels {
    /// The occupied cells of an OctoMap `.bt` file's bytes; OctoMap's cell (0, 0, 0)
    /// has its minimum corner at `origin`.
    #[staticmethod]
    fn from_octomap(py: Python<'_>, bt: &[u8], origin: [f64; 3]) -> PyResult<Self> {
        py.detach(|| Octomap::from_bt(bt).and_then(|m| Ok(m.to_voxels(Point3::from(origin))?)))
            .map(PyVoxels)
            .map_err(|e| to_pyerr(py, octomap_error(e)))
    }

    /// The same from the parts of an `octomap_msgs/Octomap` message with `binary`
    /// set: its tree type `id`, `resolution` and the tree stream `data`.
    #[staticmethod]
    fn from_octomap_data(
        py: Python<'_>,
        tree_id: &str,
        resolution: f64,
        data: &[u8],
        origin: [f64; 3],
    ) -> PyResult<Self> {
        // The id goes into a header line: nothing but a name.
        if tree_id.is_empty() || !tree_id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(to_pyerr(
                py,
                ErrorInfo::new(
                    "invalid_delta",
                    format!("OctoMap tree type `{tree_id}` is not supported; only `OcTree`"),
                ),
            ));
        }
        let mut bt =
            format!("{BT_MAGIC}\nid {tree_id}\nsize {}\nres {resolution}\ndata\n", tree_nodes(data)).into_bytes();
        bt.extend_from_slice(data);
        Self::from_octomap(py, &bt, origin)
    }

    /// The cells containing `points` (x, y, z triples of native-endian f64, in the
    /// OctoMap's frame): cell (i, j, k) holds `resolution·[i, i+1) × ...`, placed
    /// with its minimum corner at `origin + resolution·(i, j, k)`.
    #[staticmethod]
    fn from_points(py: Python<'_>, points: &[u8], resolution: f64, origin: [f64; 3]) -> PyResult<Self> {
        if !points.len().is_multiple_of(24) {
            return Err(to_pyerr(
                py,
                ErrorInfo::new("malformed_request", format!("{} bytes are not x, y, z triples of f64", points.len())),
            ));
        }
        let origin = Point3::from(origin);
        let result = py.detach(|| {
            VoxelGrid::empty(resolution, origin).map_err(|e| voxel_error("points", e))?;
            let mut bad = None;
            let cells = points.chunks_exact(24).enumerate().map_while(|(n, p)| {
                let v = |k: usize| f64::from_ne_bytes(p[8 * k..8 * k + 8].try_into().unwrap_or_default());
                let cell: Option<CellIndex> = (0..3)
                    .map(|k| {
                        let i = (v(k) / resolution).floor();
                        // Beyond i64 is beyond every limit: the grid refuses it by its index.
                        i.is_finite().then(|| i.clamp(-9.0e18, 9.0e18) as i64)
                    })
                    .collect::<Option<Vec<_>>>()
                    .map(|c| [c[0], c[1], c[2]]);
                if cell.is_none() {
                    bad = Some(n);
                }
                cell
            });
            let grid = VoxelGrid::new(resolution, origin, cells).map_err(|e| voxel_error("points", e))?;
            match bad {
                Some(n) => Err(ErrorInfo::new("invalid_delta", format!("point {n} is not a finite position"))),
                None => Ok(grid),
            }
        });
        result.map(PyVoxels).map_err(|e| to_pyerr(py, e))
    }

    /// Occupied cells.
    fn __len__(&self) -> usize {
        usize::try_from(self.0.len()).unwrap_or(usize::MAX)
    }

    /// Cell side, m.
    #[getter]
    fn resolution(&self) -> f64 {
        self.0.resolution()
    }

    /// Minimum corner of cell (0, 0, 0).
    #[getter]
    fn origin(&self) -> [f64; 3] {
        self.0.origin().coords.into()
    }

    /// Delta records that [`update_voxels`] sends to turn `previous` into this map,
    /// or `None` if it cannot (another resolution or origin: upload it whole).
    fn change_records(&self, py: Python<'_>, previous: PyRef<'_, PyVoxels>) -> Option<usize> {
        let (old, new) = (&previous.0, &self.0);
        py.detach(|| changes(old, new).map(|d| d.iter().map(records).sum()))
    }
}

/// Wire records of a delta: a run header plus one per block.
fn records(delta: &MapDelta) -> usize {
    match delta {
        MapDelta::SetVoxelBlocks { blocks, .. } => 1 + blocks.len(),
        _ => 1,
    }
}

/// The deltas that turn `old` into `new`: the freed cells, then the occupied ones,
/// as 4³ blocks (none if nothing changed); `None` for grids of another resolution
/// or origin.
fn changes(old: &VoxelGrid, new: &VoxelGrid) -> Option<Vec<MapDelta>> {
    if old.resolution() != new.resolution() || old.origin() != new.origin() {
        return None;
    }
    let mut before: HashMap<CellIndex, u64> = old.blocks().map(|b| (b.min, b.mask)).collect();
    let mut occupied = Vec::new();
    for b in new.blocks() {
        let had = before.remove(&b.min).unwrap_or(0);
        if b.mask & !had != 0 {
            occupied.push(VoxelBlock { min: b.min, mask: b.mask & !had });
        }
        if had & !b.mask != 0 {
            before.insert(b.min, had & !b.mask);
        }
    }
    let mut freed: Vec<VoxelBlock> = before.into_iter().map(|(min, mask)| VoxelBlock { min, mask }).collect();
    freed.sort_unstable_by_key(|b| b.min);
    occupied.sort_unstable_by_key(|b| b.min);
    let (resolution, origin) = (new.resolution(), new.origin());
    Some(
        [(freed, false), (occupied, true)]
            .into_iter()
            .filter(|(blocks, _)| !blocks.is_empty())
            .map(|(blocks, occupied)| MapDelta::SetVoxelBlocks { resolution, origin, blocks, occupied })
            .collect(),
    )
}

/// Uploads `voxels` as map `map_id` with `bounds` and `sun`, as `upload_octomap`
/// does (`replace` an existing map whole); returns the version.
#[pyfunction]
#[pyo3(signature = (client, map_id, voxels, bounds, sun, replace=false, timeout=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn upload_voxels(
    py: Python<'_>,
    client: PyRef<'_, PyClient>,
    map_id: u64,
    voxels: PyRef<'_, PyVoxels>,
    bounds: [f64; 4],
    sun: (f64, f64),
    replace: bool,
    timeout: Option<f64>,
) -> PyResult<u64> {
    let (bounds, sun) = crate::bounds_and_sun(bounds, sun).map_err(|e| to_pyerr(py, e))?;
    let world = World::new(0, bounds, sun, [], Some(voxels.0.clone()))
        .map_err(|e| to_pyerr(py, ErrorInfo::new("invalid_delta", e)))?;
    client.call(py, timeout, |c, t| c.upload_map(map_id, &world, replace, t))
}

/// Sends the cells that changed from `previous` to `voxels` to map `map_id` as one
/// atomic batch (with `expected_version`, the map must be there first); returns the
/// new version, or `None` if nothing changed (nothing is sent).
#[pyfunction]
#[pyo3(signature = (client, map_id, previous, voxels, expected_version=None, timeout=None))]
pub(crate) fn update_voxels(
    py: Python<'_>,
    client: PyRef<'_, PyClient>,
    map_id: u64,
    previous: PyRef<'_, PyVoxels>,
    voxels: PyRef<'_, PyVoxels>,
    expected_version: Option<u64>,
    timeout: Option<f64>,
) -> PyResult<Option<u64>> {
    let (old, new) = (&previous.0, &voxels.0);
    let deltas = py.detach(|| changes(old, new)).ok_or_else(|| {
        to_pyerr(
            py,
            ErrorInfo::new(
                "invalid_delta",
                "the two maps differ in resolution or origin: upload the new one whole (upload_voxels)",
            ),
        )
    })?;
    if deltas.is_empty() {
        return Ok(None);
    }
    let n: usize = deltas.iter().map(records).sum();
    if n > MAX_DELTAS_PER_MESSAGE {
        return Err(to_pyerr(
            py,
            ErrorInfo::new(
                "over_capacity",
                format!(
                    "the change takes {n} delta records, more than the {MAX_DELTAS_PER_MESSAGE} of one batch: upload the new map whole (upload_voxels with replace)"
                ),
            ),
        ));
    }
    client.call(py, timeout, |c, t| c.apply(map_id, expected_version, &deltas, t)).map(Some)
}
