//! End-to-end tests of `scarp campaign`: real missions on the small world (aggregation,
//! resume), and sharding plus `merge` on hand-made run folders.

mod common;
use common::{path_str, read_json, scarp, scarp_ok, test_data};

use std::path::Path;

/// Every figure of a campaign row equals the one in its run's own `mission.json`.
fn assert_rows_match_missions(campaign_dir: &Path) {
    let campaign = read_json(&campaign_dir.join("campaign.json"));
    let rows = campaign["targets"].as_array().unwrap();
    assert!(!rows.is_empty(), "{campaign:#}");
    for row in rows {
        let run_dir = campaign_dir.join(row["run_dir"].as_str().unwrap());
        let mission = read_json(&run_dir.join("mission.json"));
        let target = mission["targets"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["id"] == row["target_id"])
            .unwrap_or_else(|| panic!("row {row:#} has no target in {mission:#}"));
        assert_eq!(target["gt_rock_id"], row["rock_id"]);
        for key in [
            "status",
            "fscore_1cm",
            "fscore_2cm",
            "alpha_min_deg",
            "alpha_min_gt_deg",
            "localization_error_m",
        ] {
            assert_eq!(target[key], row[key], "{key} of {row:#}");
        }
        if let (Some(a), Some(g)) = (
            target["alpha_min_deg"].as_f64(),
            target["alpha_min_gt_deg"].as_f64(),
        ) {
            assert_eq!(row["alpha_error_deg"].as_f64(), Some(a - g));
        }
        assert_eq!(row["run_collisions"], mission["collisions"]);
    }
    let runs = campaign["runs"].as_array().unwrap();
    for run in runs {
        let mission = read_json(
            &campaign_dir
                .join(run["run_dir"].as_str().unwrap())
                .join("mission.json"),
        );
        for key in ["collisions", "min_clearance_m", "wall_time_s", "end_reason"] {
            assert_eq!(run[key], mission[key], "{key}");
        }
    }
    let md = std::fs::read_to_string(campaign_dir.join("campaign.md")).unwrap();
    for heading in [
        "## Totals",
        "## Figures",
        "## Worst cases",
        "## Per world",
        "## Targets",
    ] {
        assert!(md.contains(heading), "{heading} in\n{md}");
    }
}

#[test]
fn small_world_campaign_tabulates_its_missions_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    let world = test_data("small_world.toml");
    // The small mission, ended once its one target is mapped (the rest of its search adds
    // nothing to the tables), so that two missions fit the test's time.
    let config = dir.path().join("mission.toml");
    let small = std::fs::read_to_string(test_data("small_mission.toml")).unwrap();
    std::fs::write(&config, format!("{small}\nmax_targets = 1\n")).unwrap();
    // An earlier, interrupted campaign: seed 2 finished (a hand-made run, so that the test
    // flies only two missions), seed 1 was interrupted half-way, seed 0 never started.
    fake_run(&out.join("runs/small_world/seed-2"), 2);
    let seed2_before = std::fs::read(out.join("runs/small_world/seed-2/mission.json")).unwrap();
    let seed1 = out.join("runs/small_world/seed-1");
    std::fs::create_dir_all(&seed1).unwrap();
    std::fs::write(seed1.join("mission.json"), r#"{"interrupted": true}"#).unwrap();
    std::fs::write(seed1.join("stale.txt"), "from the interrupted attempt").unwrap();
    let args = [
        "campaign",
        "--worlds",
        &world,
        "--seeds",
        "0-2",
        "--jobs",
        "2",
        "--config",
        path_str(&config),
        "--out",
        path_str(&out),
        "--json",
    ];
    let run = scarp_ok(&args);
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(log.contains("1 already finished, 2 to run"), "{log}");
    let totals: serde_json::Value = serde_json::from_slice(&run.stdout).expect("totals on stdout");
    assert_eq!(totals["runs"], 3, "{totals:#}");
    assert_eq!(totals["runs_finished"], 3, "{totals:#}");
    // The flown runs ended at their target limit, which counts as a completed mission.
    assert_eq!(totals["runs_completed"]["count"], 3, "{totals:#}");
    // One true target per run.
    assert_eq!(totals["targets_flown"]["of"], 3, "{totals:#}");
    // The finished run was left alone; the interrupted one ran again from a clean folder.
    assert_eq!(
        std::fs::read(out.join("runs/small_world/seed-2/mission.json")).unwrap(),
        seed2_before
    );
    assert_eq!(read_json(&seed1.join("mission.json"))["interrupted"], false);
    assert!(
        !seed1.join("stale.txt").exists(),
        "the retried run starts clean"
    );
    assert!(seed1.join("run.log").is_file());
    assert_rows_match_missions(&out);
    let campaign = read_json(&out.join("campaign.json"));
    assert_eq!(campaign["totals"], totals);
    assert!(
        campaign["config_toml"]
            .as_str()
            .unwrap()
            .contains("search_height_agl_m")
    );
    // Run again: nothing left to fly, the same tables.
    let again = scarp_ok(&args);
    assert!(String::from_utf8_lossy(&again.stderr).contains("3 already finished, 0 to run"));
    assert_eq!(
        read_json(&out.join("campaign.json"))["targets"],
        campaign["targets"]
    );

    // The same folder with another configuration is refused.
    let other = dir.path().join("other.toml");
    std::fs::write(&other, "search_height_agl_m = 13.0\n").unwrap();
    let mut mixed = args.to_vec();
    mixed[8] = path_str(&other);
    let refused = scarp(&mixed);
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("another configuration"), "{err}");
}

