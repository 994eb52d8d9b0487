//! Where in a block its occupied cells lie: the bounding box of each brick's cells
//! (kept beside its bits) and of each node's, so the walk passes an occupied block
//! whose cells all lie away from the segment in one step.
//!
//! To the level walk a block with any occupied cell is occupied, and its cells are
//! walked. Along a floor slab every brick is occupied, so a sight line ending a few
//! cells above the floor walked every cell under it; beside a wall, the same. The
//! box says where the cells are: when the segment's part inside the block stays
//! clear of the box by a margin far above the walk's rounding, the walk of that
//! block can find no contact, and is skipped. Only skipped: the walks of the other
//! blocks, and so the contacts found, are the ones the walk finds without boxes.

use super::CellIndex;
use super::tree::Bits;
use crate::math::Point3;
use crate::world::segment::Segment;

/// The bounding box of a brick's occupied cells, in cells from the brick's minimum
/// corner (each 0..8), inclusive: 3 bits a bound, minimum x, y, z then maximum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct BrickBox(u32);

impl BrickBox {
    /// The box of the cells of `bits`, or `None` when it has none.
    pub(super) fn of(bits: &Bits) -> Option<BrickBox> {
        let xs = (0..8).fold(0u32, |a, x| a | u32::from(bits[x] != 0) << x);
        if xs == 0 {
            return None;
        }
        // Word x, bit 8y + z: the OR of the words holds every (y, z) used.
        let yz = bits.iter().fold(0u64, |a, w| a | w);
        let ys = (0..8).fold(0u32, |a, y| a | u32::from(yz >> (y * 8) & 0xff != 0) << y);
        let zs = (0..8).fold(0u64, |a, y| a | (yz >> (y * 8) & 0xff)) as u32;
        let first = |m: u32| m.trailing_zeros();
        let last = |m: u32| 31 - m.leading_zeros();
        Some(BrickBox::new([first(xs), first(ys), first(zs)], [last(xs), last(ys), last(zs)]))
    }

    fn new(lo: [u32; 3], hi: [u32; 3]) -> BrickBox {
        BrickBox(lo[0] | lo[1] << 3 | lo[2] << 6 | hi[0] << 9 | hi[1] << 12 | hi[2] << 15)
    }

    /// This box grown to hold local cell `cell` (each 0..8).
    pub(super) fn with(self, cell: [u32; 3]) -> BrickBox {
        let (lo, hi) = (self.lo(), self.hi());
        BrickBox::new(std::array::from_fn(|a| lo[a].min(cell[a])), std::array::from_fn(|a| hi[a].max(cell[a])))
    }

    /// Minimum cell, from the brick's corner.
    pub(super) fn lo(self) -> [u32; 3] {
        [self.0 & 7, self.0 >> 3 & 7, self.0 >> 6 & 7]
    }

    /// Maximum cell, from the brick's corner.
    pub(super) fn hi(self) -> [u32; 3] {
        [self.0 >> 9 & 7, self.0 >> 12 & 7, self.0 >> 15 & 7]
    }
}

/// Cells `lo..=hi` (absolute indices) that hold every occupied cell of a block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct CellBox {
    /// Minimum cell.
    pub(super) lo: CellIndex,
    /// Maximum cell, inclusive.
    pub(super) hi: CellIndex,
}

/// Decides, for one segment, whether its part stays clear of a [`CellBox`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Clearance {
    resolution: f64,
    origin: Point3<f64>,
    /// 1 / the segment's direction: no division per block.
    inv_dir: [f64; 3],
    /// Whether the test may decide at all (see [`Clearance::new`]).
    enabled: bool,
}

/// How far from a block's box a segment must stay, in cells. A walk places its points
/// within 1e-9 cells (its snapping) plus the rounding of its coordinates and of a few
/// dozen steps, which [`Clearance::new`] keeps below 1e-6 cells; a thousandth of a
/// cell is far above both, and far below the clearance of a sight line passing a
/// cell above a floor.
pub(super) const MARGIN_CELLS: f64 = 1e-3;

