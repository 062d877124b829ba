//! Features on a 640×480 frame pair: Harris corners (whole image, 500 best; and one 50 px box,
//! 20 best), pyramidal LK of 160 points (8 boxes × 20 corners, 25 px window, 4 levels,
//! forward–backward check) and the similarity motion of one box's 20 corners.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Point2;
use scarp_slam::features::pattern::shifted_texture;
use scarp_slam::features::{
    CornerConfig, CornerRegion, KltConfig, KltPyramid, MotionConfig, PixelRect, detect_corners,
    track_points, track_similarity,
};
use scarp_slam::image::GrayImage;

fn frame(dx: f32, dy: f32) -> GrayImage {
    shifted_texture(640, 480, dx, dy)
}

fn bench(c: &mut Criterion) {
    let (prev, next) = (frame(0.0, 0.0), frame(3.0, 1.5));
    let klt = KltConfig::default();
    let (pp, np) = (
        KltPyramid::new(&prev, klt.pyramid_levels),
        KltPyramid::new(&next, klt.pyramid_levels),
    );
    let whole = CornerConfig {
        max_corners: 500,
        min_distance_px: 8.0,
        ..CornerConfig::default()
    };
    c.bench_function("harris_whole_image_500", |b| {
        b.iter(|| detect_corners(&prev, &whole, &CornerRegion::Whole).expect("corners"))
    });
    let rect = |i: u32| PixelRect {
        u_min: 60 + 130 * (i % 4),
        v_min: 80 + 180 * (i / 4),
        u_max: 110 + 130 * (i % 4),
        v_max: 130 + 180 * (i / 4),
    };
    c.bench_function("harris_one_50px_box_20", |b| {
        b.iter(|| {
            detect_corners(
                &prev,
                &CornerConfig::default(),
                &CornerRegion::Rect(rect(0)),
            )
            .expect("corners")
        })
    });
    let points: Vec<Point2<f32>> = (0..8)
        .flat_map(|i| {
            detect_corners(
                &prev,
                &CornerConfig::default(),
                &CornerRegion::Rect(rect(i)),
            )
            .expect("corners")
            .into_iter()
            .map(|c| c.position)
        })
        .collect();
    c.bench_function("pyramid_640x480_4_levels", |b| {
        b.iter(|| KltPyramid::new(&next, klt.pyramid_levels))
    });
    c.bench_function(&format!("klt_{}_points_fb", points.len()), |b| {
        b.iter(|| track_points(&pp, &np, &points, &klt).expect("klt"))
    });
    let one_box = &points[..20.min(points.len())];
    c.bench_function("similarity_motion_one_box_refined", |b| {
        b.iter(|| track_similarity(&pp, &np, one_box, &MotionConfig::default()).expect("fit"))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
