//! Sequence round trips and bad-input handling.

use std::path::Path;

use scarp_datasets::paths;
use scarp_datasets::sequence::{RenderSettings, Sequence, write_sequence};
use scarp_datasets::world::World;
use scarp_datasets::{estimator::EstimatorConfig, sensor::SensorConfig};
use scarp_slam::PinholeCamera;

/// A fresh temporary directory, removed when dropped.
fn temp_dir() -> tempfile::TempDir {
    tempfile::tempdir().expect("a temporary directory")
}

fn small_world() -> World {
    World::from_toml_str(
        r#"
        [terrain.procedural]
        size_m = 30.0
        resolution_m = 0.5
        [[rocks]]
        id = 4
        role = "target"
        position_m = [0.0, 0.0]
        height_m = 1.2
        shape = { boulder = { seed = 3, subdivisions = 4 } }
        pedestal = { height_m = 0.8, top_radius_m = 0.3 }
        contact_radius_m = 0.12
        "#,
        Path::new("small.toml"),
        Path::new("."),
    )
    .unwrap()
}

fn settings(noise: bool) -> RenderSettings {
    RenderSettings {
        camera: PinholeCamera::from_hfov(160, 120, 80.0).unwrap(),
        noise,
        sensor: SensorConfig::default(),
        estimator: EstimatorConfig::default(),
        seed: 5,
        depth_scale: 5000.0,
    }
}

#[test]
fn sequence_round_trip_is_exact() {
    let dir = temp_dir();
    let world = small_world();
    let poses = paths::default_orbit(&world, 6).unwrap();
    let settings = settings(false);
    let summary = write_sequence(dir.path(), &world, &poses, &settings, &|| {}).unwrap();
    assert_eq!(summary.frames, 6);
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.len(), 6);
    assert_eq!(seq.camera, settings.camera);
    assert!(seq.boxes.iter().any(|b| b.id == 4));
    let renderer = scarp_datasets::render::Renderer::new(&world);
    for (i, (entry, pose)) in seq.entries.iter().zip(&poses).enumerate() {
        let truth = entry.world_from_camera_truth.unwrap();
        assert!(
            (truth.translation.vector - pose.world_from_camera.translation.vector).norm() <= 1e-9
        );
        assert!(truth.rotation.angle_to(&pose.world_from_camera.rotation) <= 1e-9);
        assert_eq!(
            entry.world_from_camera_estimate,
            entry.world_from_camera_truth
        );
        let frame = seq.load_frame(i).unwrap();
        let clean = renderer
            .render(&settings.camera, &pose.world_from_camera)
            .unwrap();
        assert_eq!(frame.rgb, clean.rgb);
        assert_eq!(frame.instance_mask.as_ref().unwrap(), &clean.instance);
        for (&read, &rendered) in frame
            .depth_m
            .as_slice()
            .iter()
            .zip(clean.depth_m.as_slice())
        {
            if rendered > 0.0 && rendered < 13.0 {
                assert!(
                    (read - rendered).abs() <= 0.5 / 5000.0 + 1e-6,
                    "{read} vs {rendered}"
                );
            }
        }
    }
}

#[test]
fn noisy_sequences_are_deterministic() {
    let (a, b) = (temp_dir(), temp_dir());
    let world = small_world();
    let poses = paths::default_orbit(&world, 3).unwrap();
    write_sequence(a.path(), &world, &poses, &settings(true), &|| {}).unwrap();
    write_sequence(b.path(), &world, &poses, &settings(true), &|| {}).unwrap();
    for file in [
        "estimate.txt",
        "boxes.txt",
        "depth/0.050000.png",
        "rgb/0.100000.png",
    ] {
        assert_eq!(
            std::fs::read(a.path().join(file)).unwrap(),
            std::fs::read(b.path().join(file)).unwrap(),
            "{file}"
        );
    }
    let seq = Sequence::open(a.path()).unwrap();
    let estimate = seq.entries[0].world_from_camera_estimate.unwrap();
    let truth = seq.entries[0].world_from_camera_truth.unwrap();
    assert!((estimate.translation.vector - truth.translation.vector).norm() > 1e-3);
    // camera.toml states the sensor's depth noise, σ at 1 m, for the TSDF's allocation.
    let s = settings(true);
    let sigma = s.sensor.depth_sigma_m(1.0, s.camera.fx);
    assert!(sigma > 0.0);
    assert_eq!(seq.camera_file.depth_sigma_at_1m_m, Some(sigma));
    let c = temp_dir();
    write_sequence(c.path(), &world, &poses, &settings(false), &|| {}).unwrap();
    let clean = Sequence::open(c.path()).unwrap();
    assert_eq!(clean.camera_file.depth_sigma_at_1m_m, Some(0.0));
}

fn expect_error(
    result: Result<impl std::fmt::Debug, scarp_datasets::DatasetError>,
    needles: &[&str],
) {
    let message = result.expect_err("expected an error").to_string();
    for needle in needles {
        assert!(
            message.contains(needle),
            "`{message}` should mention `{needle}`"
        );
    }
}

