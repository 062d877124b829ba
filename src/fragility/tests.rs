//! End-to-end tests of [`analyze`] on analytic solids and bad meshes.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use scarp_slam::TriangleMesh;

use super::test_shapes::{cuboid_solid, icosphere, loft_solid, rect, regular_ring, to_mesh};
use super::topology::Solid;
use super::*;

/// The default configuration without the perturbation study (fast).
fn quick() -> FragilityConfig {
    FragilityConfig {
        uncertainty: UncertaintyConfig {
            samples: 0,
            ..UncertaintyConfig::default()
        },
        ..FragilityConfig::default()
    }
}

fn deg(x: f64) -> f64 {
    x.to_degrees()
}

fn moved(solid: &Solid, motion: &Isometry3<f64>) -> Solid {
    Solid {
        positions: solid.positions.iter().map(|p| motion * p).collect(),
        faces: solid.faces.clone(),
    }
}

#[test]
fn block_on_full_base_gives_atan_b_over_h_each_way() {
    let (bx, by, h) = (1.0, 0.6, 2.0);
    let block = moved(
        &cuboid_solid([bx, by, h]),
        &Isometry3::translation(100.0, -50.0, 20.0),
    );
    let r = analyze(&to_mesh(&block), ContactSpec::Auto, &quick()).unwrap();
    assert_eq!(r.contact_method, ContactMethod::Base);
    for (az, b) in [(0, bx), (90, by), (180, bx), (270, by)] {
        let expected = deg((b / h).atan());
        assert!(
            (r.alpha_deg[az] - expected).abs() < 0.05,
            "{az}°: {} vs {expected}",
            r.alpha_deg[az]
        );
        assert!((r.alpha_deg[az] - expected).abs() < 1e-4);
    }
    assert!((r.alpha_min_deg - deg((by / h).atan())).abs() < 1e-4);
    assert!(r.alpha_min_azimuth_deg == 90.0 || r.alpha_min_azimuth_deg == 270.0);
    assert!((r.toppling_pga_g - by / h).abs() < 1e-5);
    assert!((r.contact_area_m2 - bx * by).abs() < 1e-5);
    assert!((r.com_height_above_contact_m - h / 2.0).abs() < 1e-5);
    assert!((r.height_to_width - h / by).abs() < 1e-4);
    let mass = bx * by * h * 2650.0;
    assert!((r.mass_kg - mass).abs() < 1e-3 * mass);
    // Purvance: I_O about the long bottom edge of the block.
    let radius = (by / 2.0f64).hypot(h / 2.0);
    let i_o = mass / 12.0 * (by * by + h * h) + mass * radius * radius;
    assert!((r.rocking_radius_m - radius).abs() < 1e-5);
    assert!((r.inertia_about_rocking_axis_kg_m2 - i_o).abs() < 1e-3 * i_o);
    let p = (mass * 9.80665 * radius / i_o).sqrt();
    assert!((r.purvance_p_rad_s - p).abs() < 1e-3 * p);
    assert_eq!(r.opposite_pairs.len(), 180);
    assert!((r.opposite_pairs[0].opposite_alpha_deg - deg((bx / h).atan())).abs() < 1e-4);
}

/// A block 1 m wide and 2 m tall on a column `a` wide centred at `(ox, 0)`, which stands on a
/// wide slab.
fn block_on_column(a: f64, ox: f64) -> (Solid, Solid, Solid) {
    let slab = rect(-1.5, -1.5, 1.5, 1.5);
    let column = rect(ox - a / 2.0, -a / 2.0, ox + a / 2.0, a / 2.0);
    let block = rect(-0.5, -0.5, 0.5, 0.5);
    let merged = loft_solid(&[
        (&slab, -0.6),
        (&slab, -0.4),
        (&column, -0.4),
        (&column, 0.0),
        (&block, 0.0),
        (&block, 2.0),
    ]);
    let pedestal = loft_solid(&[
        (&slab, -0.6),
        (&slab, -0.4),
        (&column, -0.4),
        (&column, 0.0),
    ]);
    let rock = loft_solid(&[(&block, 0.0), (&block, 2.0)]);
    (merged, pedestal, rock)
}

