//! The spread of α_min under perturbation: each sample adds isotropic Gaussian noise to every
//! vertex and shifts the contact height by a Gaussian amount, then repeats the analysis.
//! Samples are seeded from (seed, sample index), so results do not depend on the thread count.

use nalgebra::{Point2, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::topology::Solid;
use super::{FragilityConfig, Support, evaluate, rocking};

/// Settings of the perturbation study. The defaults are choices for a rock mapped at about
/// 1 cm voxels, not values from the paper.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UncertaintyConfig {
    /// Number of perturbed analyses; 0 turns the study off. Default 32.
    pub samples: usize,
    /// Standard deviation of the contact-height shift, metres. Default 0.005.
    pub contact_height_sigma_m: f64,
    /// Standard deviation of the per-coordinate vertex noise, metres. Default 0.002.
    pub mesh_noise_sigma_m: f64,
    /// Seed of the random perturbations. Default 0.
    pub seed: u64,
}

impl Default for UncertaintyConfig {
    fn default() -> Self {
        Self {
            samples: 32,
            contact_height_sigma_m: 0.005,
            mesh_noise_sigma_m: 0.002,
            seed: 0,
        }
    }
}

/// Summary of the perturbed α_min values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UncertaintyReport {
    /// Samples requested.
    pub samples: usize,
    /// Samples whose analysis failed (for example the perturbed contact missed the support);
    /// they are left out of the statistics.
    pub failed_samples: usize,
    /// Standard deviation of the contact-height shift used, metres.
    pub contact_height_sigma_m: f64,
    /// Standard deviation of the vertex noise used, metres.
    pub mesh_noise_sigma_m: f64,
    /// The seed used.
    pub seed: u64,
    /// Mean of the perturbed α_min, degrees (0 without successful samples).
    pub alpha_min_mean_deg: f64,
    /// Sample standard deviation of the perturbed α_min, degrees (0 with fewer than two).
    pub alpha_min_std_deg: f64,
    /// Smallest perturbed α_min, degrees (0 without successful samples).
    pub alpha_min_lowest_deg: f64,
    /// Largest perturbed α_min, degrees (0 without successful samples).
    pub alpha_min_highest_deg: f64,
}

