//! Point–triangle queries.

use nalgebra::Point3;

/// The point of triangle (`a`, `b`, `c`) closest to `p` (Ericson, *Real-Time Collision
/// Detection*, §5.1.5). Works for degenerate triangles too (returns a closest vertex or edge
/// point).
pub fn closest_point_on_triangle(
    p: &Point3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
    c: &Point3<f64>,
) -> Point3<f64> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return a + ab * v;
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + ac * w;
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + (c - b) * w;
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        return *a;
    }
    let v = vb / denom;
    let w = vc / denom;
    a + ab * v + ac * w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions() {
        let a = Point3::new(0.0, 0.0, 0.0);
        let b = Point3::new(1.0, 0.0, 0.0);
        let c = Point3::new(0.0, 1.0, 0.0);
        let q =
            |x: f64, y: f64, z: f64| closest_point_on_triangle(&Point3::new(x, y, z), &a, &b, &c);
        assert!((q(0.2, 0.2, 3.0) - Point3::new(0.2, 0.2, 0.0)).norm() < 1e-12);
        assert_eq!(q(-1.0, -1.0, 0.0), a);
        assert_eq!(q(2.0, -0.5, 0.0), b);
        assert_eq!(q(0.5, -2.0, 1.0), Point3::new(0.5, 0.0, 0.0));
        let h = q(1.0, 1.0, 0.0);
        assert!((h - Point3::new(0.5, 0.5, 0.0)).norm() < 1e-12);
    }
}
