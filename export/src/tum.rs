//! TUM trajectory files: one pose a line, `timestamp tx ty tz qx qy qz qw`, `#` comments.
//! Each pose is `world_from_camera` (metres, Hamilton quaternion).

use std::path::{Path, PathBuf};

use nalgebra::Isometry3;
use scarp_slam::geometry::{isometry_from_tum, tum_from_isometry};
use thiserror::Error;

/// A timestamped pose: `world_from_camera` at `timestamp_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampedPose {
    /// Time in seconds.
    pub timestamp_s: f64,
    /// The camera's pose in the world.
    pub world_from_camera: Isometry3<f64>,
}

/// A trajectory file that cannot be read or written.
#[derive(Debug, Error)]
pub enum TumError {
    /// The file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        #[source]
        source: std::io::Error,
    },
    /// The file could not be written.
    #[error(transparent)]
    Write(#[from] crate::atomic::AtomicWriteError),
    /// A bad line: wrong field count, a bad number, a bad quaternion, or a timestamp that does
    /// not increase.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// Parses TUM trajectory text. Timestamps must strictly increase.
///
/// # Errors
/// The 1-based line and a message for a line without 8 numbers, a non-finite value, a zero
/// quaternion, or a timestamp not after the previous one.
pub fn parse_tum_trajectory(text: &str) -> Result<Vec<StampedPose>, (usize, String)> {
    let mut poses: Vec<StampedPose> = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line_no = number + 1;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let values: Vec<f64> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|w| !w.is_empty())
            .map(|w| {
                w.parse::<f64>()
                    .map_err(|_| (line_no, format!("`{w}` is not a number")))
            })
            .collect::<Result<_, _>>()?;
        if values.len() != 8 {
            return Err((
                line_no,
                format!(
                    "expected 8 values (t tx ty tz qx qy qz qw), found {}",
                    values.len()
                ),
            ));
        }
        let timestamp_s = values[0];
        if !timestamp_s.is_finite() {
            return Err((line_no, "timestamp is not finite".into()));
        }
        if let Some(previous) = poses.last()
            && timestamp_s <= previous.timestamp_s
        {
            return Err((
                line_no,
                format!(
                    "timestamp {timestamp_s} is not after the previous one ({})",
                    previous.timestamp_s
                ),
            ));
        }
        let mut pose = [0.0; 7];
        pose.copy_from_slice(&values[1..]);
        let world_from_camera = isometry_from_tum(&pose).map_err(|e| (line_no, e.to_string()))?;
        poses.push(StampedPose {
            timestamp_s,
            world_from_camera,
        });
    }
    Ok(poses)
}

/// Reads a TUM trajectory file; see [`parse_tum_trajectory`].
///
/// # Errors
/// [`TumError::Io`] or [`TumError::Parse`] naming the file and line.
pub fn read_tum_trajectory(path: &Path) -> Result<Vec<StampedPose>, TumError> {
    let text = std::fs::read_to_string(path).map_err(|source| TumError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_tum_trajectory(&text).map_err(|(line, message)| TumError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    })
}

/// A timestamp as sequence files write it: to the microsecond (`0.250000`) when that reads back
/// as the same number, else in full (`22.800000000000765`), so that a reader gets the very
/// time the writer had (the simulated detector draws by it).
///
/// ```
/// use scarp_export::tum::format_timestamp;
/// assert_eq!(format_timestamp(0.25), "0.250000");
/// assert_eq!(format_timestamp(22.800000000000765), "22.800000000000765");
/// ```
pub fn format_timestamp(timestamp_s: f64) -> String {
    let short = format!("{timestamp_s:.6}");
    if short.parse::<f64>() == Ok(timestamp_s) {
        short
    } else {
        format!("{timestamp_s}")
    }
}

/// Formats poses as TUM text, with a header comment. Timestamps get 6 decimals (microseconds),
/// or every digit when 6 would change them ([`format_timestamp`]); pose values get 17
/// significant digits, so reading back is exact to f64 round-off.
pub fn format_tum_trajectory(poses: &[StampedPose], comment: &str) -> String {
    let mut text = String::new();
    for line in comment.lines() {
        text.push_str("# ");
        text.push_str(line);
        text.push('\n');
    }
    text.push_str("# timestamp tx ty tz qx qy qz qw\n");
    for pose in poses {
        let v = tum_from_isometry(&pose.world_from_camera);
        text.push_str(&format_timestamp(pose.timestamp_s));
        for value in v {
            text.push_str(&format!(" {value:.17e}"));
        }
        text.push('\n');
    }
    text
}

/// Writes poses to a TUM trajectory file, atomically.
///
/// # Errors
/// [`TumError::Write`] naming the file.
pub fn write_tum_trajectory(
    path: &Path,
    poses: &[StampedPose],
    comment: &str,
) -> Result<(), TumError> {
    let text = format_tum_trajectory(poses, comment);
    crate::atomic::write_bytes_atomically(path, text.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn round_trip_is_exact() {
        let poses: Vec<StampedPose> = (0..50)
            .map(|i| StampedPose {
                timestamp_s: 1_305_031_102.0 + i as f64 * 0.05,
                world_from_camera: Isometry3::new(
                    Vector3::new(i as f64 * 0.1234567, -3.3, 1e-3 * i as f64),
                    Vector3::new(0.1 * i as f64, -0.2, 0.3),
                ),
            })
            .collect();
        let back = parse_tum_trajectory(&format_tum_trajectory(&poses, "test")).unwrap();
        assert_eq!(back.len(), poses.len());
        for (a, b) in poses.iter().zip(&back) {
            assert!((a.timestamp_s - b.timestamp_s).abs() < 1e-6);
            assert!(
                (a.world_from_camera.translation.vector - b.world_from_camera.translation.vector)
                    .norm()
                    < 1e-9
            );
            assert!(
                a.world_from_camera
                    .rotation
                    .angle_to(&b.world_from_camera.rotation)
                    < 1e-9
            );
        }
    }

    #[test]
    fn rejects_out_of_order_and_bad_lines() {
        let err = parse_tum_trajectory("1 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n").unwrap_err();
        assert_eq!(err.0, 2);
        assert!(err.1.contains("not after"));
        assert_eq!(
            parse_tum_trajectory("# c\n1 0 0 0 0 0 1\n").unwrap_err().0,
            2
        );
        assert!(parse_tum_trajectory("1 0 0 nan 0 0 0 1\n").is_err());
        assert!(
            parse_tum_trajectory("1 0 0 0 0 0 0 0\n")
                .unwrap_err()
                .1
                .contains("zero norm")
        );
    }
}
