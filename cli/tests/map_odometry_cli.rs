//! End-to-end `scarp map --poses odometry [--ba]` on a short noisy orbit of the default world
//! (48 frames, 7.5° apart): the tracked trajectory is written and beats the state estimate, and
//! `map.json` carries the odometry and bundle-adjustment figures. The 360-frame figures of
//! issues 4 and 5 come from the commands in `src/cli/map.rs`.

mod common;
use common::{first_rock_centroid_m, read_json as json, scarp_stdout as scarp};

fn number(map: &serde_json::Value, key: &str) -> f64 {
    map[key]
        .as_f64()
        .unwrap_or_else(|| panic!("map.json has no number `{key}`: {map}"))
}

#[test]
fn odometry_mapping_and_bundle_adjustment() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    scarp(&[
        "render",
        "--path",
        "orbit",
        "--frames",
        "48",
        "--out",
        &d("seq"),
    ]);
    let [x, y, z] = first_rock_centroid_m(dir.path());
    // Tall: the odometry map is anchored at the first state estimate, metres off vertically.
    let roi = format!("cyl:{x},{y},{},{},2.5", z - 4.0, z + 4.0);
    scarp(&[
        "map",
        &d("seq"),
        "--poses",
        "odometry",
        "--ba",
        "--world",
        "default",
        "--roi",
        &roi,
        "--out",
        &d("map"),
    ]);
    let map = json(&dir.path().join("map/map.json"));
    let trajectory = std::fs::read_to_string(dir.path().join("map/trajectory.txt")).unwrap();
    let poses = trajectory
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .count();
    assert_eq!(poses, 48);
    assert!(number(&map, "odometry_ms_median") > 0.0);
    assert!(map["odometry_failures"].as_u64().is_some());
    let ate = number(&map, "ate_rmse_m");
    let estimate = number(&map, "estimate_ate_rmse_m");
    assert!(ate < 0.01 && ate * 10.0 < estimate, "{ate} vs {estimate}");
    for key in [
        "ate_rmse_before_ba_m",
        "ate_rmse_after_ba_m",
        "fscore_before_ba",
        "fscore_after_ba",
        "ba_initial_cost",
        "ba_final_cost",
    ] {
        assert!(number(&map, key).is_finite(), "{key}");
    }
    assert!(map["ba_landmarks"].as_u64().unwrap() > 200, "{map}");
    assert!(number(&map, "ba_final_cost") < number(&map, "ba_initial_cost"));
    // Landmarks are matched from their anchor keyframe along the odometry's prediction:
    // re-triangulated with the true poses they reproject within a fraction of a pixel (the
    // old keyframe-to-keyframe chains gave a median of 0.35 px and a 90th percentile of 1 px).
    let residuals = &map["ba_landmark_residuals_truth"];
    assert!(
        number(residuals, "median_px") < 0.2 && number(residuals, "p90_px") < 0.5,
        "{residuals}"
    );
    let (before, after) = (
        number(&map, "ate_rmse_before_ba_m"),
        number(&map, "ate_rmse_after_ba_m"),
    );
    assert!(after < before, "BA raised the ATE: {before} -> {after}");
    assert!(dir.path().join("map/keyframes_ba.txt").exists());
    assert!(dir.path().join("map/mesh.ply").exists());
}
