//! Where a scanned rock's α_min goes wrong: for every mapped target of a finished campaign,
//! re-runs the scan analysis on the saved mesh (moved into the world frame by the keyframes'
//! map-to-world alignment) and compares each part of it with the world's truth: the contact
//! height, the contact polygon's area and centre, the centre of mass, and α_min with the true
//! contact or the true centre of mass swapped in.
//!
//! ```text
//! cargo run --release --example contact_diagnosis -- CAMPAIGN_DIR [FRAGILITY_TOML [OUT_DIR]]
//! cargo run --release --example contact_diagnosis -- --mesh MESH WORLD ROCK_ID LABEL [FRAGILITY_TOML]
//! ```
//!
//! With `PROFILE=LABEL` in the environment (a row's label: `world seed-N rock-id shape`), that
//! target's per-sector profiles, its true and scanned contact polygons and the support outline
//! the scan read are printed too. With `PATCHES` set, every unseen patch of every scan is
//! printed (`PATCH label area-m² centroid-xyz area-vector-direction-xyz area-vector-m²`).
//!
//! With `OUT_DIR`, each run's `mission.json` is written there with its targets' α_min, interval
//! and true α_min re-analysed (and `world_gt/world.json` beside it), so that
//! `scarp campaign --tabulate-only --out OUT_DIR` tabulates the new analysis of the same
//! flights.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use nalgebra::{Isometry3, Point2, Point3, Vector3};
use scarp::fragility::rocking::minimum_support;
use scarp::fragility::scan::{ClosedScan, analyze_scan, scan_centroid};
use scarp::fragility::{ContactSpec, FragilityAnalysis, FragilityConfig, FragilityReport, analyze};
use scarp::mission::mapping::map_to_world;
use scarp_datasets::world::World;
use scarp_export::ply::read_mesh;
use scarp_export::tum::read_tum_trajectory;

/// α_min, degrees, of a centre of mass over a contact polygon (both world frame).
fn alpha_deg(polygon: &[[f64; 3]], com: &[f64; 3]) -> f64 {
    let hull: Vec<Point2<f64>> = polygon.iter().map(|p| Point2::new(p[0], p[1])).collect();
    let height = com[2] - polygon.iter().map(|p| p[2]).sum::<f64>() / polygon.len() as f64;
    minimum_support(&hull, &Point2::new(com[0], com[1]))
        .map_or(f64::NAN, |m| m.distance_m.atan2(height).to_degrees())
}

fn centroid_xy(polygon: &[[f64; 3]]) -> Point2<f64> {
    let hull: Vec<Point2<f64>> = polygon.iter().map(|p| Point2::new(p[0], p[1])).collect();
    scarp_slam::geometry::polygon_centroid(&hull).unwrap_or(hull[0])
}

fn world_from_map(target_dir: &Path) -> Result<Isometry3<f64>> {
    let truth = read_tum_trajectory(&target_dir.join("keyframes_groundtruth.txt"))?;
    let ba: Vec<Isometry3<f64>> = read_tum_trajectory(&target_dir.join("keyframes_ba.txt"))?
        .iter()
        .map(|p| p.world_from_camera)
        .collect();
    map_to_world(&truth, &ba).context("aligning the keyframes to the truth")
}

