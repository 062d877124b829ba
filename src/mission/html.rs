//! `report.html` and its pictures: a top-down map of the mission (terrain hillshade, the flight
//! path coloured by mode, targets with their localization ellipses and mapping cylinders),
//! each mapped target's mesh from four sides and from below, and tables of metrics; and the
//! interactive part ([`super::report_viewer`]): a three.js view of each target's mesh, its
//! α(θ) polar plot and a table of every target's α with its interval.
//!
//! Pictures are PNGs beside the HTML, drawn with plotters into memory (no fonts: the HTML
//! carries the words) and written atomically.

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Isometry3, Vector3};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::{Rock, RockRole, World};
use scarp_export::atomic::write_bytes_atomically;
use scarp_planning::plot::{PlotConfig, write_png};
use scarp_slam::{PinholeCamera, TriangleMesh};

use super::catalog::Catalog;
use super::error::{MissionError, MissionResult};
use super::mode::{FlightLogEntry, Mode};
use super::report::MissionReport;
use super::safety::SafetyEvent;

/// Side of the square top-down map, pixels.
const MAP_PX: u32 = 900;

/// Mode colours on the map: search blue, fine localization orange, map green.
fn mode_color(mode: Mode) -> RGBColor {
    match mode {
        Mode::Search | Mode::Done => RGBColor(40, 90, 220),
        Mode::FineLocalize(_) => RGBColor(240, 140, 0),
        Mode::Map(_) => RGBColor(0, 170, 60),
    }
}

fn draw_err(e: impl std::fmt::Display) -> MissionError {
    MissionError::Drawing {
        what: "the mission map",
        message: e.to_string(),
    }
}

/// Hillshade of the heightfield under a sun from the north-west, in [0, 1].
fn hillshade(world: &World, x: f64, y: f64, step_m: f64) -> f64 {
    let h = |x: f64, y: f64| world.terrain_height_m(x, y);
    let dzdx = (h(x + step_m, y) - h(x - step_m, y)) / (2.0 * step_m);
    let dzdy = (h(x, y + step_m) - h(x, y - step_m)) / (2.0 * step_m);
    let normal = Vector3::new(-dzdx, -dzdy, 1.0).normalize();
    let sun = Vector3::new(-1.0, 1.0, 1.5).normalize();
    normal.dot(&sun).clamp(0.0, 1.0)
}

/// The terrain hillshade and the true rocks of `world` over `extent` (x0, y0, x1, y1).
fn draw_terrain<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    world: &World,
    (x0, y0, x1, y1): (f64, f64, f64, f64),
) -> MissionResult<()>
where
    DB::ErrorType: 'static,
{
    let cells = 150usize;
    let (dx, dy) = ((x1 - x0) / cells as f64, (y1 - y0) / cells as f64);
    let (lo, hi) = world.heightfield.height_range_m();
    let span = (hi - lo).max(1e-6);
    let mut shading = Vec::with_capacity(cells * cells);
    for j in 0..cells {
        for i in 0..cells {
            let (x, y) = (x0 + (i as f64 + 0.5) * dx, y0 + (j as f64 + 0.5) * dy);
            let shade = hillshade(world, x, y, dx);
            let tint = (world.terrain_height_m(x, y) - lo) / span;
            let v = |base: f64| (base * (0.45 + 0.55 * shade)).clamp(0.0, 255.0) as u8;
            let color = RGBColor(v(200.0 + 40.0 * tint), v(190.0 + 20.0 * tint), v(170.0));
            shading.push(Rectangle::new(
                [(x - 0.5 * dx, y - 0.5 * dy), (x + 0.5 * dx, y + 0.5 * dy)],
                color.filled(),
            ));
        }
    }
    chart.draw_series(shading).map_err(draw_err)?;
    for rock in &world.rocks {
        let color = match rock.role {
            RockRole::Target => RGBColor(200, 0, 0),
            RockRole::Distractor => RGBColor(90, 90, 90),
        };
        chart
            .draw_series(std::iter::once(Circle::new(
                (rock.centroid.x, rock.centroid.y),
                4,
                color.filled(),
            )))
            .map_err(draw_err)?;
    }
    Ok(())
}

