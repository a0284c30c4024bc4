//! Geomipmapping without tessellation shaders: per-patch levels, neighbour
//! balancing, and the index buffers every patch shares.
//!
//! A patch of N cells is drawn from one vertex template of (N+1)^2 grid
//! offsets. At level l it uses every 2^l-th vertex: N / 2^l cells a side,
//! from full resolution (level 0) down to a single quad (level log2 N).
//!
//! **No cracks at any level difference.** Neighbours are first balanced to
//! at most one level apart (only by refining the coarser one, so error never
//! grows). A side whose neighbour is one level coarser is *stitched*: every
//! 2x2 block of cells touching it is drawn as a fan from the block's centre
//! that skips the midpoint the coarser neighbour lacks, so both patches meet
//! along the same edges and there is no T-junction. Other blocks keep
//! `height_at`'s split (diagonal from the upper-right to the lower-left
//! corner), so level 0 is exactly the brute mesh. One index list per level
//! and coarser-side mask (16 per level), built once, serves every patch.
//! A fan splits half its cells along the other diagonal, so a stitched side
//! can stray from the reference further than its level does (a spike a
//! cell inside it, by half its height: `StitchErrors`); the error LOD
//! keeps a drawn neighbour at the patch's own level where that would show
//! (`stitchable_sides`).
//!
//! **Geomorphing** (in the vertex shader) moves the vertices a level drops
//! onto the next coarser surface (`morph_target`) as the patch's distance
//! nears the next level, so a level change does not pop. Factors are per
//! patch, from the same distance that picks its level, so a switch happens
//! exactly at morph 1 (going coarser) or 0 (going finer). A side shared with
//! a patch of the same level takes the factor of the farther of the two, so
//! both move its vertices alike; a side shared with a finer patch does not
//! morph, because that patch stitches to its vertices where they are.

use glam::Vec3;
use rayon::prelude::*;

use super::hierarchy::Hierarchy;
use super::plan::PlannedBlock;
use super::view::LodView;
use crate::terrain::error_table::ErrorTable;
use crate::terrain::grid::{PatchGrid, PatchId, SampleRect};
use crate::terrain::heightmap::Heightmap;
use crate::terrain::Terrain;

/// Sides of a patch, as bits of a mask.
pub const LEFT: u8 = 1;
pub const TOP: u8 = 2;
pub const RIGHT: u8 = 4;
pub const BOTTOM: u8 = 8;

/// Number of levels for `cells_per_patch` (a power of two): log2(N) + 1.
pub fn level_count(cells_per_patch: usize) -> usize {
    cells_per_patch.trailing_zeros() as usize + 1
}

/// The error table's level index of geomip level `level`, of `count`
/// levels (`level_count`): level l has n / 2^l segments a side, which the
/// table indexes as log2(n) - l.
pub fn table_index(level: usize, count: usize) -> usize {
    count - 1 - level
}

/// The geomip level of the error table's level index `index`, of `count`
/// levels: `table_index` undone.
pub fn level_of_index(index: usize, count: usize) -> usize {
    count - 1 - index
}

/// Index of template vertex (row i, column j) for patches of `n` cells.
fn vertex(n: usize, i: usize, j: usize) -> u32 {
    (i * (n + 1) + j) as u32
}

/// The vertex template: (column, row) offsets of the (n+1)^2 vertices.
pub fn vertex_template(n: usize) -> Vec<[u16; 2]> {
    let mut v = Vec::with_capacity((n + 1) * (n + 1));
    for i in 0..=n {
        for j in 0..=n {
            v.push([j as u16, i as u16]);
        }
    }
    v
}

/// The two triangles of the quad from template vertex (i, j) to
/// (i + step, j + step), split like `height_at`: with A = (i, j),
/// B = (i, j+step), C = (i+step, j), D = (i+step, j+step), ABC and DCB.
fn push_quad(out: &mut Vec<u32>, n: usize, i: usize, j: usize, step: usize) {
    let (a, b) = (vertex(n, i, j), vertex(n, i, j + step));
    let (c, d) = (vertex(n, i + step, j), vertex(n, i + step, j + step));
    out.extend_from_slice(&[a, b, c, d, c, b]);
}

/// Triangles of one patch at `level` whose sides in `coarser` border a patch
/// one level coarser, as template vertex indices.
pub fn patch_indices(n: usize, level: usize, coarser: u8) -> Vec<u32> {
    let s = 1usize << level;
    let k = n / s;
    let mut out = Vec::new();
    let cell = |out: &mut Vec<u32>, i, j, step| push_quad(out, n, i, j, step);
    if k == 1 || coarser == 0 {
        for bi in 0..k {
            for bj in 0..k {
                cell(&mut out, bi * s, bj * s, s);
            }
        }
        return out;
    }
    // k >= 2 and even: work in 2x2 blocks of cells.
    let blocks = k / 2;
    for bi in 0..blocks {
        for bj in 0..blocks {
            let (i0, j0) = (bi * 2 * s, bj * 2 * s);
            let stitched = block_sides(bi, bj, blocks) & coarser;
            if stitched == 0 {
                for (di, dj) in [(0, 0), (0, s), (s, 0), (s, s)] {
                    cell(&mut out, i0 + di, j0 + dj, s);
                }
                continue;
            }
            let v = |(di, dj): (usize, usize)| vertex(n, i0 + di, j0 + dj);
            let ring: Vec<u32> = fan_ring(s, stitched).map(v).collect();
            let centre = v((s, s));
            for t in 0..ring.len() {
                out.extend_from_slice(&[centre, ring[t], ring[(t + 1) % ring.len()]]);
            }
        }
    }
    out
}

