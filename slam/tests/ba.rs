//! Bundle adjustment: synthetic problems with known truth, the BAL problems against Ceres'
//! results, thread-count independence, dense vs sparse reduced solvers, robust losses.

use std::path::PathBuf;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use scarp_slam::ba::{
    LinearSolverKind, LmConfig, Observation, RobustLoss, SnavelyCamera, SnavelyModel, read_bal,
    solve, solve_bal,
};

/// Ceres 2.1's final cost on shrink-1800 (see `tests/data/README.md`).
const CERES_SHRINK_1800: f64 = 3001.362;
/// Ceres 2.1's final cost on problem-49-7776.
const CERES_PROBLEM_49_7776: f64 = 13344.318;

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

/// `shared/data/bal/` beside the repository (CI clones it there).
fn shared_bal_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/bal")
}

/// A Snavely camera at `center` looking at the origin (its −z axis towards the origin).
fn camera_looking_at_origin(
    center: Vector3<f64>,
    focal_px: f64,
    k1: f64,
    k2: f64,
) -> SnavelyCamera {
    let z = center.normalize();
    let up = if z.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let x = up.cross(&z).normalize();
    let y = z.cross(&x);
    let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
        x.transpose(),
        y.transpose(),
        z.transpose(),
    ]));
    let rotation = UnitQuaternion::from_rotation_matrix(&rotation);
    let translation = -(rotation * center);
    SnavelyCamera {
        camera_from_world: Isometry3::from_parts(Translation3::from(translation), rotation),
        focal_px,
        k1,
        k2,
    }
}

struct Synthetic {
    cameras: Vec<SnavelyCamera>,
    points: Vec<Vector3<f64>>,
    observations: Vec<Observation>,
}

/// Random cameras on a sphere of radius 6 around random points in [−1, 1]³; every camera sees
/// every point; noise-free observations.
fn synthetic(seed: u64, num_cameras: usize, num_points: usize) -> Synthetic {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let cameras: Vec<SnavelyCamera> = (0..num_cameras)
        .map(|_| {
            let dir = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(0.3..1.0),
            )
            .normalize();
            camera_looking_at_origin(
                dir * rng.random_range(5.0..7.0),
                rng.random_range(400.0..600.0),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.05..0.05),
            )
        })
        .collect();
    let points: Vec<Vector3<f64>> = (0..num_points)
        .map(|_| {
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        })
        .collect();
    let mut observations = Vec::new();
    for (c, camera) in cameras.iter().enumerate() {
        for (p, x) in points.iter().enumerate() {
            observations.push(Observation {
                camera: c,
                point: p,
                pixel: camera.project(x),
            });
        }
    }
    Synthetic {
        cameras,
        points,
        observations,
    }
}

/// Perturbs cameras (rotation ~0.02 rad, translation ~0.05, focal ~2%, distortion) and points
/// (~0.05) with a seeded RNG.
fn perturbed(truth: &Synthetic, seed: u64) -> (Vec<SnavelyCamera>, Vec<Vector3<f64>>) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut jitter = |scale: f64| {
        Vector3::new(
            rng.random_range(-scale..scale),
            rng.random_range(-scale..scale),
            rng.random_range(-scale..scale),
        )
    };
    let cameras = truth
        .cameras
        .iter()
        .map(|c| {
            let w = jitter(0.02);
            let t = jitter(0.05);
            let intr = jitter(1.0);
            SnavelyCamera {
                camera_from_world: Isometry3::from_parts(
                    Translation3::from(c.camera_from_world.translation.vector + t),
                    UnitQuaternion::from_scaled_axis(w) * c.camera_from_world.rotation,
                ),
                focal_px: c.focal_px * (1.0 + 0.02 * intr.x),
                k1: c.k1 + 0.01 * intr.y,
                k2: c.k2 + 0.005 * intr.z,
            }
        })
        .collect();
    let points = truth.points.iter().map(|p| p + jitter(0.05)).collect();
    (cameras, points)
}

