//! Pyramidal Lucas–Kanade point tracking (Bouguet's scheme) with a forward–backward check.
//!
//! Each point is tracked coarse to fine. At every level a square template window is sampled
//! bilinearly around the point in the previous image; its gradients give the 2×2 normal matrix
//! once per level (the inverse-compositional trick for pure translation), and Gauss–Newton
//! steps move the displacement until the step is below `convergence_px` or `max_iterations`
//! is reached. The result at one level, doubled, seeds the next finer one.
//!
//! The forward–backward check tracks the result back into the previous image; a point whose
//! round trip misses its start by more than `max_forward_backward_px` is rejected (occlusion,
//! repeated texture, garbage).
//!
//! Points are independent, so they run in parallel with rayon; the output is identical for
//! any thread count.

use nalgebra::{Matrix2, Point2, Vector2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::FeatureError;
use crate::image::{GrayImage, downsample_gray};

/// Lucas–Kanade parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KltConfig {
    /// Side of the square window, px (odd). Default 25, the paper's window.
    pub window_px: u32,
    /// Gauss–Newton iterations per level. Default 15, as in the paper.
    pub max_iterations: u32,
    /// Pyramid levels including the full image. Default 4: with a 25 px window this follows
    /// motions up to about 12·2³ ≈ 100 px.
    pub pyramid_levels: usize,
    /// Stop iterating when a step is shorter than this, px. Default 0.01.
    pub convergence_px: f32,
    /// Reject a window whose normal matrix has a smaller eigenvalue below this, per window
    /// pixel, in squared intensity gradient per pixel. Default 1e-6 for `[0, 1]` images
    /// (untextured windows cannot be tracked).
    pub min_eigenvalue: f32,
    /// Reject a track whose mean absolute intensity residual over the final window exceeds
    /// this. Default 0.1 (a tenth of the `[0, 1]` range).
    pub max_mean_residual: f32,
    /// Reject a track whose forward–backward round trip misses its start by more than this,
    /// px; `None` disables the check. Default 0.5 px.
    pub max_forward_backward_px: Option<f32>,
}

impl Default for KltConfig {
    fn default() -> Self {
        Self {
            window_px: 25,
            max_iterations: 15,
            pyramid_levels: 4,
            convergence_px: 0.01,
            min_eigenvalue: 1e-6,
            max_mean_residual: 0.1,
            max_forward_backward_px: Some(0.5),
        }
    }
}

impl KltConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`FeatureError::InvalidConfig`] naming the field.
    pub fn validate(&self) -> Result<(), FeatureError> {
        let bad = |field, reason| Err(FeatureError::InvalidConfig { field, reason });
        if self.window_px < 3 || self.window_px.is_multiple_of(2) || self.window_px > 101 {
            return bad("window_px", "must be odd and in 3..=101");
        }
        if self.max_iterations == 0 {
            return bad("max_iterations", "must be at least 1");
        }
        if self.pyramid_levels == 0 || self.pyramid_levels > 10 {
            return bad("pyramid_levels", "must be in 1..=10");
        }
        if !(self.convergence_px.is_finite() && self.convergence_px > 0.0) {
            return bad("convergence_px", "must be finite and > 0");
        }
        if !(self.min_eigenvalue.is_finite() && self.min_eigenvalue >= 0.0) {
            return bad("min_eigenvalue", "must be finite and ≥ 0");
        }
        if !(self.max_mean_residual > 0.0) {
            return bad("max_mean_residual", "must be > 0");
        }
        if let Some(fb) = self.max_forward_backward_px
            && !(fb.is_finite() && fb > 0.0)
        {
            return bad("max_forward_backward_px", "must be finite and > 0");
        }
        Ok(())
    }
}

/// An intensity pyramid for tracking: level 0 is the image, level k is halved k times (a
/// `[1, 2, 1]` blur, then 2×2 averages, so coarse pixel centre `u` sits at fine `2u + 0.5`).
#[derive(Debug, Clone)]
pub struct KltPyramid {
    levels: Vec<GrayImage>,
}

impl KltPyramid {
    /// Builds `levels` levels (at least 1; fewer when the image becomes smaller than 2×2).
    pub fn new(gray: &GrayImage, levels: usize) -> Self {
        let mut out = vec![gray.clone()];
        while out.len() < levels.max(1) {
            let last = &out[out.len() - 1];
            if last.width() < 4 || last.height() < 4 {
                break;
            }
            let next = downsample_gray(&smoothed(last));
            out.push(next);
        }
        Self { levels: out }
    }

