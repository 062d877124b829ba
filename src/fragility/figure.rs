//! The fragility figure: on the left the rock's side silhouette in the vertical plane of the
//! α_min azimuth, with the centre of mass, the contact, the vertical through the centre of mass
//! and the α_min line to the rocking point; on the right a polar plot of α(θ).
//!
//! Drawn with `plotters` without system fonts: SVG output carries text labels (the viewer
//! renders them), PNG output is drawn without text. Files are written to a temporary name in
//! the same folder and renamed.

use std::path::Path;

use nalgebra::{Point2, Vector2};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::section::{Side, section_segments};
use super::topology::Solid;
use super::{FragilityAnalysis, FragilityError, azimuth_direction};

/// Width of the figure in pixels (two square panels).
pub const FIGURE_WIDTH_PX: u32 = 1200;
/// Height of the figure in pixels.
pub const FIGURE_HEIGHT_PX: u32 = 600;

/// Outline of a solid's side view in the vertical plane along `u`: for `levels` heights between
/// `z_lo` and `z_hi`, the extreme horizontal offsets (s = (p − origin)·u) of its section.
/// Returned as a closed polygon of `(s, z)`: left side upwards, then right side downwards.
pub(crate) fn silhouette(
    solid: &Solid,
    origin: &Point2<f64>,
    u: &Vector2<f64>,
    z_lo: f64,
    z_hi: f64,
    levels: usize,
) -> Vec<(f64, f64)> {
    let mut left = Vec::new();
    let mut right = Vec::new();
    for i in 0..=levels {
        // Sample just inside both ends so the end sections exist.
        let t = (i as f64 + 0.5) / (levels as f64 + 1.0);
        let z = z_lo + t * (z_hi - z_lo);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (a, b) in section_segments(solid, z, Side::Above) {
            for p in [a, b] {
                let s = (p.xy() - origin).dot(u);
                lo = lo.min(s);
                hi = hi.max(s);
            }
        }
        if lo <= hi {
            left.push((lo, z));
            right.push((hi, z));
        }
    }
    right.reverse();
    left.extend(right);
    left
}

/// Maps data coordinates to pixels with equal scales on both axes.
struct View {
    origin: (f64, f64),
    scale: f64,
    offset: (f64, f64),
}

impl View {
    fn fit(x: (f64, f64), y: (f64, f64), size: (f64, f64), margin: f64) -> Self {
        let w = (x.1 - x.0).max(1e-9);
        let h = (y.1 - y.0).max(1e-9);
        let scale = ((size.0 - 2.0 * margin) / w).min((size.1 - 2.0 * margin) / h);
        let offset = ((size.0 - scale * w) / 2.0, (size.1 - scale * h) / 2.0);
        Self {
            origin: (x.0, y.1),
            scale,
            offset,
        }
    }

    fn px(&self, x: f64, y: f64) -> (i32, i32) {
        (
            (self.offset.0 + (x - self.origin.0) * self.scale).round() as i32,
            (self.offset.1 + (self.origin.1 - y) * self.scale).round() as i32,
        )
    }
}

type DrawResult = Result<(), String>;

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

fn label<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: bool,
    s: &str,
    at: (i32, i32),
    size: u32,
    color: RGBColor,
) -> DrawResult {
    if text {
        area.draw(&Text::new(
            s.to_string(),
            at,
            ("sans-serif", size).into_font().color(&color),
        ))
        .map_err(err)?;
    }
    Ok(())
}