/// The sides of a patch that 2x2 block (row `bi`, column `bj`) of a
/// patch `blocks` blocks a side touches.
pub fn block_sides(bi: usize, bj: usize, blocks: usize) -> u8 {
    let mut touching = 0u8;
    if bj == 0 {
        touching |= LEFT;
    }
    if bi == 0 {
        touching |= TOP;
    }
    if bj + 1 == blocks {
        touching |= RIGHT;
    }
    if bi + 1 == blocks {
        touching |= BOTTOM;
    }
    touching
}

/// The ring a stitched 2x2 block of cells of `step` samples is fanned over
/// from its centre (`step`, `step`), as (row, column) offsets from its
/// upper-left corner, clockwise from that corner: corners and side
/// midpoints, less the midpoints of the `stitched` sides.
pub fn fan_ring(step: usize, stitched: u8) -> impl Iterator<Item = (usize, usize)> {
    let (m, e) = (step, 2 * step);
    [
        ((0, 0), 0),
        ((0, m), TOP),
        ((0, e), 0),
        ((m, e), RIGHT),
        ((e, e), 0),
        ((e, m), BOTTOM),
        ((e, 0), 0),
        ((m, 0), LEFT),
    ]
    .into_iter()
    .filter(move |&(_, side)| stitched & side == 0)
    .map(|(offset, _)| offset)
}

/// The reference's own triangles over the first `cells` (columns, rows) of
/// a patch of `n` cells: level 0 unstitched, cut to a remainder patch at
/// the terrain's far edges so that it draws no collapsed triangles.
pub fn full_resolution_indices(n: usize, cells: [usize; 2]) -> Vec<u32> {
    let [cx, cz] = cells;
    let mut out = Vec::with_capacity(6 * cx * cz);
    for i in 0..cz.min(n) {
        for j in 0..cx.min(n) {
            push_quad(&mut out, n, i, j, 1);
        }
    }
    out
}

/// Every (level, coarser mask) index list concatenated, with the
/// (first index, count) of each at `level * 16 + mask`.
pub struct IndexVariants {
    pub indices: Vec<u32>,
    pub ranges: Vec<(u32, u32)>,
}

impl IndexVariants {
    pub fn build(n: usize) -> Self {
        let mut indices = Vec::new();
        let mut ranges = Vec::new();
        for level in 0..level_count(n) {
            for mask in 0..16u8 {
                let list = patch_indices(n, level, mask);
                ranges.push((indices.len() as u32, list.len() as u32));
                indices.extend(list);
            }
        }
        IndexVariants { indices, ranges }
    }

    pub fn range(&self, level: usize, coarser: u8) -> (u32, u32) {
        self.ranges[level * 16 + usize::from(coarser)]
    }
}

/// Where a vertex the level drops glides to: the midpoint of the two level
/// l+1 vertices on the coarse edge or diagonal through it. `(i, j)` is the
/// template position (a multiple of the level's step `s`); None for a vertex
/// that the next level keeps.
pub fn morph_target(i: usize, j: usize, s: usize) -> Option<[(isize, isize); 2]> {
    let (odd_i, odd_j) = ((i / s) % 2 == 1, (j / s) % 2 == 1);
    let (i, j, s) = (i as isize, j as isize, s as isize);
    match (odd_i, odd_j) {
        (false, false) => None,
        (false, true) => Some([(i, j - s), (i, j + s)]),
        (true, false) => Some([(i - s, j), (i + s, j)]),
        // The centre of a coarse cell lies on its B-C diagonal.
        (true, true) => Some([(i - s, j + s), (i + s, j - s)]),
    }
}

/// Level by distance (seed 001): level l covers distances
/// [d0 * 2^l, d0 * 2^(l+1)), level 0 everything nearer than 2 * d0.
pub fn level_for_distance(distance: f32, d0: f32, levels: usize) -> usize {
    let ratio = distance / d0.max(f32::MIN_POSITIVE);
    if ratio.is_nan() || ratio < 2.0 {
        return 0;
    }
    (ratio.log2().floor() as usize).min(levels - 1)
}

/// Morph factor of a patch of `level` at `distance`: 0 up to 70% of the
/// level's far distance, rising to 1 at it, where the next level takes over.
pub fn morph_factor(distance: f32, d0: f32, level: usize) -> f32 {
    let end = d0 * (1u32 << (level + 1)) as f32;
    let start = 0.7 * end;
    super::factors::saturate((distance - start) / (end - start))
}

/// How far the error plan's `block`, drawn at level index `k` (2^k
/// segments a side), glides towards its next coarser level: as far as
/// the view has come from the distance where the bound accepts its level
/// to where it accepts the next, from its box's nearest point. None where
/// the share chose its level, at the coarsest level, and where the view
/// model puts pixels over tau at the coarser level
/// (`PlannedBlock::coarser_over_px`): the bound is face-on, a ray grazing
/// a step sees more of it, and the share did not count those pixels.
pub fn block_glide(block: &PlannedBlock, k: usize, hierarchy: &Hierarchy, view: &LodView) -> f32 {
    if block.chosen || k == 0 || block.coarser_over_px > 0.0 {
        return 0.0;
    }
    let node = hierarchy.node(block.node());
    let d = node.distance(view.eye_local);
    let at = |k: usize| node.patch_max[k] * view.pixels_per_radian / view.tau.px();
    // This level is accepted from `at(k)` on, the next coarser one from
    // `at(k - 1)`.
    let (from, to) = (at(k), at(k - 1));
    if to <= from {
        1.0
    } else {
        super::factors::saturate((d - from) / (to - from))
    }
}

