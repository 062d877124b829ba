//! Top and side view PNGs of a mapping plan: the target cylinder, the rings, the planned
//! trajectory, the flown track and the terrain profile.
//!
//! Drawn with plotters' bitmap backend into memory and encoded with `image`, so no font or
//! system library is needed. There is no text: a light grid every `grid_spacing_m` metres and
//! a legend of colours in the docs stand in for labels.
//!
//! Colours: terrain grey (top, lighter is higher) or brown (side profile), scan bands light blue, cylinder black, rings blue, waypoints blue dots,
//! planned trajectory red, flown track green.

use nalgebra::Point3;
use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::clearance::Environment;
use crate::error::{PlanError, check_positive};
use crate::geometry::VerticalCylinder;
use crate::mapping_rings::Ring;

/// Image settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlotConfig {
    /// Image width (pixels). Default 800.
    pub width_px: u32,
    /// Image height (pixels). Default 800.
    pub height_px: u32,
    /// Margin around the content (metres). Default 2.
    pub margin_m: f64,
    /// Grid spacing (metres). Default 1.
    pub grid_spacing_m: f64,
}

impl Default for PlotConfig {
    fn default() -> Self {
        Self {
            width_px: 800,
            height_px: 800,
            margin_m: 2.0,
            grid_spacing_m: 1.0,
        }
    }
}

/// What to draw (world ENU metres).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlotScene {
    /// The target's bounding cylinder.
    pub cylinder: Option<VerticalCylinder>,
    /// Mapping rings.
    pub rings: Vec<Ring>,
    /// Path waypoints.
    pub waypoints: Vec<Point3<f64>>,
    /// Planned trajectory, densely sampled.
    pub trajectory: Vec<Point3<f64>>,
    /// Flown track.
    pub flown: Vec<Point3<f64>>,
}

/// Maps world metres to pixels with equal scale on both axes.
struct View {
    min: (f64, f64),
    scale: f64,
    height_px: u32,
    offset: (f64, f64),
}

impl View {
    fn fit(points: &[(f64, f64)], cfg: &PlotConfig) -> Self {
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in points.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
        }
        let (x0, x1, y0, y1) = (
            x0 - cfg.margin_m,
            x1 + cfg.margin_m,
            y0 - cfg.margin_m,
            y1 + cfg.margin_m,
        );
        let sx = f64::from(cfg.width_px) / (x1 - x0).max(1e-6);
        let sy = f64::from(cfg.height_px) / (y1 - y0).max(1e-6);
        let scale = sx.min(sy);
        // Centre the content.
        let offset = (
            0.5 * (f64::from(cfg.width_px) - scale * (x1 - x0)),
            0.5 * (f64::from(cfg.height_px) - scale * (y1 - y0)),
        );
        Self {
            min: (x0, y0),
            scale,
            height_px: cfg.height_px,
            offset,
        }
    }

    fn px(&self, x: f64, y: f64) -> (i32, i32) {
        let u = self.offset.0 + (x - self.min.0) * self.scale;
        let v = f64::from(self.height_px) - (self.offset.1 + (y - self.min.1) * self.scale);
        (u.round() as i32, v.round() as i32)
    }

    fn world_range(&self, cfg: &PlotConfig) -> ((f64, f64), (f64, f64)) {
        let x0 = self.min.0 - self.offset.0 / self.scale;
        let y0 = self.min.1 - self.offset.1 / self.scale;
        (
            (x0, x0 + f64::from(cfg.width_px) / self.scale),
            (y0, y0 + f64::from(cfg.height_px) / self.scale),
        )
    }
}

fn plot_err(e: impl std::fmt::Display) -> PlanError {
    PlanError::Output {
        path: "(in memory)".into(),
        reason: format!("drawing failed: {e}"),
    }
}

fn draw_grid<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    view: &View,
    cfg: &PlotConfig,
) -> Result<(), PlanError> {
    let ((x0, x1), (y0, y1)) = view.world_range(cfg);
    let g = cfg.grid_spacing_m;
    let style = RGBColor(228, 228, 228).stroke_width(1);
    let mut x = (x0 / g).ceil() * g;
    while x <= x1 && (x1 - x0) / g < 2000.0 {
        area.draw(&PathElement::new(
            vec![view.px(x, y0), view.px(x, y1)],
            style,
        ))
        .map_err(plot_err)?;
        x += g;
    }
    let mut y = (y0 / g).ceil() * g;
    while y <= y1 && (y1 - y0) / g < 2000.0 {
        area.draw(&PathElement::new(
            vec![view.px(x0, y), view.px(x1, y)],
            style,
        ))
        .map_err(plot_err)?;
        y += g;
    }
    Ok(())
}

fn draw_polyline<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    view: &View,
    pts: impl Iterator<Item = (f64, f64)>,
    style: ShapeStyle,
) -> Result<(), PlanError> {
    let px: Vec<(i32, i32)> = pts.map(|(x, y)| view.px(x, y)).collect();
    if px.len() >= 2 {
        area.draw(&PathElement::new(px, style)).map_err(plot_err)?;
    }
    Ok(())
}

