//! `camera.toml` through seeded mutations (the stable twin of the `camera_file` fuzz target):
//! values swapped for hostile ones, lines dropped, repeated or cut short. The parser must answer
//! `Ok` or `Err`, never panic, and an accepted file must give usable cameras.

use std::path::Path;

use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use scarp_datasets::sequence::CameraFile;

const KINECT_V1: &str = include_str!("../../fuzz/seeds/camera_file/kinect_v1.toml");

const HOSTILE_VALUES: [&str; 12] = [
    "nan",
    "inf",
    "-inf",
    "-1.0",
    "0",
    "0.0",
    "1e308",
    "-0.0",
    "\"585\"",
    "[]",
    "true",
    "4294967296",
];

fn mutate(rng: &mut Xoshiro256PlusPlus) -> String {
    let mut lines: Vec<String> = KINECT_V1.lines().map(str::to_owned).collect();
    for _ in 0..rng.random_range(1..4) {
        let i = rng.random_range(0..lines.len());
        match rng.random_range(0..4) {
            0 => {
                if let Some((key, _)) = lines[i].split_once('=') {
                    let value = HOSTILE_VALUES[rng.random_range(0..HOSTILE_VALUES.len())];
                    lines[i] = format!("{key}= {value}");
                }
            }
            1 => {
                lines.remove(i);
            }
            2 => {
                let copy = lines[i].clone();
                lines.insert(i, copy);
            }
            _ => {
                let cut = rng.random_range(0..=lines[i].len());
                lines[i].truncate(cut);
            }
        }
        if lines.is_empty() {
            break;
        }
    }
    lines.join("\n")
}

#[test]
fn mutated_camera_files_are_refused_or_usable() {
    let path = Path::new("camera.toml");
    assert!(
        CameraFile::parse(KINECT_V1, path).is_ok(),
        "the seed itself"
    );
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(16);
    let (mut accepted, mut refused) = (0, 0);
    for _ in 0..5000 {
        let text = mutate(&mut rng);
        match CameraFile::parse(&text, path) {
            Ok(file) => {
                accepted += 1;
                assert!(file.camera().is_ok(), "{text}");
                assert!(
                    file.depth_scale > 0.0 && file.depth_scale.is_finite(),
                    "{text}"
                );
                assert!(file.color_camera().is_ok(), "{text}");
                if let Some(color) = file.color {
                    let pose = color.color_from_depth();
                    assert!(
                        pose.translation.vector.iter().all(|v| v.is_finite()),
                        "{text}"
                    );
                    assert!(pose.rotation.coords.iter().all(|v| v.is_finite()), "{text}");
                }
            }
            Err(error) => {
                refused += 1;
                assert!(error.to_string().contains("camera.toml"), "{error}");
            }
        }
    }
    // Both kinds of outcome occur, so the mutations neither always break nor never touch the file.
    assert!(
        accepted > 100 && refused > 100,
        "{accepted} accepted, {refused} refused"
    );
}
