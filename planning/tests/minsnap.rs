//! Min-snap: waypoints hit exactly, continuity to snap at the knots, limits respected under
//! dense sampling, lower snap cost than a naive spline, start from the current velocity, and
//! clear errors on bad input.

use nalgebra::{Point3, Vector3};
use proptest::prelude::*;
use scarp_planning::minsnap::{Segment, solve_fixed_times};
use scarp_planning::prelude::*;

fn zigzag() -> Path {
    Path::new(vec![
        Waypoint::new(Point3::new(0.0, 0.0, 5.0), 0.0),
        Waypoint::new(Point3::new(4.0, 1.0, 5.5), 0.3),
        Waypoint::new(Point3::new(6.0, 5.0, 6.0), 1.2),
        Waypoint::new(Point3::new(2.0, 7.0, 5.0), 2.5),
        Waypoint::new(Point3::new(-3.0, 4.0, 4.0), 3.0),
        Waypoint::new(Point3::new(-1.0, 0.5, 5.0), 4.0),
    ])
}

fn assert_hits_waypoints(traj: &Trajectory, path: &Path) {
    let times = traj.waypoint_times_s();
    assert_eq!(times.len(), path.waypoints.len());
    for (t, w) in times.iter().zip(&path.waypoints) {
        let s = traj.sample(*t);
        assert!(
            (s.position_m - w.position_m).norm() < 1e-9,
            "at {t}: {} vs {}",
            s.position_m,
            w.position_m
        );
        assert!((s.yaw_rad - w.yaw_rad).abs() < 1e-9);
    }
}

/// Derivatives 0..=4 from both sides of every interior knot, evaluated on the two polynomials
/// that meet there, and by finite differences across the knot.
fn assert_continuous_to_snap(traj: &Trajectory) {
    let segs = traj.segments();
    for j in 0..segs.len() - 1 {
        for order in 0..=4 {
            let left = segs[j].derivative(1.0, order);
            let right = segs[j + 1].derivative(0.0, order);
            let scale = left.norm().max(right.norm()).max(1.0);
            assert!(
                (left - right).norm() < 1e-7 * scale,
                "knot {j}, derivative {order}: {left} vs {right}"
            );
            // Numeric: the trajectory sampled just either side of the knot.
            let t = traj.knot_times_s()[j + 1];
            let eps = 1e-7;
            let a = traj.derivative(t - eps, order);
            let b = traj.derivative(t + eps, order);
            assert!(
                (a - b).norm() < 1e-4 * scale,
                "knot {j}, derivative {order}: jump {}",
                (a - b).norm()
            );
        }
    }
}

#[test]
fn waypoints_exact_and_continuous_to_snap() {
    let path = zigzag();
    let traj = plan_min_snap(&path, &StartState::default(), &MinSnapConfig::default()).unwrap();
    assert_hits_waypoints(&traj, &path);
    assert_continuous_to_snap(&traj);
    // Ends at rest.
    let end = traj.sample(traj.duration_s());
    assert!(end.velocity_mps.norm() < 1e-9 && end.acceleration_mps2.norm() < 1e-9);
}

#[test]
fn limits_hold_under_dense_sampling() {
    let cfg = MinSnapConfig::default();
    let traj = plan_min_snap(&zigzag(), &StartState::default(), &cfg).unwrap();
    let (mut vmax, mut amax) = (0.0f64, 0.0f64);
    let n = (traj.duration_s() / 0.001) as usize;
    for k in 0..=n {
        let s = traj.sample(k as f64 * 0.001);
        vmax = vmax.max(s.velocity_mps.norm());
        amax = amax.max(s.acceleration_mps2.norm());
    }
    println!(
        "duration {:.2} s, v_max {vmax:.4}, a_max {amax:.4}",
        traj.duration_s()
    );
    assert!(vmax <= cfg.max_speed_mps, "speed {vmax}");
    assert!(amax <= cfg.max_accel_mps2, "accel {amax}");
    // Time scaling makes the tightest limit nearly active rather than leaving the plan slow.
    assert!(vmax >= 0.9 * cfg.max_speed_mps || amax >= 0.9 * cfg.max_accel_mps2);
}

