//! Fusion of analytic shapes rendered without noise from a ring of views.

use std::collections::{HashMap, HashSet};

use nalgebra::{Isometry3, Point3, Vector3};

use super::raycast::{RaycastConfig, raycast};
use super::*;
use crate::geometry::{PinholeCamera, closest_point_on_triangle, look_at};
use crate::image::{DepthImage, RgbImage};
use crate::mesh::TriangleMesh;
use crate::meshing::{MeshingConfig, extract_mesh};

const VOXEL: f32 = 0.01;
const COLOR: [u8; 3] = [200, 120, 40];

#[derive(Clone, Copy)]
enum Shape {
    Sphere { center: Point3<f64>, radius: f64 },
    Cuboid { min: Point3<f64>, max: Point3<f64> },
}

impl Shape {
    /// Ray parameter of the first hit of `o + s·d` (s > 0).
    fn hit(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
        match *self {
            Shape::Sphere { center, radius } => {
                let oc = o - center;
                let a = d.dot(d);
                let b = oc.dot(d);
                let c = oc.dot(&oc) - radius * radius;
                let disc = b * b - a * c;
                (disc >= 0.0)
                    .then(|| (-b - disc.sqrt()) / a)
                    .filter(|&s| s > 0.0)
            }
            Shape::Cuboid { min, max } => {
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                for a in 0..3 {
                    let inv = 1.0 / d[a];
                    let (mut lo, mut hi) = ((min[a] - o[a]) * inv, (max[a] - o[a]) * inv);
                    if lo > hi {
                        std::mem::swap(&mut lo, &mut hi);
                    }
                    t0 = t0.max(lo);
                    t1 = t1.min(hi);
                }
                (t0 <= t1 && t0 > 0.0).then_some(t0)
            }
        }
    }

    /// Unsigned distance from `p` to the surface.
    fn distance(&self, p: &Point3<f64>) -> f64 {
        match *self {
            Shape::Sphere { center, radius } => ((p - center).norm() - radius).abs(),
            Shape::Cuboid { min, max } => {
                let c = nalgebra::center(&min, &max);
                let h = (max - min) * 0.5;
                let q = (p - c).abs() - h;
                let outside = q.map(|v| v.max(0.0)).norm();
                let inside = q.max().min(0.0);
                (outside + inside).abs()
            }
        }
    }

    /// Points spread over the surface (for recall), about `spacing` apart.
    fn surface_samples(&self, spacing: f64) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        match *self {
            Shape::Sphere { center, radius } => {
                let n =
                    (4.0 * std::f64::consts::PI * radius * radius / (spacing * spacing)) as usize;
                // Fibonacci sphere.
                let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
                for i in 0..n {
                    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                    let r = (1.0 - z * z).sqrt();
                    let phi = golden * i as f64;
                    out.push(center + Vector3::new(r * phi.cos(), r * phi.sin(), z) * radius);
                }
            }
            Shape::Cuboid { min, max } => {
                for axis in 0..3 {
                    for side in [min[axis], max[axis]] {
                        let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
                        let n1 = ((max[a1] - min[a1]) / spacing) as usize;
                        let n2 = ((max[a2] - min[a2]) / spacing) as usize;
                        for i in 0..=n1 {
                            for j in 0..=n2 {
                                let mut p = Point3::origin();
                                p[axis] = side;
                                p[a1] = min[a1] + (max[a1] - min[a1]) * i as f64 / n1 as f64;
                                p[a2] = min[a2] + (max[a2] - min[a2]) * j as f64 / n2 as f64;
                                out.push(p);
                            }
                        }
                    }
                }
            }
        }
        out
    }
}

fn camera() -> PinholeCamera {
    PinholeCamera::from_hfov(320, 240, 60.0).unwrap()
}

fn render(shape: &Shape, camera: &PinholeCamera, world_from_camera: &Isometry3<f64>) -> RgbdFrame {
    let mut depth = DepthImage::filled(camera.width, camera.height, 0.0);
    let o = Point3::from(world_from_camera.translation.vector);
    for v in 0..camera.height {
        for u in 0..camera.width {
            let ray = Vector3::new(
                (f64::from(u) - camera.cx) / camera.fx,
                (f64::from(v) - camera.cy) / camera.fy,
                1.0,
            );
            if let Some(s) = shape.hit(&o, &(world_from_camera.rotation * ray)) {
                *depth.get_mut(u, v).unwrap() = s as f32;
            }
        }
    }
    let rgb = RgbImage::filled(camera.width, camera.height, COLOR);
    RgbdFrame::new(0.0, rgb, depth, None).unwrap()
}

