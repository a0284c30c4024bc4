//! The error a view sees of a patch drawn at a coarser level: the error
//! table's levels re-measured for one eye, the way the benchmark measures a
//! render against the reference, and the frame's share of pixels over the
//! tolerance spent where it saves the most triangles.
//!
//! **What a pixel shows.** The error table bounds each level's largest
//! vertical error anywhere on the patch, and the bound is projected face-on
//! from the patch's nearest point. A pixel's view ray meets the reference at
//! R; the drawn surface lies a vertical distance delta above or below R, and
//! the ray runs on (or back) until it meets it. For a ray that falls `t`
//! per unit of horizontal travel (`t` < 0 rising) onto a drawn surface that
//! rises `s` per unit in the ray's horizontal direction, the meeting points
//! lie `|delta| / (s + t)` apart horizontally and `|t|` times that
//! vertically, which at distance `d` covers that many times `K / d` pixels
//! (K the viewport's pixels per radian). On flat ground that is the face-on
//! projection; on ground rising towards the eye, seen from low down, a
//! fraction of it; on ground falling away, towards a silhouette, more. The
//! horizontal run is cut at the drawn quad's diagonal: at the quad's
//! corners the drawn surface is the reference, which the ray has entered,
//! so a ray that grazes the drawn surface meets it within the quad. That
//! holds only while the ray sinks into the reference (rising `s_ref` along
//! it) fast enough to be `|delta|` deep within the diagonal; a ray that
//! sinks slower may clear the drawn surface and land further on. That ray
//! is followed over the level's quads to where it meets the drawn surface
//! (`PatchSamples::landing`); so is one over a drawn surface that falls
//! away along it as fast as the ray falls (`s + t` <= 0), within the
//! diagonal. A sample's vertices are the reference: its error, and its
//! pixels' error, is zero whatever the slopes.
//!
//! **Escaping rays.** A ray that never lands (it leaves the patch, whose
//! neighbours' levels are not known, or runs as far as puts it `|delta|`
//! above the drawn surface) is counted face-on, as the bound counts it,
//! though never more than `|t|` times the run to the terrain's edge. Only
//! the sample's top rays escape: one `p` pixels lower passes the sample
//! `p K / d` lower, under the drawn surface once that exceeds `|delta|`.
//! So a band `|delta| K / d` pixels tall and the sample's width wide takes
//! the face-on error, and the rest of the sample's pixels, whose rays meet
//! the drawn surface in front of it, the local estimate.
//!
//! **Which vertices.** A level is laid over the patch as its path draws
//! it (`Layout`): the tessellator cuts each side into 2^k equal segments
//! whatever its cells, so on the far remainders (patches narrower than the
//! rest, where the map's size is not a multiple of the patch size) vertices
//! fall between samples and take the reference's height there; the geomip
//! template takes every (N / 2^k)-th sample, clamped to the patch's far
//! sides.
//!
//! **Which pixels.** Each sample stands for the ground its viewshed ring
//! step adds to the view (`Viewshed::exposure`): the solid angle between
//! the horizon in front of it and the sample, within the frustum's height,
//! so ground a ray grazes covers few pixels, ground facing away or hidden
//! (wholly or in part) by nearer terrain adds only what shows, and the
//! steps add up to the ground the eye sees. A pixel `a` off the view axis
//! covers `cos^3(a) / K^2` steradians. Samples outside the frustum or
//! hidden cover no pixels, but for one beside the view whose triangles
//! reach into it: it shows its errors on the share of them in view, which
//! the frame's share over tau is not taken of. So a level's error is a
//! distribution over the patch's pixels, not one worst value.
//!
//! **Silhouettes.** A seen sample with hidden ground right behind it
//! (`Viewshed::crest`) is on a silhouette: a vertical error there moves the
//! silhouette by its face-on size, but no further than the sample rises
//! above the horizon in front of it (below that, nearer ground is the
//! silhouette), and, drawn lower, no further than the highest the level's
//! drawn surface rises along its line of sight within the patch (a vertex
//! in front of or behind it may hold the outline up;
//! `PatchSamples::sunk_silhouette`). Each pixel it sweeps shows the silhouette in one render and
//! the ground where its line of sight lands in the other: as far apart, in
//! pixels, as the line of sight falls between them, seen at the sample.
//! Against the sky, each is off by its distance to the moved silhouette.
//! Seen from outside the map, the samples of its edge towards the eye
//! (`Viewshed::edge`) show no ground of their own, but draw the map's
//! outline against the background below it: a vertical error moves that
//! outline by its face-on size either way, and each pixel it sweeps is
//! off by its distance to the moved outline, as against the sky
//! (`Seen::outline_width`).
//!
//! **The frame's share.** The benchmark's target is the frame's 99th
//! percentile, so 1 % of the frame's terrain pixels may exceed tau; the
//! choice spends half of it on the errors it models (`EXCEED_FRACTION`, of
//! the seen pixels the samples add up to, at most the viewport), keeping
//! the other half for what the model misses. A patch drawn at full
//! resolution is the reference itself, where the model misses nothing, so
//! its pixels count at the whole 1 % (`Budget`). Starting from every patch
//! at its coarsest level, that share is handed out greedily: the patch and
//! finer level that remove the most pixels over tau per triangle added go
//! first, until what remains over tau fits. A step is all or nothing, so
//! the last may overshoot; the few largest are each held back in turn and
//! the cheapest choice that fits is kept (`greedy_levels`). Each
//! patch then has its own share `q` of its pixels, and each of its levels
//! the error that all but `q` of its pixels stay within (a pixel-weighted
//! percentile). Geomip draws refine patches to within one level of their
//! neighbours afterwards, which leaves pixels over tau unspent, and draw
//! each side next to a coarser neighbour stitched, which may put more over
//! tau: the 2x2 blocks of cells along it are fans that skip the
//! neighbour's missing midpoints (`geomip::patch_indices`), measured as
//! drawn (`PatchSamples::stitched`). For them the greedy share is raised,
//! or lowered, to the largest whose refined and stitched levels still fit.
//! The samples do not see where a fan's diagonal crosses the reference's,
//! between them (a spike one cell inside a side has its near faces cut to
//! half its height): the geomip path's choice from this table keeps a
//! neighbour at a patch's level wherever those fans would stray past tau
//! (`geomip::select_levels_by_error`, `geomip::StitchErrors`).
//!
//! **Geomorphing.** A geomip patch glides towards its next coarser level;
//! its morph factor is capped where the blend would put more of its pixels
//! over tau than its level does, stitched where it is (`morph_limit`).
//!
//! **Which levels.** The bound projects the largest vertical error
//! face-on; a ray running on down ground that falls away from the eye
//! shows more than that. So the levels the bound accepts from a patch's
//! nearest point are measured as well, up to the first that puts no pixel
//! over tau, and only the levels from there on keep the bound's word.
//! Patches whose coarsest level the bound accepts are not measured.
//!
//! **Units.** The result is given in the error table's units, a length at
//! the patch's nearest point: the percentile in pixels times that distance
//! over K. The control shader and every CPU choice use it exactly as they
//! use the table, so nothing on the GPU changes, and both sides of a shared
//! edge still agree. Levels stay non-increasing as they rise.

use glam::{DVec2, DVec3, Vec3};

use crate::terrain::camera::Frustum;
use rayon::prelude::*;

use super::factors::{patch_box_distance, within_tolerance};
use super::geomip;
use super::viewshed::Viewshed;
use crate::terrain::error_table::{split_ad, split_bc, ErrorTable, LEVEL_COUNT};
use crate::terrain::grid::SampleRect;
use crate::terrain::heightmap::Heightmap;
use crate::terrain::Terrain;

/// Share of the frame's terrain pixels the view's choice lets its modelled
/// errors put over tau: half the 1 % a 99th percentile allows. The other
/// half is left to what the samples do not model: errors between samples,
/// the tessellator's transition triangles, geomip patches that balancing
/// left finer than their choice gliding uncapped towards the next level,
/// and rays that skim the drawn surface to land further on than the
/// sample's own neighbourhood shows.
pub const EXCEED_FRACTION: f64 = 0.005;

/// Most half-cell steps a ray is followed to where it meets a drawn
/// surface (`PatchSamples::landing`); a ray that runs further counts as
/// not meeting it.
const MAX_LANDING_STEPS: f64 = 256.0;

/// Share of the frame's pixels above its 99th percentile.
const P99_FRACTION: f64 = 0.01;

/// Which triangulation a level's quads are drawn with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Diagonal {
    /// The tessellator's: either diagonal, so the larger error of the two.
    Either,
    /// The reference's (upper-right to lower-left), as the geomip path
    /// draws every quad.
    Reference,
}

/// How a path lays a level's vertices over a patch, along one side of
/// `cells` cells.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Layout {
    /// The tessellator's (`Diagonal::Either`): level k cuts each side into
    /// 2^k equal segments, whatever its cells; a vertex between samples
    /// takes the reference's height there (`Heightmap::interpolate`, as
    /// the evaluation shader reads it). A patch is drawn at full resolution
    /// from the first level whose segments reach its smaller side.
    Tessellated,
    /// The geomip template's (`Diagonal::Reference`): level k takes every
    /// (N / 2^k)-th sample of a template of N cells a side, clamped to the
    /// patch's far sides (the far remainders are narrower); level log2 N
    /// is full resolution.
    Template(usize),
}

impl Layout {
    /// The layout the path drawing `diagonal` uses, for patches of
    /// `cells_per_patch` cells.
    fn of(diagonal: Diagonal, cells_per_patch: usize) -> Self {
        match diagonal {
            Diagonal::Either => Layout::Tessellated,
            Diagonal::Reference => Layout::Template(cells_per_patch),
        }
    }

    /// Level `k`'s vertex positions along a side of `cells` cells, in
    /// samples from its start: increasing, from 0 to `cells`.
    fn vertices(self, k: usize, cells: usize) -> Vec<f64> {
        match self {
            Layout::Tessellated => {
                let segments = 1usize << k;
                (0..=segments)
                    .map(|i| (i * cells) as f64 / segments as f64)
                    .collect()
            }
            Layout::Template(_) => {
                let step = self.step(k);
                (0..cells)
                    .step_by(step)
                    .chain(std::iter::once(cells))
                    .map(|v| v as f64)
                    .collect()
            }
        }
    }

    /// The geomip template's step at level `k`, in samples (0 for the
    /// tessellator's layout, whose vertices need not fall on samples).
    fn step(self, k: usize) -> usize {
        match self {
            Layout::Tessellated => 0,
            Layout::Template(n) => (n >> k).max(1),
        }
    }

