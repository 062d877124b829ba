//! PLY read/write: the real rock, exact round trips, and every kind of bad file.

mod common;

use common::*;
use nalgebra::{Point3, Vector3};
use proptest::prelude::*;
use scarp_export::ply::{
    PlyEncoding, PlyError, read_mesh, read_mesh_from_reader, read_point_cloud,
    read_point_cloud_from_reader, write_mesh, write_mesh_to_writer, write_point_cloud,
    write_point_cloud_to_writer,
};
use scarp_slam::{PointCloud, TriangleMesh};

const ENCODINGS: [PlyEncoding; 3] = [
    PlyEncoding::Ascii,
    PlyEncoding::BinaryLittleEndian,
    PlyEncoding::BinaryBigEndian,
];

fn to_bytes(mesh: &TriangleMesh, encoding: PlyEncoding) -> Vec<u8> {
    let mut out = Vec::new();
    write_mesh_to_writer(&mut out, mesh, encoding).unwrap();
    out
}

fn read_bytes(bytes: &[u8]) -> Result<TriangleMesh, PlyError> {
    read_mesh_from_reader(bytes, "test.ply")
}

fn assert_bit_exact(a: &TriangleMesh, b: &TriangleMesh) {
    assert_eq!(bits(&a.positions), bits(&b.positions));
    assert_eq!(normal_bits(&a.normals), normal_bits(&b.normals));
    assert_eq!(a.colors, b.colors);
    assert_eq!(a.faces, b.faces);
}

/// An ASCII PLY from header lines and data lines.
fn ascii(header: &[&str], data: &[&str]) -> Vec<u8> {
    let mut s = String::from("ply\nformat ascii 1.0\n");
    for h in header {
        s.push_str(h);
        s.push('\n');
    }
    s.push_str("end_header\n");
    for d in data {
        s.push_str(d);
        s.push('\n');
    }
    s.into_bytes()
}

const TETRA_HEADER: &[&str] = &[
    "element vertex 4",
    "property float x",
    "property float y",
    "property float z",
    "element face 1",
    "property list uchar int vertex_indices",
];
const TETRA_VERTICES: &[&str] = &["0 0 0", "1 0 0", "0 1 0", "0 0 1"];

