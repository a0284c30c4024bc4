//! Front-to-back draw order.
//!
//! An eye above a heightfield sees a point only past the ground between
//! them in plan, and that ground is nearer the eye in plan. Drawn nearest
//! first, the nearer ground's depth is in place before what it hides
//! arrives, so a device that tests depth before shading drops the hidden
//! fragments unshaded. Patches are ordered by the plan distance from the
//! eye to their nearest point. A run of consecutive patches is one draw in
//! index order, which left of the eye comes towards it; so a row's runs are
//! split at the eye's column and kept to [`MAX_RUN`] patches, and a run is
//! placed by its nearest patch.

use glam::{DVec2, Vec3};

use crate::terrain::grid::PatchGrid;
use crate::terrain::info::TerrainInfo;

/// Longest run of consecutive patches drawn together.
pub const MAX_RUN: u32 = 8;

/// The eye's place over a patch grid, for ordering its patches.
#[derive(Clone, Copy, Debug)]
pub struct DrawOrder {
    grid: PatchGrid,
    /// The eye in sample coordinates (column, row).
    eye: DVec2,
    /// World distance between samples along x and z.
    spacing: DVec2,
}

impl DrawOrder {
    /// The order of `grid`'s patches seen from `eye_local` (relative to
    /// the terrain's centre).
    pub fn new(info: &TerrainInfo, grid: &PatchGrid, eye_local: Vec3) -> Self {
        let origin = info.origin();
        DrawOrder {
            grid: *grid,
            eye: info.world_to_grid(
                origin.x + f64::from(eye_local.x),
                origin.y + f64::from(eye_local.z),
            ),
            spacing: info.spacing(),
        }
    }

    /// The grid ordered.
    pub fn grid(&self) -> &PatchGrid {
        &self.grid
    }

    /// Sort key of patch `index` (row-major): its nearest point's plan
    /// distance from the eye, as bits that order like the distance.
    pub fn key(&self, index: u32) -> u32 {
        let rect = self.grid.sample_rect(self.grid.patch_id(index as usize));
        let outside = |e: f64, lo: usize, hi: usize| (lo as f64 - e).max(e - hi as f64).max(0.0);
        let d = DVec2::new(
            outside(self.eye.x, rect.col0, rect.col1) * self.spacing.x,
            outside(self.eye.y, rect.row0, rect.row1) * self.spacing.y,
        );
        // Non-negative floats order as their bits do.
        (d.length() as f32).to_bits()
    }

    /// `patches` (row-major indices, increasing) as runs of consecutive
    /// patches (first, count), nearest run first: each row's runs split at
    /// the eye's column and into runs of at most `MAX_RUN`, ordered by
    /// their nearest patch, ties in index order.
    pub fn runs(&self, patches: impl IntoIterator<Item = u32>) -> Vec<(u32, u32)> {
        let cols = self.grid.patch_cols() as u32;
        let mut rows: Vec<(u32, u32)> = Vec::new();
        for p in patches {
            match rows.last_mut() {
                Some((first, n)) if *first + *n == p && p % cols != 0 => *n += 1,
                _ => rows.push((p, 1)),
            }
        }
        self.order_runs(rows)
    }

    /// The runs of `runs`, as `runs` orders them, for the patches `marks`
    /// holds: found a word of the grid's rows at a time, not sorted.
    pub fn marked_runs(&self, marks: &PatchMarks) -> Vec<(u32, u32)> {
        self.order_runs(marks.runs())
    }

