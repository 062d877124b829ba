//! A campaign's tables, computed from its run folders alone: one [`RunRow`] per mission, one
//! [`TargetRow`] per true target per mission, and the [`Totals`].
//!
//! Only what the runs wrote is read: `mission.json` and `world_gt/world.json`. Keys that later
//! versions of `mission.json` add (`alpha_min_low_deg`, `alpha_min_high_deg`,
//! `localization_error_estimate_frame_m`, a target's own `min_clearance_m`) are read where a
//! run has them and left `null` where it does not.

use std::path::Path;

use scarp_slam::stats::{median, quantile};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::plan::{RunSpec, mission_is_finished};
use super::{CampaignError, read_json_file};

/// F-score at 2 cm a mapped target must reach.
pub const FSCORE_2CM_MIN: f64 = 0.85;
/// Largest |α_min error| that counts as right, degrees.
pub const ALPHA_ERROR_MAX_DEG: f64 = 2.0;
/// An overestimate of α_min beyond this calls a rock dangerously safer than it is, degrees.
pub const ALPHA_OVERESTIMATE_MAX_DEG: f64 = 3.0;
/// Largest absolute localization error that counts as right, metres (the mission issue's).
pub const LOCALIZATION_ERROR_MAX_M: f64 = 1.0;
/// Largest localization error in the frame the vehicle flies in, metres.
pub const LOCALIZATION_ESTIMATE_FRAME_MAX_M: f64 = 0.5;
/// Smallest true clearance a safe flight keeps, metres.
pub const CLEARANCE_MIN_M: f64 = 0.5;

/// How a run ended, as far as the campaign can tell from its folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunState {
    /// `mission.json` exists and the mission was not interrupted.
    Finished,
    /// `mission.json` says the mission was interrupted (Ctrl-C).
    Interrupted,
    /// The mission exited with an error and wrote no `mission.json` (see its `run.log`).
    Failed,
    /// Started, but neither finished nor failed: running now, or killed.
    Started,
    /// The run has not been started.
    NotRun,
}

/// One mission of the campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRow {
    /// World as given to `--worlds`.
    pub world: String,
    /// Seed.
    pub seed: u64,
    /// The run's folder, relative to the campaign folder.
    pub run_dir: String,
    /// How it ended.
    pub state: RunState,
    /// `end_reason` from `mission.json` (`complete`, `timeout`, …).
    pub end_reason: Option<String>,
    /// The failure's message (the last `error:` line of `run.log`), for failed runs.
    pub error: Option<String>,
    /// Mission wall time, seconds.
    pub wall_time_s: Option<f64>,
    /// Simulated time, seconds.
    pub sim_time_s: Option<f64>,
    /// Camera steps in collision.
    pub collisions: Option<u64>,
    /// Smallest true clearance of the flight, metres.
    pub min_clearance_m: Option<f64>,
    /// Targets mapped (as the mission counts them).
    pub targets_mapped: Option<u64>,
    /// Distractors mapped.
    pub distractors_mapped: Option<u64>,
    /// The safety monitor's interventions, where the mission records them.
    pub safety_events: Option<u64>,
}

impl RunRow {
    /// Whether the run finished and its mission ran to its end (`end_reason` `complete`, or
    /// `target_limit` when the configuration capped the targets), not stopped by an error, a
    /// timeout or a crash.
    pub fn completed_mission(&self) -> bool {
        self.state == RunState::Finished
            && matches!(
                self.end_reason.as_deref(),
                Some("complete" | "target_limit")
            )
    }
}

