//! Reader for the "Bundle Adjustment in the Large" (BAL) text format.
//!
//! Layout: a header `num_cameras num_points num_observations`; then one observation a line
//! (`camera point x y`, pixels with the origin at the image centre, y up); then 9 parameters a
//! camera (angle-axis rotation ×3, translation ×3, focal length, radial k1, k2) and 3 a point, as
//! whitespace-separated numbers (usually one a line). The camera maps world to camera
//! coordinates with P = R·X + t and looks down −z: see [`SnavelyCamera`].
//!
//! The reader checks everything before it allocates by a count from the file: negative counts,
//! counts that the file is too short to hold, tokens that are not numbers, non-finite values and
//! out-of-range indices are errors naming the line.
//!
//! ```
//! use scarp_slam::ba::bal::parse_bal;
//!
//! let text = "1 1 1\n0 0 -10.0 5.0\n0\n0\n0\n0\n0\n-5\n500\n0\n0\n0.1\n-0.2\n1\n";
//! let problem = parse_bal(text.as_bytes(), "inline.txt").unwrap();
//! assert_eq!((problem.cameras.len(), problem.points.len()), (1, 1));
//! assert!(parse_bal(b"1 1 2\n0 0 1 1\n", "short.txt").is_err());
//! ```

use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};

use super::error::BaError;
use super::problem::Observation;
use super::snavely::SnavelyCamera;

/// A BAL problem: cameras, points and the observations linking them.
#[derive(Debug, Clone, PartialEq)]
pub struct BalProblem {
    /// The cameras, in file order.
    pub cameras: Vec<SnavelyCamera>,
    /// The points, in world coordinates (file units), in file order.
    pub points: Vec<Vector3<f64>>,
    /// The observations, in file order. `pixel` is in the BAL convention (origin at the image
    /// centre, as predicted by [`SnavelyCamera::project`]).
    pub observations: Vec<Observation>,
}

/// The shortest text a count of items can occupy: every number needs at least one character and
/// one separator.
const MIN_BYTES_PER_NUMBER: usize = 2;

/// Reads a BAL file from disk.
///
/// # Errors
/// [`BaError::Io`] if the file cannot be read; [`BaError::Parse`] (naming the file and line) if
/// it is malformed, as for [`parse_bal`].
pub fn read_bal(path: impl AsRef<Path>) -> Result<BalProblem, BaError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| BaError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_bal(&bytes, &path.display().to_string())
}

