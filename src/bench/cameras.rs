//! The benchmark's cameras, placed from the terrain alone so that any
//! heightmap gets comparable views: a low grazing view, a high overview, a
//! view down into the lowest valley, and a closed flythrough loop.

use glam::DVec3;

use crate::terrain::camera::Camera;
use crate::terrain::TerrainInfo;

/// Vertical field of view of every benchmark camera.
pub const BENCH_FOV_DEG: f32 = 55.0;

/// A camera with the name rows are reported under.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NamedView {
    pub name: &'static str,
    pub camera: Camera,
}

/// Name of the flythrough's rows.
pub const FLYTHROUGH: &str = "flythrough";

/// World position of the point at fractions (u, v) of the terrain's
/// extent from its centre (u, v in [-0.5, 0.5]), on the surface.
fn surface(info: &TerrainInfo, u: f64, v: f64) -> DVec3 {
    let o = info.origin();
    let x = o.x + u * info.world_width();
    let z = o.y + v * info.world_depth();
    DVec3::new(x, f64::from(info.clamped_height_at(x, z)), z)
}

fn height_range(info: &TerrainInfo) -> (f64, f64) {
    let (lo, hi) = info.min_max();
    (f64::from(lo), f64::from(hi))
}

/// Highest surface point on the straight line from `a` to `b` (x, z).
fn highest_between(info: &TerrainInfo, a: DVec3, b: DVec3) -> f64 {
    const STEPS: usize = 64;
    (0..=STEPS)
        .map(|i| {
            let p = a.lerp(b, i as f64 / STEPS as f64);
            f64::from(info.clamped_height_at(p.x, p.z))
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The three fixed views.
pub fn named_views(info: &TerrainInfo) -> Vec<NamedView> {
    let (lo, hi) = height_range(info);
    let range = (hi - lo).max(1.0);
    let size = info.world_width().max(info.world_depth());
    let o = info.origin();
    let camera = |eye, target| Camera {
        eye,
        target,
        fov_y_deg: BENCH_FOV_DEG,
    };

    // Grazing: a few percent of the relief above the ground near one
    // corner, looking level across the terrain to the opposite corner.
    let start = surface(info, -0.42, -0.42);
    let lift = 0.03 * range + info.spacing().max_element();
    let far = surface(info, 0.42, 0.42);
    let grazing = camera(
        start + DVec3::Y * lift,
        DVec3::new(far.x, start.y + lift, far.z),
    );

    // Overview: high above and beyond one corner, the whole terrain in view.
    let overview = camera(
        DVec3::new(
            o.x - 0.3 * info.world_width(),
            hi + 0.3 * size,
            o.y - 0.75 * info.world_depth(),
        ),
        DVec3::new(o.x, 0.5 * (lo + hi), o.y + 0.1 * info.world_depth()),
    );

    // Valley: the lowest point of the inner 60 % (on a coarse lattice),
    // seen from a fifth of the terrain away, above everything between.
    const LATTICE: usize = 48;
    let floor = (0..LATTICE * LATTICE)
        .map(|i| {
            let f = |k: usize| -0.3 + 0.6 * k as f64 / (LATTICE - 1) as f64;
            surface(info, f(i % LATTICE), f(i / LATTICE))
        })
        .min_by(|a, b| a.y.total_cmp(&b.y))
        .expect("the lattice is not empty");
    // From the side of the terrain's centre, so the view looks outwards
    // across the valley rather than off the edge.
    let towards_centre = (DVec3::new(o.x, floor.y, o.y) - floor)
        .try_normalize()
        .unwrap_or(DVec3::NEG_Z);
    let mut eye = floor + towards_centre * 0.2 * size;
    let clamped = info.clamp_to_terrain(glam::DVec2::new(eye.x, eye.z));
    eye = DVec3::new(clamped.x, 0.0, clamped.y);
    eye.y = highest_between(info, eye, floor) + 0.1 * range;
    let valley = camera(eye, floor);

    vec![
        NamedView {
            name: "grazing",
            camera: grazing,
        },
        NamedView {
            name: "overview",
            camera: overview,
        },
        NamedView {
            name: "valley",
            camera: valley,
        },
    ]
}

/// `frames` cameras around a closed elliptical loop at 30 % of the
/// terrain's extent from its centre, looking ahead and down along the path.
/// The altitude is a running mean of the highest ground within a window of
/// frames either side, plus a clearance: every frame in the mean has this
/// frame's ground in its window, so the camera stays above it, and a peak
/// entering the window raises the altitude over the window's length rather
/// than in one frame.
pub fn flythrough(info: &TerrainInfo, frames: usize) -> Vec<Camera> {
    if frames == 0 {
        return Vec::new();
    }
    let (lo, hi) = height_range(info);
    let range = (hi - lo).max(1.0);
    let at = |i: isize| {
        let t = std::f64::consts::TAU * i as f64 / frames as f64;
        surface(info, 0.3 * t.cos(), 0.3 * t.sin())
    };
    let ground: Vec<DVec3> = (0..frames as isize).map(at).collect();
    let window = (frames / 20).max(1) as isize;
    let wrap = |i: isize| i.rem_euclid(frames as isize) as usize;
    let envelope: Vec<f64> = (0..frames as isize)
        .map(|i| {
            (-window..=window)
                .map(|k| ground[wrap(i + k)].y)
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect();
    let altitude = |i: isize| {
        (-window..=window)
            .map(|k| envelope[wrap(i + k)])
            .sum::<f64>()
            / (2 * window + 1) as f64
            + 0.08 * range
    };
    let ahead = (frames / 25).max(1) as isize;
    (0..frames as isize)
        .map(|i| {
            let p = ground[i as usize];
            let q = ground[wrap(i + ahead)];
            Camera {
                eye: DVec3::new(p.x, altitude(i), p.z),
                target: DVec3::new(q.x, q.y, q.z),
                fov_y_deg: BENCH_FOV_DEG,
            }
        })
        .collect()
}
