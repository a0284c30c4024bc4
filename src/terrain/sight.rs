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
//! seen at the angle between the ray and the reference there: `(r + t)
//! cos(angle of depression)` pixels per unit area times `K^2 / d^2`, with
//! `r` the reference's rise along the ray; none where it faces away. A
//! level's error over the patch is then a distribution over its pixels.
//!
//! **The table.** For each direction of a lattice (`AZIMUTHS` horizontal
//! directions times the `SLOPES` a ray may fall) and each level of a
//! full-size patch (one whose levels' vertices are samples), the table
//! keeps the errors that `FRACTIONS` of the patch's pixels exceed, and the
//! patch's pixel area per `K^2 / d^2`. A frame reads the directions its
//! view of the patch spans and the fraction of pixels over its tolerance
//! at each level (`over_fraction`). The far remainders (narrower patches)
//! have no entry: their levels' vertices fall between samples, and the
//! level choice keeps their error bound.
//!
//! Hidden ground and silhouettes are not modelled: a patch behind a ridge
//! counts its pixels as if seen, and a moved silhouette's pixels are not
//! counted at all.
//!
//! Errors are stored as one byte each, on a log scale below the patch's
//! largest (`CODES_PER_OCTAVE` to an octave), rounded up.

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
pub const FRACTION_EXPONENTS: [i32; 8] = [i32::MIN, -12, -10, -8, -6, -4, -2, 0];
const FRACTIONS: usize = FRACTION_EXPONENTS.len();
/// Levels with an entry: those below the largest patch's cell count.
pub const LEVELS: usize = LEVEL_COUNT - 1;
/// Steps of the stored error's log scale per octave.
pub const CODES_PER_OCTAVE: f32 = 16.0;
/// The code of an error of zero.
const ZERO: u8 = u8::MAX;

/// The lattice's horizontal direction `a` as (x, z).
pub fn azimuth(a: usize) -> [f32; 2] {
    let phi = std::f32::consts::TAU * a as f32 / AZIMUTHS as f32;
    [phi.cos(), phi.sin()]
}

/// One patch's entry.
#[derive(Clone, Debug, PartialEq)]
struct PatchSight {
    /// The largest stored error: code 0.
    scale: f32,
    /// Pixel area per `K^2 / d^2` from each direction.
    area: [f32; DIRECTIONS],
    /// [level][direction][fraction] codes.
    codes: Vec<u8>,
}

/// Every full-size patch's view model (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct SightTable {
    patches: Vec<Option<PatchSight>>,
}

/// A direction within the lattice: two neighbouring azimuths and two
/// neighbouring slopes, with the weights that interpolate between them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LatticePoint {
    pub azimuths: [usize; 2],
    pub azimuth_weight: f32,
    pub slopes: [usize; 2],
    pub slope_weight: f32,
}

impl LatticePoint {
    /// The lattice point of horizontal direction `(x, z)` (any length) and
    /// fall `t`, clamped to the lattice's slopes.
    pub fn new(x: f32, z: f32, t: f32) -> Self {
        let phi = z.atan2(x).rem_euclid(std::f32::consts::TAU);
        let a = phi / std::f32::consts::TAU * AZIMUTHS as f32;
        let a0 = (a.floor() as usize).min(AZIMUTHS - 1);
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
            azimuths: [a0, (a0 + 1) % AZIMUTHS],
            azimuth_weight: (a - a0 as f32).clamp(0.0, 1.0),
            slopes: [s0, s0 + 1],
            slope_weight,
        }
    }

    /// The four lattice directions and their weights.
    fn corners(&self) -> [(usize, f32); 4] {
        let (wa, ws) = (self.azimuth_weight, self.slope_weight);
        let d = |a: usize, s: usize| self.azimuths[a] * SLOPES.len() + self.slopes[s];
        [
            (d(0, 0), (1.0 - wa) * (1.0 - ws)),
            (d(0, 1), (1.0 - wa) * ws),
            (d(1, 0), wa * (1.0 - ws)),
            (d(1, 1), wa * ws),
        ]
    }
}

impl SightTable {
    /// The table of every patch of `grid` over `map`, whose samples are
    /// `spacing` (dx, dz) apart.
    pub fn compute(map: &Heightmap, grid: &PatchGrid, spacing: (f64, f64)) -> SightTable {
        let patches = (0..grid.patch_count())
            .into_par_iter()
            .map(|p| {
                let rect = grid.sample_rect(grid.patch_id(p));
                let n = grid.cells_per_patch();
                (rect.cells_x() == n && rect.cells_z() == n)
                    .then(|| patch_sight(map, rect, spacing))
            })
            .collect();
        SightTable { patches }
    }

    /// Whether patch `p` has an entry (it is full-size).
    pub fn has(&self, p: usize) -> bool {
        self.patches[p].is_some()
    }

