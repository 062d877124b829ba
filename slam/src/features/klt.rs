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
use crate::image::GrayImage;
#[cfg(test)]
use crate::image::downsample_gray;

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
    /// Compare each window after matching its brightness to the template's (the same mean and
    /// standard deviation over the samples both define): a gain and bias per window, which an
    /// auto-exposure change or a light change between frames would otherwise turn into
    /// residual. Default false (the simulated sensor's exposure is fixed).
    pub compensate_brightness: bool,
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
            compensate_brightness: false,
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
            let next = half_level(last);
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

/// The next pyramid level of `image` (at least 2×2): its 2×2 block averages
/// ([`crate::image::downsample_gray`]) after a separable `[1, 2, 1]/4` blur (edges replicated),
/// which keeps
/// them from aliasing fine texture (the kernel is centred, so the pyramid geometry is
/// unchanged). Computed one coarse row at a time from the four fine rows it needs, without the
/// full-resolution blurred image, the same sums in the same order as the two-step form; rows
/// are independent, so they run in parallel with a result that does not depend on the thread
/// count.
fn half_level(image: &GrayImage) -> GrayImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let (cw, ch) = ((w / 2).max(1), (h / 2).max(1));
    let src = image.as_slice();
    let mut out = vec![0.0f32; cw * ch];
    out.par_chunks_mut(cw).enumerate().for_each_init(
        || vec![0.0f32; 6 * w],
        |buf, (v, dst)| {
            let fine_row = |k: isize| {
                let y = (2 * v as isize + k).clamp(0, h as isize - 1) as usize;
                &src[y * w..][..w]
            };
            let (blurred, rest) = buf.split_at_mut(4 * w);
            let (top, bottom) = rest.split_at_mut(w);
            // Horizontal pass over fine rows 2v − 1 ..= 2v + 2 (edges replicated).
            for (k, row) in blurred.chunks_exact_mut(w).enumerate() {
                smooth_row(fine_row(k as isize - 1), row);
            }
            let (r0, r1, r2, r3) = (
                &blurred[..w],
                &blurred[w..2 * w],
                &blurred[2 * w..3 * w],
                &blurred[3 * w..],
            );
            // Vertical pass for fine rows 2v and 2v + 1 (2v + 1 < h since v < h / 2 when
            // h ≥ 2; a one-row image repeats its row).
            let two_rows = 2 * v + 1 < h;
            for (((o, a), b), c) in top.iter_mut().zip(r0).zip(r2).zip(r1) {
                *o = 0.25 * (a + b) + 0.5 * c;
            }
            if two_rows {
                for (((o, a), b), c) in bottom.iter_mut().zip(r1).zip(r3).zip(r2) {
                    *o = 0.25 * (a + b) + 0.5 * c;
                }
            } else {
                bottom.copy_from_slice(top);
            }
            // 2×2 averages, summed in downsample_gray's order.
            let max_u = w - 1;
            for (u, o) in dst.iter_mut().enumerate() {
                let (u0, u1) = ((2 * u).min(max_u), (2 * u + 1).min(max_u));
                *o = (top[u0] + top[u1] + bottom[u0] + bottom[u1]) * 0.25;
            }
        },
    );
    // cw·ch values by construction.
    GrayImage::from_vec(cw as u32, ch as u32, out).expect("cw·ch pixels")
}

/// The image blurred by the separable `[1, 2, 1]/4` kernel (edges replicated): the reference
/// form of [`half_level`]'s blur.
#[cfg(test)]
fn smoothed(image: &GrayImage) -> GrayImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let src = image.as_slice();
    let mut rows = vec![0.0f32; w * h];
    for (r, out) in src.chunks_exact(w).zip(rows.chunks_exact_mut(w)) {
        smooth_row(r, out);
    }
    let mut out = vec![0.0f32; w * h];
    for (v, dst) in out.chunks_exact_mut(w).enumerate() {
        let (up, down) = (v.saturating_sub(1), (v + 1).min(h - 1));
        let (a, c, b) = (
            &rows[up * w..][..w],
            &rows[v * w..][..w],
            &rows[down * w..][..w],
        );
        for (((o, a), b), c) in dst.iter_mut().zip(a).zip(b).zip(c) {
            *o = 0.25 * (a + b) + 0.5 * c;
        }
    }
    // Same size as the input, so the length is w·h.
    GrayImage::from_vec(image.width(), image.height(), out).expect("w·h pixels")
}