/// Draws the side view: silhouette, contact, centre of mass, vertical and α_min line.
fn draw_side<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    a: &FragilityAnalysis,
    text: bool,
) -> DrawResult {
    let u = azimuth_direction(a.alpha_min_azimuth);
    let origin = a.com.xy();
    let h = a.contact_height;
    let (_, top) = a.rock.z_range().unwrap_or((h, h + 1.0));
    let rock = silhouette(&a.rock, &origin, &u, h, top, 160);
    let depth = 0.5 * (top - h);
    let support = a
        .support
        .as_ref()
        .and_then(|s| s.z_range().map(|(lo, _)| (s, lo)))
        .filter(|(_, lo)| *lo < h)
        .map(|(s, lo)| silhouette(s, &origin, &u, lo.max(h - depth), h, 80))
        .unwrap_or_default();
    let xs = rock.iter().chain(&support).map(|p| p.0);
    let (x0, x1) = xs.fold((0.0f64, 0.0f64), |(lo, hi), x| (lo.min(x), hi.max(x)));
    let z0 = support.iter().map(|p| p.1).fold(h, f64::min);
    let (w, hpx) = area.dim_in_pixel();
    let view = View::fit((x0, x1), (z0, top), (w as f64, hpx as f64), 50.0);

    let grey = RGBColor(150, 150, 150);
    if support.len() >= 3 {
        let pts: Vec<(i32, i32)> = support.iter().map(|p| view.px(p.0, p.1)).collect();
        area.draw(&Polygon::new(pts, RGBColor(225, 215, 195).filled()))
            .map_err(err)?;
    }
    if rock.len() >= 3 {
        let pts: Vec<(i32, i32)> = rock.iter().map(|p| view.px(p.0, p.1)).collect();
        area.draw(&Polygon::new(pts.clone(), RGBColor(200, 200, 205).filled()))
            .map_err(err)?;
        let mut closed = pts;
        closed.push(closed[0]);
        area.draw(&PathElement::new(closed, grey.stroke_width(1)))
            .map_err(err)?;
    }
    // Contact extent along u.
    let along = |dir: Vector2<f64>| {
        a.contact_hull
            .iter()
            .map(|p| (p - origin).dot(&dir))
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let (s_plus, s_minus) = (along(u), -along(-u));
    area.draw(&PathElement::new(
        vec![view.px(s_minus, h), view.px(s_plus, h)],
        BLACK.stroke_width(4),
    ))
    .map_err(err)?;
    // Vertical through the centre of mass, dashed.
    let com_z = a.com.z;
    let dashes = 24;
    for k in (0..dashes).step_by(2) {
        let za = h + (com_z - h) * 1.3 * k as f64 / dashes as f64;
        let zb = h + (com_z - h) * 1.3 * (k + 1) as f64 / dashes as f64;
        area.draw(&PathElement::new(
            vec![view.px(0.0, za), view.px(0.0, zb)],
            BLUE.stroke_width(1),
        ))
        .map_err(err)?;
    }
    // α_min line from the centre of mass to the rocking point.
    area.draw(&PathElement::new(
        vec![view.px(0.0, com_z), view.px(s_plus, h)],
        RED.stroke_width(2),
    ))
    .map_err(err)?;
    area.draw(&Circle::new(view.px(0.0, com_z), 6, BLUE.filled()))
        .map_err(err)?;
    area.draw(&Circle::new(view.px(s_plus, h), 4, RED.filled()))
        .map_err(err)?;
    let r = &a.report;
    label(
        area,
        text,
        &format!(
            "side view towards azimuth {:.1}°: α_min = {:.2}° (±{:.2}°), PGA = {:.3} g",
            r.alpha_min_azimuth_deg, r.alpha_min_deg, r.alpha_min_spread_deg, r.toppling_pga_g
        ),
        (10, 10),
        16,
        BLACK,
    )?;
    let (cx, cy) = view.px(0.0, com_z);
    label(area, text, "centre of mass", (cx + 10, cy - 20), 14, BLUE)?;
    let (px, py) = view.px(s_plus, h);
    label(area, text, "rocking point", (px + 8, py + 6), 14, RED)?;
    label(
        area,
        text,
        &format!(
            "contact at {:.3} m, {:.4} m²",
            r.contact_height_m, r.contact_area_m2
        ),
        (10, hpx as i32 - 24),
        14,
        BLACK,
    )?;
    Ok(())
}

/// Draws the polar plot of α(θ) (radius α in degrees, angle θ counter-clockwise from +x).
fn draw_polar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    a: &FragilityAnalysis,
    text: bool,
) -> DrawResult {
    let r = &a.report;
    let (w, h) = area.dim_in_pixel();
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0 + 10.0);
    let radius_px = 0.4 * w.min(h) as f64;
    let max_alpha = r.alpha_deg.iter().copied().fold(1.0f64, f64::max);
    let ring_step = if max_alpha > 40.0 { 20.0 } else { 10.0 };
    let outer = (max_alpha / ring_step).ceil() * ring_step;
    let px = |alpha: f64, theta_deg: f64| {
        let rho = alpha.max(0.0) / outer * radius_px;
        let t = theta_deg.to_radians();
        (
            (cx + rho * t.cos()).round() as i32,
            (cy - rho * t.sin()).round() as i32,
        )
    };
    let light = RGBColor(210, 210, 210);
    let mut ring = ring_step;
    while ring <= outer + 1e-9 {
        let pts: Vec<(i32, i32)> = (0..=120).map(|k| px(ring, k as f64 * 3.0)).collect();
        area.draw(&PathElement::new(pts, light.stroke_width(1)))
            .map_err(err)?;
        let (lx, ly) = px(ring, 80.0);
        label(
            area,
            text,
            &format!("{ring:.0}°"),
            (lx + 3, ly),
            12,
            RGBColor(120, 120, 120),
        )?;
        ring += ring_step;
    }
    for k in 0..12 {
        let theta = k as f64 * 30.0;
        area.draw(&PathElement::new(
            vec![px(0.0, theta), px(outer, theta)],
            light.stroke_width(1),
        ))
        .map_err(err)?;
        let (lx, ly) = px(outer * 1.08, theta);
        label(
            area,
            text,
            &format!("{theta:.0}°"),
            (lx - 12, ly - 6),
            12,
            BLACK,
        )?;
    }
    let n = r.alpha_deg.len();
    let mut curve: Vec<(i32, i32)> = r
        .alpha_deg
        .iter()
        .enumerate()
        .map(|(i, &alpha)| px(alpha, i as f64 * 360.0 / n as f64))
        .collect();
    if let Some(&first) = curve.first() {
        curve.push(first);
    }
    area.draw(&PathElement::new(curve, BLUE.stroke_width(2)))
        .map_err(err)?;
    area.draw(&Circle::new(
        px(r.alpha_min_deg, r.alpha_min_azimuth_deg),
        6,
        RED.filled(),
    ))
    .map_err(err)?;
    label(
        area,
        text,
        "α(θ), degrees; θ counter-clockwise from +x (east)",
        (10, 10),
        16,
        BLACK,
    )?;
    Ok(())
}

