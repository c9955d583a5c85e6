//! Scenario files (TOML): bodies, materials, friction, gravity, time stepping, solver, drivers,
//! outputs. Every field is checked; an error names the field, the value and what is allowed.
//!
//! ```toml
//! [simulation]
//! dt = 2e-4            # s
//! steps = 5000         # or: duration = 1.0 (s)
//! theta = 0.5          # in [0.5, 1]
//! gravity = [0, 0, -9.81]
//! alert = 1e-3         # m
//! reuse_distance = 1e-5 # m: contact geometry reused until a grain moved this far (0 = never)
//! contact_stiffness = 1e7 # N/m per contact point (absent or inf = rigid contacts)
//! tangential_stiffness = 1e7 # N/m, sticking contacts' spring (absent = rigid sticking)
//! max_closure = 7.5e-4   # m: hyperbolic law, deflection F Vm/(k Vm + F) (absent = F/k)
//! overlap_recovery = 0   # compliant law: fraction of the overlap beyond F/k removed per step
//! overlap_slop = 2.5e-4  # m: excess overlap the recovery tolerates
//! output_interval = 50 # steps between rows of series.csv
//! checkpoint_interval = 1000 # steps between checkpoints (0 = only at the end)
//! vtk_interval = 500   # steps between ParaView frames (0 = none)
//!
//! [solver]
//! tolerance = 1e-4
//! max_iterations = 1000
//! norm = "quad"        # or "natural_map"
//!
//! [correction]        # overlap post-stabilisation (position only); fraction = 0 turns it off
//! fraction = 0.2
//! slop = 1e-5          # m
//! sweeps = 10
//! max_push = inf       # m per step and contact
//! guard = false        # also hold the open contacts
//! rotation = true      # false: translate the bodies only
//!
//! [ddm]               # domain decomposition (Algorithm 1); absent = monolithic NLGS
//! subdomains = [1, 7, 1]
//! inner_sweeps = 1     # n
//! interface_sweeps = 1 # m
//! balance = "contacts" # or "volume" (the paper's uniform boxes)
//! parallel_interface = true
//! min_parallel_contacts = 4096  # smaller phases run on one thread (× 2/threads; same results)
//!
//! [materials]
//! stone = 2700         # density, kg/m³
//!
//! [friction]
//! default = 1.0
//! pairs = [{ groups = ["grain", "wall"], mu = 0.8 }]
//!
//! [[body]]
//! shape = "plane"
//! point = [0, 0, 0]
//! normal = [0, 0, 1]
//! group = "wall"
//!
//! [[body]]
//! shape = "box"        # or "polyhedron" with vertices = [[x, y, z], …]
//! half_extents = [0.05, 0.05, 0.05]
//! center = [0, 0, 0.05]
//! material = "stone"
//! group = "grain"
//! kind = "dynamic"     # or "kinematic" (with a [body.driver]) or "fixed"
//!
//! [[grains]]           # packs of random grains, see GrainPack
//! count = 300
//! min = [0, 0, 0.02]
//! max_xy = [0.4, 0.4]
//! diameter = [0.025, 0.05]
//! material = "stone"
//! group = "grain"
//! ```

pub mod generate;
pub mod presets;

pub use generate::GrainPack;

use crate::bodies::{BodyKind, BodySet, Driver};
use crate::laws::FrictionTable;
use crate::math::{DQuat, DVec3};
use crate::shapes::ConvexPolyhedron;
use crate::solver::{CorrectionSettings, DdmSettings, SolverSettings};
use crate::world::{StepSettings, World};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

pub use crate::error::ScenarioError;

fn err<T>(msg: impl Into<String>) -> Result<T, ScenarioError> {
    Err(ScenarioError(msg.into()))
}

