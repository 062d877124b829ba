//! The user's yardsticks: how good a reconstruction is against the ground truth.
//!
//! [`mesh`] scores a reconstructed mesh against a ground-truth mesh (accuracy, completeness,
//! precision, recall and F-score at τ, as Tanks and Temples defines them).

pub mod mesh;
