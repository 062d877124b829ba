//! GLB export: structure as Blender and MeshLab read it (checked with the `gltf` crate), exact
//! round trips through our reader, and rejection of truncated and corrupt files.

mod common;

use std::panic::{AssertUnwindSafe, catch_unwind};

use common::*;
use gltf::Semantic;
use gltf::accessor::{DataType, Dimensions};
use scarp_export::glb::{
    GlbError, GlbNode, GlbOptions, enu_to_gltf, glb_to_vec, gltf_to_enu, linear_to_srgb, read_glb,
    read_glb_from_slice, srgb_to_linear, write_glb,
};
use scarp_export::ply::read_mesh;
use scarp_slam::TriangleMesh;
use serde_json::{Value, json};

fn scene_bytes() -> (TriangleMesh, TriangleMesh, Vec<u8>) {
    let rock = read_mesh(double_rock_path()).unwrap();
    let cube = coloured_box();
    let nodes = [
        GlbNode::new("double_rock", &rock)
            .with_extras(json!({"rock_id": 7, "alpha_min_deg": 21.5})),
        GlbNode::new("box", &cube),
    ];
    let options = GlbOptions {
        scene_extras: json!({"survey": "test", "origin": [33.6, -116.1, 1200.0]}),
        ..GlbOptions::default()
    };
    let bytes = glb_to_vec(&nodes, &options).unwrap();
    (rock, cube, bytes)
}

fn extras(raw: &Option<Box<serde_json::value::RawValue>>) -> Option<Value> {
    raw.as_ref().map(|r| serde_json::from_str(r.get()).unwrap())
}

fn f32_bounds(mesh: &TriangleMesh) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        let g = enu_to_gltf(&p.coords);
        for k in 0..3 {
            lo[k] = lo[k].min(g[k]);
            hi[k] = hi[k].max(g[k]);
        }
    }
    (lo, hi)
}

fn as_f32x3(v: Option<Value>) -> [f32; 3] {
    let a = v.unwrap();
    let a = a.as_array().unwrap();
    [0, 1, 2].map(|k| a[k].as_f64().unwrap() as f32)
}

#[test]
fn structure_is_what_viewers_expect() {
    let (rock, cube, bytes) = scene_bytes();
    // Container: header length, 4-byte padding.
    assert_eq!(&bytes[..4], b"glTF");
    assert_eq!(u32::from_le_bytes(bytes[4..8].try_into().unwrap()), 2);
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
        bytes.len()
    );
    assert_eq!(bytes.len() % 4, 0);

    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = gltf.blob.as_ref().unwrap();
    assert_eq!(blob.len() % 4, 0);
    let buffers: Vec<_> = gltf.buffers().collect();
    assert_eq!(buffers.len(), 1);
    assert!(matches!(buffers[0].source(), gltf::buffer::Source::Bin));
    assert!(buffers[0].length() <= blob.len() && blob.len() < buffers[0].length() + 4);
    for view in gltf.views() {
        assert_eq!(view.offset() % 4, 0, "view {} misaligned", view.index());
        assert!(view.offset() + view.length() <= buffers[0].length());
        assert!(view.stride().is_none());
    }
    assert_eq!(
        gltf.as_json().asset.generator.as_deref(),
        Some("scarp-export 0.1.0")
    );

    let scene = gltf.default_scene().unwrap();
    assert_eq!(
        extras(scene.extras()),
        Some(json!({"survey": "test", "origin": [33.6, -116.1, 1200.0]}))
    );
    let nodes: Vec<_> = scene.nodes().collect();
    assert_eq!(nodes.len(), 2);
    assert_eq!(nodes[0].name(), Some("double_rock"));
    assert_eq!(nodes[1].name(), Some("box"));
    assert_eq!(
        extras(nodes[0].extras()),
        Some(json!({"rock_id": 7, "alpha_min_deg": 21.5}))
    );
    assert_eq!(extras(nodes[1].extras()), None);

    for (node, mesh) in nodes.iter().zip([&rock, &cube]) {
        let m = node.mesh().unwrap();
        assert_eq!(m.name(), node.name());
        let prims: Vec<_> = m.primitives().collect();
        assert_eq!(prims.len(), 1);
        let prim = &prims[0];
        assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);

        let pos = prim.get(&Semantic::Positions).unwrap();
        assert_eq!(pos.count(), mesh.vertex_count());
        assert_eq!(
            (pos.data_type(), pos.dimensions()),
            (DataType::F32, Dimensions::Vec3)
        );
        let (lo, hi) = f32_bounds(mesh);
        assert_eq!(as_f32x3(pos.min()), lo);
        assert_eq!(as_f32x3(pos.max()), hi);
        assert_eq!(pos.view().unwrap().length(), mesh.vertex_count() * 12);

        let idx = prim.indices().unwrap();
        assert_eq!(idx.count(), mesh.face_count() * 3);
        assert_eq!(
            (idx.data_type(), idx.dimensions()),
            (DataType::U32, Dimensions::Scalar)
        );
        assert_eq!(
            idx.view().unwrap().target(),
            Some(gltf::buffer::Target::ElementArrayBuffer)
        );

        let has_extra = !mesh.normals.is_empty();
        assert_eq!(prim.get(&Semantic::Normals).is_some(), has_extra);
        assert_eq!(
            prim.get(&Semantic::Colors(0)).is_some(),
            !mesh.colors.is_empty()
        );
        if let Some(c) = prim.get(&Semantic::Colors(0)) {
            assert_eq!(c.count(), mesh.vertex_count());
        }

        let pbr = prim.material().pbr_metallic_roughness();
        assert!((pbr.roughness_factor() - 0.9).abs() < 1e-6);
        assert_eq!(pbr.metallic_factor(), 0.0);
        assert!(prim.material().double_sided());

        // The gltf crate's own reader sees the same data.
        let reader = prim.reader(|b| (b.index() == 0).then_some(&blob[..]));
        let read: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        assert_eq!(read.len(), mesh.vertex_count());
        assert_eq!(read[5], enu_to_gltf(&mesh.positions[5].coords));
    }

    // Up is up: the rock's ENU height is glTF's y extent.
    let (lo, hi) = f32_bounds(&rock);
    let (elo, ehi) = rock.bounds().unwrap();
    assert_eq!(hi[1] - lo[1], ehi.z - elo.z);
    assert_eq!(hi[2] - lo[2], ehi.y - elo.y);
}

