//! Distance-driven tessellation factors: the Rust side of the formula the
//! tessellation control shader evaluates. The GLSL mirrors these functions
//! operation for operation, including how they treat degenerate input.
//!
//! Positions given to these functions are relative to the eye (the shader
//! works in camera-relative coordinates), so the eye is the origin.

use glam::{Vec2, Vec3};

use crate::terrain::error_table::PatchErrors;

pub use crate::shader_constants::{MAX_TESS_EXPONENT, MAX_TESS_FACTOR, MIN_TESS_FACTOR};

pub use crate::terrain::lod_params::{DistanceLod, DistanceMode, LodError};

/// Clamp to [0, 1] with NaN going to 1 (the coarsest level), so a broken eye
/// position can never ask for maximum tessellation everywhere.
#[inline]
pub fn saturate(x: f32) -> f32 {
    if x < 1.0 {
        if x > 0.0 {
            x
        } else {
            0.0
        }
    } else {
        1.0
    }
}

/// Clamp to [1, 64] with NaN going to 1.
#[inline]
pub fn clamp_tess_factor(f: f32) -> f32 {
    if f > MIN_TESS_FACTOR {
        if f < MAX_TESS_FACTOR {
            f
        } else {
            MAX_TESS_FACTOR
        }
    } else {
        MIN_TESS_FACTOR
    }
}

/// Tessellation factor at `rel`, a position relative to the eye.
///
/// Degenerate input stays finite: `min_dist == max_dist` makes the formula a
/// step at that distance (the range is floored at the smallest positive
/// float, so `d == min_dist` still gets the finest level); a NaN or infinite
/// distance yields the coarsest level.
#[inline]
pub fn tess_factor(rel: Vec3, lod: &DistanceLod, mode: DistanceMode) -> f32 {
    let d = match mode {
        DistanceMode::Smooth => rel.length(),
        DistanceMode::Debug => rel.x.abs().max(rel.z.abs()),
    };
    let range = (lod.max_dist - lod.min_dist).max(f32::MIN_POSITIVE);
    let s = saturate((d - lod.min_dist) / range);
    // lerp(max_exp, min_exp, s) written as the shader's mix().
    let exponent = lod.max_exp + s * (lod.min_exp - lod.max_exp);
    let exponent = match mode {
        DistanceMode::Smooth => exponent,
        // floor(x + 0.5) rather than round(): GLSL leaves round()'s
        // behaviour at .5 to the implementation.
        DistanceMode::Debug => (exponent + 0.5).floor(),
    };
    clamp_tess_factor(exponent.exp2())
}

/// Tessellation factors of one quad patch.
///
/// Edge order follows the control point order (0 upper-left, 1 upper-right,
/// 2 lower-left, 3 lower-right): edge 0 is the left edge (0-2), 1 the top
/// (0-1), 2 the right (1-3), 3 the bottom (2-3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchTessFactors {
    pub edges: [f32; 4],
    pub inside: [f32; 2],
}

impl PatchTessFactors {
    pub const CULLED: PatchTessFactors = PatchTessFactors {
        edges: [0.0; 4],
        inside: [0.0; 2],
    };
}

/// Midpoint of an edge. `0.5 * (a + b)` is symmetric in a and b in floating
/// point too, so two patches sharing an edge compute the same midpoint
/// whichever way round they list its ends.
#[inline]
pub fn edge_midpoint(a: Vec3, b: Vec3) -> Vec3 {
    0.5 * (a + b)
}

/// A patch's edges as (first, second) ends, from its corners in control
/// point order, in the order of the factors (and of the control shader's
/// `ends`): left (0-2), top (0-1), right (1-3), bottom (2-3). The patches
/// either side of an edge list its ends the same way round.
pub fn patch_edges(corners: [Vec3; 4]) -> [(Vec3, Vec3); 4] {
    let [ul, ur, ll, lr] = corners;
    [(ul, ll), (ul, ur), (ur, lr), (ll, lr)]
}