/// Prints a scan's contact readings (`READINGS label truth α…`, in
/// [`ClosedScan::hypotheses`]' order), its interval (`INTERVAL label truth α_min low high
/// name:below:above…`, one triple per source), the centre-of-mass spread of its unseen patches
/// (`UNSEEN label patches area-m² below above` at bulge ratios 0.25, 0.5 and 1) and its
/// features (`FEATURES label truth α_min contact-α-low contact-α-high near-fraction
/// neck-offset filled-fraction support-found rock-height com-height`), the lines
/// `docs/campaigns/tools/interval_calibration.py` reads.
fn print_readings(
    label: &str,
    truth_deg: f64,
    closed: &ClosedScan,
    a: &FragilityAnalysis,
    config: &FragilityConfig,
) {
    let label = label.replace(' ', "_");
    let readings: Vec<String> = closed
        .hypotheses(config)
        .iter()
        .map(|h| {
            closed
                .contact_under(h)
                .ok()
                .and_then(|p| a.alpha_min_on_contact(&p))
                .map_or("nan".into(), |v| format!("{v:.3}"))
        })
        .collect();
    println!("READINGS {} {:.3} {}", label, truth_deg, readings.join(" "));
    let r = &a.report;
    let sources: Vec<String> = r
        .alpha_interval
        .sources
        .iter()
        .map(|s| format!("{}:{:.3}:{:.3}", s.name, s.below_deg, s.above_deg))
        .collect();
    println!(
        "INTERVAL {} {:.3} {:.3} {:.3} {:.3} {}",
        label,
        truth_deg,
        r.alpha_min_deg,
        r.alpha_min_low_deg,
        r.alpha_min_high_deg,
        sources.join(" ")
    );
    let spreads: Vec<String> = [0.25, 0.5, 1.0]
        .iter()
        .map(|ratio| {
            let (below, above) =
                closed.unseen_shape_alpha_spread_deg(a, &a.report.contact_polygon, *ratio);
            format!("{below:.3} {above:.3}")
        })
        .collect();
    let unseen_m2: f64 = closed.unseen_patches().map(|p| p.area_m2).sum();
    if std::env::var("PATCHES").is_ok() {
        for q in closed.unseen_patches() {
            let direction = q.area_vector_m2 / q.area_vector_m2.norm().max(1e-12);
            println!(
                "PATCH {label} {:.4} {:.3} {:.3} {:.3} {:.2} {:.2} {:.2} {:.3}",
                q.area_m2,
                q.centroid.x,
                q.centroid.y,
                q.centroid.z,
                direction.x,
                direction.y,
                direction.z,
                q.area_vector_m2.norm()
            );
        }
    }
    println!(
        "UNSEEN {} {} {:.4} {}",
        label,
        closed.unseen_patches().count(),
        unseen_m2,
        spreads.join(" ")
    );
    let sectors = closed.profile.radius_m.len();
    let near = closed.profile.sectors_seen_near(&config.scan);
    println!(
        "FEATURES {} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3} {} {:.3} {:.3}",
        label,
        truth_deg,
        a.report.alpha_min_deg,
        a.report
            .alpha_interval
            .contact_alpha_low_deg
            .unwrap_or(f64::NAN),
        a.report
            .alpha_interval
            .contact_alpha_high_deg
            .unwrap_or(f64::NAN),
        near as f64 / sectors as f64,
        closed.contact_height_m() - closed.neck_height_m,
        closed.filled_area_m2 / (closed.filled_area_m2 + closed.scanned_area_m2),
        closed.support_plane.is_some(),
        a.report.rock_height_m,
        a.report.com_height_above_contact_m,
    );
}

/// The fragility configuration in `path` (empty or absent: the defaults).
fn fragility_config(path: Option<String>) -> Result<FragilityConfig> {
    Ok(match path {
        Some(path) if !path.is_empty() => toml::from_str(&std::fs::read_to_string(path)?)?,
        Some(_) | None => FragilityConfig::default(),
    })
}

/// `config` with the world's up (+z): the truth is analysed in the world frame whatever up the
/// scan's analysis takes.
fn world_up_config(config: &FragilityConfig) -> FragilityConfig {
    FragilityConfig {
        up: [0.0, 0.0, 1.0],
        ..config.clone()
    }
}

