//! The generic image buffer.

use crate::SlamError;

/// A row-major image of `T` pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Image<T> {
    width: u32,
    height: u32,
    data: Vec<T>,
}

/// Colour image, 8-bit sRGB, `[r, g, b]`.
pub type RgbImage = Image<[u8; 3]>;
/// Depth image: z-depth in metres along the camera z axis; 0.0 means no measurement.
pub type DepthImage = Image<f32>;
/// Intensity image in [0, 1] (or any linear scale), used for photometric work and pyramids.
pub type GrayImage = Image<f32>;
/// Instance-id image: 0 means no surface; the meaning of other ids is set by the producer.
pub type MaskImage = Image<u16>;

impl<T: Clone> Image<T> {
    /// An image filled with `value`.
    pub fn filled(width: u32, height: u32, value: T) -> Self {
        Self {
            width,
            height,
            data: vec![value; width as usize * height as usize],
        }
    }
}

impl<T> Image<T> {
    /// Wraps a row-major buffer.
    ///
    /// # Errors
    /// [`SlamError::ImageBufferLength`] when `data.len() != width · height`.
    pub fn from_vec(width: u32, height: u32, data: Vec<T>) -> Result<Self, SlamError> {
        let expected = width as usize * height as usize;
        if data.len() != expected {
            return Err(SlamError::ImageBufferLength {
                width,
                height,
                expected,
                len: data.len(),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The pixels, row-major.
    pub fn as_slice(&self) -> &[T] {
        &self.data
    }

    /// The pixels, row-major, mutable.
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Consumes the image and returns its row-major pixels.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }

    /// Row `v` as a slice. Panics only if `v ≥ height`, which is a caller bug.
    pub fn row(&self, v: u32) -> &[T] {
        let w = self.width as usize;
        &self.data[v as usize * w..(v as usize + 1) * w]
    }

    /// The pixel at (u, v), or `None` outside the image.
    pub fn get(&self, u: u32, v: u32) -> Option<&T> {
        (u < self.width && v < self.height)
            .then(|| &self.data[v as usize * self.width as usize + u as usize])
    }

    /// Mutable access to the pixel at (u, v), or `None` outside the image.
    pub fn get_mut(&mut self, u: u32, v: u32) -> Option<&mut T> {
        let w = self.width as usize;
        (u < self.width && v < self.height).then(|| &mut self.data[v as usize * w + u as usize])
    }

    /// Checks that this image is `width × height`.
    ///
    /// # Errors
    /// [`SlamError::ImageSizeMismatch`] naming `what`.
    pub fn check_size(&self, what: &'static str, width: u32, height: u32) -> Result<(), SlamError> {
        if self.width == width && self.height == height {
            Ok(())
        } else {
            Err(SlamError::ImageSizeMismatch {
                what,
                expected_width: width,
                expected_height: height,
                actual_width: self.width,
                actual_height: self.height,
            })
        }
    }

    /// Applies `f` to every pixel.
    pub fn map<U>(&self, f: impl Fn(&T) -> U) -> Image<U> {
        Image {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(f).collect(),
        }
    }
}

impl GrayImage {
    /// Bilinear interpolation at a sub-pixel position, or `None` when any of the four
    /// neighbours is outside the image.
    pub fn sample_bilinear(&self, u: f32, v: f32) -> Option<f32> {
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (u0, v0) = (u.floor() as u32, v.floor() as u32);
        if u0 + 1 >= self.width || v0 + 1 >= self.height {
            return None;
        }
        let (fu, fv) = (u - u0 as f32, v - v0 as f32);
        let w = self.width as usize;
        let i = v0 as usize * w + u0 as usize;
        let d = &self.data;
        let top = d[i] + (d[i + 1] - d[i]) * fu;
        let bottom = d[i + w] + (d[i + w + 1] - d[i + w]) * fu;
        Some(top + (bottom - top) * fv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_vec_checks_length() {
        assert!(Image::from_vec(2, 2, vec![0u8; 3]).is_err());
        let img = Image::from_vec(2, 2, vec![1u8, 2, 3, 4]).unwrap();
        assert_eq!(img.get(1, 1), Some(&4));
        assert_eq!(img.get(2, 0), None);
        assert_eq!(img.row(1), &[3, 4]);
    }

    #[test]
    fn bilinear_is_exact_on_a_ramp() {
        let img = Image::from_vec(
            4,
            3,
            (0..12)
                .map(|i| (i % 4) as f32 + 10.0 * (i / 4) as f32)
                .collect(),
        )
        .unwrap();
        let s = img.sample_bilinear(1.25, 0.5).unwrap();
        assert!((s - (1.25 + 5.0)).abs() < 1e-5);
        assert!(img.sample_bilinear(3.0, 0.0).is_none());
        assert!(img.sample_bilinear(-0.1, 0.0).is_none());
    }
}