/// Edge factors from the edge midpoints and the inside factors from the
/// patch centre. `corners` are eye-relative, in control point order.
///
/// This is the seed's distance formula as it stands: near the eye it may
/// ask for more segments than the patch has cells, which brings the surface
/// closer to the reference's split than a vertex on every sample would
/// (the tessellator folds cells either way). The error LOD instead draws
/// such patches with the reference's own triangles.
pub fn patch_tess_factors(
    corners: [Vec3; 4],
    lod: &DistanceLod,
    mode: DistanceMode,
) -> PatchTessFactors {
    let [ul, ur, ll, lr] = corners;
    let centre = 0.25 * (ul + ur + ll + lr);
    let inside = tess_factor(centre, lod, mode);
    PatchTessFactors {
        edges: patch_edges(corners).map(|(a, b)| tess_factor(edge_midpoint(a, b), lod, mode)),
        inside: [inside, inside],
    }
}

/// Whether an error seen at `scale` pixels per unit is within `tau` pixels.
/// A zero error always is, even from inside a patch's box, where the scale
/// is infinite (an eye inside a patch is told its accepted levels by zero
/// errors). Mirror: `within_tolerance` in glsl/terrain_common.glsl.
pub fn within_tolerance(error: f32, scale: f32, tau: f32) -> bool {
    error == 0.0 || error * scale <= tau
}

/// Error-bounded tessellation factor of a span of `cells` cells (an edge,
/// or the smaller side of a patch) at `distance` from the eye (the tess
/// path's `--lod error`).
///
/// `errors[k]` bounds the geometric error of tessellating with 2^k
/// segments (the error table's levels). At `distance` an error e covers
/// e * pixels_per_radian / distance pixels. The factor is the smallest
/// power of two below `cells` whose projected error is at most
/// `pixel_error`. When none is, it is `cells` itself: a vertex on every
/// sample, the data's full resolution, which the renderer draws with the
/// reference's own triangles (see `patch_is_full_resolution`). Factors are
/// whole numbers (the error mode tessellates with equal spacing), so the
/// surface drawn is the one the table bounds, and a shared edge of `cells`
/// segments puts its vertices exactly on the samples. A NaN scale gives
/// the coarsest factor.
pub fn error_tess_factor(
    errors: &PatchErrors,
    distance: f32,
    pixels_per_radian: f32,
    pixel_error: f32,
    cells: u32,
) -> f32 {
    let scale = pixels_per_radian / distance.max(f32::MIN_POSITIVE);
    if scale.is_nan() {
        return MIN_TESS_FACTOR;
    }
    let tau = pixel_error.max(f32::MIN_POSITIVE);
    let full = (cells as f32).clamp(MIN_TESS_FACTOR, MAX_TESS_FACTOR);
    for (k, &error) in errors.iter().enumerate() {
        let factor = (1u32 << k) as f32;
        if factor >= full {
            break;
        }
        if within_tolerance(error, scale, tau) {
            return factor;
        }
    }
    full
}

/// Whether a patch of `cells` (columns, rows) needs the data's full
/// resolution: no tessellation level coarser than its smaller side keeps
/// its own errors within `pixel_error` from `distance`. Such a patch is
/// drawn with the reference's triangles instead of tessellated, and every
/// edge it shares is tessellated with a vertex on every sample. The inside
/// factor `patch_error_factors` gives is then the smaller side's count.
pub fn patch_is_full_resolution(
    own: &PatchErrors,
    distance: f32,
    pixels_per_radian: f32,
    pixel_error: f32,
    cells: [u32; 2],
) -> bool {
    patch_inside_factor(own, distance, pixels_per_radian, pixel_error, cells).is_none()
}

/// The inside factor of a patch of `cells` (columns, rows) whose box is
/// `distance` away: the error-bounded factor over its smaller side, or None
/// where that is the side itself (full resolution).
pub fn patch_inside_factor(
    own: &PatchErrors,
    distance: f32,
    pixels_per_radian: f32,
    pixel_error: f32,
    cells: [u32; 2],
) -> Option<f32> {
    let side = cells[0].min(cells[1]);
    let factor = error_tess_factor(own, distance, pixels_per_radian, pixel_error, side);
    (factor < side as f32).then_some(factor)
}

/// Per-level errors of an edge shared by two patches: the larger of each.
pub fn shared_edge_errors(a: &PatchErrors, b: Option<&PatchErrors>) -> PatchErrors {
    match b {
        Some(b) => std::array::from_fn(|k| a[k].max(b[k])),
        None => *a,
    }
}

/// Distance from the eye (the origin: points are eye-relative) to the box
/// `[lo, hi]`; 0 inside it.
pub fn box_distance(lo: Vec3, hi: Vec3) -> f32 {
    lo.max(-hi).max(Vec3::ZERO).length()
}

