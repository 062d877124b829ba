//! Sensor models: stereo depth noise, range limits, dropouts at depth edges, and RGB noise.

use rayon::prelude::*;
use scarp_slam::image::{DepthImage, RgbImage};
use scarp_slam::stats::standard_normal_quantile;
use serde::{Deserialize, Serialize};

use crate::noise::derive_seed;

/// A stereo depth camera and an RGB camera's noise. Depth noise follows the stereo model:
/// disparity d = f·b/z gets Gaussian noise of σ_d pixels, so σ_z ≈ z²·σ_d/(f·b).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    /// Disparity noise σ_d, pixels. Default 0.1.
    pub disparity_sigma_px: f64,
    /// Stereo baseline b, metres. Default 0.12.
    pub baseline_m: f64,
    /// Nearest measured depth, metres. Default 0.3.
    pub min_depth_m: f64,
    /// Farthest measured depth, metres. Default 30.
    pub max_depth_m: f64,
    /// Relative depth jump to a 4-neighbour that marks a depth edge. Default 0.05.
    pub edge_jump_ratio: f64,
    /// Probability that a pixel on a depth edge has no measurement. Default 0.7.
    pub edge_dropout_probability: f64,
    /// Probability that any other pixel has no measurement. Default 0.002.
    pub random_dropout_probability: f64,
    /// Gaussian RGB noise σ, 8-bit levels. Default 2.0.
    pub rgb_sigma: f64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            disparity_sigma_px: 0.1,
            baseline_m: 0.12,
            min_depth_m: 0.3,
            max_depth_m: 30.0,
            edge_jump_ratio: 0.05,
            edge_dropout_probability: 0.7,
            random_dropout_probability: 0.002,
            rgb_sigma: 2.0,
        }
    }
}

impl SensorConfig {
    /// The model's depth σ at depth `depth_m` for focal length `focal_px`: z²·σ_d/(f·b).
    pub fn depth_sigma_m(&self, depth_m: f64, focal_px: f64) -> f64 {
        depth_m * depth_m * self.disparity_sigma_px / (focal_px * self.baseline_m)
    }

