//! The rock library and the built-in worlds: every built-in world builds with seated targets,
//! tilt matches a closed-form rocking angle, mirroring keeps volume, and bad keys name
//! themselves.

use std::collections::BTreeSet;
use std::path::Path;

use nalgebra::{Point2, Point3, Vector2};
use scarp_datasets::DatasetError;
use scarp_datasets::world::{
    BUILTIN_MESHES, BUILTIN_WORLDS, Rock, RockShape, STABILITY_MARGIN_FRACTION, World,
    builtin_world_names, load_mesh,
};
use scarp_slam::TriangleMesh;

/// The static rocking angle of a seated rock about each edge of its contact polygon: the
/// smallest, in degrees, and the outward unit normal of its edge (world x, y). For a rock on a
/// flat contact this is what the fragility analysis computes from the same polygon and centre
/// of mass.
fn alpha_min(rock: &Rock) -> (f64, Vector2<f64>) {
    let contact = rock.contact.as_ref().expect("a seated target");
    let polygon = &contact.polygon_xy_m;
    let com = Point2::new(rock.centroid.x, rock.centroid.y);
    let height = rock.centroid.z - contact.height_m;
    (0..polygon.len())
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            let edge = Vector2::new(b[0] - a[0], b[1] - a[1]);
            let outward = Vector2::new(edge.y, -edge.x).normalize();
            let inside = (Point2::new(a[0], a[1]) - com).dot(&outward);
            (inside.atan2(height).to_degrees(), outward)
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .expect("a contact polygon has edges")
}

fn world_from(text: &str, dir: &Path) -> Result<World, DatasetError> {
    World::from_toml_str(text, &dir.join("world.toml"), dir)
}