/// `[simulation]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Simulation {
    pub dt: f64,
    #[serde(default)]
    pub steps: Option<u64>,
    #[serde(default)]
    pub duration: Option<f64>,
    #[serde(default = "half")]
    pub theta: f64,
    #[serde(default = "earth")]
    pub gravity: [f64; 3],
    #[serde(default = "default_alert")]
    pub alert: f64,
    /// Detection reuses a pair's manifold until a point of either body moved this far (m);
    /// 0 = every pair detected anew each step (see `StepSettings::reuse_distance`).
    #[serde(default = "crate::world::default_reuse_distance")]
    pub reuse_distance: f64,
    /// Normal stiffness of a contact point (N/m); absent or `inf`: rigid contacts (see
    /// `StepSettings::contact_stiffness`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_stiffness: Option<f64>,
    /// Tangential stiffness of a contact point (N/m), with `contact_stiffness` only; absent or
    /// `inf`: rigid sticking (see `StepSettings::tangential_stiffness`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tangential_stiffness: Option<f64>,
    /// Maximum closure of a contact point (m), with `contact_stiffness` only; absent or `inf`:
    /// the linear law (see `StepSettings::max_closure`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_closure: Option<f64>,
    /// Where a compliant contact's force starts each step from: `"rate"` (default) or
    /// `"overlap"` (see `StepSettings::normal_law`).
    #[serde(default, skip_serializing_if = "crate::laws::NormalLaw::is_rate")]
    pub normal_law: crate::laws::NormalLaw,
    /// With `normal_law = "overlap"`: the overlap cap (m; see `StepSettings::overlap_cap`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overlap_cap: Option<f64>,
    /// Overlap recovery β ∈ [0, 1] of the compliant law (see `StepSettings::overlap_recovery`).
    #[serde(default = "crate::world::default_overlap_recovery")]
    pub overlap_recovery: f64,
    /// Excess overlap the recovery tolerates (m; see `StepSettings::overlap_slop`).
    #[serde(default = "crate::world::default_overlap_slop")]
    pub overlap_slop: f64,
    #[serde(default = "default_interval")]
    pub output_interval: u64,
    /// Steps between checkpoints (one is also written at the end of a run); 0 = only at the end.
    #[serde(default = "default_checkpoint_interval")]
    pub checkpoint_interval: u64,
    /// Steps between ParaView frames; 0 = none.
    #[serde(default = "default_vtk_interval")]
    pub vtk_interval: u64,
    /// Health check: speed (m/s) of a body's fastest point beyond which the run is stopped as
    /// diverged; `None` = the default bound (see [`crate::health`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_speed: Option<f64>,
    /// Health check: overlap (m) beyond which the run is stopped as diverged; `None` = the
    /// default bound, a fraction of the smaller inradius of the two bodies in contact.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_overlap: Option<f64>,
}

fn default_checkpoint_interval() -> u64 {
    1000
}
fn default_vtk_interval() -> u64 {
    500
}

fn half() -> f64 {
    0.5
}
fn earth() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}
fn default_alert() -> f64 {
    1e-3
}
fn default_interval() -> u64 {
    50
}

/// `[friction]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Friction {
    pub default: f64,
    #[serde(default)]
    pub pairs: Vec<FrictionPair>,
}

/// One entry of `friction.pairs`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionPair {
    pub groups: [String; 2],
    pub mu: f64,
}

/// Shape of a `[[body]]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    Polyhedron,
    Box,
    Plane,
}

/// One `[[body]]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    pub shape: ShapeKind,
    #[serde(default = "dynamic")]
    pub kind: BodyKind,
    #[serde(default = "default_group")]
    pub group: String,
    /// Material name (density from `[materials]`); required for dynamic polyhedra and boxes.
    #[serde(default)]
    pub material: Option<String>,
    /// Polyhedron vertices, world coordinates (m).
    #[serde(default)]
    pub vertices: Option<Vec<[f64; 3]>>,
    /// Box half extents (m).
    #[serde(default)]
    pub half_extents: Option<[f64; 3]>,
    /// Box centre (m).
    #[serde(default)]
    pub center: Option<[f64; 3]>,
    /// Box rotation as a rotation vector (axis × angle, rad).
    #[serde(default)]
    pub rotation: Option<[f64; 3]>,
    /// Plane point and outward normal.
    #[serde(default)]
    pub point: Option<[f64; 3]>,
    #[serde(default)]
    pub normal: Option<[f64; 3]>,
    /// Initial velocities.
    #[serde(default)]
    pub velocity: Option<[f64; 3]>,
    #[serde(default)]
    pub angular_velocity: Option<[f64; 3]>,
    /// Imposed velocity (kinematic bodies).
    #[serde(default)]
    pub driver: Option<Driver>,
}