/// A hand-made finished run in `run`: a world with one target, a mission that mapped it.
fn fake_run(run: &Path, seed: u64) {
    std::fs::create_dir_all(run.join("world_gt")).unwrap();
    std::fs::write(
        run.join("world_gt/world.json"),
        r#"{"rocks": [{"id": 1, "role": "target"}, {"id": 2, "role": "distractor"}]}"#,
    )
    .unwrap();
    let s = seed as f64;
    let mission = serde_json::json!({
        "interrupted": false, "end_reason": "complete", "wall_time_s": 10.0 + s,
        "collisions": seed % 3, "min_clearance_m": 0.3 + 0.1 * s, "distractors_mapped": 0,
        "targets": [{"id": 1, "status": if seed == 4 { "incomplete" } else { "mapped" },
            "gt_rock_id": 1, "gt_role": "target", "fscore_2cm": 0.8 + 0.02 * s,
            "alpha_min_deg": 5.0 + 0.8 * s, "alpha_min_gt_deg": 6.0,
            "localization_error_m": 0.2 * s}],
    });
    std::fs::write(run.join("mission.json"), mission.to_string()).unwrap();
}

#[test]
fn shards_merge_into_the_unsharded_tables() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, shard0, shard1, merged) = (
        dir.path().join("whole"),
        dir.path().join("s0"),
        dir.path().join("s1"),
        dir.path().join("merged"),
    );
    // The same runs, as one folder and as the two shards' folders (seed 0, 2, 4 / 1, 3).
    for seed in 0..5 {
        let run = format!("runs/w/seed-{seed}");
        fake_run(&whole.join(&run), seed);
        let shard = if seed % 2 == 0 { &shard0 } else { &shard1 };
        fake_run(&shard.join(&run), seed);
    }
    let tabulate = |out: &Path, shard: Option<&str>| {
        let mut args = vec![
            "campaign",
            "--worlds",
            "w.toml",
            "--seeds",
            "0-4",
            "--tabulate-only",
            "--out",
            path_str(out),
        ];
        if let Some(s) = shard {
            args.extend(["--shard", s]);
        }
        scarp_ok(&args);
    };
    tabulate(&whole, None);
    tabulate(&shard0, Some("0/2"));
    tabulate(&shard1, Some("1/2"));
    assert_eq!(
        read_json(&shard0.join("campaign.json"))["plan"]
            .as_array()
            .unwrap()
            .len(),
        3
    );
    // Shards listed in any order.
    scarp_ok(&[
        "campaign",
        "merge",
        path_str(&shard1),
        path_str(&shard0),
        "--out",
        path_str(&merged),
    ]);
    let (a, b) = (
        read_json(&whole.join("campaign.json")),
        read_json(&merged.join("campaign.json")),
    );
    for key in ["totals", "targets", "runs", "plan", "worlds", "seeds"] {
        assert_eq!(a[key], b[key], "{key}");
    }
    assert_eq!(a["totals"]["runs_without_collision"]["count"], 2);
    assert_eq!(a["totals"]["alpha_error_within_2deg"]["count"], 4);
    assert!(merged.join("runs/w/seed-3/mission.json").is_file());
    assert_rows_match_missions(&merged);

    // A merge of folders run with different configurations is refused.
    std::fs::write(dir.path().join("c.toml"), "search_height_agl_m = 13.0\n").unwrap();
    let other = dir.path().join("other");
    fake_run(&other.join("runs/w/seed-0"), 0);
    scarp_ok(&[
        "campaign",
        "--worlds",
        "w.toml",
        "--seeds",
        "0",
        "--tabulate-only",
        "--config",
        path_str(&dir.path().join("c.toml")),
        "--out",
        path_str(&other),
    ]);
    let refused = scarp(&[
        "campaign",
        "merge",
        path_str(&whole),
        path_str(&other),
        "--out",
        path_str(&dir.path().join("bad")),
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("another configuration"));
}

#[test]
fn bad_campaign_arguments_are_named() {
    let dir = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (vec!["--seeds", "3-1"], "--seeds"),
        (vec!["--shard", "2/2"], "--shard"),
        (vec!["--jobs", "0"], "--jobs"),
        (vec!["--worlds", "a/x.toml,b/x.toml"], "share the folder"),
    ] {
        let mut full = vec!["campaign", "--out", path_str(dir.path())];
        full.extend(args);
        let out = scarp(&full);
        assert!(!out.status.success(), "{full:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{full:?}: {err}");
    }
}
