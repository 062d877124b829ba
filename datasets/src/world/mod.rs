//! Worlds: terrain, rocks on pedestals, lighting and texture, built from a `world.toml`.

mod config;
mod mesh_source;

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use scarp_slam::TriangleMesh;
use serde::Serialize;

pub use config::{
    DemTerrain, GeodeticOrigin, RockConfig, RockRole, RockShape, Sun, TerrainConfig, TextureConfig,
    WorldConfig,
};
pub use mesh_source::{BUILTIN_MESHES, BuiltinMesh, DOUBLE_ROCK_PLY, builtin_mesh, load_mesh};

use crate::DatasetError;
use crate::rock::{Contact, mirror_y, seat_on_flat_contact};
use crate::terrain::Heightfield;
use crate::texture::AlbedoMap;

/// How far inside its contact polygon a seated rock's centre of mass must stand, as a fraction
/// of the requested contact radius, so that targets stand stably (the default world's have
/// α_min of about 4–11°) rather than balanced on an edge.
pub const STABILITY_MARGIN_FRACTION: f64 = 0.25;

/// The built-in default world's TOML.
pub const DEFAULT_WORLD_TOML: &str = include_str!("default.toml");

/// The built-in worlds, by name, with their TOML (the files beside this module):
/// - `default`: 120 m of fault scarp, three targets (the double rock and two boulders) and twelve
///   distractors;
/// - `library-a`: 80 m of steeper scarp, four targets from the rock library (the double rock in
///   its scanned pose, a scanned slab stood on its edge, a tall column, a scanned elongated
///   stone) and distractors, one of them beside a target;
/// - `library-b`: 80 m of steeper scarp, the rest of the library (the mirrored double rock, a
///   wide squat block, a boulder resting on a boulder, a scanned blocky stone) and distractors,
///   one target near the scarp's slope.
pub const BUILTIN_WORLDS: &[(&str, &str)] = &[
    ("default", DEFAULT_WORLD_TOML),
    ("library-a", include_str!("library-a.toml")),
    ("library-b", include_str!("library-b.toml")),
];

/// The names of the built-in worlds (see [`BUILTIN_WORLDS`]).
pub fn builtin_world_names() -> impl Iterator<Item = &'static str> {
    BUILTIN_WORLDS.iter().map(|(name, _)| *name)
}

/// Instance ids written to masks: 0 is no surface (sky), a rock's id (1–999) is that rock,
/// 1000 + id is its pedestal, and [`TERRAIN_INSTANCE_ID`] is the terrain.
pub const PEDESTAL_INSTANCE_OFFSET: u16 = 1000;
/// The terrain's instance id in masks.
pub const TERRAIN_INSTANCE_ID: u16 = 2000;

/// A rock placed in the world, with its ground truth.
#[derive(Debug, Clone)]
pub struct Rock {
    /// Id from the world file (1–999); also its instance id in masks.
    pub id: u32,
    /// Target or distractor.
    pub role: RockRole,
    /// The rock alone, closed, in world coordinates (metres), with vertex normals.
    pub mesh: TriangleMesh,
    /// The pedestal, closed, in world coordinates, if the rock has one.
    pub pedestal: Option<TriangleMesh>,
    /// Centre of the rock's volume (uniform density), world metres.
    pub centroid: Point3<f64>,
    /// Enclosed volume, m³.
    pub volume_m3: f64,
    /// Vertical extent of the rock mesh, metres.
    pub height_m: f64,
    /// The basal contact with the pedestal, in world coordinates (targets on pedestals).
    pub contact: Option<Contact>,
}

/// A built world: everything the renderer and the ground-truth writers need.
#[derive(Debug, Clone)]
pub struct World {
    /// The configuration it was built from.
    pub config: WorldConfig,
    /// Terrain heights.
    pub heightfield: Heightfield,
    /// Terrain mesh in world coordinates, with normals.
    pub terrain_mesh: TriangleMesh,
    /// Rocks in file order.
    pub rocks: Vec<Rock>,
    /// Unit vector toward the sun, world ENU.
    pub sun_direction: Vector3<f64>,
    /// Baked terrain albedo.
    pub terrain_albedo: AlbedoMap,
}