    /// Applies range limits, edge and random dropouts and stereo noise to a clean depth image.
    /// Each pixel draws from its own counter-based stream (64 bits from [`derive_seed`] of the frame's seed and the pixel's index), so the result does
    /// not depend on the thread count, and a pixel's noise does not depend on the others.
    pub fn corrupt_depth(&self, depth_m: &DepthImage, focal_px: f64, seed: u64) -> DepthImage {
        let (w, h) = (depth_m.width() as usize, depth_m.height() as usize);
        let src = depth_m.as_slice();
        let fb = focal_px * self.baseline_m;
        let sigma_px = self.disparity_sigma_px.max(0.0);
        let edge_threshold = probability_threshold(self.edge_dropout_probability);
        let random_threshold = probability_threshold(self.random_dropout_probability);
        let normal = NormalQuantiles::shared();
        let mut out = src.to_vec();
        out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
            for (u, value) in row.iter_mut().enumerate() {
                let z = f64::from(src[v * w + u]);
                if !(z >= self.min_depth_m && z <= self.max_depth_m) {
                    *value = 0.0;
                    continue;
                }
                let bits = derive_seed(seed, (v * w + u) as u64);
                // Bits 48–63 decide an edge dropout, 32–47 a random one, 0–31 the noise.
                let (edge_draw, random_draw) = ((bits >> 48) as u32, (bits >> 32) as u32 & 0xffff);
                if random_draw < random_threshold {
                    *value = 0.0;
                    continue;
                }
                let neighbours = [
                    (u.wrapping_sub(1), v),
                    (u + 1, v),
                    (u, v.wrapping_sub(1)),
                    (u, v + 1),
                ];
                let on_edge = || {
                    neighbours.iter().any(|&(nu, nv)| {
                        nu < w && nv < h && {
                            let n = f64::from(src[nv * w + nu]);
                            n <= 0.0 || (n - z).abs() > self.edge_jump_ratio * z
                        }
                    })
                };
                if edge_draw < edge_threshold && on_edge() {
                    *value = 0.0;
                    continue;
                }
                let disparity_noise = sigma_px * normal.draw(bits as u32);
                let disparity = fb / z + disparity_noise;
                *value = if disparity > 0.0 {
                    (fb / disparity) as f32
                } else {
                    0.0
                };
            }
        });
        // The buffer keeps the input's size.
        DepthImage::from_vec(w as u32, h as u32, out).expect("same size as input")
    }

    /// Adds Gaussian noise of σ = `rgb_sigma` to every channel of an RGB image, rounded to whole
    /// levels and clamped to [0, 255], with per-pixel counter-based streams.
    ///
    /// Because a channel's value c is an integer, round(c + n) = c + round(n): the noise is
    /// drawn directly as the integer round(n), from a table of its quantiles at 2⁻¹⁶ steps.
    pub fn corrupt_rgb(&self, rgb: &RgbImage, seed: u64) -> RgbImage {
        let w = rgb.width() as usize;
        if !(self.rgb_sigma > 0.0) {
            return rgb.clone();
        }
        let offsets = rounded_normal_table(self.rgb_sigma);
        let seed = seed ^ RGB_NOISE_SALT;
        let mut out = rgb.as_slice().to_vec();
        out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
            for (u, pixel) in row.iter_mut().enumerate() {
                let bits = derive_seed(seed, (v * w + u) as u64);
                for (k, channel) in pixel.iter_mut().enumerate() {
                    let offset = offsets[(bits >> (16 * k)) as usize & 0xffff];
                    *channel = (i32::from(*channel) + offset).clamp(0, 255) as u8;
                }
            }
        });
        // The buffer keeps the input's size.
        RgbImage::from_vec(rgb.width(), rgb.height(), out).expect("same size as input")
    }
}

/// Mixed into the frame's seed for the RGB noise (the bytes of "grb"), so that its draws are
/// not the depth noise's.
const RGB_NOISE_SALT: u64 = 0x0067_7262;

/// The 16-bit threshold below which a uniform 16-bit draw happens with probability `p`.
fn probability_threshold(p: f64) -> u32 {
    (p.clamp(0.0, 1.0) * 65536.0).round() as u32
}

/// Standard normal draws from 32 uniform bits by inverse transform: Φ⁻¹ at the bits' cell
/// midpoint, |z| reaching 6.2 in the tails. Φ⁻¹ is tabulated at 2¹² cell boundaries and
/// interpolated linearly inside a cell by the low 20 bits (error below 10⁻³ σ); the 64 cells
/// at each end, where Φ⁻¹ curves away to infinity, are evaluated exactly (3% of draws). The
/// table costs 4097 evaluations, against one per pixel.
struct NormalQuantiles {
    boundaries: Vec<f64>,
}

impl NormalQuantiles {
    const CELL_BITS: u32 = 12;
    const EXACT_END_CELLS: usize = 64;

    /// The table, built once per process: it is the same for every frame, and building it cost
    /// a serial tenth of a millisecond or more per frame.
    fn shared() -> &'static Self {
        static TABLE: std::sync::OnceLock<NormalQuantiles> = std::sync::OnceLock::new();
        TABLE.get_or_init(Self::new)
    }

    fn new() -> Self {
        let cells = 1u32 << Self::CELL_BITS;
        Self {
            boundaries: (0..=cells)
                .map(|i| standard_normal_quantile(f64::from(i) / f64::from(cells)))
                .collect(),
        }
    }

    fn draw(&self, bits: u32) -> f64 {
        let cell = (bits >> (32 - Self::CELL_BITS)) as usize;
        let cells = self.boundaries.len() - 1;
        if cell < Self::EXACT_END_CELLS || cell >= cells - Self::EXACT_END_CELLS {
            return standard_normal_quantile((f64::from(bits) + 0.5) / 4_294_967_296.0);
        }
        let low_bits = 32 - Self::CELL_BITS;
        let fraction =
            (f64::from(bits & ((1 << low_bits) - 1)) + 0.5) / f64::from(1u32 << low_bits);
        let (a, b) = (self.boundaries[cell], self.boundaries[cell + 1]);
        a + (b - a) * fraction
    }
}

