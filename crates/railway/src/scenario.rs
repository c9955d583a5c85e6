//! Track scenarios (TOML with a `[track]` table) and the presets `default` and `paper`.
//!
//! ```toml
//! [simulation]          # all optional
//! dt = 1e-4             # s (the paper preset: 2e-4)
//! theta = 0.6           # θ-scheme weight
//! steps = 17640         # default: the whole cycle, tamping.duration / dt
//! alert = 4e-4          # m
//! reuse_distance = 1e-5 # m, contact geometry reused until a grain moved this far (0 = never)
//! contact_stiffness = 1e6 # N/m per contact point (inf: rigid contacts, the paper preset)
//! tangential_stiffness = 1e6 # N/m, sticking contacts' spring (inf: rigid sticking)
//! max_closure = 7.5e-4  # m, hyperbolic closure: deflection F Vm/(k Vm + F) (inf: F/k)
//! normal_law = "overlap" # force from the measured overlap ("rate": the force carried)
//! overlap_cap = 6e-4    # m, deepest overlap a step's force starts from (default 0.8 max_closure, else 1 mm)
//! overlap_recovery = 0.2  # compliant contacts: fraction of the overlap beyond F/k removed per step (engine default: 0)
//! overlap_slop = 2.5e-4   # m, excess overlap the recovery tolerates
//! output_interval = 200 # steps between rows of series.csv
//! vtk_interval = 1000   # steps between ParaView frames (0 = none)
//! checkpoint_interval = 4000
//!
//! [track]               # see TrackSpec
//! blocks = 1
//! block_size = [0.29, 0.84, 0.22]
//! spacing = 0.6
//! depth = 0.30
//! width = 1.0
//!
//! [ballast]             # see GrainSpec: grading, vertices, elongation, flatness, density
//! grading = "31.5/50"   # or "31.5/50 coarse", "25/50", or { sieves_mm = [...], passing = [...] }
//! seed = 1
//!
//! [preparation]         # see PreparationSpec
//! [tamping]             # see TampingSpec
//! [friction]            # grain_grain, grain_block, grain_tine, grain_wall
//! [indicators]
//! depth = 0.10          # height of the control volumes under the blocks (m)
//! [solver]              # as in engine scenarios
//! [correction]
//! [ddm]
//! ```

use crate::defaults::{
    default_ddm, DEFAULT_ALERT, DEFAULT_DT, DEFAULT_MAX_CLOSURE, DEFAULT_STIFFNESS,
};
use crate::error::{check_range, refuse, Error, FieldError};
use crate::grading::{GradingCurve, GradingTable};
use crate::grains::GrainSpec;
use crate::indicators::Indicators;
use crate::preparation::{
    load_or_prepare_shared, BallastSpec, PrepProgress, PreparationReport, PreparationSpec,
};
use crate::scene::{build_bodies, Blocks, Layout, TrackFriction};
use crate::tamping::{Cycle, TampingSpec};
use crate::track::TrackSpec;
use ballast_engine::laws::NormalLaw;
use ballast_engine::solver::{
    ConvergenceNorm, CorrectionSettings, DdmSettings, Exchange, SolverSettings,
};
use ballast_engine::world::{StepSettings, World};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

/// `[simulation]` of a track scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackSimulation {
    pub dt: f64,
    pub theta: f64,
    /// Alert distance (m): pairs closer than this (plus each body's speculative margin, the
    /// distance it can move in a step) become contacts.
    pub alert: f64,
    /// Reuse distance (m): a pair's contact geometry is reused until a point of either body
    /// moved this far since it was computed; 0 = every pair detected anew each step.
    pub reuse_distance: f64,
    /// Normal stiffness of a contact point (N/m) during the cycle; `None` or `inf`: rigid
    /// contacts (see `ballast_engine::world::StepSettings::contact_stiffness`).
    #[serde(serialize_with = "inf_if_none")]
    pub contact_stiffness: Option<f64>,
    /// Tangential stiffness of a contact point (N/m), with `contact_stiffness` only; `None` or
    /// `inf`: rigid sticking (see `ballast_engine::world::StepSettings::tangential_stiffness`).
    #[serde(serialize_with = "inf_if_none")]
    pub tangential_stiffness: Option<f64>,
    /// Maximum closure of a contact point (m), with `contact_stiffness` only; `None` or `inf`:
    /// the linear law (see `ballast_engine::world::StepSettings::max_closure`).
    #[serde(serialize_with = "inf_if_none")]
    pub max_closure: Option<f64>,
    /// Where a compliant contact's force starts each step from (see
    /// `ballast_engine::laws::NormalLaw`): `"rate"` (the force it carried) or `"overlap"`.
    pub normal_law: NormalLaw,
    /// With `normal_law = "overlap"`: the deepest overlap (m) whose force a step starts from;
    /// `None`: `ballast_engine::laws::default_overlap_cap`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub overlap_cap: Option<f64>,
    /// Overlap recovery β ∈ [0, 1] of the compliant law (see
    /// `ballast_engine::world::StepSettings::overlap_recovery`).
    pub overlap_recovery: f64,
    /// Excess overlap over the elastic deflection the recovery tolerates (m).
    pub overlap_slop: f64,
    /// Steps to run; `None` = the whole cycle.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steps: Option<u64>,
    pub output_interval: u64,
    pub vtk_interval: u64,
    pub checkpoint_interval: u64,
    /// Health check: speed (m/s) beyond which the run is stopped as diverged; `None` = the
    /// default bound of `ballast_engine::health`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_speed: Option<f64>,
    /// Health check: overlap (m) beyond which the run is stopped as diverged; `None` = the
    /// default bound (a fraction of the smaller inradius of the two bodies).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_overlap: Option<f64>,
}

