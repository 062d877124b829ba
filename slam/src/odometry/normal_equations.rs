//! Linearisation: the Gauss–Newton normal equations of the photometric and point-to-plane
//! residuals of every current-frame point, for one pyramid level and one pose.
//!
//! The pose is `reference_from_current`; it is perturbed on the left in the reference frame,
//! `T ← exp(δ)·T` with δ = (translation, rotation), so a transformed point q = T·p moves by
//! dq/dδ = [I | −[q]×]. A residual r with gradient a = ∂r/∂q then has the Jacobian
//! (aᵀ, (q × a)ᵀ).

use nalgebra::{Isometry3, Matrix6, Vector6};
use rayon::prelude::*;

use super::OdometryConfig;
use super::reference::{RefPixel, ReferenceLevel};
use super::source::SourcePoint;

/// Σ w·JᵀJ, Σ w·Jᵀr and counts over a set of points.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct NormalEquations {
    /// Upper triangle of H, row-major (21 entries).
    pub h: [f64; 21],
    pub g: [f64; 6],
    /// Σ of the Huber loss, in σ² units.
    pub cost: f64,
    /// Points with a valid projective correspondence.
    pub correspondences: usize,
    /// Correspondences whose residuals are all within `inlier_sigmas`.
    pub inliers: usize,
    /// Σ of the correspondences' reference depths (for the degeneracy test's scale).
    pub depth_sum: f64,
    /// Sums over the geometric inliers with a photometric sample, for the brightness fit
    /// `reference ≈ gain · current + bias`: count, Σc, Σr, Σc², Σr² (c current intensity, r
    /// reference intensity).
    pub brightness: [f64; 5],
}

impl NormalEquations {
    /// The `(gain, bias)` of `reference ≈ gain · current + bias` that matches the mean and
    /// standard deviation of the two intensities over the geometric inliers, or `None` with
    /// fewer than `min_samples` of them or no contrast. Moments, not a regression: while the
    /// pose is still off, the two intensities correlate less, which would pull a regression's
    /// gain below 1 and flatten the photometric term; their spreads do not change.
    pub fn brightness_fit(&self, min_samples: usize) -> Option<(f64, f64)> {
        let [n, c, r, cc, rr] = self.brightness;
        if n < min_samples as f64 {
            return None;
        }
        let variance_c = cc / n - (c / n).powi(2);
        let variance_r = rr / n - (r / n).powi(2);
        if !(variance_c > 1e-6 && variance_r > 1e-6) {
            return None;
        }
        let gain = (variance_r / variance_c).sqrt();
        let bias = r / n - gain * c / n;
        (gain.is_finite() && bias.is_finite()).then_some((gain, bias))
    }

    fn add(&mut self, other: &Self) {
        for (a, b) in self.h.iter_mut().zip(other.h.iter()) {
            *a += b;
        }
        for (a, b) in self.g.iter_mut().zip(other.g.iter()) {
            *a += b;
        }
        self.cost += other.cost;
        self.correspondences += other.correspondences;
        self.inliers += other.inliers;
        self.depth_sum += other.depth_sum;
        for (a, b) in self.brightness.iter_mut().zip(other.brightness.iter()) {
            *a += b;
        }
    }

    /// H as a full symmetric matrix.
    pub fn hessian(&self) -> Matrix6<f64> {
        let mut m = Matrix6::zeros();
        let mut k = 0;
        for r in 0..6 {
            for c in r..6 {
                m[(r, c)] = self.h[k];
                m[(c, r)] = self.h[k];
                k += 1;
            }
        }
        m
    }

    /// The gradient Σ w·Jᵀr.
    pub fn gradient(&self) -> Vector6<f64> {
        Vector6::from_column_slice(&self.g)
    }
}

/// f32 accumulator for one chunk (fast), flushed into f64.
struct ChunkSums {
    h: [f32; 21],
    g: [f32; 6],
    cost: f32,
    correspondences: usize,
    inliers: usize,
    depth_sum: f32,
    brightness: [f32; 5],
}

impl ChunkSums {
    fn new() -> Self {
        Self {
            h: [0.0; 21],
            g: [0.0; 6],
            cost: 0.0,
            correspondences: 0,
            inliers: 0,
            depth_sum: 0.0,
            brightness: [0.0; 5],
        }
    }

    #[inline]
    fn add_residual(&mut self, j: &[f32; 6], r: f32, w: f32) {
        let mut k = 0;
        for a in 0..6 {
            let wa = w * j[a];
            for &jb in &j[a..] {
                self.h[k] += wa * jb;
                k += 1;
            }
            self.g[a] += wa * r;
        }
    }

