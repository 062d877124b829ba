//! Sensor models: stereo depth noise, range limits, dropouts at depth edges, and RGB noise.

use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use scarp_slam::image::{DepthImage, RgbImage};
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
    /// Rows draw from their own seeded streams, so the result does not depend on the thread
    /// count.
    pub fn corrupt_depth(&self, depth_m: &DepthImage, focal_px: f64, seed: u64) -> DepthImage {
        let (w, h) = (depth_m.width() as usize, depth_m.height() as usize);
        let src = depth_m.as_slice();
        let fb = focal_px * self.baseline_m;
        let normal = Normal::new(0.0, self.disparity_sigma_px.max(0.0)).ok();
        let mut out = src.to_vec();
        out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(derive_seed(seed, v as u64));
            for (u, value) in row.iter_mut().enumerate() {
                let z = f64::from(src[v * w + u]);
                // Draw every random number for every pixel so streams stay aligned.
                let (edge_draw, random_draw) = (rng.random::<f64>(), rng.random::<f64>());
                let disparity_noise = normal.map_or(0.0, |n| n.sample(&mut rng));
                if !(z >= self.min_depth_m && z <= self.max_depth_m) {
                    *value = 0.0;
                    continue;
                }
                let neighbours = [
                    (u.wrapping_sub(1), v),
                    (u + 1, v),
                    (u, v.wrapping_sub(1)),
                    (u, v + 1),
                ];
                let on_edge = neighbours.iter().any(|&(nu, nv)| {
                    nu < w && nv < h && {
                        let n = f64::from(src[nv * w + nu]);
                        n <= 0.0 || (n - z).abs() > self.edge_jump_ratio * z
                    }
                });
                if (on_edge && edge_draw < self.edge_dropout_probability)
                    || random_draw < self.random_dropout_probability
                {
                    *value = 0.0;
                    continue;
                }
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

    /// Adds Gaussian noise to every channel of an RGB image, per-row seeded.
    pub fn corrupt_rgb(&self, rgb: &RgbImage, seed: u64) -> RgbImage {
        let w = rgb.width() as usize;
        let Ok(normal) = Normal::new(0.0f32, self.rgb_sigma.max(0.0) as f32) else {
            return rgb.clone();
        };
        let mut out = rgb.as_slice().to_vec();
        out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
            let mut rng =
                Xoshiro256PlusPlus::seed_from_u64(derive_seed(seed ^ 0x0067_7262, v as u64));
            for pixel in row {
                *pixel = pixel.map(|c| {
                    (f32::from(c) + normal.sample(&mut rng))
                        .round()
                        .clamp(0.0, 255.0) as u8
                });
            }
        });
        // The buffer keeps the input's size.
        RgbImage::from_vec(rgb.width(), rgb.height(), out).expect("same size as input")
    }
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
