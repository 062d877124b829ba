//! Harris and Shi–Tomasi corners with non-maximum suppression and a minimum distance.
//!
//! The structure tensor `[Σ gx², Σ gx·gy; Σ gx·gy, Σ gy²]` is summed over a square block of
//! central-difference gradients around each pixel. Its score is either Harris'
//! `det − k·trace²` or Shi–Tomasi's smaller eigenvalue. Candidates are 3×3 local maxima above
//! `quality_level × best score` (and above an absolute floor, so flat images give nothing); they
//! are taken strongest first, skipping any within `min_distance_px` of one already taken.

use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use super::FeatureError;
use crate::image::{GrayImage, MaskImage};

/// Which corner score to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CornerScore {
    /// Harris: `det(M) − k·trace(M)²` (the paper's choice).
    Harris,
    /// Shi–Tomasi: the smaller eigenvalue of `M` ("good features to track").
    ShiTomasi,
}

/// Corner detector parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CornerConfig {
    /// The score. Default Harris, as in the paper.
    pub score: CornerScore,
    /// Harris' `k`. Default 0.04 (the usual 0.04–0.06).
    pub harris_k: f32,
    /// Half-size of the structure-tensor block, px: the block is `2r + 1` wide. Default 2
    /// (5×5, a common choice for 640×480 images).
    pub block_radius_px: u32,
    /// Keep at most this many corners. Default 20 (the paper's maximum per box).
    pub max_corners: usize,
    /// Candidates scoring below this fraction of the best score are dropped. Default 0.01
    /// (OpenCV's usual quality level).
    pub quality_level: f32,
    /// Absolute score floor, in squared intensity-gradient units summed over the block.
    /// Default 1e-7, which rejects flat and nearly flat regions of `[0, 1]` images.
    pub min_score: f32,
    /// No two corners closer than this, px. Default 3.
    pub min_distance_px: f32,
    /// Spread the corners over a grid of `[columns, rows]` cells of the candidate area: each
    /// cell keeps at most its share of `max_corners` (rounded up), strongest first, so a
    /// textured corner of the image cannot take every corner. `None` keeps the strongest
    /// corners wherever they are. Default `None`.
    pub grid_cells: Option<[u32; 2]>,
}

impl Default for CornerConfig {
    fn default() -> Self {
        Self {
            score: CornerScore::Harris,
            harris_k: 0.04,
            block_radius_px: 2,
            max_corners: 20,
            quality_level: 0.01,
            min_score: 1e-7,
            min_distance_px: 3.0,
            grid_cells: None,
        }
    }
}

impl CornerConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`FeatureError::InvalidConfig`] naming the field.
    pub fn validate(&self) -> Result<(), FeatureError> {
        let bad = |field, reason| Err(FeatureError::InvalidConfig { field, reason });
        if !(self.harris_k.is_finite() && self.harris_k >= 0.0 && self.harris_k < 0.25) {
            return bad("harris_k", "must be in [0, 0.25)");
        }
        if self.block_radius_px == 0 || self.block_radius_px > 16 {
            return bad("block_radius_px", "must be in 1..=16");
        }
        if !(self.quality_level >= 0.0 && self.quality_level <= 1.0) {
            return bad("quality_level", "must be in [0, 1]");
        }
        if !(self.min_score.is_finite() && self.min_score >= 0.0) {
            return bad("min_score", "must be finite and ≥ 0");
        }
        if !(self.min_distance_px.is_finite() && self.min_distance_px >= 0.0) {
            return bad("min_distance_px", "must be finite and ≥ 0");
        }
        if self.grid_cells.is_some_and(|[c, r]| c == 0 || r == 0) {
            return bad("grid_cells", "needs at least one column and one row");
        }
        Ok(())
    }
}

/// An inclusive rectangle of whole pixels: columns `u_min..=u_max`, rows `v_min..=v_max`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PixelRect {
    /// First column.
    pub u_min: u32,
    /// First row.
    pub v_min: u32,
    /// Last column (inclusive).
    pub u_max: u32,
    /// Last row (inclusive).
    pub v_max: u32,
}

impl PixelRect {
    /// The pixels whose centres lie inside the continuous box `[x_min, x_max] × [y_min, y_max]`
    /// (pixel centres at integers), clipped to a `width × height` image; `None` when no pixel
    /// centre is inside or an edge is not finite.
    pub fn from_continuous(
        x_min: f64,
        y_min: f64,
        x_max: f64,
        y_max: f64,
        width: u32,
        height: u32,
    ) -> Option<Self> {
        if ![x_min, y_min, x_max, y_max].iter().all(|v| v.is_finite()) || width == 0 || height == 0
        {
            return None;
        }
        let u0 = x_min.ceil().max(0.0);
        let v0 = y_min.ceil().max(0.0);
        let u1 = x_max.floor().min(f64::from(width - 1));
        let v1 = y_max.floor().min(f64::from(height - 1));
        (u0 <= u1 && v0 <= v1).then_some(Self {
            u_min: u0 as u32,
            v_min: v0 as u32,
            u_max: u1 as u32,
            v_max: v1 as u32,
        })
    }
}

