//! Finding the basal contact: the cross-section area profile and its neck, the contact height
//! under a pedestal mesh, and the point sets on either side of the contact plane whose convex
//! hulls bound the contact polygon. Levelled frame (z up, metres).

use nalgebra::Point2;

use super::FragilityError;
use super::section::{Side, section_area, section_segments};
use super::topology::Solid;

/// Horizontal cross-section area against height.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct AreaProfile {
    /// Heights of the sample planes, metres, increasing.
    pub heights_m: Vec<f64>,
    /// Section area at each height, m².
    pub areas_m2: Vec<f64>,
}

/// Samples the section area at `levels` evenly spaced heights strictly inside the solid's
/// vertical extent (cell centres).
pub(crate) fn area_profile(solid: &Solid, levels: usize) -> AreaProfile {
    let Some((lo, hi)) = solid.z_range() else {
        return AreaProfile {
            heights_m: Vec::new(),
            areas_m2: Vec::new(),
        };
    };
    let step = (hi - lo) / levels as f64;
    let heights_m: Vec<f64> = (0..levels).map(|i| lo + (i as f64 + 0.5) * step).collect();
    let areas_m2 = heights_m
        .iter()
        .map(|&h| section_area(solid, h, Side::Above))
        .collect();
    AreaProfile {
        heights_m,
        areas_m2,
    }
}

/// The outcome of the neck search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct NeckSearch {
    /// The contact height, metres: the top of the neck, or the lowest point of the mesh when
    /// there is no neck.
    pub height_m: f64,
    /// Whether a neck was found (otherwise the rock rests on its lowest points).
    pub found: bool,
    /// min(widest section below, widest section above) / neck section, for the deepest valley.
    pub depth_ratio: f64,
}

/// For each sample, min(largest area below, largest area above) / own area: how deep a valley
/// of the profile the sample sits in (infinite for an empty section between two bodies).
pub(crate) fn valley_depths(areas: &[f64]) -> Vec<f64> {
    let n = areas.len();
    let mut below = vec![0.0f64; n];
    let mut above = vec![0.0f64; n];
    for i in 1..n {
        below[i] = below[i - 1].max(areas[i - 1]);
    }
    for i in (0..n.saturating_sub(1)).rev() {
        above[i] = above[i + 1].max(areas[i + 1]);
    }
    (0..n)
        .map(|i| {
            let rim = below[i].min(above[i]);
            if rim <= 0.0 {
                0.0
            } else if areas[i] <= 0.0 {
                f64::INFINITY
            } else {
                rim / areas[i]
            }
        })
        .collect()
}