#[test]
fn bad_input_gives_errors_that_name_the_culprit() {
    let dir = temp_dir();
    let world = small_world();
    let poses = paths::default_orbit(&world, 2).unwrap();
    write_sequence(dir.path(), &world, &poses, &settings(false), &|| {}).unwrap();

    // A missing file.
    expect_error(
        Sequence::open(&dir.path().join("nowhere")),
        &["nowhere", "camera.toml"],
    );
    // A corrupt PNG.
    let seq = Sequence::open(dir.path()).unwrap();
    std::fs::write(&seq.entries[1].rgb_path, b"\x89PNG\r\n\x1a\nnot really").unwrap();
    expect_error(seq.load_frame(1), &["0.050000.png"]);
    // A depth PNG of the wrong kind (8-bit colour).
    std::fs::copy(&seq.entries[0].rgb_path, &seq.entries[0].depth_path).unwrap();
    expect_error(seq.load_frame(0), &["depth", "16-bit"]);
    // Timestamps out of order.
    std::fs::write(
        dir.path().join("depth.txt"),
        "0.05 depth/0.050000.png\n0.0 depth/0.000000.png\n",
    )
    .unwrap();
    expect_error(Sequence::open(dir.path()), &["depth.txt:2", "not after"]);
    std::fs::write(
        dir.path().join("groundtruth.txt"),
        "0 0 0 0 0 0 0 1\n0 1 0 0 0 0 0 1\n",
    )
    .unwrap();
    std::fs::write(dir.path().join("depth.txt"), "0.0 depth/0.000000.png\n").unwrap();
    expect_error(Sequence::open(dir.path()), &["groundtruth.txt:2"]);
    // An unknown key in camera.toml and in a world file.
    std::fs::write(dir.path().join("camera.toml"), "fx = 1.0\nfy = 1.0\ncx = 0.0\ncy = 0.0\nwidth = 2\nheight = 2\ndepth_scale = 5000.0\nfocal = 3\n").unwrap();
    expect_error(Sequence::open(dir.path()), &["camera.toml", "focal"]);
    expect_error(
        World::from_toml_str(
            "[terrain.procedural]\nsize_m = 10.0\nroughnes_m = 1.0\n",
            Path::new("w.toml"),
            Path::new("."),
        ),
        &["w.toml", "roughnes_m", "line 3"],
    );
    // A truncated PLY rock mesh.
    let full = scarp_datasets::world::DOUBLE_ROCK_PLY;
    std::fs::write(dir.path().join("rock.ply"), &full[..full.len() / 2]).unwrap();
    let world_text = "[terrain.procedural]\nsize_m = 10.0\n[[rocks]]\nid = 1\nrole = \"target\"\nposition_m = [0.0, 0.0]\nheight_m = 1.0\nshape = { mesh = \"rock.ply\" }\n";
    expect_error(
        World::from_toml_str(world_text, Path::new("w.toml"), dir.path()),
        &["rock.ply"],
    );
    // A missing rock mesh, and a missing world file.
    std::fs::remove_file(dir.path().join("rock.ply")).unwrap();
    expect_error(
        World::from_toml_str(world_text, Path::new("w.toml"), dir.path()),
        &["rock.ply"],
    );
    expect_error(
        World::load(&dir.path().join("absent.toml")),
        &["absent.toml"],
    );
    // A rock outside the terrain names its key.
    expect_error(
        World::from_toml_str(
            &world_text
                .replace("[0.0, 0.0]", "[90.0, 0.0]")
                .replace("rock.ply", "builtin:double_rock"),
            Path::new("w.toml"),
            dir.path(),
        ),
        &["rocks[0].position_m"],
    );
}

#[test]
fn real_tum_style_sequences_load() {
    let dir = temp_dir();
    let world = small_world();
    let poses = paths::default_orbit(&world, 3).unwrap();
    write_sequence(dir.path(), &world, &poses, &settings(false), &|| {}).unwrap();
    // A real sequence has no estimate, boxes or masks, depth stamped apart from colour, a
    // denser ground truth, and sometimes a negative fy.
    for extra in ["estimate.txt", "boxes.txt"] {
        std::fs::remove_file(dir.path().join(extra)).unwrap();
    }
    std::fs::remove_dir_all(dir.path().join("mask")).unwrap();
    let camera = std::fs::read_to_string(dir.path().join("camera.toml")).unwrap();
    let fy_line = camera
        .lines()
        .find(|l| l.starts_with("fy"))
        .unwrap()
        .to_string();
    std::fs::write(
        dir.path().join("camera.toml"),
        camera.replace(&fy_line, &fy_line.replace("= ", "= -")),
    )
    .unwrap();
    std::fs::write(
        dir.path().join("depth.txt"),
        "0.012 depth/0.000000.png\n0.065 depth/0.050000.png\n0.1001 depth/0.100000.png\n",
    )
    .unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert!(seq.camera.fy < 0.0);
    // 0.065 is 0.015 s from 0.05 (kept); the first pair is 0.012 s apart (kept).
    assert_eq!(seq.len(), 3);
    assert!(
        seq.entries
            .iter()
            .all(|e| e.mask_path.is_none() && e.world_from_camera_estimate.is_none())
    );
    assert!(seq.boxes.is_empty());
    assert!(seq.load_frame(1).unwrap().instance_mask.is_none());
    // Depth more than 0.02 s away is not associated.
    std::fs::write(
        dir.path().join("depth.txt"),
        "0.028 depth/0.000000.png\n0.076 depth/0.050000.png\n0.1001 depth/0.100000.png\n",
    )
    .unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(
        seq.entries
            .iter()
            .map(|e| e.timestamp_s)
            .collect::<Vec<_>>(),
        vec![0.1]
    );
}

