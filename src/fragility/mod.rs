//! # Fragility of a precariously balanced rock
//!
//! From a closed rock mesh (reconstructed or ground truth) and the up direction, this module
//! finds the basal contact, cuts the rock above it and closes the cut, integrates the mass
//! properties, and derives the rocking angles α(θ) around the convex contact polygon:
//! α_min with its azimuth, the opposite-direction pairs, the quasi-static toppling acceleration
//! g·tan(α_min), the height-to-width ratio, Purvance's p, and the spread of α_min under
//! perturbation of the contact height and the mesh.
//!
//! ## Frames and units
//! - Input meshes are in any right-handed frame in metres (world ENU by convention). The
//!   *levelled frame* is that frame rotated about the origin by the smallest rotation that takes
//!   [`FragilityConfig::up`] to +z; for the default up (+z) the two frames coincide.
//! - Heights (`contact_height_m`, [`ContactSpec::Height`]) are coordinates along up, that is
//!   levelled z.
//! - Azimuths are degrees counter-clockwise from levelled +x towards levelled +y (for up = +z:
//!   from east towards north), in [0, 360). The azimuth of α(θ) is the direction in which the
//!   rock would tip.
//! - Positions, the centre of mass and the inertia tensor in the report are in the input frame.
//!
//! ## Steps and their failure cases
//! 1. The mesh is checked: NaN, bad indices, no faces, open, non-manifold or inconsistently
//!    wound surfaces are errors ([`FragilityError`]). Documented repairs, reported in
//!    [`MeshRepairs`]: vertices at bit-identical positions are welded, faces that repeat a vertex
//!    are dropped, and shells wound inwards are flipped.
//! 2. The contact ([`ContactSpec`]): the neck of the horizontal cross-section area profile, a
//!    given height, the top of a given pedestal mesh, or a given contact polygon (for a scan,
//!    [`scan::analyze_scan`] extrapolates it from the rock's basal profile).
//! 3. The rock is cut just above the contact plane and closed by triangulating the section
//!    polygons (ear clipping after bridging holes), then volume, centre of mass and inertia come
//!    from signed tetrahedra at uniform density.
//! 4. The contact polygon is the convex hull of the rock's section at the contact (plus vertices
//!    within [`FragilityConfig::contact_band_m`] above it), clipped by the convex hull of
//!    whatever supports it from below (the pedestal's top or the mesh's own section just below),
//!    then grown by every point of the base over that support that the rock would land on before
//!    toppling ([`rocking::landing_hull`]): a base hanging millimetres above its pedestal beyond
//!    the touching part is pivoted on, not toppled past.
//! 5. α(θ) = atan(r(θ)/H) for [`FragilityConfig::azimuth_count`] azimuths, where r(θ) is the
//!    horizontal distance from the centre of mass to the supporting line of the contact polygon
//!    in direction θ and H the height of the centre of mass above the contact. α_min is the
//!    exact minimum over all directions (the centre of mass's distance to the nearest hull
//!    edge), so it is never above the smallest sampled α.
//! 6. A 95% interval, `alpha_min_low_deg` to `alpha_min_high_deg` ([`AlphaInterval`]): for a
//!    closed rock, the perturbation study's range; for a scan ([`scan::analyze_scan`]), the span
//!    of the readings of the extrapolated contact (54, and as many again where the support's
//!    edge was not seen all round; each also shrunk by two voxels), widened by the perturbation
//!    spread and by margins set on three campaigns' flights.
//!
//! ```
//! use nalgebra::Point3;
//! use scarp::fragility::{ContactSpec, FragilityConfig, analyze};
//! use scarp_slam::TriangleMesh;
//!
//! // A 1 m × 1 m × 2 m block standing on its base at z = 0.
//! let (b, h) = (1.0f32, 2.0f32);
//! let positions = (0..8)
//!     .map(|i| Point3::new(
//!         if i & 1 == 0 { 0.0 } else { b },
//!         if i & 2 == 0 { 0.0 } else { b },
//!         if i & 4 == 0 { 0.0 } else { h },
//!     ))
//!     .collect();
//! let faces = vec![
//!     [0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
//!     [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5],
//! ];
//! let block = TriangleMesh::new(positions, faces).unwrap();
//! let report = analyze(&block, ContactSpec::Auto, &FragilityConfig::default()).unwrap();
//! // α = atan(b/h) in each of the four face directions.
//! assert!((report.alpha_min_deg - 0.5f64.atan().to_degrees()).abs() < 0.05);
//! assert!((report.toppling_pga_g - 0.5).abs() < 1e-6);
//! assert_eq!(report.alpha_deg.len(), 360);
//! let json = serde_json::to_string(&report).unwrap();
//! assert!(json.contains("\"alpha_min_deg\""));
//! ```

mod contact;
mod error;
pub mod figure;
pub mod mass;
#[cfg(test)]
mod real_rock;
pub mod rocking;
pub mod scan;
mod section;
#[cfg(test)]
pub(crate) mod test_shapes;
#[cfg(test)]
mod tests;
mod topology;
pub mod uncertainty;

