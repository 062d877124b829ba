//! A modelled detector for synthetic sequences: ground-truth instance masks in, boxes with the
//! errors of a trained network out.
//!
//! # The model
//!
//! For every frame, each rock id `1..=999` of the instance mask that the role map knows is
//! measured: its visible pixel count, its tight box (inclusive pixel bounds turned into
//! continuous coordinates, see [`BoundingBox::from_inclusive_pixels`]) and how much of it lies
//! on the image border. Pedestal (`1000 + id`) and terrain (`2000`) pixels are background.
//!
//! A rock is *detectable* when
//! - it has at least [`SimulatedDetectorConfig::min_visible_px`] pixels;
//! - its *fill* (visible pixels / box area, px²) is at least
//!   [`SimulatedDetectorConfig::min_fill_fraction`]. Without an unoccluded rendering the fill is
//!   the occlusion proxy: an unoccluded boulder fills about 0.5–0.8 of its box, one with a
//!   large bite taken out of it much less;
//! - its *truncation* is at most [`SimulatedDetectorConfig::max_truncation_fraction`]. The
//!   truncation is, over the four image borders, the largest share of the box's side along that
//!   border covered by the rock's pixels on the outermost row or column: 0 for a rock clear of
//!   the border, 1 for a rock cut off along the full height (or width) of its box.
//!
//! A detectable **target** is missed with probability [`SimulatedDetectorConfig::miss_rate`];
//! otherwise it gives one box whose four edges are moved independently by
//! N(0, [`SimulatedDetectorConfig::jitter_sigma_px`]²), with a true-positive score. A detectable
//! **distractor** gives a false positive with probability
//! [`SimulatedDetectorConfig::distractor_fp_probability`] (its jittered box, a false-positive
//! score). On top, a Poisson number of boxes with mean
//! [`SimulatedDetectorConfig::random_fp_rate_per_frame`] fire on random texture: uniform sizes
//! and positions inside the image.
//!
//! Scores are N(mean, σ²) clamped to `[0.01, 1]`, with separate means for true and false
//! positives, so a score threshold trades misses for false positives as with a real network.
//! Every box is clipped to the image and keeps at least 1 px of width and height. All boxes
//! have class 0 ([`SimulatedDetectorConfig::class_id`]).
//!
//! # Determinism
//!
//! Each frame draws from its own `Xoshiro256PlusPlus`, seeded from
//! [`SimulatedDetectorConfig::seed`] and the bits of the frame's timestamp, and rocks are visited
//! in increasing id order with a fixed number of draws each. The detections of a frame therefore
//! depend only on the seed and the frame, not on which frames came before.

use std::collections::BTreeMap;

use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use scarp_datasets::noise::derive_seed;
use scarp_datasets::sequence::BoxRecord;
use scarp_datasets::world::{RockRole, World};
use scarp_slam::frame::RgbdFrame;
use scarp_slam::image::MaskImage;

use super::{BoundingBox, Detection, DetectionError, Detector};

/// The largest instance id that is a rock (ids `1..=999`).
const MAX_ROCK_ID: u16 = 999;
/// Lowest score a modelled detection gets.
const MIN_SCORE: f64 = 0.01;
/// Largest accepted mean number of random false positives per frame (keeps the Poisson draw
/// cheap and the model sane).
const MAX_RANDOM_FP_RATE: f64 = 20.0;

