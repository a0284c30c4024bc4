//! How much of a patch a coarser level puts over a screen-space error, by
//! the direction it is seen from: the error LOD's precomputed view model,
//! computed once per terrain.
//!
//! **What a pixel shows.** A view ray meets the reference at R; the drawn
//! surface lies `delta` above or below R, and the ray runs on (or back)
//! until it meets it. For a ray falling `t` per unit of horizontal travel
//! onto a drawn surface that rises `s` per unit along the ray's horizontal
//! direction, the two meet `delta / (s + t)` apart horizontally and `|t|`
//! times that apart vertically. The benchmark's error is that vertical
//! gap, seen at R's distance. On flat ground it is `delta` (the face-on
//! error the error table bounds); on ground rising towards a low eye a
//! fraction of it. The run is cut at the drawn quad's diagonal: at the
//! quad's corners the drawn surface is the reference, which the ray has
//! entered. Where the drawn surface falls away as fast as the ray falls
//! (`s + t <= 0`), the ray is taken to run the whole diagonal.
//!
//! **Which pixels.** A sample stands for its share of the patch's area,
//! the four quarters of cells around it, each seen at the angle between
//! the ray and the reference there: `(r + t) cos(angle of depression)`
//! pixels per unit area times `K^2 / d^2`, with `r` the quarter's rise
//! along the ray (from the sample's one-sided slopes); none where it faces
//! away. Each quarter's errors run from those at its corners (the
//! sample, the points half-way to its neighbours and the cell's centre,
//! the error running linearly between samples) over its two triangles,
//! sample, side and centre, each counted in equal parts at the largest
//! error of each (`quarter_errors`); a quarter rising faster than the ray
//! falls, where a coarser level moves a silhouette, counts all its pixels
//! at the largest error at its corners (`upright`). A peak one sample wide
//! thus shows the ray its near faces, as steep as it is high and as far
//! off as half its height where they meet its neighbours, though its
//! central differences are flat and its own error is one sample's. A
//! level's error over the patch is then a distribution over its pixels.
//!
//! **Which surface.** Each quad of a level is split as the paths draw it:
//! the tessellator in four quadrants, each quad's diagonal parallel to the
//! line from its quadrant's corner of the patch to the centre
//! (`tess_splits_bc`, checked against the device by
//! `the_tessellator_splits_quads_as_the_view_model_expects`), the geomip
//! path along every quad's B-C diagonal. In the two quadrants where they
//! differ a sample's error is the larger of the two splits'.
//!
//! **The table.** For each direction of a lattice (`AZIMUTHS` horizontal
//! directions times the `SLOPES` a ray may fall) and each level of a
//! patch, laid over it as the tessellator cuts it (on the far remainders,
//! patches narrower than the rest, its vertices fall between samples), the
//! table keeps the errors that `FRACTIONS` of the patch's pixels exceed
//! (each the largest error in the histogram bin, an eighth of an octave
//! wide, where that share is crossed: at most one bin above the exact one),
//! and the patch's pixel area per `K^2 / d^2`, and its mean height, to
//! which the rays that show it fall. A frame reads the directions its view
//! of the patch spans and the fraction of pixels over its tolerance at
//! each level (`over_fraction`).
//!
//! Hidden ground and silhouettes are not modelled: a patch behind a ridge
//! counts its pixels as if seen, and a moved silhouette's pixels are not
//! counted as such. Only the quarters they stand on are read cautiously:
//! an upright quarter, where a silhouette lies, counts wholly at its
//! largest error (`upright`).
//!
//! **Blocks.** The level choice may decide a whole aligned block of 2^m x
//! 2^m full-size patches at once (m up to `BLOCK_LEVELS`), every patch at
//! the same level: a block's entry is its patches' pixel areas added up
//! and two sets of errors (`BlockShares`). Pooled: at each share, the
//! error over which that share of the block's pixels lie, its patches'
//! pixels taken together, so a rough patch among smooth ones counts its
//! own pixels over an error, not the whole block's. Largest: at each
//! share the largest of its patches' errors, so no patch's share over an
//! error is more than the entry says.
//!
//! Errors are stored as one byte each, on a log scale below one scale for
//! the whole terrain (`CODES_PER_OCTAVE` to an octave), rounded up: the
//! longest run a ray can have times the steepest fall of the lattice, which
//! no error exceeds.

use rayon::prelude::*;

use super::error_table::{split_ad, split_bc, LEVEL_COUNT};
use super::grid::{PatchGrid, SampleRect};
use super::heightmap::Heightmap;

/// Horizontal directions of the lattice, evenly spaced from +x towards +z.
pub const AZIMUTHS: usize = 8;
/// How fast a ray falls per unit of horizontal travel (negative: it
/// rises), at the lattice's directions.
pub const SLOPES: [f32; 10] = [-0.2, -0.05, 0.0, 0.012, 0.03, 0.07, 0.16, 0.36, 0.8, 2.0];
/// Directions of the lattice: azimuth-major, `SLOPES.len()` slopes each.
pub const DIRECTIONS: usize = AZIMUTHS * SLOPES.len();
/// The shares of a patch's pixels the stored errors leave over, as powers
/// of two (`i32::MIN` for none: the largest error).
pub const FRACTION_EXPONENTS: [i32; 9] = [i32::MIN, -12, -10, -8, -6, -4, -2, -1, 0];
const FRACTIONS: usize = FRACTION_EXPONENTS.len();
/// Levels with an entry: those below the largest patch's cell count.
pub const LEVELS: usize = LEVEL_COUNT - 1;
/// Changes whenever what the table holds, or how it is computed, changes:
/// part of its on-disk cache key. A number is never taken twice, not even
/// by a change that was tried and dropped: the tables it cached stay on
/// the machines that ran it and would be read back as the next change's.
/// 10 to 14, 16 and 17 were taken so (notes sections 51, 55, 58, 59 and
/// 60); the next change takes 19.
pub const MODEL_VERSION: u32 = 18;
/// How far above the largest of four errors their weighted sum can round
/// (`LatticePoint`'s weights add up to 1 within a few roundings).
const WEIGHTS_ROUNDING: f32 = 1e-5;
/// Steps of the stored error's log scale per octave.
pub const CODES_PER_OCTAVE: f32 = 16.0;
/// The code of an error of zero.
const ZERO: u8 = u8::MAX;

/// The lattice's horizontal direction `a` as (x, z).
pub fn azimuth(a: usize) -> [f32; 2] {
    let phi = std::f32::consts::TAU * a as f32 / AZIMUTHS as f32;
    [phi.cos(), phi.sin()]
}

/// Levels of blocks with an entry: 2x2 up to 2^BLOCK_LEVELS a side.
pub const BLOCK_LEVELS: u32 = 3;

/// One patch's or block's entry.
#[derive(Clone, Debug, PartialEq)]
struct Entry {
    /// Its mean height: where the rays that show it land, on average.
    mean: f32,
    /// Pixel area per `K^2 / d^2` from each direction.
    area: [f32; DIRECTIONS],
    /// [direction][level][fraction] codes: a direction's levels lie
    /// together, as a frame reads them. A block's shares are pooled over
    /// its patches' pixels (`BlockShares::Pooled`).
    codes: Vec<u8>,
    /// A block's codes with each share its patches' largest
    /// (`BlockShares::Largest`); None for a patch, whose are `codes`.
    largest: Option<Vec<u8>>,
}

impl Entry {
    /// Its codes with each share its patches' largest.
    fn largest_codes(&self) -> &[u8] {
        self.largest.as_deref().unwrap_or(&self.codes)
    }
}

/// One level of blocks (level 0: the patches), row-major over
/// `cols` x `rows` blocks, laid out by direction first: blocks near each
/// other, which a view sees from nearly the same direction, have their
/// figures near each other in memory, so a frame reads few pages and
/// lines.
#[derive(Clone, Debug, PartialEq)]
struct EntryLevel {
    cols: usize,
    blocks: usize,
    /// Per block, whether it has an entry.
    present: Vec<bool>,
    /// Per block, its mean height.
    mean: Vec<f32>,
    /// [direction][block] pixel areas per `K^2 / d^2`.
    area: Vec<f32>,
    /// [direction][block][level][fraction] codes.
    codes: Vec<u8>,
    /// The same, each share its patches' largest; empty for the patches.
    largest: Vec<u8>,
    /// [block][level][slope] the code of the largest error, over the
    /// lattice's azimuths at that slope, at which a reading of `codes`
    /// leaves some of the block's pixels within (`keeps_some_within`):
    /// the error all of its pixels exceed. Derived from the codes when the
    /// table is built or read back.
    within: Vec<u8>,
    /// The same of `largest` (read as a patch's codes); empty for the
    /// patches.
    largest_within: Vec<u8>,
}

impl EntryLevel {
    /// A level of `cols` columns of blocks from its stored figures, with
    /// what is derived from them.
    fn new(
        cols: usize,
        present: Vec<bool>,
        (mean, area): (Vec<f32>, Vec<f32>),
        codes: Vec<u8>,
        largest: Vec<u8>,
    ) -> Self {
        let blocks = present.len();
        EntryLevel {
            within: least_over_azimuths(&codes, blocks, FRACTIONS - 1),
            largest_within: least_over_azimuths(&largest, blocks, FRACTIONS - 1),
            cols,
            blocks,
            present,
            mean,
            area,
            codes,
            largest,
        }
    }