/// Sides of a block as `refine_and_balance_blocks` visits them: the
/// column before its first (least x), the column after its last (most
/// x), the row before its first (most z: rows run towards -z) and the row
/// after its last (least z).
pub const BLOCK_SIDES: usize = 4;

/// The patch side (mask bit) of each of `BLOCK_SIDES`.
pub const BLOCK_SIDE_BITS: [u8; BLOCK_SIDES] = [LEFT, RIGHT, TOP, BOTTOM];

/// The index in `BLOCK_SIDES`' order of a patch side's mask bit.
fn block_side(bit: u8) -> usize {
    BLOCK_SIDE_BITS
        .iter()
        .position(|&b| b == bit)
        .expect("a side's bit")
}

/// Which sides of the error plan's `block`, drawn at level index `k`
/// (2^k segments a patch side), may border a drawn neighbour one level
/// coarser (`BLOCK_SIDES`' order). Such a side is stitched: each 2x2 block
/// of quads along it is drawn as a fan (`patch_indices`), whose triangles
/// are not the level's own, and which can stray from the reference by
/// more than the level does: a spike one cell inside a full-resolution
/// patch's side has its near faces cut to half its height. A side may be
/// stitched where every patch along it strays there by no more than its
/// level's own error (`StitchErrors`), or, where one strays more, by no
/// more than tau seen from the nearest point of the strip the fans
/// cover. A side beside the eye thus keeps its neighbour at its own level
/// wherever the fans would show. Without stitching errors (`stitch`
/// None), or at the coarsest level, every side may be stitched.
pub fn stitchable_sides(
    (block, k): (&PlannedBlock, usize),
    (hierarchy, grid): (&Hierarchy, &PatchGrid),
    view: &LodView,
    stitch: Option<&StitchErrors>,
) -> [bool; BLOCK_SIDES] {
    let Some(stitch) = stitch.filter(|_| k > 0) else {
        return [true; BLOCK_SIDES];
    };
    let level = level_of_index(k, level_count(grid.cells_per_patch()));
    let excess = stitch.block_excess(block, level);
    if excess.iter().all(|&e| e == 0.0) {
        return [true; BLOCK_SIDES];
    }
    let node = hierarchy.node(block.node());
    let (lo, hi) = node.aabb();
    let strips = fan_strips(lo - view.eye_local, hi - view.eye_local, block.span() << k);
    std::array::from_fn(|side| {
        let (a, b) = strips[side];
        let scale = view.scale(super::factors::box_distance(a, b));
        excess[side] == 0.0 || super::factors::within_tolerance(excess[side], scale, view.tau.px())
    })
}

/// The strips stitched fans cover along each side (`BLOCK_SIDES`' order)
/// of the box `lo`..`hi`, drawn as `quads` quads a side: two quads from
/// the side inwards.
fn fan_strips(lo: Vec3, hi: Vec3, quads: u32) -> [(Vec3, Vec3); BLOCK_SIDES] {
    let quads = quads as f32;
    let (wx, wz) = (
        (2.0 * (hi.x - lo.x) / quads).min(hi.x - lo.x),
        (2.0 * (hi.z - lo.z) / quads).min(hi.z - lo.z),
    );
    [
        (lo, Vec3::new(lo.x + wx, hi.y, hi.z)),
        (Vec3::new(hi.x - wx, lo.y, lo.z), hi),
        (Vec3::new(lo.x, lo.y, hi.z - wz), hi),
        (lo, Vec3::new(hi.x, hi.y, lo.z + wz)),
    ]
}

/// `stitchable_sides` for single patches at balanced `levels`: wherever a
/// drawn patch's side is stitched (its neighbour one level coarser) and
/// the fans there stray past tau (`StitchErrors`, `pixel_error` pixels at
/// `pixels_per_radian`), seen from `eye_local` at the nearest point of the
/// strip they cover, the neighbour is refined to the patch's level, and
/// the levels balanced again. One pass, as `refine_and_balance_blocks`
/// keeps a block's neighbour: a neighbour refined has its own sides
/// stitched as balancing leaves them.
fn refine_unstitchable(
    levels: &mut [u8],
    terrain: &Terrain,
    drawn: &[bool],
    stitch: &StitchErrors,
    (eye_local, pixels_per_radian, pixel_error): (Vec3, f32, f32),
) {
    let grid = terrain.grid();
    let quads = |level: u8| (grid.cells_per_patch() >> level).max(1) as u32;
    let mut lowered = Vec::new();
    for p in (0..grid.patch_count()).filter(|&p| drawn[p]) {
        let id = grid.patch_id(p);
        let level = levels[p];
        let mut strips = None;
        for (side, q) in [LEFT, TOP, RIGHT, BOTTOM]
            .into_iter()
            .zip(grid.neighbours_of(id))
        {
            let Some(q) = q.map(|q| grid.patch_index(q)) else {
                continue;
            };
            let excess = stitch.excess(p, usize::from(level), side);
            if levels[q] <= level || excess == 0.0 {
                continue;
            }
            let strips = strips.get_or_insert_with(|| {
                let (centre, half) = terrain.patch_aabb(id);
                let centre = centre - eye_local;
                fan_strips(centre - half, centre + half, quads(level))
            });
            let (a, b) = strips[block_side(side)];
            let scale = pixels_per_radian / super::factors::box_distance(a, b);
            if !super::factors::within_tolerance(excess, scale, pixel_error) {
                lowered.push((grid.patch_id(q), level));
            }
        }
    }
    for &(q, level) in &lowered {
        let at = &mut levels[grid.patch_index(q)];
        *at = (*at).min(level);
    }
    let lowered: Vec<PatchId> = lowered.into_iter().map(|(q, _)| q).collect();
    balance_from(levels, grid, &lowered);
}

