//! Ground that nearer ground hides, found from the plan's own boxes: what
//! a frame without counts (`lod::seen`) knows of hidden ground.
//!
//! A height field is solid below its surface. Each box of the plan is
//! taken as a slab of ground, solid over its footprint up to a height: its
//! bottom, which every point of the footprint reaches, or for a block the
//! view model reads, its mean height, the surface the model's rays land on
//! (`SightTable::mean_height`). A line of sight crossing a block's
//! footprint below its mean passes under its ground somewhere, unless the
//! ground along the whole crossing stays below the mean: a line clipping a
//! corner, or one running down a valley. So the mean's slab is the model's
//! estimate of what the block hides, where the bottom's was a bound that
//! left most hidden ground shown. Camera 5 of the default scene's 20-frame
//! flythrough, held still, drew 134,449 triangles at 1 px on its first
//! frame with bottoms, 53,563 with means, and 28,636 once its counts were
//! read (notes section 50).
//!
//! A patch large on screen is also added as its parts higher than its
//! mean (`add_part`, `terrain::slabs`), each solid up to its own samples'
//! mean. They only hide: a ridge among them hides the ground behind it
//! where the patch's mean, below the ridge, would not (notes section 61).
//! A part lower than the patch's mean lies under the patch's own slab,
//! which already hides more of what lies beyond the patch: leaving such
//! parts out drew the same triangles on the DEM's flythrough and the
//! 4097^2 grazing view.
//!
//! Seen from the eye, a vertical line of sight over the footprint at
//! azimuth `a` crosses the slab from where it enters the footprint to
//! where it leaves it, `t_out(a)` away horizontally: anything further
//! along `a` whose elevation is below the slab's top at some point of that
//! crossing is hidden. Over an azimuth bin wholly inside the footprint's
//! span, the slab's top hides every elevation whose tangent is below
//! `solid / t_out` for the bin's smallest `t_out` (its largest for a top
//! above the eye, `solid > 0`; bounded there by the footprint's farthest
//! corner): the bin's horizon. A box is hidden in a bin where its highest
//! elevation (its top seen from its nearest point, or from its farthest
//! for a top below the eye) is below the horizon of the boxes wholly
//! nearer than it.
//!
//! Boxes are taken nearest first; each bin keeps the highest horizon of the
//! boxes whose farthest point is nearer than the box tested. A box's
//! share shown is the share of the bins it overlaps where it is not hidden.
//! Past the slab's height, every step errs towards showing: a bin counts
//! as shown where any part of the box may rise over the horizon (the
//! pixels over tau a coarser level puts on a partly hidden block lie
//! mostly on its peaks, which are what rises over a ridge), and only
//! boxes wholly nearer hide. The cost is a few bins per box (`BINS`
//! around the eye), whatever the terrain's size.

use glam::{Vec2, Vec3};

use super::buffers::touched;
use super::factors::footprint_distance;

/// Azimuth bins around the eye (`quarter_turns`): 1.4 to 2.8 degrees
/// each, 20 to 40 pixels across at the bench's 1280 x 720 and 55 degrees.
/// 512 drew 1.4 % fewer triangles on one flythrough frame of the default
/// scene and as many on another, each bin a box spans costing its share.
pub const BINS: usize = 256;

/// One box of the frame's ground, eye-relative.
#[derive(Clone, Copy, Debug)]
struct Item {
    lo: Vec3,
    hi: Vec3,
    /// The height its ground is taken as solid up to.
    solid: f32,
    /// Horizontal distances to its footprint's nearest and farthest
    /// points.
    near: f32,
    far: f32,
    /// Its footprint's azimuth span in bins (`first..last`, `last` past
    /// `first`, unwrapped); None where the footprint holds the eye.
    span: Option<(f32, f32)>,
    /// Whether `shown` tells its share; otherwise it only hides.
    target: bool,
}

