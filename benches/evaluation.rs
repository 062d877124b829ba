//! Point-to-mesh distance ([`MeshDistance`]) on a rock of the built-in default world: building
//! the index, and 10 000 queries sampled on a copy of the rock whose vertices are moved by
//! Gaussian noise (σ = 3 mm), one thread.
//!
//! `cargo bench --bench evaluation`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Point3;
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, Normal};
use scarp::evaluation::mesh::{MeshDistance, sample_surface};
use scarp_datasets::world::World;

const QUERIES: usize = 10_000;

fn bench(c: &mut Criterion) {
    let world = World::builtin_default().expect("default world");
    let gt = &world.rocks[0].mesh;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(42);
    let noise = Normal::new(0.0f32, 0.003).expect("σ > 0");
    let mut perturbed = gt.clone();
    for p in &mut perturbed.positions {
        for a in 0..3 {
            p[a] += noise.sample(&mut rng);
        }
    }
    let queries: Vec<Point3<f64>> = sample_surface(&perturbed, QUERIES, &mut rng)
        .into_iter()
        .map(|(p, _)| p)
        .collect();
    let index = MeshDistance::new(gt, "ground truth").expect("rock mesh");
    let mut group = c.benchmark_group("mesh distance");
    group.bench_function("build, rock 0", |b| {
        b.iter(|| MeshDistance::new(gt, "ground truth").expect("rock mesh"))
    });
    group.throughput(Throughput::Elements(QUERIES as u64));
    group.bench_function("10k queries, rock 0 (3 mm noise)", |b| {
        b.iter(|| queries.iter().map(|p| index.distance(p)).sum::<f64>())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
