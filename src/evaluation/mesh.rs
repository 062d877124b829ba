//! Mesh accuracy and completeness, and precision / recall / F-score at τ (Knapitsch et al.
//! 2017, *Tanks and Temples*).
//!
//! Both surfaces are sampled densely and area-weighted with a seeded RNG. The distance from a
//! sample to the other mesh is the exact distance to its nearest triangle ([`MeshDistance`], a
//! bounding-volume hierarchy searched branch-and-bound). All lengths are metres in the meshes'
//! common frame (world ENU).
//!
//! - accuracy: distances from reconstruction samples to the ground truth;
//! - completeness: distances from ground-truth samples to the reconstruction;
//! - precision: the fraction of accuracy distances ≤ τ; recall: the fraction of completeness
//!   distances ≤ τ; F-score: their harmonic mean.

use nalgebra::{Isometry3, Point3};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::World;
use scarp_slam::geometry::closest_point_on_triangle;
use scarp_slam::{PinholeCamera, TriangleMesh};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Mesh-evaluation parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MeshEvalConfig {
    /// Precision/recall threshold τ, metres. Default 0.01 (1 cm, the mapping voxel size).
    pub tau_m: f64,
    /// Surface samples per square metre on each mesh. Default 40 000 (5 mm apart).
    pub samples_per_m2: f64,
    /// Cap on the samples of one mesh. Default 2 000 000.
    pub max_samples: usize,
    /// Unused: the distance search has been exact since session 42 (it was the number of
    /// candidate triangles a k-d tree examined per query). Kept so that configuration files and
    /// JSON that set it still parse (`deny_unknown_fields`). Default 16.
    pub neighbours: usize,
    /// Ignore reconstruction triangles whose centroid lies farther than this from the
    /// ground-truth bounding box, metres. Default none (keep everything).
    pub crop_to_gt_m: Option<f64>,
    /// Seed of the surface sampling. Default 0.
    pub seed: u64,
}

impl Default for MeshEvalConfig {
    fn default() -> Self {
        Self {
            tau_m: 0.01,
            samples_per_m2: 40_000.0,
            max_samples: 2_000_000,
            neighbours: 16,
            crop_to_gt_m: None,
            seed: 0,
        }
    }
}

/// An error of the mesh evaluation.
#[derive(Debug, Error)]
pub enum MeshEvalError {
    /// A configuration field is out of range.
    #[error("invalid evaluation setting `{field}` = {value}: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// A mesh has no area (after cropping) to sample.
    #[error("the {which} mesh has no triangles of positive area{hint}")]
    EmptyMesh {
        /// `reconstruction` or `ground truth`.
        which: &'static str,
        /// Extra context (for example cropping).
        hint: &'static str,
    },
    /// A mesh is malformed (face index out of range, attribute length).
    #[error("the {which} mesh is invalid: {source}")]
    InvalidMesh {
        /// `reconstruction`, `ground truth` or `context`.
        which: &'static str,
        /// What is wrong.
        source: scarp_slam::SlamError,
    },
    /// Rendering for the visibility test failed.
    #[error("visibility rendering: {0}")]
    Render(#[from] scarp_datasets::DatasetError),
}

/// The scores. Field names are the `scarp eval mesh --json` keys.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshEvaluation {
    /// Mean distance from the reconstruction to the ground truth, metres.
    pub accuracy_mean_m: f64,
    /// Median of those distances, metres.
    pub accuracy_median_m: f64,
    /// 90th percentile of those distances, metres.
    pub accuracy_p90_m: f64,
    /// Mean distance from the ground truth to the reconstruction, metres.
    pub completeness_mean_m: f64,
    /// Median of those distances, metres.
    pub completeness_median_m: f64,
    /// 90th percentile of those distances, metres.
    pub completeness_p90_m: f64,
    /// Fraction of reconstruction samples within τ of the ground truth.
    pub precision: f64,
    /// Fraction of (visible) ground-truth samples within τ of the reconstruction.
    pub recall: f64,
    /// Harmonic mean of precision and recall (0 when both are 0).
    pub fscore: f64,
    /// The threshold τ, metres.
    pub tau_m: f64,
    /// Reconstruction samples scored.
    pub reconstruction_samples: usize,
    /// Ground-truth samples scored (visible ones only with a visibility test).
    pub ground_truth_samples: usize,
    /// Fraction of ground-truth samples that passed the visibility test (1 without one).
    pub gt_visible_fraction: f64,
}

