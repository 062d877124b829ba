//! `campaign.md`: the totals, the figures' distributions, the worst cases with their run
//! folders, a table per world and every target's row.

use std::fmt::Write;

use super::CampaignReport;
use super::table::{
    ALPHA_ERROR_MAX_DEG, ALPHA_OVERESTIMATE_MAX_DEG, CLEARANCE_MIN_M, FSCORE_2CM_MIN,
    LOCALIZATION_ERROR_MAX_M, LOCALIZATION_ESTIMATE_FRAME_MAX_M, Rate, RunState, TargetRow, totals,
};

/// How many rows each worst-case list shows.
const WORST_ROWS: usize = 5;

/// A table cell: `|` would end the cell, so it is escaped.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "–".into(), |v| format!("{v:.digits$}"))
}

fn rate(r: &Rate) -> String {
    match r.rate {
        Some(x) => format!("{} / {} ({:.0}%)", r.count, r.of, 100.0 * x),
        None => "– (none to count)".into(),
    }
}

/// Renders `campaign.md`.
pub fn render(report: &CampaignReport) -> String {
    let mut md = String::new();
    let t = &report.totals;
    // `write!` into a String cannot fail.
    let _ = writeln!(md, "# Campaign\n");
    let _ = writeln!(
        md,
        "- worlds: {}\n- seeds: {}\n- runs: {} ({} finished, {} not)\n- configuration: {}{}{}",
        report.worlds.join(", "),
        seed_list(&report.seeds),
        t.runs,
        t.runs_finished,
        t.runs_unfinished,
        if report.config_toml.is_some() {
            "custom (in campaign.json)"
        } else {
            "defaults"
        },
        report
            .shard
            .map_or(String::new(), |s| format!("\n- shard: {s}")),
        if report.merged_from.is_empty() {
            String::new()
        } else {
            format!("\n- merged from: {}", report.merged_from.join(", "))
        },
    );
    if let Some(w) = report.wall_time_s {
        let _ = writeln!(md, "- campaign wall time: {w:.0} s");
    }

    let _ = writeln!(md, "\n## Totals\n\n| must-show | result |\n|---|---|");
    let rows: [(String, String); 16] = [
        (
            "runs that completed the mission (not ended by an error or a crash)".into(),
            rate(&t.runs_completed),
        ),
        (
            "runs without a collision".into(),
            rate(&t.runs_without_collision),
        ),
        (
            format!("runs with true clearance ≥ {CLEARANCE_MIN_M} m"),
            rate(&t.runs_clearance_at_least_0_5m),
        ),
        (
            "camera steps in collision, all runs".into(),
            t.collisions_total.to_string(),
        ),
        (
            "safety interventions, all runs".into(),
            t.safety_events_total
                .map_or("– (not recorded)".into(), |n| n.to_string()),
        ),
        ("true targets mapped".into(), rate(&t.targets_mapped)),
        (
            "true targets flown in Map mode (mapped or incomplete)".into(),
            rate(&t.targets_flown),
        ),
        ("true targets missed".into(), t.targets_missed.to_string()),
        (
            "distractors mapped".into(),
            t.distractors_mapped.to_string(),
        ),
        (
            format!("F@2cm ≥ {FSCORE_2CM_MIN} (of flown)"),
            rate(&t.fscore_2cm_at_least_0_85),
        ),
        (
            format!("|α error| ≤ {ALPHA_ERROR_MAX_DEG}° (of flown; a refusal counts as a miss)"),
            format!(
                "{} ({} refused)",
                rate(&t.alpha_error_within_2deg),
                t.alpha_refused
            ),
        ),
        (
            format!("α overestimated by > {ALPHA_OVERESTIMATE_MAX_DEG}°"),
            t.alpha_overestimates_above_3deg.to_string(),
        ),
        (
            "truth inside the reported α interval".into(),
            format!(
                "{}; median width {}°",
                rate(&t.truth_in_interval),
                num(t.interval_width_median_deg, 2)
            ),
        ),
        (
            format!("localization error ≤ {LOCALIZATION_ERROR_MAX_M} m"),
            rate(&t.localization_within_1m),
        ),
        (
            format!("localization error ≤ {LOCALIZATION_ESTIMATE_FRAME_MAX_M} m, estimate frame"),
            rate(&t.localization_estimate_frame_within_0_5m),
        ),
        (
            format!(
                "catalogue centre ≤ {LOCALIZATION_ESTIMATE_FRAME_MAX_M} m, estimate frame (the scan's centroid once mapped)"
            ),
            rate(&t.center_estimate_frame_within_0_5m),
        ),
    ];
    for (what, result) in rows {
        let _ = writeln!(md, "| {} | {} |", cell(&what), cell(&result));
    }

    let _ = writeln!(
        md,
        "\n## Figures\n\n| figure | n | median | p10 | p90 | worst | where |\n|---|---|---|---|---|---|---|"
    );
    for f in &t.figures {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} |",
            cell(&f.name),
            f.n,
            num(f.median, 3),
            num(f.p10, 3),
            num(f.p90, 3),
            num(f.worst, 3),
            f.worst_at.as_deref().unwrap_or("–")
        );
    }

    worst_cases(&mut md, report);
    per_world(&mut md, report);

    let _ = writeln!(
        md,
        "\n## Targets\n\n| world | seed | rock | shape | status | F@1cm | F@2cm | seen | α_min (°) | truth (°) | error (°) | interval (°) | in | loc. error (m) | est.-frame (m) | its vertical (m) | centre, est.-frame (m) | sweep (°) | min clearance (m) | collisions |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in &report.targets {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.world,
            r.seed,
            r.rock_id,
            r.shape.as_deref().unwrap_or("–"),
            r.status,
            num(r.fscore_1cm, 3),
            num(r.fscore_2cm, 3),
            num(r.gt_visible_fraction, 2),
            num(r.alpha_min_deg, 2),
            num(r.alpha_min_gt_deg, 2),
            num(r.alpha_error_deg, 2),
            match (r.alpha_min_low_deg, r.alpha_min_high_deg) {
                (Some(lo), Some(hi)) => format!("[{lo:.2}, {hi:.2}]"),
                _ => "–".into(),
            },
            match r.truth_in_interval {
                Some(true) => "yes",
                Some(false) => "**no**",
                None => "–",
            },
            num(r.localization_error_m, 2),
            num(r.localization_error_estimate_frame_m, 2),
            r.localization_vertical_estimate_frame_m
                .map_or("–".into(), |v| format!("{v:+.2}")),
            match (r.center_error_estimate_frame_m, r.center_source.as_deref()) {
                (Some(e), Some("scan")) => format!("{e:.2} (scan)"),
                (e, _) => num(e, 2),
            },
            num(r.sweep_deg, 0),
            num(r.min_clearance_m, 2),
            r.run_collisions.map_or("–".into(), |c| c.to_string()),
        );
    }
    md
}

