//! GeoJSON (RFC 7946) maps of targets, and the local ENU ↔ WGS84 conversions they need.
//!
//! scarp works in a local ENU frame (x east, y north, z up, metres) anchored at a geodetic
//! origin. [`EnuFrame`] converts between that frame and WGS84 latitude, longitude and
//! ellipsoidal height exactly (ENU → ECEF by rotation and translation, then ECEF → geodetic
//! by a fixed-point iteration on the WGS84 ellipsoid that converges to below 1e-12 rad
//! everywhere, poles included), not with a flat-earth approximation.
//!
//! Heights are ellipsoidal (above the WGS84 ellipsoid), as RFC 7946 requires for the third
//! coordinate; an origin altitude given above mean sea level must be converted first.
//!
//! ```
//! use nalgebra::Point3;
//! use scarp_export::geojson::{EnuFrame, Geodetic, PointFeature, feature_collection};
//!
//! let frame = EnuFrame::new(Geodetic { lat_deg: 33.6, lon_deg: -116.45, alt_m: 1200.0 }).unwrap();
//! let rock = PointFeature {
//!     position_enu_m: Point3::new(120.0, -35.0, 4.0), // 120 m east, 35 m south, 4 m up
//!     properties: serde_json::json!({"rock_id": 7}),
//! };
//! let fc = feature_collection(&frame, &[rock]).unwrap();
//! let lon = fc["features"][0]["geometry"]["coordinates"][0].as_f64().unwrap();
//! assert!(lon > -116.45 && lon < -116.44);
//! ```

use std::path::Path;

use nalgebra::{Matrix3, Point3, Vector3};
use serde_json::{Map, Value, json};
use thiserror::Error;

use crate::atomic::{AtomicWriteError, write_atomically};

/// WGS84 semi-major axis, metres.
pub const WGS84_A_M: f64 = 6_378_137.0;
/// WGS84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS84 first eccentricity squared, e² = f (2 − f).
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// What went wrong building or writing GeoJSON.
#[derive(Debug, Error)]
pub enum GeoJsonError {
    /// A geodetic coordinate out of range or not finite.
    #[error("invalid geodetic position {what}: {value} ({reason})")]
    InvalidGeodetic {
        /// Which coordinate (`lat_deg`, `lon_deg`, `alt_m`).
        what: &'static str,
        /// The offending value.
        value: f64,
        /// The valid range.
        reason: &'static str,
    },
    /// An ENU position that is not finite.
    #[error("ENU position {index} is not finite: {value:?}")]
    NotFinite {
        /// The feature's index.
        index: usize,
        /// The offending coordinates (east, north, up), metres.
        value: [f64; 3],
    },
    /// Feature properties that are neither a JSON object nor null (RFC 7946, 3.2).
    #[error("feature {index}: properties must be a JSON object or null, not {found}")]
    BadProperties {
        /// The feature's index.
        index: usize,
        /// The JSON type found.
        found: &'static str,
    },
    /// Writing the file failed (the message names the path and the failed step).
    #[error(transparent)]
    Write(#[from] AtomicWriteError),
}

/// A WGS84 geodetic position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    /// Latitude, degrees north, [−90, 90].
    pub lat_deg: f64,
    /// Longitude, degrees east, (−180, 180] on output; any finite value on input.
    pub lon_deg: f64,
    /// Height above the WGS84 ellipsoid, metres.
    pub alt_m: f64,
}

impl Geodetic {
    /// Checks that the coordinates are finite and the latitude is in [−90, 90].
    ///
    /// # Errors
    /// [`GeoJsonError::InvalidGeodetic`] naming the coordinate.
    pub fn validate(&self) -> Result<(), GeoJsonError> {
        let bad = |what, value, reason| {
            Err(GeoJsonError::InvalidGeodetic {
                what,
                value,
                reason,
            })
        };
        if !self.lat_deg.is_finite() || self.lat_deg.abs() > 90.0 {
            return bad(
                "lat_deg",
                self.lat_deg,
                "must be finite and within [-90, 90]",
            );
        }
        if !self.lon_deg.is_finite() {
            return bad("lon_deg", self.lon_deg, "must be finite");
        }
        if !self.alt_m.is_finite() {
            return bad("alt_m", self.alt_m, "must be finite");
        }
        Ok(())
    }
}

