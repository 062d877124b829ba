//! Planar polygons: convex hulls, areas and centroids.

use nalgebra::Point2;

/// The convex hull of a point set, counter-clockwise, without collinear points (Andrew's
/// monotone chain). Fewer than three distinct points give the distinct points themselves.
/// Non-finite points are ignored.
pub fn convex_hull_2d(points: &[Point2<f64>]) -> Vec<Point2<f64>> {
    let mut sorted: Vec<Point2<f64>> = points
        .iter()
        .copied()
        .filter(|p| p.x.is_finite() && p.y.is_finite())
        .collect();
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return sorted;
    }
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * sorted.len());
    for pass in [
        sorted.as_slice(),
        &sorted.iter().rev().copied().collect::<Vec<_>>(),
    ] {
        let start = hull.len();
        for p in pass {
            while hull.len() >= start + 2
                && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(*p);
        }
        hull.pop();
    }
    hull
}

/// Signed area of a simple polygon (shoelace formula): positive when counter-clockwise.
pub fn polygon_signed_area(polygon: &[Point2<f64>]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        / 2.0
}

/// The area centroid of a simple polygon; `None` for fewer than three points or no area.
pub fn polygon_centroid(polygon: &[Point2<f64>]) -> Option<Point2<f64>> {
    let area = polygon_signed_area(polygon);
    if polygon.len() < 3 || area == 0.0 || !area.is_finite() {
        return None;
    }
    let n = polygon.len();
    let sum = (0..n).fold(nalgebra::Vector2::zeros(), |acc, i| {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        acc + (a.coords + b.coords) * (a.x * b.y - b.x * a.y)
    });
    Some(Point2::from(sum / (6.0 * area)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn square_hull_drops_interior_and_collinear_points() {
        let pts: Vec<_> = [
            (0.0, 0.0),
            (1.0, 0.0),
            (0.5, 0.0),
            (1.0, 1.0),
            (0.0, 1.0),
            (0.5, 0.5),
        ]
        .iter()
        .map(|&(x, y)| Point2::new(x, y))
        .collect();
        let hull = convex_hull_2d(&pts);
        assert_eq!(hull.len(), 4);
        assert!((polygon_signed_area(&hull) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn centroid_is_the_area_centroid_not_the_vertex_mean() {
        // An L of two unit squares: the vertex mean leans to the corner, the area centroid not.
        let l: Vec<_> = [
            (0.0, 0.0),
            (2.0, 0.0),
            (2.0, 1.0),
            (1.0, 1.0),
            (1.0, 2.0),
            (0.0, 2.0),
        ]
        .iter()
        .map(|&(x, y)| Point2::new(x, y))
        .collect();
        let c = polygon_centroid(&l).unwrap();
        assert!(
            (c.x - 5.0 / 6.0).abs() < 1e-12 && (c.y - 5.0 / 6.0).abs() < 1e-12,
            "{c}"
        );
        let line = [
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(2.0, 2.0),
        ];
        assert_eq!(polygon_centroid(&line), None);
    }

    proptest! {
        #[test]
        fn hull_contains_all_points(pts in proptest::collection::vec((-10.0f64..10.0, -10.0f64..10.0), 3..60)) {
            let pts: Vec<_> = pts.into_iter().map(|(x, y)| Point2::new(x, y)).collect();
            let hull = convex_hull_2d(&pts);
            if hull.len() >= 3 {
                prop_assert!(polygon_signed_area(&hull) > 0.0);
                for p in &pts {
                    for i in 0..hull.len() {
                        let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
                        let c = (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
                        prop_assert!(c >= -1e-9);
                    }
                }
            }
        }
    }
}