    /// Patch `p`'s pixel area per `K^2 / d^2` seen from `at`: what it
    /// covers at distance d is this times `(K / d)^2`. None without an
    /// entry.
    pub fn area(&self, p: usize, at: &LatticePoint) -> Option<f32> {
        let sight = self.patches[p].as_ref()?;
        Some(at.corners().iter().map(|&(d, w)| w * sight.area[d]).sum())
    }

    /// The share of patch `p`'s pixels that level index `k` (2^k segments
    /// a side) puts over `error` (a vertical error, in the heightmap's
    /// units, at the patch), seen from `at`. None without an entry or for
    /// a level the table does not hold (full resolution and finer, whose
    /// error is 0).
    pub fn over_fraction(&self, p: usize, k: usize, at: &LatticePoint, error: f32) -> Option<f32> {
        let sight = self.patches[p].as_ref()?;
        if k >= LEVELS {
            return None;
        }
        let code = if error > 0.0 && sight.scale > 0.0 {
            CODES_PER_OCTAVE * (sight.scale / error).log2()
        } else if error > 0.0 {
            f32::INFINITY
        } else {
            f32::NEG_INFINITY
        };
        let mut fraction = 0.0;
        for (d, w) in at.corners() {
            if w <= 0.0 {
                continue;
            }
            let row = &sight.codes[(k * DIRECTIONS + d) * FRACTIONS..][..FRACTIONS];
            fraction += w * fraction_over(row, code);
        }
        Some(fraction)
    }
}

/// The share over an error of log code `code` of a row of codes at
/// `FRACTION_EXPONENTS` (non-decreasing: errors fall as the share grows),
/// interpolated between them in log-log.
fn fraction_over(row: &[u8], code: f32) -> f32 {
    // The first stored error at or below the given one.
    let Some(j) = row.iter().position(|&c| f32::from(c) >= code || c == ZERO) else {
        return 1.0;
    };
    if j == 0 {
        return 0.0;
    }
    let (lo, hi) = (FRACTION_EXPONENTS[j - 1], FRACTION_EXPONENTS[j]);
    if lo == i32::MIN {
        return (hi as f32).exp2();
    }
    let (c0, c1) = (f32::from(row[j - 1]), f32::from(row[j]));
    let w = if row[j] == ZERO || c1 <= c0 {
        1.0
    } else {
        ((code - c0) / (c1 - c0)).clamp(0.0, 1.0)
    };
    (lo as f32 + w * (hi - lo) as f32).exp2()
}

/// Bins per octave of the errors' histogram, and its octaves.
const BINS_PER_OCTAVE: f32 = 4.0;
const BINS: usize = 64;