/// A degree-9 spline through the same points with the same durations, whose interior
/// derivatives are guessed instead of optimised: Catmull-Rom velocities, zero higher
/// derivatives. Continuous to snap, but not minimum-snap.
fn naive_spline(path: &Path, durations: &[f64]) -> Trajectory {
    let p: Vec<Vector3<f64>> = path.waypoints.iter().map(|w| w.position_m.coords).collect();
    let n = p.len();
    let vel: Vec<Vector3<f64>> = (0..n)
        .map(|i| {
            if i == 0 || i == n - 1 {
                Vector3::zeros()
            } else {
                (p[i + 1] - p[i - 1]) / (durations[i - 1] + durations[i])
            }
        })
        .collect();
    // Coefficients from endpoint values (position, velocity; acc, jerk, snap zero) by solving
    // the 10×10 Hermite system with nalgebra.
    let a = nalgebra::SMatrix::<f64, 10, 10>::from_fn(|r, i| {
        let k = r % 5;
        let tau: f64 = if r < 5 { 0.0 } else { 1.0 };
        if i < k {
            0.0
        } else {
            let f: f64 = (0..k).map(|m| (i - m) as f64).product();
            f * tau.powi((i - k) as i32)
        }
    });
    let a_inv = a.try_inverse().unwrap();
    let segs = (0..n - 1)
        .map(|j| {
            let t = durations[j];
            let mut coeffs = [[0.0; 10]; 4];
            for d in 0..3 {
                let mut b = nalgebra::SVector::<f64, 10>::zeros();
                b[0] = p[j][d];
                b[1] = vel[j][d] * t;
                b[5] = p[j + 1][d];
                b[6] = vel[j + 1][d] * t;
                coeffs[d].copy_from_slice((a_inv * b).as_slice());
            }
            let mut b = nalgebra::SVector::<f64, 10>::zeros();
            b[0] = path.waypoints[j].yaw_rad;
            b[5] = path.waypoints[j + 1].yaw_rad;
            coeffs[3].copy_from_slice((a_inv * b).as_slice());
            Segment {
                duration_s: t,
                coeffs,
            }
        })
        .collect();
    Trajectory::from_segments(segs).unwrap()
}

#[test]
fn snap_cost_beats_a_naive_spline() {
    let path = zigzag();
    let traj = plan_min_snap(&path, &StartState::default(), &MinSnapConfig::default()).unwrap();
    // The same points: every knot of the min-snap trajectory (long legs are subdivided).
    let knots = traj.knot_path();
    let durations: Vec<f64> = traj.segments().iter().map(|s| s.duration_s).collect();
    let naive = naive_spline(&knots, &durations);
    assert_hits_waypoints(&naive, &knots);
    let (j_opt, j_naive) = (traj.snap_cost(), naive.snap_cost());
    println!("snap cost: min-snap {j_opt:.6}, naive {j_naive:.6}");
    assert!(j_opt < j_naive, "{j_opt} vs {j_naive}");
}

#[test]
fn starts_from_the_current_velocity() {
    let path = zigzag();
    let start = StartState {
        velocity_mps: Vector3::new(0.0, -0.6, 0.2),
        acceleration_mps2: Vector3::new(0.1, 0.0, 0.0),
        yaw_rate_radps: 0.2,
    };
    let cfg = MinSnapConfig::default();
    let traj = plan_min_snap(&path, &start, &cfg).unwrap();
    let s0 = traj.sample(0.0);
    assert!((s0.velocity_mps - start.velocity_mps).norm() < 1e-9);
    assert!((s0.acceleration_mps2 - start.acceleration_mps2).norm() < 1e-9);
    assert!((s0.yaw_rate_radps - 0.2).abs() < 1e-9);
    assert_hits_waypoints(&traj, &path);
    let peaks = traj.peaks(0.001);
    assert!(
        peaks.speed_mps <= cfg.max_speed_mps && peaks.accel_mps2 <= cfg.max_accel_mps2,
        "{peaks:?}"
    );
    // Too fast a start is refused.
    let fast = StartState {
        velocity_mps: Vector3::new(2.0, 0.0, 0.0),
        ..Default::default()
    };
    assert!(matches!(
        plan_min_snap(&path, &fast, &cfg),
        Err(PlanError::StartTooFast { .. })
    ));
}

