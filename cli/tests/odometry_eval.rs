//! End-to-end tests of `scarp eval traj` (hand-computed values, alignment with a known rotation
//! and scale) and `scarp odometry` (a short noisy orbit tracked to ≤ 1 cm ATE, ≥ 10× better than
//! the state estimate).

use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};
use scarp_export::tum::{StampedPose, write_tum_trajectory};

struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("scarp-odo-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn scarp(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_scarp"))
        .args(args)
        .output()
        .expect("the scarp binary runs");
    assert!(
        out.status.success(),
        "scarp {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn pose(t: f64, x: f64, y: f64, z: f64, yaw: f64) -> StampedPose {
    StampedPose {
        timestamp_s: t,
        world_from_camera: Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        ),
    }
}

fn close(json: &serde_json::Value, key: &str, expected: f64) {
    let v = json[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} missing in {json}"));
    assert!(
        (v - expected).abs() < 1e-6,
        "{key} = {v}, expected {expected}"
    );
}

#[test]
fn eval_traj_matches_hand_computed_values() {
    let dir = TempDir::new("eval");
    let (gt_path, est_path) = (dir.0.join("gt.txt"), dir.0.join("est.txt"));
    // Truth: 0, 1, 2, 3 m along x, no rotation. The estimate (stamped 10 ms later) is off by
    // 0, +0.1, 0, −0.2 m in y.
    let gt: Vec<_> = (0..4)
        .map(|i| pose(i as f64, i as f64, 0.0, 0.0, 0.0))
        .collect();
    let dy = [0.0, 0.1, 0.0, -0.2];
    let est: Vec<_> = (0..4)
        .map(|i| pose(i as f64 + 0.01, i as f64, dy[i], 0.0, 0.0))
        .collect();
    write_tum_trajectory(&gt_path, &gt, "gt").unwrap();
    write_tum_trajectory(&est_path, &est, "est").unwrap();
    let json = scarp(&[
        "eval",
        "traj",
        "--gt",
        s(&gt_path),
        "--est",
        s(&est_path),
        "--align",
        "none",
        "--json",
    ]);
    // ATE: errors 0, 0.1, 0, 0.2.
    close(&json, "ate_rmse_m", (0.05f64 / 4.0).sqrt());
    close(&json, "ate_mean_m", 0.075);
    close(&json, "ate_median_m", 0.05);
    close(&json, "ate_max_m", 0.2);
    // RPE between consecutive frames: 0.1, 0.1, 0.2 m; each pair is 1 m and 1 s apart.
    let rpe = ((0.01 + 0.01 + 0.04) / 3.0f64).sqrt();
    close(&json, "rpe_trans_m_per_frame", rpe);
    close(&json, "rpe_trans_per_m", rpe);
    close(&json, "rpe_rot_deg_per_frame", 0.0);
    assert_eq!(json["pairs"], 4);

    // With SE(3) alignment: offsets +0.1, −0.1, −0.1, +0.1 have zero mean and no correlation
    // with x, so no shift or turn reduces them (turns about the x axis, which the collinear truth
    // leaves free, keep each distance): every error stays 0.1 m.
    let dy = [0.1, -0.1, -0.1, 0.1];
    let est: Vec<_> = (0..4)
        .map(|i| pose(i as f64 - 0.015, i as f64, dy[i], 0.0, 0.0))
        .collect();
    write_tum_trajectory(&est_path, &est, "est").unwrap();
    let json = scarp(&[
        "eval",
        "traj",
        "--gt",
        s(&gt_path),
        "--est",
        s(&est_path),
        "--align",
        "se3",
        "--json",
    ]);
    close(&json, "ate_rmse_m", 0.1);
    close(&json, "ate_mean_m", 0.1);
    close(&json, "ate_median_m", 0.1);
    close(&json, "ate_max_m", 0.1);
    close(&json, "scale", 1.0);
}