use nalgebra::{Matrix3, Point2, Point3, Rotation3, Unit, Vector2, Vector3};
use scarp_slam::TriangleMesh;
use serde::{Deserialize, Serialize};

pub use error::FragilityError;
pub use mass::{MassProperties, mass_properties};
pub use rocking::MinimumSupport;
pub use topology::MeshRepairs;
pub use uncertainty::{UncertaintyConfig, UncertaintyReport};

use section::{Cut, cut_above};
use topology::{Solid, prepare};
use uncertainty::{SampleSupport, alpha_min_spread};

/// Settings of the fragility analysis. Every field has a documented default;
/// `FragilityConfig::default()` is what `scarp fragility` uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FragilityConfig {
    /// Up direction in the mesh's frame (need not be unit length). Default `[0, 0, 1]` (ENU z).
    pub up: [f64; 3],
    /// Uniform rock density, kg/m³. Default 2650 (granite, as in the design).
    pub density_kg_m3: f64,
    /// Number of evenly spaced azimuths for α(θ); must be even (for opposite pairs) and ≥ 4.
    /// Default 360.
    pub azimuth_count: usize,
    /// Gravitational acceleration, m/s². Default 9.80665 (standard gravity).
    pub g_m_s2: f64,
    /// Number of heights at which the automatic contact search samples the cross-section area.
    /// Default 256.
    pub profile_levels: usize,
    /// The automatic search accepts a neck only if the widest sections both below and above it
    /// are at least this many times its area; otherwise the rock rests on its lowest points.
    /// Default 1.5.
    pub neck_min_area_ratio: f64,
    /// Relative area tolerance of the neck floor: the contact is the highest height whose section
    /// is within this fraction of the narrowest one (so a straight column counts as pedestal).
    /// Default 0.01.
    pub neck_plateau_tolerance: f64,
    /// Vertices within this height of the contact plane (above it for the rock, below it for the
    /// support) also count as touching; covers a rough base resting on the ground. Metres.
    /// Default 0.001.
    pub contact_band_m: f64,
    /// Largest gap between the rock's lowest point and the pedestal's top that is still treated
    /// as contact (the rock is lowered onto the pedestal), metres. Default 0.01.
    pub pedestal_gap_tolerance_m: f64,
    /// The perturbation study for `alpha_min_spread_deg`.
    pub uncertainty: UncertaintyConfig,
    /// Closing a scan and extrapolating its contact ([`scan::close_scan`]).
    pub scan: scan::ScanConfig,
}

impl Default for FragilityConfig {
    fn default() -> Self {
        Self {
            up: [0.0, 0.0, 1.0],
            density_kg_m3: 2650.0,
            azimuth_count: 360,
            g_m_s2: 9.80665,
            profile_levels: 256,
            neck_min_area_ratio: 1.5,
            neck_plateau_tolerance: 0.01,
            contact_band_m: 0.001,
            pedestal_gap_tolerance_m: 0.01,
            uncertainty: UncertaintyConfig::default(),
            scan: scan::ScanConfig::default(),
        }
    }
}

fn invalid(field: &'static str, value: impl ToString, reason: &'static str) -> FragilityError {
    FragilityError::InvalidConfig {
        field,
        value: value.to_string(),
        reason,
    }
}

impl FragilityConfig {
    /// Checks every field's range.
    ///
    /// # Errors
    /// [`FragilityError::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), FragilityError> {
        let up = Vector3::from(self.up);
        if !(up.iter().all(|c| c.is_finite()) && up.norm() > 1e-12) {
            return Err(invalid(
                "up",
                format!("{:?}", self.up),
                "must be a finite non-zero vector",
            ));
        }
        let positive = |field, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(field, v, "must be positive and finite"))
            }
        };
        let non_negative = |field, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(invalid(field, v, "must be non-negative and finite"))
            }
        };
        positive("density_kg_m3", self.density_kg_m3)?;
        positive("g_m_s2", self.g_m_s2)?;
        positive("neck_min_area_ratio", self.neck_min_area_ratio)?;
        non_negative("neck_plateau_tolerance", self.neck_plateau_tolerance)?;
        non_negative("contact_band_m", self.contact_band_m)?;
        non_negative("pedestal_gap_tolerance_m", self.pedestal_gap_tolerance_m)?;
        non_negative(
            "uncertainty.contact_height_sigma_m",
            self.uncertainty.contact_height_sigma_m,
        )?;
        non_negative(
            "uncertainty.mesh_noise_sigma_m",
            self.uncertainty.mesh_noise_sigma_m,
        )?;
        if self.azimuth_count < 4 || !self.azimuth_count.is_multiple_of(2) {
            return Err(invalid(
                "azimuth_count",
                self.azimuth_count,
                "must be even and at least 4",
            ));
        }
        self.scan.validate()?;
        if self.profile_levels < 8 {
            return Err(invalid(
                "profile_levels",
                self.profile_levels,
                "must be at least 8",
            ));
        }
        Ok(())
    }

    /// The rotation taking the input frame to the levelled frame (up to +z).
    fn levelled_from_input(&self) -> Rotation3<f64> {
        let up = Vector3::from(self.up);
        Rotation3::rotation_between(&up, &Vector3::z()).unwrap_or_else(|| {
            // Only `up` anti-parallel to +z has no unique smallest rotation: turn half about x.
            Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        })
    }
}