#[test]
fn round_trip_through_our_reader_is_exact() {
    let (rock, cube, bytes) = scene_bytes();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.glb");
    let nodes = [
        GlbNode::new("double_rock", &rock)
            .with_extras(json!({"rock_id": 7, "alpha_min_deg": 21.5})),
        GlbNode::new("box", &cube),
    ];
    let options = GlbOptions {
        scene_extras: json!({"survey": "test", "origin": [33.6, -116.1, 1200.0]}),
        ..GlbOptions::default()
    };
    write_glb(&path, &nodes, &options).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);

    let contents = read_glb(&path).unwrap();
    assert_eq!(contents.scene_extras.as_ref().unwrap()["survey"], "test");
    assert_eq!(contents.nodes.len(), 2);
    let back_rock = &contents.nodes[0];
    assert_eq!(back_rock.name.as_deref(), Some("double_rock"));
    assert_eq!(
        back_rock.extras,
        Some(json!({"rock_id": 7, "alpha_min_deg": 21.5}))
    );
    assert_eq!(bits(&back_rock.mesh.positions), bits(&rock.positions));
    assert_eq!(back_rock.mesh.faces, rock.faces);
    assert!(back_rock.mesh.normals.is_empty() && back_rock.mesh.colors.is_empty());

    let back_box = &contents.nodes[1].mesh;
    assert_eq!(bits(&back_box.positions), bits(&cube.positions));
    assert_eq!(back_box.faces, cube.faces);
    assert_eq!(back_box.colors, cube.colors);
    for (a, b) in back_box.normals.iter().zip(&cube.normals) {
        assert!((a - b).norm() < 1e-6);
    }
}

#[test]
fn axis_conversion_and_colours_are_exact_inverses() {
    let v = nalgebra::Vector3::new(1.5f32, -2.25, 3.0);
    assert_eq!(enu_to_gltf(&v), [1.5, 3.0, 2.25]);
    assert_eq!(gltf_to_enu(enu_to_gltf(&v)), v);
    for b in 0..=255u8 {
        assert_eq!(linear_to_srgb(srgb_to_linear(b)), b);
    }
    assert_eq!(srgb_to_linear(0), 0.0);
    assert_eq!(srgb_to_linear(255), 1.0);
    assert!((srgb_to_linear(128) - 0.2158605).abs() < 1e-6);
    assert_eq!(linear_to_srgb(f32::NAN), 0);
    assert_eq!(linear_to_srgb(7.0), 255);
}