    /// The full-resolution level's index for a patch of `cells` (columns,
    /// rows).
    fn full(self, (cx, cz): (usize, usize)) -> usize {
        match self {
            Layout::Tessellated => cx.min(cz).next_power_of_two().trailing_zeros() as usize,
            Layout::Template(n) => n.trailing_zeros() as usize,
        }
    }
}

/// The height at (u, v) in a quad [A upper-left, B upper-right, C
/// lower-left, D lower-right] split like the reference, along B-C.
fn split_reference(corners: [f64; 4], u: f64, v: f64) -> f64 {
    split_bc(corners, u, v, u + v <= 1.0)
}

/// The same quad split along the other diagonal, A-D.
fn split_other(corners: [f64; 4], u: f64, v: f64) -> f64 {
    split_ad(corners, u, v, u >= v)
}

/// What the view is: the eye relative to the terrain's centre, the
/// viewport's pixels per radian and size, the frustum (eye-relative) and
/// the tolerance the choice is for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewLod {
    pub eye_local: Vec3,
    pub pixels_per_radian: f32,
    pub viewport_pixels: f64,
    pub frustum: Frustum,
    pub pixel_error: f32,
}

/// The error table as one view sees it, and what the view expects of it.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewErrors {
    pub table: ErrorTable,
    /// The 99th percentile error the choice expects over the measured
    /// patches' pixels, each patch at the level its path is expected to
    /// draw (geomip's balancing refines some past their own choice, and
    /// stitches their sides next to coarser neighbours), in
    /// pixels (the choice's own target is the 99.5th, `EXCEED_FRACTION`).
    pub predicted_p99_px: f32,
    /// The largest error the choice expects on any seen sample, in pixels,
    /// at the same levels.
    pub predicted_max_px: f32,
    /// Per patch, for `Diagonal::Reference` (geomorphing draws): the level
    /// index the choice expects and the largest morph factor towards the
    /// next coarser level that puts no more of the patch's pixels over tau
    /// than that level does (see `morph_limit`); None where any factor does.
    pub morph_limits: Vec<Option<(usize, f32)>>,
}

/// One patch's levels as the view sees them at its share (second pass):
/// the patch, its table entries, and (error, pixels) of each seen sample
/// at the level the control shader will pick.
type Measured = (
    usize,
    [f32; LEVEL_COUNT],
    Vec<(f64, f64)>,
    Option<(usize, f32)>,
);

/// One patch's measured levels (first pass).
struct Estimate {
    patch: usize,
    /// Distance from the eye to the patch's box.
    distance: f32,
    /// Its seen pixels.
    pixels: f64,
    /// Per level index: pixels over tau, 0 from `from` on.
    over: [f64; LEVEL_COUNT],
    /// The first level that puts no pixel over tau, measured or accepted
    /// by the bound (at most `full`): the levels below it are the measured
    /// ones.
    from: usize,
    /// The full-resolution level's index (`Layout::full`).
    full: usize,
    /// Triangles at full resolution (the reference's own); a coarser level
    /// k draws 2 x 4^k.
    full_triangles: f64,
}

/// The error table `bound` as this view sees it, for the patches `wanted`
/// (the others keep their bounds). See the module documentation: the
/// frame's share of pixels over tau (`EXCEED_FRACTION`) is spent where it
/// saves the most triangles, and each patch's levels get the error that
/// all but its share of pixels stay within, in the table's units. Levels
/// stay non-increasing as they rise. The levels the bound rejects from a
/// patch's nearest point are measured, and the accepted ones up to the
/// first with no pixel over tau, the far remainders' as their path lays
/// them (`Layout`). A patch the eye is inside has no nearest distance to
/// scale by: its accepted levels get error 0 (`within_tolerance`), the
/// others keep their bounds.
pub fn view_error_table(
    terrain: &Terrain,
    heightmap: &Heightmap,
    bound: &ErrorTable,
    diagonal: Diagonal,
    view: &ViewLod,
    wanted: &[bool],
) -> ViewErrors {
    let grid = terrain.grid();
    let info = terrain.info();
    let tau = f64::from(view.pixel_error.max(f32::MIN_POSITIVE));
    let distance = |p: usize| {
        let corners = terrain
            .patch_corners(grid.patch_id(p))
            .map(|c| c - view.eye_local);
        let [lo, hi] = terrain.y_bounds()[p];
        patch_box_distance(corners, [lo - view.eye_local.y, hi - view.eye_local.y])
    };
    // The coarsest level the bound accepts from the patch's nearest point.
    // The view's error at a sample is never over the bound's there, so
    // every level from this one on has no pixel over tau, and a patch whose
    // coarsest level is accepted needs no measuring at all (its pixels are
    // left out of the frame's share: fewer pixels, a smaller share).
    let accepted = |p: usize| {
        let scale = view.pixels_per_radian / distance(p).max(f32::MIN_POSITIVE);
        (0..LEVEL_COUNT)
            .find(|&k| within_tolerance(bound.error(p, k), scale, view.pixel_error))
            .unwrap_or(LEVEL_COUNT)
    };
    let measured: Vec<bool> = (0..grid.patch_count())
        .into_par_iter()
        .map(|p| wanted[p] && accepted(p) > 0)
        .collect();
    let viewshed = sweep_viewshed(terrain, heightmap, view, &measured);
    let layout = Layout::of(diagonal, grid.cells_per_patch());
    let samples = |p: usize| {
        let rect = grid.sample_rect(grid.patch_id(p));
        PatchSamples::new(heightmap, rect, layout, info, view, &viewshed)
    };
    // First pass: each patch's seen pixels, and its pixels over tau at
    // every level the bound rejects.
    let estimates: Vec<Estimate> = (0..grid.patch_count())
        .into_par_iter()
        .filter(|&p| measured[p])
        .filter_map(|p| {
            let mut patch = samples(p);
            let full = patch.full();
            if full == 0 {
                return None;
            }
            let mut from = accepted(p).min(full);
            let distance = distance(p);
            let mut over = [0.0; LEVEL_COUNT];
            for (k, o) in over.iter_mut().enumerate().take(from) {
                patch.level(k, diagonal);
                *o = patch.over(tau);
            }
            // The bound is the vertical error seen face-on; a ray running
            // down a slope that falls away from the eye travels further to
            // the drawn surface and shows more. The levels the bound
            // accepts are measured too, up to the first with no pixel over
            // tau.
            while from < full {
                patch.level(from, diagonal);
                over[from] = patch.over(tau);
                if over[from] <= 0.0 {
                    break;
                }
                from += 1;
            }
            // A level's table entry is the largest of it and every finer
            // level's (see below), so it is within tau only where they all
            // are.
            for k in (0..full.saturating_sub(1)).rev() {
                over[k] = over[k].max(over[k + 1]);
            }
            Some(Estimate {
                patch: p,
                distance,
                pixels: patch.pixels(),
                over,
                from,
                full,
                full_triangles: 2.0 * (patch.cells.0 * patch.cells.1) as f64,
            })
        })
        .collect();
    // A geomip patch's pixels over tau at level `k` with `sides` stitched
    // to coarser neighbours.
    let stitched_over = |e: &Estimate, k: usize, sides: u8| {
        let mut patch = samples(e.patch);
        patch.stitched = sides;
        patch.level(k, diagonal);
        patch.over(tau)
    };
    let stitched = (diagonal == Diagonal::Reference).then_some(Stitching {
        grid,
        over: &stitched_over,
    });
    let shares = allocate(&estimates, view.viewport_pixels, stitched);

    // Second pass: each measured patch's levels at its share. The levels
    // are measured again rather than kept from the first pass: kept, every
    // measured patch's samples at every level would be held at once
    // (hundreds of megabytes on a 4097^2 terrain).
    let mut errors = bound.as_slice().to_vec();
    let per_patch: Vec<Measured> = estimates
        .par_iter()
        .zip(shares.par_iter())
        .filter_map(|(e, &(share, drawn, sides))| {
            let (p, from) = (e.patch, e.from);
            let d = f64::from(e.distance);
            let mut patch = samples(p);
            patch.keep_signed = diagonal == Diagonal::Reference;
            let own = bound.patch(p);
            let mut levels: [f32; LEVEL_COUNT] = own.try_into().expect("LEVEL_COUNT levels");
            let mut seen = vec![Vec::new(); e.full + 1];
            let mut signed = vec![Vec::new(); e.full + 1];
            for (k, level) in levels.iter_mut().enumerate().take(from) {
                patch.level(k, diagonal);
                let px = patch.percentile(share * e.pixels);
                if d > 0.0 {
                    *level = (px * d / f64::from(view.pixels_per_radian)) as f32;
                } else if px <= tau {
                    // The eye is inside the patch's box, where every error
                    // but none projects to infinitely many pixels: an
                    // accepted level is told by a zero error.
                    *level = 0.0;
                }
                seen[k] = std::mem::take(&mut patch.scratch);
                signed[k] = std::mem::take(&mut patch.signed);
            }
            for k in (0..LEVEL_COUNT - 1).rev() {
                levels[k] = levels[k].max(levels[k + 1]);
            }
            // The level the control shader will pick, and what it shows.
            let scale = view.pixels_per_radian / d as f32;
            let chosen = (0..e.full)
                .find(|&k| within_tolerance(levels[k], scale, view.pixel_error))
                .unwrap_or(e.full);
            // What it shows at the level it is drawn at: geomip's
            // balancing may refine it past the chosen one. Its stitched
            // sides are known where it is drawn at the level the
            // allocation balanced it to.
            let expected = chosen.max(drawn).min(e.full);
            let stitched = (expected == drawn && sides != 0).then(|| {
                patch.stitched = sides;
                patch.level(expected, diagonal);
                let over = patch.over(tau);
                let measured = (
                    std::mem::take(&mut patch.scratch),
                    std::mem::take(&mut patch.signed),
                );
                patch.stitched = 0;
                (measured, over)
            });
            // Geomorphing blends the chosen level into the next coarser
            // one; where that one was measured (the bound rejects it), the
            // blend may put no more pixels over tau than the chosen level,
            // stitched where it is.
            let limit =
                (diagonal == Diagonal::Reference && chosen > 0 && chosen - 1 < from).then(|| {
                    let (finer, allowed) = match &stitched {
                        Some(((_, signed), over)) if expected == chosen => {
                            (Some(signed.as_slice()), *over)
                        }
                        _ if chosen < e.full => (Some(signed[chosen].as_slice()), e.over[chosen]),
                        _ => (None, 0.0),
                    };
                    (
                        chosen,
                        morph_limit(finer, &signed[chosen - 1], tau, allowed),
                    )
                });
            let shown = if let Some(((scratch, _), _)) = stitched {
                scratch
            } else if expected == e.full {
                vec![(0.0, e.pixels)]
            } else {
                if expected >= from {
                    patch.level(expected, diagonal);
                    seen[expected] = std::mem::take(&mut patch.scratch);
                }
                std::mem::take(&mut seen[expected])
            };
            Some((p, levels, shown, limit))
        })
        .collect();
    let mut shown: Vec<(f64, f64)> = Vec::new();
    let mut morph_limits = vec![None; grid.patch_count()];
    for (p, levels, seen, limit) in per_patch {
        errors[p * LEVEL_COUNT..(p + 1) * LEVEL_COUNT].copy_from_slice(&levels);
        shown.extend(seen);
        morph_limits[p] = limit;
    }
    // A moved silhouette's pixels are past any bound: the largest finite.
    let predicted_max_px = shown
        .iter()
        .map(|s| s.0)
        .filter(|e| e.is_finite())
        .fold(0.0f64, f64::max) as f32;
    let predicted_p99_px = weighted_percentile(&mut shown, P99_FRACTION) as f32;
    ViewErrors {
        table: ErrorTable::from_flat(errors).expect("the bound's layout, finite and not negative"),
        predicted_p99_px,
        predicted_max_px,
        morph_limits,
    }
}