#[test]
fn eval_traj_sim3_undoes_a_known_rotation_and_scale() {
    let dir = TempDir::new("sim3");
    let (gt_path, est_path) = (dir.0.join("gt.txt"), dir.0.join("est.txt"));
    let gt: Vec<_> = (0..30)
        .map(|i| {
            let a = i as f64 * 0.2;
            pose(
                i as f64 * 0.05,
                3.0 * a.cos(),
                3.0 * a.sin(),
                0.1 * i as f64,
                a,
            )
        })
        .collect();
    // The estimate lives in a frame rotated by 30° about z and 10° about x, scaled by 0.5,
    // shifted by (1, 2, 3).
    let rotation = Rotation3::from_euler_angles(10f64.to_radians(), 0.0, 30f64.to_radians());
    let q = UnitQuaternion::from_rotation_matrix(&rotation);
    let est: Vec<_> = gt
        .iter()
        .map(|p| StampedPose {
            timestamp_s: p.timestamp_s,
            world_from_camera: Isometry3::from_parts(
                Translation3::from(
                    0.5 * (rotation * p.world_from_camera.translation.vector)
                        + Vector3::new(1.0, 2.0, 3.0),
                ),
                q * p.world_from_camera.rotation,
            ),
        })
        .collect();
    write_tum_trajectory(&gt_path, &gt, "gt").unwrap();
    write_tum_trajectory(&est_path, &est, "est").unwrap();
    let sim3 = scarp(&[
        "eval",
        "traj",
        "--gt",
        s(&gt_path),
        "--est",
        s(&est_path),
        "--align",
        "sim3",
        "--json",
    ]);
    close(&sim3, "ate_rmse_m", 0.0);
    close(&sim3, "scale", 2.0);
    close(&sim3, "rpe_trans_m_per_frame", 0.0);
    close(&sim3, "rpe_rot_deg_per_frame", 0.0);
    assert_eq!(sim3["pairs"], 30);
    // SE(3) alignment cannot undo the scale.
    let se3 = scarp(&[
        "eval",
        "traj",
        "--gt",
        s(&gt_path),
        "--est",
        s(&est_path),
        "--align",
        "se3",
        "--json",
    ]);
    assert!(se3["ate_rmse_m"].as_f64().unwrap() > 0.5, "{se3}");
}

#[test]
fn odometry_tracks_a_short_noisy_orbit_to_a_centimetre() {
    let dir = TempDir::new("orbit");
    // The first 40 frames (40°, about 2.8 m of path) of the default 360-frame orbit, rendered
    // with the default sensor and state-estimator noise.
    let world = scarp_datasets::world::World::builtin_default().unwrap();
    let orbit = scarp_datasets::paths::default_orbit(&world, 360).unwrap();
    let path = dir.0.join("path.txt");
    write_tum_trajectory(&path, &orbit[..40], "first 40 frames of the default orbit").unwrap();
    let seq = dir.0.join("seq");
    scarp(&["render", "--path", s(&path), "--out", s(&seq), "--json"]);
    let out = dir.0.join("odo");
    let summary = scarp(&["odometry", s(&seq), "--out", s(&out), "--json"]);
    assert_eq!(summary["frames"], 40);
    assert_eq!(summary["odometry_failures"], 0, "{summary}");
    assert!(summary["odometry_ms_median"].as_f64().unwrap() > 0.0);
    let saved: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("odometry.json")).unwrap()).unwrap();
    assert_eq!(saved["odometry_failures"], summary["odometry_failures"]);

    let odometry = scarp(&[
        "eval",
        "traj",
        "--gt",
        s(&seq.join("groundtruth.txt")),
        "--est",
        s(&out.join("trajectory.txt")),
        "--json",
    ]);
    let estimate = scarp(&[
        "eval",
        "traj",
        "--gt",
        s(&seq.join("groundtruth.txt")),
        "--est",
        s(&seq.join("estimate.txt")),
        "--json",
    ]);
    let ate_odometry = odometry["ate_rmse_m"].as_f64().unwrap();
    let ate_estimate = estimate["ate_rmse_m"].as_f64().unwrap();
    assert_eq!(odometry["pairs"], 40);
    assert!(ate_odometry <= 0.01, "odometry ATE {ate_odometry} m");
    assert!(
        ate_odometry * 10.0 <= ate_estimate,
        "odometry {ate_odometry} m vs estimate {ate_estimate} m"
    );
}

#[test]
fn eval_traj_reports_bad_input() {
    let dir = TempDir::new("bad");
    let gt_path = dir.0.join("gt.txt");
    std::fs::write(&gt_path, "0 0 0 0 0 0 0 1\n1 nan 0 0 0 0 0 1\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_scarp"))
        .args([
            "eval",
            "traj",
            "--gt",
            s(&gt_path),
            "--est",
            s(&gt_path),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("gt.txt"));
}
