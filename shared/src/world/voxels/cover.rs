//! A node's occupied cells covered by a few boxes: the coarse level a segment is
//! tested against before it walks a node's bricks.
//!
//! One box per node (its cells' bounding box) is useless where it matters: a room's
//! floor and a wall beside it span the whole node. A handful of boxes, grown from
//! the bricks' boxes, keep the floor a slab, a wall a slab and a table a slab, so a
//! sight line passing above the floor clears the node in a few box tests instead of
//! a walk over its bricks. The boxes hold every occupied cell of the node; how
//! tightly decides only how often a segment clears them.

use super::bounds::{BrickBox, CellBox};

/// Most boxes a node keeps.
pub(super) const COVER_BOXES: usize = 8;

/// A box of cells within a node, from its minimum corner (each 0..64), inclusive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
struct LocalBox {
    lo: [u8; 3],
    hi: [u8; 3],
}

impl LocalBox {
    fn volume(&self) -> u64 {
        (0..3).map(|a| u64::from(self.hi[a] - self.lo[a]) + 1).product()
    }

    fn union(&self, other: &LocalBox) -> LocalBox {
        LocalBox {
            lo: std::array::from_fn(|a| self.lo[a].min(other.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(other.hi[a])),
        }
    }
}

/// Up to [`COVER_BOXES`] boxes holding every occupied cell of a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub(super) struct Cover {
    boxes: [LocalBox; COVER_BOXES],
    len: u8,
}

impl Cover {
    /// The cover of a node's bricks, given in slot order as (brick's minimum cell
    /// from the node's corner, its cells' box): a brick joins the box whose union
    /// with it wastes least, unless that union is more than twice their volumes
    /// and a box is still free. The same bricks give the same cover.
    pub(super) fn of(bricks: impl Iterator<Item = ([i64; 3], BrickBox)>) -> Cover {
        let mut cover = Cover::default();
        for (min, bounds) in bricks {
            let (lo, hi) = (bounds.lo(), bounds.hi());
            let brick = LocalBox {
                lo: std::array::from_fn(|a| (min[a] + i64::from(lo[a])) as u8),
                hi: std::array::from_fn(|a| (min[a] + i64::from(hi[a])) as u8),
            };
            let boxes = &mut cover.boxes[..usize::from(cover.len)];
            let best = boxes
                .iter()
                .enumerate()
                .map(|(i, b)| (b.union(&brick).volume() - b.volume(), i))
                .min()
                .map(|(growth, i)| (growth, i, boxes[i].volume()));
            match best {
                Some((growth, i, volume))
                    if growth + volume <= 2 * (volume + brick.volume()) || usize::from(cover.len) == COVER_BOXES =>
                {
                    boxes[i] = boxes[i].union(&brick);
                }
                _ => {
                    cover.boxes[usize::from(cover.len)] = brick;
                    cover.len += 1;
                }
            }
        }
        cover
    }

    /// The boxes in absolute cells, for the node whose minimum cell is `base`.
    pub(super) fn boxes(&self, base: [i64; 3]) -> impl Iterator<Item = CellBox> + '_ {
        self.boxes[..usize::from(self.len)].iter().map(move |b| CellBox {
            lo: std::array::from_fn(|a| base[a] + i64::from(b.lo[a])),
            hi: std::array::from_fn(|a| base[a] + i64::from(b.hi[a])),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brick(min: [i64; 3], lo: [u32; 3], hi: [u32; 3]) -> ([i64; 3], BrickBox) {
        let mut bits = [0u64; 8];
        for c in [lo, hi] {
            bits[c[0] as usize] |= 1 << (c[1] * 8 + c[2]);
        }
        (min, BrickBox::of(&bits).unwrap())
    }

    /// A floor of bricks and a wall of bricks standing on it: two slabs, and every
    /// brick's box inside one of them.
    #[test]
    fn a_floor_and_a_wall_stay_two_slabs() {
        let mut bricks = Vec::new();
        for x in 0..8 {
            for y in 0..8 {
                for z in 0..8 {
                    if z == 0 && x != 4 {
                        bricks.push(brick([x * 8, y * 8, 0], [0, 0, 0], [7, 7, 0]));
                    } else if x == 4 {
                        // The wall at x = 36; its bottom bricks hold the floor too.
                        let lo = if z == 0 { [0, 0, 0] } else { [4, 0, 0] };
                        bricks.push(brick([32, y * 8, z * 8], lo, [4, 7, 7]));
                    }
                }
            }
        }
        bricks.sort_by_key(|(min, _)| *min);
        let cover = Cover::of(bricks.iter().copied());
        let boxes: Vec<CellBox> = cover.boxes([0; 3]).collect();
        assert_eq!(boxes.len(), 2, "{boxes:?}");
        for (min, b) in &bricks {
            let (lo, hi) = (b.lo(), b.hi());
            assert!(boxes.iter().any(|c| {
                (0..3).all(|a| c.lo[a] <= min[a] + i64::from(lo[a]) && min[a] + i64::from(hi[a]) <= c.hi[a])
            }));
        }
        let volume: i64 = boxes.iter().map(|c| (0..3).map(|a| c.hi[a] - c.lo[a] + 1).product::<i64>()).sum();
        assert!(volume <= 64 * 64 + 8 * 64 * 64, "{volume}: {boxes:?}");
    }
}
