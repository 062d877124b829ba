//! One target: its point set, Gaussian fit, counters and status.

use nalgebra::{Isometry3, Point2, Point3};
use serde::{Deserialize, Serialize};

use super::LocalizationConfig;
use super::gaussian::{Ellipsoid, Gaussian3};
use super::triangulation::{BoxRay, nearest_point, span_deg, view_arc_deg};

/// The least spread of the keyframe boxes' rays for C_e to come from their nearest point
/// ([`Target::located_center`]): the smallest eigenvalue of their mean `I − d dᵀ`, about that
/// of views 26° apart. Rays from a narrower arc place the object badly along the line of sight.
const MIN_RAY_SPREAD: f64 = 0.05;

/// Where a target stands. Statuses only move forward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetStatus {
    /// Points are being filtered; the set is still spread out.
    Tracking,
    /// The point-set entropy h_p fell below the threshold: plan the fine-localization circle.
    ReadyForFineLocalization,
    /// KL between successive fits stayed at or below the threshold for the configured number of
    /// updates in a row (while ready).
    Converged,
}

impl TargetStatus {
    /// `tracking`, `ready_for_fine_localization` or `converged`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Tracking => "tracking",
            Self::ReadyForFineLocalization => "ready_for_fine_localization",
            Self::Converged => "converged",
        }
    }
}

/// A target of the depth filter. Points are world ENU, metres.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    pub(crate) id: u32,
    pub(crate) status: TargetStatus,
    pub(crate) points: Vec<Point3<f64>>,
    pub(crate) gaussian: Gaussian3,
    pub(crate) last_kl_nats: Option<f64>,
    pub(crate) small_kl_streak: u32,
    pub(crate) updates: u32,
    pub(crate) hits: u32,
    pub(crate) misses: u32,
    pub(crate) last_update_world_from_camera: Isometry3<f64>,
    pub(crate) last_track_id: Option<u64>,
    /// Where the camera was at registration and at every update (world, m).
    pub(crate) view_positions: Vec<Point3<f64>>,
    /// Set by [`super::TargetCatalog::restart_on_next_box`]: the next box paired with this
    /// target starts its points afresh.
    pub(crate) restart_pending: bool,
    /// The object's horizontal centre that the depth inside each keyframe box gave (world xy,
    /// m), since registration or the last restart.
    pub(crate) seen_centers_xy: Vec<Point2<f64>>,
    /// The ray through each keyframe box's centre (world), since registration or the last
    /// restart.
    pub(crate) box_rays: Vec<BoxRay>,
}

impl Target {
    /// A new target from freshly generated `points` (at least 2, finite), seen by a camera at
    /// `world_from_camera` (its first keyframe).
    ///
    /// # Errors
    /// [`super::LocalizationError::TooFewPoints`] when the points cannot be fitted.
    pub fn new(
        id: u32,
        points: Vec<Point3<f64>>,
        world_from_camera: Isometry3<f64>,
        track_id: Option<u64>,
    ) -> Result<Self, super::LocalizationError> {
        let gaussian = Gaussian3::from_points(&points)?;
        Ok(Self {
            id,
            status: TargetStatus::Tracking,
            points,
            gaussian,
            last_kl_nats: None,
            small_kl_streak: 0,
            updates: 0,
            hits: 1,
            misses: 0,
            last_update_world_from_camera: world_from_camera,
            last_track_id: track_id,
            view_positions: vec![Point3::from(world_from_camera.translation.vector)],
            restart_pending: false,
            seen_centers_xy: Vec::new(),
            box_rays: Vec::new(),
        })
    }

