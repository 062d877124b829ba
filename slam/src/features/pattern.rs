//! A synthetic test pattern for the feature trackers' tests and benchmarks: a smooth,
//! corner-rich, broadband texture (plane waves of wavelengths 13–160 px), so that coarse
//! pyramid levels see structure too, and images of it shifted by known amounts.

use crate::image::GrayImage;

/// The texture's intensity at pixel `(x, y)`, around 0.5 (range about 0.02–0.98).
pub fn plane_wave_texture(x: f32, y: f32) -> f32 {
    // (direction in radians, wavelength px, amplitude, phase)
    let waves = [
        (0.3f32, 160.0f32, 0.12f32, 0.0f32),
        (1.9, 110.0, 0.10, 1.1),
        (2.7, 70.0, 0.08, 2.3),
        (0.9, 45.0, 0.06, 0.7),
        (2.2, 30.0, 0.05, 1.9),
        (1.3, 20.0, 0.04, 2.9),
        (0.1, 13.0, 0.03, 0.4),
    ];
    0.5 + waves
        .iter()
        .map(|&(dir, lambda, amp, phase)| {
            let k = std::f32::consts::TAU / lambda;
            amp * (k * (dir.cos() * x + dir.sin() * y) + phase).sin()
        })
        .sum::<f32>()
}

/// A `width × height` image whose pixel `(u, v)` is `f(u, v)`.
pub fn image_from_fn(width: u32, height: u32, f: impl Fn(f32, f32) -> f32) -> GrayImage {
    let data = (0..width * height)
        .map(|i| f((i % width) as f32, (i / width) as f32))
        .collect();
    // Invariant: exactly width · height values were generated.
    GrayImage::from_vec(width, height, data).expect("width · height pixels")
}

/// The texture shifted by `(dx, dy)` pixels: content at `x` in the unshifted image appears at
/// `x + (dx, dy)`.
pub fn shifted_texture(width: u32, height: u32, dx: f32, dy: f32) -> GrayImage {
    image_from_fn(width, height, |x, y| plane_wave_texture(x - dx, y - dy))
}