#[test]
fn bad_input_gives_clear_errors() {
    let cfg = MinSnapConfig::default();
    let mut path = zigzag();
    path.waypoints[2].position_m.y = f64::NAN;
    let err = plan_min_snap(&path, &StartState::default(), &cfg).unwrap_err();
    assert!(
        err.to_string().contains("waypoints[2].position_m.y"),
        "{err}"
    );
    let mut path = zigzag();
    path.waypoints[3].yaw_rad = f64::INFINITY;
    let err = plan_min_snap(&path, &StartState::default(), &cfg).unwrap_err();
    assert!(err.to_string().contains("waypoints[3].yaw_rad"), "{err}");
    let mut path = zigzag();
    path.waypoints[2] = path.waypoints[1];
    assert_eq!(
        plan_min_snap(&path, &StartState::default(), &cfg).unwrap_err(),
        PlanError::DuplicateWaypoint { index: 1 }
    );
    let one = Path::new(vec![zigzag().waypoints[0]]);
    assert!(matches!(
        plan_min_snap(&one, &StartState::default(), &cfg),
        Err(PlanError::TooFew { .. })
    ));
    let nan_start = StartState {
        velocity_mps: Vector3::new(f64::NAN, 0.0, 0.0),
        ..Default::default()
    };
    assert!(matches!(
        plan_min_snap(&zigzag(), &nan_start, &cfg),
        Err(PlanError::NonFinite { .. })
    ));
    let zero_limit = MinSnapConfig {
        max_speed_mps: 0.0,
        ..cfg
    };
    let err = plan_min_snap(&zigzag(), &StartState::default(), &zero_limit).unwrap_err();
    assert!(err.to_string().contains("max_speed_mps"), "{err}");
    assert!(solve_fixed_times(&zigzag(), &StartState::default(), &[1.0, 1.0]).is_err());
    assert!(
        solve_fixed_times(
            &zigzag(),
            &StartState::default(),
            &[1.0, 1.0, -1.0, 1.0, 1.0]
        )
        .is_err()
    );
}

#[test]
fn yaw_only_segment_turns_in_place() {
    let path = Path::new(vec![
        Waypoint::new(Point3::new(0.0, 0.0, 5.0), 0.0),
        Waypoint::new(Point3::new(0.0, 0.0, 5.0), 1.5),
        Waypoint::new(Point3::new(3.0, 0.0, 5.0), 1.5),
    ]);
    let cfg = MinSnapConfig::default();
    let traj = plan_min_snap(&path, &StartState::default(), &cfg).unwrap();
    assert_hits_waypoints(&traj, &path);
    assert!(traj.peaks(0.001).yaw_rate_radps <= cfg.max_yaw_rate_radps);
}