    /// Starts the filter again from freshly generated `points` seen at `world_from_camera`, as
    /// [`Self::new`] does, keeping the id, the hit and miss counters and the track: every
    /// earlier view is forgotten, with the state estimate's error at those views.
    ///
    /// # Errors
    /// [`super::LocalizationError::TooFewPoints`] when the points cannot be fitted; the
    /// target is then left unchanged.
    pub fn restart(
        &mut self,
        points: Vec<Point3<f64>>,
        world_from_camera: Isometry3<f64>,
    ) -> Result<(), super::LocalizationError> {
        let fresh = Self::new(self.id, points, world_from_camera, self.last_track_id)?;
        *self = Self {
            hits: self.hits,
            misses: self.misses,
            ..fresh
        };
        Ok(())
    }

    /// Whether the next paired box restarts the filter.
    pub fn restart_pending(&self) -> bool {
        self.restart_pending
    }

    /// Replaces the points after an update and advances the status: KL of the new fit against
    /// the previous one (both widened by `converged_kl_floor_m`), the small-KL streak, then
    /// Tracking → ReadyForFineLocalization (h_p < `ready_entropy_nats`) → Converged
    /// (`converged_updates` updates in a row with KL ≤ `converged_kl_nats`, while ready, once
    /// the views span `converged_min_view_span_deg` around the target: see
    /// [`Self::view_span_deg`]).
    ///
    /// # Errors
    /// [`super::LocalizationError::TooFewPoints`] when the new points cannot be fitted; the
    /// target is then left unchanged.
    pub fn apply_update(
        &mut self,
        points: Vec<Point3<f64>>,
        world_from_camera: Isometry3<f64>,
        config: &LocalizationConfig,
    ) -> Result<(), super::LocalizationError> {
        let gaussian = Gaussian3::from_points(&points)?;
        let floor_m2 = config.converged_kl_floor_m.powi(2);
        let kl = gaussian
            .with_variance_floor(floor_m2)
            .kl_divergence(&self.gaussian.with_variance_floor(floor_m2));
        self.points = points;
        self.gaussian = gaussian;
        self.last_kl_nats = Some(kl);
        self.updates += 1;
        self.last_update_world_from_camera = world_from_camera;
        self.view_positions
            .push(Point3::from(world_from_camera.translation.vector));
        if kl <= config.converged_kl_nats {
            self.small_kl_streak += 1;
        } else {
            self.small_kl_streak = 0;
        }
        self.advance_status(config);
        Ok(())
    }

    fn advance_status(&mut self, config: &LocalizationConfig) {
        if self.status == TargetStatus::Tracking
            && self.gaussian.entropy_nats() < config.ready_entropy_nats
        {
            self.status = TargetStatus::ReadyForFineLocalization;
        }
        if self.status == TargetStatus::ReadyForFineLocalization
            && self.small_kl_streak >= config.converged_updates
            && self.view_span_deg() >= config.converged_min_view_span_deg
        {
            self.status = TargetStatus::Converged;
        }
    }

    /// The catalog's id of this target (1, 2, … in order of registration).
    pub fn id(&self) -> u32 {
        self.id
    }

    /// The horizontal angle the views of this target span around its centre, degrees in
    /// [0, 360): 360° less the widest gap between the bearings (from the centre, in the world xy
    /// plane) of the camera at registration and at every update.
    pub fn view_span_deg(&self) -> f64 {
        let c = self.center();
        let bearings: Vec<f64> = self
            .view_positions
            .iter()
            .filter(|p| (p.x - c.x).hypot(p.y - c.y) > 1e-9)
            .map(|p| (p.y - c.y).atan2(p.x - c.x).to_degrees())
            .collect();
        span_deg(bearings)
    }

    /// Current status.
    pub fn status(&self) -> TargetStatus {
        self.status
    }

    /// The point set, world frame, m.
    pub fn points(&self) -> &[Point3<f64>] {
        &self.points
    }

    /// The Gaussian fit of the points.
    pub fn gaussian(&self) -> &Gaussian3 {
        &self.gaussian
    }

    /// Mean of the points, world frame, m: the paper's C_e, which the filter's own tests (the
    /// view span, misses in view) use.
    pub fn center(&self) -> Point3<f64> {
        self.gaussian.mean
    }

