//! A recorded flight as a sensor source: the TUM RGB-D layout with `estimate.txt` (see
//! [`crate::mission::record`] for what `scarp simulate --record` writes), read frame after
//! frame. `flight.txt`, when present, gives each frame's mount pitch and the mode the flight
//! was in; `origin.toml` places the ENU frame on the globe.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::Isometry3;
use scarp_datasets::sequence::Sequence;
use scarp_slam::{PinholeCamera, RgbdFrame};

use super::super::error::{Context, MissionError, MissionResult};
use super::super::mode::Mode;
use super::super::record::FlightOrigin;
use super::{SensedPose, Sensors};

/// One line of `flight.txt`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FlightLogLine {
    mount_pitch_down_deg: f64,
    mode: Mode,
}

/// A recorded flight, read in time order (see the [module docs](self)).
pub struct Recorded {
    sequence: Sequence,
    estimates: Vec<Isometry3<f64>>,
    /// `flight.txt` by frame time (microseconds), if the folder has one.
    flight_log: Option<BTreeMap<u64, FlightLogLine>>,
    /// The frame [`Sensors::next_pose`] returns next.
    next: usize,
    /// The frame it returned last.
    current: Option<usize>,
}

impl Recorded {
    /// Opens the flight folder `dir`.
    ///
    /// # Errors
    /// An unreadable folder (a missing list, camera model or image named by the sequence
    /// reader), a flight without frames, a frame without a pose in `estimate.txt`, or a
    /// malformed `flight.txt` (its line named).
    pub fn open(dir: &Path) -> MissionResult<Self> {
        let sequence =
            Sequence::open(dir).with_context(|| format!("opening the flight {}", dir.display()))?;
        if sequence.is_empty() {
            return Err(MissionError::invalid(format!(
                "{}: the flight has no frames",
                dir.display()
            )));
        }
        let estimates = sequence
            .entries
            .iter()
            .enumerate()
            .map(|(i, e)| {
                e.world_from_camera_estimate.with_context(|| {
                    format!(
                        "{}: frame {i} (t = {:.6} s) has no pose in estimate.txt",
                        dir.display(),
                        e.timestamp_s
                    )
                })
            })
            .collect::<MissionResult<_>>()?;
        let flight_log = read_flight_log(&dir.join("flight.txt"))?;
        Ok(Self {
            sequence,
            estimates,
            flight_log,
            next: 0,
            current: None,
        })
    }

    /// The flight folder's contents: frames, lists and the simulated detector's `boxes.txt`.
    pub fn sequence(&self) -> &Sequence {
        &self.sequence
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.estimates.len()
    }

    /// Never true: [`Self::open`] refuses a flight without frames.
    pub fn is_empty(&self) -> bool {
        self.estimates.is_empty()
    }

    /// Whether the folder has `flight.txt` (the modes the flight was flown in).
    pub fn has_flight_log(&self) -> bool {
        self.flight_log.is_some()
    }

    /// [`Sensors::next_pose`] with the frame's index in the flight, for passes that also read
    /// frames by index.
    ///
    /// # Errors
    /// As [`Sensors::next_pose`].
    pub fn next_indexed(&mut self) -> MissionResult<Option<(usize, SensedPose)>> {
        let index = self.next;
        Ok(self.next_pose()?.map(|pose| (index, pose)))
    }

    /// The index of the frame [`Sensors::next_pose`] returned last.
    pub fn index(&self) -> Option<usize> {
        self.current
    }

    /// The mode the flight was in at the current frame (`flight.txt`); `Search` without a
    /// flight log, before the first frame, or for a frame the log does not list.
    pub fn mode(&self) -> Mode {
        self.current
            .and_then(|i| self.log_line(i))
            .map_or(Mode::Search, |line| line.mode)
    }

    /// The pose estimate of frame `index`.
    pub fn estimate(&self, index: usize) -> Option<&Isometry3<f64>> {
        self.estimates.get(index)
    }

    /// Seconds from the first frame to the last.
    pub fn duration_s(&self) -> f64 {
        let entries = &self.sequence.entries;
        entries.last().map_or(0.0, |e| e.timestamp_s)
            - entries.first().map_or(0.0, |e| e.timestamp_s)
    }

    /// Back to before the first frame, for another pass.
    pub fn rewind(&mut self) {
        self.next = 0;
        self.current = None;
    }

