//! Rocking geometry on the convex contact polygon: convex hull, convex clipping, support
//! distances, the rocking angle α(θ) per azimuth, its exact minimum, and Purvance's p.
//!
//! Frame: the levelled frame (z up, metres). Azimuth θ is measured in degrees counter-clockwise
//! from levelled +x (east when up is +z) towards +y (north); it is the direction in which the
//! rock tips over. α(θ) = atan(r(θ) / H), where r(θ) is the horizontal distance from the centre
//! of mass to the supporting line of the contact polygon in direction θ and H is the height of
//! the centre of mass above the contact plane. A horizontal ground acceleration of g·tan α(θ)
//! pushing the rock towards θ brings the resultant force onto that edge.

use nalgebra::{Point2, Point3, Vector2};
use scarp_slam::geometry::{convex_hull_2d, polygon_signed_area};
use serde::{Deserialize, Serialize};

use super::section::orient;

/// Convex hull of 2-D points, counter-clockwise, without collinear or repeated points; fewer
/// than three distinct points come back as they are, non-finite points are ignored (the geometry
/// core's [`convex_hull_2d`]).
pub fn convex_hull(points: &[Point2<f64>]) -> Vec<Point2<f64>> {
    convex_hull_2d(points)
}

/// Area of a polygon given counter-clockwise (negative when clockwise), m² (the geometry core's
/// [`polygon_signed_area`]; 0 for fewer than three points).
pub fn polygon_area(polygon: &[Point2<f64>]) -> f64 {
    if polygon.len() < 3 {
        0.0
    } else {
        polygon_signed_area(polygon)
    }
}

/// Intersection of a convex polygon with a convex counter-clockwise clip polygon
/// (Sutherland–Hodgman). Both must be convex; the result is convex and counter-clockwise, or
/// empty when they do not overlap. A clip polygon of fewer than three points leaves `subject`
/// unchanged.
pub fn clip_convex(subject: &[Point2<f64>], clip: &[Point2<f64>]) -> Vec<Point2<f64>> {
    if clip.len() < 3 {
        return subject.to_vec();
    }
    let mut out = subject.to_vec();
    for k in 0..clip.len() {
        let (a, b) = (clip[k], clip[(k + 1) % clip.len()]);
        let input = std::mem::take(&mut out);
        if input.is_empty() {
            break;
        }
        for i in 0..input.len() {
            let p = input[i];
            let q = input[(i + 1) % input.len()];
            let dp = orient(&a, &b, &p);
            let dq = orient(&a, &b, &q);
            if dp >= 0.0 {
                out.push(p);
            }
            if (dp >= 0.0) != (dq >= 0.0) {
                let t = dp / (dp - dq);
                out.push(p + (q - p) * t);
            }
        }
    }
    convex_hull(&out)
}

/// Unit direction of an azimuth in radians (counter-clockwise from +x).
#[inline]
pub fn direction(azimuth_rad: f64) -> Vector2<f64> {
    Vector2::new(azimuth_rad.cos(), azimuth_rad.sin())
}

/// Horizontal distance, metres, from `com` to the supporting line of `hull` in `direction`
/// (unit): max over the hull of (p − com)·direction. Negative when the whole hull lies behind
/// the centre of mass. `None` for an empty hull.
pub fn support_distance(
    hull: &[Point2<f64>],
    com: &Point2<f64>,
    direction: &Vector2<f64>,
) -> Option<f64> {
    hull.iter()
        .map(|p| (p - com).dot(direction))
        .max_by(f64::total_cmp)
}

/// α(θ) in degrees for `count` azimuths θᵢ = i·360°/count, for a centre of mass `com_height_m`
/// (> 0) above the contact plane at horizontal position `com`. Empty when the hull is empty.
pub fn rocking_angles_deg(
    hull: &[Point2<f64>],
    com: &Point2<f64>,
    com_height_m: f64,
    count: usize,
) -> Vec<f64> {
    (0..count)
        .filter_map(|i| {
            let theta = (i as f64 * 360.0 / count as f64).to_radians();
            let r = support_distance(hull, com, &direction(theta))?;
            Some(r.atan2(com_height_m).to_degrees())
        })
        .collect()
}