#[test]
fn builtin_worlds_build_with_seated_targets_and_unique_ids() {
    let names: Vec<&str> = builtin_world_names().collect();
    assert_eq!(names, ["default", "library-a", "library-b"]);
    for (name, _) in BUILTIN_WORLDS {
        let world = World::from_name_or_path(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(world.config.name, *name);
        let ids: BTreeSet<u32> = world.rocks.iter().map(|r| r.id).collect();
        assert_eq!(ids.len(), world.rocks.len(), "{name}: duplicate ids");
        let targets: Vec<&Rock> = world.targets().collect();
        assert!(targets.len() >= 3, "{name}");
        let (x0, y0, x1, y1) = world.heightfield.extent();
        for target in &targets {
            let what = format!("{name} rock {}", target.id);
            let contact = target.contact.as_ref().expect(&what);
            let pedestal = target.pedestal.as_ref().expect(&what);
            // The rock sits on the pedestal's flat top, which is its highest point.
            let (lo, _) = target.mesh.bounds().unwrap();
            assert!((f64::from(lo.z) - contact.height_m).abs() < 1e-4, "{what}");
            let top = pedestal.bounds().unwrap().1.z;
            assert!((f64::from(top) - contact.height_m).abs() < 1e-4, "{what}");
            // Stable, not balanced on an edge: the seating margin holds and α_min is in the
            // range the campaign expects of a standing PBR.
            let (alpha, _) = alpha_min(target);
            assert!((3.5..=16.0).contains(&alpha), "{what}: α_min {alpha}°");
            let margin = (alpha.to_radians().tan()) * (target.centroid.z - contact.height_m);
            assert!(
                margin > 0.9 * STABILITY_MARGIN_FRACTION * 0.2,
                "{what}: {margin} m"
            );
            if *name != "default" {
                // Inside the search pattern (inset 10 m) with room for the rings, and apart.
                let c = target.centroid;
                let edge = (c.x - x0).min(x1 - c.x).min(c.y - y0).min(y1 - c.y);
                assert!(edge >= 12.0, "{what}: {edge} m from the edge");
                for other in &targets {
                    let d = (other.centroid - c).xy().norm();
                    assert!(other.id == target.id || d >= 15.0, "{what}: {d} m");
                }
            }
        }
        if *name != "default" {
            // Smaller than the default's 120 m so a mission's search stays short.
            assert!(x1 - x0 <= 90.0 && y1 - y0 <= 90.0, "{name}");
            // A distractor stands beside one of the targets.
            let beside = world.rocks.iter().any(|d| {
                d.contact.is_none()
                    && targets.iter().any(|t| {
                        let dist = (t.centroid - d.centroid).xy().norm();
                        (4.0..=6.0).contains(&dist)
                    })
            });
            assert!(beside, "{name}: no distractor 4–6 m from a target");
        }
    }
}

#[test]
fn library_worlds_hold_every_library_shape() {
    let mut shapes = BTreeSet::new();
    for name in ["library-a", "library-b"] {
        let world = World::builtin(name).unwrap();
        for (rock, config) in world.rocks.iter().zip(&world.config.rocks) {
            if rock.contact.is_none() {
                continue;
            }
            let pedestal = config.pedestal.as_ref().unwrap();
            let shape = match &config.shape {
                RockShape::Mesh(m) if config.mirror => format!("{m} mirrored"),
                RockShape::Mesh(m) if config.tilt_deg.abs() >= 80.0 => format!("{m} on edge"),
                RockShape::Mesh(m) => m.clone(),
                RockShape::Block(b) if b.size_m[2] > 2.0 * b.size_m[0].max(b.size_m[1]) => {
                    "column".into()
                }
                RockShape::Block(b) if b.size_m[2] < 0.5 * b.size_m[0].max(b.size_m[1]) => {
                    "squat block".into()
                }
                RockShape::Block(_) => "block".into(),
                RockShape::Boulder(_) if pedestal.boulder.is_some() => "boulder on boulder".into(),
                RockShape::Boulder(_) => "boulder".into(),
            };
            shapes.insert(shape);
        }
    }
    for expected in [
        "builtin:double_rock",
        "builtin:double_rock mirrored",
        "builtin:stone_a0 on edge",
        "builtin:stone_e22",
        "builtin:stone_e34",
        "column",
        "squat block",
        "boulder on boulder",
    ] {
        assert!(
            shapes.contains(expected),
            "{expected} missing from {shapes:?}"
        );
    }
}

#[test]
fn boulder_pedestal_has_a_flat_top_under_the_contact_and_reaches_the_ground() {
    let world = World::builtin("library-b").unwrap();
    let (rock, config) = world
        .rocks
        .iter()
        .zip(&world.config.rocks)
        .find(|(_, c)| c.pedestal.as_ref().is_some_and(|p| p.boulder.is_some()))
        .expect("library-b has a boulder on a boulder");
    let pedestal = rock.pedestal.as_ref().unwrap();
    let contact = rock.contact.as_ref().unwrap();
    let top = contact.height_m as f32;
    let flat: Vec<Point2<f64>> = pedestal
        .positions
        .iter()
        .filter(|p| (p.z - top).abs() < 1e-5)
        .map(|p| Point2::new(f64::from(p.x), f64::from(p.y)))
        .collect();
    let hull = scarp_slam::geometry::convex_hull_2d(&flat);
    // Every contact corner lies on the pedestal's flat top.
    for c in &contact.polygon_xy_m {
        let inside = (0..hull.len()).all(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            (b - a).perp(&(Point2::new(c[0], c[1]) - a)) >= -1e-9
        });
        assert!(inside, "contact corner {c:?} off the boulder's top");
    }
    let [x, y] = config.position_m;
    let ground = world.terrain_height_m(x, y);
    let bottom = f64::from(pedestal.bounds().unwrap().0.z);
    assert!(bottom < ground - 0.3, "bottom {bottom} vs ground {ground}");
    assert!(pedestal.volume_properties().unwrap().volume_m3 > 1.0);
}

/// A box `a × b × c` (x, y, z) centred on the origin, as a prism along x: its y–z section is
/// the rectangle with `rows − 1` extra vertices along the bottom edge (so the flattened contact
/// is an exact rectangle), extruded in `segments` steps along x, with fan caps.
fn prism_box(a: f32, b: f32, c: f32, rows: usize, segments: usize) -> TriangleMesh {
    // Counter-clockwise in (y, z): bottom +y corner, top +y, top −y, bottom −y, then the bottom
    // edge back toward +y.
    let mut section = vec![(b / 2.0, -c / 2.0), (b / 2.0, c / 2.0), (-b / 2.0, c / 2.0)];
    section.extend((0..rows).map(|j| (-b / 2.0 + b * j as f32 / rows as f32, -c / 2.0)));
    let n = section.len();
    let mut mesh = TriangleMesh::default();
    for k in 0..=segments {
        let x = -a / 2.0 + a * k as f32 / segments as f32;
        mesh.positions
            .extend(section.iter().map(|&(y, z)| Point3::new(x, y, z)));
    }
    let index = |k: usize, i: usize| (k * n + i % n) as u32;
    for k in 0..segments {
        for i in 0..n {
            let (a0, b0) = (index(k, i), index(k, i + 1));
            let (c1, d1) = (index(k + 1, i + 1), index(k + 1, i));
            mesh.faces.push([a0, b0, c1]);
            mesh.faces.push([a0, c1, d1]);
        }
    }
    for (k, x) in [(0, -a / 2.0), (segments, a / 2.0)] {
        let centre = mesh.positions.len() as u32;
        mesh.positions.push(Point3::new(x, 0.0, 0.0));
        for i in 0..n {
            let (p, q) = (index(k, i), index(k, i + 1));
            mesh.faces.push(if k == 0 {
                [centre, q, p]
            } else {
                [centre, p, q]
            });
        }
    }
    mesh
}