/// One entry of `world.json`.
#[derive(Debug, Clone, Serialize)]
pub struct RockSummary {
    /// Rock id.
    pub id: u32,
    /// `target` or `distractor`.
    pub role: RockRole,
    /// Volume centroid, world metres.
    pub centroid: [f64; 3],
    /// Height, metres.
    pub height_m: f64,
    /// Volume, m³.
    pub volume_m3: f64,
    /// The rock's PLY file name in the same folder.
    pub mesh: String,
    /// Its shape, as [`RockConfig::shape_label`] describes it.
    pub shape: String,
    /// The pedestal's PLY file name, if any.
    pub pedestal_mesh: Option<String>,
    /// Basal contact, if any.
    pub contact: Option<Contact>,
}

impl World {
    /// Builds the built-in default world: about 120 m × 120 m of fault-scarp terrain, three
    /// precariously balanced targets (one the scanned double rock, scaled to 1.5 m) and
    /// distractor boulders.
    ///
    /// # Errors
    /// Only if the built-in description were broken; a test guards it.
    pub fn builtin_default() -> Result<Self, DatasetError> {
        Self::from_toml_str(
            DEFAULT_WORLD_TOML,
            Path::new("<built-in default world>"),
            Path::new("."),
        )
    }

    /// Builds the built-in world called `name` (one of [`BUILTIN_WORLDS`]).
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] for an unknown name (the message lists the built-in ones);
    /// otherwise only if a built-in description were broken, which a test guards.
    pub fn builtin(name: &str) -> Result<Self, DatasetError> {
        let Some((_, text)) = BUILTIN_WORLDS.iter().find(|(n, _)| *n == name) else {
            return Err(DatasetError::invalid(
                "world",
                format!(
                    "`{name}` is not a built-in world (built in: {})",
                    builtin_world_names().collect::<Vec<_>>().join(", ")
                ),
            ));
        };
        Self::from_toml_str(
            text,
            Path::new(&format!("<built-in {name} world>")),
            Path::new("."),
        )
    }

    /// The built-in world of that name (`default`, `library-a`, `library-b`: see
    /// [`BUILTIN_WORLDS`]), otherwise a world file path. A built-in name wins over a file of
    /// the same name in the working directory; write `./library-a` for the file.
    ///
    /// # Errors
    /// As [`Self::load`].
    pub fn from_name_or_path(name: &str) -> Result<Self, DatasetError> {
        if builtin_world_names().any(|n| n == name) {
            Self::builtin(name)
        } else {
            Self::load(Path::new(name))
        }
    }

    /// Reads and builds a world file. Mesh and DEM paths inside it are relative to its folder.
    ///
    /// # Errors
    /// [`DatasetError::Io`] for a missing file, [`DatasetError::Toml`] for a schema error (it
    /// names the key and line), and the errors of [`Self::build`].
    pub fn load(path: &Path) -> Result<Self, DatasetError> {
        let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
        let base = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        Self::from_toml_str(&text, path, &base)
    }

    /// Parses and builds a world from TOML text; `source` names it in errors.
    ///
    /// # Errors
    /// As [`Self::load`].
    pub fn from_toml_str(text: &str, source: &Path, base_dir: &Path) -> Result<Self, DatasetError> {
        let config: WorldConfig = toml::from_str(text).map_err(|e| DatasetError::Toml {
            path: source.to_path_buf(),
            message: e.to_string(),
        })?;
        Self::build(config, base_dir)
    }

    /// Builds a world from its configuration.
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] naming the key for duplicate or out-of-range ids, rocks outside
    /// the terrain, contacts wider than their pedestal's top, or meshes that enclose no volume;
    /// mesh and DEM reading errors.
    pub fn build(config: WorldConfig, base_dir: &Path) -> Result<Self, DatasetError> {
        let heightfield = match &config.terrain {
            TerrainConfig::Procedural(p) => p.generate()?,
            TerrainConfig::Dem(d) => crate::terrain::read_esri_ascii(&base_dir.join(&d.path))?,
        };
        let mut terrain_mesh = crate::terrain::terrain_mesh(&heightfield);
        terrain_mesh.validate()?;
        let sun = &config.sun;
        if !(0.0..=1.0).contains(&sun.ambient) {
            return Err(DatasetError::invalid("sun.ambient", "must lie in [0, 1]"));
        }
        let (az, el) = (sun.azimuth_deg.to_radians(), sun.elevation_deg.to_radians());
        let sun_direction = Vector3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin());
        let mut ids = std::collections::BTreeSet::new();
        let mut rocks = Vec::with_capacity(config.rocks.len());
        for (index, rock) in config.rocks.iter().enumerate() {
            let key = format!("rocks[{index}]");
            if !(1..=999).contains(&rock.id) || !ids.insert(rock.id) {
                return Err(DatasetError::invalid(
                    format!("{key}.id"),
                    format!("id {} must be unique and in 1..=999", rock.id),
                ));
            }
            rocks.push(place_rock(rock, &key, &heightfield, base_dir)?);
        }
        let terrain_albedo = AlbedoMap::bake(&config.texture, &heightfield);
        terrain_mesh.colors.clear();
        Ok(Self {
            config,
            heightfield,
            terrain_mesh,
            rocks,
            sun_direction,
            terrain_albedo,
        })
    }

    /// The rock with this id.
    pub fn rock(&self, id: u32) -> Option<&Rock> {
        self.rocks.iter().find(|r| r.id == id)
    }

    /// Targets in file order.
    pub fn targets(&self) -> impl Iterator<Item = &Rock> {
        self.rocks.iter().filter(|r| r.role == RockRole::Target)
    }

    /// Terrain height at (x, y), metres; the nearest edge height outside the grid.
    pub fn terrain_height_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (x0, y0, x1, y1) = self.heightfield.extent();
        self.heightfield
            .height_at(x_m.clamp(x0, x1), y_m.clamp(y0, y1))
            .unwrap_or_default()
    }

    /// The `world.json` entries, with mesh names `rock_<id>.ply` and `pedestal_<id>.ply`.
    pub fn summaries(&self) -> Vec<RockSummary> {
        self.rocks
            .iter()
            .map(|r| RockSummary {
                id: r.id,
                role: r.role,
                centroid: r.centroid.coords.into(),
                height_m: r.height_m,
                volume_m3: r.volume_m3,
                mesh: format!("rock_{}.ply", r.id),
                shape: self
                    .config
                    .rocks
                    .iter()
                    .find(|c| c.id == r.id)
                    .map_or_else(String::new, RockConfig::shape_label),
                pedestal_mesh: r
                    .pedestal
                    .as_ref()
                    .map(|_| format!("pedestal_{}.ply", r.id)),
                contact: r.contact.clone(),
            })
            .collect()
    }
}

