//! Analytic rendering tests: exact depth of a plane, cube corners on their analytic pixels,
//! back-projection onto the world mesh, and thread-count independence.

use std::path::Path;

use nalgebra::{Isometry3, Point2, Point3, Vector3};
use scarp_datasets::render::Renderer;
use scarp_datasets::world::{TERRAIN_INSTANCE_ID, World};
use scarp_slam::PinholeCamera;
use scarp_slam::geometry::{convex_hull_2d, look_at};

fn flat_world(extra: &str, dir: &Path) -> World {
    let text = format!(
        r#"
        [terrain.procedural]
        size_m = 40.0
        resolution_m = 1.0
        scarp_height_m = 0.0
        roughness_m = 0.0
        {extra}
        "#
    );
    World::from_toml_str(&text, Path::new("test.toml"), dir).unwrap()
}

fn camera() -> PinholeCamera {
    PinholeCamera::from_hfov(640, 480, 80.0).unwrap()
}

#[test]
fn plane_renders_exact_depth_and_ids() {
    let world = flat_world("", Path::new("."));
    let renderer = Renderer::new(&world);
    let cam = camera();
    // Straight down from 7.5 m: every pixel's z-depth is 7.5 m.
    let down = look_at(
        &Point3::new(0.3, -0.2, 7.5),
        &Point3::new(0.3, -0.2, 0.0),
        &Vector3::y(),
    )
    .unwrap();
    let out = renderer.render(&cam, &down).unwrap();
    let worst = out
        .depth_m
        .as_slice()
        .iter()
        .map(|&d| (f64::from(d) - 7.5).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-4, "worst depth error {worst}");
    assert!(
        out.instance
            .as_slice()
            .iter()
            .all(|&id| id == TERRAIN_INSTANCE_ID)
    );
    // Oblique view: depth equals the analytic ray–plane intersection.
    let oblique = look_at(
        &Point3::new(-3.0, -6.0, 5.0),
        &Point3::new(2.0, 4.0, 0.0),
        &Vector3::z(),
    )
    .unwrap();
    let out = renderer.render(&cam, &oblique).unwrap();
    let mut checked = 0;
    for v in (0..480).step_by(7) {
        for u in (0..640).step_by(7) {
            let ray_camera = cam.unproject(&Point2::new(f64::from(u), f64::from(v)), 1.0);
            let ray_world = oblique.rotation * ray_camera.coords;
            let depth = *out.depth_m.get(u, v).unwrap();
            let id = *out.instance.get(u, v).unwrap();
            let t = -oblique.translation.z / ray_world.z;
            let hit = oblique.translation.vector + ray_world * t;
            if ray_world.z < 0.0 && hit.x.abs() < 19.9 && hit.y.abs() < 19.9 {
                assert_eq!(id, TERRAIN_INSTANCE_ID, "pixel ({u}, {v})");
                assert!(
                    (f64::from(depth) - t).abs() <= 1e-4 * t.max(1.0),
                    "pixel ({u}, {v}): {depth} vs {t}"
                );
                checked += 1;
            } else if ray_world.z >= 0.0 {
                assert_eq!((depth, id), (0.0, 0), "sky pixel ({u}, {v})");
            }
        }
    }
    assert!(checked > 2000);
}

