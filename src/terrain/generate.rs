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
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let wrap = |i: i64| if period > 0 { i.rem_euclid(period) } else { i };
    let grad = |i: i64, j: i64, dx: f64, dy: f64| {
        let (i, j) = (wrap(i), wrap(j));
        let mut h = seed
            ^ (i as u64).wrapping_mul(0x8CB9_2BA7_2F3D_8DD7)
            ^ (j as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h ^= h >> 31;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 29;
        let angle = (h >> 11) as f64 / (1u64 << 53) as f64 * std::f64::consts::TAU;
        angle.cos() * dx + angle.sin() * dy
    };
    // Quintic fade: continuous second derivative, no grid creases.
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

fn fbm(seed: u64, x: f64, y: f64, octaves: u32) -> f64 {
    let (mut sum, mut amp, mut freq) = (0.0, 0.5, 1.0);
    for o in 0..octaves {
        sum += amp * gradient_noise(seed.wrapping_add(u64::from(o)), x * freq, y * freq);
        freq *= 2.03;
        amp *= 0.5;
    }
    sum
}

/// Ridged multifractal: sharp crests where the noise crosses zero, with
/// finer octaves weighted by the coarser ones so ridges stay crisp.
fn ridged(seed: u64, x: f64, y: f64, octaves: u32) -> f64 {
    let (mut sum, mut amp, mut freq, mut weight) = (0.0, 0.5, 1.0, 1.0);
    for o in 0..octaves {
        let n =
            1.0 - gradient_noise(seed.wrapping_add(100 + u64::from(o)), x * freq, y * freq).abs();
        let n = n * n * weight;
        weight = (n * 2.0).clamp(0.0, 1.0);
        sum += amp * n;
        freq *= 2.1;
        amp *= 0.5;
    }
    sum
}

/// The uneroded shape, row-major, in [0, 1].
fn base_shape(size: usize, seed: u64) -> Vec<f64> {
    let mut heights: Vec<f64> = (0..size * size)
        .map(|i| {
            let (r, c) = ((i / size) as f64, (i % size) as f64);
            let (x, y) = (c / size as f64 * 4.0, r / size as f64 * 4.0);
            // Domain warp bends the features so nothing looks grid-aligned.
            let wx = x + 0.45 * fbm(seed ^ 0xA5, x * 0.7, y * 0.7, 4);
            let wy = y + 0.45 * fbm(seed ^ 0x5A, x * 0.7 + 3.1, y * 0.7 - 1.7, 4);
            let mountains = ridged(seed, wx * 0.9, wy * 0.9, 7);
            let hills = fbm(seed ^ 0x33, wx * 1.3, wy * 1.3, 7);
            // A low-frequency mask decides where mountains rise.
            let mask = (0.5 + 0.9 * fbm(seed ^ 0x77, x * 0.35, y * 0.35, 3)).clamp(0.0, 1.0);
            let mask = mask * mask * (3.0 - 2.0 * mask);
            0.25 + 0.35 * hills + 0.75 * mask * mountains
        })
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

/// Height and gradient of the bilinear surface at (x, y) in sample units.
fn height_gradient(h: &[f64], size: usize, x: f64, y: f64) -> (f64, f64, f64) {
    let (cx, cy) = (x as usize, y as usize);
    let (u, v) = (x - cx as f64, y - cy as f64);
    let i = cy * size + cx;
    let (a, b, c, d) = (h[i], h[i + 1], h[i + size], h[i + size + 1]);
    let gx = (b - a) * (1.0 - v) + (d - c) * v;
    let gy = (c - a) * (1.0 - u) + (d - b) * u;
    let height = a * (1.0 - u) * (1.0 - v) + b * u * (1.0 - v) + c * (1.0 - u) * v + d * u * v;
    (height, gx, gy)
}

/// Droplet hydraulic erosion: each drop runs downhill with inertia, picks up
/// sediment while it is fast and has capacity, and drops it where it slows.
/// Erosion is spread over a small disc so channels are smooth.
fn erode(h: &mut [f64], size: usize, droplets: u32, seed: u64) {
    const INERTIA: f64 = 0.05;
    const CAPACITY: f64 = 4.0;
    const MIN_SLOPE: f64 = 0.01;
    const DEPOSITION: f64 = 0.3;
    const EROSION: f64 = 0.3;
    const EVAPORATION: f64 = 0.015;
    const GRAVITY: f64 = 4.0;
    const MAX_STEPS: usize = 80;
    const RADIUS: i64 = 3;
    // Disc weights, normalised.
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
    // Heights are in [0, 1]; erosion works in a scaled copy where slopes
    // per sample are comparable to the constants above.
    let scale = size as f64 * 0.25;
    for v in h.iter_mut() {
        *v *= scale;
    }
    let mut rng = Rng::new(seed ^ 0xE0D);
    let limit = (size - 2) as f64;
    for _ in 0..droplets {
        let (mut x, mut y) = (rng.unit() * limit, rng.unit() * limit);
        let (mut dx, mut dy) = (0.0f64, 0.0f64);
        let (mut speed, mut water, mut sediment) = (1.0f64, 1.0f64, 0.0f64);
        for _ in 0..MAX_STEPS {
            let (cx, cy) = (x as usize, y as usize);
            let (u, v) = (x - cx as f64, y - cy as f64);
            let (height, gx, gy) = height_gradient(h, size, x, y);
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
            let (new_height, _, _) = height_gradient(h, size, nx, ny);
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
                let i = cy * size + cx;
                h[i] += amount * (1.0 - u) * (1.0 - v);
                h[i + 1] += amount * u * (1.0 - v);
                h[i + size] += amount * (1.0 - u) * v;
                h[i + size + 1] += amount * u * v;
            } else {
                let amount = ((capacity - sediment) * EROSION).min(-dh);
                for &(bx, by, w) in &brush {
                    let (px, py) = (cx as i64 + bx, cy as i64 + by);
                    if px < 0 || py < 0 || px >= size as i64 || py >= size as i64 {
                        continue;
                    }
                    let j = py as usize * size + px as usize;
                    let take = (amount * w).min(h[j].max(0.0));
                    h[j] -= take;
                    sediment += take;
                }
            }
            speed = (speed * speed + dh.abs() * GRAVITY).sqrt().min(8.0);
            water *= 1.0 - EVAPORATION;
            x = nx;
            y = ny;
        }
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