/// 8 azimuths × 4 elevations at 1.2 m, plus views from straight above and below.
fn ring_views(target: &Point3<f64>) -> Vec<Isometry3<f64>> {
    let mut views = Vec::new();
    for elevation_deg in [-60.0f64, -20.0, 20.0, 60.0] {
        for k in 0..8 {
            let az = (k as f64 * 45.0 + elevation_deg).to_radians();
            let el = elevation_deg.to_radians();
            let eye =
                target + Vector3::new(az.cos() * el.cos(), az.sin() * el.cos(), el.sin()) * 1.2;
            views.push(look_at(&eye, target, &Vector3::z()).unwrap());
        }
    }
    for sign in [1.0, -1.0] {
        let eye = target + Vector3::new(0.0, 0.0, sign * 1.2);
        views.push(look_at(&eye, target, &Vector3::x()).unwrap());
    }
    views
}

fn fuse(shape: &Shape, config: TsdfConfig) -> (TsdfVolume, Vec<RgbdFrame>, Vec<Isometry3<f64>>) {
    let cam = camera();
    let poses = ring_views(&Point3::new(0.01, -0.02, 0.005));
    let frames: Vec<RgbdFrame> = poses.iter().map(|p| render(shape, &cam, p)).collect();
    let mut volume = TsdfVolume::new(config).unwrap();
    for (f, p) in frames.iter().zip(&poses) {
        volume.integrate(f, &cam, p).unwrap();
    }
    (volume, frames, poses)
}

fn sphere() -> Shape {
    Shape::Sphere {
        center: Point3::new(0.013, -0.021, 0.007),
        radius: 0.3,
    }
}

fn cuboid() -> Shape {
    Shape::Cuboid {
        min: Point3::new(-0.213, -0.151, -0.182),
        max: Point3::new(0.187, 0.243, 0.214),
    }
}

/// Distance from `p` to the mesh through a bucket grid of triangles.
struct MeshDistance<'a> {
    mesh: &'a TriangleMesh,
    cell: f64,
    grid: HashMap<[i64; 3], Vec<usize>>,
}

impl<'a> MeshDistance<'a> {
    fn new(mesh: &'a TriangleMesh, cell: f64) -> Self {
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for f in 0..mesh.face_count() {
            let t = mesh.triangle(f);
            let lo = t[0].inf(&t[1]).inf(&t[2]);
            let hi = t[0].sup(&t[1]).sup(&t[2]);
            let l = lo.map(|v| (v / cell).floor() as i64);
            let h = hi.map(|v| (v / cell).floor() as i64);
            for x in l.x..=h.x {
                for y in l.y..=h.y {
                    for z in l.z..=h.z {
                        grid.entry([x, y, z]).or_default().push(f);
                    }
                }
            }
        }
        Self { mesh, cell, grid }
    }

    /// Distance to the nearest triangle if it is within one cell.
    fn distance(&self, p: &Point3<f64>) -> f64 {
        let c = p.map(|v| (v / self.cell).floor() as i64);
        let mut best = f64::INFINITY;
        for x in -1..=1 {
            for y in -1..=1 {
                for z in -1..=1 {
                    if let Some(list) = self.grid.get(&[c.x + x, c.y + y, c.z + z]) {
                        for &f in list {
                            let t = self.mesh.triangle(f);
                            best = best.min(
                                (closest_point_on_triangle(p, &t[0], &t[1], &t[2]) - p).norm(),
                            );
                        }
                    }
                }
            }
        }
        best
    }
}