    /// Whether `shares` reads this level's largest shares: a block's, not
    /// a patch's, which has one set.
    fn reads_largest(&self, shares: BlockShares) -> bool {
        shares == BlockShares::Largest && !self.largest.is_empty()
    }

    /// `within` or `largest_within`, as `shares` reads this level.
    fn within_of(&self, shares: BlockShares) -> &[u8] {
        match self.reads_largest(shares) {
            true => &self.largest_within,
            false => &self.within,
        }
    }

    /// `cols` x `entries.len() / cols` blocks' entries, packed; blocks of
    /// patches (`of_blocks`) keep their largest shares too.
    fn pack(cols: usize, entries: &[Option<Entry>], of_blocks: bool) -> Self {
        let blocks = entries.len();
        let per = LEVELS * FRACTIONS;
        let mut area = vec![0.0f32; DIRECTIONS * blocks];
        let mut codes = vec![ZERO; DIRECTIONS * blocks * per];
        let mut largest = vec![ZERO; if of_blocks { codes.len() } else { 0 }];
        for (b, entry) in entries.iter().enumerate() {
            let Some(entry) = entry else { continue };
            for d in 0..DIRECTIONS {
                area[d * blocks + b] = entry.area[d];
                let at = (d * blocks + b) * per;
                codes[at..][..per].copy_from_slice(&entry.codes[d * per..(d + 1) * per]);
                if let Some(own) = &entry.largest {
                    largest[at..][..per].copy_from_slice(&own[d * per..(d + 1) * per]);
                }
            }
        }
        let mean = entries
            .iter()
            .map(|e| e.as_ref().map_or(0.0, |e| e.mean))
            .collect();
        EntryLevel::new(
            cols,
            entries.iter().map(Option::is_some).collect(),
            (mean, area),
            codes,
            largest,
        )
    }
}

/// [block][level][slope] the smallest of share `share`'s codes (the
/// largest error) over the lattice's azimuths, of a level's
/// [direction][block][level][fraction] `codes` (none for none).
fn least_over_azimuths(codes: &[u8], blocks: usize, share: usize) -> Vec<u8> {
    let per = LEVELS * FRACTIONS;
    if codes.is_empty() {
        return Vec::new();
    }
    let mut least = vec![ZERO; blocks * LEVELS * SLOPES.len()];
    for d in 0..DIRECTIONS {
        let slope = d % SLOPES.len();
        let rows = &codes[d * blocks * per..][..blocks * per];
        for (b, block) in rows.chunks_exact(per).enumerate() {
            for (k, row) in block.chunks_exact(FRACTIONS).enumerate() {
                let at = &mut least[(b * LEVELS + k) * SLOPES.len() + slope];
                *at = (*at).min(row[share]);
            }
        }
    }
    least
}

/// Every full-size patch's view model, and every block's of whole
/// full-size patches (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct SightTable {
    /// The error of code 0.
    scale: f32,
    /// The error of each code.
    decoded: [f32; 256],
    /// Level 0: the patches; level m: blocks of 2^m x 2^m patches.
    levels: Vec<EntryLevel>,
}

/// A direction within the lattice: two neighbouring azimuths and two
/// neighbouring slopes, with the weights that interpolate between them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LatticePoint {
    pub azimuths: [u8; 2],
    pub azimuth_weight: f32,
    pub slopes: [u8; 2],
    pub slope_weight: f32,
}

impl LatticePoint {
    /// The lattice point of horizontal direction `(x, z)` (any length) and
    /// fall `t`, clamped to the lattice's slopes.
    pub fn new(x: f32, z: f32, t: f32) -> Self {
        let a = turns(x, z) * AZIMUTHS as f32;
        // Not negative: truncation is its floor.
        let a0 = (a as usize).min(AZIMUTHS - 1);
        let last = SLOPES.len() - 1;
        // NaN falls to the lowest slope.
        let (s0, slope_weight) = if t.is_nan() || t <= SLOPES[0] {
            (0, 0.0)
        } else if t >= SLOPES[last] {
            (last - 1, 1.0)
        } else {
            let i = SLOPES
                .iter()
                .rposition(|&s| s <= t)
                .unwrap_or(0)
                .min(last - 1);
            (i, (t - SLOPES[i]) / (SLOPES[i + 1] - SLOPES[i]))
        };
        LatticePoint {
            azimuths: [a0 as u8, ((a0 + 1) % AZIMUTHS) as u8],
            azimuth_weight: (a - a0 as f32).clamp(0.0, 1.0),
            slopes: [s0 as u8, s0 as u8 + 1],
            slope_weight,
        }
    }

    /// The four lattice directions and their weights.
    fn corners(&self) -> [(usize, f32); 4] {
        let (wa, ws) = (self.azimuth_weight, self.slope_weight);
        let d = |a: usize, s: usize| {
            usize::from(self.azimuths[a]) * SLOPES.len() + usize::from(self.slopes[s])
        };
        [
            (d(0, 0), (1.0 - wa) * (1.0 - ws)),
            (d(0, 1), (1.0 - wa) * ws),
            (d(1, 0), wa * (1.0 - ws)),
            (d(1, 1), wa * ws),
        ]
    }
}

/// The angle from +x towards +z of the direction `(x, z)`, in turns, in
/// [0, 1] (0 for no direction): an arctangent of the smaller side over the
/// larger, within 1e-5 radians (Abramowitz and Stegun 4.4.49), turned into
/// its octant. A lattice point is found for every part of every block a
/// frame reads, where the library's `atan2` took 3 % of the choice's
/// instructions.
fn turns(x: f32, z: f32) -> f32 {
    let (ax, az) = (x.abs(), z.abs());
    let (lo, hi) = if ax >= az { (az, ax) } else { (ax, az) };
    if hi == 0.0 {
        return 0.0;
    }
    let r = lo / hi;
    let r2 = r * r;
    let poly =
        (((0.020_835_1 * r2 - 0.085_133) * r2 + 0.180_141) * r2 - 0.330_299_5) * r2 + 0.999_866;
    // In [0, 1/8] of a turn, then its octant.
    let t = r * poly / std::f32::consts::TAU;
    let t = if az > ax { 0.25 - t } else { t };
    let t = if x < 0.0 { 0.5 - t } else { t };
    if z < 0.0 {
        1.0 - t
    } else {
        t
    }
}

impl SightTable {
    /// The table of every patch of `grid` over `map`, whose samples are
    /// `spacing` (dx, dz) apart.
    pub fn compute(map: &Heightmap, grid: &PatchGrid, spacing: (f64, f64)) -> SightTable {
        let n = grid.cells_per_patch();
        // No run is longer than the coarsest level's diagonal (the patch's),
        // no ray falls faster than the lattice's steepest slope, and no
        // face-on error is more than the terrain's height range.
        let diagonal = (n as f64 * spacing.0).hypot(n as f64 * spacing.1) as f32;
        let steepest = SLOPES.iter().fold(0.0f32, |m, t| m.max(t.abs()));
        let (lo, hi) = map.min_max();
        let scale = (diagonal * steepest).max(hi - lo);
        let patches: Vec<Option<Entry>> = (0..grid.patch_count())
            .into_par_iter()
            .map(|p| {
                Some(patch_entry(
                    map,
                    grid.sample_rect(grid.patch_id(p)),
                    spacing,
                    scale,
                ))
            })
            .collect();
        // Blocks are of full-size patches only: a block's patches all take
        // one level, which a narrower patch lays out differently.
        let full_size: Vec<bool> = (0..grid.patch_count())
            .map(|p| {
                let rect = grid.sample_rect(grid.patch_id(p));
                rect.cells_x() == n && rect.cells_z() == n
            })
            .collect();
        let decoded = decoded_codes(scale);
        let mut built: Vec<(usize, Vec<Option<Entry>>)> = vec![(grid.patch_cols(), patches)];
        let mut rows = grid.patch_rows();
        for _ in 0..BLOCK_LEVELS {
            let of_patches = built.len() == 1;
            let (below_cols, below) = built.last().expect("level 0");
            let (cols, below_rows) = (below_cols.div_ceil(2), rows);
            rows = rows.div_ceil(2);
            let entries = (0..cols * rows)
                .into_par_iter()
                .map(|b| {
                    let (c, r) = (b % cols, b / cols);
                    let child = |dc: usize, dr: usize| {
                        let (cc, cr) = (2 * c + dc, 2 * r + dr);
                        let i = cr * below_cols + cc;
                        (cc < *below_cols && cr < below_rows && (!of_patches || full_size[i]))
                            .then(|| below[i].as_ref())
                            .flatten()
                    };
                    let children = [child(0, 0), child(1, 0), child(0, 1), child(1, 1)];
                    let children: Option<Vec<&Entry>> = children.into_iter().collect();
                    children.map(|children| block_entry(&children, &decoded))
                })
                .collect();
            built.push((cols, entries));
        }
        let levels = built
            .iter()
            .enumerate()
            .map(|(level, (cols, entries))| EntryLevel::pack(*cols, entries, level > 0))
            .collect();
        SightTable::with_levels(scale, levels)
    }

