//! Terrain: a regular heightfield (DEM), procedural fault-scarp generation, ESRI ASCII grid
//! reading, and the triangle mesh the renderer draws.

use std::path::Path;

use nalgebra::{Point3, Vector3};
use scarp_slam::TriangleMesh;
use serde::{Deserialize, Serialize};

use crate::DatasetError;
use crate::noise::fbm_2d;
pub use scarp_slam::geometry::Heightfield;

/// Parameters of the procedural fault-scarp terrain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProceduralTerrain {
    /// Seed of the roughness noise.
    pub seed: u64,
    /// Side of the square terrain, metres, centred on the world origin. Default 120.
    pub size_m: f64,
    /// Grid spacing, metres. Default 0.5.
    pub resolution_m: f64,
    /// Vertical offset across the fault scarp, metres. Default 4.
    pub scarp_height_m: f64,
    /// Azimuth of the fault trace, degrees clockwise from north. Default 30.
    pub scarp_strike_deg: f64,
    /// Horizontal width of the scarp's slope (tanh scale), metres. Default 6.
    pub scarp_width_m: f64,
    /// Signed distance of the fault trace from the world origin, metres (positive toward the
    /// upthrown side). Default 25, which keeps the scarp clear of the default targets.
    pub scarp_offset_m: f64,
    /// Amplitude of the fractal roughness, metres. Default 0.8.
    pub roughness_m: f64,
    /// Wavelength of the roughness's first octave, metres. Default 25.
    pub roughness_wavelength_m: f64,
}

impl Default for ProceduralTerrain {
    fn default() -> Self {
        Self {
            seed: 7,
            size_m: 120.0,
            resolution_m: 0.5,
            scarp_height_m: 4.0,
            scarp_strike_deg: 30.0,
            scarp_width_m: 6.0,
            scarp_offset_m: 25.0,
            roughness_m: 0.8,
            roughness_wavelength_m: 25.0,
        }
    }
}

impl ProceduralTerrain {
    /// The terrain height at (x, y), metres: a tanh fault scarp plus fractal roughness.
    pub fn height_at(&self, x_m: f64, y_m: f64) -> f64 {
        let strike = self.scarp_strike_deg.to_radians();
        // Unit normal to the trace (trace direction is (sin, cos) in ENU).
        let distance = x_m * strike.cos() - y_m * strike.sin() - self.scarp_offset_m;
        let scarp = 0.5 * self.scarp_height_m * (distance / self.scarp_width_m.max(1e-6)).tanh();
        let rough = f64::from(fbm_2d(self.seed, x_m, y_m, self.roughness_wavelength_m, 6));
        scarp + self.roughness_m * rough
    }

    /// Samples the terrain on its grid.
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] for a non-positive size or resolution, or a grid over 16 M
    /// samples.
    pub fn generate(&self) -> Result<Heightfield, DatasetError> {
        if !(self.size_m > 0.0 && self.resolution_m > 0.0) {
            return Err(DatasetError::invalid(
                "terrain.procedural",
                "size_m and resolution_m must be positive",
            ));
        }
        let n = (self.size_m / self.resolution_m).round() as usize + 1;
        if n * n > 16_000_000 {
            return Err(DatasetError::invalid(
                "terrain.procedural",
                format!("{n}×{n} samples is too many; raise resolution_m"),
            ));
        }
        let origin = -self.size_m / 2.0;
        let heights_m = (0..n * n)
            .map(|k| {
                let (i, j) = (k % n, k / n);
                mesh_precision(self.height_at(
                    origin + i as f64 * self.resolution_m,
                    origin + j as f64 * self.resolution_m,
                ))
            })
            .collect();
        Ok(Heightfield {
            origin_x_m: origin,
            origin_y_m: origin,
            spacing_m: self.resolution_m,
            nx: n,
            ny: n,
            heights_m,
        })
    }
}

/// The widest grid [`read_esri_ascii`] accepts, metres: Earth's quarter meridian. Wider, the
/// f32 vertices of its mesh lose all precision.
const MAX_GRID_EXTENT_M: f64 = 1.0e7;

/// `height_m` rounded to the f32 precision of the terrain mesh's vertices, so that the
/// heightfield the planner and the clearance checks read is the very surface the renderer draws.
fn mesh_precision(height_m: f64) -> f64 {
    f64::from(height_m as f32)
}