impl Clearance {
    /// The test for `seg` in a grid of `resolution` at `origin`, deciding only if
    /// `enabled`. It refuses to decide (every box is "touched") when the coordinates
    /// are so large against the cells that float rounding along the walk nears the
    /// margin: cells below 2^-24 of the coordinates' magnitude (16 M cells; a grid's
    /// indices stay within 2^20), or anything not finite.
    /// `inv_dir` is 1 / `seg.dir`, per axis.
    pub(super) fn new(
        resolution: f64,
        origin: Point3<f64>,
        seg: &Segment,
        inv_dir: [f64; 3],
        enabled: bool,
    ) -> Clearance {
        let scale = (0..3).map(|a| seg.origin[a].abs().max(origin[a].abs())).fold(0.0, f64::max) + seg.length.abs();
        let enabled = enabled
            && (0..3).all(|a| seg.dir[a] == 0.0 || inv_dir[a].is_finite())
            && scale.is_finite()
            && resolution.is_finite()
            && scale * (-24f64).exp2() <= resolution;
        Clearance { resolution, origin, inv_dir, enabled }
    }

    /// Whether the test decides at all.
    pub(super) fn enabled(&self) -> bool {
        self.enabled
    }

    /// Whether the part `[ta, tb]` of `seg` stays more than the margin away from
    /// every cell of `cells` (closed cubes): then no walk over that part touches one.
    #[inline]
    pub(super) fn clears(&self, seg: &Segment, ta: f64, tb: f64, cells: &CellBox) -> bool {
        self.clears_region(seg, ta, tb, &Region::of(self.resolution, &self.origin, cells))
    }

    /// [`Clearance::clears`] against a box already in metres ([`Region::of`]).
    #[inline]
    pub(super) fn clears_region(&self, seg: &Segment, ta: f64, tb: f64, region: &Region) -> bool {
        // Every comparison below is one that NaN fails, so NaN never clears.
        if !(self.enabled && ta.is_finite() && tb.is_finite()) {
            return false;
        }
        let (mut t0, mut t1) = (ta, tb.max(ta));
        for a in 0..3 {
            let (lo, hi) = (region.lo[a], region.hi[a]);
            let (o, d) = (seg.origin[a], seg.dir[a]);
            let outside = if d == 0.0 {
                o < lo || o > hi
            } else {
                let (ea, eb) = ((lo - o) * self.inv_dir[a], (hi - o) * self.inv_dir[a]);
                t0 = t0.max(ea.min(eb));
                t1 = t1.min(ea.max(eb));
                t0 > t1
            };
            if outside {
                #[cfg(test)]
                PASSED.with(|p| p.set(p.get() + 1));
                return true;
            }
        }
        false
    }
}

/// A box of cells in metres, grown by the clearance margin ([`Region::of`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Region {
    pub(super) lo: [f64; 3],
    pub(super) hi: [f64; 3],
}

impl Region {
    /// The closed cubes of `cells` in a grid of `resolution` at `origin`, grown by
    /// [`MARGIN_CELLS`].
    #[inline]
    pub(super) fn of(resolution: f64, origin: &Point3<f64>, cells: &CellBox) -> Region {
        let margin = MARGIN_CELLS * resolution;
        Region {
            lo: std::array::from_fn(|a| origin[a] + cells.lo[a] as f64 * resolution - margin),
            hi: std::array::from_fn(|a| origin[a] + (cells.hi[a] + 1) as f64 * resolution + margin),
        }
    }
}

