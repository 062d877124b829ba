//! Procedural surface albedo: a baked map for the terrain, and a solid (3D) texture for rocks and
//! pedestals, so that images carry corners and texture for tracking and photometric odometry.

use rayon::prelude::*;
use wide::{f32x4, i32x4};

use crate::noise::{derive_seed, fbm_2d, fbm_3d_of_octaves, value_noise_2d, value_noise_3d};
use crate::terrain::Heightfield;
use crate::world::TextureConfig;

/// A baked terrain albedo map over the heightfield's extent, 8-bit sRGB, from the south-west
/// corner.
///
/// Texels are stored in square tiles of 16 × 16 texels, each with the next tile's first row
/// and column as an apron, so a bilinear sample reads one tile. A frame's samples follow lines
/// across the map at any heading; row-major storage put each texel row on its own page, and the
/// renderer stalled on the texture (about a quarter of a frame).
#[derive(Debug, Clone)]
pub struct AlbedoMap {
    origin_x_m: f64,
    origin_y_m: f64,
    /// `1 / texel size`, so a sample multiplies rather than divides.
    inv_texel: f64,
    /// The largest grid coordinates a sample's lower corner may take: just inside the last
    /// cell, so the cell index needs no second clamp.
    gx_max: f64,
    gy_max: f64,
    /// Tiles along x.
    tiles_x: usize,
    /// RGB and a zero byte, 17² a tile (apron included): a texel is one 32-bit load, its channels
    /// one set of lanes.
    texels: Vec<[u8; 4]>,
}

/// Texels along a tile's side, without its apron.
const TILE: usize = 16;
/// A tile's row, apron included.
const TILE_ROW: usize = TILE + 1;
/// A tile's texels, apron included.
const TILE_TEXELS: usize = TILE_ROW * TILE_ROW;

fn mix(a: [u8; 3], b: [u8; 3], t: f32) -> [f32; 3] {
    [0, 1, 2].map(|i| f32::from(a[i]) + (f32::from(b[i]) - f32::from(a[i])) * t)
}

fn scale_color(c: [f32; 3], s: f32) -> [u8; 3] {
    c.map(|v| (v * s).clamp(0.0, 255.0) as u8)
}

fn smoothstep(lo: f32, hi: f32, x: f32) -> f32 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Terrain albedo at (x, y): sandy ground with darker patches, scattered pebbles and grain.
pub fn terrain_albedo(config: &TextureConfig, x_m: f64, y_m: f64) -> [u8; 3] {
    let seed = config.seed;
    let patches = fbm_2d(derive_seed(seed, 1), x_m, y_m, 8.0, 4);
    let base = mix(
        config.terrain_color,
        config.terrain_patch_color,
        smoothstep(0.05, 0.45, patches),
    );
    let variation = fbm_2d(
        derive_seed(seed, 2),
        x_m,
        y_m,
        config.variation_wavelength_m * 4.0,
        3,
    );
    // Pebbles: thresholded cellular-scale noise gives crisp blobs (good corners).
    let pebble = value_noise_2d(derive_seed(seed, 3), x_m / 0.12, y_m / 0.12);
    let pebble_shade = if pebble > 0.6 {
        0.55
    } else if pebble < -0.7 {
        1.25
    } else {
        1.0
    };
    let grain = value_noise_2d(
        derive_seed(seed, 4),
        x_m / config.speckle_wavelength_m,
        y_m / config.speckle_wavelength_m,
    );
    let shade =
        (1.0 + 0.25 * variation) * pebble_shade * (1.0 + config.speckle as f32 * 0.5 * grain);
    scale_color(base, shade)
}

/// The solid texture of rock and pedestal surfaces: base colour with coarse mottling,
/// lichen-dark patches and mineral grain. Its noise seeds are derived once, when it is built:
/// the renderer samples it at every rock pixel, where deriving them cost a quarter of the
/// hashing.
#[derive(Debug, Clone)]
pub struct RockTexture {
    /// The coarse mottling's two octaves.
    coarse_seeds: [u64; 2],
    grain_seed: u64,
    variation_wavelength_m: f64,
    speckle_wavelength_m: f64,
    speckle: f32,
}

