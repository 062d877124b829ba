//! The default world's targets are real precariously balanced rocks: each stands on its pedestal
//! (its centre of mass over the contact), with a small rocking angle, and the analysis agrees with
//! the world's own contact description.

use scarp::fragility::{ContactSpec, FragilityConfig, analyze};
use scarp_datasets::world::World;

#[test]
fn default_world_targets_stand_and_are_precarious() {
    let world = World::builtin_default().unwrap();
    let config = FragilityConfig::default();
    for target in world.targets() {
        let pedestal = target.pedestal.as_ref().unwrap();
        let report = analyze(&target.mesh, ContactSpec::Pedestal(pedestal), &config)
            .unwrap_or_else(|e| panic!("rock {}: {e}", target.id));
        let contact = target.contact.as_ref().unwrap();
        assert!(
            (report.contact_height_m - contact.height_m).abs() < 0.02,
            "rock {}",
            target.id
        );
        // Standing (α_min > 0 with margin) yet precarious (a small toppling acceleration).
        assert!(
            report.alpha_min_deg > 2.0 && report.alpha_min_deg < 20.0,
            "rock {}: α_min {}",
            target.id,
            report.alpha_min_deg
        );
        let com_error =
            (nalgebra::Vector3::from(report.center_of_mass) - target.centroid.coords).norm();
        assert!(
            com_error < 0.01,
            "rock {}: centre of mass differs by {com_error} m",
            target.id
        );
    }
}