/// `--mesh MESH WORLD ROCK_ID LABEL [FRAGILITY_TOML]`: one scan (world frame, z up, such as
/// `scarp map --poses groundtruth` writes) against rock `ROCK_ID` of `WORLD`; prints its
/// readings, or `REFUSED label truth reason`.
fn single_mesh(args: &[String]) -> Result<()> {
    let [mesh, world, rock_id, label, rest @ ..] = args else {
        anyhow::bail!("usage: --mesh MESH WORLD ROCK_ID LABEL [FRAGILITY_TOML]");
    };
    let config = fragility_config(rest.first().cloned())?;
    let world = World::from_name_or_path(world)?;
    let rock = world
        .rock(rock_id.parse()?)
        .context("no such rock in the world")?;
    let pedestal = rock.pedestal.as_ref().context("the rock has no pedestal")?;
    let truth = analyze(
        &rock.mesh,
        ContactSpec::Pedestal(pedestal),
        &world_up_config(&config),
    )?;
    let mesh = read_mesh(mesh)?;
    match analyze_scan(&mesh, &config) {
        Ok((closed, a)) => {
            print_readings(label, truth.alpha_min_deg, &closed, &a, &config);
            print_plane(label, &closed, truth.contact_height_m);
            if std::env::var("PROFILE").is_ok_and(|v| &v == label) {
                print_target_profile(&truth, &rock.mesh, &mesh, Some(&(closed, a)));
            }
        }
        Err(e) => println!(
            "REFUSED {label} {:.3} {}",
            truth.alpha_min_deg,
            e.to_string().replace(' ', "_")
        ),
    }
    Ok(())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().is_some_and(|a| a == "--mesh") {
        return single_mesh(&args[1..]);
    }
    let dir = PathBuf::from(args.first().context("usage: CAMPAIGN_DIR")?);
    let config = fragility_config(args.get(1).cloned())?;
    let mut errors: Vec<f64> = Vec::new();
    let mut written: Vec<(PathBuf, serde_json::Value)> = Vec::new();
    let mut refused = 0usize;
    println!(
        "world seed id shape | a_gt a_map err | dh_mm area_ratio dc_cm dcom_cm dcomz_cm | a(scanC,trueCOM) a(trueC,scanCOM)"
    );
    let mut runs: Vec<PathBuf> = glob_runs(&dir)?;
    runs.sort();
    for run in runs {
        let mut mission: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(run.join("mission.json"))?)?;
        let world = World::load(&run.join("world_gt/world.toml"))
            .with_context(|| format!("world of {}", run.display()))?;
        let shapes: HashMap<u32, String> = world
            .config
            .rocks
            .iter()
            .map(|r| (r.id, r.shape_label()))
            .collect();
        for t in mission["targets"].as_array_mut().into_iter().flatten() {
            let (Some(id), Some(gt_id)) = (t["id"].as_u64(), t["gt_rock_id"].as_u64()) else {
                continue;
            };
            let target_dir = run.join("targets").join(id.to_string());
            let Ok(mesh) = read_mesh(target_dir.join("mesh.ply")) else {
                continue;
            };
            let rock = world.rock(gt_id as u32).context("gt rock")?;
            print_centre(&run, gt_id, t, &mesh, &rock.centroid, &config);
            let Some(pedestal) = &rock.pedestal else {
                continue;
            };
            let truth = analyze(
                &rock.mesh,
                ContactSpec::Pedestal(pedestal),
                &world_up_config(&config),
            )?;
            let label = format!(
                "{} {} {} {}",
                run.parent().unwrap().file_name().unwrap().to_string_lossy(),
                run.file_name().unwrap().to_string_lossy(),
                gt_id,
                shapes.get(&(gt_id as u32)).cloned().unwrap_or_default()
            );
            let map_result = analyze_scan(&mesh, &config);
            if let Ok((closed, a)) = &map_result {
                print_readings(&label, truth.alpha_min_deg, closed, a, &config);
            }
            let map_analysis = map_result.map(|(_, a)| a.report);
            update_target(t, &map_analysis, &truth);
            let map_alpha = map_analysis.map(|r| r.alpha_min_deg);
            let mut world_mesh = mesh.clone();
            world_mesh.transform(&world_from_map(&target_dir)?);
            let world_analysis = analyze_scan(&world_mesh, &config);
            if std::env::var("PROFILE").is_ok_and(|v| v == label) {
                print_target_profile(
                    &truth,
                    &rock.mesh,
                    &world_mesh,
                    world_analysis.as_ref().ok(),
                );
            }
            match (map_alpha, world_analysis) {
                (Ok(a_map), Ok((_, analysis))) => {
                    print_row(&label, &truth, a_map, &analysis.report);
                    errors.push(a_map - truth.alpha_min_deg);
                }
                (Err(e), _) | (_, Err(e)) => {
                    refused += 1;
                    println!("{label} | {:.2} refused: {e}", truth.alpha_min_deg);
                }
            }
        }
        written.push((run.clone(), mission));
    }
    let total = errors.len() + refused;
    if let Some(out) = args.get(2) {
        for (run, mission) in &written {
            let rel = run.strip_prefix(&dir)?;
            let target = Path::new(&out).join(rel);
            std::fs::create_dir_all(target.join("world_gt"))?;
            std::fs::write(
                target.join("mission.json"),
                serde_json::to_string_pretty(mission)?,
            )?;
            std::fs::copy(
                run.join("world_gt/world.json"),
                target.join("world_gt/world.json"),
            )?;
        }
    }
    let within = errors.iter().filter(|e| e.abs() <= 2.0).count();
    let over = errors.iter().filter(|e| **e > 3.0).count();
    let mut sorted = errors.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "TOTAL {total}: within 2° {within} ({:.0}%), refused {refused}, over 3° {over}, median {:+.2}, worst {:+.2}",
        100.0 * within as f64 / total as f64,
        sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN),
        sorted.last().copied().unwrap_or(f64::NAN),
    );
    Ok(())
}