fn dynamic() -> BodyKind {
    BodyKind::Dynamic
}
fn default_group() -> String {
    "default".into()
}

/// One `[[grains]]` pack.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, from = "GrainsFile")]
pub struct GrainsSpec {
    #[serde(flatten)]
    pub pack: GrainPack,
    pub material: String,
    #[serde(default = "grain_group")]
    pub group: String,
}

/// `[[grains]]` as read: the pack's keys spelled out rather than flattened, so that a value of
/// the wrong type is reported at its key (`count = 1e12`: "expected usize" at `count`, not at
/// the `[[grains]]` header, which is all serde's buffered flatten can say).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GrainsFile {
    count: usize,
    min: [f64; 3],
    max_xy: [f64; 2],
    diameter: [f64; 2],
    #[serde(default = "generate::default_vertices")]
    vertices: [usize; 2],
    #[serde(default = "generate::one")]
    elongation: f64,
    #[serde(default = "generate::one")]
    flatness: f64,
    #[serde(default)]
    seed: u64,
    material: String,
    #[serde(default = "grain_group")]
    group: String,
}

impl From<GrainsFile> for GrainsSpec {
    fn from(f: GrainsFile) -> Self {
        GrainsSpec {
            pack: GrainPack {
                count: f.count,
                min: f.min,
                max_xy: f.max_xy,
                diameter: f.diameter,
                vertices: f.vertices,
                elongation: f.elongation,
                flatness: f.flatness,
                seed: f.seed,
            },
            material: f.material,
            group: f.group,
        }
    }
}

fn grain_group() -> String {
    "grain".into()
}

/// A whole scenario file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub simulation: Simulation,
    #[serde(default)]
    pub solver: SolverSettings,
    #[serde(default)]
    pub correction: CorrectionSettings,
    /// Domain decomposition; absent = monolithic NLGS.
    #[serde(default)]
    pub ddm: Option<DdmSettings>,
    #[serde(default)]
    pub materials: BTreeMap<String, f64>,
    pub friction: Friction,
    #[serde(default, rename = "body")]
    pub bodies: Vec<BodySpec>,
    #[serde(default)]
    pub grains: Vec<GrainsSpec>,
}

/// Memory of a grain besides its shape's vertices (bytes): body state, about 8 contact points
/// and their local problems, detection entries.
pub const BYTES_PER_GRAIN: u128 = 5_000;
/// Memory per vertex of a grain's shape (bytes): vertices, faces, edges and their adjacency.
pub const BYTES_PER_VERTEX: u128 = 200;

/// The memory this process may still use (bytes): Linux's `MemAvailable`; `None` elsewhere.
pub fn available_memory() -> Option<u128> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// A byte count for a message (`8.0 TB`).
fn bytes(n: u128) -> String {
    let units = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut x = n as f64;
    let mut u = 0;
    while x >= 1000.0 && u + 1 < units.len() {
        x /= 1000.0;
        u += 1;
    }
    format!("{x:.1} {}", units[u])
}

/// The advice for `[key]` written where `[[key]]` is meant.
fn single_table(key: &str) -> String {
    format!(
        "\n[{key}] is a single table: use [[{key}]] (an array of tables, one [[{key}]] header \
         per entry)"
    )
}