/// How to find the basal contact.
#[derive(Debug, Clone, Copy)]
pub enum ContactSpec<'a> {
    /// The neck of the cross-section area profile between the rock and its pedestal or the
    /// ground, when the mesh includes them; without a neck, the rock's lowest points (within
    /// [`FragilityConfig::contact_band_m`]).
    Auto,
    /// A given height along up, metres (levelled z). The rock is the part of the mesh above it.
    Height(f64),
    /// A separate closed pedestal mesh in the rock's frame. The contact plane is the pedestal's
    /// highest point under the rock (or the rock's lowest point, if it floats above the pedestal
    /// by at most [`FragilityConfig::pedestal_gap_tolerance_m`]); the contact polygon is the rock's
    /// base there clipped by the pedestal's top.
    Pedestal(&'a TriangleMesh),
    /// A contact polygon measured elsewhere, such as the basal profile of a scan
    /// ([`scan::close_scan`]): points in the input frame, metres. The contact plane is at their
    /// mean height along up and the polygon is their convex hull in it, taken as the rock's
    /// support as it is (not clipped by the rock's own section, which for a closed scan is only a
    /// patched cut). The rock is the part of the mesh above the plane.
    Polygon(&'a [[f64; 3]]),
}

/// How the contact was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContactMethod {
    /// The neck of the area profile (automatic).
    Neck,
    /// The rock's lowest points (automatic, no neck found).
    Base,
    /// A given height.
    Height,
    /// The top of a pedestal mesh.
    Pedestal,
    /// A given contact polygon.
    Polygon,
}

/// α in two opposite directions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OppositePair {
    /// Azimuth of the first direction, degrees in [0, 180) (or the α_min azimuth).
    pub azimuth_deg: f64,
    /// α towards `azimuth_deg`, degrees.
    pub alpha_deg: f64,
    /// α towards `azimuth_deg + 180°`, degrees.
    pub opposite_alpha_deg: f64,
}

/// The result of [`analyze`]; the JSON of `scarp fragility --json`. Frames and units as in the
/// [module documentation](self).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FragilityReport {
    /// The smallest rocking angle over all directions, degrees (exact, not sampled).
    pub alpha_min_deg: f64,
    /// Azimuth in which the rock tips at α_min, degrees.
    pub alpha_min_azimuth_deg: f64,
    /// Quasi-static toppling peak ground acceleration, in units of g: tan(α_min).
    pub toppling_pga_g: f64,
    /// The same in m/s²: g·tan(α_min).
    pub toppling_pga_m_s2: f64,
    /// Volume of the rock above the contact, m³.
    pub volume_m3: f64,
    /// Mass of the rock, kg.
    pub mass_kg: f64,
    /// Density used, kg/m³.
    pub density_kg_m3: f64,
    /// Centre of mass, metres, input frame.
    pub center_of_mass: [f64; 3],
    /// Height of the centre of mass above the contact plane, metres.
    pub com_height_above_contact_m: f64,
    /// Height of the contact plane along up, metres.
    pub contact_height_m: f64,
    /// How the contact was found.
    pub contact_method: ContactMethod,
    /// Area of the convex contact polygon, m².
    pub contact_area_m2: f64,
    /// Area of the rock's cross-section at the contact (non-convex, holes subtracted), m².
    pub section_area_m2: f64,
    /// Vertices of the convex contact polygon, counter-clockwise seen from above, metres, input
    /// frame.
    pub contact_polygon: Vec<[f64; 3]>,
    /// Height of the rock from the contact plane to its top, metres.
    pub rock_height_m: f64,
    /// Width of the contact polygon along the α_min azimuth, metres.
    pub contact_width_m: f64,
    /// `rock_height_m / contact_width_m`.
    pub height_to_width: f64,
    /// α(θ) in degrees for θ = i·360°/n, i = 0..n (n = `azimuth_count`, default 360).
    pub alpha_deg: Vec<f64>,
    /// α for each pair of opposite sampled directions, θ in [0°, 180°).
    pub opposite_pairs: Vec<OppositePair>,
    /// The pair through the α_min azimuth.
    pub alpha_min_pair: OppositePair,
    /// Inertia tensor about the centre of mass, kg·m², input-frame axes.
    pub inertia_kg_m2: [[f64; 3]; 3],
    /// Distance from the centre of mass to the α_min rocking axis, metres (Purvance's R).
    pub rocking_radius_m: f64,
    /// Moment of inertia about the α_min rocking axis, kg·m² (Purvance's I_O).
    pub inertia_about_rocking_axis_kg_m2: f64,
    /// Purvance's frequency parameter p = √(m g R / I_O), rad/s.
    pub purvance_p_rad_s: f64,
    /// Standard deviation of α_min under perturbation, degrees (0 when the study is off).
    pub alpha_min_spread_deg: f64,
    /// Lower end of the 95% interval of α_min, degrees. See [`AlphaInterval`] for what it
    /// spans.
    pub alpha_min_low_deg: f64,
    /// Upper end of the 95% interval of α_min, degrees.
    pub alpha_min_high_deg: f64,
    /// How the interval was formed.
    pub alpha_interval: AlphaInterval,
    /// Details of the perturbation study.
    pub uncertainty: UncertaintyReport,
    /// Up direction used, unit vector, input frame.
    pub up: [f64; 3],
    /// The tilt of the support plane the contact was read in from the plane normal to `up`,
    /// degrees: a scan's support as fitted ([`scan::close_scan`]), 0 where the contact was read
    /// normal to up (every other analysis, and a scan whose support was not levelled).
    #[serde(default)]
    pub support_tilt_deg: f64,
    /// Repairs made to the rock mesh.
    pub repairs: MeshRepairs,
}

