//! The sparse storage of a voxel grid: a tree of fixed depth, root → node → brick.
//!
//! A brick is 8³ cells as 512 bits; a node holds up to 8³ bricks (64³ cells); the
//! root is a dense array over the nodes' bounding box. Empty bricks and nodes are not
//! stored, so memory follows the occupied cells (about 1–3 bytes per cell on surfaces),
//! and the walk of [`super::walk`] skips empty 64³ and 8³ blocks in one step.
//!
//! Nodes are shared between versions of a map (`Arc`): an update copies the root's
//! index and the nodes it touches, not the map, so a 10 000-cell change to a 50 M-cell
//! map costs in proportion to the change.

use super::CellIndex;
use super::bounds::{BrickBox, CellBox};
use super::cover::Cover;
use std::collections::HashMap;
use std::sync::Arc;

/// log2 of a brick's side in cells.
pub(super) const BRICK_SHIFT: u32 = 3;
/// log2 of a node's side in cells.
pub(super) const NODE_SHIFT: u32 = 6;
/// Bricks per node.
const SLOTS: usize = 512;
/// The bits of a brick: word `x`, bit `8y + z`.
pub(crate) type Bits = [u64; 8];
/// An empty root slot.
const EMPTY: u32 = u32::MAX;

/// The bits (`8y + z`) of a brick word in the 4 × 4 quarter (y half, z half) =
/// (i / 2, i % 2).
const QUAD_MASKS: [u64; 4] = {
    let mut masks = [0u64; 4];
    let mut i = 0;
    while i < 4 {
        let (y0, z0) = ((i / 2) * 4, (i % 2) * 4);
        let mut y = 0;
        while y < 4 {
            masks[i] |= 0xf << ((y0 + y) * 8 + z0);
            y += 1;
        }
        i += 1;
    }
    masks
};

/// The bit of local cell (x, y, z), each in 0..8: (word, bit).
#[inline]
fn bit_of(x: i64, y: i64, z: i64) -> (usize, u32) {
    (x as usize, (y * 8 + z) as u32)
}

/// The slot of brick (x, y, z) within its node, each in 0..8.
#[inline]
fn slot_of(x: i64, y: i64, z: i64) -> usize {
    ((x * 8 + y) * 8 + z) as usize
}

/// The bits `8y + z` of a brick word (or of a node's `present` word) with y in
/// `y0..=y1` and z in `z0..=z1`, each range within 0..8.
#[inline]
fn rows_and_columns(y0: i64, y1: i64, z0: i64, z1: i64) -> u64 {
    let rows = (u64::MAX >> (8 * (7 - y1))) & (u64::MAX << (8 * y0));
    rows & (((0xffu64 >> (7 - z1 + z0)) << z0) * 0x0101_0101_0101_0101)
}

/// A non-empty brick: its slot in the node, its cells' box and its bits. The box
/// takes padding the slot left (the element is 72 bytes with or without it).
#[derive(Clone, Debug)]
struct Brick {
    slot: u16,
    bounds: BrickBox,
    bits: Bits,
}

/// Up to 8³ bricks: 64³ cells.
#[derive(Clone, Debug)]
pub(super) struct Node {
    /// Node coordinates: the cell index divided by 64, rounded down.
    pub(super) key: [i64; 3],
    /// Brick slot → 1 + its index in `bricks`; 0 for an empty brick.
    slots: [u16; SLOTS],
    /// The non-empty bricks.
    bricks: Vec<Brick>,
    /// Which bricks are non-empty, laid out as a brick's cells (word x, bit 8y + z):
    /// a box test over the bricks is then the same few word operations as over
    /// the cells of one brick.
    present: Bits,
    /// Occupied cells.
    cells: u32,
    /// The occupied cells' bounding box, in cells from the node's minimum corner,
    /// inclusive; meaningless while `cells == 0`.
    lo: [i64; 3],
    hi: [i64; 3],
    /// A few boxes holding the occupied cells; meaningless while `cells == 0`.
    cover: Cover,
}