/// One true target of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetRow {
    /// World as given to `--worlds`.
    pub world: String,
    /// Seed.
    pub seed: u64,
    /// The run's folder, relative to the campaign folder.
    pub run_dir: String,
    /// The true rock's id in the world.
    pub rock_id: u64,
    /// The rock's shape, where `world.json` names it.
    pub shape: Option<String>,
    /// The mission's target id matched to this rock (`None`: never registered).
    pub target_id: Option<u64>,
    /// The mission's status for it (`mapped`, `incomplete`, …), `missed` when no mission
    /// target matched it, `run_failed` when its run wrote no `mission.json`.
    pub status: String,
    /// F-score at 1 cm against the visible ground truth.
    pub fscore_1cm: Option<f64>,
    /// F-score at 2 cm against the visible ground truth.
    pub fscore_2cm: Option<f64>,
    /// α_min from the mesh, degrees (`None`: not analysed, or refused).
    pub alpha_min_deg: Option<f64>,
    /// α_min of the true rock on its pedestal, degrees.
    pub alpha_min_gt_deg: Option<f64>,
    /// α_min − truth, degrees: positive calls the rock safer than it is.
    pub alpha_error_deg: Option<f64>,
    /// Lower end of the reported 95% interval of α_min, degrees, where reported.
    pub alpha_min_low_deg: Option<f64>,
    /// Upper end of the reported 95% interval of α_min, degrees, where reported.
    pub alpha_min_high_deg: Option<f64>,
    /// Whether the truth lies in the reported interval (`None` without an interval).
    pub truth_in_interval: Option<bool>,
    /// Distance from the localized centre to the true centroid, metres.
    pub localization_error_m: Option<f64>,
    /// The same in the frame the vehicle flies in, where reported.
    pub localization_error_estimate_frame_m: Option<f64>,
    /// The vertical of that error (C_e's height less the moved centroid's; + above it),
    /// metres, where reported.
    #[serde(default)]
    pub localization_vertical_estimate_frame_m: Option<f64>,
    /// The depth filter's own vertical spread (1σ) about C_e, metres, where reported.
    #[serde(default)]
    pub localization_sigma_z_m: Option<f64>,
    /// The horizontal of that error, metres, where reported.
    #[serde(default)]
    pub localization_horizontal_estimate_frame_m: Option<f64>,
    /// Fraction of the true rock's surface that the mapping views saw, where reported. The
    /// F-scores are taken against that part only: a map of half a rock can score 1.
    #[serde(default)]
    pub gt_visible_fraction: Option<f64>,
    /// Where the catalogue puts the target (`scan` or `localization`), where reported.
    pub center_source: Option<String>,
    /// Distance from the catalogue's centre to the true centroid in the frame the vehicle
    /// flies in, metres, where reported.
    pub center_error_estimate_frame_m: Option<f64>,
    /// Smallest true clearance: the target's own where reported, else the whole run's, metres.
    pub min_clearance_m: Option<f64>,
    /// How far the vehicle's navigation error moved while it flew the target's rings, metres,
    /// where reported.
    #[serde(default)]
    pub ring_drift_m: Option<f64>,
    /// Mapped frames after a gap in view tracked from a search over the estimate's walk, where
    /// reported.
    #[serde(default)]
    pub reacquisitions: Option<u64>,
    /// Keyframe links no landmark spans across dropped frames (the map held together there by
    /// one odometry result after a loss of tracking), where reported.
    #[serde(default)]
    pub keyframe_links_unspanned_after_drops: Option<u64>,
    /// Tracked frames whose odometry the map frame's gate refused, where reported.
    #[serde(default)]
    pub map_frame_refusals: Option<u64>,
    /// How far round the rock's axis the camera went while mapping it, degrees, where
    /// reported (`sweep_deg`): a flight that ends short of a full turn saw the base from part
    /// of the way round only.
    #[serde(default)]
    pub sweep_deg: Option<f64>,
    /// The share of the rock patched over unseen parts and its cut in the map when mapping
    /// ended, where read (`map_patched_fraction`).
    #[serde(default)]
    pub map_patched_fraction: Option<f64>,
    /// The support plane's tilt from the map's up the analysis levelled, degrees, where
    /// analysed (`support_tilt_deg`).
    #[serde(default)]
    pub support_tilt_deg: Option<f64>,
    /// Collisions of the whole run.
    pub run_collisions: Option<u64>,
    /// Why it is not mapped or not analysed, from the mission.
    pub error: Option<String>,
}

/// `count` of `of`, and their ratio (`None` when `of` is 0).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Rate {
    /// How many met it.
    pub count: usize,
    /// Out of how many.
    pub of: usize,
    /// count / of.
    pub rate: Option<f64>,
}

impl Rate {
    fn new(count: usize, of: usize) -> Self {
        Self {
            count,
            of,
            rate: (of > 0).then(|| count as f64 / of as f64),
        }
    }
}

/// The distribution of one figure over the campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricStats {
    /// What it measures, with its unit.
    pub name: String,
    /// Whether larger values are worse (errors) or smaller ones (F-scores, clearance).
    pub larger_is_worse: bool,
    /// How many values.
    pub n: usize,
    /// Median.
    pub median: Option<f64>,
    /// 10th percentile (nearest rank).
    pub p10: Option<f64>,
    /// 90th percentile (nearest rank).
    pub p90: Option<f64>,
    /// The worst value.
    pub worst: Option<f64>,
    /// Where the worst value is: `<run_dir>` or `<run_dir>#rock-<id>`.
    pub worst_at: Option<String>,
}

