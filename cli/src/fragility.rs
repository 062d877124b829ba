//! `scarp fragility`: fragility analysis of a rock mesh (see [`scarp::fragility`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use scarp_slam::TriangleMesh;

use scarp::fragility::scan::{ClosedScan, analyze_closed_scan, close_scan};
use scarp::fragility::{
    ContactSpec, FragilityConfig, FragilityReport, analyze_detailed, figure::write_figure,
};

/// Arguments of `scarp fragility`.
#[derive(Debug, clap::Args)]
pub struct FragilityArgs {
    /// Closed rock mesh, metres (PLY or OBJ).
    pub mesh: PathBuf,
    /// Up direction in the mesh's frame as `x,y,z` (default `0,0,1`, or the config file's).
    #[arg(long, value_parser = parse_vector, allow_hyphen_values = true)]
    pub up: Option<[f64; 3]>,
    /// Height of the basal contact along up, metres; without it (and without `--pedestal`) the
    /// contact is found automatically as the neck of the cross-section area profile.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "pedestal")]
    pub contact_height: Option<f64>,
    /// Closed pedestal mesh in the rock's frame; the contact is the pedestal's top.
    #[arg(long)]
    pub pedestal: Option<PathBuf>,
    /// The mesh is an open scan of the rock standing on its pedestal or the ground (z up), as
    /// `scarp map` and `scarp simulate` write it: find the support's top under the neck, cut
    /// the rock off above it, extrapolate the contact polygon from the rock's basal profile and
    /// close the rock before the analysis (see `fragility::scan`).
    #[arg(long, conflicts_with_all = ["pedestal", "contact_height"])]
    pub scan: bool,
    /// Print the full report as JSON on stdout instead of a summary.
    #[arg(long)]
    pub json: bool,
    /// Write a figure (side silhouette and polar plot of α(θ)); `.svg` or `.png`.
    #[arg(long)]
    pub figure: Option<PathBuf>,
    /// TOML file with a `FragilityConfig` (any subset of its fields).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Seed of the perturbation study (overrides the config file).
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Parses `x,y,z`.
fn parse_vector(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected three comma-separated numbers, got `{text}`"
        ));
    }
    let mut v = [0.0; 3];
    for (slot, part) in v.iter_mut().zip(&parts) {
        *slot = part
            .parse()
            .map_err(|e| format!("`{part}` in `{text}` is not a number: {e}"))?;
    }
    Ok(v)
}

/// Reads a mesh file, choosing the reader by extension.
fn read_mesh(path: &Path) -> anyhow::Result<TriangleMesh> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "ply" => scarp_export::ply::read_mesh(path)
            .with_context(|| format!("reading mesh {}", path.display())),
        "obj" => scarp_export::obj::read_obj(path)
            .with_context(|| format!("reading mesh {}", path.display())),
        _ => bail!(
            "mesh {}: unsupported format `.{ext}` (supported: .ply, .obj)",
            path.display()
        ),
    }
}

/// Loads the configuration file (if any) and applies the command-line overrides.
fn load_config(args: &FragilityArgs) -> anyhow::Result<FragilityConfig> {
    let mut config = match &args.config {
        Some(path) => super::read_toml_config(path)?,
        None => FragilityConfig::default(),
    };
    if let Some(up) = args.up {
        config.up = up;
    }
    if let Some(seed) = args.seed {
        config.uncertainty.seed = seed;
    }
    Ok(config)
}