    /// The table as bytes, `encoded_len` of them, for the on-disk cache:
    /// its scale, then per level each block's presence, mean heights, areas
    /// and codes, and above the patches the largest shares' codes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(&self.scale.to_le_bytes());
        for level in &self.levels {
            out.extend(level.present.iter().map(|&p| u8::from(p)));
            for m in &level.mean {
                out.extend_from_slice(&m.to_le_bytes());
            }
            for a in &level.area {
                out.extend_from_slice(&a.to_le_bytes());
            }
            out.extend_from_slice(&level.codes);
            out.extend_from_slice(&level.largest);
        }
        out
    }

    /// The length of `to_bytes` for `grid`'s table.
    pub fn encoded_len(grid: &PatchGrid) -> usize {
        let per_block = |level: usize| {
            let code_sets = if level == 0 { 1 } else { 2 };
            1 + 4 + DIRECTIONS * (4 + code_sets * LEVELS * FRACTIONS)
        };
        4 + level_sizes(grid)
            .iter()
            .enumerate()
            .map(|(level, &(cols, rows))| cols * rows * per_block(level))
            .sum::<usize>()
    }

    /// The table `to_bytes` wrote for `grid`; None where the bytes are not
    /// one (a length the grid's table cannot have).
    pub fn from_bytes(grid: &PatchGrid, bytes: &[u8]) -> Option<SightTable> {
        if bytes.len() != Self::encoded_len(grid) {
            return None;
        }
        let scale = f32::from_le_bytes(bytes[..4].try_into().ok()?);
        let mut at = 4;
        let mut take = |n: usize| {
            let slice = &bytes[at..at + n];
            at += n;
            slice
        };
        let levels = level_sizes(grid)
            .into_iter()
            .enumerate()
            .map(|(level, (cols, rows))| {
                let blocks = cols * rows;
                let present = take(blocks).iter().map(|&b| b != 0).collect();
                let floats = |bytes: &[u8]| -> Vec<f32> {
                    bytes
                        .chunks_exact(4)
                        .map(|c| f32::from_le_bytes(c.try_into().expect("four bytes")))
                        .collect()
                };
                let mean = floats(take(4 * blocks));
                let area = floats(take(4 * DIRECTIONS * blocks));
                let codes = take(DIRECTIONS * blocks * LEVELS * FRACTIONS).to_vec();
                let largest = match level {
                    0 => Vec::new(),
                    _ => take(DIRECTIONS * blocks * LEVELS * FRACTIONS).to_vec(),
                };
                EntryLevel::new(cols, present, (mean, area), codes, largest)
            })
            .collect();
        Some(SightTable::with_levels(scale, levels))
    }

    fn with_levels(scale: f32, levels: Vec<EntryLevel>) -> SightTable {
        SightTable {
            scale,
            decoded: decoded_codes(scale),
            levels,
        }
    }

    /// `block`'s level and index there, where it has an entry.
    fn entry(&self, block: Block) -> Option<(&EntryLevel, usize)> {
        let level = self.levels.get(block.level as usize)?;
        let b = block.row * level.cols + block.col;
        level.present[b].then_some((level, b))
    }

    /// Whether `block` has an entry: every patch has one, and every block
    /// whole and of full-size patches.
    pub fn has(&self, block: Block) -> bool {
        self.entry(block).is_some()
    }

    /// `block`'s mean height, where it has an entry: the rays that show it
    /// fall from the eye to about this height.
    pub fn mean_height(&self, block: Block) -> Option<f32> {
        let (level, b) = self.entry(block)?;
        Some(level.mean[b])
    }

    /// `block` seen from `at` against a vertical error `error` (in the
    /// heightmap's units, at the block): the entry's figures at the
    /// lattice directions around `at`: their area, and where their codes
    /// lie (`touch` fetches them, `over_fraction` reads them); None without
    /// an entry.
    pub fn view(
        &self,
        block: Block,
        at: &LatticePoint,
        error: f32,
        shares: BlockShares,
    ) -> Option<BlockView> {
        let (level, b) = self.entry(block)?;
        let largest = level.reads_largest(shares);
        let corners = at.corners();
        let at_direction = |d: usize| d * level.blocks + b;
        let area = corners
            .iter()
            .map(|&(d, w)| level.area[at_direction(d)] * w)
            .sum();
        Some(BlockView {
            area,
            codes: corners.map(|(d, _)| at_direction(d) * LEVELS * FRACTIONS),
            weights: corners.map(|(_, w)| w),
            error,
            level: block.level as u8,
            largest,
        })
    }

    /// Whether drawing `block`'s patches at level index `k` leaves some of
    /// its pixels within `error`, as `ViewCodes::over_fraction` reads
    /// `shares` from any azimuth at a fall between the lattice's `slopes`:
    /// a share over below 1. A block counted with no pixel shown at that
    /// level then showed none over `error` either: nearer ground hid it.
    /// False without an entry.
    ///
    /// One memory line a block, where a reading fetches four directions'
    /// codes and searches each level's shares.
    pub fn keeps_some_within(
        &self,
        block: Block,
        k: usize,
        slopes: [u8; 2],
        error: f32,
        shares: BlockShares,
    ) -> bool {
        if k >= LEVELS {
            // Full resolution: no error, where there is an entry.
            return self.entry(block).is_some();
        }
        // The reading weighs four directions' errors with weights that add
        // up to 1 within a few roundings.
        self.all_over_below(block, k, slopes, shares)
            .is_some_and(|largest| largest * (1.0 + WEIGHTS_ROUNDING) < error)
    }

    /// The largest error, over the lattice's azimuths at a fall between
    /// `slopes`, that every pixel of `block` drawn at level index `k` (below
    /// `LEVELS`) exceeds as `shares` is read: the figure
    /// `keeps_some_within` compares with. None without an entry.
    fn all_over_below(
        &self,
        block: Block,
        k: usize,
        slopes: [u8; 2],
        shares: BlockShares,
    ) -> Option<f32> {
        let (level, b) = self.entry(block)?;
        let row = &level.within_of(shares)[(b * LEVELS + k) * SLOPES.len()..][..SLOPES.len()];
        let code = row[usize::from(slopes[0])].min(row[usize::from(slopes[1])]);
        Some(self.decoded[usize::from(code)])
    }

    /// A byte of the memory line `keeps_some_within` reads first for
    /// `block` (0 without an entry), so that the lines of many blocks can
    /// be fetched at once.
    pub fn touch_within(&self, block: Block, shares: BlockShares) -> u8 {
        self.entry(block).map_or(0, |(level, b)| {
            level.within_of(shares)[b * LEVELS * SLOPES.len()]
        })
    }

    /// `view`'s codes, ready to read (`ViewCodes::over_fraction`).
    pub fn codes(&self, view: &BlockView) -> ViewCodes<'_> {
        let codes = self.level_codes(view);
        let row = |at: usize| -> &[u8; LEVELS * FRACTIONS] {
            codes[at..].first_chunk().expect("a direction's codes")
        };
        let [a, b, c, d] = view.codes;
        ViewCodes {
            area: view.area,
            codes: [row(a), row(b), row(c), row(d)],
            weights: view.weights,
            error: view.error,
            decoded: &self.decoded,
        }
    }

    /// The codes of `view`'s block level and shares.
    fn level_codes(&self, view: &BlockView) -> &[u8] {
        let level = &self.levels[usize::from(view.level)];
        match view.largest {
            true => &level.largest,
            false => &level.codes,
        }
    }

    /// A byte from each memory line `view`'s codes lie on, folded
    /// together: reading every view's lines before any is used lets them be
    /// fetched many at a time.
    pub fn touch(&self, view: &BlockView) -> u8 {
        let codes = self.level_codes(view);
        view.codes.iter().fold(0, |acc, &at| {
            acc ^ codes[at] ^ codes[at + LEVELS * FRACTIONS - 1]
        })
    }
}

/// A block's codes from the four lattice directions of one view, with
/// their weights and the error the shares are over.
#[derive(Clone, Copy, Debug)]
pub struct ViewCodes<'a> {
    area: f32,
    codes: [&'a [u8; LEVELS * FRACTIONS]; 4],
    weights: [f32; 4],
    error: f32,
    decoded: &'a [f32; 256],
}

impl ViewCodes<'_> {
    /// The view's pixel area per `K^2 / d^2` (`BlockView::area`).
    pub fn area(&self) -> f32 {
        self.area
    }

    /// The share of the view's pixels that drawing each of its patches at
    /// level index `k` (2^k segments a side) puts over its error: its
    /// errors interpolated between the lattice's directions (a ray's gap
    /// grows about in proportion to its fall), then the share between the
    /// stored ones as spread evenly between their errors (`fraction_over`),
    /// a patch's shares and a block's alike. Pooled over patches unlike each
    /// other, a block's errors can fall in a step between two stored shares
    /// (a rough patch's, then a smooth one's), and the line between them
    /// then passes below the share over, by at most the step between the
    /// two shares (4x); so can a patch's, rough in part. Reading a block's
    /// pooled shares at the larger of the two instead drew 7 % more
    /// triangles on the overviews at 1 px, and 17 % more on the 4097^2
    /// overview at 0.5 px, at the same p99 on every view (notes section
    /// 58). 0 for a level the table does not hold (full resolution and
    /// finer, whose error is 0).
    pub fn over_fraction(&self, k: usize) -> f32 {
        if k >= LEVELS {
            return 0.0;
        }
        // The row's errors are found as the search reaches them
        // (`first_within`): most searches read three of the eight.
        let error_at = |j: usize| {
            self.codes
                .iter()
                .zip(&self.weights)
                .fold(0.0f32, |e, (codes, &w)| {
                    e + w * self.decoded[usize::from(codes[k * FRACTIONS + j])]
                })
        };
        fraction_over(error_at, self.error)
    }
}

