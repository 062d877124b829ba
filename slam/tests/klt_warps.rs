//! The KLT must-show: the similarity transform of synthetic warps (shift, rotation,
//! scale) of a textured image is recovered to < 0.1 px, using the same pipeline as the box
//! tracker (corners in a box, pyramidal LK with the forward–backward check, robust fit).

use nalgebra::{Point2, Vector2};
use scarp_slam::features::{
    CornerConfig, CornerRegion, KltPyramid, MotionConfig, PixelRect, Similarity2, detect_corners,
    track_similarity,
};
use scarp_slam::image::GrayImage;

/// A smooth, corner-rich, broadband texture: plane waves of wavelengths 13–160 px (so that
/// coarse pyramid levels see structure too).
fn texture(x: f64, y: f64) -> f32 {
    // (direction in radians, wavelength px, amplitude, phase)
    let waves: [(f64, f64, f64, f64); 8] = [
        (0.3, 160.0, 0.12, 0.0),
        (1.9, 110.0, 0.10, 1.1),
        (2.7, 70.0, 0.08, 2.3),
        (0.9, 45.0, 0.06, 0.7),
        (2.2, 30.0, 0.05, 1.9),
        (1.3, 20.0, 0.04, 2.9),
        (0.1, 13.0, 0.03, 0.4),
        (2.5, 17.0, 0.03, 1.4),
    ];
    (0.5 + waves
        .iter()
        .map(|&(dir, lambda, amp, phase)| {
            let k = std::f64::consts::TAU / lambda;
            amp * (k * (dir.cos() * x + dir.sin() * y) + phase).sin()
        })
        .sum::<f64>()) as f32
}

/// The image of the texture seen through `next_from_prev`: pixel x of the warped image shows
/// the texture at `next_from_prev⁻¹ x`.
fn render(width: u32, height: u32, next_from_prev: Option<&Similarity2>) -> GrayImage {
    let inverse = next_from_prev.map(|s| {
        let m = s.matrix().try_inverse().expect("similarity is invertible");
        Similarity2 {
            a: m[(0, 0)],
            b: m[(1, 0)],
            translation: Vector2::new(m[(0, 2)], m[(1, 2)]),
        }
    });
    let data = (0..width * height)
        .map(|i| {
            let p = Point2::new(f64::from(i % width), f64::from(i / width));
            let q = inverse.map_or(p, |s| s.apply(&p));
            texture(q.x, q.y)
        })
        .collect();
    GrayImage::from_vec(width, height, data).expect("w·h pixels")
}

/// Worst error, px, of the recovered transform over the corners of the tracked box.
fn recovered_error_px(truth: &Similarity2) -> f64 {
    let (w, h) = (320, 240);
    let prev = render(w, h, None);
    let next = render(w, h, Some(truth));
    let rect = PixelRect {
        u_min: 120,
        v_min: 80,
        u_max: 200,
        v_max: 160,
    };
    let corners = detect_corners(&prev, &CornerConfig::default(), &CornerRegion::Rect(rect))
        .expect("valid config");
    assert!(corners.len() >= 15, "only {} corners", corners.len());
    let config = MotionConfig::default();
    let points: Vec<_> = corners.iter().map(|c| c.position).collect();
    let levels = config.klt.pyramid_levels;
    let fit = track_similarity(
        &KltPyramid::new(&prev, levels),
        &KltPyramid::new(&next, levels),
        &points,
        &config,
    )
    .expect("fit");
    assert!(
        fit.inlier_count() >= 10,
        "only {} inliers",
        fit.inlier_count()
    );
    [(120.0, 80.0), (200.0, 80.0), (120.0, 160.0), (200.0, 160.0)]
        .iter()
        .map(|&(x, y)| {
            let p = Point2::new(x, y);
            (fit.transform.apply(&p) - truth.apply(&p)).norm()
        })
        .fold(0.0, f64::max)
}

#[test]
fn shift_is_recovered_to_a_tenth_of_a_pixel() {
    for (dx, dy) in [(4.3, -2.7), (-11.6, 7.2), (23.4, 15.1)] {
        let truth = Similarity2::from_translation(Vector2::new(dx, dy));
        let e = recovered_error_px(&truth);
        eprintln!("{truth:?}: worst box-corner error {e:.4} px");
        assert!(e < 0.1, "shift ({dx}, {dy}): {e} px");
    }
}

#[test]
fn rotation_about_the_box_is_recovered_to_a_tenth_of_a_pixel() {
    for deg in [-4.0f64, 2.5, 6.0] {
        // Rotate about the box centre (160, 120) and shift a little.
        let r = Similarity2::from_parts(1.0, deg.to_radians(), Vector2::zeros());
        let c = Point2::new(160.0, 120.0);
        let t = c - r.apply(&c) + Vector2::new(1.5, -0.8);
        let truth = Similarity2 {
            translation: t,
            ..r
        };
        let e = recovered_error_px(&truth);
        eprintln!("{truth:?}: worst box-corner error {e:.4} px");
        assert!(e < 0.1, "rotation {deg}°: {e} px");
    }
}

#[test]
fn scale_is_recovered_to_a_tenth_of_a_pixel() {
    for scale in [0.93f64, 1.05, 1.1] {
        let s = Similarity2::from_parts(scale, 0.02, Vector2::zeros());
        let c = Point2::new(160.0, 120.0);
        let t = c - s.apply(&c) + Vector2::new(-2.0, 3.0);
        let truth = Similarity2 {
            translation: t,
            ..s
        };
        let e = recovered_error_px(&truth);
        eprintln!("{truth:?}: worst box-corner error {e:.4} px");
        assert!(e < 0.1, "scale {scale}: {e} px");
    }
}