/// (mean vertex distance to the shape, F-score at τ).
fn score(shape: &Shape, mesh: &TriangleMesh, tau: f64) -> (f64, f64) {
    let d: Vec<f64> = mesh
        .positions
        .iter()
        .map(|p| shape.distance(&p.cast()))
        .collect();
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    // Precision over triangle centroids and vertices; recall over analytic samples.
    let mut precise = 0usize;
    let mut total = 0usize;
    for f in 0..mesh.face_count() {
        let t = mesh.triangle(f);
        let c = Point3::from((t[0].coords + t[1].coords + t[2].coords) / 3.0);
        total += 1;
        precise += usize::from(shape.distance(&c) <= tau);
    }
    let precision = precise as f64 / total as f64;
    let index = MeshDistance::new(mesh, tau);
    let gt = shape.surface_samples(0.005);
    let recalled = gt.iter().filter(|p| index.distance(p) <= tau).count();
    let recall = recalled as f64 / gt.len() as f64;
    (mean, 2.0 * precision * recall / (precision + recall))
}

fn check_watertight(mesh: &TriangleMesh) {
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    for f in &mesh.faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let bad = edges.values().filter(|&&n| n != 2).count();
    assert_eq!(
        bad,
        0,
        "{bad} of {} edges are not shared by exactly two faces",
        edges.len()
    );
    let distinct: HashSet<[u32; 3]> = mesh
        .positions
        .iter()
        .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        .collect();
    assert_eq!(distinct.len(), mesh.vertex_count(), "duplicate vertices");
}

#[test]
fn sphere_is_accurate_complete_and_watertight() {
    let shape = sphere();
    let (volume, _, _) = fuse(&shape, TsdfConfig::default());
    let mesh = extract_mesh(&volume, &MeshingConfig::default());
    mesh.validate().unwrap();
    let (mean, fscore) = score(&shape, &mesh, f64::from(VOXEL));
    eprintln!("sphere: mean distance {mean:.6} m, F-score {fscore:.4} at 1 voxel");
    assert!(mean < 0.25 * f64::from(VOXEL), "mean distance {mean}");
    assert!(fscore >= 0.98, "F-score {fscore}");
    check_watertight(&mesh);
    // The sphere spans many blocks, so sharing across block borders was exercised.
    assert!(volume.block_count() > 100);
    // Normals point outward and colours come from the frames.
    let c = match shape {
        Shape::Sphere { center, .. } => center,
        Shape::Cuboid { .. } => unreachable!(),
    };
    let outward = mesh
        .positions
        .iter()
        .zip(&mesh.normals)
        .filter(|(p, n)| {
            (p.cast::<f64>() - c).dot(&n.cast::<f64>()) > 0.9 * (p.cast::<f64>() - c).norm()
        })
        .count();
    assert!(outward as f64 > 0.99 * mesh.vertex_count() as f64);
    assert!(
        mesh.colors
            .iter()
            .all(|c| c.iter().zip(COLOR).all(|(&a, b)| a.abs_diff(b) <= 1))
    );
    // Face winding agrees with the normals (counter-clockwise seen from outside).
    let agree = (0..mesh.face_count())
        .filter(|&f| {
            let n = mesh.face_normal(f);
            let v = mesh.faces[f][0] as usize;
            n.dot(&mesh.normals[v].cast()) > 0.0
        })
        .count();
    assert!(agree as f64 > 0.99 * mesh.face_count() as f64);
}

#[test]
fn box_is_accurate_and_complete() {
    let shape = cuboid();
    let (volume, _, _) = fuse(&shape, TsdfConfig::default());
    let mesh = extract_mesh(&volume, &MeshingConfig::default());
    let (mean, fscore) = score(&shape, &mesh, f64::from(VOXEL));
    eprintln!("box: mean distance {mean:.6} m, F-score {fscore:.4} at 1 voxel");
    assert!(mean < 0.25 * f64::from(VOXEL), "mean distance {mean}");
    assert!(fscore >= 0.98, "F-score {fscore}");
    check_watertight(&mesh);
}

type BlockBits = (BlockCoord, Vec<u32>, Vec<u32>, Vec<[u8; 4]>);

fn bits(volume: &TsdfVolume) -> Vec<BlockBits> {
    let mut out: Vec<_> = volume
        .block_coords()
        .iter()
        .zip(volume.blocks())
        .map(|(c, b)| {
            (
                *c,
                b.tsdf.iter().map(|v| v.to_bits()).collect(),
                b.weight.iter().map(|v| v.to_bits()).collect(),
                b.color.to_vec(),
            )
        })
        .collect();
    out.sort_by_key(|e| e.0);
    out
}

