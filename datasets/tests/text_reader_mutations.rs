//! The line-based readers of outside files through seeded mutations (the stable twins of the
//! `tum_trajectory`, `obj_reader`, `sequence_lists` and `esri_ascii` fuzz targets): tokens
//! swapped for hostile ones, lines dropped, repeated, swapped or cut short. Each parser must
//! answer `Ok` or `Err`, never panic, and what it accepts must be usable.

use std::path::Path;

use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use scarp_datasets::sequence::{parse_boxes, parse_image_list};
use scarp_datasets::terrain::{parse_esri_ascii, terrain_mesh};
use scarp_export::obj::parse_obj;
use scarp_export::tum::parse_tum_trajectory;
use scarp_slam::geometry::check_finite_isometry;

const TUM: &str = include_str!("../../fuzz/seeds/tum_trajectory/groundtruth.txt");
const OBJ: &str = include_str!("../../fuzz/seeds/obj_reader/quad.obj");
const IMAGE_LIST: &str = include_str!("../../fuzz/seeds/sequence_lists/rgb.txt");
const BOXES: &str = include_str!("../../fuzz/seeds/sequence_lists/boxes.txt");
const ESRI: &str = include_str!("../../fuzz/seeds/esri_ascii/grid.asc");

/// Tokens a mutation puts in place of another: non-finite, beyond f32's or an integer's range,
/// negative, empty, or of another kind.
const HOSTILE_TOKENS: [&str; 18] = [
    "nan",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "3.5e38",
    "1e39",
    "0",
    "-0",
    "-1",
    "4294967296",
    "18446744073709551616",
    "",
    "#",
    "1/2/3",
    "1e-320",
    "target",
    "x",
];

/// `seed` with one to three random edits.
fn mutate(seed: &str, rng: &mut Xoshiro256PlusPlus) -> String {
    let mut lines: Vec<String> = seed.lines().map(str::to_owned).collect();
    for _ in 0..rng.random_range(1..4) {
        if lines.is_empty() {
            break;
        }
        let i = rng.random_range(0..lines.len());
        match rng.random_range(0..5) {
            0 => {
                let mut words: Vec<&str> = lines[i].split_whitespace().collect();
                if !words.is_empty() {
                    let k = rng.random_range(0..words.len());
                    words[k] = HOSTILE_TOKENS[rng.random_range(0..HOSTILE_TOKENS.len())];
                    lines[i] = words.join(" ");
                }
            }
            1 => {
                lines.remove(i);
            }
            2 => {
                let copy = lines[i].clone();
                lines.insert(i, copy);
            }
            3 => {
                let cut = rng.random_range(0..=lines[i].len());
                lines[i].truncate(cut);
            }
            _ => {
                let j = rng.random_range(0..lines.len());
                lines.swap(i, j);
            }
        }
    }
    lines.join("\n")
}

/// Runs `check` on 3000 mutations of `seed` (and on the seed itself, which must be accepted);
/// `check` says whether the text was accepted, asserting what an accepted one must hold.
/// Both outcomes must occur often, so that the mutations neither always break the file nor
/// never touch what the parser checks.
fn mutations_are_refused_or_usable(
    name: &str,
    seed: &str,
    rng_seed: u64,
    check: impl Fn(&str) -> bool,
) {
    assert!(check(seed), "{name}: the seed itself is refused");
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(rng_seed);
    let (mut accepted, mut refused) = (0, 0);
    for _ in 0..3000 {
        let text = mutate(seed, &mut rng);
        if check(&text) {
            accepted += 1;
        } else {
            refused += 1;
        }
    }
    assert!(
        accepted > 100 && refused > 100,
        "{name}: {accepted} accepted, {refused} refused"
    );
}

/// A refusal of the parsers that answer `(line, message)`: it names a line and says why.
fn refused_at_a_line(line: usize, message: &str, text: &str) -> bool {
    assert!(line >= 1 && !message.is_empty(), "{text}");
    false
}

/// A refusal of the sequence readers: its message names the file and the line (`file:line`).
fn refused_naming_the_file(error: &scarp_datasets::DatasetError, file: &str) -> bool {
    assert!(error.to_string().contains(&format!("{file}:")), "{error}");
    false
}