impl Node {
    fn new(key: [i64; 3]) -> Self {
        Node {
            key,
            slots: [0; SLOTS],
            bricks: Vec::new(),
            present: [0; 8],
            cells: 0,
            lo: [0; 3],
            hi: [0; 3],
            cover: Cover::default(),
        }
    }

    #[inline]
    fn brick(&self, slot: usize) -> Option<&Bits> {
        let i = self.slots[slot];
        (i != 0).then(|| &self.bricks[usize::from(i) - 1].bits)
    }

    /// Sets (`occupied`) or clears the cells of `bits` in brick `slot`.
    fn edit(&mut self, slot: usize, bits: &Bits, occupied: bool) {
        let i = self.slots[slot];
        if i == 0 {
            if !occupied {
                return;
            }
            let Some(bounds) = BrickBox::of(bits) else { return };
            self.bricks.push(Brick { slot: slot as u16, bounds, bits: *bits });
            self.slots[slot] = self.bricks.len() as u16;
            self.present[slot >> 6] |= 1 << (slot & 63);
            self.cells += bits.iter().map(|w| w.count_ones()).sum::<u32>();
            return;
        }
        let index = usize::from(i) - 1;
        let brick = &mut self.bricks[index];
        let before: u32 = brick.bits.iter().map(|w| w.count_ones()).sum();
        for (w, b) in brick.bits.iter_mut().zip(bits) {
            *w = if occupied { *w | b } else { *w & !b };
        }
        let after: u32 = brick.bits.iter().map(|w| w.count_ones()).sum();
        self.cells = self.cells + after - before;
        if let Some(bounds) = BrickBox::of(&brick.bits) {
            brick.bounds = bounds;
        }
        if after == 0 {
            self.slots[slot] = 0;
            self.present[slot >> 6] &= !(1 << (slot & 63));
            self.bricks.swap_remove(index);
            if let Some(moved) = self.bricks.get(index) {
                self.slots[usize::from(moved.slot)] = i;
            }
        }
    }

    /// Sets or clears one bit of brick `slot`: the common case of [`Node::edit`]
    /// without counting whole bricks.
    fn edit_bit(&mut self, slot: usize, word: usize, bit: u32, occupied: bool) {
        let i = self.slots[slot];
        if i == 0 || !occupied {
            let mut bits = [0u64; 8];
            bits[word] = 1 << bit;
            return self.edit(slot, &bits, occupied);
        }
        let brick = &mut self.bricks[usize::from(i) - 1];
        if brick.bits[word] >> bit & 1 == 0 {
            brick.bits[word] |= 1 << bit;
            brick.bounds = brick.bounds.with([word as u32, bit >> 3, bit & 7]);
            self.cells += 1;
        }
    }

    /// Recomputes the bounding box and the cover from the bricks.
    fn refresh_bounds(&mut self) {
        self.cover = Cover::of((0..SLOTS).filter_map(|slot| {
            let i = self.slots[slot];
            let s = slot as i64;
            (i != 0).then(|| ([(s >> 6) * 8, (s >> 3 & 7) * 8, (s & 7) * 8], self.bricks[usize::from(i) - 1].bounds))
        }));
        let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
        for Brick { slot, bounds, .. } in &self.bricks {
            let s = i64::from(*slot);
            let base = [(s >> 6) * 8, (s >> 3 & 7) * 8, (s & 7) * 8];
            let (first, last) = (bounds.lo(), bounds.hi());
            let b_lo: [i64; 3] = std::array::from_fn(|a| base[a] + i64::from(first[a]));
            let b_hi: [i64; 3] = std::array::from_fn(|a| base[a] + i64::from(last[a]));
            for a in 0..3 {
                lo[a] = lo[a].min(b_lo[a]);
                hi[a] = hi[a].max(b_hi[a]);
            }
        }
        (self.lo, self.hi) = (lo, hi);
    }

