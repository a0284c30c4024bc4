//! The generator of the default heightmap: fractal gradient noise with
//! ridges and domain warping for the shape, then droplet hydraulic erosion
//! for valleys and drainage. Deterministic for a given size, seed and
//! droplet count (one thread, a fixed PRNG), so the committed asset can be
//! rebuilt bit for bit with `vkterrain generate`.

use super::error::HeightmapError;
use super::heightmap::Heightmap;

/// Parameters of `generate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneratorParams {
    pub size: usize,
    pub seed: u64,
    /// Raindrops simulated by the erosion pass (0: none).
    pub droplets: u32,
}

impl Default for GeneratorParams {
    fn default() -> Self {
        GeneratorParams {
            size: 1025,
            seed: 7,
            droplets: 250_000,
        }
    }
}

/// A small, fast PRNG (xorshift64*); quality is ample for terrain.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Gradient noise on the integer lattice, in about [-1, 1].
fn gradient_noise(seed: u64, x: f64, y: f64) -> f64 {
    periodic_noise(seed, x, y, 0)
}

/// Gradient noise that repeats every `period` lattice cells in x and y
/// (0: never), in about [-1, 1]. Tileable textures use a period that
/// divides their size.
pub(crate) fn periodic_noise(seed: u64, x: f64, y: f64, period: i64) -> f64 {
    let wrap = |i: i64| if period > 0 { i.rem_euclid(period) } else { i };
    lattice_noise(x, y, |i, j, dx, dy| {
        let angle = (lattice_hash(seed, wrap(i), wrap(j)) >> 11) as f64 / (1u64 << 53) as f64
            * std::f64::consts::TAU;
        angle.cos() * dx + angle.sin() * dy
    })
}

/// The hash that picks a lattice point's gradient.
#[inline]
fn lattice_hash(seed: u64, i: i64, j: i64) -> u64 {
    let mut h = seed
        ^ (i as u64).wrapping_mul(0x8CB9_2BA7_2F3D_8DD7)
        ^ (j as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    h ^= h >> 31;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 29;
    h
}

/// Gradient noise at (x, y): `grad(i, j, dx, dy)` is lattice point
/// (i, j)'s gradient dotted with the offset from it, blended over the
/// cell with a quintic fade (continuous second derivative, no grid
/// creases); in about [-1, 1].
#[inline]
fn lattice_noise(x: f64, y: f64, grad: impl Fn(i64, i64, f64, f64) -> f64) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v) = (fade(fx), fade(fy));
    let a = grad(ix, iy, fx, fy);
    let b = grad(ix + 1, iy, fx - 1.0, fy);
    let c = grad(ix, iy + 1, fx, fy - 1.0);
    let d = grad(ix + 1, iy + 1, fx - 1.0, fy - 1.0);
    let top = a + u * (b - a);
    let bottom = c + u * (d - c);
    (top + v * (bottom - top)) * std::f64::consts::SQRT_2
}

fn fbm_with(noise: fn(u64, f64, f64) -> f64, seed: u64, x: f64, y: f64, octaves: u32) -> f64 {
    let (mut sum, mut amp, mut freq) = (0.0, 0.5, 1.0);
    for o in 0..octaves {
        sum += amp * noise(seed.wrapping_add(u64::from(o)), x * freq, y * freq);
        freq *= 2.03;
        amp *= 0.5;
    }
    sum
}

/// Ridged multifractal: sharp crests where the noise crosses zero, with
/// finer octaves weighted by the coarser ones so ridges stay crisp.
fn ridged_with(noise: fn(u64, f64, f64) -> f64, seed: u64, x: f64, y: f64, octaves: u32) -> f64 {
    let (mut sum, mut amp, mut freq, mut weight) = (0.0, 0.5, 1.0, 1.0);
    for o in 0..octaves {
        let n = 1.0 - noise(seed.wrapping_add(100 + u64::from(o)), x * freq, y * freq).abs();
        let n = n * n * weight;
        weight = (n * 2.0).clamp(0.0, 1.0);
        sum += amp * n;
        freq *= 2.1;
        amp *= 0.5;
    }
    sum
}