#[test]
fn mutated_tum_trajectories_are_refused_or_usable() {
    mutations_are_refused_or_usable("TUM", TUM, 21, |text| match parse_tum_trajectory(text) {
        Ok(poses) => {
            for pose in &poses {
                assert!(pose.timestamp_s.is_finite(), "{text}");
                assert!(
                    check_finite_isometry(&pose.world_from_camera, "pose").is_ok(),
                    "{text}"
                );
                let norm = pose.world_from_camera.rotation.quaternion().norm();
                assert!((norm - 1.0).abs() < 1e-9, "norm {norm}: {text}");
            }
            assert!(
                poses
                    .windows(2)
                    .all(|w| w[0].timestamp_s < w[1].timestamp_s),
                "{text}"
            );
            true
        }
        Err((line, message)) => refused_at_a_line(line, &message, text),
    });
}

#[test]
fn mutated_obj_files_are_refused_or_usable() {
    mutations_are_refused_or_usable("OBJ", OBJ, 22, |text| match parse_obj(text) {
        Ok(mesh) => {
            assert!(!mesh.faces.is_empty(), "{text}");
            assert!(mesh.validate().is_ok(), "{text}");
            true
        }
        Err((line, message)) => refused_at_a_line(line, &message, text),
    });
}

#[test]
fn mutated_image_lists_are_refused_or_usable() {
    let path = Path::new("rgb.txt");
    mutations_are_refused_or_usable("rgb.txt", IMAGE_LIST, 23, |text| {
        match parse_image_list(text, path) {
            Ok(entries) => {
                assert!(
                    entries
                        .iter()
                        .all(|(t, file)| t.is_finite() && !file.is_empty()),
                    "{text}"
                );
                assert!(entries.windows(2).all(|w| w[0].0 < w[1].0), "{text}");
                true
            }
            Err(error) => refused_naming_the_file(&error, "rgb.txt"),
        }
    });
}

#[test]
fn mutated_box_lists_are_refused_or_usable() {
    let path = Path::new("boxes.txt");
    mutations_are_refused_or_usable("boxes.txt", BOXES, 24, |text| {
        match parse_boxes(text, path) {
            Ok(boxes) => {
                for b in &boxes {
                    let [x0, y0, x1, y1] = b.bbox_px;
                    assert!(b.timestamp_s.is_finite() && x0 <= x1 && y0 <= y1, "{text}");
                }
                true
            }
            Err(error) => refused_naming_the_file(&error, "boxes.txt"),
        }
    });
}

#[test]
fn mutated_esri_grids_are_refused_or_usable() {
    mutations_are_refused_or_usable("ESRI", ESRI, 25, |text| match parse_esri_ascii(text) {
        Ok(heightfield) => {
            assert!(heightfield.validate().is_ok(), "{text}");
            assert!(terrain_mesh(&heightfield).validate().is_ok(), "{text}");
            true
        }
        Err((line, message)) => refused_at_a_line(line, &message, text),
    });
}

/// Values the parsers once let through as silent garbage: each now names its line.
#[test]
fn values_that_would_turn_infinite_are_refused() {
    // An f64 beyond f32's range became an infinite vertex.
    let obj = "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    assert_eq!(parse_obj(obj).unwrap_err().0, 1);
    // A NaN timestamp was a box of no frame.
    let error = parse_boxes("nan 1 target 1 2 3 4\n", Path::new("boxes.txt")).unwrap_err();
    assert!(error.to_string().contains("boxes.txt:1"), "{error}");
    // A height or a grid beyond f32's range became an infinite terrain vertex.
    let grid = |cellsize: &str, corner: &str| {
        format!(
            "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize {cellsize}\n1 2\n3 {corner}\n"
        )
    };
    assert!(parse_esri_ascii(&grid("1", "4")).is_ok());
    assert_eq!(parse_esri_ascii(&grid("1", "1e39")).unwrap_err().0, 7);
    assert_eq!(parse_esri_ascii(&grid("1e300", "4")).unwrap_err().0, 1);
    // A quaternion whose squared norm overflows gave a zero "unit" quaternion.
    let tum = parse_tum_trajectory("0 0 0 0 0 0 1e300 1e300\n").unwrap();
    let norm = tum[0].world_from_camera.rotation.quaternion().norm();
    assert!((norm - 1.0).abs() < 1e-12, "{norm}");
}
