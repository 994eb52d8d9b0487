//! OctoMap's binary tree files (`.bt`, `OcTree::writeBinary`), read into occupied
//! cells (SPEC §1).
//!
//! A `.bt` file is a few text lines (`# Octomap OcTree binary file`, `id OcTree`,
//! `size N`, `res R`, `data`) and then the tree, depth first: for each inner node two
//! bytes, read as one little-endian 16-bit word `w`, give its eight children: child
//! `i` is `(w >> 2i) & 3`, 0 unknown (absent), 1 free, 2 occupied, 3 inner (its own
//! two bytes follow, children in order). `size` counts the nodes, root included. A node at depth `d`
//! covers `2^(16−d)` finest cells per axis; its cells are found from keys, never from
//! coordinates: child `i` of a node takes the upper half of axis `k` when bit `k` of
//! `i` is set, and the finest key `key` is cell index `key − 32768`.
//!
//! The reader is strict and bounded: a truncated, oversized, wrong-id or hostile file
//! is an [`OctomapError`] naming what is wrong, never a panic; it allocates in
//! proportion to the bytes it is given. Not supported, each with its own error: `.ot`
//! files (full probabilities: `# Octomap OcTree file`), other tree types
//! (`ColorOcTree`, `OcTreeStamped`, …), and anything after the tree.
//!
//! ```
//! use dyfos_shared::world::octomap::Octomap;
//!
//! // A tree whose root has one occupied child (index 0, the lower half on every axis)
//! // and whose other children are unknown: 2 nodes, 32768 cells per axis.
//! let mut file = b"# Octomap OcTree binary file\nid OcTree\nsize 2\nres 0.1\ndata\n".to_vec();
//! file.extend([0b0000_0010, 0b0000_0000]);
//! let map = Octomap::from_bt(&file).unwrap();
//! assert_eq!(map.resolution(), 0.1);
//! let cube = map.occupied()[0];
//! assert_eq!((cube.min, cube.side), ([-32768, -32768, -32768], 32768));
//! assert!(Octomap::from_bt(&file[..file.len() - 1]).unwrap_err().to_string().contains("truncated"));
//! ```

use crate::world::{CellIndex, VoxelError};

/// The depth of OctoMap's trees: 16 levels, keys of 16 bits.
pub const TREE_DEPTH: u32 = 16;

/// The key of cell index 0 (OctoMap's `tree_max_val`).
const KEY_OFFSET: i64 = 1 << (TREE_DEPTH - 1);

/// Longest header accepted before `data`, bytes.
const MAX_HEADER: usize = 4096;

/// The first line of every `.bt` file.
const BT_MAGIC: &str = "# Octomap OcTree binary file";

/// The first line of `.ot` files.
const OT_MAGIC: &str = "# Octomap OcTree file";

/// A cube of occupied cells: an occupied node of the tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OccupiedCube {
    /// The cell index of its minimum corner (key − 32768 per axis).
    pub min: CellIndex,
    /// Cells per axis: `2^(16 − depth)`.
    pub side: i64,
}

impl OccupiedCube {
    /// Its cells, in x-fastest order.
    pub fn cells(&self) -> impl Iterator<Item = CellIndex> + '_ {
        let s = self.side;
        (0..s).flat_map(move |k| {
            (0..s).flat_map(move |j| (0..s).map(move |i| [self.min[0] + i, self.min[1] + j, self.min[2] + k]))
        })
    }

    /// How many cells it holds.
    pub fn cell_count(&self) -> u64 {
        (self.side as u64).pow(3)
    }
}

/// The occupied part of an OctoMap: its resolution and its occupied nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Octomap {
    resolution: f64,
    nodes: u64,
    occupied: Vec<OccupiedCube>,
}

/// Why a `.bt` file was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OctomapError {
    /// An `.ot` file, which stores full probabilities.
    #[error(
        "this is an OctoMap .ot file (full probabilities), which is not supported; write a .bt file instead (OcTree::writeBinary, or `convert_octree in.ot out.bt` from octomap-tools)"
    )]
    OtFile,
    /// The first line is not OctoMap's.
    #[error("not an OctoMap .bt file: the first line must be `{BT_MAGIC}`")]
    NotBt,
    /// The header is malformed.
    #[error("OctoMap header: {0}")]
    Header(String),
    /// A tree type other than `OcTree`.
    #[error("OctoMap tree type `{0}` is not supported; only `OcTree` (.bt) files are read")]
    UnsupportedTree(String),
    /// The tree data ended early.
    #[error("OctoMap data is truncated: {0}")]
    Truncated(String),
    /// The tree data is inconsistent.
    #[error("OctoMap data is corrupt: {0}")]
    Corrupt(String),
    /// The file's cells do not make a map (too many cells, spread too far).
    #[error("the OctoMap's occupied cells do not fit a map: {0}")]
    Map(#[from] VoxelError),
    /// The bounds or sun given with it are invalid.
    #[error("the map around the OctoMap: {0}")]
    World(String),
    /// A cell to write lies outside OctoMap's keys.
    #[error("cell {0:?} lies outside OctoMap's key range (indices -32768 to 32767 per axis); move the map's origin")]
    OutOfRange(CellIndex),
}