#[test]
fn block_on_narrow_pedestal_uses_the_contact_width() {
    let (a, ox) = (0.3, 0.1);
    let (merged, pedestal, rock) = block_on_column(a, ox);
    let expect_east = deg(((ox + a / 2.0) / 1.0).atan());
    let expect_west = deg(((a / 2.0 - ox) / 1.0).atan());
    let expect_north = deg((a / 2.0f64).atan());
    let pedestal = to_mesh(&pedestal);
    for (name, mesh, spec) in [
        ("auto neck", to_mesh(&merged), ContactSpec::Auto),
        ("height", to_mesh(&merged), ContactSpec::Height(0.0)),
        ("pedestal", to_mesh(&rock), ContactSpec::Pedestal(&pedestal)),
    ] {
        let r = analyze(&mesh, spec, &quick()).unwrap();
        assert!(
            (r.contact_height_m).abs() < 1e-5,
            "{name}: {}",
            r.contact_height_m
        );
        assert!(
            (r.contact_area_m2 - a * a).abs() < 1e-5,
            "{name}: {}",
            r.contact_area_m2
        );
        assert!(
            (r.alpha_deg[0] - expect_east).abs() < 0.05,
            "{name}: {}",
            r.alpha_deg[0]
        );
        assert!(
            (r.alpha_deg[180] - expect_west).abs() < 0.05,
            "{name}: {}",
            r.alpha_deg[180]
        );
        assert!(
            (r.alpha_deg[90] - expect_north).abs() < 0.05,
            "{name}: {}",
            r.alpha_deg[90]
        );
        assert!((r.alpha_min_deg - expect_west).abs() < 0.05, "{name}");
        assert!((r.alpha_min_azimuth_deg - 180.0).abs() < 1e-6, "{name}");
        assert!((r.volume_m3 - 2.0).abs() < 1e-4, "{name}: {}", r.volume_m3);
        assert!((r.height_to_width - 2.0 / a).abs() < 1e-3, "{name}");
    }
    let merged_report = analyze(&to_mesh(&merged), ContactSpec::Auto, &quick()).unwrap();
    assert_eq!(merged_report.contact_method, ContactMethod::Neck);
}

#[test]
fn cylinder_on_its_base_and_on_a_neck() {
    let (radius, height, n) = (0.4, 1.5, 256);
    let ring = regular_ring(n, radius, 0.0);
    let cylinder = loft_solid(&[(&ring, 0.0), (&ring, height)]);
    let r = analyze(&to_mesh(&cylinder), ContactSpec::Auto, &quick()).unwrap();
    let exact = deg((2.0 * radius / height).atan());
    let inscribed = deg((2.0 * radius * (std::f64::consts::PI / n as f64).cos() / height).atan());
    assert!((r.alpha_min_deg - exact).abs() < 0.05);
    for a in &r.alpha_deg {
        assert!(*a >= inscribed - 1e-4 && *a <= exact + 1e-4, "{a}");
    }
    let volume = std::f64::consts::PI * radius * radius * height;
    assert!(((r.volume_m3 - volume) / volume).abs() < 1e-3);

    // The same cylinder on a narrow round neck of a wider base.
    let neck = regular_ring(n, 0.1, 0.0);
    let base = regular_ring(n, 1.0, 0.0);
    let on_neck = loft_solid(&[
        (&base, -1.0),
        (&base, -0.5),
        (&neck, -0.2),
        (&neck, 0.0),
        (&ring, 0.0),
        (&ring, height),
    ]);
    let r = analyze(&to_mesh(&on_neck), ContactSpec::Auto, &quick()).unwrap();
    assert_eq!(r.contact_method, ContactMethod::Neck);
    assert!(r.contact_height_m.abs() < 1e-5);
    assert!(
        (r.alpha_min_deg - deg((0.1 / (height / 2.0)).atan())).abs() < 0.05,
        "{}",
        r.alpha_min_deg
    );
}