/// The uneroded shape at sample (r, c) of a `size` x `size` terrain, not
/// yet normalised, with `noise` as the gradient noise.
#[inline]
fn shape_at(noise: fn(u64, f64, f64) -> f64, size: usize, seed: u64, r: usize, c: usize) -> f64 {
    let (x, y) = (c as f64 / size as f64 * 4.0, r as f64 / size as f64 * 4.0);
    let fbm = |seed: u64, x: f64, y: f64, octaves: u32| fbm_with(noise, seed, x, y, octaves);
    // Domain warp bends the features so nothing looks grid-aligned.
    let wx = x + 0.45 * fbm(seed ^ 0xA5, x * 0.7, y * 0.7, 4);
    let wy = y + 0.45 * fbm(seed ^ 0x5A, x * 0.7 + 3.1, y * 0.7 - 1.7, 4);
    let mountains = ridged_with(noise, seed, wx * 0.9, wy * 0.9, 7);
    let hills = fbm(seed ^ 0x33, wx * 1.3, wy * 1.3, 7);
    // A low-frequency mask decides where mountains rise.
    let mask = (0.5 + 0.9 * fbm(seed ^ 0x77, x * 0.35, y * 0.35, 3)).clamp(0.0, 1.0);
    let mask = mask * mask * (3.0 - 2.0 * mask);
    0.25 + 0.35 * hills + 0.75 * mask * mountains
}

/// The uneroded shape, row-major, in [0, 1].
fn base_shape(size: usize, seed: u64) -> Vec<f64> {
    let mut heights: Vec<f64> = (0..size * size)
        .map(|i| shape_at(gradient_noise, size, seed, i / size, i % size))
        .collect();
    normalize(&mut heights);
    heights
}

fn normalize(heights: &mut [f64]) {
    let lo = heights.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    for h in heights {
        *h = (*h - lo) / span;
    }
}

// Droplet constants: see `erode`.
const INERTIA: f64 = 0.05;
const CAPACITY: f64 = 4.0;
const MIN_SLOPE: f64 = 0.01;
const DEPOSITION: f64 = 0.3;
const EROSION: f64 = 0.3;
const EVAPORATION: f64 = 0.015;
const GRAVITY: f64 = 4.0;
const MAX_STEPS: usize = 80;
const RADIUS: i64 = 3;

/// The erosion brush: offsets in a disc and their weights, normalised.
fn brush() -> Vec<(i64, i64, f64)> {
    let mut brush: Vec<(i64, i64, f64)> = Vec::new();
    for dy in -RADIUS..=RADIUS {
        for dx in -RADIUS..=RADIUS {
            let d = ((dx * dx + dy * dy) as f64).sqrt();
            if d <= RADIUS as f64 {
                brush.push((dx, dy, 1.0 - d / RADIUS as f64));
            }
        }
    }
    let total: f64 = brush.iter().map(|b| b.2).sum();
    for b in &mut brush {
        b.2 /= total;
    }
    brush
}

/// Heights a droplet reads and changes, by global (row, column).
trait Field {
    fn at(&mut self, row: usize, col: usize) -> &mut f64;
}

/// A whole map, row-major.
struct WholeField<'a> {
    h: &'a mut [f64],
    size: usize,
}

impl Field for WholeField<'_> {
    #[inline]
    fn at(&mut self, row: usize, col: usize) -> &mut f64 {
        &mut self.h[row * self.size + col]
    }
}

/// Height and gradient of the bilinear surface at (x, y) in sample units.
fn height_gradient(h: &mut dyn Field, x: f64, y: f64) -> (f64, f64, f64) {
    let (cx, cy) = (x as usize, y as usize);
    let (u, v) = (x - cx as f64, y - cy as f64);
    let (a, b) = (*h.at(cy, cx), *h.at(cy, cx + 1));
    let (c, d) = (*h.at(cy + 1, cx), *h.at(cy + 1, cx + 1));
    let gx = (b - a) * (1.0 - v) + (d - c) * v;
    let gy = (c - a) * (1.0 - u) + (d - b) * u;
    let height = a * (1.0 - u) * (1.0 - v) + b * u * (1.0 - v) + c * (1.0 - u) * v + d * u * v;
    (height, gx, gy)
}

/// Rows a droplet starting on row `y` can read or change: it moves at
/// most one sample a step, and its brush reaches `RADIUS` further.
const DROPLET_REACH: usize = MAX_STEPS + RADIUS as usize + 2;

