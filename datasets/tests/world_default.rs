//! The built-in default world matches its description.

use scarp_datasets::world::{RockRole, World};

#[test]
fn default_world_has_precarious_targets_and_distractors() {
    let world = World::builtin_default().unwrap();
    let (x0, y0, x1, y1) = world.heightfield.extent();
    assert!((x1 - x0 - 120.0).abs() < 1.0 && (y1 - y0 - 120.0).abs() < 1.0);
    let targets: Vec<_> = world.targets().collect();
    assert_eq!(targets.len(), 3);
    assert!(
        world
            .rocks
            .iter()
            .filter(|r| r.role == RockRole::Distractor)
            .count()
            >= 10
    );
    // Target 1 is the scanned double rock at about 1.5 m.
    assert!(
        (targets[0].height_m - 1.5).abs() < 0.05,
        "{}",
        targets[0].height_m
    );
    assert!(targets[0].mesh.face_count() > 40_000);
    for target in &targets {
        let contact = target.contact.as_ref().expect("targets sit on pedestals");
        let (lo, hi) = target.mesh.bounds().unwrap();
        // Seated exactly on the pedestal's flat top.
        assert!((f64::from(lo.z) - contact.height_m).abs() < 1e-4);
        let pedestal_top = target.pedestal.as_ref().unwrap().bounds().unwrap().1.z;
        assert!((f64::from(pedestal_top) - contact.height_m).abs() < 1e-4);
        // Precarious: the contact is a small fraction of the rock's footprint, and the rock's
        // centre of mass is well above it.
        let footprint = f64::from((hi.x - lo.x) * (hi.y - lo.y));
        assert!(
            contact.area_m2 < 0.1 * footprint,
            "contact {} m² vs footprint {footprint} m²",
            contact.area_m2
        );
        assert!(target.centroid.z - contact.height_m > 0.4);
        assert!(target.volume_m3 > 0.1);
        // Statically stable: the centre of mass stands inside the contact polygon, with margin.
        let polygon = &contact.polygon_xy_m;
        let margin = (0..polygon.len())
            .map(|i| {
                let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
                let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
                (ex * (target.centroid.y - a[1]) - ey * (target.centroid.x - a[0])) / ex.hypot(ey)
            })
            .fold(f64::INFINITY, f64::min);
        assert!(
            margin > 0.02,
            "rock {}: centre of mass {margin} m inside the contact edge",
            target.id
        );
    }
}

#[test]
fn readme_world_example_builds() {
    let readme = include_str!("../README.md");
    let start = readme.find("```toml\n").expect("README has a TOML example") + "```toml\n".len();
    let end = start + readme[start..].find("```").expect("closed block");
    let world = World::from_toml_str(
        &readme[start..end],
        std::path::Path::new("README.md"),
        std::path::Path::new("."),
    )
    .unwrap();
    assert_eq!(world.config.name, "granite-pass");
    assert_eq!(world.rocks.len(), 2);
    assert!((world.rock(1).unwrap().height_m - 1.5).abs() < 0.01);
    assert_eq!(world.rock(10).unwrap().role, RockRole::Distractor);
}