/// The campaign's totals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Totals {
    /// Runs in the plan.
    pub runs: usize,
    /// Runs that finished.
    pub runs_finished: usize,
    /// Runs that failed, were interrupted, or have not run.
    pub runs_unfinished: usize,
    /// Finished runs whose mission ran to its end (`end_reason` `complete`), not stopped by an
    /// error (a leg that could not be planned) or a crash.
    #[serde(default)]
    pub runs_completed: Rate,
    /// Finished runs with no collision.
    pub runs_without_collision: Rate,
    /// Camera steps in collision, summed over the runs.
    pub collisions_total: u64,
    /// Finished runs whose true clearance stayed ≥ 0.5 m.
    pub runs_clearance_at_least_0_5m: Rate,
    /// Safety interventions summed over the runs that record them.
    pub safety_events_total: Option<u64>,
    /// True targets mapped, of all true targets of the finished runs.
    pub targets_mapped: Rate,
    /// True targets flown in Map mode (`mapped`, or `incomplete`: too little coverage or a
    /// refused analysis), of all true targets of the finished runs.
    pub targets_flown: Rate,
    /// True targets no mission target matched.
    pub targets_missed: usize,
    /// Distractors mapped, summed over the runs.
    pub distractors_mapped: u64,
    /// Flown targets with F@2cm ≥ 0.85, of the flown targets (a missing score counts as
    /// not meeting it).
    pub fscore_2cm_at_least_0_85: Rate,
    /// Flown targets with |α error| ≤ 2°, of the flown targets with a true α_min; a refused
    /// analysis counts as not meeting it.
    pub alpha_error_within_2deg: Rate,
    /// Flown targets whose analysis refused to give α_min.
    pub alpha_refused: usize,
    /// Targets whose α_min overestimates the truth by more than 3°.
    pub alpha_overestimates_above_3deg: usize,
    /// Truth inside the reported interval, of the targets with an interval and a truth.
    pub truth_in_interval: Rate,
    /// Median width of the reported intervals, degrees.
    pub interval_width_median_deg: Option<f64>,
    /// Registered targets localized within 1 m of the true centroid.
    pub localization_within_1m: Rate,
    /// Registered targets localized within 0.5 m in the estimate's frame, where reported.
    pub localization_estimate_frame_within_0_5m: Rate,
    /// Registered targets whose catalogue centre (the scan's centroid once mapped) lies within
    /// 0.5 m of the truth in the estimate's frame, where reported.
    #[serde(default)]
    pub center_estimate_frame_within_0_5m: Rate,
    /// The distribution of every figure.
    pub figures: Vec<MetricStats>,
}

fn f(v: &Value, key: &str) -> Option<f64> {
    v.get(key).and_then(Value::as_f64).filter(|x| x.is_finite())
}

fn u(v: &Value, key: &str) -> Option<u64> {
    v.get(key).and_then(Value::as_u64)
}

fn s(v: &Value, key: &str) -> Option<String> {
    v.get(key).and_then(Value::as_str).map(str::to_string)
}

/// The file a campaign writes into a run's folder when its mission exits with an error; it
/// holds the exit status.
pub const FAILED_MARKER: &str = "failed.txt";

/// The last `error:` line of a failed run's `run.log`.
fn failure_message(run_dir: &Path) -> Option<String> {
    let log = std::fs::read_to_string(run_dir.join("run.log")).ok()?;
    log.lines()
        .rev()
        .find(|l| l.trim_start().starts_with("error:"))
        .or_else(|| log.lines().rev().find(|l| !l.trim().is_empty()))
        .map(|l| l.trim().to_string())
}

/// Statuses of targets that went through Map mode and have a mesh.
pub const FLOWN_STATUSES: [&str; 2] = ["mapped", "incomplete"];

/// Preference among several mission targets matched to one rock: the furthest along.
fn status_rank(status: &str) -> u8 {
    match status {
        "mapped" => 0,
        "incomplete" => 1,
        "mapping" => 2,
        "unreachable" => 3,
        "unconverged" => 4,
        "localized" => 5,
        "fine_localizing" => 6,
        "localizing" => 7,
        _ => 8,
    }
}