fn draw_all<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    a: &FragilityAnalysis,
    text: bool,
) -> DrawResult {
    root.fill(&WHITE).map_err(err)?;
    let (left, right) = root.split_horizontally(FIGURE_WIDTH_PX / 2);
    draw_side(&left, a, text)?;
    draw_polar(&right, a, text)?;
    root.present().map_err(err)
}

/// Renders the figure as SVG text (with labels).
///
/// # Errors
/// [`FragilityError::Figure`] if drawing fails.
pub fn render_svg(analysis: &FragilityAnalysis) -> Result<String, FragilityError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (FIGURE_WIDTH_PX, FIGURE_HEIGHT_PX))
            .into_drawing_area();
        draw_all(root, analysis, true).map_err(|reason| FragilityError::Figure {
            path: "<svg>".into(),
            reason,
        })?;
    }
    Ok(svg)
}

/// Renders the figure as an RGB8 pixel buffer (row-major, no text labels).
///
/// # Errors
/// [`FragilityError::Figure`] if drawing fails.
pub fn render_rgb(analysis: &FragilityAnalysis) -> Result<Vec<u8>, FragilityError> {
    let mut buf = vec![255u8; (FIGURE_WIDTH_PX * FIGURE_HEIGHT_PX * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (FIGURE_WIDTH_PX, FIGURE_HEIGHT_PX))
            .into_drawing_area();
        draw_all(root, analysis, false).map_err(|reason| FragilityError::Figure {
            path: "<png>".into(),
            reason,
        })?;
    }
    Ok(buf)
}

/// Writes the figure to `path`, as SVG (with text labels) or PNG (without text) according to
/// its extension, atomically (temporary file, then rename).
///
/// # Errors
/// [`FragilityError::Figure`] for another extension, a drawing failure or an I/O error, naming
/// the path.
pub fn write_figure(analysis: &FragilityAnalysis, path: &Path) -> Result<(), FragilityError> {
    let fail = |reason: String| FragilityError::Figure {
        path: path.display().to_string(),
        reason,
    };
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let bytes = match ext.as_str() {
        "svg" => render_svg(analysis)?.into_bytes(),
        "png" => {
            let rgb = render_rgb(analysis)?;
            let image = image::RgbImage::from_raw(FIGURE_WIDTH_PX, FIGURE_HEIGHT_PX, rgb)
                .ok_or_else(|| fail("pixel buffer has the wrong size".into()))?;
            let mut png = std::io::Cursor::new(Vec::new());
            image
                .write_to(&mut png, image::ImageFormat::Png)
                .map_err(|e| fail(e.to_string()))?;
            png.into_inner()
        }
        _ => {
            return Err(fail(format!(
                "unsupported figure extension `{ext}` (use .svg or .png)"
            )));
        }
    };
    scarp_export::atomic::write_bytes_atomically(path, &bytes).map_err(|e| fail(e.to_string()))
}