/// The pixels a silhouette sweeps when it moves `moved` pixels along
/// `width` pixels, as (error, pixels): each shows the silhouette in one
/// render and the ground behind it in the other, `crest_px` apart; against
/// the sky (`crest_px` infinite), each is off by its distance to the moved
/// silhouette, spread evenly up to the whole move.
fn silhouette(moved: f64, width: f64, crest_px: f64) -> [(f64, f64); 2] {
    let swept = moved * width;
    if crest_px.is_finite() {
        [(crest_px, swept), (0.0, 0.0)]
    } else {
        [(moved, 0.5 * swept), (0.5 * moved, 0.5 * swept)]
    }
}

/// Steps of the morph factor `morph_limit` tries.
const MORPH_STEPS: usize = 16;

/// The largest morph factor, in steps of 1 / `MORPH_STEPS`, at which a
/// patch's surface blended from `finer` towards `coarser` has at most
/// `allowed` pixels over `tau`. A geomorph moves vertices vertically, so at
/// factor m each sample's signed error is the blend (1 - m) a + m b of the
/// two levels' (None: the reference itself, no error). The blend of two
/// errors within tau is within it, but one of a level far under tau and the
/// next far over it is not: a linear morph between the levels' own
/// percentiles would put every morphing patch's share at tau and many of
/// its pixels over.
fn morph_limit(finer: Option<&[Signed]>, coarser: &[Signed], tau: f64, allowed: f64) -> f32 {
    // Both levels list the same seen samples; the finer one's by sample
    // index, the reference (no error) where it is not listed.
    let finer = finer.unwrap_or_default();
    let samples = coarser.iter().chain(finer).map(|s| s.sample as usize + 1);
    let mut finer_at = vec![None; samples.max().unwrap_or(0)];
    for a in finer {
        finer_at[a.sample as usize] = Some(a);
    }
    let over = |m: f64| -> f64 {
        coarser
            .iter()
            .map(|b| {
                let a = finer_at[b.sample as usize];
                let blend = |f: fn(&Signed) -> f64| ((1.0 - m) * a.map_or(0.0, f) + m * f(b)).abs();
                let (moved, face_on) = (blend(|s| s.moved), blend(|s| s.face_on));
                let swept = silhouette(moved, b.crest_width, b.crest_px);
                let outline = silhouette(face_on, b.outline_width, f64::INFINITY);
                // Where either level's ray escapes, so may the blend's.
                let band = a.map_or(0.0, |a| a.band).max(b.band);
                let over_in = |px: f64, pixels: f64| if px > tau { pixels } else { 0.0 };
                swept
                    .iter()
                    .chain(&outline)
                    .filter(|s| s.0 > tau)
                    .map(|s| s.1)
                    .sum::<f64>()
                    + over_in(face_on, band)
                    + over_in(blend(|s| s.px), b.pixels - band)
            })
            .sum()
    };
    (0..=MORPH_STEPS)
        .rev()
        .map(|i| i as f64 / MORPH_STEPS as f64)
        .find(|&m| m == 0.0 || over(m) <= allowed * (1.0 + 1e-9))
        .unwrap_or(0.0) as f32
}

/// The viewshed out to the farthest wanted sample. Samples within a pixel
/// below their horizon count as seen: they share its pixels.
fn sweep_viewshed(
    terrain: &Terrain,
    heightmap: &Heightmap,
    view: &ViewLod,
    wanted: &[bool],
) -> Viewshed {
    let grid = terrain.grid();
    let info = terrain.info();
    let eye_grid = info.world_to_grid(
        f64::from(view.eye_local.x) + info.origin().x,
        f64::from(view.eye_local.z) + info.origin().y,
    );
    let max_ring = (0..grid.patch_count())
        .filter(|&p| wanted[p])
        .map(|p| {
            let rect = grid.sample_rect(grid.patch_id(p));
            let far =
                |lo: usize, hi: usize, e: f64| (lo as f64 - e).abs().max((hi as f64 - e).abs());
            far(rect.col0, rect.col1, eye_grid.x).max(far(rect.row0, rect.row1, eye_grid.y))
        })
        .fold(0.0f64, f64::max);
    let mut viewshed = Viewshed::default();
    if max_ring.is_finite() {
        viewshed.sweep(
            info,
            heightmap,
            view.eye_local,
            1.0 / f64::from(view.pixels_per_radian),
            max_ring.ceil() as usize + 1,
            Some(&view.frustum),
        );
    }
    viewshed
}

/// How geomip draws stitch: the patch grid whose neighbours are balanced,
/// and an estimate's pixels over tau at a level (its index) with the given
/// sides stitched to coarser neighbours.
struct Stitching<'a> {
    grid: &'a crate::terrain::grid::PatchGrid,
    over: &'a (dyn Fn(&Estimate, usize, u8) -> f64 + Sync),
}

/// Each estimate's share of its own pixels that may exceed tau: the
/// frame's `EXCEED_FRACTION` of its seen pixels (at most the viewport) is
/// handed out greedily (`greedy_levels`). Geomip draws (`stitched`) then
/// refine a patch to within one level of its neighbours, which leaves
/// fewer pixels over tau than the greedy choice spent, and draw a side
/// next to a coarser neighbour stitched, which may put more over tau: the
/// greedy budget is raised, or lowered, in steps, to the largest whose
/// balanced and stitched levels fit the frame's share. With each share,
/// the level the path is expected to draw the patch at (the greedy one,
/// refined by the balancing) and its stitched sides.
fn allocate(
    estimates: &[Estimate],
    viewport_pixels: f64,
    stitched: Option<Stitching>,
) -> Vec<(f64, usize, u8)> {
    let total: f64 = estimates.iter().map(|e| e.pixels).sum();
    // Past a full viewport of seen pixels, each counts for less.
    let scale = (viewport_pixels / total).min(1.0);
    let budget = Budget {
        modelled: EXCEED_FRACTION * scale,
        exact: P99_FRACTION * scale,
    };
    let mut levels = greedy_levels(estimates, budget);
    let mut drawn = levels.clone();
    let mut sides = vec![0u8; estimates.len()];
    if let Some(stitching) = stitched {
        let grid = stitching.grid;
        let count = LEVEL_COUNT;
        // The levels balanced to within one of their neighbours, and each
        // one's sides next to a coarser neighbour.
        let balanced = |levels: &[usize]| -> (Vec<usize>, Vec<u8>) {
            // Geomip levels count down from the finest; patches without an
            // estimate (coarsest accepted, or not drawn) constrain nothing.
            let mut geomip = vec![(count - 1) as u8; grid.patch_count()];
            for (e, &k) in estimates.iter().zip(levels) {
                geomip[e.patch] = super::geomip::level_of_index(k, count) as u8;
            }
            super::geomip::balance(&mut geomip, grid);
            estimates
                .iter()
                .map(|e| {
                    let id = grid.patch_id(e.patch);
                    let k = super::geomip::table_index(usize::from(geomip[e.patch]), count);
                    (k, super::geomip::neighbour_masks(&geomip, grid, id).0)
                })
                .unzip()
        };
        // Stitched levels measured so far, by (estimate, level, sides).
        let measured = std::sync::Mutex::new(std::collections::HashMap::new());
        // The pixels over tau of the estimates at their balanced levels,
        // stitched.
        let over = |drawn: &[usize], sides: &[u8]| -> f64 {
            (0..estimates.len())
                .into_par_iter()
                .map(|i| {
                    let (e, k, s) = (&estimates[i], drawn[i], sides[i]);
                    if s == 0 {
                        return e.over[k];
                    }
                    let known = measured
                        .lock()
                        .expect("not poisoned")
                        .get(&(i, k, s))
                        .copied();
                    let stitched_over = known.unwrap_or_else(|| {
                        let o = (stitching.over)(e, k, s);
                        measured.lock().expect("not poisoned").insert((i, k, s), o);
                        o
                    });
                    stitched_over.max(e.over[k])
                })
                .sum()
        };
        let try_factor = |factor: f64| {
            let greedy = greedy_levels(estimates, budget.scaled(factor));
            let (refined, refined_sides) = balanced(&greedy);
            let fits = over(&refined, &refined_sides) <= budget.of(estimates, &refined);
            (fits, greedy, refined, refined_sides)
        };
        let (fits, greedy, refined, refined_sides) = try_factor(1.0);
        (levels, drawn, sides) = (greedy, refined, refined_sides);
        let (raise, lower) = (
            [1.5, 2.0, 3.0, 4.0, 6.0, 8.0],
            [0.7, 0.5, 0.35, 0.25, 0.15, 0.1, 0.0],
        );
        if fits {
            for factor in raise {
                let (fits, greedy, refined, refined_sides) = try_factor(factor);
                if !fits {
                    break;
                }
                (levels, drawn, sides) = (greedy, refined, refined_sides);
            }
        } else {
            for factor in lower {
                let (fits, greedy, refined, refined_sides) = try_factor(factor);
                (levels, drawn, sides) = (greedy, refined, refined_sides);
                if fits {
                    break;
                }
            }
        }
    }
    estimates
        .iter()
        .zip(levels.iter().zip(&drawn).zip(&sides))
        .map(|(e, ((&k, &d), &s))| {
            let share = if e.pixels > 0.0 {
                e.over[k] / e.pixels
            } else {
                0.0
            };
            (share, d, s)
        })
        .collect()
}

/// The frame's share of pixels over tau, per seen pixel. A patch drawn at
/// full resolution is the reference, exact: nothing on it goes unmodelled,
/// so its pixels need no headroom and count at the whole `P99_FRACTION`.
#[derive(Clone, Copy)]
struct Budget {
    /// Per pixel of a patch drawn coarser than full resolution.
    modelled: f64,
    /// Per pixel of a patch drawn at full resolution.
    exact: f64,
}