#[cfg(test)]
thread_local! {
    /// Blocks passed by their box on this thread: tests check the boxes were used.
    static PASSED: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

#[cfg(test)]
mod tests {
    use super::super::{VoxelBlock, VoxelGrid};
    use super::*;
    use crate::math::Vector3;
    use crate::world::tests::Lcg;

    fn passed() -> u64 {
        PASSED.with(std::cell::Cell::get)
    }

    /// Asserts that `seg`'s first contact is the same, bit for bit, with and without
    /// the boxes, and without the nodes' covers tried first; whether it hits.
    fn same_with_and_without_boxes(grid: &VoxelGrid, seg: &Segment) -> bool {
        let with = grid.first_contact_with(seg, true, None, true);
        let without = grid.first_contact_with(seg, false, None, true);
        let walked = grid.first_contact_with(seg, true, None, false);
        assert_eq!(
            with.map(f64::to_bits),
            without.map(f64::to_bits),
            "{seg:?}: with boxes {with:?}, without {without:?}"
        );
        assert_eq!(with.map(f64::to_bits), walked.map(f64::to_bits), "{seg:?}: without the nodes' covers {walked:?}");
        without.is_some()
    }

    /// A building of `rooms`² rooms of `room` cells: a floor slab (k = 0), walls one
    /// cell thick and `room / 2` high with a doorway in each, a table in each room.
    fn building(rooms: i64, room: i64) -> Vec<CellIndex> {
        let side = rooms * room;
        let mut cells = Vec::new();
        for i in 0..side {
            for j in 0..side {
                cells.push([i, j, 0]);
                for k in 1..=room / 2 {
                    let (ri, rj) = (i % room, j % room);
                    let door = |along: i64| (along - room / 2).abs() < room / 10 && k <= room / 3;
                    let wall = (ri == 0 || i == side - 1) && !door(rj) || (rj == 0 || j == side - 1) && !door(ri);
                    let table = (room * 6 / 10..room * 8 / 10).contains(&ri)
                        && (room / 5..room * 2 / 5).contains(&rj)
                        && k == room / 6;
                    if wall || table {
                        cells.push([i, j, k]);
                    }
                }
            }
        }
        cells
    }

    /// Segments of every kind over `grid` (cells `lo..hi`, floor at k = 0): random
    /// ones; sight lines from above to just over the floor; and segments on the
    /// grid's planes, along the floor's top face and at distances from it around
    /// the margin, along axes and diagonals.
    fn segments(rng: &mut Lcg, grid: &VoxelGrid, lo: CellIndex, hi: CellIndex, n: usize) -> Vec<Segment> {
        let r = grid.resolution();
        let at = |c: [f64; 3]| grid.origin() + Vector3::new(c[0], c[1], c[2]) * r;
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let span = |rng: &mut Lcg, a: usize| lo[a] as f64 - 2.0 + rng.next() * (hi[a] - lo[a] + 4) as f64;
            let seg = match i % 4 {
                0 => {
                    let a = at([span(rng, 0), span(rng, 1), span(rng, 2)]);
                    let b = at([span(rng, 0), span(rng, 1), span(rng, 2)]);
                    Segment::sight_line(&a, &b, 1e-6)
                }
                1 => {
                    // A viewer above, a target 1 to 5 cells over the floor's top.
                    let a = at([span(rng, 0), span(rng, 1), 10.0 + rng.next() * (hi[2] as f64)]);
                    let b = at([span(rng, 0), span(rng, 1), 2.0 + rng.next() * 4.0]);
                    Segment::sight_line(&a, &b, 1e-6)
                }
                _ => {
                    // On the grid's planes (some on 8- and 64-cell planes), or along the
                    // floor's top (z = 1 cell) at a distance from it about the margin.
                    let every = [1.0, 8.0, 64.0][i % 3];
                    let snap = |v: f64| (v / every).round() * every;
                    let height = [0.0, 1e-12, 1e-9, 0.5e-3, 1e-3, 2e-3, 0.25, 1.0][rng.below(8) as usize];
                    let z = if i % 4 == 2 { 1.0 + height } else { snap(span(rng, 2)).max(lo[2] as f64 - 1.0) };
                    let o = at([snap(span(rng, 0)), snap(span(rng, 1)), z]);
                    let pick = |rng: &mut Lcg| [-1.0, 0.0, 1.0][rng.below(3) as usize];
                    let d = Vector3::new(pick(rng), pick(rng), if i % 4 == 2 { 0.0 } else { pick(rng) });
                    (d != Vector3::zeros()).then(|| Segment::closed(o, d.normalize(), rng.next() * 80.0 * r))
                }
            };
            out.extend(seg);
        }
        out
    }

    /// Every kind of segment over `grid`: the same contacts with and without the
    /// boxes, and the boxes passed blocks (so the comparison means something).
    fn check(rng: &mut Lcg, grid: &VoxelGrid, n: usize) {
        let (lo, end) = grid.tree.bounds().expect("cells");
        let before = passed();
        let mut hits = 0;
        for seg in segments(rng, grid, lo, end, n) {
            hits += usize::from(same_with_and_without_boxes(grid, &seg));
        }
        let skips = passed() - before;
        assert!(hits > n / 20 && hits < n * 9 / 10, "{hits} hits of {n}");
        assert!(skips > n as u64 / 4, "the boxes passed only {skips} blocks over {n} segments");
    }

    /// A building with a floor slab, walls, doorways and tables, plus scattered
    /// cells (negative indices included) at an exact binary resolution, so grid
    /// planes mean the same to every computation.
    fn random_building(rng: &mut Lcg) -> VoxelGrid {
        let mut cells = building(3, 40);
        for _ in 0..3000 {
            cells.push([rng.below(160) - 20, rng.below(160) - 20, rng.below(30)]);
        }
        VoxelGrid::new(0.125, Point3::new(-3.0, 2.0, -1.0), cells).unwrap()
    }

    #[test]
    fn boxes_change_no_contact_in_a_building() {
        let mut rng = Lcg(3);
        let grid = random_building(&mut rng);
        assert!(grid.tree.boxes_are_tight());
        check(&mut rng, &grid, 40_000);
    }

    /// The same at the synthetic OctoMap building's resolution (0.05 m, not a binary
    /// fraction) and origin.
    #[test]
    fn boxes_change_no_contact_in_a_building_at_5_cm() {
        let mut rng = Lcg(11);
        let grid = VoxelGrid::new(0.05, Point3::origin(), building(4, 100)).unwrap();
        check(&mut rng, &grid, 20_000);
    }

    /// Random clusters of cells over several nodes, no floor.
    #[test]
    fn boxes_change_no_contact_on_random_clusters() {
        let mut rng = Lcg(19);
        let mut cells = vec![[0, 0, 0]];
        for _ in 0..60 {
            let c = [rng.below(200) - 100, rng.below(200) - 100, rng.below(40) - 20];
            let size = [1 + rng.below(12), 1 + rng.below(12), 1 + rng.below(6)];
            for _ in 0..(size[0] * size[1] * size[2] / 3).max(1) {
                cells.push([c[0] + rng.below(size[0]), c[1] + rng.below(size[1]), c[2] + rng.below(size[2])]);
            }
        }
        let grid = VoxelGrid::new(0.25, Point3::new(1.0, -2.0, 0.5), cells).unwrap();
        check(&mut rng, &grid, 20_000);
    }

    /// OctoMap's real Freiburg building scan.
    #[test]
    fn boxes_change_no_contact_in_the_octomap_scan() {
        let bt = include_bytes!("../../../../tests/data/octomap/geb079.bt");
        let grid = crate::world::octomap::Octomap::from_bt(bt).unwrap().to_voxels(Point3::origin()).unwrap();
        let mut rng = Lcg(23);
        check(&mut rng, &grid, 20_000);
    }

    /// After deltas that free cells, clear whole bricks and add cells, every box is
    /// still tight, and the contacts are the same with and without them.
    #[test]
    fn boxes_follow_deltas() {
        let mut rng = Lcg(29);
        let grid = random_building(&mut rng);
        let cells: Vec<CellIndex> = grid.cells().collect();
        let freed: Vec<CellIndex> = cells.iter().copied().filter(|_| rng.next() < 0.3).collect();
        let grid = grid.with_cells(&freed, false).unwrap();
        // Whole bricks (and parts of others) of the floor.
        let floor: Vec<VoxelBlock> =
            VoxelBlock::from_cells((0..48).flat_map(|i| (0..20).map(move |j| [i, j, 0]))).into_iter().collect();
        let grid = grid.with_blocks(&floor, false).unwrap();
        let added: Vec<CellIndex> = (0..2000).map(|_| [rng.below(120), rng.below(120), rng.below(8)]).collect();
        let grid = grid.with_cells(&added, true).unwrap();
        let blocks: Vec<VoxelBlock> = VoxelBlock::from_cells(added.iter().map(|c| [c[0] + 200, c[1], c[2]]));
        let grid = grid.with_blocks(&blocks, true).unwrap();
        assert!(grid.tree.boxes_are_tight());
        check(&mut rng, &grid, 20_000);
    }

    /// The packed box is the bounding box of the bits, for single cells, pairs and
    /// planes, and `with` grows it as adding the cell's bit would.
    #[test]
    fn brick_box_is_the_bits_bounding_box() {
        assert_eq!(BrickBox::of(&[0; 8]), None);
        let mut state = 99u64;
        let mut next = |n: u64| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) % n
        };
        for _ in 0..2000 {
            let mut bits = [0u64; 8];
            let mut cells = Vec::new();
            for _ in 0..=next(5) {
                let c = [next(8) as u32, next(8) as u32, next(8) as u32];
                bits[c[0] as usize] |= 1 << (c[1] * 8 + c[2]);
                cells.push(c);
            }
            let b = BrickBox::of(&bits).unwrap();
            for a in 0..3 {
                assert_eq!(b.lo()[a], cells.iter().map(|c| c[a]).min().unwrap(), "{cells:?}");
                assert_eq!(b.hi()[a], cells.iter().map(|c| c[a]).max().unwrap(), "{cells:?}");
            }
            let extra = [next(8) as u32, next(8) as u32, next(8) as u32];
            bits[extra[0] as usize] |= 1 << (extra[1] * 8 + extra[2]);
            assert_eq!(b.with(extra), BrickBox::of(&bits).unwrap());
        }
    }
}