/// Horizontal distance from the eye (the origin) to the footprint (x, z)
/// of the box `[lo, hi]`; 0 where the eye is over it.
pub fn footprint_distance(lo: Vec3, hi: Vec3) -> f32 {
    Vec2::new(lo.x.max(-hi.x), lo.z.max(-hi.z))
        .max(Vec2::ZERO)
        .length()
}

/// Distance from the eye (the origin) to the vertical strip standing on the
/// segment `a`-`b` (eye-relative x, z) between heights `y_lo` and `y_hi`
/// (eye-relative). A degenerate segment is its point.
pub fn edge_distance(a: Vec2, b: Vec2, y_lo: f32, y_hi: f32) -> f32 {
    let ab = b - a;
    let len2 = ab.dot(ab);
    let t = if len2 > 0.0 {
        (-a.dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let p = a + t * ab;
    let dy = y_lo.max(-y_hi).max(0.0);
    (p.dot(p) + dy * dy).sqrt()
}

/// What lies across a patch's edge, for its error-bounded factor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Across<'a> {
    /// The terrain's border: the edge is the patch's own.
    Border,
    /// A patch tessellated by its errors: the edge takes the larger of each.
    Patch(&'a PatchErrors),
    /// A patch drawn at full resolution: a vertex on every sample.
    FullResolution,
    /// A merged node (`lod::patch_merge`): one segment, as the node
    /// puts one on each patch along its side.
    Merged,
}

/// Distance from the eye to the strip standing on the edge `ends` (eye-
/// relative, only x and z read) between the terrain's lowest and highest
/// heights (`height_range`, eye-relative): what every patch or node
/// sharing the edge knows alike.
pub fn strip_distance((a, b): (Vec3, Vec3), height_range: [f32; 2]) -> f32 {
    let xz = |v: Vec3| Vec2::new(v.x, v.z);
    edge_distance(xz(a), xz(b), height_range[0], height_range[1])
}

/// Error-bounded factors of one patch: each edge from the errors it shares
/// with the neighbour across it (left, top, right, bottom; None at the
/// terrain's border), the inside from the patch's own errors. Each is
/// projected from the nearest point that can carry it, so no part of the
/// patch is nearer than the distance its factor assumes:
/// - an edge from the strip standing on it between the terrain's lowest and
///   highest heights (`height_range`), which both patches sharing it know
///   alike, so they agree on its factor;
/// - the inside from the patch's box: its corners' x and z, `bounds_y`.
///
/// What lies across each edge (`Across`) sets the edges towards a
/// full-resolution patch (a vertex on every sample) and towards a merged
/// node (one segment). `cells` is the patch's (columns, rows). `corners`
/// and both height pairs are eye-relative.
#[allow(clippy::too_many_arguments)]
pub fn patch_error_factors(
    corners: [Vec3; 4],
    bounds_y: [f32; 2],
    height_range: [f32; 2],
    own: &PatchErrors,
    neighbours: [Across; 4],
    cells: [u32; 2],
    pixels_per_radian: f32,
    pixel_error: f32,
) -> PatchTessFactors {
    let ends = patch_edges(corners);
    let [cx, cz] = cells;
    let edge_cells = [cz, cx, cz, cx];
    let edges = std::array::from_fn(|i| {
        let errors = match neighbours[i] {
            Across::FullResolution => return edge_cells[i] as f32,
            Across::Merged => return MIN_TESS_FACTOR,
            Across::Border => *own,
            Across::Patch(theirs) => shared_edge_errors(own, Some(theirs)),
        };
        let d = strip_distance(ends[i], height_range);
        error_tess_factor(&errors, d, pixels_per_radian, pixel_error, edge_cells[i])
    });
    let distance = patch_box_distance(corners, bounds_y);
    let inside = patch_inside_factor(own, distance, pixels_per_radian, pixel_error, cells)
        .unwrap_or(cx.min(cz) as f32);
    PatchTessFactors {
        edges,
        inside: [inside, inside],
    }
}

/// Distance from the eye to a patch's box: its corners' x and z (eye-
/// relative, control point order) and `bounds_y` (eye-relative).
pub fn patch_box_distance(corners: [Vec3; 4], bounds_y: [f32; 2]) -> f32 {
    let [_, ur, ll, _] = corners;
    // Lower-left has the smallest x and z, upper-right the largest.
    let lo = Vec3::new(ll.x, bounds_y[0], ll.z);
    let hi = Vec3::new(ur.x, bounds_y[1], ur.z);
    box_distance(lo, hi)
}

/// The tess path's error-bounded choice for one frame, made on the CPU
/// with the control shader's own formulas: which patches are drawn at full
/// resolution, and what error each is expected to show.
#[derive(Clone, Debug, PartialEq)]
pub struct TessErrorChoice {
    /// One bit a patch, 32 to a word, in patch order: set where the patch
    /// is drawn at full resolution (`patch_is_full_resolution`).
    pub full_resolution: Vec<u32>,
    /// Per patch, its error bound at the level chosen for its inside, in
    /// pixels from its box's nearest point; 0 at full resolution.
    pub predicted_px: Vec<f32>,
}

impl TessErrorChoice {
    pub fn is_full_resolution(&self, patch: usize) -> bool {
        self.full_resolution[patch / 32] & (1 << (patch % 32)) != 0
    }
}

/// Chooses, for every patch (culled ones too: their neighbours need it),
/// whether it is drawn at full resolution at `pixel_error` pixels, seen
/// from `eye_local` (relative to the terrain's centre).
pub fn choose_tess_error(
    terrain: &crate::terrain::Terrain,
    table: &crate::terrain::ErrorTable,
    eye_local: Vec3,
    pixels_per_radian: f32,
    pixel_error: f32,
) -> TessErrorChoice {
    let grid = terrain.grid();
    let count = grid.patch_count();
    let mut full_resolution = vec![0u32; count.div_ceil(32).max(1)];
    let mut predicted_px = vec![0.0f32; count];
    for (p, predicted) in predicted_px.iter_mut().enumerate() {
        let id = grid.patch_id(p);
        let rect = grid.sample_rect(id);
        let cells = [rect.cells_x() as u32, rect.cells_z() as u32];
        let corners = terrain.patch_corners(id).map(|c| c - eye_local);
        let [lo, hi] = terrain.y_bounds()[p];
        let distance = patch_box_distance(corners, [lo - eye_local.y, hi - eye_local.y]);
        let own: &PatchErrors = table
            .patch(p)
            .try_into()
            .expect("LEVEL_COUNT levels a patch");
        match patch_inside_factor(own, distance, pixels_per_radian, pixel_error, cells) {
            None => full_resolution[p / 32] |= 1 << (p % 32),
            Some(factor) => {
                let k = (factor as u32).trailing_zeros() as usize;
                *predicted = own[k] * pixels_per_radian / distance.max(f32::MIN_POSITIVE);
            }
        }
    }
    TessErrorChoice {
        full_resolution,
        predicted_px,
    }
}

/// Published parameters of the peers' LOD policies, run as they are for
/// comparison (`--lod sphere | edge-length | cdlod`, and bench rows).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeerLod {
    /// SaschaWillems/Vulkan terraintessellation
    /// (shaders/glsl/terraintessellation/terrain.tesc): an edge's bounding
    /// sphere projected to the screen, over this many pixels...
    pub sphere_edge_px: f32,
    /// ...times this factor.
    pub sphere_factor: f32,
    /// Dupuy's longest-edge-bisection terrain (jdupuy/LongestEdgeBisection2D,
    /// terrain/shaders/TerrainRenderCommon.glsl, TriangleLevelOfDetail):
    /// an edge's length on screen over this target, in pixels.
    pub edge_target_px: f32,
    /// CDLOD (fstrugar/CDLOD; Strugar, "Continuous Distance-Dependent Level
    /// of Detail for Rendering Heightmaps", 2010): each level's range twice
    /// the last, and a level starts morphing into the next this far through
    /// its range.
    pub cdlod_morph_start: f32,
}

impl Default for PeerLod {
    fn default() -> Self {
        PeerLod {
            sphere_edge_px: 20.0,
            sphere_factor: 0.75,
            edge_target_px: 7.0,
            cdlod_morph_start: 0.66,
        }
    }
}

/// The camera for the screen-space peers: its view-projection
/// (camera-relative), its right vector, and the viewport in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenParams {
    pub view_proj: glam::Mat4,
    pub right: Vec3,
    pub viewport: Vec2,
    pub pixels_per_radian: f32,
}

