//! TUM RGB-D sequences, read and written.
//!
//! A sequence directory holds `rgb.txt`, `depth.txt` (`timestamp path` lines), `rgb/`, `depth/`
//! (16-bit PNG, `depth_scale` units per metre, 0 = no measurement), `groundtruth.txt` and
//! `estimate.txt` (TUM trajectories of `world_from_camera`), `camera.toml` (`fx`, `fy`, `cx`,
//! `cy`, `width`, `height`, `depth_scale`), and for synthetic sequences `mask/` (16-bit instance
//! ids) and `boxes.txt` (`t id role x_min y_min x_max y_max`, inclusive pixel bounds). Real
//! sequences without `estimate.txt`, `boxes.txt` or `mask/` load too.

mod camera_file;
mod images;
mod lists;
mod read;
mod write;

pub use camera_file::CameraFile;
pub use images::{
    read_depth_png, read_mask_png, read_rgb_png, write_depth_png, write_mask_png, write_rgb_png,
};
pub use lists::{BoxRecord, boxes_from_mask, format_boxes, parse_boxes, parse_image_list};
pub use read::{MAX_ASSOCIATION_DT_S, Sequence, SequenceEntry};
pub use write::{RenderSettings, SequenceSummary, frame_name, write_image_lists, write_sequence};