/// How far each side's stitched fans (`patch_indices`) stray from the
/// reference, per patch, geomip level and side, where that is further
/// than the level's own error (the geomip path's table): the largest
/// difference, over the 2x2 blocks of quads along the side, between the
/// fan drawn with every side the block touches stitched and the
/// reference's own triangles (`Heightmap::height_at`'s split), or 0 where
/// it is within the level's error. Both are planar over each triangle,
/// and the fans' edges run along grid lines and cell diagonals, so the
/// largest difference lies at a sample or at a cell's centre, where a
/// fan's diagonal crosses the reference's. A remainder patch's template
/// vertices past its last sample are clamped to it, as the vertex shader
/// clamps them. Computed once per terrain.
#[derive(Clone, Debug, PartialEq)]
pub struct StitchErrors {
    levels: usize,
    /// Per block level m (0: the patches; m: blocks of 2^m x 2^m, as the
    /// hierarchy's nodes), its columns of blocks and [level][block] the
    /// largest excess of the patches along each of its sides, in
    /// `BLOCK_SIDES`' order: a block's sides are read at once, and blocks
    /// side by side at one level, as a frame reads them, share lines.
    blocks: Vec<(usize, Vec<[f32; BLOCK_SIDES]>)>,
}

impl StitchErrors {
    /// Every patch of `grid` over `map`, whose geomip path's error table
    /// is `errors`, and every block of them.
    pub fn compute(map: &Heightmap, grid: &PatchGrid, errors: &ErrorTable) -> StitchErrors {
        let n = grid.cells_per_patch();
        let levels = level_count(n);
        let count = grid.patch_count();
        let patches: Vec<[f32; BLOCK_SIDES]> = (0..levels * count)
            .into_par_iter()
            .map(|i| {
                let (level, p) = (i / count, i % count);
                let own = errors.error(p, table_index(level, levels));
                let rect = grid.sample_rect(grid.patch_id(p));
                patch_stitch_errors(map, rect, n, level).map(|e| if e > own { e } else { 0.0 })
            })
            .collect();
        let (mut cols, mut rows) = (grid.patch_cols(), grid.patch_rows());
        let mut blocks = vec![(cols, patches)];
        while cols > 1 || rows > 1 {
            let (below_cols, below_rows) = (cols, rows);
            (cols, rows) = (cols.div_ceil(2), rows.div_ceil(2));
            let below = &blocks.last().expect("the patches").1;
            let (below_count, count) = (below_cols * below_rows, cols * rows);
            let mut next = vec![[0.0f32; BLOCK_SIDES]; count * levels];
            for b in 0..count {
                let (c, r) = (b % cols, b / cols);
                // The children along each side: the last column or row of
                // a block at the far edges may be its first.
                let (last_c, last_r) = (
                    (2 * c + 1).min(below_cols - 1),
                    (2 * r + 1).min(below_rows - 1),
                );
                for (side, (cs, rs)) in [
                    (2 * c..=2 * c, 2 * r..=last_r),
                    (last_c..=last_c, 2 * r..=last_r),
                    (2 * c..=last_c, 2 * r..=2 * r),
                    (2 * c..=last_c, last_r..=last_r),
                ]
                .into_iter()
                .enumerate()
                {
                    for rr in rs {
                        for cc in cs.clone() {
                            for level in 0..levels {
                                let e = below[level * below_count + rr * below_cols + cc][side];
                                let o = &mut next[level * count + b][side];
                                *o = o.max(e);
                            }
                        }
                    }
                }
            }
            blocks.push((cols, next));
        }
        StitchErrors { levels, blocks }
    }

    /// The largest excess of the patches along each side of the plan's
    /// `block` at geomip level `level` (`BLOCK_SIDES`' order).
    pub fn block_excess(&self, block: &PlannedBlock, level: usize) -> [f32; BLOCK_SIDES] {
        let (cols, excess) = &self.blocks[block.level as usize];
        let b = (block.row >> block.level) as usize * cols + (block.col >> block.level) as usize;
        excess[level * (excess.len() / self.levels) + b]
    }

    /// Patch `patch`'s fans' error at geomip level `level` along side
    /// `side` (one of `LEFT`, `TOP`, `RIGHT`, `BOTTOM`) where it is past
    /// the level's own, else 0.
    pub fn excess(&self, patch: usize, level: usize, side: u8) -> f32 {
        let patches = &self.blocks[0].1;
        patches[level * (patches.len() / self.levels) + patch][block_side(side)]
    }
}

/// `StitchErrors` of one patch (`rect`, of a grid of `n`-cell patches) at
/// geomip `level`, in `BLOCK_SIDES`' order, however far past the level's
/// own error.
fn patch_stitch_errors(
    map: &Heightmap,
    rect: SampleRect,
    n: usize,
    level: usize,
) -> [f32; BLOCK_SIDES] {
    let s = 1usize << level;
    let k = n / s;
    let mut out = [0.0f32; BLOCK_SIDES];
    if k < 2 {
        // A single quad is never stitched.
        return out;
    }
    let (rows, cols) = (rect.cells_z(), rect.cells_x());
    let h =
        |i: usize, j: usize| f64::from(map.get(rect.row0 + i.min(rows), rect.col0 + j.min(cols)));
    let blocks = k / 2;
    for bi in 0..blocks {
        for bj in 0..blocks {
            let sides = block_sides(bi, bj, blocks);
            let (i0, j0) = (bi * 2 * s, bj * 2 * s);
            if sides == 0 || i0 >= rows || j0 >= cols {
                continue;
            }
            let clamp = |(di, dj): (usize, usize)| ((i0 + di).min(rows), (j0 + dj).min(cols));
            let ring: Vec<(usize, usize)> = fan_ring(s, sides).map(clamp).collect();
            let centre = clamp((s, s));
            let worst = (0..ring.len())
                .map(|t| fan_error(&h, [centre, ring[t], ring[(t + 1) % ring.len()]]))
                .fold(0.0f64, f64::max) as f32;
            for (bit, o) in BLOCK_SIDE_BITS.into_iter().zip(&mut out) {
                if sides & bit != 0 {
                    *o = o.max(worst);
                }
            }
        }
    }
    out
}