    /// Number of levels.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// The image at `level` (0 = full resolution), or `None` past the last level.
    pub fn level(&self, level: usize) -> Option<&GrayImage> {
        self.levels.get(level)
    }

    /// The full-resolution image (level 0, which always exists).
    pub fn base(&self) -> &GrayImage {
        &self.levels[0]
    }

    /// Width and height of the full-resolution image, px.
    pub fn size(&self) -> (u32, u32) {
        (self.levels[0].width(), self.levels[0].height())
    }
}

/// The image blurred by the separable `[1, 2, 1]/4` kernel (edges replicated), so that the
/// 2×2 averages of the next level do not alias fine texture. The kernel is centred, so the
/// pyramid geometry is unchanged.
fn smoothed(image: &GrayImage) -> GrayImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let src = image.as_slice();
    let mut rows = vec![0.0f32; w * h];
    for v in 0..h {
        let r = &src[v * w..(v + 1) * w];
        for u in 0..w {
            let (l, c, rt) = (r[u.saturating_sub(1)], r[u], r[(u + 1).min(w - 1)]);
            rows[v * w + u] = 0.25 * (l + rt) + 0.5 * c;
        }
    }
    let mut out = vec![0.0f32; w * h];
    for v in 0..h {
        let (up, down) = (v.saturating_sub(1), (v + 1).min(h - 1));
        for u in 0..w {
            out[v * w + u] = 0.25 * (rows[up * w + u] + rows[down * w + u]) + 0.5 * rows[v * w + u];
        }
    }
    // Same size as the input, so the length is w·h.
    GrayImage::from_vec(image.width(), image.height(), out).expect("w·h pixels")
}

/// The outcome of tracking one point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KltStatus {
    /// Tracked and passed every check.
    Tracked,
    /// The point (or its window) left the image, or the input point was not finite.
    OutOfImage,
    /// The window has too little texture (small eigenvalue of the normal matrix).
    Untextured,
    /// The final window does not match the template (mean residual too large).
    LargeResidual,
    /// The forward–backward round trip missed its start.
    ForwardBackward,
}

/// One tracked point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KltTrack {
    /// Position in the next image, px (meaningful only when `status` is `Tracked`; otherwise
    /// the last estimate).
    pub position: Point2<f32>,
    /// What happened.
    pub status: KltStatus,
    /// Mean absolute intensity residual over the final window (image units); infinite when
    /// the window could not be sampled.
    pub residual: f32,
    /// Forward–backward round-trip error, px; NaN when the check did not run.
    pub forward_backward_px: f32,
}

/// Tracks `points` (px in `prev`'s level-0 image) into `next`.
///
/// The result has one entry per input point, in order. Points whose status is not
/// [`KltStatus::Tracked`] should be ignored.
///
/// # Errors
/// [`FeatureError::InvalidConfig`] for a bad config; [`FeatureError::SizeMismatch`] when the
/// two pyramids differ in size or level count.
pub fn track_points(
    prev: &KltPyramid,
    next: &KltPyramid,
    points: &[Point2<f32>],
    config: &KltConfig,
) -> Result<Vec<KltTrack>, FeatureError> {
    track_points_warped(prev, next, points, &Matrix2::identity(), config)
}

/// As [`track_points`], with the windows in `next` deformed by the known linear part
/// `next_from_prev_linear` of the motion (for example the scale and rotation of a similarity
/// fitted to a first pass): the window offset `o` around a point in `prev` is compared with
/// offset `A·o` around its match in `next`. This removes the bias that rotation and scale
/// leave in pure-translation tracking. The backward check uses `A⁻¹`.
///
/// # Errors
/// As [`track_points`]; [`FeatureError::Degenerate`] when `A` is not invertible or not finite.
pub fn track_points_warped(
    prev: &KltPyramid,
    next: &KltPyramid,
    points: &[Point2<f32>],
    next_from_prev_linear: &Matrix2<f32>,
    config: &KltConfig,
) -> Result<Vec<KltTrack>, FeatureError> {
    config.validate()?;
    let linear = *next_from_prev_linear;
    let inverse = linear
        .try_inverse()
        .filter(|m| m.iter().all(|v| v.is_finite()) && linear.iter().all(|v| v.is_finite()))
        .ok_or(FeatureError::Degenerate("window warp is not invertible"))?;
    check_same_size(prev, next)?;
    let levels = prev.levels().min(config.pyramid_levels);
    Ok(points
        .par_iter()
        .map(|&p| {
            track_with_check(
                prev,
                next,
                p,
                Vector2::zeros(),
                &linear,
                &inverse,
                levels,
                config,
            )
        })
        .collect())
}

