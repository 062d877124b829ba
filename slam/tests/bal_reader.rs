//! The BAL reader: round trips, clear errors for malformed files, and seeded random mutations
//! (the stable counterpart of the `bal_reader` fuzz target) that must never panic.

use nalgebra::{Vector2, Vector3};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use scarp_slam::ba::bal::format_bal;
use scarp_slam::ba::{BaError, BalProblem, Observation, SnavelyCamera, parse_bal, read_bal};

/// A small valid problem: 2 cameras, 3 points, 5 observations, one number a line after the
/// observations (as BAL files are written).
const SMALL: &str = "2 3 5
0 0 -10.5 3.25
0 1 4.0 -2.0
1 0 1e1 2E-1
1 1 0.5 0.5
1 2 -3 7
0.01
-0.02
0.03
0.1
0.2
-5.0
500
-0.01
0.001
-0.01
0.02
0.0
0.3
0.0
-5.5
480
0.0
0.0
0.1
0.2
0.3
-0.1
0.0
0.4
1.0
1.0
-1.0
";

fn parse(text: &str) -> Result<BalProblem, BaError> {
    parse_bal(text.as_bytes(), "test.txt")
}

/// The error's line and message; panics on success.
fn error_of(text: &str) -> (usize, String) {
    match parse(text) {
        Err(BaError::Parse { line, reason, .. }) => (line, reason),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn a_valid_file_parses() {
    let p = parse(SMALL).unwrap();
    assert_eq!(
        (p.cameras.len(), p.points.len(), p.observations.len()),
        (2, 3, 5)
    );
    assert_eq!(
        p.observations[2],
        Observation {
            camera: 1,
            point: 0,
            pixel: Vector2::new(10.0, 0.2)
        }
    );
    assert_eq!(p.cameras[1].focal_px, 480.0);
    assert_eq!(p.points[2], Vector3::new(1.0, 1.0, -1.0));
    let w = p.cameras[0].bal_parameters();
    assert!((w[2] - 0.03).abs() < 1e-15 && (w[5] + 5.0).abs() < 1e-15);
}

#[test]
fn format_and_parse_round_trip() {
    let p = parse(SMALL).unwrap();
    let q = parse(&format_bal(&p)).unwrap();
    assert_eq!(p.observations, q.observations);
    assert_eq!(p.points, q.points);
    for (a, b) in p.cameras.iter().zip(&q.cameras) {
        for (x, y) in a.bal_parameters().iter().zip(b.bal_parameters().iter()) {
            assert!((x - y).abs() < 1e-14);
        }
    }
}

#[test]
fn truncated_files_name_what_is_missing() {
    let lines: Vec<&str> = SMALL.lines().collect();
    // Cut after the observations, inside the cameras and inside the points.
    for keep in [0, 1, 3, 6, 14, 30] {
        let text = lines[..keep].join("\n");
        let (line, reason) = error_of(&text);
        assert!(
            reason.contains("truncated") || reason.contains("need more numbers"),
            "{reason}"
        );
        assert!(
            line >= 1 && line <= keep.max(1),
            "line {line} for {keep} lines"
        );
    }
    let text = lines[..lines.len() - 1].join("\n");
    let (_, reason) = error_of(&text);
    assert!(reason.contains("coordinate z of point 2"), "{reason}");
}

#[test]
fn negative_and_absurd_counts_are_rejected() {
    let (line, reason) = error_of(&SMALL.replacen("2 3 5", "2 -3 5", 1));
    assert_eq!(line, 1);
    assert!(reason.contains("point count is negative"), "{reason}");
    let (_, reason) = error_of(&SMALL.replacen("2 3 5", "2 3 99999999999999", 1));
    assert!(reason.contains("need more numbers"), "{reason}");
    let (_, reason) = error_of(&SMALL.replacen("2 3 5", "18446744073709551615 3 5", 1));
    assert!(
        reason.contains("integer") || reason.contains("need more"),
        "{reason}"
    );
    let (_, reason) = error_of(&SMALL.replacen("2 3 5", "2 x 5", 1));
    assert!(reason.contains("not an integer"), "{reason}");
}

#[test]
fn non_finite_and_non_numeric_values_name_the_line() {
    let (line, reason) = error_of(&SMALL.replacen("0 1 4.0 -2.0", "0 1 nan -2.0", 1));
    assert_eq!(line, 3);
    assert!(
        reason.contains("x of observation 1") && reason.contains("not finite"),
        "{reason}"
    );
    let (line, reason) = error_of(&SMALL.replacen("\n480\n", "\ninf\n", 1));
    assert_eq!(line, 22);
    assert!(reason.contains("focal length of camera 1"), "{reason}");
    let (line, reason) = error_of(&SMALL.replacen("\n0.4\n", "\n0.4abc\n", 1));
    assert_eq!(line, 30);
    assert!(
        reason.contains("point 1") && reason.contains("not a number"),
        "{reason}"
    );
}

#[test]
fn bad_indices_name_the_line() {
    let (line, reason) = error_of(&SMALL.replacen("1 2 -3 7", "2 2 -3 7", 1));
    assert_eq!(line, 6);
    assert!(
        reason.contains("camera index 2 of observation 4"),
        "{reason}"
    );
    let (line, reason) = error_of(&SMALL.replacen("1 2 -3 7", "1 -1 -3 7", 1));
    assert_eq!(line, 6);
    assert!(reason.contains("point index -1"), "{reason}");
    let (_, reason) = error_of(&SMALL.replacen("1 2 -3 7", "1 2.5 -3 7", 1));
    assert!(reason.contains("not an integer"), "{reason}");
}

#[test]
fn non_utf8_and_missing_files_are_errors() {
    let mut bytes = SMALL.as_bytes().to_vec();
    bytes[22] = 0xff; // inside line 3
    assert!(matches!(
        parse_bal(&bytes, "x"),
        Err(BaError::Parse { line: 3, .. })
    ));
    let err = read_bal("/nonexistent/problem.txt").unwrap_err();
    assert!(
        err.to_string().contains("/nonexistent/problem.txt"),
        "{err}"
    );
}

/// Seeded random mutations (byte flips, insertions, deletions, truncations, token swaps) of a
/// valid file: the reader returns `Ok` or `Err` and never panics; an `Ok` problem is consistent.
#[test]
fn random_mutations_never_panic() {
    let base = SMALL.as_bytes().to_vec();
    let alphabet = b"0123456789-+.eE nainf\n\t x";
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
    let mut accepted = 0;
    for _ in 0..20_000 {
        let mut bytes = base.clone();
        for _ in 0..rng.random_range(1..5) {
            let len = bytes.len();
            match rng.random_range(0..5) {
                0 if len > 0 => {
                    let i = rng.random_range(0..len);
                    bytes[i] = alphabet[rng.random_range(0..alphabet.len())];
                }
                1 => {
                    let i = rng.random_range(0..=len);
                    bytes.insert(i, alphabet[rng.random_range(0..alphabet.len())]);
                }
                2 if len > 0 => {
                    bytes.remove(rng.random_range(0..len));
                }
                3 => bytes.truncate(rng.random_range(0..=len)),
                _ if len > 0 => {
                    let i = rng.random_range(0..len);
                    bytes[i] = rng.random();
                }
                _ => {}
            }
        }
        if let Ok(p) = parse_bal(&bytes, "mutant.txt") {
            accepted += 1;
            for o in &p.observations {
                assert!(o.camera < p.cameras.len() && o.point < p.points.len());
                assert!(o.pixel.iter().all(|v| v.is_finite()));
            }
            assert!(p.points.iter().all(|x| x.iter().all(|v| v.is_finite())));
            let cameras_finite = p
                .cameras
                .iter()
                .all(|c: &SnavelyCamera| c.bal_parameters().iter().all(|v| v.is_finite()));
            assert!(cameras_finite);
        }
    }
    assert!(
        accepted > 0,
        "some mutations (digit changes) keep the file valid"
    );
}