#[test]
fn reintegration_is_bit_identical_and_thread_count_independent() {
    let shape = sphere();
    let (volume, frames, poses) = fuse(&shape, TsdfConfig::default());
    let before = bits(&volume);
    let mut again = volume.clone();
    again.reintegrate(&frames, &camera(), &poses).unwrap();
    assert_eq!(before, bits(&again));
    assert_eq!(volume.block_coords(), again.block_coords());
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let mut one = TsdfVolume::new(TsdfConfig::default()).unwrap();
    single
        .install(|| one.reintegrate(&frames, &camera(), &poses))
        .unwrap();
    assert_eq!(before, bits(&one));
    let m1 = single.install(|| extract_mesh(&one, &MeshingConfig::default()));
    let m2 = extract_mesh(&volume, &MeshingConfig::default());
    assert_eq!(m1, m2);
    // Different poses give a different volume.
    let mut moved = poses.clone();
    moved[0].translation.vector.x += 0.003;
    again.reintegrate(&frames, &camera(), &moved).unwrap();
    assert_ne!(before, bits(&again));
    assert!(matches!(
        again.reintegrate(&frames, &camera(), &poses[1..]),
        Err(TsdfError::PoseCount { .. })
    ));
}

#[test]
fn roi_limits_allocation() {
    let shape = sphere();
    let roi = Roi::Box {
        min: [-1.0, -1.0, 0.1],
        max: [1.0, 1.0, 1.0],
    };
    let (volume, _, _) = fuse(
        &shape,
        TsdfConfig {
            roi: Some(roi),
            ..TsdfConfig::default()
        },
    );
    let (full, _, _) = fuse(&shape, TsdfConfig::default());
    assert!(volume.block_count() < full.block_count() / 2);
    let block = f64::from(volume.config().block_size_m());
    for c in volume.block_coords() {
        // Blocks reach at most one block below z = 0.1.
        assert!(
            f64::from(c[2] + 1) * block > 0.1 - 1e-9,
            "block {c:?} outside the ROI"
        );
    }
    let mesh = extract_mesh(&volume, &MeshingConfig::default());
    assert!(mesh.positions.iter().all(|p| p.z > 0.1 - 0.09));
    let stats = volume.stats();
    assert_eq!(stats.voxels, stats.blocks * BLOCK_VOXELS);
    assert!(stats.memory_bytes >= stats.blocks * Block::BYTES);
}

#[test]
fn raycast_matches_the_analytic_depth() {
    let shape = sphere();
    let (volume, _, _) = fuse(&shape, TsdfConfig::default());
    let cam = camera();
    // A view between the fused ones.
    let eye = Point3::new(0.9, 0.5, 0.4);
    let target = Point3::new(0.0, 0.0, 0.0);
    let world_from_camera = look_at(&eye, &target, &Vector3::z()).unwrap();
    let truth = render(&shape, &cam, &world_from_camera);
    let out = raycast(&volume, &cam, &world_from_camera, &RaycastConfig::default()).unwrap();
    let (mut n, mut err, mut missed, mut normal_ok, mut extra) =
        (0usize, 0.0f64, 0usize, 0usize, 0usize);
    for v in 0..cam.height {
        for u in 0..cam.width {
            let t = *truth.depth_m.get(u, v).unwrap();
            let r = *out.depth_m.get(u, v).unwrap();
            if t > 0.0 && r > 0.0 {
                n += 1;
                err += f64::from((t - r).abs());
                let p_cam = cam.unproject(
                    &nalgebra::Point2::new(f64::from(u), f64::from(v)),
                    f64::from(r),
                );
                let p_world = world_from_camera * p_cam;
                let c = match shape {
                    Shape::Sphere { center, .. } => center,
                    Shape::Cuboid { .. } => unreachable!(),
                };
                let expected = world_from_camera.inverse() * (p_world - c).normalize();
                let got = out.normals_camera.get(u, v).unwrap();
                let got = Vector3::new(f64::from(got[0]), f64::from(got[1]), f64::from(got[2]));
                normal_ok += usize::from(got.dot(&expected) > 0.95);
                assert_eq!(*out.rgb.get(u, v).unwrap(), COLOR);
            } else if t > 0.0 {
                missed += 1;
            } else if r > 0.0 {
                extra += 1;
            }
        }
    }
    assert!(n > 10_000);
    assert!(
        err / (n as f64) < 0.3 * f64::from(VOXEL),
        "mean depth error {}",
        err / n as f64
    );
    assert!(missed < n / 100, "{missed} pixels missed");
    // Only silhouette pixels may see a surface that is not there.
    assert!(extra < n / 100, "{extra} pixels hit nothing real");
    assert!(normal_ok as f64 > 0.98 * n as f64);
}

