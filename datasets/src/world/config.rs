//! The world file schema (`world.toml`). See the crate docs for a full example.

use serde::{Deserialize, Serialize};

use crate::rock::{BlockShape, BoulderShape, PedestalShape};
use crate::terrain::ProceduralTerrain;

/// A whole world file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldConfig {
    /// A name for reports.
    #[serde(default = "default_name")]
    pub name: String,
    /// The geodetic position of the local ENU origin.
    #[serde(default)]
    pub origin: GeodeticOrigin,
    /// Lighting.
    #[serde(default)]
    pub sun: Sun,
    /// Surface texture.
    #[serde(default)]
    pub texture: TextureConfig,
    /// Terrain source.
    pub terrain: TerrainConfig,
    /// Rocks, targets and distractors.
    #[serde(default)]
    pub rocks: Vec<RockConfig>,
}

fn default_name() -> String {
    "world".into()
}

/// WGS84 position of the world origin, for geo-referencing outputs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeodeticOrigin {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Ellipsoidal altitude, metres.
    pub alt_m: f64,
}

impl Default for GeodeticOrigin {
    /// A granite PBR field in southern California (Granite Pass, near the San Jacinto fault).
    fn default() -> Self {
        Self {
            lat_deg: 33.584,
            lon_deg: -116.428,
            alt_m: 1280.0,
        }
    }
}

/// The sun, for Lambert shading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Sun {
    /// Azimuth toward the sun, degrees clockwise from north. Default 135 (south-east).
    pub azimuth_deg: f64,
    /// Elevation above the horizon, degrees. Default 50.
    pub elevation_deg: f64,
    /// Ambient (sky) light as a fraction of full light, in [0, 1]. Default 0.35.
    pub ambient: f64,
}

impl Default for Sun {
    fn default() -> Self {
        Self {
            azimuth_deg: 135.0,
            elevation_deg: 50.0,
            ambient: 0.35,
        }
    }
}

/// Procedural surface texture: albedo = base colour modulated by fractal noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TextureConfig {
    /// Seed of the texture noise.
    pub seed: u64,
    /// Texel size of the baked terrain albedo map, metres. Default 0.04.
    pub terrain_texel_m: f64,
    /// Terrain base colour, sRGB. Default a sandy grus.
    pub terrain_color: [u8; 3],
    /// Secondary terrain colour (darker patches, vegetation), sRGB.
    pub terrain_patch_color: [u8; 3],
    /// Rock base colour, sRGB. Default a light granite grey.
    pub rock_color: [u8; 3],
    /// Pedestal base colour, sRGB.
    pub pedestal_color: [u8; 3],
    /// Strength of the fine speckle (grain) modulation, in [0, 1]. Default 0.35.
    pub speckle: f64,
    /// Wavelength of the coarse colour variation, metres. Default 0.6.
    pub variation_wavelength_m: f64,
    /// Wavelength of the fine speckle, metres. Default 0.03.
    pub speckle_wavelength_m: f64,
}

impl Default for TextureConfig {
    fn default() -> Self {
        Self {
            seed: 11,
            terrain_texel_m: 0.04,
            terrain_color: [196, 170, 130],
            terrain_patch_color: [112, 110, 80],
            rock_color: [170, 165, 158],
            pedestal_color: [150, 132, 110],
            speckle: 0.35,
            variation_wavelength_m: 0.6,
            speckle_wavelength_m: 0.03,
        }
    }
}

/// Where the terrain comes from: a `[terrain.procedural]` or a `[terrain.dem]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TerrainConfig {
    /// A procedural fault scarp.
    Procedural(ProceduralTerrain),
    /// An ESRI ASCII grid file.
    Dem(DemTerrain),
}

/// A DEM file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DemTerrain {
    /// Path to the `.asc` grid, relative to the world file.
    pub path: String,
}

/// Whether a rock is something to map or a decoy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RockRole {
    /// A precariously balanced rock to find, localize and map.
    Target,
    /// An ordinary boulder that must not be mapped.
    Distractor,
}

impl RockRole {
    /// `target` or `distractor`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Target => "target",
            Self::Distractor => "distractor",
        }
    }
}