#[test]
fn invalid_meshes_are_refused() {
    let empty = TriangleMesh::default();
    assert!(matches!(
        glb_to_vec(&[GlbNode::new("e", &empty)], &GlbOptions::default()),
        Err(GlbError::EmptyMesh { .. })
    ));
    let mut bad = coloured_box();
    bad.faces.push([0, 1, 99]);
    let err = glb_to_vec(&[GlbNode::new("bad", &bad)], &GlbOptions::default()).unwrap_err();
    assert!(err.to_string().contains("mesh 'bad'"), "{err}");
    // Degenerate normals are replaced, not written as NaN.
    let mut flat = coloured_box();
    flat.normals[3] = nalgebra::Vector3::zeros();
    flat.normals[4] = nalgebra::Vector3::new(f32::NAN, 0.0, 0.0);
    let bytes = glb_to_vec(&[GlbNode::new("flat", &flat)], &GlbOptions::default()).unwrap();
    let back = read_glb_from_slice(&bytes, "flat.glb").unwrap();
    for n in &back.nodes[0].mesh.normals {
        assert!((n.norm() - 1.0).abs() < 1e-5, "{n:?}");
    }
    // A missing file names its path.
    let err = read_glb("/nonexistent/rock.glb").unwrap_err();
    assert!(
        err.to_string().starts_with("/nonexistent/rock.glb"),
        "{err}"
    );
}

fn expect_err(bytes: &[u8]) -> GlbError {
    match catch_unwind(AssertUnwindSafe(|| read_glb_from_slice(bytes, "t.glb"))) {
        Ok(Ok(c)) => panic!("expected an error, read {} nodes", c.nodes.len()),
        Ok(Err(e)) => e,
        Err(_) => panic!("the GLB reader panicked"),
    }
}

#[test]
fn truncated_files_are_rejected() {
    let cube = coloured_box();
    let bytes = glb_to_vec(&[GlbNode::new("box", &cube)], &GlbOptions::default()).unwrap();
    for cut in 0..bytes.len() {
        let err = expect_err(&bytes[..cut]);
        assert!(
            matches!(err, GlbError::Truncated { .. }),
            "cut {cut}: {err}"
        );
    }
    let (_, _, big) = scene_bytes();
    for cut in (0..big.len()).step_by(997) {
        let err = expect_err(&big[..cut]);
        assert!(err.to_string().starts_with("t.glb: truncated"), "{err}");
    }
    assert_eq!(
        expect_err(&big[..big.len() - 100]).to_string(),
        format!(
            "t.glb: truncated: the length in the GLB header needs {} bytes, the file has {}",
            big.len(),
            big.len() - 100
        )
    );
}

/// Rebuilds a GLB with edited JSON and/or binary chunk.
fn rebuild(
    bytes: &[u8],
    edit_json: impl FnOnce(&mut Value),
    edit_bin: impl FnOnce(&mut Vec<u8>),
) -> Vec<u8> {
    let glb = gltf::Glb::from_slice(bytes).unwrap();
    let mut json: Value = serde_json::from_slice(&glb.json).unwrap();
    edit_json(&mut json);
    let mut bin = glb.bin.unwrap().into_owned();
    edit_bin(&mut bin);
    let json = serde_json::to_vec(&json).unwrap();
    let length =
        (12 + 8 + json.len().next_multiple_of(4) + 8 + bin.len().next_multiple_of(4)) as u32;
    gltf::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length,
        },
        json: json.into(),
        bin: Some(bin.into()),
    }
    .to_vec()
    .unwrap()
}