#[test]
fn small_components_are_dropped() {
    let shape = sphere();
    let (volume, _, _) = fuse(&shape, TsdfConfig::default());
    let all = extract_mesh(&volume, &MeshingConfig::default());
    let none = extract_mesh(
        &volume,
        &MeshingConfig {
            min_component_triangles: all.face_count() + 1,
            ..MeshingConfig::default()
        },
    );
    assert!(none.is_empty());
    let kept = extract_mesh(
        &volume,
        &MeshingConfig {
            min_component_triangles: all.face_count(),
            ..MeshingConfig::default()
        },
    );
    assert_eq!(kept.face_count(), all.face_count());
}

#[test]
fn rejects_bad_input() {
    assert!(
        TsdfVolume::new(TsdfConfig {
            voxel_size_m: 0.0,
            ..TsdfConfig::default()
        })
        .is_err()
    );
    assert!(
        TsdfVolume::new(TsdfConfig {
            max_depth_m: 0.05,
            ..TsdfConfig::default()
        })
        .is_err()
    );
    let mut volume = TsdfVolume::new(TsdfConfig::default()).unwrap();
    let frame = render(&sphere(), &camera(), &ring_views(&Point3::origin())[0]);
    let small = PinholeCamera::from_hfov(160, 120, 60.0).unwrap();
    assert!(matches!(
        volume.integrate(&frame, &small, &Isometry3::identity()),
        Err(TsdfError::FrameSize { .. })
    ));
    let mut short_depth = frame.clone();
    short_depth.depth_m = DepthImage::filled(10, 10, 1.0);
    assert!(matches!(
        volume.integrate(&short_depth, &camera(), &Isometry3::identity()),
        Err(TsdfError::FrameSize { .. })
    ));
    let mut bad = Isometry3::identity();
    bad.translation.vector.x = f64::NAN;
    assert!(volume.integrate(&frame, &camera(), &bad).is_err());
    assert!("cyl:1,2,0,3".parse::<Roi>().is_err());
    assert!("cyl:1,2,3,0,1".parse::<Roi>().is_err());
    assert!("ball:1,2,3".parse::<Roi>().is_err());
    assert_eq!(
        "cyl:1,2,0,3,0.5".parse::<Roi>().unwrap(),
        Roi::Cylinder {
            center_xy: [1.0, 2.0],
            z_min: 0.0,
            z_max: 3.0,
            radius_m: 0.5
        }
    );
    assert_eq!(
        "box:0,0,0,1,2,3".parse::<Roi>().unwrap(),
        Roi::Box {
            min: [0.0; 3],
            max: [1.0, 2.0, 3.0]
        }
    );
}

/// A frontal plane at 1 m with a few isolated stray measurements 0.5 m behind it, as depth
/// noise or dropouts leave them, seen from the origin looking along +z.
fn plane_with_strays(strays: &[(u32, u32)]) -> (RgbdFrame, PinholeCamera) {
    let cam = camera();
    // Depth along the optical axis of the plane z = 1 is 1 at every pixel.
    let mut depth = DepthImage::filled(cam.width, cam.height, 1.0);
    for &(u, v) in strays {
        *depth.get_mut(u, v).unwrap() = 1.5;
    }
    let rgb = RgbImage::filled(cam.width, cam.height, COLOR);
    (RgbdFrame::new(0.0, rgb, depth, None).unwrap(), cam)
}