impl Octomap {
    /// Reads a `.bt` file's bytes.
    pub fn from_bt(bytes: &[u8]) -> Result<Octomap, OctomapError> {
        let (resolution, nodes, data) = header(bytes)?;
        let (occupied, read) = tree(data, nodes)?;
        if read != nodes {
            return Err(OctomapError::Corrupt(format!("the header says {nodes} nodes, the tree has {read}")));
        }
        Ok(Octomap { resolution, nodes, occupied })
    }

    /// The cell side, m, as stored in the file.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The tree's node count (its `size`).
    pub fn nodes(&self) -> u64 {
        self.nodes
    }

    /// The occupied nodes, in the file's depth-first order.
    pub fn occupied(&self) -> &[OccupiedCube] {
        &self.occupied
    }

    /// How many finest cells are occupied.
    pub fn cell_count(&self) -> u64 {
        self.occupied.iter().map(OccupiedCube::cell_count).sum()
    }

    /// The occupied cells as a voxel grid whose cell (0, 0, 0) has its minimum corner
    /// at `origin` (SPEC §1). Refused, before any cell is listed, if there are more
    /// than [`crate::limits::MAX_OCCUPIED_VOXELS`].
    pub fn to_voxels(&self, origin: crate::math::Point3<f64>) -> Result<crate::world::VoxelGrid, VoxelError> {
        let count = self.cell_count();
        if count > crate::limits::MAX_OCCUPIED_VOXELS as u64 {
            return Err(VoxelError::TooManyCells { count });
        }
        crate::world::VoxelGrid::from_cubes(self.resolution, origin, self.occupied.iter().map(|c| (c.min, c.side)))
    }
}

/// The map an OctoMap `.bt` file describes: its occupied cells as the voxels of a
/// map with `bounds` and `sun`, OctoMap's cell (0, 0, 0) with its minimum corner at
/// `origin` (SPEC §1, §11), at version 0. What `dyfos map upload --octomap` sends.
///
/// ```
/// use dyfos_shared::world::octomap::{world_from_bt, write_bt};
/// use dyfos_shared::world::{Bounds, Sun};
/// use nalgebra::Point3;
///
/// let bt = write_bt(0.05, [[0, 0, 0], [1, 0, 0]]).unwrap();
/// let bounds = Bounds::new([-5.0, -5.0, 5.0, 5.0]).unwrap();
/// let world = world_from_bt(&bt, Point3::new(0.0, 0.0, -0.05), bounds, Sun::new(0.5, 1.0).unwrap()).unwrap();
/// assert_eq!(world.voxels().unwrap().len(), 2);
/// assert!(world_from_bt(&bt[..bt.len() - 1], Point3::origin(), bounds, Sun::new(0.5, 1.0).unwrap()).is_err());
/// ```
pub fn world_from_bt(
    bytes: &[u8],
    origin: crate::math::Point3<f64>,
    bounds: crate::world::Bounds,
    sun: crate::world::Sun,
) -> Result<crate::world::World, OctomapError> {
    let grid = Octomap::from_bt(bytes)?.to_voxels(origin)?;
    crate::world::World::new(0, bounds, sun, [], Some(grid)).map_err(|e| OctomapError::World(e.to_string()))
}