#[test]
fn corrupt_files_are_rejected_with_reasons() {
    let cube = coloured_box();
    let good = glb_to_vec(&[GlbNode::new("box", &cube)], &GlbOptions::default()).unwrap();
    // The rebuild helper itself produces a readable file.
    read_glb_from_slice(&rebuild(&good, |_| {}, |_| {}), "t.glb").unwrap();

    let mut b = good.clone();
    b[..4].copy_from_slice(b"PLY\n");
    assert!(matches!(expect_err(&b), GlbError::NotGlb { .. }));
    let mut b = good.clone();
    b[4] = 1;
    assert!(matches!(expect_err(&b), GlbError::Unsupported { .. }));
    let mut b = good.clone();
    b.extend_from_slice(&[0; 8]);
    assert!(matches!(expect_err(&b), GlbError::Corrupt { .. }));
    let mut b = good.clone();
    b[16..20].copy_from_slice(b"BIN\0");
    assert!(expect_err(&b).to_string().contains("not JSON"));
    let mut b = good.clone();
    b[20] = b'!';
    assert!(matches!(expect_err(&b), GlbError::Gltf { .. }));

    let cases: Vec<(Vec<u8>, &str)> = vec![
        (
            rebuild(&good, |j| j["accessors"][0]["count"] = json!(9000), |_| {}),
            "do not fit buffer view",
        ),
        (
            // A huge count must be checked before anything is allocated for it.
            rebuild(
                &good,
                |j| j["accessors"][1]["count"] = json!(1_000_000_000_000_000u64),
                |_| {},
            ),
            "NORMAL has 1000000000000000 items",
        ),
        (
            rebuild(
                &good,
                |j| {
                    for a in 0..4 {
                        j["accessors"][a]["count"] = json!(1_000_000_000_000_002u64);
                    }
                },
                |_| {},
            ),
            "do not fit buffer view",
        ),
        (
            rebuild(
                &good,
                |j| j["accessors"][0]["byteOffset"] = json!(2),
                |_| {},
            ),
            "misaligned",
        ),
        (
            rebuild(
                &good,
                |j| j["bufferViews"][0]["byteLength"] = json!(100000),
                |_| {},
            ),
            "runs past its buffer",
        ),
        (
            rebuild(
                &good,
                |j| j["buffers"][0]["byteLength"] = json!(100000),
                |_| {},
            ),
            "BIN chunk holds",
        ),
        (
            rebuild(
                &good,
                |j| {
                    j["accessors"][0].as_object_mut().unwrap().remove("min");
                },
                |_| {},
            ),
            "min: Missing",
        ),
        (
            rebuild(
                &good,
                |j| j["accessors"][0]["max"] = json!([0.0, 0.0, 0.0]),
                |_| {},
            ),
            "outside the declared bounds",
        ),
        (
            rebuild(
                &good,
                |j| j["meshes"][0]["primitives"][0]["mode"] = json!(0),
                |_| {},
            ),
            "only triangles",
        ),
        (
            rebuild(&good, |j| j["nodes"][0]["children"] = json!([0]), |_| {}),
            "",
        ),
        (
            rebuild(
                &good,
                |_| {},
                |bin| {
                    // The last index (the end of the binary chunk) points far away.
                    let n = bin.len();
                    bin[n - 4..].copy_from_slice(&999_999u32.to_le_bytes());
                },
            ),
            "refers to vertex 999999",
        ),
        (
            rebuild(
                &good,
                |_| {},
                |bin| bin[4..8].copy_from_slice(&f32::NAN.to_le_bytes()),
            ),
            "not finite",
        ),
    ];
    for (bytes, expected) in cases {
        let msg = expect_err(&bytes).to_string();
        assert!(msg.starts_with("t.glb: "), "{msg}");
        assert!(msg.contains(expected), "expected '{expected}' in: {msg}");
    }
}

#[test]
fn node_transforms_are_applied() {
    let cube = coloured_box();
    let good = glb_to_vec(&[GlbNode::new("box", &cube)], &GlbOptions::default()).unwrap();
    let moved = rebuild(
        &good,
        |j| j["nodes"][0]["translation"] = json!([1.0, 2.0, 3.0]),
        |_| {},
    );
    let back = read_glb_from_slice(&moved, "t.glb").unwrap();
    // glTF (1, 2, 3) is ENU (1, -3, 2).
    for (a, b) in back.nodes[0].mesh.positions.iter().zip(&cube.positions) {
        assert!((a - b - nalgebra::Vector3::new(1.0, -3.0, 2.0)).norm() < 1e-6);
    }
}

#[test]
fn mutated_files_never_panic() {
    let cube = coloured_box();
    let good = glb_to_vec(
        &[GlbNode::new("box", &cube).with_extras(json!({"id": 1}))],
        &GlbOptions::default(),
    )
    .unwrap();
    let mut rng = SplitMix(42);
    for _ in 0..3000 {
        let mut b = good.clone();
        match rng.below(3) {
            0 => {
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(b.len());
                    b[i] ^= 1 << rng.below(8);
                }
            }
            1 => {
                let i = rng.below(b.len());
                b[i] = rng.next_u64() as u8;
            }
            _ => b.truncate(rng.below(b.len())),
        }
        let result = catch_unwind(AssertUnwindSafe(|| read_glb_from_slice(&b, "m.glb")));
        assert!(result.is_ok(), "panicked");
        if let Ok(Ok(c)) = result {
            for n in &c.nodes {
                n.mesh.validate().unwrap();
            }
        }
    }
}