fn print_row(label: &str, truth: &FragilityReport, a_map: f64, scan: &FragilityReport) {
    let dh_mm = (scan.contact_height_m - truth.contact_height_m) * 1e3;
    let area_ratio = scan.contact_area_m2 / truth.contact_area_m2;
    let dc_cm =
        (centroid_xy(&scan.contact_polygon) - centroid_xy(&truth.contact_polygon)).norm() * 100.0;
    let dcom = Vector3::from(scan.center_of_mass) - Vector3::from(truth.center_of_mass);
    println!(
        "{label} | {:.2} {:.2} {:+.2} | {:+.0} {:.2} {:.1} {:.1} {:+.1} | {:.2} {:.2}",
        truth.alpha_min_deg,
        a_map,
        a_map - truth.alpha_min_deg,
        dh_mm,
        area_ratio,
        dc_cm,
        dcom.xy().norm() * 100.0,
        dcom.z * 100.0,
        alpha_deg(&scan.contact_polygon, &truth.center_of_mass),
        alpha_deg(&truth.contact_polygon, &scan.center_of_mass),
    );
}

/// `PLANE label found dh_mm roughness_mm`: whether the support plane was found, the contact
/// height's error against the truth's `truth_z`, and the support's measured roughness
/// ([`scarp::fragility::scan::SupportPlane::roughness_m`]; `nan` without a plane).
fn print_plane(label: &str, closed: &ClosedScan, truth_z: f64) {
    // The contact's height at the rock's axis, in the scan's frame (the closed scan's is its
    // support's, levelled).
    let axis = closed.profile.axis_xy;
    let contact =
        closed.support_from_scan.inverse() * Point3::new(axis.x, axis.y, closed.contact_height_m());
    println!(
        "PLANE {} {} {:+.1} {:.1}",
        label.replace(' ', "_"),
        closed.support_plane.is_some(),
        (contact.z - truth_z) * 1e3,
        closed
            .support_plane
            .map_or(f64::NAN, |p| p.roughness_m * 1e3)
    );
}

/// Prints `CENTRE world seed rock status localized-m scan-m`: the estimate-frame errors of the
/// target's localized centre (from `mission.json`) and of its scan's centroid
/// ([`scan_centroid`] of the saved mesh, against the true centroid moved by the estimator's
/// mean error over the keyframes); `nan` where one is missing.
fn print_centre(
    run: &Path,
    gt_id: u64,
    target: &serde_json::Value,
    mesh: &scarp_slam::TriangleMesh,
    true_centroid: &Point3<f64>,
    config: &FragilityConfig,
) {
    let scan_error = match (
        scan_centroid(mesh, &config.scan),
        serde_json::from_value::<[f64; 3]>(target["estimator_error_over_keyframes_m"].clone()),
    ) {
        (Ok(c), Ok(e)) => (true_centroid + Vector3::from(e) - c).norm(),
        _ => f64::NAN,
    };
    println!(
        "CENTRE {} {} {gt_id} {} {:.3} {scan_error:.3}",
        run.parent().unwrap().file_name().unwrap().to_string_lossy(),
        run.file_name().unwrap().to_string_lossy(),
        target["status"].as_str().unwrap_or("?"),
        target["localization_error_estimate_frame_m"]
            .as_f64()
            .unwrap_or(f64::NAN),
    );
}

fn glob_runs(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for world in std::fs::read_dir(dir.join("runs"))? {
        for seed in std::fs::read_dir(world?.path())? {
            let p = seed?.path();
            if p.join("mission.json").exists() {
                out.push(p);
            }
        }
    }
    Ok(out)
}