    /// The images of frame `index`, out of order.
    ///
    /// # Errors
    /// An index beyond the flight, or an image that cannot be read (named).
    pub fn images_at(&self, index: usize) -> MissionResult<RgbdFrame> {
        self.sequence.load_frame(index).with_context(|| {
            format!(
                "reading frame {index} of the flight {}",
                self.sequence.dir.display()
            )
        })
    }

    /// `origin.toml`, or `None` when the folder has none.
    ///
    /// # Errors
    /// A malformed `origin.toml`.
    pub fn origin(&self) -> MissionResult<Option<FlightOrigin>> {
        let path = self.sequence.dir.join("origin.toml");
        if path.exists() {
            FlightOrigin::read(&path).map(Some)
        } else {
            Ok(None)
        }
    }

    fn log_line(&self, index: usize) -> Option<FlightLogLine> {
        let t = self.sequence.entries.get(index)?.timestamp_s;
        self.flight_log.as_ref()?.get(&time_key(t)).copied()
    }
}

impl Sensors for Recorded {
    fn camera(&self) -> &PinholeCamera {
        &self.sequence.camera
    }

    fn next_pose(&mut self) -> MissionResult<Option<SensedPose>> {
        let index = self.next;
        let Some(entry) = self.sequence.entries.get(index) else {
            self.current = None;
            return Ok(None);
        };
        self.next += 1;
        self.current = Some(index);
        Ok(Some(SensedPose {
            timestamp_s: entry.timestamp_s,
            world_from_camera_estimate: self.estimates[index],
            mount_pitch_down_deg: self.log_line(index).map(|l| l.mount_pitch_down_deg),
            world_from_camera_truth: entry.world_from_camera_truth,
        }))
    }

    fn images(&mut self) -> MissionResult<RgbdFrame> {
        let index = self.current.ok_or_else(|| {
            MissionError::invalid(format!(
                "{}: no current frame to read the images of",
                self.sequence.dir.display()
            ))
        })?;
        self.images_at(index)
    }
}

/// Reads `flight.txt` (`timestamp_s mount_pitch_down_deg mode target` per line); `None` when
/// the file does not exist.
fn read_flight_log(path: &Path) -> MissionResult<Option<BTreeMap<u64, FlightLogLine>>> {
    if !path.exists() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = BTreeMap::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        let bad = || {
            MissionError::invalid(format!(
                "{}:{}: expected `timestamp_s mount_pitch_down_deg mode target`, got `{line}`",
                path.display(),
                number + 1
            ))
        };
        let [t, pitch, mode, target] = fields[..] else {
            return Err(bad());
        };
        let t: f64 = t.parse().map_err(|_| bad())?;
        let mount_pitch_down_deg: f64 = pitch
            .parse()
            .ok()
            .filter(|p: &f64| p.is_finite())
            .ok_or_else(bad)?;
        let target = match target {
            "-" => None,
            id => Some(id.parse::<u32>().map_err(|_| bad())?),
        };
        let mode = Mode::parse(mode, target).ok_or_else(bad)?;
        lines.insert(
            time_key(t),
            FlightLogLine {
                mount_pitch_down_deg,
                mode,
            },
        );
    }
    Ok(Some(lines))
}

/// A timestamp as a map key, to the microsecond the lists are written with.
fn time_key(t: f64) -> u64 {
    (t * 1e6).round() as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flight_log_is_read_and_bad_lines_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flight.txt");
        assert!(read_flight_log(&path).unwrap().is_none());
        std::fs::write(
            &path,
            "# header\n0.250000 55.0 search -\n0.500000 20.0 map 3\n0.750000 55.0 fine_localize 4\n",
        )
        .unwrap();
        let lines = read_flight_log(&path).unwrap().unwrap();
        assert_eq!(lines[&time_key(0.25)].mode, Mode::Search);
        assert_eq!(lines[&time_key(0.5)].mode, Mode::Map(3));
        assert_eq!(lines[&time_key(0.5)].mount_pitch_down_deg, 20.0);
        assert_eq!(lines[&time_key(0.75)].mode, Mode::FineLocalize(4));
        std::fs::write(&path, "0.25 55.0 map -\n").unwrap();
        let err = read_flight_log(&path).unwrap_err().to_string();
        assert!(err.contains("flight.txt:1"), "{err}");
        std::fs::write(&path, "0.25 55.0 hover -\n").unwrap();
        assert!(read_flight_log(&path).is_err());
        std::fs::write(&path, "0.25 nan search -\n").unwrap();
        assert!(read_flight_log(&path).is_err());
    }
}