// Percentile p ∈ [0, 1] of sorted values by linear interpolation between order statistics
// (rank p·(n − 1), as NumPy's default), shared with every crate.
pub use scarp_slam::stats::percentile_sorted;

/// Scores given distance sets: `accuracy` from reconstruction samples to the ground truth,
/// `completeness` from ground-truth samples to the reconstruction.
pub fn score_distances(accuracy: &[f64], completeness: &[f64], tau_m: f64) -> MeshEvaluation {
    let stats = |d: &[f64]| {
        let mut s = d.to_vec();
        s.sort_by(f64::total_cmp);
        let mean = s.iter().sum::<f64>() / s.len().max(1) as f64;
        let within = s.iter().filter(|&&v| v <= tau_m).count() as f64 / s.len().max(1) as f64;
        (
            mean,
            percentile_sorted(&s, 0.5),
            percentile_sorted(&s, 0.9),
            within,
        )
    };
    let (am, amed, ap90, precision) = stats(accuracy);
    let (cm, cmed, cp90, recall) = stats(completeness);
    let fscore = if precision + recall > 0.0 {
        2.0 * precision * recall / (precision + recall)
    } else {
        0.0
    };
    MeshEvaluation {
        accuracy_mean_m: am,
        accuracy_median_m: amed,
        accuracy_p90_m: ap90,
        completeness_mean_m: cm,
        completeness_median_m: cmed,
        completeness_p90_m: cp90,
        precision,
        recall,
        fscore,
        tau_m,
        reconstruction_samples: accuracy.len(),
        ground_truth_samples: completeness.len(),
        gt_visible_fraction: 1.0,
    }
}

