//! Tunables of the depth filter, with the defaults of the paper and its code (DESIGN.md).

use serde::{Deserialize, Serialize};

use super::LocalizationError;

/// Every tunable of target localization. Defaults come from DESIGN.md ("Defaults from the paper
/// and its code"); the hit/miss counters are ours.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizationConfig {
    /// Points per target (the paper's m). Default 2000 (DESIGN; the paper used 1000).
    pub points_per_target: usize,
    /// Margin added on every side of a tracked box before generating and weighting points, px.
    /// Default 30 (seed code).
    pub box_enlargement_px: f64,
    /// Nearest depth of generated points along the camera z axis, m. Default 3.
    pub min_depth_m: f64,
    /// Farthest depth of generated points along the camera z axis (the paper's d_m), m.
    /// Default 18.
    pub max_depth_m: f64,
    /// Draw a new target's points (and a restarted one's) between the depths the frame
    /// measured over its box, padded by the rock's size
    /// ([`super::box_depth::measured_depth_range`]), instead of over
    /// `min_depth_m`–`max_depth_m` (ours, not the paper's). Only where the caller passes the
    /// frame's depth ([`super::TargetCatalog::observe_with_depth`]) and it holds enough
    /// samples. Default false, the paper's Algorithm 2.
    ///
    /// Why: the search hands the filter a rock's box once it is within 18 m, so over 3–18 m
    /// nearly every point is born between the camera and the rock. With an exact state
    /// estimate that left the default world's centres 0.35–0.39 m high (seed 36); born at the
    /// measured depth they were 0.05–0.13 m off. Under the GPS walk it gained nothing (14 / 22
    /// within 0.5 m against the paper's 16 / 22 over three worlds, seeds 38–39; session 38):
    /// the walk within the localization window dominates there.
    pub birth_depth_from_image: bool,
    /// Standard deviation of the isotropic noise added to every point before weighting
    /// (Algorithm 3), m. Default 0.1.
    pub update_noise_sigma_m: f64,
    /// Weight w1 of the Gaussian centred on the box (σ = half its width and height). Default 0.2.
    pub gaussian_weight: f64,
    /// Weight w2 of the uniform density over the enlarged box. Default 0.8.
    pub uniform_weight: f64,
    /// The share of its weight that a noised point keeps when the frame's depth rules it out:
    /// in the free space in front of the surface measured where it projects, on the line of
    /// sight to ground, or below the lowest part of the rock the box shows (ours, not the
    /// paper's; see [`super::free_space`]). 1 turns the depth evidence off, as in the paper's
    /// Algorithm 3. Default 1 (off): with 0.05, the first version (without the rock's floor)
    /// sank the centres into the pedestals, 1.1–1.7 m too low on 3 of 6 targets (session 36).
    pub free_space_weight: f64,
    /// The depth evidence's tolerance: a point is in free space when it lies more than
    /// `free_space_margin_m + free_space_margin_per_m · d²` in front of the measured depth d, and
    /// under the ground when more than `free_space_margin_m` below it, m. It covers depth noise
    /// and the state estimate's walk between updates. Default 0.2.
    pub free_space_margin_m: f64,
    /// The part of the free-space tolerance that grows as the square of the measured depth,
    /// 1/m: a stereo camera's depth noise σ_z = d²·σ_d/(f·b). Default 0.0022, one σ of the
    /// simulated camera (σ_d 0.1 px, b 0.12 m, f 381 px): only points within the tolerance of
    /// the rock's front surface risk being ruled out by a noisy pixel, and the centre lies
    /// deeper, while every σ more leaves that much more free space in front of the rock
    /// (0.3 m at the 12 m of the fine-localization circle).
    pub free_space_margin_per_m: f64,
    /// A target is updated only when the camera has moved more than this since its last update,
    /// m. Default 1.5.
    pub keyframe_translation_m: f64,
    /// ... or turned more than this (the angle of the relative rotation, so always wrapped to
    /// [0°, 180°]), degrees. Default 30.
    pub keyframe_rotation_deg: f64,
    /// A target whose point-set differential entropy h_p (nats) falls below this is ready for
    /// fine localization. Default 3.0.
    pub ready_entropy_nats: f64,
    /// KL divergence (nats) between successive Gaussian fits counted as "no change". Default 0.01.
    pub converged_kl_nats: f64,
    /// A standard deviation added along every axis of both fits before their KL is taken, m
    /// (ours; see [`super::Gaussian3::with_variance_floor`]). Default 0, the paper's KL.
    ///
    /// Why: KL ≤ `converged_kl_nats` is scale-free, so a cloud that a sharper likelihood has
    /// shrunk must hold its centre proportionally stiller to converge; carried by the state
    /// estimate's walk between updates, it rarely does (session 36: 4–5 of 6 fine circles ended
    /// unconverged with the depth evidence on). A floor near the bound the centre must meet
    /// makes the test about the centre's motion on that scale.
    pub converged_kl_floor_m: f64,
    /// Updates in a row with KL at most [`Self::converged_kl_nats`] for convergence. Default 3.
    pub converged_updates: u32,
    /// Convergence also needs the views (registration and updates) to span at least this
    /// horizontal angle around the target, degrees (ours, not the paper's). Default 120.
    ///
    /// Why: the box cones of views from one side meet in a sliver along the line of sight, and
    /// a few of them agree with each other long before the sliver shrinks. On the default world
    /// the filter declared two rocks converged after 34° and 70° of the fine-localization
    /// circle, 1.3 and 1.1 m from their centroids; a full circle with true poses puts them
    /// within 3 cm.
    pub converged_min_view_span_deg: f64,
    /// Converged targets whose centres are closer than this merge, m. Default 1.0.
    pub merge_distance_m: f64,
    /// Frames with a box on a target (hits) after which it is confirmed and never removed for
    /// misses. Default 5.
    pub confirm_hits: u32,
    /// An unconfirmed target is removed after this many frames in which its centre was in view
    /// (inside the image, in front of the camera, within `max_depth_m`) but no box matched it
    /// (misses). Default 3.
    pub max_misses: u32,
    /// A box updates an existing target when at least this many of its points satisfy the box's
    /// four inward half-spaces (N·L > 0); otherwise it registers a new target. Default 1 (the
    /// paper: "any point").
    pub min_points_in_cone: usize,
    /// Once this many keyframes boxed the target, C_e is the point nearest their boxes' central
    /// rays ([`super::triangulation`]), where those spread over enough directions to place it
    /// (about 26° of views); otherwise, once this many keyframes' depth gave an object centre
    /// ([`super::silhouette::center_in_box`]), horizontally the median of those centres and
    /// vertically the points' mean. Until then, and with 0, it is the mean of the points (the
    /// paper's). Default 3.
    ///
    /// Why the rays: the points' mean also carries the filter's history. A target first boxed
    /// from beyond `max_depth_m` is born in front of itself, and the resampling's small steps
    /// never bring all of it back; its height is weakly held from one elevation. Replayed
    /// from a default-world flight's frames (seed 60) with true poses and clean images, the
    /// points' mean stood 0.51, 0.33 and 0.09 m above the three targets' centroids, the rays'
    /// nearest point 0.01–0.05 m. Over 28 targets of ten flights (three worlds), the rays'
    /// point in the frame flown was within 0.5 m of the centroid on 23 against the filter's
    /// 19; with each ray moved to its true pose, its height was 0.08 m off (median; 90th
    /// percentile 0.17 m). Session 49 (`docs/campaigns/2026-11-30-session49-*`).
    ///
    /// Why the depth, where the rays cannot: the depth inside one box already places the rock
    /// across the view. Rendered from 25 views around the fine-localization circle (10 m up, 55° down,
    /// with the sensor's depth noise), the median of those centres came within 0.15 m of the
    /// centroid on all 11 targets of three worlds, and on 15 fine-localization sequences
    /// `scarp localize` came 0.17 m off (median) against 0.23 m. In flight it has not shown:
    /// over a 55-target campaign (session 46) the horizontal error was 0.24 m (median) against
    /// 0.22 m with the points' mean.
    pub center_from_depth_views: usize,
}

