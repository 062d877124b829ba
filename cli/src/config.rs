//! `scarp config`: print every tunable with its default, as TOML.

use clap::Args;

/// Print the default configuration of every stage as TOML.
#[derive(Debug, Args)]
pub struct ConfigArgs {}

/// The defaults as TOML text.
///
/// # Errors
/// Only if a configuration type could not be expressed in TOML.
pub fn defaults_toml() -> anyhow::Result<String> {
    Ok(format!(
        "# scarp defaults: every tunable, with the value used when a configuration omits it.\n# Save as mission.toml, keep what you change, and run `scarp simulate --config mission.toml`.\n{}",
        toml::to_string_pretty(&scarp::mission::config::MissionConfig::default())?
    ))
}

/// Runs `scarp config`.
///
/// # Errors
/// As [`defaults_toml`].
pub fn run(_args: ConfigArgs) -> anyhow::Result<()> {
    print!("{}", defaults_toml()?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_print_and_parse_back() {
        let text = defaults_toml().unwrap();
        let value: toml::Table = toml::from_str(&text).unwrap();
        for section in [
            "sensor",
            "estimator",
            "planning",
            "fragility",
            "detection",
            "localization",
            "tracker",
        ] {
            assert!(value.contains_key(section), "{section}");
        }
        let sensor: scarp_datasets::sensor::SensorConfig =
            value["sensor"].clone().try_into().unwrap();
        assert_eq!(sensor, scarp_datasets::sensor::SensorConfig::default());
        assert_eq!(value["sensor"]["baseline_m"].as_float(), Some(0.12));
        let simulated: scarp::detection::SimulatedDetectorConfig =
            value["detection"]["simulated"].clone().try_into().unwrap();
        assert_eq!(
            simulated,
            scarp::detection::SimulatedDetectorConfig::default()
        );
        let localization: scarp::localization::LocalizationConfig =
            value["localization"].clone().try_into().unwrap();
        assert_eq!(
            localization,
            scarp::localization::LocalizationConfig::default()
        );
        let tracker: scarp::tracking::TrackerConfig = value["tracker"].clone().try_into().unwrap();
        assert_eq!(tracker, scarp::tracking::TrackerConfig::default());
    }
}
