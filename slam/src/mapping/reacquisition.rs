//! Re-acquiring the map after a gap in view, when the state estimate has walked.
//!
//! The tracker's guess for a frame is the previous kept frame moved by the state estimate's
//! motion since then. Over a fraction of a second that motion is right to centimetres; but
//! when the target has been out of view for seconds, a GPS-grade estimate walks by up to metres
//! (σ 0.5 m with a 30 s correlation time: 1.3 m in 14 s on holdout-c seed 48), while the
//! odometry corrects a guess by at most [`crate::odometry::OdometryConfig::max_correction_m`].
//! A single guess then either diverges or converges beside the truth; the keyframe taken there
//! shifts the rest of the map (session 33: a 1.3 m shift, two rocks in one volume).
//!
//! So the first frame after a gap is tracked from a grid of guesses that spans the estimate's
//! walk over the gap ([`ReacquisitionSearch::offsets_m`]), and the best is kept
//! ([`crate::odometry::track_multi_start`]). Only the position is searched: the attitude's walk
//! over the same time is a degree or two, within the odometry's reach.
//!
//! The first frame kept after a run of dropped frames is searched for too, however short the
//! run ([`ReacquisitionSearch::after_dropped_frames`]): the frames were dropped because the
//! odometry met a view it could not track, and the estimate's motion over the run is off by
//! its white noise and its walk at once, decimetres (default world, seed 62, session 65: 0.4 m
//! over a 0.9 s run; the one guess converged 0.13 m beside the truth at an inlier ratio of
//! 0.34, became a keyframe, and split the map in two, F@2cm 0.34).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::MappingError;

/// How far to search for the first frame after a gap, from the state estimator's position walk:
/// a first-order Gauss–Markov process per axis (σ, correlation time τ) plus white noise per
/// sample. The difference of two of its positions Δt apart has, per axis, the standard
/// deviation `√(2σ²(1 − e^(−Δt/τ)) + 2w²)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReacquisitionSearch {
    /// A frame this long after the previous kept one (seconds, by timestamp) is searched for.
    pub min_gap_s: f64,
    /// The first frame after frames were dropped (see
    /// [`super::ModelTrackingConfig::max_dropped_frames`]) is searched for as well, whatever
    /// the gap.
    pub after_dropped_frames: bool,
    /// The walk's σ per horizontal axis, metres.
    pub horizontal_sigma_m: f64,
    /// The walk's σ vertically, metres.
    pub vertical_sigma_m: f64,
    /// The walk's correlation time τ, seconds.
    pub correlation_s: f64,
    /// The estimate's white noise per sample, per axis, metres.
    pub white_sigma_m: f64,
    /// The search spans this many σ of the difference, horizontally (radius) and vertically
    /// (half height).
    pub sigmas: f64,
    /// Spacing of the grid of guesses, metres. Each point of the searched region is within
    /// `step_m · √3 / 2` of a guess, which must be within the odometry's reach. A search
    /// narrower than this (after a short run of dropped frames) is spaced at its own extent,
    /// the larger of its radius and half height, so that it still tries a guess either way of
    /// the plain one: a one-guess search is the plain guess that converged 6 cm beside the
    /// truth after a 0.24 s run (default world, seed 62, session 65).
    pub step_m: f64,
    /// At most this many guesses; a longer grid is spaced wider to fit.
    pub max_starts: usize,
    /// Besides the plain guess, this many of the best-ranked guesses are tracked in full.
    pub refine_starts: usize,
}

impl ReacquisitionSearch {
    /// The search for an estimator whose position walks with σ `horizontal_sigma_m` and
    /// `vertical_sigma_m` per axis, correlation time `correlation_s` and white noise
    /// `white_sigma_m`: after a gap of 1 s or more or after dropped frames, 3 σ of the walk,
    /// guesses 0.4 m apart (every point of the search within 0.35 m of one, inside the
    /// odometry's 0.5 m reach), at most 1500 of them, the best 4 tracked in full.
    pub fn for_walk(
        horizontal_sigma_m: f64,
        vertical_sigma_m: f64,
        correlation_s: f64,
        white_sigma_m: f64,
    ) -> Self {
        Self {
            min_gap_s: 1.0,
            after_dropped_frames: true,
            horizontal_sigma_m,
            vertical_sigma_m,
            correlation_s,
            white_sigma_m,
            sigmas: 3.0,
            step_m: 0.4,
            max_starts: 1500,
            refine_starts: 4,
        }
    }