/// What the α_min interval of a [`FragilityReport`] spans.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlphaInterval {
    /// Where the interval comes from: `perturbation` (the mesh-noise and contact-height study
    /// alone, for a closed rock with a known contact) or `scan_contact` (also the readings of a
    /// scan's extrapolated contact, [`scan::analyze_scan`]).
    pub source: String,
    /// Contact readings evaluated (0 for `perturbation`).
    pub contact_hypotheses: usize,
    /// Contact readings that gave no polygon.
    pub contact_hypotheses_failed: usize,
    /// Smallest α_min over the contact readings, degrees.
    pub contact_alpha_low_deg: Option<f64>,
    /// Largest α_min over the contact readings, degrees.
    pub contact_alpha_high_deg: Option<f64>,
    /// The independent sources of the interval, each a 95% half-width below and above α_min;
    /// the interval is α_min minus the root sum of squares of the `below_deg`, to α_min plus
    /// that of the `above_deg` (never below 0°).
    pub sources: Vec<IntervalSource>,
    /// 1σ of a scanned contact's height, metres: the `support_plane` source moves the plane by
    /// ±1.96 of it ([`scan::ClosedScan::contact_height_sigma_m`]: the support's measured
    /// roughness and the mesh's error, or, without a support plane, the reach from the neck to
    /// the support seen on part of the turn). `None` for `perturbation`.
    #[serde(default)]
    pub contact_height_sigma_m: Option<f64>,
}

/// One independent source of an α_min interval: how far it may move α_min at 95%.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntervalSource {
    /// What moves α_min: `perturbation` (mesh noise and contact height, the perturbation
    /// study), `support_plane`, `profile_model`, `unseen_support_edge`, `unseen_base`,
    /// `contact_edge`, `deep_fill`, `unseen_shape` or `margin` ([`scan::analyze_closed_scan`]
    /// names each).
    pub name: String,
    /// How far it may lower α_min, degrees (≥ 0).
    pub below_deg: f64,
    /// How far it may raise α_min, degrees (≥ 0).
    pub above_deg: f64,
}

impl IntervalSource {
    /// A source named `name` with the given half-widths, degrees (negative ones are taken as
    /// 0: a source that can only raise α_min does not lower it).
    pub fn new(name: &str, below_deg: f64, above_deg: f64) -> Self {
        Self {
            name: name.into(),
            below_deg: below_deg.max(0.0),
            above_deg: above_deg.max(0.0),
        }
    }
}

/// A report together with the levelled geometry behind it, for figures.
#[derive(Debug, Clone)]
pub struct FragilityAnalysis {
    /// The report.
    pub report: FragilityReport,
    /// The rock cut above the contact and closed, levelled frame.
    pub(crate) rock: Solid,
    /// The body below the contact (pedestal mesh, or the part of the input mesh below it).
    pub(crate) support: Option<Solid>,
    /// Convex contact polygon, levelled xy.
    pub(crate) contact_hull: Vec<Point2<f64>>,
    /// Centre of mass, levelled frame.
    pub(crate) com: Point3<f64>,
    /// Contact height, levelled z.
    pub(crate) contact_height: f64,
    /// α_min azimuth, radians.
    pub(crate) alpha_min_azimuth: f64,
    input_from_levelled: Rotation3<f64>,
}

impl FragilityAnalysis {
    /// Moves the analysis to another input frame, `new_from_old` (a rotation about the origin):
    /// the report's positions, inertia and up, and what [`Self::closed_rock`] and
    /// [`Self::alpha_min_on_contact`] take and give. Heights, azimuths and angles are the
    /// levelled frame's and do not change.
    pub(crate) fn rotate_input_frame(&mut self, new_from_old: &Rotation3<f64>) {
        self.input_from_levelled = new_from_old * self.input_from_levelled;
        let r = &mut self.report;
        let rotate = |p: [f64; 3]| -> [f64; 3] { (new_from_old * Vector3::from(p)).into() };
        r.center_of_mass = rotate(r.center_of_mass);
        r.up = rotate(r.up);
        for p in &mut r.contact_polygon {
            *p = rotate(*p);
        }
        let inertia = Matrix3::from(r.inertia_kg_m2);
        r.inertia_kg_m2 =
            (new_from_old.matrix() * inertia * new_from_old.matrix().transpose()).into();
    }

