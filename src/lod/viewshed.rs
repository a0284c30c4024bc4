//! Which heightmap samples the eye can see over the terrain in front of
//! them: a viewshed, swept outwards from the eye in square rings (Franklin
//! and Ray's XDraw).
//!
//! Every sample carries the horizon behind it: the steepest elevation
//! (height above the eye over horizontal distance) of any terrain between
//! it and the eye. A sample on ring k (Chebyshev distance k from the eye's
//! nearest grid point) takes its horizon from the two samples of ring k-1
//! its line of sight passes between, and passes on the larger of that
//! horizon and its own elevation. The sweep takes the lower of the two
//! (XDraw interpolates): a sample is only called hidden when the terrain on
//! both sides of its line of sight hides it, so a gap in a ridge or a lone
//! peak never hides what lies behind it. A sample also counts as seen when
//! it lies within `margin` radians below its horizon, so a drawn occluder
//! that sits that much lower than the reference cannot uncover it.
//!
//! Outside the heightmap there is no terrain; an eye outside it sweeps
//! from its nearest grid point beyond the edge.
//!
//! The sweep also measures what each sample shows. Its exposure is the
//! solid angle its ring step adds to the view: the sample's wedge of
//! azimuth times the rise, in sine of elevation, from the horizon
//! interpolated along its line of sight (not the lower one) to the sample,
//! within the frustum's lower and upper planes when one is given. Along a
//! line of sight the rises add up to the ground seen, so partly hidden
//! ground counts only what shows. A seen sample that hides the next one
//! behind it is a crest (or, where that sample lies below its own horizon,
//! seen only within the margin, the sample that set the horizon: the
//! outline is there); it records how far its line of sight falls to the
//! first sample that shows again behind the hidden run (the sample whose
//! elevation set the hidden run's horizon is followed along the sweep), or
//! that none does. Where the run goes on under another sample's horizon
//! (a neighbour on the same ridge), or past the last ring swept, the
//! crest's own line of sight is followed over the surface to where it
//! meets the ground, or leaves the map (sky).
//!
//! Seen from outside the map, the samples of its edge towards the eye have
//! no ground in front of them: their steps rise from nothing, and add no
//! exposure. Below them on screen lies the background, not nearer ground,
//! so each is on the outline of the map's edge (`edge`), which a drawn
//! surface lying lower or higher moves against the background.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::terrain::camera::Frustum;
use crate::terrain::heightmap::Heightmap;
use crate::terrain::TerrainInfo;

/// A silhouette sample (`Viewshed::crest`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crest {
    /// The height its line of sight falls (or rises) from it to where the
    /// hidden ground behind it ends; infinite where it never does (sky).
    pub fall: f64,
    /// The rise, in sine of elevation, from the horizon in front of it to
    /// the sample: as far as the silhouette can sink before nearer ground
    /// takes it over.
    pub rise: f64,
}

/// The samples hidden from one eye.
#[derive(Clone, Debug, Default)]
pub struct Viewshed {
    cols: usize,
    /// Per sample, row-major: hidden behind nearer terrain.
    hidden: Vec<bool>,
    /// Per sample: NaN unless it is seen with ground right behind it hidden
    /// (a silhouette); else the height its line of sight falls (or rises)
    /// from it to where that hidden ground ends, infinite where it never
    /// does (sky).
    /// With it, per sample, the rise in sine of elevation from the horizon
    /// behind it to the sample (0 where it does not rise above it).
    crest: Vec<[f32; 2]>,
    /// Per sample: the solid angle, in steradians, of the ground its ring
    /// step raises the horizon by (see `exposure`); NaN where not swept.
    exposure: Vec<f32>,
    /// Per sample: on the outline of the map's edge (`edge`).
    edge: Vec<bool>,
}