    /// [`Tree::any_in_box`] within this node (key `key`), spending `budget` a brick
    /// word and a brick looked into.
    #[inline]
    fn any_in_box(&self, budget: &mut u32, key: [i64; 3], lo: CellIndex, hi: CellIndex) -> Option<bool> {
        // The box in cells from the node's corner, cut to the occupied cells' box.
        let mut l = [0i64; 3];
        let mut h = [0i64; 3];
        for a in 0..3 {
            let base = key[a] << NODE_SHIFT;
            l[a] = (lo[a] - base).max(self.lo[a]);
            h[a] = (hi[a] - base).min(self.hi[a]);
            if l[a] > h[a] {
                return Some(false);
            }
        }
        // The bricks the box meets, and those it covers whole (every cell of a
        // non-empty covered brick is in the box: one found).
        let (b0, b1) = (l.map(|v| v >> 3), h.map(|v| v >> 3));
        let f0: [i64; 3] = std::array::from_fn(|a| b0[a] + i64::from(l[a] & 7 != 0));
        let f1: [i64; 3] = std::array::from_fn(|a| b1[a] - i64::from(h[a] & 7 != 7));
        let met = rows_and_columns(b0[1], b1[1], b0[2], b1[2]);
        let covered = if f0[1] <= f1[1] && f0[2] <= f1[2] { rows_and_columns(f0[1], f1[1], f0[2], f1[2]) } else { 0 };
        for bx in b0[0]..=b1[0] {
            *budget = budget.checked_sub(1)?;
            let mut partial = self.present[bx as usize] & met;
            if (f0[0]..=f1[0]).contains(&bx) {
                if partial & covered != 0 {
                    return Some(true);
                }
                partial &= !covered;
            }
            let (x0, x1) = ((l[0] - bx * 8).max(0) as usize, (h[0] - bx * 8).min(7) as usize);
            while partial != 0 {
                *budget = budget.checked_sub(1)?;
                let bit = i64::from(partial.trailing_zeros());
                partial &= partial - 1;
                let (by, bz) = (bit >> 3, bit & 7);
                let Some(bits) = self.brick(slot_of(bx, by, bz)) else { continue };
                let (y0, y1) = ((l[1] - by * 8).max(0), (h[1] - by * 8).min(7));
                let (z0, z1) = ((l[2] - bz * 8).max(0), (h[2] - bz * 8).min(7));
                let yz = rows_and_columns(y0, y1, z0, z1);
                if bits[x0..=x1].iter().any(|w| w & yz != 0) {
                    return Some(true);
                }
            }
        }
        Some(false)
    }

    /// The non-empty bricks in slot order: (brick's minimum cell, bits).
    fn bricks_in_order(&self) -> impl Iterator<Item = (CellIndex, &Bits)> + '_ {
        let base = self.key.map(|k| k << NODE_SHIFT);
        (0..SLOTS).filter_map(move |slot| {
            let bits = self.brick(slot)?;
            let s = slot as i64;
            Some(([base[0] + (s >> 6) * 8, base[1] + (s >> 3 & 7) * 8, base[2] + (s & 7) * 8], bits))
        })
    }
}

/// The tree: a dense root over the nodes' bounding box, the nodes, and totals.
#[derive(Clone, Debug, Default)]
pub(super) struct Tree {
    /// The root's minimum node key and extent, in nodes.
    lo: [i64; 3],
    dims: [i64; 3],
    /// Root slot → index in `nodes`, or [`EMPTY`].
    slots: Vec<u32>,
    nodes: Vec<Arc<Node>>,
    cells: u64,
    /// The occupied cells' bounding box: minimum cell and one past the maximum.
    bounds: Option<(CellIndex, CellIndex)>,
}

/// Why an edit could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum TreeLimit {
    /// More occupied cells than allowed.
    Cells(u64),
    /// The root would span more than allowed nodes.
    Span(u64),
}

impl Tree {
    /// Occupied cells.
    pub(super) fn cells(&self) -> u64 {
        self.cells
    }

    /// Minimum occupied cell and one past the maximum, per axis.
    pub(super) fn bounds(&self) -> Option<(CellIndex, CellIndex)> {
        self.bounds
    }

    /// Stored nodes and bricks, for the memory estimate.
    pub(super) fn counts(&self) -> (usize, usize, usize) {
        (self.slots.len(), self.nodes.len(), self.nodes.iter().map(|n| n.bricks.len()).sum())
    }

