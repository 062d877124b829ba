//! End-to-end `scarp map` and `scarp eval mesh` on a short no-noise orbit of the default world:
//! the cylinder ROI keeps memory under 10 % of the unrestricted map, and the target's mesh
//! scores well against its ground truth (reduced version of the 120-frame figure), with
//! either depth sample.

mod common;
use common::{first_rock_centroid_m, read_json as json, scarp_stdout as scarp};

#[test]
fn map_and_evaluate_default_orbit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    scarp(&[
        "render",
        "--path",
        "orbit",
        "--frames",
        "8",
        "--no-noise",
        "--out",
        &d("seq"),
    ]);
    let [x, y, z] = first_rock_centroid_m(dir.path());
    let roi = format!("cyl:{x},{y},{},{},1.2", z - 1.6, z + 1.2);
    // `scarp map` of the sequence into `out`, with ground-truth poses at 1 cm.
    let map = |out: &str, extra: &[&str]| {
        let (seq, out) = (d("seq"), d(out));
        let mut args = vec!["map", &seq, "--poses", "groundtruth", "--voxel", "0.01"];
        args.extend_from_slice(extra);
        args.extend(["--out", &out]);
        scarp(&args);
    };
    map("roi", &["--roi", &roi]);
    map("full", &[]);
    let roi_map = json(&dir.path().join("roi/map.json"));
    let full_map = json(&dir.path().join("full/map.json"));
    for key in [
        "frames",
        "blocks",
        "voxels",
        "memory_bytes",
        "integrate_ms_median",
        "integrate_ms_p90",
        "mesh_ms",
        "vertices",
        "triangles",
    ] {
        assert!(roi_map.get(key).is_some(), "map.json lacks {key}");
    }
    assert_eq!(roi_map["frames"], 8);
    let (b_roi, b_full) = (
        roi_map["blocks"].as_f64().unwrap(),
        full_map["blocks"].as_f64().unwrap(),
    );
    assert!(b_roi < 0.1 * b_full, "ROI blocks {b_roi} vs {b_full}");
    assert!(dir.path().join("roi/mesh.glb").exists());
    let score = |mesh: &str| -> serde_json::Value {
        serde_json::from_str(&scarp(&[
            "eval",
            "mesh",
            "--gt",
            &d("world/rock_1.ply"),
            "--mesh",
            &d(mesh),
            "--tau",
            "0.01",
            "--crop-to-gt",
            "0.1",
            "--visible-from",
            &d("seq"),
            "--world",
            "default",
            "--samples-per-m2",
            "10000",
            "--json",
        ]))
        .expect("json")
    };
    let scores = score("roi/mesh.ply");
    for key in [
        "accuracy_mean_m",
        "accuracy_median_m",
        "accuracy_p90_m",
        "completeness_mean_m",
        "completeness_median_m",
        "completeness_p90_m",
        "precision",
        "recall",
        "fscore",
        "tau_m",
        "gt_visible_fraction",
    ] {
        assert!(scores.get(key).is_some(), "eval json lacks {key}");
    }
    let f = scores["fscore"].as_f64().unwrap();
    assert!(f >= 0.9, "F-score {f}: {scores}");
    let visible = scores["gt_visible_fraction"].as_f64().unwrap();
    assert!(visible > 0.5 && visible < 1.0, "visible fraction {visible}");

    // The nearest pixel's depth: another mesh, as accurate.
    map("nearest", &["--roi", &roi, "--depth-sample", "nearest"]);
    let read = |mesh: &str| std::fs::read(dir.path().join(mesh)).expect("mesh");
    assert_ne!(read("nearest/mesh.ply"), read("roi/mesh.ply"));
    let f_nearest = score("nearest/mesh.ply")["fscore"].as_f64().unwrap();
    assert!(
        (f_nearest - f).abs() < 0.01,
        "F-score {f_nearest} nearest, {f} bilinear"
    );
}