/// Writes an absent stiffness or closure as `inf`, which reads back as the same setting (an
/// absent key would read back as the default preset's value).
fn inf_if_none<S: serde::Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64(v.unwrap_or(f64::INFINITY))
}

impl TrackSimulation {
    /// Reads `inf` stiffnesses and closure as absent, then, for rigid contacts
    /// (`contact_stiffness = inf`) in a file that sets no other setting of the compliant law,
    /// switches the preset's tangential spring, closure and normal law off with its stiffness
    /// rather than refusing them. `given`: the `[simulation]` keys the file sets.
    fn normalise_compliant_law(&mut self, given: Option<&toml::Table>) {
        // `inf` is written for an absent setting (see `inf_if_none`): the same, absent.
        for v in [
            &mut self.contact_stiffness,
            &mut self.tangential_stiffness,
            &mut self.max_closure,
        ] {
            if *v == Some(f64::INFINITY) {
                *v = None;
            }
        }
        if self.contact_stiffness.is_some() {
            return;
        }
        let given = |key: &str| given.is_some_and(|t| t.contains_key(key));
        if !given("tangential_stiffness") {
            self.tangential_stiffness = None;
        }
        if !given("max_closure") {
            self.max_closure = None;
        }
        if !given("normal_law") {
            self.normal_law = NormalLaw::Rate;
        }
    }
}

impl Default for TrackSimulation {
    fn default() -> Self {
        // Elastic contacts whose force follows the measured overlap: with rigid contacts
        // NLGS missed its tolerance on nearly every step of the default cycle, with these it
        // misses it on 0.12 % of them (BENCHMARKS.md, the overlap law and the 1e-4 s step).
        TrackSimulation {
            dt: DEFAULT_DT,
            theta: 0.6,
            alert: DEFAULT_ALERT,
            reuse_distance: ballast_engine::world::default_reuse_distance(),
            contact_stiffness: Some(DEFAULT_STIFFNESS),
            tangential_stiffness: Some(DEFAULT_STIFFNESS),
            max_closure: Some(DEFAULT_MAX_CLOSURE),
            normal_law: NormalLaw::Overlap,
            overlap_cap: None,
            // Tines wedge grains against the block: there the rate form's overlaps drift by
            // millimetres without it (BENCHMARKS.md, the overlap recovery).
            overlap_recovery: 0.2,
            overlap_slop: ballast_engine::world::default_overlap_slop(),
            steps: None,
            // Every 20 ms and 0.1 s of the default cycle.
            output_interval: 200,
            vtk_interval: 1000,
            checkpoint_interval: 4000,
            max_speed: None,
            max_overlap: None,
        }
    }
}

/// `[indicators]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IndicatorSpec {
    /// Height of the control volumes under the blocks (m).
    pub depth: f64,
}

impl Default for IndicatorSpec {
    fn default() -> Self {
        IndicatorSpec { depth: 0.10 }
    }
}

/// The grading as written in a file: a standard's name or a sieve table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
enum GradingInput {
    Named(String),
    /// Checked after reading ([`GradingCurve::from_table`]): inside an untagged enum, the
    /// check's message (which entry, what is allowed) would be lost.
    Table(GradingTable),
}

/// `[ballast]` as written in a file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct BallastInput {
    #[serde(default)]
    grading: Option<GradingInput>,
    #[serde(default)]
    vertices: Option<[usize; 2]>,
    #[serde(default)]
    elongation: Option<f64>,
    #[serde(default)]
    flatness: Option<f64>,
    #[serde(default)]
    density: Option<f64>,
    #[serde(default)]
    seed: Option<u64>,
}

/// A whole track scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackScenario {
    pub simulation: TrackSimulation,
    pub track: TrackSpec,
    pub ballast: BallastSpec,
    pub preparation: PreparationSpec,
    pub tamping: TampingSpec,
    pub friction: TrackFriction,
    pub indicators: IndicatorSpec,
    pub solver: SolverSettings,
    pub correction: CorrectionSettings,
    pub ddm: Option<DdmSettings>,
}