    #[inline]
    fn node(&self, key: [i64; 3]) -> Option<&Node> {
        let (x, y, z) = (key[0] - self.lo[0], key[1] - self.lo[1], key[2] - self.lo[2]);
        if !((0..self.dims[0]).contains(&x) && (0..self.dims[1]).contains(&y) && (0..self.dims[2]).contains(&z)) {
            return None;
        }
        let i = self.slots[((z * self.dims[1] + y) * self.dims[0] + x) as usize];
        (i != EMPTY).then(|| self.nodes[i as usize].as_ref())
    }

    /// Whether the 64³ block with node key `key` holds an occupied cell.
    #[inline]
    pub(super) fn has_node(&self, key: [i64; 3]) -> bool {
        self.node(key).is_some()
    }

    /// The boxes covering the occupied cells of the 64³ block with node key `key`,
    /// or `None` when it has none.
    #[inline]
    pub(super) fn node_cover(&self, key: [i64; 3]) -> Option<impl Iterator<Item = CellBox> + '_> {
        let node = self.node(key)?;
        Some(node.cover.boxes(key.map(|k| k << NODE_SHIFT)))
    }

    /// The box of the occupied cells of the 8³ brick with brick key `key` (cell index
    /// >> 3), or `None` when it has none.
    #[inline]
    pub(super) fn brick_box(&self, key: [i64; 3]) -> Option<CellBox> {
        let node = self.node(key.map(|k| k >> (NODE_SHIFT - BRICK_SHIFT)))?;
        let i = node.slots[slot_of(key[0] & 7, key[1] & 7, key[2] & 7)];
        if i == 0 {
            return None;
        }
        let bounds = node.bricks[usize::from(i) - 1].bounds;
        let (lo, hi, base) = (bounds.lo(), bounds.hi(), key.map(|k| k << BRICK_SHIFT));
        Some(CellBox {
            lo: std::array::from_fn(|a| base[a] + i64::from(lo[a])),
            hi: std::array::from_fn(|a| base[a] + i64::from(hi[a])),
        })
    }

    /// Whether the 4³ block with key `key` (cell index >> 2) holds an occupied cell.
    #[inline]
    pub(super) fn has_quad(&self, key: [i64; 3]) -> bool {
        let Some(node) = self.node(key.map(|k| k >> (NODE_SHIFT - 2))) else {
            return false;
        };
        let Some(bits) = node.brick(slot_of(key[0] >> 1 & 7, key[1] >> 1 & 7, key[2] >> 1 & 7)) else {
            return false;
        };
        let x = ((key[0] & 1) * 4) as usize;
        let words = bits[x] | bits[x + 1] | bits[x + 2] | bits[x + 3];
        words & QUAD_MASKS[((key[1] & 1) * 2 + (key[2] & 1)) as usize] != 0
    }

    /// Whether an occupied cell lies in the cells `lo..=hi`: `Some(false)` proven
    /// empty, `Some(true)` found, `None` when the box spans more than `budget`
    /// bricks or the test would take more than `budget` node lookups, brick words
    /// and bricks looked into.
    pub(super) fn any_in_box(&self, lo: CellIndex, hi: CellIndex, mut budget: u32) -> Option<bool> {
        // Give up before any work when the box's nodes alone exceed the budget.
        let nodes = (0..3)
            .try_fold(1u64, |n, a| n.checked_mul(((hi[a] >> NODE_SHIFT) - (lo[a] >> NODE_SHIFT) + 1).max(0) as u64));
        if nodes.is_none_or(|b| b > u64::from(budget)) {
            return None;
        }
        // Plain loops over inclusive bounds: this runs for most candidates (the
        // collision star's box), and range iterators cost more than the lookups.
        let mut nx = lo[0] >> NODE_SHIFT;
        while nx <= hi[0] >> NODE_SHIFT {
            let mut ny = lo[1] >> NODE_SHIFT;
            while ny <= hi[1] >> NODE_SHIFT {
                let mut nz = lo[2] >> NODE_SHIFT;
                while nz <= hi[2] >> NODE_SHIFT {
                    budget = budget.checked_sub(1)?;
                    if let Some(node) = self.node([nx, ny, nz])
                        && node.any_in_box(&mut budget, [nx, ny, nz], lo, hi)?
                    {
                        return Some(true);
                    }
                    nz += 1;
                }
                ny += 1;
            }
            nx += 1;
        }
        Some(false)
    }

    /// Calls `f` with the key (cell index >> 3) of every non-empty 8³ brick whose key
    /// lies in `lo..=hi`, node by node.
    pub(super) fn for_each_brick_in(&self, lo: [i64; 3], hi: [i64; 3], mut f: impl FnMut([i64; 3])) {
        const PER_NODE: i64 = 1 << (NODE_SHIFT - BRICK_SHIFT);
        const SHIFT: u32 = NODE_SHIFT - BRICK_SHIFT;
        for nx in lo[0] >> SHIFT..=hi[0] >> SHIFT {
            for ny in lo[1] >> SHIFT..=hi[1] >> SHIFT {
                for nz in lo[2] >> SHIFT..=hi[2] >> SHIFT {
                    let Some(node) = self.node([nx, ny, nz]) else { continue };
                    let base = [nx * PER_NODE, ny * PER_NODE, nz * PER_NODE];
                    // The node's bricks within the range, from its corner (each 0..8).
                    let l: [i64; 3] = std::array::from_fn(|a| (lo[a] - base[a]).max(0));
                    let h: [i64; 3] = std::array::from_fn(|a| (hi[a] - base[a]).min(PER_NODE - 1));
                    let yz = rows_and_columns(l[1], h[1], l[2], h[2]);
                    for bx in l[0]..=h[0] {
                        let mut present = node.present[bx as usize] & yz;
                        while present != 0 {
                            let bit = i64::from(present.trailing_zeros());
                            present &= present - 1;
                            f([base[0] + bx, base[1] + (bit >> 3), base[2] + (bit & 7)]);
                        }
                    }
                }
            }
        }
    }

    /// Whether cell `c` is occupied.
    #[inline]
    pub(super) fn get(&self, c: CellIndex) -> bool {
        let Some(node) = self.node(c.map(|v| v >> NODE_SHIFT)) else {
            return false;
        };
        let Some(bits) = node.brick(slot_of(c[0] >> 3 & 7, c[1] >> 3 & 7, c[2] >> 3 & 7)) else {
            return false;
        };
        let (w, b) = bit_of(c[0] & 7, c[1] & 7, c[2] & 7);
        bits[w] >> b & 1 == 1
    }

    /// The nodes in key order (x, then y, then z).
    fn nodes_in_order(&self) -> impl Iterator<Item = &Node> + '_ {
        let d = self.dims;
        (0..d[0]).flat_map(move |x| {
            (0..d[1]).flat_map(move |y| {
                (0..d[2]).filter_map(move |z| {
                    let i = self.slots[((z * d[1] + y) * d[0] + x) as usize];
                    (i != EMPTY).then(|| self.nodes[i as usize].as_ref())
                })
            })
        })
    }

    /// The non-empty bricks in the canonical order (node key, then brick, each x, y,
    /// z): the brick's minimum cell and its bits.
    pub(super) fn bricks(&self) -> impl Iterator<Item = (CellIndex, &Bits)> + '_ {
        self.nodes_in_order().flat_map(Node::bricks_in_order)
    }

    /// An editor over a copy of this tree (nodes are shared until written).
    pub(super) fn edit(&self) -> Editor {
        Editor { tree: self.clone(), added: HashMap::new(), dirty: vec![false; self.nodes.len()], last: None }
    }
}