/// The similarity (scale, rotation, translation) that best maps `from` onto `to` (Umeyama).
fn umeyama(from: &[Vector3<f64>], to: &[Vector3<f64>]) -> (f64, Matrix3<f64>, Vector3<f64>) {
    let n = from.len() as f64;
    let mu_f = from.iter().sum::<Vector3<f64>>() / n;
    let mu_t = to.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    let mut var_f = 0.0;
    for (f, t) in from.iter().zip(to) {
        cov += (t - mu_t) * (f - mu_f).transpose();
        var_f += (f - mu_f).norm_squared();
    }
    cov /= n;
    var_f /= n;
    let svd = cov.svd(true, true);
    let (u, v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut s = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let rotation = u * s * v_t;
    let scale = (svd.singular_values.component_mul(&s.diagonal())).sum() / var_f;
    let translation = mu_t - rotation * mu_f * scale;
    (scale, rotation, translation)
}

fn camera_center(c: &SnavelyCamera) -> Vector3<f64> {
    c.camera_from_world.inverse().translation.vector
}

/// Largest error of points and camera centres after Sim(3) alignment, relative to the scene
/// size, and the largest relative intrinsic error.
fn relative_error(truth: &Synthetic, cameras: &[SnavelyCamera], points: &[Vector3<f64>]) -> f64 {
    let mut est: Vec<Vector3<f64>> = points.to_vec();
    est.extend(cameras.iter().map(camera_center));
    let mut tru: Vec<Vector3<f64>> = truth.points.clone();
    tru.extend(truth.cameras.iter().map(camera_center));
    let (s, r, t) = umeyama(&est, &tru);
    let size = tru.iter().map(|p| p.norm()).fold(0.0, f64::max);
    let geometric = est
        .iter()
        .zip(&tru)
        .map(|(e, g)| (r * e * s + t - g).norm() / size)
        .fold(0.0, f64::max);
    let intrinsic = cameras
        .iter()
        .zip(&truth.cameras)
        .map(|(e, g)| {
            ((e.focal_px - g.focal_px).abs() / g.focal_px)
                .max((e.k1 - g.k1).abs())
                .max((e.k2 - g.k2).abs())
        })
        .fold(0.0, f64::max);
    geometric.max(intrinsic)
}

fn tight_config() -> LmConfig {
    LmConfig {
        max_iterations: 200,
        function_tolerance: 1e-16,
        gradient_tolerance: 1e-16,
        parameter_tolerance: 1e-16,
        ..LmConfig::default()
    }
}

#[test]
fn synthetic_problems_converge_back_to_the_truth() {
    for seed in 0..3 {
        let truth = synthetic(seed, 6, 40);
        let (mut cameras, mut points) = perturbed(&truth, 100 + seed);
        let before = relative_error(&truth, &cameras, &points);
        let summary = solve(
            &SnavelyModel,
            &mut cameras,
            &mut points,
            &truth.observations,
            &tight_config(),
        )
        .unwrap();
        let after = relative_error(&truth, &cameras, &points);
        assert!(before > 1e-3, "the start must be perturbed ({before})");
        assert!(
            after < 1e-6,
            "seed {seed}: relative error {after:e} (from {before:e}), summary {:?}",
            summary.termination
        );
        assert!(summary.final_cost < 1e-12 * summary.initial_cost);
        // Costs never increase: rejected steps keep the cost.
        assert!(summary.costs.windows(2).all(|w| w[1] <= w[0]));
        assert_eq!(summary.costs.len(), summary.iterations + 1);
    }
}

#[test]
fn sparse_and_dense_reduced_solvers_agree() {
    let truth = synthetic(7, 8, 30);
    let (cameras0, points0) = perturbed(&truth, 8);
    let config = LmConfig {
        max_iterations: 10,
        ..LmConfig::default()
    };
    let (mut cd, mut pd) = (cameras0.clone(), points0.clone());
    let dense = solve(
        &SnavelyModel,
        &mut cd,
        &mut pd,
        &truth.observations,
        &config,
    )
    .unwrap();
    let (mut cs, mut ps) = (cameras0, points0);
    let sparse_config = LmConfig {
        dense_max_unknowns: 0,
        ..config
    };
    let sparse = solve(
        &SnavelyModel,
        &mut cs,
        &mut ps,
        &truth.observations,
        &sparse_config,
    )
    .unwrap();
    assert_eq!(dense.linear_solver, LinearSolverKind::DenseCholesky);
    assert_eq!(sparse.linear_solver, LinearSolverKind::SparseCholesky);
    assert_eq!(dense.iterations, sparse.iterations);
    for (a, b) in dense.costs.iter().zip(&sparse.costs) {
        assert!(
            (a - b).abs() <= 1e-6 * a.max(1e-9),
            "dense {a} vs sparse {b}"
        );
    }
    for (a, b) in pd.iter().zip(&ps) {
        assert!((a - b).norm() < 1e-6);
    }
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let truth = synthetic(11, 7, 50);
    let (cameras0, points0) = perturbed(&truth, 12);
    let run = |threads: usize, dense_max_unknowns: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (mut c, mut p) = (cameras0.clone(), points0.clone());
            let config = LmConfig {
                max_iterations: 8,
                dense_max_unknowns,
                ..LmConfig::default()
            };
            let s = solve(&SnavelyModel, &mut c, &mut p, &truth.observations, &config).unwrap();
            (s.costs, c, p)
        })
    };
    for dense_max in [1000, 0] {
        let one = run(1, dense_max);
        let three = run(3, dense_max);
        assert_eq!(one.0, three.0);
        assert_eq!(one.1, three.1);
        assert_eq!(one.2, three.2);
    }
}

