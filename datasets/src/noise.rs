//! Deterministic value noise and fractal Brownian motion, the source of procedural terrain
//! roughness, rock shapes and surface texture.
//!
//! Lattice values come from an integer hash of the lattice point and a seed, so the same seed
//! gives the same field on every machine and thread count.

/// A 64-bit mix (SplitMix64's finaliser): a good avalanche for lattice hashing.
pub fn mix64(mut x: u64) -> u64 {
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// A seed for stream `index` derived from `seed`, for per-frame or per-row generators.
pub fn derive_seed(seed: u64, index: u64) -> u64 {
    mix64(seed ^ mix64(index.wrapping_add(0x9e37_79b9_7f4a_7c15)))
}

pub use scarp_slam::geometry::floor_i64;

fn lattice(seed: u64, x: i64, y: i64, z: i64) -> f32 {
    let h = mix64(
        seed ^ (x as u64).wrapping_mul(0x8da6_b343)
            ^ (y as u64).wrapping_mul(0xd816_3841)
            ^ (z as u64).wrapping_mul(0xcb1a_b31f),
    );
    // Top 24 bits to [-1, 1].
    (h >> 40) as f32 / (1u64 << 23) as f32 - 1.0
}

fn smooth(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// 2D value noise in [−1, 1] with quintic interpolation; one lattice cell per unit.
pub fn value_noise_2d(seed: u64, x: f64, y: f64) -> f32 {
    let (xi, yi) = (floor_i64(x), floor_i64(y));
    let (tx, ty) = (
        smooth((x - xi as f64) as f32),
        smooth((y - yi as f64) as f32),
    );
    let a = lerp(lattice(seed, xi, yi, 0), lattice(seed, xi + 1, yi, 0), tx);
    let b = lerp(
        lattice(seed, xi, yi + 1, 0),
        lattice(seed, xi + 1, yi + 1, 0),
        tx,
    );
    lerp(a, b, ty)
}

/// 3D value noise in [−1, 1] with quintic interpolation; one lattice cell per unit.
pub fn value_noise_3d(seed: u64, x: f64, y: f64, z: f64) -> f32 {
    value_noise_3d_cached(seed, x, y, z, &mut LatticeCell::default())
}

/// The lattice values at the eight corners of one cell of a 3D value-noise field: neighbouring
/// samples of a fine field (a rendered surface's pixels) mostly fall in the cell of the sample
/// before, and then reuse its corners instead of hashing them again.
#[derive(Debug, Clone, Default)]
pub struct LatticeCell {
    /// The field's seed and the cell's lower corner; `None` before the first sample.
    key: Option<(u64, [i64; 3])>,
    /// Corner (i, j, k) of the cell at index i + 2j + 4k.
    corners: [f32; 8],
}

/// [`value_noise_3d`], bit for bit, reusing `cell`'s corners when (x, y, z) falls in the same
/// cell of the same field, and caching the new cell's otherwise.
pub fn value_noise_3d_cached(seed: u64, x: f64, y: f64, z: f64, cell: &mut LatticeCell) -> f32 {
    let (xi, yi, zi) = (floor_i64(x), floor_i64(y), floor_i64(z));
    let (tx, ty, tz) = (
        smooth((x - xi as f64) as f32),
        smooth((y - yi as f64) as f32),
        smooth((z - zi as f64) as f32),
    );
    let key = (seed, [xi, yi, zi]);
    if cell.key != Some(key) {
        cell.key = Some(key);
        cell.corners = std::array::from_fn(|k| {
            let (i, j, l) = ((k & 1) as i64, ((k >> 1) & 1) as i64, (k >> 2) as i64);
            lattice(seed, xi + i, yi + j, zi + l)
        });
    }
    let c = &cell.corners;
    let plane = |base: usize| {
        let a = lerp(c[base], c[base + 1], tx);
        let b = lerp(c[base + 2], c[base + 3], tx);
        lerp(a, b, ty)
    };
    lerp(plane(0), plane(4), tz)
}

/// Fractal sum of `octaves` 2D value-noise layers, each at twice the frequency and half the
/// amplitude of the last, normalised to [−1, 1]. `wavelength` is the period of the first octave
/// in input units.
pub fn fbm_2d(seed: u64, x: f64, y: f64, wavelength: f64, octaves: u32) -> f32 {
    let (mut sum, mut amplitude, mut total, mut frequency) = (0.0, 1.0, 0.0, 1.0 / wavelength);
    for octave in 0..octaves {
        sum += amplitude
            * value_noise_2d(
                derive_seed(seed, u64::from(octave)),
                x * frequency,
                y * frequency,
            );
        total += amplitude;
        amplitude *= 0.5;
        frequency *= 2.0;
    }
    sum / total.max(f32::EPSILON)
}

/// Fractal sum of 3D value noise, as [`fbm_2d`].
pub fn fbm_3d(seed: u64, x: f64, y: f64, z: f64, wavelength: f64, octaves: u32) -> f32 {
    fbm_3d_of_octaves(
        (0..octaves).map(|octave| derive_seed(seed, u64::from(octave))),
        &mut [],
        x,
        y,
        z,
        wavelength,
    )
}

/// [`fbm_3d`] with its octaves' seeds given (`derive_seed(seed, octave)` for octave 0, 1, …), so
/// a caller sampling one field many times derives them once, and a lattice cell cached per
/// octave (see [`value_noise_3d_cached`]; octaves beyond the cells given are not cached).
pub fn fbm_3d_of_octaves(
    octave_seeds: impl IntoIterator<Item = u64>,
    cells: &mut [LatticeCell],
    x: f64,
    y: f64,
    z: f64,
    wavelength: f64,
) -> f32 {
    let (mut sum, mut amplitude, mut total, mut frequency) = (0.0, 1.0, 0.0, 1.0 / wavelength);
    for (octave, octave_seed) in octave_seeds.into_iter().enumerate() {
        let (x, y, z) = (x * frequency, y * frequency, z * frequency);
        sum += amplitude
            * match cells.get_mut(octave) {
                Some(cell) => value_noise_3d_cached(octave_seed, x, y, z, cell),
                None => value_noise_3d(octave_seed, x, y, z),
            };
        total += amplitude;
        amplitude *= 0.5;
        frequency *= 2.0;
    }
    sum / total.max(f32::EPSILON)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// A walk of nearby samples through one cached cell (staying in a cell, stepping to the
        /// next, switching fields) gives each sample's uncached value bit for bit.
        #[test]
        fn cached_samples_equal_uncached_ones(
            start in prop::array::uniform3(-40.0f64..40.0),
            steps in prop::collection::vec((prop::array::uniform3(-0.4f64..0.4), 0u64..3), 1..60),
        ) {
            let mut cell = LatticeCell::default();
            let mut p = start;
            for (step, seed) in steps {
                p = [p[0] + step[0], p[1] + step[1], p[2] + step[2]];
                let cached = value_noise_3d_cached(seed, p[0], p[1], p[2], &mut cell);
                let fresh = value_noise_3d(seed, p[0], p[1], p[2]);
                prop_assert_eq!(cached.to_bits(), fresh.to_bits());
            }
        }
    }

    #[test]
    fn noise_is_bounded_deterministic_and_continuous() {
        let mut max_abs = 0.0f32;
        for i in 0..2000 {
            let x = i as f64 * 0.137 - 50.0;
            let y = i as f64 * 0.291 - 80.0;
            let n = value_noise_2d(3, x, y);
            assert_eq!(n, value_noise_2d(3, x, y));
            max_abs = max_abs.max(n.abs());
            assert!((value_noise_2d(3, x + 1e-6, y) - n).abs() < 1e-4);
            let f = fbm_3d(5, x, y, 0.3 * x, 2.0, 4);
            assert!(f.abs() <= 1.0);
        }
        assert!(max_abs <= 1.0 && max_abs > 0.5);
        assert_ne!(value_noise_2d(3, 0.5, 0.5), value_noise_2d(4, 0.5, 0.5));
    }
}