/// Edits a copy of a tree; [`Editor::finish`] checks the limits and rebuilds the root.
pub(super) struct Editor {
    tree: Tree,
    /// Nodes created by this edit, by key (not yet in the root).
    added: HashMap<[i64; 3], usize>,
    /// Per node: written by this edit.
    dirty: Vec<bool>,
    /// The last node written: runs of cells usually share one.
    last: Option<([i64; 3], usize)>,
}

impl Editor {
    fn node_mut(&mut self, key: [i64; 3], create: bool) -> Option<&mut Node> {
        let index = match self.last {
            Some((k, i)) if k == key => i,
            _ => {
                let found = self.tree.root_index(key).or_else(|| self.added.get(&key).copied());
                let i = match found {
                    Some(i) => i,
                    None if create => {
                        self.tree.nodes.push(Arc::new(Node::new(key)));
                        self.dirty.push(false);
                        let i = self.tree.nodes.len() - 1;
                        self.added.insert(key, i);
                        i
                    }
                    None => return None,
                };
                self.dirty[i] = true;
                self.last = Some((key, i));
                i
            }
        };
        Some(Arc::make_mut(&mut self.tree.nodes[index]))
    }

    /// Sets or clears the cells of `bits` in the brick whose minimum cell is `min`
    /// (each index a multiple of 8).
    pub(super) fn edit_brick(&mut self, min: CellIndex, bits: &Bits, occupied: bool) {
        let key = min.map(|v| v >> NODE_SHIFT);
        if let Some(node) = self.node_mut(key, occupied) {
            let before = node.cells;
            node.edit(slot_of(min[0] >> 3 & 7, min[1] >> 3 & 7, min[2] >> 3 & 7), bits, occupied);
            let after = node.cells;
            self.tree.cells = self.tree.cells + u64::from(after) - u64::from(before);
        }
    }