/// The file form of [`TrackScenario`].
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TrackFile {
    #[serde(default)]
    simulation: TrackSimulation,
    track: TrackSpec,
    #[serde(default)]
    ballast: Option<BallastInput>,
    #[serde(default)]
    preparation: PreparationSpec,
    #[serde(default)]
    tamping: TampingSpec,
    #[serde(default)]
    friction: TrackFriction,
    #[serde(default)]
    indicators: IndicatorSpec,
    /// Keys given here override the track defaults ([`track_solver`]) one by one.
    #[serde(default)]
    solver: Option<toml::Table>,
    #[serde(default)]
    correction: CorrectionSettings,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    ddm: Option<DdmSettings>,
}

/// Solver defaults of track runs: stop at a relative natural-map residual of 1e-3 (the
/// measure of the contact law's violation; the Quad norm at 1e-3 stopped with residuals of
/// 1e-2 to 2e-1 and called those steps converged), at most 300 sweeps, the sweeps skipping
/// contacts whose bodies did not move (`skip = 1`). With the default soft contacts nearly
/// every step reaches the tolerance in a few dozen sweeps; a step that does not reports the
/// residual it reached (BENCHMARKS.md).
fn track_solver() -> SolverSettings {
    SolverSettings {
        tolerance: 1e-3,
        max_iterations: 300,
        norm: ConvergenceNorm::NaturalMap,
        skip: 1.0,
        ..SolverSettings::default()
    }
}

/// The track solver defaults with the keys of a `[solver]` table on top (unknown keys and
/// wrong types are refused by name).
fn merge_solver(table: Option<toml::Table>) -> Result<SolverSettings, Error> {
    let Some(table) = table else {
        return Ok(track_solver());
    };
    let mut merged =
        toml::Table::try_from(track_solver()).map_err(|e| Error::Toml(e.to_string()))?;
    merged.extend(table);
    merged
        .try_into()
        .map_err(|e: toml::de::Error| Error::Toml(format!("[solver]: {}", e.message())))
}