/// Where to look for corners.
#[derive(Debug, Clone, Copy)]
pub enum CornerRegion<'a> {
    /// The whole image.
    Whole,
    /// Only pixels inside this rectangle (the block may reach outside it).
    Rect(PixelRect),
    /// Only pixels where `mask` equals `id`. The mask must have the image's size.
    Mask {
        /// Instance mask.
        mask: &'a MaskImage,
        /// The instance id to keep.
        id: u16,
    },
}

/// One detected corner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Position, px (a pixel centre).
    pub position: Point2<f32>,
    /// The corner score (see [`CornerScore`]).
    pub score: f32,
}

/// Detects corners in `gray`, strongest first (ties broken by row, then column, so the order
/// is deterministic).
///
/// Corners keep a border of `block_radius_px + 1` px from the image edge, where the structure
/// tensor is defined. An image too small for that gives no corners.
///
/// # Errors
/// [`FeatureError::InvalidConfig`] for a bad config; [`FeatureError::MaskSize`] when a mask's
/// size differs from the image's.
pub fn detect_corners(
    gray: &GrayImage,
    config: &CornerConfig,
    region: &CornerRegion<'_>,
) -> Result<Vec<Corner>, FeatureError> {
    config.validate()?;
    let (width, height) = (gray.width(), gray.height());
    let (rect, mask) = match *region {
        CornerRegion::Whole => (None, None),
        CornerRegion::Rect(r) => (Some(r), None),
        CornerRegion::Mask { mask, id } => {
            if mask.width() != width || mask.height() != height {
                return Err(FeatureError::MaskSize {
                    mask_width: mask.width(),
                    mask_height: mask.height(),
                    width,
                    height,
                });
            }
            (mask_bounds(mask, id), Some((mask, id)))
        }
    };
    if matches!(region, CornerRegion::Mask { .. }) && rect.is_none() {
        return Ok(Vec::new());
    }
    let radius = config.block_radius_px;
    let border = radius + 1;
    if width <= 2 * border || height <= 2 * border || config.max_corners == 0 {
        return Ok(Vec::new());
    }
    // Candidate area: the region clipped to where the block fits.
    let (mut u0, mut v0, mut u1, mut v1) =
        (border, border, width - 1 - border, height - 1 - border);
    if let Some(r) = rect {
        u0 = u0.max(r.u_min);
        v0 = v0.max(r.v_min);
        u1 = u1.min(r.u_max);
        v1 = v1.min(r.v_max);
    }
    if u0 > u1 || v0 > v1 {
        return Ok(Vec::new());
    }
    let scores = ScoreField::compute(gray, config, [u0, v0, u1, v1]);
    // With a grid, each cell's quality threshold is relative to its own best score: a weakly
    // textured cell keeps its best corners.
    let grid = config.grid_cells.map(|[columns, rows]| CornerGrid {
        origin: (u0, v0),
        columns,
        cell_size: (
            (u1 - u0 + 1).div_ceil(columns).max(1),
            (v1 - v0 + 1).div_ceil(rows).max(1),
        ),
        cells: (columns * rows) as usize,
    });
    let mut candidates = Vec::new();
    for v in v0..=v1 {
        for u in u0..=u1 {
            let s = scores.at(u, v);
            if !(s > config.min_score) || !scores.is_local_max(u, v) {
                continue;
            }
            if let Some((m, id)) = mask
                && m.get(u, v) != Some(&id)
            {
                continue;
            }
            candidates.push((s, u, v));
        }
    }
    let cells = grid.as_ref().map_or(1, |g| g.cells);
    let cell_of = |u: u32, v: u32| grid.as_ref().map_or(0, |g| g.cell(u, v));
    let mut best = vec![0.0f32; cells];
    for &(s, u, v) in &candidates {
        let b = &mut best[cell_of(u, v)];
        *b = b.max(s);
    }
    candidates.retain(|&(s, u, v)| s > config.quality_level * best[cell_of(u, v)]);
    // Strongest first; equal scores in raster order.
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.2.cmp(&b.2)).then(a.1.cmp(&b.1)));
    let per_cell = config.max_corners.div_ceil(cells);
    let mut counts = vec![0usize; cells];
    Ok(select_spread(&candidates, config, |u, v| {
        let count = &mut counts[cell_of(u, v)];
        *count += 1;
        *count <= per_cell
    }))
}