/// Tunables of [`SimulatedDetector`]; the defaults model a YOLO-class network fine-tuned on
/// the targets (the lawn-mower test setting: σ 4 px, 10 % misses, false positives on
/// distractors).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimulatedDetectorConfig {
    /// Seed of the random draws. Default 0.
    pub seed: u64,
    /// σ of the independent Gaussian shift of each box edge, px. Default 4.
    pub jitter_sigma_px: f64,
    /// Probability that a detectable target gives no box in a frame. Default 0.1.
    pub miss_rate: f64,
    /// Probability that a detectable distractor boulder gives a (false) box in a frame.
    /// Default 0.05.
    pub distractor_fp_probability: f64,
    /// Mean number of false boxes on random texture per frame (Poisson). Default 0.02, about
    /// one every 2.5 s at 20 Hz.
    pub random_fp_rate_per_frame: f64,
    /// Smallest side of a random-texture false box, px. Default 16.
    pub random_fp_min_size_px: f64,
    /// Largest side of a random-texture false box, px. Default 96.
    pub random_fp_max_size_px: f64,
    /// Fewest visible pixels for a rock to be detectable. Default 64 (an 8 × 8 px blob, about
    /// the smallest object a YOLO at 640 px input finds reliably).
    pub min_visible_px: u32,
    /// Smallest fill (visible pixels / box area) for a rock to be detectable: the occlusion
    /// limit. Default 0.2.
    pub min_fill_fraction: f64,
    /// Largest truncation (share of the box side lying on the image border) for a rock to be
    /// detectable. Default 0.5.
    pub max_truncation_fraction: f64,
    /// Mean score of a true positive. Default 0.85.
    pub true_positive_score_mean: f64,
    /// Mean score of a false positive. Default 0.5.
    pub false_positive_score_mean: f64,
    /// σ of every score around its mean. Default 0.1.
    pub score_sigma: f64,
    /// Class of every box. Default 0 (precariously balanced rock).
    pub class_id: u32,
}

impl Default for SimulatedDetectorConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            jitter_sigma_px: 4.0,
            miss_rate: 0.1,
            distractor_fp_probability: 0.05,
            random_fp_rate_per_frame: 0.02,
            random_fp_min_size_px: 16.0,
            random_fp_max_size_px: 96.0,
            min_visible_px: 64,
            min_fill_fraction: 0.2,
            max_truncation_fraction: 0.5,
            true_positive_score_mean: 0.85,
            false_positive_score_mean: 0.5,
            score_sigma: 0.1,
            class_id: 0,
        }
    }
}

impl SimulatedDetectorConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`DetectionError::Config`] naming the first field out of range: a negative or non-finite
    /// σ, a probability or fraction outside `[0, 1]`, a random false-positive rate outside
    /// `[0, 20]`, random box sizes that are not `1 <= min <= max`, or a score mean outside
    /// `[0, 1]`.
    pub fn validate(&self) -> Result<(), DetectionError> {
        let bad =
            |field: &'static str, reason: String| Err(DetectionError::Config { field, reason });
        let non_negative = [
            ("jitter_sigma_px", self.jitter_sigma_px),
            ("score_sigma", self.score_sigma),
        ];
        for (field, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return bad(field, format!("must be finite and >= 0, got {value}"));
            }
        }
        let unit = [
            ("miss_rate", self.miss_rate),
            ("distractor_fp_probability", self.distractor_fp_probability),
            ("min_fill_fraction", self.min_fill_fraction),
            ("max_truncation_fraction", self.max_truncation_fraction),
            ("true_positive_score_mean", self.true_positive_score_mean),
            ("false_positive_score_mean", self.false_positive_score_mean),
        ];
        for (field, value) in unit {
            if !(0.0..=1.0).contains(&value) {
                return bad(field, format!("must lie in [0, 1], got {value}"));
            }
        }
        let rate = self.random_fp_rate_per_frame;
        if !(0.0..=MAX_RANDOM_FP_RATE).contains(&rate) {
            return bad(
                "random_fp_rate_per_frame",
                format!("must lie in [0, {MAX_RANDOM_FP_RATE}], got {rate}"),
            );
        }
        let (lo, hi) = (self.random_fp_min_size_px, self.random_fp_max_size_px);
        if !(lo.is_finite() && lo >= 1.0) {
            return bad(
                "random_fp_min_size_px",
                format!("must be finite and >= 1, got {lo}"),
            );
        }
        if !(hi.is_finite() && hi >= lo) {
            return bad(
                "random_fp_max_size_px",
                format!("must be finite and >= random_fp_min_size_px ({lo}), got {hi}"),
            );
        }
        Ok(())
    }
}

