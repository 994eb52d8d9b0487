//! The exact first contact of a segment with the occupied closed cells, walking the
//! tree level by level.
//!
//! At each level (64³ blocks, 8³ bricks, 4³ quads, cells) the segment walks the grid
//! of that level cell by cell (Amanatides & Woo). Because cells are closed, a segment
//! running exactly along a face or through an edge also touches the neighbours
//! there, and the walk checks those too. A touched block that holds occupied cells
//! is walked at the next level, over the part of the segment inside it; an empty one
//! is passed in one step. Every contact found is a real one, and the cell of the
//! first contact is reached through the blocks that contain it, so the smallest
//! contact found is the first: the answer is the one a walk over every cell would
//! give. The 4³ level is what lets a sight line pass just above a floor without
//! walking its cells.

use super::CellIndex;
use super::bounds::{CellBox, Clearance, MARGIN_CELLS};
use super::tree::{BRICK_SHIFT, NODE_SHIFT, Tree};
use crate::math::{Point3, floor};
use crate::world::segment::{Segment, clip_slab};

/// One query: the tree, the grid's placement and the segment.
pub(super) struct Walk<'a> {
    tree: &'a Tree,
    resolution: f64,
    origin: Point3<f64>,
    seg: &'a Segment,
    /// The occupied cells' bounding box: minimum cell, one past the maximum.
    lo: CellIndex,
    end: CellIndex,
    /// 1 / resolution and 1 / direction, once per segment rather than per level:
    /// divisions are most of a short walk's cost.
    inv_resolution: f64,
    inv_dir: [f64; 3],
    /// Whether the segment's part in a block clears the block's occupied cells.
    clearance: Clearance,
}

/// log2 of a level's cell side, in cells: cells, 4³ quads, 8³ bricks, 64³ nodes.
const SHIFTS: [u32; 4] = [0, 2, BRICK_SHIFT, NODE_SHIFT];

/// The coarsest level.
pub(super) const TOP: usize = 3;

impl<'a> Walk<'a> {
    pub(super) fn new(
        tree: &'a Tree,
        resolution: f64,
        origin: Point3<f64>,
        seg: &'a Segment,
        lo: CellIndex,
        end: CellIndex,
        boxes: bool,
    ) -> Self {
        let inv_dir = [1.0 / seg.dir[0], 1.0 / seg.dir[1], 1.0 / seg.dir[2]];
        let clearance = Clearance::new(resolution, origin, seg, inv_dir, boxes);
        Walk { tree, resolution, origin, seg, lo, end, inv_resolution: 1.0 / resolution, inv_dir, clearance }
    }

    /// Whether block `c` of level `L` holds an occupied cell, and for bricks the box
    /// of its occupied cells.
    #[inline(always)]
    fn occupied<const L: usize>(&self, c: CellIndex) -> Option<Option<CellBox>> {
        match L {
            0 => self.tree.get(c).then_some(None),
            1 => self.tree.has_quad(c).then_some(None),
            2 => self.tree.brick_box(c).map(Some),
            _ => self.tree.has_node(c).then_some(None),
        }
    }