/// The largest difference over the triangle `tri` (template (row, column)
/// offsets) between the plane through its vertices' heights and the
/// reference (`h` at the samples, the split's midpoint at cell centres):
/// at its samples and at its cells' centres (`StitchErrors`).
fn fan_error(h: &impl Fn(usize, usize) -> f64, tri: [(usize, usize); 3]) -> f64 {
    let p = tri.map(|(i, j)| (i as f64, j as f64));
    let (a, b) = (
        (p[1].0 - p[0].0, p[1].1 - p[0].1),
        (p[2].0 - p[0].0, p[2].1 - p[0].1),
    );
    let det = a.0 * b.1 - a.1 * b.0;
    if det == 0.0 {
        // Collapsed by clamping: it draws nothing.
        return 0.0;
    }
    let heights = tri.map(|(i, j)| h(i, j));
    let [(i0, j0), (i1, j1), (i2, j2)] = tri;
    let (i_lo, i_hi) = (i0.min(i1).min(i2), i0.max(i1).max(i2));
    let (j_lo, j_hi) = (j0.min(j1).min(j2), j0.max(j1).max(j2));
    let plane = |r: f64, c: f64| {
        let d = (r - p[0].0, c - p[0].1);
        let w1 = (d.0 * b.1 - d.1 * b.0) / det;
        let w2 = (a.0 * d.1 - a.1 * d.0) / det;
        let w0 = 1.0 - w1 - w2;
        let eps = -1e-9;
        (w0 >= eps && w1 >= eps && w2 >= eps)
            .then(|| w0 * heights[0] + w1 * heights[1] + w2 * heights[2])
    };
    let mut worst = 0.0f64;
    for r in i_lo..=i_hi {
        for c in j_lo..=j_hi {
            if let Some(drawn) = plane(r as f64, c as f64) {
                worst = worst.max((drawn - h(r, c)).abs());
            }
            if r < i_hi && c < j_hi {
                if let Some(drawn) = plane(r as f64 + 0.5, c as f64 + 0.5) {
                    let centre = 0.5 * (h(r, c + 1) + h(r + 1, c));
                    worst = worst.max((drawn - centre).abs());
                }
            }
        }
    }
    worst
}

/// Balances levels so neighbours differ by at most one, only ever lowering
/// (refining) a level.
pub fn balance(levels: &mut [u8], grid: &PatchGrid) {
    loop {
        let mut changed = false;
        for p in 0..grid.patch_count() {
            let limit = grid
                .neighbours(p)
                .into_iter()
                .flatten()
                .fold(levels[p], |limit, q| limit.min(levels[q] + 1));
            if limit < levels[p] {
                levels[p] = limit;
                changed = true;
            }
        }
        if !changed {
            return;
        }
    }
}

/// `balance` where every patch but those listed in `lowered` is at the
/// coarsest level (`levels.len()` patches of `grid`): the same levels, in
/// time that grows with the patches listed and the levels, not the grid.
/// A lowered patch lowers its neighbours to one level above it, and so on
/// outwards, which ends within `level_count` steps of it.
pub fn balance_from(levels: &mut [u8], grid: &PatchGrid, lowered: &[PatchId]) {
    balance_queue(levels, grid, &mut lowered.to_vec());
}

/// `balance_from` the patches in `queue`, which it empties.
fn balance_queue(levels: &mut [u8], grid: &PatchGrid, queue: &mut Vec<PatchId>) {
    while let Some(p) = queue.pop() {
        let limit = levels[grid.patch_index(p)] + 1;
        for q in grid.neighbours_of(p).into_iter().flatten() {
            let at = &mut levels[grid.patch_index(q)];
            if *at > limit {
                *at = limit;
                queue.push(q);
            }
        }
    }
}

/// Lowers every patch that is not drawn but shares a side with one that
/// is (`drawn`, one flag per patch) to the finest level of its drawn
/// neighbours, and returns the patches lowered. The shared side can be on
/// screen though the patch beyond it is culled: left coarser, that
/// neighbour would have the drawn patch stitch the side to a level no
/// choice made for it. Only ever lowers, so balancing afterwards keeps it;
/// a patch lowered twice is listed twice.
pub fn refine_beside_drawn(levels: &mut [u8], grid: &PatchGrid, drawn: &[bool]) -> Vec<PatchId> {
    let all: Vec<PatchId> = (0..grid.patch_count())
        .filter(|&p| drawn[p])
        .map(|p| grid.patch_id(p))
        .collect();
    refine_beside(levels, grid, drawn, &all)
}