/// Writes `cells` (indices, any order, duplicates allowed) as a `.bt` file of
/// resolution `resolution`, as `OcTree::writeBinary` would: a full octant of occupied
/// cells becomes one pruned node, everything else unknown (OctoMap reads it back with
/// the same occupied cells). A cell outside OctoMap's key range (index < −32768 or
/// ≥ 32768 on an axis) is an error naming it.
pub fn write_bt(resolution: f64, cells: impl IntoIterator<Item = CellIndex>) -> Result<Vec<u8>, OctomapError> {
    let mut keys: Vec<u64> = Vec::new();
    for c in cells {
        let mut k = [0u64; 3];
        for axis in 0..3 {
            let key = c[axis] + KEY_OFFSET;
            if !(0..1 << TREE_DEPTH).contains(&key) {
                return Err(OctomapError::OutOfRange(c));
            }
            k[axis] = key as u64;
        }
        keys.push(morton(k));
    }
    keys.sort_unstable();
    keys.dedup();
    let mut data = Vec::new();
    let nodes = if keys.is_empty() { 0 } else { 1 + write_node(&keys, 0, &mut data) };
    let mut out =
        format!("{BT_MAGIC}\n# written by dyfos\nid OcTree\nsize {nodes}\nres {resolution}\ndata\n").into_bytes();
    out.extend(data);
    Ok(out)
}

/// Interleaves the three 16-bit keys so that, from the top, each 3-bit group is
/// the child index at that depth (x in bit 0, y in bit 1, z in bit 2).
fn morton(k: [u64; 3]) -> u64 {
    let mut m = 0;
    for bit in 0..TREE_DEPTH as u64 {
        for (axis, key) in k.iter().enumerate() {
            m |= ((key >> bit) & 1) << (3 * bit + axis as u64);
        }
    }
    m
}

/// Writes the inner node whose cells (Morton-sorted, all within it) are `keys`, at
/// `depth`, and its inner descendants; returns how many child nodes it wrote.
fn write_node(keys: &[u64], depth: u32, out: &mut Vec<u8>) -> u64 {
    let shift = 3 * (TREE_DEPTH - 1 - depth);
    let child_cells = 1u64 << shift; // cells in a full child
    let at = out.len();
    out.extend([0, 0]);
    let mut bits = 0u16;
    let mut nodes = 0;
    let mut inner = Vec::new();
    let mut rest = keys;
    for i in 0..8u64 {
        let n = rest.iter().take_while(|k| (*k >> shift) & 7 == i).count();
        let (mine, tail) = rest.split_at(n);
        rest = tail;
        if mine.is_empty() {
            continue;
        }
        nodes += 1;
        let full = mine.len() as u64 == child_cells; // deduplicated, so full means every cell
        let code: u16 = if full { 2 } else { 3 };
        bits |= code << (2 * i);
        if !full {
            inner.push(mine);
        }
    }
    out[at..at + 2].copy_from_slice(&bits.to_le_bytes());
    for mine in inner {
        nodes += write_node(mine, depth + 1, out);
    }
    nodes
}

/// Splits the header from the data: (resolution, node count, data).
fn header(bytes: &[u8]) -> Result<(f64, u64, &[u8]), OctomapError> {
    let mut rest = bytes;
    let mut line_no = 0;
    let (mut id, mut size, mut res) = (None, None, None);
    loop {
        let consumed = bytes.len() - rest.len();
        let Some(end) = rest.iter().position(|b| *b == b'\n') else {
            return Err(if line_no == 0 {
                OctomapError::NotBt
            } else {
                OctomapError::Truncated("the header has no `data` line".into())
            });
        };
        if consumed + end > MAX_HEADER {
            return Err(OctomapError::Header(format!("longer than {MAX_HEADER} bytes before `data`")));
        }
        let line = std::str::from_utf8(&rest[..end])
            .map_err(|_| OctomapError::Header(format!("line {} is not text", line_no + 1)))?
            .trim_end_matches('\r');
        rest = &rest[end + 1..];
        line_no += 1;
        if line_no == 1 {
            if line.starts_with(OT_MAGIC) {
                return Err(OctomapError::OtFile);
            }
            if !line.starts_with(BT_MAGIC) {
                return Err(OctomapError::NotBt);
            }
            continue;
        }
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (key, value) = line.split_once(char::is_whitespace).map_or((line, ""), |(k, v)| (k, v.trim()));
        match key {
            "id" => id = Some(value.to_string()),
            "size" => {
                size = Some(
                    value
                        .parse::<u64>()
                        .map_err(|_| OctomapError::Header(format!("size `{value}` is not a node count")))?,
                )
            }
            "res" => {
                let r =
                    value.parse::<f64>().ok().filter(|r| r.is_finite() && *r >= 1e-6 && *r <= 1e3).ok_or_else(
                        || OctomapError::Header(format!("res `{value}` must be a number in [1e-6, 1000] m")),
                    )?;
                res = Some(r);
            }
            "data" => break,
            other => return Err(OctomapError::Header(format!("unknown keyword `{other}` on line {line_no}"))),
        }
    }
    match id.as_deref() {
        Some("OcTree") => {}
        Some(other) => return Err(OctomapError::UnsupportedTree(other.to_string())),
        None => return Err(OctomapError::Header("no `id` line".into())),
    }
    let size = size.ok_or_else(|| OctomapError::Header("no `size` line".into()))?;
    let res = res.ok_or_else(|| OctomapError::Header("no `res` line".into()))?;
    Ok((res, size, rest))
}