/// A standard normal deviate (Box–Muller).
fn standard_normal(rng: &mut StdRng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1], so the logarithm is finite
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Mixes the sample index into the seed (SplitMix64 finaliser).
fn sample_seed(seed: u64, index: u64) -> u64 {
    let mut z = seed ^ index.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Where the support of the rock (and of each perturbed sample) comes from.
pub(crate) enum SampleSupport<'a> {
    /// The perturbed mesh itself below the contact (automatic or given height).
    SelfBelow,
    /// A fixed support polygon (from a pedestal mesh).
    Fixed(&'a [Point2<f64>]),
    /// A given contact polygon.
    Exact(&'a [Point2<f64>]),
}

impl<'a> SampleSupport<'a> {
    /// The support of `solid` (the unperturbed rock or a perturbed sample of it).
    pub(crate) fn of<'s>(&self, solid: &'s Solid) -> Support<'s>
    where
        'a: 's,
    {
        match *self {
            SampleSupport::SelfBelow => Support::Below(solid),
            SampleSupport::Fixed(hull) => Support::Fixed(hull),
            SampleSupport::Exact(hull) => Support::Exact(hull),
        }
    }
}

/// The vertices a rock resting on its own base touches the ground with: those within the
/// contact band of its lowest point, when the contact is at that base (the support is the rock
/// itself below a contact at or under its lowest point). `None` for any other contact.
///
/// Why: re-deciding which vertices touch on every noised sample turns vertex noise into a
/// tilt of the whole rock. A coarse base (a box's 4 corners) then often "touches" with 2 or 3
/// corners, and the study reported negative α_min for a box that stands.
fn resting_base_vertices(
    rock: &Solid,
    contact_height_m: f64,
    support: &SampleSupport<'_>,
    config: &FragilityConfig,
) -> Option<Vec<usize>> {
    let (z_min, _) = rock.z_range()?;
    let at_base = matches!(support, SampleSupport::SelfBelow) && contact_height_m <= z_min;
    if !at_base {
        return None;
    }
    let indices: Vec<usize> = (0..rock.positions.len())
        .filter(|&i| rock.positions[i].z <= z_min + config.contact_band_m)
        .collect();
    (indices.len() >= 3).then_some(indices)
}

/// Runs the perturbed analyses of `rock` around `contact_height_m` and summarises α_min.
pub(crate) fn alpha_min_spread(
    rock: &Solid,
    contact_height_m: f64,
    support: SampleSupport<'_>,
    config: &FragilityConfig,
) -> UncertaintyReport {
    let u = &config.uncertainty;
    // Noise roughens a flat base; widen the contact band so the base still counts as touching.
    let band = config.contact_band_m.max(3.0 * u.mesh_noise_sigma_m);
    let base_vertices = resting_base_vertices(rock, contact_height_m, &support, config);
    let results: Vec<Option<f64>> = (0..u.samples)
        .into_par_iter()
        .map(|k| {
            let mut rng = StdRng::seed_from_u64(sample_seed(u.seed, k as u64));
            let dh = u.contact_height_sigma_m * standard_normal(&mut rng);
            let noisy = Solid {
                positions: rock
                    .positions
                    .iter()
                    .map(|p| {
                        let n = Vector3::new(
                            standard_normal(&mut rng),
                            standard_normal(&mut rng),
                            standard_normal(&mut rng),
                        );
                        p + n * u.mesh_noise_sigma_m
                    })
                    .collect(),
                faces: rock.faces.clone(),
            };
            let evaluation = match &base_vertices {
                // The rock rests on its base: the noise moves the base's vertices, but the
                // same vertices keep touching the ground, at their mean height (no cut height
                // to get wrong).
                Some(indices) => {
                    let hull = rocking::convex_hull(
                        &indices
                            .iter()
                            .map(|&i| noisy.positions[i].xy())
                            .collect::<Vec<_>>(),
                    );
                    let h = indices.iter().map(|&i| noisy.positions[i].z).sum::<f64>()
                        / indices.len() as f64;
                    evaluate(&noisy, h, &Support::Exact(&hull), band, config)
                }
                None => evaluate(
                    &noisy,
                    contact_height_m + dh,
                    &support.of(&noisy),
                    band,
                    config,
                ),
            };
            evaluation.ok().map(|e| e.alpha_min_rad.to_degrees())
        })
        .collect();
    let ok: Vec<f64> = results.iter().flatten().copied().collect();
    let n = ok.len() as f64;
    let mean = if ok.is_empty() {
        0.0
    } else {
        ok.iter().sum::<f64>() / n
    };
    let std = if ok.len() < 2 {
        0.0
    } else {
        (ok.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    UncertaintyReport {
        samples: u.samples,
        failed_samples: results.len() - ok.len(),
        contact_height_sigma_m: u.contact_height_sigma_m,
        mesh_noise_sigma_m: u.mesh_noise_sigma_m,
        seed: u.seed,
        alpha_min_mean_deg: mean,
        alpha_min_std_deg: std,
        alpha_min_lowest_deg: ok.iter().copied().reduce(f64::min).unwrap_or(0.0),
        alpha_min_highest_deg: ok.iter().copied().reduce(f64::max).unwrap_or(0.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_deviates_have_unit_variance() {
        let mut rng = StdRng::seed_from_u64(7);
        let xs: Vec<f64> = (0..20000).map(|_| standard_normal(&mut rng)).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(mean.abs() < 0.03 && (var - 1.0).abs() < 0.05);
        assert_ne!(sample_seed(0, 0), sample_seed(0, 1));
    }
}
