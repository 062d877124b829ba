//! The interactive part of `report.html`: for each target with a mesh, a three.js view of the
//! mesh (orbit, zoom; toggles for the contact polygon, the centre of mass and the ground-truth
//! mesh; colours from the camera or from the distance to the ground truth), a polar plot of
//! α(θ) with α_min and its interval, and a table of every target's α with its interval.
//!
//! The report must work offline from `file://`, where Chromium blocks `fetch` and ES-module
//! imports of local files, so everything is inside the one HTML file:
//! - three.js (vendored in `src/mission/vendor/`, see its README) as a classic inline script;
//! - the viewer (`viewer.js`, our code) as another;
//! - the meshes as base64 little-endian typed arrays inside a JSON `<script>` block, decimated
//!   by vertex clustering to at most [`MAX_VIEW_TRIANGLES`] triangles a mesh so the file stays
//!   a few megabytes.
//!
//! Frames: everything is drawn in the *map frame* of the target (the frame of `mesh.ply` and
//! `fragility.json`: world ENU metres as the state estimator saw it). The ground-truth rock is
//! moved into it by the inverse of the alignment that the mission's mesh scores use
//! ([`map_to_world`]: the keyframes' refined camera centres onto their true ones), and the
//! per-vertex error is the distance from each shown vertex to that moved ground truth.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Isometry3, Point3};
use scarp_datasets::world::World;
use scarp_export::ply::read_mesh;
use scarp_export::tum::read_tum_trajectory;
use scarp_slam::TriangleMesh;

use super::mapping::map_to_world;
use super::report::{MissionReport, TargetReport};
use crate::evaluation::mesh::{MeshDistance, crop_to_box};
use crate::fragility::FragilityReport;

/// three.js 0.187.0, minified, defining the global `THREE` (see `vendor/README.md`).
const THREE_JS: &str = include_str!("vendor/three.min.js");
/// The viewer: builds the scenes from the embedded data.
const VIEWER_JS: &str = include_str!("viewer.js");

/// Most triangles of one mesh shown in the report (reconstruction or ground truth).
pub const MAX_VIEW_TRIANGLES: usize = 60_000;