    /// Walks level `L` over `[t0, t1]`, lowering `best` to any contact found before it.
    pub(super) fn walk<const L: usize>(&self, t0: f64, t1: f64, best: &mut f64) {
        let shift = SHIFTS[L];
        let size = self.resolution * f64::from(1u32 << shift);
        // Powers of two: exact.
        let inv_size = self.inv_resolution / f64::from(1u32 << shift);
        let seg = self.seg;
        // Grid coordinates, in this level's cells.
        let g = |t: f64, a: usize| (seg.origin[a] + seg.dir[a] * t - self.origin[a]) * inv_size;
        let box_lo: CellIndex = self.lo.map(|v| v >> shift);
        let box_end: CellIndex = self.end.map(|v| ((v - 1) >> shift) + 1);
        let mut cell = [0i64; 3];
        let mut step = [0i64; 3];
        let mut t_max = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        // Axes along which the segment lies exactly on a cell boundary: there the
        // closed cells on both sides are touched.
        let mut twin = [false; 3];
        // The walk never leaves the box (plus the layer of cells touching it): entry
        // coordinates are clamped into it and the walk ends when it steps out. With
        // cells far smaller than the float spacing of `t` (or of the entry point),
        // rounding could otherwise start the walk far outside, or stall `t` while the
        // cells advance forever.
        for a in 0..3 {
            // Snap entry points within 1e-9 cells of a plane onto it, so rounding in
            // the clip does not decide whether a face or edge is touched.
            let raw = g(t0, a).clamp((box_lo[a] - 1) as f64, box_end[a] as f64);
            // (`floor(raw + 0.5)` is `raw.round()` within 1e-9 of an integer, all that matters here.)
            let near = floor(raw + 0.5);
            let ga = if (raw - near).abs() < 1e-9 { near } else { raw };
            let fa = floor(ga);
            cell[a] = fa as i64;
            let on_plane = ga == fa;
            let d = seg.dir[a];
            let per_cell = size * self.inv_dir[a].abs();
            if d > 0.0 {
                step[a] = 1;
                t_delta[a] = per_cell;
                t_max[a] = t0 + (fa + 1.0 - ga) * per_cell;
                twin[a] = on_plane; // the cell behind touches the entry point
            } else if d < 0.0 {
                step[a] = -1;
                t_delta[a] = per_cell;
                // On a plane moving down, the current (upper) cell touches only at
                // entry; the walk steps down at t0 itself.
                t_max[a] = t0 + (ga - fa) * per_cell;
            } else {
                twin[a] = on_plane;
            }
        }
        self.visit::<L>(cell, &twin, [false; 3], &step, t0, t1, best);
        if *best <= t0 {
            return;
        }
        // `t1` comes from a clip, `t_next` from sums of steps: a contact exactly at
        // `t1` (a corner where the segment leaves the box) may come out a few ulps
        // after it. Walk on for 1e-9 cells, as entry points snap within 1e-9 cells.
        let slack = 1e-9 * size;
        loop {
            let t_next = t_max[0].min(t_max[1]).min(t_max[2]);
            if t_next.is_nan() || t_next > t1 + slack || t_next > *best {
                return;
            }
            // Every axis whose boundary is crossed at t_next steps together; the cells
            // reached by stepping any subset of them touch the segment at t_next.
            let tied = [t_max[0] == t_next, t_max[1] == t_next, t_max[2] == t_next];
            // Stepping further out of the box reaches no cell that touches it.
            if (0..3)
                .any(|a| tied[a] && ((step[a] > 0 && cell[a] >= box_end[a]) || (step[a] < 0 && cell[a] < box_lo[a])))
            {
                return;
            }
            for a in 0..3 {
                if tied[a] {
                    cell[a] += step[a];
                    t_max[a] += t_delta[a];
                }
            }
            // Twins on moving axes touch only the start point, so they count while the
            // walk is still there (several axes can step at t0 itself).
            let at_start = t_next <= t0;
            let still: [bool; 3] = std::array::from_fn(|a| twin[a] && (step[a] == 0 || at_start));
            let t = t_next.max(t0);
            self.visit::<L>(cell, &still, tied, &step, t, t1, best);
            if *best <= t {
                return;
            }
        }
    }

    /// Whether no occupied cell's closed cube can meet the segment's part `[ta, tb]`:
    /// its bounding box, widened by a cell for rounding, holds none (decided only
    /// when the box spans few bricks).
    #[inline]
    fn part_is_clear(&self, ta: f64, tb: f64) -> bool {
        let (a, b) = (self.seg.point_at(ta), self.seg.point_at(tb));
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        for i in 0..3 {
            let to_cell = |v: f64| floor((v - self.origin[i]) * self.inv_resolution);
            let (l, h) = (to_cell(a[i].min(b[i])) - 2.0, to_cell(a[i].max(b[i])) + 1.0);
            if !(l.is_finite() && h.is_finite()) {
                return false;
            }
            // Within the occupied box (plus one): far coordinates stay small integers.
            lo[i] = l.max((self.lo[i] - 1) as f64) as i64;
            hi[i] = h.min(self.end[i] as f64) as i64;
            if lo[i] > hi[i] {
                return true;
            }
        }
        self.tree.any_in_box(lo, hi, 8) == Some(false)
    }