/// Geodetic → ECEF (earth-centred, earth-fixed), metres.
pub fn geodetic_to_ecef(g: &Geodetic) -> Vector3<f64> {
    let (lat, lon) = (g.lat_deg.to_radians(), g.lon_deg.to_radians());
    let (s, c) = lat.sin_cos();
    let n = WGS84_A_M / (1.0 - WGS84_E2 * s * s).sqrt();
    Vector3::new(
        (n + g.alt_m) * c * lon.cos(),
        (n + g.alt_m) * c * lon.sin(),
        (n * (1.0 - WGS84_E2) + g.alt_m) * s,
    )
}

/// ECEF → geodetic. Iterates φ ← atan2(z + e² N(φ) sin φ, p), which contracts by about e²
/// per step, then takes h = p cos φ + z sin φ − a²/N, which is stable at every latitude.
/// The earth's centre maps to latitude 0, longitude 0, height −a.
pub fn ecef_to_geodetic(ecef: &Vector3<f64>) -> Geodetic {
    let (x, y, z) = (ecef.x, ecef.y, ecef.z);
    let p = x.hypot(y);
    let lon = y.atan2(x);
    let mut lat = z.atan2(p * (1.0 - WGS84_E2));
    for _ in 0..20 {
        let s = lat.sin();
        let n = WGS84_A_M / (1.0 - WGS84_E2 * s * s).sqrt();
        let next = (z + WGS84_E2 * n * s).atan2(p);
        let done = (next - lat).abs() < 1e-14;
        lat = next;
        if done {
            break;
        }
    }
    let (s, c) = lat.sin_cos();
    let n = WGS84_A_M / (1.0 - WGS84_E2 * s * s).sqrt();
    Geodetic {
        lat_deg: lat.to_degrees(),
        lon_deg: lon.to_degrees(),
        alt_m: p * c + z * s - WGS84_A_M * WGS84_A_M / n,
    }
}

/// A local ENU frame (x east, y north, z up, metres) tangent to the WGS84 ellipsoid at a
/// geodetic origin.
#[derive(Debug, Clone, PartialEq)]
pub struct EnuFrame {
    origin: Geodetic,
    origin_ecef: Vector3<f64>,
    /// Columns are the east, north and up unit vectors in ECEF.
    ecef_from_enu: Matrix3<f64>,
}

impl EnuFrame {
    /// The ENU frame at `origin`.
    ///
    /// # Errors
    /// [`GeoJsonError::InvalidGeodetic`] if the origin is not finite or its latitude is out of
    /// range.
    pub fn new(origin: Geodetic) -> Result<Self, GeoJsonError> {
        origin.validate()?;
        let (sl, cl) = origin.lat_deg.to_radians().sin_cos();
        let (so, co) = origin.lon_deg.to_radians().sin_cos();
        let east = Vector3::new(-so, co, 0.0);
        let north = Vector3::new(-sl * co, -sl * so, cl);
        let up = Vector3::new(cl * co, cl * so, sl);
        Ok(Self {
            origin,
            origin_ecef: geodetic_to_ecef(&origin),
            ecef_from_enu: Matrix3::from_columns(&[east, north, up]),
        })
    }

    /// The geodetic origin.
    pub fn origin(&self) -> Geodetic {
        self.origin
    }

    /// A point in this frame (metres) to WGS84.
    pub fn enu_to_geodetic(&self, p_enu_m: &Point3<f64>) -> Geodetic {
        ecef_to_geodetic(&(self.origin_ecef + self.ecef_from_enu * p_enu_m.coords))
    }

    /// A WGS84 position to this frame (metres). Inverse of [`Self::enu_to_geodetic`].
    pub fn geodetic_to_enu(&self, g: &Geodetic) -> Point3<f64> {
        Point3::from(self.ecef_from_enu.transpose() * (geodetic_to_ecef(g) - self.origin_ecef))
    }
}

/// One point feature: an ENU position and its properties.
#[derive(Debug, Clone, PartialEq)]
pub struct PointFeature {
    /// Position in the local ENU frame, metres.
    pub position_enu_m: Point3<f64>,
    /// The feature's properties: a JSON object (or `Value::Null` for none).
    pub properties: Value,
}