/// What `PROFILE=LABEL` prints for one target: the per-sector profiles of the world's rock and of
/// the scan ([`print_profiles`]), the scan's own basal profile as the analysis measured it, and
/// the true and scanned contact polygons with the support outline the scan read.
fn print_target_profile(
    truth: &FragilityReport,
    rock: &scarp_slam::TriangleMesh,
    scan: &scarp_slam::TriangleMesh,
    analysis: Option<&(ClosedScan, FragilityAnalysis)>,
) {
    print_profiles(truth, rock, scan);
    let polygon = |name: &str, r: &FragilityReport| {
        let xy: Vec<String> = r
            .contact_polygon
            .iter()
            .map(|p| format!("({:.3},{:.3})", p[0], p[1]))
            .collect();
        println!(
            "{name}: α {:.2} at azimuth {:.0}°, com ({:.3},{:.3},{:.3}), contact {}",
            r.alpha_min_deg,
            r.alpha_min_azimuth_deg,
            r.center_of_mass[0],
            r.center_of_mass[1],
            r.center_of_mass[2],
            xy.join(" ")
        );
    };
    polygon("truth", truth);
    let Some((closed, a)) = analysis else {
        return;
    };
    polygon("scan", &a.report);
    let profile = &closed.profile;
    println!(
        "scan profile: axis ({:.3},{:.3}), plane {:.4} m, slab tops {:?} cm",
        profile.axis_xy.x,
        profile.axis_xy.y,
        profile.plane_z,
        profile
            .slab_top_m
            .iter()
            .map(|t| (t * 1000.0).round() / 10.0)
            .collect::<Vec<_>>()
    );
    for (s, (radii, azimuths)) in profile
        .radius_m
        .iter()
        .zip(&profile.azimuth_rad)
        .enumerate()
    {
        let cells: Vec<String> = radii
            .iter()
            .zip(azimuths)
            .map(|(r, az)| format!("{:4.1}@{:3.0}", r * 100.0, az.to_degrees()))
            .collect();
        println!("  sector {s:2}: {}", cells.join(" "));
    }
    if let Some(o) = &closed.support_outline {
        let xy: Vec<String> = o
            .hull(scarp::fragility::scan::OutlineGaps::Interpolated)
            .unwrap_or_default()
            .iter()
            .map(|p| format!("({:.3},{:.3})", p.x, p.y))
            .collect();
        println!(
            "outline: seen {} of {}: {}",
            o.seen_sectors(),
            o.radius_m.len(),
            xy.join(" ")
        );
    }
}

/// Per-sector largest radius of each mesh's vertices in 1 cm slabs above the true contact, around
/// the true contact's centroid, and the true contact's radius in that sector.
fn print_profiles(
    truth: &FragilityReport,
    rock: &scarp_slam::TriangleMesh,
    scan: &scarp_slam::TriangleMesh,
) {
    let axis = centroid_xy(&truth.contact_polygon);
    let plane = truth.contact_height_m;
    let sectors = 12;
    let radii = |mesh: &scarp_slam::TriangleMesh| {
        let mut r = vec![vec![0.0f64; 16]; sectors];
        for p in &mesh.positions {
            let h = f64::from(p.z) - plane;
            if !(0.0..0.16).contains(&h) {
                continue;
            }
            let d = Point2::new(f64::from(p.x), f64::from(p.y)) - axis;
            let s = ((d.y.atan2(d.x).rem_euclid(std::f64::consts::TAU)) / std::f64::consts::TAU
                * sectors as f64) as usize
                % sectors;
            let k = (h / 0.01) as usize;
            r[s][k] = r[s][k].max(d.norm());
        }
        r
    };
    let (rt, rs) = (radii(rock), radii(scan));
    for s in 0..sectors {
        let row = |r: &Vec<f64>| {
            r.iter()
                .map(|v| format!("{:3.0}", v * 100.0))
                .collect::<Vec<_>>()
                .join("")
        };
        println!(
            "sector {s:2} truth {}\n          scan  {}",
            row(&rt[s]),
            row(&rs[s])
        );
    }
}

/// Rewrites a `mission.json` target's fragility figures from a new analysis: α_min, its interval,
/// the toppling acceleration, the truth and the error; a refusal clears them and records why, and
/// moves a mapped target to incomplete (as the mission does).
fn update_target(
    t: &mut serde_json::Value,
    analysis: &Result<FragilityReport, scarp::fragility::FragilityError>,
    truth: &FragilityReport,
) {
    t["alpha_min_gt_deg"] = truth.alpha_min_deg.into();
    let fragility_error = t["error"]
        .as_str()
        .is_none_or(|e| e.starts_with("fragility:"));
    match analysis {
        Ok(r) => {
            t["alpha_min_deg"] = r.alpha_min_deg.into();
            t["alpha_min_low_deg"] = r.alpha_min_low_deg.into();
            t["alpha_min_high_deg"] = r.alpha_min_high_deg.into();
            t["toppling_pga_g"] = r.toppling_pga_g.into();
            t["support_tilt_deg"] = r.support_tilt_deg.into();
            t["alpha_error_deg"] = (r.alpha_min_deg - truth.alpha_min_deg).abs().into();
            if fragility_error {
                t["error"] = serde_json::Value::Null;
                t["status"] = "mapped".into();
            }
        }
        Err(e) => {
            for key in [
                "alpha_min_deg",
                "alpha_min_low_deg",
                "alpha_min_high_deg",
                "toppling_pga_g",
                "support_tilt_deg",
                "alpha_error_deg",
            ] {
                t[key] = serde_json::Value::Null;
            }
            if fragility_error {
                t["error"] = format!("fragility: {e}").into();
                t["status"] = "incomplete".into();
            }
        }
    }
}