    /// Whether passing block `c` of level `L` over the part `[ta, tb]` (which clears
    /// its occupied cells) leaves every contact the walk finds as it was. A walk of
    /// the block would also touch cells outside it where the part meets its faces:
    /// at the part's ends, and all along it when the part lies in a face. Such a
    /// contact belongs to a neighbouring block too, whose walk finds it as well, but
    /// its `t` may differ there in the last bit. So the block is passed only when
    /// the part lies in none of its faces and no cell touching either end (within
    /// the clearance margin) is occupied.
    fn nothing_at_the_ends<const L: usize>(&self, c: CellIndex, ta: f64, tb: f64) -> bool {
        let delta = MARGIN_CELLS;
        let cells = |t: f64| -> [f64; 3] {
            let p = self.seg.point_at(t);
            std::array::from_fn(|a| (p[a] - self.origin[a]) * self.inv_resolution)
        };
        let (a, b) = (cells(ta), cells(tb.max(ta)));
        let side = (1i64 << SHIFTS[L]) as f64;
        for i in 0..3 {
            for plane in [c[i] as f64 * side, (c[i] + 1) as f64 * side] {
                if (a[i] - plane).abs() < delta && (b[i] - plane).abs() < delta {
                    return false;
                }
            }
        }
        for g in [a, b] {
            let lo: [i64; 3] = std::array::from_fn(|i| floor(g[i] - delta) as i64);
            let hi: [i64; 3] = std::array::from_fn(|i| floor(g[i] + delta) as i64);
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        if self.tree.get([x, y, z]) {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    /// Whether the part `[ta, tb]` clears every box of node `key`'s cover.
    #[inline]
    fn node_is_cleared(&self, key: CellIndex, ta: f64, tb: f64) -> bool {
        self.tree.node_cover(key).is_some_and(|mut boxes| boxes.all(|b| self.clearance.clears(self.seg, ta, tb, &b)))
    }

    /// Whether the part `[ta, tb]` clears the covers of every node near it (a few
    /// at most): then it touches no occupied cell, and needs no walk.
    pub(super) fn clears_nodes(&self, ta: f64, tb: f64) -> bool {
        if !self.clearance.enabled() {
            return false;
        }
        let (a, b) = (self.seg.point_at(ta), self.seg.point_at(tb));
        let mut first = [0i64; 3];
        let mut last = [0i64; 3];
        for i in 0..3 {
            // The cells near the part's box, one more on each side for rounding.
            let to_cell = |v: f64| floor((v - self.origin[i]) * self.inv_resolution);
            let (l, h) = (to_cell(a[i].min(b[i])) - 1.0, to_cell(a[i].max(b[i])) + 1.0);
            if !(l.is_finite() && h.is_finite()) {
                return false;
            }
            let (l, h) = (l.max((self.lo[i] - 1) as f64) as i64, h.min(self.end[i] as f64) as i64);
            if l > h {
                return true;
            }
            (first[i], last[i]) = (l >> NODE_SHIFT, h >> NODE_SHIFT);
        }
        if (0..3).map(|i| last[i] - first[i] + 1).product::<i64>() > 8 {
            return false;
        }
        for x in first[0]..=last[0] {
            for y in first[1]..=last[1] {
                for z in first[2]..=last[2] {
                    if let Some(mut boxes) = self.tree.node_cover([x, y, z])
                        && !boxes.all(|b| self.clearance.clears(self.seg, ta, tb, &b))
                    {
                        return false;
                    }
                }
            }
        }
        true
    }

    /// Checks `cell` and the cells reached from it by un-stepping any subset of the
    /// `tied` axes or moving to the lower twin on `twin` axes, all touched at `t`: a
    /// contact at the finest level, a walk of the next level inside a coarser one.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn visit<const L: usize>(
        &self,
        cell: CellIndex,
        twin: &[bool; 3],
        tied: [bool; 3],
        step: &[i64; 3],
        t: f64,
        t1: f64,
        best: &mut f64,
    ) {
        let tied_mask = (0..3).fold(0u8, |m, a| m | u8::from(tied[a]) << a);
        let movable = (0..3).fold(tied_mask, |m, a| m | u8::from(twin[a]) << a);
        // The common step: one axis crossed, no face or edge grazed. Only `cell`
        // itself is new.
        let masks = if movable & movable.wrapping_sub(1) == 0 && movable == tied_mask { 1 } else { 8 };
        for mask in 0u8..masks {
            // Un-stepping every tied axis (and nothing else) is the cell the walk just
            // left: checked (or walked into) when it was reached.
            if mask & !movable != 0 || (mask != 0 && mask == tied_mask) {
                continue;
            }
            let mut c = cell;
            for a in 0..3 {
                if mask >> a & 1 == 1 {
                    c[a] -= if tied[a] { step[a] } else { 1 };
                }
            }
            let Some(cells) = self.occupied::<L>(c) else {
                continue;
            };
            if L == 0 {
                *best = best.min(t.min(t1));
                return;
            }
            if t > *best {
                return;
            }
            // The part of the segment inside the block: from where it touched it to
            // where it leaves (at least `t`, so a graze is still walked).
            let size = self.resolution * f64::from(1u32 << SHIFTS[L]);
            let (mut ta, mut tb) = (t, t1);
            let mut inside = true;
            for (a, index) in c.iter().enumerate() {
                let lo = self.origin[a] + *index as f64 * size;
                inside &= clip_slab(self.seg.origin[a], self.seg.dir[a], lo, lo + size, &mut ta, &mut tb);
            }
            let exit = if inside { tb.max(t) } else { t };
            let end = exit.min(t1).min(*best);
            // A part that stays clear of the block's occupied cells (a sight line
            // above a floor slab, beside a wall) is passed without walking them.
            let clear = match L {
                3 => self.node_is_cleared(c, t, end),
                _ => cells.is_some_and(|cells| self.clearance.clears(self.seg, t, end, &cells)),
            };
            if clear && self.nothing_at_the_ends::<L>(c, t, end) {
                continue;
            }
            // The cells around that part of the segment, when few, settle it at once.
            if L >= 2 && self.part_is_clear(t, end) {
                continue;
            }
            match L {
                1 => self.walk::<0>(t, end, best),
                2 => self.walk::<1>(t, end, best),
                _ => self.walk::<2>(t, end, best),
            }
        }
    }
}
