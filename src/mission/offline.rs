//! Offline processing of a recorded flight (`scarp process`): the rock catalog from the frames
//! and the pose estimate a drone brought home, with no world and no ground truth.
//!
//! The flight folder is the TUM RGB-D layout with `estimate.txt` (see [`super::record`] for
//! what `scarp simulate --record` writes). The steps are the live mission's, run over the
//! recording instead of in the loop:
//!
//! 1. **Search detection and localization:** the mission's [`Perception`] (detector, box
//!    tracker, depth filter, with the mission's settings) over the frames the live flight
//!    searched and localized with (`flight.txt`'s `search` and `fine_localize` frames), or,
//!    without a flight log, over every frame at the search camera rate. The box tracks are
//!    reset when the log returns to the search, as the live mission does.
//! 2. **Targets:** with a flight log, the targets the flight mapped, each with its point set as
//!    it was when the log enters `map` (the perception replays the live one exactly: the
//!    simulated detector draws by the frame's time to the microsecond); without one, every
//!    confirmed target whose point set is compact (ready for fine localization or
//!    converged), less those within the duplicate radius of one already taken.
//! 3. **Mapping:** each target's cylinder from its points and the ground the depth camera saw
//!    around it (the last fine-localization frame before mapping, or the last frame that
//!    updated the target); the frames that see the cylinder feed its map (odometry and TSDF):
//!    with a flight log, those of its `map` phase, as the live flight fused; without one,
//!    every frame. The first one after the cylinder is recentred on where the frame's box
//!    sees the rock.
//! 4. **Finishing:** bundle adjustment, re-integration, mesh, fragility and export per target,
//!    then `mission.json`, `targets.csv`, `targets.geojson` and `report.html` as a live
//!    mission writes them, without the ground-truth columns unless a world is given. A target
//!    is mapped when its fragility is analysed: the coverage threshold, which ends a live
//!    mapping flight, is reported but not required (the recorded flight cannot be extended,
//!    and 1 mm depth PNGs can move a coverage right at the threshold by a cell).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use super::error::{Context, MissionResult};
use nalgebra::Point3;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;

use super::catalog::{Catalog, MissionTarget, TargetStatus};
use super::config::MissionConfig;
use super::mapping::{
    MappingSession, RecenterStep, Recentering, cylinder_around, cylinder_radius_m,
    cylinder_seen_in_frame, finish_target, ground_height_near, mapped_status,
};
use super::mode::{FlightLogEntry, Mode};
use super::perception::{Perception, TargetState};
use super::record::FlightOrigin;
use super::report::{MissionReport, ModeChange, StageTimings};
use super::sensors::{Recorded, Sensors};
use crate::detection::simulated::roles_from_boxes;

/// What to process and how.
pub struct ProcessInputs<'a> {
    /// The flight folder.
    pub flight: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// The mission's settings (detector, tracker, filter, cylinder, mapping, fragility).
    pub config: MissionConfig,
    /// The world the flight was simulated in, for the ground-truth columns only.
    pub world: Option<&'a World>,
    /// Seed of the simulated detector and the depth filter (the live mission's `--seed`
    /// reproduces its perception).
    pub seed: u64,
}