/// Reads one run's folder into its run row and its true targets' rows.
///
/// # Errors
/// A `mission.json` or `world.json` that exists but does not parse.
pub fn read_run(
    campaign_dir: &Path,
    run: &RunSpec,
) -> Result<(RunRow, Vec<TargetRow>), CampaignError> {
    let rel = run.dir();
    let run_dir_text = rel.display().to_string();
    let dir = campaign_dir.join(&rel);
    let mission_path = dir.join("mission.json");
    let mission = if mission_path.is_file() {
        Some(read_json_file::<Value>(&mission_path)?)
    } else {
        None
    };
    let state = match &mission {
        _ if !dir.exists() => RunState::NotRun,
        None if dir.join(FAILED_MARKER).is_file() => RunState::Failed,
        None => RunState::Started,
        Some(m) if mission_is_finished(m) => RunState::Finished,
        Some(_) => RunState::Interrupted,
    };
    let empty = Value::Null;
    let m = mission.as_ref().unwrap_or(&empty);
    let run_row = RunRow {
        world: run.world.clone(),
        seed: run.seed,
        run_dir: run_dir_text.clone(),
        state,
        end_reason: s(m, "end_reason"),
        error: (state == RunState::Failed)
            .then(|| failure_message(&dir))
            .flatten(),
        wall_time_s: f(m, "wall_time_s"),
        sim_time_s: f(m, "sim_time_s"),
        collisions: u(m, "collisions"),
        min_clearance_m: f(m, "min_clearance_m"),
        targets_mapped: u(m, "targets_mapped"),
        distractors_mapped: u(m, "distractors_mapped"),
        safety_events: u(m, "safety_interventions"),
    };
    let world_path = dir.join("world_gt").join("world.json");
    if !world_path.is_file() {
        return Ok((run_row, Vec::new()));
    }
    let world = read_json_file::<Value>(&world_path)?;
    let mission_targets: Vec<&Value> = m
        .get("targets")
        .and_then(Value::as_array)
        .map(|a| a.iter().collect())
        .unwrap_or_default();
    let mut rows = Vec::new();
    for rock in world
        .get("rocks")
        .and_then(Value::as_array)
        .ok_or_else(|| CampaignError::json(&world_path, "no `rocks` array"))?
    {
        if rock.get("role").and_then(Value::as_str) != Some("target") {
            continue;
        }
        let rock_id = u(rock, "id")
            .ok_or_else(|| CampaignError::json(&world_path, "a rock without an id"))?;
        let matched = mission_targets
            .iter()
            .filter(|t| {
                u(t, "gt_rock_id") == Some(rock_id) && s(t, "gt_role").as_deref() == Some("target")
            })
            .min_by(|a, b| {
                let key = |t: &Value| {
                    (
                        status_rank(s(t, "status").as_deref().unwrap_or("")),
                        f(t, "localization_error_m").unwrap_or(f64::INFINITY),
                    )
                };
                let (ka, kb) = (key(a), key(b));
                ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
            })
            .copied();
        let t = matched.unwrap_or(&empty);
        let status = match (matched, &mission) {
            (Some(t), _) => s(t, "status").unwrap_or_else(|| "unknown".into()),
            (None, Some(_)) => "missed".into(),
            (None, None) => "run_failed".into(),
        };
        let alpha = f(t, "alpha_min_deg");
        let truth = f(t, "alpha_min_gt_deg");
        let low = f(t, "alpha_min_low_deg");
        let high = f(t, "alpha_min_high_deg");
        let offset = t
            .get("localization_offset_estimate_frame_m")
            .and_then(Value::as_array)
            .and_then(|a| {
                let v: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
                (v.len() == 3 && v.iter().all(|x| x.is_finite())).then_some(v)
            });
        rows.push(TargetRow {
            world: run.world.clone(),
            seed: run.seed,
            run_dir: run_dir_text.clone(),
            rock_id,
            shape: s(rock, "shape"),
            target_id: matched.and_then(|t| u(t, "id")),
            status,
            fscore_1cm: f(t, "fscore_1cm"),
            fscore_2cm: f(t, "fscore_2cm"),
            alpha_min_deg: alpha,
            alpha_min_gt_deg: truth,
            alpha_error_deg: alpha.zip(truth).map(|(a, g)| a - g),
            alpha_min_low_deg: low,
            alpha_min_high_deg: high,
            truth_in_interval: match (low, high, truth) {
                (Some(lo), Some(hi), Some(g)) => Some(lo <= g && g <= hi),
                _ => None,
            },
            localization_error_m: f(t, "localization_error_m"),
            localization_error_estimate_frame_m: f(t, "localization_error_estimate_frame_m"),
            localization_vertical_estimate_frame_m: offset.as_ref().map(|v| v[2]),
            localization_horizontal_estimate_frame_m: offset.as_ref().map(|v| v[0].hypot(v[1])),
            localization_sigma_z_m: t
                .get("localized_sigma_m")
                .and_then(|s| s.get(2))
                .and_then(Value::as_f64)
                .filter(|s| s.is_finite() && *s > 0.0),
            gt_visible_fraction: f(t, "gt_visible_fraction"),
            center_source: s(t, "center_source"),
            center_error_estimate_frame_m: f(t, "center_error_estimate_frame_m"),
            min_clearance_m: f(t, "min_clearance_m").or(run_row.min_clearance_m),
            ring_drift_m: f(t, "ring_drift_m"),
            reacquisitions: u(t, "reacquisitions"),
            keyframe_links_unspanned_after_drops: u(t, "keyframe_links_unspanned_after_drops"),
            map_frame_refusals: u(t, "map_frame_refusals"),
            sweep_deg: f(t, "sweep_deg"),
            map_patched_fraction: f(t, "map_patched_fraction"),
            support_tilt_deg: f(t, "support_tilt_deg"),
            run_collisions: run_row.collisions,
            error: s(t, "error"),
        });
    }
    Ok((run_row, rows))
}

