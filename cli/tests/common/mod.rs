//! Helpers shared by the end-to-end tests: run the `scarp` binary and read what it wrote.

// Each test binary compiles this module and uses a subset of it.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// The path of a file in `tests/data/`, as a command-line argument.
pub fn test_data(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data")
        .join(name)
        .display()
        .to_string()
}

/// Runs `scarp` with `args` and returns whatever happened.
pub fn scarp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_scarp"))
        .args(args)
        .output()
        .expect("the scarp binary runs")
}

/// Runs `scarp` and fails the test, showing the arguments and stderr, unless it succeeds.
pub fn scarp_ok(args: &[&str]) -> Output {
    let out = scarp(args);
    assert!(
        out.status.success(),
        "scarp {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// As [`scarp_ok`], returning stdout.
pub fn scarp_stdout(args: &[&str]) -> String {
    String::from_utf8(scarp_ok(args).stdout).expect("UTF-8 on stdout")
}

/// Reads a JSON file the binary wrote.
pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).expect("the file exists")).expect("valid JSON")
}

/// A temporary path as a command-line argument.
pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 temporary path")
}

/// Writes the default world into `dir/world` with `scarp world` and returns the centroid of its
/// first rock (the orbit's target), world ENU metres.
pub fn first_rock_centroid_m(dir: &Path) -> [f64; 3] {
    let out = dir.join("world");
    scarp_ok(&["world", "--out", path_str(&out)]);
    let world = read_json(&out.join("world.json"));
    let c = &world["rocks"][0]["centroid"];
    [0, 1, 2].map(|k| c[k].as_f64().expect("a numeric centroid"))
}