/// The horizon's buffers, kept from frame to frame.
#[derive(Debug, Default)]
pub struct Horizon {
    items: Vec<Item>,
    /// Per bin, the tangent of the elevation below which ground is hidden.
    bins: Vec<f32>,
    /// The reciprocals of the components of unit vectors along the bins'
    /// edges, bin `i` from edge `i` to `i + 1` (edge `BINS` is edge 0).
    edges: Vec<Vec2>,
    /// Per bin, whether a box whose share is asked for overlaps it.
    needed: Vec<bool>,
    /// The boxes whose share is asked for, nearest first, and all of them,
    /// farthest point nearest first: each a distance's bits over its index.
    by_near: Vec<u64>,
    by_far: Vec<u64>,
}

/// A distance (not negative, so its bits sort as it does) over an index.
fn key(distance: f32, index: usize) -> u64 {
    (u64::from(distance.to_bits()) << 32) | index as u64
}

impl Horizon {
    /// Room for `boxes` boxes without growing (`buffers::touched`).
    pub fn reserve(&mut self, boxes: usize) {
        touched(&mut self.items, boxes);
        touched(&mut self.by_near, boxes);
        touched(&mut self.by_far, boxes);
    }

    /// Forgets the last frame's boxes.
    pub fn clear(&mut self) {
        self.items.clear();
    }

    /// Adds a box of ground (its corners relative to the eye), solid up to
    /// `solid` (clamped to its heights); returns its index for `shown`.
    pub fn add(&mut self, lo: Vec3, hi: Vec3, solid: f32) -> usize {
        self.push(lo, hi, solid, true)
    }

    /// Adds a box of ground solid up to its bottom whose own share is not
    /// asked for: it only hides.
    pub fn add_occluder(&mut self, lo: Vec3, hi: Vec3) {
        self.push(lo, hi, lo.y, false);
    }

    /// Adds a part of a box added before, solid up to `solid` (clamped to
    /// its heights), whose own share is not asked for: it only hides
    /// (`terrain::slabs`).
    pub fn add_part(&mut self, lo: Vec3, hi: Vec3, solid: f32) {
        self.push(lo, hi, solid, false);
    }

    fn push(&mut self, lo: Vec3, hi: Vec3, solid: f32, target: bool) -> usize {
        let near = footprint_distance(lo, hi);
        let far = Vec2::new(lo.x.abs().max(hi.x.abs()), lo.z.abs().max(hi.z.abs())).length();
        let span = (near > 0.0).then(|| azimuth_span(lo, hi));
        self.items.push(Item {
            lo,
            hi,
            solid: solid.clamp(lo.y, hi.y),
            near,
            far,
            span,
            target,
        });
        self.items.len() - 1
    }

    /// Each box's share of its azimuth bins where nearer boxes do not hide
    /// it, in the order added: 1 for a box nothing hides, 0 for one hidden
    /// in every bin.
    pub fn shown(&mut self, shown: &mut Vec<f32>) {
        if self.edges.len() != BINS {
            self.edges = (0..BINS)
                .map(|i| direction(4.0 * i as f32 / BINS as f32).recip())
                .collect();
        }
        self.bins.clear();
        self.bins.resize(BINS, f32::NEG_INFINITY);
        self.needed.clear();
        self.needed.resize(BINS, false);
        let items = &self.items;
        self.by_near.clear();
        self.by_far.clear();
        for (i, item) in items.iter().enumerate() {
            self.by_far.push(key(item.far, i));
            if let (true, Some((a, b))) = (item.target, item.span) {
                self.by_near.push(key(item.near, i));
                for j in target_bins(a, b) {
                    self.needed[wrap(j)] = true;
                }
            }
        }
        self.by_near.sort_unstable();
        self.by_far.sort_unstable();
        shown.clear();
        shown.resize(items.len(), 1.0);
        let mut occluders = self
            .by_far
            .iter()
            .map(|&k| &items[k as u32 as usize])
            .peekable();
        for &k in &self.by_near {
            let target = &items[k as u32 as usize];
            while let Some(occluder) = occluders.next_if(|o| o.far < target.near) {
                raise(occluder, &self.edges, &self.needed, &mut self.bins);
            }
            shown[k as u32 as usize] = shown_share(target, &self.bins);
        }
    }
}