/// Mistakes of shape that the typed reader reports obscurely ("invalid type: map, expected a
/// sequence") or not at all (a third group in a friction pair is dropped).
fn check_shape(v: &toml::Table) -> Result<(), ScenarioError> {
    for key in ["body", "grains"] {
        if v.get(key).is_some_and(toml::Value::is_table) {
            return err(single_table(key).trim_start().to_string());
        }
    }
    let pairs = v
        .get("friction")
        .and_then(|f| f.get("pairs"))
        .and_then(toml::Value::as_array);
    for (k, p) in pairs.into_iter().flatten().enumerate() {
        if let Some(g) = p.get("groups").and_then(toml::Value::as_array) {
            if g.len() != 2 {
                return err(format!(
                    "friction.pairs[{k}].groups has {} entries: a friction pair names exactly \
                     two groups, e.g. groups = [\"grain\", \"wall\"]",
                    g.len()
                ));
            }
        }
    }
    Ok(())
}

/// The health check of `world` with the bounds a scenario may set (`None`: the default).
pub fn health_check(
    world: &World,
    max_speed: Option<f64>,
    max_overlap: Option<f64>,
) -> crate::health::HealthCheck {
    let mut h = crate::health::HealthCheck::new(world);
    if let Some(v) = max_speed {
        h = h.with_max_speed(v);
    }
    if let Some(d) = max_overlap {
        h = h.with_max_overlap(d);
    }
    h
}

/// A vector as a scenario file writes it, `[x, y, z]` (not Rust's `DVec3(x, y, z)`).
fn v3(v: DVec3) -> String {
    format!("[{}, {}, {}]", v.x, v.y, v.z)
}

/// A body kind as a scenario file writes it.
fn kind_name(k: BodyKind) -> &'static str {
    match k {
        BodyKind::Dynamic => "dynamic",
        BodyKind::Kinematic => "kinematic",
        BodyKind::Fixed => "fixed",
    }
}

/// A shape as a scenario file writes it.
fn shape_name(k: ShapeKind) -> &'static str {
    match k {
        ShapeKind::Polyhedron => "polyhedron",
        ShapeKind::Box => "box",
        ShapeKind::Plane => "plane",
    }
}

