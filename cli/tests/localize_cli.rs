//! End-to-end test of `scarp localize` (issue 7, "Must show", small): one lawn-mower pass plus
//! one fine-localization circle over target 1 of the default world, rendered by `scarp render`,
//! then localized with ground-truth and with estimated poses.

mod common;
use common::{path_str, scarp, scarp_ok};

use std::path::Path;

/// Renders the small must-show sequence: a 30 m lawn-mower square and a circle around target 1
/// at 10 m search altitude.
fn render(dir: &Path) {
    scarp_ok(&[
        "render",
        "--path",
        "lawnmower+finecircle",
        "--target",
        "1",
        "--altitude",
        "10",
        "--frames",
        "48",
        "--seed",
        "3",
        "--out",
        path_str(dir),
    ]);
}

fn localize(seq: &Path, out: &Path, poses: &str, tracker: &str) -> serde_json::Value {
    let stdout = scarp_ok(&[
        "localize",
        path_str(seq),
        "--detector",
        "simulated",
        "--tracker",
        tracker,
        "--poses",
        poses,
        "--out",
        path_str(out),
        "--json",
    ])
    .stdout;
    let json: serde_json::Value = serde_json::from_slice(&stdout).expect("JSON on stdout");
    // The same summary is written to the output directory.
    let file: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("localization.json")).unwrap()).unwrap();
    assert_eq!(json["targets"], file["targets"]);
    json
}

/// The target matched to rock 1, with the interface fields checked.
fn rock_one(json: &serde_json::Value, out: &Path) -> serde_json::Value {
    let targets = json["targets"].as_array().expect("a targets array");
    for t in targets {
        for key in ["id", "status", "center", "lambda_max", "entropy", "points"] {
            assert!(!t[key].is_null(), "missing {key} in {t}");
        }
        assert_eq!(t["center"].as_array().unwrap().len(), 3);
        let ply = out.join(t["points"].as_str().unwrap());
        let cloud = scarp_export::ply::read_point_cloud(&ply).expect("points.ply reads back");
        assert_eq!(cloud.positions.len(), 2000);
        let id = t["id"].as_u64().unwrap();
        assert!(out.join(format!("targets/{id}/target.json")).exists());
    }
    let matched: Vec<_> = targets
        .iter()
        .filter(|t| t["gt_rock_id"].as_u64() == Some(1))
        .collect();
    assert_eq!(matched.len(), 1, "one target on rock 1: {targets:?}");
    matched[0].clone()
}

#[test]
fn lawnmower_and_circle_localize_target_one() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let seq = dir.path().join("seq");
    render(&seq);

    let out_gt = dir.path().join("gt");
    let json = localize(&seq, &out_gt, "groundtruth", "klt");
    let t = rock_one(&json, &out_gt);
    let error_m = t["centroid_error_m"].as_f64().unwrap();
    assert!(
        error_m <= 0.3,
        "ground-truth poses: centroid error {error_m} m"
    );
    assert_eq!(t["status"], "converged", "{t}");
    assert!(t["fraction_on_surface"].as_f64().unwrap() > 0.2, "{t}");
    assert!(
        json["false_targets"].as_array().unwrap().is_empty(),
        "{json}"
    );

    // With the noisy state estimate every point is placed through a biased pose: the GPS random
    // walk (σ 0.5 m horizontal, 0.8 m vertical, 30 s correlation) is nearly constant over this
    // 5 s sequence and no filter can see it. The depth filter must add little to that bias.
    let out_est = dir.path().join("est");
    let json = localize(&seq, &out_est, "estimate", "klt");
    let t = rock_one(&json, &out_est);
    let error_m = t["centroid_error_m"].as_f64().unwrap();
    let bias_m = mean_pose_bias_m(&seq);
    assert!(
        error_m <= bias_m + 0.3,
        "estimated poses: centroid error {error_m} m, pose bias {bias_m} m"
    );
    // In the frame the vehicle flies in, the bias drops out: what is left is the filter's own.
    let in_estimate_frame = t["localization_error_estimate_frame_m"].as_f64().unwrap();
    assert!(
        in_estimate_frame <= 0.5 && in_estimate_frame < error_m.max(0.3),
        "estimate-frame error {in_estimate_frame} m, absolute {error_m} m"
    );
    assert!(
        json["false_targets"].as_array().unwrap().is_empty(),
        "{json}"
    );
}

/// Mean distance between the estimated and the true camera positions of a sequence, m.
fn mean_pose_bias_m(seq: &Path) -> f64 {
    let truth = scarp_export::tum::read_tum_trajectory(&seq.join("groundtruth.txt")).unwrap();
    let estimate = scarp_export::tum::read_tum_trajectory(&seq.join("estimate.txt")).unwrap();
    assert_eq!(truth.len(), estimate.len());
    let total: f64 = truth
        .iter()
        .zip(&estimate)
        .map(|(a, b)| {
            (a.world_from_camera.translation.vector - b.world_from_camera.translation.vector).norm()
        })
        .sum();
    total / truth.len() as f64
}

#[test]
fn missing_sequence_is_a_clear_error() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let out = scarp(&[
        "localize",
        path_str(&dir.path().join("nope")),
        "--out",
        path_str(&dir.path().join("out")),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("nope"), "{stderr}");
}

/// Issue 21's must-show: with its defaults (the mission's perception path, detector and
/// tracker settings), `scarp localize` on the default fine-localization circle of seed 6 gives
/// one target for rock 1 and no false one.
#[test]
fn the_default_fine_circle_gives_one_target() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let seq = dir.path().join("seq");
    scarp_ok(&[
        "render",
        "--path",
        "finecircle",
        "--frames",
        "300",
        "--seed",
        "6",
        "--out",
        path_str(&seq),
    ]);
    let out = dir.path().join("lz");
    let json = localize(&seq, &out, "estimate", "klt");
    rock_one(&json, &out);
    assert_eq!(json["targets"].as_array().unwrap().len(), 1, "{json}");
    assert_eq!(json["false_targets"].as_array().unwrap().len(), 0, "{json}");
}