impl Budget {
    fn scaled(self, factor: f64) -> Self {
        Budget {
            modelled: self.modelled * factor,
            exact: self.exact * factor,
        }
    }

    /// The pixels over tau allowed with each estimate at the level given.
    fn of(self, estimates: &[Estimate], levels: &[usize]) -> f64 {
        estimates
            .iter()
            .zip(levels)
            .map(|(e, &k)| self.per_pixel(e, k) * e.pixels)
            .sum()
    }

    fn per_pixel(self, e: &Estimate, k: usize) -> f64 {
        if k >= e.full {
            self.exact
        } else {
            self.modelled
        }
    }
}

/// How many of the greedy choice's largest steps are each held back in
/// turn (`greedy_levels`).
const HOLD_BACK: usize = 4;

/// Each estimate's level: from every patch at its coarsest, each step
/// takes the patch and finer level that removes the most pixels over tau
/// per triangle added (counting what a step to full resolution adds to
/// the share), until what remains over tau fits the share. A step is
/// all or nothing, so the last ones may overshoot: a patch refined to full
/// resolution for a few pixels more than the rest could give. So the
/// `HOLD_BACK` patches whose last step added the most triangles are each
/// kept one step back in turn, the others refined in their place, and the
/// fewest triangles that fit win.
fn greedy_levels(estimates: &[Estimate], budget: Budget) -> Vec<usize> {
    let first = greedy_run(estimates, budget, None);
    if !first.fits {
        return first.level;
    }
    // Each refined patch's last step.
    let mut stepped = vec![false; estimates.len()];
    let mut lumps: Vec<&(usize, usize, f64)> = first
        .steps
        .iter()
        .rev()
        .filter(|&&(i, _, _)| !std::mem::replace(&mut stepped[i], true))
        .collect();
    lumps.sort_unstable_by(|a, b| b.2.total_cmp(&a.2));
    let held = lumps
        .into_par_iter()
        .take(HOLD_BACK)
        .map(|&(i, from, _)| greedy_run(estimates, budget, Some((i, from))))
        .filter(|run| run.fits)
        .min_by(|a, b| a.triangles.total_cmp(&b.triangles));
    match held {
        Some(run) if run.triangles < first.triangles => run.level,
        _ => first.level,
    }
}

/// One greedy choice (`greedy_levels`).
struct Greedy {
    /// Per estimate, its level.
    level: Vec<usize>,
    /// Whether what remains over tau fits the share.
    fits: bool,
    /// The steps taken, in order: (estimate, level it left, triangles
    /// added).
    steps: Vec<(usize, usize, f64)>,
    /// Triangles in all.
    triangles: f64,
}

/// The greedy choice, with estimate `cap.0` held to levels no finer than
/// `cap.1` where given.
fn greedy_run(estimates: &[Estimate], budget: Budget, cap: Option<(usize, usize)>) -> Greedy {
    use std::cmp::Ordering;
    use std::collections::BinaryHeap;
    let triangles = |e: &Estimate, k: usize| {
        if k == e.full {
            e.full_triangles
        } else {
            2.0 * 4f64.powi(k as i32)
        }
    };
    let mut level = vec![0; estimates.len()];
    let mut over: f64 = estimates.iter().zip(&level).map(|(e, &k)| e.over[k]).sum();
    let mut share = budget.of(estimates, &level);
    // What a step from `from` to `k` adds to the share (a step to full
    // resolution lifts the patch's pixels to the exact rate).
    let share_added = |e: &Estimate, from: usize, k: usize| {
        (budget.per_pixel(e, k) - budget.per_pixel(e, from)) * e.pixels
    };
    // What it takes off the pixels over tau, net of that.
    let relief =
        |e: &Estimate, from: usize, k: usize| e.over[from] - e.over[k] + share_added(e, from, k);
    // The best finer level from `from`: (pixels relieved per triangle,
    // level).
    let best = |i: usize, from: usize| -> Option<(f64, usize)> {
        let e = &estimates[i];
        let finest = match cap {
            Some((held, k)) if held == i => k,
            _ => e.full,
        };
        (from + 1..=finest)
            .map(|k| (relief(e, from, k), k))
            .filter(|&(r, _)| r > 0.0)
            .map(|(r, k)| {
                let added = (triangles(e, k) - triangles(e, from)).max(1.0);
                (r / added, k)
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
    };
    #[derive(PartialEq)]
    struct Step(f64, usize, usize);
    impl Eq for Step {}
    impl PartialOrd for Step {
        fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
            Some(self.cmp(other))
        }
    }
    impl Ord for Step {
        fn cmp(&self, other: &Self) -> Ordering {
            self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
        }
    }
    let mut heap: BinaryHeap<Step> = (0..estimates.len())
        .filter_map(|i| best(i, level[i]).map(|(g, next)| Step(g, i, next)))
        .collect();
    let mut steps = Vec::new();
    while over > share {
        let Some(Step(_, i, k)) = heap.pop() else {
            break;
        };
        let e = &estimates[i];
        over -= e.over[level[i]] - e.over[k];
        share += share_added(e, level[i], k);
        steps.push((i, level[i], triangles(e, k) - triangles(e, level[i])));
        level[i] = k;
        if let Some((g, next)) = best(i, k) {
            heap.push(Step(g, i, next));
        }
    }
    let total = estimates
        .iter()
        .zip(&level)
        .map(|(e, &k)| triangles(e, k))
        .sum();
    Greedy {
        level,
        fits: over <= share,
        steps,
        triangles: total,
    }
}

/// The smallest error that at most `fraction` of the pixels of `items`
/// (error, pixels) exceed.
fn weighted_percentile(items: &mut [(f64, f64)], fraction: f64) -> f64 {
    let total: f64 = items.iter().map(|i| i.1).sum::<f64>();
    largest_within(items, fraction * total)
}

/// The smallest error that at most `allowed` pixels of `items` (error,
/// pixels) exceed.
fn largest_within(items: &mut [(f64, f64)], allowed: f64) -> f64 {
    items.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
    let mut over = 0.0;
    for &(px, pixels) in items.iter() {
        if over + pixels > allowed {
            return px;
        }
        over += pixels;
    }
    0.0
}

/// One patch's samples as the eye sees them.
struct PatchSamples<'a> {
    map: &'a Heightmap,
    rect: SampleRect,
    /// Cells across (columns) and down (rows).
    cells: (usize, usize),
    /// How the path lays a level's vertices over the patch.
    layout: Layout,
    /// The last measured level's vertex columns and rows, patch-local, in
    /// samples: the quads' sides.
    columns: Vec<f64>,
    rows: Vec<f64>,
    /// The geomip template's step at the last measured level, in samples
    /// (0 for the tessellator's layout).
    step: usize,
    /// Sides stitched to a coarser neighbour (`geomip::LEFT`, ...): the
    /// template's blocks touching them are drawn as fans
    /// (`geomip::patch_indices`). Only the template's levels of two or
    /// more segments a side are stitched.
    stitched: u8,
    /// Per sample, row-major over the rect.
    seen: Vec<Seen>,
    /// Sample spacing (dx, dz).
    spacing: DVec2,
    /// The last measured level's (error in pixels, pixels) per seen sample.
    scratch: Vec<(f64, f64)>,
    /// With `keep_signed`, the last measured level's signed errors per
    /// seen sample (only geomorphing blends two levels).
    signed: Vec<Signed>,
    keep_signed: bool,
    /// The last measured level's (error in pixels, face-on error in
    /// pixels) per sample, row-major over the rect, both signed (drawn
    /// below the reference is positive); the first is 0 where the sample
    /// shows no pixels.
    field: Vec<(f64, f64)>,
    /// The viewport's pixels per radian (K).
    pixels_per_radian: f64,
    /// The last measured level's escaping band per sample, row-major over
    /// the rect: the pixels whose rays pass over the drawn surface and
    /// never land (taking the face-on error); 0 where the sample's ray
    /// lands.
    band: Vec<f64>,
}

/// A stitched block of the geomip template (`PatchSamples::stitched_block`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Fan {
    /// Its upper-left corner, patch-local (row, column).
    corner: (usize, usize),
    /// The stitched sides it touches.
    sides: u8,
}

/// One seen sample's error at a measured level, signed (drawn above the
/// reference is negative), for blending two levels.
#[derive(Clone, Copy)]
struct Signed {
    /// Row-major index over the patch's samples.
    sample: u32,
    /// Error in pixels, signed.
    px: f64,
    /// Face-on error in pixels, signed alike, which the escaping band
    /// takes.
    face_on: f64,
    /// The sample's escaping band (`PatchSamples::band`), in pixels.
    band: f64,
    /// How far a silhouette moves (`PatchSamples::field`), signed alike.
    moved: f64,
    /// `Seen::crest_width` and `Seen::crest_px`.
    crest_width: f64,
    crest_px: f64,
    /// `Seen::outline_width`.
    outline_width: f64,
    /// The sample's pixels.
    pixels: f64,
}

/// How the eye sees one sample.
#[derive(Clone, Copy)]
struct Seen {
    /// Pixels a unit of vertical error covers face-on (K / d).
    face_on: f64,
    /// The ray's horizontal direction (x, z).
    dir: DVec2,
    /// The ray's fall `t` per unit of horizontal travel; infinite straight
    /// down.
    fall: f64,
    /// The pixels of the ground the sample stands for (see the module
    /// documentation); 0 where hidden, out of view or facing away.
    pixels: f64,
    /// Whether the sample lies beside the view, its pixels only those of
    /// the triangles meeting at it that reach into it: they show its
    /// errors, but are not counted among the frame's pixels, whose share
    /// sets how many may be over tau (`PatchSamples::pixels`).
    beside: bool,
    /// On a silhouette (`Viewshed::crest`): the pixels across the sample's
    /// cell, along which a vertical error moves the silhouette; else 0.
    crest_width: f64,
    /// On a silhouette, the error of the pixels it sweeps: the height its
    /// line of sight falls to the hidden ground's end, in pixels at the
    /// sample; infinite where the sky lies behind.
    crest_px: f64,
    /// On a silhouette, how far it rises above the horizon in front of it,
    /// in pixels: the silhouette sinks no further before nearer ground
    /// takes it over.
    crest_rise_px: f64,
    /// On the outline of the map's edge seen from outside the map
    /// (`Viewshed::edge`) and in view: the pixels across the sample's
    /// cell, along which a vertical error moves the outline against the
    /// background below it, by its face-on size either way; else 0.
    outline_width: f64,
    /// The reference's own slope along the ray.
    ground_rise: f64,
    /// Horizontal distance from the sample to the terrain's edge along the
    /// ray.
    beyond: f64,
    /// Horizontal distance from the eye.
    reach: f64,
}

