//! Keyframe selection: a frame becomes a keyframe when it brings new information over the last
//! keyframe: enough parallax for triangulation (the baseline seen from the scene's median depth),
//! a turn, or lost view overlap (co-visibility). A fixed translation step can be added, as the
//! mission's rings use.
//!
//! Two presets: [`KeyframeConfig::default`] for the mission's mapping rings (a UAV orbiting a
//! rock at 4–5 m, 0.5 m steps) and [`KeyframeConfig::handheld`] for a camera carried by hand at
//! 30 Hz (millimetre steps, so a step size would make a keyframe every few seconds only).

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::PinholeCamera;
use crate::image::DepthImage;

/// Keyframe thresholds. A frame is a keyframe when any one is crossed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KeyframeConfig {
    /// Camera translation since the last keyframe, metres; `None` disables it. Default 0.5 m
    /// (about a tenth of the 4 m mapping stand-off).
    pub min_translation_m: Option<f64>,
    /// Parallax since the last keyframe: the angle that the camera's translation subtends at
    /// the median depth of the current frame, degrees; `None` disables it. Scale-free, so one
    /// value suits a rock at 4 m and a kitchen at 2 m. Default `None` (the mission's rings step
    /// by `min_translation_m`, about 6° at 4.5 m).
    pub min_parallax_deg: Option<f64>,
    /// Camera rotation since the last keyframe, degrees. Default 10°.
    pub min_rotation_deg: f64,
    /// Overlap below this (fraction of the frame's depth pixels that land inside the keyframe's
    /// image) makes a keyframe. Default 0.7.
    pub min_overlap: f64,
    /// Pixel stride when measuring the overlap (every n-th row and column). Default 4.
    pub overlap_stride_px: u32,
}

impl Default for KeyframeConfig {
    fn default() -> Self {
        Self {
            min_translation_m: Some(0.5),
            min_parallax_deg: None,
            min_rotation_deg: 10.0,
            min_overlap: 0.7,
            overlap_stride_px: 4,
        }
    }
}

impl KeyframeConfig {
    /// A camera carried by hand at 30 Hz (a few millimetres and a fraction of a degree a
    /// frame): a keyframe at 1° of parallax (3.5 cm at 2 m), 5° of turn or below 85% overlap,
    /// which gives the bundle adjustment keyframes a few frames apart that share most of their
    /// view, and no translation step.
    pub fn handheld() -> Self {
        Self {
            min_translation_m: None,
            min_parallax_deg: Some(1.0),
            min_rotation_deg: 5.0,
            min_overlap: 0.85,
            overlap_stride_px: 4,
        }
    }

    /// Checks the ranges.
    ///
    /// # Errors
    /// [`crate::SlamError::InvalidConfig`] naming the field.
    pub fn validate(&self) -> Result<(), crate::SlamError> {
        let bad = |field: &'static str, reason: &'static str| {
            Err(crate::SlamError::InvalidConfig { field, reason })
        };
        for (field, value) in [
            ("min_translation_m", self.min_translation_m),
            ("min_parallax_deg", self.min_parallax_deg),
        ] {
            if value.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
                return bad(field, "must be positive and finite (or absent)");
            }
        }
        if !(self.min_rotation_deg.is_finite() && self.min_rotation_deg > 0.0) {
            return bad("min_rotation_deg", "must be positive and finite");
        }
        if !(0.0..=1.0).contains(&self.min_overlap) {
            return bad("min_overlap", "must be in [0, 1]");
        }
        if self.overlap_stride_px == 0 {
            return bad("overlap_stride_px", "must be at least 1");
        }
        Ok(())
    }
}

/// Which threshold made a frame a keyframe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum KeyframeReason {
    /// The first frame of a sequence.
    First,
    /// Moved farther than `min_translation_m` (the distance, metres).
    Translation(f64),
    /// Parallax above `min_parallax_deg` (the angle, degrees).
    Parallax(f64),
    /// Turned farther than `min_rotation_deg` (the angle, degrees).
    Rotation(f64),
    /// Overlap fell below `min_overlap` (the overlap).
    Overlap(f64),
}

/// What the current frame shares with the keyframe, measured on its depth pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewOverlap {
    /// Fraction of the frame's depth pixels that project inside the keyframe's image, in front
    /// of its camera (0 without depth or with a non-finite transform).
    pub overlap: f64,
    /// Median depth of those pixels, metres (0 without depth).
    pub median_depth_m: f64,
}

impl ViewOverlap {
    /// The parallax of a camera translation of `baseline_m` seen from the median depth,
    /// degrees: `atan(baseline / median depth)`; 90° without depth.
    pub fn parallax_deg(&self, baseline_m: f64) -> f64 {
        if self.median_depth_m > 0.0 {
            baseline_m.atan2(self.median_depth_m).to_degrees()
        } else {
            90.0
        }
    }
}