    /// Sets or clears one cell.
    pub(super) fn edit_cell(&mut self, c: CellIndex, occupied: bool) {
        let key = c.map(|v| v >> NODE_SHIFT);
        if let Some(node) = self.node_mut(key, occupied) {
            let before = node.cells;
            let (w, b) = bit_of(c[0] & 7, c[1] & 7, c[2] & 7);
            node.edit_bit(slot_of(c[0] >> 3 & 7, c[1] >> 3 & 7, c[2] >> 3 & 7), w, b, occupied);
            let after = node.cells;
            self.tree.cells = self.tree.cells + u64::from(after) - u64::from(before);
        }
    }

    /// Occupied cells so far.
    pub(super) fn cells(&self) -> u64 {
        self.tree.cells
    }

    /// The edited tree: empty nodes dropped, bounds refreshed, the root rebuilt if
    /// nodes came or went. Refused if it holds more than `max_cells` cells or its
    /// root would span more than `max_span` nodes.
    pub(super) fn finish(mut self, max_cells: u64, max_span: u64) -> Result<Tree, TreeLimit> {
        if self.tree.cells > max_cells {
            return Err(TreeLimit::Cells(self.tree.cells));
        }
        let mut emptied = false;
        for (i, _) in self.dirty.iter().enumerate().filter(|(_, d)| **d) {
            let node = Arc::make_mut(&mut self.tree.nodes[i]);
            if node.cells == 0 {
                emptied = true;
            } else {
                node.refresh_bounds();
            }
        }
        let mut tree = self.tree;
        if emptied {
            tree.nodes.retain(|n| n.cells > 0);
        }
        if emptied || !self.added.is_empty() {
            tree.rebuild_root(max_span)?;
        }
        tree.bounds = tree.nodes.iter().fold(None, |acc, n| {
            let base = n.key.map(|k| k << NODE_SHIFT);
            let lo = [base[0] + n.lo[0], base[1] + n.lo[1], base[2] + n.lo[2]];
            let end = [base[0] + n.hi[0] + 1, base[1] + n.hi[1] + 1, base[2] + n.hi[2] + 1];
            Some(match acc {
                None => (lo, end),
                Some((l, e)) => (
                    std::array::from_fn(|a| std::cmp::min(l[a], lo[a])),
                    std::array::from_fn(|a| std::cmp::max(e[a], end[a])),
                ),
            })
        });
        Ok(tree)
    }
}

impl Tree {
    fn root_index(&self, key: [i64; 3]) -> Option<usize> {
        let (x, y, z) = (key[0] - self.lo[0], key[1] - self.lo[1], key[2] - self.lo[2]);
        if !((0..self.dims[0]).contains(&x) && (0..self.dims[1]).contains(&y) && (0..self.dims[2]).contains(&z)) {
            return None;
        }
        let i = self.slots[((z * self.dims[1] + y) * self.dims[0] + x) as usize];
        (i != EMPTY).then_some(i as usize)
    }