/// A sequence whose `camera.toml` has a `[distortion]` table loads as the pinhole camera's
/// images. The files hold what a distorted lens records of a known field (the depth ramps along
/// the ideal column, the colour encodes the ideal pixel); loaded, every pixel must carry its own
/// pinhole pixel's values. The same files read as a pinhole are off by pixels at the border.
#[test]
fn a_distorted_sequence_loads_as_its_pinhole_images() {
    use scarp_datasets::sequence::{CameraFile, write_depth_png, write_image_lists, write_rgb_png};
    use scarp_slam::image::{DepthImage, LensDistortion, RgbImage};

    let dir = temp_dir();
    let camera = PinholeCamera::new(120.0, 120.0, 79.5, 59.5, 160, 120).unwrap();
    let lens = LensDistortion {
        k1: 0.25,
        k2: -0.1,
        p1: 0.002,
        p2: -0.001,
        k3: 0.0,
    };
    let depth_at = |ideal_u: f64| 2.0 + 0.005 * ideal_u;
    let (mut depth, mut rgb) = (Vec::new(), Vec::new());
    for v in 0..camera.height {
        for u in 0..camera.width {
            // The ideal point the lens images at (u, v).
            let (x, y) = lens.undistort(
                (f64::from(u) - camera.cx) / camera.fx,
                (f64::from(v) - camera.cy) / camera.fy,
            );
            let (ideal_u, ideal_v) = (camera.fx * x + camera.cx, camera.fy * y + camera.cy);
            depth.push(depth_at(ideal_u) as f32);
            rgb.push([ideal_u.round() as u8, ideal_v.round() as u8, 0]);
        }
    }
    std::fs::create_dir_all(dir.path().join("rgb")).unwrap();
    std::fs::create_dir_all(dir.path().join("depth")).unwrap();
    let name = scarp_datasets::sequence::frame_name(0.0);
    let depth = DepthImage::from_vec(160, 120, depth).unwrap();
    write_depth_png(&dir.path().join("depth").join(&name), &depth, 5000.0).unwrap();
    let rgb = RgbImage::from_vec(160, 120, rgb).unwrap();
    write_rgb_png(&dir.path().join("rgb").join(&name), &rgb).unwrap();
    write_image_lists(dir.path(), &[0.0]).unwrap();
    let mut file = CameraFile::new(&camera, 5000.0);

    // Worst depth error (in pixels of the ramp) and colour error over the loaded frame.
    let worst = |file: &CameraFile| {
        file.write(&dir.path().join("camera.toml")).unwrap();
        let frame = Sequence::open(dir.path()).unwrap().load_frame(0).unwrap();
        let (mut depth_px, mut color_px, mut kept) = (0.0f64, 0.0f64, 0);
        for v in 0..120 {
            for u in 0..160 {
                let z = f64::from(*frame.depth_m.get(u, v).unwrap());
                if z == 0.0 {
                    continue;
                }
                kept += 1;
                depth_px = depth_px.max((z - depth_at(f64::from(u))).abs() / 0.005);
                let c = frame.rgb.get(u, v).unwrap();
                color_px = color_px
                    .max((f64::from(c[0]) - f64::from(u)).abs())
                    .max((f64::from(c[1]) - f64::from(v)).abs());
            }
        }
        (depth_px, color_px, kept)
    };
    let (pinhole_depth_px, pinhole_color_px, _) = worst(&file);
    assert!(
        pinhole_depth_px > 5.0 && pinhole_color_px > 5.0,
        "read as a pinhole, the border is off by {pinhole_depth_px:.1} / {pinhole_color_px:.1} px"
    );
    file.distortion = Some(lens);
    let (depth_px, color_px, kept) = worst(&file);
    assert!(
        kept > 15_000,
        "{kept} of 19200 pixels kept after undistortion"
    );
    // Nearest-neighbour depth lands within a pixel; bilinear colour within a pixel and rounding.
    assert!(depth_px <= 1.0, "depth off by {depth_px:.2} px");
    assert!(color_px <= 1.5, "colour off by {color_px:.2} px");
    // The table round-trips through camera.toml.
    let read = CameraFile::read(&dir.path().join("camera.toml")).unwrap();
    assert_eq!(read.distortion, Some(lens));
}