/// SaschaWillems's factor for the edge `a`-`b` (eye-relative): the sphere
/// around it, its diameter along the camera's right vector projected to
/// normalised device coordinates and scaled by the viewport, over
/// `sphere_edge_px`, times `sphere_factor`, clamped to [1, 64].
pub fn sphere_tess_factor(a: Vec3, b: Vec3, screen: &ScreenParams, peer: &PeerLod) -> f32 {
    let mid = 0.5 * (a + b);
    let radius = 0.5 * a.distance(b);
    let project = |p: Vec3| {
        let clip = screen.view_proj * p.extend(1.0);
        let ndc = clip / clip.w;
        Vec3::new(ndc.x * screen.viewport.x, ndc.y * screen.viewport.y, ndc.z)
    };
    let span = project(mid - radius * screen.right).distance(project(mid + radius * screen.right));
    clamp_tess_factor(span / peer.sphere_edge_px * peer.sphere_factor)
}

/// Dupuy's factor for the edge `a`-`b` (eye-relative): its length seen
/// from its centre, in pixels, over `edge_target_px` segments' worth,
/// clamped to [1, 64].
pub fn edge_length_tess_factor(a: Vec3, b: Vec3, screen: &ScreenParams, peer: &PeerLod) -> f32 {
    let distance = (0.5 * (a + b)).length().max(f32::MIN_POSITIVE);
    let pixels = a.distance(b) * screen.pixels_per_radian / distance;
    clamp_tess_factor(pixels / peer.edge_target_px)
}