    fn into_f64(self) -> NormalEquations {
        NormalEquations {
            h: self.h.map(f64::from),
            g: self.g.map(f64::from),
            cost: f64::from(self.cost),
            correspondences: self.correspondences,
            inliers: self.inliers,
            depth_sum: f64::from(self.depth_sum),
            brightness: self.brightness.map(f64::from),
        }
    }
}

/// Huber weight and loss of a residual in σ units.
#[inline]
fn huber(e: f32, k: f32) -> (f32, f32) {
    let a = e.abs();
    if a <= k {
        (1.0, 0.5 * e * e)
    } else {
        (k / a, k * (a - 0.5 * k))
    }
}

#[inline]
fn jacobian(a: [f32; 3], q: [f32; 3]) -> [f32; 6] {
    [
        a[0],
        a[1],
        a[2],
        q[1] * a[2] - q[2] * a[1],
        q[2] * a[0] - q[0] * a[2],
        q[0] * a[1] - q[1] * a[0],
    ]
}

/// Per-level constants of the linearisation.
struct Weights {
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    photometric_info: f32,
    photometric_sigma: f32,
    geometric_info_scale: f32,
    geometric_sigma_1m: f32,
    geometric_on: bool,
    photometric_on: bool,
    huber_k: f32,
    inlier_sigmas: f32,
    max_distance_sq: f32,
    /// The current frame's intensities are compared as `gain · I + bias`.
    gain: f32,
    bias: f32,
}

/// Builds the normal equations of `points` against `reference` at `reference_from_current`,
/// comparing the current intensities as `gain · I + bias` (`brightness`). Chunks are summed in
/// order, so the result is the same for any thread count.
pub(crate) fn normal_equations(
    reference: &ReferenceLevel,
    points: &[SourcePoint],
    reference_from_current: &Isometry3<f64>,
    brightness: (f64, f64),
    config: &OdometryConfig,
) -> NormalEquations {
    let rot = reference_from_current.rotation.to_rotation_matrix();
    let m = rot.matrix().cast::<f32>();
    let t = reference_from_current.translation.vector.cast::<f32>();
    let weights = Weights {
        fx: reference.camera.fx as f32,
        fy: reference.camera.fy as f32,
        cx: reference.camera.cx as f32,
        cy: reference.camera.cy as f32,
        photometric_info: (config.photometric_weight
            / (config.photometric_sigma * config.photometric_sigma))
            as f32,
        photometric_sigma: config.photometric_sigma as f32,
        geometric_info_scale: config.geometric_weight as f32,
        geometric_sigma_1m: config.geometric_sigma_at_1m_m as f32,
        geometric_on: config.geometric_weight > 0.0,
        photometric_on: config.photometric_weight > 0.0,
        huber_k: config.huber_k as f32,
        inlier_sigmas: config.inlier_sigmas as f32,
        max_distance_sq: (config.max_correspondence_distance_m
            * config.max_correspondence_distance_m) as f32,
        gain: brightness.0 as f32,
        bias: brightness.1 as f32,
    };
    let partials: Vec<NormalEquations> = points
        .par_chunks(config.chunk_points)
        .map(|chunk| {
            let mut sums = ChunkSums::new();
            for sp in chunk {
                let p = sp.p;
                let q = [
                    m[(0, 0)] * p[0] + m[(0, 1)] * p[1] + m[(0, 2)] * p[2] + t[0],
                    m[(1, 0)] * p[0] + m[(1, 1)] * p[1] + m[(1, 2)] * p[2] + t[1],
                    m[(2, 0)] * p[0] + m[(2, 1)] * p[1] + m[(2, 2)] * p[2] + t[2],
                ];
                accumulate_point(reference, &weights, q, sp.intensity, &mut sums);
            }
            sums.into_f64()
        })
        .collect();
    let mut total = NormalEquations::default();
    for part in &partials {
        total.add(part);
    }
    total
}