/// One full-size patch's entry.
fn patch_sight(map: &Heightmap, rect: SampleRect, (dx, dz): (f64, f64)) -> PatchSight {
    let n = rect.cells_x();
    let stride = n + 1;
    let (w, d) = (map.width(), map.depth());
    let h = |r: usize, c: usize| f64::from(map.get(r, c));
    // The reference's gradient (x, z) at each sample, by central
    // differences, one-sided at the map's edges; local z falls as rows rise.
    let mut reference = Vec::with_capacity(stride * stride);
    let mut heights = Vec::with_capacity(stride * stride);
    for r in rect.row0..=rect.row1 {
        for c in rect.col0..=rect.col1 {
            let (c0, c1) = (c.saturating_sub(1), (c + 1).min(w - 1));
            let (r0, r1) = (r.saturating_sub(1), (r + 1).min(d - 1));
            reference.push([
                ((h(r, c1) - h(r, c0)) / ((c1 - c0) as f64 * dx)) as f32,
                ((h(r0, c) - h(r1, c)) / ((r1 - r0) as f64 * dz)) as f32,
            ]);
            heights.push(h(r, c));
        }
    }
    let cos = SLOPES.map(|t| 1.0 / (1.0 + t * t).sqrt());
    let point_area = (dx * dz) as f32;
    let mut area = [0.0f32; DIRECTIONS];
    for a in 0..AZIMUTHS {
        let [ux, uz] = azimuth(a);
        for (ti, &t) in SLOPES.iter().enumerate() {
            let seen: f32 = reference
                .iter()
                .map(|g| (g[0] * ux + g[1] * uz + t).max(0.0))
                .sum();
            area[a * SLOPES.len() + ti] = seen * point_area * cos[ti];
        }
    }
    // Errors per level and direction, at each fraction.
    let mut errors = vec![0.0f32; LEVELS * DIRECTIONS * FRACTIONS];
    let mut delta = vec![0.0f32; stride * stride];
    let mut drawn = vec![[0.0f32; 2]; stride * stride];
    let mut along: Vec<(f32, f32, f32)> = Vec::with_capacity(stride * stride);
    for k in 0..LEVELS {
        let segments = 1usize << k;
        if segments >= n {
            break;
        }
        let q = n / segments;
        let (quad_x, quad_z) = (q as f64 * dx, q as f64 * dz);
        let diagonal = (quad_x * quad_x + quad_z * quad_z).sqrt() as f32;
        for i in 0..=n {
            let (qi, fi) = if i == n {
                (segments - 1, q)
            } else {
                (i / q, i % q)
            };
            for j in 0..=n {
                let (qj, fj) = if j == n {
                    (segments - 1, q)
                } else {
                    (j / q, j % q)
                };
                let (r0, c0) = (qi * q, qj * q);
                // A upper-left, B upper-right, C lower-left, D lower-right.
                let corners = [
                    heights[r0 * stride + c0],
                    heights[r0 * stride + c0 + q],
                    heights[(r0 + q) * stride + c0],
                    heights[(r0 + q) * stride + c0 + q],
                ];
                let (u, v) = (fj as f64 / q as f64, fi as f64 / q as f64);
                let here = heights[i * stride + j];
                let bc = split_bc(corners, u, v, fi + fj <= q);
                let ad = split_ad(corners, u, v, fj >= fi);
                delta[i * stride + j] = (here - bc).abs().max((here - ad).abs()) as f32;
                let [a, b, c, dd] = corners;
                drawn[i * stride + j] = [
                    (((1.0 - v) * (b - a) + v * (dd - c)) / quad_x) as f32,
                    (-((1.0 - u) * (c - a) + u * (dd - b)) / quad_z) as f32,
                ];
            }
        }
        for a in 0..AZIMUTHS {
            let [ux, uz] = azimuth(a);
            // Per sample: how it faces the ray's direction, and the drawn
            // surface's rise along it.
            along.clear();
            along.extend(
                reference
                    .iter()
                    .zip(&delta)
                    .zip(&drawn)
                    .map(|((g, &e), s)| (g[0] * ux + g[1] * uz, s[0] * ux + s[1] * uz, e)),
            );
            for (ti, &t) in SLOPES.iter().enumerate() {
                let dir = a * SLOPES.len() + ti;
                let out = &mut errors[(k * DIRECTIONS + dir) * FRACTIONS..][..FRACTIONS];
                // No run is longer than the diagonal.
                let top = t.abs() * diagonal;
                if top <= 0.0 {
                    out.fill(0.0);
                    continue;
                }
                let mut histogram = Histogram::new(top);
                for &(rise, drawn_rise, e) in &along {
                    let seen = (rise + t).max(0.0);
                    histogram.total += seen;
                    if seen > 0.0 && e > 0.0 {
                        let meet = drawn_rise + t;
                        let run = if meet > 0.0 {
                            (e / meet).min(diagonal)
                        } else {
                            diagonal
                        };
                        histogram.add(run * t.abs(), seen);
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
    let scale = errors.iter().copied().fold(0.0f32, f32::max);
    let codes = errors
        .iter()
        .map(|&e| {
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
    PatchSight { scale, area, codes }
}

/// Weights of errors in bins `1 / BINS_PER_OCTAVE` octave wide below a
/// largest possible error, and the total weight the fractions are of.
struct Histogram {
    top: f32,
    largest: f32,
    total: f32,
    bins: [f32; BINS],
}

/// The quarter-octave steps within an octave: 2^(1/4), 2^(1/2), 2^(3/4).
const QUARTERS: [f32; 3] = [1.189_207_1, std::f32::consts::SQRT_2, 1.681_792_8];
const _: () = assert!(BINS_PER_OCTAVE == 4.0);

impl Histogram {
    fn new(top: f32) -> Self {
        Histogram {
            top,
            largest: 0.0,
            total: 0.0,
            bins: [0.0; BINS],
        }
    }

    /// Adds `weight` at `error` (at most `top`), in the bin whose upper
    /// edge is the first at or above it: floor(4 log2(top / error)),
    /// from the float's exponent and three comparisons.
    fn add(&mut self, error: f32, weight: f32) {
        self.largest = self.largest.max(error);
        let x = (self.top / error).max(1.0);
        let bits = x.to_bits();
        let octave = ((bits >> 23) & 0xff) as i32 - 127;
        let mantissa = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
        let quarter = QUARTERS.iter().filter(|&&q| mantissa >= q).count() as i32;
        let bin = (4 * octave + quarter).clamp(0, BINS as i32 - 1) as usize;
        self.bins[bin] += weight;
    }

    /// The errors above which at most each of `FRACTION_EXPONENTS` of the
    /// total lie, each rounded up to its bin's upper edge.
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
                    let edge = self.top * (-(b as f32) / BINS_PER_OCTAVE).exp2();
                    *slot = edge.min(self.largest);
                    break;
                }
            }
        }
    }
}