/// A short human-readable summary of a report.
pub fn summary(report: &FragilityReport) -> String {
    let pair = &report.alpha_min_pair;
    format!(
        "alpha_min           {:.2}°, 95% interval [{:.2}°, {:.2}°] ({}), tipping towards azimuth {:.1}°\n\
         perturbation        ± {:.2}° (1σ of {} perturbed runs)\n\
         opposite direction  {:.2}°\n\
         toppling PGA        {:.3} g ({:.2} m/s²)\n\
         contact             {:?} at {:.4} m, area {:.4} m² (section {:.4} m²)\n\
         centre of mass      [{:.4}, {:.4}, {:.4}] m, {:.4} m above the contact\n\
         volume, mass        {:.4} m³, {:.1} kg at {} kg/m³\n\
         height/width        {:.2} ({:.3} m / {:.3} m)\n\
         Purvance p          {:.3} rad/s (R = {:.3} m)\n",
        report.alpha_min_deg,
        report.alpha_min_low_deg,
        report.alpha_min_high_deg,
        report.alpha_interval.source,
        report.alpha_min_azimuth_deg,
        report.alpha_min_spread_deg,
        report.uncertainty.samples - report.uncertainty.failed_samples,
        pair.opposite_alpha_deg,
        report.toppling_pga_g,
        report.toppling_pga_m_s2,
        report.contact_method,
        report.contact_height_m,
        report.contact_area_m2,
        report.section_area_m2,
        report.center_of_mass[0],
        report.center_of_mass[1],
        report.center_of_mass[2],
        report.com_height_above_contact_m,
        report.volume_m3,
        report.mass_kg,
        report.density_kg_m3,
        report.height_to_width,
        report.rock_height_m,
        report.contact_width_m,
        report.purvance_p_rad_s,
        report.rocking_radius_m,
    ) + &interval_sources(report)
}

/// The interval's sources, one line each, largest first (empty for the perturbation alone).
fn interval_sources(report: &FragilityReport) -> String {
    let mut sources = report.alpha_interval.sources.clone();
    if sources.len() < 2 {
        return String::new();
    }
    sources.sort_by(|a, b| (b.below_deg + b.above_deg).total_cmp(&(a.below_deg + a.above_deg)));
    let lines: Vec<String> = sources
        .iter()
        .map(|s| {
            format!(
                "  {:<20}−{:.2}° +{:.2}°\n",
                s.name, s.below_deg, s.above_deg
            )
        })
        .collect();
    let sigma = report
        .alpha_interval
        .contact_height_sigma_m
        .map_or(String::new(), |s| {
            format!(
                "contact height σ    {:.1} mm (support roughness and mesh error)\n",
                s * 1e3
            )
        });
    format!(
        "interval sources    95% half-widths, combined in quadrature\n{}{sigma}",
        lines.concat()
    )
}