/// Reads the tree: its occupied cubes and how many nodes it has.
fn tree(data: &[u8], expected_nodes: u64) -> Result<(Vec<OccupiedCube>, u64), OctomapError> {
    let mut occupied = Vec::new();
    if expected_nodes == 0 {
        if !data.is_empty() {
            return Err(OctomapError::Corrupt(format!("{} bytes after an empty tree", data.len())));
        }
        return Ok((occupied, 0));
    }
    // Each inner node is two bytes: no file holds more of them than half its length,
    // so nothing below grows past what the file's size allows.
    let mut at = 0usize;
    let mut nodes = 1u64; // the root
    // Depth-first, as written: (min key, depth) of each inner node still to read.
    let mut stack: Vec<([i64; 3], u32)> = vec![([0; 3], 0)];
    while let Some((min, depth)) = stack.pop() {
        let Some(pair) = data.get(at..at + 2) else {
            return Err(OctomapError::Truncated(format!(
                "the node at byte {at} of the data (depth {depth}) is missing; the file was cut short"
            )));
        };
        at += 2;
        let bits = u16::from(pair[0]) | (u16::from(pair[1]) << 8);
        let child_depth = depth + 1;
        let half = 1i64 << (TREE_DEPTH - child_depth);
        let mut inner = [None; 8];
        for (i, slot) in inner.iter_mut().enumerate() {
            let code = (bits >> (2 * i)) & 0b11;
            if code == 0 {
                continue;
            }
            nodes += 1;
            let child = std::array::from_fn(|k| min[k] + if i & (1 << k) != 0 { half } else { 0 });
            match code {
                2 => occupied.push(OccupiedCube { min: child.map(|k| k - KEY_OFFSET), side: half }),
                1 => {} // free
                _ if child_depth == TREE_DEPTH => {
                    return Err(OctomapError::Corrupt(format!(
                        "a node at the finest depth ({TREE_DEPTH}) claims children (byte {})",
                        at - 2
                    )));
                }
                _ => *slot = Some(child),
            }
        }
        // Pushed in reverse, so child 0's subtree is read first, as written.
        for child in inner.iter().rev().flatten() {
            stack.push((*child, child_depth));
        }
        if nodes > expected_nodes {
            return Err(OctomapError::Corrupt(format!("more nodes than the {expected_nodes} the header says")));
        }
    }
    if at != data.len() {
        return Err(OctomapError::Corrupt(format!("{} bytes after the tree", data.len() - at)));
    }
    Ok((occupied, nodes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn file(header: &str, data: &[u8]) -> Vec<u8> {
        let mut f = format!("{BT_MAGIC}\n{header}").into_bytes();
        f.extend_from_slice(data);
        f
    }

    /// Root → child 7 (inner) → its child 0 occupied, child 1 free.
    fn small() -> Vec<u8> {
        let root = 3u16 << 14; // child 7 inner
        let inner = 2u16 | (1 << 2); // child 0 occupied, child 1 free
        let mut data = root.to_le_bytes().to_vec();
        data.extend(inner.to_le_bytes());
        file("id OcTree\nsize 4\nres 0.05\ndata\n", &data)
    }

    #[test]
    fn children_take_the_upper_half_where_their_index_bit_is_set() {
        let map = Octomap::from_bt(&small()).unwrap();
        assert_eq!((map.resolution(), map.nodes()), (0.05, 4));
        // Child 7 of the root: upper half on every axis, min key 32768 = index 0;
        // its child 0 is its lower octant, 16384 cells per axis.
        assert_eq!(map.occupied(), &[OccupiedCube { min: [0, 0, 0], side: 16384 }]);
        assert_eq!(map.cell_count(), 16384u64.pow(3));
    }

    #[test]
    fn every_cut_of_a_valid_file_is_an_error() {
        let full = small();
        for len in 0..full.len() {
            assert!(Octomap::from_bt(&full[..len]).is_err(), "cut at {len}");
        }
        let mut longer = full.clone();
        longer.push(0);
        assert!(matches!(Octomap::from_bt(&longer), Err(OctomapError::Corrupt(_))));
    }

    #[test]
    fn unsupported_and_malformed_headers_say_what_is_wrong() {
        let ot = b"# Octomap OcTree file\nid OcTree\nsize 1\nres 0.1\ndata\n".to_vec();
        assert_eq!(Octomap::from_bt(&ot), Err(OctomapError::OtFile));
        assert_eq!(Octomap::from_bt(b"PK\x03\x04 zip\n"), Err(OctomapError::NotBt));
        let color = file("id ColorOcTree\nsize 1\nres 0.1\ndata\n", &[0, 0]);
        assert_eq!(Octomap::from_bt(&color), Err(OctomapError::UnsupportedTree("ColorOcTree".into())));
        for (header, says) in [
            ("id OcTree\nsize -1\nres 0.1\ndata\n", "size"),
            ("id OcTree\nsize 1\nres nan\ndata\n", "res"),
            ("id OcTree\nsize 1\nres 0\ndata\n", "res"),
            ("id OcTree\nsize 1\ndata\n", "res"),
            ("size 1\nres 0.1\ndata\n", "id"),
            ("id OcTree\nsize 1\nres 0.1\ncolour 3\ndata\n", "unknown keyword"),
        ] {
            let err = Octomap::from_bt(&file(header, &[0, 0])).unwrap_err().to_string();
            assert!(err.contains(says), "{header:?}: {err}");
        }
        let long = format!("# {}\n", "x".repeat(MAX_HEADER));
        assert!(Octomap::from_bt(&file(&long, &[0, 0])).is_err());
    }

    #[test]
    fn node_counts_and_depths_are_checked() {
        // The header says 3 nodes, the tree has 4.
        let mut wrong = small();
        let at = wrong.windows(6).position(|w| w == b"size 4").unwrap();
        wrong[at + 5] = b'3';
        assert!(matches!(Octomap::from_bt(&wrong), Err(OctomapError::Corrupt(_))));
        // A chain of inner nodes 16 deep: the last claims children below the finest depth.
        let chain: Vec<u8> = (0..17).flat_map(|_| 3u16.to_le_bytes()).collect();
        let err = Octomap::from_bt(&file("id OcTree\nsize 18\nres 0.1\ndata\n", &chain)).unwrap_err();
        assert!(err.to_string().contains("finest depth"), "{err}");
        // An empty tree has no data.
        assert_eq!(Octomap::from_bt(&file("id OcTree\nsize 0\nres 0.1\ndata\n", &[])).unwrap().cell_count(), 0);
    }

    #[test]
    fn written_files_read_back_to_the_same_cells() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut cells: Vec<CellIndex> = (0..2000).map(|_| std::array::from_fn(|_| rng.random_range(-40..40))).collect();
        // A full 4-cell block aligned to 4: one pruned node.
        cells.extend((0..64).map(|n| [8 + n % 4, 12 + (n / 4) % 4, -16 + n / 16]));
        cells.extend([[-32768, 32767, 0]]);
        let bt = write_bt(0.05, cells.iter().copied()).unwrap();
        let map = Octomap::from_bt(&bt).unwrap();
        let mut back: Vec<CellIndex> = map.occupied().iter().flat_map(|c| c.cells().collect::<Vec<_>>()).collect();
        back.sort_unstable();
        cells.sort_unstable();
        cells.dedup();
        assert_eq!(back, cells);
        assert!(map.occupied().iter().any(|c| c.side == 4));
        assert_eq!(map.resolution(), 0.05);
        assert!(write_bt(0.1, [[32768, 0, 0]]).is_err());
        assert_eq!(Octomap::from_bt(&write_bt(0.1, []).unwrap()).unwrap().cell_count(), 0);
    }

    #[test]
    fn random_damage_never_panics() {
        let base = small();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(13);
        for _ in 0..20_000 {
            let mut f = base.clone();
            for _ in 0..rng.random_range(1..4) {
                let i = rng.random_range(0..f.len());
                f[i] = rng.random();
            }
            let _ = Octomap::from_bt(&f);
            let n = rng.random_range(0..64);
            let noise: Vec<u8> = (0..n).map(|_| rng.random()).collect();
            let _ = Octomap::from_bt(&file("id OcTree\nsize 1000\nres 0.1\ndata\n", &noise));
        }
    }
}
