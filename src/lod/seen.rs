//! The pixels each patch showed in earlier frames of the same view: what
//! the frames' own depth says of hidden ground, which the view model
//! counts as seen.
//!
//! The view model knows how many pixels a block covers from where it is
//! seen, not how many of them nearer ground hides. A frame that counts,
//! for each patch, the pixels whose front-most surface lies on it tells
//! the next frames of the same view how much of each block shows: the
//! plan scales a block's modelled pixels over tau down to the pixels its
//! patches showed (`SeenPixels::block_pixels`), never up. Counts from
//! several frames of one view are kept as each patch's largest, so a
//! patch that showed through once, drawn coarser, keeps the pixels it
//! showed and the choice settles instead of swinging between levels.
//!
//! A block can also show fewer pixels than the model counts because it was
//! drawn coarser than the reference: a spike drawn away shows the ground or
//! sky behind it. Those pixels are not hidden, and they are exactly the
//! ones over tau. So each count keeps the level its patch was drawn at
//! (`SeenPixels::drawn_level`), and the plan takes the pixels the model put
//! over tau at that level as possibly missing rather than hidden.

use crate::terrain::PatchGrid;

/// A patch's drawn level where no frame counted it drawn (outside the
/// frustum): `SeenPixels::drawn_level` reads None.
pub const NOT_DRAWN: u8 = u8::MAX;

/// Each patch's largest count of pixels shown, over the frames counted,
/// and the level it was drawn at in that frame, with a summed-area table
/// over the patch grid so that a block's pixels are four reads.
#[derive(Clone, Debug, PartialEq)]
pub struct SeenPixels {
    cols: usize,
    rows: usize,
    /// Per patch, row-major (`PatchGrid::patch_index`).
    counts: Vec<u32>,
    /// Per patch, the level index it was drawn at when its count was
    /// taken (`FramePlan::patch_levels`), `NOT_DRAWN` where it was not.
    levels: Vec<u8>,
    /// (rows + 1) x (cols + 1): the pixels of the patches above and left
    /// of each boundary point.
    sums: Vec<u64>,
}

/// Why counts, or the levels beside them, do not fit a grid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{got} pixel counts or drawn levels for a grid of {patches} patches")]
pub struct SeenCountError {
    pub got: usize,
    pub patches: usize,
}

impl SeenPixels {
    /// One frame's counts and the levels its patches were drawn at, a
    /// patch each in row-major order.
    pub fn new(grid: &PatchGrid, counts: &[u32], levels: &[u8]) -> Result<Self, SeenCountError> {
        for got in [counts.len(), levels.len()] {
            if got != grid.patch_count() {
                return Err(SeenCountError {
                    got,
                    patches: grid.patch_count(),
                });
            }
        }
        let mut seen = SeenPixels {
            cols: grid.patch_cols(),
            rows: grid.patch_rows(),
            counts: counts.to_vec(),
            levels: levels.to_vec(),
            sums: Vec::new(),
        };
        seen.sum();
        Ok(seen)
    }

    /// Adds another frame's counts of the same view: each patch keeps the
    /// larger of its two counts, with the level it was drawn at then; of
    /// two equal counts, the finer level's, which lost no more.
    pub fn merge(&mut self, counts: &[u32], levels: &[u8]) -> Result<(), SeenCountError> {
        for got in [counts.len(), levels.len()] {
            if got != self.counts.len() {
                return Err(SeenCountError {
                    got,
                    patches: self.counts.len(),
                });
            }
        }
        for ((kept, level), (&c, &l)) in self
            .counts
            .iter_mut()
            .zip(&mut self.levels)
            .zip(counts.iter().zip(levels))
        {
            let finer = l != NOT_DRAWN && (*level == NOT_DRAWN || l > *level);
            if c > *kept || (c == *kept && finer) {
                (*kept, *level) = (c, l);
            }
        }
        self.sum();
        Ok(())
    }

    /// Rebuilds the summed table from the counts, row by row in place:
    /// its first row and column stay 0, every other entry is written.
    fn sum(&mut self) {
        let w = self.cols + 1;
        self.sums.resize(w * (self.rows + 1), 0);
        // A grid without columns has no counts and no rows to sum.
        for (r, counts) in self.counts.chunks_exact(self.cols.max(1)).enumerate() {
            let (above, below) = self.sums.split_at_mut((r + 1) * w);
            let above = &above[r * w..];
            let mut across = 0u64;
            for c in 0..self.cols {
                across += u64::from(counts[c]);
                below[c + 1] = above[c + 1] + across;
            }
        }
    }

    /// One patch's pixels (row-major index).
    pub fn patch(&self, index: usize) -> u32 {
        self.counts[index]
    }

