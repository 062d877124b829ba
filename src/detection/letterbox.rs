//! Letterbox preprocessing of YOLO networks: resize keeping the aspect ratio, pad to the
//! network's input size with grey (114/255), and map boxes between the two images.
//!
//! Two coordinate conventions meet here:
//! - the **image** uses scarp's continuous pixel coordinates: pixel centres at integers, so a
//!   `w`-wide image spans `-0.5 ..= w - 0.5`;
//! - the **network input** uses the Ultralytics convention: pixel edges at integers, so the
//!   input spans `0 ..= input_w`. YOLO exports give their boxes in these units.
//!
//! In edge coordinates the map is affine per axis: `input = image · scale + pad`.

use scarp_slam::image::RgbImage;

use super::{BoundingBox, DetectionError};

/// The grey that fills the padding, as Ultralytics uses (114 of 255).
pub const PAD_VALUE: f32 = 114.0 / 255.0;

/// How one image size is letterboxed into one network input size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Letterbox {
    /// Source image width, px.
    pub image_width: u32,
    /// Source image height, px.
    pub image_height: u32,
    /// Network input width, px.
    pub input_width: u32,
    /// Network input height, px.
    pub input_height: u32,
    /// Width of the resized image inside the input, px.
    pub resized_width: u32,
    /// Height of the resized image inside the input, px.
    pub resized_height: u32,
    /// Columns of padding left of the resized image.
    pub pad_x_px: u32,
    /// Rows of padding above the resized image.
    pub pad_y_px: u32,
}

impl Letterbox {
    /// The letterbox of an `image_width × image_height` image into an
    /// `input_width × input_height` network input: uniform scale `min(input_w / w, input_h / h)`,
    /// resized sides rounded to whole pixels (at least 1), padding split evenly (the odd pixel
    /// goes right / below).
    ///
    /// # Errors
    /// [`DetectionError::Config`] (`input_size`) when a size is zero.
    pub fn new(
        image_width: u32,
        image_height: u32,
        input_width: u32,
        input_height: u32,
    ) -> Result<Self, DetectionError> {
        if image_width == 0 || image_height == 0 || input_width == 0 || input_height == 0 {
            return Err(DetectionError::Config {
                field: "input_size",
                reason: format!(
                    "cannot letterbox a {image_width}×{image_height} image into a \
                     {input_width}×{input_height} input: sizes must be positive"
                ),
            });
        }
        let (w, h) = (f64::from(image_width), f64::from(image_height));
        let (iw, ih) = (f64::from(input_width), f64::from(input_height));
        let ratio = (iw / w).min(ih / h);
        // Rounded, clamped to [1, input]: the casts cannot overflow.
        let resized_width = ((w * ratio).round() as u32).clamp(1, input_width);
        let resized_height = ((h * ratio).round() as u32).clamp(1, input_height);
        Ok(Self {
            image_width,
            image_height,
            input_width,
            input_height,
            resized_width,
            resized_height,
            pad_x_px: (input_width - resized_width) / 2,
            pad_y_px: (input_height - resized_height) / 2,
        })
    }

    /// Horizontal scale from image to input (resized width / image width).
    pub fn scale_x(&self) -> f64 {
        f64::from(self.resized_width) / f64::from(self.image_width)
    }

    /// Vertical scale from image to input (resized height / image height).
    pub fn scale_y(&self) -> f64 {
        f64::from(self.resized_height) / f64::from(self.image_height)
    }

    /// A box of the network input (edge coordinates) in the image (continuous coordinates),
    /// not clipped.
    pub fn to_image(&self, input_box: &BoundingBox) -> BoundingBox {
        let (sx, sy) = (self.scale_x(), self.scale_y());
        let (px, py) = (f64::from(self.pad_x_px), f64::from(self.pad_y_px));
        BoundingBox {
            x_min: (input_box.x_min - px) / sx - 0.5,
            y_min: (input_box.y_min - py) / sy - 0.5,
            x_max: (input_box.x_max - px) / sx - 0.5,
            y_max: (input_box.y_max - py) / sy - 0.5,
        }
    }

    /// A box of the image (continuous coordinates) in the network input (edge coordinates);
    /// the inverse of [`Letterbox::to_image`].
    pub fn to_input(&self, image_box: &BoundingBox) -> BoundingBox {
        let (sx, sy) = (self.scale_x(), self.scale_y());
        let (px, py) = (f64::from(self.pad_x_px), f64::from(self.pad_y_px));
        BoundingBox {
            x_min: (image_box.x_min + 0.5) * sx + px,
            y_min: (image_box.y_min + 0.5) * sy + py,
            x_max: (image_box.x_max + 0.5) * sx + px,
            y_max: (image_box.y_max + 0.5) * sy + py,
        }
    }