    /// The closed rock above the contact (section triangulated), in the input frame, metres.
    pub fn closed_rock(&self) -> TriangleMesh {
        self.rock.to_mesh(&self.input_from_levelled)
    }

    /// α_min, degrees, of this rock (its centre of mass) standing on another contact polygon:
    /// points in the input frame, metres, whose mean height along up is the contact plane.
    /// Negative when the centre of mass lies outside it; `None` for a polygon with no area or a
    /// non-finite point.
    pub fn alpha_min_on_contact(&self, polygon: &[[f64; 3]]) -> Option<f64> {
        self.alpha_min_on_contact_with_com_moved(polygon, &Vector3::zeros())
    }

    /// As [`Self::alpha_min_on_contact`], with the centre of mass moved by `com_shift_m`
    /// (input frame, metres).
    pub fn alpha_min_on_contact_with_com_moved(
        &self,
        polygon: &[[f64; 3]],
        com_shift_m: &Vector3<f64>,
    ) -> Option<f64> {
        let levelled_from_input = self.input_from_levelled.inverse();
        let (h, hull) = levelled_polygon(polygon, &levelled_from_input).ok()?;
        let com = self.com + levelled_from_input * com_shift_m;
        let support = rocking::minimum_support(&hull, &com.xy())?;
        Some(support.distance_m.atan2(com.z - h).to_degrees())
    }

    /// Replaces the α_min interval by one of independent sources: the perturbation study's
    /// (as [`analyze_detailed`] recorded it) and `sources`, combined in quadrature on each side.
    /// `contact_alphas` are α_min on the contact readings behind the sources (degrees;
    /// `failed` readings gave none), reported with the interval, as is the contact height's
    /// 1σ `contact_height_sigma_m` the readings moved the plane by.
    pub fn combine_interval(
        &mut self,
        contact_alphas: &[f64],
        failed: usize,
        sources: Vec<IntervalSource>,
        contact_height_sigma_m: f64,
    ) {
        let r = &mut self.report;
        let mut all = std::mem::take(&mut r.alpha_interval.sources);
        all.retain(|s| s.name == "perturbation");
        all.extend(sources);
        let below = all.iter().map(|s| s.below_deg.powi(2)).sum::<f64>().sqrt();
        let above = all.iter().map(|s| s.above_deg.powi(2)).sum::<f64>().sqrt();
        r.alpha_min_low_deg = (r.alpha_min_deg - below).max(0.0);
        r.alpha_min_high_deg = r.alpha_min_deg + above;
        r.alpha_interval = AlphaInterval {
            source: "scan_contact".into(),
            contact_hypotheses: contact_alphas.len() + failed,
            contact_hypotheses_failed: failed,
            contact_alpha_low_deg: contact_alphas.iter().copied().reduce(f64::min),
            contact_alpha_high_deg: contact_alphas.iter().copied().reduce(f64::max),
            sources: all,
            contact_height_sigma_m: Some(contact_height_sigma_m),
        };
    }
}

