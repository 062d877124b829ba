//! `scarp world`: write a world's ground-truth meshes and `world.json`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use scarp_datasets::world::World;
use scarp_export::atomic::write_bytes_atomically;
use scarp_export::ply::{PlyEncoding, write_mesh};

/// Write the ground truth of a world: `terrain.ply`, `rock_<id>.ply`, `pedestal_<id>.ply` and
/// `world.json`.
#[derive(Debug, Args)]
pub struct WorldArgs {
    /// A built-in world (`default`, `library-a`, `library-b`: see
    /// `scarp_datasets::world::BUILTIN_WORLDS`), or a world TOML file.
    #[arg(long, default_value = "default")]
    pub world: String,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Print `world.json` on stdout too.
    #[arg(long)]
    pub json: bool,
}

/// Writes the ground truth of `world` into `out`; returns the `world.json` value.
///
/// # Errors
/// Writing errors naming the file.
pub fn write_world(world: &World, out: &std::path::Path) -> anyhow::Result<serde_json::Value> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_mesh(
        out.join("terrain.ply"),
        &world.terrain_mesh,
        PlyEncoding::BinaryLittleEndian,
    )?;
    for rock in &world.rocks {
        write_mesh(
            out.join(format!("rock_{}.ply", rock.id)),
            &rock.mesh,
            PlyEncoding::BinaryLittleEndian,
        )?;
        if let Some(pedestal) = &rock.pedestal {
            write_mesh(
                out.join(format!("pedestal_{}.ply", rock.id)),
                pedestal,
                PlyEncoding::BinaryLittleEndian,
            )?;
        }
    }
    let (x0, y0, x1, y1) = world.heightfield.extent();
    let json = serde_json::json!({
        "name": world.config.name,
        "origin": world.config.origin,
        "terrain": { "mesh": "terrain.ply", "extent_m": [x0, y0, x1, y1] },
        "rocks": world.summaries(),
    });
    write_bytes_atomically(
        out.join("world.json"),
        serde_json::to_string_pretty(&json)?.as_bytes(),
    )?;
    let config = toml::to_string(&world.config).context("serialising the world configuration")?;
    write_bytes_atomically(out.join("world.toml"), config.as_bytes())?;
    Ok(json)
}

/// Runs `scarp world`.
///
/// # Errors
/// World loading and writing errors.
pub fn run(args: WorldArgs) -> anyhow::Result<()> {
    let world = World::from_name_or_path(&args.world)
        .with_context(|| format!("loading world `{}`", args.world))?;
    let json = write_world(&world, &args.out)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&json)?);
    } else {
        eprintln!(
            "wrote the terrain and {} rocks to {}",
            world.rocks.len(),
            args.out.display()
        );
    }
    Ok(())
}