/// `heightfield` as a triangle mesh in world coordinates, two triangles a cell, wound
/// counter-clockwise seen from above, with normals from central differences.
pub fn terrain_mesh(heightfield: &Heightfield) -> TriangleMesh {
    let hf = heightfield;
    let (nx, ny) = (hf.nx, hf.ny);
    let sample = |i: usize, j: usize| hf.node(i, j) as f32;
    let mut mesh = TriangleMesh::default();
    mesh.positions.reserve(nx * ny);
    mesh.normals.reserve(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            mesh.positions.push(Point3::new(
                (hf.origin_x_m + i as f64 * hf.spacing_m) as f32,
                (hf.origin_y_m + j as f64 * hf.spacing_m) as f32,
                sample(i, j),
            ));
            let dzdx = (sample((i + 1).min(nx - 1), j) - sample(i.saturating_sub(1), j))
                / (((i + 1).min(nx - 1) - i.saturating_sub(1)).max(1) as f64 * hf.spacing_m) as f32;
            let dzdy = (sample(i, (j + 1).min(ny - 1)) - sample(i, j.saturating_sub(1)))
                / (((j + 1).min(ny - 1) - j.saturating_sub(1)).max(1) as f64 * hf.spacing_m) as f32;
            mesh.normals
                .push(Vector3::new(-dzdx, -dzdy, 1.0).normalize());
        }
    }
    for j in 0..ny.saturating_sub(1) {
        for i in 0..nx.saturating_sub(1) {
            let a = (j * nx + i) as u32;
            let (b, c, d) = (a + 1, a + nx as u32, a + nx as u32 + 1);
            mesh.faces.push([a, b, d]);
            mesh.faces.push([a, d, c]);
        }
    }
    mesh
}

/// Reads an ESRI ASCII grid (`.asc`): header keys `ncols`, `nrows`, `xllcorner`|`xllcenter`,
/// `yllcorner`|`yllcenter`, `cellsize` and optional `NODATA_value`, then `nrows` rows of
/// heights from the north edge southwards. The grid is re-centred on the world origin (the
/// DEM's own projected coordinates are dropped), and NODATA cells take the lowest valid
/// height.
///
/// # Errors
/// [`DatasetError::Io`] for an unreadable file; [`DatasetError::Parse`] naming the line for
/// a bad header (or a grid wider than 10 000 km), a bad number (or a height beyond f32's
/// range), a wrong value count, or a grid with no valid height.
pub fn read_esri_ascii(path: &Path) -> Result<Heightfield, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
    parse_esri_ascii(&text).map_err(|(line, message)| DatasetError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    })
}