fn polygon_centroid(polygon: &[(f64, f64)]) -> (f64, f64) {
    let (mut area2, mut cy, mut cz) = (0.0, 0.0, 0.0);
    for i in 0..polygon.len() {
        let ((y0, z0), (y1, z1)) = (polygon[i], polygon[(i + 1) % polygon.len()]);
        let cross = y0 * z1 - y1 * z0;
        area2 += cross;
        cy += (y0 + y1) * cross;
        cz += (z0 + z1) * cross;
    }
    (cy / (3.0 * area2), cz / (3.0 * area2))
}

/// A box tilted by θ leans on its lowest bottom edge; seating flattens the bottom face up to
/// the first row of vertices where the contact's half-diagonal reaches `contact_radius_m`, so
/// the rock's section is a known pentagon and its rocking angle toward the lean has a closed
/// form. Checked for a lean to the north, to the east after a 90° yaw (yaw turns the mesh
/// first, tilt then leans it in the world frame), and a negative tilt.
#[test]
fn tilted_box_stands_at_its_closed_form_rocking_angle() {
    let (a, b, c) = (0.4f64, 0.5f64, 1.5f64);
    let (rows, contact_radius) = (50usize, 0.25f64);
    let theta = 12f64.to_radians();
    let dir = tempfile::tempdir().unwrap();
    scarp_export::ply::write_mesh(
        dir.path().join("box.ply"),
        &prism_box(a as f32, b as f32, c as f32, rows, 8),
        scarp_export::ply::PlyEncoding::BinaryLittleEndian,
    )
    .unwrap();

    // The closed form, in the box's section plane: horizontal s along the lean, z up.
    let (sin, cos) = theta.sin_cos();
    let tilt = |(y, z): (f64, f64)| (y * cos + z * sin, -y * sin + z * cos);
    let height = b * sin + c * cos;
    let (edge_s, edge_z) = tilt((b / 2.0, -c / 2.0));
    // Row j of the bottom face sits j·step up the face from the lowest edge.
    let step = b / rows as f64;
    let width = |j: usize| j as f64 * step * cos;
    let row = (0..=rows)
        .find(|&j| 0.5 * (a * a + width(j).powi(2)).sqrt() >= contact_radius)
        .unwrap();
    // The binding row is clear of the threshold, so float rounding cannot move it.
    assert!(0.5 * (a * a + width(row - 1).powi(2)).sqrt() < contact_radius - 1e-4);
    let cut_z = edge_z + row as f64 * step * sin;
    let section = [
        (edge_s, cut_z),
        tilt((b / 2.0, c / 2.0)),
        tilt((-b / 2.0, c / 2.0)),
        tilt((-b / 2.0, -c / 2.0)),
        (edge_s - width(row), cut_z),
    ];
    let (com_s, com_z) = polygon_centroid(&section);
    let lean_arm = edge_s - com_s;
    let com_height = com_z - cut_z;
    let expected_alpha = lean_arm.atan2(com_height).to_degrees();
    // The seating's centre-of-mass margin holds at this row, so it is where the cut stops,
    // and the lean is the weakest direction.
    let margin = STABILITY_MARGIN_FRACTION * contact_radius;
    let back_arm = com_s - (edge_s - width(row));
    assert!(lean_arm > margin && back_arm > margin && a / 2.0 > margin);
    assert!(lean_arm < back_arm && lean_arm < a / 2.0);
    assert!((5.0..8.0).contains(&expected_alpha), "{expected_alpha}");

    for (yaw, tilt_deg, azimuth, lean) in [
        (0.0, 12.0, 0.0, Vector2::new(0.0, 1.0)),
        (90.0, 12.0, 90.0, Vector2::new(1.0, 0.0)),
        (0.0, -12.0, 0.0, Vector2::new(0.0, -1.0)),
    ] {
        let world = world_from(
            &format!(
                r#"
                [terrain.procedural]
                size_m = 10.0
                resolution_m = 0.5
                scarp_height_m = 0.0
                roughness_m = 0.0

                [[rocks]]
                id = 1
                role = "target"
                position_m = [1.0, -2.0]
                yaw_deg = {yaw}
                tilt_deg = {tilt_deg}
                tilt_azimuth_deg = {azimuth}
                height_m = {height}
                shape = {{ mesh = "box.ply" }}
                pedestal = {{ height_m = 1.0, top_radius_m = 0.4 }}
                contact_radius_m = {contact_radius}
                "#
            ),
            dir.path(),
        )
        .unwrap();
        let rock = world.rock(1).unwrap();
        let case = format!("yaw {yaw}, tilt {tilt_deg} toward {azimuth}");
        let contact = rock.contact.as_ref().unwrap();
        // The flattened section's centre of mass above the contact …
        assert!(
            (rock.centroid.z - contact.height_m - com_height).abs() < 2e-5,
            "{case}: {} vs {com_height}",
            rock.centroid.z - contact.height_m
        );
        // … and its lever arm to the contact's edge on the lean side.
        let com = Vector2::new(rock.centroid.x, rock.centroid.y);
        let lean_edge = contact
            .polygon_xy_m
            .iter()
            .map(|p| Vector2::new(p[0], p[1]).dot(&lean))
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(
            (lean_edge - com.dot(&lean) - lean_arm).abs() < 2e-5,
            "{case}: arm {} vs {lean_arm}",
            lean_edge - com.dot(&lean)
        );
        // The contact is the flattened strip: the box's length by the rows' width.
        assert!(
            (contact.area_m2 - a * width(row)).abs() < 1e-4,
            "{case}: {}",
            contact.area_m2
        );
        // The rock is weakest toward its lean, at the closed-form angle.
        let (alpha, toward) = alpha_min(rock);
        assert!(
            (alpha - expected_alpha).abs() < 2e-3,
            "{case}: α_min {alpha}° vs {expected_alpha}°"
        );
        assert!(
            toward.dot(&lean) > 0.9999,
            "{case}: topples toward {toward:?}"
        );
        // The vertical extent before the flat cut is `height_m`.
        let cut = row as f64 * step * sin;
        assert!((rock.height_m - (height - cut)).abs() < 1e-4, "{case}");
    }
}