/// `refine_beside_drawn` from `edges`, the drawn patches that can have a
/// neighbour not drawn (all of them, or only those on the sides of drawn
/// blocks): the same levels, in time that grows with the edges.
pub fn refine_beside(
    levels: &mut [u8],
    grid: &PatchGrid,
    drawn: &[bool],
    edges: &[PatchId],
) -> Vec<PatchId> {
    let mut lowered = Vec::new();
    for &p in edges {
        let level = levels[grid.patch_index(p)];
        for q in grid.neighbours_of(p).into_iter().flatten() {
            let i = grid.patch_index(q);
            if !drawn[i] && levels[i] > level {
                levels[i] = level;
                lowered.push(q);
            }
        }
    }
    lowered
}

/// How many patches beyond the drawn ones refining and balancing can
/// change a level, for patches of `cells_per_patch`: a drawn patch at the
/// finest level refines a culled neighbour to its own (`refine_beside`),
/// and balancing lowers each ring beyond to one level coarser than the
/// ring before, until a ring would take the coarsest level, which every
/// patch starts at (`balance_from`).
pub fn balance_reach(cells_per_patch: usize) -> usize {
    level_count(cells_per_patch) - 1
}

/// `refine_beside` from `edges`, then `balance_from` the edges and the
/// patches it refined, each only where it is at least two levels finer
/// than the coarsest (a coarser one lowers no neighbour): the levels of
/// `refine_beside_drawn` and `balance` where every patch but those drawn
/// is at the coarsest.
pub fn refine_and_balance(levels: &mut [u8], grid: &PatchGrid, drawn: &[bool], edges: &[PatchId]) {
    let count = level_count(grid.cells_per_patch());
    let beside = refine_beside(levels, grid, drawn, edges);
    let lowered: Vec<PatchId> = edges
        .iter()
        .chain(&beside)
        .copied()
        .filter(|&p| usize::from(levels[grid.patch_index(p)]) + 2 < count)
        .collect();
    balance_from(levels, grid, &lowered);
}

/// `refine_beside` and `balance_from` for patches drawn in blocks that
/// each share one level (`blocks`: columns and rows of patches, end
/// exclusive, each block's patches at its level in `levels`), the rest at
/// the coarsest: the same levels, in time that grows with the blocks'
/// sides. Inside a block no side changes level, so only the patches just
/// beyond a block's sides are looked at, once each: refining the culled
/// ones and seeding the balancing in the same pass. Where a side of a
/// block may not be stitched to a coarser neighbour (`stitched(i)[s]`
/// false for side `s` of block `i`, `stitchable_sides`), a drawn patch
/// beyond it is refined to the block's level as a culled one is.
/// `stitched(i)` is asked for only where a drawn patch beyond block `i`
/// is coarser than it, at most once a block: most blocks border none
/// (6 to 44 % of the bench views' blocks do, at 0.25 and 1 px).
pub fn refine_and_balance_blocks(
    levels: &mut [u8],
    grid: &PatchGrid,
    drawn: &[bool],
    blocks: &[([usize; 2], [usize; 2])],
    stitched: impl FnMut(usize) -> [bool; BLOCK_SIDES],
) {
    Balancing::default().blocks(levels, grid, (drawn, blocks), stitched);
}

/// Patches of a grid as columns and rows, end exclusive.
pub type PatchRect = ([usize; 2], [usize; 2]);

/// The buffers of `refine_and_balance_blocks`, kept from one choice to the
/// next so that a frame's balancing allocates nothing.
#[derive(Debug, Default)]
pub struct Balancing {
    /// Each block's own level.
    own: Vec<u8>,
    /// Patches lowered whose neighbours are still to be looked at.
    queue: Vec<PatchId>,
}

impl Balancing {
    /// `refine_and_balance_blocks` in these buffers.
    pub fn blocks(
        &mut self,
        levels: &mut [u8],
        grid: &PatchGrid,
        (drawn, blocks): (&[bool], &[PatchRect]),
        stitched: impl FnMut(usize) -> [bool; BLOCK_SIDES],
    ) {
        let Balancing { own, queue } = self;
        queue.clear();
        // The blocks' own levels: balancing may lower a block's patches
        // one by one, and those it lowers go on the queue themselves.
        own.clear();
        own.extend(
            blocks
                .iter()
                .map(|&([c0, _], [r0, _])| levels[grid.patch_index(PatchId { row: r0, col: c0 })]),
        );
        refine_beyond_sides(levels, grid, (drawn, blocks, own), stitched, queue);
        balance_queue(levels, grid, queue);
    }
}

/// The one look beyond each block's sides of `refine_and_balance_blocks`,
/// each patch it lowers added to `queue`.
fn refine_beyond_sides(
    levels: &mut [u8],
    grid: &PatchGrid,
    (drawn, blocks, own): (&[bool], &[PatchRect], &[u8]),
    mut stitched: impl FnMut(usize) -> [bool; BLOCK_SIDES],
    queue: &mut Vec<PatchId>,
) {
    // One look beyond each side: a culled patch takes the finest level of
    // the blocks beside it, a drawn one at most one coarser than each
    // (none beyond a side that may not be stitched). Both are minima over
    // the blocks, so one pass in any order gives them; a patch at its
    // blocks' finest is never more than one coarser than any of them.
    // Nothing is coarser than a block at the coarsest level.
    let coarsest = (level_count(grid.cells_per_patch()) - 1) as u8;
    for (b, (block, &level)) in blocks.iter().zip(own).enumerate() {
        if level >= coarsest {
            continue;
        }
        let mut sides = None;
        for_each_beyond(grid, block, |side, i, q| {
            // A patch beyond at the block's level or finer stays.
            if levels[i] <= level {
                return;
            }
            let limit = match drawn[i] && sides.get_or_insert_with(|| stitched(b))[side] {
                true => level + 1,
                false => level,
            };
            if levels[i] > limit {
                levels[i] = limit;
                queue.push(q);
            }
        });
    }
}