/// What the detector should do with a rock id: find it or (sometimes) confuse it.
pub type RoleMap = BTreeMap<u32, RockRole>;

/// The role of every rock of a world.
pub fn roles_from_world(world: &World) -> RoleMap {
    world.rocks.iter().map(|r| (r.id, r.role)).collect()
}

/// The role of every rock named in a sequence's `boxes.txt` (rocks never seen are absent,
/// which is harmless: they are never in a mask either).
pub fn roles_from_boxes(boxes: &[BoxRecord]) -> RoleMap {
    boxes.iter().map(|b| (b.id, b.role)).collect()
}

/// What one frame's mask shows of one rock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InstanceStats {
    /// Rock id.
    pub id: u32,
    /// Visible pixels.
    pub visible_px: u32,
    /// Inclusive pixel bounds `[x_min, y_min, x_max, y_max]`.
    pub bounds_px: [u32; 4],
    /// Rock pixels on the left, top, right and bottom image borders (column 0, row 0, last
    /// column, last row).
    pub border_px: [u32; 4],
}

impl InstanceStats {
    /// The tight box in continuous pixel coordinates.
    pub fn bbox(&self) -> BoundingBox {
        BoundingBox::from_inclusive_pixels(self.bounds_px)
    }

    /// Visible pixels over box area, in `(0, 1]`.
    pub fn fill_fraction(&self) -> f64 {
        f64::from(self.visible_px) / self.bbox().area()
    }

    /// The largest share of a box side lying on the image border, in `[0, 1]` (see the module
    /// docs).
    pub fn truncation_fraction(&self) -> f64 {
        let [x0, y0, x1, y1] = self.bounds_px;
        let box_h = f64::from(y1 - y0 + 1);
        let box_w = f64::from(x1 - x0 + 1);
        let [left, top, right, bottom] = self.border_px.map(f64::from);
        (left / box_h)
            .max(right / box_h)
            .max(top / box_w)
            .max(bottom / box_w)
    }
}

/// Per-rock statistics of an instance mask, for ids `1..=999`, in increasing id order.
pub fn instance_stats(mask: &MaskImage) -> Vec<InstanceStats> {
    let (w, h) = (mask.width(), mask.height());
    let mut slots: Vec<Option<InstanceStats>> = vec![None; usize::from(MAX_ROCK_ID) + 1];
    for v in 0..h {
        for (u, &id) in mask.row(v).iter().enumerate() {
            if id == 0 || id > MAX_ROCK_ID {
                continue;
            }
            // `u` indexes a row of a `w`-wide image, so it fits in u32.
            let u = u as u32;
            let s = slots[usize::from(id)].get_or_insert(InstanceStats {
                id: u32::from(id),
                visible_px: 0,
                bounds_px: [u, v, u, v],
                border_px: [0; 4],
            });
            s.visible_px += 1;
            let b = &mut s.bounds_px;
            *b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
            s.border_px[0] += u32::from(u == 0);
            s.border_px[1] += u32::from(v == 0);
            s.border_px[2] += u32::from(u + 1 == w);
            s.border_px[3] += u32::from(v + 1 == h);
        }
    }
    slots.into_iter().flatten().collect()
}

/// The modelled network (see the module docs).
#[derive(Debug, Clone)]
pub struct SimulatedDetector {
    config: SimulatedDetectorConfig,
    roles: RoleMap,
}

impl SimulatedDetector {
    /// A detector with a checked config and the role of each rock id; ids missing from `roles`
    /// are ignored (treated as background).
    ///
    /// # Errors
    /// [`DetectionError::Config`] from [`SimulatedDetectorConfig::validate`].
    pub fn new(config: SimulatedDetectorConfig, roles: RoleMap) -> Result<Self, DetectionError> {
        config.validate()?;
        Ok(Self { config, roles })
    }