/// A block's entry read from one direction against one error: where its
/// figures lie at the four lattice directions around it, and their
/// weights (`SightTable::view`).
#[derive(Clone, Copy, Debug)]
pub struct BlockView {
    area: f32,
    /// Where each direction's codes start in its level's codes.
    codes: [usize; 4],
    weights: [f32; 4],
    /// The error the shares are over.
    error: f32,
    /// Its block level.
    level: u8,
    /// Read from the largest shares (a block's, `BlockShares::Largest`).
    largest: bool,
}

impl BlockView {
    /// Its pixel area per `K^2 / d^2`: what it covers at distance d is
    /// this times `(K / d)^2`.
    pub fn area(&self) -> f32 {
        self.area
    }
}

/// `FRACTION_EXPONENTS` as shares (0 for the largest error).
const FRACTION_SHARES: [f32; FRACTIONS] = {
    let mut shares = [0.0; FRACTIONS];
    let mut j = 0;
    while j < FRACTIONS {
        if FRACTION_EXPONENTS[j] != i32::MIN {
            shares[j] = 1.0 / (1u64 << -FRACTION_EXPONENTS[j]) as f32;
        }
        j += 1;
    }
    shares
};

/// The first of a row of errors at `FRACTION_EXPONENTS` (`error_at(j)`,
/// non-increasing: errors fall as the share grows) at or below `error`:
/// its index, and its error and the one before it (infinite before the
/// first); None where every error is over. The first and the last are read
/// first: many rows are within at the first, and almost every row at the
/// last. The errors within are the row's last ones, so the rest are read
/// from the last down, to the first over: most rows are over until the
/// last few shares.
fn first_within(error_at: impl Fn(usize) -> f32, error: f32) -> Option<(usize, f32, f32)> {
    let first = error_at(0);
    if first <= error {
        return Some((0, first, f32::INFINITY));
    }
    let mut within = error_at(FRACTIONS - 1);
    if within > error {
        return None;
    }
    for j in (1..FRACTIONS - 1).rev() {
        let e = error_at(j);
        if e > error {
            return Some((j + 1, within, e));
        }
        within = e;
    }
    Some((1, within, first))
}

/// The share of pixels over `error` of a row of errors at
/// `FRACTION_EXPONENTS` (`error_at(j)`, non-increasing: errors fall as the
/// share grows). Between two stored shares the pixels' errors are read as
/// spread evenly between the two stored errors: the share runs linearly
/// from the smaller stored share at the larger error to the larger share at
/// the smaller error.
///
/// The reading grows with every stored error and is continuous in them,
/// so a block whose stored errors are each at least a patch's reads at
/// least the patch's share, and an exact zero reads as a tiny error does.
/// A few pixels far over the error beside exact ones (a spike) read close
/// to the larger share, where the truth may lie. It is never below the line
/// in log-log through the same two errors, which bends below the straight
/// one between them.
fn fraction_over(error_at: impl Fn(usize) -> f32, error: f32) -> f32 {
    // The first stored error at or below the given one, and the one
    // before it.
    let Some((j, e1, e0)) = first_within(error_at, error) else {
        return 1.0;
    };
    if j == 0 {
        return 0.0;
    }
    let (s0, s1) = (FRACTION_SHARES[j - 1], FRACTION_SHARES[j]);
    if FRACTION_EXPONENTS[j - 1] == i32::MIN || e0 <= e1 {
        return s1;
    }
    let w = ((e0 - error) / (e0 - e1)).clamp(0.0, 1.0);
    s0 + w * (s1 - s0)
}

/// Bins per octave of the errors' histogram, and its octaves.
const BINS_PER_OCTAVE: f32 = 8.0;
const BINS: usize = 128;

/// Columns and rows of blocks at each level the table keeps.
fn level_sizes(grid: &PatchGrid) -> Vec<(usize, usize)> {
    let (mut cols, mut rows) = (grid.patch_cols(), grid.patch_rows());
    let mut sizes = vec![(cols, rows)];
    for _ in 0..BLOCK_LEVELS {
        (cols, rows) = (cols.div_ceil(2), rows.div_ceil(2));
        sizes.push((cols, rows));
    }
    sizes
}

/// The error of each code, below `scale`.
fn decoded_codes(scale: f32) -> [f32; 256] {
    std::array::from_fn(|c| {
        if c == usize::from(ZERO) {
            0.0
        } else {
            scale * (-(c as f32) / CODES_PER_OCTAVE).exp2()
        }
    })
}

/// Which of a block's errors a reading takes (see the module
/// documentation); a patch has one set, which both read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockShares {
    /// Each share's error over the block's pixels taken together.
    Pooled,
    /// Each share's error the largest of its patches'.
    Largest,
}

/// A block of patches or blocks: its level (0 for a patch), and its column
/// and row among that level's blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Block {
    pub level: u32,
    pub col: usize,
    pub row: usize,
}