#[test]
fn tilted_block_cut_flat_at_its_lowest_corner() {
    // A b × w × h block rotated by φ about y, standing on a flat cut d above its lowest corner.
    let (b, w, h, phi, d) = (1.0f64, 0.8, 2.0, 20f64.to_radians(), 0.2);
    let block = cuboid_solid([b, w, h]);
    let rot = Isometry3::rotation(Vector3::y() * phi);
    let tilted = moved(&block, &rot);
    // Lowest corner C = R·(b, 0, 0) = (b cos φ, −b sin φ); the cut removes a triangle there.
    let rotate = |x: f64, z: f64| {
        (
            x * phi.cos() + z * phi.sin(),
            -x * phi.sin() + z * phi.cos(),
        )
    };
    let c = rotate(b, 0.0);
    let z0 = c.1 + d;
    let t = [
        c,
        (c.0 - d / phi.tan(), c.1 + d),
        (c.0 + d * phi.tan(), c.1 + d),
    ];
    let area_t = 0.5 * (d / phi.tan() + d * phi.tan()) * d;
    let centroid_t = (
        (t[0].0 + t[1].0 + t[2].0) / 3.0,
        (t[0].1 + t[1].1 + t[2].1) / 3.0,
    );
    let centroid_r = rotate(b / 2.0, h / 2.0);
    let area = b * h - area_t;
    let com = (
        (b * h * centroid_r.0 - area_t * centroid_t.0) / area,
        (b * h * centroid_r.1 - area_t * centroid_t.1) / area,
    );
    let (left, right) = (t[1].0, t[2].0);
    let com_height = com.1 - z0;
    let r = analyze(&to_mesh(&tilted), ContactSpec::Height(z0), &quick()).unwrap();
    assert!((r.volume_m3 - area * w).abs() < 1e-5);
    assert!((r.center_of_mass[0] - com.0).abs() < 1e-5);
    assert!((r.com_height_above_contact_m - com_height).abs() < 1e-5);
    let east = deg(((right - com.0) / com_height).atan());
    let west = deg(((com.0 - left) / com_height).atan());
    let north = deg((w / 2.0 / com_height).atan());
    assert!(
        (r.alpha_deg[0] - east).abs() < 0.05,
        "{} vs {east}",
        r.alpha_deg[0]
    );
    assert!(
        (r.alpha_deg[180] - west).abs() < 0.05,
        "{} vs {west}",
        r.alpha_deg[180]
    );
    assert!((r.alpha_deg[90] - north).abs() < 0.05);
    assert!((r.alpha_min_deg - east.min(west).min(north)).abs() < 0.05);
    assert!((r.contact_area_m2 - (right - left) * w).abs() < 1e-5);
}

#[test]
fn sphere_and_box_mass_properties_within_a_tenth_of_a_percent() {
    let radius = 0.75;
    let mut sphere = to_mesh(&icosphere(5, radius));
    sphere.transform(&Isometry3::translation(3.0, -2.0, 1.0));
    let m = mass_properties(&sphere, 2650.0).unwrap();
    let volume = 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3);
    assert!(
        ((m.volume_m3 - volume) / volume).abs() < 1e-3,
        "{}",
        m.volume_m3
    );
    assert!((m.center_of_mass - Point3::new(3.0, -2.0, 1.0)).norm() < 1e-3 * radius);
    assert!(((m.mass_kg - 2650.0 * volume) / (2650.0 * volume)).abs() < 1e-3);

    let mut cube = to_mesh(&cuboid_solid([0.5, 1.5, 2.5]));
    cube.transform(&Isometry3::from_parts(
        Translation3::new(-4.0, 7.0, 2.0),
        UnitQuaternion::from_euler_angles(0.4, 0.1, -0.7),
    ));
    let m = mass_properties(&cube, 1000.0).unwrap();
    assert!(((m.volume_m3 - 1.875) / 1.875).abs() < 1e-3);
    let centre = Isometry3::from_parts(
        Translation3::new(-4.0, 7.0, 2.0),
        UnitQuaternion::from_euler_angles(0.4, 0.1, -0.7),
    ) * Point3::new(0.25, 0.75, 1.25);
    assert!((m.center_of_mass - centre).norm() < 1e-3 * 2.5);
}