/// Builds a GeoJSON `FeatureCollection` of `Point` features with `[lon, lat, alt]`
/// coordinates (degrees, degrees, metres above the ellipsoid).
///
/// # Errors
/// [`GeoJsonError::NotFinite`] for a non-finite position; [`GeoJsonError::BadProperties`] if
/// properties are not an object or null.
pub fn feature_collection(
    frame: &EnuFrame,
    features: &[PointFeature],
) -> Result<Value, GeoJsonError> {
    let mut out = Vec::with_capacity(features.len());
    for (index, f) in features.iter().enumerate() {
        let p = f.position_enu_m;
        if !p.iter().all(|c| c.is_finite()) {
            return Err(GeoJsonError::NotFinite {
                index,
                value: [p.x, p.y, p.z],
            });
        }
        let properties = match &f.properties {
            Value::Null => Value::Object(Map::new()),
            Value::Object(m) => Value::Object(m.clone()),
            other => {
                return Err(GeoJsonError::BadProperties {
                    index,
                    found: match other {
                        Value::Bool(_) => "a boolean",
                        Value::Number(_) => "a number",
                        Value::String(_) => "a string",
                        _ => "an array",
                    },
                });
            }
        };
        let g = frame.enu_to_geodetic(&p);
        out.push(json!({
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [g.lon_deg, g.lat_deg, g.alt_m]},
            "properties": properties,
        }));
    }
    Ok(json!({"type": "FeatureCollection", "features": out}))
}