/// Whether `rel` (relative to the eye) lies on the inner side of `plane`.
fn in_front(plane: glam::DVec4, rel: DVec3) -> bool {
    plane.truncate().dot(rel) + plane.w >= 0.0
}

/// The share of the box `lo`..`hi` in front of `plane` (its normal's side),
/// measured along the normal: 1 for a box wholly in front, 0 for one
/// wholly behind.
fn share_in_front(plane: glam::DVec4, lo: DVec3, hi: DVec3) -> f64 {
    let n = plane.truncate();
    let ahead = n.dot(DVec3::select(n.cmpge(DVec3::ZERO), hi, lo)) + plane.w;
    let behind = n.dot(DVec3::select(n.cmpge(DVec3::ZERO), lo, hi)) + plane.w;
    if behind >= 0.0 {
        1.0
    } else if ahead <= 0.0 {
        0.0
    } else {
        ahead / (ahead - behind)
    }
}

/// The eye-relative box of the triangles meeting at sample (`r`, `c`),
/// whose eye-relative position is `rel`: a cell either way (within the
/// map), from the lowest of the sample and its eight neighbours to the
/// highest.
fn neighbourhood_box(
    map: &Heightmap,
    r: usize,
    c: usize,
    rel: DVec3,
    spacing: DVec2,
) -> (DVec3, DVec3) {
    let (w, d) = (map.width(), map.depth());
    let (r0, r1) = (r.saturating_sub(1), (r + 1).min(d - 1));
    let (c0, c1) = (c.saturating_sub(1), (c + 1).min(w - 1));
    let here = f64::from(map.get(r, c));
    let (mut y0, mut y1) = (here, here);
    for rr in r0..=r1 {
        for cc in c0..=c1 {
            let y = f64::from(map.get(rr, cc));
            (y0, y1) = (y0.min(y), y1.max(y));
        }
    }
    // Local x grows with columns; local z falls as rows grow.
    let lo = DVec3::new(
        rel.x - (c - c0) as f64 * spacing.x,
        rel.y + (y0 - here),
        rel.z - (r1 - r) as f64 * spacing.y,
    );
    let hi = DVec3::new(
        rel.x + (c1 - c) as f64 * spacing.x,
        rel.y + (y1 - here),
        rel.z + (r - r0) as f64 * spacing.y,
    );
    (lo, hi)
}

impl<'a> PatchSamples<'a> {
    fn new(
        map: &'a Heightmap,
        rect: SampleRect,
        layout: Layout,
        info: &crate::terrain::TerrainInfo,
        view: &ViewLod,
        viewshed: &Viewshed,
    ) -> Self {
        let cells = (rect.cells_x(), rect.cells_z());
        let spacing = info.spacing();
        let eye = view.eye_local.as_dvec3();
        let k = f64::from(view.pixels_per_radian);
        let cell_area = spacing.x * spacing.y;
        // A pixel `a` radians off the view axis covers cos^3(a) / K^2
        // steradians. The axis is along the sum of the four side planes'
        // inward normals.
        let forward = view.frustum.planes[..4]
            .iter()
            .map(|p| p.truncate().as_dvec3())
            .sum::<DVec3>()
            .normalize_or_zero();
        let per_steradian = |rel: DVec3| {
            let cos = (rel.dot(forward) / rel.length()).max(0.1);
            k * k / (cos * cos * cos)
        };
        let (w, d) = (map.width(), map.depth());
        let h = |r: usize, c: usize| f64::from(map.get(r, c));
        // The terrain's horizontal extent (local x, then local z).
        let x_range = (info.local_x(0), info.local_x(w - 1));
        let z_range = (info.local_z(d - 1), info.local_z(0));
        let mut seen = Vec::with_capacity((cells.0 + 1) * (cells.1 + 1));
        for r in rect.row0..=rect.row1 {
            for c in rect.col0..=rect.col1 {
                let rel = DVec3::new(info.local_x(c), h(r, c), info.local_z(r)) - eye;
                // A sample outside the frustum or hidden shows no pixels.
                // Its exposure is already cut to the frustum's height, and
                // the ground it stands for may show while the sample itself
                // lies above or below the view: only the side planes and
                // the near plane are tested where it has one. Beside the
                // view, its error still shows on the triangles that meet at
                // it, which reach a cell either way and fall to its
                // neighbours' heights: a spike just off the side of the
                // view can fill a fifth of it. So a sample beside a side
                // plane shows the share of that box in front of the plane,
                // along its normal; those pixels carry its errors but are
                // not the frame's own (`Seen::beside`).
                let exposure = viewshed.exposure(r, c);
                let planes: &[usize] = if exposure.is_some() {
                    &[0, 1, 4]
                } else {
                    &[0, 1, 2, 3, 4]
                };
                let mut beside = false;
                let in_view: f64 = planes
                    .iter()
                    .map(|&i| {
                        let p = view.frustum.planes[i].as_dvec4();
                        if in_front(p, rel) {
                            1.0
                        } else if i >= 2 {
                            0.0
                        } else {
                            beside = true;
                            let (lo, hi) = neighbourhood_box(map, r, c, rel, spacing);
                            share_in_front(p, lo, hi)
                        }
                    })
                    .product();
                let shown = if viewshed.hidden(r, c) { 0.0 } else { in_view };
                let horizontal = DVec2::new(rel.x, rel.z);
                let reach = horizontal.length();
                let distance = rel.length().max(f64::MIN_POSITIVE);
                if reach <= 0.0 {
                    // Straight below the eye: seen face-on.
                    seen.push(Seen {
                        face_on: k / distance,
                        dir: DVec2::X,
                        fall: f64::INFINITY,
                        pixels: shown
                            * (cell_area / (distance * distance) * per_steradian(rel))
                                .min(view.viewport_pixels),
                        crest_width: 0.0,
                        crest_px: 0.0,
                        crest_rise_px: 0.0,
                        outline_width: 0.0,
                        ground_rise: 0.0,
                        beyond: 0.0,
                        reach: 0.0,
                        beside,
                    });
                    continue;
                }
                let dir = horizontal / reach;
                let fall = -rel.y / reach;
                // The reference's gradient (x, z) by central differences,
                // one-sided at the map's edges; local z falls as rows rise.
                let (c0, c1) = (c.saturating_sub(1), (c + 1).min(w - 1));
                let (r0, r1) = (r.saturating_sub(1), (r + 1).min(d - 1));
                let gx = (h(r, c1) - h(r, c0)) / ((c1 - c0) as f64 * spacing.x);
                let gz = (h(r0, c) - h(r1, c)) / ((r1 - r0) as f64 * spacing.y);
                let rise = gx * dir.x + gz * dir.y;
                let crest = viewshed.crest(r, c).filter(|_| shown > 0.0);
                // The edge's outline shows where the sample itself lies in
                // the view.
                let outline = viewshed.edge(r, c)
                    && view
                        .frustum
                        .planes
                        .iter()
                        .all(|p| in_front(p.as_dvec4(), rel));
                // The pixels across the sample's cell, along which a
                // silhouette or the edge's outline moves.
                let cell_px = spacing.min_element() * k / distance;
                let solid_angle = exposure.unwrap_or_else(|| {
                    (rise + fall).max(0.0) / ((1.0 + fall * fall).sqrt() * distance * distance)
                        * cell_area
                });
                seen.push(Seen {
                    face_on: k / distance,
                    dir,
                    fall,
                    pixels: shown * (solid_angle * per_steradian(rel)).min(view.viewport_pixels),
                    crest_width: if crest.is_some() { cell_px } else { 0.0 },
                    crest_px: crest.map_or(0.0, |crest| crest.fall * k / distance),
                    crest_rise_px: crest
                        .map_or(0.0, |crest| crest.rise * k * (1.0 + fall * fall).sqrt()),
                    outline_width: if outline { cell_px } else { 0.0 },
                    ground_rise: rise,
                    reach,
                    beside,
                    beyond: {
                        let (x, z) = (rel.x + eye.x, rel.z + eye.z);
                        let across = |p: f64, d: f64, lo: f64, hi: f64| {
                            if d > 0.0 {
                                (hi - p) / d
                            } else if d < 0.0 {
                                (lo - p) / d
                            } else {
                                f64::INFINITY
                            }
                        };
                        across(x, dir.x, x_range.0, x_range.1)
                            .min(across(z, dir.y, z_range.0, z_range.1))
                            .max(0.0)
                    },
                });
            }
        }
        PatchSamples {
            map,
            rect,
            cells,
            layout,
            columns: Vec::new(),
            rows: Vec::new(),
            step: 0,
            stitched: 0,
            seen,
            spacing,
            scratch: Vec::new(),
            signed: Vec::new(),
            keep_signed: false,
            field: Vec::new(),
            pixels_per_radian: k,
            band: Vec::new(),
        }
    }

    /// The full-resolution level's index (`Layout::full`).
    fn full(&self) -> usize {
        self.layout.full(self.cells)
    }

    /// The patch's seen pixels, those of samples beside the view apart.
    fn pixels(&self) -> f64 {
        self.seen
            .iter()
            .filter(|s| !s.beside)
            .map(|s| s.pixels)
            .sum()
    }