impl Default for LocalizationConfig {
    fn default() -> Self {
        Self {
            points_per_target: 2000,
            box_enlargement_px: 30.0,
            min_depth_m: 3.0,
            max_depth_m: 18.0,
            birth_depth_from_image: false,
            update_noise_sigma_m: 0.1,
            gaussian_weight: 0.2,
            uniform_weight: 0.8,
            free_space_weight: 1.0,
            free_space_margin_m: 0.2,
            free_space_margin_per_m: 0.0022,
            keyframe_translation_m: 1.5,
            keyframe_rotation_deg: 30.0,
            ready_entropy_nats: 3.0,
            converged_kl_nats: 0.01,
            converged_kl_floor_m: 0.0,
            converged_updates: 3,
            converged_min_view_span_deg: 120.0,
            merge_distance_m: 1.0,
            confirm_hits: 5,
            max_misses: 3,
            min_points_in_cone: 1,
            center_from_depth_views: 3,
        }
    }
}

impl LocalizationConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`LocalizationError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), LocalizationError> {
        let bad = |field: &'static str, value: f64, reason: &'static str| {
            Err(LocalizationError::InvalidConfig {
                field,
                value,
                reason,
            })
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        if self.points_per_target < 4 {
            return bad(
                "points_per_target",
                self.points_per_target as f64,
                "must be at least 4",
            );
        }
        if !non_negative(self.box_enlargement_px) {
            return bad(
                "box_enlargement_px",
                self.box_enlargement_px,
                "must be finite and ≥ 0",
            );
        }
        if !positive(self.min_depth_m) {
            return bad("min_depth_m", self.min_depth_m, "must be finite and > 0");
        }
        if !(self.max_depth_m.is_finite() && self.max_depth_m > self.min_depth_m) {
            return bad(
                "max_depth_m",
                self.max_depth_m,
                "must be finite and above min_depth_m",
            );
        }
        if !non_negative(self.update_noise_sigma_m) {
            return bad(
                "update_noise_sigma_m",
                self.update_noise_sigma_m,
                "must be finite and ≥ 0",
            );
        }
        if !non_negative(self.gaussian_weight) {
            return bad(
                "gaussian_weight",
                self.gaussian_weight,
                "must be finite and ≥ 0",
            );
        }
        if !non_negative(self.uniform_weight) {
            return bad(
                "uniform_weight",
                self.uniform_weight,
                "must be finite and ≥ 0",
            );
        }
        if self.gaussian_weight + self.uniform_weight <= 0.0 {
            return bad(
                "uniform_weight",
                self.uniform_weight,
                "gaussian_weight + uniform_weight must be > 0",
            );
        }
        if !(self.free_space_weight > 0.0 && self.free_space_weight <= 1.0) {
            return bad(
                "free_space_weight",
                self.free_space_weight,
                "must lie in (0, 1]",
            );
        }
        if !non_negative(self.free_space_margin_m) {
            return bad(
                "free_space_margin_m",
                self.free_space_margin_m,
                "must be finite and ≥ 0",
            );
        }
        if !non_negative(self.free_space_margin_per_m) {
            return bad(
                "free_space_margin_per_m",
                self.free_space_margin_per_m,
                "must be finite and ≥ 0",
            );
        }
        if !non_negative(self.keyframe_translation_m) {
            return bad(
                "keyframe_translation_m",
                self.keyframe_translation_m,
                "must be finite and ≥ 0",
            );
        }
        if !non_negative(self.keyframe_rotation_deg) {
            return bad(
                "keyframe_rotation_deg",
                self.keyframe_rotation_deg,
                "must be finite and ≥ 0",
            );
        }
        if !self.ready_entropy_nats.is_finite() {
            return bad(
                "ready_entropy_nats",
                self.ready_entropy_nats,
                "must be finite",
            );
        }
        if !non_negative(self.converged_kl_nats) {
            return bad(
                "converged_kl_nats",
                self.converged_kl_nats,
                "must be finite and ≥ 0",
            );
        }
        if !non_negative(self.converged_kl_floor_m) {
            return bad(
                "converged_kl_floor_m",
                self.converged_kl_floor_m,
                "must be finite and ≥ 0",
            );
        }
        if !(0.0..=360.0).contains(&self.converged_min_view_span_deg) {
            return bad(
                "converged_min_view_span_deg",
                self.converged_min_view_span_deg,
                "must lie in [0, 360]",
            );
        }
        if self.converged_updates == 0 {
            return bad("converged_updates", 0.0, "must be at least 1");
        }
        if !non_negative(self.merge_distance_m) {
            return bad(
                "merge_distance_m",
                self.merge_distance_m,
                "must be finite and ≥ 0",
            );
        }
        if self.max_misses == 0 {
            return bad("max_misses", 0.0, "must be at least 1");
        }
        if self.min_points_in_cone == 0 {
            return bad("min_points_in_cone", 0.0, "must be at least 1");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_match_design() {
        let c = LocalizationConfig::default();
        c.validate().unwrap();
        assert_eq!(c.points_per_target, 2000);
        assert_eq!((c.min_depth_m, c.max_depth_m), (3.0, 18.0));
        assert_eq!((c.gaussian_weight, c.uniform_weight), (0.2, 0.8));
    }

    #[test]
    fn bad_fields_are_named() {
        let c = LocalizationConfig {
            max_depth_m: 2.0,
            ..Default::default()
        };
        let err = c.validate().unwrap_err();
        assert!(err.to_string().contains("max_depth_m"), "{err}");
        for (field, value) in [
            ("free_space_weight", 0.0),
            ("free_space_weight", 1.5),
            ("free_space_margin_m", -0.1),
            ("free_space_margin_per_m", f64::NAN),
            ("converged_kl_floor_m", -0.3),
        ] {
            let mut c = LocalizationConfig::default();
            match field {
                "free_space_weight" => c.free_space_weight = value,
                "free_space_margin_m" => c.free_space_margin_m = value,
                "converged_kl_floor_m" => c.converged_kl_floor_m = value,
                _ => c.free_space_margin_per_m = value,
            }
            let err = c.validate().unwrap_err();
            assert!(err.to_string().contains(field), "{err}");
        }
        let toml_text = "points_per_target = 500\n";
        let c: LocalizationConfig = toml::from_str(toml_text).unwrap();
        assert_eq!(c.points_per_target, 500);
        assert_eq!(c.max_misses, 3);
    }
}