/// Whitespace-separated tokens with their 1-based line numbers.
struct Tokens<'a> {
    text: &'a str,
    pos: usize,
    line: usize,
    source_name: &'a str,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str, source_name: &'a str) -> Self {
        Self {
            text,
            pos: 0,
            line: 1,
            source_name,
        }
    }

    fn error(&self, line: usize, reason: String) -> BaError {
        BaError::Parse {
            source_name: self.source_name.to_string(),
            line,
            reason,
        }
    }

    /// The next token and its line, or a truncation error describing what was expected.
    fn next(&mut self, expected: &dyn Fn() -> String) -> Result<(&'a str, usize), BaError> {
        let bytes = self.text.as_bytes();
        while self.pos < bytes.len() && bytes[self.pos].is_ascii_whitespace() {
            if bytes[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        if self.pos >= bytes.len() {
            return Err(self.error(
                self.line,
                format!("file is truncated: expected {} but it ended", expected()),
            ));
        }
        let start = self.pos;
        while self.pos < bytes.len() && !bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        // Both ends sit at ASCII whitespace or the ends of the text, so they are char boundaries.
        Ok((&self.text[start..self.pos], self.line))
    }

    fn count(&mut self, what: &'static str) -> Result<usize, BaError> {
        let (token, line) = self.next(&|| format!("the header's {what}"))?;
        let value: i64 = token
            .parse()
            .map_err(|_| self.error(line, format!("header {what} `{token}` is not an integer")))?;
        usize::try_from(value)
            .map_err(|_| self.error(line, format!("header {what} is negative ({value})")))
    }

    fn index(&mut self, what: &str, observation: usize, limit: usize) -> Result<usize, BaError> {
        let (token, line) =
            self.next(&|| format!("the {what} index of observation {observation}"))?;
        let value: i64 = token.parse().map_err(|_| {
            self.error(
                line,
                format!("{what} index `{token}` of observation {observation} is not an integer"),
            )
        })?;
        match usize::try_from(value) {
            Ok(index) if index < limit => Ok(index),
            _ => Err(self.error(
                line,
                format!(
                    "{what} index {value} of observation {observation} is out of range (the file has {limit} {what}s)"
                ),
            )),
        }
    }

    fn number(&mut self, expected: &dyn Fn() -> String) -> Result<f64, BaError> {
        let (token, line) = self.next(expected)?;
        let value: f64 = token
            .parse()
            .map_err(|_| self.error(line, format!("{} `{token}` is not a number", expected())))?;
        if !value.is_finite() {
            return Err(self.error(line, format!("{} is not finite ({token})", expected())));
        }
        Ok(value)
    }
}

/// Parses a BAL problem from bytes; `source_name` labels errors (usually the file name).
///
/// # Errors
/// [`BaError::Parse`] naming the line for: non-UTF-8 text, a truncated file, negative counts,
/// counts the file is too short to hold, tokens that are not numbers, NaN or infinite values,
/// and camera or point indices out of range. Trailing text after the last point is ignored.
pub fn parse_bal(bytes: &[u8], source_name: &str) -> Result<BalProblem, BaError> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let line = 1 + bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        BaError::Parse {
            source_name: source_name.to_string(),
            line,
            reason: "file is not UTF-8 text".to_string(),
        }
    })?;
    let mut tokens = Tokens::new(text, source_name);
    let num_cameras = tokens.count("camera count")?;
    let num_points = tokens.count("point count")?;
    let num_observations = tokens.count("observation count")?;

    // Reject counts the file cannot hold before allocating anything by them.
    let needed_numbers = num_observations
        .checked_mul(4)
        .and_then(|o| num_cameras.checked_mul(9).and_then(|c| o.checked_add(c)))
        .and_then(|oc| num_points.checked_mul(3).and_then(|p| oc.checked_add(p)));
    let needed_bytes = needed_numbers.and_then(|n| n.checked_mul(MIN_BYTES_PER_NUMBER));
    match needed_bytes {
        // The last number may lack a trailing separator.
        Some(needed) if needed <= text.len() + 1 => {}
        _ => {
            return Err(BaError::Parse {
                source_name: source_name.to_string(),
                line: 1,
                reason: format!(
                    "header counts ({num_cameras} cameras, {num_points} points, {num_observations} observations) \
                     need more numbers than a {}-byte file can hold",
                    text.len()
                ),
            });
        }
    }

    let mut observations = Vec::with_capacity(num_observations);
    for k in 0..num_observations {
        let camera = tokens.index("camera", k, num_cameras)?;
        let point = tokens.index("point", k, num_points)?;
        let x = tokens.number(&|| format!("x of observation {k}"))?;
        let y = tokens.number(&|| format!("y of observation {k}"))?;
        observations.push(Observation {
            camera,
            point,
            pixel: Vector2::new(x, y),
        });
    }

    const CAMERA_FIELDS: [&str; 9] = [
        "rotation x",
        "rotation y",
        "rotation z",
        "translation x",
        "translation y",
        "translation z",
        "focal length",
        "k1",
        "k2",
    ];
    let mut cameras = Vec::with_capacity(num_cameras);
    for c in 0..num_cameras {
        let mut v = [0.0; 9];
        for (i, slot) in v.iter_mut().enumerate() {
            *slot = tokens.number(&|| format!("{} of camera {c}", CAMERA_FIELDS[i]))?;
        }
        cameras.push(SnavelyCamera::from_bal_parameters(&v));
    }

    let mut points = Vec::with_capacity(num_points);
    for p in 0..num_points {
        let mut v = [0.0; 3];
        for (i, slot) in v.iter_mut().enumerate() {
            *slot = tokens.number(&|| format!("coordinate {} of point {p}", ["x", "y", "z"][i]))?;
        }
        points.push(Vector3::new(v[0], v[1], v[2]));
    }
    Ok(BalProblem {
        cameras,
        points,
        observations,
    })
}

/// Builds a rigid `camera_from_world` transform from a BAL angle-axis rotation and translation.
pub(crate) fn isometry_from_angle_axis(
    angle_axis: &Vector3<f64>,
    t: &Vector3<f64>,
) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(*t),
        UnitQuaternion::from_scaled_axis(*angle_axis),
    )
}

/// Writes a problem in BAL text format (full `f64` precision), for round trips and tests.
pub fn format_bal(problem: &BalProblem) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        out,
        "{} {} {}",
        problem.cameras.len(),
        problem.points.len(),
        problem.observations.len()
    );
    for o in &problem.observations {
        let _ = writeln!(
            out,
            "{} {} {:e} {:e}",
            o.camera, o.point, o.pixel.x, o.pixel.y
        );
    }
    for c in &problem.cameras {
        for v in c.bal_parameters() {
            let _ = writeln!(out, "{v:e}");
        }
    }
    for p in &problem.points {
        for v in p.iter() {
            let _ = writeln!(out, "{v:e}");
        }
    }
    out
}