#[test]
fn cube_corners_land_on_their_analytic_pixels() {
    let dir = std::env::temp_dir().join(format!("scarp-cube-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cube = scarp_slam::TriangleMesh::cuboid(Point3::origin(), Point3::new(1.0, 1.0, 1.0));
    let mut obj = String::new();
    for p in &cube.positions {
        obj.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
    }
    for f in &cube.faces {
        obj.push_str(&format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1));
    }
    std::fs::write(dir.join("cube.obj"), obj).unwrap();
    let world = flat_world(
        r#"
        [[rocks]]
        id = 7
        role = "target"
        position_m = [1.0, 2.0]
        height_m = 1.0
        embed_fraction = 0.0
        shape = { mesh = "cube.obj" }
        "#,
        &dir,
    );
    // The unit cube now spans x ∈ [0.5, 1.5], y ∈ [1.5, 2.5], z ∈ [0, 1].
    let corners: Vec<Point3<f64>> = (0..8)
        .map(|i| {
            Point3::new(
                0.5 + f64::from(i & 1),
                1.5 + f64::from((i >> 1) & 1),
                f64::from((i >> 2) & 1),
            )
        })
        .collect();
    let rock = world.rock(7).unwrap();
    let (lo, hi) = rock.mesh.bounds().unwrap();
    assert!(
        (lo - Point3::new(0.5, 1.5, 0.0)).norm() < 1e-6
            && (hi - Point3::new(1.5, 2.5, 1.0)).norm() < 1e-6
    );
    let cam = camera();
    let world_from_camera = look_at(
        &Point3::new(-2.2, -1.3, 3.1),
        &Point3::new(1.0, 2.0, 0.5),
        &Vector3::z(),
    )
    .unwrap();
    let out = Renderer::new(&world)
        .render(&cam, &world_from_camera)
        .unwrap();
    let camera_from_world = world_from_camera.inverse();
    let projected: Vec<Point2<f64>> = corners
        .iter()
        .map(|p| cam.project(&(camera_from_world * p)).unwrap())
        .collect();
    // The cube is convex, so its silhouette is the hull of its projected corners. A pixel is
    // drawn as the cube exactly when its centre lies inside that hull; a corner off by more than
    // half a pixel would flip pixels near it.
    let hull = convex_hull_2d(&projected);
    let signed_distance = |p: &Point2<f64>| {
        (0..hull.len())
            .map(|i| {
                let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
                let edge = b - a;
                (edge.x * (p.y - a.y) - edge.y * (p.x - a.x)) / edge.norm()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let (mut inside, mut mismatches) = (0, 0);
    for v in 0..480u32 {
        for u in 0..640u32 {
            let d = signed_distance(&Point2::new(f64::from(u), f64::from(v)));
            if d.abs() < 1e-3 {
                continue;
            }
            let is_cube = *out.instance.get(u, v).unwrap() == 7;
            inside += usize::from(d > 0.0);
            mismatches += usize::from(is_cube != (d > 0.0));
        }
    }
    assert!(inside > 1000, "cube covers {inside} pixels");
    assert_eq!(mismatches, 0);
    // The same test against corners shifted by half a pixel finds mismatches, so it would catch
    // a half-pixel error in the rasterizer.
    let hull = convex_hull_2d(
        &projected
            .iter()
            .map(|p| Point2::new(p.x + 0.5, p.y + 0.5))
            .collect::<Vec<_>>(),
    );
    let shifted_mismatches = (0..480u32)
        .flat_map(|v| (0..640u32).map(move |u| (u, v)))
        .filter(|&(u, v)| {
            let p = Point2::new(f64::from(u), f64::from(v));
            let d = (0..hull.len())
                .map(|i| {
                    let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
                    let edge = b - a;
                    (edge.x * (p.y - a.y) - edge.y * (p.x - a.x)) / edge.norm()
                })
                .fold(f64::INFINITY, f64::min);
            (*out.instance.get(u, v).unwrap() == 7) != (d > 0.0)
        })
        .count();
    assert!(shifted_mismatches > 100, "{shifted_mismatches}");
    std::fs::remove_dir_all(&dir).ok();
}

fn point_triangle_distance(p: &Point3<f64>, [a, b, c]: [Point3<f64>; 3]) -> f64 {
    let n = (b - a).cross(&(c - a));
    let area2 = n.norm_squared();
    if area2 < 1e-30 {
        return f64::INFINITY;
    }
    // Projection onto the plane; inside → plane distance, else distance to the edges.
    let q = p - n * (p - a).dot(&n) / area2;
    let inside = [(a, b), (b, c), (c, a)]
        .iter()
        .all(|(s, e)| (e - s).cross(&(q - s)).dot(&n) >= 0.0);
    if inside {
        return (p - q).norm();
    }
    [(a, b), (b, c), (c, a)]
        .iter()
        .map(|(s, e)| {
            let t = ((p - s).dot(&(e - s)) / (e - s).norm_squared()).clamp(0.0, 1.0);
            (p - (s + (e - s) * t)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn back_projected_depth_lands_on_the_world_mesh() {
    let world = World::builtin_default().unwrap();
    let target = world.targets().next().unwrap();
    let cam = camera();
    let world_from_camera = look_at(
        &(target.centroid + Vector3::new(3.0, -2.5, 1.5)),
        &target.centroid,
        &Vector3::z(),
    )
    .unwrap();
    let out = Renderer::new(&world)
        .render(&cam, &world_from_camera)
        .unwrap();
    let mut errors = Vec::new();
    for v in (0..480u32).step_by(3) {
        for u in (0..640u32).step_by(3) {
            let depth = f64::from(*out.depth_m.get(u, v).unwrap());
            if depth <= 0.0 {
                continue;
            }
            let p =
                world_from_camera * cam.unproject(&Point2::new(f64::from(u), f64::from(v)), depth);
            let id = *out.instance.get(u, v).unwrap();
            let mesh = if id == TERRAIN_INSTANCE_ID {
                &world.terrain_mesh
            } else if id < 1000 {
                &world.rock(u32::from(id)).unwrap().mesh
            } else {
                world
                    .rock(u32::from(id - 1000))
                    .unwrap()
                    .pedestal
                    .as_ref()
                    .unwrap()
            };
            // Brute force over the triangles near p: independent of the rasterizer.
            let distance = (0..mesh.face_count())
                .filter(|&f| {
                    let t = mesh.triangle(f);
                    (0..3).all(|k| {
                        let lo = t.iter().map(|q| q[k]).fold(f64::INFINITY, f64::min);
                        let hi = t.iter().map(|q| q[k]).fold(f64::NEG_INFINITY, f64::max);
                        p[k] >= lo - 0.01 && p[k] <= hi + 0.01
                    })
                })
                .map(|f| point_triangle_distance(&p, mesh.triangle(f)))
                .fold(f64::INFINITY, f64::min);
            errors.push(distance);
        }
    }
    assert!(errors.len() > 20_000);
    errors.sort_by(f64::total_cmp);
    let p99 = errors[errors.len() * 99 / 100];
    assert!(p99 <= 0.002, "99th percentile distance {p99} m");
}

#[test]
fn rendering_does_not_depend_on_the_thread_count() {
    let world = World::builtin_default().unwrap();
    let cam = camera();
    let target = world.targets().next().unwrap();
    let pose: Isometry3<f64> = look_at(
        &(target.centroid + Vector3::new(-3.0, 2.0, 2.0)),
        &target.centroid,
        &Vector3::z(),
    )
    .unwrap();
    let render_with = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| Renderer::new(&world).render(&cam, &pose).unwrap())
    };
    let (one, three) = (render_with(1), render_with(3));
    assert_eq!(one.rgb, three.rgb);
    assert_eq!(one.depth_m, three.depth_m);
    assert_eq!(one.instance, three.instance);
}

#[test]
fn a_geometry_render_is_the_full_renders_depth_and_instances() {
    let world = World::builtin_default().unwrap();
    let renderer = Renderer::new(&world);
    let cam = camera();
    let target = world.targets().next().unwrap();
    // A close oblique view (rock, pedestal, terrain and sky), one from above, one grazing.
    let views = [
        (Vector3::new(-3.0, 2.0, 2.0), target.centroid),
        (Vector3::new(0.5, 0.0, 12.0), target.centroid),
        (
            Vector3::new(6.0, -4.0, 0.4),
            target.centroid + Vector3::new(30.0, -20.0, 0.0),
        ),
    ];
    for (offset, look) in views {
        let pose = look_at(&(target.centroid + offset), &look, &Vector3::z()).unwrap();
        let full = renderer.render(&cam, &pose).unwrap();
        let geometry = renderer.render_geometry(&cam, &pose).unwrap();
        assert!(full.depth_m.as_slice().iter().any(|&d| d > 0.0));
        assert_eq!(full.depth_m, geometry.depth_m);
        assert_eq!(full.instance, geometry.instance);
    }
    let bad = Isometry3::translation(f64::NAN, 0.0, 0.0);
    assert!(renderer.render_geometry(&cam, &bad).is_err());
}
