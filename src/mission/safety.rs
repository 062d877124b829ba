//! The true clearance of the flight, as ground truth sees it: the smallest clearance overall, per
//! mode and per target, and collisions as events (each run of consecutive camera steps closer
//! than the collision radius is one event, with when, where and against what).
//!
//! This is bookkeeping of the simulation's truth, not a safety layer: nothing here changes the
//! flight.

use std::collections::BTreeMap;

use scarp_planning::clearance::{ClearanceSample, ClearanceSource};
use serde::{Deserialize, Serialize};

use super::mode::Mode;

/// One collision (consecutive steps closer than the collision radius to one surface), or one
/// intervention of the safety monitor (a sensed surface inside its safety radius).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SafetyEvent {
    /// `collision` or `intervention`.
    pub kind: String,
    /// Mission time of the first step in collision, seconds.
    pub start_time_s: f64,
    /// Mission time of the last step in collision, seconds.
    pub end_time_s: f64,
    /// The mode when it began (`search`, `fine_localize`, `map`).
    pub mode: String,
    /// The mission target the mode worked on, if any.
    pub target: Option<u64>,
    /// The true vehicle position at the smallest clearance, world ENU metres.
    pub position_true_m: [f64; 3],
    /// What was hit at the smallest clearance: `terrain`, `rock <id>` or `pedestal <id>`.
    pub obstacle: String,
    /// The smallest true clearance during the event, metres (negative: inside the surface).
    pub min_clearance_m: f64,
    /// Camera steps in collision.
    pub steps: usize,
}

/// Accumulates the flight's true clearance, step by step.
#[derive(Debug, Clone)]
pub struct SafetyLog {
    collision_radius_m: f64,
    obstacle_names: Vec<String>,
    /// Smallest clearance of the whole flight, metres.
    pub min_clearance_m: Option<f64>,
    /// Smallest clearance per mode name, metres.
    pub min_clearance_by_mode_m: BTreeMap<String, f64>,
    /// Smallest clearance while fine-localizing or mapping each mission target, metres.
    pub min_clearance_by_target_m: BTreeMap<u32, f64>,
    /// Closed collision events, in time order.
    pub events: Vec<SafetyEvent>,
    /// Steps in collision, all events together.
    pub collision_steps: usize,
    open: Option<SafetyEvent>,
}

fn keep_min(slot: &mut f64, value: f64) {
    *slot = slot.min(value);
}

impl SafetyLog {
    /// A log for a vehicle that collides closer than `collision_radius_m`; `obstacle_names`
    /// names each obstacle index of the planning environment.
    pub fn new(collision_radius_m: f64, obstacle_names: Vec<String>) -> Self {
        Self {
            collision_radius_m,
            obstacle_names,
            min_clearance_m: None,
            min_clearance_by_mode_m: BTreeMap::new(),
            min_clearance_by_target_m: BTreeMap::new(),
            events: Vec::new(),
            collision_steps: 0,
            open: None,
        }
    }

    fn obstacle_name(&self, source: ClearanceSource) -> String {
        match source {
            ClearanceSource::Terrain => "terrain".into(),
            ClearanceSource::Obstacle(i) => self
                .obstacle_names
                .get(i)
                .cloned()
                .unwrap_or_else(|| format!("obstacle {i}")),
        }
    }

    /// Records one step at mission time `time_s` with the vehicle's true position and its
    /// clearance. Returns the event a collision opened at this step, so the caller can warn.
    pub fn observe(
        &mut self,
        time_s: f64,
        mode: Mode,
        position_true_m: [f64; 3],
        sample: ClearanceSample,
    ) -> Option<SafetyEvent> {
        let c = sample.clearance_m;
        self.min_clearance_m = Some(self.min_clearance_m.map_or(c, |m| m.min(c)));
        keep_min(
            self.min_clearance_by_mode_m
                .entry(mode.as_str().into())
                .or_insert(c),
            c,
        );
        if let Some(target) = mode.target() {
            keep_min(self.min_clearance_by_target_m.entry(target).or_insert(c), c);
        }
        if c >= self.collision_radius_m {
            self.close();
            return None;
        }
        self.collision_steps += 1;
        let obstacle = self.obstacle_name(sample.source);
        match &mut self.open {
            Some(event) => {
                event.end_time_s = time_s;
                event.steps += 1;
                if c < event.min_clearance_m {
                    event.min_clearance_m = c;
                    event.position_true_m = position_true_m;
                    event.obstacle = obstacle;
                }
                None
            }
            None => {
                let event = SafetyEvent {
                    kind: "collision".into(),
                    start_time_s: time_s,
                    end_time_s: time_s,
                    mode: mode.as_str().into(),
                    target: mode.target().map(u64::from),
                    position_true_m,
                    obstacle,
                    min_clearance_m: c,
                    steps: 1,
                };
                self.open = Some(event.clone());
                Some(event)
            }
        }
    }