/// Reads every run of `runs` under `campaign_dir`, in order.
///
/// # Errors
/// As [`read_run`].
pub fn read_runs(
    campaign_dir: &Path,
    runs: &[RunSpec],
) -> Result<(Vec<RunRow>, Vec<TargetRow>), CampaignError> {
    let mut run_rows = Vec::with_capacity(runs.len());
    let mut target_rows = Vec::new();
    for run in runs {
        let (r, t) = read_run(campaign_dir, run)?;
        run_rows.push(r);
        target_rows.extend(t);
    }
    Ok((run_rows, target_rows))
}

fn figure<'a>(
    name: &str,
    larger_is_worse: bool,
    values: impl Iterator<Item = (f64, String)> + 'a,
) -> MetricStats {
    let values: Vec<(f64, String)> = values.collect();
    let plain: Vec<f64> = values.iter().map(|(v, _)| *v).collect();
    let worst = values
        .iter()
        .max_by(|a, b| {
            if larger_is_worse {
                a.0.total_cmp(&b.0)
            } else {
                b.0.total_cmp(&a.0)
            }
        })
        .cloned();
    MetricStats {
        name: name.into(),
        larger_is_worse,
        n: values.len(),
        median: median(&plain),
        p10: quantile(&plain, 0.1),
        p90: quantile(&plain, 0.9),
        worst: worst.as_ref().map(|w| w.0),
        worst_at: worst.map(|w| w.1),
    }
}

fn at(row: &TargetRow) -> String {
    format!("{}#rock-{}", row.run_dir, row.rock_id)
}