/// One row of the blur's horizontal pass: `out[u] = (r[u−1] + r[u+1])/4 + r[u]/2`, edges
/// replicated. `r` and `out` have the same, non-zero length.
fn smooth_row(r: &[f32], out: &mut [f32]) {
    let w = r.len().min(out.len());
    if w < 3 {
        for u in 0..w {
            let (l, c, rt) = (r[u.saturating_sub(1)], r[u], r[(u + 1).min(w - 1)]);
            out[u] = 0.25 * (l + rt) + 0.5 * c;
        }
        return;
    }
    out[0] = 0.25 * (r[0] + r[1]) + 0.5 * r[0];
    for (((o, l), c), rt) in out[1..w - 1]
        .iter_mut()
        .zip(&r[..w - 2])
        .zip(&r[1..w - 1])
        .zip(&r[2..])
    {
        *o = 0.25 * (l + rt) + 0.5 * c;
    }
    out[w - 1] = 0.25 * (r[w - 2] + r[w - 1]) + 0.5 * r[w - 1];
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
    track_points_warped_from(prev, next, points, None, next_from_prev_linear, config)
}

/// As [`track_points_warped`], refining an earlier pass `initial` (one track per point, for
/// example from [`track_points`]): a point whose initial status is
/// [`KltStatus::Tracked`] starts from its initial position and is refined on the full-resolution
/// level only (forward, and backward from the forward result), which is all a refinement by a
/// few tenths of a pixel needs; the other points are tracked through the whole pyramid as in
/// [`track_points_warped`]. With `initial` `None` this is [`track_points_warped`].
///
/// # Errors
/// As [`track_points_warped`]; [`FeatureError::SizeMismatch`] when `initial` and `points`
/// differ in length.
pub fn track_points_warped_from(
    prev: &KltPyramid,
    next: &KltPyramid,
    points: &[Point2<f32>],
    initial: Option<&[KltTrack]>,
    next_from_prev_linear: &Matrix2<f32>,
    config: &KltConfig,
) -> Result<Vec<KltTrack>, FeatureError> {
    config.validate()?;
    if let Some(initial) = initial
        && initial.len() != points.len()
    {
        return Err(FeatureError::SizeMismatch {
            what: "points and their initial tracks",
            left: points.len(),
            right: initial.len(),
        });
    }
    let linear = *next_from_prev_linear;
    let inverse = linear
        .try_inverse()
        .filter(|m| m.iter().all(|v| v.is_finite()) && linear.iter().all(|v| v.is_finite()))
        .ok_or(FeatureError::Degenerate("window warp is not invertible"))?;
    check_same_size(prev, next)?;
    let levels = prev.levels().min(config.pyramid_levels);
    Ok(points
        .par_iter()
        .enumerate()
        .map(|(k, &p)| {
            // A refined point starts from its earlier match, on level 0 only.
            let start = initial
                .map(|tracks| tracks[k])
                .filter(|t| t.status == KltStatus::Tracked)
                .map(|t| t.position - p);
            let (guess, levels) = match start {
                Some(guess) => (guess, 1),
                None => (Vector2::zeros(), levels),
            };
            track_with_check(prev, next, p, guess, &linear, &inverse, levels, config)
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
    // One set of buffers per point, reused by every level of both directions.
    let mut scratch = Scratch::default();
    let forward = track_one(prev, next, p, guess, linear, levels, config, &mut scratch);
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
        &mut scratch,
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

/// Working buffers of one point's tracking, allocated once per point and reused by every
/// level, iteration and the backward pass (no allocation inside the Gauss–Newton loop).
///
/// The template of the current level is kept as separate arrays of intensity and gradients
/// (row-major over the window), so the per-iteration sums run over contiguous slices. A
/// template sample that could not be taken (window partly outside the image) has `valid`
/// false and zero intensity and gradients, so it adds nothing to the Gauss–Newton sums.
#[derive(Debug, Default)]
struct Scratch {
    /// Template intensities.
    t: Vec<f32>,
    /// Template x gradients (central differences).
    gx: Vec<f32>,
    /// Template y gradients (central differences).
    gy: Vec<f32>,
    /// Whether each template sample exists.
    valid: Vec<bool>,
    /// Whether every template sample exists (the window and its frame are inside the image).
    complete: bool,
    /// Bilinear samples of a window (template with its frame, or the next image's window).
    patch: Vec<f32>,
}

impl Scratch {
    /// Samples the template window of half-size `half` around `p` in `image`, with its
    /// gradients. Returns the number of valid samples and the normal-matrix entries
    /// `(Σ gx², Σ gx·gy, Σ gy²)`.
    fn build_template(
        &mut self,
        image: &GrayImage,
        p: Point2<f32>,
        half: i32,
    ) -> (usize, [f32; 3]) {
        let side = (2 * half + 1) as usize;
        let n = side * side;
        self.t.clear();
        self.gx.clear();
        self.gy.clear();
        self.valid.clear();
        if sample_window(image, p.x, p.y, half + 1, &mut self.patch) {
            // Fast path: the window and its one-pixel frame are inside the image. Central
            // differences of the bilinear patch equal bilinear samples of central differences.
            let stride = side + 2;
            for j in 0..side {
                let up = &self.patch[j * stride..][..stride];
                let row = &self.patch[(j + 1) * stride..][..stride];
                let down = &self.patch[(j + 2) * stride..][..stride];
                self.t.extend_from_slice(&row[1..=side]);
                self.gx.extend(
                    row[2..]
                        .iter()
                        .zip(&row[..side])
                        .map(|(r, l)| 0.5 * (r - l)),
                );
                self.gy.extend(
                    down[1..=side]
                        .iter()
                        .zip(&up[1..=side])
                        .map(|(d, u)| 0.5 * (d - u)),
                );
            }
            self.valid.resize(n, true);
            self.complete = true;
        } else {
            // Near the border: undefined samples are NaN, and so is every difference that
            // uses one, which marks the template samples that cannot be taken.
            sample_window_or_nan(image, p.x, p.y, half + 1, &mut self.patch);
            let stride = side + 2;
            for j in 0..side {
                let up = &self.patch[j * stride..][..stride];
                let row = &self.patch[(j + 1) * stride..][..stride];
                let down = &self.patch[(j + 2) * stride..][..stride];
                for i in 1..=side {
                    let (t, gx, gy) = (
                        row[i],
                        0.5 * (row[i + 1] - row[i - 1]),
                        0.5 * (down[i] - up[i]),
                    );
                    let ok = !(t.is_nan() || gx.is_nan() || gy.is_nan());
                    let (t, gx, gy) = if ok { (t, gx, gy) } else { (0.0, 0.0, 0.0) };
                    self.t.push(t);
                    self.gx.push(gx);
                    self.gy.push(gy);
                    self.valid.push(ok);
                }
            }
            self.complete = false;
        }
        let valid = if self.complete {
            n
        } else {
            self.valid.iter().filter(|&&v| v).count()
        };
        let normal = [
            lane_dot(&self.gx, &self.gx),
            lane_dot(&self.gx, &self.gy),
            lane_dot(&self.gy, &self.gy),
        ];
        (valid, normal)
    }
}

/// Number of independent accumulators in the window sums (lets the compiler use SIMD lanes;
/// the summation order is fixed, so results do not depend on the machine's thread count).
const LANES: usize = 8;

/// `Σ a·b` over two equally long slices, accumulated in [`LANES`] fixed lanes.
fn lane_dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; LANES];
    let (ac, bc) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        for l in 0..LANES {
            acc[l] += x[l] * y[l];
        }
    }
    for (l, (x, y)) in ar.iter().zip(br).enumerate() {
        acc[l] += x * y;
    }
    acc.iter().sum()
}

/// The Gauss–Newton right-hand side `(Σ gx·e, Σ gy·e)` with `e = j − t`, over equally long
/// slices, in [`LANES`] fixed lanes.
fn gradient_error_sums(j: &[f32], t: &[f32], gx: &[f32], gy: &[f32]) -> (f32, f32) {
    let (mut ax, mut ay) = ([0.0f32; LANES], [0.0f32; LANES]);
    let (jc, tc, xc, yc) = (
        j.chunks_exact(LANES),
        t.chunks_exact(LANES),
        gx.chunks_exact(LANES),
        gy.chunks_exact(LANES),
    );
    let rest = (
        jc.remainder(),
        tc.remainder(),
        xc.remainder(),
        yc.remainder(),
    );
    for (((jv, tv), xv), yv) in jc.zip(tc).zip(xc).zip(yc) {
        for l in 0..LANES {
            let e = jv[l] - tv[l];
            ax[l] += xv[l] * e;
            ay[l] += yv[l] * e;
        }
    }
    for (l, (((jv, tv), xv), yv)) in rest
        .0
        .iter()
        .zip(rest.1)
        .zip(rest.2)
        .zip(rest.3)
        .enumerate()
    {
        let e = jv - tv;
        ax[l] += xv * e;
        ay[l] += yv * e;
    }
    (ax.iter().sum(), ay.iter().sum())
}

/// As [`gradient_error_sums`], skipping the entries where `j` is NaN (not sampled).
fn masked_gradient_error_sums(j: &[f32], t: &[f32], gx: &[f32], gy: &[f32]) -> (f32, f32) {
    let (mut ax, mut ay) = ([0.0f32; LANES], [0.0f32; LANES]);
    for (k, (((jv, tv), xv), yv)) in j.iter().zip(t).zip(gx).zip(gy).enumerate() {
        let e = jv - tv;
        let e = if e.is_nan() { 0.0 } else { e };
        ax[k % LANES] += xv * e;
        ay[k % LANES] += yv * e;
    }
    (ax.iter().sum(), ay.iter().sum())
}

/// The mean of `|j − t|` over the entries where `j` is not NaN; infinite when there are none.
fn masked_mean_abs_difference(j: &[f32], t: &[f32]) -> f32 {
    let (mut sum, mut count) = (0.0f32, 0u32);
    for (jv, tv) in j.iter().zip(t) {
        if !jv.is_nan() {
            sum += (jv - tv).abs();
            count += 1;
        }
    }
    if count == 0 {
        f32::INFINITY
    } else {
        sum / count as f32
    }
}

/// `Σ |a − b|` over two equally long slices, in [`LANES`] fixed lanes.
fn abs_difference_sum(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; LANES];
    let (ac, bc) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        for l in 0..LANES {
            acc[l] += (x[l] - y[l]).abs();
        }
    }
    for (l, (x, y)) in ar.iter().zip(br).enumerate() {
        acc[l] += (x - y).abs();
    }
    acc.iter().sum()
}