    /// Records an intervention of the safety monitor at `time_s`, with the true clearance and
    /// obstacle at that step (ground truth, for the report).
    pub fn record_intervention(
        &mut self,
        time_s: f64,
        mode: Mode,
        position_true_m: [f64; 3],
        sample: ClearanceSample,
    ) -> SafetyEvent {
        let event = SafetyEvent {
            kind: "intervention".into(),
            start_time_s: time_s,
            end_time_s: time_s,
            mode: mode.as_str().into(),
            target: mode.target().map(u64::from),
            position_true_m,
            obstacle: self.obstacle_name(sample.source),
            min_clearance_m: sample.clearance_m,
            steps: 1,
        };
        self.events.push(event.clone());
        event
    }

    /// Ends the collision in progress, if any, and returns it.
    pub fn close(&mut self) -> Option<&SafetyEvent> {
        let event = self.open.take()?;
        self.events.push(event);
        self.events.last()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(c: f64, source: ClearanceSource) -> ClearanceSample {
        ClearanceSample {
            clearance_m: c,
            source,
        }
    }

    #[test]
    fn consecutive_steps_in_collision_are_one_event() {
        let mut log = SafetyLog::new(0.3, vec!["rock 1".into(), "pedestal 1".into()]);
        let p = |x: f64| [x, 0.0, 1.0];
        assert!(
            log.observe(
                0.0,
                Mode::Search,
                p(0.0),
                sample(5.0, ClearanceSource::Terrain)
            )
            .is_none()
        );
        let opened = log
            .observe(
                1.0,
                Mode::Map(4),
                p(1.0),
                sample(0.2, ClearanceSource::Obstacle(1)),
            )
            .expect("a collision opens an event");
        assert_eq!(opened.obstacle, "pedestal 1");
        assert!(
            log.observe(
                1.1,
                Mode::Map(4),
                p(2.0),
                sample(-0.1, ClearanceSource::Terrain)
            )
            .is_none()
        );
        log.observe(
            1.2,
            Mode::Map(4),
            p(3.0),
            sample(0.25, ClearanceSource::Obstacle(0)),
        );
        log.observe(
            1.3,
            Mode::Map(4),
            p(4.0),
            sample(0.9, ClearanceSource::Terrain),
        );
        log.observe(
            2.0,
            Mode::Search,
            p(5.0),
            sample(0.1, ClearanceSource::Obstacle(7)),
        );
        assert!(log.close().is_some());
        assert_eq!(log.events.len(), 2);
        let first = &log.events[0];
        assert_eq!(
            (first.start_time_s, first.end_time_s, first.steps),
            (1.0, 1.2, 3)
        );
        assert_eq!(first.obstacle, "terrain", "named at its deepest point");
        assert_eq!(first.min_clearance_m, -0.1);
        assert_eq!(first.position_true_m, p(2.0));
        assert_eq!((first.mode.as_str(), first.target), ("map", Some(4)));
        assert_eq!(log.events[1].obstacle, "obstacle 7");
        assert_eq!(log.collision_steps, 4);
        assert_eq!(log.min_clearance_m, Some(-0.1));
        assert_eq!(log.min_clearance_by_mode_m["map"], -0.1);
        assert_eq!(log.min_clearance_by_mode_m["search"], 0.1);
        assert_eq!(log.min_clearance_by_target_m[&4], -0.1);
        assert!(log.close().is_none());
    }
}