/// `count` points on `mesh`, area-weighted, uniform within each triangle, each with its face.
pub fn sample_surface(
    mesh: &TriangleMesh,
    count: usize,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<(Point3<f64>, u32)> {
    let mut cumulative = Vec::with_capacity(mesh.face_count());
    let mut total = 0.0;
    for f in 0..mesh.face_count() {
        let [a, b, c] = mesh.triangle(f);
        total += 0.5 * (b - a).cross(&(c - a)).norm();
        cumulative.push(total);
    }
    if total <= 0.0 {
        return Vec::new();
    }
    (0..count)
        .map(|_| {
            let r = rng.random::<f64>() * total;
            let f = cumulative
                .partition_point(|&c| c < r)
                .min(mesh.face_count() - 1);
            let [a, b, c] = mesh.triangle(f);
            let (mut u, mut v) = (rng.random::<f64>(), rng.random::<f64>());
            if u + v > 1.0 {
                u = 1.0 - u;
                v = 1.0 - v;
            }
            (a + (b - a) * u + (c - a) * v, f as u32)
        })
        .collect()
}

/// Exact distances from points to a triangle mesh: a bounding-volume hierarchy (BVH) over its
/// triangles, searched branch-and-bound.
///
/// The answer is the minimum over *all* triangles of the distance to
/// [`closest_point_on_triangle`], computed in f64 from the mesh's f32 vertices, so it equals a
/// brute-force scan. (Until session 42 a k-d tree over samples, vertices and centroids picked 16
/// candidate triangles, which could miss the nearest one and spent most of the mission's
/// evaluation stage in the k-d tree.) A query is a pure function of the mesh and the point:
/// results do not depend on the thread count or query order.
pub struct MeshDistance {
    /// Depth-first order: an inner node's left child follows it, its right child is at `first`.
    nodes: Vec<BvhNode>,
    /// The triangles' vertices in f64, metres, permuted so that each leaf's are contiguous.
    triangles: Vec<[Point3<f64>; 3]>,
}

/// A BVH node: the axis-aligned box of its triangles (metres) and either its leaf triangles
/// (`count` > 0: `triangles[first..first + count]`) or, for `count` = 0, its right child's index.
#[derive(Debug, Clone, Copy)]
struct BvhNode {
    lo: [f64; 3],
    hi: [f64; 3],
    first: u32,
    count: u32,
}

/// Triangles per leaf at most (a common choice; not tuned).
const BVH_LEAF_TRIANGLES: usize = 4;

/// Entries of the traversal stack: it holds at most one pending sibling per level, and the
/// median split keeps the depth at ⌈log₂(faces)⌉ + 1 ≤ 33 for any u32 face count.
const BVH_STACK: usize = 64;

impl BvhNode {
    /// Squared distance from `p` to the node's box (0 inside), square metres: a lower bound of
    /// the squared distance to any of its triangles.
    #[inline]
    fn distance_squared_m2(&self, p: &Point3<f64>) -> f64 {
        let mut d2 = 0.0;
        for a in 0..3 {
            let d = (self.lo[a] - p[a]).max(p[a] - self.hi[a]).max(0.0);
            d2 += d * d;
        }
        d2
    }
}

impl MeshDistance {
    /// Indexes the triangles of `mesh` (positions in metres, any frame; queries use the same
    /// frame). Degenerate triangles are kept: [`closest_point_on_triangle`] handles them.
    /// `which` names the mesh in the error.
    ///
    /// # Errors
    /// [`MeshEvalError::EmptyMesh`] when the mesh has no faces.
    ///
    /// # Panics
    /// When a face indexes a vertex out of range; [`TriangleMesh::validate`] rules that out.
    pub fn new(mesh: &TriangleMesh, which: &'static str) -> Result<Self, MeshEvalError> {
        if mesh.face_count() == 0 {
            return Err(MeshEvalError::EmptyMesh { which, hint: "" });
        }
        let triangles: Vec<[Point3<f64>; 3]> =
            (0..mesh.face_count()).map(|f| mesh.triangle(f)).collect();
        // (centroid, face) of each triangle, reordered in place by the build.
        let mut items: Vec<([f64; 3], u32)> = triangles
            .iter()
            .enumerate()
            .map(|(f, [a, b, c])| {
                let m = (a.coords + b.coords + c.coords) / 3.0;
                ([m.x, m.y, m.z], f as u32)
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * items.len() / BVH_LEAF_TRIANGLES + 1);
        build_bvh(&triangles, &mut items, 0, &mut nodes);
        let triangles = items.iter().map(|(_, f)| triangles[*f as usize]).collect();
        Ok(Self { nodes, triangles })
    }

    /// Distance from `p` (metres, the mesh's frame) to the nearest point of the mesh, metres.
    /// Infinite when `p` has a NaN coordinate.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        self.distance_squared_m2(p).sqrt()
    }

    /// Squared distance from `p` to the mesh, square metres (see [`Self::distance`]).
    pub fn distance_squared_m2(&self, p: &Point3<f64>) -> f64 {
        let mut best = f64::INFINITY;
        // Nearer child first, the farther one pushed with its box distance; anything whose
        // box is no nearer than the best triangle so far cannot hold a nearer one.
        let mut stack = [(0u32, 0.0f64); BVH_STACK];
        let mut len = 0;
        let mut node = 0usize;
        let mut node_d2 = self.nodes[0].distance_squared_m2(p);
        loop {
            if node_d2 < best {
                let n = &self.nodes[node];
                if n.count > 0 {
                    let first = n.first as usize;
                    for [a, b, c] in &self.triangles[first..first + n.count as usize] {
                        let d2 = (closest_point_on_triangle(p, a, b, c) - p).norm_squared();
                        best = best.min(d2);
                    }
                } else {
                    let (left, right) = (node + 1, n.first as usize);
                    let dl = self.nodes[left].distance_squared_m2(p);
                    let dr = self.nodes[right].distance_squared_m2(p);
                    let (near, near_d2, far, far_d2) = if dl <= dr {
                        (left, dl, right, dr)
                    } else {
                        (right, dr, left, dl)
                    };
                    if far_d2 < best {
                        stack[len] = (far as u32, far_d2);
                        len += 1;
                    }
                    node = near;
                    node_d2 = near_d2;
                    continue;
                }
            }
            let Some(top) = len.checked_sub(1) else {
                break;
            };
            len = top;
            (node, node_d2) = (stack[top].0 as usize, stack[top].1);
        }
        best
    }
}

/// Appends the subtree over `items` (centroids and faces, starting at leaf-order position
/// `offset`) to `nodes` in depth-first order and returns its root's index. Splits at the median
/// centroid along the longest axis of the centroids' box, so the tree is balanced (bounded
/// depth for the fixed query stack) and the build is deterministic.
fn build_bvh(
    triangles: &[[Point3<f64>; 3]],
    items: &mut [([f64; 3], u32)],
    offset: usize,
    nodes: &mut Vec<BvhNode>,
) -> usize {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let (mut clo, mut chi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (centroid, f) in items.iter() {
        for v in &triangles[*f as usize] {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        for a in 0..3 {
            clo[a] = clo[a].min(centroid[a]);
            chi[a] = chi[a].max(centroid[a]);
        }
    }
    let index = nodes.len();
    nodes.push(BvhNode {
        lo,
        hi,
        first: offset as u32,
        count: items.len() as u32,
    });
    if items.len() <= BVH_LEAF_TRIANGLES {
        return index;
    }
    let axis = (0..3)
        .max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b])))
        .unwrap_or(0);
    let mid = items.len() / 2;
    // Ties broken by face so that the order does not depend on the input permutation.
    items.select_nth_unstable_by(mid, |x, y| {
        x.0[axis].total_cmp(&y.0[axis]).then(x.1.cmp(&y.1))
    });
    let (left, right) = items.split_at_mut(mid);
    build_bvh(triangles, left, offset, nodes);
    let right_index = build_bvh(triangles, right, offset + mid, nodes);
    nodes[index].first = right_index as u32;
    nodes[index].count = 0;
    index
}