/// The top-down map as RGB8 pixels, `MAP_PX` square: with a world, its terrain and rocks under
/// the true flight path; without one (a recorded flight), the estimated path on white, framed
/// around the flight.
pub fn render_map(
    world: Option<&World>,
    log: &[FlightLogEntry],
    targets: &Catalog,
    safety_events: &[SafetyEvent],
) -> MissionResult<Vec<u8>> {
    let path_of = |e: &FlightLogEntry| {
        e.world_from_camera_truth
            .unwrap_or(e.world_from_camera_estimate)
            .translation
            .vector
    };
    let (x0, y0, x1, y1) = match world {
        Some(world) => world.heightfield.extent(),
        None => {
            let (mut x0, mut y0) = (f64::INFINITY, f64::INFINITY);
            let (mut x1, mut y1) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
            for p in log.iter().map(path_of) {
                (x0, y0, x1, y1) = (x0.min(p.x), y0.min(p.y), x1.max(p.x), y1.max(p.y));
            }
            if x0 > x1 {
                (-10.0, -10.0, 10.0, 10.0)
            } else {
                let pad = 0.05 * (x1 - x0).max(y1 - y0).max(1.0);
                (x0 - pad, y0 - pad, x1 + pad, y1 + pad)
            }
        }
    };
    let mut buffer = vec![255u8; (MAP_PX * MAP_PX * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (MAP_PX, MAP_PX)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(draw_err)?;
        if let Some(world) = world {
            draw_terrain(&mut chart, world, (x0, y0, x1, y1))?;
        }
        for pair in log.windows(2) {
            let (a, b) = (path_of(&pair[0]), path_of(&pair[1]));
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(a.x, a.y), (b.x, b.y)],
                    mode_color(pair[1].mode).stroke_width(2),
                )))
                .map_err(draw_err)?;
        }
        for target in targets.values() {
            let c = target.report.center;
            if let Some([sxx, sxy, syy]) = target.covariance_xy {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        ellipse_2sigma(c[0], c[1], sxx, sxy, syy),
                        RGBColor(160, 0, 160).stroke_width(2),
                    )))
                    .map_err(draw_err)?;
            }
            if let Some(cyl) = &target.cylinder {
                let ring: Vec<(f64, f64)> = (0..=48)
                    .map(|k| {
                        let a = f64::from(k) / 48.0 * std::f64::consts::TAU;
                        (
                            cyl.center_x_m + cyl.radius_m * a.cos(),
                            cyl.center_y_m + cyl.radius_m * a.sin(),
                        )
                    })
                    .collect();
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        ring,
                        BLACK.stroke_width(1),
                    )))
                    .map_err(draw_err)?;
            }
        }
        // Collisions as red crosses, the monitor's interventions as orange triangles.
        for event in safety_events {
            let at = (event.position_true_m[0], event.position_true_m[1]);
            if event.kind == "collision" {
                chart
                    .draw_series(std::iter::once(Cross::new(
                        at,
                        7,
                        RGBColor(220, 0, 0).stroke_width(3),
                    )))
                    .map_err(draw_err)?;
            } else {
                chart
                    .draw_series(std::iter::once(TriangleMarker::new(
                        at,
                        6,
                        RGBColor(255, 140, 0).filled(),
                    )))
                    .map_err(draw_err)?;
            }
        }
        root.present().map_err(draw_err)?;
    }
    Ok(buffer)
}

/// The 2σ ellipse of a 2-D covariance `[[sxx, sxy], [sxy, syy]]` about (cx, cy).
pub fn ellipse_2sigma(cx: f64, cy: f64, sxx: f64, sxy: f64, syy: f64) -> Vec<(f64, f64)> {
    let m = nalgebra::Matrix2::new(sxx, sxy, sxy, syy);
    let eig = m.symmetric_eigen();
    (0..=64)
        .map(|k| {
            let a = f64::from(k) / 64.0 * std::f64::consts::TAU;
            let unit = nalgebra::Vector2::new(
                2.0 * eig.eigenvalues[0].max(0.0).sqrt() * a.cos(),
                2.0 * eig.eigenvalues[1].max(0.0).sqrt() * a.sin(),
            );
            let p = eig.eigenvectors * unit;
            (cx + p.x, cy + p.y)
        })
        .collect()
}

/// Names and camera directions of the mesh views: four sides, then from below.
pub const MESH_VIEWS: [(&str, [f64; 3]); 5] = [
    ("east", [1.0, 0.0, 0.35]),
    ("north", [0.0, 1.0, 0.35]),
    ("west", [-1.0, 0.0, 0.35]),
    ("south", [0.0, -1.0, 0.35]),
    ("below", [0.05, 0.0, -1.0]),
];

