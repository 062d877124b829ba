//! Which position the controller flies on: the state estimate (its height corrected by the
//! safety monitor), moved into the map's frame while a target is mapped.
//!
//! A target's map is anchored at the state estimate of its first mapped frame, and its
//! cylinder, rings and coverage live in that frame. The GPS walk then moves the estimate away
//! from it (σ 0.5 m, τ 30 s: a metre in a ring's minute), while the odometry stays within
//! centimetres of the anchor. A vehicle flying its rings on the estimate therefore carries the
//! rings across the rock by the walk; holdout-c seed 47 flew into a rock that way while its
//! odometry was 5 cm from its anchor. So while mapping the vehicle flies on the map's
//! odometry, as a survey autopilot flies on its visual odometry near structure.
//!
//! The odometry enters as an offset: `map frame − estimate` at the last tracked frame. The
//! offset is
//! - taken at every frame the odometry tracked, when it is one the estimator could have walked
//!   to (beyond [`MapFrameOffset::gate_m`] the odometry is the one at fault, and the last
//!   plausible offset is kept);
//! - held while frames are dropped, unseen or failed (the estimate's motion carries on);
//! - held after mapping, while the vehicle backs away and climbs out (near the rock the map's
//!   frame is the one the rock is known in), then brought to zero at a walking pace
//!   ([`HANDOVER_SPEED_MPS`]) once it is clear, so the next target is found in the estimate's
//!   frame and the controller never sees a jump.

use nalgebra::Vector3;
use scarp_datasets::estimator::EstimatorConfig;

/// The speed at which the map's offset is handed back to the estimate once the vehicle is
/// clear of the target, m/s: a twentieth of the cruise speed, so the move is smooth.
pub const HANDOVER_SPEED_MPS: f64 = 0.25;

/// How far beyond the estimator's walk the odometry may drift over a ring, metres (a ring's
/// odometry drifts by centimetres).
const ODOMETRY_ALLOWANCE_M: f64 = 0.1;

/// The Rayleigh quantile that bounds the horizontal difference of two positions of the walk
/// (each axis σ√2) 99.9% of the time: √(2 ln 1000) scales of σ√2. The walk is sampled at
/// every frame of a minute's rings, and 99% refused a good odometry on the default world
/// (seed 3, 2.28 m).
const HORIZONTAL_SIGMAS: f64 = 3.717;
/// The two-sided normal quantile that does the same for the vertical.
const VERTICAL_SIGMAS: f64 = 3.291;

/// The offset between the map's frame and the state estimate's.
#[derive(Debug, Clone, PartialEq)]
pub struct MapFrameOffset {
    offset_m: Vector3<f64>,
    gate_horizontal_m: f64,
    gate_vertical_m: f64,
    previous_time_s: Option<f64>,
    rejected_in_a_row: usize,
    /// Offsets refused by the gate since [`Self::take_rejected`] last counted them.
    pub rejected: usize,
}

impl MapFrameOffset {
    /// No offset yet; the gate scaled to `estimator`'s walk.
    pub fn new(estimator: &EstimatorConfig) -> Self {
        let walk_of_differences = std::f64::consts::SQRT_2;
        Self {
            offset_m: Vector3::zeros(),
            gate_horizontal_m: HORIZONTAL_SIGMAS
                * walk_of_differences
                * estimator.horizontal_sigma_m
                + ODOMETRY_ALLOWANCE_M,
            gate_vertical_m: VERTICAL_SIGMAS * walk_of_differences * estimator.vertical_sigma_m
                + ODOMETRY_ALLOWANCE_M,
            previous_time_s: None,
            rejected_in_a_row: 0,
            rejected: 0,
        }
    }

    /// The largest offset taken from the odometry, horizontal and vertical, metres: 99.9% of
    /// the estimator's walk between two times, plus a ring's odometry drift.
    pub fn gate_m(&self) -> (f64, f64) {
        (self.gate_horizontal_m, self.gate_vertical_m)
    }

    /// The offset in force (map frame − estimate, world ENU metres): add it to the estimate's
    /// position to fly in the map's frame.
    pub fn offset_m(&self) -> Vector3<f64> {
        self.offset_m
    }

    /// Takes a tracked frame's offset, `odometry_m − estimate_m` (the same frame's positions,
    /// or their errors against the same truth, world ENU metres). Returns false, keeping the
    /// offset in force, when it is beyond the gate or not finite.
    pub fn observe(&mut self, odometry_m: &Vector3<f64>, estimate_m: &Vector3<f64>) -> bool {
        let offset = odometry_m - estimate_m;
        let plausible = offset.iter().all(|v| v.is_finite())
            && offset.xy().norm() <= self.gate_horizontal_m
            && offset.z.abs() <= self.gate_vertical_m;
        if plausible {
            self.offset_m = offset;
            self.rejected_in_a_row = 0;
        } else {
            self.rejected += 1;
            self.rejected_in_a_row += 1;
        }
        plausible
    }

    /// Offsets refused since the last one taken.
    pub fn rejected_in_a_row(&self) -> usize {
        self.rejected_in_a_row
    }