fn seed_list(seeds: &[u64]) -> String {
    match (seeds.first(), seeds.last()) {
        (Some(a), Some(b)) if (b - a) as usize + 1 == seeds.len() && a != b => format!("{a}–{b}"),
        _ => seeds
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(", "),
    }
}

fn worst_cases(md: &mut String, report: &CampaignReport) {
    let _ = writeln!(md, "\n## Worst cases\n");
    let mut by_alpha: Vec<&TargetRow> = report
        .targets
        .iter()
        .filter(|r| r.alpha_error_deg.is_some())
        .collect();
    by_alpha.sort_by(|a, b| {
        b.alpha_error_deg
            .unwrap_or(0.0)
            .abs()
            .total_cmp(&a.alpha_error_deg.unwrap_or(0.0).abs())
    });
    let _ = writeln!(md, "Largest |α error|:\n");
    for r in by_alpha.iter().take(WORST_ROWS) {
        let _ = writeln!(
            md,
            "- {:+.2}° (α {} vs truth {}) — `{}` rock {}",
            r.alpha_error_deg.unwrap_or(0.0),
            num(r.alpha_min_deg, 2),
            num(r.alpha_min_gt_deg, 2),
            r.run_dir,
            r.rock_id
        );
    }
    let mut by_f: Vec<&TargetRow> = report
        .targets
        .iter()
        .filter(|r| r.fscore_2cm.is_some())
        .collect();
    by_f.sort_by(|a, b| {
        a.fscore_2cm
            .unwrap_or(0.0)
            .total_cmp(&b.fscore_2cm.unwrap_or(0.0))
    });
    let _ = writeln!(md, "\nLowest F@2cm:\n");
    for r in by_f.iter().take(WORST_ROWS) {
        let _ = writeln!(
            md,
            "- {} — `{}` rock {}",
            num(r.fscore_2cm, 3),
            r.run_dir,
            r.rock_id
        );
    }
    let unmapped = report
        .targets
        .iter()
        .filter(|r| {
            r.status != "mapped" || (r.alpha_min_deg.is_none() && r.alpha_min_gt_deg.is_some())
        })
        .map(|r| {
            let error = dash_suffix(r.error.as_deref());
            format!("`{}` rock {}: {}{error}", r.run_dir, r.rock_id, r.status)
        });
    bullet_section(md, "Not mapped, or not analysed", unmapped);
    let mut by_clearance: Vec<_> = report
        .runs
        .iter()
        .filter(|r| r.min_clearance_m.is_some())
        .collect();
    by_clearance.sort_by(|a, b| {
        a.min_clearance_m
            .unwrap_or(0.0)
            .total_cmp(&b.min_clearance_m.unwrap_or(0.0))
    });
    let _ = writeln!(md, "\nLowest true clearance:\n");
    for r in by_clearance.iter().take(WORST_ROWS) {
        let _ = writeln!(
            md,
            "- {} m, {} camera steps in collision — `{}`",
            num(r.min_clearance_m, 2),
            r.collisions.unwrap_or(0),
            r.run_dir
        );
    }
    let ended_early = report
        .runs
        .iter()
        .filter(|r| r.state == RunState::Finished && !r.completed_mission())
        .map(|r| {
            let reason = r.end_reason.as_deref().unwrap_or("no end reason");
            format!("`{}`: {reason}", r.run_dir)
        });
    bullet_section(
        md,
        "Runs that ended before completing the mission",
        ended_early,
    );
    let unfinished = report
        .runs
        .iter()
        .filter(|r| r.state != RunState::Finished)
        .map(|r| {
            let error = dash_suffix(r.error.as_deref());
            format!("`{}`: {:?}{error}", r.run_dir, r.state)
        });
    bullet_section(md, "Unfinished runs", unfinished);
}

