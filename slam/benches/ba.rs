//! Bundle adjustment on the two BAL problems, single-threaded (as Ceres' reference timings:
//! 0.29 s on shrink-1800, 2.66 s on problem-49-7776 with SPARSE_SCHUR on one thread) and on
//! all cores. The full problem is read from `../shared/data/bal/` beside the repository and
//! skipped when absent.

use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use scarp_slam::ba::{BalProblem, LmConfig, read_bal, solve_bal};

fn problems() -> Vec<(&'static str, BalProblem)> {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut out = Vec::new();
    let shrink = manifest.join("tests/data/bal-ladybug-problem-49-7776-pre-shrink-1800.txt");
    match read_bal(&shrink) {
        Ok(p) => out.push(("shrink-1800", p)),
        Err(e) => eprintln!("skipping shrink-1800: {e}"),
    }
    let full = manifest.join("../../shared/data/bal/problem-49-7776-pre.txt");
    if full.exists() {
        match read_bal(&full) {
            Ok(p) => out.push(("problem-49-7776", p)),
            Err(e) => eprintln!("skipping problem-49-7776: {e}"),
        }
    } else {
        eprintln!("skipping problem-49-7776: {} is absent", full.display());
    }
    out
}

fn bench_ba(c: &mut Criterion) {
    let mut group = c.benchmark_group("ba");
    group.sample_size(10);
    let config = LmConfig::default();
    for (name, problem) in problems() {
        for threads in [1, 0] {
            let mut builder = rayon::ThreadPoolBuilder::new();
            if threads > 0 {
                builder = builder.num_threads(threads);
            }
            let Ok(pool) = builder.build() else {
                eprintln!("could not start a thread pool");
                return;
            };
            let label = if threads == 1 {
                "1-thread"
            } else {
                "all-threads"
            };
            group.bench_function(format!("{name}/{label}"), |b| {
                b.iter_batched(
                    || problem.clone(),
                    |mut p| {
                        pool.install(|| solve_bal(&mut p, &config))
                            .map(|s| s.final_cost)
                            .unwrap_or(f64::NAN)
                    },
                    criterion::BatchSize::LargeInput,
                )
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_ba);
criterion_main!(benches);