/// The reconstruction's faces whose centroid lies within `margin_m` of the axis-aligned box
/// of `gt`.
pub fn crop_to_box(mesh: &TriangleMesh, gt: &TriangleMesh, margin_m: f64) -> TriangleMesh {
    let Some((lo, hi)) = gt.bounds() else {
        return TriangleMesh::default();
    };
    let lo = lo.cast::<f64>().map(|v| v - margin_m);
    let hi = hi.cast::<f64>().map(|v| v + margin_m);
    let mut cropped = mesh.clone();
    cropped.faces.retain(|f| {
        let c = f
            .iter()
            .map(|&v| mesh.positions[v as usize].cast::<f64>().coords)
            .sum::<nalgebra::Vector3<f64>>()
            / 3.0;
        (0..3).all(|a| c[a] >= lo[a] && c[a] <= hi[a])
    });
    scarp_slam::meshing::remove_small_components(&cropped, 0)
}

fn sample_count(mesh: &TriangleMesh, config: &MeshEvalConfig) -> usize {
    ((mesh.surface_area() * config.samples_per_m2).ceil() as usize).clamp(1, config.max_samples)
}

/// A visibility test for ground-truth samples: a point counts when at least one camera sees
/// it unoccluded.
pub struct Visibility<'w> {
    /// The whole world (rocks, pedestals, terrain) as occluders.
    pub world: &'w World,
    /// The camera of the sequence.
    pub camera: PinholeCamera,
    /// Ground-truth `world_from_camera` of each frame.
    pub world_from_camera: Vec<Isometry3<f64>>,
    /// A point is visible when its z-depth is within this of the rendered depth at one of the
    /// four pixels around its projection, metres. Default in the CLI: 0.01.
    pub tolerance_m: f64,
}

impl Visibility<'_> {
    /// Which of `points` are visible from at least one camera (z-buffer test against renders
    /// of the whole world).
    ///
    /// # Errors
    /// [`MeshEvalError::Render`] for a bad camera or pose.
    pub fn visible(&self, points: &[Point3<f64>]) -> Result<Vec<bool>, MeshEvalError> {
        let renderer = Renderer::new(self.world);
        let mut visible = vec![false; points.len()];
        let (w, h) = (self.camera.width as i64, self.camera.height as i64);
        for pose in &self.world_from_camera {
            let depth = renderer.render_geometry(&self.camera, pose)?.depth_m;
            let camera_from_world = pose.inverse();
            visible.par_iter_mut().zip(points).for_each(|(vis, p)| {
                if *vis {
                    return;
                }
                let q = camera_from_world * p;
                let Some(px) = self.camera.project(&q) else {
                    return;
                };
                let (u0, v0) = (px.x.floor() as i64, px.y.floor() as i64);
                for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (u, v) = (u0 + du, v0 + dv);
                    if u < 0 || v < 0 || u >= w || v >= h {
                        continue;
                    }
                    // In range by the check above.
                    let d = f64::from(*depth.get(u as u32, v as u32).unwrap_or(&0.0));
                    if d > 0.0 && (q.z - d).abs() <= self.tolerance_m {
                        *vis = true;
                        return;
                    }
                }
            });
        }
        Ok(visible)
    }
}

/// Scores `reconstruction` against `ground_truth`, optionally counting only the ground-truth
/// samples that `visibility` finds visible.
///
/// # Errors
/// [`MeshEvalError::InvalidConfig`] for a bad τ or density; [`MeshEvalError::EmptyMesh`] when a
/// mesh (after cropping) has nothing to sample; [`MeshEvalError::Render`] from the visibility
/// test.
pub fn evaluate_mesh(
    reconstruction: &TriangleMesh,
    ground_truth: &TriangleMesh,
    config: &MeshEvalConfig,
    visibility: Option<&Visibility<'_>>,
) -> Result<MeshEvaluation, MeshEvalError> {
    let mut scores = evaluate_mesh_at_taus(
        reconstruction,
        ground_truth,
        None,
        config,
        visibility,
        &[config.tau_m],
    )?;
    // One τ in, one score out.
    Ok(scores.remove(0))
}

