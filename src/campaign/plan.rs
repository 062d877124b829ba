//! Which runs a campaign holds, where each lives, and whether it is done.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::CampaignError;

/// One mission of a campaign: a world and a seed.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct RunSpec {
    /// The world as given to `scarp simulate --world`: a built-in name or a TOML path.
    pub world: String,
    /// The mission seed.
    pub seed: u64,
}

impl RunSpec {
    /// The run's folder relative to the campaign folder: `runs/<world label>/seed-<seed>`.
    pub fn dir(&self) -> PathBuf {
        Path::new("runs")
            .join(world_label(&self.world))
            .join(format!("seed-{}", self.seed))
    }
}

/// A world's name in folder names and tables: a built-in name as it is, a file by its stem,
/// with anything but ASCII letters, digits, `-` and `_` replaced by `_`.
pub fn world_label(world: &str) -> String {
    let stem = if world.ends_with(".toml") || world.contains(['/', '\\']) {
        Path::new(world)
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or(world)
    } else {
        world
    };
    stem.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Parses a seed list: comma-separated seeds and inclusive ranges, `0-9` or `0-4,7,10-12`.
/// Duplicates are dropped; the order is ascending.
///
/// # Errors
/// [`CampaignError::Parse`] for an empty list, a non-number, or a range whose end is below its
/// start.
pub fn parse_seeds(text: &str) -> Result<Vec<u64>, CampaignError> {
    let error = |message: &str| CampaignError::Parse {
        what: "--seeds",
        value: text.into(),
        message: message.into(),
    };
    let mut seeds = std::collections::BTreeSet::new();
    for part in text.split(',').map(str::trim) {
        if part.is_empty() {
            return Err(error("empty item; expected e.g. `0-9` or `0,3,5-7`"));
        }
        let (lo, hi) = match part.split_once('-') {
            Some((a, b)) => (a.trim(), b.trim()),
            None => (part, part),
        };
        let parse = |s: &str| {
            s.parse::<u64>()
                .map_err(|_| error(&format!("`{s}` is not a non-negative whole number")))
        };
        let (lo, hi) = (parse(lo)?, parse(hi)?);
        if hi < lo {
            return Err(error(&format!("range {lo}-{hi} ends below its start")));
        }
        if hi - lo >= 1_000_000 {
            return Err(error("a range of a million seeds or more is surely a typo"));
        }
        seeds.extend(lo..=hi);
    }
    Ok(seeds.into_iter().collect())
}

/// Parses a comma-separated world list (built-in names or TOML paths), dropping repeats.
///
/// # Errors
/// [`CampaignError::Parse`] for an empty list or item, or two different worlds whose labels
/// ([`world_label`]) would share a folder.
pub fn parse_worlds(text: &str) -> Result<Vec<String>, CampaignError> {
    let mut worlds: Vec<String> = Vec::new();
    for part in text.split(',').map(str::trim) {
        if part.is_empty() {
            return Err(CampaignError::Parse {
                what: "--worlds",
                value: text.into(),
                message: "empty item; expected e.g. `default,library-a`".into(),
            });
        }
        if worlds.iter().any(|w| w == part) {
            continue;
        }
        if let Some(other) = worlds.iter().find(|w| world_label(w) == world_label(part)) {
            return Err(CampaignError::Parse {
                what: "--worlds",
                value: text.into(),
                message: format!(
                    "`{other}` and `{part}` would share the folder runs/{}; rename one file",
                    world_label(part)
                ),
            });
        }
        worlds.push(part.to_string());
    }
    Ok(worlds)
}

/// Every (world, seed) pair, world by world.
pub fn plan_runs(worlds: &[String], seeds: &[u64]) -> Vec<RunSpec> {
    worlds
        .iter()
        .flat_map(|w| {
            seeds.iter().map(move |&seed| RunSpec {
                world: w.clone(),
                seed,
            })
        })
        .collect()
}

/// One shard of a campaign: run `index`, `index + count`, `index + 2·count`, … of the plan,
/// so that a job array of N tasks covers it with no scheduler of ours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This shard, 0-based.
    pub index: usize,
    /// How many shards.
    pub count: usize,
}