/// One droplet from (x, y) on a `size`-wide field of scaled heights: it
/// runs downhill with inertia, picks up sediment while it is fast and has
/// capacity, and drops it where it slows. Erosion is spread over the
/// brush so channels are smooth.
fn run_droplet(h: &mut dyn Field, size: usize, brush: &[(i64, i64, f64)], mut x: f64, mut y: f64) {
    let limit = (size - 2) as f64;
    let (mut dx, mut dy) = (0.0f64, 0.0f64);
    let (mut speed, mut water, mut sediment) = (1.0f64, 1.0f64, 0.0f64);
    for _ in 0..MAX_STEPS {
        let (cx, cy) = (x as usize, y as usize);
        let (u, v) = (x - cx as f64, y - cy as f64);
        let (height, gx, gy) = height_gradient(h, x, y);
        dx = dx * INERTIA - gx * (1.0 - INERTIA);
        dy = dy * INERTIA - gy * (1.0 - INERTIA);
        let len = (dx * dx + dy * dy).sqrt();
        if len < 1e-12 {
            break;
        }
        dx /= len;
        dy /= len;
        let (nx, ny) = (x + dx, y + dy);
        if !(0.0..limit).contains(&nx) || !(0.0..limit).contains(&ny) {
            break;
        }
        let (new_height, _, _) = height_gradient(h, nx, ny);
        let dh = new_height - height;
        let capacity = (-dh).max(MIN_SLOPE) * speed * water * CAPACITY;
        if sediment > capacity || dh > 0.0 {
            // Uphill: fill the pit behind us (never above the step);
            // otherwise drop a share of the excess. Bilinear deposit.
            let amount = if dh > 0.0 {
                dh.min(sediment)
            } else {
                (sediment - capacity) * DEPOSITION
            };
            sediment -= amount;
            *h.at(cy, cx) += amount * (1.0 - u) * (1.0 - v);
            *h.at(cy, cx + 1) += amount * u * (1.0 - v);
            *h.at(cy + 1, cx) += amount * (1.0 - u) * v;
            *h.at(cy + 1, cx + 1) += amount * u * v;
        } else {
            let amount = ((capacity - sediment) * EROSION).min(-dh);
            for &(bx, by, w) in brush {
                let (px, py) = (cx as i64 + bx, cy as i64 + by);
                if px < 0 || py < 0 || px >= size as i64 || py >= size as i64 {
                    continue;
                }
                let cell = h.at(py as usize, px as usize);
                let take = (amount * w).min(cell.max(0.0));
                *cell -= take;
                sediment += take;
            }
        }
        speed = (speed * speed + dh.abs() * GRAVITY).sqrt().min(8.0);
        water *= 1.0 - EVAPORATION;
        x = nx;
        y = ny;
    }
}

/// Heights are in [0, 1]; erosion works in a scaled copy where slopes per
/// sample are comparable to the droplet constants.
fn erosion_scale(size: usize) -> f64 {
    size as f64 * 0.25
}

/// Droplet hydraulic erosion of a whole map (`run_droplet`), droplets
/// seeded uniformly from one PRNG.
fn erode(h: &mut [f64], size: usize, droplets: u32, seed: u64) {
    let brush = brush();
    let scale = erosion_scale(size);
    for v in h.iter_mut() {
        *v *= scale;
    }
    let mut rng = Rng::new(seed ^ 0xE0D);
    let limit = (size - 2) as f64;
    let mut field = WholeField { h, size };
    for _ in 0..droplets {
        let (x, y) = (rng.unit() * limit, rng.unit() * limit);
        run_droplet(&mut field, size, &brush, x, y);
    }
    for v in h.iter_mut() {
        *v /= scale;
    }
}

/// Heights in [0, 1] of a `size` x `size` terrain.
pub fn generate(params: &GeneratorParams) -> Result<Heightmap, HeightmapError> {
    let size = params.size;
    if size < 2 {
        return Heightmap::from_heights(size, size, vec![0.0; size * size]);
    }
    let mut h = base_shape(size, params.seed);
    if size >= 4 {
        erode(&mut h, size, params.droplets, params.seed);
    }
    normalize(&mut h);
    Heightmap::from_heights(size, size, h.into_iter().map(|v| v as f32).collect())
}

/// Quantises heights in [0, 1] to 16 bits and writes a grayscale PNG.
pub fn write_png16(map: &Heightmap, path: &std::path::Path) -> Result<(), image::ImageError> {
    let pixels: Vec<u16> = map
        .heights()
        .iter()
        .map(|&h| (f64::from(h.clamp(0.0, 1.0)) * 65535.0).round() as u16)
        .collect();
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(
        map.width() as u32,
        map.depth() as u32,
        pixels,
    )
    .expect("pixel count matches the size");
    img.save_with_format(path, image::ImageFormat::Png)
}

/// Sizes up to this are generated whole; larger ones a band of rows at a
/// time (`BandedRows`).
pub const WHOLE_MAX_SIZE: usize = 8193;

/// Erosion droplets per sample of the banded generator: about a tenth of
/// the whole generator's default density, so a 32769^2 map erodes in
/// minutes on two cores.
pub const BANDED_DROPLETS_PER_SAMPLE: f64 = 0.02;

/// Rows seeded with droplets together in the banded generator.
const BAND_ROWS: usize = 256;

