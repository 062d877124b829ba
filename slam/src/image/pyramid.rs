//! Image pyramids for coarse-to-fine estimation.

use rayon::prelude::*;

use super::{DepthImage, GrayImage, Image, RgbImage};

/// Intensity in [0, 1] from an 8-bit RGB image (ITU-R BT.601 luma weights).
pub fn gray_from_rgb(rgb: &RgbImage) -> GrayImage {
    rgb.map(|&[r, g, b]| {
        (0.299 * f32::from(r) + 0.587 * f32::from(g) + 0.114 * f32::from(b)) / 255.0
    })
}

/// Halves an intensity image by averaging 2×2 blocks. Coarse pixel (u, v) covers fine pixels
/// (2u..2u+2, 2v..2v+2), matching [`crate::PinholeCamera::downsampled`]. Odd trailing rows and
/// columns are dropped.
pub fn downsample_gray(image: &GrayImage) -> GrayImage {
    downsample_with(image, |block| Some(block.iter().sum::<f32>() * 0.25)).map(|p| p.unwrap_or(0.0))
}

/// Halves a depth image, averaging the valid (non-zero) depths of each 2×2 block only when
/// they agree within 5%; blocks that straddle a depth edge or hold no valid depth become 0
/// (no measurement), so that no depth is invented between foreground and background.
pub fn downsample_depth(depth: &DepthImage) -> DepthImage {
    downsample_with(depth, |block| {
        let (mut sum, mut count, mut min, mut max) = (0.0f32, 0u32, f32::INFINITY, 0.0f32);
        for &d in block {
            if d > 0.0 {
                sum += d;
                count += 1;
                min = min.min(d);
                max = max.max(d);
            }
        }
        (count > 0 && max - min <= 0.05 * min).then(|| sum / count as f32)
    })
    .map(|p| p.unwrap_or(0.0))
}

fn downsample_with<T: Copy + Send + Sync, U: Send>(
    image: &Image<T>,
    reduce: impl Fn(&[T; 4]) -> U + Sync,
) -> Image<U> {
    let (w, h) = ((image.width() / 2).max(1), (image.height() / 2).max(1));
    let fine_w = image.width() as usize;
    let src = image.as_slice();
    let (max_u, max_v) = (image.width() as usize - 1, image.height() as usize - 1);
    let data: Vec<U> = (0..h as usize)
        .into_par_iter()
        .flat_map_iter(|v| {
            let (v0, v1) = ((2 * v).min(max_v), (2 * v + 1).min(max_v));
            let reduce = &reduce;
            (0..w as usize).map(move |u| {
                let (u0, u1) = ((2 * u).min(max_u), (2 * u + 1).min(max_u));
                reduce(&[
                    src[v0 * fine_w + u0],
                    src[v0 * fine_w + u1],
                    src[v1 * fine_w + u0],
                    src[v1 * fine_w + u1],
                ])
            })
        })
        .collect();
    // The length is w·h by construction.
    Image::from_vec(w, h, data).expect("downsampled buffer has w·h pixels")
}

/// An intensity and depth pyramid: level 0 is the full image, level k is halved k times.
#[derive(Debug, Clone)]
pub struct ImagePyramid {
    /// Intensity per level, in [0, 1].
    pub gray: Vec<GrayImage>,
    /// Depth per level, metres (0.0 = no measurement).
    pub depth_m: Vec<DepthImage>,
}

impl ImagePyramid {
    /// Builds `levels` levels (at least 1) from an intensity and a depth image of equal size.
    pub fn new(gray: GrayImage, depth_m: DepthImage, levels: usize) -> Self {
        let mut pyramid = Self {
            gray: vec![gray],
            depth_m: vec![depth_m],
        };
        for level in 1..levels.max(1) {
            let g = downsample_gray(&pyramid.gray[level - 1]);
            let d = downsample_depth(&pyramid.depth_m[level - 1]);
            pyramid.gray.push(g);
            pyramid.depth_m.push(d);
        }
        pyramid
    }

    /// Number of levels.
    pub fn levels(&self) -> usize {
        self.gray.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gray_downsample_averages_blocks() {
        let img = Image::from_vec(4, 2, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]).unwrap();
        let d = downsample_gray(&img);
        assert_eq!((d.width(), d.height()), (2, 1));
        assert_eq!(d.as_slice(), &[2.5, 4.5]);
    }

    #[test]
    fn depth_downsample_keeps_edges_empty() {
        let img = Image::from_vec(4, 2, vec![1.0, 1.02, 1.0, 5.0, 0.0, 1.0, 1.0, 1.0]).unwrap();
        let d = downsample_depth(&img);
        assert!((d.as_slice()[0] - 1.02 / 3.0 - 2.0 / 3.0).abs() < 1e-6);
        assert_eq!(d.as_slice()[1], 0.0);
    }

    #[test]
    fn pyramid_has_requested_levels() {
        let p = ImagePyramid::new(
            GrayImage::filled(640, 480, 0.5),
            DepthImage::filled(640, 480, 2.0),
            4,
        );
        assert_eq!(p.levels(), 4);
        assert_eq!((p.gray[3].width(), p.gray[3].height()), (80, 60));
        assert!(p.depth_m[3].as_slice().iter().all(|&d| d == 2.0));
    }
}