/// Shades the terrain height in grey (lighter is higher) in 4-pixel blocks.
fn shade_terrain<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    view: &View,
    env: &Environment,
    cfg: &PlotConfig,
) -> Result<(), PlanError> {
    let Some(t) = env.terrain() else {
        return Ok(());
    };
    let (lo, hi) = t.height_range_m();
    let span = (hi - lo).max(1e-6);
    let ((x0, x1), (y0, y1)) = view.world_range(cfg);
    let block = 4u32;
    let (nu, nv) = (cfg.width_px / block + 1, cfg.height_px / block + 1);
    for j in 0..nv {
        for i in 0..nu {
            let x = x0 + (x1 - x0) * (f64::from(i) + 0.5) / f64::from(nu);
            let y = y1 - (y1 - y0) * (f64::from(j) + 0.5) / f64::from(nv);
            if let Some(h) = env.terrain_height_at(x, y) {
                let g = (200.0 + 50.0 * (h - lo) / span) as u8;
                let (u, v) = ((i * block) as i32, (j * block) as i32);
                area.draw(&Rectangle::new(
                    [(u, v), (u + block as i32, v + block as i32)],
                    RGBColor(g, g, g).filled(),
                ))
                .map_err(plot_err)?;
            }
        }
    }
    Ok(())
}

/// Renders the top view (x east right, y north up) as RGB8 pixels, row-major. With `env`, the
/// terrain height is shaded in grey (lighter is higher).
pub fn render_top_view(
    scene: &PlotScene,
    env: Option<&Environment>,
    cfg: &PlotConfig,
) -> Result<Vec<u8>, PlanError> {
    validate(cfg)?;
    let mut extent: Vec<(f64, f64)> = Vec::new();
    for r in &scene.rings {
        extent.push((r.center_x_m - r.radius_m, r.center_y_m - r.radius_m));
        extent.push((r.center_x_m + r.radius_m, r.center_y_m + r.radius_m));
    }
    extent.extend(
        scene
            .waypoints
            .iter()
            .chain(&scene.trajectory)
            .chain(&scene.flown)
            .map(|p| (p.x, p.y)),
    );
    if let Some(c) = &scene.cylinder {
        extent.push((c.center_x_m - c.radius_m, c.center_y_m - c.radius_m));
        extent.push((c.center_x_m + c.radius_m, c.center_y_m + c.radius_m));
    }
    let view = View::fit(&extent, cfg);
    let mut buf = vec![255u8; (cfg.width_px as usize) * (cfg.height_px as usize) * 3];
    {
        let area =
            BitMapBackend::with_buffer(&mut buf, (cfg.width_px, cfg.height_px)).into_drawing_area();
        area.fill(&WHITE).map_err(plot_err)?;
        if let Some(env) = env {
            shade_terrain(&area, &view, env, cfg)?;
        }
        draw_grid(&area, &view, cfg)?;
        let circle = |cx: f64, cy: f64, r: f64| {
            (0..=128).map(move |k| {
                let a = std::f64::consts::TAU * k as f64 / 128.0;
                (cx + r * a.cos(), cy + r * a.sin())
            })
        };
        if let Some(c) = &scene.cylinder {
            draw_polyline(
                &area,
                &view,
                circle(c.center_x_m, c.center_y_m, c.radius_m),
                BLACK.stroke_width(2),
            )?;
        }
        for r in &scene.rings {
            draw_polyline(
                &area,
                &view,
                circle(r.center_x_m, r.center_y_m, r.radius_m),
                BLUE.stroke_width(1),
            )?;
        }
        draw_polyline(
            &area,
            &view,
            scene.trajectory.iter().map(|p| (p.x, p.y)),
            RED.stroke_width(2),
        )?;
        draw_polyline(
            &area,
            &view,
            scene.flown.iter().map(|p| (p.x, p.y)),
            GREEN.stroke_width(1),
        )?;
        for p in &scene.waypoints {
            area.draw(&Circle::new(view.px(p.x, p.y), 3, BLUE.filled()))
                .map_err(plot_err)?;
        }
        area.present().map_err(plot_err)?;
    }
    Ok(buf)
}