#[test]
fn stray_pixels_do_not_allocate_blocks_with_support() {
    let strays = [(40, 40), (160, 120), (250, 60), (90, 200), (300, 230)];
    let (frame, cam) = plane_with_strays(&strays);
    let pose = Isometry3::identity();
    let fused = |support| {
        let mut volume = TsdfVolume::new(TsdfConfig {
            min_block_support: support,
            ..TsdfConfig::default()
        })
        .unwrap();
        let stats = volume.integrate(&frame, &cam, &pose).unwrap();
        assert_eq!(stats.blocks_allocated, volume.block_count());
        volume
    };
    let block = fused(1).config().block_size_m();
    let behind = |v: &TsdfVolume| {
        v.block_coords()
            .iter()
            .filter(|c| c[2] as f32 * block > 1.2)
            .count()
    };
    let (every, supported) = (fused(1), fused(4));
    // Each stray band allocates its own blocks without a support threshold ...
    assert!(behind(&every) >= strays.len(), "{}", behind(&every));
    // ... and none with it, while the plane keeps its blocks and its surface.
    assert_eq!(behind(&supported), 0);
    assert_eq!(
        every.block_count() - behind(&every),
        supported.block_count(),
        "plane blocks differ"
    );
    let triangles = |v: &TsdfVolume| extract_mesh(v, &MeshingConfig::default()).face_count();
    assert!(triangles(&supported) > 1000);
    assert_eq!(triangles(&supported), triangles(&every));
    // A support of 0 is rejected.
    assert!(
        TsdfVolume::new(TsdfConfig {
            min_block_support: 0,
            ..TsdfConfig::default()
        })
        .is_err()
    );
}

#[test]
fn precise_pixels_allocate_alone_and_noisy_ones_need_support() {
    // One measured pixel at 1 m, nothing else: its band crosses a block or two, with a support
    // of one pixel.
    let cam = camera();
    let mut depth = DepthImage::filled(cam.width, cam.height, 0.0);
    *depth.get_mut(160, 120).unwrap() = 1.0;
    let rgb = RgbImage::filled(cam.width, cam.height, COLOR);
    let frame = RgbdFrame::new(0.0, rgb, depth, None).unwrap();
    let blocks = |depth_sigma_at_1m_m| {
        let mut volume = TsdfVolume::new(TsdfConfig {
            min_block_support: 4,
            depth_sigma_at_1m_m,
            ..TsdfConfig::default()
        })
        .unwrap();
        volume
            .integrate(&frame, &cam, &Isometry3::identity())
            .unwrap();
        volume.block_count()
    };
    // Truncation 4 cm: σ(1 m) = 0.02 m is precise (limit √2 m), 0.05 m is not (limit 0.89 m).
    let config = |sigma| TsdfConfig {
        depth_sigma_at_1m_m: sigma,
        ..TsdfConfig::default()
    };
    assert!((config(Some(0.02)).precise_depth_limit_m() - 2f32.sqrt()).abs() < 1e-5);
    assert_eq!(config(Some(0.0)).precise_depth_limit_m(), f32::INFINITY);
    assert_eq!(config(None).precise_depth_limit_m(), 0.0);
    assert!(blocks(Some(0.02)) >= 1);
    assert_eq!(blocks(Some(0.0)), blocks(Some(0.02)));
    assert_eq!(blocks(Some(0.05)), 0);
    assert_eq!(blocks(None), 0);
    // The plane with strays 0.5 m behind it: a limit between the two (σ(1 m) = 0.0256 m, limit
    // 1.25 m) keeps the plane's blocks and drops the strays', as a support of 4 for every pixel
    // does.
    let (frame, cam) = plane_with_strays(&[(40, 40), (160, 120), (250, 60)]);
    let coords = |config: TsdfConfig| {
        let mut volume = TsdfVolume::new(config).unwrap();
        volume
            .integrate(&frame, &cam, &Isometry3::identity())
            .unwrap();
        let mut c = volume.block_coords().to_vec();
        c.sort_unstable();
        c
    };
    let noise_aware = coords(TsdfConfig {
        min_block_support: 4,
        depth_sigma_at_1m_m: Some(0.0256),
        ..TsdfConfig::default()
    });
    let supported = coords(TsdfConfig {
        min_block_support: 4,
        ..TsdfConfig::default()
    });
    assert_eq!(noise_aware, supported);
    assert!(noise_aware.len() < coords(TsdfConfig::default()).len());
    for bad in [f32::NAN, -0.01, f32::INFINITY] {
        let err = TsdfVolume::new(config(Some(bad))).unwrap_err();
        assert!(err.to_string().contains("depth_sigma_at_1m_m"), "{err}");
    }
}