/// The exact minimum of the support distance over all azimuths.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MinimumSupport {
    /// Minimum horizontal distance from the centre of mass to a rocking line, metres (negative
    /// when the centre of mass lies outside the hull: minus its distance to the hull).
    pub distance_m: f64,
    /// Azimuth of that rocking direction, degrees in [0, 360).
    pub azimuth_deg: f64,
}

/// Whether `p` lies inside or on the convex counter-clockwise `polygon` (false for fewer than
/// three points).
pub(crate) fn contains(polygon: &[Point2<f64>], p: &Point2<f64>) -> bool {
    let n = polygon.len();
    n >= 3 && (0..n).all(|k| orient(&polygon[k], &polygon[(k + 1) % n], p) >= 0.0)
}

/// Closest point to `p` on segment `a`–`b`.
fn closest_on_segment(a: &Point2<f64>, b: &Point2<f64>, p: &Point2<f64>) -> Point2<f64> {
    let d = b - a;
    let len2 = d.norm_squared();
    if len2 == 0.0 {
        return *a;
    }
    let t = ((p - a).dot(&d) / len2).clamp(0.0, 1.0);
    a + d * t
}

fn azimuth_deg_of(v: &Vector2<f64>) -> f64 {
    v.y.atan2(v.x).to_degrees().rem_euclid(360.0)
}

/// The exact minimum over all azimuths of [`support_distance`]. For a centre of mass inside a
/// convex counter-clockwise hull this is its distance to the nearest edge, in the direction of
/// that edge's outward normal; outside, it is minus its distance to the hull, in the direction
/// from the hull towards the centre of mass. `None` for an empty hull.
pub fn minimum_support(hull: &[Point2<f64>], com: &Point2<f64>) -> Option<MinimumSupport> {
    let n = hull.len();
    if n == 0 {
        return None;
    }
    if contains(hull, com) {
        let (distance_m, normal) = (0..n)
            .map(|k| {
                let (a, b) = (hull[k], hull[(k + 1) % n]);
                let e = (b - a).normalize();
                let normal = Vector2::new(e.y, -e.x);
                ((a - com).dot(&normal), normal)
            })
            .min_by(|x, y| x.0.total_cmp(&y.0))?;
        return Some(MinimumSupport {
            distance_m,
            azimuth_deg: azimuth_deg_of(&normal),
        });
    }
    // Outside (or a point/segment hull): the nearest point of the hull boundary.
    let nearest = (0..n)
        .map(|k| closest_on_segment(&hull[k], &hull[(k + 1) % n], com))
        .min_by(|a, b| {
            (a - com)
                .norm_squared()
                .total_cmp(&(b - com).norm_squared())
        })?;
    let away = com - nearest;
    let distance = away.norm();
    if distance == 0.0 {
        // On the boundary of a degenerate hull: the rock balances on a point or a line.
        let normal = if n >= 2 {
            let e = hull[1] - hull[0];
            Vector2::new(e.y, -e.x)
        } else {
            Vector2::x()
        };
        return Some(MinimumSupport {
            distance_m: 0.0,
            azimuth_deg: azimuth_deg_of(&normal),
        });
    }
    Some(MinimumSupport {
        distance_m: -distance,
        azimuth_deg: azimuth_deg_of(&away),
    })
}