/// Renders `mesh` alone from the [`MESH_VIEWS`] with the world's sun, and writes
/// `dir/view_<name>.png` for each. Returns the file names.
///
/// # Errors
/// An empty mesh, a rendering or a writing error.
pub fn write_mesh_views(
    world: &World,
    mesh: &TriangleMesh,
    dir: &Path,
) -> MissionResult<Vec<String>> {
    let (lo, hi) = mesh
        .bounds()
        .ok_or_else(|| MissionError::invalid("the mesh is empty"))?;
    let (lo, hi) = (lo.cast::<f64>(), hi.cast::<f64>());
    let center = nalgebra::center(&lo, &hi);
    let radius = 0.5 * (hi - lo).norm();
    // The renderer draws a world; a world holding only this mesh as a rock draws just it.
    let mut alone = world.clone();
    alone.terrain_mesh = TriangleMesh::default();
    alone.rocks = vec![Rock {
        mesh: mesh.clone(),
        pedestal: None,
        ..world
            .rocks
            .first()
            .cloned()
            .ok_or_else(|| MissionError::invalid("the world has no rock"))?
    }];
    let renderer = Renderer::new(&alone);
    let camera = PinholeCamera::from_hfov(480, 480, 40.0)?;
    let distance = radius / (20f64.to_radians()).tan() * 1.1;
    let mut names = Vec::new();
    for (name, direction) in MESH_VIEWS {
        let d = Vector3::from(direction).normalize();
        let eye = center + d * distance;
        let up = if d.z.abs() > 0.9 {
            Vector3::y()
        } else {
            Vector3::z()
        };
        let pose: Isometry3<f64> = scarp_slam::geometry::look_at(&eye, &center, &up)?;
        let out = renderer.render(&camera, &pose)?;
        let mut rgb = out
            .rgb
            .as_slice()
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<u8>>();
        // Sky to white, so the rock stands out on the page.
        for (px, &id) in rgb.chunks_exact_mut(3).zip(out.instance.as_slice()) {
            if id == 0 {
                px.copy_from_slice(&[255, 255, 255]);
            }
        }
        let file = format!("view_{name}.png");
        let cfg = PlotConfig {
            width_px: camera.width,
            height_px: camera.height,
            ..PlotConfig::default()
        };
        write_png(&dir.join(&file), &rgb, &cfg)?;
        names.push(file);
    }
    Ok(names)
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("–".into(), |v| format!("{v:.digits$}"))
}

