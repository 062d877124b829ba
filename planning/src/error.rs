//! The crate's error type.

use thiserror::Error;

/// Everything that can go wrong while planning, checking or flying a path.
///
/// Each variant names the field or value at fault, so a caller can tell the user what to fix.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlanError {
    /// A number that must be finite is NaN or infinite.
    #[error("`{field}` is not finite ({value})")]
    NonFinite {
        /// Which input, e.g. `waypoints[3].position_m`.
        field: String,
        /// The offending value.
        value: f64,
    },
    /// A parameter is outside its valid range.
    #[error("`{field}` = {value} is invalid: {reason}")]
    InvalidParameter {
        /// Which parameter, e.g. `radius_m`.
        field: String,
        /// The offending value.
        value: f64,
        /// What the valid range is.
        reason: String,
    },
    /// Too few points or waypoints were given.
    #[error("`{field}` needs at least {need} entries, got {got}")]
    TooFew {
        /// Which input.
        field: String,
        /// How many were given.
        got: usize,
        /// How many are needed.
        need: usize,
    },
    /// Two consecutive waypoints are identical in position and yaw, so the segment between them
    /// has no length and no duration.
    #[error("waypoints {index} and {} are identical (position and yaw)", index + 1)]
    DuplicateWaypoint {
        /// Index of the first of the two waypoints.
        index: usize,
    },
    /// The target lies below the terrain surface.
    #[error(
        "target at z = {target_z_m:.3} m is below the terrain (z = {terrain_z_m:.3} m at x = {x_m:.3}, y = {y_m:.3})"
    )]
    TargetBelowTerrain {
        /// Height of the target (world z, metres).
        target_z_m: f64,
        /// Terrain height under the target (world z, metres).
        terrain_z_m: f64,
        /// World x of the query (metres).
        x_m: f64,
        /// World y of the query (metres).
        y_m: f64,
    },
    /// A terrain-following ring would have to climb this far above its planned height to keep
    /// its clearance over a slope: from there it no longer looks level at the rock's base, and
    /// part of it may see the rock only beyond the depth range.
    #[error(
        "ring {ring} would climb {lift_m:.2} m over the slope to keep its clearance (limit {limit_m:.2} m): it no longer looks level at the base"
    )]
    TerrainLift {
        /// Index of the ring in flying order.
        ring: usize,
        /// The largest climb of its waypoints (metres).
        lift_m: f64,
        /// The configured limit (metres).
        limit_m: f64,
    },
    /// The search altitude is not above the target, so no circle with the camera pitch exists.
    #[error(
        "search altitude h_s = {search_altitude_m:.3} m must be above the target centre z_e = {target_z_m:.3} m"
    )]
    AltitudeBelowTarget {
        /// Search altitude (world z, metres).
        search_altitude_m: f64,
        /// Target centre height (world z, metres).
        target_z_m: f64,
    },
    /// The terrain grid is malformed.
    #[error(transparent)]
    InvalidTerrain(#[from] scarp_slam::SlamError),
    /// An obstacle is malformed.
    #[error("obstacle {index}: {reason}")]
    InvalidObstacle {
        /// Index of the obstacle in the list given.
        index: usize,
        /// What is wrong.
        reason: String,
    },
    /// The linear solve of the min-snap QP failed.
    #[error("min-snap solve failed: {reason}")]
    Solver {
        /// What failed.
        reason: String,
    },
    /// The start velocity already exceeds the speed limit.
    #[error("start speed {speed_mps:.3} m/s exceeds v_max = {v_max_mps:.3} m/s")]
    StartTooFast {
        /// Speed of the given start velocity (m/s).
        speed_mps: f64,
        /// The configured limit (m/s).
        v_max_mps: f64,
    },
    /// Time scaling did not bring the trajectory within the motion limits.
    #[error(
        "trajectory exceeds limits after time scaling: speed {speed_mps:.3} m/s (max {v_max_mps}), acceleration {accel_mps2:.3} m/s² (max {a_max_mps2})"
    )]
    LimitsNotMet {
        /// Peak sampled speed (m/s).
        speed_mps: f64,
        /// Peak sampled acceleration (m/s²).
        accel_mps2: f64,
        /// Speed limit (m/s).
        v_max_mps: f64,
        /// Acceleration limit (m/s²).
        a_max_mps2: f64,
    },
    /// A plan comes too close to the terrain or an obstacle and could not be repaired.
    #[error(
        "clearance {clearance_m:.3} m < required {required_m:.3} m near ({x_m:.2}, {y_m:.2}, {z_m:.2}) [{source_name}]: {reason}"
    )]
    Clearance {
        /// The smallest clearance found (metres; negative means inside the terrain or obstacle).
        clearance_m: f64,
        /// The required minimum (metres).
        required_m: f64,
        /// World x of the worst point (metres).
        x_m: f64,
        /// World y of the worst point (metres).
        y_m: f64,
        /// World z of the worst point (metres).
        z_m: f64,
        /// What was hit: `terrain` or `obstacle N`.
        source_name: String,
        /// Why no repair was possible.
        reason: String,
    },
    /// Writing or drawing an output failed.
    #[error("cannot write {path}: {reason}")]
    Output {
        /// The file (or `(in memory)` for drawing).
        path: String,
        /// What failed.
        reason: String,
    },
    /// The simulated vehicle left the reference so far that the flight was abandoned.
    #[error("flight diverged at t = {time_s:.2} s: position error {position_error_m:.2} m")]
    FlightDiverged {
        /// Simulation time (s).
        time_s: f64,
        /// Position error at that time (metres).
        position_error_m: f64,
    },
}

/// Returns an error naming `field` if `value` is not finite.
pub(crate) fn check_finite(field: impl Into<String>, value: f64) -> Result<f64, PlanError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(PlanError::NonFinite {
            field: field.into(),
            value,
        })
    }
}

/// Returns an error naming `field` unless `value` is finite and strictly positive.
pub(crate) fn check_positive(field: impl Into<String>, value: f64) -> Result<f64, PlanError> {
    let field = field.into();
    check_finite(field.clone(), value)?;
    if value > 0.0 {
        Ok(value)
    } else {
        Err(PlanError::InvalidParameter {
            field,
            value,
            reason: "must be > 0".into(),
        })
    }
}

/// Returns an error naming `field` unless `value` is finite and in `[lo, hi]`.
pub(crate) fn check_range(
    field: impl Into<String>,
    value: f64,
    lo: f64,
    hi: f64,
) -> Result<f64, PlanError> {
    let field = field.into();
    check_finite(field.clone(), value)?;
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(PlanError::InvalidParameter {
            field,
            value,
            reason: format!("must be in [{lo}, {hi}]"),
        })
    }
}

/// Returns an error naming `field` if any coordinate of the point is not finite.
pub(crate) fn check_point(
    field: impl Into<String>,
    p: &nalgebra::Point3<f64>,
) -> Result<(), PlanError> {
    let field = field.into();
    for (axis, v) in ["x", "y", "z"].iter().zip(p.iter()) {
        if !v.is_finite() {
            return Err(PlanError::NonFinite {
                field: format!("{field}.{axis}"),
                value: *v,
            });
        }
    }
    Ok(())
}

/// Returns an error naming `field` if any component of the vector is not finite.
pub(crate) fn check_vector(
    field: impl Into<String>,
    v: &nalgebra::Vector3<f64>,
) -> Result<(), PlanError> {
    check_point(field, &nalgebra::Point3::from(*v))
}