/// The contact a rock pivots about by the time it topples: `hull` (the base that touches,
/// convex, counter-clockwise, levelled xy) grown by every point of `underside` (levelled, the
/// rock's vertices) over `support` (the support's top, convex counter-clockwise xy; empty for
/// an unbounded plane at `plane_z`) that lands before the rock topples.
///
/// Tipping about a hull edge by β lowers a point at height z above the plane and a distance d
/// beyond the edge until it touches when tan β = z / d. If that comes before the centre of mass
/// `com` passes over the edge (tan β < its distance to the edge / its height), the rock lands
/// on the point and pivots about it instead. A base that hangs millimetres above its support
/// beyond the touching part is therefore part of the support: a rock does not topple about the
/// edge of a contact it would land beyond after a fraction of a degree. The edges are revisited
/// until no point lands (each pass only moves pivots outwards).
pub fn landing_hull(
    hull: &[Point2<f64>],
    underside: &[Point3<f64>],
    support: &[Point2<f64>],
    plane_z: f64,
    com: &Point3<f64>,
) -> Vec<Point2<f64>> {
    let com_height = com.z - plane_z;
    if hull.len() < 3 || com_height <= 0.0 {
        return hull.to_vec();
    }
    let mut candidates: Vec<Point3<f64>> = underside
        .iter()
        .filter(|p| p.z >= plane_z && (support.len() < 3 || contains(support, &p.xy())))
        .copied()
        .collect();
    let mut hull = hull.to_vec();
    // Each pass adds at least one point or stops; a bound keeps a pathological mesh finite.
    for _ in 0..64 {
        candidates.retain(|p| !contains(&hull, &p.xy()));
        // Per edge: a point on it, its outward normal, and the centre of mass's distance inside.
        let n = hull.len();
        let edges: Vec<(Point2<f64>, Vector2<f64>, f64)> = (0..n)
            .map(|k| {
                let (a, b) = (hull[k], hull[(k + 1) % n]);
                let e = (b - a).normalize();
                let outward = Vector2::new(e.y, -e.x);
                (a, outward, (a - com.xy()).dot(&outward))
            })
            .collect();
        let landed: Vec<Point2<f64>> = candidates
            .iter()
            .filter(|p| {
                edges.iter().any(|(a, outward, com_inside)| {
                    let beyond = (p.xy() - a).dot(outward);
                    beyond > 0.0
                        && *com_inside > 0.0
                        && (p.z - plane_z) * com_height < beyond * com_inside
                })
            })
            .map(|p| p.xy())
            .collect();
        if landed.is_empty() {
            break;
        }
        hull.extend(landed);
        hull = convex_hull(&hull);
    }
    hull
}