/// Gradient noise like `gradient_noise`, with each lattice point's
/// gradient taken from a table of 256 directions by the same hash instead
/// of computed with a sine and a cosine: a few times faster, for maps too
/// large to generate whole.
fn table_noise(seed: u64, x: f64, y: f64) -> f64 {
    static TABLE: std::sync::OnceLock<[(f64, f64); 256]> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        std::array::from_fn(|i| {
            let a = (i as f64 + 0.5) / 256.0 * std::f64::consts::TAU;
            (a.cos(), a.sin())
        })
    });
    lattice_noise(x, y, |i, j, dx, dy| {
        let (gx, gy) = table[(lattice_hash(seed, i, j) >> 56) as usize];
        gx * dx + gy * dy
    })
}

/// Rows of the banded generator in memory, by global row.
struct BandField<'a> {
    rows: &'a mut std::collections::VecDeque<Vec<f64>>,
    start: usize,
}

impl Field for BandField<'_> {
    #[inline]
    fn at(&mut self, row: usize, col: usize) -> &mut f64 {
        &mut self.rows[row - self.start][col]
    }
}

/// A generated terrain too large to hold whole, made a row at a time: the
/// same shape as `generate` (with `table_noise`), normalised by its range
/// over a subsampled grid and clamped to [0, 1], then eroded by droplets
/// seeded a band of rows at a time. A droplet changes rows at most
/// `DROPLET_REACH` from where it starts, so a row is final, and handed
/// out, once every band that could reach it has run: the map is the same
/// as eroding it whole with the droplets in that order, with no seams,
/// while only a band and its reach are in memory. Heights are quantised to
/// 16 bits like `write_png16` and mapped to `height_scale * q / 65535`.
pub struct BandedRows {
    size: usize,
    seed: u64,
    droplets_per_sample: f64,
    range: (f64, f64),
    rows: std::collections::VecDeque<Vec<f64>>,
    /// Global row of `rows[0]`.
    start: usize,
    /// Rows whose droplets have run.
    seeded: usize,
    brush: Vec<(i64, i64, f64)>,
    mapping: super::tiled::IntegerMapping,
}

impl BandedRows {
    pub fn new(size: usize, seed: u64, droplets_per_sample: f64, height_scale: f64) -> Self {
        // The shape's range on a grid of about 1024^2 samples.
        let step = (size / 1024).max(1);
        let grid: Vec<usize> = (0..size).step_by(step).chain([size - 1]).collect();
        use rayon::prelude::*;
        let range = grid
            .par_iter()
            .map(|&r| {
                grid.iter()
                    .map(|&c| shape_at(table_noise, size, seed, r, c))
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                        (lo.min(v), hi.max(v))
                    })
            })
            .reduce(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        BandedRows {
            size,
            seed,
            droplets_per_sample,
            range,
            rows: std::collections::VecDeque::new(),
            start: 0,
            seeded: 0,
            brush: brush(),
            mapping: super::tiled::IntegerMapping {
                scale: height_scale,
                divisor: 65535.0,
                offset: 0.0,
            },
        }
    }

    /// Computes the shape of rows up to `end` (exclusive), scaled for
    /// erosion.
    fn compute_rows(&mut self, end: usize) {
        use rayon::prelude::*;
        let from = self.start + self.rows.len();
        if end <= from {
            return;
        }
        let (size, seed) = (self.size, self.seed);
        let (lo, hi) = self.range;
        let span = (hi - lo).max(f64::MIN_POSITIVE);
        let scale = erosion_scale(size);
        let new: Vec<Vec<f64>> = (from..end)
            .into_par_iter()
            .map(|r| {
                (0..size)
                    .map(|c| {
                        let v = (shape_at(table_noise, size, seed, r, c) - lo) / span;
                        v.clamp(0.0, 1.0) * scale
                    })
                    .collect()
            })
            .collect();
        self.rows.extend(new);
    }

    /// Runs the droplets of the next band of rows.
    fn seed_band(&mut self) {
        let size = self.size;
        let limit = (size - 2) as f64;
        let (a, b) = (self.seeded, (self.seeded + BAND_ROWS).min(size));
        self.compute_rows((b + DROPLET_REACH + 1).min(size));
        let top = (b as f64).min(limit);
        if top > a as f64 {
            let count = (self.droplets_per_sample * (top - a as f64) * limit).round() as u64;
            let band = (a / BAND_ROWS) as u64;
            let mut rng = Rng::new(self.seed ^ 0xE0D ^ band.wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let mut field = BandField {
                rows: &mut self.rows,
                start: self.start,
            };
            for _ in 0..count {
                let x = rng.unit() * limit;
                let y = a as f64 + rng.unit() * (top - a as f64);
                run_droplet(&mut field, size, &self.brush, x, y);
            }
        }
        self.seeded = b;
    }
}