/// Azimuth in quarter turns, [0, 4), measured along the square rather
/// than the circle (`x` and `z` not both 0): monotonic in the angle, and
/// one division instead of an arc tangent. Bins are equal in it, and
/// twice as wide in angle along the diagonals as along the axes.
fn quarter_turns(x: f32, z: f32) -> f32 {
    match (x >= 0.0, z >= 0.0) {
        (true, true) => z / (x + z),
        (false, true) => 1.0 - x / (z - x),
        (false, false) => 2.0 - z / (-x - z),
        (true, false) => 3.0 + x / (x - z),
    }
}

/// The direction at `p` quarter turns (`quarter_turns`), a unit vector.
fn direction(p: f32) -> Vec2 {
    let q = p.fract();
    let v = match p as u32 {
        0 => Vec2::new(1.0 - q, q),
        1 => Vec2::new(-q, 1.0 - q),
        2 => Vec2::new(q - 1.0, -q),
        _ => Vec2::new(q, q - 1.0),
    };
    v.normalize()
}

/// The azimuth span of a footprint that does not hold the eye, in bins:
/// its corners' azimuths about its centre's, which is less than half a
/// turn from any of them.
fn azimuth_span(lo: Vec3, hi: Vec3) -> (f32, f32) {
    let mid = quarter_turns(lo.x + hi.x, lo.z + hi.z);
    let (mut first, mut last) = (f32::INFINITY, f32::NEG_INFINITY);
    for (x, z) in [(lo.x, lo.z), (hi.x, lo.z), (lo.x, hi.z), (hi.x, hi.z)] {
        let a = match quarter_turns(x, z) - mid {
            a if a > 2.0 => a - 4.0,
            a if a < -2.0 => a + 4.0,
            a => a,
        };
        first = first.min(a);
        last = last.max(a);
    }
    let to_bins = BINS as f32 / 4.0;
    ((mid + first) * to_bins, (mid + last) * to_bins)
}

/// Bin `i` of an unwrapped index.
fn wrap(i: i64) -> usize {
    i.rem_euclid(BINS as i64) as usize
}

/// Where a line of sight from the eye along a direction whose components'
/// reciprocals are `per` leaves the footprint `lo`..`hi` (x, z),
/// horizontally.
fn exit_distance(lo: Vec3, hi: Vec3, per: Vec2) -> f32 {
    let along = |r: f32, lo: f32, hi: f32| if r > 0.0 { hi * r } else { lo * r };
    along(per.x, lo.x, hi.x).min(along(per.y, lo.z, hi.z))
}

/// The bins a box spanning `a` to `b` overlaps, unwrapped: one at least.
fn target_bins(a: f32, b: f32) -> std::ops::Range<i64> {
    let first = floor(a);
    first..ceil(b).max(first + 1)
}

/// `x.floor()` as an integer, for the few turns' worth of bins a span
/// covers: a conversion and a compare, where the baseline x86-64 target
/// calls the C library's `floorf`.
fn floor(x: f32) -> i64 {
    let i = x as i64;
    i - i64::from((i as f32) > x)
}

/// `x.ceil()` as an integer (`floor`).
fn ceil(x: f32) -> i64 {
    let i = x as i64;
    i + i64::from((i as f32) < x)
}

/// Raises the horizon of every bin wholly inside `item`'s span and
/// `needed` to its solid slab's top.
fn raise(item: &Item, edges: &[Vec2], needed: &[bool], bins: &mut [f32]) {
    let solid = item.solid;
    let (first, last) = match item.span {
        Some((a, b)) => (ceil(a), floor(b)),
        None => (0, BINS as i64),
    };
    if solid >= 0.0 {
        let tangent = solid / item.far;
        for i in first..last {
            let b = wrap(i);
            if needed[b] {
                bins[b] = bins[b].max(tangent);
            }
        }
        return;
    }
    // The nearest exit over a bin is at one of its edges: each side's exit
    // distance, d / cos, is least where the line of sight is square to the
    // side, and the four azimuths square to the sides are bin edges.
    // An edge on the span's side grazes a corner, where rounding can put
    // the exit anywhere: no exit is nearer than the footprint.
    let exit_at = |i: i64| exit_distance(item.lo, item.hi, edges[wrap(i)]).max(item.near);
    // Each edge's exit is found once, for the bins either side of it.
    let mut before = None;
    for i in first..last {
        let b = wrap(i);
        if !needed[b] {
            before = None;
            continue;
        }
        let after = exit_at(i + 1);
        let exit = before.unwrap_or_else(|| exit_at(i)).min(after);
        bins[b] = bins[b].max(solid / exit);
        before = Some(after);
    }
}

