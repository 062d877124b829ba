//! Row-major image buffers and image pyramids.
//!
//! Pixel (u, v) is (column, row); index = v · width + u. Pixel centres sit at integers.

mod buffer;
mod pyramid;
mod registration;
mod undistortion;

pub use buffer::{DepthImage, GrayImage, Image, MaskImage, RgbImage};
pub use pyramid::{ImagePyramid, downsample_depth, downsample_gray, gray_from_rgb};
pub use registration::register_color_to_depth;
pub use undistortion::{LensDistortion, Undistortion};