/// CDLOD's factor at `rel` (eye-relative): level l covers distances up to
/// `min_dist * 2^l` (level 0 from the eye), drawn at 2^(max_exp - l) and
/// morphing into the next level over the last (1 - `cdlod_morph_start`) of
/// its range; never below 2^min_exp. Continuous in distance.
pub fn cdlod_tess_factor(rel: Vec3, lod: &DistanceLod, peer: &PeerLod) -> f32 {
    let d = rel.length();
    let r0 = lod.min_dist.max(f32::MIN_POSITIVE);
    let level = if d < r0 {
        0.0
    } else {
        (d / r0).log2().floor() + 1.0
    };
    let hi = r0 * level.exp2();
    let lo = if level == 0.0 { 0.0 } else { 0.5 * hi };
    let start = lo + peer.cdlod_morph_start * (hi - lo);
    let morph = saturate((d - start) / ((hi - start).max(f32::MIN_POSITIVE)));
    let exponent = (lod.max_exp - (level + morph)).max(lod.min_exp);
    clamp_tess_factor(exponent.exp2())
}

/// Which peer policy `patch_peer_factors` applies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PeerPolicy {
    Sphere,
    EdgeLength,
    Cdlod,
}

impl PeerPolicy {
    pub const ALL: [PeerPolicy; 3] = [
        PeerPolicy::Sphere,
        PeerPolicy::EdgeLength,
        PeerPolicy::Cdlod,
    ];

    /// Its name on the command line and in bench rows.
    pub fn name(self) -> &'static str {
        match self {
            PeerPolicy::Sphere => "sphere",
            PeerPolicy::EdgeLength => "edge-length",
            PeerPolicy::Cdlod => "cdlod",
        }
    }
}

/// Factors of one patch by a peer's policy, as its source sets them: the
/// screen-space policies per edge from its ends, the inside factors the
/// means of the edges along them; CDLOD at edge midpoints and the centre.
pub fn patch_peer_factors(
    corners: [Vec3; 4],
    policy: PeerPolicy,
    lod: &DistanceLod,
    screen: &ScreenParams,
    peer: &PeerLod,
) -> PatchTessFactors {
    let [ul, ur, ll, lr] = corners;
    let edges = patch_edges(corners).map(|(a, b)| match policy {
        PeerPolicy::Sphere => sphere_tess_factor(a, b, screen, peer),
        PeerPolicy::EdgeLength => edge_length_tess_factor(a, b, screen, peer),
        PeerPolicy::Cdlod => cdlod_tess_factor(edge_midpoint(a, b), lod, peer),
    });
    let inside = match policy {
        PeerPolicy::Cdlod => {
            let f = cdlod_tess_factor(0.25 * (ul + ur + ll + lr), lod, peer);
            [f, f]
        }
        // Inner 0 runs along u (the top and bottom edges), inner 1 along v.
        _ => [0.5 * (edges[1] + edges[3]), 0.5 * (edges[0] + edges[2])],
    };
    PatchTessFactors { edges, inside }
}