fn err_string(bytes: &[u8]) -> String {
    match read_bytes(bytes) {
        Ok(m) => panic!("expected an error, read {} vertices", m.vertex_count()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn reads_the_double_rock() {
    let mesh = read_mesh(double_rock_path()).unwrap();
    assert_eq!(mesh.vertex_count(), DOUBLE_ROCK_VERTICES);
    assert_eq!(mesh.face_count(), DOUBLE_ROCK_FACES);
    assert!(mesh.normals.is_empty() && mesh.colors.is_empty());
    mesh.validate().unwrap();
    let (lo, hi) = mesh.bounds().unwrap();
    let extent = hi - lo;
    for (got, want) in extent.iter().zip([0.1051, 0.0639, 0.1280]) {
        assert!((f64::from(*got) - want).abs() < 5e-4, "extent {extent:?}");
    }
    // Watertight, outward winding: positive volume close to the README's 3.378e-4 m³.
    let volume = mesh.volume_properties().unwrap().volume_m3;
    assert!((volume - 3.378e-4).abs() < 2e-6, "volume {volume}");

    let cloud = read_point_cloud(double_rock_path()).unwrap();
    assert_eq!(cloud.positions, mesh.positions);
}

#[test]
fn double_rock_round_trips_bit_exact_in_every_encoding() {
    let mesh = read_mesh(double_rock_path()).unwrap();
    for encoding in ENCODINGS {
        let back = read_bytes(&to_bytes(&mesh, encoding)).unwrap();
        assert_bit_exact(&mesh, &back);
    }
    // Binary little-endian re-encodes to the same payload layout as the original file.
    let original = double_rock_bytes();
    let ours = to_bytes(&mesh, PlyEncoding::BinaryLittleEndian);
    let payload = |b: &[u8]| {
        let end = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        b[end..].to_vec()
    };
    assert_eq!(payload(&original), payload(&ours));
}

#[test]
fn round_trips_with_normals_and_colours_through_files() {
    let dir = tempfile::tempdir().unwrap();
    let full = coloured_box();
    let mut no_colour = full.clone();
    no_colour.colors.clear();
    let mut no_normal = full.clone();
    no_normal.normals.clear();
    let empty = TriangleMesh::default();
    for (k, mesh) in [full, no_colour, no_normal, empty].iter().enumerate() {
        for encoding in ENCODINGS {
            let path = dir.path().join(format!("m{k}-{encoding}.ply"));
            write_mesh(&path, mesh, encoding).unwrap();
            let back = read_mesh(&path).unwrap();
            assert_bit_exact(mesh, &back);
        }
    }
    // Only the outputs are left: no temporary files.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn point_clouds_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = coloured_box();
    let cloud = PointCloud {
        positions: mesh.positions.clone(),
        normals: mesh.normals.clone(),
        colors: mesh.colors.clone(),
    };
    let bare = PointCloud::from_positions(vec![Point3::new(1.5e-7, -3.25e4, f32::MAX)]);
    for (k, c) in [cloud, bare, PointCloud::default()].iter().enumerate() {
        for encoding in ENCODINGS {
            let path = dir.path().join(format!("c{k}-{encoding}.ply"));
            write_point_cloud(&path, c, encoding).unwrap();
            let back = read_point_cloud(&path).unwrap();
            assert_eq!(bits(&back.positions), bits(&c.positions));
            assert_eq!(normal_bits(&back.normals), normal_bits(&c.normals));
            assert_eq!(back.colors, c.colors);
            // A cloud file also reads as a mesh without faces.
            let as_mesh = read_mesh(&path).unwrap();
            assert!(as_mesh.faces.is_empty());
            assert_eq!(as_mesh.positions.len(), c.positions.len());

            let mut buffer = Vec::new();
            write_point_cloud_to_writer(&mut buffer, c, encoding).unwrap();
            assert_eq!(buffer, std::fs::read(&path).unwrap());
        }
    }
}

fn arb_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        // Every finite bit pattern: subnormals, ±0, extremes.
        any::<u32>()
            .prop_map(f32::from_bits)
            .prop_filter("finite", |v| v.is_finite()),
        -1000.0f32..1000.0,
    ]
}

fn arb_mesh() -> impl Strategy<Value = TriangleMesh> {
    (1usize..40, any::<bool>(), any::<bool>()).prop_flat_map(|(n, with_normals, with_colors)| {
        let n_vec = if with_normals { n } else { 0 };
        let n_col = if with_colors { n } else { 0 };
        (
            proptest::collection::vec((arb_f32(), arb_f32(), arb_f32()), n),
            proptest::collection::vec((arb_f32(), arb_f32(), arb_f32()), n_vec),
            proptest::collection::vec(any::<[u8; 3]>(), n_col),
            proptest::collection::vec(
                (0..n as u32, 0..n as u32, 0..n as u32).prop_map(|(a, b, c)| [a, b, c]),
                0..60,
            ),
        )
            .prop_map(|(p, nrm, colors, faces)| TriangleMesh {
                positions: p
                    .into_iter()
                    .map(|(x, y, z)| Point3::new(x, y, z))
                    .collect(),
                normals: nrm
                    .into_iter()
                    .map(|(x, y, z)| Vector3::new(x, y, z))
                    .collect(),
                colors,
                faces,
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn random_meshes_round_trip_exactly(mesh in arb_mesh()) {
        for encoding in ENCODINGS {
            let back = read_bytes(&to_bytes(&mesh, encoding)).unwrap();
            prop_assert_eq!(bits(&mesh.positions), bits(&back.positions));
            prop_assert_eq!(normal_bits(&mesh.normals), normal_bits(&back.normals));
            prop_assert_eq!(&mesh.colors, &back.colors);
            prop_assert_eq!(&mesh.faces, &back.faces);
        }
    }

    #[test]
    fn random_clouds_round_trip_exactly(mesh in arb_mesh()) {
        let cloud = PointCloud { positions: mesh.positions, normals: mesh.normals, colors: mesh.colors };
        for encoding in ENCODINGS {
            let mut bytes = Vec::new();
            write_point_cloud_to_writer(&mut bytes, &cloud, encoding).unwrap();
            let back = read_point_cloud_from_reader(&bytes[..], "cloud.ply").unwrap();
            prop_assert_eq!(bits(&cloud.positions), bits(&back.positions));
            prop_assert_eq!(normal_bits(&cloud.normals), normal_bits(&back.normals));
            prop_assert_eq!(&cloud.colors, &back.colors);
        }
    }
}

/// Cuts a file at `cut` bytes; the read must fail (never panic, never a shorter mesh).
fn assert_cut_fails(bytes: &[u8], cut: usize) -> PlyError {
    match read_bytes(&bytes[..cut]) {
        Ok(m) => panic!(
            "a file cut at {cut} of {} bytes read as {} vertices, {} faces",
            bytes.len(),
            m.vertex_count(),
            m.face_count()
        ),
        Err(e) => e,
    }
}

#[test]
fn truncated_binary_double_rock_is_always_an_error() {
    let bytes = double_rock_bytes();
    let header_len = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let mut cuts: Vec<usize> = (0..header_len + 16).collect();
    cuts.extend((header_len..bytes.len()).step_by(487));
    cuts.extend(bytes.len() - 64..bytes.len());
    for &cut in &cuts {
        let err = assert_cut_fails(&bytes, cut);
        if cut > header_len {
            assert!(
                matches!(err, PlyError::Truncated { .. }),
                "cut at {cut}: {err}"
            );
        }
    }
    // The message says what was expected and how much was there.
    let vertex_bytes = DOUBLE_ROCK_VERTICES * 12;
    let face_bytes = 13;
    let cut = header_len + vertex_bytes + 1200 * face_bytes + 5;
    let msg = assert_cut_fails(&bytes, cut).to_string();
    assert_eq!(msg, "test.ply: truncated: expected 40276 faces, read 1200");
    let msg = assert_cut_fails(&bytes, header_len + 12 * 7 + 3).to_string();
    assert_eq!(msg, "test.ply: truncated: expected 20140 vertices, read 7");
}

#[test]
fn truncated_ascii_is_always_an_error() {
    let mut mesh = coloured_box();
    mesh.positions[7] = Point3::new(0.123_456_79, -9876.543, 1.0e-3);
    let bytes = to_bytes(&mesh, PlyEncoding::Ascii);
    let header_len = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    for cut in 0..bytes.len() {
        let err = assert_cut_fails(&bytes, cut);
        if cut > header_len {
            assert!(
                matches!(err, PlyError::Truncated { .. }),
                "cut at {cut}: {err}"
            );
        }
    }
    // Cut inside the last number of the last line: still an error, not a different face.
    let msg = assert_cut_fails(&bytes, bytes.len() - 2).to_string();
    assert!(
        msg.contains("truncated: expected 12 faces, read 11"),
        "{msg}"
    );
}

#[test]
fn counts_larger_than_the_data_are_truncation() {
    let text = String::from_utf8(double_rock_bytes()[..400].to_vec()).unwrap_or_default();
    assert!(text.is_empty() || text.contains("element face 40276"));
    let mut bytes = double_rock_bytes();
    let at = bytes
        .windows(16)
        .position(|w| w == b"element face 402")
        .unwrap();
    bytes[at + 13..at + 18].copy_from_slice(b"50276");
    let msg = err_string(&bytes);
    assert!(
        msg.contains("truncated: expected 50276 faces, read 40276"),
        "{msg}"
    );
    // A huge count must not allocate up front or hang.
    let huge = ascii(
        &[
            "element vertex 18446744073709551615",
            "property float x",
            "property float y",
            "property float z",
        ],
        &["0 0 0"],
    );
    assert!(matches!(read_bytes(&huge), Err(PlyError::Layout { .. })));
    let many = ascii(
        &[
            "element vertex 4000000000",
            "property float x",
            "property float y",
            "property float z",
        ],
        &["0 0 0"],
    );
    assert!(matches!(
        read_bytes(&many),
        Err(PlyError::Truncated { read: 1, .. })
    ));
}

#[test]
fn smaller_counts_leave_trailing_data_or_bad_indices() {
    let mut bytes = double_rock_bytes();
    let at = bytes
        .windows(16)
        .position(|w| w == b"element face 402")
        .unwrap();
    bytes[at + 13..at + 18].copy_from_slice(b"30276");
    let msg = err_string(&bytes);
    assert!(
        msg.contains("unexpected data after the last element"),
        "{msg}"
    );

    let mut bytes = double_rock_bytes();
    let at = bytes
        .windows(20)
        .position(|w| w == b"element vertex 20140")
        .unwrap();
    bytes[at + 15..at + 20].copy_from_slice(b"20139");
    // One vertex fewer: the payload is misaligned by 12 bytes, which must not pass.
    assert!(read_bytes(&bytes).is_err());
}

#[test]
fn out_of_range_and_negative_indices_are_named() {
    let bytes = ascii(TETRA_HEADER, &[TETRA_VERTICES, &["3 0 1 7"]].concat());
    assert_eq!(
        err_string(&bytes),
        "test.ply: face 0 refers to vertex 7 but the file has 4 vertices"
    );
    let bytes = ascii(TETRA_HEADER, &[TETRA_VERTICES, &["3 0 -1 2"]].concat());
    assert_eq!(
        err_string(&bytes),
        "test.ply: face 0 refers to vertex -1 but the file has 4 vertices"
    );
    let bytes = ascii(TETRA_HEADER, &[TETRA_VERTICES, &["2 0 1"]].concat());
    assert!(err_string(&bytes).contains("face 0 has 2 corners"));
    // In a real file, with the path in the message.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rocks-a.ply");
    let mut header = TETRA_HEADER.to_vec();
    header[4] = "element face 2";
    std::fs::write(
        &path,
        ascii(
            &header,
            &[TETRA_VERTICES, &["3 0 1 2", "3 1 2 900"]].concat(),
        ),
    )
    .unwrap();
    let msg = read_mesh(&path).unwrap_err().to_string();
    assert_eq!(
        msg,
        format!(
            "{}: face 1 refers to vertex 900 but the file has 4 vertices",
            path.display()
        )
    );
    // Point clouds do not care about faces.
    assert_eq!(read_point_cloud(&path).unwrap().len(), 4);
}

#[test]
fn non_finite_coordinates_are_rejected() {
    let mut mesh = coloured_box();
    for encoding in [
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
    ] {
        let mut bytes = to_bytes(&mesh, encoding);
        // Vertex 3's y is at header + 3 * (12 + 12 + 3) + 4.
        let header_len = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        let at = header_len + 3 * 27 + 4;
        let nan = match encoding {
            PlyEncoding::BinaryBigEndian => f32::NAN.to_be_bytes(),
            _ => f32::NAN.to_le_bytes(),
        };
        bytes[at..at + 4].copy_from_slice(&nan);
        let err = read_bytes(&bytes).unwrap_err();
        assert!(
            matches!(
                err,
                PlyError::NotFinite {
                    vertex: 3,
                    attribute: "position",
                    ..
                }
            ),
            "{err}"
        );
        // A NaN normal (vertex 5's nz) too.
        let mut bytes = to_bytes(&mesh, encoding);
        let at = header_len + 5 * 27 + 20;
        bytes[at..at + 4].copy_from_slice(&nan);
        let err = read_bytes(&bytes).unwrap_err();
        assert!(
            matches!(
                err,
                PlyError::NotFinite {
                    vertex: 5,
                    attribute: "normal",
                    ..
                }
            ),
            "{err}"
        );
    }
    // ASCII: "nan" and "inf" are not numbers; a double too large for f32 is not finite.
    for bad in ["nan 0 0", "0 inf 0", "0 0 NaN"] {
        let bytes = ascii(
            TETRA_HEADER,
            &[&[bad], &TETRA_VERTICES[1..], &["3 0 1 2"]].concat(),
        );
        assert!(matches!(
            read_bytes(&bytes),
            Err(PlyError::Malformed { index: 0, .. })
        ));
    }
    let header: Vec<&str> = TETRA_HEADER
        .iter()
        .map(|h| {
            if h.starts_with("property float") {
                h.replace("float", "double").leak() as &str
            } else {
                h
            }
        })
        .collect();
    let bytes = ascii(
        &header,
        &[&["0 1e300 0"], &TETRA_VERTICES[1..], &["3 0 1 2"]].concat(),
    );
    assert!(err_string(&bytes).contains("vertex 0 has a non-finite position (1e300)"));

    // The writer refuses them too, and leaves no file behind.
    mesh.positions[2].x = f32::INFINITY;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.ply");
    let err = write_mesh(&path, &mesh, PlyEncoding::Ascii).unwrap_err();
    assert!(matches!(err, PlyError::InvalidMesh { .. }), "{err}");
    assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
}

#[test]
fn corrupt_headers_are_rejected_with_reasons() {
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"".to_vec(), "bad header"),
        (
            b"plx\nformat ascii 1.0\nend_header\n".to_vec(),
            "bad header",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n".to_vec(),
            "missing 'end_header'",
        ),
        (
            b"ply\nformat weird 1.0\nend_header\n".to_vec(),
            "bad header",
        ),
        (b"ply\nend_header\n".to_vec(), "No format line"),
        (
            b"ply\nformat ascii 1.0\nproperty float x\nend_header\n".to_vec(),
            "without preceding element",
        ),
        (ascii(&[], &[]), "no 'vertex' element"),
        (
            ascii(
                &["element vertex 1", "property float x", "property float y"],
                &["0 0"],
            ),
            "no 'z' property",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property list uchar float x",
                    "property float y",
                    "property float z",
                ],
                &["1 0 0 0"],
            ),
            "'x' is a list",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "property float nx",
                ],
                &["0 0 0 1"],
            ),
            "only 1 of the 3 normal",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "property uchar red",
                    "property uchar diffuse_red",
                ],
                &["0 0 0 1 1"],
            ),
            "both 'red' and 'diffuse_red'",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "property short red",
                    "property short green",
                    "property short blue",
                ],
                &["0 0 0 1 1 1"],
            ),
            "has type short",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "property uchar red",
                    "property uchar green",
                    "property float blue",
                ],
                &["0 0 0 1 1 1"],
            ),
            "different types",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "element face 1",
                    "property list uchar float vertex_indices",
                ],
                &["0 0 0", "3 0 0 0"],
            ),
            "both must be integers",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "element face 1",
                    "property int vertex_indices",
                ],
                &["0 0 0", "0"],
            ),
            "expected a list",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "element face 1",
                    "property uchar flags",
                ],
                &["0 0 0", "0"],
            ),
            "no 'vertex_indices'",
        ),
        (
            ascii(
                &[
                    "element vertex 1",
                    "property float x",
                    "property float y",
                    "property float z",
                    "element face 1",
                    "property list uchar int vertex_indices",
                    "property list uchar int vertex_index",
                ],
                &["0 0 0", "3 0 0 0 3 0 0 0"],
            ),
            "both 'vertex_indices' and 'vertex_index'",
        ),
        (
            ascii(
                &[
                    "element junk 5",
                    "element vertex 0",
                    "property float x",
                    "property float y",
                    "property float z",
                ],
                &[],
            ),
            "no properties",
        ),
    ];
    for (bytes, expected) in cases {
        let msg = err_string(&bytes);
        assert!(msg.starts_with("test.ply: "), "{msg}");
        assert!(msg.contains(expected), "expected '{expected}' in: {msg}");
    }
}