#[test]
fn voxels_count_their_observations_and_meshing_thresholds_them() {
    let (frame, cam) = plane_with_strays(&[]);
    let pose = Isometry3::identity();
    let mut volume = TsdfVolume::new(TsdfConfig::default()).unwrap();
    let on_axis = [0, 0, 100];
    let mesh = |volume: &TsdfVolume, min_observations| {
        let config = MeshingConfig {
            min_observations,
            ..MeshingConfig::default()
        };
        extract_mesh(volume, &config).face_count()
    };
    for n in 1..=3u8 {
        volume.integrate(&frame, &cam, &pose).unwrap();
        assert_eq!(volume.voxel(on_axis).unwrap().observations, n);
        // Voxels more than the truncation distance behind the plane are never observed.
        assert_eq!(volume.voxel([0, 0, 106]).unwrap().observations, 0);
        // The plane is meshed once it has been seen by `min_observations` frames.
        assert_eq!(mesh(&volume, 3) > 0, n >= 3, "after {n} frames");
    }
    assert_eq!(mesh(&volume, 3), mesh(&volume, 0));
    assert_eq!(mesh(&volume, 4), 0);
    // The count saturates at 255 (it is one byte) without disturbing the colour.
    for _ in 3..300 {
        volume.integrate(&frame, &cam, &pose).unwrap();
    }
    let v = volume.voxel(on_axis).unwrap();
    assert_eq!((v.observations, v.color), (255, COLOR));
    assert_eq!(mesh(&volume, 255), mesh(&volume, 0));
}

#[test]
fn colours_blend_by_weight() {
    // A frontal plane at 1 m seen twice from the same pose, in two colours: every observed
    // voxel takes the first colour, then the rounded mean (equal weights).
    let (frame, cam) = plane_with_strays(&[]);
    let mut second = frame.clone();
    second.rgb = RgbImage::filled(cam.width, cam.height, [100, 21, 240]);
    let mut volume = TsdfVolume::new(TsdfConfig::default()).unwrap();
    let pose = Isometry3::identity();
    volume.integrate(&frame, &cam, &pose).unwrap();
    // Voxels on the optical axis, 3 cm in front of, on, and 3 cm behind the plane.
    let on_axis = [97, 100, 103].map(|k| [0, 0, k]);
    for voxel in on_axis {
        assert_eq!(volume.voxel(voxel).unwrap().color, COLOR, "{voxel:?}");
    }
    volume.integrate(&second, &cam, &pose).unwrap();
    for voxel in on_axis {
        let v = volume.voxel(voxel).unwrap();
        // (200 + 100) / 2, (120 + 21) / 2 = 70.5 rounds up, (40 + 240) / 2.
        assert_eq!(v.color, [150, 71, 140], "{voxel:?}");
        // Each observation weighs 1/z².
        let z = voxel[2] as f32 * VOXEL;
        assert!(
            (v.weight - 2.0 / (z * z)).abs() < 1e-4,
            "{voxel:?}: weight {}",
            v.weight
        );
    }
}

#[test]
fn a_region_out_of_view_takes_nothing_from_a_frame() {
    let (frame, cam) = plane_with_strays(&[]);
    let pose = Isometry3::identity();
    // Behind the camera (which looks along +z), and beside its field of view.
    for roi in [
        Roi::Box {
            min: [-1.0, -1.0, -3.0],
            max: [1.0, 1.0, -0.5],
        },
        Roi::Cylinder {
            center_xy: [40.0, 0.0],
            z_min: 0.0,
            z_max: 2.0,
            radius_m: 1.0,
        },
    ] {
        let mut volume = TsdfVolume::new(TsdfConfig {
            roi: Some(roi),
            ..TsdfConfig::default()
        })
        .unwrap();
        let stats = volume.integrate(&frame, &cam, &pose).unwrap();
        assert_eq!((stats.blocks_updated, stats.blocks_allocated), (0, 0));
        assert_eq!(volume.block_count(), 0);
    }
}