#[test]
fn mirrored_rocks_keep_their_volume_and_mirror_their_centroid() {
    let dir = tempfile::tempdir().unwrap();
    let rocks = |mirror: bool| {
        world_from(
            &format!(
                r#"
                [terrain.procedural]
                size_m = 20.0
                resolution_m = 0.5
                scarp_height_m = 0.0
                roughness_m = 0.0

                [[rocks]]
                id = 1
                role = "distractor"
                position_m = [2.0, 3.0]
                mirror = {mirror}
                height_m = 1.2
                shape = {{ boulder = {{ seed = 9, radii_m = [0.9, 0.5, 0.7], subdivisions = 4 }} }}

                [[rocks]]
                id = 2
                role = "target"
                position_m = [-4.0, -4.0]
                yaw_deg = 20.0
                mirror = {mirror}
                height_m = 1.5
                shape = {{ mesh = "builtin:double_rock" }}
                pedestal = {{ height_m = 1.1, top_radius_m = 0.36 }}
                contact_radius_m = 0.22
                "#
            ),
            dir.path(),
        )
        .unwrap()
    };
    let (plain, mirrored) = (rocks(false), rocks(true));
    // The boulder rests on flat ground centred on its position: its centroid's offset from
    // there flips across y, its volume is unchanged and positive.
    let (p, m) = (plain.rock(1).unwrap(), mirrored.rock(1).unwrap());
    assert!(m.volume_m3 > 0.0);
    assert!((m.volume_m3 / p.volume_m3 - 1.0).abs() < 1e-6);
    let (dp, dm) = (
        p.centroid - Point3::new(2.0, 3.0, 0.0),
        m.centroid - Point3::new(2.0, 3.0, 0.0),
    );
    assert!(dp.y.abs() > 1e-3, "the boulder is not symmetric: {dp:?}");
    assert!((dm.x - dp.x).abs() < 1e-5 && (dm.y + dp.y).abs() < 1e-5 && (dm.z - dp.z).abs() < 1e-5);
    // The mirrored double rock is a new rock with the same rocking angle, mirrored in
    // direction (yaw 20° turns the mirror plane with it).
    let (p, m) = (plain.rock(2).unwrap(), mirrored.rock(2).unwrap());
    assert!((m.volume_m3 / p.volume_m3 - 1.0).abs() < 1e-5);
    let ((alpha_p, toward_p), (alpha_m, toward_m)) = (alpha_min(p), alpha_min(m));
    assert!((alpha_p - alpha_m).abs() < 1e-3, "{alpha_p} vs {alpha_m}");
    let yaw = 20f64.to_radians();
    let mirror_axis = Vector2::new(yaw.cos(), yaw.sin());
    let reflected = 2.0 * toward_p.dot(&mirror_axis) * mirror_axis - toward_p;
    assert!(
        reflected.dot(&toward_m) > 0.999,
        "{toward_p:?} → {toward_m:?}"
    );
}

