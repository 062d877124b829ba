//! Depth-filter budget: one Algorithm 3 update of 2000 points (noise, projection, mixture
//! weights, low-variance resampling) must take ≤ 1 ms, with or without the depth image's
//! evidence. Also the registration half-space test.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point3, Vector3};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use scarp::detection::BoundingBox;
use scarp::localization::cone::BoxCone;
use scarp::localization::free_space::FreeSpace;
use scarp::localization::points::generate_points;
use scarp::localization::update::{BoxLikelihood, update_points};
use scarp::localization::{LocalizationConfig, TargetCatalog};
use scarp_slam::PinholeCamera;
use scarp_slam::geometry::look_at;
use scarp_slam::image::DepthImage;

fn bench_update(c: &mut Criterion) {
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("valid camera");
    let cfg = LocalizationConfig::default();
    let first = Isometry3::identity();
    let bbox = BoundingBox::new(290.0, 210.0, 350.0, 270.0).expect("valid box");
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
    let points = generate_points(
        &camera,
        &first,
        &bbox.enlarged(cfg.box_enlargement_px),
        cfg.points_per_target,
        cfg.min_depth_m,
        cfg.max_depth_m,
        &mut rng,
    );
    // A second view from 6 m to the side, looking at 10 m depth.
    let second = look_at(
        &Point3::new(6.0, 0.0, 0.0),
        &Point3::new(0.0, 0.0, 10.0),
        &Vector3::new(0.0, -1.0, 0.0),
    )
    .expect("valid view");
    let likelihood = BoxLikelihood {
        bbox,
        enlarged: bbox.enlarged(cfg.box_enlargement_px),
        gaussian_weight: cfg.gaussian_weight,
        uniform_weight: cfg.uniform_weight,
    };
    // The second view sees a wall 10 m ahead along its axis.
    let depth = DepthImage::filled(camera.width, camera.height, 10.0);
    let free_space = FreeSpace::new(&camera, &depth, &second, &bbox, &cfg);
    for (name, evidence) in [
        ("update_2000_points", None),
        ("update_2000_points_with_depth", Some(&free_space)),
    ] {
        c.bench_function(name, |b| {
            b.iter(|| {
                update_points(
                    &points,
                    &camera,
                    &second,
                    &likelihood,
                    evidence,
                    cfg.update_noise_sigma_m,
                    &mut rng,
                )
            })
        });
    }
    let cone = BoxCone::new(&camera, &bbox);
    c.bench_function("cone_test_2000_points", |b| {
        b.iter(|| cone.count_inside(&second, &points))
    });
    c.bench_function("observe_one_box_keyframe", |b| {
        b.iter_batched(
            || {
                let mut catalog = TargetCatalog::new(cfg).expect("valid config");
                let mut r = Xoshiro256PlusPlus::seed_from_u64(2);
                catalog
                    .observe(&camera, &first, &[(1, bbox)], &mut r)
                    .expect("valid input");
                (catalog, r)
            },
            |(mut catalog, mut r)| {
                catalog
                    .observe(&camera, &second, &[(1, bbox)], &mut r)
                    .expect("valid input")
            },
            criterion::BatchSize::SmallInput,
        )
    });
}

criterion_group!(benches, bench_update);
criterion_main!(benches);
