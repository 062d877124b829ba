//! The fuzz target's logic on stable: thousands of seeded mutations of real PLY bytes go through
//! the readers, which must return `Ok` (with a valid mesh) or `Err`, and never panic.

mod common;

use std::panic::{AssertUnwindSafe, catch_unwind};

use common::*;
use scarp_export::ply::{
    PlyEncoding, read_mesh_from_reader, read_point_cloud_from_reader, write_mesh_to_writer,
};

/// Header words a mutation may substitute for another header word.
const HEADER_WORDS: &[&str] = &[
    "ply",
    "format",
    "ascii",
    "binary_little_endian",
    "binary_big_endian",
    "1.0",
    "2.5",
    "element",
    "vertex",
    "face",
    "edge",
    "property",
    "list",
    "char",
    "uchar",
    "short",
    "ushort",
    "int",
    "uint",
    "float",
    "double",
    "x",
    "nx",
    "red",
    "vertex_indices",
    "vertex_index",
    "0",
    "1",
    "3",
    "255",
    "20139",
    "40277",
    "4294967295",
    "18446744073709551615",
    "99999999999999999999999",
    "-1",
    "end_header",
    "comment",
    "",
];

fn header_len(bytes: &[u8]) -> usize {
    bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .map_or(bytes.len(), |p| p + 11)
}

/// One random mutation of `input`.
fn mutate(input: &[u8], rng: &mut SplitMix) -> Vec<u8> {
    let mut bytes = input.to_vec();
    let header = header_len(&bytes);
    match rng.below(7) {
        // Flip 1–8 bits anywhere.
        0 => {
            for _ in 0..1 + rng.below(8) {
                let i = rng.below(bytes.len());
                bytes[i] ^= 1 << rng.below(8);
            }
        }
        // Flip bits in the header, where they matter most.
        1 => {
            for _ in 0..1 + rng.below(3) {
                let i = rng.below(header.max(1));
                bytes[i] ^= 1 << rng.below(8);
            }
        }
        // Truncate.
        2 => bytes.truncate(rng.below(bytes.len() + 1)),
        // Replace one header word with another.
        3 => {
            let text = String::from_utf8_lossy(&bytes[..header]).into_owned();
            let mut words: Vec<String> = text.split(' ').map(str::to_owned).collect();
            let i = rng.below(words.len());
            let keep_newline = words[i].ends_with('\n');
            words[i] = HEADER_WORDS[rng.below(HEADER_WORDS.len())].to_owned();
            if keep_newline {
                words[i].push('\n');
            }
            let mut out = words.join(" ").into_bytes();
            out.extend_from_slice(&bytes[header..]);
            bytes = out;
        }
        // Overwrite a 4-byte word of the payload with an extreme value.
        4 => {
            if bytes.len() > header + 4 {
                let i = header + rng.below(bytes.len() - header - 4);
                let v: [u8; 4] = match rng.below(5) {
                    0 => f32::NAN.to_le_bytes(),
                    1 => f32::INFINITY.to_le_bytes(),
                    2 => u32::MAX.to_le_bytes(),
                    3 => (-1i32).to_le_bytes(),
                    _ => (rng.next_u64() as u32).to_le_bytes(),
                };
                bytes[i..i + 4].copy_from_slice(&v);
            }
        }
        // Delete or duplicate a chunk.
        5 => {
            let start = rng.below(bytes.len());
            let len = 1 + rng.below(64.min(bytes.len() - start));
            if rng.below(2) == 0 {
                bytes.drain(start..start + len);
            } else {
                let chunk = bytes[start..start + len].to_vec();
                bytes.splice(start..start, chunk);
            }
        }
        // Random bytes appended or a random byte anywhere.
        _ => {
            if rng.below(2) == 0 {
                for _ in 0..1 + rng.below(16) {
                    bytes.push(rng.next_u64() as u8);
                }
            } else {
                let i = rng.below(bytes.len());
                bytes[i] = rng.next_u64() as u8;
            }
        }
    }
    bytes
}

/// Runs both readers on `bytes`; an `Ok` mesh must be valid.
fn check(bytes: &[u8], what: &str) {
    let result = catch_unwind(AssertUnwindSafe(|| {
        if let Ok(mesh) = read_mesh_from_reader(bytes, "fuzz.ply") {
            mesh.validate()
                .unwrap_or_else(|e| panic!("{what}: reader returned an invalid mesh: {e}"));
            assert!(mesh.normals.iter().all(|n| n.iter().all(|c| c.is_finite())));
        }
        let _ = read_point_cloud_from_reader(bytes, "fuzz.ply");
    }));
    if let Err(panic) = result {
        let message = panic
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_owned()))
            .unwrap_or_default();
        panic!("{what}: the reader panicked: {message}");
    }
}

fn run(seeds: std::ops::Range<u64>, input: &[u8], name: &str) -> (usize, usize) {
    let (mut ok, mut err) = (0, 0);
    for seed in seeds {
        let mut rng = SplitMix(seed);
        let mut bytes = mutate(input, &mut rng);
        // Stack a second mutation now and then.
        if rng.below(4) == 0 {
            bytes = mutate(&bytes, &mut rng);
        }
        check(&bytes, &format!("{name}, seed {seed}"));
        match read_mesh_from_reader(&bytes[..], "fuzz.ply") {
            Ok(_) => ok += 1,
            Err(_) => err += 1,
        }
    }
    (ok, err)
}

#[test]
fn mutated_double_rock_never_panics() {
    let (ok, err) = run(0..2500, &double_rock_bytes(), "double rock");
    // Most mutations must be caught; a few (a flipped mantissa bit) are still valid files.
    assert!(err > ok, "ok {ok}, err {err}");
}

#[test]
fn mutated_ascii_and_big_endian_files_never_panic() {
    let mesh = coloured_box();
    for (k, encoding) in [PlyEncoding::Ascii, PlyEncoding::BinaryBigEndian]
        .into_iter()
        .enumerate()
    {
        let mut bytes = Vec::new();
        write_mesh_to_writer(&mut bytes, &mesh, encoding).unwrap();
        let base = 1_000_000 * (k as u64 + 1);
        run(base..base + 1500, &bytes, &format!("{encoding} box"));
    }
}