/// As [`evaluate_mesh`], scoring the same sampled distances at each of `taus_m` (metres) in
/// turn: the sampling, the nearest-neighbour queries and the visibility test run once.
/// `config.tau_m` is checked but not used.
///
/// `context` is true surface beside the ground truth that the reconstruction rightly holds
/// (the pedestal under a rock, inside the crop box around it): a reconstruction sample's
/// accuracy is its distance to the nearer of the two, while completeness counts the ground
/// truth alone. Without it, a correctly mapped pedestal top counts against the rock's
/// precision: on a slab stood on edge over a pedestal 1.2 m across, the F-score at 2 cm read
/// 0.84; scored with it, 0.994 (session 30's held-out campaign).
///
/// # Errors
/// As [`evaluate_mesh`], plus [`MeshEvalError::InvalidConfig`] for a bad or missing τ, and
/// [`MeshEvalError::InvalidMesh`] for an invalid `context`.
pub fn evaluate_mesh_at_taus(
    reconstruction: &TriangleMesh,
    ground_truth: &TriangleMesh,
    context: Option<&TriangleMesh>,
    config: &MeshEvalConfig,
    visibility: Option<&Visibility<'_>>,
    taus_m: &[f64],
) -> Result<Vec<MeshEvaluation>, MeshEvalError> {
    if let Some(&tau) = taus_m.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        return Err(MeshEvalError::InvalidConfig {
            field: "tau_m",
            value: tau,
            reason: "must be positive",
        });
    }
    if taus_m.is_empty() {
        return Err(MeshEvalError::InvalidConfig {
            field: "tau_m",
            value: f64::NAN,
            reason: "at least one τ is needed",
        });
    }
    let bad = |field, value, reason| MeshEvalError::InvalidConfig {
        field,
        value,
        reason,
    };
    if !(config.tau_m.is_finite() && config.tau_m > 0.0) {
        return Err(bad("tau_m", config.tau_m, "must be positive"));
    }
    if !(config.samples_per_m2.is_finite() && config.samples_per_m2 > 0.0) {
        return Err(bad(
            "samples_per_m2",
            config.samples_per_m2,
            "must be positive",
        ));
    }
    if let Some(m) = config.crop_to_gt_m
        && !(m.is_finite() && m >= 0.0)
    {
        return Err(bad("crop_to_gt_m", m, "must be ≥ 0"));
    }
    reconstruction
        .validate()
        .map_err(|source| MeshEvalError::InvalidMesh {
            which: "reconstruction",
            source,
        })?;
    ground_truth
        .validate()
        .map_err(|source| MeshEvalError::InvalidMesh {
            which: "ground truth",
            source,
        })?;
    let cropped;
    let recon = match config.crop_to_gt_m {
        Some(m) => {
            cropped = crop_to_box(reconstruction, ground_truth, m);
            &cropped
        }
        None => reconstruction,
    };
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(config.seed);
    let recon_samples = sample_surface(recon, sample_count(recon, config), &mut rng);
    if recon_samples.is_empty() {
        return Err(MeshEvalError::EmptyMesh {
            which: "reconstruction",
            hint: if config.crop_to_gt_m.is_some() {
                " inside the crop box"
            } else {
                ""
            },
        });
    }
    let gt_samples = sample_surface(ground_truth, sample_count(ground_truth, config), &mut rng);
    if gt_samples.is_empty() {
        return Err(MeshEvalError::EmptyMesh {
            which: "ground truth",
            hint: "",
        });
    }
    let gt_index = MeshDistance::new(ground_truth, "ground truth")?;
    let recon_index = MeshDistance::new(recon, "reconstruction")?;
    // Only the context's part near the ground truth can be nearest to a cropped sample.
    let context_mesh = match context {
        Some(mesh) => {
            mesh.validate()
                .map_err(|source| MeshEvalError::InvalidMesh {
                    which: "context",
                    source,
                })?;
            Some(crop_to_box(
                mesh,
                ground_truth,
                config.crop_to_gt_m.unwrap_or(f64::INFINITY)
                    + 2.0 * taus_m.iter().copied().fold(0.0, f64::max),
            ))
        }
        None => None,
    };
    // A context wholly outside the box scores nothing.
    let context_index = match &context_mesh {
        Some(mesh) if mesh.face_count() > 0 => Some(MeshDistance::new(mesh, "context")?),
        _ => None,
    };
    let accuracy: Vec<f64> = recon_samples
        .par_iter()
        .map(|(p, _)| {
            let to_truth = gt_index.distance(p);
            context_index
                .as_ref()
                .map_or(to_truth, |c| to_truth.min(c.distance(p)))
        })
        .collect();
    let gt_points: Vec<Point3<f64>> = gt_samples.iter().map(|(p, _)| *p).collect();
    let (kept, fraction) = match visibility {
        Some(v) => {
            let mask = v.visible(&gt_points)?;
            let kept: Vec<Point3<f64>> = gt_points
                .iter()
                .zip(&mask)
                .filter(|(_, m)| **m)
                .map(|(p, _)| *p)
                .collect();
            let fraction = kept.len() as f64 / gt_points.len() as f64;
            (kept, fraction)
        }
        None => (gt_points, 1.0),
    };
    let completeness: Vec<f64> = kept.par_iter().map(|p| recon_index.distance(p)).collect();
    Ok(taus_m
        .iter()
        .map(|&tau| {
            let mut out = score_distances(&accuracy, &completeness, tau);
            out.gt_visible_fraction = fraction;
            out
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn square(z: f32, size: f32) -> TriangleMesh {
        TriangleMesh::new(
            vec![
                Point3::new(0.0, 0.0, z),
                Point3::new(size, 0.0, z),
                Point3::new(size, size, z),
                Point3::new(0.0, size, z),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap()
    }

    /// A rock's face over its pedestal's top, 5 cm below it and as large: the mapped pedestal
    /// is inside the crop box, an error of the rock's only when nothing says it is true surface.
    #[test]
    fn a_mapped_context_surface_is_no_error() {
        let (rock, pedestal) = (square(0.0, 1.0), square(-0.05, 1.0));
        let mut both = rock.positions.clone();
        both.extend(&pedestal.positions);
        let recon =
            TriangleMesh::new(both, vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]).unwrap();
        let config = MeshEvalConfig {
            crop_to_gt_m: Some(0.1),
            samples_per_m2: 4000.0,
            ..MeshEvalConfig::default()
        };
        let score = |context| {
            evaluate_mesh_at_taus(&recon, &rock, context, &config, None, &[0.01])
                .unwrap()
                .remove(0)
        };
        let (alone, with) = (score(None), score(Some(&pedestal)));
        assert!((alone.precision - 0.5).abs() < 0.05, "{alone:?}");
        assert!(with.precision > 0.999, "{with:?}");
        assert!(alone.recall > 0.999 && with.recall > 0.999);
        assert!(with.accuracy_mean_m < 1e-6 && alone.accuracy_mean_m > 0.02);
    }

    /// Minimum over every triangle: what [`MeshDistance`] must equal.
    fn brute_force_m(mesh: &TriangleMesh, p: &Point3<f64>) -> f64 {
        (0..mesh.face_count())
            .map(|f| {
                let [a, b, c] = mesh.triangle(f);
                (closest_point_on_triangle(p, &a, &b, &c) - p).norm()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Checks [`MeshDistance`] on `queries`: equal to the brute-force minimum over all
    /// triangles (to 1e-12 m), and never above the old k-d tree's minimum over a subset of them
    /// (indexed with `samples`). The first failure, described, as the error.
    fn exact_and_below_the_kd_tree(
        mesh: &TriangleMesh,
        samples: &[(Point3<f64>, u32)],
        queries: &[Point3<f64>],
    ) -> Result<(), String> {
        let index = MeshDistance::new(mesh, "test").map_err(|e| e.to_string())?;
        let old = kd_tree_distances_m(mesh, samples, queries);
        for (p, old) in queries.iter().zip(old) {
            let (new, exact) = (index.distance(p), brute_force_m(mesh, p));
            if (new - exact).abs() > 1e-12 {
                return Err(format!("{p:?}: {new} against {exact}"));
            }
            if new > old + 1e-12 {
                return Err(format!("{p:?}: {new} against the k-d tree's {old}"));
            }
        }
        Ok(())
    }

    /// The index before session 42: a k-d tree over centroids, vertices and surface samples,
    /// then the exact distance to the faces of the 16 nearest points.
    fn kd_tree_distances_m(
        mesh: &TriangleMesh,
        samples: &[(Point3<f64>, u32)],
        queries: &[Point3<f64>],
    ) -> Vec<f64> {
        use kiddo::{ImmutableKdTree, SquaredEuclidean};
        let (mut points, mut faces) = (Vec::new(), Vec::new());
        for f in 0..mesh.face_count() {
            let [a, b, c] = mesh.triangle(f);
            let centroid = (a.coords + b.coords + c.coords) / 3.0;
            for p in [centroid, a.coords, b.coords, c.coords] {
                points.push([p.x, p.y, p.z]);
                faces.push(f as u32);
            }
        }
        for (p, f) in samples {
            points.push([p.x, p.y, p.z]);
            faces.push(*f);
        }
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&points).unwrap();
        let k = std::num::NonZero::new(16).unwrap();
        queries
            .iter()
            .map(|p| {
                tree.query(&[p.x, p.y, p.z])
                    .nearest_n::<SquaredEuclidean<f64>>(k)
                    .execute()
                    .iter()
                    .map(|r| {
                        let [a, b, c] = mesh.triangle(faces[r.item as usize] as usize);
                        (closest_point_on_triangle(p, &a, &b, &c) - p).norm()
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    /// A mesh of `faces` random triangles (vertex indices taken modulo the vertex count, so
    /// degenerate and repeated triangles occur) and query points: random ones in a box 4× the
    /// mesh's, far ones (up to 1 km) and points on the surface.
    fn mesh_and_queries() -> impl Strategy<Value = (TriangleMesh, Vec<Point3<f64>>)> {
        let vertex = prop::array::uniform3(-1.0f32..1.0);
        let query = prop::array::uniform3(-4.0f64..4.0);
        (
            prop::collection::vec(vertex, 3..60),
            prop::collection::vec(prop::array::uniform3(0u32..1000), 1..120),
            prop::collection::vec(query, 1..40),
            prop::collection::vec(prop::array::uniform3(-1000.0f64..1000.0), 1..10),
            prop::collection::vec((0usize..1000, 0.0f64..1.0, 0.0f64..1.0), 1..40),
        )
            .prop_map(|(positions, faces, near, far, on)| {
                let n = positions.len() as u32;
                let mesh = TriangleMesh::new(
                    positions.into_iter().map(Point3::from).collect(),
                    faces.into_iter().map(|f| f.map(|i| i % n)).collect(),
                )
                .unwrap();
                let mut queries: Vec<Point3<f64>> =
                    near.into_iter().chain(far).map(Point3::from).collect();
                for (f, mut u, mut v) in on {
                    if u + v > 1.0 {
                        (u, v) = (1.0 - u, 1.0 - v);
                    }
                    let [a, b, c] = mesh.triangle(f % mesh.face_count());
                    queries.push(a + (b - a) * u + (c - a) * v);
                }
                (mesh, queries)
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Exact: equal to the minimum over all triangles, and never above the k-d tree's
        /// minimum over a subset of them.
        #[test]
        fn distance_is_the_brute_force_minimum((mesh, queries) in mesh_and_queries()) {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
            let samples = sample_surface(&mesh, 200, &mut rng);
            let checked = exact_and_below_the_kd_tree(&mesh, &samples, &queries);
            prop_assert!(checked.is_ok(), "{}", checked.unwrap_err());
        }
    }

    /// A deep tree (thousands of faces of a noisy sphere): exact on points around it, inside
    /// and outside.
    #[test]
    fn exact_on_a_large_mesh() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let (rings, segments) = (60, 80);
        let mut positions = Vec::new();
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segments {
                let phi = std::f32::consts::TAU * j as f32 / segments as f32;
                let r = 1.0 + 0.05 * rng.random::<f32>();
                positions.push(Point3::new(
                    r * theta.sin() * phi.cos(),
                    r * theta.sin() * phi.sin(),
                    r * theta.cos(),
                ));
            }
        }
        let mut faces = Vec::new();
        for i in 0..rings as u32 {
            for j in 0..segments {
                let (a, b) = (i * segments + j, i * segments + (j + 1) % segments);
                let (c, d) = (a + segments, b + segments);
                faces.push([a, b, d]);
                faces.push([a, d, c]);
            }
        }
        let mesh = TriangleMesh::new(positions, faces).unwrap();
        let queries: Vec<Point3<f64>> = (0..2000)
            .map(|_| {
                let v = nalgebra::Vector3::new(
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                );
                Point3::from(v * 3.0)
            })
            .collect();
        let samples = sample_surface(&mesh, 20_000, &mut rng);
        exact_and_below_the_kd_tree(&mesh, &samples, &queries).unwrap();
    }

    #[test]
    fn an_empty_mesh_is_an_error() {
        let empty = TriangleMesh::default();
        assert!(matches!(
            MeshDistance::new(&empty, "ground truth"),
            Err(MeshEvalError::EmptyMesh {
                which: "ground truth",
                hint: ""
            })
        ));
        let config = MeshEvalConfig::default();
        assert!(matches!(
            evaluate_mesh(&square(0.0, 1.0), &empty, &config, None),
            Err(MeshEvalError::EmptyMesh {
                which: "ground truth",
                ..
            })
        ));
        assert!(matches!(
            evaluate_mesh(&empty, &square(0.0, 1.0), &config, None),
            Err(MeshEvalError::EmptyMesh {
                which: "reconstruction",
                ..
            })
        ));
    }

    /// Configurations written before the search became exact still parse.
    #[test]
    fn the_unused_neighbours_setting_still_parses() {
        let config: MeshEvalConfig = serde_json::from_str(r#"{"neighbours": 8}"#).unwrap();
        assert_eq!(config.neighbours, 8);
    }

    #[test]
    fn hand_computed_scores() {
        let e = score_distances(&[0.0, 0.005, 0.02, 0.03], &[0.001, 0.002, 0.05], 0.01);
        assert!((e.accuracy_mean_m - 0.01375).abs() < 1e-12);
        assert!((e.accuracy_median_m - 0.0125).abs() < 1e-12);
        // rank 0.9·3 = 2.7: 0.02 + 0.7·0.01.
        assert!((e.accuracy_p90_m - 0.027).abs() < 1e-12);
        assert!((e.completeness_median_m - 0.002).abs() < 1e-12);
        assert!((e.completeness_p90_m - (0.002 + 0.8 * 0.048)).abs() < 1e-12);
        assert_eq!(e.precision, 0.5);
        assert!((e.recall - 2.0 / 3.0).abs() < 1e-12);
        assert!((e.fscore - 4.0 / 7.0).abs() < 1e-12);
        let zero = score_distances(&[1.0], &[1.0], 0.01);
        assert_eq!(zero.fscore, 0.0);
    }

    #[test]
    fn offset_squares() {
        // Two 1 m squares 3 mm apart: every distance is 3 mm.
        let gt = square(0.0, 1.0);
        let recon = square(0.003, 1.0);
        let config = MeshEvalConfig {
            samples_per_m2: 2000.0,
            ..MeshEvalConfig::default()
        };
        let e = evaluate_mesh(&recon, &gt, &config, None).unwrap();
        for v in [
            e.accuracy_mean_m,
            e.accuracy_median_m,
            e.accuracy_p90_m,
            e.completeness_mean_m,
            e.completeness_p90_m,
        ] {
            assert!((v - 0.003).abs() < 1e-6, "{v}");
        }
        assert_eq!(e.fscore, 1.0);
        let strict = MeshEvalConfig {
            tau_m: 0.002,
            ..config.clone()
        };
        assert_eq!(
            evaluate_mesh(&recon, &gt, &strict, None).unwrap().fscore,
            0.0
        );
        // Half the ground truth missing from the reconstruction: recall ½, precision 1.
        let half = square(0.0, 1.0);
        let mut big = square(0.0, 2.0);
        big.positions[2] = Point3::new(2.0, 1.0, 0.0);
        big.positions[3] = Point3::new(0.0, 1.0, 0.0);
        let e = evaluate_mesh(&half, &big, &config, None).unwrap();
        assert_eq!(e.precision, 1.0);
        assert!((e.recall - 0.5).abs() < 0.03, "{}", e.recall);
        // Cropping removes the far part of a reconstruction.
        let mut far = square(0.0, 1.0);
        far.append(&square(5.0, 1.0));
        let cropped = MeshEvalConfig {
            crop_to_gt_m: Some(0.1),
            ..config.clone()
        };
        assert_eq!(
            evaluate_mesh(&far, &gt, &cropped, None).unwrap().precision,
            1.0
        );
        let e = evaluate_mesh(&far, &gt, &config, None).unwrap();
        assert!((e.precision - 0.5).abs() < 0.03);
        assert!(evaluate_mesh(&square(9.0, 1.0), &gt, &cropped, None).is_err());
        let mut broken = square(0.0, 1.0);
        broken.faces.push([0, 1, 7]);
        assert!(matches!(
            evaluate_mesh(&broken, &gt, &config, None),
            Err(MeshEvalError::InvalidMesh { .. })
        ));
    }
}