    /// Records the object's horizontal centre (world xy, m) that the depth inside this
    /// keyframe's box gave.
    pub fn record_seen_center(&mut self, center_xy: Point2<f64>) {
        self.seen_centers_xy.push(center_xy);
    }

    /// Records the ray through this keyframe box's centre.
    pub fn record_box_ray(&mut self, ray: BoxRay) {
        self.box_rays.push(ray);
    }

    /// How many keyframe boxes' rays are recorded.
    pub fn box_rays(&self) -> usize {
        self.box_rays.len()
    }

    /// How far around `center` (world ENU, m) this target's keyframe boxes were seen from,
    /// degrees ([`super::triangulation::view_arc_deg`]).
    pub fn view_arc_deg(&self, center: &Point3<f64>) -> f64 {
        view_arc_deg(&self.box_rays, center)
    }

    /// How many keyframes gave an object centre from their depth.
    pub fn seen_centers(&self) -> usize {
        self.seen_centers_xy.len()
    }

    /// C_e as the mission reports and plans with it, world frame, m, once at least
    /// `min_views` > 0 keyframes gave their evidence (else, and with 0, the points' mean): the
    /// point nearest the keyframe boxes' central rays
    /// ([`super::triangulation::nearest_point`]) where they spread enough to place it;
    /// otherwise horizontally the median (per axis) of the object centres the depth in the
    /// boxes gave, and vertically the points' mean. See
    /// [`LocalizationConfig::center_from_depth_views`].
    pub fn located_center(&self, min_views: usize) -> Point3<f64> {
        let mean = self.center();
        if min_views == 0 {
            return mean;
        }
        if self.box_rays.len() >= min_views
            && let Some(point) = nearest_point(&self.box_rays, MIN_RAY_SPREAD)
        {
            return point;
        }
        if self.seen_centers_xy.len() < min_views {
            return mean;
        }
        let median = |axis: fn(&Point2<f64>) -> f64, fallback: f64| {
            let mut values: Vec<f64> = self.seen_centers_xy.iter().map(axis).collect();
            scarp_slam::stats::quantile_in_place(&mut values, 0.5).unwrap_or(fallback)
        };
        Point3::new(median(|p| p.x, mean.x), median(|p| p.y, mean.y), mean.z)
    }

    /// Covariance of the points, m².
    pub fn covariance(&self) -> nalgebra::Matrix3<f64> {
        self.gaussian.covariance
    }

    /// PCA ellipsoid of the points (right-handed).
    pub fn ellipsoid(&self) -> Ellipsoid {
        self.gaussian.ellipsoid()
    }

    /// Largest covariance eigenvalue λ_max, m².
    pub fn lambda_max(&self) -> f64 {
        self.gaussian.lambda_max()
    }

    /// Differential entropy h_p of the Gaussian fit, nats.
    pub fn entropy_nats(&self) -> f64 {
        self.gaussian.entropy_nats()
    }

    /// KL divergence of the last update against the fit before it, nats; `None` before the
    /// first update.
    pub fn last_kl_nats(&self) -> Option<f64> {
        self.last_kl_nats
    }

    /// Updates applied (keyframes with a box on this target).
    pub fn updates(&self) -> u32 {
        self.updates
    }

    /// Frames in which a box matched this target.
    pub fn hits(&self) -> u32 {
        self.hits
    }

    /// Frames in a row in which the target was in view but no box matched it.
    pub fn misses(&self) -> u32 {
        self.misses
    }

    /// Whether the target has enough hits never to be removed for misses.
    pub fn is_confirmed(&self, config: &LocalizationConfig) -> bool {
        self.hits >= config.confirm_hits
    }

    /// The camera pose of the last update (or of registration), `world_from_camera`.
    pub fn last_update_world_from_camera(&self) -> &Isometry3<f64> {
        &self.last_update_world_from_camera
    }