/// Writes `report.html` and `map.png` into `dir`.
///
/// # Errors
/// Drawing or writing errors naming the file.
pub fn write_report(
    dir: &Path,
    world: Option<&World>,
    report: &MissionReport,
    log: &[FlightLogEntry],
    targets: &Catalog,
) -> MissionResult<()> {
    let map = render_map(world, log, targets, &report.safety_events)?;
    let cfg = PlotConfig {
        width_px: MAP_PX,
        height_px: MAP_PX,
        ..PlotConfig::default()
    };
    write_png(&dir.join("map.png"), &map, &cfg)?;
    let mut html = String::new();
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>scarp mission</title>\
<style>body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}\
td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}}img{{margin:2px}}{}</style></head><body>\n\
<h1>scarp mission on world <code>{}</code> (seed {})</h1>\n\
<p>{}: {} of {} targets mapped; {} distractors mapped; missed true targets: {:?}; collisions: {} camera steps; safety interventions: {}.<br>\
Simulated {:.0} s in {:.0} s of wall time (real-time factor {:.1}).</p>\n\
<h2>Map</h2><p>Terrain hillshade; flight path by mode (search blue, fine localization orange, \
mapping green); true targets red, distractors grey; localization 2σ ellipses purple; mapping \
cylinders black; collisions red crosses, safety interventions orange triangles.</p><img src=\"map.png\" width=\"700\">\n",
        super::report_viewer::STYLE,
        report.world,
        report.seed,
        report.end_reason,
        report.targets_mapped,
        report.targets_found,
        report.distractors_mapped,
        report.targets_missed,
        report.collisions,
        report.safety_interventions,
        report.sim_time_s,
        report.wall_time_s,
        report.real_time_factor
    );
    html.push_str(
        "<h2>Targets</h2><table><tr><th>id</th><th>status</th><th>true rock</th>\
<th>localization error (m)</th><th>centre error, estimate frame (m)</th><th>coverage</th><th>base coverage</th><th>F1cm</th><th>F2cm</th>\
<th>accuracy (mm)</th><th>completeness (mm)</th><th>visible GT</th><th>ATE before BA (mm)</th>\
<th>ATE after BA (mm)</th><th>α_min (°)</th><th>95% interval (°)</th><th>α_min true (°)</th><th>toppling PGA (g)</th></tr>\n",
    );
    for t in &report.targets {
        let mm = |v: Option<f64>| opt(v.map(|v| v * 1000.0), 1);
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td>\
<td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            t.id,
            t.status,
            t.gt_rock_id.map_or("–".into(), |id| format!(
                "{id} ({})",
                t.gt_role.as_deref().unwrap_or("")
            )),
            opt(t.localization_error_m, 2),
            match t.center_error_estimate_frame_m {
                Some(e) => format!("{e:.2} ({})", t.center_source),
                None => "–".into(),
            },
            t.coverage,
            t.base_coverage,
            opt(t.fscore_1cm, 3),
            opt(t.fscore_2cm, 3),
            mm(t.accuracy_mean_m),
            mm(t.completeness_mean_m),
            opt(t.gt_visible_fraction, 2),
            mm(t.ate_before_ba_m),
            mm(t.ate_after_ba_m),
            opt(t.alpha_min_deg, 2),
            match (t.alpha_min_low_deg, t.alpha_min_high_deg) {
                (Some(low), Some(high)) => format!("{low:.1}–{high:.1}"),
                _ => "–".into(),
            },
            opt(t.alpha_min_gt_deg, 2),
            opt(t.toppling_pga_g, 3),
        );
    }
    html.push_str("</table>\n");
    // The interactive views (three.js, embedded data), the α(θ) plots and the α table.
    html.push_str(&super::report_viewer::interactive_sections(
        dir, world, report,
    ));
    html.push_str("<h2>Mesh views</h2>\n");
    for t in report.targets.iter().filter(|t| t.status == "mapped") {
        let _ = writeln!(html, "<h3>Target {}</h3><p>", t.id);
        for (name, _) in MESH_VIEWS {
            let _ = write!(
                html,
                "<img src=\"targets/{}/view_{name}.png\" width=\"220\" alt=\"{name}\" title=\"{name}\">",
                t.id
            );
        }
        html.push_str("</p>\n");
    }
    let s = &report.timings;
    let _ = write!(
        html,
        "<h2>Wall time per stage (s)</h2><table><tr><th>setup</th><th>flight</th><th>planning</th><th>render</th>\
<th>detect</th><th>track</th><th>localize</th><th>map</th><th>BA + mesh</th><th>fragility + export</th>\
<th>evaluation</th></tr><tr><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td>\
<td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr></table>\n</body></html>\n",
        s.setup_s,
        s.flight_s,
        s.planning_s,
        s.render_s,
        s.detect_s,
        s.track_s,
        s.localize_s,
        s.map_s,
        s.ba_mesh_s,
        s.fragility_export_s,
        s.evaluation_s
    );
    write_bytes_atomically(dir.join("report.html"), html.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn ellipse_has_the_covariance_axes() {
        let pts = ellipse_2sigma(1.0, 2.0, 4.0, 0.0, 1.0);
        let max_dx = pts.iter().map(|p| (p.0 - 1.0).abs()).fold(0.0, f64::max);
        let max_dy = pts.iter().map(|p| (p.1 - 2.0).abs()).fold(0.0, f64::max);
        assert!((max_dx - 4.0).abs() < 1e-9, "{max_dx}");
        assert!((max_dy - 2.0).abs() < 1e-2, "{max_dy}");
    }

    #[test]
    fn mesh_views_show_the_mesh() {
        let world = World::builtin_default().unwrap();
        let mut mesh = TriangleMesh::icosphere(2);
        for p in &mut mesh.positions {
            *p = Point3::new(0.5 * p.x, 0.5 * p.y, 0.5 * p.z + 1.0);
        }
        let dir = tempfile::tempdir().unwrap();
        let names = write_mesh_views(&world, &mesh, dir.path()).unwrap();
        assert_eq!(names.len(), 5);
        for name in names {
            let img = image::open(dir.path().join(&name)).unwrap().to_rgb8();
            let rock = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
            let fraction = rock as f64 / f64::from(img.width() * img.height());
            assert!(fraction > 0.1 && fraction < 0.9, "{name}: {fraction}");
        }
    }
}