    /// Measures level `k` (2^k segments a side, `Layout::vertices`) into
    /// `scratch`: each seen sample's error in pixels and its pixels.
    fn level(&mut self, k: usize, diagonal: Diagonal) {
        let (cx, cz) = self.cells;
        self.columns = self.layout.vertices(k, cx);
        self.rows = self.layout.vertices(k, cz);
        self.step = self.layout.step(k);
        let stride = cx + 1;
        let (row0, col0) = (self.rect.row0 as f64, self.rect.col0 as f64);
        let at = |r: f64, c: f64| self.map.interpolate(col0 + c, row0 + r);
        self.scratch.clear();
        self.signed.clear();
        self.field.clear();
        self.field.resize(stride * (cz + 1), (0.0, 0.0));
        self.band.clear();
        self.band.resize(stride * (cz + 1), 0.0);
        let (columns, rows) = (&self.columns, &self.rows);
        for (qi, z) in rows.windows(2).enumerate() {
            let last_row = qi + 2 == rows.len();
            for (qj, x) in columns.windows(2).enumerate() {
                let last_column = qj + 2 == columns.len();
                // A upper-left, B upper-right, C lower-left, D lower-right.
                let (a, b) = (at(z[0], x[0]), at(z[0], x[1]));
                let (c, d) = (at(z[1], x[0]), at(z[1], x[1]));
                let quad = DVec2::new(
                    (x[1] - x[0]) * self.spacing.x,
                    (z[1] - z[0]) * self.spacing.y,
                );
                let diagonal_length = quad.length();
                let (inv_u, inv_v) = (1.0 / (x[1] - x[0]), 1.0 / (z[1] - z[0]));
                let fan = self.stitched_block(diagonal, qi, qj);
                // The samples in the quad; those on its right or lower side
                // belong to the next quad, except at the patch's own far
                // sides.
                let samples = |lo: f64, hi: f64, last: bool| {
                    let first = lo.ceil() as usize;
                    let end = if last {
                        hi.floor() as usize + 1
                    } else {
                        hi.ceil() as usize
                    };
                    first..end
                };
                for r in samples(z[0], z[1], last_row) {
                    let v = (r as f64 - z[0]) * inv_v;
                    for cc in samples(x[0], x[1], last_column) {
                        let u = (cc as f64 - x[0]) * inv_u;
                        let seen = self.seen[r * stride + cc];
                        let here = f64::from(self.map.get(self.rect.row0 + r, self.rect.col0 + cc));
                        let fanned = fan.and_then(|f| self.fan_at(f, r as f64, cc as f64));
                        let error = match diagonal {
                            Diagonal::Reference => {
                                here - fanned
                                    .map_or_else(|| split_reference([a, b, c, d], u, v), |(h, _)| h)
                            }
                            Diagonal::Either => {
                                let bc = here - split_reference([a, b, c, d], u, v);
                                let ad = here - split_other([a, b, c, d], u, v);
                                if ad.abs() > bc.abs() {
                                    ad
                                } else {
                                    bc
                                }
                            }
                        };
                        let delta = error.abs();
                        // The ray meets the drawn surface `delta / meet`
                        // on (or back) horizontally, `fall` times that
                        // apart vertically, within the quad's diagonal: at
                        // the quad's corners the drawn surface is the
                        // reference, which the ray sinks into. Where the
                        // ray sinks into the reference too slowly to be
                        // `delta` deep within the diagonal, it may clear
                        // the drawn surface: followed to where it lands
                        // (`landing`). A sample showing no pixels needs
                        // only its face-on error, which a silhouette in
                        // front of it reads.
                        let mut band = 0.0;
                        let px = if seen.pixels <= 0.0 {
                            0.0
                        } else if seen.fall.is_infinite() {
                            delta * seen.face_on
                        } else {
                            // The drawn quad's slope along the ray (its
                            // bilinear gradient; local z falls as rows
                            // rise) and how fast the ray closes on it.
                            let (gx, gz) = match fanned {
                                Some((_, slope)) => (slope.x, slope.y),
                                None => (
                                    ((1.0 - v) * (b - a) + v * (d - c)) / quad.x,
                                    -((1.0 - u) * (c - a) + u * (d - b)) / quad.y,
                                ),
                            };
                            let meet = gx * seen.dir.x + gz * seen.dir.y + seen.fall;
                            // The run to the drawn quad's plane by its
                            // slope here, within the diagonal; none where
                            // the drawn surface falls away as fast as the
                            // ray falls, since its slope then says nothing
                            // of where they meet.
                            let local = (meet > 0.0).then(|| (delta / meet).min(diagonal_length));
                            let sink = seen.ground_rise + seen.fall;
                            let travel = if sink <= 0.0 || delta > sink * diagonal_length {
                                match self.landing(diagonal, (r, cc), &seen, error, f64::INFINITY) {
                                    Ok(run) => run,
                                    Err(limit) => {
                                        // The ray through the sample never
                                        // lands: only the rays within its
                                        // face-on error below it pass over
                                        // the drawn surface here, a band
                                        // that many pixels tall and the
                                        // sample's width wide. Those below
                                        // meet the drawn surface in front.
                                        let face_px = delta * seen.face_on;
                                        let wide = self.spacing.min_element() * seen.face_on;
                                        band = (face_px * wide).min(seen.pixels);
                                        local.unwrap_or(diagonal_length).min(limit)
                                    }
                                }
                            } else {
                                // Without a local run the ray is followed
                                // over the drawn quads, within the diagonal.
                                local.unwrap_or_else(|| {
                                    self.landing(diagonal, (r, cc), &seen, error, diagonal_length)
                                        .unwrap_or_else(|limit| limit)
                                })
                            };
                            travel * seen.fall.abs() * seen.face_on
                        };
                        self.field[r * stride + cc] = (px.copysign(error), error * seen.face_on);
                        self.band[r * stride + cc] = band;
                    }
                }
            }
        }
        // Each seen sample's pixels take its error; its neighbours' are all
        // known now, seen or not.
        let field = &self.field;
        for r in 0..=cz {
            for c in 0..=cx {
                let i = r * stride + c;
                let seen = self.seen[i];
                if seen.pixels <= 0.0 && seen.outline_width <= 0.0 {
                    continue;
                }
                let (own, face_on) = field[i];
                // A silhouette drawn higher rises by its face-on error. One
                // drawn lower sinks by it, but no further than the ground
                // in front of it (the neighbour towards the eye), itself
                // drawn lower by its own error, then takes over.
                let moved = if seen.crest_width > 0.0 && face_on > 0.0 {
                    let (fr, fc) = (
                        r.checked_add_signed(seen.dir.y.round() as isize),
                        c.checked_add_signed(-seen.dir.x.round() as isize),
                    );
                    let front = match (fr, fc) {
                        (Some(fr), Some(fc)) if fr <= cz && fc <= cx => field[fr * stride + fc].1,
                        _ => face_on,
                    };
                    face_on
                        .min(seen.crest_rise_px + front.max(0.0))
                        .min(self.sunk_silhouette(diagonal, (r, c), &seen))
                } else {
                    face_on
                };
                // The escaping band takes the face-on error, the rest the
                // sample's own.
                let band = self.band[i];
                if band > 0.0 {
                    self.scratch.push((face_on.abs(), band));
                }
                self.scratch.push((own.abs(), seen.pixels - band));
                if self.keep_signed {
                    self.signed.push(Signed {
                        sample: i as u32,
                        px: own,
                        face_on,
                        band,
                        moved,
                        crest_width: seen.crest_width,
                        crest_px: seen.crest_px,
                        outline_width: seen.outline_width,
                        pixels: seen.pixels,
                    });
                }
                // A silhouette, and the edge's outline against the
                // background (moved by the face-on error, as against the
                // sky).
                for (moved, width, behind) in [
                    (moved.abs(), seen.crest_width, seen.crest_px),
                    (face_on.abs(), seen.outline_width, f64::INFINITY),
                ] {
                    if width > 0.0 {
                        self.scratch.extend(
                            silhouette(moved, width, behind)
                                .into_iter()
                                .filter(|s| s.1 > 0.0),
                        );
                    }
                }
            }
        }
    }

    /// How far (horizontally) the ray through sample `at` (patch-local row,
    /// column) runs from the reference to the drawn surface of the last
    /// measured level, where the ray sinks into the reference too slowly
    /// for the quad's diagonal to bound it: marched in half-cell steps over
    /// the level's quads. Drawn below the reference (`error` > 0), the ray
    /// runs on until the drawn surface rises to it; drawn above, it met the
    /// drawn surface before the sample, where that surface last rose above
    /// it. The tessellator may split a quad along either diagonal: the
    /// march takes the one that keeps the ray off the surface longer.
    /// `Ok(run)` where it meets the surface; `Err(limit)` where it does not
    /// within the limit: what puts the two points `|error|` apart
    /// vertically (the face-on error, as the bound counts it), the
    /// terrain's edge or `cap`, whichever is nearest. A ray that leaves the
    /// patch first does not meet it either, since the neighbours' levels
    /// are not known here.
    fn landing(
        &self,
        diagonal: Diagonal,
        (row, col): (usize, usize),
        seen: &Seen,
        error: f64,
        cap: f64,
    ) -> Result<f64, f64> {
        let delta = error.abs();
        let fall = seen.fall.abs().max(f64::MIN_POSITIVE);
        let limit = (delta / fall).min(seen.beyond).min(cap);
        let step = 0.5 * self.spacing.min_element();
        let steps = (limit / step).ceil().min(MAX_LANDING_STEPS) as usize;
        let below = error > 0.0;
        // Drawn below: forward, the ray above the surface until it lands.
        // Drawn above: backward, the ray below the surface until it leaves.
        let sign = if below { 1.0 } else { -1.0 };
        let here = f64::from(self.map.get(self.rect.row0 + row, self.rect.col0 + col));
        // Samples moved per unit of horizontal travel; local z falls as
        // rows rise.
        let (dc, dr) = (
            sign * seen.dir.x / self.spacing.x,
            -sign * seen.dir.y / self.spacing.y,
        );
        // The drawn surface `x` along the ray, None off the patch.
        let drawn =
            |x: f64| self.drawn_at(diagonal, below, row as f64 + x * dr, col as f64 + x * dc);
        // The ray's clearance from the drawn surface: positive while it has
        // not met it (forward) or is still under it (backward). The ray
        // rises `fall` per unit back towards the eye.
        let (mut before, mut previous) = (0.0, delta);
        for k in 1..=steps {
            let x = (k as f64 * step).min(limit);
            let surface = drawn(x).ok_or(limit)?;
            let gap = sign * (here - sign * fall * x - surface);
            if gap <= 0.0 {
                return Ok(before + (x - before) * previous / (previous - gap));
            }
            (before, previous) = (x, gap);
        }
        Err(limit)
    }

    /// The last measured level's drawn surface at patch-local (row,
    /// column), None off the patch. Where the tessellator may split a quad
    /// along either diagonal, the `lower` of the two, else the higher.
    fn drawn_at(&self, diagonal: Diagonal, lower: bool, r: f64, c: f64) -> Option<f64> {
        let (cx, cz) = (self.cells.0 as f64, self.cells.1 as f64);
        if !(0.0..=cx).contains(&c) || !(0.0..=cz).contains(&r) {
            return None;
        }
        // The quad along one axis holding `p`: the last side at or before it.
        let quad = |sides: &[f64], p: f64| {
            sides.partition_point(|&l| l <= p).clamp(1, sides.len() - 1) - 1
        };
        let (qj, qi) = (quad(&self.columns, c), quad(&self.rows, r));
        if let Some((h, _)) = self
            .stitched_block(diagonal, qi, qj)
            .and_then(|f| self.fan_at(f, r, c))
        {
            return Some(h);
        }
        let (x0, x1) = (self.columns[qj], self.columns[qj + 1]);
        let (z0, z1) = (self.rows[qi], self.rows[qi + 1]);
        let (row0, col0) = (self.rect.row0 as f64, self.rect.col0 as f64);
        let at = |r: f64, c: f64| self.map.interpolate(col0 + c, row0 + r);
        let corners = [at(z0, x0), at(z0, x1), at(z1, x0), at(z1, x1)];
        let (u, v) = ((c - x0) / (x1 - x0), (r - z0) / (z1 - z0));
        let bc = split_reference(corners, u, v);
        Some(match diagonal {
            Diagonal::Reference => bc,
            Diagonal::Either if lower => bc.min(split_other(corners, u, v)),
            Diagonal::Either => bc.max(split_other(corners, u, v)),
        })
    }