    /// `rows` (each a run of consecutive patches within one row, none
    /// touching the next in the same row), split at the eye's column and
    /// into runs of at most `MAX_RUN`, nearest first.
    fn order_runs(&self, rows: Vec<(u32, u32)>) -> Vec<(u32, u32)> {
        let cols = self.grid.patch_cols() as u32;
        // The patch column the eye is over (outside the grid: its nearest).
        let eye_col = (self.eye.x / self.grid.cells_per_patch() as f64)
            .floor()
            .clamp(0.0, f64::from(cols - 1)) as u32;
        let mut keyed: Vec<(u32, (u32, u32))> = Vec::with_capacity(rows.len());
        let mut push = |first: u32, n: u32| {
            let key = self.key(first).min(self.key(first + n - 1));
            keyed.push((key, (first, n)));
        };
        for (first, n) in rows {
            let col = first % cols;
            // The eye's column starts a run of its own.
            let split = if col < eye_col && eye_col < col + n {
                eye_col - col
            } else {
                n
            };
            for (start, len) in [(first, split), (first + split, n - split)] {
                let mut at = 0;
                while at < len {
                    let take = (len - at).min(MAX_RUN);
                    push(start + at, take);
                    at += take;
                }
            }
        }
        keyed.sort_unstable();
        keyed.into_iter().map(|(_, run)| run).collect()
    }
}

/// A set of a patch grid's patches as bits, each row of the grid starting
/// a word: marked by rectangles, read back as each row's runs in index
/// order, so a frame's patches are listed without sorting them.
#[derive(Clone, Debug)]
pub struct PatchMarks {
    cols: usize,
    words_per_row: usize,
    words: Vec<u64>,
}

impl PatchMarks {
    /// No patch of `grid` marked.
    pub fn new(grid: &PatchGrid) -> Self {
        let words_per_row = grid.patch_cols().div_ceil(64);
        PatchMarks {
            cols: grid.patch_cols(),
            words_per_row,
            words: vec![0; words_per_row * grid.patch_rows()],
        }
    }

    /// Marks the patches of columns `cols[0]..cols[1]` in rows
    /// `rows[0]..rows[1]` (within the grid).
    pub fn mark(&mut self, [c0, c1]: [usize; 2], [r0, r1]: [usize; 2]) {
        debug_assert!(c1 <= self.cols && r1 * self.words_per_row <= self.words.len());
        for r in r0..r1 {
            let row = &mut self.words[r * self.words_per_row..][..self.words_per_row];
            let mut c = c0;
            while c < c1 {
                let (w, b) = (c / 64, c % 64);
                let n = (c1 - c).min(64 - b);
                let bits = if n == 64 {
                    u64::MAX
                } else {
                    ((1u64 << n) - 1) << b
                };
                row[w] |= bits;
                c += n;
            }
        }
    }

