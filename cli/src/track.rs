//! `scarp track`: detect and track target boxes through a sequence.
//!
//! Writes `DIR/tracks.txt` (`t id x_min y_min x_max y_max`, one line per frame and confirmed
//! track, continuous pixel coordinates) and `DIR/track.json`. When the sequence has
//! ground-truth boxes (`boxes.txt`), the JSON also scores the tracks (MOTA, ID switches, mean
//! IoU, false tracks; see [`scarp::evaluation::tracking`]).
//!
//! The issue-6 lawn-mower figure comes from:
//!
//! ```text
//! scarp render --path lawnmower --frames 1200 --out /tmp/lawnmower
//! scarp track /tmp/lawnmower --detector simulated --out /tmp/lawnmower-tracks --json
//! ```

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use scarp_datasets::sequence::{BoxRecord, Sequence};
use scarp_datasets::world::RockRole;
use scarp_export::atomic::{write_atomically, write_bytes_atomically};
use scarp_slam::image::gray_from_rgb;
use serde::{Deserialize, Serialize};

use scarp::detection::simulated::roles_from_boxes;
use scarp::detection::{
    BoundingBox, Detector, OnnxDetectorConfig, SimulatedDetector, SimulatedDetectorConfig,
};
use scarp::evaluation::tracking::{
    EvalFrame, TrackObservation, TrackingEvalConfig, TrackingScores, TruthBox, evaluate_tracking,
};
use scarp::tracking::{TrackedBox, Tracker, TrackerConfig};

/// Track target boxes through a sequence (`tracks.txt`, `track.json`).
#[derive(Debug, Args)]
pub struct TrackArgs {
    /// The sequence directory (TUM RGB-D layout; `mask/` and `boxes.txt` for the simulated
    /// detector and the scores).
    pub sequence: PathBuf,
    /// `simulated` (needs instance masks) or `onnx:MODEL` (a YOLO v5/v8 ONNX export; needs
    /// the `onnx` cargo feature).
    #[arg(long, default_value = "simulated")]
    pub detector: String,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// A TOML file with `[tracker]`, `[simulated_detector]`, `[onnx_detector]` and
    /// `[evaluation]` tables; missing keys keep their defaults.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Seed of the simulated detector (overrides the config file's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Track only the first N frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Print the JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The tunables of `scarp track`, as read from `--config`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackConfig {
    /// The box tracker.
    pub tracker: TrackerConfig,
    /// The simulated detector.
    pub simulated_detector: SimulatedDetectorConfig,
    /// The ONNX YOLO detector (`--detector onnx:MODEL`, cargo feature `onnx`).
    pub onnx_detector: OnnxDetectorConfig,
    /// Scoring against `boxes.txt`.
    pub evaluation: TrackingEvalConfig,
}

/// The JSON summary.
#[derive(Debug, Clone, Serialize)]
pub struct TrackSummary {
    /// Frames tracked.
    pub frames: usize,
    /// Distinct confirmed track ids.
    pub tracks: usize,
    /// Mean IoU of matched track boxes with the true target boxes (`null` without `boxes.txt`).
    pub mean_iou: Option<f64>,
    /// ID switches on targets (`null` without `boxes.txt`).
    pub id_switches: Option<usize>,
    /// CLEAR MOT accuracy (`null` without `boxes.txt`).
    pub mota: Option<f64>,
    /// Tracks that never matched a target (`null` without `boxes.txt`).
    pub false_tracks: Option<usize>,
    /// Longest false-track lifetime, s (`null` without `boxes.txt`).
    pub false_track_max_lifetime_s: Option<f64>,
    /// Median tracker time per frame (detection and image loading excluded), ms.
    pub ms_per_frame_median: f64,
    /// 95th-percentile tracker time per frame, ms.
    pub ms_per_frame_p95: f64,
    /// The detector used.
    pub detector: String,
    /// All scores (`null` without `boxes.txt`).
    pub scores: Option<TrackingScores>,
    /// The configuration used.
    pub config: TrackConfig,
}

/// Loads `--config`, or the defaults.
fn load_config(path: Option<&Path>) -> anyhow::Result<TrackConfig> {
    let Some(path) = path else {
        return Ok(TrackConfig::default());
    };
    super::read_toml_config(path)
}

/// Builds the detector named by `--detector`.
fn make_detector(
    name: &str,
    config: &TrackConfig,
    boxes: &[BoxRecord],
) -> anyhow::Result<Box<dyn Detector>> {
    if name == "simulated" {
        let detector =
            SimulatedDetector::new(config.simulated_detector.clone(), roles_from_boxes(boxes))?;
        return Ok(Box::new(detector));
    }
    if let Some(model) = name.strip_prefix("onnx:") {
        return scarp::detection::load_onnx_detector(
            Path::new(model),
            config.onnx_detector.clone(),
        )
        .with_context(|| format!("--detector onnx:{model}"));
    }
    bail!("--detector must be `simulated` or `onnx:MODEL`, got `{name}`")
}