    /// The network input tensor: `[3, input_height, input_width]` (RGB planes, row-major),
    /// values in `[0, 1]`, the image resized bilinearly (pixel-centre aligned) and padded with
    /// [`PAD_VALUE`].
    ///
    /// # Errors
    /// [`DetectionError::MissingInput`] when `rgb` is not the size this letterbox was made for.
    pub fn apply(&self, rgb: &RgbImage) -> Result<Vec<f32>, DetectionError> {
        if (rgb.width(), rgb.height()) != (self.image_width, self.image_height) {
            return Err(DetectionError::MissingInput(format!(
                "letterbox made for {}×{} images got a {}×{} image",
                self.image_width,
                self.image_height,
                rgb.width(),
                rgb.height()
            )));
        }
        let (iw, ih) = (self.input_width as usize, self.input_height as usize);
        let plane = iw * ih;
        let mut out = vec![PAD_VALUE; 3 * plane];
        let columns: Vec<Tap> = (0..self.resized_width)
            .map(|i| Tap::new(i, self.scale_x(), self.image_width))
            .collect();
        for j in 0..self.resized_height {
            let row = Tap::new(j, self.scale_y(), self.image_height);
            let (top, bottom) = (rgb.row(row.lo), rgb.row(row.hi));
            let y = (j + self.pad_y_px) as usize;
            for (i, col) in columns.iter().enumerate() {
                let x = i + self.pad_x_px as usize;
                let sample = |r: &[[u8; 3]], c: usize| {
                    let a = f32::from(r[col.lo as usize][c]);
                    let b = f32::from(r[col.hi as usize][c]);
                    a + (b - a) * col.t
                };
                for c in 0..3 {
                    let t = sample(top, c);
                    let b = sample(bottom, c);
                    out[c * plane + y * iw + x] = (t + (b - t) * row.t) / 255.0;
                }
            }
        }
        Ok(out)
    }
}

/// The two source pixels and the blend weight of one output pixel along one axis.
#[derive(Debug, Clone, Copy)]
struct Tap {
    lo: u32,
    hi: u32,
    t: f32,
}

impl Tap {
    /// Output pixel `i` of an axis scaled by `scale` from a source of `len` pixels: its centre
    /// `(i + 0.5) / scale - 0.5` in source continuous coordinates, clamped to the source.
    fn new(i: u32, scale: f64, len: u32) -> Self {
        let last = f64::from(len - 1);
        let s = ((f64::from(i) + 0.5) / scale - 0.5).clamp(0.0, last);
        let lo = s.floor();
        // `lo` lies in [0, len - 1]: the casts are exact.
        let lo_px = lo as u32;
        Self {
            lo: lo_px,
            hi: (lo_px + 1).min(len - 1),
            t: (s - lo) as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wide_image_is_padded_top_and_bottom() {
        let lb = Letterbox::new(640, 480, 640, 640).unwrap();
        assert_eq!((lb.resized_width, lb.resized_height), (640, 480));
        assert_eq!((lb.pad_x_px, lb.pad_y_px), (0, 80));
        let lb = Letterbox::new(128, 64, 64, 64).unwrap();
        assert_eq!((lb.resized_width, lb.resized_height), (64, 32));
        assert_eq!((lb.pad_x_px, lb.pad_y_px), (0, 16));
        assert_eq!((lb.scale_x(), lb.scale_y()), (0.5, 0.5));
        let tall = Letterbox::new(30, 100, 64, 64).unwrap();
        assert_eq!((tall.resized_width, tall.resized_height), (19, 64));
        assert_eq!(tall.pad_x_px, 22);
        assert!(Letterbox::new(0, 10, 64, 64).is_err());
    }

    #[test]
    fn boxes_round_trip_and_hand_values() {
        let lb = Letterbox::new(128, 64, 64, 64).unwrap();
        // The whole image maps to the resized band: x 0..64, y 16..48 in input edges.
        let whole = BoundingBox::new(-0.5, -0.5, 127.5, 63.5).unwrap();
        let input = lb.to_input(&whole);
        assert_eq!(
            [input.x_min, input.y_min, input.x_max, input.y_max],
            [0.0, 16.0, 64.0, 48.0]
        );
        // Input box x 12..28, y 20..28 → image edges x 24..56, y 8..24 → centres −0.5.
        let b = lb.to_image(&BoundingBox::new(12.0, 20.0, 28.0, 28.0).unwrap());
        assert_eq!(
            [b.x_min, b.y_min, b.x_max, b.y_max],
            [23.5, 7.5, 55.5, 23.5]
        );
        for (w, h, iw, ih) in [
            (640, 480, 640, 640),
            (37, 91, 320, 256),
            (1920, 1080, 64, 48),
        ] {
            let lb = Letterbox::new(w, h, iw, ih).unwrap();
            let b = BoundingBox::new(3.25, 7.5, 20.0, 33.75).unwrap();
            let back = lb.to_image(&lb.to_input(&b));
            for (x, y) in [
                (back.x_min, b.x_min),
                (back.y_min, b.y_min),
                (back.x_max, b.x_max),
                (back.y_max, b.y_max),
            ] {
                assert!(
                    (x - y).abs() < 1e-9,
                    "{w}×{h} → {iw}×{ih}: {back:?} vs {b:?}"
                );
            }
        }
    }

    #[test]
    fn apply_resizes_pads_and_normalises() {
        // A 4×2 image: left half red, right half blue; into 2×2 → resized 2×1, pad row 0 top
        // (padding (2 - 1) / 2 = 0 rows above, 1 below).
        let mut rgb = RgbImage::filled(4, 2, [255, 0, 0]);
        for v in 0..2 {
            for u in 2..4 {
                *rgb.get_mut(u, v).unwrap() = [0, 0, 255];
            }
        }
        let lb = Letterbox::new(4, 2, 2, 2).unwrap();
        assert_eq!(
            (lb.resized_width, lb.resized_height, lb.pad_y_px),
            (2, 1, 0)
        );
        let t = lb.apply(&rgb).unwrap();
        assert_eq!(t.len(), 12);
        // Output pixel 0 samples source x = 0.5 (between two red pixels): pure red.
        assert_eq!(&t[0..4], &[1.0, 0.0, PAD_VALUE, PAD_VALUE]);
        assert_eq!(&t[8..12], &[0.0, 1.0, PAD_VALUE, PAD_VALUE]);
        assert!(lb.apply(&RgbImage::filled(3, 2, [0, 0, 0])).is_err());
    }
}
