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

use glam::Vec3;

use super::heightmap::Heightmap;
use super::TerrainInfo;

/// The samples hidden from one eye.
#[derive(Clone, Debug, Default)]
pub struct Viewshed {
    cols: usize,
    /// Per sample, row-major: hidden behind nearer terrain.
    hidden: Vec<bool>,
    /// Per sample: seen, with ground right behind it hidden (a silhouette).
    crest: Vec<bool>,
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
    ) {
        let (cols, rows) = (map.width(), map.depth());
        self.cols = cols;
        self.hidden.clear();
        self.hidden.resize(cols * rows, false);
        self.crest.clear();
        self.crest.resize(cols * rows, false);
        // The horizon each sample passes on.
        let mut horizon = vec![f32::NEG_INFINITY; cols * rows];
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
        let horizon_at = |horizon: &[f32], c: i64, r: i64| {
            if inside(c, r) {
                horizon[r as usize * cols + c as usize]
            } else {
                f32::NEG_INFINITY
            }
        };
        // A sample's height above the eye over its horizontal distance.
        let elevation = |r: usize, c: usize| {
            let (dx, dz) = (info.local_x(c) - eye.x, info.local_z(r) - eye.z);
            let reach = (dx * dx + dz * dz).sqrt().max(f64::MIN_POSITIVE);
            (f64::from(map.get(r, c)) - eye.y) / reach
        };
        let (ec, er) = (ec as i64, er as i64);
        if inside(ec, er) {
            let (c, r) = (ec as usize, er as usize);
            horizon[r * cols + c] = elevation(r, c) as f32;
        }
        for k in 1..=last as i64 {
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
                        // passes between.
                        let (a, b) = if dc.abs() == dr.abs() {
                            let p = (c - dc.signum(), r - dr.signum());
                            (p, p)
                        } else if dc.abs() > dr.abs() {
                            let cc = c - dc.signum();
                            let t = dr as f64 * (k - 1) as f64 / k as f64 + er as f64;
                            ((cc, t.floor() as i64), (cc, t.ceil() as i64))
                        } else {
                            let rr = r - dr.signum();
                            let t = dc as f64 * (k - 1) as f64 / k as f64 + ec as f64;
                            ((t.floor() as i64, rr), (t.ceil() as i64, rr))
                        };
                        let behind =
                            horizon_at(&horizon, a.0, a.1).min(horizon_at(&horizon, b.0, b.1));
                        let i = r as usize * cols + c as usize;
                        let elevation = elevation(r as usize, c as usize);
                        self.hidden[i] = elevation + margin < f64::from(behind);
                        horizon[i] = behind.max(elevation as f32);
                        if self.hidden[i] {
                            // What hides it and is itself seen is a crest.
                            for (pc, pr) in [a, b] {
                                if inside(pc, pr) {
                                    let j = pr as usize * cols + pc as usize;
                                    self.crest[j] |= !self.hidden[j];
                                }
                            }
                        }
                    }
                    c += step as i64;
                }
            }
        }
    }

    /// Whether sample (row, col) is seen with ground right behind it
    /// hidden: a silhouette, which a drawn surface lying lower or higher
    /// moves, uncovering or covering what is behind.
    pub fn crest(&self, row: usize, col: usize) -> bool {
        self.crest
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
