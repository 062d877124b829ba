//! How much a saved scan's α_min depends on the frame it is analysed in: rotates the mesh about
//! its bounding box's centre by small yaws and tilts (about x and y) and prints, for each, α_min,
//! its interval, the neck, and the support plane or half-turn support the analysis read.
//!
//! The mission analyses each mesh in its map frame, which differs from the world by the state
//! estimator's attitude error (a fraction of a degree to about a degree). A reading that jumps
//! under such rotations is not a property of the rock.
//!
//! ```text
//! cargo run --release --example frame_probe -- MESH.ply [FRAGILITY_TOML]
//! ```

use std::path::Path;

use anyhow::{Context, Result};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use scarp::fragility::FragilityConfig;
use scarp::fragility::scan::analyze_scan;
use scarp_export::ply::read_mesh;

/// Rotations tried about each axis, degrees.
const ANGLES_DEG: [f64; 7] = [-1.0, -0.5, -0.25, 0.0, 0.25, 0.5, 1.0];

/// Heights to the millimetre, for printing.
fn mm(height_m: Option<f64>) -> String {
    height_m.map_or_else(|| "-".to_string(), |z| format!("{z:.3}"))
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .context("usage: frame_probe MESH.ply [FRAGILITY_TOML]")?;
    let mesh = read_mesh(Path::new(path))?;
    let config: FragilityConfig = match args.get(1) {
        Some(toml_path) => {
            let text = std::fs::read_to_string(toml_path)
                .with_context(|| format!("reading {toml_path}"))?;
            toml::from_str(&text).with_context(|| format!("parsing {toml_path}"))?
        }
        None => FragilityConfig::default(),
    };
    let (lo, hi) = mesh.bounds().context("the mesh is empty")?;
    let centre = (lo.coords.cast::<f64>() + hi.coords.cast::<f64>()) / 2.0;
    println!("rotation | alpha_min_deg [low, high] | neck_m plane_m partial_support_m");
    for (name, axis) in [
        ("yaw", Vector3::z()),
        ("tilt-x", Vector3::x()),
        ("tilt-y", Vector3::y()),
    ] {
        for deg in ANGLES_DEG {
            let rotation =
                UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), deg.to_radians());
            let about_centre = Isometry3::from_parts(Translation3::from(centre), rotation)
                * Isometry3::translation(-centre.x, -centre.y, -centre.z);
            let mut rotated = mesh.clone();
            rotated.transform(&about_centre);
            match analyze_scan(&rotated, &config) {
                Ok((closed, analysis)) => println!(
                    "{name} {deg:+.2} | {:.2} [{:.2}, {:.2}] | {:.3} {} {}",
                    analysis.report.alpha_min_deg,
                    analysis.report.alpha_min_low_deg,
                    analysis.report.alpha_min_high_deg,
                    closed.neck_height_m,
                    mm(closed.support_plane.map(|p| p.height_m)),
                    mm(closed.partial_support.map(|p| p.height_m)),
                ),
                Err(e) => println!("{name} {deg:+.2} | refused: {e}"),
            }
        }
    }
    Ok(())
}