/// Appends `title` and one bullet per item, or nothing when there are no items.
fn bullet_section(md: &mut String, title: &str, items: impl Iterator<Item = String>) {
    let mut items = items.peekable();
    if items.peek().is_some() {
        let _ = writeln!(md, "\n{title}:\n");
        for item in items {
            let _ = writeln!(md, "- {item}");
        }
    }
}

/// " — text", or nothing without a text.
fn dash_suffix(text: Option<&str>) -> String {
    text.map_or(String::new(), |t| format!(" — {t}"))
}

fn per_world(md: &mut String, report: &CampaignReport) {
    let _ = writeln!(
        md,
        "\n## Per world\n\n| world | runs finished | targets mapped | F@2cm ≥ {FSCORE_2CM_MIN} | \\|α error\\| ≤ {ALPHA_ERROR_MAX_DEG}° | runs without collision | median run wall time (s) |\n|---|---|---|---|---|---|---|"
    );
    for world in &report.worlds {
        let runs: Vec<_> = report
            .runs
            .iter()
            .filter(|r| &r.world == world)
            .cloned()
            .collect();
        let targets: Vec<_> = report
            .targets
            .iter()
            .filter(|r| &r.world == world)
            .cloned()
            .collect();
        let t = totals(&runs, &targets);
        let wall = t
            .figures
            .iter()
            .find(|f| f.name.starts_with("run wall time"))
            .and_then(|f| f.median);
        let _ = writeln!(
            md,
            "| {world} | {} / {} | {} | {} | {} | {} | {} |",
            t.runs_finished,
            t.runs,
            rate(&t.targets_mapped),
            rate(&t.fscore_2cm_at_least_0_85),
            rate(&t.alpha_error_within_2deg),
            rate(&t.runs_without_collision),
            num(wall, 0)
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bullet_section_lists_its_items_and_is_absent_without_any() {
        let mut md = String::new();
        bullet_section(&mut md, "Unfinished runs", std::iter::empty());
        assert_eq!(md, "");
        let items = ["`runs/a`: Failed", "`runs/b`: Interrupted"].map(String::from);
        bullet_section(&mut md, "Unfinished runs", items.into_iter());
        assert_eq!(
            md,
            "\nUnfinished runs:\n\n- `runs/a`: Failed\n- `runs/b`: Interrupted\n"
        );
        assert_eq!(dash_suffix(Some("timed out")), " — timed out");
        assert_eq!(dash_suffix(None), "");
    }
}