/// A rock's shape: `shape = { mesh = "file.ply" }`, `shape = { boulder = { … } }` or
/// `shape = { block = { … } }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RockShape {
    /// A mesh file (PLY or OBJ), relative to the world file, or a built-in scan
    /// (`builtin:double_rock`, `builtin:stone_e22`, …: see
    /// [`BUILTIN_MESHES`](super::BUILTIN_MESHES)).
    Mesh(String),
    /// A procedural boulder: a lumpy ellipsoid.
    Boulder(BoulderShape),
    /// A procedural block: a lumpy rounded box, for slabs, columns and squat blocks.
    Block(BlockShape),
}

/// One rock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RockConfig {
    /// Unique id, 1–999 (it also sets the rock's instance id in masks).
    pub id: u32,
    /// Target or distractor.
    pub role: RockRole,
    /// Position of the rock's base (the pedestal axis, or the rock's contact) in world x, y,
    /// metres. z follows from the terrain.
    pub position_m: [f64; 2],
    /// Rotation about the mesh's own vertical (z) axis, degrees counter-clockwise seen from
    /// above. Applied first (after `mirror`), before the tilt.
    #[serde(default)]
    pub yaw_deg: f64,
    /// Tilt of the (yawed) mesh, degrees, in [−90, 90]: a rotation about the horizontal world
    /// axis perpendicular to `tilt_azimuth_deg`, so that the rock's top leans toward that
    /// azimuth (a negative tilt leans it the opposite way). 90 lays the mesh's vertical axis
    /// flat, which stands a flat stone on its edge. Default 0.
    #[serde(default)]
    pub tilt_deg: f64,
    /// Direction the tilted rock's top leans toward, degrees clockwise from north (0 north, 90
    /// east), like the sun's azimuth and the scarp's strike. Default 0.
    #[serde(default)]
    pub tilt_azimuth_deg: f64,
    /// Mirror the mesh across its own x–z plane (y → −y) before yaw and tilt, keeping it wound
    /// outwards: a scan's mirror image, a new rock with the same fragility statistics.
    /// Default false.
    #[serde(default)]
    pub mirror: bool,
    /// Rock height after scaling, metres: the mesh is scaled uniformly so that its vertical
    /// extent, once yawed and tilted, is this height (seating it on a pedestal then cuts a few
    /// centimetres off its bottom).
    pub height_m: f64,
    /// The shape.
    pub shape: RockShape,
    /// The pedestal; without one the rock rests on the terrain.
    #[serde(default)]
    pub pedestal: Option<PedestalShape>,
    /// Radius of the flat basal contact, metres. Default 0.15.
    #[serde(default = "default_contact_radius")]
    pub contact_radius_m: f64,
    /// How far a rock without a pedestal sinks into the terrain, as a fraction of its height.
    /// Default 0.1.
    #[serde(default = "default_embed_fraction")]
    pub embed_fraction: f64,
}

impl RockConfig {
    /// A short description of the rock's shape for tables: the mesh source, or the procedural
    /// kind with its proportions (height over the larger horizontal extent), then the pose
    /// changes, e.g. `builtin:double_rock, mirrored` or `block 0.35×1.0×0.8, tilt 12°`.
    pub fn shape_label(&self) -> String {
        let fmt3 = |v: [f64; 3]| format!("{:.2}×{:.2}×{:.2}", v[0], v[1], v[2]);
        let mut label = match &self.shape {
            RockShape::Mesh(source) => source.clone(),
            RockShape::Boulder(b) => format!("boulder {}", fmt3(b.radii_m)),
            RockShape::Block(b) => format!("block {}", fmt3(b.size_m)),
        };
        if self.mirror {
            label.push_str(", mirrored");
        }
        if self.tilt_deg != 0.0 {
            label.push_str(&format!(", tilt {:.0}°", self.tilt_deg));
        }
        if let Some(p) = &self.pedestal
            && p.boulder.is_some()
        {
            label.push_str(", on a boulder");
        }
        label
    }
}

fn default_contact_radius() -> f64 {
    0.15
}

fn default_embed_fraction() -> f64 {
    0.1
}