    /// The standard deviation per horizontal and vertical axis of the walk between two
    /// positions `gap_s` seconds apart, metres (a negative or non-finite gap counts as 0).
    pub fn difference_sigma_m(&self, gap_s: f64) -> (f64, f64) {
        let gap_s = if gap_s.is_finite() {
            gap_s.max(0.0)
        } else {
            0.0
        };
        let correlated = 2.0 * (1.0 - (-gap_s / self.correlation_s).exp());
        let white = 2.0 * self.white_sigma_m.powi(2);
        let sigma = |walk: f64| (walk.powi(2) * correlated + white).sqrt();
        (sigma(self.horizontal_sigma_m), sigma(self.vertical_sigma_m))
    }

    /// Whether the frame `gap_s` seconds after the previous kept one, with `dropped_frames`
    /// dropped between them, is searched for: a gap of [`Self::min_gap_s`] or more, or
    /// dropped frames when [`Self::after_dropped_frames`].
    pub fn applies(&self, gap_s: f64, dropped_frames: usize) -> bool {
        gap_s >= self.min_gap_s || (self.after_dropped_frames && dropped_frames > 0)
    }

    /// The world-frame offsets (ENU metres) to add to the plain guess's position after a gap
    /// of `gap_s` seconds: a cubic grid over the cylinder of radius `sigmas ·` σ horizontal and
    /// half height `sigmas ·` σ vertical, nearest first, the zero offset (the plain guess)
    /// first of all. Whether to search at all is [`Self::applies`].
    pub fn offsets_m(&self, gap_s: f64) -> Vec<Vector3<f64>> {
        let (horizontal, vertical) = self.difference_sigma_m(gap_s);
        let radius_m = self.sigmas * horizontal;
        let half_height_m = self.sigmas * vertical;
        let extent_m = radius_m.max(half_height_m);
        if !(extent_m > 0.0) {
            return vec![Vector3::zeros()];
        }
        let mut step_m = self.step_m.min(extent_m);
        loop {
            let offsets = grid(radius_m, half_height_m, step_m);
            if offsets.len() <= self.max_starts.max(1) {
                return offsets;
            }
            step_m *= 1.1;
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`MappingError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), MappingError> {
        for (field, value) in [
            ("reacquisition.min_gap_s", self.min_gap_s),
            ("reacquisition.horizontal_sigma_m", self.horizontal_sigma_m),
            ("reacquisition.vertical_sigma_m", self.vertical_sigma_m),
            ("reacquisition.white_sigma_m", self.white_sigma_m),
            ("reacquisition.sigmas", self.sigmas),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(MappingError::InvalidConfig {
                    field,
                    reason: "must be finite and not negative",
                });
            }
        }
        for (field, value) in [
            ("reacquisition.correlation_s", self.correlation_s),
            ("reacquisition.step_m", self.step_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(MappingError::InvalidConfig {
                    field,
                    reason: "must be positive and finite",
                });
            }
        }
        if self.max_starts == 0 {
            return Err(MappingError::InvalidConfig {
                field: "reacquisition.max_starts",
                reason: "must be at least 1",
            });
        }
        Ok(())
    }
}

/// Points of the cubic lattice of spacing `step_m` through the origin inside the vertical
/// cylinder (radius, half height) about it, nearest first (ties in lattice order).
fn grid(radius_m: f64, half_height_m: f64, step_m: f64) -> Vec<Vector3<f64>> {
    let nh = (radius_m / step_m).floor() as i64;
    let nv = (half_height_m / step_m).floor() as i64;
    let mut offsets = Vec::new();
    for k in -nv..=nv {
        for j in -nh..=nh {
            for i in -nh..=nh {
                let offset = Vector3::new(i as f64, j as f64, k as f64) * step_m;
                if offset.xy().norm() <= radius_m + 1e-9 {
                    offsets.push(offset);
                }
            }
        }
    }
    // A stable sort keeps the lattice order among equal distances: deterministic.
    offsets.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
    offsets
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gps() -> ReacquisitionSearch {
        ReacquisitionSearch::for_walk(0.5, 0.8, 30.0, 0.02)
    }

    #[test]
    fn the_walk_of_a_difference_grows_to_twice_the_variance() {
        let search = gps();
        let (h0, v0) = search.difference_sigma_m(0.0);
        assert!((h0 - 0.02 * 2f64.sqrt()).abs() < 1e-12 && (v0 - h0).abs() < 1e-12);
        let (h, v) = search.difference_sigma_m(1e6);
        assert!(
            (h - (2.0 * 0.25 + 2.0 * 0.0004f64).sqrt()).abs() < 1e-9,
            "{h}"
        );
        assert!(
            (v - (2.0 * 0.64 + 2.0 * 0.0004f64).sqrt()).abs() < 1e-9,
            "{v}"
        );
        // One correlation time: 1 − 1/e of the way.
        let (h_tau, _) = search.difference_sigma_m(30.0);
        let expected = (2.0 * 0.25 * (1.0 - (-1f64).exp()) + 0.0008).sqrt();
        assert!((h_tau - expected).abs() < 1e-12);
        assert_eq!(
            search.difference_sigma_m(f64::NAN),
            search.difference_sigma_m(0.0)
        );
    }

    #[test]
    fn the_grid_spans_the_walk_nearest_first_and_fits_the_budget() {
        let search = gps();
        assert!(!search.applies(0.5, 0), "below the minimum gap");
        assert!(search.applies(0.5, 3) && search.applies(1.0, 0));
        let no_drop_rule = ReacquisitionSearch {
            after_dropped_frames: false,
            ..search
        };
        assert!(!no_drop_rule.applies(0.5, 3) && no_drop_rule.applies(1.0, 0));
        // A short run's grid: the walk's vertical σ over 0.9 s reaches a step up and down.
        let short = search.offsets_m(0.9);
        assert_eq!(short[0], Vector3::zeros());
        assert!(short.len() >= 3, "{short:?}");
        // A shorter one's grid is spaced at its extent: one guess up and one down at least.
        let (_, vertical) = search.difference_sigma_m(0.24);
        let shortest = search.offsets_m(0.24);
        assert!(3.0 * vertical < 0.4, "{vertical}");
        assert!(
            shortest.contains(&Vector3::new(0.0, 0.0, 3.0 * vertical))
                && shortest.contains(&Vector3::new(0.0, 0.0, -3.0 * vertical)),
            "{shortest:?}"
        );
        let none = ReacquisitionSearch {
            sigmas: 0.0,
            ..search
        };
        assert_eq!(none.offsets_m(5.0), vec![Vector3::zeros()]);
        let offsets = search.offsets_m(14.0);
        assert_eq!(offsets[0], Vector3::zeros());
        assert!(offsets.windows(2).all(|w| w[0].norm() <= w[1].norm()));
        let (h, v) = search.difference_sigma_m(14.0);
        // Holdout-c seed 48's 1.34 m walk in 14 s lies within a grid cell of a guess.
        assert!(3.0 * h > 1.2, "{h}");
        let walked = Vector3::new(1.0, -0.85, 0.3);
        let nearest = offsets
            .iter()
            .map(|o| (o - walked).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(nearest <= 0.4 * 3f64.sqrt() / 2.0 + 1e-9, "{nearest}");
        for o in &offsets {
            assert!(o.xy().norm() <= 3.0 * h + 1e-9 && o.z.abs() <= 3.0 * v + 1e-9);
        }
        let squeezed = ReacquisitionSearch {
            max_starts: 50,
            ..search
        }
        .offsets_m(14.0);
        assert!(
            squeezed.len() <= 50 && squeezed.len() > 10,
            "{}",
            squeezed.len()
        );
        assert_eq!(squeezed[0], Vector3::zeros());
    }

    #[test]
    fn bad_settings_are_named() {
        let bad = ReacquisitionSearch {
            step_m: 0.0,
            ..gps()
        };
        let err = bad.validate().unwrap_err().to_string();
        assert!(err.contains("reacquisition.step_m"), "{err}");
        assert!(gps().validate().is_ok());
    }
}