    /// The stitched block (`stitched`) of the last measured level that quad
    /// (row `qi`, column `qj`) lies in: its upper-left corner (patch-local
    /// row, column) and the stitched sides it touches. None where the quad
    /// keeps the reference's split.
    fn stitched_block(&self, diagonal: Diagonal, qi: usize, qj: usize) -> Option<Fan> {
        let Layout::Template(n) = self.layout else {
            return None;
        };
        let segments = n / self.step.max(1);
        if diagonal != Diagonal::Reference || self.stitched == 0 || segments < 2 {
            return None;
        }
        let (bi, bj) = (qi / 2, qj / 2);
        let sides = geomip::block_sides(bi, bj, segments / 2) & self.stitched;
        (sides != 0).then_some(Fan {
            corner: (2 * bi * self.step, 2 * bj * self.step),
            sides,
        })
    }

    /// A stitched block's drawn surface at patch-local (r, c), as the fan
    /// `geomip::patch_indices` draws (its vertices clamped to the patch's
    /// far sides, like the template's): the height and its slope along
    /// local x and z. None off the block.
    fn fan_at(&self, fan: Fan, r: f64, c: f64) -> Option<(f64, DVec2)> {
        let (cx, cz) = self.cells;
        let (i0, j0) = fan.corner;
        // (column, row, height) of the block vertex at offset (di, dj).
        let vertex = |(di, dj): (usize, usize)| {
            let (i, j) = ((i0 + di).min(cz), (j0 + dj).min(cx));
            let h = self.map.get(self.rect.row0 + i, self.rect.col0 + j);
            DVec3::new(j as f64, i as f64, f64::from(h))
        };
        let centre = vertex((self.step, self.step));
        // At most the eight corners and midpoints; this runs per sample and
        // per march step, so the ring stays off the heap.
        let mut ring = [DVec3::ZERO; 8];
        let mut len = 0;
        for (slot, offset) in ring.iter_mut().zip(geomip::fan_ring(self.step, fan.sides)) {
            *slot = vertex(offset);
            len += 1;
        }
        let ring = &ring[..len];
        let p = DVec2::new(c, r) - centre.truncate();
        const SLACK: f64 = 1e-9;
        (0..ring.len()).find_map(|t| {
            let (e0, e1) = (ring[t] - centre, ring[(t + 1) % ring.len()] - centre);
            let det = e0.x * e1.y - e1.x * e0.y;
            if det.abs() < SLACK {
                // Collapsed by the clamp to the far sides.
                return None;
            }
            let a = (p.x * e1.y - e1.x * p.y) / det;
            let b = (e0.x * p.y - p.x * e0.y) / det;
            if a < -SLACK || b < -SLACK || a + b > 1.0 + SLACK {
                return None;
            }
            // The plane's slope per sample (column, row), then per unit of
            // local x and z (local z falls as rows rise).
            let per_column = (e0.z * e1.y - e1.z * e0.y) / det;
            let per_row = (e0.x * e1.z - e1.x * e0.z) / det;
            Some((
                centre.z + a * e0.z + b * e1.z,
                DVec2::new(per_column / self.spacing.x, -per_row / self.spacing.y),
            ))
        })
    }

    /// How far, in pixels, a silhouette at sample (row, col) drawn lower
    /// sinks: from its own elevation down to the highest the drawn surface
    /// rises along its line of sight within the patch (the crest's own
    /// drawn point included; before and behind it other drawn points may
    /// hold the outline up). Marched in half-cell steps.
    fn sunk_silhouette(&self, diagonal: Diagonal, (row, col): (usize, usize), seen: &Seen) -> f64 {
        let here = f64::from(self.map.get(self.rect.row0 + row, self.rect.col0 + col));
        let eye_y = here + seen.fall * seen.reach;
        let (dc, dr) = (seen.dir.x / self.spacing.x, -seen.dir.y / self.spacing.y);
        let step = 0.5 * self.spacing.min_element();
        let across =
            (self.cells.0 as f64 * self.spacing.x).hypot(self.cells.1 as f64 * self.spacing.y);
        let steps = (across / step).ceil() as i64;
        let mut highest = f64::NEG_INFINITY;
        for k in -steps..=steps {
            let x = k as f64 * step;
            if seen.reach + x <= 0.5 * step {
                continue;
            }
            let Some(h) = self.drawn_at(diagonal, true, row as f64 + x * dr, col as f64 + x * dc)
            else {
                continue;
            };
            highest = highest.max((h - eye_y) / (seen.reach + x));
        }
        let drop = (-seen.fall - highest).max(0.0);
        drop * self.pixels_per_radian / (1.0 + seen.fall * seen.fall)
    }

    /// The measured level's pixels over `tau` pixels of error.
    fn over(&self, tau: f64) -> f64 {
        self.scratch.iter().filter(|s| s.0 > tau).map(|s| s.1).sum()
    }

    /// The measured level's error that at most `allowed` of its pixels
    /// exceed.
    fn percentile(&mut self, allowed: f64) -> f64 {
        // Pixels handed out as a level's pixels over tau must all get
        // through, whatever the order of the sums.
        largest_within(&mut self.scratch, allowed * (1.0 + 1e-9))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An estimate of `pixels` seen pixels and the given pixels over tau
    /// per level, the last full resolution (32 triangles).
    fn estimate(patch: usize, pixels: f64, over: [f64; 3]) -> Estimate {
        let mut all = [0.0; LEVEL_COUNT];
        all[..3].copy_from_slice(&over);
        Estimate {
            patch,
            distance: 1.0,
            pixels,
            over: all,
            from: 2,
            full: 2,
            full_triangles: 32.0,
        }
    }

    #[test]
    fn a_patch_at_full_resolution_frees_its_headroom_for_the_rest() {
        // The share starts at 1 % of the 2000 pixels (20). Refining the
        // first patch to full resolution leaves 25 over tau: within its
        // pixels' whole 2 % (20 + 10 = 30), the second patch stays coarse;
        // counted at 1 % like the rest, it must be refined too.
        let estimates = [
            estimate(0, 1000.0, [100.0, 100.0, 0.0]),
            estimate(1, 1000.0, [25.0, 0.0, 0.0]),
        ];
        let exact = Budget {
            modelled: 0.01,
            exact: 0.02,
        };
        assert_eq!(greedy_levels(&estimates, exact), [2, 0]);
        let uniform = Budget {
            modelled: 0.01,
            exact: 0.01,
        };
        assert_eq!(greedy_levels(&estimates, uniform), [2, 1]);
    }

    #[test]
    fn a_last_step_that_overshoots_is_held_back_for_a_cheaper_one() {
        // 59 over tau against a share of 55. The first patch's step to
        // full resolution (50 pixels for 30 triangles) removes the most
        // per triangle and is taken first, though the second's (9 for 6)
        // is enough on its own: held back, the choice draws 10 triangles
        // instead of 34.
        let estimates = [
            estimate(0, 1000.0, [50.0, 50.0, 0.0]),
            estimate(1, 100.0, [9.0, 0.0, 0.0]),
        ];
        let budget = Budget {
            modelled: 0.05,
            exact: 0.05,
        };
        let first = greedy_run(&estimates, budget, None);
        assert!(first.fits);
        assert_eq!(
            (first.level.as_slice(), first.triangles),
            ([2, 0].as_slice(), 34.0)
        );
        assert_eq!(greedy_levels(&estimates, budget), [0, 1]);
    }

    #[test]
    fn the_tessellator_cuts_any_side_evenly_and_the_template_clamps_to_it() {
        let tess = Layout::Tessellated;
        assert_eq!(tess.vertices(2, 16), [0.0, 4.0, 8.0, 12.0, 16.0]);
        assert_eq!(tess.vertices(2, 10), [0.0, 2.5, 5.0, 7.5, 10.0]);
        // Full resolution from the first level reaching the smaller side.
        assert_eq!(tess.full((16, 16)), 4);
        assert_eq!(tess.full((10, 16)), 4);
        assert_eq!(tess.full((16, 8)), 3);
        assert_eq!(tess.full((1, 16)), 0);
        let template = Layout::Template(16);
        assert_eq!(template.vertices(2, 16), [0.0, 4.0, 8.0, 12.0, 16.0]);
        assert_eq!(template.vertices(2, 10), [0.0, 4.0, 8.0, 10.0]);
        assert_eq!(template.vertices(0, 10), [0.0, 10.0]);
        assert_eq!(template.vertices(4, 3), [0.0, 1.0, 2.0, 3.0]);
        assert_eq!(template.full((10, 6)), 4);
    }

    #[test]
    fn both_splits_meet_the_corners_and_the_reference_split_is_the_maps() {
        let corners = [1.0, 2.0, 4.0, 8.0];
        for split in [split_reference, split_other] {
            for (u, v, h) in [
                (0.0, 0.0, 1.0),
                (1.0, 0.0, 2.0),
                (0.0, 1.0, 4.0),
                (1.0, 1.0, 8.0),
            ] {
                assert_eq!(split(corners, u, v), h);
            }
        }
        // The map's split runs from upper-right to lower-left.
        let map = Heightmap::from_heights(2, 2, vec![1.0, 2.0, 4.0, 8.0]).expect("valid size");
        for (u, v) in [(0.25, 0.25), (0.75, 0.5), (0.5, 0.5), (0.9, 0.8)] {
            assert!((split_reference(corners, u, v) - map.interpolate(u, v)).abs() < 1e-12);
        }
        assert_eq!(split_other(corners, 0.5, 0.5), 4.5);
        assert_eq!(split_reference(corners, 0.5, 0.5), 3.0);
    }

    /// A 33 x 33 unit-spaced map rising `slope` per column, with `bump`
    /// added at sample (8, 8), and its patch of rows and columns 0-16.
    fn ramp(slope: f32, bump: f32) -> Heightmap {
        Heightmap::from_fn(33, 33, |r, c| {
            slope * c as f32 + if (r, c) == (8, 8) { bump } else { 0.0 }
        })
        .expect("valid size")
    }

    /// Patch 0-16 of `map` at level `k` of `layout`, for `landing` alone.
    fn patch(map: &Heightmap, layout: Layout, k: usize) -> PatchSamples<'_> {
        let cells = (16, 16);
        PatchSamples {
            map,
            rect: SampleRect {
                row0: 0,
                row1: 16,
                col0: 0,
                col1: 16,
            },
            cells,
            layout,
            columns: layout.vertices(k, cells.0),
            rows: layout.vertices(k, cells.1),
            step: layout.step(k),
            stitched: 0,
            seen: Vec::new(),
            spacing: DVec2::ONE,
            scratch: Vec::new(),
            signed: Vec::new(),
            keep_signed: false,
            field: Vec::new(),
            pixels_per_radian: 1000.0,
            band: Vec::new(),
        }
    }