#[inline]
fn accumulate_point(
    reference: &ReferenceLevel,
    w: &Weights,
    q: [f32; 3],
    intensity: f32,
    sums: &mut ChunkSums,
) {
    if !(q[2] > 1e-6) {
        return;
    }
    let inv_z = 1.0 / q[2];
    let (fx, fy) = (w.fx, w.fy);
    let u = fx * q[0] * inv_z + w.cx;
    let v = fy * q[1] * inv_z + w.cy;
    // Bilinear sampling needs (u0, v0) and (u0 + 1, v0 + 1) inside the image.
    if !(u >= 0.0 && v >= 0.0) {
        return;
    }
    let (u0, v0) = (u as usize, v as usize);
    if u0 + 1 >= reference.width || v0 + 1 >= reference.height {
        return;
    }
    let (fu, fv) = (u - u0 as f32, v - v0 as f32);
    let nearest = (v0 + usize::from(fv >= 0.5)) * reference.width + u0 + usize::from(fu >= 0.5);
    let pixels = &reference.pixels;
    let vertex = pixels[nearest].vertex;
    if vertex[2] <= 0.0 {
        return;
    }
    let d = [q[0] - vertex[0], q[1] - vertex[1], q[2] - vertex[2]];
    if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > w.max_distance_sq {
        return;
    }
    sums.correspondences += 1;
    sums.depth_sum += vertex[2];
    let mut inlier = true;

    let n = pixels[nearest].normal;
    let mut geometric_inlier = false;
    if w.geometric_on && (n[0] != 0.0 || n[1] != 0.0 || n[2] != 0.0) {
        let r = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
        let sigma = w.geometric_sigma_1m * vertex[2] * vertex[2];
        let e = r / sigma;
        let (hw, loss) = huber(e, w.huber_k);
        let info = w.geometric_info_scale / (sigma * sigma);
        sums.add_residual(&jacobian(n, q), r, hw * info);
        sums.cost += loss * w.geometric_info_scale;
        inlier &= e.abs() <= w.inlier_sigmas;
        geometric_inlier = e.abs() <= w.inlier_sigmas;
    }

    let i0 = v0 * reference.width + u0;
    let (p00, p01) = (&pixels[i0], &pixels[i0 + 1]);
    let (p10, p11) = (
        &pixels[i0 + reference.width],
        &pixels[i0 + reference.width + 1],
    );
    let photometric_ok = !reference.intensity_needs_surface
        || (p00.vertex[2] > 0.0
            && p01.vertex[2] > 0.0
            && p10.vertex[2] > 0.0
            && p11.vertex[2] > 0.0);
    if w.photometric_on && photometric_ok {
        let bilinear = |get: fn(&RefPixel) -> f32| {
            let top = get(p00) + (get(p01) - get(p00)) * fu;
            let bottom = get(p10) + (get(p11) - get(p10)) * fu;
            top + (bottom - top) * fv
        };
        let reference_intensity = bilinear(|p| p.intensity);
        if geometric_inlier {
            let b = &mut sums.brightness;
            b[0] += 1.0;
            b[1] += intensity;
            b[2] += reference_intensity;
            b[3] += intensity * intensity;
            b[4] += reference_intensity * reference_intensity;
        }
        let r = reference_intensity - (w.gain * intensity + w.bias);
        let gu = bilinear(|p| p.grad_u);
        let gv = bilinear(|p| p.grad_v);
        let a0 = gu * fx * inv_z;
        let a1 = gv * fy * inv_z;
        let a2 = -(a0 * q[0] + a1 * q[1]) * inv_z;
        let e = r / w.photometric_sigma;
        let (hw, loss) = huber(e, w.huber_k);
        sums.add_residual(&jacobian([a0, a1, a2], q), r, hw * w.photometric_info);
        sums.cost += loss * w.photometric_info * w.photometric_sigma * w.photometric_sigma;
        inlier &= e.abs() <= w.inlier_sigmas;
    }
    if inlier {
        sums.inliers += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_matches_a_finite_difference() {
        // r(q) = a·q, q = exp(δ)·p: check the rotation columns numerically.
        let a = [0.3f32, -0.2, 0.9];
        let p = nalgebra::Point3::new(0.4, -0.3, 2.0);
        let j = jacobian(a, [0.4, -0.3, 2.0]);
        let r = |q: nalgebra::Point3<f64>| {
            f64::from(a[0]) * q.x + f64::from(a[1]) * q.y + f64::from(a[2]) * q.z
        };
        for k in 0..3 {
            let mut w = nalgebra::Vector3::zeros();
            w[k] = 1e-6;
            let t = Isometry3::new(nalgebra::Vector3::zeros(), w);
            let numeric = (r(t * p) - r(p)) / 1e-6;
            assert!(
                (numeric - f64::from(j[3 + k])).abs() < 1e-4,
                "{k}: {numeric} vs {}",
                j[3 + k]
            );
        }
    }

    #[test]
    fn huber_is_quadratic_then_linear() {
        assert_eq!(huber(0.5, 1.0), (1.0, 0.125));
        let (w, loss) = huber(-3.0, 1.0);
        assert!((w - 1.0 / 3.0).abs() < 1e-6 && (loss - 2.5).abs() < 1e-6);
    }
}
