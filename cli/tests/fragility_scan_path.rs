//! The whole scan path of the fragility analysis, on rocks whose α_min is known from their exact
//! geometry: a flat-bottomed block and the same block leaning 12°, each on a pedestal narrower
//! than itself, are rendered from two rings (one just above the contact, one above the rock),
//! fused into a 1 cm TSDF, closed above their support and analysed (`scarp world`, `render`,
//! `map`, `fragility --scan`). The truth is the analysis of the world's own rock and pedestal
//! meshes.

mod common;
use common::scarp_stdout as scarp;
use nalgebra::{Point3, Vector3};
use scarp_export::tum::{StampedPose, write_tum_trajectory};
use scarp_slam::geometry::look_at;

/// A flat 16 m world with one block on a pedestal whose top (0.8 m up) is narrower than the
/// block; `tilt` adds a lean.
fn world_toml(tilt: &str) -> String {
    format!(
        r#"name = "scan-path"
[origin]
lat_deg = 33.0
lon_deg = -116.0
alt_m = 1000.0
[sun]
azimuth_deg = 200.0
elevation_deg = 45.0
ambient = 0.35
[texture]
seed = 3
[terrain.procedural]
seed = 1
size_m = 16.0
resolution_m = 0.25
scarp_height_m = 0.0
scarp_strike_deg = 0.0
scarp_width_m = 1.0
scarp_offset_m = 0.0
roughness_m = 0.02
roughness_wavelength_m = 8.0
[[rocks]]
id = 1
role = "target"
position_m = [0.0, 0.0]
height_m = 0.9
{tilt}
shape = {{ block = {{ seed = 1, size_m = [0.7, 0.5, 0.9], squareness = 12.0, roughness = 0.0, facets = 0, facet_depth = 0.1 }} }}
pedestal = {{ height_m = 0.8, base_radius_m = 0.5, top_radius_m = 0.25 }}
contact_radius_m = 0.12
"#
    )
}

/// Two rings of views at the rock on the origin: 30 just above the contact (1 m up, 1.8 m out),
/// 20 above the rock (2.2 m up, 2 m out).
fn rings() -> Vec<StampedPose> {
    let mut poses = Vec::new();
    for (height_m, radius_m, look_z_m, count) in [(1.0, 1.8, 0.85, 30), (2.2, 2.0, 1.2, 20)] {
        for k in 0..count {
            let a = std::f64::consts::TAU * f64::from(k) / f64::from(count);
            let eye = Point3::new(radius_m * a.cos(), radius_m * a.sin(), height_m);
            let world_from_camera =
                look_at(&eye, &Point3::new(0.0, 0.0, look_z_m), &Vector3::z()).unwrap();
            poses.push(StampedPose {
                timestamp_s: 0.1 * (poses.len() + 1) as f64,
                world_from_camera,
            });
        }
    }
    poses
}

/// (truth, scan estimate, interval low, interval high) of α_min, degrees.
fn scan_path(dir: &std::path::Path, tilt: &str) -> (f64, f64, f64, f64) {
    let p = |name: &str| dir.join(name).to_string_lossy().into_owned();
    std::fs::write(dir.join("world.toml"), world_toml(tilt)).unwrap();
    write_tum_trajectory(&dir.join("rings.txt"), &rings(), "scan path").unwrap();
    scarp(&["world", "--world", &p("world.toml"), "--out", &p("gt")]);
    let truth: serde_json::Value = serde_json::from_str(&scarp(&[
        "fragility",
        &p("gt/rock_1.ply"),
        "--pedestal",
        &p("gt/pedestal_1.ply"),
        "--json",
    ]))
    .unwrap();
    scarp(&[
        "render",
        "--world",
        &p("world.toml"),
        "--path",
        &p("rings.txt"),
        "--no-noise",
        "--out",
        &p("seq"),
    ]);
    scarp(&[
        "map",
        &p("seq"),
        "--poses",
        "groundtruth",
        "--voxel",
        "0.01",
        "--roi",
        "cyl:0,0,0.5,1.9,0.7",
        "--out",
        &p("map"),
    ]);
    let scan: serde_json::Value = serde_json::from_str(&scarp(&[
        "fragility",
        &p("map/mesh.ply"),
        "--scan",
        "--json",
    ]))
    .unwrap();
    assert_eq!(scan["alpha_interval"]["source"], "scan_contact");
    let f = |v: &serde_json::Value, key: &str| v[key].as_f64().unwrap();
    (
        f(&truth, "alpha_min_deg"),
        f(&scan, "alpha_min_deg"),
        f(&scan, "alpha_min_low_deg"),
        f(&scan, "alpha_min_high_deg"),
    )
}

#[test]
fn a_block_on_a_narrow_pedestal_through_render_map_close_analyse() {
    let dir = tempfile::tempdir().unwrap();
    let (truth, estimate, low, high) = scan_path(dir.path(), "");
    // The flat base rests on its flat contact: the block's half depth over its centre of
    // mass's height, shortened by the rounded edges of a squareness-12 block.
    assert!((20.0..26.0).contains(&truth), "truth {truth}");
    assert!((estimate - truth).abs() < 2.0, "{estimate} vs {truth}");
    assert!(
        low <= truth && truth <= high,
        "{truth} outside [{low}, {high}]"
    );
}

#[test]
fn a_leaning_parallelepiped_through_render_map_close_analyse() {
    let dir = tempfile::tempdir().unwrap();
    let (truth, estimate, low, high) =
        scan_path(dir.path(), "tilt_deg = 12.0\ntilt_azimuth_deg = 90.0");
    // Leaning 12° towards its tipping side leaves it less than its upright 23°.
    assert!((8.0..18.0).contains(&truth), "truth {truth}");
    // Measured +3.4°: the leaning face's wedge is filled wider than the contact (see issue
    // #18's note); the interval must hold the truth all the same.
    assert!((estimate - truth).abs() < 5.0, "{estimate} vs {truth}");
    assert!(
        low <= truth && truth <= high,
        "{truth} outside [{low}, {high}]"
    );
}