    /// A detector for the rocks of `world`.
    ///
    /// # Errors
    /// As [`SimulatedDetector::new`].
    pub fn for_world(
        config: SimulatedDetectorConfig,
        world: &World,
    ) -> Result<Self, DetectionError> {
        Self::new(config, roles_from_world(world))
    }

    /// The configuration.
    pub fn config(&self) -> &SimulatedDetectorConfig {
        &self.config
    }

    /// Whether a rock as seen in a mask passes the visibility, occlusion and truncation limits.
    pub fn is_detectable(&self, stats: &InstanceStats) -> bool {
        stats.visible_px >= self.config.min_visible_px
            && stats.fill_fraction() >= self.config.min_fill_fraction
            && stats.truncation_fraction() <= self.config.max_truncation_fraction
    }

    /// Detections in a bare instance mask taken at `timestamp_s` (the frame's clock, used only
    /// to seed the frame's draws), sorted by descending score.
    pub fn detect_mask(&self, mask: &MaskImage, timestamp_s: f64) -> Vec<Detection> {
        let c = &self.config;
        let (w, h) = (mask.width(), mask.height());
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(derive_seed(c.seed, timestamp_s.to_bits()));
        let mut out = Vec::new();
        for stats in instance_stats(mask) {
            let Some(&role) = self.roles.get(&stats.id) else {
                continue;
            };
            if !self.is_detectable(&stats) {
                continue;
            }
            // Fixed draws per rock, whatever the outcome, so that one rock's fate does not
            // shift another's.
            let fires: f64 = rng.random();
            let shifts: [f64; 4] = std::array::from_fn(|_| gaussian(&mut rng));
            let score_noise = gaussian(&mut rng);
            let (fire_probability, score_mean) = match role {
                RockRole::Target => (1.0 - c.miss_rate, c.true_positive_score_mean),
                RockRole::Distractor => (c.distractor_fp_probability, c.false_positive_score_mean),
            };
            if fires < fire_probability {
                let bbox = jittered(stats.bbox(), shifts, c.jitter_sigma_px, w, h);
                out.push(self.detection(bbox, score_mean, score_noise));
            }
        }
        let count = poisson(c.random_fp_rate_per_frame, &mut rng);
        for _ in 0..count {
            let bbox = random_box(
                c.random_fp_min_size_px,
                c.random_fp_max_size_px,
                w,
                h,
                &mut rng,
            );
            let score_noise = gaussian(&mut rng);
            out.push(self.detection(bbox, c.false_positive_score_mean, score_noise));
        }
        out.sort_by(|a, b| b.score.total_cmp(&a.score));
        out
    }

    fn detection(&self, bbox: BoundingBox, score_mean: f64, noise: f64) -> Detection {
        let score = (score_mean + self.config.score_sigma * noise).clamp(MIN_SCORE, 1.0);
        Detection {
            bbox,
            score: score as f32,
            class_id: self.config.class_id,
        }
    }
}

impl Detector for SimulatedDetector {
    /// # Errors
    /// [`DetectionError::MissingInput`] when the frame has no instance mask.
    fn detect(&mut self, frame: &RgbdFrame) -> Result<Vec<Detection>, DetectionError> {
        let mask = frame.instance_mask.as_ref().ok_or_else(|| {
            DetectionError::MissingInput(format!(
                "the simulated detector needs the frame's instance mask; frame at t = {} s has none",
                frame.timestamp_s
            ))
        })?;
        Ok(self.detect_mask(mask, frame.timestamp_s))
    }
}

/// A standard normal draw.
fn gaussian(rng: &mut Xoshiro256PlusPlus) -> f64 {
    StandardNormal.sample(rng)
}