/// A point to track with a predicted position and a predicted local warp (see
/// [`track_points_guided`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuidedPoint {
    /// The point in the previous (template) image, px.
    pub position: Point2<f32>,
    /// Where it is expected in the next image, px (the search starts there).
    pub predicted: Point2<f32>,
    /// The linear part of the local next-from-previous image mapping at the point (for example
    /// the Jacobian of a plane-induced homography): window offset `o` in the previous image is
    /// compared with offset `A·o` around the match.
    pub next_from_prev_linear: Matrix2<f32>,
}

/// Tracks points whose position and local warp in `next` are predicted (from depth and a pose,
/// say): each point's search starts at its `predicted` position, coarse to fine over
/// `config.pyramid_levels` levels (one or two suffice when the prediction is within a few
/// pixels), with its own window warp; the forward–backward check tracks back with the inverse
/// warp from the prediction's offset. Tracking far apart views this way (rather than chaining
/// small steps) keeps each observation's error independent of the others.
///
/// A point whose warp is not finite or not invertible gets [`KltStatus::Untextured`].
///
/// # Errors
/// [`FeatureError::InvalidConfig`] for a bad config; [`FeatureError::SizeMismatch`] when the
/// two pyramids differ in size or level count.
pub fn track_points_guided(
    prev: &KltPyramid,
    next: &KltPyramid,
    points: &[GuidedPoint],
    config: &KltConfig,
) -> Result<Vec<KltTrack>, FeatureError> {
    config.validate()?;
    check_same_size(prev, next)?;
    let levels = prev.levels().min(config.pyramid_levels);
    Ok(points
        .par_iter()
        .map(|g| {
            let linear = g.next_from_prev_linear;
            let inverse = linear.try_inverse().filter(|m| {
                m.iter().all(|v| v.is_finite()) && linear.iter().all(|v| v.is_finite())
            });
            let guess = g.predicted - g.position;
            match inverse {
                Some(inverse) if guess.x.is_finite() && guess.y.is_finite() => track_with_check(
                    prev, next, g.position, guess, &linear, &inverse, levels, config,
                ),
                _ => KltTrack {
                    position: g.position,
                    status: KltStatus::Untextured,
                    residual: f32::INFINITY,
                    forward_backward_px: f32::NAN,
                },
            }
        })
        .collect())
}

/// Errors unless the two pyramids have the same size and level count.
fn check_same_size(prev: &KltPyramid, next: &KltPyramid) -> Result<(), FeatureError> {
    let (pw, ph) = prev.size();
    let (nw, nh) = next.size();
    if (pw, ph) != (nw, nh) {
        return Err(FeatureError::SizeMismatch {
            what: "previous and next image widths·heights",
            left: pw as usize * ph as usize,
            right: nw as usize * nh as usize,
        });
    }
    if prev.levels() != next.levels() {
        return Err(FeatureError::SizeMismatch {
            what: "previous and next pyramid levels",
            left: prev.levels(),
            right: next.levels(),
        });
    }
    Ok(())
}

/// Tracks `p` forward from the displacement guess `guess` (level-0 px), then back, and applies
/// the forward–backward check.
#[allow(clippy::too_many_arguments)]
fn track_with_check(
    prev: &KltPyramid,
    next: &KltPyramid,
    p: Point2<f32>,
    guess: Vector2<f32>,
    linear: &Matrix2<f32>,
    inverse: &Matrix2<f32>,
    levels: usize,
    config: &KltConfig,
) -> KltTrack {
    let forward = track_one(prev, next, p, guess, linear, levels, config);
    if forward.status != KltStatus::Tracked {
        return forward;
    }
    let Some(max_fb) = config.max_forward_backward_px else {
        return forward;
    };
    let back = track_one(
        next,
        prev,
        forward.position,
        p - forward.position,
        inverse,
        levels,
        config,
    );
    let fb = if back.status == KltStatus::Tracked {
        (back.position - p).norm()
    } else {
        f32::INFINITY
    };
    KltTrack {
        forward_backward_px: fb,
        status: if fb <= max_fb {
            KltStatus::Tracked
        } else {
            KltStatus::ForwardBackward
        },
        ..forward
    }
}

