//! `scarp campaign`: the mission over many worlds and seeds, in parallel processes, resumable
//! and shardable; `scarp campaign merge` joins shards. See [`scarp::campaign`].

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use scarp::campaign::plan::{
    RunSpec, Shard, parse_seeds, parse_worlds, plan_runs, run_is_finished,
};
use scarp::campaign::table::{FAILED_MARKER, RunState};
use scarp::campaign::{CAMPAIGN_JSON, CampaignHeader, CampaignReport};

/// Run the mission over many worlds and seeds and tabulate every figure (`campaign.json`,
/// `campaign.md`). Finished runs are skipped, so an interrupted campaign resumes where it
/// stopped.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct CampaignArgs {
    /// `merge`: join shards.
    #[command(subcommand)]
    pub command: Option<CampaignCommand>,
    /// Worlds, comma-separated: built-in names (`default`, `library-a`, `library-b`) or TOML
    /// files.
    #[arg(long, default_value = "default,library-a,library-b")]
    pub worlds: String,
    /// Seeds: `0-9`, or a list such as `0-4,7`.
    #[arg(long, default_value = "0-9")]
    pub seeds: String,
    /// The campaign folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Missions run at once, each in its own process (each gets cores / N rayon threads
    /// unless `RAYON_NUM_THREADS` is set).
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Run only shard I of N (every N-th run of the plan, from the I-th): one task of a job
    /// array. Join the shards' folders with `scarp campaign merge`.
    #[arg(long)]
    pub shard: Option<String>,
    /// Mission configuration (TOML) for every run.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Do not run anything: tabulate the runs already in the folder.
    #[arg(long)]
    pub tabulate_only: bool,
    /// Print `campaign.json`'s totals on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `scarp campaign` subcommands.
#[derive(Debug, Subcommand)]
pub enum CampaignCommand {
    /// Join campaign folders (shards) into one: their run folders are linked (or copied) under
    /// `--out`, and the tables are recomputed from them.
    Merge(MergeArgs),
}

/// `scarp campaign merge DIR1 DIR2 ... --out DIR`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// Campaign folders to join (each with its `campaign.json`).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// The merged campaign folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Print the merged totals on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `scarp campaign` or `scarp campaign merge`.
///
/// # Errors
/// Bad arguments, a campaign folder run before with another configuration, file-system
/// errors, and, after the tables are written, runs that failed.
pub fn run(args: CampaignArgs) -> anyhow::Result<()> {
    if let Some(CampaignCommand::Merge(merge_args)) = args.command {
        return merge(merge_args);
    }
    let started = Instant::now();
    let out = args
        .out
        .clone()
        .context("--out DIR is required (the campaign folder)")?;
    let worlds = parse_worlds(&args.worlds)?;
    let seeds = parse_seeds(&args.seeds)?;
    let shard = args.shard.as_deref().map(Shard::parse).transpose()?;
    if args.jobs == 0 {
        bail!("--jobs must be at least 1");
    }
    let config_toml = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            // Fail here, once, rather than in every run.
            scarp::mission::config::MissionConfig::from_toml_str(
                &text,
                &path.display().to_string(),
            )?;
            Some(text)
        }
        None => None,
    };
    let full_plan = plan_runs(&worlds, &seeds);
    let plan = match shard {
        Some(s) => s.select(&full_plan),
        None => full_plan,
    };
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    check_same_config(&out, config_toml.as_deref())?;
    let config_path = match &config_toml {
        // Every run reads the campaign's own copy, so the folder says what it ran with.
        Some(text) => {
            let path = out.join("campaign_config.toml");
            scarp_export::atomic::write_bytes_atomically(&path, text.as_bytes())?;
            Some(std::path::absolute(&path)?)
        }
        None => None,
    };

    let todo: Vec<RunSpec> = plan
        .iter()
        .filter(|r| !run_is_finished(&out.join(r.dir())))
        .cloned()
        .collect();
    tracing::info!(
        "campaign: {} runs in {}, {} already finished, {} to run with {} job(s)",
        plan.len(),
        out.display(),
        plan.len() - todo.len(),
        todo.len(),
        args.jobs
    );
    let failures = if args.tabulate_only || todo.is_empty() {
        0
    } else {
        run_missions(&out, &todo, args.jobs, config_path.as_deref())?
    };

    let mut report = CampaignReport::collect(&out, plan, config_toml, shard)?;
    report.wall_time_s = (!args.tabulate_only).then(|| started.elapsed().as_secs_f64());
    report.write(&out)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report.totals)?);
    }
    print_summary(&report, &out);
    let unfinished = report
        .runs
        .iter()
        .filter(|r| r.state == RunState::Failed || r.state == RunState::Interrupted)
        .count();
    if failures > 0 || unfinished > 0 {
        bail!(
            "{} run(s) did not finish (see {} and each run's run.log)",
            failures.max(unfinished),
            out.join(scarp::campaign::CAMPAIGN_MD).display()
        );
    }
    Ok(())
}