/// The cells of [`CornerConfig::grid_cells`] over the candidate area.
struct CornerGrid {
    origin: (u32, u32),
    columns: u32,
    cell_size: (u32, u32),
    cells: usize,
}

impl CornerGrid {
    /// The cell of a pixel of the candidate area, row-major.
    fn cell(&self, u: u32, v: u32) -> usize {
        let column = ((u - self.origin.0) / self.cell_size.0).min(self.columns - 1);
        let row = (v - self.origin.1) / self.cell_size.1;
        ((row * self.columns + column) as usize).min(self.cells - 1)
    }
}

/// The tight bounds of the pixels of `mask` equal to `id`.
fn mask_bounds(mask: &MaskImage, id: u16) -> Option<PixelRect> {
    let mut r: Option<PixelRect> = None;
    for v in 0..mask.height() {
        for (u, &m) in mask.row(v).iter().enumerate() {
            if m == id {
                let u = u as u32;
                let b = r.get_or_insert(PixelRect {
                    u_min: u,
                    v_min: v,
                    u_max: u,
                    v_max: v,
                });
                b.u_min = b.u_min.min(u);
                b.u_max = b.u_max.max(u);
                b.v_max = v;
            }
        }
    }
    r
}

/// Greedy selection, strongest first, of candidates at least `min_distance_px` apart, using a
/// grid of cells one minimum distance wide.
fn select_spread(
    candidates: &[(f32, u32, u32)],
    config: &CornerConfig,
    mut admit: impl FnMut(u32, u32) -> bool,
) -> Vec<Corner> {
    let min_d = config.min_distance_px;
    let cell = min_d.max(1.0);
    let mut taken: std::collections::HashMap<(i64, i64), Vec<Point2<f32>>> =
        std::collections::HashMap::new();
    let mut out = Vec::new();
    for &(score, u, v) in candidates {
        let p = Point2::new(u as f32, v as f32);
        let (cu, cv) = ((p.x / cell).floor() as i64, (p.y / cell).floor() as i64);
        let near = (-1..=1).any(|du| {
            (-1..=1).any(|dv| {
                taken
                    .get(&(cu + du, cv + dv))
                    .is_some_and(|pts| pts.iter().any(|q| (q - p).norm() < min_d))
            })
        });
        if near || !admit(u, v) {
            continue;
        }
        taken.entry((cu, cv)).or_default().push(p);
        out.push(Corner { position: p, score });
        if out.len() == config.max_corners {
            break;
        }
    }
    out
}

/// Corner scores over an inclusive rectangle, with a one-pixel frame for the local-maximum
/// test (zero outside the image's valid area).
struct ScoreField {
    /// First column and row of the stored field (the rectangle minus the frame).
    origin: (i64, i64),
    width: usize,
    values: Vec<f32>,
}

impl ScoreField {
    fn compute(gray: &GrayImage, config: &CornerConfig, rect: [u32; 4]) -> Self {
        let [u0, v0, u1, v1] = rect;
        let r = config.block_radius_px as i64;
        let (w_img, h_img) = (i64::from(gray.width()), i64::from(gray.height()));
        // Score field covers rect ± 1 (for the 3×3 maximum test).
        let (su0, sv0) = (i64::from(u0) - 1, i64::from(v0) - 1);
        let (su1, sv1) = (i64::from(u1) + 1, i64::from(v1) + 1);
        // Gradients cover the score field ± r.
        let (gu0, gv0) = (su0 - r, sv0 - r);
        let (gw, gh) = ((su1 + r - gu0 + 1) as usize, (sv1 + r - gv0 + 1) as usize);
        let px = |u: i64, v: i64| -> f32 {
            let u = u.clamp(0, w_img - 1) as u32;
            let v = v.clamp(0, h_img - 1) as u32;
            // Clamped into the image just above.
            *gray.get(u, v).unwrap_or(&0.0)
        };
        let mut products = vec![[0.0f32; 3]; gw * gh];
        for j in 0..gh {
            let v = gv0 + j as i64;
            for i in 0..gw {
                let u = gu0 + i as i64;
                // Gradients exist only one pixel inside the image.
                if u < 1 || v < 1 || u > w_img - 2 || v > h_img - 2 {
                    continue;
                }
                let gx = 0.5 * (px(u + 1, v) - px(u - 1, v));
                let gy = 0.5 * (px(u, v + 1) - px(u, v - 1));
                products[j * gw + i] = [gx * gx, gx * gy, gy * gy];
            }
        }
        // Separable box sums: rows, then columns.
        let block = (2 * r + 1) as usize;
        let (sw, sh) = ((su1 - su0 + 1) as usize, (sv1 - sv0 + 1) as usize);
        let mut row_sums = vec![[0.0f32; 3]; sw * gh];
        for j in 0..gh {
            for i in 0..sw {
                let mut acc = [0.0f32; 3];
                for k in 0..block {
                    let p = products[j * gw + i + k];
                    acc = [acc[0] + p[0], acc[1] + p[1], acc[2] + p[2]];
                }
                row_sums[j * sw + i] = acc;
            }
        }
        let mut values = vec![0.0f32; sw * sh];
        for j in 0..sh {
            let v = sv0 + j as i64;
            for i in 0..sw {
                let u = su0 + i as i64;
                if u < r + 1 || v < r + 1 || u > w_img - 2 - r || v > h_img - 2 - r {
                    continue;
                }
                let mut m = [0.0f32; 3];
                for k in 0..block {
                    let p = row_sums[(j + k) * sw + i];
                    m = [m[0] + p[0], m[1] + p[1], m[2] + p[2]];
                }
                values[j * sw + i] = corner_score(m, config);
            }
        }
        Self {
            origin: (su0, sv0),
            width: sw,
            values,
        }
    }

