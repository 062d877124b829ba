//! Frame-to-model odometry: a frame tracked against a raycast of a TSDF model built from other
//! frames (the reference is the model, not the previous frame).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use scarp_datasets::paths::default_orbit;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::World;
use scarp_slam::image::{ImagePyramid, gray_from_rgb};
use scarp_slam::odometry::{
    OdometryConfig, RaycastImages, SourceFrame, TrackingReference, frame_pyramid, track,
};
use scarp_slam::tsdf::raycast::{RaycastConfig, raycast};
use scarp_slam::tsdf::{Roi, TsdfConfig, TsdfVolume};
use scarp_slam::{PinholeCamera, RgbdFrame};

#[test]
fn frame_to_model_tracking_recovers_the_pose() {
    let world = World::builtin_default().unwrap();
    let renderer = Renderer::new(&world);
    let camera = PinholeCamera::from_hfov(320, 240, 80.0).unwrap();
    let orbit = default_orbit(&world, 360).unwrap();
    let target = world.targets().next().unwrap().centroid;
    // The model: the target's surroundings (a 3 m cylinder) fused from five true views.
    let mut volume = TsdfVolume::new(TsdfConfig {
        voxel_size_m: 0.01,
        roi: Some(Roi::Cylinder {
            center_xy: [target.x, target.y],
            z_min: target.z - 3.0,
            z_max: target.z + 3.0,
            radius_m: 3.0,
        }),
        ..TsdfConfig::default()
    })
    .unwrap();
    let render = |k: usize| {
        let out = renderer
            .render(&camera, &orbit[k].world_from_camera)
            .unwrap();
        RgbdFrame::new(orbit[k].timestamp_s, out.rgb, out.depth_m, None).unwrap()
    };
    for k in [0usize, 3, 6, 9, 12] {
        volume
            .integrate(&render(k), &camera, &orbit[k].world_from_camera)
            .unwrap();
    }
    // Predicted pose of the new frame: the last model view; the frame is 2° further on.
    let (predicted, current) = (12usize, 14usize);
    let world_from_reference = orbit[predicted].world_from_camera;
    let model = raycast(
        &volume,
        &camera,
        &world_from_reference,
        &RaycastConfig::default(),
    )
    .unwrap();
    assert!(
        model
            .depth_m
            .as_slice()
            .iter()
            .filter(|&&d| d > 0.0)
            .count()
            > 10_000
    );
    let config = OdometryConfig::default();
    let reference = TrackingReference::from_raycast(
        &camera,
        &RaycastImages {
            depth_m: model.depth_m.clone(),
            normals: model.normals_camera.clone(),
            intensity: gray_from_rgb(&model.rgb),
        },
        &config,
    )
    .unwrap();
    let frame = render(current);
    let source =
        SourceFrame::from_pyramid(&camera, &frame_pyramid(&frame, config.levels), &config).unwrap();
    let truth = world_from_reference.inverse() * orbit[current].world_from_camera;
    let guess = Isometry3::from_parts(
        Translation3::new(0.02, 0.01, -0.015),
        UnitQuaternion::from_scaled_axis(Vector3::new(
            0.4f64.to_radians(),
            0.0,
            0.2f64.to_radians(),
        )),
    ) * truth;
    let result = track(&reference, &source, &guess, &config).unwrap();
    assert!(result.is_ok(), "{:?}", result.failure);
    let e = truth.inverse() * result.reference_from_current;
    let (e_m, e_deg) = (e.translation.vector.norm(), e.rotation.angle().to_degrees());
    eprintln!("frame-to-model error {:.3} mm, {:.4}°", e_m * 1e3, e_deg);
    assert!(e_m < 2e-3 && e_deg < 0.05, "{e_m} m, {e_deg}°");

    // The raycast reference must also agree with a reference made from the true frame's own
    // images at the same pose (same pyramid sizes, similar depth).
    let direct = ImagePyramid::new(
        gray_from_rgb(&render(predicted).rgb),
        render(predicted).depth_m,
        config.levels,
    );
    let direct_reference = TrackingReference::from_pyramid(&camera, &direct, &config).unwrap();
    let r2 = track(&direct_reference, &source, &guess, &config).unwrap();
    assert!(r2.is_ok());
    assert_eq!(reference.levels(), direct_reference.levels());
}