/// Level-`l` coordinates of a level-0 point.
fn to_level(p: Point2<f32>, level: usize) -> Point2<f32> {
    let s = 0.5f32.powi(level as i32);
    Point2::new((p.x + 0.5) * s - 0.5, (p.y + 0.5) * s - 0.5)
}

/// Whether a position lies where bilinear sampling is defined.
fn inside(image: &GrayImage, p: Point2<f32>) -> bool {
    p.x >= 0.0
        && p.y >= 0.0
        && p.x < (image.width() as f32 - 1.0)
        && p.y < (image.height() as f32 - 1.0)
}

/// Tracks one point coarse to fine, starting from the displacement `guess` (level-0 px).
fn track_one(
    prev: &KltPyramid,
    next: &KltPyramid,
    p0: Point2<f32>,
    guess: Vector2<f32>,
    linear: &Matrix2<f32>,
    levels: usize,
    config: &KltConfig,
) -> KltTrack {
    let failed = |status| KltTrack {
        position: p0,
        status,
        residual: f32::INFINITY,
        forward_backward_px: f32::NAN,
    };
    if !(p0.x.is_finite() && p0.y.is_finite() && inside(&prev.levels[0], p0)) {
        return failed(KltStatus::OutOfImage);
    }
    let half = (config.window_px / 2) as i32;
    let mut d = guess * 0.5f32.powi(levels.saturating_sub(1) as i32);
    for level in (0..levels).rev() {
        let (t_img, j_img) = (&prev.levels[level], &next.levels[level]);
        let p = to_level(p0, level);
        match refine_level(t_img, j_img, p, d, linear, half, config) {
            LevelResult::Refined(new_d) => d = new_d,
            // Coarse levels may lack room or texture; the finer levels decide.
            LevelResult::TooFewSamples if level > 0 => {}
            LevelResult::Untextured if level > 0 => {}
            LevelResult::TooFewSamples => return failed(KltStatus::OutOfImage),
            LevelResult::Untextured => return failed(KltStatus::Untextured),
        }
        if level > 0 {
            d *= 2.0;
        }
    }
    let q = p0 + d;
    let j0 = &next.levels[0];
    if !inside(j0, q) {
        return KltTrack {
            position: q,
            ..failed(KltStatus::OutOfImage)
        };
    }
    let residual = mean_residual(&prev.levels[0], j0, p0, q, linear, half);
    let status = if residual <= config.max_mean_residual {
        KltStatus::Tracked
    } else {
        KltStatus::LargeResidual
    };
    KltTrack {
        position: q,
        status,
        residual,
        forward_backward_px: f32::NAN,
    }
}

enum LevelResult {
    Refined(Vector2<f32>),
    TooFewSamples,
    Untextured,
}