/// Calls `f` with the side (`BLOCK_SIDES`' order), index and place of
/// each patch just beyond a side of the block of columns `c0..c1` and rows
/// `r0..r1` of `grid`.
fn for_each_beyond(
    grid: &PatchGrid,
    &([c0, c1], [r0, r1]): &([usize; 2], [usize; 2]),
    mut f: impl FnMut(usize, usize, PatchId),
) {
    let mut visit = |side: usize, id: PatchId| f(side, grid.patch_index(id), id);
    if c0 > 0 {
        (r0..r1).for_each(|row| visit(0, PatchId { row, col: c0 - 1 }));
    }
    if c1 < grid.patch_cols() {
        (r0..r1).for_each(|row| visit(1, PatchId { row, col: c1 }));
    }
    if r0 > 0 {
        (c0..c1).for_each(|col| visit(2, PatchId { row: r0 - 1, col }));
    }
    if r1 < grid.patch_rows() {
        (c0..c1).for_each(|col| visit(3, PatchId { row: r1, col }));
    }
}

/// Sides of `id` whose neighbour is coarser (`.0`) and finer (`.1`), for
/// balanced levels.
pub fn neighbour_masks(levels: &[u8], grid: &PatchGrid, id: PatchId) -> (u8, u8) {
    let p = grid.patch_index(id);
    let here = levels[p];
    let (mut coarser, mut finer) = (0u8, 0u8);
    let sides = [LEFT, TOP, RIGHT, BOTTOM];
    for (bit, q) in sides.into_iter().zip(grid.neighbours(p)) {
        let Some(q) = q else { continue };
        if levels[q] > here {
            coarser |= bit;
        } else if levels[q] < here {
            finer |= bit;
        }
    }
    (coarser, finer)
}

/// Levels of every patch (culled ones too: their neighbours need them) and
/// each patch's own morph factor towards the next coarser level.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchLevels {
    pub levels: Vec<u8>,
    pub morph: Vec<f32>,
}

/// Distance from `eye_local` (the eye relative to the terrain's centre) to
/// the nearest point of each patch's box.
fn patch_distances(terrain: &Terrain, eye_local: Vec3) -> Vec<f32> {
    let grid = terrain.grid();
    (0..grid.patch_count())
        .map(|p| {
            let (centre, extents) = terrain.patch_aabb(grid.patch_id(p));
            ((eye_local - centre).abs() - extents)
                .max(Vec3::ZERO)
                .length()
        })
        .collect()
}

/// Levels by distance (seed 001), balanced; morph by `morph_factor`.
pub fn select_levels_by_distance(terrain: &Terrain, eye_local: Vec3, d0: f32) -> PatchLevels {
    let grid = terrain.grid();
    let count = level_count(grid.cells_per_patch());
    let distances = patch_distances(terrain, eye_local);
    let mut levels: Vec<u8> = distances
        .iter()
        .map(|&d| level_for_distance(d, d0, count) as u8)
        .collect();
    balance(&mut levels, grid);
    let morph = distances
        .iter()
        .zip(&levels)
        .map(|(&d, &l)| {
            let l = usize::from(l);
            if l + 1 >= count {
                0.0
            } else {
                morph_factor(d, d0, l)
            }
        })
        .collect();
    PatchLevels { levels, morph }
}

/// Levels by projected error (seed 002): the coarsest level whose
/// max-error vertex, seen from the patch's nearest point, is at most
/// `pixel_error` pixels on screen. `pixels_per_radian` is the viewport
/// height over 2 tan(fov / 2): an error e at distance d covers
/// e * pixels_per_radian / d pixels. Level l is good enough from the
/// distance t_l = e_l * pixels_per_radian / pixel_error on; the morph
/// factor is the fraction of the way from t_l to t_(l+1). With stitching
/// errors (`stitch`), a stitched side whose fans would stray past the
/// tolerance keeps its neighbour at its own level (`refine_unstitchable`).
pub fn select_levels_by_error(
    terrain: &Terrain,
    table: &ErrorTable,
    eye_local: Vec3,
    pixels_per_radian: f32,
    pixel_error: f32,
    drawn: &[bool],
    stitch: Option<&StitchErrors>,
) -> PatchLevels {
    let grid = terrain.grid();
    let n = grid.cells_per_patch();
    let count = level_count(n);
    let distances = patch_distances(terrain, eye_local);
    let threshold = |p: usize, level: usize| {
        table.error(p, table_index(level, count)) * pixels_per_radian
            / pixel_error.max(f32::MIN_POSITIVE)
    };
    let mut levels: Vec<u8> = distances
        .iter()
        .enumerate()
        .map(|(p, &d)| {
            if !drawn[p] {
                // Not drawn: the coarsest level, unless a drawn neighbour
                // needs it finer (`refine_beside_drawn`).
                return (count - 1) as u8;
            }
            (0..count)
                .rev()
                .find(|&l| threshold(p, l) <= d)
                .unwrap_or(0) as u8
        })
        .collect();
    refine_beside_drawn(&mut levels, grid, drawn);
    balance(&mut levels, grid);
    if let Some(stitch) = stitch {
        let view = (eye_local, pixels_per_radian, pixel_error);
        refine_unstitchable(&mut levels, terrain, drawn, stitch, view);
    }
    let morph = distances
        .iter()
        .enumerate()
        .map(|(p, &d)| {
            let l = usize::from(levels[p]);
            if l + 1 >= count {
                return 0.0;
            }
            let (from, to) = (threshold(p, l), threshold(p, l + 1));
            if to <= from {
                // The next level is as good: fully on its surface.
                return 1.0;
            }
            super::factors::saturate((d - from) / (to - from))
        })
        .collect();
    PatchLevels { levels, morph }
}