impl super::tiled::RowSource for BandedRows {
    fn width(&self) -> usize {
        self.size
    }
    fn depth(&self) -> usize {
        self.size
    }
    fn read_row(&mut self, out: &mut [f32]) -> Result<(), super::tiled::TiledError> {
        let r = self.start;
        // Droplets starting below row r + DROPLET_REACH cannot reach it.
        while self.seeded < (r + DROPLET_REACH + 1).min(self.size) {
            self.seed_band();
        }
        self.compute_rows(r + 1);
        let row = self.rows.pop_front().expect("row computed");
        self.start += 1;
        let scale = erosion_scale(self.size);
        for (o, &v) in out.iter_mut().zip(&row) {
            let q = ((v / scale).clamp(0.0, 1.0) * 65535.0).round() as i64;
            *o = self.mapping.height(q);
        }
        Ok(())
    }
    fn mapping(&self) -> Option<super::tiled::IntegerMapping> {
        Some(self.mapping)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::tiled::RowSource;

    /// The committed default heightmap is what `vkterrain generate` makes
    /// with its default parameters, bit for bit.
    #[test]
    fn the_default_heightmap_is_rebuilt_exactly() {
        let asset = Heightmap::from_bytes(
            include_bytes!("../../assets/heightmaps/default.png"),
            crate::terrain::HeightmapFormat::Png,
            &crate::terrain::LoadOptions::default(),
            std::path::Path::new("default.png"),
        )
        .unwrap();
        let made = generate(&GeneratorParams::default()).unwrap();
        let quantised: Vec<f32> = made
            .heights()
            .iter()
            .map(|&h| ((f64::from(h.clamp(0.0, 1.0)) * 65535.0).round() / 65535.0) as f32)
            .collect();
        assert_eq!(asset.heights(), quantised.as_slice());
    }

    /// The banded generator hands out exactly the map that eroding the
    /// whole of it, with the same droplets in the same order, gives: no
    /// seams between bands, nothing lost at a band's edge.
    #[test]
    fn banded_rows_equal_whole_erosion_with_the_same_droplets() {
        let (size, seed, density) = (700, 11, 0.05);
        let mut banded = BandedRows::new(size, seed, density, 1000.0);
        let mut got = vec![0.0f32; size * size];
        for row in got.chunks_exact_mut(size) {
            banded.read_row(row).unwrap();
        }

        let (lo, hi) = banded.range;
        let scale = erosion_scale(size);
        let mut h: Vec<f64> = (0..size * size)
            .map(|i| {
                let v = (shape_at(table_noise, size, seed, i / size, i % size) - lo) / (hi - lo);
                v.clamp(0.0, 1.0) * scale
            })
            .collect();
        let brush = brush();
        let limit = (size - 2) as f64;
        let mut field = WholeField { h: &mut h, size };
        let mut droplets = 0;
        for a in (0..size).step_by(BAND_ROWS) {
            let top = ((a + BAND_ROWS).min(size) as f64).min(limit);
            let count = (density * (top - a as f64) * limit).round() as u64;
            let band = (a / BAND_ROWS) as u64;
            let mut rng = Rng::new(seed ^ 0xE0D ^ band.wrapping_mul(0x9E37_79B9_7F4A_7C15));
            for _ in 0..count {
                let x = rng.unit() * limit;
                let y = a as f64 + rng.unit() * (top - a as f64);
                run_droplet(&mut field, size, &brush, x, y);
                droplets += 1;
            }
        }
        // 0.05 a sample over 698 columns, bands of 256, 256 and 186 rows.
        assert_eq!(droplets, 8934 + 8934 + 6491);
        let mapping = banded.mapping;
        for (i, (&g, &e)) in got.iter().zip(&h).enumerate() {
            let q = ((e / scale).clamp(0.0, 1.0) * 65535.0).round() as i64;
            assert_eq!(g, mapping.height(q), "sample ({}, {})", i / size, i % size);
        }
        // Erosion did something: the map differs from its uneroded shape.
        let uneroded = (0..size * size)
            .filter(|&i| {
                let v = (shape_at(table_noise, size, seed, i / size, i % size) - lo) / (hi - lo);
                let q = (v.clamp(0.0, 1.0) * 65535.0).round() as i64;
                mapping.height(q) != got[i]
            })
            .count();
        assert!(uneroded > size * size / 20, "{uneroded} samples eroded");
    }
}
