//! Screen-space error of a tested render against the reference (the brute
//! path), from the two depth buffers of the same camera.
//!
//! For a pixel where both renders show terrain, its view ray meets the
//! reference surface at R and the tested surface at T. Both lie on the same
//! ray, so they differ along it; their vertical separation |T.y - R.y| is
//! the geometric error there, and the error in pixels is that length seen
//! face-on at the reference's distance: |T.y - R.y| * K / |R - eye|, with
//! K = viewport height / (2 tan(fov / 2)). This is the same measure the LOD
//! choices bound (an error e at distance d covers e * K / d pixels), so a
//! tolerance of tau pixels and a measured error are directly comparable.
//!
//! A pixel that is terrain in one render and sky in the other is a coverage
//! mismatch: its error is the screen distance, in pixels, to the nearest
//! pixel where the tested render shows what the reference shows here (how
//! far the tested silhouette moved), searched up to `MISMATCH_RADIUS`;
//! beyond that it counts as the radius.
//!
//! Statistics are over every pixel that is terrain in either render.

use glam::{DMat4, DVec3, DVec4};

/// Furthest a silhouette is searched for, in pixels.
pub const MISMATCH_RADIUS: usize = 32;

/// Error statistics of one frame, in pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    pub max_px: f64,
    pub p99_px: f64,
    pub mean_px: f64,
    /// Pixels that are terrain in either render.
    pub pixels: usize,
    /// Pixels that are terrain in one render and sky in the other.
    pub mismatched: usize,
}

/// One render's depth with what is needed to turn it back into positions.
pub struct DepthView<'a> {
    pub width: usize,
    pub height: usize,
    /// Reversed Z: 0 is the far plane (sky).
    pub depth: &'a [f32],
    /// The camera-relative view-projection the frame was drawn with.
    pub view_proj: DMat4,
}

impl DepthView<'_> {
    /// Camera-relative position seen at pixel `i`'s centre, or None for sky.
    pub fn position(&self, inverse: &DMat4, i: usize) -> Option<DVec3> {
        let d = self.depth[i];
        if d <= 0.0 {
            return None;
        }
        let (x, y) = ((i % self.width) as f64 + 0.5, (i / self.width) as f64 + 0.5);
        let ndc = DVec4::new(
            x / self.width as f64 * 2.0 - 1.0,
            y / self.height as f64 * 2.0 - 1.0,
            f64::from(d),
            1.0,
        );
        let p = *inverse * ndc;
        Some(p.truncate() / p.w)
    }
}

/// Error of `tested` against `reference` (same camera and size);
/// `pixels_per_radian` is K above.
pub fn measure(tested: &DepthView, reference: &DepthView, pixels_per_radian: f64) -> ErrorStats {
    assert_eq!(
        (tested.width, tested.height),
        (reference.width, reference.height),
        "renders of one size"
    );
    let (w, h) = (reference.width, reference.height);
    let inv_t = tested.view_proj.inverse();
    let inv_r = reference.view_proj.inverse();
    let covered = |view: &DepthView, i: usize| view.depth[i] > 0.0;
    let mut errors = Vec::new();
    let mut mismatched = 0;
    for i in 0..w * h {
        match (tested.position(&inv_t, i), reference.position(&inv_r, i)) {
            (Some(t), Some(r)) => errors
                .push((t.y - r.y).abs() * pixels_per_radian / r.length().max(f64::MIN_POSITIVE)),
            (None, None) => {}
            _ => {
                mismatched += 1;
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                let radius = MISMATCH_RADIUS as i64;
                let want = covered(reference, i);
                let mut nearest = MISMATCH_RADIUS as f64;
                for dy in -radius..=radius {
                    for dx in -radius..=radius {
                        let (qx, qy) = (x + dx, y + dy);
                        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                            continue;
                        }
                        let q = qy as usize * w + qx as usize;
                        if covered(tested, q) == want {
                            nearest = nearest.min(((dx * dx + dy * dy) as f64).sqrt());
                        }
                    }
                }
                errors.push(nearest);
            }
        }
    }
    if errors.is_empty() {
        return ErrorStats::default();
    }
    let pixels = errors.len();
    let mean_px = errors.iter().sum::<f64>() / pixels as f64;
    errors.sort_by(f64::total_cmp);
    let p99_index = ((pixels as f64 * 0.99).ceil() as usize).clamp(1, pixels) - 1;
    ErrorStats {
        max_px: errors[pixels - 1],
        p99_px: errors[p99_index],
        mean_px,
        pixels,
        mismatched,
    }
}