/// Standard base64 (RFC 4648, with padding) of `bytes`.
pub fn base64(bytes: &[u8]) -> String {
    const TABLE: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for (i, shift) in [18u32, 12, 6, 0].into_iter().enumerate() {
            if i <= chunk.len() {
                out.push(char::from(TABLE[((n >> shift) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn f32_base64(values: impl IntoIterator<Item = f32>) -> String {
    let bytes: Vec<u8> = values.into_iter().flat_map(f32::to_le_bytes).collect();
    base64(&bytes)
}

fn u32_base64(values: impl IntoIterator<Item = u32>) -> String {
    let bytes: Vec<u8> = values.into_iter().flat_map(u32::to_le_bytes).collect();
    base64(&bytes)
}

/// Simplifies `mesh` by vertex clustering until it has at most `max_triangles` triangles: the
/// vertices in each cubic cell merge into their mean (colour averaged too), and triangles whose
/// corners fall into fewer than three cells disappear. The cell starts at a hundredth of the
/// bounding box's largest side and grows by 1.25× a round. A mesh already small enough is
/// returned as it is. Normals are dropped.
pub fn decimate(mesh: &TriangleMesh, max_triangles: usize) -> TriangleMesh {
    if mesh.faces.len() <= max_triangles {
        return mesh.clone();
    }
    let Some((lo, hi)) = mesh.bounds() else {
        return mesh.clone();
    };
    let extent = (hi - lo).max();
    let mut cell = f64::from(extent.max(1e-6)) / 100.0;
    loop {
        let out = cluster(mesh, &lo, cell);
        if out.faces.len() <= max_triangles || cell > f64::from(extent) {
            return out;
        }
        cell *= 1.25;
    }
}

fn cluster(mesh: &TriangleMesh, origin: &Point3<f32>, cell_m: f64) -> TriangleMesh {
    let mut index: HashMap<[i64; 3], u32> = HashMap::new();
    let mut sums: Vec<([f64; 3], [f64; 3], f64)> = Vec::new();
    let has_colors = mesh.colors.len() == mesh.positions.len();
    let remap: Vec<u32> = mesh
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let key = [
                ((f64::from(p.x - origin.x)) / cell_m).floor() as i64,
                ((f64::from(p.y - origin.y)) / cell_m).floor() as i64,
                ((f64::from(p.z - origin.z)) / cell_m).floor() as i64,
            ];
            let id = *index.entry(key).or_insert_with(|| {
                sums.push(([0.0; 3], [0.0; 3], 0.0));
                (sums.len() - 1) as u32
            });
            let s = &mut sums[id as usize];
            for k in 0..3 {
                s.0[k] += f64::from(p[k]);
                if has_colors {
                    s.1[k] += f64::from(mesh.colors[i][k]);
                }
            }
            s.2 += 1.0;
            id
        })
        .collect();
    let positions = sums
        .iter()
        .map(|(p, _, n)| Point3::new((p[0] / n) as f32, (p[1] / n) as f32, (p[2] / n) as f32))
        .collect();
    let colors = if has_colors {
        sums.iter()
            .map(|(_, c, n)| [(c[0] / n) as u8, (c[1] / n) as u8, (c[2] / n) as u8])
            .collect()
    } else {
        Vec::new()
    };
    let mut seen = std::collections::HashSet::new();
    let faces = mesh
        .faces
        .iter()
        .map(|f| f.map(|v| remap[v as usize]))
        .filter(|[a, b, c]| a != b && b != c && a != c)
        .filter(|f| {
            // The same cell triangle from several source triangles: keep one.
            let mut key = *f;
            key.sort_unstable();
            seen.insert(key)
        })
        .collect();
    TriangleMesh {
        positions,
        normals: Vec::new(),
        colors,
        faces,
    }
}

/// What the viewer shows of one target (JSON for `viewer.js`).
#[derive(serde::Serialize)]
struct ViewData {
    id: u64,
    status: String,
    /// Reconstruction (map frame): base64 f32 xyz, u32 indices, u8 rgb.
    positions: String,
    indices: String,
    colors: Option<String>,
    triangles_full: usize,
    triangles_shown: usize,
    /// Ground truth (rock, pedestal, nearby terrain) in the map frame, decimated.
    gt_positions: Option<String>,
    gt_indices: Option<String>,
    /// Per shown vertex: distance to the ground truth, metres (base64 f32).
    error_m: Option<String>,
    error_p50_m: Option<f64>,
    error_p90_m: Option<f64>,
    center_of_mass: Option<[f64; 3]>,
    contact_polygon: Option<Vec<[f64; 3]>>,
    alpha_min_deg: Option<f64>,
    alpha_min_azimuth_deg: Option<f64>,
}

/// The ground truth around a target, moved into the map frame: the true rock, its pedestal and
/// the terrain within 0.5 m of the reconstruction's bounding box (so that every part of the
/// reconstruction, ground included, has its true surface to be compared with). `None` without
/// a ground-truth rock or without the keyframe trajectories for the alignment.
fn ground_truth_in_map_frame(
    world: &World,
    target: &TargetReport,
    target_dir: &Path,
    reconstruction: &TriangleMesh,
) -> Option<TriangleMesh> {
    let rock = world
        .rocks
        .iter()
        .find(|r| Some(r.id) == target.gt_rock_id)?;
    let truth = read_tum_trajectory(&target_dir.join("keyframes_groundtruth.txt")).ok()?;
    let refined = read_tum_trajectory(&target_dir.join("keyframes_ba.txt")).ok()?;
    if truth.len() != refined.len() {
        return None;
    }
    let poses: Vec<Isometry3<f64>> = refined.iter().map(|p| p.world_from_camera).collect();
    let world_from_map = map_to_world(&truth, &poses)?;
    let mut gt = rock.mesh.clone();
    if let Some(pedestal) = &rock.pedestal {
        gt.append(pedestal);
    }
    let mut in_world = reconstruction.clone();
    in_world.transform(&world_from_map);
    gt.append(&crop_to_box(&world.terrain_mesh, &in_world, 0.5));
    gt.transform(&world_from_map.inverse());
    Some(gt)
}

/// The nearest-rank `p`-quantile of the finite `values`; `None` without any.
fn percentile(values: &[f32], p: f64) -> Option<f64> {
    let mut v: Vec<f64> = values
        .iter()
        .map(|&x| f64::from(x))
        .filter(|x| x.is_finite())
        .collect();
    scarp_slam::stats::quantile_in_place(&mut v, p)
}

fn view_data(world: Option<&World>, target: &TargetReport, target_dir: &Path) -> Option<ViewData> {
    let mesh = read_mesh(target_dir.join("mesh.ply")).ok()?;
    if mesh.faces.is_empty() {
        return None;
    }
    let fragility: Option<FragilityReport> = std::fs::read(target_dir.join("fragility.json"))
        .ok()
        .and_then(|bytes| serde_json::from_slice(&bytes).ok());
    let shown = decimate(&mesh, MAX_VIEW_TRIANGLES);
    let gt = world.and_then(|world| ground_truth_in_map_frame(world, target, target_dir, &mesh));
    let error: Option<Vec<f32>> = gt.as_ref().and_then(|gt| {
        let index = MeshDistance::new(gt, "ground truth").ok()?;
        Some(
            shown
                .positions
                .iter()
                .map(|p| index.distance(&p.cast::<f64>()) as f32)
                .collect(),
        )
    });
    let gt_shown = gt.map(|g| decimate(&g, MAX_VIEW_TRIANGLES));
    Some(ViewData {
        id: target.id,
        status: target.status.clone(),
        positions: f32_base64(shown.positions.iter().flat_map(|p| [p.x, p.y, p.z])),
        indices: u32_base64(shown.faces.iter().flatten().copied()),
        colors: (shown.colors.len() == shown.positions.len())
            .then(|| base64(&shown.colors.concat())),
        triangles_full: mesh.faces.len(),
        triangles_shown: shown.faces.len(),
        gt_positions: gt_shown
            .as_ref()
            .map(|g| f32_base64(g.positions.iter().flat_map(|p| [p.x, p.y, p.z]))),
        gt_indices: gt_shown
            .as_ref()
            .map(|g| u32_base64(g.faces.iter().flatten().copied())),
        error_p50_m: error.as_deref().and_then(|e| percentile(e, 0.5)),
        error_p90_m: error.as_deref().and_then(|e| percentile(e, 0.9)),
        error_m: error.map(f32_base64),
        center_of_mass: fragility.as_ref().map(|f| f.center_of_mass),
        contact_polygon: fragility.as_ref().map(|f| f.contact_polygon.clone()),
        alpha_min_deg: fragility.as_ref().map(|f| f.alpha_min_deg),
        alpha_min_azimuth_deg: fragility.as_ref().map(|f| f.alpha_min_azimuth_deg),
    })
}

/// The polar plot of α(θ) as inline SVG: the curve, α_min (red dot at its azimuth, dashed
/// circle), its 95% interval (shaded ring) and the true α_min where known (green dashed circle).
/// Azimuths are counter-clockwise from east (right) towards north (up), as in `fragility.json`.
pub fn polar_plot_svg(report: &FragilityReport, alpha_true_deg: Option<f64>) -> String {
    const SIZE: f64 = 320.0;
    const R: f64 = 120.0;
    let c = SIZE / 2.0;
    let finite_max = report
        .alpha_deg
        .iter()
        .copied()
        .chain([report.alpha_min_high_deg, alpha_true_deg.unwrap_or(0.0)])
        .filter(|a| a.is_finite())
        .fold(1.0_f64, f64::max);
    // Round the outer ring up to a multiple of 10°.
    let outer = (finite_max / 10.0).ceil() * 10.0;
    let radius = |alpha: f64| alpha.clamp(0.0, outer) / outer * R;
    let point = |alpha: f64, az_deg: f64| {
        let a = az_deg.to_radians();
        (c + radius(alpha) * a.cos(), c - radius(alpha) * a.sin())
    };
    let mut svg = String::new();
    let _ = write!(
        svg,
        "<svg class=\"polar\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{SIZE}\" height=\"{SIZE}\" \
viewBox=\"0 0 {SIZE} {SIZE}\" role=\"img\" aria-label=\"alpha of theta\">"
    );
    // The interval as a ring between its ends (even-odd fill).
    let (low, high) = (report.alpha_min_low_deg, report.alpha_min_high_deg);
    if low.is_finite() && high.is_finite() {
        let (r0, r1) = (radius(low), radius(high));
        let _ = write!(
            svg,
            "<path fill=\"#f4a6a6\" fill-opacity=\"0.55\" fill-rule=\"evenodd\" d=\"M{x1} {c}a{r1} {r1} 0 1 0 {d1} 0a{r1} {r1} 0 1 0 {n1} 0Z\
M{x0} {c}a{r0} {r0} 0 1 0 {d0} 0a{r0} {r0} 0 1 0 {n0} 0Z\"><title>95% interval of α_min: {low:.2}° – {high:.2}°</title></path>",
            x1 = c - r1,
            d1 = 2.0 * r1,
            n1 = -2.0 * r1,
            x0 = c - r0,
            d0 = 2.0 * r0,
            n0 = -2.0 * r0,
        );
    }
    // Grid: a ring every 10°, spokes every 30°.
    let mut ring = 10.0;
    while ring <= outer + 1e-9 {
        let _ = write!(
            svg,
            "<circle cx=\"{c}\" cy=\"{c}\" r=\"{:.2}\" fill=\"none\" stroke=\"#ccc\"/>\
<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"9\" fill=\"#888\">{ring:.0}°</text>",
            radius(ring),
            c + 2.0,
            c - radius(ring) - 2.0
        );
        ring += 10.0;
    }
    for k in 0..12 {
        let az = f64::from(k) * 30.0;
        let (x, y) = point(outer, az);
        let (tx, ty) = (
            c + (R + 14.0) * az.to_radians().cos(),
            c - (R + 14.0) * az.to_radians().sin(),
        );
        let _ = write!(
            svg,
            "<line x1=\"{c}\" y1=\"{c}\" x2=\"{x:.1}\" y2=\"{y:.1}\" stroke=\"#e2e2e2\"/>\
<text x=\"{tx:.1}\" y=\"{ty:.1}\" font-size=\"10\" text-anchor=\"middle\" dominant-baseline=\"middle\" fill=\"#555\">{az:.0}°</text>"
        );
    }
    // α(θ).
    let n = report.alpha_deg.len();
    if n > 0 {
        let pts: Vec<String> = report
            .alpha_deg
            .iter()
            .enumerate()
            .map(|(i, &a)| {
                let (x, y) = point(a, i as f64 * 360.0 / n as f64);
                format!("{x:.1},{y:.1}")
            })
            .collect();
        let _ = write!(
            svg,
            "<polygon points=\"{}\" fill=\"#4a78c2\" fill-opacity=\"0.15\" stroke=\"#1f4e9c\" stroke-width=\"1.5\"><title>α(θ)</title></polygon>",
            pts.join(" ")
        );
    }
    if let Some(truth) = alpha_true_deg.filter(|a| a.is_finite()) {
        let _ = write!(
            svg,
            "<circle cx=\"{c}\" cy=\"{c}\" r=\"{:.2}\" fill=\"none\" stroke=\"#1a9641\" stroke-width=\"1.5\" stroke-dasharray=\"2 3\"><title>true α_min {truth:.2}°</title></circle>",
            radius(truth)
        );
    }
    let _ = write!(
        svg,
        "<circle cx=\"{c}\" cy=\"{c}\" r=\"{:.2}\" fill=\"none\" stroke=\"#c0392b\" stroke-width=\"1.2\" stroke-dasharray=\"5 3\"/>",
        radius(report.alpha_min_deg)
    );
    let (mx, my) = point(report.alpha_min_deg, report.alpha_min_azimuth_deg);
    let _ = write!(
        svg,
        "<circle cx=\"{mx:.1}\" cy=\"{my:.1}\" r=\"4.5\" fill=\"#c0392b\"><title>α_min {:.2}° at θ = {:.1}°</title></circle></svg>",
        report.alpha_min_deg, report.alpha_min_azimuth_deg
    );
    svg
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("–".into(), |v| format!("{v:.digits$}"))
}

/// The interactive sections of `report.html` for the mission in `dir` (its `targets/<id>/`
/// folders must be written): the α table, then per target with a mesh its 3D view and polar
/// plot, then the scripts. Targets whose files cannot be read are left out of the views.
pub fn interactive_sections(dir: &Path, world: Option<&World>, report: &MissionReport) -> String {
    let start = std::time::Instant::now();
    let mut html = String::new();
    // The table of every target's α with its interval.
    html.push_str(
        "<h2>Fragility: α_min of every target</h2><table id=\"alpha-table\"><tr><th>id</th><th>status</th>\
<th>α_min (°)</th><th>95% interval (°)</th><th>true α_min (°)</th><th>truth in interval</th>\
<th>toppling PGA (g)</th></tr>\n",
    );
    for t in &report.targets {
        let inside = match (
            t.alpha_min_gt_deg,
            t.alpha_min_low_deg,
            t.alpha_min_high_deg,
        ) {
            (Some(truth), Some(lo), Some(hi)) => {
                if (lo..=hi).contains(&truth) {
                    "yes"
                } else {
                    "no"
                }
            }
            _ => "–",
        };
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{inside}</td><td>{}</td></tr>",
            t.id,
            t.status,
            opt(t.alpha_min_deg, 2),
            match (t.alpha_min_low_deg, t.alpha_min_high_deg) {
                (Some(lo), Some(hi)) => format!("{lo:.2} – {hi:.2}"),
                _ => "–".into(),
            },
            opt(t.alpha_min_gt_deg, 2),
            opt(t.toppling_pga_g, 3),
        );
    }
    html.push_str("</table>\n");

    let mut views = Vec::new();
    for t in &report.targets {
        let target_dir = dir.join("targets").join(t.id.to_string());
        let Some(view) = view_data(world, t, &target_dir) else {
            continue;
        };
        let fragility: Option<FragilityReport> = std::fs::read(target_dir.join("fragility.json"))
            .ok()
            .and_then(|bytes| serde_json::from_slice(&bytes).ok());
        let id = t.id;
        let _ = write!(
            html,
            "<section class=\"target\" id=\"target-{id}\"><h3>Target {id} ({status})</h3>\n\
<div class=\"row\"><div class=\"viewer\"><canvas id=\"view-{id}\" width=\"560\" height=\"420\"></canvas>\
<div class=\"controls\">drag: orbit · wheel: zoom · double-click: reset<br>\
<label><input type=\"checkbox\" data-target=\"{id}\" data-layer=\"contact\" checked> contact polygon</label> \
<label><input type=\"checkbox\" data-target=\"{id}\" data-layer=\"com\" checked> centre of mass</label> ",
            status = t.status
        );
        if view.gt_positions.is_some() {
            let _ = write!(
                html,
                "<label><input type=\"checkbox\" data-target=\"{id}\" data-layer=\"gt\"> ground-truth mesh</label><br>\
colours: <label><input type=\"radio\" name=\"colour-{id}\" data-target=\"{id}\" data-colour=\"camera\" checked> camera</label> \
<label><input type=\"radio\" name=\"colour-{id}\" data-target=\"{id}\" data-colour=\"error\"> distance to ground truth</label>\
<div class=\"legend\" id=\"legend-{id}\"></div>"
            );
        }
        let _ = write!(
            html,
            "</div></div><div class=\"polar-box\"><b>α(θ)</b> (°; θ counter-clockwise from east, north up)<br>{}\
<div class=\"polar-legend\"><span style=\"color:#1f4e9c\">━ α(θ)</span> <span style=\"color:#c0392b\">● ╌ α_min</span> \
<span style=\"background:#f4a6a6\">&nbsp;95% interval&nbsp;</span>{}</div></div></div>",
            fragility.as_ref().map_or_else(
                || "<p>no fragility analysis</p>".to_string(),
                |f| polar_plot_svg(f, t.alpha_min_gt_deg)
            ),
            if t.alpha_min_gt_deg.is_some() {
                " <span style=\"color:#1a9641\">╌ true α_min</span>"
            } else {
                ""
            }
        );
        let _ = writeln!(
            html,
            "<p class=\"note\">{} of {} triangles shown{}.</p></section>",
            view.triangles_shown,
            view.triangles_full,
            match (view.error_p50_m, view.error_p90_m) {
                (Some(p50), Some(p90)) => format!(
                    "; distance of the shown vertices to the ground truth: median {:.1} mm, p90 {:.1} mm",
                    p50 * 1e3,
                    p90 * 1e3
                ),
                _ => String::new(),
            }
        );
        views.push(view);
    }
    tracing::info!(
        "report.html: {} interactive target view(s) prepared in {:.2} s",
        views.len(),
        start.elapsed().as_secs_f64()
    );
    if views.is_empty() {
        return html;
    }
    // `</` cannot appear inside a script element; JSON allows `<\/` for it.
    let json = serde_json::to_string(&views)
        .unwrap_or_else(|_| "[]".into())
        .replace("</", "<\\/");
    let _ = write!(
        html,
        "<script type=\"application/json\" id=\"scarp-view-data\">{json}</script>\n\
<script>{THREE_JS}</script>\n<script>{VIEWER_JS}</script>\n"
    );
    html
}

/// CSS of the interactive sections.
pub const STYLE: &str = ".row{display:flex;flex-wrap:wrap;gap:16px;align-items:flex-start}\
.viewer canvas{border:1px solid #bbb;background:#f7f7f7;cursor:grab;touch-action:none}\
.controls{font-size:90%;margin-top:4px;max-width:560px}.legend{margin-top:4px;height:14px;font-size:80%}\
.polar-box{font-size:90%}.polar-legend{font-size:85%}.note{font-size:85%;color:#555}";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (input, expected) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(input.as_bytes()), expected, "{input}");
        }
    }

    #[test]
    fn polar_plot_marks_alpha_min_at_its_azimuth() {
        let mesh = TriangleMesh::cuboid(Point3::new(-0.2, -0.2, 0.0), Point3::new(0.2, 0.2, 1.0));
        let report = crate::fragility::analyze(
            &mesh,
            crate::fragility::ContactSpec::Auto,
            &crate::fragility::FragilityConfig::default(),
        )
        .unwrap();
        let svg = polar_plot_svg(&report, Some(21.8));
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>"));
        assert_eq!(svg.matches("<polygon").count(), 1);
        // α_min = atan(0.4) ≈ 21.8° on an outer ring of 30°: the marker sits 21.8/30 of the
        // 120 px radius from the centre (160, 160), in the direction of its azimuth.
        let a = report.alpha_min_azimuth_deg.to_radians();
        let r = report.alpha_min_deg / 30.0 * 120.0;
        let marker = format!(
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4.5\"",
            160.0 + r * a.cos(),
            160.0 - r * a.sin()
        );
        assert!(svg.contains(&marker), "{marker} not in {svg}");
        assert!(svg.contains("true α_min 21.80°"));
    }

    #[test]
    fn decimation_caps_the_triangles_and_keeps_the_shape() {
        let mut sphere = TriangleMesh::icosphere(5); // 20 480 triangles
        sphere.colors = vec![[200, 100, 50]; sphere.positions.len()];
        let small = decimate(&sphere, 2_000);
        assert!(
            small.faces.len() <= 2_000 && small.faces.len() > 500,
            "{}",
            small.faces.len()
        );
        assert_eq!(small.colors.len(), small.positions.len());
        assert!(small.colors.iter().all(|c| *c == [200, 100, 50]));
        for p in &small.positions {
            let r = p.coords.norm();
            assert!((0.9..=1.01).contains(&r), "radius {r}");
        }
        assert!(
            small
                .faces
                .iter()
                .flatten()
                .all(|&v| (v as usize) < small.positions.len())
        );
        // Small enough already: unchanged.
        assert_eq!(decimate(&sphere, 30_000), sphere);
    }
}