fn vec3(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

fn finite3(field: &str, a: [f64; 3]) -> Result<DVec3, ScenarioError> {
    if a.iter().all(|x| x.is_finite()) {
        Ok(vec3(a))
    } else {
        err(format!("{field} = {a:?} must have finite components"))
    }
}

impl Scenario {
    /// Parses TOML text (syntax and unknown-field errors come from the TOML reader, with the
    /// line), then validates.
    pub fn from_toml(text: &str) -> Result<Self, ScenarioError> {
        match text.parse::<toml::Table>() {
            Ok(v) => check_shape(&v)?,
            // `[body]` beside `[[body]]` is a syntax error (a key defined twice): say why, on
            // the parser's line rather than after its quoted source (8 lines in all).
            Err(e) => {
                if let Some(k) = ["body", "grains"]
                    .into_iter()
                    .find(|k| text.lines().any(|l| l.trim() == format!("[{k}]")))
                {
                    let at = e.span().map_or(String::new(), |r| {
                        format!(" at line {}", text[..r.start].matches('\n').count() + 1)
                    });
                    return err(format!(
                        "TOML parse error{at}: {}{}",
                        e.message().trim().replace('\n', "; "),
                        single_table(k)
                    ));
                }
            }
        }
        let s: Scenario = toml::from_str(text).map_err(|e| ScenarioError(e.to_string()))?;
        s.validate()?;
        Ok(s)
    }

    /// The health check of this scenario's run on `world` (built from it, not yet stepped):
    /// the default bounds, or those of `[simulation] max_speed` / `max_overlap`.
    pub fn health_check(&self, world: &World) -> crate::health::HealthCheck {
        health_check(
            world,
            self.simulation.max_speed,
            self.simulation.max_overlap,
        )
    }

    /// The scenario as TOML text that [`Scenario::from_toml`] reads back equal (comments of the
    /// original file are not kept).
    pub fn to_toml(&self) -> Result<String, ScenarioError> {
        toml::to_string(self).map_err(|e| ScenarioError(format!("cannot write the scenario: {e}")))
    }

    /// Bytes the run of this scenario is expected to need: per grain [`BYTES_PER_GRAIN`] plus
    /// [`BYTES_PER_VERTEX`] per vertex of its largest shape (shape, state, contacts and their
    /// local problems, at about 8 contact points a grain).
    pub fn memory_estimate(&self) -> u128 {
        let per = |vertices: usize| BYTES_PER_GRAIN + BYTES_PER_VERTEX * vertices as u128;
        let grains: u128 = self
            .grains
            .iter()
            .map(|g| g.pack.count as u128 * per(g.pack.vertices[1]))
            .sum();
        let bodies: u128 = self
            .bodies
            .iter()
            .map(|b| per(b.vertices.as_ref().map_or(8, Vec::len)))
            .sum();
        grains + bodies
    }

    /// Refuses a scenario whose [`Scenario::memory_estimate`] exceeds `available` bytes (when
    /// known) before anything is allocated, naming the largest grain pack.
    pub fn check_memory(&self, available: Option<u128>) -> Result<(), ScenarioError> {
        let (Some(avail), need) = (available, self.memory_estimate()) else {
            return Ok(());
        };
        if need <= avail {
            return Ok(());
        }
        let field = match self
            .grains
            .iter()
            .enumerate()
            .max_by_key(|(_, g)| g.pack.count)
        {
            Some((k, g)) => format!("grains[{k}].count = {}", g.pack.count),
            None => format!("{} [[body]] entries", self.bodies.len()),
        };
        err(format!(
            "{field}: the scenario needs about {} of memory (about {} kB a grain: shape, state \
             and contacts) but this machine has {} available; use fewer grains",
            bytes(need),
            (BYTES_PER_GRAIN + BYTES_PER_VERTEX * 20) / 1000,
            bytes(avail)
        ))
    }

    /// Number of steps to run.
    pub fn steps(&self) -> u64 {
        match (self.simulation.steps, self.simulation.duration) {
            (Some(n), _) => n,
            (None, Some(d)) => (d / self.simulation.dt).round() as u64,
            (None, None) => 0,
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let s = &self.simulation;
        if !(s.dt.is_finite() && s.dt > 0.0 && s.dt <= 0.1) {
            return err(format!("simulation.dt = {} must be in (0, 0.1] s", s.dt));
        }
        match (s.steps, s.duration) {
            (Some(_), Some(_)) => {
                return err("simulation: give either steps or duration, not both");
            }
            (None, None) => return err("simulation: steps or duration is required"),
            (None, Some(d)) if !(d.is_finite() && d > 0.0) => {
                return err(format!("simulation.duration = {d} must be > 0 s"));
            }
            _ => {}
        }
        if !(0.5..=1.0).contains(&s.theta) {
            return err(format!(
                "simulation.theta = {} must be in [0.5, 1]",
                s.theta
            ));
        }
        finite3("simulation.gravity", s.gravity)?;
        if !(s.alert.is_finite() && s.alert > 0.0) {
            return err(format!("simulation.alert = {} must be > 0 m", s.alert));
        }
        if !(s.reuse_distance >= 0.0 && s.reuse_distance <= 0.25 * s.alert) {
            return err(format!(
                "simulation.reuse_distance = {} must be in [0, alert/4 = {}] m",
                s.reuse_distance,
                0.25 * s.alert
            ));
        }
        crate::world::check_contact_stiffness(s.contact_stiffness).map_err(ScenarioError)?;
        crate::world::check_tangential_stiffness(s.tangential_stiffness, s.contact_stiffness)
            .map_err(ScenarioError)?;
        crate::world::check_max_closure(s.max_closure, s.contact_stiffness)
            .map_err(ScenarioError)?;
        crate::world::check_normal_law(
            s.normal_law,
            s.overlap_cap,
            s.contact_stiffness,
            s.max_closure,
        )
        .map_err(ScenarioError)?;
        crate::world::check_overlap_recovery(s.overlap_recovery, s.overlap_slop)
            .map_err(ScenarioError)?;
        if s.output_interval == 0 {
            return err("simulation.output_interval = 0 must be ≥ 1 step");
        }
        for (field, v) in [("max_speed", s.max_speed), ("max_overlap", s.max_overlap)] {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return err(format!(
                    "simulation.{field} = {v} must be a finite number > 0 ({})",
                    if field == "max_speed" { "m/s" } else { "m" }
                ));
            }
        }
        self.solver.validate()?;
        self.correction.validate()?;
        if let Some(d) = &self.ddm {
            d.validate()?;
        }
        for (name, rho) in &self.materials {
            if !(rho.is_finite() && *rho > 0.0) {
                return err(format!(
                    "materials.{name} = {rho} must be a density > 0 kg/m³"
                ));
            }
        }
        let mu_ok = |mu: f64| mu.is_finite() && mu >= 0.0;
        if !mu_ok(self.friction.default) {
            return err(format!(
                "friction.default = {} must be ≥ 0",
                self.friction.default
            ));
        }
        // The groups the bodies have, in order of first appearance.
        let mut groups: Vec<&str> = Vec::new();
        for g in self.bodies.iter().map(|b| b.group.as_str()) {
            if !groups.contains(&g) {
                groups.push(g);
            }
        }
        for g in self.grains.iter().map(|g| g.group.as_str()) {
            if !groups.contains(&g) {
                groups.push(g);
            }
        }
        for (k, p) in self.friction.pairs.iter().enumerate() {
            if !mu_ok(p.mu) {
                return err(format!("friction.pairs[{k}].mu = {} must be ≥ 0", p.mu));
            }
            for g in &p.groups {
                if !groups.contains(&g.as_str()) {
                    return err(format!(
                        "friction.pairs[{k}].groups names \"{g}\", which no [[body]] or \
                         [[grains]] has (groups: {})",
                        groups
                            .iter()
                            .map(|g| format!("\"{g}\""))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ));
                }
            }
            let same = |q: &FrictionPair| {
                let (a, b) = (&p.groups, &q.groups);
                (a[0] == b[0] && a[1] == b[1]) || (a[0] == b[1] && a[1] == b[0])
            };
            if let Some(j) = self.friction.pairs[..k].iter().position(same) {
                let q = &self.friction.pairs[j];
                if q.mu != p.mu {
                    return err(format!(
                        "friction.pairs[{k}] gives groups \"{}\" and \"{}\" mu = {}, but \
                         friction.pairs[{j}] gives them mu = {}: one coefficient per pair",
                        p.groups[0], p.groups[1], p.mu, q.mu
                    ));
                }
            }
        }
        for (k, b) in self.bodies.iter().enumerate() {
            self.validate_body(k, b)?;
        }
        for (k, g) in self.grains.iter().enumerate() {
            g.pack
                .validate()
                .map_err(|e| ScenarioError(format!("grains[{k}].{e}")))?;
            self.density(&format!("grains[{k}]"), Some(&g.material))?;
        }
        if self.bodies.is_empty() && self.grains.is_empty() {
            return err("the scenario has no [[body]] and no [[grains]]");
        }
        Ok(())
    }

    fn density(&self, at: &str, material: Option<&String>) -> Result<f64, ScenarioError> {
        let Some(m) = material else {
            return err(format!(
                "{at}.material is required (one of {:?})",
                self.material_names()
            ));
        };
        match self.materials.get(m) {
            Some(d) => Ok(*d),
            None => err(format!(
                "{at}.material = \"{m}\" is not defined in [materials] (defined: {:?})",
                self.material_names()
            )),
        }
    }

    fn material_names(&self) -> Vec<&String> {
        self.materials.keys().collect()
    }

    fn validate_body(&self, k: usize, b: &BodySpec) -> Result<(), ScenarioError> {
        let at = format!("body[{k}]");
        let forbid = |name: &str, present: bool| {
            if present {
                err(format!(
                    "{at}.{name} is not allowed for shape = \"{}\"",
                    shape_name(b.shape)
                ))
            } else {
                Ok(())
            }
        };
        match b.shape {
            ShapeKind::Plane => {
                if b.kind != BodyKind::Fixed {
                    return err(format!(
                        "{at}.kind = \"{}\": a plane must be \"fixed\"",
                        kind_name(b.kind)
                    ));
                }
                let Some(p) = b.point else {
                    return err(format!("{at}.point is required"));
                };
                let Some(n) = b.normal else {
                    return err(format!("{at}.normal is required"));
                };
                finite3(&format!("{at}.point"), p)?;
                let n = finite3(&format!("{at}.normal"), n)?;
                if n.length() < 1e-12 {
                    return err(format!("{at}.normal = {} must be a non-zero vector", v3(n)));
                }
                forbid("vertices", b.vertices.is_some())?;
                forbid("half_extents", b.half_extents.is_some())?;
                forbid("driver", b.driver.is_some())?;
            }
            ShapeKind::Box | ShapeKind::Polyhedron => {
                if b.shape == ShapeKind::Box {
                    let Some(h) = b.half_extents else {
                        return err(format!("{at}.half_extents is required"));
                    };
                    let h = finite3(&format!("{at}.half_extents"), h)?;
                    if h.min_element() <= 0.0 {
                        return err(format!("{at}.half_extents = {} must be > 0", v3(h)));
                    }
                    let Some(c) = b.center else {
                        return err(format!("{at}.center is required"));
                    };
                    finite3(&format!("{at}.center"), c)?;
                    if let Some(r) = b.rotation {
                        finite3(&format!("{at}.rotation"), r)?;
                    }
                    forbid("vertices", b.vertices.is_some())?;
                } else {
                    if b.vertices.is_none() {
                        return err(format!("{at}.vertices is required"));
                    }
                    forbid("half_extents", b.half_extents.is_some())?;
                    forbid("center", b.center.is_some())?;
                    forbid("rotation", b.rotation.is_some())?;
                }
                forbid("point", b.point.is_some())?;
                forbid("normal", b.normal.is_some())?;
                self.build_shape(k, b)?;
                if b.kind == BodyKind::Dynamic {
                    self.density(&at, b.material.as_ref())?;
                }
            }
        }
        if let Some(v) = b.velocity {
            finite3(&format!("{at}.velocity"), v)?;
        }
        if let Some(v) = b.angular_velocity {
            finite3(&format!("{at}.angular_velocity"), v)?;
        }
        match (&b.driver, b.kind) {
            (Some(d), BodyKind::Kinematic) => {
                d.validate()
                    .map_err(|e| ScenarioError(format!("{at}.driver.{e}")))?;
                if let Some(p) = d.attached_to {
                    let parent_ok = self.bodies.get(p).is_some_and(|pb| {
                        p != k
                            && pb.kind == BodyKind::Kinematic
                            && pb.driver.as_ref().is_none_or(|pd| pd.attached_to.is_none())
                    });
                    if !parent_ok {
                        return err(format!(
                            "{at}.driver.attached_to = {p} must be the index of another \
                             kinematic [[body]] (0..{}) that is not attached itself",
                            self.bodies.len()
                        ));
                    }
                }
            }
            (Some(_), kind) => {
                return err(format!(
                    "{at}.driver is only allowed for kind = \"kinematic\" (got \"{}\")",
                    kind_name(kind)
                ))
            }
            _ => {}
        }
        Ok(())
    }

    fn build_shape(
        &self,
        k: usize,
        b: &BodySpec,
    ) -> Result<crate::shapes::PolyhedronBuild, ScenarioError> {
        let at = format!("body[{k}]");
        let built = match b.shape {
            ShapeKind::Box => {
                let h = vec3(b.half_extents.unwrap_or_default());
                ConvexPolyhedron::cuboid(h).map(|mut p| {
                    let q = DQuat::from_scaled_axis(vec3(b.rotation.unwrap_or_default()));
                    p.position = vec3(b.center.unwrap_or_default()) + q * p.position;
                    p.orientation = (q * p.orientation).normalize();
                    p
                })
            }
            _ => {
                let pts: Vec<DVec3> = b
                    .vertices
                    .as_deref()
                    .unwrap_or_default()
                    .iter()
                    .map(|a| vec3(*a))
                    .collect();
                ConvexPolyhedron::from_points(&pts)
            }
        };
        built.map_err(|e| {
            let field = if b.shape == ShapeKind::Box {
                "half_extents"
            } else {
                "vertices"
            };
            ScenarioError(format!("{at}.{field}: {e}"))
        })
    }

    /// Builds the world. Groups are numbered in order of first appearance (bodies, then grain
    /// packs, then friction pairs).
    pub fn build(&self) -> Result<World, ScenarioError> {
        self.validate()?;
        self.check_memory(available_memory())?;
        let mut groups: Vec<String> = Vec::new();
        let mut group_id = |name: &str| -> u32 {
            match groups.iter().position(|g| g == name) {
                Some(i) => i as u32,
                None => {
                    groups.push(name.to_string());
                    (groups.len() - 1) as u32
                }
            }
        };
        let mut bodies = BodySet::default();
        for (k, b) in self.bodies.iter().enumerate() {
            let g = group_id(&b.group);
            let i = match b.shape {
                ShapeKind::Plane => bodies.add_plane(
                    vec3(b.point.unwrap_or_default()),
                    vec3(b.normal.unwrap_or_default()),
                    g,
                ),
                _ => {
                    let shape = self.build_shape(k, b)?;
                    let released = b.driver.as_ref().is_some_and(|d| d.release_at.is_some());
                    let density = match b.kind {
                        BodyKind::Dynamic => {
                            self.density(&format!("body[{k}]"), b.material.as_ref())?
                        }
                        // A released or force-limited driven body moves with its mass.
                        BodyKind::Kinematic
                            if released
                                || b.driver.as_ref().is_some_and(|d| d.is_force_limited()) =>
                        {
                            self.density(&format!("body[{k}]"), b.material.as_ref())?
                        }
                        _ => 1.0,
                    };
                    bodies.add_polyhedron(shape, density, b.kind, g)
                }
            };
            if let Some(v) = b.velocity {
                bodies.velocity[i] = vec3(v);
            }
            if let Some(w) = b.angular_velocity {
                bodies.set_angular_velocity(i, vec3(w));
            }
            bodies.driver[i] = b.driver.clone().map(Box::new);
        }
        for (k, gs) in self.grains.iter().enumerate() {
            let g = group_id(&gs.group);
            let density = self.density(&format!("grains[{k}]"), Some(&gs.material))?;
            let grains = gs
                .pack
                .build()
                .map_err(|e| ScenarioError(format!("grains[{k}]: {e}")))?;
            for p in grains {
                bodies.add_polyhedron(p, density, BodyKind::Dynamic, g);
            }
        }
        let mut friction = FrictionTable::new(self.friction.default);
        for p in &self.friction.pairs {
            let (a, b) = (group_id(&p.groups[0]), group_id(&p.groups[1]));
            friction.set(a, b, p.mu);
        }
        let s = &self.simulation;
        let settings = StepSettings {
            dt: s.dt,
            theta: s.theta,
            gravity: vec3(s.gravity),
            alert: s.alert,
            reuse_distance: s.reuse_distance,
            contact_stiffness: crate::world::check_contact_stiffness(s.contact_stiffness)
                .unwrap_or(None),
            tangential_stiffness: crate::world::check_tangential_stiffness(
                s.tangential_stiffness,
                s.contact_stiffness,
            )
            .unwrap_or(None),
            max_closure: crate::world::check_max_closure(s.max_closure, s.contact_stiffness)
                .unwrap_or(None),
            normal_law: s.normal_law,
            overlap_cap: s.overlap_cap,
            overlap_recovery: s.overlap_recovery,
            overlap_slop: s.overlap_slop,
            solver: self.solver.clone(),
            correction: self.correction.clone(),
            ddm: self.ddm.clone(),
            ..StepSettings::default()
        };
        let mut world = World::new(bodies, friction, settings);
        world.group_names = groups;
        Ok(world)
    }
}