impl Shard {
    /// Parses `I/N` with 0 ≤ I < N.
    ///
    /// # Errors
    /// [`CampaignError::Parse`] naming what is wrong.
    pub fn parse(text: &str) -> Result<Self, CampaignError> {
        let error = |message: &str| CampaignError::Parse {
            what: "--shard",
            value: text.into(),
            message: message.into(),
        };
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| error("expected I/N, e.g. 0/4"))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| error("I is not a whole number"))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| error("N is not a whole number"))?;
        if count == 0 || index >= count {
            return Err(error("needs 0 ≤ I < N"));
        }
        Ok(Self { index, count })
    }

    /// The runs of `plan` that belong to this shard, in plan order.
    pub fn select(&self, plan: &[RunSpec]) -> Vec<RunSpec> {
        plan.iter()
            .skip(self.index)
            .step_by(self.count)
            .cloned()
            .collect()
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Whether the run in `run_dir` is finished: its `mission.json` exists, parses, and does not
/// say it was interrupted. A run that failed or was stopped is run again on resume.
pub fn run_is_finished(run_dir: &Path) -> bool {
    let Ok(bytes) = std::fs::read(run_dir.join("mission.json")) else {
        return false;
    };
    serde_json::from_slice::<serde_json::Value>(&bytes).is_ok_and(|json| mission_is_finished(&json))
}

/// Whether a parsed `mission.json` is a finished run's: it says it was not interrupted.
pub fn mission_is_finished(mission: &serde_json::Value) -> bool {
    mission.get("interrupted").and_then(|v| v.as_bool()) == Some(false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_ranges_and_errors() {
        assert_eq!(parse_seeds("0-3").unwrap(), vec![0, 1, 2, 3]);
        assert_eq!(parse_seeds("5, 1-2,2").unwrap(), vec![1, 2, 5]);
        assert_eq!(parse_seeds("7").unwrap(), vec![7]);
        for bad in ["", "1,", "a", "3-1", "-2", "0-99999999"] {
            let err = parse_seeds(bad).unwrap_err().to_string();
            assert!(err.contains("--seeds"), "{bad}: {err}");
        }
    }

    #[test]
    fn shards_partition_the_plan() {
        let plan = plan_runs(&["a".into(), "b".into(), "c".into()], &[0, 1, 2, 3, 4]);
        for n in 1..=7 {
            let mut all: Vec<RunSpec> = (0..n)
                .flat_map(|i| Shard { index: i, count: n }.select(&plan))
                .collect();
            all.sort();
            let mut expected = plan.clone();
            expected.sort();
            assert_eq!(all, expected, "{n} shards");
        }
        for bad in ["1", "2/2", "0/0", "x/3", "1/y"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        assert_eq!(Shard::parse(" 1/ 3").unwrap().to_string(), "1/3");
    }

    #[test]
    fn world_labels_and_clashes() {
        assert_eq!(world_label("library-a"), "library-a");
        assert_eq!(world_label("worlds/steep site.toml"), "steep_site");
        assert_eq!(
            RunSpec {
                world: "tests/data/small_world.toml".into(),
                seed: 3
            }
            .dir(),
            Path::new("runs/small_world/seed-3")
        );
        assert_eq!(
            parse_worlds("default, library-a,default").unwrap(),
            vec!["default".to_string(), "library-a".to_string()]
        );
        let err = parse_worlds("a/x.toml,b/x.toml").unwrap_err().to_string();
        assert!(err.contains("share the folder"), "{err}");
    }

    #[test]
    fn only_a_complete_mission_json_finishes_a_run() {
        let dir = tempfile::tempdir().unwrap();
        assert!(!run_is_finished(dir.path()));
        std::fs::write(dir.path().join("mission.json"), "{\"interrupted\": tr").unwrap();
        assert!(!run_is_finished(dir.path()));
        std::fs::write(dir.path().join("mission.json"), "{\"interrupted\": true}").unwrap();
        assert!(!run_is_finished(dir.path()));
        std::fs::write(dir.path().join("mission.json"), "{\"interrupted\": false}").unwrap();
        assert!(run_is_finished(dir.path()));
    }
}