impl RockTexture {
    /// The rock texture of `config`.
    pub fn new(config: &TextureConfig) -> Self {
        let seed = derive_seed(config.seed, 10);
        Self {
            coarse_seeds: [derive_seed(seed, 0), derive_seed(seed, 1)],
            // The grain shares the second octave's seed, as it always has: another seed would
            // change every rendered rock.
            grain_seed: derive_seed(seed, 1),
            variation_wavelength_m: config.variation_wavelength_m,
            speckle_wavelength_m: config.speckle_wavelength_m,
            speckle: config.speckle as f32,
        }
    }

    /// The albedo (8-bit sRGB) of a surface point (world metres) of base colour `base`.
    pub fn albedo(&self, base: [u8; 3], x_m: f64, y_m: f64, z_m: f64) -> [u8; 3] {
        let coarse = fbm_3d_of_octaves(
            self.coarse_seeds,
            x_m,
            y_m,
            z_m,
            self.variation_wavelength_m,
        );
        let s = self.speckle_wavelength_m;
        let grain = value_noise_3d(self.grain_seed, x_m / s, y_m / s, z_m / s);
        let crystal = if grain > 0.55 {
            0.45
        } else if grain < -0.6 {
            1.3
        } else {
            1.0
        };
        let shade = (1.0 + 0.3 * coarse) * (1.0 + (crystal - 1.0) * self.speckle * 2.0);
        scale_color(base.map(f32::from), shade)
    }
}

impl AlbedoMap {
    /// Bakes the terrain albedo over a heightfield's extent at `config.terrain_texel_m`.
    /// Parallel over rows; the result does not depend on the thread count.
    pub fn bake(config: &TextureConfig, heightfield: &Heightfield) -> Self {
        let (x0, y0, x1, y1) = heightfield.extent();
        let texel_m = config.terrain_texel_m.max(1e-3);
        let nx = ((x1 - x0) / texel_m).ceil() as usize + 1;
        let ny = ((y1 - y0) / texel_m).ceil() as usize + 1;
        let row_major: Vec<[u8; 4]> = (0..ny)
            .into_par_iter()
            .flat_map_iter(|j| {
                (0..nx).map(move |i| {
                    let [r, g, b] =
                        terrain_albedo(config, x0 + i as f64 * texel_m, y0 + j as f64 * texel_m);
                    [r, g, b, 0]
                })
            })
            .collect();
        // A sample's lower corner is at most (nx − 2, ny − 2), so its tile is at most that
        // corner's; apron texels beyond the map repeat its edge and are never weighted.
        let tiles_x = nx.saturating_sub(2) / TILE + 1;
        let tiles_y = ny.saturating_sub(2) / TILE + 1;
        let mut texels = vec![[0u8; 4]; tiles_x * tiles_y * TILE_TEXELS];
        texels
            .par_chunks_mut(TILE_TEXELS)
            .enumerate()
            .for_each(|(tile, out)| {
                let (ti, tj) = (tile % tiles_x, tile / tiles_x);
                for (k, texel) in out.iter_mut().enumerate() {
                    let i = (ti * TILE + k % TILE_ROW).min(nx - 1);
                    let j = (tj * TILE + k / TILE_ROW).min(ny - 1);
                    *texel = row_major[j * nx + i];
                }
            });
        Self {
            origin_x_m: x0,
            origin_y_m: y0,
            inv_texel: 1.0 / texel_m,
            gx_max: (nx - 1) as f64 - 1e-9,
            gy_max: (ny - 1) as f64 - 1e-9,
            tiles_x,
            texels,
        }
    }