/// The share of the bins `item` overlaps where its highest elevation is
/// not below the horizon.
fn shown_share(item: &Item, bins: &[f32]) -> f32 {
    let Some((a, b)) = item.span else {
        return 1.0;
    };
    let top = if item.hi.y >= 0.0 {
        item.hi.y / item.near
    } else {
        item.hi.y / item.far
    };
    let overlapped = target_bins(a, b);
    let all = overlapped.end - overlapped.start;
    let shown = overlapped.filter(|&i| top >= bins[wrap(i)]).count();
    shown as f32 / all as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The integer floor and ceiling agree with the float ones over the
    /// spans' range, halves and whole numbers included.
    #[test]
    fn integer_floor_and_ceiling_agree_with_the_float_ones() {
        for i in -4096..=4096 {
            for x in [
                i as f32 * 0.25,
                i as f32 * 0.25 + 1e-3,
                i as f32 * 0.25 - 1e-3,
            ] {
                assert_eq!(floor(x), x.floor() as i64, "{x}");
                assert_eq!(ceil(x), x.ceil() as i64, "{x}");
            }
        }
    }

    /// Adds the box from `lo` to `hi`, solid up to its bottom.
    fn solid_to_bottom(h: &mut Horizon, lo: [f32; 3], hi: [f32; 3]) -> usize {
        h.add(Vec3::from(lo), Vec3::from(hi), lo[1])
    }

    /// A box solid up to its mean hides what its bottom leaves in view:
    /// a hummock whose bottom is under the eye's line to lower ground
    /// beyond, and whose mean is over it.
    #[test]
    fn a_mean_higher_than_the_bottom_hides_more() {
        let shown_behind = |solid: f32| {
            let mut h = Horizon::default();
            // From 20 to 40 away, 12 to 2 below the eye.
            let (lo, hi) = (Vec3::new(-50.0, -12.0, 20.0), Vec3::new(50.0, -2.0, 40.0));
            h.add(lo, hi, solid);
            // 200 to 210 away, 80 to 40 below the eye: its highest
            // elevation, -40/210, is under -4/40, and its lowest, -80/200,
            // under -12/40 (lines of sight straight ahead leave the slab 40
            // away, those to its sides a little further).
            let behind = h.add(
                Vec3::new(-5.0, -80.0, 200.0),
                Vec3::new(5.0, -40.0, 210.0),
                -80.0,
            );
            let mut shown = Vec::new();
            h.shown(&mut shown);
            shown[behind]
        };
        let (bottom, mean) = (shown_behind(-12.0), shown_behind(-4.0));
        assert!(bottom > 0.5, "{bottom}");
        assert_eq!(mean, 0.0);
        // Clamped to the box's heights.
        assert_eq!(shown_behind(-30.0), bottom);
    }

    /// A wide box whose mean lies under a ridge along its far side hides
    /// what is behind the ridge once its parts are added, each solid up
    /// to its own mean; the parts hide nothing of the box itself, and a
    /// part lower than the box's mean hides no more than the box does.
    #[test]
    fn a_ridge_among_a_boxs_parts_hides_what_its_mean_does_not() {
        let shown = |parts: &[([f32; 3], [f32; 3], f32)]| {
            let mut h = Horizon::default();
            // A plain 20 to 60 away, 30 below the eye, with a ridge 50 to
            // 60 away rising to 10 below it: mean -26 over the whole box.
            let near = h.add(
                Vec3::new(-40.0, -30.0, 20.0),
                Vec3::new(40.0, -10.0, 60.0),
                -26.0,
            );
            for &(lo, hi, solid) in parts {
                h.add_part(Vec3::from(lo), Vec3::from(hi), solid);
            }
            // Ground 200 to 210 away, 70 to 60 below the eye: -60/210 is
            // over -26/60 (not hidden by the box), under -12/60 (hidden by
            // the ridge's part).
            let behind = solid_to_bottom(&mut h, [-5.0, -70.0, 200.0], [5.0, -60.0, 210.0]);
            let mut shown = Vec::new();
            h.shown(&mut shown);
            (shown[near], shown[behind])
        };
        let plain = ([-40.0, -30.0, 20.0], [40.0, -29.0, 50.0], -29.5);
        let ridge = ([-40.0, -30.0, 50.0], [40.0, -10.0, 60.0], -12.0);
        assert_eq!(shown(&[]), (1.0, 1.0));
        assert_eq!(shown(&[plain]), (1.0, 1.0));
        assert_eq!(shown(&[plain, ridge]), (1.0, 0.0));
    }

    /// A wall across the line of sight hides lower ground behind it, not
    /// ground that rises over it, nor ground beside it.
    #[test]
    fn a_wall_hides_lower_ground_behind_it() {
        let mut h = Horizon::default();
        // The eye at the origin, 10 above a plain at -10; a wall 100 wide
        // along x, 20 to 30 away along z, rising to 5 above the eye.
        let wall = solid_to_bottom(&mut h, [-50.0, 5.0, 20.0], [50.0, 6.0, 30.0]);
        let behind = solid_to_bottom(&mut h, [-5.0, -10.0, 100.0], [5.0, -9.0, 110.0]);
        let tall = solid_to_bottom(&mut h, [-5.0, -10.0, 100.0], [5.0, 40.0, 110.0]);
        let beside = solid_to_bottom(&mut h, [200.0, -10.0, -5.0], [210.0, -9.0, 5.0]);
        let mut shown = Vec::new();
        h.shown(&mut shown);
        assert_eq!(shown[wall], 1.0);
        assert_eq!(shown[behind], 0.0);
        assert_eq!(shown[tall], 1.0);
        assert_eq!(shown[beside], 1.0);
    }

    /// The slab hides only along lines of sight that cross it: a ridge
    /// low enough to look over, or one the box reaches round, hides
    /// nothing, or only part.
    #[test]
    fn only_ground_wholly_behind_the_slab_is_hidden() {
        let mut h = Horizon::default();
        // A ridge at -1 under an eye at 0, from 10 to 20 away: its top's
        // tangent straight ahead is -1/20, and lower towards its ends,
        // where lines of sight leave it through its sides.
        solid_to_bottom(&mut h, [-5.0, -1.0, 10.0], [5.0, 0.0, 20.0]);
        // Ground at -4 to -3, 100 away: its top at -3/100 is over -1/20.
        let over = solid_to_bottom(&mut h, [-5.0, -4.0, 100.0], [5.0, -3.0, 110.0]);
        // Ground at -10 to -9, 100 to 110 away: -9/110 is under -1/20.
        let under = solid_to_bottom(&mut h, [-5.0, -10.0, 100.0], [5.0, -9.0, 110.0]);
        // As low, but reaching past the ridge's end on one side.
        let round = solid_to_bottom(&mut h, [-5.0, -10.0, 100.0], [100.0, -9.0, 110.0]);
        let mut shown = Vec::new();
        h.shown(&mut shown);
        assert_eq!(shown[over], 1.0);
        assert_eq!(shown[under], 0.0);
        assert!(shown[round] > 0.0 && shown[round] < 1.0, "{}", shown[round]);
    }

    /// Ground whose footprint holds the eye is never hidden, and hides
    /// what lies below its bottom all round.
    #[test]
    fn ground_under_the_eye_hides_all_round() {
        let mut h = Horizon::default();
        let under = solid_to_bottom(&mut h, [-10.0, -2.0, -10.0], [10.0, -1.0, 10.0]);
        let deep: Vec<usize> = [(50.0, 0.0), (-50.0, 0.0), (0.0, 50.0), (0.0, -50.0)]
            .into_iter()
            .map(|(x, z)| {
                solid_to_bottom(&mut h, [x - 1.0, -30.0, z - 1.0], [x + 1.0, -20.0, z + 1.0])
            })
            .collect();
        let mut shown = Vec::new();
        h.shown(&mut shown);
        assert_eq!(shown[under], 1.0);
        for d in deep {
            assert_eq!(shown[d], 0.0, "box {d}");
        }
    }
}