/// What a swept sample passes on to the next ring: the horizons (the
/// lower of the two behind it and its own elevation, which samples it
/// hides; the two interpolated along the line of sight, which its
/// exposure rises from), the sample whose elevation sets the lower one,
/// and whether it is hidden.
#[derive(Clone, Copy, Debug)]
struct Slot {
    horizon: [f32; 2],
    source: u32,
    hidden: bool,
}

impl Slot {
    /// A ring cell outside the heightmap: no terrain, no horizon.
    const OUTSIDE: Slot = Slot {
        horizon: [f32::NEG_INFINITY; 2],
        source: u32::MAX,
        hidden: false,
    };
}

/// The place of the cell (dc, dr) from the eye's grid point in ring k's
/// 8k cells (1 for the point itself): the top row left to right, the
/// bottom row, then the left and right columns between them.
fn ring_slot(dc: i64, dr: i64, k: i64) -> usize {
    let slot = if k == 0 {
        0
    } else if dr == -k {
        dc + k
    } else if dr == k {
        3 * k + 1 + dc
    } else if dc == -k {
        5 * k + 1 + dr
    } else {
        7 * k + dr
    };
    debug_assert!(
        (dc.abs().max(dr.abs()) == k) && (0..(8 * k).max(1)).contains(&slot),
        "({dc}, {dr}) is not on ring {k}"
    );
    slot as usize
}

/// How far the line of sight from `eye` (local) over sample (row, col)
/// falls (or rises) from it to where it meets the terrain behind it,
/// marched in half-cell steps over the interpolated surface; None where it
/// leaves the heightmap or climbs above `highest` first (sky).
fn line_of_sight_fall(
    info: &TerrainInfo,
    map: &Heightmap,
    eye: DVec3,
    (row, col): (usize, usize),
    highest: f32,
) -> Option<f32> {
    let height = f64::from(map.get(row, col));
    let (dx, dz) = (info.local_x(col) - eye.x, info.local_z(row) - eye.z);
    let reach = dx.hypot(dz);
    if reach <= 0.0 {
        return None;
    }
    // Per unit of horizontal travel: the line's rise, and the grid's
    // columns and rows (local z falls as rows rise).
    let rise = (height - eye.y) / reach;
    let spacing = info.spacing();
    let (dc, dr) = (dx / reach / spacing.x, -dz / reach / spacing.y);
    let step = 0.5 * spacing.min_element();
    let (last_col, last_row) = ((map.width() - 1) as f64, (map.depth() - 1) as f64);
    let mut travel = step;
    // The line's height over the ground at the last step (the crest
    // itself: 0).
    let mut clear = (0.0, height);
    loop {
        let mut line = height + rise * travel;
        if line > f64::from(highest) {
            if rise >= 0.0 {
                return None;
            }
            // Nothing to meet until the line falls to the highest sample.
            travel = (f64::from(highest) - height) / rise;
            line = f64::from(highest);
        }
        let (c, r) = (col as f64 + dc * travel, row as f64 + dr * travel);
        if !(0.0..=last_col).contains(&c) || !(0.0..=last_row).contains(&r) {
            return None;
        }
        let over = line - map.interpolate(c, r);
        if over <= 0.0 {
            // Where the line meets the ground between the two steps.
            let (last_over, last_line) = clear;
            let t = if last_over > over {
                last_over / (last_over - over)
            } else {
                1.0
            };
            let meets = last_line + (line - last_line) * t;
            return Some((height - meets).abs() as f32);
        }
        clear = (over, line);
        travel += step;
    }
}

