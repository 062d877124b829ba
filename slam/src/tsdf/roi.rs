//! Regions of interest: only blocks intersecting them are allocated or updated.

use std::str::FromStr;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::TsdfError;

/// A region of interest in world ENU metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Roi {
    /// Axis-aligned box from `min` to `max` (each component of `min` ≤ that of `max`).
    Box {
        /// Lower corner (x, y, z), metres.
        min: [f64; 3],
        /// Upper corner (x, y, z), metres.
        max: [f64; 3],
    },
    /// Vertical cylinder: axis through (x, y), from `z_min` to `z_max`, radius `radius_m`.
    Cylinder {
        /// Axis position (x, y), metres.
        center_xy: [f64; 2],
        /// Bottom height, metres.
        z_min: f64,
        /// Top height, metres.
        z_max: f64,
        /// Radius, metres.
        radius_m: f64,
    },
}

/// A malformed `--roi` string.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error(
    "bad region of interest `{text}`: {reason} (expected `cyl:x,y,z_min,z_max,r` or `box:x0,y0,z0,x1,y1,z1`)"
)]
pub struct RoiParseError {
    /// The text given.
    pub text: String,
    /// What is wrong with it.
    pub reason: String,
}

impl FromStr for Roi {
    type Err = RoiParseError;

    /// Parses `cyl:x,y,z_min,z_max,r` or `box:x0,y0,z0,x1,y1,z1` (metres).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let err = |reason: String| RoiParseError {
            text: text.to_string(),
            reason,
        };
        let (kind, rest) = text
            .split_once(':')
            .ok_or_else(|| err("missing `kind:`".into()))?;
        let values = rest
            .split(',')
            .map(|s| {
                s.trim()
                    .parse::<f64>()
                    .map_err(|e| err(format!("`{s}`: {e}")))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        let roi = match (kind.trim(), values.as_slice()) {
            ("cyl", &[x, y, z_min, z_max, r]) => Roi::Cylinder {
                center_xy: [x, y],
                z_min,
                z_max,
                radius_m: r,
            },
            ("box", &[x0, y0, z0, x1, y1, z1]) => Roi::Box {
                min: [x0, y0, z0],
                max: [x1, y1, z1],
            },
            ("cyl", v) => return Err(err(format!("cyl needs 5 numbers, got {}", v.len()))),
            ("box", v) => return Err(err(format!("box needs 6 numbers, got {}", v.len()))),
            (k, _) => return Err(err(format!("unknown kind `{k}`"))),
        };
        roi.validate().map_err(|e| err(e.to_string()))?;
        Ok(roi)
    }
}

impl Roi {
    /// Checks the region is finite and not inverted.
    ///
    /// # Errors
    /// [`TsdfError::InvalidConfig`] naming the field.
    pub fn validate(&self) -> Result<(), TsdfError> {
        let bad = |field, value: f64, reason| {
            Err(TsdfError::InvalidConfig {
                field,
                value,
                reason,
            })
        };
        match *self {
            Roi::Box { min, max } => {
                for a in 0..3 {
                    if !(min[a].is_finite() && max[a].is_finite()) {
                        return bad("roi.box", min[a], "not finite");
                    }
                    if min[a] > max[a] {
                        return bad("roi.box", min[a], "min exceeds max");
                    }
                }
            }
            Roi::Cylinder {
                center_xy,
                z_min,
                z_max,
                radius_m,
            } => {
                if !(center_xy[0].is_finite() && center_xy[1].is_finite()) {
                    return bad("roi.cylinder.center_xy", center_xy[0], "not finite");
                }
                if !(z_min.is_finite() && z_max.is_finite() && z_min <= z_max) {
                    return bad("roi.cylinder.z_min", z_min, "must be finite and ≤ z_max");
                }
                if !(radius_m.is_finite() && radius_m > 0.0) {
                    return bad("roi.cylinder.radius_m", radius_m, "must be positive");
                }
            }
        }
        Ok(())
    }

    /// Whether the axis-aligned box [`lo`, `hi`] (metres) intersects the region.
    pub fn intersects_box(&self, lo: [f64; 3], hi: [f64; 3]) -> bool {
        match *self {
            Roi::Box { min, max } => (0..3).all(|a| lo[a] <= max[a] && hi[a] >= min[a]),
            Roi::Cylinder {
                center_xy,
                z_min,
                z_max,
                radius_m,
            } => {
                if lo[2] > z_max || hi[2] < z_min {
                    return false;
                }
                let dx = (lo[0] - center_xy[0]).max(0.0) + (center_xy[0] - hi[0]).max(0.0);
                let dy = (lo[1] - center_xy[1]).max(0.0) + (center_xy[1] - hi[1]).max(0.0);
                dx * dx + dy * dy <= radius_m * radius_m
            }
        }
    }

    /// The region's centre (world metres): the box's middle, or the middle of the cylinder's
    /// axis.
    pub fn center(&self) -> nalgebra::Point3<f64> {
        let (min, max) = self.bounding_box();
        nalgebra::Point3::from(std::array::from_fn(|a| 0.5 * (min[a] + max[a])))
    }

    /// The same region moved by `offset_m` (world metres); a cylinder stays vertical.
    pub fn translated(&self, offset_m: &nalgebra::Vector3<f64>) -> Roi {
        match *self {
            Roi::Box { min, max } => Roi::Box {
                min: std::array::from_fn(|a| min[a] + offset_m[a]),
                max: std::array::from_fn(|a| max[a] + offset_m[a]),
            },
            Roi::Cylinder {
                center_xy,
                z_min,
                z_max,
                radius_m,
            } => Roi::Cylinder {
                center_xy: [center_xy[0] + offset_m.x, center_xy[1] + offset_m.y],
                z_min: z_min + offset_m.z,
                z_max: z_max + offset_m.z,
                radius_m,
            },
        }
    }

    /// The smallest axis-aligned box `(min, max)` (metres) holding the region.
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        match *self {
            Roi::Box { min, max } => (min, max),
            Roi::Cylinder {
                center_xy,
                z_min,
                z_max,
                radius_m,
            } => (
                [center_xy[0] - radius_m, center_xy[1] - radius_m, z_min],
                [center_xy[0] + radius_m, center_xy[1] + radius_m, z_max],
            ),
        }
    }

    /// The eight corners (world metres) of the bounding box grown by `margin_m` on every side;
    /// corner `c` takes the maximum along axis `a` when bit `a` of `c` is set.
    pub fn corners(&self, margin_m: f64) -> [nalgebra::Point3<f64>; 8] {
        let (min, max) = self.bounding_box();
        std::array::from_fn(|c| {
            let pick = |a: usize| {
                if c >> a & 1 == 1 {
                    max[a] + margin_m
                } else {
                    min[a] - margin_m
                }
            };
            nalgebra::Point3::new(pick(0), pick(1), pick(2))
        })
    }

    /// Whether the point (metres) lies inside the region.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        self.intersects_box(p, p)
    }
}
