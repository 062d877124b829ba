//! Benchmark of the fragility analysis on the real rock (`shared/data/rocks/double_rock.ply`,
//! scaled to about 1.5 m): the core analysis, and the default analysis with its 32 perturbed
//! runs.

use criterion::{Criterion, criterion_group, criterion_main};
use scarp::fragility::{ContactSpec, FragilityConfig, UncertaintyConfig, analyze};

fn rock() -> scarp_slam::TriangleMesh {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/rocks/double_rock.ply");
    let mut mesh = scarp_export::ply::read_mesh(&path).expect("the real rock PLY");
    mesh.scale(11.72);
    mesh
}

fn bench(c: &mut Criterion) {
    let mesh = rock();
    // The contact 0.7 m below the centre of mass, on the rock's lower lobe.
    let contact = ContactSpec::Height(-0.7);
    let core = FragilityConfig {
        uncertainty: UncertaintyConfig {
            samples: 0,
            ..UncertaintyConfig::default()
        },
        ..FragilityConfig::default()
    };
    let full = FragilityConfig::default();
    let mut group = c.benchmark_group("fragility");
    group.sample_size(10);
    group.bench_function("analyze real rock, given height", |b| {
        b.iter(|| analyze(&mesh, contact, &core).expect("analysis"))
    });
    group.bench_function("analyze real rock, automatic contact", |b| {
        b.iter(|| analyze(&mesh, ContactSpec::Auto, &core))
    });
    group.bench_function("analyze real rock, 32 perturbed runs", |b| {
        b.iter(|| analyze(&mesh, contact, &full).expect("analysis"))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