impl Viewshed {
    /// Sweeps the viewshed of `eye_local` (relative to the terrain's
    /// centre) out to Chebyshev ring `max_ring` around it; samples past it
    /// count as seen.
    pub fn sweep(
        &mut self,
        info: &TerrainInfo,
        map: &Heightmap,
        eye_local: Vec3,
        margin: f64,
        max_ring: usize,
        frustum: Option<&Frustum>,
    ) {
        let (cols, rows) = (map.width(), map.depth());
        self.cols = cols;
        self.hidden.clear();
        self.hidden.resize(cols * rows, false);
        self.crest.clear();
        self.crest.resize(cols * rows, [f32::NAN, 0.0]);
        self.exposure.clear();
        self.exposure.resize(cols * rows, f32::NAN);
        self.edge.clear();
        self.edge.resize(cols * rows, false);
        // The sample whose elevation sets each sample's lower horizon, and
        // per such sample the largest height its line of sight falls or
        // rises to where the ground it hides ends (NaN: none yet).
        let mut source: Vec<u32> = (0..(cols * rows) as u32).collect();
        let mut landing = vec![f32::NAN; cols * rows];
        let eye = eye_local.as_dvec3();
        // The eye in grid units (column, row), and its nearest grid point.
        let origin = info.origin();
        let eye_grid = info.world_to_grid(eye.x + origin.x, eye.z + origin.y);
        if !eye_grid.is_finite() {
            return;
        }
        let (ec, er) = (eye_grid.x.round(), eye_grid.y.round());
        // Rings that reach the heightmap at all.
        let reach = |e: f64, n: usize| (e.abs().max((e - (n - 1) as f64).abs())) as usize;
        let last = reach(ec, cols).max(reach(er, rows)).min(max_ring);
        let inside =
            |c: i64, r: i64| c >= 0 && r >= 0 && (c as usize) < cols && (r as usize) < rows;
        // The sine of the angle above the horizontal of an elevation.
        let sine = |e: f64| {
            if e.is_finite() {
                e / e.hypot(1.0)
            } else {
                e.signum()
            }
        };
        let spacing = info.spacing();
        // The frustum's lower and upper planes (through the eye) bound the
        // sine of elevation seen along a horizontal direction.
        let vertical: Vec<glam::DVec4> = frustum
            .map(|f| f.planes[2..4].iter().map(|p| p.as_dvec4()).collect())
            .unwrap_or_default();
        // (x, z) the horizontal offset from the eye, `reach` its length.
        let in_view = |x: f64, z: f64, reach: f64| {
            let (mut lo, mut hi) = (-1.0f64, 1.0f64);
            for p in &vertical {
                // Seen where p.xz . (x, z) cos(e) + p.y sin(e) >= 0 (x, z
                // the unit direction).
                let a = (p.x * x + p.z * z) / reach;
                if p.y > 0.0 {
                    lo = lo.max(sine(-a / p.y));
                } else if p.y < 0.0 {
                    hi = hi.min(sine(-a / p.y));
                } else if a < 0.0 {
                    hi = -1.0;
                }
            }
            (lo, hi)
        };
        let (ec, er) = (ec as i64, er as i64);
        // What the last ring passes on to this one and this one to the
        // next, in ring order (`ring_slot`): each ring reads only the one
        // before it, kept together rather than spread over as many rows.
        let mut previous: Vec<Slot> = Vec::new();
        let mut current = vec![Slot::OUTSIDE];
        if inside(ec, er) {
            let i = er as usize * cols + ec as usize;
            // The eye's own grid point lies (nearly) straight below or
            // above it: it hides nothing, and the first ring rises from
            // straight down.
            current[0] = Slot {
                horizon: [f32::MIN; 2],
                source: i as u32,
                hidden: false,
            };
            self.exposure[i] = 0.0;
        }
        for k in 1..=last as i64 {
            std::mem::swap(&mut previous, &mut current);
            current.clear();
            current.resize(8 * k as usize, Slot::OUTSIDE);
            // The ring's cells within the heightmap: rows er-k..=er+k,
            // columns ec-k..=ec+k, on its border.
            let (r_lo, r_hi) = ((er - k).max(0), (er + k).min(rows as i64 - 1));
            let (c_lo, c_hi) = ((ec - k).max(0), (ec + k).min(cols as i64 - 1));
            if r_lo > r_hi || c_lo > c_hi {
                continue;
            }
            for r in r_lo..=r_hi {
                let on_side = (r - er).abs() == k;
                let step = if on_side { 1 } else { (2 * k).max(1) as usize };
                let mut c = if on_side { c_lo } else { ec - k };
                while c <= c_hi {
                    if c >= c_lo {
                        let (dc, dr) = (c - ec, r - er);
                        // The two cells of ring k-1 the line of sight
                        // passes between, and how far it lies from the
                        // first towards the second.
                        let (a, b, f) = if dc.abs() == dr.abs() {
                            let p = (c - dc.signum(), r - dr.signum());
                            (p, p, 0.0)
                        } else if dc.abs() > dr.abs() {
                            let cc = c - dc.signum();
                            let t = dr as f64 * (k - 1) as f64 / k as f64 + er as f64;
                            ((cc, t.floor() as i64), (cc, t.ceil() as i64), t.fract())
                        } else {
                            let rr = r - dr.signum();
                            let t = dc as f64 * (k - 1) as f64 / k as f64 + ec as f64;
                            ((t.floor() as i64, rr), (t.ceil() as i64, rr), t.fract())
                        };
                        let slot =
                            |(pc, pr): (i64, i64)| previous[ring_slot(pc - ec, pr - er, k - 1)];
                        let (sa, sb) = (slot(a), slot(b));
                        let (ha, hb) = (sa.horizon, sb.horizon);
                        let behind = ha[0].min(hb[0]);
                        // The predecessor whose horizon is the lower one.
                        let lower = if hb[0] < ha[0] { sb } else { sa };
                        // Interpolated. Where either cell lies outside the
                        // map, the line of sight crosses ring k-1 outside
                        // it (the cell inside is on the map's edge, and the
                        // crossing lies beyond it): no ground in front.
                        // Taking the cell inside instead would carry the
                        // edge's horizon along the edge from cell to cell,
                        // over ground no line of sight to this sample
                        // crosses.
                        let line = if ha[1] == f32::NEG_INFINITY || hb[1] == f32::NEG_INFINITY {
                            f32::NEG_INFINITY
                        } else {
                            ha[1] + (hb[1] - ha[1]) * f.abs() as f32
                        };
                        let i = r as usize * cols + c as usize;
                        // The sample's offset from the eye, and its height
                        // above the eye over its horizontal distance.
                        let (dx, dz) = (
                            info.local_x(c as usize) - eye.x,
                            info.local_z(r as usize) - eye.z,
                        );
                        let reach_squared = dx * dx + dz * dz;
                        let reach = reach_squared.sqrt().max(f64::MIN_POSITIVE);
                        let elevation =
                            (f64::from(map.get(r as usize, c as usize)) - eye.y) / reach;
                        let hidden = elevation + margin < f64::from(behind);
                        self.hidden[i] = hidden;
                        if lower.source != Slot::OUTSIDE.source {
                            if f64::from(behind) > elevation {
                                source[i] = lower.source;
                            }
                            if !hidden && lower.hidden {
                                // The hidden run behind the source ends here.
                                let s = lower.source as usize;
                                let fall = (map.get(s / cols, s % cols)
                                    - map.get(r as usize, c as usize))
                                .abs();
                                landing[s] = landing[s].max(fall);
                            }
                        }
                        current[ring_slot(dc, dr, k)] = Slot {
                            horizon: [behind.max(elevation as f32), line.max(elevation as f32)],
                            source: source[i],
                            hidden,
                        };
                        // The ring step's wedge of azimuth: the sample's
                        // width across the line of sight over its distance
                        // (a ring's corner shares both sides' halves).
                        let (x, z) = (dx.abs(), dz.abs());
                        let wedge = if dc.abs() == dr.abs() {
                            0.5 * (spacing.y * x + spacing.x * z)
                        } else if dc.abs() > dr.abs() {
                            spacing.y * x
                        } else {
                            spacing.x * z
                        } / reach_squared.max(f64::MIN_POSITIVE);
                        // Nothing before the map's edge: no step to raise.
                        // Only the part of the step within the frustum's
                        // height counts.
                        let (rise, crest_rise) = if line == f32::NEG_INFINITY {
                            // The map's edge, seen from outside it.
                            self.edge[i] = true;
                            (0.0, 0.0)
                        } else {
                            let (lo, hi) = in_view(dx, dz, reach);
                            let (top, bottom) = (sine(elevation), sine(f64::from(line)));
                            (
                                (top.min(hi) - bottom.max(lo)).max(0.0),
                                (top - bottom).max(0.0),
                            )
                        };
                        self.exposure[i] = (wedge * rise) as f32;
                        self.crest[i][1] = crest_rise as f32;
                        if hidden {
                            // What hides it and is itself seen is a crest:
                            // the sample in front, or, where that one lies
                            // below its own horizon (seen only within the
                            // margin), the sample that set the horizon,
                            // which is where the outline shows.
                            for ((pc, pr), p) in [(a, sa), (b, sb)] {
                                if inside(pc, pr) && !p.hidden {
                                    let j = pr as usize * cols + pc as usize;
                                    let j = if self.crest[j][1] > 0.0 {
                                        j
                                    } else {
                                        source[j] as usize
                                    };
                                    self.crest[j][0] = 0.0;
                                }
                            }
                        }
                    }
                    c += step as i64;
                }
            }
        }
        // A crest whose source's hidden run did not end within the sweep
        // (the run went on under another source's horizon, or past the
        // last ring) is followed along its line of sight instead.
        let highest = map.min_max().1;
        self.crest
            .par_iter_mut()
            .zip(source.par_iter())
            .enumerate()
            .filter(|(_, ([crest, _], _))| !crest.is_nan())
            .for_each(|(i, ([crest, _], &s))| {
                let fall = landing[s as usize];
                *crest = if fall.is_nan() {
                    line_of_sight_fall(info, map, eye, (i / cols, i % cols), highest)
                        .unwrap_or(f32::INFINITY)
                } else {
                    fall
                };
            });
    }