    /// The pixels shown by the patches of columns `cols[0]..cols[1]` and
    /// rows `rows[0]..rows[1]` (clamped to the grid).
    pub fn block_pixels(&self, cols: [usize; 2], rows: [usize; 2]) -> u64 {
        let w = self.cols + 1;
        let (c0, c1) = (cols[0].min(self.cols), cols[1].min(self.cols));
        let (r0, r1) = (rows[0].min(self.rows), rows[1].min(self.rows));
        if c0 >= c1 || r0 >= r1 {
            return 0;
        }
        self.sums[r1 * w + c1] + self.sums[r0 * w + c0]
            - self.sums[r0 * w + c1]
            - self.sums[r1 * w + c0]
    }

    /// The level index patch (`col`, `row`) was drawn at when its count
    /// was taken; None where it was not drawn or lies outside the grid.
    pub fn drawn_level(&self, col: usize, row: usize) -> Option<u8> {
        if col >= self.cols || row >= self.rows {
            return None;
        }
        Some(self.levels[row * self.cols + col]).filter(|&l| l != NOT_DRAWN)
    }

    /// Every patch's pixels.
    pub fn total(&self) -> u64 {
        self.sums[self.sums.len() - 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(cols: usize, rows: usize) -> PatchGrid {
        PatchGrid::for_size(cols * 4 + 1, rows * 4 + 1, 4)
    }

    #[test]
    fn a_block_sums_its_own_patches_only() {
        let g = grid(5, 3);
        let check = |seen: &SeenPixels, counts: &[u32]| {
            for c0 in 0..5 {
                for c1 in c0..=6 {
                    for r0 in 0..3 {
                        for r1 in r0..=4 {
                            let mut expect = 0u64;
                            for r in r0..r1.min(3) {
                                for c in c0..c1.min(5) {
                                    expect += u64::from(counts[r * 5 + c]);
                                }
                            }
                            assert_eq!(seen.block_pixels([c0, c1], [r0, r1]), expect);
                        }
                    }
                }
            }
        };
        let counts: Vec<u32> = (0..15).map(|i| 1 << i).collect();
        let mut seen = SeenPixels::new(&g, &counts, &[0; 15]).unwrap();
        check(&seen, &counts);
        assert_eq!(seen.total(), (1 << 15) - 1);
        // A merge rewrites the sums over the old ones.
        let more: Vec<u32> = counts.iter().map(|c| 3 * c + 1).collect();
        seen.merge(&more, &[0; 15]).unwrap();
        check(&seen, &more);
    }

    #[test]
    fn a_grid_without_columns_sums_to_nothing() {
        // One sample across: no patch columns, one row of none.
        let g = PatchGrid::for_size(1, 5, 4);
        assert_eq!((g.patch_cols(), g.patch_rows()), (0, 1));
        let mut seen = SeenPixels::new(&g, &[], &[]).unwrap();
        seen.merge(&[], &[]).unwrap();
        assert_eq!(seen.total(), 0);
        assert_eq!(seen.block_pixels([0, 4], [0, 4]), 0);
    }

    #[test]
    fn merged_counts_keep_each_patchs_largest() {
        let g = grid(2, 2);
        let mut seen = SeenPixels::new(&g, &[5, 0, 7, 1], &[1, NOT_DRAWN, 2, 3]).unwrap();
        seen.merge(&[3, 4, 9, 1], &[4, 4, 4, 4]).unwrap();
        assert_eq!(
            (0..4).map(|i| seen.patch(i)).collect::<Vec<_>>(),
            [5, 4, 9, 1]
        );
        // Each count's level comes with it; a tie keeps the finer.
        let levels = [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(c, r)| seen.drawn_level(c, r));
        assert_eq!(levels, [Some(1), Some(4), Some(4), Some(4)]);
        seen.merge(&[0, 0, 0, 1], &[0, 0, 0, 2]).unwrap();
        assert_eq!(seen.drawn_level(1, 1), Some(4));
        assert_eq!(seen.drawn_level(2, 0), None);
        assert_eq!(seen.block_pixels([0, 2], [0, 2]), 19);
        assert_eq!(seen.block_pixels([1, 2], [0, 2]), 5);
        assert!(seen.merge(&[1, 2, 3], &[0; 4]).is_err());
        assert!(seen.merge(&[1, 2, 3, 4], &[0; 3]).is_err());
        assert!(SeenPixels::new(&g, &[1], &[0; 4]).is_err());
        assert!(SeenPixels::new(&g, &[1; 4], &[0]).is_err());
        let fresh = SeenPixels::new(&g, &[1; 4], &[NOT_DRAWN, 0, 0, 0]).unwrap();
        assert_eq!(fresh.drawn_level(0, 0), None);
        assert_eq!(fresh.drawn_level(1, 0), Some(0));
    }
}
