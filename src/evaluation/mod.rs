//! The user's yardsticks: how good a reconstruction is against the ground truth.
//!
//! [`mesh`] scores a reconstructed mesh against a ground-truth mesh (accuracy, completeness,
//! precision, recall and F-score at τ, as Tanks and Temples defines them). [`trajectory`] scores
//! an estimated trajectory (ATE and RPE, as the TUM RGB-D benchmark tools define them).
//! [`tracking`] scores box tracks (CLEAR MOT: MOTA, ID switches; mean IoU; false tracks).

pub mod mesh;
pub mod tracking;
pub mod trajectory;