/// Tracks one point coarse to fine through `levels` levels, starting from the displacement
/// `guess` (level-0 px). `scratch` is reused; on return it holds the level-0 template at `p0`.
#[allow(clippy::too_many_arguments)]
fn track_one(
    prev: &KltPyramid,
    next: &KltPyramid,
    p0: Point2<f32>,
    guess: Vector2<f32>,
    linear: &Matrix2<f32>,
    levels: usize,
    config: &KltConfig,
    scratch: &mut Scratch,
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
    // The displacement at the coarsest level used, in that level's pixels.
    let mut d = guess * 0.5f32.powi(levels.saturating_sub(1) as i32);
    for level in (0..levels).rev() {
        let (t_img, j_img) = (&prev.levels[level], &next.levels[level]);
        let p = to_level(p0, level);
        match refine_level(t_img, j_img, p, d, linear, half, config, scratch) {
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
    // The scratch holds the level-0 template at `p0` (level 0 was refined last).
    let unwarped = *linear == Matrix2::identity();
    let residual = if config.compensate_brightness {
        if unwarped {
            sample_window_or_nan(j0, q.x, q.y, half, &mut scratch.patch);
        } else {
            sample_window_warped(j0, q.x, q.y, linear, half, &mut scratch.patch);
        }
        for (sample, &valid) in scratch.patch.iter_mut().zip(&scratch.valid) {
            if !valid {
                *sample = f32::NAN;
            }
        }
        match_brightness(&mut scratch.patch, &scratch.t, &scratch.valid);
        masked_mean_abs_difference(&scratch.patch, &scratch.t)
    } else if !scratch.complete {
        mean_residual(&prev.levels[0], j0, p0, q, linear, half)
    } else if unwarped && sample_window(j0, q.x, q.y, half, &mut scratch.patch) {
        abs_difference_sum(&scratch.patch, &scratch.t) / scratch.t.len() as f32
    } else {
        sample_window_warped(j0, q.x, q.y, linear, half, &mut scratch.patch);
        masked_mean_abs_difference(&scratch.patch, &scratch.t)
    };
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

/// Gauss–Newton on the displacement `d` of the window around `p` (level coordinates). The
/// template and its normal matrix are computed once (inverse-compositional for translation);
/// each iteration samples the next image's window once.
#[allow(clippy::too_many_arguments)]
fn refine_level(
    t_img: &GrayImage,
    j_img: &GrayImage,
    p: Point2<f32>,
    mut d: Vector2<f32>,
    linear: &Matrix2<f32>,
    half: i32,
    config: &KltConfig,
    scratch: &mut Scratch,
) -> LevelResult {
    let side = (2 * half + 1) as usize;
    let (valid, [gxx, gxy, gyy]) = scratch.build_template(t_img, p, half);
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
    let Scratch {
        t,
        gx,
        gy,
        patch,
        valid,
        ..
    } = scratch;
    for _ in 0..config.max_iterations {
        let (x, y) = (p.x + d.x, p.y + d.y);
        let (bx, by) = if unwarped && sample_window(j_img, x, y, half, patch) {
            if config.compensate_brightness {
                match_brightness(patch, t, valid);
            }
            gradient_error_sums(patch, t, gx, gy)
        } else {
            // The window reaches past the border or is deformed: samples are taken one by
            // one, and those the image does not define are skipped.
            if unwarped {
                sample_window_or_nan(j_img, x, y, half, patch);
            } else {
                sample_window_warped(j_img, x, y, linear, half, patch);
            }
            if config.compensate_brightness {
                match_brightness(patch, t, valid);
            }
            masked_gradient_error_sums(patch, t, gx, gy)
        };
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

/// The weights of the four neighbours (top-left, top-right, bottom-left, bottom-right) of a
/// sample at fractional offset `(fx, fy)` from the top-left one.
#[inline]
fn bilinear_weights(fx: f32, fy: f32) -> (f32, f32, f32, f32) {
    (
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    )
}

/// Bilinear samples of the `(2r + 1)²` window centred at `(x, y)`, row-major, into `out`;
/// `false` (and `out` unspecified) unless the whole window lies where bilinear sampling is
/// defined. All samples share one fractional offset, so the weights are computed once.
fn sample_window(image: &GrayImage, x: f32, y: f32, r: i32, out: &mut Vec<f32>) -> bool {
    // Far-off (or non-finite) positions are outside; the bound keeps the integer maths exact.
    if !(x.abs() < FAR_PX && y.abs() < FAR_PX) {
        return false;
    }
    let (xf, yf) = (floor(x), floor(y));
    let (fx, fy) = (x - xf, y - yf);
    let (x0, y0) = (xf as i64 - i64::from(r), yf as i64 - i64::from(r));
    let side = 2 * i64::from(r) + 1;
    let (w, h) = (i64::from(image.width()), i64::from(image.height()));
    if x0 < 0 || y0 < 0 || x0 + side >= w || y0 + side >= h {
        return false;
    }
    let (w00, w10, w01, w11) = bilinear_weights(fx, fy);
    let data = image.as_slice();
    let (stride, side) = (w as usize, side as usize);
    let (x0, y0) = (x0 as usize, y0 as usize);
    out.clear();
    out.resize(side * side, 0.0);
    for (j, row) in out.chunks_exact_mut(side).enumerate() {
        let top = &data[(y0 + j) * stride + x0..][..side + 1];
        let bottom = &data[(y0 + j + 1) * stride + x0..][..side + 1];
        // Equal-length slices, indexed in step, so the loop compiles to vector lanes.
        let (a, b) = (&top[..side], &top[1..]);
        let (c, e) = (&bottom[..side], &bottom[1..]);
        for i in 0..side {
            row[i] = w00 * a[i] + w10 * b[i] + w01 * c[i] + w11 * e[i];
        }
    }
    true
}

/// As [`sample_window`] for a window that may reach past the image: the samples where
/// bilinear sampling is not defined are NaN (all of them when `(x, y)` is not finite or far
/// off).
fn sample_window_or_nan(image: &GrayImage, x: f32, y: f32, r: i32, out: &mut Vec<f32>) {
    let side = 2 * i64::from(r) + 1;
    out.clear();
    out.resize((side * side) as usize, f32::NAN);
    if !(x.abs() < FAR_PX && y.abs() < FAR_PX) {
        return;
    }
    let (xf, yf) = (floor(x), floor(y));
    let (fx, fy) = (x - xf, y - yf);
    let (x0, y0) = (xf as i64 - i64::from(r), yf as i64 - i64::from(r));
    let (w, h) = (i64::from(image.width()), i64::from(image.height()));
    // Window column c samples between image columns x0 + c and x0 + c + 1, which must both
    // exist (the same for rows).
    let (c_lo, c_hi) = ((-x0).clamp(0, side), (w - 1 - x0).clamp(0, side));
    let (r_lo, r_hi) = ((-y0).clamp(0, side), (h - 1 - y0).clamp(0, side));
    if c_lo >= c_hi || r_lo >= r_hi {
        return;
    }
    let (w00, w10, w01, w11) = bilinear_weights(fx, fy);
    let data = image.as_slice();
    let (stride, side) = (w as usize, side as usize);
    let (c_lo, c_hi) = (c_lo as usize, c_hi as usize);
    let n = c_hi - c_lo;
    // Columns c_lo..c_hi and rows r_lo..r_hi map to image pixels ≥ 0 by construction.
    let u = (x0 + c_lo as i64) as usize;
    for j in r_lo as usize..r_hi as usize {
        let v = (y0 + j as i64) as usize;
        let top = &data[v * stride + u..][..n + 1];
        let bottom = &data[(v + 1) * stride + u..][..n + 1];
        for ((((o, a), b), c), e) in out[j * side + c_lo..j * side + c_hi]
            .iter_mut()
            .zip(&top[..n])
            .zip(&top[1..])
            .zip(&bottom[..n])
            .zip(&bottom[1..])
        {
            *o = w00 * a + w10 * b + w01 * c + w11 * e;
        }
    }
}

/// Samples of the window deformed by `linear` around `(x, y)`: entry `(i, j)` (row-major,
/// `i, j` in `−r..=r`) is the bilinear sample at `(x, y) + linear·(i, j)`, or NaN where
/// bilinear sampling is not defined.
fn sample_window_warped(
    image: &GrayImage,
    x: f32,
    y: f32,
    linear: &Matrix2<f32>,
    r: i32,
    out: &mut Vec<f32>,
) {
    out.clear();
    let (w, h) = (image.width() as f32, image.height() as f32);
    let stride = image.width() as usize;
    let data = image.as_slice();
    let (ax, ay) = (linear[(0, 0)], linear[(1, 0)]);
    let (bx, by) = (linear[(0, 1)], linear[(1, 1)]);
    for j in -r..=r {
        let (fj, fi0) = (j as f32, -r as f32);
        for i in 0..2 * r + 1 {
            let fi = fi0 + i as f32;
            let (u, v) = (x + ax * fi + bx * fj, y + ay * fi + by * fj);
            // `u < w − 1` ⇔ the pixel right of floor(u) exists (w is an integer); NaN fails.
            if !(u >= 0.0 && v >= 0.0 && u < w - 1.0 && v < h - 1.0) {
                out.push(f32::NAN);
                continue;
            }
            // Non-negative, so truncation is the floor.
            let (u0, v0) = (u as usize, v as usize);
            let (fu, fv) = (u - u0 as f32, v - v0 as f32);
            let k = v0 * stride + u0;
            let (a, b, c, e) = (data[k], data[k + 1], data[k + stride], data[k + stride + 1]);
            let top = a + (b - a) * fu;
            let bottom = c + (e - c) * fu;
            out.push(top + (bottom - top) * fv);
        }
    }
}

/// Maps the samples of `patch` affinely so that, over the samples both windows define (`valid`
/// template samples, non-NaN patch samples), their mean and standard deviation equal the
/// template's `t`. Leaves `patch` as it is when the overlap is flat or empty.
fn match_brightness(patch: &mut [f32], t: &[f32], valid: &[bool]) {
    let (mut n, mut sp, mut spp, mut st, mut stt) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for ((&j, &tv), &ok) in patch.iter().zip(t).zip(valid) {
        if ok && !j.is_nan() {
            n += 1.0;
            sp += j;
            spp += j * j;
            st += tv;
            stt += tv * tv;
        }
    }
    if n < 2.0 {
        return;
    }
    let (mean_p, mean_t) = (sp / n, st / n);
    let var_p = spp / n - mean_p * mean_p;
    let var_t = stt / n - mean_t * mean_t;
    if !(var_p > 1e-8 && var_t > 1e-8) {
        return;
    }
    let gain = (var_t / var_p).sqrt();
    for j in patch.iter_mut() {
        *j = (*j - mean_p) * gain + mean_t;
    }
}

/// Window positions at least this far from the origin, px, are outside any image.
const FAR_PX: f32 = 1e9;

/// `x.floor()` for window positions (|x| < [`FAR_PX`]), without a libm call (the baseline
/// x86-64 target has no rounding instruction).
fn floor(x: f32) -> f32 {
    let t = x as i64 as f32;
    if t > x { t - 1.0 } else { t }
}

/// Mean absolute difference between the window at `p` in `t_img` and at `q` in `j_img`, over
/// the samples both images define; infinite when none. (The general case: windows at the
/// image border or deformed by `linear`.)
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
    fn brightness_compensation_tracks_through_an_exposure_change() {
        // The next image is the shifted texture at 60% gain and +0.15 bias (an auto-exposure
        // step): plain KLT's residual test rejects the matches, the compensated one recovers
        // the shift.
        let (dx, dy) = (3.4f32, -2.2f32);
        let prev = image(200, 160, texture);
        let next = image(200, 160, |x, y| 0.6 * texture(x - dx, y - dy) + 0.15);
        let points: Vec<_> = detect_corners(
            &prev,
            &CornerConfig {
                max_corners: 30,
                min_distance_px: 10.0,
                ..CornerConfig::default()
            },
            &CornerRegion::Rect(crate::features::PixelRect {
                u_min: 40,
                v_min: 40,
                u_max: 160,
                v_max: 120,
            }),
        )
        .unwrap()
        .iter()
        .map(|c| c.position)
        .collect();
        assert!(points.len() >= 10);
        let (prev, next) = (KltPyramid::new(&prev, 3), KltPyramid::new(&next, 3));
        let plain = KltConfig {
            max_mean_residual: 0.02,
            ..KltConfig::default()
        };
        let tracked = |config: &KltConfig| {
            track_points(&prev, &next, &points, config)
                .unwrap()
                .into_iter()
                .zip(&points)
                .filter(|(t, p)| {
                    t.status == KltStatus::Tracked
                        && (t.position.x - p.x - dx).abs() < 0.05
                        && (t.position.y - p.y - dy).abs() < 0.05
                })
                .count()
        };
        assert_eq!(tracked(&plain), 0);
        let compensated = KltConfig {
            compensate_brightness: true,
            ..plain
        };
        assert_eq!(tracked(&compensated), points.len());
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
    fn pyramid_levels_equal_blur_then_block_average() {
        for (w, h) in [
            (64u32, 48u32),
            (7, 5),
            (9, 4),
            (5, 9),
            (2, 2),
            (1, 3),
            (3, 1),
        ] {
            let img = image(w, h, texture);
            let fused = half_level(&img);
            let reference = downsample_gray(&smoothed(&img));
            assert_eq!(
                (fused.width(), fused.height()),
                (reference.width(), reference.height())
            );
            for (a, b) in fused.as_slice().iter().zip(reference.as_slice()) {
                assert_eq!(a, b, "{w}×{h}");
            }
        }
        // The same for any number of threads.
        let img = image(64, 48, texture);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| half_level(&img));
        assert_eq!(one.as_slice(), half_level(&img).as_slice());
    }

    #[test]
    fn border_windows_match_per_sample_bilinear() {
        let img = image(40, 30, texture);
        let mut out = Vec::new();
        let centres = [
            (1.3f32, 2.7f32),
            (38.2, 28.9),
            (-3.5, 10.25),
            (20.0, 15.0),
            (39.5, -0.5),
            (f32::NAN, 3.0),
        ];
        for &(x, y) in &centres {
            sample_window_or_nan(&img, x, y, 4, &mut out);
            assert_eq!(out.len(), 81);
            let mut k = 0;
            for j in -4..=4 {
                for i in -4..=4 {
                    match img.sample_bilinear(x + i as f32, y + j as f32) {
                        Some(v) => assert!((out[k] - v).abs() < 1e-5, "{x},{y} {i},{j}"),
                        None => assert!(out[k].is_nan(), "{x},{y} {i},{j}: {}", out[k]),
                    }
                    k += 1;
                }
            }
        }
        // Deformed windows, inside and across the border.
        let linear = Matrix2::new(0.98f32, -0.17, 0.17, 0.98) * 1.05;
        for &(x, y) in &centres {
            sample_window_warped(&img, x, y, &linear, 4, &mut out);
            assert_eq!(out.len(), 81);
            let mut k = 0;
            for j in -4..=4 {
                for i in -4..=4 {
                    let o = linear * Vector2::new(i as f32, j as f32);
                    match img.sample_bilinear(x + o.x, y + o.y) {
                        Some(v) => assert!((out[k] - v).abs() < 1e-4, "{x},{y} {i},{j}"),
                        None => assert!(out[k].is_nan(), "{x},{y} {i},{j}: {}", out[k]),
                    }
                    k += 1;
                }
            }
        }
        assert!(!sample_window(&img, 2.0, 15.0, 4, &mut out));
        assert!(sample_window(&img, 20.0, 15.0, 4, &mut out));
        assert_eq!(floor(-1.5), -2.0);
        assert_eq!(floor(-2.0), -2.0);
        assert_eq!(floor(2.75), 2.0);
    }

    #[test]
    fn points_whose_windows_cross_the_border_still_track() {
        let (dx, dy) = (1.6f32, -0.7f32);
        let prev = image(160, 120, texture);
        let next = image(160, 120, |x, y| texture(x - dx, y - dy));
        // 25 px windows reach past the left, top and right edges at every level.
        let points = vec![
            Point2::new(6.0, 60.0),
            Point2::new(80.0, 5.0),
            Point2::new(150.0, 70.0),
        ];
        let tracks = track_points(
            &KltPyramid::new(&prev, 3),
            &KltPyramid::new(&next, 3),
            &points,
            &KltConfig::default(),
        )
        .unwrap();
        for (t, p) in tracks.iter().zip(&points) {
            assert_eq!(t.status, KltStatus::Tracked, "{p:?}: {t:?}");
            assert!((t.position.x - p.x - dx).abs() < 0.05, "{p:?}: {t:?}");
            assert!((t.position.y - p.y - dy).abs() < 0.05, "{p:?}: {t:?}");
        }
    }

    #[test]
    fn refinement_from_an_earlier_pass_matches_full_retracking() {
        // A 4° rotation and 3% zoom about (80, 60), plus a shift.
        let (c, s) = (
            1.03 * 4f32.to_radians().cos(),
            1.03 * 4f32.to_radians().sin(),
        );
        let warp = |x: f32, y: f32| {
            let (u, v) = (x - 80.0, y - 60.0);
            (80.0 + c * u - s * v + 2.3, 60.0 + s * u + c * v - 1.1)
        };
        let prev = image(160, 120, texture);
        // next(warp(p)) = prev(p): invert the similarity per pixel.
        let next = image(160, 120, |x, y| {
            let (u, v) = (x - 80.0 - 2.3, y - 60.0 + 1.1);
            let det = c * c + s * s;
            texture(80.0 + (c * u + s * v) / det, 60.0 + (-s * u + c * v) / det)
        });
        let points: Vec<_> = (0..12)
            .map(|k| Point2::new(50.0 + (k % 4) as f32 * 20.0, 40.0 + (k / 4) as f32 * 20.0))
            .collect();
        let (pp, np) = (KltPyramid::new(&prev, 3), KltPyramid::new(&next, 3));
        let config = KltConfig::default();
        let linear = Matrix2::new(c, -s, s, c);
        let first = track_points(&pp, &np, &points, &config).unwrap();
        let full = track_points_warped(&pp, &np, &points, &linear, &config).unwrap();
        let warm =
            track_points_warped_from(&pp, &np, &points, Some(&first), &linear, &config).unwrap();
        for ((p, f), w) in points.iter().zip(&full).zip(&warm) {
            let (tx, ty) = warp(p.x, p.y);
            assert_eq!(f.status, KltStatus::Tracked, "{p:?}: {f:?}");
            assert_eq!(w.status, KltStatus::Tracked, "{p:?}: {w:?}");
            assert!((w.position - f.position).norm() < 0.02, "{w:?} vs {f:?}");
            assert!((w.position.x - tx).abs() < 0.05 && (w.position.y - ty).abs() < 0.05);
        }
        assert!(matches!(
            track_points_warped_from(&pp, &np, &points, Some(&first[1..]), &linear, &config),
            Err(FeatureError::SizeMismatch { .. })
        ));
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