    /// The offsets refused since the last call (or since [`Self::new`]), counting afresh from
    /// zero: one target's count when called as its mapping starts and ends.
    pub fn take_rejected(&mut self) -> usize {
        std::mem::take(&mut self.rejected)
    }

    /// Advances to mission time `time_s` (non-decreasing): when `clear` (not mapping, and out
    /// of the target's way), the offset shrinks toward zero at [`HANDOVER_SPEED_MPS`];
    /// otherwise it is held.
    pub fn advance(&mut self, time_s: f64, clear: bool) {
        let dt = self.previous_time_s.map_or(0.0, |t| (time_s - t).max(0.0));
        self.previous_time_s = Some(time_s);
        if !clear {
            return;
        }
        let norm = self.offset_m.norm();
        let step = HANDOVER_SPEED_MPS * dt;
        self.offset_m = if norm <= step {
            Vector3::zeros()
        } else {
            self.offset_m * ((norm - step) / norm)
        };
    }
}

/// How far the navigation error (the position the controller flies on, less the truth) moves
/// while one target's rings are flown, from its value at the first mapped frame: the rings'
/// drift across the rock (ground truth; simulation only).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RingDrift {
    first_m: Option<Vector3<f64>>,
    largest_m: f64,
}

impl RingDrift {
    /// Takes the navigation error at one step, world ENU metres.
    pub fn observe(&mut self, navigation_error_m: &Vector3<f64>) {
        match self.first_m {
            None => self.first_m = Some(*navigation_error_m),
            Some(first) => {
                self.largest_m = self.largest_m.max((navigation_error_m - first).norm());
            }
        }
    }

    /// The largest move from the first value, metres; `None` before any.
    pub fn largest_m(&self) -> Option<f64> {
        self.first_m.map(|_| self.largest_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gps() -> EstimatorConfig {
        EstimatorConfig::default()
    }

    #[test]
    fn a_tracked_offset_is_taken_and_held_until_clear() {
        let mut frame = MapFrameOffset::new(&gps());
        assert!(frame.observe(
            &Vector3::new(0.3, -0.7, -0.2),
            &Vector3::new(1.5, 0.2, -0.1)
        ));
        let taken = frame.offset_m();
        assert!((taken - Vector3::new(-1.2, -0.9, -0.1)).norm() < 1e-12);
        frame.advance(0.0, false);
        frame.advance(100.0, false);
        assert_eq!(frame.offset_m(), taken, "held while not clear");
        // 1.5 m at 0.25 m/s: 2 s take 0.5 m off, along the offset.
        frame.advance(102.0, true);
        let left = taken * ((taken.norm() - 0.5) / taken.norm());
        assert!((frame.offset_m() - left).norm() < 1e-12);
        frame.advance(110.0, true);
        assert_eq!(frame.offset_m(), Vector3::zeros());
    }

    #[test]
    fn an_offset_the_estimator_could_not_have_walked_is_refused() {
        let mut frame = MapFrameOffset::new(&gps());
        let (horizontal, vertical) = frame.gate_m();
        // σ 0.5 m horizontal: 99.9% of the walk's differences lie within 2.63 m.
        assert!((horizontal - (3.717 * 0.5 * 2f64.sqrt() + 0.1)).abs() < 1e-12);
        assert!(vertical > horizontal, "the vertical walk is wider");
        assert!(frame.observe(&Vector3::new(1.0, 0.0, 0.0), &Vector3::zeros()));
        assert!(!frame.observe(
            &Vector3::new(horizontal + 0.01, 0.0, 0.0),
            &Vector3::zeros()
        ));
        assert!(!frame.observe(&Vector3::new(0.0, 0.0, vertical + 0.01), &Vector3::zeros()));
        assert!(!frame.observe(&Vector3::new(f64::NAN, 0.0, 0.0), &Vector3::zeros()));
        assert_eq!(
            frame.offset_m(),
            Vector3::new(1.0, 0.0, 0.0),
            "the last good one"
        );
        assert_eq!((frame.rejected, frame.rejected_in_a_row()), (3, 3));
        assert!(frame.observe(&Vector3::new(0.9, 0.0, 0.0), &Vector3::zeros()));
        assert_eq!((frame.rejected, frame.rejected_in_a_row()), (3, 0));
        assert_eq!(frame.take_rejected(), 3);
        assert_eq!(frame.take_rejected(), 0, "counted afresh");
    }

    #[test]
    fn rtk_leaves_the_odometry_decimetres() {
        let rtk = EstimatorConfig::preset(scarp_datasets::estimator::EstimatorPreset::Rtk);
        let (horizontal, vertical) = MapFrameOffset::new(&rtk).gate_m();
        assert!(
            horizontal < 0.25 && vertical < 0.3,
            "{horizontal} {vertical}"
        );
    }

    #[test]
    fn ring_drift_is_the_largest_move_from_the_first_error() {
        let mut drift = RingDrift::default();
        assert_eq!(drift.largest_m(), None);
        drift.observe(&Vector3::new(1.0, 1.0, 0.0));
        assert_eq!(drift.largest_m(), Some(0.0));
        drift.observe(&Vector3::new(1.0, 4.0, 4.0));
        drift.observe(&Vector3::new(1.0, 2.0, 1.0));
        assert_eq!(drift.largest_m(), Some(5.0));
    }
}