#[test]
fn robust_losses_resist_outliers() {
    let truth = synthetic(21, 6, 60);
    let mut observations = truth.observations.clone();
    // Every 29th observation is off by 50 pixels.
    let is_outlier = |k: usize| k.is_multiple_of(29);
    for (k, o) in observations.iter_mut().enumerate() {
        if is_outlier(k) {
            o.pixel += Vector2::new(40.0, -30.0);
        }
    }
    let (cameras0, points0) = perturbed(&truth, 22);
    // Largest residual over the inliers after each solve (gauge-free: inliers are noise-free).
    let mut worst_inlier_px = Vec::new();
    for loss in [
        RobustLoss::Trivial,
        RobustLoss::Huber { delta_px: 5.0 },
        RobustLoss::Cauchy { scale_px: 5.0 },
    ] {
        let (mut c, mut p) = (cameras0.clone(), points0.clone());
        let config = LmConfig {
            loss,
            max_iterations: 100,
            function_tolerance: 1e-10,
            ..LmConfig::default()
        };
        let summary = solve(&SnavelyModel, &mut c, &mut p, &observations, &config).unwrap();
        assert!(summary.final_cost < summary.initial_cost);
        let worst = observations
            .iter()
            .enumerate()
            .filter(|(k, _)| !is_outlier(*k))
            .map(|(_, o)| (c[o.camera].project(&p[o.point]) - o.pixel).norm())
            .fold(0.0, f64::max);
        worst_inlier_px.push(worst);
    }
    println!("worst inlier residuals (least squares, Huber, Cauchy): {worst_inlier_px:?} px");
    let [trivial, huber, cauchy] = worst_inlier_px[..] else {
        unreachable!("three losses were run")
    };
    assert!(
        trivial > 5.0,
        "least squares spreads the outliers: {trivial}"
    );
    assert!(
        huber < 0.5 * trivial,
        "Huber {huber} vs least squares {trivial}"
    );
    assert!(
        cauchy < 0.05 * trivial && cauchy < 1.0,
        "Cauchy {cauchy} vs least squares {trivial}"
    );
}

#[test]
fn bad_problems_and_settings_are_rejected() {
    let truth = synthetic(1, 2, 3);
    let (mut c, mut p) = (truth.cameras.clone(), truth.points.clone());
    let mut bad = truth.observations.clone();
    bad[0].point = 99;
    let err = solve(&SnavelyModel, &mut c, &mut p, &bad, &LmConfig::default()).unwrap_err();
    assert!(err.to_string().contains("observation 0"), "{err}");
    p[1].y = f64::NAN;
    let err = solve(
        &SnavelyModel,
        &mut c,
        &mut p,
        &truth.observations,
        &LmConfig::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("point 1"), "{err}");
    p[1].y = 0.0;
    let config = LmConfig {
        loss: RobustLoss::Huber { delta_px: -1.0 },
        ..LmConfig::default()
    };
    let err = solve(&SnavelyModel, &mut c, &mut p, &truth.observations, &config).unwrap_err();
    assert!(err.to_string().contains("delta_px"), "{err}");
}

#[test]
fn bal_shrink_1800_matches_ceres() {
    let mut problem =
        read_bal(data_dir().join("bal-ladybug-problem-49-7776-pre-shrink-1800.txt")).unwrap();
    assert_eq!(
        (
            problem.cameras.len(),
            problem.points.len(),
            problem.observations.len()
        ),
        (49, 1800, 10863)
    );
    let summary = solve_bal(&mut problem, &LmConfig::default()).unwrap();
    assert!(
        (summary.initial_cost - 234519.80).abs() < 0.01,
        "{}",
        summary.initial_cost
    );
    let relative = (summary.final_cost - CERES_SHRINK_1800) / CERES_SHRINK_1800;
    assert!(
        relative < 1e-3,
        "final cost {} vs Ceres {CERES_SHRINK_1800} ({} iterations, {:?})",
        summary.final_cost,
        summary.iterations,
        summary.termination
    );
}

#[test]
fn bal_problem_49_7776_matches_ceres() {
    let path = shared_bal_dir().join("problem-49-7776-pre.txt");
    if !path.exists() {
        println!("skipping: {} is absent", path.display());
        return;
    }
    let mut problem = read_bal(&path).unwrap();
    let summary = solve_bal(&mut problem, &LmConfig::default()).unwrap();
    assert!(
        (summary.initial_cost - 850912.46).abs() < 0.01,
        "{}",
        summary.initial_cost
    );
    let relative = (summary.final_cost - CERES_PROBLEM_49_7776) / CERES_PROBLEM_49_7776;
    assert!(
        relative < 1e-3,
        "final cost {} vs Ceres {CERES_PROBLEM_49_7776} ({} iterations, {:?})",
        summary.final_cost,
        summary.iterations,
        summary.termination
    );
}