#[test]
fn builtin_meshes_load_closed_and_wound_outwards() {
    for builtin in BUILTIN_MESHES {
        let source = format!("builtin:{}", builtin.name);
        let mesh = load_mesh(&source, Path::new(".")).unwrap();
        mesh.validate().unwrap();
        assert!(mesh.face_count() >= 5000, "{source}: {}", mesh.face_count());
        assert!(
            mesh.volume_properties().unwrap().volume_m3 > 0.0,
            "{source}"
        );
        // Closed: every directed edge has its reverse exactly once.
        let mut edges = std::collections::HashMap::new();
        for f in &mesh.faces {
            for (u, v) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                *edges.entry((u, v)).or_insert(0) += 1;
            }
        }
        assert!(
            edges
                .iter()
                .all(|(&(u, v), &n)| n == 1 && edges.get(&(v, u)) == Some(&1)),
            "{source} is not closed"
        );
    }
}

#[test]
fn bad_rock_keys_name_themselves() {
    let dir = tempfile::tempdir().unwrap();
    let with = |extra: &str, shape: &str| {
        world_from(
            &format!(
                r#"
                [terrain.procedural]
                size_m = 10.0
                resolution_m = 0.5

                [[rocks]]
                id = 1
                role = "distractor"
                position_m = [0.0, 0.0]
                height_m = 1.0
                shape = {shape}
                {extra}
                "#
            ),
            dir.path(),
        )
        .map(|_| ())
        .unwrap_err()
        .to_string()
    };
    let boulder = "{ boulder = { subdivisions = 3 } }";
    let message = with("tilt = 10.0", boulder);
    assert!(message.contains("unknown field `tilt`"), "{message}");
    let message = with("tilt_deg = 120.0", boulder);
    assert!(message.contains("rocks[0].tilt_deg"), "{message}");
    let message = with("tilt_deg = nan", boulder);
    assert!(message.contains("rocks[0].tilt_deg"), "{message}");
    let message = with("tilt_azimuth_deg = inf", boulder);
    assert!(message.contains("rocks[0].tilt_azimuth_deg"), "{message}");
    let message = with("", "{ block = { squareness = 1.0 } }");
    assert!(
        message.contains("rocks[0].shape.block.squareness"),
        "{message}"
    );
    let message = with("", "{ block = { size = [1.0, 1.0, 1.0] } }");
    assert!(message.contains("unknown field `size`"), "{message}");
    let message = with("", "{ mesh = \"builtin:granite\" }");
    for builtin in BUILTIN_MESHES {
        assert!(
            message.contains(&format!("builtin:{}", builtin.name)),
            "{message}"
        );
    }
    let message = with(
        "pedestal = { top_radius_m = 1.5, boulder = { radii_m = [1.0, 0.9, 0.8] } }\ncontact_radius_m = 0.2",
        boulder,
    );
    assert!(
        message.contains("rocks[0].pedestal.top_radius_m"),
        "{message}"
    );
    let message = World::builtin("library-z").unwrap_err().to_string();
    assert!(
        message.contains("default")
            && message.contains("library-a")
            && message.contains("library-b"),
        "{message}"
    );
}

#[test]
fn readme_library_example_builds() {
    let readme = include_str!("../README.md");
    let after = readme
        .find("A world using the library")
        .expect("README has the library example");
    let start = after + readme[after..].find("```toml\n").expect("a TOML block") + 8;
    let end = start + readme[start..].find("```").expect("closed block");
    let world =
        World::from_toml_str(&readme[start..end], Path::new("README.md"), Path::new(".")).unwrap();
    assert_eq!(world.rocks.len(), 3);
    assert_eq!(world.targets().count(), 2);
    assert!(world.targets().all(|t| alpha_min(t).0 > 3.0));
}