/// Writes [`feature_collection`] as pretty-printed JSON to `path`, atomically.
///
/// # Errors
/// As [`feature_collection`], plus [`GeoJsonError::Write`] if the file cannot be written.
pub fn write_geojson(
    path: impl AsRef<Path>,
    frame: &EnuFrame,
    features: &[PointFeature],
) -> Result<(), GeoJsonError> {
    let collection = feature_collection(frame, features)?;
    write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, &collection)?;
        std::io::Write::write_all(w, b"\n")
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(lat: f64, lon: f64, alt: f64) -> EnuFrame {
        EnuFrame::new(Geodetic {
            lat_deg: lat,
            lon_deg: lon,
            alt_m: alt,
        })
        .unwrap()
    }

    #[test]
    fn ecef_of_known_points() {
        let e = geodetic_to_ecef(&Geodetic {
            lat_deg: 0.0,
            lon_deg: 0.0,
            alt_m: 0.0,
        });
        assert!((e - Vector3::new(WGS84_A_M, 0.0, 0.0)).norm() < 1e-9);
        // The pole is at the semi-minor axis b = a (1 − f).
        let pole = geodetic_to_ecef(&Geodetic {
            lat_deg: 90.0,
            lon_deg: 33.0,
            alt_m: 10.0,
        });
        assert!((pole.z - (WGS84_A_M * (1.0 - WGS84_F) + 10.0)).abs() < 1e-6);
        let g = ecef_to_geodetic(&pole);
        assert!((g.lat_deg - 90.0).abs() < 1e-12 && (g.alt_m - 10.0).abs() < 1e-6);
        // The centre does not panic.
        let c = ecef_to_geodetic(&Vector3::zeros());
        assert!(c.lat_deg.is_finite() && c.alt_m.is_finite());
    }

    #[test]
    fn one_degree_offsets_at_the_equator() {
        let f = frame(0.0, 0.0, 0.0);
        // 111.32 km is the equatorial degree of longitude (2πa/360 = 111.3195 km of arc).
        let east = f.enu_to_geodetic(&Point3::new(111_320.0, 0.0, 0.0));
        assert!((east.lon_deg - 1.0).abs() < 0.005, "{east:?}");
        assert!(east.lat_deg.abs() < 1e-12);
        // A degree of latitude there is shorter: 110.574 km along the meridian, whose radius
        // at the equator is a(1 − e²). So 110.574 km north is one degree (±0.05%), and
        // 111.32 km north is 1.0067°, 0.67% more.
        let north = f.enu_to_geodetic(&Point3::new(0.0, 110_574.0, 0.0));
        assert!((north.lat_deg - 1.0).abs() < 0.0005, "{north:?}");
        let north = f.enu_to_geodetic(&Point3::new(0.0, 111_320.0, 0.0));
        assert!((north.lat_deg - 1.0067).abs() < 0.0005, "{north:?}");
        assert!(north.lon_deg.abs() < 1e-12);
        // Straight up is altitude.
        let up = f.enu_to_geodetic(&Point3::new(0.0, 0.0, 1234.5));
        assert!((up.alt_m - 1234.5).abs() < 1e-6 && up.lat_deg.abs() < 1e-12);
    }

    #[test]
    fn round_trips_everywhere() {
        let mut state = 1u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..500 {
            let lat = -89.99 + 179.98 * next();
            let lon = -180.0 + 360.0 * next();
            let f = frame(lat, lon, -100.0 + 5000.0 * next());
            let p = Point3::new(
                -50_000.0 + 100_000.0 * next(),
                -50_000.0 + 100_000.0 * next(),
                -500.0 + 3000.0 * next(),
            );
            let g = f.enu_to_geodetic(&p);
            let back = f.geodetic_to_enu(&g);
            assert!((back - p).norm() < 1e-6, "{lat} {lon}: {p} → {back}");
        }
        // Exactly at the poles and across the antimeridian.
        for (lat, lon) in [(90.0, 0.0), (-90.0, 45.0), (0.0, 180.0), (12.0, -179.9999)] {
            let f = frame(lat, lon, 0.0);
            let p = Point3::new(250.0, -730.0, 12.0);
            assert!((f.geodetic_to_enu(&f.enu_to_geodetic(&p)) - p).norm() < 1e-6);
        }
    }

    #[test]
    fn invalid_origins_are_rejected() {
        for (lat, lon, alt) in [
            (91.0, 0.0, 0.0),
            (f64::NAN, 0.0, 0.0),
            (0.0, f64::INFINITY, 0.0),
            (0.0, 0.0, f64::NAN),
        ] {
            assert!(
                EnuFrame::new(Geodetic {
                    lat_deg: lat,
                    lon_deg: lon,
                    alt_m: alt
                })
                .is_err()
            );
        }
    }

    #[test]
    fn feature_collection_shape() {
        let f = frame(33.6, -116.45, 1200.0);
        let features = [
            PointFeature {
                position_enu_m: Point3::new(0.0, 0.0, 0.0),
                properties: json!({"rock_id": 1, "pga_g": 0.31}),
            },
            PointFeature {
                position_enu_m: Point3::new(100.0, 50.0, 2.0),
                properties: Value::Null,
            },
        ];
        let fc = feature_collection(&f, &features).unwrap();
        assert_eq!(fc["type"], "FeatureCollection");
        let first = &fc["features"][0];
        assert_eq!(first["geometry"]["type"], "Point");
        let c = first["geometry"]["coordinates"].as_array().unwrap();
        assert!((c[0].as_f64().unwrap() + 116.45).abs() < 1e-9);
        assert!((c[1].as_f64().unwrap() - 33.6).abs() < 1e-9);
        assert!((c[2].as_f64().unwrap() - 1200.0).abs() < 1e-6);
        assert_eq!(first["properties"]["rock_id"], 1);
        assert_eq!(fc["features"][1]["properties"], json!({}));

        let bad = [PointFeature {
            position_enu_m: Point3::origin(),
            properties: json!([1, 2]),
        }];
        assert!(matches!(
            feature_collection(&f, &bad),
            Err(GeoJsonError::BadProperties { index: 0, .. })
        ));
        let nan = [PointFeature {
            position_enu_m: Point3::new(f64::NAN, 0.0, 0.0),
            properties: Value::Null,
        }];
        assert!(matches!(
            feature_collection(&f, &nan),
            Err(GeoJsonError::NotFinite { .. })
        ));

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("targets.geojson");
        write_geojson(&path, &f, &features).unwrap();
        let read: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        // serde_json's default float parser may be off by an ulp, so compare with a tolerance.
        for k in 0..2 {
            let (a, b) = (&read["features"][k], &fc["features"][k]);
            assert_eq!(a["properties"], b["properties"]);
            for c in 0..3 {
                let (x, y) = (
                    a["geometry"]["coordinates"][c].as_f64().unwrap(),
                    b["geometry"]["coordinates"][c].as_f64().unwrap(),
                );
                assert!((x - y).abs() <= 1e-12 * y.abs(), "{x} vs {y}");
            }
        }
    }
}