/// round(σ·Φ⁻¹(p)) at p = (i + ½)/2¹⁶ for every 16-bit i: a uniform 16-bit index gives a
/// rounded normal draw. Built from the half-integer boundaries' quantiles (a few hundred
/// evaluations), not one evaluation per entry.
fn rounded_normal_table(sigma: f64) -> Vec<i32> {
    const N: usize = 1 << 16;
    let draw = |i: usize| sigma * standard_normal_quantile((i as f64 + 0.5) / N as f64);
    let mut table = Vec::with_capacity(N);
    let mut i = 0;
    while i < N {
        let value = draw(i).round();
        // The first index whose draw rounds above `value`: draws increase with i.
        let (mut lo, mut hi) = (i, N);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if draw(mid).round() > value {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        table.resize(hi, value as i32);
        i = hi;
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measured_depth_sigma_matches_the_model() {
        let config = SensorConfig {
            random_dropout_probability: 0.0,
            ..Default::default()
        };
        let focal = 381.0;
        for z in [2.0f32, 5.0, 12.0] {
            let clean = DepthImage::filled(200, 200, z);
            let noisy = config.corrupt_depth(&clean, focal, 42);
            let values: Vec<f64> = noisy
                .as_slice()
                .iter()
                .filter(|&&d| d > 0.0)
                .map(|&d| f64::from(d))
                .collect();
            let n = values.len() as f64;
            let mean = values.iter().sum::<f64>() / n;
            let sigma = (values.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let model = config.depth_sigma_m(f64::from(z), focal);
            assert!(
                (sigma / model - 1.0).abs() < 0.1,
                "z={z}: measured {sigma}, model {model}"
            );
            // Inverting a noisy disparity biases depth by about σ_z²/z (second order).
            let expected_mean = f64::from(z) + model * model / f64::from(z);
            assert!(
                (mean - expected_mean).abs() < 4.0 * model / n.sqrt() + 1e-4,
                "z={z}: mean {mean}"
            );
        }
    }

    #[test]
    fn rgb_noise_has_the_configured_sigma_and_clamps() {
        let config = SensorConfig {
            rgb_sigma: 3.0,
            ..Default::default()
        };
        let grey = RgbImage::filled(200, 200, [100, 0, 255]);
        let noisy = config.corrupt_rgb(&grey, 7);
        let offsets: Vec<f64> = noisy
            .as_slice()
            .iter()
            .map(|p| f64::from(p[0]) - 100.0)
            .collect();
        let n = offsets.len() as f64;
        let mean = offsets.iter().sum::<f64>() / n;
        let variance = offsets.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0);
        // Rounding to whole levels adds 1/12 to the variance (Sheppard).
        let expected = (9.0f64 + 1.0 / 12.0).sqrt();
        assert!(mean.abs() < 0.05, "mean {mean}");
        assert!(
            (variance.sqrt() / expected - 1.0).abs() < 0.02,
            "σ {}",
            variance.sqrt()
        );
        // Channels at the ends of the range clamp, and half of their draws go past it.
        let at_zero = noisy.as_slice().iter().filter(|p| p[1] == 0).count() as f64 / n;
        let at_top = noisy.as_slice().iter().filter(|p| p[2] == 255).count() as f64 / n;
        assert!((at_zero - 0.566).abs() < 0.02, "{at_zero}");
        assert!((at_top - 0.566).abs() < 0.02, "{at_top}");
        assert_eq!(noisy, config.corrupt_rgb(&grey, 7));
        assert_ne!(noisy, config.corrupt_rgb(&grey, 8));
    }

    #[test]
    fn tabulated_normal_draws_match_the_exact_quantile() {
        let normal = NormalQuantiles::new();
        // Every cell, at several offsets inside it.
        for k in 0..(1u32 << 16) {
            let bits = (k << 16) | (k.wrapping_mul(40_503) & 0xffff);
            let exact = standard_normal_quantile((f64::from(bits) + 0.5) / 4_294_967_296.0);
            let drawn = normal.draw(bits);
            assert!(
                (drawn - exact).abs() < 1e-3,
                "bits {bits}: {drawn} vs {exact}"
            );
        }
        assert!(normal.draw(0) < -6.0 && normal.draw(u32::MAX) > 6.0);
    }

    #[test]
    fn the_rounded_normal_table_holds_each_integer_with_its_probability() {
        let table = rounded_normal_table(2.0);
        assert_eq!(table.len(), 1 << 16);
        assert!(table.windows(2).all(|w| w[0] <= w[1]));
        // P(round(N(0, 2)) = 0) = P(|N(0, 1)| < 0.25) = 0.19741.
        let zero = table.iter().filter(|&&k| k == 0).count() as f64 / 65536.0;
        assert!((zero - 0.19741).abs() < 1e-4, "{zero}");
        assert_eq!(table[0], -table[65535]);
    }

    /// The RGB noise as the formula states it, with no table and no bound on the offsets:
    /// round(σ·Φ⁻¹(p)) at the pixel's three 16-bit draws, added and clamped, at the default σ
    /// and at one that takes many channels past 0 and 255. (Holding the table to ±256 as i16,
    /// half the size, was tried: no faster.)
    #[test]
    fn rgb_noise_is_the_rounded_normal_formula_for_any_sigma() {
        for rgb_sigma in [2.0, 300.0] {
            let config = SensorConfig {
                rgb_sigma,
                ..Default::default()
            };
            let mut rgb = RgbImage::filled(16, 8, [0u8; 3]);
            for (i, pixel) in rgb.as_mut_slice().iter_mut().enumerate() {
                *pixel = [
                    (i * 7 % 256) as u8,
                    (i * 31 % 256) as u8,
                    (255 - i % 256) as u8,
                ];
            }
            let noisy = config.corrupt_rgb(&rgb, 9);
            for (i, (before, after)) in rgb.as_slice().iter().zip(noisy.as_slice()).enumerate() {
                let bits = derive_seed(9 ^ RGB_NOISE_SALT, i as u64);
                for k in 0..3 {
                    let p = (((bits >> (16 * k)) & 0xffff) as f64 + 0.5) / 65536.0;
                    let offset = (rgb_sigma * standard_normal_quantile(p)).round();
                    let expected = (f64::from(before[k]) + offset).clamp(0.0, 255.0) as u8;
                    assert_eq!(after[k], expected, "σ {rgb_sigma}, pixel {i}, channel {k}");
                }
            }
        }
    }

    #[test]
    fn range_limits_and_edges_drop_pixels() {
        let config = SensorConfig {
            edge_dropout_probability: 1.0,
            ..Default::default()
        };
        let mut depth = DepthImage::filled(20, 10, 5.0);
        for v in 0..10 {
            for u in 10..20 {
                *depth.get_mut(u, v).unwrap() = if u < 15 { 10.0 } else { 50.0 };
            }
        }
        let noisy = config.corrupt_depth(&depth, 381.0, 1);
        assert_eq!(*noisy.get(9, 5).unwrap(), 0.0);
        assert_eq!(*noisy.get(10, 5).unwrap(), 0.0);
        assert_eq!(*noisy.get(17, 5).unwrap(), 0.0);
        assert!(*noisy.get(5, 5).unwrap() > 0.0);
        assert_eq!(noisy, config.corrupt_depth(&depth, 381.0, 1));
    }
}
