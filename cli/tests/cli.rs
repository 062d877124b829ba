//! End-to-end tests of the `scarp` binary: world ground truth, sequence rendering, bundle
//! adjustment of a BAL problem, bad input.

mod common;
use common::{path_str, read_json, scarp, scarp_ok};

use std::path::Path;

/// A fresh temporary directory, removed when dropped.
fn temp_dir() -> tempfile::TempDir {
    tempfile::tempdir().expect("a temporary directory")
}

#[test]
fn world_writes_ground_truth_meshes_and_world_json() {
    let dir = temp_dir();
    let out = scarp_ok(&[
        "world",
        "--world",
        "default",
        "--out",
        path_str(dir.path()),
        "--json",
    ]);
    let json: serde_json::Value = read_json(&dir.path().join("world.json"));
    let rocks = json["rocks"].as_array().unwrap();
    assert_eq!(rocks.iter().filter(|r| r["role"] == "target").count(), 3);
    assert!(rocks.iter().filter(|r| r["role"] == "distractor").count() >= 10);
    for rock in rocks {
        assert_eq!(rock["centroid"].as_array().unwrap().len(), 3);
        assert!(rock["height_m"].as_f64().unwrap() > 0.3);
        let mesh =
            scarp_export::ply::read_mesh(dir.path().join(rock["mesh"].as_str().unwrap())).unwrap();
        assert!(mesh.face_count() > 1000);
    }
    assert!(
        rocks
            .iter()
            .filter(|r| r["role"] == "target")
            .all(|r| r["contact"]["area_m2"].as_f64().unwrap() > 0.0)
    );
    assert!(dir.path().join("terrain.ply").exists());
    // The printed JSON is the file's content.
    let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(printed, json);
}

#[test]
fn render_writes_a_tum_sequence_that_loads() {
    let dir = temp_dir();
    let seq = dir.path().join("seq");
    let out = scarp_ok(&[
        "render",
        "--path",
        "orbit",
        "--frames",
        "4",
        "--out",
        path_str(&seq),
        "--seed",
        "3",
        "--json",
    ]);
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["frames"], 4);
    for file in [
        "rgb.txt",
        "depth.txt",
        "groundtruth.txt",
        "estimate.txt",
        "camera.toml",
        "boxes.txt",
    ] {
        assert!(seq.join(file).exists(), "{file}");
    }
    let sequence = scarp_datasets::sequence::Sequence::open(&seq).unwrap();
    assert_eq!(sequence.len(), 4);
    assert_eq!(sequence.camera_file.depth_scale, 5000.0);
    // The orbit looks at target 1, which is in every frame's boxes.
    let frames_with_target = sequence.boxes.iter().filter(|b| b.id == 1).count();
    assert_eq!(frames_with_target, 4);
    let frame = sequence.load_frame(2).unwrap();
    assert!(frame.valid_depth_count() > 100_000);
    assert!(frame.instance_mask.is_some());
}