/// Keyframe poses on a ring around landmarks, noise-free pixels and depths, exact odometry and
/// GPS priors: from a perturbed start the solver returns to the truth (the absolute priors fix
/// the gauge, so no alignment is needed).
#[test]
fn keyframe_problem_with_priors_converges_back_to_the_truth() {
    use nalgebra::{Matrix6, Point3};
    use scarp_slam::PinholeCamera;
    use scarp_slam::ba::{
        AbsolutePosePrior, KeyframeModel, KeyframeNoise, KeyframeObservation, RelativePosePrior,
    };
    use scarp_slam::geometry::look_at;

    let intrinsics = PinholeCamera::new(500.0, 500.0, 319.5, 239.5, 640, 480).unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(31);
    let truth_poses: Vec<Isometry3<f64>> = (0..8)
        .map(|k| {
            let angle = k as f64 * 0.35;
            let eye = Point3::new(
                6.0 * angle.cos(),
                6.0 * angle.sin(),
                2.0 + 0.3 * (k % 2) as f64,
            );
            look_at(&eye, &Point3::new(0.0, 0.0, 0.5), &Vector3::z()).unwrap()
        })
        .collect();
    let truth_points: Vec<Vector3<f64>> = (0..60)
        .map(|_| {
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(0.0..1.5),
            )
        })
        .collect();
    let mut observations = Vec::new();
    for (c, pose) in truth_poses.iter().enumerate() {
        for (p, x) in truth_points.iter().enumerate() {
            let p_cam = pose.inverse() * Point3::from(*x);
            let Some(pixel) = intrinsics.project(&p_cam) else {
                continue;
            };
            if !intrinsics.in_bounds(&pixel, 0.0) {
                continue;
            }
            observations.push(KeyframeObservation {
                camera: c,
                point: p,
                pixel: pixel.coords,
                depth_m: ((c + p) % 2 == 0).then_some(p_cam.z),
            });
        }
    }
    assert!(observations.len() > 300);
    let gps_information = Matrix6::from_diagonal(&nalgebra::Vector6::new(
        100.0, 100.0, 100.0, 400.0, 400.0, 400.0,
    ));
    let absolute = truth_poses
        .iter()
        .enumerate()
        .map(|(camera, pose)| AbsolutePosePrior {
            camera,
            world_from_camera: *pose,
            information: gps_information,
        })
        .collect();
    let relative = truth_poses
        .windows(2)
        .enumerate()
        .map(|(k, w)| RelativePosePrior {
            camera_a: k,
            camera_b: k + 1,
            camera_a_from_camera_b: w[0].inverse() * w[1],
            information: Matrix6::identity() * 1e4,
        })
        .collect();
    let model =
        KeyframeModel::new(intrinsics, KeyframeNoise::default(), absolute, relative).unwrap();
    let poses: Vec<Isometry3<f64>> = truth_poses
        .iter()
        .map(|p| {
            let dt = Vector3::new(
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
            );
            let dw = Vector3::new(
                rng.random_range(-0.03..0.03),
                rng.random_range(-0.03..0.03),
                rng.random_range(-0.03..0.03),
            );
            Isometry3::from_parts(
                Translation3::from(p.translation.vector + dt),
                p.rotation * UnitQuaternion::from_scaled_axis(dw),
            )
        })
        .collect();
    let points: Vec<Vector3<f64>> = truth_points
        .iter()
        .map(|x| {
            x + Vector3::new(
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
            )
        })
        .collect();
    for dense_max_unknowns in [1000, 0] {
        let (mut c, mut p) = (poses.clone(), points.clone());
        let config = LmConfig {
            dense_max_unknowns,
            ..tight_config()
        };
        let summary = solve(&model, &mut c, &mut p, &observations, &config).unwrap();
        let scene = 6.5;
        let pose_error = c
            .iter()
            .zip(&truth_poses)
            .map(|(e, t)| {
                let d = t.inverse() * e;
                (d.translation.vector.norm() / scene).max(d.rotation.angle())
            })
            .fold(0.0, f64::max);
        let point_error = p
            .iter()
            .zip(&truth_points)
            .map(|(e, t)| (e - t).norm() / scene)
            .fold(0.0, f64::max);
        assert!(
            pose_error < 1e-6 && point_error < 1e-6,
            "pose error {pose_error:e}, point error {point_error:e}, {:?} after {} iterations",
            summary.termination,
            summary.iterations
        );
        assert!(summary.final_cost < 1e-12 * summary.initial_cost);
    }
}