    #[test]
    fn stitched_sides_are_measured_on_the_fans_the_geomip_path_draws() {
        // Rough heights, so that every triangulation differs.
        let map = Heightmap::from_fn(33, 33, |r, c| ((r * 7 + c * 13) % 11) as f32 * 3.0)
            .expect("valid size");
        let n = 16;
        for cells in [(16, 16), (13, 10)] {
            for k in 1..=4 {
                for sides in 1..16u8 {
                    let mut patch = patch(&map, Layout::Template(n), k);
                    patch.cells = cells;
                    patch.rect.col1 = cells.0;
                    patch.rect.row1 = cells.1;
                    patch.columns = patch.layout.vertices(k, cells.0);
                    patch.rows = patch.layout.vertices(k, cells.1);
                    patch.stitched = sides;
                    // The index list's triangles, the template clamped to
                    // the patch as the vertex shader clamps it.
                    let level = geomip::level_of_index(k, geomip::level_count(n));
                    let corner = |v: u32| {
                        let (i, j) = (v as usize / (n + 1), v as usize % (n + 1));
                        let (i, j) = (i.min(cells.1), j.min(cells.0));
                        DVec3::new(j as f64, i as f64, f64::from(map.get(i, j)))
                    };
                    let triangles: Vec<[DVec3; 3]> = geomip::patch_indices(n, level, sides)
                        .chunks(3)
                        .map(|t| [corner(t[0]), corner(t[1]), corner(t[2])])
                        .collect();
                    let drawn = |r: f64, c: f64| {
                        triangles.iter().find_map(|[a, b, t]| {
                            let (e0, e1) = (*b - *a, *t - *a);
                            let det = e0.x * e1.y - e1.x * e0.y;
                            let p = DVec2::new(c - a.x, r - a.y);
                            let u = (p.x * e1.y - e1.x * p.y) / det;
                            let v = (e0.x * p.y - p.x * e0.y) / det;
                            (det.abs() > 1e-9 && u >= -1e-9 && v >= -1e-9 && u + v <= 1.0 + 1e-9)
                                .then_some(a.z + u * e0.z + v * e1.z)
                        })
                    };
                    for r in 0..=2 * cells.1 {
                        for c in 0..=2 * cells.0 {
                            let (r, c) = (0.5 * r as f64, 0.5 * c as f64);
                            let want = drawn(r, c).expect("the triangles cover the patch");
                            let got = patch
                                .drawn_at(Diagonal::Reference, false, r, c)
                                .expect("on the patch");
                            assert!(
                                (got - want).abs() < 1e-9,
                                "cells {cells:?} level {k} sides {sides}: at ({r}, {c}) {got} != {want}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// A sample seen along +x, falling `fall` per unit.
    fn along_x(fall: f64, beyond: f64) -> Seen {
        Seen {
            face_on: 1.0,
            dir: DVec2::X,
            fall,
            pixels: 1.0,
            crest_width: 0.0,
            crest_px: 0.0,
            crest_rise_px: 0.0,
            outline_width: 0.0,
            ground_rise: 0.0,
            beyond,
            reach: 20.0,
            beside: false,
        }
    }

    #[test]
    fn a_skimming_ray_lands_where_the_drawn_ramp_rises_to_it() {
        // The coarsest level draws the ramp without the bump: the ray over
        // the bump's top falls 0.05 a unit onto ground rising 0.1, so
        // drawn 3 below the reference it would run 3 / 0.15 = 20 on, past
        // the patch's far side (8 + 20 > 16): it never lands, and runs as
        // far as face-on.
        let map = ramp(0.1, 3.0);
        let far = |diagonal, layout| {
            let p = patch(&map, layout, 0);
            p.landing(diagonal, (8, 8), &along_x(0.05, 100.0), 3.0, f64::INFINITY)
        };
        for diagonal in [Diagonal::Reference, Diagonal::Either] {
            for layout in [Layout::Tessellated, Layout::Template(16)] {
                assert_eq!(
                    far(diagonal, layout),
                    Err(3.0 / 0.05),
                    "{diagonal:?} {layout:?}"
                );
                // Rising 0.4 a unit it lands within the patch, 6 on.
                let steep = ramp(0.4, 3.0);
                let p = patch(&steep, layout, 0);
                let run = p.landing(diagonal, (8, 8), &along_x(0.1, 100.0), 3.0, f64::INFINITY);
                // Heights are f32: the ramp is straight to rounding.
                let run = run.expect("lands");
                assert!((run - 6.0).abs() < 1e-5, "{diagonal:?} {layout:?}: {run}");
                // A pit drawn 3 above: the ray met the drawn ramp 6 before.
                let pit = ramp(0.4, -3.0);
                let p = patch(&pit, layout, 0);
                let run = p.landing(diagonal, (8, 8), &along_x(0.1, 100.0), -3.0, f64::INFINITY);
                let run = run.expect("lands");
                assert!((run - 6.0).abs() < 1e-5, "{diagonal:?} {layout:?}: {run}");
                // Capped, it stops at the cap.
                let p = patch(&map, layout, 0);
                let capped = p.landing(diagonal, (8, 8), &along_x(0.05, 100.0), 3.0, 2.5);
                assert_eq!(capped, Err(2.5), "{diagonal:?} {layout:?}");
            }
        }
        // Never past the terrain's edge.
        let p = patch(&map, Layout::Tessellated, 0);
        assert_eq!(
            p.landing(
                Diagonal::Either,
                (8, 8),
                &along_x(0.05, 5.0),
                3.0,
                f64::INFINITY
            ),
            Err(5.0)
        );
    }

    /// `patch` with every sample seen along `seen`.
    fn seen_patch<'a>(map: &'a Heightmap, layout: Layout, seen: Seen) -> PatchSamples<'a> {
        let mut p = patch(map, layout, 0);
        p.seen = vec![seen; 17 * 17];
        p
    }

    #[test]
    fn ground_drawn_exactly_shows_no_error_however_it_falls_away() {
        // A plane falling 0.1 a unit away from the eye, seen falling only
        // 0.05: the ray never meets the drawn surface near the sample, but
        // every level draws the plane exactly, so no pixel is off.
        let map = ramp(-0.1, 0.0);
        for diagonal in [Diagonal::Reference, Diagonal::Either] {
            for layout in [Layout::Tessellated, Layout::Template(16)] {
                let mut p = seen_patch(&map, layout, along_x(0.05, 100.0));
                for k in 0..=p.full() {
                    p.level(k, diagonal);
                    let worst = p.scratch.iter().map(|s| s.0).fold(0.0f64, f64::max);
                    // Heights are f32: the plane is flat to rounding.
                    assert!(worst < 1e-5, "{diagonal:?} {layout:?} level {k}: {worst}");
                    assert_eq!(p.pixels(), 17.0 * 17.0);
                }
            }
        }
    }

    #[test]
    fn only_a_band_of_an_escaping_sample_takes_its_face_on_error() {
        // A bump 3 high on flat ground, seen rising 0.01 a unit: drawn
        // without it (level 0), the ray through its top never lands. Of
        // its 10 pixels, the band 3 px tall (3 units face-on at 1 px a
        // unit) and 1 px wide (one unit of spacing) takes 3 px; the other
        // 7 meet the drawn ground within the quad's diagonal, rising 0.01
        // a unit: 16 sqrt(2) x 0.01 px.
        let map = ramp(0.0, 3.0);
        let mut p = seen_patch(&map, Layout::Tessellated, along_x(-0.01, 100.0));
        p.seen[8 * 17 + 8].pixels = 10.0;
        p.level(0, Diagonal::Reference);
        let near = 16.0 * 2f64.sqrt() * 0.01;
        let off: Vec<(f64, f64)> = p.scratch.iter().copied().filter(|s| s.0 > 1e-9).collect();
        assert_eq!(off.len(), 2, "{off:?}");
        assert!(
            (off[0].0 - 3.0).abs() < 1e-6 && (off[0].1 - 3.0).abs() < 1e-6,
            "{off:?}"
        );
        assert!(
            (off[1].0 - near).abs() < 1e-6 && (off[1].1 - 7.0).abs() < 1e-9,
            "{off:?}"
        );
        // A sample with fewer pixels than the band gives them all.
        p.seen[8 * 17 + 8].pixels = 2.0;
        p.level(0, Diagonal::Reference);
        let off: Vec<(f64, f64)> = p
            .scratch
            .iter()
            .copied()
            .filter(|s| s.1 > 0.0 && s.0 > 1e-9)
            .collect();
        assert_eq!(off.len(), 1, "{off:?}");
        assert!(
            (off[0].0 - 3.0).abs() < 1e-6 && (off[0].1 - 2.0).abs() < 1e-9,
            "{off:?}"
        );
    }

    #[test]
    fn a_sunk_silhouette_stops_where_a_drawn_vertex_in_front_holds_it() {
        // Along row 8: a crest 3.2 high at column 9, seen rising 0.01 from
        // 20 away at height 3, and a sample 3 high at column 8 in front.
        // Level 2 has vertices on columns 0, 4, 8, 12 and 16: the crest is
        // drawn 0.95 lower, but the vertex at column 8 keeps the outline
        // at elevation 0, 0.01 below the crest's.
        let map = Heightmap::from_fn(33, 33, |r, c| match (r, c) {
            (8, 8) => 3.0,
            (8, 9) => 3.2,
            _ => 0.0,
        })
        .expect("valid size");
        for diagonal in [Diagonal::Reference, Diagonal::Either] {
            let p = patch(&map, Layout::Tessellated, 2);
            let sunk = p.sunk_silhouette(diagonal, (8, 9), &along_x(-0.01, 100.0));
            // f32 heights: 3.2 is 3.2 to 1e-7.
            assert!(
                (sunk - 0.01 * 1000.0 / 1.0001).abs() < 1e-3,
                "{diagonal:?}: {sunk}"
            );
        }
        // With nothing in front it sinks to the highest drawn point along
        // its line of sight within the patch: flat ground at 0, highest in
        // elevation at the patch's far side, 7 columns on (-3 / 27).
        let lone = Heightmap::from_fn(33, 33, |r, c| if (r, c) == (8, 9) { 3.2 } else { 0.0 })
            .expect("valid size");
        let p = patch(&lone, Layout::Tessellated, 2);
        let sunk = p.sunk_silhouette(Diagonal::Reference, (8, 9), &along_x(-0.01, 100.0));
        let highest = -3.0 / 27.0;
        assert!(
            (sunk - (0.01 - highest) * 1000.0 / 1.0001).abs() < 1e-2,
            "{sunk}"
        );
    }
}