/// A Poisson draw by multiplying uniforms (Knuth); fine for the small means accepted here.
fn poisson(mean: f64, rng: &mut Xoshiro256PlusPlus) -> u32 {
    if mean <= 0.0 {
        return 0;
    }
    let limit = (-mean).exp();
    let mut product: f64 = rng.random();
    let mut count = 0;
    while product > limit {
        count += 1;
        product *= rng.random::<f64>();
    }
    count
}

/// The image extent in continuous coordinates: `(-0.5, -0.5) ..= (w - 0.5, h - 0.5)`.
fn image_extent(width: u32, height: u32) -> [f64; 4] {
    [-0.5, -0.5, f64::from(width) - 0.5, f64::from(height) - 0.5]
}

/// `bbox` with each edge moved by `sigma_px · shift`, clipped to the image and kept at least
/// 1 px wide and high (the image is at least 1 px, as the box came from its mask).
pub fn jittered(
    bbox: BoundingBox,
    shifts: [f64; 4],
    sigma_px: f64,
    width: u32,
    height: u32,
) -> BoundingBox {
    let [ex0, ey0, ex1, ey1] = image_extent(width, height);
    let x = ordered_span(
        bbox.x_min + sigma_px * shifts[0],
        bbox.x_max + sigma_px * shifts[2],
        ex0,
        ex1,
    );
    let y = ordered_span(
        bbox.y_min + sigma_px * shifts[1],
        bbox.y_max + sigma_px * shifts[3],
        ey0,
        ey1,
    );
    BoundingBox {
        x_min: x.0,
        y_min: y.0,
        x_max: x.1,
        y_max: y.1,
    }
}

/// An interval from two jittered edges: clipped to `[lo, hi]` (with `hi - lo >= 1`) and at
/// least 1 px long.
fn ordered_span(a: f64, b: f64, lo: f64, hi: f64) -> (f64, f64) {
    let (a, b) = (a.clamp(lo, hi), b.clamp(lo, hi));
    if b - a >= 1.0 {
        return (a, b);
    }
    let centre = (0.5 * (a + b)).clamp(lo + 0.5, hi - 0.5);
    (centre - 0.5, centre + 0.5)
}