/// Processes a recorded flight into a rock catalog (see the [module docs](self)).
///
/// # Errors
/// An unreadable flight folder, a frame without a pose estimate, a malformed `flight.txt` or
/// `origin.toml`, invalid settings, or a write failure. A target whose mapping or analysis
/// fails is reported in its row, not as an error.
pub fn process_flight(inputs: &ProcessInputs<'_>) -> MissionResult<MissionReport> {
    let started = Instant::now();
    let config = &inputs.config;
    let mut flight = Recorded::open(&inputs.flight)?;
    let camera = *flight.camera();
    let origin = flight.origin()?.unwrap_or_else(|| {
        tracing::warn!(
            "{} has no origin.toml: targets.geojson places the ENU origin at 0°N 0°E",
            inputs.flight.display()
        );
        FlightOrigin {
            lat_deg: 0.0,
            lon_deg: 0.0,
            alt_m: 0.0,
        }
    });
    std::fs::create_dir_all(&inputs.out)
        .with_context(|| format!("creating {}", inputs.out.display()))?;

    let mut timings = StageTimings {
        setup_s: started.elapsed().as_secs_f64(),
        ..StageTimings::default()
    };
    let mut report = MissionReport {
        world: format!("recorded flight {}", inputs.flight.display()),
        seed: inputs.seed,
        end_reason: "processed".into(),
        ..MissionReport::default()
    };

    // 1. Search detection and localization.
    let mut perception = Perception::with_roles(
        roles_from_boxes(&flight.sequence().boxes),
        config,
        inputs.seed,
    )?;
    let search_period_s = 1.0 / config.search_camera_rate_hz;
    let mut last_perceived: Option<f64> = None;
    let mut previous_mode = Mode::Search;
    // When each target was first confirmed (the live mission's "found").
    let mut found_at: BTreeMap<u32, f64> = BTreeMap::new();
    // The frame that last updated each target: its depth shows the ground around it.
    let mut last_update_frame: BTreeMap<u32, usize> = BTreeMap::new();
    let mut last_fine_frame: Option<usize> = None;
    // With a flight log: the targets it mapped, in order, as they were when mapping began.
    let mut mapped_live: Vec<MapPlan> = Vec::new();
    let mut log = Vec::with_capacity(flight.len());
    let has_flight_log = flight.has_flight_log();
    while let Some((index, pose)) = flight.next_indexed()? {
        let t = pose.timestamp_s;
        let estimate = pose.world_from_camera_estimate;
        let mode = flight.mode();
        log.push(FlightLogEntry {
            time_s: t,
            world_from_camera_truth: None,
            world_from_camera_estimate: estimate,
            mode,
        });
        if let Mode::Map(id) = mode
            && previous_mode != mode
            && !mapped_live.iter().any(|p| p.state.id == id)
            && let Some(state) = perception.target_state(id)
        {
            mapped_live.push(MapPlan {
                state,
                ground_frame: last_fine_frame,
                map_frames_of: Some(id),
            });
        }
        if mode.as_str() != previous_mode.as_str() {
            report.modes.push(ModeChange {
                time_s: t,
                mode: mode.as_str().into(),
                target: mode.target().map(u64::from),
            });
        }
        match mode {
            Mode::Search => report.frames_search += 1,
            Mode::FineLocalize(_) => report.frames_fine_localize += 1,
            Mode::Map(_) => report.frames_map += 1,
            Mode::Done => {}
        }
        let perceives = match (has_flight_log, mode) {
            (true, Mode::Search | Mode::FineLocalize(_)) => true,
            (true, _) => false,
            (false, _) => last_perceived.is_none_or(|last| t - last >= search_period_s - 1e-6),
        };
        // The live mission resets the box tracks whenever it returns to the search, and
        // starts a target's filter afresh as its fine-localization circle begins.
        if previous_mode != Mode::Search && mode == Mode::Search {
            perception.reset_tracks()?;
        }
        if let Mode::FineLocalize(id) = mode
            && previous_mode != mode
            && config.restart_filter_for_fine_localization
        {
            perception.restart_target(id);
        }
        previous_mode = mode;
        if !perceives {
            continue;
        }
        last_perceived = Some(t);
        if matches!(mode, Mode::FineLocalize(_)) {
            last_fine_frame = Some(index);
        }
        let clock = Instant::now();
        let frame = flight.images()?;
        timings.render_s += clock.elapsed().as_secs_f64();
        let step = perception.process(&frame, &camera, &estimate)?;
        timings.detect_s += step.detect_s;
        timings.track_s += step.track_s;
        timings.localize_s += step.localize_s;
        let catalog = perception.catalog();
        for target in catalog.targets() {
            if target.is_confirmed(catalog.config()) {
                found_at.entry(target.id()).or_insert(t);
            }
        }
        for id in &step.updated {
            last_update_frame.insert(*id, index);
        }
    }
    report.sim_time_s = flight.duration_s();

    // 2. Targets.
    let mut catalog = Catalog::new();
    let plans: Vec<MapPlan> = if has_flight_log {
        mapped_live
    } else {
        let mut chosen: Vec<MapPlan> = Vec::new();
        for state in perception.target_states() {
            let duplicate = chosen.iter().any(|c| {
                (c.state.center.x - state.center.x).hypot(c.state.center.y - state.center.y)
                    < config.duplicate_radius_m
            });
            if (state.ready_for_fine_localization || state.converged) && !duplicate {
                chosen.push(MapPlan {
                    ground_frame: last_update_frame.get(&state.id).copied(),
                    state,
                    map_frames_of: None,
                });
            }
        }
        chosen
    };
    for state in perception.target_states() {
        let t_found = found_at.get(&state.id).copied().unwrap_or(0.0);
        let mut target = MissionTarget::new(state.id, &state.center, t_found);
        target.follow_filter(&state);
        target.report.localization_converged = state.converged;
        target.set_status(if state.ready_for_fine_localization || state.converged {
            TargetStatus::Localized
        } else {
            TargetStatus::Unconverged
        });
        catalog.insert(state.id, target);
    }
    for plan in &plans {
        let state = &plan.state;
        let t_found = found_at.get(&state.id).copied().unwrap_or(0.0);
        let target = catalog
            .entry(state.id)
            .or_insert_with(|| MissionTarget::new(state.id, &state.center, t_found));
        // The row describes the localization the map was planned from.
        target.follow_filter(state);
        target.report.localization_converged = state.converged;
        target.set_status(TargetStatus::Mapping);
    }

    // 3. Mapping: one session per target.
    let mut sessions: Vec<(MappingSession, Recentering, Option<u32>)> = Vec::new();
    for plan in &plans {
        let state = &plan.state;
        let cylinder = target_cylinder(&flight, &camera, plan, config)?;
        if let Some(target) = catalog.get_mut(&state.id) {
            let r = &mut target.report;
            r.cylinder_center_xy = [cylinder.center_x_m, cylinder.center_y_m];
            r.cylinder_radius_m = cylinder.radius_m;
            r.cylinder_z_bottom_m = cylinder.z_bottom_m;
            r.cylinder_z_top_m = cylinder.z_top_m;
            target.cylinder = Some(cylinder);
        }
        sessions.push((
            MappingSession::new(state.id, &cylinder, &camera, config)?
                .without_coverage_requirement(),
            Recentering::default(),
            plan.map_frames_of,
        ));
    }
    if !sessions.is_empty() {
        let bar_clock = Instant::now();
        flight.rewind();
        while let Some((index, pose)) = flight.next_indexed()? {
            let estimate = &pose.world_from_camera_estimate;
            let mode = flight.mode();
            let wanted: Vec<usize> = (0..sessions.len())
                .filter(|&k| {
                    let (session, _, only) = &sessions[k];
                    only.is_none_or(|id| mode == Mode::Map(id)) && session.would_map(estimate)
                })
                .collect();
            if wanted.is_empty() {
                continue;
            }
            let clock = Instant::now();
            let frame = flight.images()?;
            timings.render_s += clock.elapsed().as_secs_f64();
            for k in wanted {
                let (session, recentering, _) = &mut sessions[k];
                let clock = Instant::now();
                if config.mapping.recenter_on_first_frame
                    && session.is_empty()
                    && !recentering.is_settled()
                {
                    let old = *session.cylinder();
                    let seen = cylinder_seen_in_frame(
                        &mut perception,
                        &frame,
                        &camera,
                        estimate,
                        &old,
                        &config.cylinder,
                    )?;
                    match recentering.step(seen) {
                        RecenterStep::Move { cylinder, moved_m } => {
                            let rise_m = cylinder.z_bottom_m - old.z_bottom_m;
                            tracing::info!(
                                "target {}: map cylinder moved {moved_m:.2} m across and \
                                 {rise_m:+.2} m up to where frame {index} and the one before \
                                 see it",
                                session.target_id()
                            );
                            session.recenter(&cylinder, config)?;
                            if let Some(target) = catalog.get_mut(&session.target_id()) {
                                target.report.cylinder_center_xy =
                                    [cylinder.center_x_m, cylinder.center_y_m];
                                target.cylinder = Some(cylinder);
                            }
                        }
                        // Unseen, or not yet seen twice alike: wait for another frame, as the
                        // live mission does.
                        RecenterStep::Wait => {
                            timings.map_s += clock.elapsed().as_secs_f64();
                            continue;
                        }
                        RecenterStep::Map => {}
                    }
                }
                session.process(frame.clone(), estimate, None)?;
                timings.map_s += clock.elapsed().as_secs_f64();
            }
        }
        tracing::debug!(
            "mapping pass over {} frames: {:.1} s",
            flight.len(),
            bar_clock.elapsed().as_secs_f64()
        );
    }

    // 4. Finishing.
    for (session, _, _) in sessions {
        let id = session.target_id();
        let points = perception
            .target_state(id)
            .map(|s| s.points)
            .unwrap_or_default();
        let dir = inputs.out.join("targets").join(id.to_string());
        let Some(target) = catalog.get_mut(&id) else {
            continue;
        };
        let outcome = finish_target(
            session,
            &points,
            inputs.world,
            config,
            &dir,
            &mut target.report,
            &mut timings,
        );
        let status = mapped_status(outcome, &mut target.report);
        tracing::info!(
            "target {id} {} (coverage {:.2}, {} keyframes, α_min {:?}°)",
            status.as_str(),
            target.report.coverage,
            target.report.keyframes,
            target.report.alpha_min_deg
        );
        target.set_status(status);
    }
    if let Some(world) = inputs.world {
        let clock = Instant::now();
        super::evaluation::ground_truth_summary(world, &mut catalog, &mut report);
        timings.evaluation_s += clock.elapsed().as_secs_f64();
    }
    report.targets = catalog.values().map(|m| m.report.clone()).collect();
    report.targets_found = catalog.len();
    report.targets_mapped = catalog
        .values()
        .filter(|t| t.status == TargetStatus::Mapped)
        .count();
    let wall_s = started.elapsed().as_secs_f64();
    report.wall_time_s = wall_s;
    report.real_time_factor = if wall_s > 0.0 {
        report.sim_time_s / wall_s
    } else {
        0.0
    };
    report.timings = timings;
    report.write(&inputs.out, origin.geodetic())?;
    super::html::write_report(&inputs.out, inputs.world, &report, &log, &catalog)?;
    Ok(report)
}