/// Gauss–Newton on the displacement `d` of the window around `p` (level coordinates).
fn refine_level(
    t_img: &GrayImage,
    j_img: &GrayImage,
    p: Point2<f32>,
    mut d: Vector2<f32>,
    linear: &Matrix2<f32>,
    half: i32,
    config: &KltConfig,
) -> LevelResult {
    let side = (2 * half + 1) as usize;
    // Template samples and gradients; `None` where the window leaves the image.
    let mut template: Vec<Option<(f32, f32, f32)>> = Vec::with_capacity(side * side);
    let (mut gxx, mut gxy, mut gyy) = (0.0f32, 0.0f32, 0.0f32);
    let mut patch = Vec::new();
    if sample_window(t_img, p.x, p.y, half + 1, &mut patch) {
        // Fast path: the window and its one-pixel frame are inside the image. Central
        // differences of the bilinear patch equal bilinear samples of central differences.
        let stride = side + 2;
        for j in 0..side {
            for i in 0..side {
                let c = (j + 1) * stride + i + 1;
                let gx = 0.5 * (patch[c + 1] - patch[c - 1]);
                let gy = 0.5 * (patch[c + stride] - patch[c - stride]);
                gxx += gx * gx;
                gxy += gx * gy;
                gyy += gy * gy;
                template.push(Some((patch[c], gx, gy)));
            }
        }
    }
    let slow_template = template.is_empty();
    for j in (-half..=half).filter(|_| slow_template) {
        for i in -half..=half {
            let (x, y) = (p.x + i as f32, p.y + j as f32);
            let s = (|| {
                let t = t_img.sample_bilinear(x, y)?;
                let gx = 0.5
                    * (t_img.sample_bilinear(x + 1.0, y)? - t_img.sample_bilinear(x - 1.0, y)?);
                let gy = 0.5
                    * (t_img.sample_bilinear(x, y + 1.0)? - t_img.sample_bilinear(x, y - 1.0)?);
                Some((t, gx, gy))
            })();
            if let Some((_, gx, gy)) = s {
                gxx += gx * gx;
                gxy += gx * gy;
                gyy += gy * gy;
            }
            template.push(s);
        }
    }
    let valid = template.iter().filter(|s| s.is_some()).count();
    if valid * 2 < side * side {
        return LevelResult::TooFewSamples;
    }
    let det = gxx * gyy - gxy * gxy;
    let min_eig = 0.5 * (gxx + gyy) - (0.25 * (gxx - gyy) * (gxx - gyy) + gxy * gxy).sqrt();
    if !(min_eig / valid as f32 >= config.min_eigenvalue) || !(det > 0.0) {
        return LevelResult::Untextured;
    }
    let inv = [gyy / det, -gxy / det, gxx / det];
    let unwarped = *linear == Matrix2::identity();
    let mut next_patch = Vec::new();
    for _ in 0..config.max_iterations {
        let (mut bx, mut by) = (0.0f32, 0.0f32);
        let fast = unwarped && sample_window(j_img, p.x + d.x, p.y + d.y, half, &mut next_patch);
        if fast {
            for (s, &jv) in template.iter().zip(&next_patch) {
                if let Some((t, gx, gy)) = *s {
                    let e = jv - t;
                    bx += gx * e;
                    by += gy * e;
                }
            }
        }
        let mut k = 0;
        for j in (-half..=half).filter(|_| !fast) {
            for i in -half..=half {
                let o = linear * Vector2::new(i as f32, j as f32);
                if let Some((t, gx, gy)) = template[k]
                    && let Some(jv) = j_img.sample_bilinear(p.x + d.x + o.x, p.y + d.y + o.y)
                {
                    let e = jv - t;
                    bx += gx * e;
                    by += gy * e;
                }
                k += 1;
            }
        }
        let step = Vector2::new(inv[0] * bx + inv[1] * by, inv[1] * bx + inv[2] * by);
        d -= step;
        if !(d.x.is_finite() && d.y.is_finite()) {
            return LevelResult::Untextured;
        }
        if step.norm() < config.convergence_px {
            break;
        }
    }
    LevelResult::Refined(d)
}

/// Bilinear samples of the `(2r + 1)²` window centred at `(x, y)`, row-major, into `out`;
/// `false` (and `out` unspecified) unless the whole window lies where bilinear sampling is
/// defined. All samples share one fractional offset, so the weights are computed once.
fn sample_window(image: &GrayImage, x: f32, y: f32, r: i32, out: &mut Vec<f32>) -> bool {
    if !(x.is_finite() && y.is_finite()) {
        return false;
    }
    let (xf, yf) = (x.floor(), y.floor());
    let (fx, fy) = (x - xf, y - yf);
    let (x0, y0) = (xf as i64 - i64::from(r), yf as i64 - i64::from(r));
    let side = 2 * i64::from(r) + 1;
    let (w, h) = (i64::from(image.width()), i64::from(image.height()));
    if x0 < 0 || y0 < 0 || x0 + side >= w || y0 + side >= h {
        return false;
    }
    let (w00, w10, w01, w11) = (
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    );
    let data = image.as_slice();
    let stride = w as usize;
    out.clear();
    for j in 0..side as usize {
        let top = &data[(y0 as usize + j) * stride + x0 as usize..][..side as usize + 1];
        let bottom = &data[(y0 as usize + j + 1) * stride + x0 as usize..][..side as usize + 1];
        for i in 0..side as usize {
            out.push(w00 * top[i] + w10 * top[i + 1] + w01 * bottom[i] + w11 * bottom[i + 1]);
        }
    }
    true
}

