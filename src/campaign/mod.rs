//! Campaigns: the same mission over many worlds and seeds, and the tables that say how often it
//! meets its must-shows.
//!
//! A campaign is a folder. Every (world, seed) run is an ordinary mission folder under
//! `runs/<world>/seed-<seed>/`, written by `scarp simulate`, and the campaign's tables
//! (`campaign.json`, `campaign.md`) are computed from those folders' own `mission.json` and
//! `world_gt/world.json` files alone. So a table can always be checked against its runs, a
//! campaign can be resumed (a run whose `mission.json` exists and was not interrupted is done),
//! and shards run on different machines can be merged by collecting their run folders.
//!
//! - [`plan`]: which runs a campaign (or one shard of it) holds, and where they live.
//! - [`table`]: one row per true target per run, and the totals.
//! - [`markdown`]: renders `campaign.md`.
//!
//! ```
//! use scarp::campaign::plan::{parse_seeds, plan_runs, Shard};
//! let seeds = parse_seeds("0-3,7").unwrap();
//! let runs = plan_runs(&["default".to_string(), "library-a".to_string()], &seeds);
//! assert_eq!(runs.len(), 10);
//! // Two shards split the runs between them, every run exactly once.
//! let a = Shard::parse("0/2").unwrap().select(&runs);
//! let b = Shard::parse("1/2").unwrap().select(&runs);
//! assert_eq!(a.len() + b.len(), runs.len());
//! assert_eq!(runs[0].dir().to_str(), Some("runs/default/seed-0"));
//! ```

pub mod markdown;
pub mod plan;
pub mod table;

use std::path::PathBuf;

/// What can go wrong in a campaign's bookkeeping.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    /// A command-line value (seeds, shard, worlds) that does not parse.
    #[error("{what}: `{value}`: {message}")]
    Parse {
        /// Which value.
        what: &'static str,
        /// The text given.
        value: String,
        /// What is wrong with it.
        message: String,
    },
    /// A file that cannot be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A JSON file that does not parse or lacks a field.
    #[error("{}: {message}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Folders that cannot be merged, or a campaign folder reused with another configuration.
    #[error("{0}")]
    Inconsistent(String),
}

impl CampaignError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn json(path: impl Into<PathBuf>, message: impl std::fmt::Display) -> Self {
        Self::Json {
            path: path.into(),
            message: message.to_string(),
        }
    }
}

use std::path::Path;

use serde::{Deserialize, Serialize};

use plan::{RunSpec, Shard};
use table::{RunRow, TargetRow, Totals};

/// `campaign.json`: what was planned, every run, every true target, and the totals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CampaignReport {
    /// The scarp version that wrote the tables.
    pub scarp_version: String,
    /// Worlds, as given to `--worlds`.
    pub worlds: Vec<String>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// The mission configuration every run used (TOML text; `None`: the defaults).
    pub config_toml: Option<String>,
    /// The shard this folder holds (`None`: the whole plan, or a merge).
    pub shard: Option<Shard>,
    /// The folders a merge collected.
    pub merged_from: Vec<String>,
    /// Wall time of the `scarp campaign` call that wrote this file, seconds (`None` for a merge).
    pub wall_time_s: Option<f64>,
    /// The runs this folder holds, in plan order.
    pub plan: Vec<RunSpec>,
    /// The totals.
    pub totals: Totals,
    /// One row per run.
    pub runs: Vec<RunRow>,
    /// One row per true target per run.
    pub targets: Vec<TargetRow>,
}

/// What resuming and merging need of an existing `campaign.json`: its configuration and its
/// plan. Read on its own so that a folder tabulated by another scarp version (whose totals
/// have other fields) still resumes and merges.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct CampaignHeader {
    /// The mission configuration every run used (`None`: the defaults).
    pub config_toml: Option<String>,
    /// The runs the folder holds.
    pub plan: Vec<RunSpec>,
}

impl CampaignHeader {
    /// Reads the header of `dir/campaign.json`.
    ///
    /// # Errors
    /// A missing or malformed file, naming it.
    pub fn read(dir: &Path) -> Result<Self, CampaignError> {
        read_json_file(&dir.join(CAMPAIGN_JSON))
    }
}

/// Reads and parses a JSON file, naming it in any error.
pub(crate) fn read_json_file<T: serde::de::DeserializeOwned>(
    path: &Path,
) -> Result<T, CampaignError> {
    let bytes = std::fs::read(path).map_err(|e| CampaignError::io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| CampaignError::json(path, e))
}

/// The file names a campaign folder holds besides `runs/`.
pub const CAMPAIGN_JSON: &str = "campaign.json";
/// The human-readable tables.
pub const CAMPAIGN_MD: &str = "campaign.md";

impl CampaignReport {
    /// Reads every run of `plan` under `dir` and computes the tables.
    ///
    /// # Errors
    /// A run's `mission.json` or `world.json` that exists but does not parse.
    pub fn collect(
        dir: &Path,
        plan: Vec<RunSpec>,
        config_toml: Option<String>,
        shard: Option<Shard>,
    ) -> Result<Self, CampaignError> {
        let (runs, targets) = table::read_runs(dir, &plan)?;
        let mut worlds: Vec<String> = Vec::new();
        for r in &plan {
            if !worlds.contains(&r.world) {
                worlds.push(r.world.clone());
            }
        }
        let mut seeds: Vec<u64> = plan.iter().map(|r| r.seed).collect();
        seeds.sort_unstable();
        seeds.dedup();
        Ok(Self {
            scarp_version: env!("CARGO_PKG_VERSION").into(),
            worlds,
            seeds,
            config_toml,
            shard,
            merged_from: Vec::new(),
            wall_time_s: None,
            totals: table::totals(&runs, &targets),
            plan,
            runs,
            targets,
        })
    }

    /// Reads `dir/campaign.json`.
    ///
    /// # Errors
    /// A missing or malformed file, naming it.
    pub fn read(dir: &Path) -> Result<Self, CampaignError> {
        read_json_file(&dir.join(CAMPAIGN_JSON))
    }

    /// Writes `campaign.json` and `campaign.md` into `dir`, each atomically.
    ///
    /// # Errors
    /// File-system errors naming the file.
    pub fn write(&self, dir: &Path) -> Result<(), CampaignError> {
        let json = serde_json::to_string_pretty(self)
            .map_err(|e| CampaignError::json(dir.join(CAMPAIGN_JSON), e))?;
        for (name, text) in [(CAMPAIGN_JSON, json), (CAMPAIGN_MD, markdown::render(self))] {
            let path = dir.join(name);
            scarp_export::atomic::write_bytes_atomically(&path, text.as_bytes())
                .map_err(|e| CampaignError::io(&path, std::io::Error::other(e.to_string())))?;
        }
        Ok(())
    }
}