/// Caps each patch's morph factor at the view's limit for the level it
/// expected (`ViewErrors::morph_limits`, by error table index: log2 of the
/// segments a side). A patch balancing left finer morphs towards a level
/// the view already accepts, and keeps its factor. A side shared with a
/// patch of the same level takes the larger of the two factors
/// (`patch_morph`), so each patch is capped by its same-level neighbours'
/// limits as well: the side stays within both. A patch not `drawn` has no
/// limit measured and does not morph: its drawn neighbours' sides follow
/// their own limits.
pub fn limit_morph(
    chosen: &mut PatchLevels,
    limits: &[Option<(usize, f32)>],
    drawn: &[bool],
    grid: &PatchGrid,
) {
    let top = level_count(grid.cells_per_patch()) - 1;
    let caps: Vec<f32> = (0..grid.patch_count())
        .map(|p| match limits[p] {
            _ if !drawn[p] => 0.0,
            Some((k, cap)) if usize::from(chosen.levels[p]) + k == top => cap,
            _ => 1.0,
        })
        .collect();
    for p in 0..grid.patch_count() {
        let cap = grid
            .neighbours(p)
            .into_iter()
            .flatten()
            .filter(|&q| drawn[q] && chosen.levels[q] == chosen.levels[p])
            .fold(caps[p], |cap, q| cap.min(caps[q]));
        chosen.morph[p] = chosen.morph[p].min(cap);
    }
}

/// Morph factors of one patch: for its interior, and for its sides (left,
/// top, right, bottom). All 0 at the coarsest level (its own factor is).
pub fn patch_morph(chosen: &PatchLevels, grid: &PatchGrid, id: PatchId) -> (f32, [f32; 4]) {
    let p = grid.patch_index(id);
    let own = chosen.morph[p];
    let side = |neighbour: Option<usize>| match neighbour {
        None => own,
        Some(q) => {
            if chosen.levels[q] == chosen.levels[p] {
                // Whichever of the two switches first has morph 1 then.
                own.max(chosen.morph[q])
            } else {
                // Finer: frozen. Coarser: the stitched side has no vertex to move.
                0.0
            }
        }
    };
    (own, grid.neighbours(p).map(side))
}

/// A drawn patch as `predicted_px` reads it.
#[derive(Clone, Copy, Debug)]
pub struct DrawnPatch {
    /// Its box: footprint and Y bounds, terrain-local.
    pub lo: Vec3,
    pub hi: Vec3,
    /// Its geomip level.
    pub level: usize,
    /// The largest of its interior's and sides' morph factors.
    pub morph: f32,
    /// Its sides stitched to a coarser neighbour (`neighbour_masks`).
    pub coarser: u8,
    /// How far each side's fans, where it is stitched, stray from the
    /// reference past the level's own error (`StitchErrors::excess`), by
    /// the masks' bits (left, top, right, bottom); 0 where not known.
    pub fans: [f32; 4],
    /// Where its box holds the eye, the nearest its surface comes
    /// (`Terrain::surface_distances`); None elsewhere, or where the
    /// terrain's samples are not held.
    pub ground: Option<f32>,
}

/// The error a patch's level choice expects on screen, in pixels: its
/// level's error (`error`, by geomip level) from its box's nearest point,
/// or while it glides towards the next coarser level, the blend of the
/// two by its largest morph factor; a side stitched to a coarser
/// neighbour adds that level's error, or its fans' where they stray
/// further (`DrawnPatch::fans`), from the nearest point of that side.
/// Level 0 is the reference itself (error 0) but for its stitched
/// sides. A patch whose box holds the eye is seen from the nearest its
/// drawn surface can come, its ground's distance less its error
/// (infinite where that is none); without its ground, it is taken to be
/// drawn at level 0, as the choice keeps it there.
pub fn predicted_px(
    error: impl Fn(usize) -> f32,
    patch: &DrawnPatch,
    eye_local: Vec3,
    pixels_per_radian: f32,
) -> f32 {
    let (lo, hi) = (patch.lo - eye_local, patch.hi - eye_local);
    let level = patch.level;
    let mut px = 0.0f32;
    if level > 0 {
        let m = patch.morph;
        let e = match m > 0.0 {
            true => (1.0 - m) * error(level) + m * error(level + 1),
            false => error(level),
        };
        let d = match (super::factors::box_distance(lo, hi), patch.ground) {
            (d, _) if d > 0.0 => d,
            (_, Some(ground)) if ground > e => ground - e,
            (_, Some(_)) => return f32::INFINITY,
            (_, None) => return 0.0,
        };
        px = e * pixels_per_radian / d;
    }
    if patch.coarser != 0 {
        // The corners in control point order (upper-left has the
        // smallest x and largest z); only their x and z are read.
        let corners = [(lo.x, hi.z), (hi.x, hi.z), (lo.x, lo.z), (hi.x, lo.z)]
            .map(|(x, z)| Vec3::new(x, 0.0, z));
        let xz = |v: Vec3| glam::Vec2::new(v.x, v.z);
        // Left, top, right, bottom, as the masks' bits.
        for (bit, (a, b)) in super::factors::patch_edges(corners).into_iter().enumerate() {
            if patch.coarser & (1 << bit) != 0 {
                let d = super::factors::edge_distance(xz(a), xz(b), lo.y, hi.y);
                let e = error(level + 1).max(patch.fans[bit]);
                px = px.max(e * pixels_per_radian / d.max(f32::MIN_POSITIVE));
            }
        }
    }
    px
}
