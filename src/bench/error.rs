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

use std::collections::BTreeMap;

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

impl<'a> DepthView<'a> {
    /// A headless frame's depth, with the view-projection it was drawn with.
    pub fn of(frame: &'a crate::render::HeadlessFrame) -> Self {
        DepthView {
            width: frame.readback.width as usize,
            height: frame.readback.height as usize,
            depth: &frame.readback.depth,
            view_proj: frame.view.view_proj.as_dmat4(),
        }
    }

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
    let errors = pixel_errors(tested, reference, pixels_per_radian);
    let mismatched = errors.iter().filter(|e| e.mismatched).count();
    let mut errors: Vec<f64> = errors.into_iter().map(|e| e.px).collect();
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

/// The error at one pixel that is terrain in either render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelError {
    /// Row-major pixel index.
    pub index: usize,
    pub px: f64,
    /// Terrain in one render and sky in the other.
    pub mismatched: bool,
}

/// The error at every pixel that is terrain in either render, in pixel
/// order.
pub fn pixel_errors(
    tested: &DepthView,
    reference: &DepthView,
    pixels_per_radian: f64,
) -> Vec<PixelError> {
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
    for i in 0..w * h {
        match (tested.position(&inv_t, i), reference.position(&inv_r, i)) {
            (Some(t), Some(r)) => errors.push(PixelError {
                index: i,
                px: (t.y - r.y).abs() * pixels_per_radian / r.length().max(f64::MIN_POSITIVE),
                mismatched: false,
            }),
            (None, None) => {}
            _ => {
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
                errors.push(PixelError {
                    index: i,
                    px: nearest,
                    mismatched: true,
                });
            }
        }
    }
    errors
}

/// Errors pooled over many frames, in logarithmic bins: max and mean are
/// exact. A coverage mismatch's error is one of a few exact values (the
/// distance between two pixel centres, or the search radius), kept
/// exactly; the others are binned, 1/1000 of a decade wide from 1e-4 px
/// up, with each bin's largest. The 99th percentile takes a bin's binned
/// errors at their largest: never below the exact value, within 0.23 %
/// above it, and exact where it falls on a mismatch's distance (a
/// silhouette moved by one whole pixel measures 1 px).
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorHistogram {
    /// Bin 0 holds errors below `SMALLEST`; bin i > 0 holds errors in
    /// [SMALLEST * 10^((i-1)/1000), SMALLEST * 10^(i/1000)). Mismatches
    /// included.
    bins: Vec<u64>,
    /// The largest error in each bin that is not a mismatch's.
    bin_max: Vec<f64>,
    /// Mismatches' errors (their bits: positive floats order as their
    /// bits) and how many of each.
    mismatch_errors: BTreeMap<u64, u64>,
    sum: f64,
    max: f64,
    mismatched: usize,
}

impl Default for ErrorHistogram {
    fn default() -> Self {
        ErrorHistogram {
            bins: vec![0; 1 + Self::DECADES * Self::PER_DECADE],
            bin_max: vec![0.0; 1 + Self::DECADES * Self::PER_DECADE],
            mismatch_errors: BTreeMap::new(),
            sum: 0.0,
            max: 0.0,
            mismatched: 0,
        }
    }
}

impl ErrorHistogram {
    const SMALLEST: f64 = 1e-4;
    const PER_DECADE: usize = 1000;
    /// Up to 1e4 px, far beyond any image: larger errors share the last bin.
    const DECADES: usize = 8;

    fn bin(&self, px: f64) -> usize {
        if px < Self::SMALLEST {
            0
        } else {
            let i = ((px / Self::SMALLEST).log10() * Self::PER_DECADE as f64) as usize + 1;
            i.min(self.bins.len() - 1)
        }
    }

    pub fn add(&mut self, errors: &[PixelError]) {
        for e in errors {
            self.sum += e.px;
            self.max = self.max.max(e.px);
            self.mismatched += usize::from(e.mismatched);
            let bin = self.bin(e.px);
            self.bins[bin] += 1;
            if e.mismatched {
                *self.mismatch_errors.entry(e.px.to_bits()).or_default() += 1;
            } else {
                self.bin_max[bin] = self.bin_max[bin].max(e.px);
            }
        }
    }

    pub fn stats(&self) -> ErrorStats {
        let pixels: u64 = self.bins.iter().sum();
        if pixels == 0 {
            return ErrorStats::default();
        }
        // The same rank as `measure`'s: the ceil(0.99 n)-th smallest.
        let rank = ((pixels as f64 * 0.99).ceil() as u64).clamp(1, pixels);
        let mut seen = 0;
        let mut p99 = self.max;
        for (i, &n) in self.bins.iter().enumerate() {
            if seen + n >= rank {
                // The bin's mismatches at their own errors, its others at
                // their largest, in order.
                let mut left = rank - seen;
                let mismatches = self
                    .mismatch_errors
                    .iter()
                    .map(|(&bits, &count)| (f64::from_bits(bits), count))
                    .filter(|&(px, _)| self.bin(px) == i);
                let binned = n - mismatches.clone().map(|(_, c)| c).sum::<u64>();
                let mut in_order: Vec<(f64, u64)> = mismatches.collect();
                in_order.push((self.bin_max[i], binned));
                in_order.sort_by(|a, b| a.0.total_cmp(&b.0));
                for (px, count) in in_order {
                    if count >= left {
                        p99 = px;
                        break;
                    }
                    left -= count;
                }
                break;
            }
            seen += n;
        }
        ErrorStats {
            max_px: self.max,
            p99_px: p99,
            mean_px: self.sum / pixels as f64,
            pixels: pixels as usize,
            mismatched: self.mismatched,
        }
    }
}

/// Pixels whose RGBA differs between two images of the same size (any
/// channel, any amount).
pub fn differing_pixels(a: &[u8], b: &[u8]) -> usize {
    a.chunks_exact(4)
        .zip(b.chunks_exact(4))
        .filter(|(p, q)| p != q)
        .count()
}

/// Pixels of background colour not connected to the image border through
/// other background pixels: holes inside the terrain's outline.
pub fn enclosed_background(
    rgba: &[u8],
    width: usize,
    height: usize,
    is_background: impl Fn(&[u8]) -> bool,
) -> Vec<(usize, usize)> {
    let bg: Vec<bool> = rgba.chunks_exact(4).map(&is_background).collect();
    let mut outside = vec![false; bg.len()];
    let mut stack: Vec<usize> = Vec::new();
    for x in 0..width {
        stack.push(x);
        stack.push((height - 1) * width + x);
    }
    for y in 0..height {
        stack.push(y * width);
        stack.push(y * width + width - 1);
    }
    while let Some(i) = stack.pop() {
        if outside[i] || !bg[i] {
            continue;
        }
        outside[i] = true;
        let (x, y) = (i % width, i / width);
        if x > 0 {
            stack.push(i - 1);
        }
        if x + 1 < width {
            stack.push(i + 1);
        }
        if y > 0 {
            stack.push(i - width);
        }
        if y + 1 < height {
            stack.push(i + width);
        }
    }
    (0..bg.len())
        .filter(|&i| bg[i] && !outside[i])
        .map(|i| (i % width, i / width))
        .collect()
}