/// A block's entry from its four children's: their areas added; from each
/// direction and at each level, their largest error, and at each share the
/// error over which that share of the block's pixels lie, their pixels
/// pooled (each child's share over an error, weighted by its pixels from
/// that direction, `fraction_over`), rounded up to a code. A rough child
/// among smooth ones so counts its own pixels over tau, not the whole
/// block's.
fn block_entry(children: &[&Entry], decoded: &[f32; 256]) -> Entry {
    let mut entry = children[0].clone();
    entry.mean = children.iter().map(|c| c.mean).sum::<f32>() / children.len() as f32;
    let mut largest = children[0].largest_codes().to_vec();
    for child in &children[1..] {
        for (a, b) in entry.area.iter_mut().zip(&child.area) {
            *a += b;
        }
        for (a, b) in largest.iter_mut().zip(child.largest_codes()) {
            *a = (*a).min(*b);
        }
    }
    entry.largest = Some(largest);
    for d in 0..DIRECTIONS {
        let total = entry.area[d];
        for k in 0..LEVELS {
            let at = (d * LEVELS + k) * FRACTIONS;
            let rows: Vec<(&[u8], f32)> = children
                .iter()
                .map(|c| (&c.codes[at..at + FRACTIONS], c.area[d]))
                .collect();
            let largest = rows.iter().map(|(r, _)| r[0]).min().expect("children");
            let out = &mut entry.codes[at..at + FRACTIONS];
            out[0] = largest;
            if total <= 0.0 {
                // Seen from nowhere in this direction: the largest error
                // at every share.
                for (j, o) in out.iter_mut().enumerate().skip(1) {
                    *o = rows.iter().map(|(r, _)| r[j]).min().expect("children");
                }
                continue;
            }
            // The pooled share of pixels over an error: non-decreasing as
            // the error falls (as its code rises).
            let pooled = |code: u8| {
                let e = decoded[usize::from(code)];
                rows.iter()
                    .map(|(r, w)| w * fraction_over(|j| decoded[usize::from(r[j])], e))
                    .sum::<f32>()
                    / total
            };
            for (j, &exponent) in FRACTION_EXPONENTS.iter().enumerate().skip(1) {
                let share = (exponent as f32).exp2();
                // The largest code (smallest error) whose pooled share is
                // within this one: the largest error's code qualifies.
                let (mut lo, mut hi) = (largest, ZERO);
                if pooled(hi) <= share {
                    lo = hi;
                }
                while hi - lo > 1 {
                    let mid = lo + (hi - lo) / 2;
                    if pooled(mid) <= share {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                out[j] = lo;
            }
        }
    }
    entry
}

/// One patch's entry, its errors coded below `scale`. Each level is laid
/// over the patch as the tessellator cuts it: 2^k equal segments a side,
/// whatever its cells, so on a narrower patch (a far remainder) its
/// vertices fall between samples, at the reference's height there
/// (`Heightmap::interpolate`, as the evaluation shader reads it). Levels
/// from the first whose segments reach the patch's smaller side are full
/// resolution, with no error.
fn patch_entry(map: &Heightmap, rect: SampleRect, (dx, dz): (f64, f64), scale: f32) -> Entry {
    let (nx, nz) = (rect.cells_x(), rect.cells_z());
    let stride = nx + 1;
    let (w, d) = (map.width(), map.depth());
    let h = |r: usize, c: usize| f64::from(map.get(r, c));
    // The reference's one-sided slopes at each sample, towards +x, -x,
    // +z and -z (each taken the same way, so the -x slope is the rise
    // from the sample behind to this one); at the map's edges the side
    // that exists stands for both. Local z falls as rows rise.
    let mut reference = Vec::with_capacity(stride * (nz + 1));
    let mut heights = Vec::with_capacity(stride * (nz + 1));
    for r in rect.row0..=rect.row1 {
        for c in rect.col0..=rect.col1 {
            let here = h(r, c);
            let east = (c + 1 < w).then(|| (h(r, c + 1) - here) / dx);
            let west = (c > 0).then(|| (here - h(r, c - 1)) / dx);
            let north = (r > 0).then(|| (h(r - 1, c) - here) / dz);
            let south = (r + 1 < d).then(|| (here - h(r + 1, c)) / dz);
            let pair = |a: Option<f64>, b: Option<f64>| {
                let (a, b) = (a.or(b).unwrap_or(0.0), b.or(a).unwrap_or(0.0));
                [a as f32, b as f32]
            };
            let [gx0, gx1] = pair(east, west);
            let [gz0, gz1] = pair(north, south);
            reference.push(Slopes([gx0, gx1, gz0, gz1]));
            heights.push(here);
        }
    }
    // The reference at patch-local (row, column): a sample where both are
    // whole, else as the evaluation shader reads between samples.
    let at = |r: f64, c: f64| {
        if r.fract() == 0.0 && c.fract() == 0.0 {
            heights[r as usize * stride + c as usize]
        } else {
            map.interpolate(rect.col0 as f64 + c, rect.row0 as f64 + r)
        }
    };
    let cos = SLOPES.map(|t| 1.0 / (1.0 + t * t).sqrt());
    let point_area = (dx * dz) as f32;
    let mut area = [0.0f32; DIRECTIONS];
    for a in 0..AZIMUTHS {
        let [ux, uz] = azimuth(a);
        for (ti, &t) in SLOPES.iter().enumerate() {
            let seen: f32 = reference
                .iter()
                .map(|g| Slopes::seen_from(g.rises(ux, uz), t))
                .sum();
            area[a * SLOPES.len() + ti] = seen * point_area * cos[ti];
        }
    }
    // Errors per level and direction, at each fraction.
    let mut errors = vec![0.0f32; LEVELS * DIRECTIONS * FRACTIONS];
    let mut delta = vec![0.0f32; heights.len()];
    let mut drawn = vec![[0.0f32; 2]; heights.len()];
    let mut quarters = vec![[[0.0f32; QUARTER_ERRORS]; 4]; heights.len()];
    let mut along: Vec<([f32; 4], f32)> = Vec::with_capacity(heights.len());
    for k in 0..LEVELS {
        let segments = 1usize << k;
        if segments >= nx.min(nz) {
            break;
        }
        // A quad's sides in samples, and in the heightmap's units.
        let (qx, qz) = (nx as f64 / segments as f64, nz as f64 / segments as f64);
        let (quad_x, quad_z) = (qx * dx, qz * dz);
        let diagonal = (quad_x * quad_x + quad_z * quad_z).sqrt() as f32;
        // The quad along one side holding sample `i` of `cells`, and where
        // in it the sample lies (0 to 1).
        let place = |i: usize, cells: usize, q: f64| {
            let quad = ((i * segments) / cells).min(segments - 1);
            (quad, (i as f64 - quad as f64 * q) / q)
        };
        for i in 0..=nz {
            let (qi, v) = place(i, nz, qz);
            for j in 0..=nx {
                let (qj, u) = place(j, nx, qx);
                let (r0, c0) = (qi as f64 * qz, qj as f64 * qx);
                // A upper-left, B upper-right, C lower-left, D lower-right.
                let corners = [
                    at(r0, c0),
                    at(r0, c0 + qx),
                    at(r0 + qz, c0),
                    at(r0 + qz, c0 + qx),
                ];
                let here = heights[i * stride + j];
                let bc = (here - split_bc(corners, u, v, u + v <= 1.0)).abs();
                delta[i * stride + j] = if tess_splits_bc(qi, qj, segments) {
                    bc
                } else {
                    bc.max((here - split_ad(corners, u, v, u >= v)).abs())
                } as f32;
                let [a, b, c, dd] = corners;
                drawn[i * stride + j] = [
                    (((1.0 - v) * (b - a) + v * (dd - c)) / quad_x) as f32,
                    (-((1.0 - u) * (c - a) + u * (dd - b)) / quad_z) as f32,
                ];
            }
        }
        // Each quarter of cells around a sample (`Slopes`): its errors
        // from those at its corners, the sample, the points half-way to
        // its two neighbours and the cell's centre (the larger of its two
        // diagonals' midpoints), where the error runs linearly between
        // samples (`quarter_errors`). A neighbour outside the patch counts
        // as the sample.
        for i in 0..=nz {
            for j in 0..=nx {
                let here = delta[i * stride + j];
                let at = |di: isize, dj: isize| {
                    let (ii, jj) = (i as isize + di, j as isize + dj);
                    if ii < 0 || jj < 0 || ii > nz as isize || jj > nx as isize {
                        here
                    } else {
                        delta[ii as usize * stride + jj as usize]
                    }
                };
                let quarter = |di: isize, dj: isize| {
                    let (x, z, xz) = (at(0, dj), at(di, 0), at(di, dj));
                    let centre = (0.5 * (here + xz)).max(0.5 * (x + z));
                    quarter_errors(here, [0.5 * (here + x), 0.5 * (here + z)], centre)
                };
                // As `Slopes::rises` orders them; north is the row above.
                quarters[i * stride + j] = [
                    quarter(-1, 1),
                    quarter(1, 1),
                    quarter(-1, -1),
                    quarter(1, -1),
                ];
            }
        }
        let largest = delta.iter().copied().fold(0.0f32, f32::max);
        for a in 0..AZIMUTHS {
            let [ux, uz] = azimuth(a);
            // Per sample: how it faces the ray's direction, and the drawn
            // surface's rise along it.
            along.clear();
            along.extend(
                reference
                    .iter()
                    .zip(&drawn)
                    .map(|(g, s)| (g.rises(ux, uz), s[0] * ux + s[1] * uz)),
            );
            for (ti, &t) in SLOPES.iter().enumerate() {
                let dir = a * SLOPES.len() + ti;
                let out = &mut errors[(k * DIRECTIONS + dir) * FRACTIONS..][..FRACTIONS];
                if t == 0.0 {
                    // Level rays: no vertical gap between their hits.
                    out.fill(0.0);
                    continue;
                }
                // No error is more than the larger of the longest run's
                // gap and the largest face-on error.
                let top = (t.abs() * diagonal).max(largest);
                let mut histogram = Histogram::new(top);
                // The gap over the diagonal's whole run.
                let run = t.abs() * diagonal;
                for (&(rises, drawn_rise), errors) in along.iter().zip(&quarters) {
                    let meet = drawn_rise + t;
                    let per_error = t.abs() / meet;
                    for (rise, quarter) in rises.into_iter().zip(errors) {
                        let seen = 0.25 * (rise + t).max(0.0);
                        histogram.total += seen;
                        if seen <= 0.0 {
                            continue;
                        }
                        // The drawn plane carried on along the ray; no
                        // further than where the gap reaches the face-on
                        // error, or the diagonal's run where that is more
                        // (but for a quarter falling away along the ray,
                        // `falls_away`). Where the drawn surface falls away
                        // as fast as the ray, the ray meets it in front,
                        // within the diagonal.
                        let away = falls_away(rise);
                        let gap = |e: f32| match (meet > 0.0, away) {
                            (true, true) => (per_error * e).min(e),
                            (true, false) => (per_error * e).min(e.max(run)),
                            (false, true) => e,
                            (false, false) => run,
                        };
                        if upright(rise, t) {
                            let e = quarter_largest(quarter);
                            if e > 0.0 {
                                histogram.add(gap(e), seen);
                            }
                            continue;
                        }
                        let weight = seen / QUARTER_ERRORS as f32;
                        for &e in quarter {
                            if e > 0.0 {
                                histogram.add(gap(e), weight);
                            }
                        }
                    }
                }
                histogram.quantiles(out);
            }
        }
    }
    // A level's errors are at least the next finer one's, as in the error
    // table, so a level within tolerance has every finer one within too.
    for k in (0..LEVELS - 1).rev() {
        for i in 0..DIRECTIONS * FRACTIONS {
            let finer = errors[(k + 1) * DIRECTIONS * FRACTIONS + i];
            let e = &mut errors[k * DIRECTIONS * FRACTIONS + i];
            *e = e.max(finer);
        }
    }
    // Errors are [level][direction][fraction]; codes [direction][level]
    // [fraction].
    let codes = (0..DIRECTIONS * LEVELS * FRACTIONS)
        .map(|i| {
            let (d, k, j) = (
                i / (LEVELS * FRACTIONS),
                i / FRACTIONS % LEVELS,
                i % FRACTIONS,
            );
            let e = errors[(k * DIRECTIONS + d) * FRACTIONS + j];
            if e <= 0.0 || scale <= 0.0 {
                ZERO
            } else {
                // Rounded down, so the stored error is never below it.
                (CODES_PER_OCTAVE * (scale / e).log2())
                    .floor()
                    .clamp(0.0, f32::from(ZERO - 1)) as u8
            }
        })
        .collect();
    let mean = (heights.iter().sum::<f64>() / heights.len() as f64) as f32;
    Entry {
        mean,
        area,
        codes,
        largest: None,
    }
}

/// Errors standing for equal shares of a quarter of cells: its two
/// triangles' `TRIANGLE_ERRORS` each.
const QUARTER_ERRORS: usize = 2 * TRIANGLE_ERRORS;
/// Errors standing for equal shares of a triangle over which the error
/// runs linearly.
const TRIANGLE_ERRORS: usize = 4;

/// Whether a quarter rising `rise` along a ray falling `t` stands up into
/// the line of sight: it rises faster than the ray falls, so the ground
/// beyond it is seen over its top, if at all. Its pixels are where a
/// coarser level moves a silhouette (a spike or a wall drawn lower shows
/// the sky or farther ground over it, each pixel off by how far the
/// outline moved, not by the vertical gap the model reads), so it counts
/// every pixel at the largest error at its corners (`quarter_largest`).
/// A quarter lying back from the ray counts its errors as they run
/// across it (`quarter_errors`). Spread across every quarter, the errors
/// let `scripts/hard-cases`' needles and terraces over tau on 8 rows
/// (notes section 59).
fn upright(rise: f32, t: f32) -> bool {
    rise > t
}

/// Whether a quarter rising `rise` along a ray falls away from it (seen,
/// so less steeply than the ray falls): its gap is then counted at most at
/// its face-on error, where any other quarter counts it grown as far as
/// the diagonal's run.
///
/// An empirical reading, not a bound. Along the drawn plane alone, the
/// gap under ground that falls away grows as it does under any other:
/// the ray meets the drawn surface further on, and a smooth slope
/// falling away, seen whole, shows that grown gap. But read so, these
/// quarters were where the model counted most of what the frames did not
/// show: on the Jacksboro DEM's overview at 1 px it put 0.50 % of the
/// pixels over tau where 0.13 % were; with these quarters read face-on,
/// 0.50 % against 0.29 %. Part of that is hiding: ground falling away
/// from the eye is what a crest in front of it hides first, and the
/// model sees no hiding inside a block (the counts and the horizon take
/// a block's pixels as a whole). A horizon of 16 samples towards the eye
/// at each sample, with hidden samples left out, accounted for about a
/// quarter of it (0.17 % measured); the rest is not yet explained.
/// `scripts/hard-cases` has the same rows over tau with this reading, and
/// two generated terrains outside the bench stay within tau on every
/// view (notes section 62).
fn falls_away(rise: f32) -> bool {
    rise < 0.0
}

/// The largest of a quarter's errors (`quarter_errors`): the larger of
/// its two triangles' last parts, each at its triangle's largest corner.
fn quarter_largest(quarter: &[f32; QUARTER_ERRORS]) -> f32 {
    quarter[TRIANGLE_ERRORS - 1].max(quarter[QUARTER_ERRORS - 1])
}

/// Errors standing for equal shares of a quarter of cells whose corners'
/// errors are `sample` (the sample's own), `sides` (half-way to its two
/// neighbours) and `centre` (the cell's centre).
///
/// The quarter is taken as two triangles, sample, side and centre, over
/// each of which the error runs linearly: the reference's own diagonal,
/// where it crosses the quarter, runs from the sample to the centre, and
/// so does a drawn quad's whose corners are samples; elsewhere both
/// surfaces are planes over the quarter. The gap between two planes is
/// then linear, and its size at most the linear run of the sizes at the
/// corners. Each triangle's share is split into `TRIANGLE_ERRORS` equal
/// parts by how far the error runs, each part at its largest error, so no
/// error is counted below what it is, and at most a part of a triangle
/// counts over an error that it is under. (A quarter lying back from
/// the ray used to count wholly at the largest of its corners, as an
/// upright one still does: on a level that drops every other sample, a
/// quarter is half at its dropped sample's error and half below it, and a
/// tolerance a little under that error counted the whole quarter over.)
fn quarter_errors(sample: f32, sides: [f32; 2], centre: f32) -> [f32; QUARTER_ERRORS] {
    let mut out = [0.0; QUARTER_ERRORS];
    for (side, part) in sides.into_iter().zip(out.chunks_exact_mut(TRIANGLE_ERRORS)) {
        let mut v = [sample, side, centre];
        v.sort_unstable_by(f32::total_cmp);
        for (i, e) in part.iter_mut().enumerate() {
            *e = triangle_quantile(v, (i + 1) as f32 / TRIANGLE_ERRORS as f32);
        }
    }
    out
}

/// The error below which share `p` of a triangle lies, the error running
/// linearly between its corners' `a <= b <= c`: the region below an error
/// between `a` and `b` is a triangle at the `a` corner, of share
/// `(e - a)^2 / ((b - a) (c - a))`, and the region above one between `b`
/// and `c` one at the `c` corner, of share `(c - e)^2 / ((c - a) (c - b))`.
fn triangle_quantile([a, b, c]: [f32; 3], p: f32) -> f32 {
    if p >= 1.0 || c <= a {
        return c;
    }
    let below_b = (b - a) / (c - a);
    let e = if p <= below_b {
        a + (p * (b - a) * (c - a)).sqrt()
    } else {
        c - ((1.0 - p) * (c - a) * (c - b)).sqrt()
    };
    e.clamp(a, c)
}

/// Whether the tessellator splits quad (`row`, `col`) of a patch cut into
/// `segments` x `segments` quads along its B-C diagonal (upper-right to
/// lower-left), as the geomip path splits every quad. With equal spacing
/// and a power-of-two factor of at least 2, the tessellator lays its quads
/// in four quadrants, each quad's diagonal parallel to the line from its
/// quadrant's corner of the patch to the centre: B-C in the quadrants at
/// the B and C corners, A-D in the others, where the two paths differ and
/// the view model keeps the larger error of the two. That is the pattern
/// of the D3D11 reference tessellator (its rings stitched with mirrored
/// diagonals), which fixed-function tessellators and lavapipe follow. One
/// quad (`segments` 1) may be split either way.
pub fn tess_splits_bc(row: usize, col: usize, segments: usize) -> bool {
    segments >= 2 && (row < segments / 2) != (col < segments / 2)
}

/// The reference's one-sided slopes at a sample: towards +x and -x, then
/// +z and -z. The area a sample stands for is the four quarters of cells
/// around it, each rising along a ray by its own pair of slopes: a peak
/// one sample wide, whose central differences are flat, shows the ray its
/// near faces, as steep as the peak is high.
#[derive(Clone, Copy, Debug)]
struct Slopes([f32; 4]);

impl Slopes {
    /// The rise of each quarter along the horizontal direction (ux, uz).
    fn rises(&self, ux: f32, uz: f32) -> [f32; 4] {
        let [east, west, north, south] = self.0;
        let (e, w, n, s) = (east * ux, west * ux, north * uz, south * uz);
        [e + n, e + s, w + n, w + s]
    }

    /// Pixels per unit area of a sample whose quarters rise `rises` along
    /// a ray falling `t` per unit: each quarter the ray meets at a rise of
    /// `r` shows `r + t`, none where it faces away.
    fn seen_from(rises: [f32; 4], t: f32) -> f32 {
        rises.iter().map(|&r| (r + t).max(0.0)).sum::<f32>() * 0.25
    }
}

/// Weights of errors in bins `1 / BINS_PER_OCTAVE` octave wide below a
/// largest possible error, the largest error in each bin, and the total
/// weight the fractions are of.
struct Histogram {
    /// One over the largest possible error.
    inverse_top: f32,
    largest: f32,
    total: f32,
    bins: [f32; BINS],
    bin_largest: [f32; BINS],
}

/// The eighth-octave steps within an octave: 2^(1/8) to 2^(7/8).
const EIGHTHS: [f32; 7] = [
    1.090_507_7,
    1.189_207_1,
    1.296_839_6,
    std::f32::consts::SQRT_2,
    1.542_210_8,
    1.681_792_8,
    1.834_008_1,
];
const _: () = assert!(BINS_PER_OCTAVE == 8.0);

impl Histogram {
    fn new(top: f32) -> Self {
        Histogram {
            inverse_top: 1.0 / top,
            largest: 0.0,
            total: 0.0,
            bins: [0.0; BINS],
            bin_largest: [0.0; BINS],
        }
    }

    /// Adds `weight` at `error` (at most `top`), in the bin whose upper
    /// edge is the first at or above it: floor(8 log2(top / error)). With
    /// `error / top` as 2^e m (m in [1, 2)), that is -8 e where m is 1,
    /// else -8 (e + 1) and the eighth-octave steps m is within: from the
    /// float's exponent and seven comparisons, without a division.
    fn add(&mut self, error: f32, weight: f32) {
        self.largest = self.largest.max(error);
        let ratio = error * self.inverse_top;
        let bin = if ratio >= 1.0 {
            0
        } else {
            let bits = ratio.to_bits();
            let octave = ((bits >> 23) & 0xff) as i32 - 127;
            let mantissa = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
            if mantissa == 1.0 {
                -8 * octave
            } else {
                let step = EIGHTHS.iter().filter(|&&q| mantissa <= q).count() as i32;
                -8 * (octave + 1) + step
            }
        };
        let bin = bin.clamp(0, BINS as i32 - 1) as usize;
        self.bins[bin] += weight;
        self.bin_largest[bin] = self.bin_largest[bin].max(error);
    }

    /// The errors above which at most each of `FRACTION_EXPONENTS` of the
    /// total lie, each rounded up to the largest error in its bin.
    fn quantiles(&self, out: &mut [f32]) {
        if self.largest <= 0.0 || self.total <= 0.0 {
            out.fill(0.0);
            return;
        }
        for (slot, &exponent) in out.iter_mut().zip(&FRACTION_EXPONENTS) {
            if exponent == i32::MIN {
                *slot = self.largest;
                continue;
            }
            let allowed = (exponent as f32).exp2() * self.total;
            let mut over = 0.0;
            *slot = 0.0;
            for (b, &w) in self.bins.iter().enumerate() {
                over += w;
                if over > allowed {
                    *slot = self.bin_largest[b];
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn fraction_shares_are_the_exponents_powers_of_two() {
        for (share, e) in FRACTION_SHARES.iter().zip(FRACTION_EXPONENTS) {
            let expected = if e == i32::MIN {
                0.0
            } else {
                (e as f32).exp2()
            };
            assert_eq!(*share, expected);
        }
    }

    /// Rough ground with a cliff, 2 m by 3 m samples, in 16-cell patches
    /// whose last row and column are narrower.
    fn rough_cliff_table() -> SightTable {
        let map = Heightmap::from_fn(91, 75, |r, c| {
            let (x, z) = (c as f32, r as f32);
            let rough = ((x * 12.9898 + z * 78.233).sin() * 43758.547).fract();
            8.0 * (x / 7.0).sin() * (z / 5.0).cos()
                + 3.0 * rough
                + if x > 40.0 { 30.0 } else { 0.0 }
        })
        .expect("a heightmap");
        let grid = PatchGrid::for_size(91, 75, 16);
        SightTable::compute(&map, &grid, (2.0, 3.0))
    }

    /// Where `keeps_some_within` says a level leaves some of a block's
    /// pixels within an error, reading the block from any direction at a
    /// fall between those slopes puts less than all of them over it:
    /// patches and blocks, both shares, every level, falls from rising to
    /// steeper than the lattice, errors from a millimetre to a cliff's.
    /// Where it does not, the reading puts every pixel over from some of
    /// those directions, though not from all.
    #[test]
    fn a_level_that_keeps_some_pixels_within_reads_fewer_than_all_over() {
        let table = rough_cliff_table();
        let falls = [-0.3, -0.05, 0.0, 0.02, 0.05, 0.1, 0.25, 0.5, 1.0, 3.0];
        let errors = [0.001, 0.05, 0.3, 1.0, 4.0, 40.0];
        let (mut kept, mut refused_all_over) = (0, 0);
        for (m, level) in table.levels.iter().enumerate() {
            for b in (0..level.blocks).filter(|&b| level.present[b]) {
                let block = Block {
                    level: m as u32,
                    col: b % level.cols,
                    row: b / level.cols,
                };
                for shares in [BlockShares::Pooled, BlockShares::Largest] {
                    for k in 0..LEVELS {
                        for &t in &falls {
                            // Just either side of the figure itself, and a
                            // span of errors.
                            let slopes = LatticePoint::new(1.0, 0.0, t).slopes;
                            let figure = table
                                .all_over_below(block, k, slopes, shares)
                                .expect("an entry");
                            let around = [0.98 * figure, 1.02 * figure];
                            for &error in errors.iter().chain(&around) {
                                let (mut keeps, mut all_over) = (None, false);
                                for a in 0..2 * AZIMUTHS {
                                    let phi = std::f32::consts::PI * a as f32 / AZIMUTHS as f32;
                                    let at = LatticePoint::new(phi.cos(), phi.sin(), t);
                                    let said =
                                        table.keeps_some_within(block, k, at.slopes, error, shares);
                                    // The same slopes from every azimuth.
                                    assert!(keeps.is_none_or(|k| k == said));
                                    keeps = Some(said);
                                    let view = table.view(block, &at, error, shares).unwrap();
                                    let over = table.codes(&view).over_fraction(k);
                                    if said {
                                        assert!(
                                            over < 1.0,
                                            "{block:?} {shares:?} level {k} fall {t} \
                                             error {error}: {over}"
                                        );
                                    }
                                    all_over |= over == 1.0;
                                }
                                match keeps {
                                    Some(true) => kept += 1,
                                    _ => refused_all_over += usize::from(all_over),
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(kept > 1_000, "{kept} levels keep some pixels within");
        assert!(refused_all_over > 500, "{refused_all_over}");
    }

    /// Every stored row's errors fall as the share grows (its codes rise),
    /// patches' and blocks' rows, pooled and largest alike: what
    /// `first_within` relies on to read the last error second and the rest
    /// from the last down. On rough ground with a cliff, in 16-cell
    /// patches whose last row and column are narrower.
    #[test]
    fn every_stored_row_falls_as_the_share_grows() {
        let table = rough_cliff_table();
        let mut rows = 0;
        for level in &table.levels {
            for codes in [&level.codes, &level.largest] {
                for row in codes.chunks_exact(FRACTIONS) {
                    assert!(row.windows(2).all(|w| w[0] <= w[1]), "{row:?}");
                    rows += 1;
                }
            }
        }
        assert!(rows > 10_000, "{rows} rows");
    }

    proptest! {
        /// Reading the first and last errors first, then the rest from the
        /// last down, finds what a search from the first finds, on any
        /// non-increasing row: with errors drawn from a few values, rows
        /// with equal errors and errors equal to the tolerance come often.
        #[test]
        fn first_within_finds_what_a_linear_search_finds(
            row in prop::array::uniform9(0.0f32..100.0),
            error in 0.0f32..110.0,
            steps in prop::array::uniform9(0u8..6),
            step_error in 0u8..7,
        ) {
            for (mut row, error) in [(row, error), (steps.map(f32::from), f32::from(step_error))] {
                row.sort_by(|a, b| b.total_cmp(a));
                let linear = (0..FRACTIONS).position(|j| row[j] <= error).map(|j| {
                    (j, row[j], if j == 0 { f32::INFINITY } else { row[j - 1] })
                });
                prop_assert_eq!(first_within(|j| row[j], error), linear);
            }
        }

        /// A quarter's errors count, over any error, at least the share
        /// of it whose error runs over (its two triangles sampled on a
        /// grid of 100 x 100 steps, the error linear across each), and at
        /// most one part of each triangle more.
        #[test]
        fn a_quarters_errors_bound_its_share_over_within_a_part(
            sample in 0.0f32..10.0,
            sides in prop::array::uniform2(0.0f32..10.0),
            centre in 0.0f32..10.0,
            error in 0.0f32..10.0,
        ) {
            let errors = quarter_errors(sample, sides, centre);
            let counted = errors.iter().filter(|&&e| e > error).count() as f32
                / QUARTER_ERRORS as f32;
            let steps = 100;
            let (mut over, mut points) = (0.0f32, 0.0f32);
            for side in sides {
                for i in 0..=steps {
                    for j in 0..=steps - i {
                        let (u, v) = (i as f32 / steps as f32, j as f32 / steps as f32);
                        let e = sample + u * (side - sample) + v * (centre - sample);
                        points += 1.0;
                        if e > error {
                            over += 1.0;
                        }
                    }
                }
            }
            let exact = over / points;
            // The grid's edges count twice as much as a triangle's area
            // gives them: a few hundredths either way.
            prop_assert!(counted >= exact - 0.03, "{counted} counted, {exact} over");
            prop_assert!(
                counted <= exact + 1.0 / TRIANGLE_ERRORS as f32 + 0.03,
                "{counted} counted, {exact} over"
            );
        }

        /// Each stored error is the largest error in the bin where its
        /// share is crossed: never below the exact weighted quantile (the
        /// error at which the weight of the errors at or above it first
        /// exceeds the share; none for the whole), an error that was added,
        /// and within the bin's eighth of an octave above the quantile.
        #[test]
        fn stored_errors_bound_the_quantiles_within_a_bin(
            added in prop::collection::vec((0.001f32..100.0, 1u16..256), 1..400),
        ) {
            // Weights in 64ths add up exactly in any order.
            let added: Vec<(f32, f32)> =
                added.into_iter().map(|(e, w)| (e, f32::from(w) / 64.0)).collect();
            let top = 100.0;
            let mut histogram = Histogram::new(top);
            for &(error, weight) in &added {
                histogram.total += weight;
                histogram.add(error, weight);
            }
            let mut stored = [0.0f32; FRACTIONS];
            histogram.quantiles(&mut stored);
            let mut sorted = added.clone();
            sorted.sort_by(|a, b| b.0.total_cmp(&a.0));
            for (&exponent, &got) in FRACTION_EXPONENTS.iter().zip(&stored) {
                let allowed = match exponent {
                    i32::MIN => 0.0,
                    e => (e as f32).exp2() * histogram.total,
                };
                let mut over = 0.0;
                let exact = sorted
                    .iter()
                    .find(|&&(_, w)| {
                        over += w;
                        over > allowed
                    })
                    .map_or(0.0, |&(e, _)| e);
                prop_assert!(
                    got == exact || added.iter().any(|&(e, _)| e == got),
                    "{got} was not added"
                );
                prop_assert!(got >= exact, "share 2^{exponent}: {got} below {exact}");
                prop_assert!(
                    got <= exact * (1.0 / BINS_PER_OCTAVE).exp2() * 1.000_01,
                    "share 2^{exponent}: {got} over a bin above {exact}"
                );
            }
        }

        /// Raising any stored error never lowers the share read over an
        /// error, and the share is never below the log-log line through
        /// the two stored errors around it: a block whose stored errors
        /// are each at least a patch's reads at least the patch's share,
        /// an exact zero reads as a tiny error does, and smooth ground
        /// reads no lower than the power law through its stored errors.
        #[test]
        fn the_share_over_grows_with_every_stored_error(
            row in prop::array::uniform9(0.0f32..100.0),
            raise in 0.0f32..50.0,
            at in 0usize..9,
            exact in 0usize..9,
            error in 0.01f32..110.0,
        ) {
            // The last `exact` errors are zero: ground the level draws
            // exactly.
            let mut row = row;
            row.sort_by(|a, b| b.total_cmp(a));
            row[FRACTIONS - exact..].fill(0.0);
            let share = fraction_over(|j| row[j], error);
            let mut raised = row;
            raised[at] += raise;
            raised.sort_by(|a, b| b.total_cmp(a));
            prop_assert!(fraction_over(|j| raised[j], error) >= share - 1e-6);
            if let Some((j, e1, e0)) = first_within(|j| row[j], error) {
                let lo = FRACTION_EXPONENTS[j.max(1) - 1];
                if j > 0 && lo != i32::MIN && e1 > 0.0 && e0 > e1 {
                    let hi = FRACTION_EXPONENTS[j];
                    let w = (e0 / error).log2() / (e0 / e1).log2();
                    let log_log = (lo as f32 + w * (hi - lo) as f32).exp2();
                    prop_assert!(share >= log_log * (1.0 - 1e-4), "{share} {log_log}");
                }
            }
        }

        /// A direction's angle in turns is `atan2`'s, made positive, within
        /// 2e-6 of a turn (1e-5 radians and rounding), at any length and in
        /// every octant, the axes and the diagonals included.
        #[test]
        fn turns_are_atan2s(
            x in -1.0e4f32..1.0e4,
            z in -1.0e4f32..1.0e4,
            octant in 0u8..8,
            scale in -20i32..20,
        ) {
            let axis = (octant as f32 * std::f32::consts::FRAC_PI_4).sin_cos();
            for (x, z) in [(x, z), (axis.1, axis.0), (x, 0.0), (0.0, z), (x, x), (x, -x)] {
                let (x, z) = (x * (scale as f32).exp2(), z * (scale as f32).exp2());
                let phi = z.atan2(x);
                let expected = if phi < 0.0 { phi + std::f32::consts::TAU } else { phi }
                    / std::f32::consts::TAU;
                let got = turns(x, z);
                prop_assert!((0.0..=1.0).contains(&got), "{x} {z}: {got}");
                // A turn and none are one direction.
                let apart = (got - expected).abs();
                prop_assert!(apart.min(1.0 - apart) <= 2e-6, "{x} {z}: {got} against {expected}");
            }
        }
    }

    /// The entry of a map of `size` x `size` samples `spacing` apart,
    /// heights `height(row, column)`, laid out as one patch, its errors
    /// coded below `scale`.
    fn one_patch_entry(
        size: usize,
        height: impl Fn(usize, usize) -> f32 + Sync,
        spacing: f64,
        scale: f32,
    ) -> Entry {
        let map = Heightmap::from_fn(size, size, height).expect("a heightmap");
        let grid = PatchGrid::for_size(size, size, size as u32 - 1);
        let rect = grid.sample_rect(grid.patch_id(0));
        patch_entry(&map, rect, (spacing, spacing), scale)
    }

    /// A peak one sample wide, 60 m on flat ground with samples 10 m
    /// apart, dropped by the coarsest level and seen from a low eye (a
    /// ray falling 0.03 per unit): its near faces rise 6 per unit, so
    /// they and the neighbours' quarters leading up to them (30 m off at
    /// their midpoints) are about 15 % of the patch's pixels, though the
    /// peak is one sample in 1,089. The share 2^-4 of the pixels exceeds
    /// is therefore at least 30 m. Seen along the grid's axes its faces
    /// rise faster than the ray falls, so each keeps the largest error at
    /// its corners (`upright`), and that share's error is at least 45 m
    /// (62.1 m; 35.4 m with those quarters' errors spread across them, as
    /// a quarter lying back from the ray's are; 31.0 to 47.9 m on the
    /// diagonals, where a quarter's two slopes partly cancel). Read by the
    /// sample alone, with its central differences, it was none.
    #[test]
    fn a_one_sample_peak_shows_its_near_faces() {
        let scale = 200.0;
        let entry = one_patch_entry(
            33,
            |r, c| if (r, c) == (16, 16) { 60.0 } else { 0.0 },
            10.0,
            scale,
        );
        let decoded = decoded_codes(scale);
        let t = SLOPES
            .iter()
            .position(|&t| t == 0.03)
            .expect("a slope of 0.03");
        let share = FRACTION_EXPONENTS
            .iter()
            .position(|&e| e == -4)
            .expect("2^-4");
        for a in 0..AZIMUTHS {
            let dir = a * SLOPES.len() + t;
            let coarsest = decoded[usize::from(entry.codes[dir * LEVELS * FRACTIONS + share])];
            assert!(coarsest >= 30.0, "azimuth {a}: {coarsest} m at 2^-4");
            if a % 2 == 0 {
                assert!(coarsest >= 45.0, "azimuth {a}: {coarsest} m at 2^-4");
            }
            // Full resolution (the patch's 32 cells) has no error.
            let full = entry.codes[(dir * LEVELS + 5) * FRACTIONS];
            assert_eq!(full, ZERO, "azimuth {a}");
        }
    }

    /// A level that drops every other sample, on ground flat but for a
    /// bump of 1 m at each quad's centre (spread 100 m apart, so every
    /// quarter faces a steep ray about equally): a quarter around a bump
    /// runs from 1 m at the bump to 0.5 m at its sides and centre, a
    /// quarter elsewhere stays within 0.5 m. A quarter of the pixels are
    /// over 0.5 m, and (1 - e)^2 / 0.25 of those over e between: the
    /// stored errors at a share of 2^-2 and 2^-4 are never below those
    /// quantiles (0.5 and 0.75 m), and within a part of a triangle above
    /// them. Counted at each quarter's largest corner, both were 1 m.
    #[test]
    fn a_quarter_counts_its_pixels_at_the_errors_across_it() {
        let scale = 4.0;
        let bumps = |r: usize, c: usize| if r % 2 == 1 && c % 2 == 1 { 1.0 } else { 0.0 };
        let entry = one_patch_entry(33, bumps, 100.0, scale);
        let decoded = decoded_codes(scale);
        let t = SLOPES.iter().position(|&t| t == 2.0).expect("a slope of 2");
        // 16 segments over 32 cells: every other sample dropped.
        let level = 4;
        for a in 0..AZIMUTHS {
            let at = ((a * SLOPES.len() + t) * LEVELS + level) * FRACTIONS;
            let stored = |exponent: i32| {
                let j = FRACTION_EXPONENTS
                    .iter()
                    .position(|&e| e == exponent)
                    .expect("a stored share");
                decoded[usize::from(entry.codes[at + j])]
            };
            let (quarter, sixteenth) = (stored(-2), stored(-4));
            assert!(
                (0.5..0.62).contains(&quarter),
                "azimuth {a}: {quarter} m at 2^-2"
            );
            assert!(
                (0.75..0.85).contains(&sixteenth),
                "azimuth {a}: {sixteenth} m at 2^-4"
            );
            assert!(
                (0.99..1.1).contains(&stored(i32::MIN)),
                "azimuth {a}: the largest error"
            );
        }
    }

    /// On a plane every quarter of cells rises as its central differences
    /// do, so a patch's pixel area per direction is the plane's: `(r + t)
    /// cos` per unit area where it faces the ray, none where it faces away.
    #[test]
    fn a_planes_area_is_its_slopes() {
        let (gx, gz) = (0.3f32, 0.1f32);
        // Local z falls as rows rise: a row further down is further -z.
        let plane = |r: usize, c: usize| gx * 4.0 * c as f32 - gz * 4.0 * r as f32;
        let entry = one_patch_entry(17, plane, 4.0, 100.0);
        for a in 0..AZIMUTHS {
            let [ux, uz] = azimuth(a);
            for (ti, &t) in SLOPES.iter().enumerate() {
                let cos = 1.0 / (1.0 + t * t).sqrt();
                let expected = 289.0 * (gx * ux + gz * uz + t).max(0.0) * 16.0 * cos;
                let got = entry.area[a * SLOPES.len() + ti];
                assert!(
                    (got - expected).abs() <= 1e-3 * expected.max(1.0),
                    "azimuth {a}, slope {t}: {got} against {expected}"
                );
            }
        }
    }

    /// Ground falling away along +x at 0.3 per unit, samples 10 m apart,
    /// with a bump of 1 m on every other sample of every other row, seen
    /// along +x by a ray falling 0.36: the level that drops the bumps
    /// draws the plane itself, so its gap under a bump's quarter grows by
    /// 0.36 / (0.36 - 0.3) = 6 when carried along the drawn plane (up to
    /// 6 m). Every quarter the ray sees falls away along it (the bumps'
    /// near faces rise 0.1 per unit on the plane's fall of 0.3), so each counts
    /// at most its face-on error: 1 m at the bumps, within the codes'
    /// rounding. Seen from the other side, where the same ground rises
    /// towards the ray, the gaps shrink below the face-on error either way.
    #[test]
    fn ground_falling_away_from_the_ray_counts_its_face_on_error() {
        let scale = 16.0;
        let ground = |r: usize, c: usize| {
            let bump = if r % 2 == 1 && c % 2 == 1 { 1.0 } else { 0.0 };
            -0.3 * 10.0 * c as f32 + bump
        };
        let entry = one_patch_entry(33, ground, 10.0, scale);
        let decoded = decoded_codes(scale);
        let t = SLOPES
            .iter()
            .position(|&t| t == 0.36)
            .expect("a slope of 0.36");
        // 16 quads a side: every other sample dropped.
        let k = 4;
        let largest = |a: usize| {
            let dir = a * SLOPES.len() + t;
            decoded[usize::from(entry.codes[(dir * LEVELS + k) * FRACTIONS])]
        };
        let rounding = 2f32.powf(1.0 / CODES_PER_OCTAVE);
        assert_eq!(azimuth(0), [1.0, 0.0]);
        let away = largest(0);
        assert!(
            (1.0..=rounding).contains(&away),
            "{away} m along +x, where the ground falls away"
        );
        let towards = largest(AZIMUTHS / 2);
        assert!(towards <= rounding, "{towards} m along -x");
    }

    /// No direction at all is taken as +x.
    #[test]
    fn no_direction_is_no_turn() {
        assert_eq!(turns(0.0, 0.0), 0.0);
        assert_eq!(turns(-0.0, 0.0), 0.0);
    }
}