/// Renders the side view (x east right, z up) as RGB8 pixels, row-major. With `env`, the
/// terrain profile along the line y = (cylinder centre y, or 0) is drawn in brown.
pub fn render_side_view(
    scene: &PlotScene,
    env: Option<&Environment>,
    cfg: &PlotConfig,
) -> Result<Vec<u8>, PlanError> {
    validate(cfg)?;
    let mut extent: Vec<(f64, f64)> = Vec::new();
    for r in &scene.rings {
        extent.push((r.center_x_m - r.radius_m, r.z_m));
        extent.push((r.center_x_m + r.radius_m, r.z_m));
    }
    extent.extend(
        scene
            .waypoints
            .iter()
            .chain(&scene.trajectory)
            .chain(&scene.flown)
            .map(|p| (p.x, p.z)),
    );
    if let Some(c) = &scene.cylinder {
        extent.push((c.center_x_m - c.radius_m, c.z_bottom_m));
        extent.push((c.center_x_m + c.radius_m, c.z_top_m));
    }
    let view = View::fit(&extent, cfg);
    let ((x0, x1), _) = view.world_range(cfg);
    let profile_y = scene.cylinder.map_or(0.0, |c| c.center_y_m);
    let mut buf = vec![255u8; (cfg.width_px as usize) * (cfg.height_px as usize) * 3];
    {
        let area =
            BitMapBackend::with_buffer(&mut buf, (cfg.width_px, cfg.height_px)).into_drawing_area();
        area.fill(&WHITE).map_err(plot_err)?;
        draw_grid(&area, &view, cfg)?;
        if let Some(env) = env {
            let n = 400;
            let pts: Vec<(f64, f64)> = (0..=n)
                .filter_map(|k| {
                    let x = x0 + (x1 - x0) * k as f64 / n as f64;
                    env.terrain_height_at(x, profile_y).map(|z| (x, z))
                })
                .collect();
            draw_polyline(
                &area,
                &view,
                pts.into_iter(),
                RGBColor(140, 90, 40).stroke_width(2),
            )?;
        }
        if let Some(c) = &scene.cylinder {
            let (a, b) = (
                view.px(c.center_x_m - c.radius_m, c.z_top_m),
                view.px(c.center_x_m + c.radius_m, c.z_bottom_m),
            );
            area.draw(&Rectangle::new([a, b], BLACK.stroke_width(2)))
                .map_err(plot_err)?;
        }
        for r in &scene.rings {
            draw_polyline(
                &area,
                &view,
                [
                    (r.center_x_m - r.radius_m, r.z_m),
                    (r.center_x_m + r.radius_m, r.z_m),
                ]
                .into_iter(),
                BLUE.stroke_width(1),
            )?;
            // The ring's scan band on the near cylinder surface, as a thick bar.
            if let Some(c) = &scene.cylinder {
                let x = c.center_x_m + c.radius_m;
                draw_polyline(
                    &area,
                    &view,
                    [(x, r.band_bottom_m), (x, r.band_top_m)].into_iter(),
                    RGBColor(90, 140, 255).stroke_width(4),
                )?;
            }
        }
        draw_polyline(
            &area,
            &view,
            scene.trajectory.iter().map(|p| (p.x, p.z)),
            RED.stroke_width(2),
        )?;
        draw_polyline(
            &area,
            &view,
            scene.flown.iter().map(|p| (p.x, p.z)),
            GREEN.stroke_width(1),
        )?;
        for p in &scene.waypoints {
            area.draw(&Circle::new(view.px(p.x, p.z), 3, BLUE.filled()))
                .map_err(plot_err)?;
        }
        area.present().map_err(plot_err)?;
    }
    Ok(buf)
}

fn validate(cfg: &PlotConfig) -> Result<(), PlanError> {
    check_positive("plot.width_px", f64::from(cfg.width_px))?;
    check_positive("plot.height_px", f64::from(cfg.height_px))?;
    check_positive("plot.grid_spacing_m", cfg.grid_spacing_m)?;
    crate::error::check_range("plot.margin_m", cfg.margin_m, 0.0, 1e6)?;
    if cfg.width_px > 16384 || cfg.height_px > 16384 {
        return Err(PlanError::InvalidParameter {
            field: "plot.width_px".into(),
            value: f64::from(cfg.width_px.max(cfg.height_px)),
            reason: "images are limited to 16384 pixels a side".into(),
        });
    }
    Ok(())
}

/// Encodes RGB8 pixels as PNG at `path`, writing a temporary file first and renaming it, so a
/// crash never leaves half a file. Fails with the I/O or encoder error.
pub fn write_png(path: &std::path::Path, rgb: &[u8], cfg: &PlotConfig) -> Result<(), PlanError> {
    let io_err = |reason: String| PlanError::Output {
        path: path.display().to_string(),
        reason,
    };
    let img = image::RgbImage::from_raw(cfg.width_px, cfg.height_px, rgb.to_vec())
        .ok_or_else(|| io_err("pixel buffer does not match the image size".into()))?;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    img.save_with_format(&tmp, image::ImageFormat::Png)
        .map_err(|e| io_err(format!("cannot write PNG: {e}")))?;
    std::fs::rename(&tmp, path)
        .map_err(|e| io_err(format!("cannot rename {}: {e}", tmp.display())))?;
    Ok(())
}

/// Renders and writes the top view to `path` (see [`render_top_view`], [`write_png`]).
pub fn write_top_view_png(
    path: &std::path::Path,
    scene: &PlotScene,
    env: Option<&Environment>,
    cfg: &PlotConfig,
) -> Result<(), PlanError> {
    write_png(path, &render_top_view(scene, env, cfg)?, cfg)
}

/// Renders and writes the side view to `path` (see [`render_side_view`], [`write_png`]).
pub fn write_side_view_png(
    path: &std::path::Path,
    scene: &PlotScene,
    env: Option<&Environment>,
    cfg: &PlotConfig,
) -> Result<(), PlanError> {
    write_png(path, &render_side_view(scene, env, cfg)?, cfg)
}
