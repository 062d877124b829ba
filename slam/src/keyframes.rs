//! Keyframe selection: a frame becomes a keyframe when the camera has moved, turned or lost
//! enough view overlap since the last keyframe.

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::PinholeCamera;
use crate::image::DepthImage;

/// Keyframe thresholds. A frame is a keyframe when any one is crossed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KeyframeConfig {
    /// Camera translation since the last keyframe, metres. Default 0.5 m (about a tenth of the
    /// 4 m mapping stand-off).
    pub min_translation_m: f64,
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
            min_translation_m: 0.5,
            min_rotation_deg: 10.0,
            min_overlap: 0.7,
            overlap_stride_px: 4,
        }
    }
}

/// Which threshold made a frame a keyframe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum KeyframeReason {
    /// The first frame of a sequence.
    First,
    /// Moved farther than `min_translation_m` (the distance, metres).
    Translation(f64),
    /// Turned farther than `min_rotation_deg` (the angle, degrees).
    Rotation(f64),
    /// Overlap fell below `min_overlap` (the overlap).
    Overlap(f64),
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
    let stride = stride.max(1);
    let (mut seen, mut total) = (0usize, 0usize);
    for v in (0..current_depth_m.height()).step_by(stride as usize) {
        let row = current_depth_m.row(v);
        for u in (0..current_depth_m.width()).step_by(stride as usize) {
            let z = row[u as usize];
            if !(z > 0.0 && z.is_finite()) {
                continue;
            }
            total += 1;
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
        0.0
    } else {
        seen as f64 / total as f64
    }
}

/// Decides whether the current frame becomes a keyframe, given its motion since the last one and
/// its overlap with it. Checks translation, then rotation, then overlap; `None` keeps the old
/// keyframe. A non-finite motion counts as a translation of NaN and makes a keyframe.
pub fn keyframe_decision(
    config: &KeyframeConfig,
    keyframe_from_current: &Isometry3<f64>,
    overlap: f64,
) -> Option<KeyframeReason> {
    let translation_m = keyframe_from_current.translation.vector.norm();
    let rotation_deg = keyframe_from_current.rotation.angle().to_degrees();
    if !(translation_m < config.min_translation_m) {
        return Some(KeyframeReason::Translation(translation_m));
    }
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
                let overlap = overlap_ratio(
                    &self.camera,
                    depth_m,
                    &keyframe_from_current,
                    self.config.overlap_stride_px,
                );
                keyframe_decision(&self.config, &keyframe_from_current, overlap)
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

    #[test]
    fn thresholds_trigger_in_order() {
        let c = KeyframeConfig::default();
        assert_eq!(keyframe_decision(&c, &Isometry3::identity(), 1.0), None);
        let moved = Isometry3::translation(0.6, 0.0, 0.0);
        assert!(matches!(
            keyframe_decision(&c, &moved, 1.0),
            Some(KeyframeReason::Translation(d)) if (d - 0.6).abs() < 1e-12
        ));
        let turned = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 12f64.to_radians()),
        );
        assert!(matches!(
            keyframe_decision(&c, &turned, 1.0),
            Some(KeyframeReason::Rotation(_))
        ));
        assert!(matches!(
            keyframe_decision(&c, &Isometry3::identity(), 0.5),
            Some(KeyframeReason::Overlap(_))
        ));
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.0);
        assert!(keyframe_decision(&c, &nan, 1.0).is_some());
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