#[test]
fn malformed_payloads_are_rejected() {
    // Extra values on a line, letters, data after the last element.
    let bytes = ascii(
        TETRA_HEADER,
        &["0 0 0", "1 0 0 5", "0 1 0", "0 0 1", "3 0 1 2"],
    );
    let msg = err_string(&bytes);
    assert!(
        msg.contains("vertex 1 (line 11): 1 more values than the header declares"),
        "{msg}"
    );
    let bytes = ascii(
        TETRA_HEADER,
        &["0 0 0", "1 zero 0", "0 1 0", "0 0 1", "3 0 1 2"],
    );
    assert!(err_string(&bytes).contains("vertex 1 (line 11)"));
    let bytes = ascii(
        TETRA_HEADER,
        &[TETRA_VERTICES, &["3 0 1 2", "3 0 1 2"]].concat(),
    );
    assert!(err_string(&bytes).contains("unexpected data after the last element"));
    let mut bytes = to_bytes(&coloured_box(), PlyEncoding::BinaryLittleEndian);
    bytes.extend_from_slice(b"\x01\x02");
    assert!(matches!(
        read_bytes(&bytes),
        Err(PlyError::TrailingData { bytes: 2, .. })
    ));
    // Whitespace after the data is fine.
    let mut bytes = ascii(TETRA_HEADER, &[TETRA_VERTICES, &["3 0 1 2"]].concat());
    bytes.extend_from_slice(b"\n\n  \n");
    assert_eq!(read_bytes(&bytes).unwrap().face_count(), 1);
    // Invalid UTF-8 in an ASCII payload.
    let mut bytes = ascii(TETRA_HEADER, &[]);
    bytes.extend_from_slice(b"0 0 \xff\n");
    assert!(matches!(
        read_bytes(&bytes),
        Err(PlyError::Malformed { .. })
    ));
}