/// Writes `top` over `base`, key by key; tables are merged recursively, any other value
/// (arrays included) replaces the base's.
fn overlay(base: &mut toml::Table, top: toml::Table) {
    for (k, v) in top {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(t)) => overlay(b, t),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// True when a scenario text is a track scenario (it has a `[track]` table).
pub fn is_track_scenario(text: &str) -> bool {
    text.parse::<toml::Table>()
        .map(|t| t.contains_key("track"))
        .unwrap_or(false)
}

impl TrackScenario {
    /// The default job: one block and its 4 tines through the paper's cycle (T = 1.764 s,
    /// dt = 1e-4 s, half the paper's, 17,640 steps: 286 steps per period of the 35 Hz
    /// vibration), preparation included, with elastic contacts whose force follows the
    /// measured overlap (see [`TrackSimulation::default`]; BENCHMARKS.md, the overlap law).
    pub fn default_preset() -> Self {
        TrackScenario {
            simulation: TrackSimulation::default(),
            // 0.8 m rather than one spacing (0.6 m): the tines' outer faces stay 0.127 m
            // (1.5 × 63 mm, the grading's top size, and more) from the end walls, so that no
            // grain is trapped between a tine and a wall.
            track: TrackSpec {
                length: Some(0.8),
                ..TrackSpec::default()
            },
            ballast: BallastSpec::default(),
            preparation: PreparationSpec::default(),
            tamping: TampingSpec::default(),
            friction: TrackFriction::default(),
            indicators: IndicatorSpec::default(),
            solver: track_solver(),
            correction: CorrectionSettings::default(),
            ddm: Some(default_ddm()),
        }
    }

    /// The paper's case: 7 blocks on a 3.6 m × 2 m × 0.56 m bed (0.514 m spacing, the paper's
    /// length for 7 blocks; 0.34 m of ballast under the soffits), tamping of the 4th block,
    /// rigid contacts, dt = 2e-4 s, μ = 1 (0.8 against walls), DDM 7×1×1 (7 slabs along the track, x) with
    /// n = m = 1, at most 740 sweeps. The bed is tiled (one block's segment deposited and
    /// repeated) and deposited with μ = 0.3, which with the default 31.5/50 grading holds the
    /// paper's number of grains (88,100) at a bulk compacity of 0.6 (BENCHMARKS.md).
    pub fn paper_preset() -> Self {
        let mut s = Self::default_preset();
        s.track = TrackSpec {
            blocks: 7,
            spacing: 3.6 / 7.0,
            depth: 0.34,
            width: 2.0,
            length: Some(3.6),
            ..TrackSpec::default()
        };
        s.tamping.blocks = vec![4];
        // One block's segment deposited and repeated 7 times: the bed in a fraction of the
        // time of depositing 3.6 m at once; settled 0.15 s as a whole so that the joins come
        // to rest (0.05 s left them moving). Deposited with μ = 0.3 rather than 0.2, which
        // packs this bed denser than a ballast bed (BENCHMARKS.md).
        s.preparation.tiled = true;
        s.preparation.tile_settle_time = 0.15;
        s.preparation.friction = 0.3;
        s.solver.max_iterations = 740;
        // The paper's model: rigid contacts (Signorini-Coulomb) and the midpoint θ-scheme.
        let sim = &mut s.simulation;
        (
            sim.contact_stiffness,
            sim.tangential_stiffness,
            sim.max_closure,
        ) = (None, None, None);
        sim.normal_law = NormalLaw::Rate;
        sim.theta = 0.5;
        sim.dt = 2e-4;
        s.solver.skip = 0.0;
        s.ddm = Some(DdmSettings {
            subdomains: [7, 1, 1],
            ..DdmSettings::default()
        });
        // Rows every 20 ms as the default job; a bigger bed, so frames every 0.1 s.
        s.simulation.output_interval = 100;
        s.simulation.vtk_interval = 500;
        s.simulation.checkpoint_interval = 1000;
        s
    }

    /// A preset by name.
    ///
    /// # Errors
    ///
    /// An unknown name, with the known ones.
    pub fn preset(name: &str) -> Result<Self, FieldError> {
        match name {
            "default" => Ok(Self::default_preset()),
            "paper" => Ok(Self::paper_preset()),
            _ => Err(refuse("--preset", name, "one of: default, paper")),
        }
    }

    /// Parses and validates a track scenario. The file is an overlay on the default preset
    /// ([`TrackScenario::default_preset`]): every key it omits, in every table, takes the
    /// preset's value, so a file holding only `[track]` is the default job.
    ///
    /// # Errors
    ///
    /// TOML syntax or unknown fields (with the line), or the first invalid field.
    pub fn from_toml(text: &str) -> Result<Self, Error> {
        // The file alone first: its shape errors and unknown keys, with their lines.
        let file: toml::Table = toml::from_str::<TrackFile>(text)
            .and_then(|_| toml::from_str(text))
            .map_err(|e| Error::Toml(e.to_string()))?;
        let given = match file.get("simulation") {
            Some(toml::Value::Table(t)) => Some(t.clone()),
            _ => None,
        };
        let mut merged: toml::Table = toml::from_str(&Self::default_preset().to_toml())
            .expect("the default preset's TOML reads back");
        overlay(&mut merged, file);
        let mut f: TrackFile = merged
            .try_into()
            .map_err(|e: toml::de::Error| Error::Toml(e.to_string()))?;
        f.simulation.normalise_compliant_law(given.as_ref());
        let mut grains = GrainSpec::default();
        let mut seed = BallastSpec::default().seed;
        if let Some(b) = f.ballast {
            if let Some(g) = b.grading {
                grains.grading = match g {
                    GradingInput::Table(t) => GradingCurve::from_table(t.sieves_mm, t.passing)
                        .map_err(|e| FieldError {
                            field: format!("ballast.{}", e.field),
                            value: e.value,
                            allowed: e.allowed,
                        })?,
                    GradingInput::Named(n) => match n.as_str() {
                        "31.5/50" => GradingCurve::en13450_31_5_50(),
                        "31.5/50 coarse" => GradingCurve::en13450_31_5_50_coarse(),
                        "25/50" => GradingCurve::en13450_25_50(),
                        _ => {
                            return Err(refuse(
                                "ballast.grading",
                                n,
                                "\"31.5/50\", \"31.5/50 coarse\", \"25/50\" or a table \
                                 { sieves_mm = [...], passing = [...] }",
                            )
                            .into())
                        }
                    },
                };
            }
            grains.vertices = b.vertices.unwrap_or(grains.vertices);
            grains.elongation = b.elongation.unwrap_or(grains.elongation);
            grains.flatness = b.flatness.unwrap_or(grains.flatness);
            grains.density = b.density.unwrap_or(grains.density);
            seed = b.seed.unwrap_or(seed);
        }
        let s = TrackScenario {
            simulation: f.simulation,
            track: f.track,
            ballast: BallastSpec { grains, seed },
            preparation: f.preparation,
            tamping: f.tamping,
            friction: f.friction,
            indicators: f.indicators,
            solver: merge_solver(f.solver)?,
            correction: f.correction,
            ddm: f.ddm,
        };
        s.validate()?;
        Ok(s)
    }

    /// The scenario as a TOML file (what [`TrackScenario::from_toml`] reads back).
    pub fn to_toml(&self) -> String {
        #[derive(Serialize)]
        struct Out<'a> {
            simulation: &'a TrackSimulation,
            track: &'a TrackSpec,
            ballast: BallastOut<'a>,
            preparation: &'a PreparationSpec,
            tamping: &'a TampingSpec,
            friction: &'a TrackFriction,
            indicators: &'a IndicatorSpec,
            solver: toml::Table,
            correction: &'a CorrectionSettings,
            #[serde(skip_serializing_if = "Option::is_none")]
            ddm: Option<&'a DdmSettings>,
        }
        #[derive(Serialize)]
        struct BallastOut<'a> {
            seed: u64,
            vertices: [usize; 2],
            elongation: f64,
            flatness: f64,
            density: f64,
            grading: &'a GradingCurve,
        }
        let g = &self.ballast.grains;
        // The engine leaves `skip = 0` out; here it must be written, or it would read back
        // as the track default.
        let mut solver = toml::Table::try_from(&self.solver).expect("solver settings serialise");
        solver.insert("skip".into(), toml::Value::Float(self.solver.skip));
        toml::to_string(&Out {
            simulation: &self.simulation,
            track: &self.track,
            ballast: BallastOut {
                seed: self.ballast.seed,
                vertices: g.vertices,
                elongation: g.elongation,
                flatness: g.flatness,
                density: g.density,
                grading: &g.grading,
            },
            preparation: &self.preparation,
            tamping: &self.tamping,
            friction: &self.friction,
            indicators: &self.indicators,
            solver,
            correction: &self.correction,
            ddm: self.ddm.as_ref(),
        })
        .expect("scenario serialises")
    }

    /// Checks every field.
    ///
    /// # Errors
    ///
    /// The first invalid field, its value and what is allowed.
    pub fn validate(&self) -> Result<(), Error> {
        let s = &self.simulation;
        check_range("simulation.dt", s.dt, 1e-7, 1e-2, "s")?;
        check_range("simulation.theta", s.theta, 0.5, 1.0, "")?;
        check_range("simulation.alert", s.alert, 0.0, 0.1, "m")?;
        check_range(
            "simulation.reuse_distance",
            s.reuse_distance,
            0.0,
            0.25 * s.alert,
            "m",
        )?;
        if ballast_engine::world::check_contact_stiffness(s.contact_stiffness).is_err() {
            let k = s.contact_stiffness.unwrap_or(f64::NAN);
            return Err(refuse(
                "simulation.contact_stiffness",
                k,
                "> 0 N/m (inf: rigid contacts)",
            )
            .into());
        }
        if let Err(e) = ballast_engine::world::check_tangential_stiffness(
            s.tangential_stiffness,
            s.contact_stiffness,
        ) {
            return Err(ballast_engine::ScenarioError(e).into());
        }
        if let Err(e) = ballast_engine::world::check_max_closure(s.max_closure, s.contact_stiffness)
        {
            return Err(ballast_engine::ScenarioError(e).into());
        }
        if let Err(e) = ballast_engine::world::check_normal_law(
            s.normal_law,
            s.overlap_cap,
            s.contact_stiffness,
            s.max_closure,
        ) {
            return Err(ballast_engine::ScenarioError(e).into());
        }
        check_range(
            "simulation.overlap_recovery",
            s.overlap_recovery,
            0.0,
            1.0,
            "",
        )?;
        check_range("simulation.overlap_slop", s.overlap_slop, 0.0, 0.1, "m")?;
        if s.output_interval == 0 {
            return Err(refuse("simulation.output_interval", 0, "≥ 1 step").into());
        }
        for (field, v) in [
            ("simulation.max_speed", s.max_speed),
            ("simulation.max_overlap", s.max_overlap),
        ] {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(refuse(field, v, "a finite number > 0").into());
            }
        }
        if s.steps == Some(0) {
            return Err(refuse(
                "simulation.steps",
                0,
                "≥ 1 step (or absent: the whole cycle)",
            )
            .into());
        }
        self.track.validate()?;
        // The grain parameters are the file's [ballast] keys: name them so.
        self.ballast.grains.validate().map_err(|e| match e {
            crate::grains::GrainError::Field {
                field,
                value,
                allowed,
            } => Error::Field(FieldError {
                field: format!("ballast.{}", field.trim_start_matches("grains.")),
                value,
                allowed,
            }),
            e => e.into(),
        })?;
        self.preparation.validate()?;
        self.tamping.validate(&self.track)?;
        self.friction.validate()?;
        check_range(
            "indicators.depth",
            self.indicators.depth,
            1e-3,
            self.track.depth,
            "m",
        )?;
        // The engine's settings name their table already ("solver.tolerance = …").
        self.solver.validate()?;
        self.correction.validate()?;
        if let Some(d) = &self.ddm {
            d.validate()?;
        }
        Ok(())
    }

    /// Smallest distance (m) between a tine (blade or shaft, at its outermost, vibration
    /// included) and a wall of the bed. A grain caught between a tine and a wall closer than
    /// about 1.5 grain sizes cannot escape, and the tine crushes it into its neighbours.
    pub fn tine_wall_clearance(&self) -> f64 {
        let cycle = self.tamping.build(&self.track);
        let (len, half_w) = (self.track.length(), 0.5 * self.track.width);
        let a = self.tamping.amplitude;
        cycle
            .tines
            .iter()
            .flat_map(|t| [t.blade, t.shaft])
            .map(|b| {
                (b.min.x - a)
                    .min(len - b.max.x - a)
                    .min(b.min.y + half_w)
                    .min(half_w - b.max.y)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Steps of the run: `simulation.steps`, or the whole cycle.
    pub fn steps(&self) -> u64 {
        self.simulation
            .steps
            .unwrap_or_else(|| (self.tamping.duration() / self.simulation.dt).round() as u64)
    }

    /// The engine's step settings.
    pub(crate) fn step_settings(&self) -> StepSettings {
        let stiffness =
            ballast_engine::world::check_contact_stiffness(self.simulation.contact_stiffness)
                .unwrap_or(None);
        StepSettings {
            dt: self.simulation.dt,
            theta: self.simulation.theta,
            alert: self.simulation.alert,
            reuse_distance: self.simulation.reuse_distance,
            contact_stiffness: stiffness,
            tangential_stiffness: ballast_engine::world::check_tangential_stiffness(
                self.simulation.tangential_stiffness,
                self.simulation.contact_stiffness,
            )
            .unwrap_or(None),
            max_closure: ballast_engine::world::check_max_closure(
                self.simulation.max_closure,
                self.simulation.contact_stiffness,
            )
            .unwrap_or(None),
            normal_law: self.simulation.normal_law,
            overlap_cap: self.simulation.overlap_cap,
            // Inert for rigid contacts: kept at the engine's default there, so that a rigid
            // run's checkpoints do not depend on it.
            overlap_recovery: if stiffness.is_some() {
                self.simulation.overlap_recovery
            } else {
                ballast_engine::world::default_overlap_recovery()
            },
            overlap_slop: self.simulation.overlap_slop,
            solver: self.solver.clone(),
            correction: self.correction.clone(),
            ddm: self.ddm.clone(),
            ..StepSettings::default()
        }
    }

    /// Prepares the bed (or reads it from `cache_dir`) and builds the tamping world at t = 0.
    ///
    /// # Errors
    ///
    /// Invalid parameters, or grains that cannot be generated.
    pub fn build(
        &self,
        cache_dir: Option<&Path>,
        progress: &mut dyn FnMut(PrepProgress),
    ) -> Result<TrackModel, Error> {
        self.build_shared(cache_dir, None, progress)
    }

    /// [`TrackScenario::build`] by the ranks of a distributed run together: the bed prepared
    /// in lockstep ([`crate::preparation::load_or_prepare_shared`]; rank 0 writes the cache).
    /// The world returned solves alone until its caller shares it (`World::set_exchange`).
    ///
    /// # Errors
    ///
    /// As [`TrackScenario::build`].
    pub fn build_shared(
        &self,
        cache_dir: Option<&Path>,
        exchange: Option<&Arc<dyn Exchange>>,
        progress: &mut dyn FnMut(PrepProgress),
    ) -> Result<TrackModel, Error> {
        self.validate()?;
        let (sample, warning) = load_or_prepare_shared(
            &self.track,
            &self.ballast,
            &self.preparation,
            &self.friction,
            cache_dir,
            exchange,
            progress,
        )?;
        let cycle = self.tamping.build(&self.track);
        // Grains numbered along the track: NLGS sweeps the contacts in that order, which took
        // 15 % fewer sweeps over the first 200 steps of the default cycle (lift, start of the
        // insertion) than the deposition order: 79 against 93 per step (along z, y or a Morton
        // curve: 89–93). See BENCHMARKS.md.
        let mut grains = sample.grains.clone();
        grains.sort_by(|a, b| {
            a.position
                .x
                .total_cmp(&b.position.x)
                .then(a.index.cmp(&b.index))
        });
        let (bodies, layout) = build_bodies(
            &self.track,
            &Blocks::Driven(Box::new(cycle.block_driver.clone())),
            Some(&cycle),
            &grains,
            self.ballast.grains.density,
        );
        let indicators = Indicators::new(&self.track, &layout, self.indicators.depth, &bodies);
        let mut world = World::new(bodies, self.friction.table(), self.step_settings());
        world.group_names = crate::scene::GROUP_NAMES.map(String::from).to_vec();
        Ok(TrackModel {
            world,
            layout,
            cycle,
            indicators,
            preparation: sample.report,
            from_cache: sample.from_cache,
            cache_warning: warning,
        })
    }
}

/// A built track model, ready to run.
pub struct TrackModel {
    pub world: World,
    pub layout: Layout,
    pub cycle: Cycle,
    pub indicators: Indicators,
    pub preparation: PreparationReport,
    /// The bed came from the cache.
    pub from_cache: bool,
    /// Set when the prepared bed could not be cached.
    pub cache_warning: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_partial_solver_table_keeps_the_track_defaults_of_the_other_keys() {
        let s = TrackScenario::from_toml("[track]\n[solver]\ntolerance = 1e-4\n").unwrap();
        assert_eq!(s.solver.tolerance, 1e-4);
        assert_eq!(s.solver.max_iterations, 300);
        assert_eq!(s.solver.norm, ConvergenceNorm::NaturalMap);
        let none = TrackScenario::from_toml("[track]\n").unwrap();
        assert_eq!(none.solver, track_solver());
        let e = TrackScenario::from_toml("[track]\n[solver]\nsweeps = 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("[solver]") && e.contains("sweeps"), "{e}");
        let e = TrackScenario::from_toml("[track]\n[solver]\nmax_iterations = \"many\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("[solver]"), "{e}");
    }

    /// A track file is an overlay on the default preset: a bare `[track]` is the default
    /// job, a key sets just itself, and the default preset reads back from its own TOML.
    #[test]
    fn a_track_file_is_an_overlay_on_the_default_preset() {
        let d = TrackScenario::default_preset();
        assert_eq!(
            TrackScenario::from_toml("[track]\nblocks = 1\n").unwrap(),
            d
        );
        assert_eq!(TrackScenario::from_toml(&d.to_toml()).unwrap(), d);
        let s = TrackScenario::from_toml(
            "[track]\n[ddm]\ninner_sweeps = 2\n[tamping]\nsqueeze_force = 1e3\n",
        )
        .unwrap();
        let mut expected = d.clone();
        expected.ddm.as_mut().unwrap().inner_sweeps = 2;
        expected.tamping.squeeze_force = 1e3;
        assert_eq!(s, expected);
        let e = TrackScenario::from_toml("[track]\n[tamping]\nsqueeze_forces = 1e3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("squeeze_forces"), "{e}");
        let e = TrackScenario::from_toml("[track]\n[tamping]\nsqueeze_force = -1.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("tamping.squeeze_force"), "{e}");
    }

    /// The default bed keeps every tine 1.5 of the grading's top size (63 mm) from the walls.
    /// Compliant track runs (the default) recover drifting overlaps; rigid ones keep the
    /// engine's setting, so their checkpoints do not depend on an inert key.
    #[test]
    fn the_overlap_recovery_is_on_for_compliant_track_runs() {
        for soft in [
            "[track]\n",
            "[track]\n[simulation]\ncontact_stiffness = 1e7\n",
        ] {
            let soft = TrackScenario::from_toml(soft).unwrap().step_settings();
            assert_eq!((soft.overlap_recovery, soft.overlap_slop), (0.2, 2.5e-4));
        }
        let off = "[track]\n[simulation]\ncontact_stiffness = 1e7\noverlap_recovery = 0\n";
        let off = TrackScenario::from_toml(off).unwrap().step_settings();
        assert_eq!(off.overlap_recovery, 0.0);
        let rigid = "[track]\n[simulation]\ncontact_stiffness = inf\n";
        let rigid = TrackScenario::from_toml(rigid).unwrap().step_settings();
        assert_eq!(rigid.contact_stiffness, None);
        assert_eq!(
            rigid.overlap_recovery,
            ballast_engine::world::default_overlap_recovery()
        );
    }

    /// The default job's contacts: soft springs, the hyperbolic closure and the overlap law.
    /// `contact_stiffness = inf` alone switches the preset's whole compliant law off; a
    /// compliant setting written beside it is refused, by name.
    #[test]
    fn rigid_contacts_switch_the_compliant_defaults_off() {
        let preset = TrackScenario::default_preset();
        assert_eq!(TrackScenario::from_toml(&preset.to_toml()).unwrap(), preset);
        let d = TrackScenario::from_toml("[track]\n").unwrap().simulation;
        assert_eq!(d, preset.simulation);
        assert_eq!(
            (d.contact_stiffness, d.tangential_stiffness, d.max_closure),
            (Some(1e6), Some(1e6), Some(7.5e-4))
        );
        assert_eq!(d.normal_law, NormalLaw::Overlap);
        let rigid =
            TrackScenario::from_toml("[track]\n[simulation]\ncontact_stiffness = inf\n").unwrap();
        let sim = &rigid.simulation;
        assert_eq!((sim.tangential_stiffness, sim.max_closure), (None, None));
        assert_eq!(sim.normal_law, NormalLaw::Rate);
        let settings = rigid.step_settings();
        assert_eq!(
            (settings.contact_stiffness, settings.max_closure),
            (None, None)
        );
        // Written out and read back: the same scenario.
        assert_eq!(TrackScenario::from_toml(&rigid.to_toml()).unwrap(), rigid);
        let linear = "[track]\n[simulation]\nmax_closure = inf\nnormal_law = \"rate\"\n";
        let linear = TrackScenario::from_toml(linear).unwrap();
        assert_eq!(linear.simulation.max_closure, None);
        assert_eq!(TrackScenario::from_toml(&linear.to_toml()).unwrap(), linear);
        for (key, line) in [
            ("max_closure", "max_closure = 1e-3"),
            ("tangential_stiffness", "tangential_stiffness = 1e6"),
            ("normal_law", "normal_law = \"overlap\""),
        ] {
            let text = format!("[track]\n[simulation]\ncontact_stiffness = inf\n{line}\n");
            let e = TrackScenario::from_toml(&text).unwrap_err().to_string();
            assert!(e.contains(key), "{key}: {e}");
        }
    }

    #[test]
    fn default_tines_stay_clear_of_the_walls() {
        let d = TrackScenario::default_preset();
        let top = d.ballast.grains.grading.max_size_mm() * 1e-3;
        let c = d.tine_wall_clearance();
        assert!(c >= 1.5 * top, "clearance {c} m < 1.5 × {top} m");
        // One spacing long (the former default), a tine's shaft (30 mm thick, centred on the
        // blade 0.1125 m from the block face) came within 24.5 mm of an end wall.
        let mut short = d.clone();
        short.track.length = None;
        assert!((short.tine_wall_clearance() - 0.0245).abs() < 1e-9);
    }

    #[test]
    fn presets_split_the_track_along_its_length() {
        assert_eq!(
            TrackScenario::paper_preset().ddm.unwrap().subdomains,
            [7, 1, 1]
        );
        assert_eq!(TrackScenario::paper_preset().simulation.dt, 2e-4);
        let d = TrackScenario::default_preset();
        assert_eq!(d.ddm.as_ref().unwrap().subdomains, [2, 2, 1]);
        assert_eq!(d.steps(), 17640);
        let paper = TrackScenario::paper_preset();
        assert_eq!(paper.steps(), 8820);
        assert_eq!(paper.simulation.contact_stiffness, None);
        assert_eq!(TrackScenario::from_toml(&paper.to_toml()).unwrap(), paper);
    }

    /// The paper example with 740 fixed sweeps is the paper preset but for its solver stop
    /// (same bed, so the same cache entry).
    #[test]
    fn paper_740_example_is_the_paper_preset() {
        let file = example("paper_740.toml");
        let mut paper = TrackScenario::paper_preset();
        assert_eq!(file.solver.max_iterations, 740);
        assert!(file.solver.tolerance < 1e-20);
        paper.solver = file.solver.clone();
        assert_eq!(file, paper);
    }

    /// The track scenario of `examples/NAME`.
    fn example(name: &str) -> TrackScenario {
        let path = format!("{}/../../examples/{name}", env!("CARGO_MANIFEST_DIR"));
        TrackScenario::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap()
    }

    /// The converged paper example: the paper preset's bed, block and decomposition, with
    /// the default job's contact law, step and solver (and so the preset's cache entry).
    #[test]
    fn paper_converged_example_is_the_paper_case_on_the_default_law() {
        let file = example("paper_converged.toml");
        let (paper, default) = (
            TrackScenario::paper_preset(),
            TrackScenario::default_preset(),
        );
        assert_eq!(file.track, paper.track);
        assert_eq!(file.preparation, paper.preparation);
        assert_eq!(file.tamping, paper.tamping);
        assert_eq!(file.ddm, paper.ddm);
        assert_eq!(file.solver, default.solver);
        let mut sim = default.simulation.clone();
        (
            sim.output_interval,
            sim.vtk_interval,
            sim.checkpoint_interval,
        ) = (
            file.simulation.output_interval,
            file.simulation.vtk_interval,
            file.simulation.checkpoint_interval,
        );
        assert_eq!(file.simulation, sim);
        assert_eq!(file.steps(), default.steps());
    }

    /// The long-track example: the paper's bed made 15 blocks long (same spacing, width,
    /// depth, tiled preparation), the default job's contact law and step, one slab per block.
    #[test]
    fn long_track_example_is_the_paper_bed_made_longer() {
        let file = example("long_track.toml");
        let (paper, default) = (
            TrackScenario::paper_preset(),
            TrackScenario::default_preset(),
        );
        assert_eq!(file.track.blocks, 15);
        assert!((file.track.length() - 15.0 * paper.track.spacing).abs() < 1e-12);
        assert_eq!(
            (file.track.spacing, file.track.depth, file.track.width),
            (paper.track.spacing, paper.track.depth, paper.track.width)
        );
        assert_eq!(file.preparation, paper.preparation);
        assert_eq!(file.tamping.blocks, vec![8]);
        assert_eq!(file.simulation.dt, default.simulation.dt);
        assert_eq!(
            file.simulation.contact_stiffness,
            default.simulation.contact_stiffness
        );
        assert_eq!(file.solver, default.solver);
        assert_eq!(file.ddm.unwrap().subdomains, [15, 1, 1]);
        file.track.validate().unwrap();
    }
}
