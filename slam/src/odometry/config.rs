//! Tunables of the RGBD odometry.

use serde::{Deserialize, Serialize};

use super::OdometryError;

/// Every tunable of [`super::track`]. The defaults suit the simulated stereo RGBD camera
/// (640×480, 80° HFOV, disparity σ 0.1 px over a 12 cm baseline, RGB noise σ 2/255) at the
/// 2–20 m ranges of a PBR orbit; they follow Kerl et al. (DVO, 2013) for the photometric part and
/// KinectFusion (Newcombe et al., 2011) for the point-to-plane part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OdometryConfig {
    /// Pyramid levels (≥ 3; level 0 is full resolution). Default 4: the coarsest level
    /// (80×60) absorbs initial-guess errors of a few degrees.
    pub levels: usize,
    /// Gauss–Newton iterations per level, finest level first. Missing entries repeat the last.
    /// Default `[4, 6, 8, 10]`.
    pub max_iterations: Vec<usize>,
    /// Stop a level when the update is smaller than this translation, metres (at level k the
    /// thresholds are 2^k times larger: coarse levels only need to bring the estimate within
    /// reach of the next). Default 1e-5 m.
    pub convergence_translation_m: f64,
    /// … and smaller than this rotation, radians. Default 1e-5 rad (0.0006°).
    pub convergence_rotation_rad: f64,
    /// Expected intensity noise (intensity in [0, 1]). Residuals are divided by it, so the
    /// Hessian is an information matrix. Default 0.02 (RGB σ 2/255 plus interpolation error).
    pub photometric_sigma: f64,
    /// Expected point-to-plane noise at 1 m depth, metres; it grows with z² like stereo depth
    /// noise. Default 0.003 m (disparity σ 0.1 px, f 381 px, baseline 0.12 m gives 0.0022 m).
    pub geometric_sigma_at_1m_m: f64,
    /// Relative weight of the photometric term (multiplies its information). Default 1.
    pub photometric_weight: f64,
    /// Relative weight of the geometric term. Default 1.
    pub geometric_weight: f64,
    /// Huber threshold in units of σ (both terms). Default 1.345 (95% efficiency).
    pub huber_k: f64,
    /// A residual within this many σ counts as an inlier. Default 3.
    pub inlier_sigmas: f64,
    /// Current-frame depths outside [`Self::min_depth_m`, `Self::max_depth_m`] are ignored.
    /// Default 0.3 m.
    pub min_depth_m: f64,
    /// Default 25 m.
    pub max_depth_m: f64,
    /// A projective correspondence farther than this from the reference surface point is
    /// rejected (occlusion, depth edge). Default 0.25 m.
    pub max_correspondence_distance_m: f64,
    /// Normals of a depth reference come from neighbours this many pixels away (at each level).
    /// Default 1.
    pub normal_radius_px: usize,
    /// Neighbours whose depths differ by more than this fraction are not used for a normal.
    /// Default 0.05.
    pub normal_max_depth_jump_ratio: f64,
    /// Failure: fewer finest-level correspondences than this. Default 2000.
    pub min_correspondences: usize,
    /// Failure: finest-level correspondences below this fraction of the image. Default 0.05.
    pub min_correspondence_fraction: f64,
    /// Failure: inlier ratio (inliers over current-frame pixels with depth) below this.
    /// Default 0.3.
    pub min_inlier_ratio: f64,
    /// Failure: smallest over largest eigenvalue of the Hessian, with rotations scaled to metres
    /// at the mean scene depth, below this (an unconstrained direction: a flat textureless
    /// plane, a corridor). Default 1e-5.
    pub min_eigenvalue_ratio: f64,
    /// Failure: the result moved farther than this from the initial guess. Default 0.5 m.
    pub max_correction_m: f64,
    /// Failure: the result turned farther than this from the initial guess. Default 15°.
    pub max_correction_deg: f64,
    /// At most this many current-frame points per level take part (every k-th valid pixel is
    /// kept): this bounds the cost of the finest levels. 0 keeps all. Default 30 000 (of the
    /// 307 200 pixels of a 640×480 frame; level 1 has at most 76 800).
    pub max_points_per_level: usize,
    /// Current-frame points handled per parallel chunk; partial sums are added in chunk order,
    /// so results do not depend on the thread count. Default 4096.
    pub chunk_points: usize,
    /// Compare intensities through a gain and bias (`reference ≈ gain · current + bias`),
    /// refitted after every linearisation on the correspondences whose point-to-plane residual
    /// is an inlier: a real camera's auto-exposure changes brightness between frames, which
    /// would otherwise read as photometric error. Default true.
    pub estimate_brightness: bool,
}

