//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

use nalgebra::{Point3, Vector3};
use scarp_slam::TriangleMesh;

/// The vendored double-rock PLY (binary LE, 20140 vertices, 40276 faces).
pub fn double_rock_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets/assets/double_rock.ply")
}

pub fn double_rock_bytes() -> Vec<u8> {
    std::fs::read(double_rock_path())
        .expect("datasets/assets/double_rock.ply is part of the repository")
}

pub const DOUBLE_ROCK_VERTICES: usize = 20140;
pub const DOUBLE_ROCK_FACES: usize = 40276;

/// SplitMix64: a tiny seeded generator, so mutation tests are reproducible without extra
/// dependencies.
pub struct SplitMix(pub u64);

impl SplitMix {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// An axis-aligned box with outward winding, normals and colours.
pub fn coloured_box() -> TriangleMesh {
    let mut mesh = TriangleMesh::cuboid(Point3::new(-0.5, -0.25, 0.0), Point3::new(0.5, 0.25, 1.5));
    mesh.compute_vertex_normals();
    mesh.colors = (0..8u8).map(|i| [i * 30, 255 - i * 20, i * i]).collect();
    mesh
}

pub fn bits(v: &[Point3<f32>]) -> Vec<[u32; 3]> {
    v.iter()
        .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        .collect()
}

pub fn normal_bits(v: &[Vector3<f32>]) -> Vec<[u32; 3]> {
    v.iter()
        .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        .collect()
}
