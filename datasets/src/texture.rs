//! Procedural surface albedo: a baked map for the terrain, and a solid (3D) texture for rocks and
//! pedestals, so that images carry corners and texture for tracking and photometric odometry.

use rayon::prelude::*;

use crate::noise::{derive_seed, fbm_2d, fbm_3d, value_noise_2d, value_noise_3d};
use crate::terrain::Heightfield;
use crate::world::TextureConfig;

/// A baked terrain albedo map over the heightfield's extent, 8-bit sRGB, row-major from the
/// south-west corner.
#[derive(Debug, Clone)]
pub struct AlbedoMap {
    origin_x_m: f64,
    origin_y_m: f64,
    texel_m: f64,
    nx: usize,
    ny: usize,
    texels: Vec<[u8; 3]>,
}

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

/// Solid-texture albedo of a rock or pedestal surface point (world metres): base colour with
/// coarse mottling, lichen-dark patches and mineral grain.
pub fn rock_albedo(config: &TextureConfig, base: [u8; 3], x_m: f64, y_m: f64, z_m: f64) -> [u8; 3] {
    let seed = derive_seed(config.seed, 10);
    let coarse = fbm_3d(seed, x_m, y_m, z_m, config.variation_wavelength_m, 2);
    let s = config.speckle_wavelength_m;
    let grain = value_noise_3d(derive_seed(seed, 1), x_m / s, y_m / s, z_m / s);
    let crystal = if grain > 0.55 {
        0.45
    } else if grain < -0.6 {
        1.3
    } else {
        1.0
    };
    let shade = (1.0 + 0.3 * coarse) * (1.0 + (crystal - 1.0) * config.speckle as f32 * 2.0);
    scale_color(base.map(f32::from), shade)
}

impl AlbedoMap {
    /// Bakes the terrain albedo over a heightfield's extent at `config.terrain_texel_m`.
    /// Parallel over rows; the result does not depend on the thread count.
    pub fn bake(config: &TextureConfig, heightfield: &Heightfield) -> Self {
        let (x0, y0, x1, y1) = heightfield.extent();
        let texel_m = config.terrain_texel_m.max(1e-3);
        let nx = ((x1 - x0) / texel_m).ceil() as usize + 1;
        let ny = ((y1 - y0) / texel_m).ceil() as usize + 1;
        let texels = (0..ny)
            .into_par_iter()
            .flat_map_iter(|j| {
                (0..nx).map(move |i| {
                    terrain_albedo(config, x0 + i as f64 * texel_m, y0 + j as f64 * texel_m)
                })
            })
            .collect();
        Self {
            origin_x_m: x0,
            origin_y_m: y0,
            texel_m,
            nx,
            ny,
            texels,
        }
    }

    /// Bilinear albedo at (x, y), clamped to the map's edge.
    pub fn sample(&self, x_m: f64, y_m: f64) -> [f32; 3] {
        // Clamped just inside the last cell, so the cell index needs no second clamp; an i32
        // cast is cheaper than a usize one and the maps are far smaller than 2³¹ texels a side.
        let inv_texel = 1.0 / self.texel_m;
        let gx = ((x_m - self.origin_x_m) * inv_texel)
            .min((self.nx - 1) as f64 - 1e-9)
            .max(0.0);
        let gy = ((y_m - self.origin_y_m) * inv_texel)
            .min((self.ny - 1) as f64 - 1e-9)
            .max(0.0);
        let (i, j) = (gx as i32 as usize, gy as i32 as usize);
        let (fx, fy) = ((gx - i as f64) as f32, (gy - j as f64) as f32);
        // Runs for every terrain pixel of every frame: two row slices (two bounds checks) and
        // the four corner weights once, not per channel.
        let south = &self.texels[j * self.nx + i..j * self.nx + i + 2];
        let north = &self.texels[(j + 1) * self.nx + i..(j + 1) * self.nx + i + 2];
        let weights = [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ];
        let corners = [south[0], south[1], north[0], north[1]];
        let mut out = [0.0f32; 3];
        for (texel, weight) in corners.iter().zip(weights) {
            for (o, &c) in out.iter_mut().zip(texel) {
                *o += f32::from(c) * weight;
            }
        }
        out
    }
}