    fn rebuild_root(&mut self, max_span: u64) -> Result<(), TreeLimit> {
        let Some(first) = self.nodes.first() else {
            (self.lo, self.dims, self.slots) = ([0; 3], [0; 3], Vec::new());
            return Ok(());
        };
        let (mut lo, mut hi) = (first.key, first.key);
        for n in &self.nodes {
            for a in 0..3 {
                lo[a] = lo[a].min(n.key[a]);
                hi[a] = hi[a].max(n.key[a]);
            }
        }
        let dims = [hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1];
        let span = dims.iter().try_fold(1u64, |acc, d| acc.checked_mul(*d as u64)).unwrap_or(u64::MAX);
        if span > max_span {
            return Err(TreeLimit::Span(span));
        }
        let mut slots = vec![EMPTY; span as usize];
        for (i, n) in self.nodes.iter().enumerate() {
            let (x, y, z) = (n.key[0] - lo[0], n.key[1] - lo[1], n.key[2] - lo[2]);
            slots[((z * dims[1] + y) * dims[0] + x) as usize] = i as u32;
        }
        (self.lo, self.dims, self.slots) = (lo, dims, slots);
        Ok(())
    }
}

#[cfg(test)]
impl Tree {
    /// Whether every brick's stored box is the box of its bits, every node's box the
    /// box of its bricks' cells, and every node's cover holds each of its cells.
    pub(super) fn boxes_are_tight(&self) -> bool {
        self.nodes.iter().all(|node| {
            let bricks_ok = node.bricks.iter().all(|b| BrickBox::of(&b.bits) == Some(b.bounds));
            let base = node.key.map(|k| k << NODE_SHIFT);
            let cells: Vec<CellIndex> = node.bricks_in_order().flat_map(|(min, bits)| cells_of(min, bits)).collect();
            let node_ok = (0..3).all(|a| {
                let lo = cells.iter().map(|c| c[a] - base[a]).min();
                let hi = cells.iter().map(|c| c[a] - base[a]).max();
                lo == Some(node.lo[a]) && hi == Some(node.hi[a])
            });
            let boxes: Vec<CellBox> = node.cover.boxes(base).collect();
            let covered =
                cells.iter().all(|c| boxes.iter().any(|b| (0..3).all(|a| b.lo[a] <= c[a] && c[a] <= b.hi[a])));
            bricks_ok && node_ok && covered
        })
    }
}

/// The 64-bit mask of a 4³ block within a brick: bit `16x + 4y + z` for the block's
/// local cell (x, y, z). `corner` picks the block: each 0 or 4.
pub(crate) fn block_of(bits: &Bits, corner: [i64; 3]) -> u64 {
    let mut mask = 0u64;
    for x in 0..4 {
        let word = bits[(corner[0] + x) as usize];
        for y in 0..4 {
            let row = word >> ((corner[1] + y) * 8 + corner[2]) & 0xf;
            mask |= row << (x * 16 + y * 4);
        }
    }
    mask
}

/// The brick bits of a 4³ block mask placed at `corner` (each 0 or 4).
pub(crate) fn bits_of_block(mask: u64, corner: [i64; 3]) -> Bits {
    let mut bits = [0u64; 8];
    for x in 0..4 {
        for y in 0..4 {
            let row = mask >> (x * 16 + y * 4) & 0xf;
            bits[(corner[0] + x) as usize] |= row << ((corner[1] + y) * 8 + corner[2]);
        }
    }
    bits
}

/// The cells of a brick's bits, in order (x, then y, then z).
pub(super) fn cells_of(min: CellIndex, bits: &Bits) -> impl Iterator<Item = CellIndex> + '_ {
    (0..8i64).flat_map(move |x| {
        let mut word = bits[x as usize];
        std::iter::from_fn(move || {
            if word == 0 {
                return None;
            }
            let b = i64::from(word.trailing_zeros());
            word &= word - 1;
            Some([min[0] + x, min[1] + (b >> 3), min[2] + (b & 7)])
        })
    })
}