/// Refuses to mix configurations in one campaign folder.
fn check_same_config(out: &Path, config_toml: Option<&str>) -> anyhow::Result<()> {
    if !out.join(CAMPAIGN_JSON).is_file() {
        return Ok(());
    }
    let previous = CampaignHeader::read(out)?;
    if previous.config_toml.as_deref() != config_toml {
        bail!(
            "{} was run with {} configuration; resume it with the same --config, or use a new --out",
            out.display(),
            if previous.config_toml.is_some() {
                "another"
            } else {
                "the default"
            }
        );
    }
    Ok(())
}

/// Rayon threads per mission so that `jobs` missions share the machine's cores.
fn threads_per_job(jobs: usize) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (cores / jobs).max(1)
}

/// Runs each mission in its own `scarp simulate` process, `jobs` at a time, with a progress
/// bar; returns how many failed. Ctrl-C (which the children receive too) stops the queue; the
/// runs in flight write their interrupted state and are run again on resume.
fn run_missions(
    out: &Path,
    todo: &[RunSpec],
    jobs: usize,
    config: Option<&Path>,
) -> anyhow::Result<usize> {
    let exe = std::env::current_exe().context("finding the scarp executable")?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let queue = Arc::new(Mutex::new(todo.iter().cloned().collect::<VecDeque<_>>()));
    let threads = threads_per_job(jobs);
    let (sender, receiver) = mpsc::channel::<(RunSpec, Result<f64, String>)>();
    let bar = ProgressBar::new(todo.len() as u64);
    if let Ok(style) = ProgressStyle::with_template(
        "campaign [{bar:30}] {pos}/{len} runs · {msg} · {elapsed} elapsed, ETA {eta}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("0 failed");
    let mut workers = Vec::new();
    for _ in 0..jobs.min(todo.len()) {
        let (queue, sender, stop, exe) = (
            Arc::clone(&queue),
            sender.clone(),
            Arc::clone(&stop),
            exe.clone(),
        );
        let out = out.to_path_buf();
        let config = config.map(Path::to_path_buf);
        workers.push(std::thread::spawn(move || {
            loop {
                if stop.load(Ordering::Relaxed) {
                    break;
                }
                let next = queue.lock().ok().and_then(|mut q| q.pop_front());
                let Some(run) = next else { break };
                let result = run_one(&exe, &out, &run, config.as_deref(), threads);
                if sender.send((run, result)).is_err() {
                    break;
                }
            }
        }));
    }
    drop(sender);
    let mut failures = 0;
    for (run, result) in receiver {
        match result {
            Ok(wall_s) => tracing::info!(
                "campaign: {} seed {} finished in {wall_s:.0} s",
                run.world,
                run.seed
            ),
            Err(message) => {
                failures += 1;
                tracing::warn!(
                    "campaign: {} seed {} failed: {message}",
                    run.world,
                    run.seed
                );
            }
        }
        bar.inc(1);
        bar.set_message(format!("{failures} failed"));
    }
    for w in workers {
        let _ = w.join();
    }
    bar.finish_and_clear();
    if stop.load(Ordering::Relaxed) {
        tracing::warn!("campaign: interrupted; run the same command again to resume");
    }
    Ok(failures)
}

/// Runs one mission into its folder (cleared first, so no file of an earlier, unfinished
/// attempt survives), with its output in `run.log`. Returns its wall time or its error.
fn run_one(
    exe: &Path,
    out: &Path,
    run: &RunSpec,
    config: Option<&Path>,
    threads: usize,
) -> Result<f64, String> {
    let started = Instant::now();
    let dir = out.join(run.dir());
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|e| format!("clearing {}: {e}", dir.display()))?;
    }
    std::fs::create_dir_all(&dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
    let log_path = dir.join("run.log");
    let log = std::fs::File::create(&log_path)
        .map_err(|e| format!("creating {}: {e}", log_path.display()))?;
    let log_err = log
        .try_clone()
        .map_err(|e| format!("{}: {e}", log_path.display()))?;
    let mut command = Command::new(exe);
    command
        .arg("simulate")
        .arg("--world")
        .arg(&run.world)
        .arg("--seed")
        .arg(run.seed.to_string())
        .arg("--out")
        .arg(&dir)
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(log_err);
    if let Some(config) = config {
        command.arg("--config").arg(config);
    }
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        command.env("RAYON_NUM_THREADS", threads.to_string());
    }
    let status = command
        .status()
        .map_err(|e| format!("starting {}: {e}", exe.display()))?;
    if status.success() && run_is_finished(&dir) {
        Ok(started.elapsed().as_secs_f64())
    } else {
        if !dir.join("mission.json").is_file() {
            let marker = dir.join(FAILED_MARKER);
            std::fs::write(&marker, format!("{status}\n"))
                .map_err(|e| format!("writing {}: {e}", marker.display()))?;
        }
        let tail = std::fs::read_to_string(&log_path)
            .ok()
            .and_then(|l| {
                l.lines()
                    .rev()
                    .find(|l| !l.trim().is_empty())
                    .map(str::to_string)
            })
            .unwrap_or_default();
        Err(format!("{status}: {tail}"))
    }
}