/// Fraction of the current frame's depth pixels (sampled every `stride` pixels) that project
/// inside the keyframe's image, in front of its camera. Both frames share `camera`;
/// `keyframe_from_current` maps current-camera points to the keyframe camera. Returns 0 when the
/// frame has no depth or the transform is not finite.
pub fn overlap_ratio(
    camera: &PinholeCamera,
    current_depth_m: &DepthImage,
    keyframe_from_current: &Isometry3<f64>,
    stride: u32,
) -> f64 {
    view_overlap(camera, current_depth_m, keyframe_from_current, stride).overlap
}

/// [`overlap_ratio`] and the median depth of the sampled pixels, in one pass.
pub fn view_overlap(
    camera: &PinholeCamera,
    current_depth_m: &DepthImage,
    keyframe_from_current: &Isometry3<f64>,
    stride: u32,
) -> ViewOverlap {
    let stride = stride.max(1);
    let (mut seen, mut total) = (0usize, 0usize);
    let mut depths: Vec<f32> = Vec::new();
    for v in (0..current_depth_m.height()).step_by(stride as usize) {
        let row = current_depth_m.row(v);
        for u in (0..current_depth_m.width()).step_by(stride as usize) {
            let z = row[u as usize];
            if !(z > 0.0 && z.is_finite()) {
                continue;
            }
            total += 1;
            depths.push(z);
            let p = camera.unproject(
                &nalgebra::Point2::new(f64::from(u), f64::from(v)),
                f64::from(z),
            );
            if let Some(px) = camera.project(&(keyframe_from_current * p))
                && camera.in_bounds(&px, 0.0)
            {
                seen += 1;
            }
        }
    }
    if total == 0 {
        return ViewOverlap {
            overlap: 0.0,
            median_depth_m: 0.0,
        };
    }
    let middle = depths.len() / 2;
    let (_, median, _) = depths.select_nth_unstable_by(middle, f32::total_cmp);
    ViewOverlap {
        overlap: seen as f64 / total as f64,
        median_depth_m: f64::from(*median),
    }
}

/// Decides whether the current frame becomes a keyframe, given its motion since the last one and
/// what it shares with it. Checks translation, then parallax, then rotation, then overlap;
/// `None` keeps the old keyframe. A non-finite motion counts as a translation of NaN and makes a
/// keyframe.
pub fn keyframe_decision(
    config: &KeyframeConfig,
    keyframe_from_current: &Isometry3<f64>,
    view: &ViewOverlap,
) -> Option<KeyframeReason> {
    let translation_m = keyframe_from_current.translation.vector.norm();
    let rotation_deg = keyframe_from_current.rotation.angle().to_degrees();
    if !translation_m.is_finite()
        || config
            .min_translation_m
            .is_some_and(|limit| translation_m >= limit)
    {
        return Some(KeyframeReason::Translation(translation_m));
    }
    if let Some(limit) = config.min_parallax_deg {
        let parallax_deg = view.parallax_deg(translation_m);
        if parallax_deg >= limit {
            return Some(KeyframeReason::Parallax(parallax_deg));
        }
    }
    let overlap = view.overlap;
    if !(rotation_deg < config.min_rotation_deg) {
        return Some(KeyframeReason::Rotation(rotation_deg));
    }
    if !(overlap >= config.min_overlap) {
        return Some(KeyframeReason::Overlap(overlap));
    }
    None
}

/// Keeps the last keyframe's pose and applies [`keyframe_decision`] to each new frame.
#[derive(Debug, Clone)]
pub struct KeyframeSelector {
    config: KeyframeConfig,
    camera: PinholeCamera,
    last_world_from_camera: Option<Isometry3<f64>>,
}

impl KeyframeSelector {
    /// A selector with no keyframe yet.
    pub fn new(config: KeyframeConfig, camera: PinholeCamera) -> Self {
        Self {
            config,
            camera,
            last_world_from_camera: None,
        }
    }

    /// The last keyframe's `world_from_camera`, if any.
    pub fn last_keyframe(&self) -> Option<&Isometry3<f64>> {
        self.last_world_from_camera.as_ref()
    }