    /// Each row's maximal runs of marked patches, (first index, count),
    /// in index order.
    pub fn runs(&self) -> Vec<(u32, u32)> {
        let mut runs = Vec::new();
        for (r, row) in self.words.chunks_exact(self.words_per_row).enumerate() {
            let mut c = 0;
            while c < self.cols {
                let (w, b) = (c / 64, c % 64);
                let ahead = row[w] >> b;
                if ahead == 0 {
                    c = (w + 1) * 64;
                    continue;
                }
                let start = c + ahead.trailing_zeros() as usize;
                // The marked bits from `start` on, a word at a time.
                let mut end = start;
                while end < self.cols {
                    let (w, b) = (end / 64, end % 64);
                    let ones = ((!(row[w] >> b)).trailing_zeros() as usize).min(64 - b);
                    end += ones;
                    if ones < 64 - b {
                        break;
                    }
                }
                runs.push(((r * self.cols + start) as u32, (end - start) as u32));
                c = end;
            }
        }
        runs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::heightmap::Heightmap;

    /// A 33x33-sample map of 1 m cells and 4-cell patches (8x8 patches),
    /// centred on the origin.
    fn order(eye: Vec3) -> DrawOrder {
        let heightmap = Heightmap::from_heights(33, 33, vec![0.0; 33 * 33]).expect("valid");
        let info = TerrainInfo::new(heightmap, DVec2::ONE, 4, DVec2::ZERO).expect("valid");
        DrawOrder::new(&info, &info.patch_grid(), eye)
    }

    #[test]
    fn runs_cover_every_patch_once_nearest_first() {
        // The eye over patch (row 2, col 5): 16 m right and 16 m up of
        // the centre is sample (32, 0); this is sample (22, 10).
        let order = order(Vec3::new(6.0, 50.0, 6.0));
        let all: Vec<u32> = (0..64).filter(|p| p % 3 != 1).collect();
        let runs = order.runs(all.iter().copied());
        let mut covered: Vec<u32> = runs.iter().flat_map(|&(f, n)| f..f + n).collect();
        covered.sort_unstable();
        assert_eq!(covered, all);
        // The first run holds the patch under the eye, and no run's nearest
        // patch is nearer than an earlier run's.
        assert!(runs[0].0 <= 2 * 8 + 5 && 2 * 8 + 5 < runs[0].0 + runs[0].1);
        let nearest: Vec<u32> = runs
            .iter()
            .map(|&(f, n)| (f..f + n).map(|p| order.key(p)).min().expect("run"))
            .collect();
        assert!(nearest.windows(2).all(|w| w[0] <= w[1]), "{nearest:?}");
        // No run crosses a row, the eye's column or `MAX_RUN`.
        for &(f, n) in &runs {
            assert!(n <= MAX_RUN && f / 8 == (f + n - 1) / 8);
            assert!(!(f % 8 < 5 && 5 < f % 8 + n), "{f} {n} spans column 5");
        }
    }

    #[test]
    fn marked_runs_are_the_runs_of_the_same_patches() {
        // Patch sets of a 70 x 5 grid (rows wider than a word), made of
        // rectangles, against the runs of their indices listed in order.
        let heightmap = Heightmap::from_heights(141, 11, vec![0.0; 141 * 11]).expect("valid");
        let info = TerrainInfo::new(heightmap, DVec2::ONE, 2, DVec2::ZERO).expect("valid");
        let grid = info.patch_grid();
        assert_eq!((grid.patch_cols(), grid.patch_rows()), (70, 5));
        let mut seed = 7u64;
        let mut next = |n: usize| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as usize % n
        };
        for case in 0..200 {
            let eye = Vec3::new(next(160) as f32 - 80.0, 5.0, next(16) as f32 - 8.0);
            let order = DrawOrder::new(&info, &grid, eye);
            let mut marks = PatchMarks::new(&grid);
            let mut set = vec![false; 70 * 5];
            for _ in 0..next(6) + 1 {
                let (c0, r0) = (next(70), next(5));
                let (c1, r1) = (c0 + 1 + next(70 - c0), r0 + 1 + next(5 - r0));
                marks.mark([c0, c1], [r0, r1]);
                for r in r0..r1 {
                    set[r * 70 + c0..r * 70 + c1].fill(true);
                }
            }
            let listed = (0..70 * 5).filter(|&p| set[p]).map(|p| p as u32);
            assert_eq!(order.marked_runs(&marks), order.runs(listed), "case {case}");
        }
        // Whole rows, and runs that end on a word's last bit.
        let order = DrawOrder::new(&info, &grid, Vec3::ZERO);
        let mut marks = PatchMarks::new(&grid);
        marks.mark([0, 70], [1, 2]);
        marks.mark([10, 64], [3, 4]);
        let listed = (70..140).chain(3 * 70 + 10..3 * 70 + 64);
        assert_eq!(order.marked_runs(&marks), order.runs(listed));
        assert_eq!(marks.runs(), vec![(70, 70), (220, 54)]);
    }

    #[test]
    fn keys_grow_with_plan_distance() {
        // An eye off the grid's left edge, level with row 0's middle.
        let order = order(Vec3::new(-30.0, 10.0, 14.0));
        let row0: Vec<u32> = (0..8).map(|c| order.key(c)).collect();
        assert!(row0.windows(2).all(|w| w[0] < w[1]), "{row0:?}");
        // 14 m from the edge, in f32.
        assert_eq!(f32::from_bits(order.key(0)), 14.0);
        assert!(order.key(8) > order.key(0));
    }
}