/// Runs `scarp fragility`.
///
/// # Errors
/// Unreadable or invalid meshes or config, analysis failures (named by [`FragilityError`]) and
/// figure write errors, each with the path at fault.
///
/// [`FragilityError`]: scarp::fragility::FragilityError
pub fn run(args: FragilityArgs) -> anyhow::Result<()> {
    let config = load_config(&args)?;
    let mesh = read_mesh(&args.mesh)?;
    let closed_scan = if args.scan {
        let closed = close_scan(&mesh, &config.scan)
            .with_context(|| format!("closing the scan {}", args.mesh.display()))?;
        tracing::info!(
            contact_m = closed.contact_height_m(),
            support_plane_m = closed.support_plane.map(|p| p.height_m),
            support_roughness_m = closed.support_plane.map(|p| p.roughness_m),
            partial_support_m = closed.partial_support.map(|p| p.height_m),
            support_tilt_deg = closed.support_plane.map(|p| p.tilt_deg()),
            loops = closed.filled_patches.len(),
            "scan cut above its support and closed"
        );
        Some(closed)
    } else {
        None
    };
    // A given pedestal or contact height is in the scan's frame, as the closed rock must be.
    let closed_rock = closed_scan.as_ref().map(ClosedScan::mesh_in_scan_frame);
    let rock = closed_rock.as_ref().unwrap_or(&mesh);
    let pedestal = args.pedestal.as_deref().map(read_mesh).transpose()?;
    tracing::info!(mesh = %args.mesh.display(), faces = rock.faces.len(), "fragility analysis");
    // A scan without a given contact gets the extrapolated contact and its interval.
    let analysis = match (&pedestal, args.contact_height, &closed_scan) {
        (Some(p), _, _) => analyze_detailed(rock, ContactSpec::Pedestal(p), &config),
        (None, Some(h), _) => analyze_detailed(rock, ContactSpec::Height(h), &config),
        (None, None, Some(closed)) => analyze_closed_scan(closed, &config),
        (None, None, None) => analyze_detailed(rock, ContactSpec::Auto, &config),
    }
    .with_context(|| format!("analysing {}", args.mesh.display()))?;
    if let Some(path) = &args.figure {
        write_figure(&analysis, path)?;
        tracing::info!(figure = %path.display(), "figure written");
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&analysis.report)?);
    } else {
        print!("{}", summary(&analysis.report));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn parses_vectors_and_arguments() {
        assert_eq!(parse_vector("0, 0,1").unwrap(), [0.0, 0.0, 1.0]);
        assert!(parse_vector("0,1").is_err());
        assert!(parse_vector("a,b,c").is_err());
        let cli = crate::Cli::try_parse_from([
            "scarp",
            "fragility",
            "rock.obj",
            "--up",
            "0,0,-1",
            "--contact-height",
            "-0.25",
            "--json",
        ])
        .unwrap();
        let crate::Command::Fragility(args) = cli.command else {
            panic!("parsed as another subcommand");
        };
        assert_eq!(args.up, Some([0.0, 0.0, -1.0]));
        assert_eq!(args.contact_height, Some(-0.25));
        assert!(args.json);
        assert!(
            crate::Cli::try_parse_from([
                "scarp",
                "fragility",
                "r.obj",
                "--contact-height",
                "1",
                "--pedestal",
                "p.obj"
            ])
            .is_err()
        );
    }

    #[test]
    fn runs_on_an_obj_block_with_figure() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("block.obj");
        let block = TriangleMesh::cuboid(
            nalgebra::Point3::origin(),
            nalgebra::Point3::new(1.0, 1.0, 2.0),
        );
        let mut text = String::new();
        for p in &block.positions {
            text += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
        for f in &block.faces {
            text += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
        }
        std::fs::write(&mesh, text).unwrap();
        let figure = dir.path().join("out.svg");
        let args = FragilityArgs {
            mesh,
            up: None,
            contact_height: None,
            pedestal: None,
            scan: false,
            json: true,
            figure: Some(figure.clone()),
            config: None,
            seed: Some(3),
        };
        run(args).unwrap();
        assert!(std::fs::read_to_string(figure).unwrap().contains("<svg"));
        // A closed block is not a scan of a rock on a pedestal: there is no neck to cut at.
        let not_a_scan = FragilityArgs {
            mesh: dir.path().join("block.obj"),
            up: None,
            contact_height: None,
            pedestal: None,
            scan: true,
            json: false,
            figure: None,
            config: None,
            seed: None,
        };
        let e = run(not_a_scan).unwrap_err();
        assert!(format!("{e:#}").contains("closing the scan"), "{e:#}");
        let missing = FragilityArgs {
            mesh: dir.path().join("missing.obj"),
            up: None,
            contact_height: None,
            pedestal: None,
            scan: false,
            json: false,
            figure: None,
            config: None,
            seed: None,
        };
        let e = run(missing).unwrap_err();
        assert!(format!("{e:#}").contains("missing.obj"));
    }

    #[test]
    fn runs_on_the_real_rock_ply() {
        let mesh =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/rocks/double_rock.ply");
        // Where `../shared` is not beside the repository (a lone clone), skip as the library's
        // real-rock tests do.
        if !mesh.exists() {
            println!("skipping: {} is absent", mesh.display());
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let figure = dir.path().join("rock.png");
        let args = FragilityArgs {
            mesh,
            up: Some([0.0, 0.0, 1.0]),
            contact_height: Some(-0.06),
            pedestal: None,
            scan: false,
            json: true,
            figure: Some(figure.clone()),
            config: None,
            seed: None,
        };
        run(args).unwrap();
        assert!(std::fs::metadata(figure).unwrap().len() > 1000);
    }
}