#[test]
fn bad_meshes_give_clear_errors() {
    let cube = to_mesh(&cuboid_solid([1.0, 1.0, 1.0]));
    let cfg = quick();
    let run = |m: &TriangleMesh| analyze(m, ContactSpec::Auto, &cfg);

    let empty = TriangleMesh::default();
    assert!(matches!(
        run(&empty),
        Err(FragilityError::EmptyMesh { mesh: "rock" })
    ));

    let mut open = cube.clone();
    open.faces.pop();
    let e = run(&open).unwrap_err();
    assert!(
        matches!(e, FragilityError::OpenMesh { count: 3, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("open"));

    let mut non_manifold = cube.clone();
    non_manifold.faces.push(non_manifold.faces[0]);
    assert!(matches!(
        run(&non_manifold),
        Err(FragilityError::NonManifold { .. })
    ));

    let mut flipped_face = cube.clone();
    flipped_face.faces[3].swap(0, 1);
    assert!(matches!(
        run(&flipped_face),
        Err(FragilityError::InconsistentWinding { .. })
    ));

    let mut nan = cube.clone();
    nan.positions[2].y = f32::NAN;
    let e = run(&nan).unwrap_err();
    assert!(
        matches!(e, FragilityError::InvalidMesh { .. }) && e.to_string().contains("vertex 2"),
        "{e}"
    );

    let mut out_of_range = cube.clone();
    out_of_range.faces[0][1] = 99;
    assert!(matches!(
        run(&out_of_range),
        Err(FragilityError::InvalidMesh { .. })
    ));

    // A closed tetrahedron whose four corners lie in one plane.
    let flat = TriangleMesh {
        positions: vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
        ],
        faces: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        ..TriangleMesh::default()
    };
    let e = run(&flat).unwrap_err();
    assert!(matches!(e, FragilityError::Degenerate(_)), "{e}");

    // Faces that repeat a vertex are dropped (documented repair).
    let mut sliver = cube.clone();
    sliver.faces.push([0, 0, 1]);
    let r = run(&sliver).unwrap();
    assert_eq!(r.repairs.dropped_degenerate_faces, 1);

    // Split corners are welded and inward winding flipped (documented repairs).
    let mut soup = TriangleMesh::default();
    for f in &cube.faces {
        let base = soup.positions.len() as u32;
        soup.positions
            .extend(f.iter().map(|&v| cube.positions[v as usize]));
        soup.faces.push([base, base + 2, base + 1]);
    }
    let r = run(&soup).unwrap();
    assert_eq!(
        r.repairs.welded_vertices,
        3 * cube.faces.len() - cube.positions.len()
    );
    assert_eq!(r.repairs.flipped_shells, 1);
    assert!((r.alpha_min_deg - 45.0).abs() < 1e-4);

    // Contacts and settings that cannot work.
    assert!(matches!(
        analyze(&cube, ContactSpec::Height(1.0), &cfg),
        Err(FragilityError::ContactOutsideRock { .. })
    ));
    assert!(matches!(
        analyze(&cube, ContactSpec::Height(f64::NAN), &cfg),
        Err(FragilityError::ContactOutsideRock { .. })
    ));
    let mut far = to_mesh(&cuboid_solid([1.0, 1.0, 1.0]));
    far.transform(&Isometry3::translation(10.0, 0.0, -1.0));
    assert!(matches!(
        analyze(&cube, ContactSpec::Pedestal(&far), &cfg),
        Err(FragilityError::NoPedestalContact(_))
    ));
    let mut low = to_mesh(&cuboid_solid([1.0, 1.0, 1.0]));
    low.transform(&Isometry3::translation(0.0, 0.0, -1.5));
    assert!(matches!(
        analyze(&cube, ContactSpec::Pedestal(&low), &cfg),
        Err(FragilityError::NoPedestalContact(_))
    ));
    for bad in [
        FragilityConfig {
            up: [0.0; 3],
            ..quick()
        },
        FragilityConfig {
            azimuth_count: 359,
            ..quick()
        },
        FragilityConfig {
            density_kg_m3: -1.0,
            ..quick()
        },
    ] {
        assert!(matches!(
            analyze(&cube, ContactSpec::Auto, &bad),
            Err(FragilityError::InvalidConfig { .. })
        ));
    }
}

#[test]
fn centre_of_mass_outside_the_contact_is_an_error() {
    // A block leaning so far that its centre of mass overhangs the small flat cut.
    let block = cuboid_solid([0.4, 0.4, 2.0]);
    let tilted = moved(
        &block,
        &Isometry3::rotation(Vector3::y() * 40f64.to_radians()),
    );
    let (z_lo, _) = tilted.z_range().unwrap();
    let e = analyze(
        &to_mesh(&tilted),
        ContactSpec::Height(z_lo + 0.05),
        &quick(),
    )
    .unwrap_err();
    assert!(matches!(e, FragilityError::ComOutsideContact { .. }), "{e}");
}

#[test]
fn up_direction_levels_the_mesh() {
    // The block of the first test lying on its side, with up = +x.
    let (bx, by, h) = (1.0, 0.6, 2.0);
    let block = cuboid_solid([bx, by, h]);
    let on_side = moved(
        &block,
        &Isometry3::rotation(Vector3::y() * std::f64::consts::FRAC_PI_2),
    );
    let cfg = FragilityConfig {
        up: [1.0, 0.0, 0.0],
        ..quick()
    };
    let r = analyze(&to_mesh(&on_side), ContactSpec::Auto, &cfg).unwrap();
    assert!((r.alpha_min_deg - deg((by / h).atan())).abs() < 1e-4);
    assert!((r.center_of_mass[0] - 1.0).abs() < 1e-5);
    let down = FragilityConfig {
        up: [0.0, 0.0, -1.0],
        ..quick()
    };
    let flipped = moved(
        &block,
        &Isometry3::rotation(Vector3::x() * std::f64::consts::PI),
    );
    let r = analyze(&to_mesh(&flipped), ContactSpec::Auto, &down).unwrap();
    assert!((r.alpha_min_deg - deg((by / h).atan())).abs() < 1e-4);
}

#[test]
fn perturbation_spread_is_seeded_and_positive() {
    let ring = regular_ring(64, 0.3, 0.0);
    let neck = regular_ring(64, 0.12, 0.0);
    let base = regular_ring(64, 0.8, 0.0);
    let rock = loft_solid(&[
        (&base, -0.5),
        (&neck, -0.1),
        (&neck, 0.0),
        (&ring, 0.05),
        (&ring, 1.2),
    ]);
    let mesh = to_mesh(&rock);
    let cfg = FragilityConfig::default();
    let a = analyze(&mesh, ContactSpec::Auto, &cfg).unwrap();
    let b = analyze(&mesh, ContactSpec::Auto, &cfg).unwrap();
    assert_eq!(a, b);
    assert_eq!(a.uncertainty.samples, 32);
    assert_eq!(a.uncertainty.failed_samples, 0);
    assert!(
        a.alpha_min_spread_deg > 0.0 && a.alpha_min_spread_deg < 2.0,
        "{}",
        a.alpha_min_spread_deg
    );
    assert!(a.uncertainty.alpha_min_lowest_deg <= a.uncertainty.alpha_min_highest_deg);
    let other = FragilityConfig {
        uncertainty: UncertaintyConfig {
            seed: 9,
            ..UncertaintyConfig::default()
        },
        ..FragilityConfig::default()
    };
    let c = analyze(&mesh, ContactSpec::Auto, &other).unwrap();
    assert_ne!(a.alpha_min_spread_deg, c.alpha_min_spread_deg);
    assert_eq!(a.alpha_min_deg, c.alpha_min_deg);
}

#[test]
fn a_coarse_box_on_its_base_keeps_a_positive_interval_around_its_angle() {
    // 8 vertices, 12 triangles: the perturbation study used to re-decide which of the 4 base
    // corners touch on every noised sample, and reported α_min down to −27.8° for a box that
    // stands at atan(0.4) = 21.8°.
    let mesh = to_mesh(&cuboid_solid([0.4, 0.4, 1.0]));
    let r = analyze(&mesh, ContactSpec::Auto, &FragilityConfig::default()).unwrap();
    assert_eq!(r.contact_method, ContactMethod::Base);
    let truth = deg(0.4f64.atan());
    assert!((r.alpha_min_deg - truth).abs() < 1e-4);
    assert_eq!(r.uncertainty.failed_samples, 0);
    assert!(
        r.alpha_min_low_deg <= truth && truth <= r.alpha_min_high_deg,
        "[{}, {}]",
        r.alpha_min_low_deg,
        r.alpha_min_high_deg
    );
    // 2 mm of noise on a 0.4 m base moves the edges by millimetres: a fraction of a degree.
    assert!(
        r.alpha_min_low_deg > truth - 1.0 && r.alpha_min_high_deg < truth + 1.0,
        "[{}, {}]",
        r.alpha_min_low_deg,
        r.alpha_min_high_deg
    );
}

#[test]
fn report_json_has_the_interface_fields() {
    let r = analyze(
        &to_mesh(&cuboid_solid([1.0, 1.0, 2.0])),
        ContactSpec::Auto,
        &FragilityConfig::default(),
    )
    .unwrap();
    let v: serde_json::Value = serde_json::to_value(&r).unwrap();
    for key in [
        "alpha_min_deg",
        "alpha_min_azimuth_deg",
        "toppling_pga_g",
        "volume_m3",
        "mass_kg",
        "center_of_mass",
        "com_height_above_contact_m",
        "contact_height_m",
        "contact_area_m2",
        "height_to_width",
        "alpha_deg",
        "alpha_min_spread_deg",
        "opposite_pairs",
        "inertia_kg_m2",
        "purvance_p_rad_s",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["alpha_deg"].as_array().unwrap().len(), 360);
    assert_eq!(v["center_of_mass"].as_array().unwrap().len(), 3);
    let back: FragilityReport = serde_json::from_value(v).unwrap();
    assert_eq!(back.alpha_deg.len(), 360);
    // The configuration round-trips through TOML with documented defaults.
    let text = toml::to_string(&FragilityConfig::default()).unwrap();
    let parsed: FragilityConfig = toml::from_str(&text).unwrap();
    assert_eq!(parsed, FragilityConfig::default());
    let partial: FragilityConfig = toml::from_str("density_kg_m3 = 2500.0").unwrap();
    assert_eq!(partial.azimuth_count, 360);
}

#[test]
fn figure_is_written_as_svg_and_png() {
    let (merged, _, _) = block_on_column(0.3, 0.1);
    let a = analyze_detailed(&to_mesh(&merged), ContactSpec::Auto, &quick()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("f.svg");
    figure::write_figure(&a, &svg).unwrap();
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg") && text.contains("α_min"));
    let png = dir.path().join("f.png");
    figure::write_figure(&a, &png).unwrap();
    let img = image::open(&png).unwrap();
    assert_eq!(
        (img.width(), img.height()),
        (figure::FIGURE_WIDTH_PX, figure::FIGURE_HEIGHT_PX)
    );
    assert!(figure::write_figure(&a, &dir.path().join("f.bmp")).is_err());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        2,
        "no temporary files left"
    );
    let closed = a.closed_rock();
    assert!((mass_properties(&closed, 1.0).unwrap().volume_m3 - 2.0).abs() < 1e-4);
}

#[test]
fn cut_and_close_flattens_a_sphere() {
    let sphere = to_mesh(&icosphere(3, 1.0));
    let cut = cut_and_close(&sphere, [0.0, 0.0, 1.0], -0.5).unwrap();
    assert_eq!(cut.section_loops, 1);
    let m = mass_properties(&cut.mesh, 1.0).unwrap();
    // A sphere minus a cap of height 0.5 (within the tessellation error).
    let cap = std::f64::consts::PI * 0.25 * (3.0 - 0.5) / 3.0;
    let expected = 4.0 / 3.0 * std::f64::consts::PI - cap;
    assert!(
        ((m.volume_m3 - expected) / expected).abs() < 0.02,
        "{}",
        m.volume_m3
    );
}

/// A sheared (leaning) prism: unique α_min, for the rigid-motion property.
fn sheared_block() -> Solid {
    let base = rect(0.0, 0.0, 1.0, 0.7);
    let top: Vec<(f64, f64)> = base.iter().map(|&(x, y)| (x + 0.3, y + 0.1)).collect();
    loft_solid(&[(&base, 0.0), (&top, 1.8)])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn rigid_motions_leave_alpha_unchanged(
        yaw in -3.2f64..3.2, tilt_axis in 0.0f64..6.3, tilt in 0.0f64..1.2,
        tx in -50.0f64..50.0, ty in -50.0f64..50.0, tz in -20.0f64..20.0,
    ) {
        let solid = sheared_block();
        let reference = analyze(&to_mesh(&solid), ContactSpec::Auto, &quick()).unwrap();
        // Yaw about the vertical, then tilt the whole scene and tell the analysis where up is.
        let tilt_rotation = UnitQuaternion::from_axis_angle(
            &Unit::new_normalize(Vector3::new(tilt_axis.cos(), tilt_axis.sin(), 0.0)),
            tilt,
        );
        let motion = Isometry3::from_parts(
            Translation3::new(tx, ty, tz),
            tilt_rotation * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        );
        let up = tilt_rotation * Vector3::z();
        let cfg = FragilityConfig { up: up.into(), ..quick() };
        let r = analyze(&to_mesh(&moved(&solid, &motion)), ContactSpec::Auto, &cfg).unwrap();
        prop_assert!((r.alpha_min_deg - reference.alpha_min_deg).abs() < 2e-3, "{} vs {}", r.alpha_min_deg, reference.alpha_min_deg);
        prop_assert!(((r.volume_m3 - reference.volume_m3) / reference.volume_m3).abs() < 1e-4);
        prop_assert!((r.com_height_above_contact_m - reference.com_height_above_contact_m).abs() < 1e-3);
        let com = motion.inverse() * Point3::from(Vector3::from(r.center_of_mass));
        prop_assert!((com - Point3::from(Vector3::from(reference.center_of_mass))).norm() < 1e-3);
    }

    #[test]
    fn random_meshes_never_panic(
        points in prop::collection::vec((-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0), 0..12),
        faces in prop::collection::vec((0u32..14, 0u32..14, 0u32..14), 0..20),
        h in -1.5f64..1.5,
    ) {
        let mesh = TriangleMesh {
            positions: points.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect(),
            faces: faces.iter().map(|&(a, b, c)| [a, b, c]).collect(),
            ..TriangleMesh::default()
        };
        let cfg = FragilityConfig { uncertainty: UncertaintyConfig { samples: 2, ..UncertaintyConfig::default() }, ..quick() };
        let _ = analyze(&mesh, ContactSpec::Auto, &cfg);
        let _ = analyze(&mesh, ContactSpec::Height(h), &cfg);
        let _ = analyze(&mesh, ContactSpec::Pedestal(&mesh), &cfg);
        let _ = cut_and_close(&mesh, [0.0, 0.0, 1.0], h);
    }
}

#[test]
fn a_given_contact_polygon_is_the_support() {
    // A 1 × 1 × 2 m block on a 0.5 m square contact under its centre, given 1 cm below the
    // block (as a scan's plane sits below its cut): α = atan(0.25 / 1.01) in the four face
    // directions.
    let block = to_mesh(&cuboid_solid([1.0, 1.0, 2.0]));
    let square = [
        [0.25, 0.25, -0.01],
        [0.75, 0.25, -0.01],
        [0.75, 0.75, -0.01],
        [0.25, 0.75, -0.01],
    ];
    let r = analyze(
        &block,
        ContactSpec::Polygon(&square),
        &FragilityConfig::default(),
    )
    .unwrap();
    assert_eq!(r.contact_method, ContactMethod::Polygon);
    assert!((r.contact_height_m + 0.01).abs() < 1e-12);
    assert!((r.contact_area_m2 - 0.25).abs() < 1e-9);
    let expected = 0.25f64.atan2(1.01).to_degrees();
    assert!(
        (r.alpha_min_deg - expected).abs() < 1e-6,
        "{} vs {expected}",
        r.alpha_min_deg
    );

    let line = [[0.0, 0.0, 0.0], [0.5, 0.5, 0.0], [1.0, 1.0, 0.0]];
    let flat = analyze(
        &block,
        ContactSpec::Polygon(&line),
        &FragilityConfig::default(),
    );
    assert!(
        matches!(flat, Err(FragilityError::Degenerate(_))),
        "{flat:?}"
    );
    let nan = [[f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let bad = analyze(
        &block,
        ContactSpec::Polygon(&nan),
        &FragilityConfig::default(),
    );
    assert!(matches!(bad, Err(FragilityError::Degenerate(_))), "{bad:?}");
}

/// Panics unless `report`'s α_min (of the rock `label` names) is within `tolerance_deg` of
/// `truth_deg` and its interval holds the truth.
pub(crate) fn assert_reads_within(
    label: &str,
    report: &FragilityReport,
    truth_deg: f64,
    tolerance_deg: f64,
) {
    assert!(
        (report.alpha_min_deg - truth_deg).abs() < tolerance_deg,
        "{label}: α_min {:.2}° against {truth_deg:.2}°",
        report.alpha_min_deg
    );
    assert!(
        report.alpha_min_low_deg <= truth_deg && truth_deg <= report.alpha_min_high_deg,
        "{label}: {truth_deg:.2}° outside [{:.2}, {:.2}]",
        report.alpha_min_low_deg,
        report.alpha_min_high_deg
    );
}

/// The rock's faces above `contact_height_m` and the pedestal's below it as one open mesh, every
/// triangle split in four `levels` times: a perfect scan of a world's target, as dense as a
/// map's (the support's top is found from its faces).
fn exact_scan(
    rock: &TriangleMesh,
    pedestal: &TriangleMesh,
    contact_height_m: f64,
    levels: u32,
) -> TriangleMesh {
    let keep = |mesh: &TriangleMesh, above: bool| -> Vec<[u32; 3]> {
        mesh.faces
            .iter()
            .filter(|f| {
                f.iter().all(|&i| {
                    let z = f64::from(mesh.positions[i as usize].z);
                    if above {
                        z >= contact_height_m - 0.002
                    } else {
                        z <= contact_height_m + 0.002
                    }
                })
            })
            .copied()
            .collect()
    };
    let offset = rock.positions.len() as u32;
    let positions = rock
        .positions
        .iter()
        .chain(&pedestal.positions)
        .copied()
        .collect();
    let faces = keep(rock, true)
        .into_iter()
        .chain(
            keep(pedestal, false)
                .into_iter()
                .map(|f| f.map(|i| i + offset)),
        )
        .collect();
    TriangleMesh::new(positions, faces)
        .unwrap()
        .subdivided(levels, nalgebra::center)
}

#[test]
fn the_scan_path_reads_the_worlds_targets_from_their_exact_surfaces() {
    // With no map in between, the scan path's error is the contact extrapolation's alone. On the
    // three worlds' 11 targets (the rocks its settings were chosen on) it holds within 1.2°, each
    // inside its interval. Library-a's slab on edge read +2.2° until session 48, whose rounded
    // edge the profile above the cut reads wide and the surface below it does not
    // (`ScanConfig::cap_by_low_reach`). It is the floor, not a proof of generality: on rocks of
    // random shape (`docs/campaigns/tools/fresh_shapes.py --exact`) 52 of 59 are within 2°.
    use scarp_datasets::world::{RockRole, World};
    let config = FragilityConfig::default();
    for name in ["default", "library-a", "library-b"] {
        let world = World::builtin(name).unwrap();
        for rock in world.rocks.iter().filter(|r| r.role == RockRole::Target) {
            let pedestal = rock.pedestal.as_ref().unwrap();
            let truth = analyze(&rock.mesh, ContactSpec::Pedestal(pedestal), &config).unwrap();
            let contact_height_m = rock.contact.as_ref().unwrap().height_m;
            let scan = exact_scan(&rock.mesh, pedestal, contact_height_m, 2);
            let (_, analysis) = scan::analyze_scan(&scan, &config).unwrap();
            let r = &analysis.report;
            let error = r.alpha_min_deg - truth.alpha_min_deg;
            println!(
                "{name} rock {}: {:.2}° [{:.2}, {:.2}] against {:.2}° ({:+.2}°)",
                rock.id,
                r.alpha_min_deg,
                r.alpha_min_low_deg,
                r.alpha_min_high_deg,
                truth.alpha_min_deg,
                error
            );
            assert_reads_within(
                &format!("{name} rock {}", rock.id),
                r,
                truth.alpha_min_deg,
                1.2,
            );
        }
    }
}