    /// Bilinear albedo at (x, y), clamped to the map's edge.
    ///
    /// Runs for every terrain pixel of every rendered frame: the three channels are one set of
    /// SIMD lanes, summed corner by corner in the order of a per-channel loop, so the result is
    /// bit for bit the scalar one.
    #[inline]
    pub fn sample(&self, x_m: f64, y_m: f64) -> [f32; 3] {
        // An i32 cast is cheaper than a usize one and the maps are far smaller than 2³¹ texels
        // a side.
        let gx = ((x_m - self.origin_x_m) * self.inv_texel)
            .min(self.gx_max)
            .max(0.0);
        let gy = ((y_m - self.origin_y_m) * self.inv_texel)
            .min(self.gy_max)
            .max(0.0);
        let (i, j) = (gx as i32 as usize, gy as i32 as usize);
        let (fx, fy) = ((gx - i as f64) as f32, (gy - j as f64) as f32);
        // One slice of the tile (one bounds check) and the four corner weights once.
        let tile = (j / TILE) * self.tiles_x + i / TILE;
        let first = tile * TILE_TEXELS + (j % TILE) * TILE_ROW + i % TILE;
        let quad = &self.texels[first..first + TILE_ROW + 2];
        let (south, north) = (&quad[..2], &quad[TILE_ROW..]);
        // A texel's bytes as lanes without a scalar unpacking: each lane masks its byte in place,
        // converts (exactly: below 2²⁴) and scales back by a power of two (exactly).
        let byte_masks = i32x4::new([0xff, 0xff00, 0xff_0000, 0]);
        let byte_scales = f32x4::new([1.0, 1.0 / 256.0, 1.0 / 65536.0, 0.0]);
        let lanes = |texel: [u8; 4]| {
            f32x4::from_i32x4(i32x4::splat(i32::from_le_bytes(texel)) & byte_masks) * byte_scales
        };
        let weight = f32x4::splat;
        let out = lanes(south[0]) * weight((1.0 - fx) * (1.0 - fy))
            + lanes(south[1]) * weight(fx * (1.0 - fy))
            + lanes(north[0]) * weight((1.0 - fx) * fy)
            + lanes(north[1]) * weight(fx * fy);
        let [r, g, b, _] = out.to_array();
        [r, g, b]
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    /// A map of 59 × 44 texels: several tiles each way, neither a whole number of tiles.
    fn small_map() -> (TextureConfig, Heightfield, AlbedoMap) {
        let config = TextureConfig::default();
        let heightfield = Heightfield::flat(-3.0, 5.0, 0.1, 24, 18, 0.0).expect("heightfield");
        let map = AlbedoMap::bake(&config, &heightfield);
        (config, heightfield, map)
    }

    /// The bilinear sample as a per-channel loop over the texels evaluated where they lie.
    fn reference(
        config: &TextureConfig,
        heightfield: &Heightfield,
        x_m: f64,
        y_m: f64,
    ) -> [f32; 3] {
        let (x0, y0, x1, y1) = heightfield.extent();
        let texel_m = config.terrain_texel_m;
        let nx = ((x1 - x0) / texel_m).ceil() as usize + 1;
        let ny = ((y1 - y0) / texel_m).ceil() as usize + 1;
        let gx = ((x_m - x0) * (1.0 / texel_m))
            .min((nx - 1) as f64 - 1e-9)
            .max(0.0);
        let gy = ((y_m - y0) * (1.0 / texel_m))
            .min((ny - 1) as f64 - 1e-9)
            .max(0.0);
        let (i, j) = (gx as usize, gy as usize);
        let (fx, fy) = ((gx - i as f64) as f32, (gy - j as f64) as f32);
        let texel = |i: usize, j: usize| {
            terrain_albedo(config, x0 + i as f64 * texel_m, y0 + j as f64 * texel_m)
        };
        let corners = [
            texel(i, j),
            texel(i + 1, j),
            texel(i, j + 1),
            texel(i + 1, j + 1),
        ];
        let weights = [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ];
        let mut out = [0.0f32; 3];
        for (texel, weight) in corners.iter().zip(weights) {
            for (o, &c) in out.iter_mut().zip(texel) {
                *o += f32::from(c) * weight;
            }
        }
        out
    }

    #[test]
    fn a_sample_on_a_texel_is_that_texel() {
        let (config, _, map) = small_map();
        for (i, j) in [(0, 0), (15, 0), (16, 17), (31, 32), (57, 42)] {
            let (x, y) = (-3.0 + i as f64 * 0.04, 5.0 + j as f64 * 0.04);
            let expected = terrain_albedo(&config, x, y).map(f32::from);
            let got = map.sample(x, y);
            for c in 0..3 {
                assert!(
                    (got[c] - expected[c]).abs() < 1e-3,
                    "texel ({i}, {j}): {got:?} vs {expected:?}"
                );
            }
        }
    }

    proptest! {
        /// The tiled map samples bit for bit as the row-major bilinear sample, across tile
        /// seams, on the map's last row and column, and clamped outside it.
        #[test]
        fn tiled_samples_equal_the_row_major_bilinear_sample(
            x in -3.5f64..-0.4,
            y in 4.5f64..7.2,
        ) {
            let (config, heightfield, map) = small_map();
            let got = map.sample(x, y);
            let expected = reference(&config, &heightfield, x, y);
            prop_assert_eq!(got.map(f32::to_bits), expected.map(f32::to_bits));
        }
    }
}