    /// Whether sample (row, col) is seen with ground right behind it
    /// hidden: a silhouette, which a drawn surface lying lower or higher
    /// moves, uncovering or covering what is behind; if so, how far the
    /// silhouette can move and what the moved pixels show (`Crest`).
    pub fn crest(&self, row: usize, col: usize) -> Option<Crest> {
        self.crest
            .get(row * self.cols + col)
            .filter(|[fall, _]| !fall.is_nan())
            .map(|&[fall, rise]| Crest {
                fall: f64::from(fall),
                rise: f64::from(rise),
            })
    }

    /// The solid angle, in steradians, that sample (row, col) adds to the
    /// view: its wedge of azimuth (its width across the line of sight over
    /// its distance) times the rise, in sine of elevation, from the horizon
    /// behind it to the sample. Summed over the samples this is the ground
    /// the eye sees, each part counted once: ground a nearer ridge hides,
    /// wholly or in part, adds only what shows above it, and ground facing
    /// away adds nothing. None where the sweep did not reach.
    pub fn exposure(&self, row: usize, col: usize) -> Option<f64> {
        self.exposure
            .get(row * self.cols + col)
            .filter(|e| !e.is_nan())
            .map(|&e| f64::from(e))
    }

    /// Whether sample (row, col), seen from outside the map, lies on its
    /// edge towards the eye with no ground in front of it: the background
    /// lies below it on screen, and its height places the outline of the
    /// map's edge there. Such a sample adds no exposure (its step rises
    /// from nothing) and hides nothing in front of it.
    pub fn edge(&self, row: usize, col: usize) -> bool {
        self.edge
            .get(row * self.cols + col)
            .copied()
            .unwrap_or(false)
    }

    /// Whether sample (row, col) is hidden.
    pub fn hidden(&self, row: usize, col: usize) -> bool {
        self.hidden
            .get(row * self.cols + col)
            .copied()
            .unwrap_or(false)
    }
}