    /// The tracker's id of the last box that matched this target.
    pub fn last_track_id(&self) -> Option<u64> {
        self.last_track_id
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn cube(scale: f64, offset: f64) -> Vec<Point3<f64>> {
        let mut v = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                for k in 0..10 {
                    let p = Vector3::new(i as f64, j as f64, k as f64 * 1.1) * scale;
                    v.push(Point3::from(p + Vector3::repeat(offset)));
                }
            }
        }
        v
    }

    #[test]
    fn status_moves_to_ready_then_converged() {
        // The KL rule alone (the paper's): every view from the same place.
        let cfg = LocalizationConfig {
            converged_min_view_span_deg: 0.0,
            ..LocalizationConfig::default()
        };
        let mut t = Target::new(1, cube(1.0, 0.0), Isometry3::identity(), Some(4)).unwrap();
        assert_eq!(t.status(), TargetStatus::Tracking);
        // Compact but changing: ready, not converged.
        t.apply_update(cube(0.05, 0.0), Isometry3::identity(), &cfg)
            .unwrap();
        assert_eq!(t.status(), TargetStatus::ReadyForFineLocalization);
        t.apply_update(cube(0.05, 0.0), Isometry3::identity(), &cfg)
            .unwrap();
        t.apply_update(cube(0.05, 0.0), Isometry3::identity(), &cfg)
            .unwrap();
        assert_eq!(t.status(), TargetStatus::ReadyForFineLocalization);
        // A jump resets the streak.
        t.apply_update(cube(0.05, 1.0), Isometry3::identity(), &cfg)
            .unwrap();
        assert!(t.last_kl_nats().unwrap() > 1.0);
        for _ in 0..2 {
            t.apply_update(cube(0.05, 1.0), Isometry3::identity(), &cfg)
                .unwrap();
            assert_eq!(t.status(), TargetStatus::ReadyForFineLocalization);
        }
        t.apply_update(cube(0.05, 1.0), Isometry3::identity(), &cfg)
            .unwrap();
        assert_eq!(t.status(), TargetStatus::Converged);
        assert_eq!(t.updates(), 7);
        // Converged sticks.
        t.apply_update(cube(1.0, 0.0), Isometry3::identity(), &cfg)
            .unwrap();
        assert_eq!(t.status(), TargetStatus::Converged);
    }

    #[test]
    fn convergence_waits_for_views_from_around_the_target() {
        let cfg = LocalizationConfig::default();
        let centre = cube(0.05, 0.0);
        // A camera 7 m out at `bearing_deg` around the set's centre, 10 m up.
        let c = Target::new(1, centre.clone(), Isometry3::identity(), None)
            .unwrap()
            .center();
        let at = |bearing_deg: f64| {
            let b = bearing_deg.to_radians();
            Isometry3::translation(c.x + 7.0 * b.cos(), c.y + 7.0 * b.sin(), c.z + 10.0)
        };
        let mut t = Target::new(1, centre.clone(), at(0.0), None).unwrap();
        // Unchanging fits seen from within 60° of each other: not converged.
        for bearing in [20.0, 40.0, 60.0, 50.0] {
            t.apply_update(centre.clone(), at(bearing), &cfg).unwrap();
        }
        assert!(
            (t.view_span_deg() - 60.0).abs() < 1e-9,
            "{}",
            t.view_span_deg()
        );
        assert_eq!(t.status(), TargetStatus::ReadyForFineLocalization);
        // Views reaching 130° around it: converged.
        t.apply_update(centre.clone(), at(130.0), &cfg).unwrap();
        assert_eq!(t.status(), TargetStatus::Converged);
    }

    #[test]
    fn span_is_measured_across_the_wrap() {
        assert_eq!(span_deg(vec![]), 0.0);
        assert_eq!(span_deg(vec![10.0]), 0.0);
        assert!((span_deg(vec![170.0, -170.0]) - 20.0).abs() < 1e-9);
        assert!((span_deg(vec![0.0, 90.0, 180.0, 270.0]) - 270.0).abs() < 1e-9);
        assert!((span_deg(vec![-10.0, 350.0, 10.0]) - 20.0).abs() < 1e-9);
    }
}