    fn index(&self, u: i64, v: i64) -> usize {
        (v - self.origin.1) as usize * self.width + (u - self.origin.0) as usize
    }

    fn at(&self, u: u32, v: u32) -> f32 {
        self.values[self.index(i64::from(u), i64::from(v))]
    }

    /// Whether (u, v) beats its 3×3 neighbours: strictly greater than those before it in raster
    /// order and at least equal to those after, so plateaus yield exactly one maximum.
    fn is_local_max(&self, u: u32, v: u32) -> bool {
        let (u, v) = (i64::from(u), i64::from(v));
        let s = self.values[self.index(u, v)];
        for dv in -1..=1 {
            for du in -1..=1 {
                if du == 0 && dv == 0 {
                    continue;
                }
                let n = self.values[self.index(u + du, v + dv)];
                let before = dv < 0 || (dv == 0 && du < 0);
                if (before && n >= s) || (!before && n > s) {
                    return false;
                }
            }
        }
        true
    }
}

/// The corner score of a structure tensor `[a, b, c]` = `[Σgx², Σgx·gy, Σgy²]`.
fn corner_score(m: [f32; 3], config: &CornerConfig) -> f32 {
    let [a, b, c] = m;
    match config.score {
        CornerScore::Harris => a * c - b * b - config.harris_k * (a + c) * (a + c),
        CornerScore::ShiTomasi => 0.5 * (a + c) - (0.25 * (a - c) * (a - c) + b * b).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkerboard of 10 px squares, intensities 0.2 / 0.8.
    fn checkerboard(width: u32, height: u32) -> GrayImage {
        let data = (0..width * height)
            .map(|i| {
                let (u, v) = (i % width, i / width);
                if ((u / 10) + (v / 10)) % 2 == 0 {
                    0.2
                } else {
                    0.8
                }
            })
            .collect();
        GrayImage::from_vec(width, height, data).unwrap()
    }

    #[test]
    fn finds_checkerboard_corners_near_square_corners() {
        let img = checkerboard(60, 50);
        for score in [CornerScore::Harris, CornerScore::ShiTomasi] {
            let config = CornerConfig {
                score,
                max_corners: 100,
                ..CornerConfig::default()
            };
            let corners = detect_corners(&img, &config, &CornerRegion::Whole).unwrap();
            // Interior grid corners sit between pixels 9|10, 19|20, ...: (10k − 0.5); the 5×5
            // block spreads the score, so allow 2 px.
            assert!(corners.len() >= 12, "{score:?}: {}", corners.len());
            for c in &corners {
                let du = (c.position.x + 0.5) / 10.0;
                let dv = (c.position.y + 0.5) / 10.0;
                assert!((du - du.round()).abs() * 10.0 <= 2.0, "{c:?}");
                assert!((dv - dv.round()).abs() * 10.0 <= 2.0, "{c:?}");
            }
            // Strongest first.
            assert!(corners.windows(2).all(|w| w[0].score >= w[1].score));
        }
    }

    #[test]
    fn flat_image_has_no_corners_and_spacing_is_respected() {
        let flat = GrayImage::filled(40, 40, 0.5);
        let none = detect_corners(&flat, &CornerConfig::default(), &CornerRegion::Whole).unwrap();
        assert!(none.is_empty());
        let img = checkerboard(80, 80);
        let config = CornerConfig {
            min_distance_px: 15.0,
            max_corners: 1000,
            ..CornerConfig::default()
        };
        let corners = detect_corners(&img, &config, &CornerRegion::Whole).unwrap();
        for (i, a) in corners.iter().enumerate() {
            for b in &corners[i + 1..] {
                assert!((a.position - b.position).norm() >= 15.0);
            }
        }
    }

    #[test]
    fn a_grid_spreads_corners_over_weak_texture() {
        // Strong squares on the left half, the same pattern at a tenth of the contrast on the
        // right: the strongest 20 corners all sit on the left, a 2×1 grid keeps 10 on each side.
        let mut img = checkerboard(80, 40);
        for v in 0..40 {
            for u in 40..80 {
                let p = img.get_mut(u, v).unwrap();
                *p = 0.45 + 0.1 * *p;
            }
        }
        let strongest = CornerConfig {
            max_corners: 20,
            ..CornerConfig::default()
        };
        let right = |corners: &[Corner]| corners.iter().filter(|c| c.position.x > 42.0).count();
        let plain = detect_corners(&img, &strongest, &CornerRegion::Whole).unwrap();
        assert!(plain.len() >= 9, "{}", plain.len());
        assert_eq!(right(&plain), 0);
        let gridded = CornerConfig {
            grid_cells: Some([2, 1]),
            ..strongest
        };
        let spread = detect_corners(&img, &gridded, &CornerRegion::Whole).unwrap();
        // The right half has 3 × 3 interior corners.
        assert_eq!(right(&spread), 9, "{spread:?}");
        assert!(spread.len() - right(&spread) <= 10);
        let bad = CornerConfig {
            grid_cells: Some([0, 2]),
            ..CornerConfig::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn region_and_mask_restrict_corners() {
        let img = checkerboard(80, 80);
        let rect = PixelRect {
            u_min: 15,
            v_min: 15,
            u_max: 45,
            v_max: 35,
        };
        let config = CornerConfig {
            max_corners: 1000,
            ..CornerConfig::default()
        };
        let in_rect = detect_corners(&img, &config, &CornerRegion::Rect(rect)).unwrap();
        assert!(!in_rect.is_empty());
        assert!(in_rect.iter().all(|c| c.position.x >= 15.0
            && c.position.x <= 45.0
            && c.position.y >= 15.0
            && c.position.y <= 35.0));
        let mut mask = MaskImage::filled(80, 80, 0);
        for v in 40..70 {
            for u in 5..30 {
                *mask.get_mut(u, v).unwrap() = 7;
            }
        }
        let region = CornerRegion::Mask { mask: &mask, id: 7 };
        let in_mask = detect_corners(&img, &config, &region).unwrap();
        assert!(!in_mask.is_empty());
        assert!(
            in_mask
                .iter()
                .all(|c| mask.get(c.position.x as u32, c.position.y as u32) == Some(&7))
        );
        let absent = CornerRegion::Mask { mask: &mask, id: 9 };
        assert!(detect_corners(&img, &config, &absent).unwrap().is_empty());
        let small = MaskImage::filled(10, 10, 0);
        let wrong = CornerRegion::Mask {
            mask: &small,
            id: 0,
        };
        assert!(matches!(
            detect_corners(&img, &config, &wrong),
            Err(FeatureError::MaskSize { .. })
        ));
    }

    #[test]
    fn bad_config_and_tiny_images_are_handled() {
        let img = checkerboard(6, 6);
        assert!(
            detect_corners(&img, &CornerConfig::default(), &CornerRegion::Whole)
                .unwrap()
                .is_empty()
        );
        let config = CornerConfig {
            quality_level: f32::NAN,
            ..CornerConfig::default()
        };
        assert!(matches!(
            detect_corners(&img, &config, &CornerRegion::Whole),
            Err(FeatureError::InvalidConfig {
                field: "quality_level",
                ..
            })
        ));
    }

    #[test]
    fn continuous_box_to_pixels() {
        let r = PixelRect::from_continuous(-0.5, 2.2, 9.5, 7.9, 8, 100).unwrap();
        assert_eq!(
            r,
            PixelRect {
                u_min: 0,
                v_min: 3,
                u_max: 7,
                v_max: 7
            }
        );
        assert!(PixelRect::from_continuous(2.1, 0.0, 2.9, 5.0, 10, 10).is_none());
        assert!(PixelRect::from_continuous(f64::NAN, 0.0, 2.9, 5.0, 10, 10).is_none());
    }
}