/// Finds the basal contact as the neck of the area profile: the deepest valley whose rims are
/// at least `min_ratio` times its area. The contact is the top of the valley floor: the highest
/// height, found by bisection, where the area is still within `plateau_tolerance` (relative) of
/// the floor, so a column of constant section under the rock counts as pedestal. Without such a
/// valley the rock rests on its lowest points.
pub(crate) fn find_neck(
    solid: &Solid,
    levels: usize,
    min_ratio: f64,
    plateau_tolerance: f64,
) -> NeckSearch {
    let Some((z_lo, z_hi)) = solid.z_range() else {
        return NeckSearch {
            height_m: 0.0,
            found: false,
            depth_ratio: 0.0,
        };
    };
    let profile = area_profile(solid, levels);
    let depths = valley_depths(&profile.areas_m2);
    let best = (0..depths.len()).max_by(|&a, &b| {
        depths[a]
            .total_cmp(&depths[b])
            .then(profile.areas_m2[b].total_cmp(&profile.areas_m2[a]))
            .then(b.cmp(&a))
    });
    let Some(best) = best.filter(|&b| depths[b] >= min_ratio) else {
        return NeckSearch {
            height_m: z_lo,
            found: false,
            depth_ratio: depths.iter().copied().fold(0.0, f64::max),
        };
    };
    let areas = &profile.areas_m2;
    let heights = &profile.heights_m;
    let scale = areas.iter().copied().fold(0.0, f64::max);
    let limit = areas[best].max(0.0) * (1.0 + plateau_tolerance) + 1e-12 * scale;
    let mut j = best;
    while j + 1 < areas.len() && areas[j + 1] <= limit {
        j += 1;
    }
    let (mut lo, mut hi) = (heights[j], heights.get(j + 1).copied().unwrap_or(z_hi));
    let span = (z_hi - z_lo).max(f64::MIN_POSITIVE);
    for _ in 0..64 {
        if hi - lo <= 1e-10 * span {
            break;
        }
        let mid = 0.5 * (lo + hi);
        if section_area(solid, mid, Side::Above) <= limit {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    NeckSearch {
        height_m: lo,
        found: true,
        depth_ratio: depths[best],
    }
}

/// Points where a body touches the plane `z = h` from below: its section just below `h` and its
/// vertices in `[h − band, h)` (or `[h − band, h]` when `include_plane`), projected to xy.
pub(crate) fn points_below(
    solid: &Solid,
    h: f64,
    band_m: f64,
    include_plane: bool,
) -> Vec<Point2<f64>> {
    let mut points: Vec<Point2<f64>> = section_segments(solid, h, Side::Below)
        .flat_map(|(a, b)| [a.xy(), b.xy()])
        .collect();
    points.extend(
        solid
            .positions
            .iter()
            .filter(|p| p.z >= h - band_m && (p.z < h || (include_plane && p.z == h)))
            .map(|p| p.xy()),
    );
    points
}

/// Vertices of a closed solid lying on or above `h` within `band`, projected to xy: for a solid
/// cut at `h` these are the section and the surface just above it.
pub(crate) fn points_above(solid: &Solid, h: f64, band_m: f64) -> Vec<Point2<f64>> {
    solid
        .positions
        .iter()
        .filter(|p| p.z >= h && p.z <= h + band_m)
        .map(|p| p.xy())
        .collect()
}

/// The height of the pedestal's top under the rock: the highest pedestal vertex inside the rock's
/// horizontal bounding box.
///
/// # Errors
/// [`FragilityError::NoPedestalContact`] when no pedestal vertex lies under the rock.
pub(crate) fn pedestal_top(rock: &Solid, pedestal: &Solid) -> Result<f64, FragilityError> {
    let (lo, hi) = rock
        .bounds()
        .ok_or(FragilityError::EmptyMesh { mesh: "rock" })?;
    pedestal
        .positions
        .iter()
        .filter(|p| p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y)
        .map(|p| p.z)
        .max_by(f64::total_cmp)
        .ok_or_else(|| {
            FragilityError::NoPedestalContact(
                "no vertex of the pedestal lies under the rock's horizontal extent".into(),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fragility::test_shapes::{loft_solid, rect};

    #[test]
    fn valley_depth_of_a_waist() {
        let d = valley_depths(&[4.0, 2.0, 1.0, 3.0, 5.0, 0.5]);
        assert_eq!(d[2], 4.0);
        assert_eq!(d[1], 2.0);
        assert_eq!(d[0], 0.0);
        assert_eq!(d[5], 0.0);
        assert!(valley_depths(&[1.0, 0.0, 2.0])[1].is_infinite());
    }

    #[test]
    fn neck_is_the_top_of_a_narrow_column() {
        // A wide slab, a narrow column, a block: the contact is where the column meets the block.
        let slab = rect(-1.5, -1.5, 1.5, 1.5);
        let column = rect(-0.1, -0.1, 0.1, 0.1);
        let block = rect(-0.5, -0.5, 0.5, 0.5);
        let solid = loft_solid(&[
            (&slab, -0.6),
            (&slab, -0.4),
            (&column, -0.4),
            (&column, 0.0),
            (&block, 0.0),
            (&block, 2.0),
        ]);
        let neck = find_neck(&solid, 256, 1.5, 0.01);
        assert!(neck.found);
        assert!(
            neck.height_m < 0.0 && neck.height_m > -1e-6,
            "{}",
            neck.height_m
        );
        assert!((neck.depth_ratio - 25.0).abs() < 1e-6);
    }

    #[test]
    fn no_neck_on_a_lone_block() {
        let block = rect(0.0, 0.0, 1.0, 1.0);
        let solid = loft_solid(&[(&block, 0.3), (&block, 2.0)]);
        let neck = find_neck(&solid, 64, 1.5, 0.01);
        assert!(!neck.found);
        assert_eq!(neck.height_m, 0.3);
    }
}