/// A random box inside a `width × height` image with sides uniform in `[min_px, max_px]`
/// (capped at the image size).
fn random_box(
    min_px: f64,
    max_px: f64,
    width: u32,
    height: u32,
    rng: &mut Xoshiro256PlusPlus,
) -> BoundingBox {
    let [ex0, ey0, ex1, ey1] = image_extent(width, height);
    let mut side = |extent: f64| {
        let size = (min_px + (max_px - min_px) * rng.random::<f64>()).min(extent);
        let start = (extent - size) * rng.random::<f64>();
        (start, size)
    };
    let (x, w) = side(ex1 - ex0);
    let (y, h) = side(ey1 - ey0);
    BoundingBox {
        x_min: ex0 + x,
        y_min: ey0 + y,
        x_max: ex0 + x + w,
        y_max: ey0 + y + h,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scarp_slam::image::{DepthImage, RgbImage};

    const W: u32 = 160;
    const H: u32 = 120;
    const TERRAIN: u16 = 2000;

    /// A mask of terrain with filled rectangles `(id, [x0, y0, x1, y1])` (inclusive).
    fn mask_with(rects: &[(u16, [u32; 4])]) -> MaskImage {
        let mut mask = MaskImage::filled(W, H, TERRAIN);
        for &(id, [x0, y0, x1, y1]) in rects {
            for v in y0..=y1 {
                for u in x0..=x1 {
                    if let Some(p) = mask.get_mut(u, v) {
                        *p = id;
                    }
                }
            }
        }
        mask
    }

    fn frame(t: f64, mask: Option<MaskImage>) -> RgbdFrame {
        RgbdFrame::new(
            t,
            RgbImage::filled(W, H, [0, 0, 0]),
            DepthImage::filled(W, H, 5.0),
            mask,
        )
        .unwrap()
    }

    fn roles() -> RoleMap {
        BTreeMap::from([(1, RockRole::Target), (2, RockRole::Distractor)])
    }

    fn quiet() -> SimulatedDetectorConfig {
        SimulatedDetectorConfig {
            random_fp_rate_per_frame: 0.0,
            distractor_fp_probability: 0.0,
            ..SimulatedDetectorConfig::default()
        }
    }

    fn mean_std(xs: &[f64]) -> (f64, f64) {
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    #[test]
    fn jitter_and_miss_rate_match_config() {
        let truth = [50, 40, 89, 79];
        let mask = mask_with(&[(1, truth)]);
        let det = SimulatedDetector::new(quiet(), roles()).unwrap();
        let true_box = BoundingBox::from_inclusive_pixels(truth);
        let trials = 4000;
        let mut left = Vec::new();
        let mut bottom = Vec::new();
        for i in 0..trials {
            let found = det.detect_mask(&mask, f64::from(i) * 0.05);
            assert!(found.len() <= 1);
            if let Some(d) = found.first() {
                left.push(d.bbox.x_min - true_box.x_min);
                bottom.push(d.bbox.y_max - true_box.y_max);
                assert_eq!(d.class_id, 0);
                assert!((0.01..=1.0).contains(&d.score));
            }
        }
        let miss = 1.0 - left.len() as f64 / f64::from(trials);
        // Binomial σ at p = 0.1, n = 4000 is 0.0047: allow 4σ.
        assert!((miss - 0.1).abs() < 0.02, "miss rate {miss}");
        for edge in [&left, &bottom] {
            let (mean, std) = mean_std(edge);
            assert!(mean.abs() < 0.3, "edge bias {mean}");
            assert!((std - 4.0).abs() < 0.25, "edge σ {std}");
        }
    }

    #[test]
    fn same_seed_same_detections_other_seed_differs() {
        let mask = mask_with(&[(1, [10, 10, 49, 49]), (2, [80, 30, 119, 69])]);
        let config = SimulatedDetectorConfig {
            random_fp_rate_per_frame: 2.0,
            distractor_fp_probability: 0.5,
            ..SimulatedDetectorConfig::default()
        };
        let mut a = SimulatedDetector::new(config.clone(), roles()).unwrap();
        let mut b = SimulatedDetector::new(config.clone(), roles()).unwrap();
        let frames: Vec<RgbdFrame> = (0..20)
            .map(|i| frame(f64::from(i) * 0.05, Some(mask.clone())))
            .collect();
        let run = |d: &mut SimulatedDetector| -> Vec<Vec<Detection>> {
            frames.iter().map(|f| d.detect(f).unwrap()).collect()
        };
        let first = run(&mut a);
        assert_eq!(first, run(&mut b));
        // Order independence: a frame's detections depend on the frame only.
        assert_eq!(b.detect(&frames[7]).unwrap(), first[7]);
        let mut c =
            SimulatedDetector::new(SimulatedDetectorConfig { seed: 1, ..config }, roles()).unwrap();
        assert_ne!(first, run(&mut c));
        for dets in &first {
            assert!(dets.windows(2).all(|p| p[0].score >= p[1].score));
        }
    }

    #[test]
    fn all_terrain_gives_only_random_false_positives() {
        let mask = mask_with(&[]);
        let det = SimulatedDetector::new(SimulatedDetectorConfig::default(), roles()).unwrap();
        let silent = SimulatedDetector::new(quiet(), roles()).unwrap();
        let busy = SimulatedDetector::new(
            SimulatedDetectorConfig {
                random_fp_rate_per_frame: 1.5,
                ..quiet()
            },
            roles(),
        )
        .unwrap();
        let mut busy_total = 0;
        let mut default_total = 0;
        let frames = 2000;
        for i in 0..frames {
            let t = f64::from(i) * 0.05;
            assert!(silent.detect_mask(&mask, t).is_empty());
            default_total += det.detect_mask(&mask, t).len();
            for d in busy.detect_mask(&mask, t) {
                busy_total += 1;
                assert!(d.bbox.is_inside_image(W, H, 0.0), "{:?}", d.bbox);
                assert!(d.bbox.width() >= 16.0 && d.bbox.width() <= 96.0);
                assert!(d.bbox.height() >= 16.0 && d.bbox.height() <= 96.0);
            }
        }
        let mean = busy_total as f64 / f64::from(frames);
        // Poisson σ of the mean is sqrt(1.5 / 2000) = 0.027: allow 4σ.
        assert!((mean - 1.5).abs() < 0.11, "random FP mean {mean}");
        // Default: 0.02 per frame → 40 expected, σ ≈ 6.3.
        assert!((15..=65).contains(&default_total), "{default_total}");
    }

    #[test]
    fn distractors_fire_at_their_probability_and_unknown_ids_never() {
        let mask = mask_with(&[(2, [20, 20, 59, 59]), (3, [80, 20, 119, 59])]);
        let det = SimulatedDetector::new(
            SimulatedDetectorConfig {
                distractor_fp_probability: 0.3,
                ..quiet()
            },
            roles(),
        )
        .unwrap();
        let frames = 3000;
        let mut fired = 0;
        for i in 0..frames {
            let found = det.detect_mask(&mask, f64::from(i));
            for d in &found {
                // Only the distractor (id 2, left) fires; id 3 is unknown.
                assert!(d.bbox.x_max < 75.0);
                assert!(d.score < 0.99);
            }
            fired += found.len();
        }
        let rate = fired as f64 / f64::from(frames);
        assert!((rate - 0.3).abs() < 0.04, "distractor FP rate {rate}");
    }

    #[test]
    fn visibility_occlusion_and_truncation_limits() {
        let det = SimulatedDetector::new(
            SimulatedDetectorConfig {
                miss_rate: 0.0,
                ..quiet()
            },
            roles(),
        )
        .unwrap();
        let count = |mask: &MaskImage| det.detect_mask(mask, 0.0).len();
        // 8 × 8 = 64 px is enough, 7 × 8 is not.
        assert_eq!(count(&mask_with(&[(1, [50, 50, 57, 57])])), 1);
        assert_eq!(count(&mask_with(&[(1, [50, 50, 56, 57])])), 0);
        // A thin diagonal-ish outline: two small blobs at opposite corners of a large box
        // (fill 2·100 / 60² = 0.056) is "mostly occluded".
        let sparse = mask_with(&[(1, [20, 20, 29, 29]), (1, [70, 70, 79, 79])]);
        assert_eq!(count(&sparse), 0);
        // Touching the left border along its full height: truncation 1.
        assert_eq!(count(&mask_with(&[(1, [0, 30, 19, 69])])), 0);
        // Touching it along a quarter of its height (the lower blob is larger): accepted.
        let corner = mask_with(&[(1, [0, 30, 19, 39]), (1, [1, 40, 30, 69])]);
        let stats = instance_stats(&corner);
        assert_eq!(stats.len(), 1);
        assert!((stats[0].truncation_fraction() - 0.25).abs() < 1e-12);
        assert_eq!(count(&corner), 1);
        // Pedestal pixels are background, not rock.
        let pedestal = mask_with(&[(1001, [50, 50, 89, 89])]);
        assert_eq!(count(&pedestal), 0);
    }

    #[test]
    fn missing_mask_is_an_error() {
        let mut det = SimulatedDetector::new(quiet(), roles()).unwrap();
        let err = det.detect(&frame(1.5, None)).unwrap_err();
        assert!(matches!(err, DetectionError::MissingInput(_)));
        assert!(err.to_string().contains("instance mask"));
    }

    #[test]
    fn degenerate_configs_are_rejected() {
        let cases: Vec<(&str, SimulatedDetectorConfig)> = vec![
            (
                "jitter_sigma_px",
                SimulatedDetectorConfig {
                    jitter_sigma_px: -1.0,
                    ..Default::default()
                },
            ),
            (
                "jitter_sigma_px",
                SimulatedDetectorConfig {
                    jitter_sigma_px: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "miss_rate",
                SimulatedDetectorConfig {
                    miss_rate: 1.5,
                    ..Default::default()
                },
            ),
            (
                "random_fp_rate_per_frame",
                SimulatedDetectorConfig {
                    random_fp_rate_per_frame: -0.1,
                    ..Default::default()
                },
            ),
            (
                "random_fp_max_size_px",
                SimulatedDetectorConfig {
                    random_fp_min_size_px: 50.0,
                    random_fp_max_size_px: 10.0,
                    ..Default::default()
                },
            ),
            (
                "max_truncation_fraction",
                SimulatedDetectorConfig {
                    max_truncation_fraction: f64::INFINITY,
                    ..Default::default()
                },
            ),
        ];
        for (field, config) in cases {
            match SimulatedDetector::new(config, roles()) {
                Err(DetectionError::Config { field: f, .. }) => assert_eq!(f, field),
                other => panic!("expected a config error on {field}, got {other:?}"),
            }
        }
        assert!(SimulatedDetectorConfig::default().validate().is_ok());
    }

    #[test]
    fn jittered_boxes_stay_valid_and_inside() {
        let b = BoundingBox::from_inclusive_pixels([0, 0, 3, 3]);
        let j = jittered(b, [10.0, -10.0, -10.0, 10.0], 4.0, W, H);
        assert!(j.width() >= 1.0 && j.height() >= 1.0);
        assert!(j.is_inside_image(W, H, 0.0));
        assert!(BoundingBox::new(j.x_min, j.y_min, j.x_max, j.y_max).is_ok());
    }

    #[test]
    fn config_round_trips_through_toml() {
        let text = toml::to_string(&SimulatedDetectorConfig::default()).unwrap();
        let back: SimulatedDetectorConfig = toml::from_str(&text).unwrap();
        assert_eq!(back, SimulatedDetectorConfig::default());
        assert!(toml::from_str::<SimulatedDetectorConfig>("sigma = 3").is_err());
    }

    #[test]
    fn noiseless_model_reproduces_the_rendered_target_boxes() {
        use scarp_datasets::paths::default_orbit;
        use scarp_datasets::render::Renderer;
        use scarp_datasets::sequence::boxes_from_mask;
        use scarp_slam::PinholeCamera;

        let world = World::builtin_default().unwrap();
        let camera = PinholeCamera::from_hfov(320, 240, 80.0).unwrap();
        let pose = default_orbit(&world, 4).unwrap()[0].world_from_camera;
        let out = Renderer::new(&world).render(&camera, &pose).unwrap();
        let exact = SimulatedDetectorConfig {
            jitter_sigma_px: 0.0,
            miss_rate: 0.0,
            max_truncation_fraction: 1.0,
            min_fill_fraction: 0.0,
            min_visible_px: 1,
            ..quiet()
        };
        let det = SimulatedDetector::for_world(exact, &world).unwrap();
        let mut got: Vec<[f64; 4]> = det
            .detect_mask(&out.instance, 0.0)
            .iter()
            .map(|d| [d.bbox.x_min, d.bbox.y_min, d.bbox.x_max, d.bbox.y_max])
            .collect();
        let mut truth: Vec<[f64; 4]> =
            boxes_from_mask(&out.instance, 0.0, |id| world.rock(id).map(|r| r.role))
                .into_iter()
                .filter(|b| b.role == RockRole::Target)
                .map(|b| {
                    let b = BoundingBox::from_inclusive_pixels(b.bbox_px);
                    [b.x_min, b.y_min, b.x_max, b.y_max]
                })
                .collect();
        assert!(!truth.is_empty(), "the orbit looks at a target");
        got.sort_by(|a, b| a[0].total_cmp(&b[0]));
        truth.sort_by(|a, b| a[0].total_cmp(&b[0]));
        assert_eq!(got, truth);
    }
}