fn place_rock(
    rock: &RockConfig,
    key: &str,
    heightfield: &Heightfield,
    base_dir: &Path,
) -> Result<Rock, DatasetError> {
    let [x, y] = rock.position_m;
    let ground_z = heightfield.height_at(x, y).ok_or_else(|| {
        DatasetError::invalid(
            format!("{key}.position_m"),
            format!("({x}, {y}) lies outside the terrain"),
        )
    })?;
    if !(rock.height_m > 0.0 && rock.height_m.is_finite()) {
        return Err(DatasetError::invalid(
            format!("{key}.height_m"),
            "must be positive",
        ));
    }
    if !(rock.tilt_deg.abs() <= 90.0) {
        return Err(DatasetError::invalid(
            format!("{key}.tilt_deg"),
            format!("{} must lie in [-90, 90]", rock.tilt_deg),
        ));
    }
    if !rock.tilt_azimuth_deg.is_finite() {
        return Err(DatasetError::invalid(
            format!("{key}.tilt_azimuth_deg"),
            "must be finite",
        ));
    }
    let mut mesh = match &rock.shape {
        RockShape::Mesh(source) => load_mesh(source, base_dir)?,
        RockShape::Boulder(b) => b.mesh(&format!("{key}.shape.boulder"))?,
        RockShape::Block(b) => b.mesh(&format!("{key}.shape.block"))?,
    };
    mesh.normals.clear();
    mesh.colors.clear();
    if rock.mirror {
        mirror_y(&mut mesh);
    }
    let flat_error = || DatasetError::invalid(format!("{key}.shape"), "the mesh is flat");
    let vertical_extent = |mesh: &TriangleMesh| {
        mesh.bounds()
            .map(|(lo, hi)| f64::from(hi.z - lo.z))
            .ok_or_else(|| {
                DatasetError::invalid(format!("{key}.shape"), "the mesh has no vertices")
            })
    };
    let native_height = vertical_extent(&mesh)?;
    if native_height <= 0.0 {
        return Err(flat_error());
    }
    mesh.scale((rock.height_m / native_height) as f32);
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rock.yaw_deg.to_radians());
    if rock.tilt_deg == 0.0 {
        mesh.transform(&Isometry3::from_parts(Translation3::identity(), yaw));
    } else {
        // Yaw about the mesh's own vertical, then the tilt in the world frame: the top (+z)
        // turns toward the lean direction u about the horizontal axis z × u. Both in f64 and
        // rounded once, so vertices level before the tilt stay exactly level together.
        let azimuth = rock.tilt_azimuth_deg.to_radians();
        let axis = Vector3::z().cross(&Vector3::new(azimuth.sin(), azimuth.cos(), 0.0));
        let tilt = UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(axis),
            rock.tilt_deg.to_radians(),
        );
        let rotation = tilt * yaw;
        for p in &mut mesh.positions {
            *p = (rotation * p.cast::<f64>()).cast();
        }
        let tilted_height = vertical_extent(&mesh)?;
        if tilted_height <= 0.0 {
            return Err(flat_error());
        }
        mesh.scale((rock.height_m / tilted_height) as f32);
    }
    let (mut mesh, pedestal, contact) = match &rock.pedestal {
        Some(pedestal) => {
            pedestal.validate(&format!("{key}.pedestal"))?;
            if rock.contact_radius_m >= pedestal.top_radius_m {
                return Err(DatasetError::invalid(
                    format!("{key}.contact_radius_m"),
                    format!(
                        "{} m must be smaller than the pedestal's top radius {} m",
                        rock.contact_radius_m, pedestal.top_radius_m
                    ),
                ));
            }
            let (seated, contact) = seat_on_flat_contact(
                mesh,
                rock.contact_radius_m,
                STABILITY_MARGIN_FRACTION * rock.contact_radius_m,
                key,
            )?;
            let overhang_m = contact
                .polygon_xy_m
                .iter()
                .map(|p| p[0].hypot(p[1]))
                .fold(0.0, f64::max);
            if overhang_m > pedestal.top_radius_m {
                return Err(DatasetError::invalid(
                    format!("{key}.pedestal.top_radius_m"),
                    format!(
                        "the rock's flat contact reaches {overhang_m:.3} m from the axis, beyond the pedestal's top radius {} m",
                        pedestal.top_radius_m
                    ),
                ));
            }
            let top_z = ground_z + pedestal.height_m;
            // The foot follows the lowest terrain under the column so it never floats.
            let foot_z = (0..16)
                .map(|k| {
                    let a = f64::from(k) / 16.0 * std::f64::consts::TAU;
                    let r = pedestal.footprint_radius_m();
                    heightfield
                        .height_at(x + r * a.cos(), y + r * a.sin())
                        .unwrap_or(ground_z)
                })
                .fold(ground_z, f64::min);
            let pedestal_mesh = pedestal.build(
                &format!("{key}.pedestal"),
                [x, y],
                foot_z,
                top_z,
                u64::from(rock.id),
            )?;
            let mut seated = seated;
            seated.transform(&Isometry3::translation(x, y, top_z));
            let contact = Contact {
                height_m: top_z,
                polygon_xy_m: contact
                    .polygon_xy_m
                    .iter()
                    .map(|p| [p[0] + x, p[1] + y])
                    .collect(),
                area_m2: contact.area_m2,
            };
            (seated, Some(pedestal_mesh), Some(contact))
        }
        None => {
            let (lo, hi) = mesh
                .bounds()
                .ok_or_else(|| DatasetError::invalid(key, "empty mesh"))?;
            let centre = nalgebra::center(&lo, &hi);
            let sink = rock.embed_fraction * rock.height_m;
            mesh.transform(&Isometry3::translation(
                x - f64::from(centre.x),
                y - f64::from(centre.y),
                ground_z - sink - f64::from(lo.z),
            ));
            (mesh, None, None)
        }
    };
    let volume = mesh.volume_properties()?;
    if volume.volume_m3 <= 0.0 {
        return Err(DatasetError::invalid(
            format!("{key}.shape"),
            "the mesh encloses no positive volume (open, or wound inwards)",
        ));
    }
    mesh.compute_vertex_normals();
    let (lo, hi) = mesh
        .bounds()
        .ok_or_else(|| DatasetError::invalid(key, "empty mesh"))?;
    let mut pedestal = pedestal;
    if let Some(p) = pedestal.as_mut() {
        p.compute_vertex_normals();
    }
    Ok(Rock {
        id: rock.id,
        role: rock.role,
        mesh,
        pedestal,
        centroid: volume.centroid,
        volume_m3: volume.volume_m3,
        height_m: f64::from(hi.z - lo.z),
        contact,
    })
}
