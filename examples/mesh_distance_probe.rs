//! Times point-to-mesh distance queries on a realistic case: the ground truth is a rock of the
//! built-in default world, the queries are surface samples of a copy of it whose vertices are
//! moved by Gaussian noise (σ = 3 mm, about a 1 cm TSDF reconstruction's error).
//!
//! `cargo run --release --example mesh_distance_probe -- [bvh|kdtree] [queries] [rock]`
//!
//! `bvh` is [`MeshDistance`]; `kdtree` the k-d tree index it replaced (16 nearest of the
//! centroids, vertices and 40 000 samples/m², then the exact distance to their faces), kept
//! here to compare against. Queries run on one thread inside `run_queries` so that
//! `valgrind --tool=callgrind --collect-atstart=no --toggle-collect='*run_queries*'` counts the
//! instructions of the queries alone. Prints the index build time, the query time and the mean
//! distance.

use std::num::NonZero;
use std::time::Instant;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, Normal};
use scarp::evaluation::mesh::{MeshDistance, sample_surface};
use scarp_datasets::world::World;
use scarp_slam::TriangleMesh;
use scarp_slam::geometry::closest_point_on_triangle;

/// The pre-session-42 index.
struct KdTreeDistance<'a> {
    mesh: &'a TriangleMesh,
    tree: ImmutableKdTree<f64, 3>,
    faces: Vec<u32>,
}

impl<'a> KdTreeDistance<'a> {
    fn new(mesh: &'a TriangleMesh, samples: &[(Point3<f64>, u32)]) -> Self {
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
        let tree = ImmutableKdTree::new_from_slice(&points).expect("points");
        Self { mesh, tree, faces }
    }

    fn distance(&self, p: &Point3<f64>) -> f64 {
        let found = self
            .tree
            .query(&[p.x, p.y, p.z])
            .nearest_n::<SquaredEuclidean<f64>>(NonZero::new(16).expect("16 > 0"))
            .execute();
        let mut best = f64::INFINITY;
        let mut seen: Vec<u32> = Vec::with_capacity(found.len());
        for r in found {
            let f = self.faces[r.item as usize];
            if seen.contains(&f) {
                continue;
            }
            seen.push(f);
            let [a, b, c] = self.mesh.triangle(f as usize);
            best = best.min((closest_point_on_triangle(p, &a, &b, &c) - p).norm());
        }
        best
    }
}

#[inline(never)]
fn run_queries(distance: &dyn Fn(&Point3<f64>) -> f64, queries: &[Point3<f64>]) -> f64 {
    queries.iter().map(distance).sum()
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let mode = args.get(1).map_or("bvh", String::as_str);
    let count: usize = args.get(2).map_or(Ok(200_000), |s| s.parse())?;
    let rock: usize = args.get(3).map_or(Ok(0), |s| s.parse())?;
    let world = World::builtin_default()?;
    let gt = &world
        .rocks
        .get(rock)
        .ok_or_else(|| anyhow::anyhow!("no rock {rock}"))?
        .mesh;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(42);
    let noise = Normal::new(0.0f32, 0.003)?;
    let mut perturbed = gt.clone();
    for p in &mut perturbed.positions {
        for a in 0..3 {
            p[a] += noise.sample(&mut rng);
        }
    }
    let queries: Vec<Point3<f64>> = sample_surface(&perturbed, count, &mut rng)
        .into_iter()
        .map(|(p, _)| p)
        .collect();
    println!(
        "rock {rock}: {} faces, {:.3} m²; {} queries",
        gt.face_count(),
        gt.surface_area(),
        queries.len()
    );
    let start = Instant::now();
    let (sum, built_s) = match mode {
        "bvh" => {
            let index = MeshDistance::new(gt, "ground truth")?;
            let built_s = start.elapsed().as_secs_f64();
            (run_queries(&|p| index.distance(p), &queries), built_s)
        }
        "kdtree" => {
            let samples =
                sample_surface(gt, (gt.surface_area() * 40_000.0).ceil() as usize, &mut rng);
            let index = KdTreeDistance::new(gt, &samples);
            let built_s = start.elapsed().as_secs_f64();
            (run_queries(&|p| index.distance(p), &queries), built_s)
        }
        other => anyhow::bail!("unknown mode `{other}` (bvh or kdtree)"),
    };
    let query_s = start.elapsed().as_secs_f64() - built_s;
    println!(
        "{mode}: build {:.1} ms, queries {:.1} ms ({:.2} µs each), mean distance {:.9} m",
        built_s * 1e3,
        query_s * 1e3,
        query_s * 1e6 / queries.len() as f64,
        sum / queries.len() as f64
    );
    Ok(())
}