/// Parses ESRI ASCII grid text; see [`read_esri_ascii`]. Errors carry the 1-based line and a
/// message.
pub fn parse_esri_ascii(text: &str) -> Result<Heightfield, (usize, String)> {
    let mut header = std::collections::BTreeMap::new();
    let mut lines = text.lines().enumerate().peekable();
    while let Some((number, line)) = lines.peek().copied() {
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else {
            lines.next();
            continue;
        };
        if !key.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) {
            break;
        }
        let value: f64 = words
            .next()
            .and_then(|v| v.parse().ok())
            .ok_or_else(|| (number + 1, format!("header key `{key}` needs a number")))?;
        header.insert(key.to_ascii_lowercase(), value);
        lines.next();
    }
    let get = |key: &str| {
        header
            .get(key)
            .copied()
            .ok_or_else(|| (1, format!("missing header key `{key}`")))
    };
    let (ncols, nrows, cellsize) = (get("ncols")?, get("nrows")?, get("cellsize")?);
    if !(ncols >= 2.0 && nrows >= 2.0 && ncols * nrows <= 16e6)
        || ncols.fract() != 0.0
        || nrows.fract() != 0.0
    {
        return Err((
            1,
            format!("ncols {ncols} and nrows {nrows} must be integers ≥ 2 (≤ 16 M cells)"),
        ));
    }
    if !(cellsize > 0.0 && cellsize.is_finite()) {
        return Err((1, format!("cellsize {cellsize} must be positive")));
    }
    // The mesh's vertices are f32 world coordinates about the grid's centre.
    if cellsize * ncols.max(nrows) > MAX_GRID_EXTENT_M {
        return Err((
            1,
            format!(
                "cellsize {cellsize} m × {} cells spans more than {} km",
                ncols.max(nrows),
                MAX_GRID_EXTENT_M / 1000.0
            ),
        ));
    }
    let (nx, ny) = (ncols as usize, nrows as usize);
    let nodata = header.get("nodata_value").copied();
    let mut values = Vec::with_capacity(nx * ny);
    let mut last_line = 0;
    for (number, line) in lines {
        last_line = number + 1;
        for word in line.split_whitespace() {
            let v: f64 = word
                .parse()
                .map_err(|_| (number + 1, format!("`{word}` is not a number")))?;
            if v.is_finite() && v.abs() > f64::from(f32::MAX) && nodata != Some(v) {
                return Err((
                    number + 1,
                    format!("height `{word}` is beyond the range of a 32-bit float"),
                ));
            }
            values.push(v);
        }
    }
    if values.len() != nx * ny {
        return Err((
            last_line,
            format!(
                "expected {} heights ({nrows}×{ncols}), found {}",
                nx * ny,
                values.len()
            ),
        ));
    }
    let is_valid = |v: f64| v.is_finite() && nodata.is_none_or(|nd| v != nd);
    let lowest = values
        .iter()
        .copied()
        .filter(|&v| is_valid(v))
        .fold(f64::INFINITY, f64::min);
    if !lowest.is_finite() {
        return Err((last_line, "the grid holds no valid height".into()));
    }
    // File rows run north to south; ours run south to north.
    let mut heights_m = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        let file_row = ny - 1 - j;
        heights_m.extend(
            values[file_row * nx..(file_row + 1) * nx]
                .iter()
                .map(|&v| mesh_precision(if is_valid(v) { v } else { lowest })),
        );
    }
    Ok(Heightfield {
        origin_x_m: -((nx - 1) as f64) * cellsize / 2.0,
        origin_y_m: -((ny - 1) as f64) * cellsize / 2.0,
        spacing_m: cellsize,
        nx,
        ny,
        heights_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn esri_grid_reads_north_row_first() {
        let text = "ncols 3\nnrows 2\nxllcorner 500000\nyllcorner 4000000\ncellsize 2\nNODATA_value -9999\n1 2 3\n4 -9999 6\n";
        let h = parse_esri_ascii(text).unwrap();
        assert_eq!((h.nx, h.ny), (3, 2));
        // South row (file's last) first.
        assert_eq!(h.heights_m, vec![4.0, 1.0, 6.0, 1.0, 2.0, 3.0]);
        assert_eq!(h.extent(), (-2.0, -1.0, 2.0, 1.0));
        assert!((h.height_at(-1.0, 0.0).unwrap() - (4.0 + 1.0 + 1.0 + 2.0) / 4.0).abs() < 1e-9);
        assert!(h.height_at(2.1, 0.0).is_none());
    }

    #[test]
    fn esri_grid_errors_name_the_line() {
        let (line, msg) =
            parse_esri_ascii("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 x\n")
                .unwrap_err();
        assert_eq!(line, 7);
        assert!(msg.contains("`x`"));
        let (_, msg) = parse_esri_ascii("ncols 2\nnrows 2\ncellsize 1\n1 2\n3\n").unwrap_err();
        assert!(msg.contains("expected 4 heights"));
        assert!(
            parse_esri_ascii("nrows 2\ncellsize 1\n")
                .unwrap_err()
                .1
                .contains("ncols")
        );
    }

    #[test]
    fn procedural_terrain_has_a_scarp_and_a_consistent_mesh() {
        let t = ProceduralTerrain {
            size_m: 40.0,
            resolution_m: 1.0,
            roughness_m: 0.0,
            scarp_offset_m: 0.0,
            ..Default::default()
        };
        let h = t.generate().unwrap();
        assert_eq!((h.nx, h.ny), (41, 41));
        // Far across the trace the offset approaches the full scarp height.
        let strike = t.scarp_strike_deg.to_radians();
        let (nx_, ny_) = (strike.cos(), -strike.sin());
        let up = h.height_at(15.0 * nx_, 15.0 * ny_).unwrap();
        let down = h.height_at(-15.0 * nx_, -15.0 * ny_).unwrap();
        assert!((up - down - t.scarp_height_m).abs() < 0.1, "{up} {down}");
        let mesh = terrain_mesh(&h);
        mesh.validate().unwrap();
        assert_eq!(mesh.face_count(), 2 * 40 * 40);
        // Every face normal points up.
        assert!((0..mesh.face_count()).all(|i| mesh.face_normal(i).z > 0.0));
        // Interpolation reproduces the samples at grid points.
        assert!((h.height_at(-20.0, -20.0).unwrap() - h.heights_m[0]).abs() < 1e-6);
    }
}