impl Default for OdometryConfig {
    fn default() -> Self {
        Self {
            levels: 4,
            max_iterations: vec![4, 6, 8, 10],
            convergence_translation_m: 1e-5,
            convergence_rotation_rad: 1e-5,
            photometric_sigma: 0.02,
            geometric_sigma_at_1m_m: 0.003,
            photometric_weight: 1.0,
            geometric_weight: 1.0,
            huber_k: 1.345,
            inlier_sigmas: 3.0,
            min_depth_m: 0.3,
            max_depth_m: 25.0,
            max_correspondence_distance_m: 0.25,
            normal_radius_px: 1,
            normal_max_depth_jump_ratio: 0.05,
            min_correspondences: 2000,
            min_correspondence_fraction: 0.05,
            min_inlier_ratio: 0.3,
            min_eigenvalue_ratio: 1e-5,
            max_correction_m: 0.5,
            max_correction_deg: 15.0,
            max_points_per_level: 30_000,
            chunk_points: 4096,
            estimate_brightness: true,
        }
    }
}

impl OdometryConfig {
    /// Iterations allowed at `level`.
    pub fn iterations_at(&self, level: usize) -> usize {
        self.max_iterations
            .get(level)
            .or(self.max_iterations.last())
            .copied()
            .unwrap_or(10)
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`OdometryError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), OdometryError> {
        let bad = |field: &'static str, reason: &'static str| {
            Err(OdometryError::InvalidConfig { field, reason })
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if self.levels < 3 || self.levels > 8 {
            return bad("levels", "must be in 3..=8");
        }
        if self.max_iterations.is_empty() || self.max_iterations.contains(&0) {
            return bad("max_iterations", "needs at least one positive entry");
        }
        for (field, value) in [
            ("convergence_translation_m", self.convergence_translation_m),
            ("convergence_rotation_rad", self.convergence_rotation_rad),
            ("photometric_sigma", self.photometric_sigma),
            ("geometric_sigma_at_1m_m", self.geometric_sigma_at_1m_m),
            ("huber_k", self.huber_k),
            ("inlier_sigmas", self.inlier_sigmas),
            ("min_depth_m", self.min_depth_m),
            ("max_depth_m", self.max_depth_m),
            (
                "max_correspondence_distance_m",
                self.max_correspondence_distance_m,
            ),
            (
                "normal_max_depth_jump_ratio",
                self.normal_max_depth_jump_ratio,
            ),
            ("max_correction_m", self.max_correction_m),
            ("max_correction_deg", self.max_correction_deg),
        ] {
            if !positive(value) {
                return bad(field, "must be positive and finite");
            }
        }
        for (field, value) in [
            ("photometric_weight", self.photometric_weight),
            ("geometric_weight", self.geometric_weight),
            (
                "min_correspondence_fraction",
                self.min_correspondence_fraction,
            ),
            ("min_inlier_ratio", self.min_inlier_ratio),
            ("min_eigenvalue_ratio", self.min_eigenvalue_ratio),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return bad(field, "must be non-negative and finite");
            }
        }
        if self.photometric_weight + self.geometric_weight <= 0.0 {
            return bad("photometric_weight", "one of the two terms needs a weight");
        }
        if self.min_depth_m >= self.max_depth_m {
            return bad("min_depth_m", "must be below max_depth_m");
        }
        if self.normal_radius_px == 0 {
            return bad("normal_radius_px", "must be at least 1");
        }
        if self.chunk_points == 0 {
            return bad("chunk_points", "must be positive");
        }
        Ok(())
    }
}
