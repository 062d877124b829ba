//! Evaluation metrics, the user's yardsticks: trajectory error (ATE and RPE, as the TUM RGB-D
//! benchmark tools define them).

pub mod trajectory;