/// A target to map: its localization, where its ground is seen, and which frames map it.
struct MapPlan {
    /// The localization the map is planned from.
    state: TargetState,
    /// A frame whose depth shows the ground around the target.
    ground_frame: Option<usize>,
    /// Map only the frames the flight log puts in `map` mode for this target (`None`: every
    /// frame that sees the cylinder).
    map_frames_of: Option<u32>,
}

/// The mapping cylinder of `plan`'s target, standing on the ground that its ground frame's
/// depth shows around it (else the lowest of its points).
fn target_cylinder(
    flight: &Recorded,
    camera: &PinholeCamera,
    plan: &MapPlan,
    config: &MissionConfig,
) -> MissionResult<scarp_planning::prelude::VerticalCylinder> {
    let c = &config.cylinder;
    let state = &plan.state;
    let radius = cylinder_radius_m(&state.points, &state.points_center, c);
    let ground = match plan.ground_frame {
        Some(index) => {
            let frame = flight.images_at(index)?;
            let pose = flight.estimate(index).copied();
            pose.and_then(|pose| {
                ground_height_near(camera, &frame.depth_m, &pose, &state.center, radius)
            })
        }
        None => None,
    };
    let ground = ground.unwrap_or_else(|| {
        state
            .points
            .iter()
            .map(|p: &Point3<f64>| p.z)
            .fold(state.center.z, f64::min)
    });
    cylinder_around(&state.center, radius, ground, c)
}