#[test]
fn missing_file_names_the_path() {
    let err = read_mesh("/nonexistent/rocks/a.ply").unwrap_err();
    assert!(matches!(err, PlyError::Open { .. }));
    assert!(
        err.to_string()
            .starts_with("/nonexistent/rocks/a.ply: cannot open"),
        "{err}"
    );
    let err = read_point_cloud("/nonexistent/b.ply").unwrap_err();
    assert!(err.to_string().contains("/nonexistent/b.ply"));
    let err = write_mesh(
        "/nonexistent/dir/c.ply",
        &coloured_box(),
        PlyEncoding::Ascii,
    )
    .unwrap_err();
    assert!(err.to_string().contains("/nonexistent/dir/c.ply"), "{err}");
}

#[test]
fn reads_other_writers_layouts() {
    // Quads and a pentagon (fan-triangulated), `vertex_index`, ushort indices, double
    // positions, float colours under MeshLab's `diffuse_*` names, extra properties and
    // elements, CRLF line endings and blank lines.
    let text = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\n\
        element vertex 5\r\n\
        property double x\r\nproperty double y\r\nproperty double z\r\n\
        property float quality\r\n\
        property float diffuse_red\r\nproperty float diffuse_green\r\nproperty float diffuse_blue\r\n\
        element face 2\r\n\
        property uchar flags\r\n\
        property list uint ushort vertex_index\r\n\
        element edge 1\r\n\
        property int vertex1\r\nproperty int vertex2\r\n\
        end_header\r\n\
        0 0 0 7 0 0.5 1\r\n1 0 0 7 1 1 1\r\n1 1 0 7 0.2 0.3 0.4\r\n0 1 0 7 2 -1 0\r\n0.5 1.5 0 7 0 0 0\r\n\
        \r\n\
        0 4 0 1 2 3\r\n0 5 0 1 2 4 3\r\n\
        0 1\r\n";
    let mesh = read_bytes(text.as_bytes()).unwrap();
    assert_eq!(mesh.vertex_count(), 5);
    assert_eq!(
        mesh.faces,
        vec![[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 4], [0, 4, 3]]
    );
    assert_eq!(mesh.colors[0], [0, 128, 255]);
    assert_eq!(mesh.colors[2], [51, 77, 102]);
    // Out-of-range float colours are clamped.
    assert_eq!(mesh.colors[3], [255, 0, 0]);

    // Binary big-endian with normals under PCL's names and int8 indices.
    let mut bytes = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\n\
        property float32 x\nproperty float32 y\nproperty float32 z\n\
        property float32 normal_x\nproperty float32 normal_y\nproperty float32 normal_z\n\
        element face 1\nproperty list uint8 int8 vertex_indices\nend_header\n"
        .to_vec();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v.iter().chain(&[0.0, 0.0, 1.0]) {
            bytes.extend_from_slice(&c.to_be_bytes());
        }
    }
    bytes.extend_from_slice(&[3, 0, 1, 2]);
    let mesh = read_bytes(&bytes).unwrap();
    assert_eq!(mesh.faces, vec![[0, 1, 2]]);
    assert_eq!(mesh.normals[2], Vector3::new(0.0, 0.0, 1.0));
    assert_eq!(mesh.positions[1], Point3::new(1.0, 0.0, 0.0));
}

#[test]
fn ascii_floats_use_round_trip_digits() {
    let mesh = TriangleMesh::new(
        vec![
            Point3::new(0.1, 1.0 / 3.0, -2.5e-8),
            Point3::new(f32::MIN_POSITIVE / 8.0, f32::MAX, -0.0),
            Point3::new(123_456.79, 1e-3, 16_777_217.0),
        ],
        vec![[0, 1, 2]],
    )
    .unwrap();
    let bytes = to_bytes(&mesh, PlyEncoding::Ascii);
    let text = String::from_utf8(bytes.clone()).unwrap();
    assert!(text.contains("0.1 0.33333334 -0.000000025\n"), "{text}");
    assert!(text.contains("\n3 0 1 2\n"), "{text}");
    assert_bit_exact(&mesh, &read_bytes(&bytes).unwrap());
}