/// The totals of a campaign's rows.
pub fn totals(runs: &[RunRow], targets: &[TargetRow]) -> Totals {
    let finished: Vec<&RunRow> = runs
        .iter()
        .filter(|r| r.state == RunState::Finished)
        .collect();
    let counted: Vec<&TargetRow> = targets
        .iter()
        .filter(|t| {
            finished
                .iter()
                .any(|r| r.run_dir == t.run_dir && r.world == t.world)
        })
        .collect();
    let mapped = counted.iter().filter(|t| t.status == "mapped").count();
    // Flown: through Map mode, with a mesh, whether or not its analysis was refused.
    let flown: Vec<&&TargetRow> = counted
        .iter()
        .filter(|t| FLOWN_STATUSES.contains(&t.status.as_str()))
        .collect();
    let with_truth: Vec<&&&TargetRow> = flown
        .iter()
        .filter(|t| t.alpha_min_gt_deg.is_some())
        .collect();
    let with_interval: Vec<&&TargetRow> = counted
        .iter()
        .filter(|t| t.truth_in_interval.is_some())
        .collect();
    let localized: Vec<&&TargetRow> = counted
        .iter()
        .filter(|t| t.localization_error_m.is_some())
        .collect();
    let estimate_frame: Vec<f64> = counted
        .iter()
        .filter_map(|t| t.localization_error_estimate_frame_m)
        .collect();
    let center_frame: Vec<f64> = counted
        .iter()
        .filter_map(|t| t.center_error_estimate_frame_m)
        .collect();
    let widths: Vec<f64> = counted
        .iter()
        .filter_map(|t| Some(t.alpha_min_high_deg? - t.alpha_min_low_deg?))
        .collect();
    let safety: Vec<u64> = finished.iter().filter_map(|r| r.safety_events).collect();
    let figures = vec![
        figure(
            "|α_min error| (°)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.alpha_error_deg?.abs(), at(t)))),
        ),
        figure(
            "α_min error, signed (°; + = called safer than it is)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.alpha_error_deg?, at(t)))),
        ),
        figure(
            "F@2cm",
            false,
            flown.iter().filter_map(|t| Some((t.fscore_2cm?, at(t)))),
        ),
        figure(
            "true rock surface seen by the mapping views (fraction)",
            false,
            flown
                .iter()
                .filter_map(|t| Some((t.gt_visible_fraction?, at(t)))),
        ),
        figure(
            "F@1cm",
            false,
            flown.iter().filter_map(|t| Some((t.fscore_1cm?, at(t)))),
        ),
        figure(
            "localization error (m)",
            true,
            localized
                .iter()
                .filter_map(|t| Some((t.localization_error_m?, at(t)))),
        ),
        figure(
            "localization error, estimate frame (m)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.localization_error_estimate_frame_m?, at(t)))),
        ),
        figure(
            "localization error, estimate frame, vertical (m; + = above the centroid)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.localization_vertical_estimate_frame_m?, at(t)))),
        ),
        figure(
            "|vertical localization error| in the filter's own σ_z",
            true,
            counted.iter().filter_map(|t| {
                Some((
                    t.localization_vertical_estimate_frame_m?.abs() / t.localization_sigma_z_m?,
                    at(t),
                ))
            }),
        ),
        figure(
            "localization filter's own σ_z (m)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.localization_sigma_z_m?, at(t)))),
        ),
        figure(
            "localization error, estimate frame, horizontal (m)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.localization_horizontal_estimate_frame_m?, at(t)))),
        ),
        figure(
            "catalogue centre error, estimate frame (m)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.center_error_estimate_frame_m?, at(t)))),
        ),
        figure(
            "ring drift across the rock (m)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.ring_drift_m?, at(t)))),
        ),
        figure(
            "re-acquisitions after a gap in view, per target",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.reacquisitions? as f64, at(t)))),
        ),
        figure(
            "keyframe links across dropped frames no landmark spans, per target",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.keyframe_links_unspanned_after_drops? as f64, at(t)))),
        ),
        figure(
            "map frame refusals, per target",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.map_frame_refusals? as f64, at(t)))),
        ),
        figure(
            "mapping flight's sweep round the rock (°)",
            false,
            counted.iter().filter_map(|t| Some((t.sweep_deg?, at(t)))),
        ),
        figure(
            "rock patched in the map when mapping ended (fraction of its closed surface)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.map_patched_fraction?, at(t)))),
        ),
        figure(
            "support plane's tilt from the map's up, levelled before the contact is read (°)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.support_tilt_deg?, at(t)))),
        ),
        figure(
            "α_min interval width (°)",
            true,
            counted
                .iter()
                .filter_map(|t| Some((t.alpha_min_high_deg? - t.alpha_min_low_deg?, at(t)))),
        ),
        figure(
            "run min true clearance (m)",
            false,
            finished
                .iter()
                .filter_map(|r| Some((r.min_clearance_m?, r.run_dir.clone()))),
        ),
        figure(
            "run wall time (s)",
            true,
            finished
                .iter()
                .filter_map(|r| Some((r.wall_time_s?, r.run_dir.clone()))),
        ),
    ];
    Totals {
        runs: runs.len(),
        runs_finished: finished.len(),
        runs_unfinished: runs.len() - finished.len(),
        runs_completed: Rate::new(
            finished.iter().filter(|r| r.completed_mission()).count(),
            finished.len(),
        ),
        runs_without_collision: Rate::new(
            finished.iter().filter(|r| r.collisions == Some(0)).count(),
            finished.len(),
        ),
        collisions_total: finished.iter().filter_map(|r| r.collisions).sum(),
        runs_clearance_at_least_0_5m: Rate::new(
            finished
                .iter()
                .filter(|r| r.min_clearance_m.is_some_and(|c| c >= CLEARANCE_MIN_M))
                .count(),
            finished.len(),
        ),
        safety_events_total: (!safety.is_empty()).then(|| safety.iter().sum()),
        targets_mapped: Rate::new(mapped, counted.len()),
        targets_flown: Rate::new(flown.len(), counted.len()),
        targets_missed: counted.iter().filter(|t| t.status == "missed").count(),
        distractors_mapped: finished.iter().filter_map(|r| r.distractors_mapped).sum(),
        fscore_2cm_at_least_0_85: Rate::new(
            flown
                .iter()
                .filter(|t| t.fscore_2cm.is_some_and(|v| v >= FSCORE_2CM_MIN))
                .count(),
            flown.len(),
        ),
        alpha_error_within_2deg: Rate::new(
            with_truth
                .iter()
                .filter(|t| {
                    t.alpha_error_deg
                        .is_some_and(|e| e.abs() <= ALPHA_ERROR_MAX_DEG)
                })
                .count(),
            with_truth.len(),
        ),
        alpha_refused: with_truth
            .iter()
            .filter(|t| t.alpha_min_deg.is_none())
            .count(),
        alpha_overestimates_above_3deg: counted
            .iter()
            .filter(|t| {
                t.alpha_error_deg
                    .is_some_and(|e| e > ALPHA_OVERESTIMATE_MAX_DEG)
            })
            .count(),
        truth_in_interval: Rate::new(
            with_interval
                .iter()
                .filter(|t| t.truth_in_interval == Some(true))
                .count(),
            with_interval.len(),
        ),
        interval_width_median_deg: median(&widths),
        localization_within_1m: Rate::new(
            localized
                .iter()
                .filter(|t| {
                    t.localization_error_m
                        .is_some_and(|e| e <= LOCALIZATION_ERROR_MAX_M)
                })
                .count(),
            localized.len(),
        ),
        localization_estimate_frame_within_0_5m: Rate::new(
            estimate_frame
                .iter()
                .filter(|e| **e <= LOCALIZATION_ESTIMATE_FRAME_MAX_M)
                .count(),
            estimate_frame.len(),
        ),
        center_estimate_frame_within_0_5m: Rate::new(
            center_frame
                .iter()
                .filter(|e| **e <= LOCALIZATION_ESTIMATE_FRAME_MAX_M)
                .count(),
            center_frame.len(),
        ),
        figures,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Writes a fake run folder: a world with targets 1 and 2 and distractor 10, and a
    /// mission that mapped rock 1 twice (a duplicate), never found rock 2 and mapped the
    /// distractor.
    fn fake_run(dir: &Path, run: &RunSpec, alpha: f64, collisions: u64) {
        let d = dir.join(run.dir());
        std::fs::create_dir_all(d.join("world_gt")).unwrap();
        let world = json!({"rocks": [
            {"id": 1, "role": "target", "shape": "builtin:double_rock"},
            {"id": 2, "role": "target"},
            {"id": 10, "role": "distractor"},
        ]});
        std::fs::write(d.join("world_gt/world.json"), world.to_string()).unwrap();
        let mission = json!({
            "interrupted": false, "end_reason": "complete", "wall_time_s": 100.0 + alpha,
            "sim_time_s": 900.0, "collisions": collisions, "min_clearance_m": 0.8 - 0.1 * alpha,
            "targets_mapped": 2, "distractors_mapped": 1,
            "targets": [
                {"id": 7, "status": "duplicate", "gt_rock_id": 1, "gt_role": "target",
                 "localization_error_m": 0.1},
                {"id": 3, "status": "mapped", "gt_rock_id": 1, "gt_role": "target",
                 "fscore_1cm": 0.8, "fscore_2cm": 0.9, "alpha_min_deg": 5.0 + alpha,
                 "alpha_min_gt_deg": 5.0, "localization_error_m": 0.7,
                 "alpha_min_low_deg": 4.0 + 0.9 * alpha, "alpha_min_high_deg": 6.0 + alpha,
                 "gt_visible_fraction": 0.9 - 0.1 * alpha, "sweep_deg": 230.0 + 150.0 * alpha,
                 "localization_offset_estimate_frame_m": [0.3, -0.4, 0.1 * alpha],
                 "localized_sigma_m": [0.4, 0.4, 0.5]},
                {"id": 4, "status": "mapped", "gt_rock_id": 10, "gt_role": "distractor"},
            ],
        });
        let mut mission = mission;
        if collisions > 0 {
            // This run also flew rock 2, scored its mesh, and refused its analysis.
            mission["targets"].as_array_mut().unwrap().push(json!({
                "id": 5, "status": "incomplete", "gt_rock_id": 2, "gt_role": "target",
                "fscore_2cm": 0.8, "alpha_min_gt_deg": 9.0, "localization_error_m": 1.2,
                "error": "fragility: refused"}));
        }
        std::fs::write(d.join("mission.json"), mission.to_string()).unwrap();
    }

    #[test]
    fn rows_follow_mission_json_and_totals_count_them() {
        let dir = tempfile::tempdir().unwrap();
        let runs: Vec<RunSpec> = (0..4)
            .map(|seed| RunSpec {
                world: "w.toml".into(),
                seed,
            })
            .collect();
        fake_run(dir.path(), &runs[0], 1.0, 0);
        fake_run(dir.path(), &runs[1], 3.5, 12);
        // Seed 1 finished, but a leg it could not plan ended its mission early.
        let early = dir.path().join(runs[1].dir()).join("mission.json");
        let mut mission: Value =
            serde_json::from_str(&std::fs::read_to_string(&early).unwrap()).unwrap();
        mission["end_reason"] = json!("error: no clear way out");
        std::fs::write(&early, mission.to_string()).unwrap();
        // Seed 2 failed: its folder and world exist, its mission.json does not.
        fake_run(dir.path(), &runs[2], 0.0, 0);
        let failed = dir.path().join(runs[2].dir());
        std::fs::remove_file(failed.join("mission.json")).unwrap();
        std::fs::write(failed.join("run.log"), "starting\nerror: the world broke\n").unwrap();
        std::fs::write(failed.join(FAILED_MARKER), "exit status: 1").unwrap();
        // Seed 3 never ran; seed 4 is running.
        let mut runs = runs;
        runs.push(RunSpec {
            world: "w.toml".into(),
            seed: 4,
        });
        std::fs::create_dir_all(dir.path().join(runs[4].dir())).unwrap();
        let (run_rows, rows) = read_runs(dir.path(), &runs).unwrap();
        assert_eq!(
            run_rows.iter().map(|r| r.state).collect::<Vec<_>>(),
            [
                RunState::Finished,
                RunState::Finished,
                RunState::Failed,
                RunState::NotRun,
                RunState::Started
            ]
        );
        assert_eq!(run_rows[2].error.as_deref(), Some("error: the world broke"));
        // Two true targets per run with a world.json; the distractor is not a row.
        assert_eq!(rows.len(), 6);
        let first = &rows[0];
        assert_eq!(
            (first.rock_id, first.target_id),
            (1, Some(3)),
            "the mapped one wins"
        );
        assert_eq!(first.status, "mapped");
        assert_eq!(first.shape.as_deref(), Some("builtin:double_rock"));
        assert_eq!(first.alpha_error_deg, Some(1.0));
        assert_eq!(first.truth_in_interval, Some(true));
        assert_eq!(first.fscore_2cm, Some(0.9));
        assert_eq!(first.localization_error_m, Some(0.7));
        assert_eq!(first.min_clearance_m, Some(0.8 - 0.1));
        assert_eq!(first.gt_visible_fraction, Some(0.9 - 0.1));
        assert_eq!(first.sweep_deg, Some(380.0));
        assert_eq!(rows[3].sweep_deg, None);
        assert_eq!(first.localization_vertical_estimate_frame_m, Some(0.1));
        assert!((first.localization_horizontal_estimate_frame_m.unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(rows[3].localization_vertical_estimate_frame_m, None);
        assert_eq!(rows[1].status, "missed");
        assert_eq!(rows[1].rock_id, 2);
        assert_eq!(rows[2].alpha_error_deg, Some(3.5));
        assert_eq!(
            rows[2].truth_in_interval,
            Some(false),
            "5° lies below [7.15°, 9.5°]"
        );
        assert_eq!(rows[3].status, "incomplete");
        assert_eq!(rows[3].error.as_deref(), Some("fragility: refused"));
        assert_eq!(rows[4].status, "run_failed");

        let t = totals(&run_rows, &rows);
        assert_eq!((t.runs, t.runs_finished, t.runs_unfinished), (5, 2, 3));
        assert_eq!(t.runs_completed, Rate::new(1, 2));
        assert_eq!(t.runs_without_collision, Rate::new(1, 2));
        assert_eq!(t.collisions_total, 12);
        assert_eq!(
            t.targets_mapped,
            Rate::new(2, 4),
            "failed runs are not counted"
        );
        assert_eq!(t.targets_missed, 1);
        assert_eq!(t.targets_flown, Rate::new(3, 4));
        assert_eq!(t.alpha_refused, 1);
        assert_eq!(t.distractors_mapped, 2);
        assert_eq!(t.fscore_2cm_at_least_0_85, Rate::new(2, 3));
        assert_eq!(t.alpha_error_within_2deg, Rate::new(1, 3));
        assert_eq!(t.alpha_overestimates_above_3deg, 1);
        assert_eq!(t.localization_within_1m, Rate::new(2, 3));
        assert_eq!(t.runs_clearance_at_least_0_5m, Rate::new(1, 2));
        let abs = &t.figures[0];
        assert_eq!(abs.n, 2);
        assert_eq!(abs.worst, Some(3.5));
        assert_eq!(abs.worst_at.as_deref(), Some("runs/w/seed-1#rock-1"));
        assert_eq!(abs.median, Some(2.25));
        let seen = t
            .figures
            .iter()
            .find(|f| f.name.starts_with("true rock surface seen"))
            .unwrap();
        // The seed-1 mesh saw the least: 0.9 − 0.35; rock 2's refused flight reports none.
        assert_eq!(seen.n, 2);
        assert!((seen.worst.unwrap() - 0.55).abs() < 1e-12);
        assert_eq!(seen.worst_at.as_deref(), Some("runs/w/seed-1#rock-1"));
        let vertical = t
            .figures
            .iter()
            .find(|f| f.name.contains("vertical"))
            .unwrap();
        assert!((vertical.worst.unwrap() - 0.35).abs() < 1e-12);
        let in_sigma = t
            .figures
            .iter()
            .find(|f| f.name.contains("own σ_z"))
            .unwrap();
        assert!(
            (in_sigma.worst.unwrap() - 0.7).abs() < 1e-12,
            "0.35 m over σ_z 0.5 m"
        );
        let clearance = t
            .figures
            .iter()
            .find(|f| f.name.contains("clearance"))
            .unwrap();
        let worst = clearance.worst.unwrap();
        assert!(
            (worst - 0.45).abs() < 1e-12,
            "the smallest is the worst: {worst}"
        );
        assert_eq!(clearance.worst_at.as_deref(), Some("runs/w/seed-1"));
        let sweep = t.figures.iter().find(|f| f.name.contains("sweep")).unwrap();
        assert_eq!(
            (sweep.n, sweep.worst, sweep.worst_at.as_deref()),
            (2, Some(380.0), Some("runs/w/seed-0#rock-1")),
            "the shortest flight round the rock is the worst"
        );
        assert!((t.interval_width_median_deg.unwrap() - 2.225).abs() < 1e-12);
        assert_eq!(t.truth_in_interval, Rate::new(1, 2));
    }
}