    /// Offers a frame at `world_from_camera` with its depth; returns why it became a keyframe
    /// (and records it), or `None`.
    pub fn offer(
        &mut self,
        world_from_camera: &Isometry3<f64>,
        depth_m: &DepthImage,
    ) -> Option<KeyframeReason> {
        let reason = match &self.last_world_from_camera {
            None => Some(KeyframeReason::First),
            Some(last) => {
                let keyframe_from_current = last.inverse() * world_from_camera;
                let view = view_overlap(
                    &self.camera,
                    depth_m,
                    &keyframe_from_current,
                    self.config.overlap_stride_px,
                );
                keyframe_decision(&self.config, &keyframe_from_current, &view)
            }
        };
        if reason.is_some() {
            self.last_world_from_camera = Some(*world_from_camera);
        }
        reason
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn full(overlap: f64) -> ViewOverlap {
        ViewOverlap {
            overlap,
            median_depth_m: 2.0,
        }
    }

    #[test]
    fn thresholds_trigger_in_order() {
        let c = KeyframeConfig::default();
        assert_eq!(
            keyframe_decision(&c, &Isometry3::identity(), &full(1.0)),
            None
        );
        let moved = Isometry3::translation(0.6, 0.0, 0.0);
        assert!(matches!(
            keyframe_decision(&c, &moved, &full(1.0)),
            Some(KeyframeReason::Translation(d)) if (d - 0.6).abs() < 1e-12
        ));
        let turned = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 12f64.to_radians()),
        );
        assert!(matches!(
            keyframe_decision(&c, &turned, &full(1.0)),
            Some(KeyframeReason::Rotation(_))
        ));
        assert!(matches!(
            keyframe_decision(&c, &Isometry3::identity(), &full(0.5)),
            Some(KeyframeReason::Overlap(_))
        ));
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.0);
        assert!(keyframe_decision(&c, &nan, &full(1.0)).is_some());
        assert!(keyframe_decision(&KeyframeConfig::handheld(), &nan, &full(1.0)).is_some());
    }

    #[test]
    fn parallax_is_the_baseline_seen_from_the_median_depth() {
        let c = KeyframeConfig::handheld();
        // 3 cm at 2 m is 0.86°: no keyframe; 4 cm is 1.15°: a keyframe.
        let short = Isometry3::translation(0.03, 0.0, 0.0);
        assert_eq!(keyframe_decision(&c, &short, &full(1.0)), None);
        let long = Isometry3::translation(0.04, 0.0, 0.0);
        assert!(matches!(
            keyframe_decision(&c, &long, &full(1.0)),
            Some(KeyframeReason::Parallax(a)) if (a - 0.04f64.atan2(2.0).to_degrees()).abs() < 1e-9
        ));
        // The same 4 cm seen from 8 m is 0.29°: the scene is far, the baseline is not enough.
        let far = ViewOverlap {
            overlap: 1.0,
            median_depth_m: 8.0,
        };
        assert_eq!(keyframe_decision(&c, &long, &far), None);
        assert!(KeyframeConfig::handheld().validate().is_ok());
        assert!(KeyframeConfig::default().validate().is_ok());
        let bad = KeyframeConfig {
            min_parallax_deg: Some(-1.0),
            ..KeyframeConfig::handheld()
        };
        assert!(matches!(
            bad.validate(),
            Err(crate::SlamError::InvalidConfig {
                field: "min_parallax_deg",
                ..
            })
        ));
    }

    #[test]
    fn overlap_of_a_sideways_shift() {
        let camera = PinholeCamera::new(100.0, 100.0, 49.5, 39.5, 100, 80).unwrap();
        let depth = DepthImage::filled(100, 80, 1.0);
        assert_eq!(
            overlap_ratio(&camera, &depth, &Isometry3::identity(), 1),
            1.0
        );
        // Half the image width at 1 m depth is 0.5 m: the keyframe sees half the pixels.
        let shifted = Isometry3::translation(0.5, 0.0, 0.0);
        let o = overlap_ratio(&camera, &depth, &shifted, 1);
        assert!((o - 0.5).abs() < 0.02, "{o}");
        assert_eq!(
            overlap_ratio(&camera, &DepthImage::filled(100, 80, 0.0), &shifted, 1),
            0.0
        );
        let view = view_overlap(&camera, &depth, &shifted, 1);
        assert_eq!(view.median_depth_m, 1.0);
    }

    #[test]
    fn selector_keeps_the_last_keyframe() {
        let camera = PinholeCamera::new(100.0, 100.0, 49.5, 39.5, 100, 80).unwrap();
        let depth = DepthImage::filled(100, 80, 5.0);
        let mut s = KeyframeSelector::new(KeyframeConfig::default(), camera);
        assert_eq!(
            s.offer(&Isometry3::identity(), &depth),
            Some(KeyframeReason::First)
        );
        assert_eq!(
            s.offer(&Isometry3::translation(0.1, 0.0, 0.0), &depth),
            None
        );
        assert!(
            s.offer(&Isometry3::translation(0.7, 0.0, 0.0), &depth)
                .is_some()
        );
        assert_eq!(
            s.last_keyframe().unwrap().translation.vector,
            Vector3::new(0.7, 0.0, 0.0)
        );
    }
}
