//! PLY read/write throughput on the double rock (20140 vertices, 40276 triangles, 766 kB binary).
//!
//! Run with `cargo bench -p scarp-export --bench ply`.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use scarp_export::ply::{
    PlyEncoding, read_mesh, read_mesh_from_reader, write_mesh, write_mesh_to_writer,
};

fn double_rock() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets/assets/double_rock.ply")
}

fn bench_ply(c: &mut Criterion) {
    let path = double_rock();
    let bytes = std::fs::read(&path).expect("datasets/assets/double_rock.ply");
    let mesh = read_mesh(&path).expect("the double rock reads");
    let mut ascii = Vec::new();
    write_mesh_to_writer(&mut ascii, &mesh, PlyEncoding::Ascii).expect("ASCII encodes");

    let mut group = c.benchmark_group("ply_double_rock");
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    group.bench_function("read_binary_le_memory", |b| {
        b.iter(|| read_mesh_from_reader(black_box(&bytes[..]), "bench").expect("reads"))
    });
    group.bench_function("read_binary_le_file", |b| {
        b.iter(|| read_mesh(black_box(&path)).expect("reads"))
    });
    group.bench_function("write_binary_le_memory", |b| {
        let mut out = Vec::with_capacity(bytes.len());
        b.iter(|| {
            out.clear();
            write_mesh_to_writer(&mut out, black_box(&mesh), PlyEncoding::BinaryLittleEndian)
                .expect("writes");
        })
    });
    let dir = std::env::temp_dir().join(format!("scarp-ply-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let out_path = dir.join("rock.ply");
    group.bench_function("write_binary_le_file_atomic", |b| {
        b.iter(|| {
            write_mesh(&out_path, black_box(&mesh), PlyEncoding::BinaryLittleEndian)
                .expect("writes")
        })
    });
    group.throughput(Throughput::Bytes(ascii.len() as u64));
    group.bench_function("read_ascii_memory", |b| {
        b.iter(|| read_mesh_from_reader(black_box(&ascii[..]), "bench").expect("reads"))
    });
    group.bench_function("write_ascii_memory", |b| {
        let mut out = Vec::with_capacity(ascii.len());
        b.iter(|| {
            out.clear();
            write_mesh_to_writer(&mut out, black_box(&mesh), PlyEncoding::Ascii).expect("writes");
        })
    });
    group.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench_ply);
criterion_main!(benches);