fn waypoint_strategy() -> impl Strategy<Value = Vec<(f64, f64, f64, f64)>> {
    prop::collection::vec(
        (-20.0..20.0f64, -20.0..20.0f64, 1.0..15.0f64, -3.0..3.0f64),
        2..9,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn random_paths_hit_waypoints_and_respect_limits(raw in waypoint_strategy()) {
        let mut wps: Vec<Waypoint> = Vec::new();
        for (x, y, z, yaw) in raw {
            let w = Waypoint::new(Point3::new(x, y, z), yaw);
            if wps.last().is_none_or(|l| (l.position_m - w.position_m).norm() > 0.5) {
                wps.push(w);
            }
        }
        prop_assume!(wps.len() >= 2);
        let path = Path::new(wps);
        let cfg = MinSnapConfig::default();
        let traj = plan_min_snap(&path, &StartState::default(), &cfg).unwrap();
        assert_hits_waypoints(&traj, &path);
        assert_continuous_to_snap(&traj);
        let p = traj.peaks(0.002);
        prop_assert!(p.speed_mps <= cfg.max_speed_mps, "speed {}", p.speed_mps);
        prop_assert!(p.accel_mps2 <= cfg.max_accel_mps2, "accel {}", p.accel_mps2);
        prop_assert!(p.yaw_rate_radps <= cfg.max_yaw_rate_radps, "yaw rate {}", p.yaw_rate_radps);
    }
}

/// Plans `waypoints` from `start` with the default limits and checks the peaks against them.
fn assert_timed_within_limits(waypoints: &[([f64; 3], f64)], start: &StartState) {
    let path = Path::new(
        waypoints
            .iter()
            .map(|&(p, yaw)| Waypoint::new(Point3::from(p), yaw))
            .collect(),
    );
    let cfg = MinSnapConfig::default();
    let trajectory = plan_min_snap(&path, start, &cfg).expect("timed");
    let peaks = trajectory.peaks(cfg.sample_period_s);
    assert!(peaks.speed_mps <= cfg.max_speed_mps * 1.001, "{peaks:?}");
    assert!(peaks.accel_mps2 <= cfg.max_accel_mps2 * 1.001, "{peaks:?}");
    assert!(
        peaks.yaw_rate_radps <= cfg.max_yaw_rate_radps * 1.001,
        "{peaks:?}"
    );
}

/// Regression: the default mission's descent onto a base ring, started at 0.86 m/s. The
/// trajectory leaving that speed overshoots it by a fixed factor, so time scaling stalled above
/// the margin (but under the hard limit) and stretched the trajectory without end.
#[test]
fn a_descent_onto_a_base_ring_is_timed() {
    let waypoints = [
        (
            [30.86187675645039, 17.02956537632252, 12.395333766512014],
            -3.4731722213573595,
        ),
        (
            [27.45711959282551, 18.75837959559824, -0.08613840727607922],
            -3.6114324111937113,
        ),
        (
            [27.75608410112099, 19.880407479342107, -0.047763894807803714],
            -3.192553390715072,
        ),
        (
            [
                27.572831914799252,
                21.027030776387566,
                -0.030468390098515513,
            ],
            -2.7736743702364333,
        ),
        (
            [26.93904900166918, 21.999987901929824, -0.0287742187136458],
            -2.354795349757794,
        ),
        (
            [25.964322185147964, 22.63104572992463, -0.07624328396168409],
            -1.935916329279155,
        ),
        (
            [24.817190586927268, 22.81108862893129, -0.14578791593861914],
            -1.517037308800516,
        ),
        (
            [23.696003681702845, 22.508985546073166, -0.13626869971754493],
            -1.0981582883218768,
        ),
        (
            [22.794624871051273, 21.776972848896772, -0.13326354739332266],
            -0.6792792678432376,
        ),
        (
            [22.268910740103628, 20.741622182870493, -0.13346551215257238],
            -0.26040024736459877,
        ),
        (
            [22.209762038063705, 19.581955084015785, -0.13346779930636007],
            0.15847877311404046,
        ),
        (
            [22.62740611286329, 18.498488528969485, -0.13359198291900473],
            0.5773577935926792,
        ),
        (
            [23.44962850979223, 17.678563728083745, -0.14409300484919826],
            0.996236814071318,
        ),
        (
            [24.53425950676554, 17.263953128214677, -0.13555450916528952],
            1.4151158345499577,
        ),
        (
            [25.69375655084326, 17.326346668698697, -0.12427845506211951],
            1.8339948550285974,
        ),
        (
            [26.727632069404397, 17.8549559395586, -0.10500836547331346],
            2.252873875507236,
        ),
        (
            [27.45711959282551, 18.75837959559824, -0.08613840727607922],
            2.671752895985874,
        ),
        (
            [27.01129916865958, 18.984751301861433, 2.777450166162537],
            2.671752895985875,
        ),
        (
            [26.412428513876144, 18.243088286294025, 2.777450166162537],
            2.2528738755072357,
        ),
        (
            [25.563671422237928, 17.809128047084126, 2.777450166162537],
            1.833994855028597,
        ),
        (
            [24.611785705605282, 17.757906251996136, 2.777450166162537],
            1.4151158345499577,
        ),
        (
            [23.72136105199425, 18.098279614736164, 2.777450166162537],
            0.9962368140713187,
        ),
        (
            [23.04635997326821, 18.771394488691538, 2.777450166162537],
            0.5773577935926797,
        ),
        (
            [22.703496288131177, 19.660863197098717, 2.777450166162537],
            0.15847877311404046,
        ),
        (
            [22.752054242562142, 20.612888519704562, 2.777450166162537],
            -0.26040024736459877,
        ),
        (
            [23.183637725104823, 21.462856629351982, 2.777450166162537],
            -0.6792792678432376,
        ),
        (
            [23.92362203081474, 22.06380031816508, 2.777450166162537],
            -1.0981582883218768,
        ),
        (
            [24.844057150688275, 22.311810962946044, 2.777450166162537],
            -1.5170373088005156,
        ),
        (
            [25.78579149060874, 22.164005270106273, 2.777450166162537],
            -1.9359163292791544,
        ),
        (
            [26.585990627815995, 21.64594018671033, 2.777450166162537],
            -2.354795349757794,
        ),
        (
            [27.10629286190596, 20.8471938721509, 2.777450166162537],
            -2.7736743702364337,
        ),
        (
            [27.256733209807074, 19.905876820597772, 2.777450166162537],
            -3.1925533907150725,
        ),
        (
            [27.01129916865958, 18.984751301861436, 2.777450166162537],
            -3.6114324111937104,
        ),
    ];
    let start = StartState {
        velocity_mps: Vector3::new(
            -0.2795723803384477,
            -0.8145112593607139,
            1.0275672402015524e-09,
        ),
        acceleration_mps2: Vector3::new(
            -0.0906034465770791,
            0.03481618595082865,
            -5.561153693538013e-11,
        ),
        yaw_rate_radps: -0.11315960865870896,
    };
    assert_timed_within_limits(&waypoints, &start);
}

/// Regression: another such descent, started at 0.72 m/s and 0.07 m/s². Stretching time
/// multiplies the velocity that the fixed start acceleration builds up, so no timing met the
/// limits: the start's acceleration is dropped.
#[test]
fn a_start_acceleration_that_no_timing_absorbs_is_dropped() {
    let waypoints = [
        (
            [29.404428302209308, 23.450000321344554, 12.39533376618846],
            3.847678721217222,
        ),
        (
            [27.522667548546245, 21.472260832268862, -0.02996851299284073],
            3.9518538695742995,
        ),
        (
            [26.3440422727293, 22.196660028907147, -0.050277664031774],
            4.370732890052938,
        ),
        (
            [24.97267480825651, 22.379041536385923, -0.12547363215962334],
            4.789611910531578,
        ),
        (
            [23.64568704821752, 21.98786993517814, -0.13350846947261372],
            5.208490931010217,
        ),
        (
            [22.59252723162841, 21.09078234881505, -0.13389892288768843],
            5.6273699514888555,
        ),
        (
            [21.99529625843401, 19.842893370763704, -0.13350882793520844],
            6.046248971967495,
        ),
        (
            [21.95726078957269, 18.45997434204465, -0.13484694195715305],
            6.465127992446134,
        ),
        (
            [22.484997503151963, 17.18114452614837, -0.15175571713767821],
            6.884007012924773,
        ),
        (
            [23.487255927056435, 16.227525216047486, -0.15175571713767821],
            7.3028860334034125,
        ),
        (
            [24.79073647456109, 15.764005853817903, -0.15175571713767821],
            7.721765053882051,
        ),
        (
            [26.170055517253356, 15.87073314813032, -0.1067164151251124],
            8.14064407436069,
        ),
        (
            [27.38671626193162, 16.52925298021109, -0.06444652039139251],
            8.559523094839328,
        ),
        (
            [28.230347012825142, 17.625701288628594, -0.05134239829687334],
            8.97840211531797,
        ),
        (
            [28.55507634895966, 18.97049219993726, -0.04014453795007342],
            9.397281135796607,
        ),
        (
            [28.304755618044112, 20.331099148529933, -0.02235302392737401],
            9.816160156275247,
        ),
        (
            [27.52266754854625, 21.47226083226886, -0.02996851299284073],
            10.235039176753885,
        ),
        (
            [26.83335833450321, 20.747793574599218, 3.6463204942156375],
            10.235039176753887,
        ),
        (
            [27.380372936241024, 19.949632691836122, 3.6463204942156375],
            9.816160156275247,
        ),
        (
            [27.555454362833302, 18.997985560095604, 3.6463204942156375],
            9.397281135796609,
        ),
        (
            [27.328329445057413, 18.05740061389838, 3.6463204942156375],
            8.97840211531797,
        ),
        (
            [26.738270144561906, 17.290513535387927, 3.6463204942156375],
            8.55952309483933,
        ),
        (
            [25.88730307492292, 16.829926067389096, 3.6463204942156375],
            8.140644074360692,
        ),
        (
            [24.922568173274158, 16.755277967424668, 3.6463204942156375],
            7.721765053882052,
        ),
        (
            [24.010876868452133, 17.079476570135196, 3.6463204942156375],
            7.3028860334034125,
        ),
        (
            [23.309868869516063, 17.74646499186018, 3.6463204942156375],
            6.884007012924775,
        ),
        (
            [22.94075482793973, 18.64091487508379, 3.6463204942156375],
            6.465127992446135,
        ),
        (
            [22.967357914807486, 19.608167709174573, 3.6463204942156375],
            6.046248971967496,
        ),
        (
            [23.385078214718433, 20.480976691902093, 3.6463204942156375],
            5.627369951488857,
        ),
        (
            [24.12168809294818, 21.108425220932087, 3.6463204942156375],
            5.208490931010218,
        ),
        (
            [25.049821009660143, 21.382021745404327, 3.6463204942156375],
            4.789611910531578,
        ),
        (
            [26.008994351731978, 21.25445894069117, 3.6463204942156375],
            4.370732890052939,
        ),
        (
            [26.83335833450321, 20.74779357459922, 3.6463204942156375],
            3.9518538695743013,
        ),
    ];
    let start = StartState {
        velocity_mps: Vector3::new(
            -0.47754838168370256,
            0.5404409122673559,
            -2.4831761837448574e-10,
        ),
        acceleration_mps2: Vector3::new(
            -0.0647703647350602,
            -0.0188075913463803,
            3.1347312264517336e-10,
        ),
        yaw_rate_radps: 0.09703883392548826,
    };
    assert_timed_within_limits(&waypoints, &start);
}