/// `render --config` takes the mission config's `[estimator]`: with every error at zero the
/// estimate is the truth, while the default GPS estimate is decimetres off; a misspelt key is
/// refused, naming it.
#[test]
fn render_takes_the_estimator_of_a_mission_config() {
    let dir = temp_dir();
    let exact = dir.path().join("exact.toml");
    std::fs::write(
        &exact,
        "[estimator]\nhorizontal_sigma_m = 0.0\nvertical_sigma_m = 0.0\n\
         horizontal_white_m = 0.0\nvertical_white_m = 0.0\n\
         roll_pitch_sigma_deg = 0.0\nyaw_sigma_deg = 0.0\n",
    )
    .unwrap();
    let worst_estimate_error_m = |config: Option<&Path>| {
        let seq = dir.path().join("seq");
        let _ = std::fs::remove_dir_all(&seq);
        let mut args = vec![
            "render",
            "--frames",
            "3",
            "--seed",
            "5",
            "--out",
            path_str(&seq),
        ];
        if let Some(c) = config {
            args.extend(["--config", path_str(c)]);
        }
        scarp_ok(&args);
        let sequence = scarp_datasets::sequence::Sequence::open(&seq).unwrap();
        sequence
            .entries
            .iter()
            .map(|e| {
                let truth = e.world_from_camera_truth.unwrap().translation.vector;
                let estimate = e.world_from_camera_estimate.unwrap().translation.vector;
                (estimate - truth).norm()
            })
            .fold(0.0, f64::max)
    };
    let exact_m = worst_estimate_error_m(Some(&exact));
    assert!(exact_m < 1e-6, "exact estimator off by {exact_m} m");
    let gps_m = worst_estimate_error_m(None);
    assert!(gps_m > 0.05, "GPS estimator off by only {gps_m} m");

    let typo = dir.path().join("typo.toml");
    std::fs::write(&typo, "[estimator]\nyaw_sigma_degs = 0.0\n").unwrap();
    let out = scarp(&[
        "render",
        "--config",
        path_str(&typo),
        "--out",
        path_str(&dir.path().join("t")),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("yaw_sigma_degs"), "{stderr}");
}

#[test]
fn bad_input_fails_with_a_message_naming_the_culprit() {
    let dir = temp_dir();
    let world = dir.path().join("w.toml");
    std::fs::write(&world, "[terrain.procedural]\nsize_m = 20.0\nsize = 3\n").unwrap();
    let out = scarp(&[
        "world",
        "--world",
        path_str(&world),
        "--out",
        path_str(&dir.path().join("o")),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("w.toml") && stderr.contains("size"),
        "{stderr}"
    );

    let out = scarp(&[
        "render",
        "--world",
        path_str(&dir.path().join("missing.toml")),
        "--out",
        path_str(&dir.path().join("s")),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.toml"));

    let path_file = dir.path().join("path.txt");
    std::fs::write(&path_file, "0 0 0 5 0 0 0 1\n0 1 0 5 0 0 0 1\n").unwrap();
    let out = scarp(&[
        "render",
        "--path",
        path_str(&path_file),
        "--out",
        path_str(&dir.path().join("s")),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("path.txt:2"));
}

#[test]
fn plan_flies_the_mapping_rings_of_a_target() {
    let dir = temp_dir();
    scarp_ok(&[
        "plan",
        "--target",
        "2",
        "--out",
        path_str(dir.path()),
        "--json",
    ]);
    let flight: serde_json::Value = read_json(&dir.path().join("flight.json"));
    for key in [
        "position_rms_m",
        "position_max_m",
        "yaw_max_deg",
        "speed_max_mps",
        "accel_max_mps2",
        "min_clearance_m",
        "duration_s",
    ] {
        assert!(flight[key].is_number(), "{key}");
    }
    assert!(flight["position_rms_m"].as_f64().unwrap() <= 0.10);
    assert!(flight["position_max_m"].as_f64().unwrap() <= 0.30);
    assert!(flight["yaw_max_deg"].as_f64().unwrap() <= 5.0);
    assert!(flight["speed_max_mps"].as_f64().unwrap() <= 1.0 + 1e-6);
    assert!(flight["min_clearance_m"].as_f64().unwrap() >= 1.5);
    for file in [
        "rings.csv",
        "waypoints.csv",
        "trajectory.csv",
        "trajectory.txt",
        "camera_trajectory.txt",
        "top.png",
        "side.png",
    ] {
        assert!(dir.path().join(file).exists(), "{file}");
    }
    let body = scarp_export::tum::read_tum_trajectory(&dir.path().join("trajectory.txt")).unwrap();
    assert!(!body.is_empty());
    // The camera flies with the body, at the mission's 20 Hz mapping rate, its optical axis
    // pitched below the horizon (never above it on these rings), yawed as the body.
    let camera =
        scarp_export::tum::read_tum_trajectory(&dir.path().join("camera_trajectory.txt")).unwrap();
    let duration_s = flight["trajectory_duration_s"].as_f64().unwrap();
    // One pose every 0.05 s from 0 to the end, the end included.
    let expected = duration_s * 20.0 + 1.0;
    assert!(
        (camera.len() as f64 - expected).abs() <= 1.0,
        "{} poses over {duration_s} s",
        camera.len()
    );
    for pose in camera.iter().step_by(97) {
        let t = pose.world_from_camera.translation.vector;
        let b = body
            .iter()
            .min_by(|a, b| {
                (a.timestamp_s - pose.timestamp_s)
                    .abs()
                    .total_cmp(&(b.timestamp_s - pose.timestamp_s).abs())
            })
            .unwrap();
        assert!((b.timestamp_s - pose.timestamp_s).abs() < 0.03);
        assert!((b.world_from_camera.translation.vector - t).norm() < 0.05);
        let forward = pose.world_from_camera.rotation * nalgebra::Vector3::z();
        assert!(forward.z < 0.0, "the camera looks down: {forward:?}");
        let body_forward = b.world_from_camera.rotation * nalgebra::Vector3::x();
        assert!(forward.xy().dot(&body_forward.xy()) > 0.0);
    }
    let cylinder = &flight["cylinder"];
    // Rock 2's cylinder runs from 0.2 m under the ground to above the rock.
    assert!(cylinder["z_bottom_m"].as_f64().unwrap() < cylinder["z_top_m"].as_f64().unwrap());

    for (target, needle) in [
        ("999", "no rock 999"),
        ("0,0,-100", "terrain"),
        ("1,2", "x,y,z"),
    ] {
        let out = scarp(&[
            "plan",
            "--target",
            target,
            "--out",
            path_str(&dir.path().join("bad")),
        ]);
        assert!(!out.status.success(), "{target}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(needle), "{target}: {stderr}");
    }
}

#[test]
fn ba_solves_the_shrunk_bal_problem_and_prints_json() {
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../slam/tests/data/bal-ladybug-problem-49-7776-pre-shrink-1800.txt");
    let out = scarp_ok(&["ba", path_str(&file), "--threads", "2", "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["cameras"], 49);
    assert_eq!(json["points"], 1800);
    assert_eq!(json["observations"], 10863);
    let initial = json["initial_cost"].as_f64().unwrap();
    let final_cost = json["final_cost"].as_f64().unwrap();
    assert!((initial - 234519.80).abs() < 0.01, "{initial}");
    assert!((final_cost - 3001.362).abs() < 3.0, "{final_cost}");
    let costs = json["costs"].as_array().unwrap();
    let iterations = json["iterations"].as_u64().unwrap() as usize;
    assert_eq!(costs.len(), iterations + 1);
    assert_eq!(costs.last().unwrap().as_f64().unwrap(), final_cost);
    assert!(json["seconds"].as_f64().unwrap() > 0.0);
}

#[test]
fn ba_rejects_a_malformed_file_naming_the_line() {
    let dir = temp_dir();
    let file = dir.path().join("bad.txt");
    std::fs::write(&file, "1 1 1\n0 0 nan 1\n0 0 0 0 0 -5 500 0 0\n0 0 1\n").unwrap();
    let out = scarp(&["ba", path_str(&file), "--json"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("bad.txt:2") && stderr.contains("not finite"),
        "{stderr}"
    );
}