/// Purvance's rocking frequency parameter p = √(m g R / I_O), rad/s, where R is the distance
/// from the centre of mass to the rocking axis and I_O the moment of inertia about that axis.
/// For a uniform rectangular block I_O = 4/3 m R², so p = √(3g / 4R). Returns NaN when
/// `inertia_about_axis_kg_m2` is not positive.
pub fn purvance_p(mass_kg: f64, g_m_s2: f64, radius_m: f64, inertia_about_axis_kg_m2: f64) -> f64 {
    if inertia_about_axis_kg_m2 > 0.0 {
        (mass_kg * g_m_s2 * radius_m / inertia_about_axis_kg_m2).sqrt()
    } else {
        f64::NAN
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use proptest::prelude::*;

    fn square(b: f64) -> Vec<Point2<f64>> {
        vec![
            Point2::new(-b, -b),
            Point2::new(b, -b),
            Point2::new(b, b),
            Point2::new(-b, b),
        ]
    }

    #[test]
    fn square_contact_gives_atan_in_each_direction() {
        let hull = convex_hull(&square(0.5));
        assert_eq!(hull.len(), 4);
        let a = rocking_angles_deg(&hull, &Point2::origin(), 1.0, 360);
        for k in [0, 90, 180, 270] {
            assert!((a[k] - 0.5f64.atan().to_degrees()).abs() < 1e-12);
        }
        // Towards a corner the rocking line is the support line through that corner.
        assert!((a[45] - (0.5 * 2f64.sqrt()).atan().to_degrees()).abs() < 1e-12);
        let m = minimum_support(&hull, &Point2::origin()).unwrap();
        assert!((m.distance_m - 0.5).abs() < 1e-12);
    }

    #[test]
    fn clipping_two_squares_gives_their_overlap() {
        let a = square(1.0);
        let b: Vec<Point2<f64>> = square(1.0)
            .iter()
            .map(|p| p + Vector2::new(1.5, 0.5))
            .collect();
        let c = clip_convex(&a, &b);
        assert!((polygon_area(&c) - 0.5 * 1.5).abs() < 1e-12);
        let far: Vec<Point2<f64>> = square(1.0)
            .iter()
            .map(|p| p + Vector2::new(5.0, 0.0))
            .collect();
        assert!(clip_convex(&a, &far).is_empty());
    }

    #[test]
    fn outside_centre_of_mass_gives_negative_minimum() {
        let m = minimum_support(&square(1.0), &Point2::new(3.0, 0.0)).unwrap();
        assert!((m.distance_m + 2.0).abs() < 1e-12);
        assert!(
            m.azimuth_deg.abs() < 1e-9,
            "falls towards the overhanging side"
        );
        let seg = [Point2::new(-1.0, 0.0), Point2::new(1.0, 0.0)];
        let on = minimum_support(&seg, &Point2::new(0.2, 0.0)).unwrap();
        assert!(on.distance_m.abs() < 1e-12);
    }

    #[test]
    fn block_purvance_p() {
        let (m, g, r) = (10.0, 9.81, 0.7);
        let p = purvance_p(m, g, r, 4.0 / 3.0 * m * r * r);
        assert!((p - (3.0 * g / (4.0 * r)).sqrt()).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn hull_contains_points_and_is_convex(
            pts in prop::collection::vec((-10.0f64..10.0, -10.0f64..10.0), 1..60)
        ) {
            let points: Vec<Point2<f64>> = pts.iter().map(|&(x, y)| Point2::new(x, y)).collect();
            let hull = convex_hull(&points);
            let n = hull.len();
            prop_assert!(n >= 1);
            prop_assert!(hull.iter().all(|h| points.contains(h)));
            if n >= 3 {
                for k in 0..n {
                    let (a, b, c) = (hull[k], hull[(k + 1) % n], hull[(k + 2) % n]);
                    prop_assert!(orient(&a, &b, &c) > 0.0);
                    for p in &points {
                        prop_assert!(orient(&a, &b, p) >= -1e-9);
                    }
                }
                // Idempotent, and never larger than the points' bounding box.
                prop_assert_eq!(convex_hull(&hull).len(), n);
                prop_assert!(polygon_area(&hull) > 0.0);
            }
        }

        #[test]
        fn exact_minimum_bounds_the_sampled_angles(
            pts in prop::collection::vec((-1.0f64..1.0, -1.0f64..1.0), 3..40),
            cx in -0.2f64..0.2, cy in -0.2f64..0.2,
        ) {
            let points: Vec<Point2<f64>> = pts.iter().map(|&(x, y)| Point2::new(x, y)).collect();
            let hull = convex_hull(&points);
            let com = Point2::new(cx, cy);
            if let Some(m) = minimum_support(&hull, &com) {
                let sampled = (0..720)
                    .filter_map(|i| support_distance(&hull, &com, &direction((i as f64 * 0.5).to_radians())))
                    .fold(f64::INFINITY, f64::min);
                prop_assert!(m.distance_m <= sampled + 1e-12);
                let at = support_distance(&hull, &com, &direction(m.azimuth_deg.to_radians())).unwrap();
                prop_assert!((at - m.distance_m).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn a_base_hanging_just_above_the_support_is_landed_on() {
        let com = Point3::new(0.0, 0.0, 0.5);
        // 2 mm up and 0.2 m beyond the east edge: tipping east lands on it after 0.6°, long
        // before the 11.3° that topples the rock about the edge.
        let low = Point3::new(0.3, 0.0, 0.002);
        // 0.2 m up: the rock topples before it comes down.
        let high = Point3::new(-0.3, 0.0, 0.2);
        // A square contact 0.2 m wide under a centre of mass 0.5 m up.
        let hull = landing_hull(&square(0.1), &[low, high], &[], 0.0, &com);
        let east = minimum_support(&hull, &com.xy()).unwrap();
        assert!((polygon_area(&hull) - (0.2 * 0.2 + 0.5 * 0.2 * 0.2)).abs() < 1e-12);
        assert!(
            (east.distance_m - 0.1).abs() < 1e-12,
            "west and north still bind"
        );
        assert!(hull.iter().any(|p| (p.x - 0.3).abs() < 1e-12));
        assert!(hull.iter().all(|p| p.x > -0.11));
        // A support that ends at 0.2 m east leaves nothing there to land on.
        assert_eq!(
            landing_hull(&square(0.1), &[low, high], &square(0.2), 0.0, &com),
            square(0.1)
        );
    }
}