fn print_summary(report: &CampaignReport, out: &Path) {
    let t = &report.totals;
    let pct = |r: &scarp::campaign::table::Rate| {
        r.rate
            .map_or("–".to_string(), |x| format!("{:.0}%", 100.0 * x))
    };
    eprintln!(
        "campaign: {}/{} runs finished; targets mapped {}/{}; F@2cm≥0.85 {}; |α err|≤2° {}; runs without collision {}; truth in interval {} → {}",
        t.runs_finished,
        t.runs,
        t.targets_mapped.count,
        t.targets_mapped.of,
        pct(&t.fscore_2cm_at_least_0_85),
        pct(&t.alpha_error_within_2deg),
        pct(&t.runs_without_collision),
        pct(&t.truth_in_interval),
        out.join(scarp::campaign::CAMPAIGN_MD).display()
    );
}

/// Links `from` into `to` file by file (a hard link, or a copy across file systems).
fn link_tree(from: &Path, to: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for entry in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let entry = entry?;
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        if entry.file_type()?.is_dir() {
            link_tree(&src, &dst)?;
        } else {
            if dst.exists() {
                std::fs::remove_file(&dst)?;
            }
            if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst)
                    .with_context(|| format!("copying {} to {}", src.display(), dst.display()))?;
            }
        }
    }
    Ok(())
}

/// Joins campaign folders: same configuration required; a run present in several folders is
/// taken from the first that finished it.
fn merge(args: MergeArgs) -> anyhow::Result<()> {
    let mut config: Option<Option<String>> = None;
    let mut plan: Vec<RunSpec> = Vec::new();
    let mut source: Vec<PathBuf> = Vec::new();
    for dir in &args.dirs {
        let part = CampaignHeader::read(dir)?;
        match &config {
            None => config = Some(part.config_toml.clone()),
            Some(c) if *c != part.config_toml => bail!(
                "{} was run with another configuration than {}; campaigns with different configurations cannot be merged",
                dir.display(),
                args.dirs[0].display()
            ),
            Some(_) => {}
        }
        for run in part.plan {
            let finished_here = run_is_finished(&dir.join(run.dir()));
            match plan.iter().position(|r| *r == run) {
                Some(i) => {
                    if finished_here && !run_is_finished(&source[i].join(run.dir())) {
                        source[i] = dir.clone();
                    }
                }
                None => {
                    plan.push(run);
                    source.push(dir.clone());
                }
            }
        }
    }
    // Plan order (world by world, seeds ascending) whatever order the shards came in.
    let mut worlds: Vec<String> = Vec::new();
    for r in &plan {
        if !worlds.contains(&r.world) {
            worlds.push(r.world.clone());
        }
    }
    let mut order: Vec<usize> = (0..plan.len()).collect();
    order.sort_by_key(|&i| {
        (
            worlds.iter().position(|w| *w == plan[i].world),
            plan[i].seed,
        )
    });
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mut merged_plan = Vec::with_capacity(plan.len());
    for i in order {
        let (run, from) = (&plan[i], &source[i]);
        let src = from.join(run.dir());
        if src.exists() {
            let dst = args.out.join(run.dir());
            if std::path::absolute(&src)? != std::path::absolute(&dst)? {
                link_tree(&src, &dst)?;
            }
        }
        merged_plan.push(run.clone());
    }
    let mut report = CampaignReport::collect(&args.out, merged_plan, config.flatten(), None)?;
    report.merged_from = args.dirs.iter().map(|d| d.display().to_string()).collect();
    report.write(&args.out)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report.totals)?);
    }
    print_summary(&report, &args.out);
    Ok(())
}