/// Mean absolute difference between the window at `p` in `t_img` and at `q` in `j_img`, over
/// the samples both images define; infinite when none.
fn mean_residual(
    t_img: &GrayImage,
    j_img: &GrayImage,
    p: Point2<f32>,
    q: Point2<f32>,
    linear: &Matrix2<f32>,
    half: i32,
) -> f32 {
    let (mut sum, mut count) = (0.0f32, 0u32);
    for j in -half..=half {
        for i in -half..=half {
            let (fi, fj) = (i as f32, j as f32);
            let o = linear * Vector2::new(fi, fj);
            if let (Some(a), Some(b)) = (
                t_img.sample_bilinear(p.x + fi, p.y + fj),
                j_img.sample_bilinear(q.x + o.x, q.y + o.y),
            ) {
                sum += (a - b).abs();
                count += 1;
            }
        }
    }
    if count == 0 {
        f32::INFINITY
    } else {
        sum / count as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::pattern::{image_from_fn as image, plane_wave_texture as texture};
    use crate::features::{CornerConfig, CornerRegion, detect_corners};

    #[test]
    fn recovers_a_large_shift_to_a_hundredth_of_a_pixel() {
        let (dx, dy) = (17.3f32, -9.6f32);
        let prev = image(320, 240, texture);
        let next = image(320, 240, |x, y| texture(x - dx, y - dy));
        let config = KltConfig::default();
        let corners = detect_corners(
            &prev,
            &CornerConfig {
                max_corners: 50,
                min_distance_px: 10.0,
                ..CornerConfig::default()
            },
            &CornerRegion::Rect(crate::features::PixelRect {
                u_min: 60,
                v_min: 60,
                u_max: 260,
                v_max: 180,
            }),
        )
        .unwrap();
        assert!(corners.len() >= 20);
        let points: Vec<_> = corners.iter().map(|c| c.position).collect();
        let tracks = track_points(
            &KltPyramid::new(&prev, 4),
            &KltPyramid::new(&next, 4),
            &points,
            &config,
        )
        .unwrap();
        for (t, p) in tracks.iter().zip(&points) {
            assert_eq!(t.status, KltStatus::Tracked, "{p:?}: {t:?}");
            assert!((t.position.x - p.x - dx).abs() < 0.02, "{t:?}");
            assert!((t.position.y - p.y - dy).abs() < 0.02, "{t:?}");
            assert!(t.forward_backward_px < 0.05);
        }
    }

    #[test]
    fn guided_tracking_recovers_a_far_warped_match_from_its_prediction() {
        // next(q) = prev(A⁻¹(q − c − t) + c): a 10° rotation, 15% zoom and a 47 px shift,
        // searched from a prediction 2 px off with two pyramid levels.
        let (angle, scale) = (10f32.to_radians(), 1.15f32);
        let a = Matrix2::new(angle.cos(), -angle.sin(), angle.sin(), angle.cos()) * scale;
        let a_inv = a.try_inverse().unwrap();
        let (c, t) = (Vector2::new(160.0f32, 120.0), Vector2::new(40.0f32, -25.0));
        let prev = image(320, 240, texture);
        let next = image(320, 240, |x, y| {
            let q = a_inv * (Vector2::new(x, y) - c - t) + c;
            texture(q.x, q.y)
        });
        let config = KltConfig {
            window_px: 15,
            pyramid_levels: 2,
            ..KltConfig::default()
        };
        let (prev_pyramid, next_pyramid) = (KltPyramid::new(&prev, 2), KltPyramid::new(&next, 2));
        let points: Vec<_> = [(130.0f32, 100.0f32), (150.0, 130.0), (175.0, 110.0)]
            .iter()
            .map(|&(x, y)| Point2::new(x, y))
            .collect();
        let truth: Vec<Point2<f32>> = points
            .iter()
            .map(|p| Point2::from(a * (p.coords - c) + c + t))
            .collect();
        let guided: Vec<GuidedPoint> = points
            .iter()
            .zip(&truth)
            .map(|(p, q)| GuidedPoint {
                position: *p,
                predicted: Point2::new(q.x + 1.5, q.y - 1.5),
                next_from_prev_linear: a,
            })
            .collect();
        let tracks = track_points_guided(&prev_pyramid, &next_pyramid, &guided, &config).unwrap();
        for (track, q) in tracks.iter().zip(&truth) {
            assert_eq!(track.status, KltStatus::Tracked, "{track:?}");
            assert!((track.position - q).norm() < 0.05, "{track:?} vs {q:?}");
        }
        // A singular warp is refused per point.
        let singular = GuidedPoint {
            next_from_prev_linear: Matrix2::zeros(),
            ..guided[0]
        };
        let refused = track_points_guided(&prev_pyramid, &next_pyramid, &[singular], &config);
        assert_eq!(refused.unwrap()[0].status, KltStatus::Untextured);
    }

    #[test]
    fn forward_backward_rejects_occluded_points() {
        let (dx, dy) = (3.0f32, 2.0f32);
        let prev = image(200, 160, texture);
        // In the next image a block of unrelated texture covers x in 80..130.
        let next = image(200, 160, |x, y| {
            if (80.0..130.0).contains(&x) {
                0.5 + 0.3 * (1.7 * x * y).sin() * (0.9 * y).cos()
            } else {
                texture(x - dx, y - dy)
            }
        });
        let points = vec![
            Point2::new(40.0, 80.0),  // visible
            Point2::new(105.0, 80.0), // occluded
            Point2::new(160.0, 80.0), // visible
        ];
        let tracks = track_points(
            &KltPyramid::new(&prev, 3),
            &KltPyramid::new(&next, 3),
            &points,
            &KltConfig::default(),
        )
        .unwrap();
        assert_eq!(tracks[0].status, KltStatus::Tracked);
        assert_eq!(tracks[2].status, KltStatus::Tracked);
        assert_ne!(tracks[1].status, KltStatus::Tracked, "{:?}", tracks[1]);
    }

    #[test]
    fn garbage_and_edge_points_are_rejected() {
        let prev = image(120, 100, texture);
        let noise = image(120, 100, |x, y| {
            let h = ((x as u32).wrapping_mul(2_654_435_761) ^ (y as u32).wrapping_mul(40_503))
                .wrapping_mul(2_246_822_519);
            (h >> 8) as f32 / (1u32 << 24) as f32
        });
        let flat = GrayImage::filled(120, 100, 0.5);
        let points = vec![Point2::new(60.0, 50.0)];
        let config = KltConfig::default();
        let on_noise = track_points(
            &KltPyramid::new(&prev, 3),
            &KltPyramid::new(&noise, 3),
            &points,
            &config,
        )
        .unwrap();
        assert_ne!(on_noise[0].status, KltStatus::Tracked);
        let on_flat = track_points(
            &KltPyramid::new(&flat, 3),
            &KltPyramid::new(&flat, 3),
            &points,
            &config,
        )
        .unwrap();
        assert_eq!(on_flat[0].status, KltStatus::Untextured);
        let outside = vec![Point2::new(-3.0, 5.0), Point2::new(f32::NAN, 1.0)];
        let out = track_points(
            &KltPyramid::new(&prev, 3),
            &KltPyramid::new(&prev, 3),
            &outside,
            &config,
        )
        .unwrap();
        assert!(out.iter().all(|t| t.status == KltStatus::OutOfImage));
        let small = KltPyramid::new(&GrayImage::filled(50, 40, 0.5), 3);
        assert!(matches!(
            track_points(&KltPyramid::new(&prev, 3), &small, &points, &config),
            Err(FeatureError::SizeMismatch { .. })
        ));
        let bad = KltConfig {
            window_px: 24,
            ..KltConfig::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn result_does_not_depend_on_thread_count() {
        let prev = image(160, 120, texture);
        let next = image(160, 120, |x, y| texture(x - 1.7, y + 0.9));
        let points: Vec<_> = (0..40)
            .map(|k| Point2::new(30.0 + (k % 10) as f32 * 10.0, 30.0 + (k / 10) as f32 * 15.0))
            .collect();
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    track_points(
                        &KltPyramid::new(&prev, 3),
                        &KltPyramid::new(&next, 3),
                        &points,
                        &KltConfig::default(),
                    )
                    .unwrap()
                })
        };
        let (a, b) = (run(1), run(2));
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.position, y.position);
            assert_eq!(x.status, y.status);
        }
    }
}
