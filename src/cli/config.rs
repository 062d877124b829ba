//! `scarp config`: print every tunable with its default, as TOML.

use clap::Args;
use serde::Serialize;

/// Print the default configuration of every stage as TOML.
#[derive(Debug, Args)]
pub struct ConfigArgs {}

/// Every stage's tunables, grouped as in a configuration file.
#[derive(Debug, Default, Serialize)]
pub struct AllDefaults {
    /// Depth and colour sensor noise of rendered sequences.
    pub sensor: scarp_datasets::sensor::SensorConfig,
    /// State-estimator (GPS/IMU) error of rendered sequences.
    pub estimator: scarp_datasets::estimator::EstimatorConfig,
    /// Paths, trajectories, control and flight.
    pub planning: scarp_planning::PlanningConfig,
    /// Fragility analysis.
    pub fragility: crate::fragility::FragilityConfig,
    /// Target detectors.
    pub detection: DetectionDefaults,
}

/// The detectors' tunables.
#[derive(Debug, Default, Serialize)]
pub struct DetectionDefaults {
    /// The modelled detector of synthetic sequences.
    pub simulated: crate::detection::SimulatedDetectorConfig,
    /// The ONNX YOLO detector (cargo feature `onnx`).
    pub onnx: crate::detection::OnnxDetectorConfig,
}

/// The defaults as TOML text.
///
/// # Errors
/// Only if a configuration type could not be expressed in TOML.
pub fn defaults_toml() -> anyhow::Result<String> {
    Ok(format!(
        "# scarp defaults: every tunable, with the value used when a configuration omits it.\n{}",
        toml::to_string_pretty(&AllDefaults::default())?
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
        for section in ["sensor", "estimator", "planning", "fragility", "detection"] {
            assert!(value.contains_key(section), "{section}");
        }
        let sensor: scarp_datasets::sensor::SensorConfig =
            value["sensor"].clone().try_into().unwrap();
        assert_eq!(sensor, scarp_datasets::sensor::SensorConfig::default());
        assert_eq!(value["sensor"]["baseline_m"].as_float(), Some(0.12));
        let simulated: crate::detection::SimulatedDetectorConfig =
            value["detection"]["simulated"].clone().try_into().unwrap();
        assert_eq!(
            simulated,
            crate::detection::SimulatedDetectorConfig::default()
        );
    }
}