/// Where the support polygon under the rock comes from.
pub(crate) enum Support<'a> {
    /// The part of this solid just below the contact plane.
    Below(&'a Solid),
    /// A fixed convex polygon (levelled xy), clipped by the rock's section.
    Fixed(&'a [Point2<f64>]),
    /// The contact polygon itself (levelled xy), at the given height even below the rock's
    /// lowest point.
    Exact(&'a [Point2<f64>]),
}

/// One evaluation of the rock at a contact height.
pub(crate) struct Evaluation {
    pub cut: Cut,
    pub mass: MassProperties,
    pub contact_height: f64,
    pub hull: Vec<Point2<f64>>,
    pub min: MinimumSupport,
    pub com_height: f64,
    pub alpha_min_rad: f64,
}

/// Cuts `rock` at `h` (raised to its lowest point if below it), closes it, integrates its mass
/// and finds the contact polygon and the exact α_min (negative when the centre of mass lies
/// outside the contact).
pub(crate) fn evaluate(
    rock: &Solid,
    h: f64,
    support: &Support<'_>,
    band_m: f64,
    config: &FragilityConfig,
) -> Result<Evaluation, FragilityError> {
    let (z_min, z_max) = rock
        .z_range()
        .ok_or(FragilityError::EmptyMesh { mesh: "rock" })?;
    if !h.is_finite() || h >= z_max {
        return Err(FragilityError::ContactOutsideRock {
            contact_height_m: h,
            z_min_m: z_min,
            z_max_m: z_max,
        });
    }
    let plane = h;
    let h = h.max(z_min);
    let cut = cut_above(rock, h)?;
    let integrals = mass::integrate(&cut.solid)?;
    let mass = MassProperties::from_integrals(&integrals, config.density_kg_m3);
    // The rock's base clipped by what supports it (unclipped when either has no area).
    let clipped_base = |lower: &[Point2<f64>]| {
        let upper = rocking::convex_hull(&contact::points_above(&cut.solid, h, band_m));
        if lower.len() >= 3 && upper.len() >= 3 {
            rocking::clip_convex(&upper, lower)
        } else {
            upper
        }
    };
    // The contact, and the support's top that bounds where the rock can land (`None` for a
    // given contact polygon, which already is the whole support, and for a rock given without
    // its support, whose extent is unknown: landing on it could only raise α).
    let (hull, contact_height, landing_support) = match support {
        Support::Exact(hull) => (hull.to_vec(), plane, None),
        Support::Fixed(hull) => (clipped_base(hull), h, Some(hull.to_vec())),
        Support::Below(full) if full.z_range().is_some_and(|(lo, _)| lo < h) => {
            let below = rocking::convex_hull(&contact::points_below(full, h, band_m, false));
            (clipped_base(&below), h, Some(below))
        }
        Support::Below(_) => (clipped_base(&[]), h, None),
    };
    let com = mass.center_of_mass;
    let hull = match landing_support {
        Some(support) => {
            rocking::landing_hull(&hull, &cut.solid.positions, &support, contact_height, &com)
        }
        None => hull,
    };
    let min = rocking::minimum_support(&hull, &com.xy()).ok_or_else(|| {
        FragilityError::Degenerate(format!(
            "the rock and its support do not overlap at the contact height {h} m"
        ))
    })?;
    let com_height = com.z - contact_height;
    Ok(Evaluation {
        alpha_min_rad: min.distance_m.atan2(com_height),
        cut,
        mass,
        contact_height,
        hull,
        min,
        com_height,
    })
}

/// Analyses the fragility of a rock mesh: contact, mass properties, rocking angles and their
/// uncertainty. See the [module documentation](self) for frames, units and steps.
///
/// # Errors
/// - [`FragilityError::InvalidConfig`] for an out-of-range setting (including a zero `up`).
/// - [`FragilityError::InvalidMesh`], [`FragilityError::EmptyMesh`],
///   [`FragilityError::OpenMesh`], [`FragilityError::NonManifold`],
///   [`FragilityError::InconsistentWinding`] or [`FragilityError::Degenerate`] for a rock or
///   pedestal mesh that is not a closed, consistently wound solid.
/// - [`FragilityError::ContactOutsideRock`] for a contact height at or above the rock's top.
/// - [`FragilityError::NoPedestalContact`] when the pedestal is not under the rock.
/// - [`FragilityError::ComOutsideContact`] when the centre of mass is not over the contact.
pub fn analyze(
    mesh: &TriangleMesh,
    contact: ContactSpec<'_>,
    config: &FragilityConfig,
) -> Result<FragilityReport, FragilityError> {
    analyze_detailed(mesh, contact, config).map(|a| a.report)
}

/// As [`analyze`], also returning the levelled geometry (for [`figure::write_figure`] and
/// [`FragilityAnalysis::closed_rock`]).
///
/// # Errors
/// As [`analyze`].
pub fn analyze_detailed(
    mesh: &TriangleMesh,
    contact: ContactSpec<'_>,
    config: &FragilityConfig,
) -> Result<FragilityAnalysis, FragilityError> {
    config.validate()?;
    let levelled_from_input = config.levelled_from_input();
    let input_from_levelled = levelled_from_input.inverse();
    let (solid, repairs) = prepare(mesh, "rock", &levelled_from_input)?;
    let band = config.contact_band_m;

    let pedestal = match contact {
        ContactSpec::Pedestal(p) => Some(prepare(p, "pedestal", &levelled_from_input)?.0),
        _ => None,
    };
    // The support polygon from a pedestal mesh or a given contact polygon (levelled xy).
    let (h, method, given_hull) = match contact {
        ContactSpec::Auto => {
            let neck = contact::find_neck(
                &solid,
                config.profile_levels,
                config.neck_min_area_ratio,
                config.neck_plateau_tolerance,
            );
            tracing::debug!(?neck, "neck search");
            let method = if neck.found {
                ContactMethod::Neck
            } else {
                ContactMethod::Base
            };
            (neck.height_m, method, None)
        }
        ContactSpec::Height(h) => {
            let (lo, hi) = solid
                .z_range()
                .ok_or(FragilityError::EmptyMesh { mesh: "rock" })?;
            if !(h.is_finite() && h < hi) {
                return Err(FragilityError::ContactOutsideRock {
                    contact_height_m: h,
                    z_min_m: lo,
                    z_max_m: hi,
                });
            }
            (h, ContactMethod::Height, None)
        }
        ContactSpec::Pedestal(_) => {
            // Invariant: `pedestal` is `Some` exactly for `ContactSpec::Pedestal`.
            let ped = pedestal
                .as_ref()
                .ok_or(FragilityError::EmptyMesh { mesh: "pedestal" })?;
            let top = contact::pedestal_top(&solid, ped)?;
            let (rock_lo, _) = solid
                .z_range()
                .ok_or(FragilityError::EmptyMesh { mesh: "rock" })?;
            let gap = rock_lo - top;
            if gap > config.pedestal_gap_tolerance_m {
                return Err(FragilityError::NoPedestalContact(format!(
                    "the rock's lowest point is {gap:.4} m above the pedestal's top (tolerance {} m)",
                    config.pedestal_gap_tolerance_m
                )));
            }
            let hull = rocking::convex_hull(&contact::points_below(ped, top, band, true));
            if hull.is_empty() {
                return Err(FragilityError::NoPedestalContact(
                    "the pedestal has no top surface under the rock".into(),
                ));
            }
            (top.max(rock_lo), ContactMethod::Pedestal, Some(hull))
        }
        ContactSpec::Polygon(points) => {
            let (h, hull) = levelled_polygon(points, &levelled_from_input)?;
            (h, ContactMethod::Polygon, Some(hull))
        }
    };

    let given_support = match &given_hull {
        Some(hull) if method == ContactMethod::Polygon => SampleSupport::Exact(hull),
        Some(hull) => SampleSupport::Fixed(hull),
        None => SampleSupport::SelfBelow,
    };
    let eval = evaluate(&solid, h, &given_support.of(&solid), band, config)?;
    let h = eval.contact_height;
    if eval.min.distance_m < 0.0 {
        return Err(FragilityError::ComOutsideContact {
            distance_m: -eval.min.distance_m,
            azimuth_deg: eval.min.azimuth_deg,
        });
    }

    // Rocking angles.
    let com = eval.mass.center_of_mass;
    let com_xy = com.xy();
    let alpha_deg =
        rocking::rocking_angles_deg(&eval.hull, &com_xy, eval.com_height, config.azimuth_count);
    let half = config.azimuth_count / 2;
    let opposite_pairs = (0..half)
        .map(|i| OppositePair {
            azimuth_deg: i as f64 * 360.0 / config.azimuth_count as f64,
            alpha_deg: alpha_deg[i],
            opposite_alpha_deg: alpha_deg[i + half],
        })
        .collect();
    let theta = eval.min.azimuth_deg.to_radians();
    let u = rocking::direction(theta);
    let opposite = rocking::support_distance(&eval.hull, &com_xy, &(-u)).unwrap_or(0.0);
    let alpha_min_pair = OppositePair {
        azimuth_deg: eval.min.azimuth_deg,
        alpha_deg: eval.alpha_min_rad.to_degrees(),
        opposite_alpha_deg: opposite.atan2(eval.com_height).to_degrees(),
    };

    // Purvance's p about the α_min rocking axis.
    let pivot = Point3::new(
        com.x + eval.min.distance_m * u.x,
        com.y + eval.min.distance_m * u.y,
        h,
    );
    let axis = Unit::new_normalize(Vector3::new(-u.y, u.x, 0.0));
    let inertia_o = eval.mass.inertia_about_axis(&pivot, &axis);
    let radius = eval.min.distance_m.hypot(eval.com_height);
    let p = rocking::purvance_p(eval.mass.mass_kg, config.g_m_s2, radius, inertia_o);

    let (_, top) = eval.cut.solid.z_range().unwrap_or((h, h));
    let width = eval.min.distance_m + opposite;

    // Uncertainty.
    let uncertainty = alpha_min_spread(&solid, h, given_support, config);

    // The perturbed range, about the unperturbed value (which it may not contain).
    let alpha = eval.alpha_min_rad.to_degrees();
    let succeeded = uncertainty.samples > uncertainty.failed_samples;
    let (perturbed_low, perturbed_high) = if succeeded {
        (
            uncertainty.alpha_min_lowest_deg.min(alpha),
            uncertainty.alpha_min_highest_deg.max(alpha),
        )
    } else {
        (alpha, alpha)
    };

    let to_input = |p: Point3<f64>| -> [f64; 3] { (input_from_levelled * p).coords.into() };
    let r = input_from_levelled.matrix();
    let inertia: Matrix3<f64> = r * eval.mass.inertia_kg_m2 * r.transpose();
    let tan = eval.alpha_min_rad.tan();
    let report = FragilityReport {
        alpha_min_deg: eval.alpha_min_rad.to_degrees(),
        alpha_min_azimuth_deg: eval.min.azimuth_deg,
        toppling_pga_g: tan,
        toppling_pga_m_s2: config.g_m_s2 * tan,
        volume_m3: eval.mass.volume_m3,
        mass_kg: eval.mass.mass_kg,
        density_kg_m3: config.density_kg_m3,
        center_of_mass: to_input(com),
        com_height_above_contact_m: eval.com_height,
        contact_height_m: h,
        contact_method: method,
        contact_area_m2: rocking::polygon_area(&eval.hull),
        section_area_m2: eval.cut.section.area().max(0.0),
        contact_polygon: eval
            .hull
            .iter()
            .map(|q| to_input(Point3::new(q.x, q.y, h)))
            .collect(),
        rock_height_m: top - h,
        contact_width_m: width,
        height_to_width: if width > 0.0 {
            (top - h) / width
        } else {
            f64::INFINITY
        },
        alpha_deg,
        opposite_pairs,
        alpha_min_pair,
        inertia_kg_m2: inertia.transpose().into(),
        rocking_radius_m: radius,
        inertia_about_rocking_axis_kg_m2: inertia_o,
        purvance_p_rad_s: p,
        alpha_min_spread_deg: uncertainty.alpha_min_std_deg,
        alpha_min_low_deg: perturbed_low,
        alpha_min_high_deg: perturbed_high,
        alpha_interval: AlphaInterval {
            source: "perturbation".into(),
            contact_hypotheses: 0,
            contact_hypotheses_failed: 0,
            contact_alpha_low_deg: None,
            contact_alpha_high_deg: None,
            sources: vec![IntervalSource::new(
                "perturbation",
                alpha - perturbed_low,
                perturbed_high - alpha,
            )],
            contact_height_sigma_m: None,
        },
        uncertainty,
        up: Vector3::from(config.up).normalize().into(),
        support_tilt_deg: 0.0,
        repairs,
    };
    let support_solid = match pedestal {
        Some(p) => Some(p),
        None => solid
            .z_range()
            .filter(|(lo, _)| *lo < h)
            .map(|_| solid.clone()),
    };
    Ok(FragilityAnalysis {
        report,
        rock: eval.cut.solid,
        support: support_solid,
        contact_hull: eval.hull,
        com,
        contact_height: h,
        alpha_min_azimuth: theta,
        input_from_levelled,
    })
}

/// The height along up (mean levelled z) and the convex hull (levelled xy) of a given contact
/// polygon.
///
/// # Errors
/// [`FragilityError::Degenerate`] for non-finite points or a polygon with no area.
fn levelled_polygon(
    points: &[[f64; 3]],
    levelled_from_input: &Rotation3<f64>,
) -> Result<(f64, Vec<Point2<f64>>), FragilityError> {
    if points.iter().flatten().any(|c| !c.is_finite()) {
        return Err(FragilityError::Degenerate(
            "the given contact polygon has a non-finite point".into(),
        ));
    }
    let levelled: Vec<Point3<f64>> = points
        .iter()
        .map(|p| levelled_from_input * Point3::from(*p))
        .collect();
    let hull = rocking::convex_hull(&levelled.iter().map(|p| p.xy()).collect::<Vec<_>>());
    if hull.len() < 3 || rocking::polygon_area(&hull) <= 0.0 {
        return Err(FragilityError::Degenerate(format!(
            "the given contact polygon ({} points) encloses no area",
            points.len()
        )));
    }
    let h = levelled.iter().map(|p| p.z).sum::<f64>() / levelled.len() as f64;
    Ok((h, hull))
}

/// A closed solid: the part of a mesh above a height, with its cut closed.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedCut {
    /// The closed (watertight) mesh, input frame, metres; the cap's faces point down.
    pub mesh: TriangleMesh,
    /// Area of the section that closes it, m² (holes subtracted).
    pub section_area_m2: f64,
    /// Number of section loops (outer boundaries and holes).
    pub section_loops: usize,
}

/// Cuts a closed mesh at `height_m` along `up` (any non-zero vector, input frame) and closes
/// the part above by triangulating the section polygons. Used to flatten a rock's base or to
/// separate it from its pedestal for export.
///
/// # Errors
/// The mesh checks of [`analyze`], [`FragilityError::InvalidConfig`] for a zero `up`, and
/// [`FragilityError::ContactOutsideRock`] when the plane does not leave anything above it.
pub fn cut_and_close(
    mesh: &TriangleMesh,
    up: [f64; 3],
    height_m: f64,
) -> Result<ClosedCut, FragilityError> {
    let config = FragilityConfig {
        up,
        ..FragilityConfig::default()
    };
    config.validate()?;
    let levelled_from_input = config.levelled_from_input();
    let (solid, _) = prepare(mesh, "rock", &levelled_from_input)?;
    let (lo, hi) = solid
        .z_range()
        .ok_or(FragilityError::EmptyMesh { mesh: "rock" })?;
    if !(height_m.is_finite() && height_m < hi) {
        return Err(FragilityError::ContactOutsideRock {
            contact_height_m: height_m,
            z_min_m: lo,
            z_max_m: hi,
        });
    }
    let cut = cut_above(&solid, height_m.max(lo))?;
    Ok(ClosedCut {
        mesh: cut.solid.to_mesh(&levelled_from_input.inverse()),
        section_area_m2: cut.section.area(),
        section_loops: cut.section.loops.len(),
    })
}

/// The levelled-frame horizontal direction of an azimuth in radians.
pub(crate) fn azimuth_direction(azimuth_rad: f64) -> Vector2<f64> {
    rocking::direction(azimuth_rad)
}