/// Groups `boxes.txt` by frame time: the boxes whose timestamp is within 1 ms of `t`.
fn truth_at(boxes: &[BoxRecord], t: f64) -> Vec<TruthBox> {
    boxes
        .iter()
        .filter(|b| (b.timestamp_s - t).abs() < 1e-3)
        .map(|b| TruthBox {
            id: b.id,
            is_target: b.role == RockRole::Target,
            bbox: BoundingBox::from_inclusive_pixels(b.bbox_px),
        })
        .collect()
}

/// The `p`-quantile (0..=1, nearest rank) of `values`; 0 when empty.
fn quantile(values: &[f64], p: f64) -> f64 {
    scarp_slam::stats::quantile(values, p).unwrap_or(0.0)
}

/// Runs `scarp track`.
///
/// # Errors
/// Sequence, config, detector, tracker and writing errors, naming the file or key.
pub fn run(args: TrackArgs) -> anyhow::Result<()> {
    let mut config = load_config(args.config.as_deref())?;
    if let Some(seed) = args.seed {
        config.simulated_detector.seed = seed;
    }
    let sequence = Sequence::open(&args.sequence)
        .with_context(|| format!("opening sequence {}", args.sequence.display()))?;
    let mut detector = make_detector(&args.detector, &config, &sequence.boxes)?;
    let mut tracker = Tracker::new(config.tracker.clone()).context("tracker config")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;

    let count = args
        .frames
        .map_or(sequence.entries.len(), |n| n.min(sequence.entries.len()));
    let bar = super::progress_bar(count as u64, "tracking");
    let mut per_frame: Vec<(f64, Vec<TrackedBox>)> = Vec::with_capacity(count);
    let mut step_ms = Vec::with_capacity(count);
    for index in 0..count {
        let frame = sequence
            .load_frame(index)
            .with_context(|| format!("loading frame {index}"))?;
        let detections = detector
            .detect(&frame)
            .with_context(|| format!("detecting in frame {index}"))?;
        let gray = gray_from_rgb(&frame.rgb);
        let start = Instant::now();
        let tracks = tracker
            .step(&gray, &detections)
            .with_context(|| format!("tracking frame {index}"))?;
        step_ms.push(start.elapsed().as_secs_f64() * 1e3);
        per_frame.push((
            frame.timestamp_s,
            tracks.into_iter().filter(|t| t.confirmed).collect(),
        ));
        bar.inc(1);
    }
    bar.finish_and_clear();

    let tracks_path = args.out.join("tracks.txt");
    write_atomically(&tracks_path, |w| {
        writeln!(
            w,
            "# t id x_min y_min x_max y_max (px, continuous, pixel centres at integers)"
        )?;
        for (t, tracks) in &per_frame {
            for tr in tracks {
                let b = tr.bbox;
                writeln!(
                    w,
                    "{t:.6} {} {:.2} {:.2} {:.2} {:.2}",
                    tr.id, b.x_min, b.y_min, b.x_max, b.y_max
                )?;
            }
        }
        Ok(())
    })?;

    let scores = (!sequence.boxes.is_empty()).then(|| {
        let frames: Vec<EvalFrame> = per_frame
            .iter()
            .map(|(t, tracks)| EvalFrame {
                timestamp_s: *t,
                tracks: tracks
                    .iter()
                    .map(|tr| TrackObservation {
                        id: tr.id,
                        bbox: tr.bbox,
                    })
                    .collect(),
                truth: truth_at(&sequence.boxes, *t),
            })
            .collect();
        evaluate_tracking(
            &frames,
            sequence.camera.width,
            sequence.camera.height,
            &config.evaluation,
        )
    });
    let distinct: std::collections::BTreeSet<u64> = per_frame
        .iter()
        .flat_map(|(_, tracks)| tracks.iter().map(|t| t.id))
        .collect();
    let summary = TrackSummary {
        frames: count,
        tracks: distinct.len(),
        mean_iou: scores.as_ref().map(|s| s.mean_iou),
        id_switches: scores.as_ref().map(|s| s.id_switches),
        mota: scores.as_ref().map(|s| s.mota),
        false_tracks: scores.as_ref().map(|s| s.false_tracks),
        false_track_max_lifetime_s: scores.as_ref().map(|s| s.false_track_max_lifetime_s),
        ms_per_frame_median: quantile(&step_ms, 0.5),
        ms_per_frame_p95: quantile(&step_ms, 0.95),
        detector: args.detector.clone(),
        scores,
        config,
    };
    let json = serde_json::to_string_pretty(&summary)?;
    write_bytes_atomically(args.out.join("track.json"), json.as_bytes())?;
    if args.json {
        println!("{json}");
    } else {
        eprintln!(
            "tracked {} frames: {} tracks, median {:.2} ms/frame; wrote {}",
            summary.frames,
            summary.tracks,
            summary.ms_per_frame_median,
            tracks_path.display()
        );
    }
    Ok(())
}
