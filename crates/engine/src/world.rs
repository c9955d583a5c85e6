//! The Moreau-Jean time step (θ-method) over bodies → detection → contacts → local problems →
//! NLGS → update, with per-phase timers.
//!
//! One step `[tᵢ, tᵢ₊₁]`, `h = tᵢ₊₁ − tᵢ`:
//! 1. detect contacts at `qᵢ` (gaps, normals, frames), warm-start from the previous step;
//! 2. free velocities: dynamic bodies `v_free = vᵢ + h g`, `ω_free = ωᵢ`; kinematic bodies take
//!    their driver's velocity at `tᵢ₊₁`; fixed bodies 0;
//! 3. local problems and NLGS give `Vᵢ₊₁` and the impulses `r`;
//! 4. update: `xᵢ₊₁ = xᵢ + h (θ vᵢ₊₁ + (1 − θ) vᵢ)`, `qᵢ₊₁ = exp(h (θ ωᵢ₊₁ + (1 − θ) ωᵢ)) qᵢ`,
//!    world angular momentum `Lᵢ₊₁ = Lᵢ + I_w(qᵢ)(ωᵢ₊₁ − ω_free)` (the contact torques' impulse),
//!    and `ωᵢ₊₁ = I_w(qᵢ₊₁)⁻¹ Lᵢ₊₁`; overlaps are reduced by a position-only pseudo-velocity
//!    (see [`crate::solver::correction`]), which leaves the velocities untouched.

use crate::bodies::{BodyKind, BodySet, Limits};
use crate::contacts::ContactSet;
use crate::detection::{ghosts, Detector, RawContact};
use crate::laws::{default_overlap_cap, driven_overlap_cap, Elastic, FrictionTable, NormalLaw};
use crate::math::{DMat3, DQuat, DVec3};
use crate::solver::correction::{self, pseudo_velocities};
use crate::solver::delassus::{slot, LocalBuilder};
use crate::solver::exchange::PairOwners;
use crate::solver::partition::{self, SortedAxes, LEFT_OUT, STATIC};
use crate::solver::Exchange;
use crate::solver::{
    ddm, CorrectionSettings, DdmSettings, DriveRows, LocalProblem, Nlgs, Partition, SolveReport,
    SolverBody, SolverSettings,
};
use crate::timing::{Lap, PhaseTimes};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Time-stepping settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepSettings {
    /// Time step h (s).
    pub dt: f64,
    /// θ ∈ [0.5, 1].
    pub theta: f64,
    /// Gravity (m/s²).
    pub gravity: DVec3,
    /// Alert distance (m): pairs closer than this become contacts.
    pub alert: f64,
    /// A contact persists (warm start) if it moved less than this fraction of the smaller body
    /// radius in body 1's frame.
    pub match_fraction: f64,
    /// Reuse distance (m): detection reuses a pair's contact manifold while no point of either
    /// body moved by more than this since the manifold was computed (0 = every pair detected
    /// anew each step). See [`crate::detection::coherence`].
    #[serde(default = "default_reuse_distance")]
    pub reuse_distance: f64,
    /// Normal stiffness of a contact point (N/m); `None`: rigid contacts (Moreau-Jean's
    /// Signorini law). With a stiffness the normal law is the rate form of an elastic contact:
    /// over a step the normal force changes by `k` times the approach `h uₙ` (see
    /// [`crate::solver::Nlgs`]), so forces in a jammed, hyperstatic packing are those of stiff
    /// elastic grains instead of any of the rigid law's unbounded set of self-stresses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_stiffness: Option<f64>,
    /// Tangential stiffness of a contact point (N/m), with [`Self::contact_stiffness`] only;
    /// `None`: sticking contacts are rigid tangentially (Coulomb's law as such). The same
    /// rate form as the normal law: over a step a sticking contact's tangential force changes
    /// by `k_t` times its tangential displacement `h u_t`, from the force it carried, within
    /// the friction cone (the Cundall-Strack spring in NSCD form). A wedged grain at `μ = 1`
    /// then carries the elastic share of its load, not any of the rigid law's self-stresses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tangential_stiffness: Option<f64>,
    /// Maximum closure `V_m` of a compliant contact point (m): its elastic deflection under a
    /// force `F` is `F V_m/(k V_m + F)` instead of `F/k`, the hyperbolic closure law of rock
    /// joints (see [`crate::laws::closure`]): as soft as [`Self::contact_stiffness`] under light
    /// loads, stiffer without bound as the deflection nears `V_m`. `None`: the linear law.
    /// Only with [`Self::contact_stiffness`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_closure: Option<f64>,
    /// Where a compliant contact's normal force starts each step from: the force it carried
    /// (the rate form, the default) or the force its measured overlap holds (see
    /// [`NormalLaw`]). Only with [`Self::contact_stiffness`].
    #[serde(default, skip_serializing_if = "NormalLaw::is_rate")]
    pub normal_law: NormalLaw,
    /// With [`NormalLaw::Overlap`]: the deepest overlap (m) whose elastic force a step starts
    /// from (below `max_closure`); `None`: [`default_overlap_cap`]. A contact with a body that
    /// is not dynamic has the larger cap [`driven_overlap_cap`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overlap_cap: Option<f64>,
    /// Overlap recovery of the compliant law, β ∈ [0, 1]: the fraction of a contact's overlap
    /// in excess of its elastic deflection `F/k` (beyond [`Self::overlap_slop`]) that the law
    /// asks the contact to remove within a step (a separation speed `β excess / h` added to
    /// its Signorini condition, see [`crate::solver::Nlgs`]); 0 = off. Without it nothing in
    /// the rate form ties the overlap to the force, and overlaps drift by millimetres where
    /// contact points churn. Only with [`Self::contact_stiffness`].
    #[serde(default = "default_overlap_recovery")]
    pub overlap_recovery: f64,
    /// Excess overlap over `F/k` the recovery tolerates (m). With the recovery on, the
    /// position correction too treats only the excess over `F/k` as an overlap (see
    /// [`crate::solver::correction::overlaps`]): the law owns the elastic deflection.
    #[serde(default = "default_overlap_slop")]
    pub overlap_slop: f64,
    /// NLGS settings.
    pub solver: SolverSettings,
    /// Overlap post-stabilisation.
    pub correction: CorrectionSettings,
    /// Domain decomposition (Algorithm 1); `None` = monolithic NLGS.
    pub ddm: Option<DdmSettings>,
}

/// Checks a scenario's `simulation.contact_stiffness` (N/m per contact point): `None` or `inf`
/// is a rigid contact, anything else must be a number > 0. Returns the value
/// [`StepSettings::contact_stiffness`] takes.
pub fn check_contact_stiffness(k: Option<f64>) -> Result<Option<f64>, String> {
    match k {
        None => Ok(None),
        Some(k) if k == f64::INFINITY => Ok(None),
        Some(k) if k > 0.0 && k.is_finite() => Ok(Some(k)),
        Some(k) => Err(format!(
            "simulation.contact_stiffness = {k} must be > 0 N/m (inf: rigid contacts)"
        )),
    }
}

/// Checks a setting of the compliant law that needs `simulation.contact_stiffness`: absent,
/// or `> 0` with a finite stiffness (`normal`, as written); `inf` means off (`None`).
fn check_compliant_setting(
    field: &str,
    value: Option<f64>,
    normal: Option<f64>,
    allowed: &str,
) -> Result<Option<f64>, String> {
    let normal = check_contact_stiffness(normal).unwrap_or(None);
    match value {
        None => Ok(None),
        Some(v) if v == f64::INFINITY => Ok(None),
        Some(v) if v > 0.0 && v.is_finite() => match normal {
            Some(_) => Ok(Some(v)),
            None => Err(format!(
                "simulation.{field} = {v} needs compliant contacts: set \
                 simulation.contact_stiffness (> 0 N/m) too"
            )),
        },
        Some(v) => Err(format!("simulation.{field} = {v} must be {allowed}")),
    }
}

/// Checks a scenario's `simulation.tangential_stiffness` (N/m): absent, or `> 0` with a
/// finite `simulation.contact_stiffness` (`normal`, as written); `inf` means rigid
/// tangentially (`None`).
pub fn check_tangential_stiffness(
    k: Option<f64>,
    normal: Option<f64>,
) -> Result<Option<f64>, String> {
    check_compliant_setting(
        "tangential_stiffness",
        k,
        normal,
        "> 0 N/m (inf: rigid sticking)",
    )
}

/// Checks a scenario's `simulation.max_closure` (m): absent, or `> 0` with a finite
/// `simulation.contact_stiffness` (`normal`, as written); `inf` means the linear law (`None`).
pub fn check_max_closure(vm: Option<f64>, normal: Option<f64>) -> Result<Option<f64>, String> {
    check_compliant_setting("max_closure", vm, normal, "> 0 m (inf: the linear law)")
}

impl Default for StepSettings {
    fn default() -> Self {
        Self {
            dt: 2e-4,
            theta: 0.5,
            gravity: DVec3::new(0.0, 0.0, -9.81),
            alert: 1e-3,
            match_fraction: 0.1,
            reuse_distance: default_reuse_distance(),
            contact_stiffness: None,
            tangential_stiffness: None,
            max_closure: None,
            normal_law: NormalLaw::Rate,
            overlap_cap: None,
            overlap_recovery: default_overlap_recovery(),
            overlap_slop: default_overlap_slop(),
            solver: SolverSettings::default(),
            correction: CorrectionSettings::default(),
            ddm: None,
        }
    }
}

/// Default [`StepSettings::overlap_recovery`]: off, the rate form alone. It pays where
/// driven tools wedge grains (the track model's default is 0.2); in piles settling from a
/// pour it pays with a tangential stiffness, but with rigid sticking the measurements
/// disagree between step sizes (BENCHMARKS.md, the correction on the excess).
pub fn default_overlap_recovery() -> f64 {
    0.0
}

/// Default [`StepSettings::overlap_slop`]: 0.25 mm, a quarter of the 1 mm an overlap may reach
/// in a trusted run; below it the rate form alone decides.
pub fn default_overlap_slop() -> f64 {
    2.5e-4
}

/// Checks a scenario's `simulation.normal_law` and `simulation.overlap_cap` (m): the overlap
/// law needs compliant contacts; the cap is a number > 0, below `max_closure` (as written).
pub fn check_normal_law(
    law: NormalLaw,
    cap: Option<f64>,
    normal: Option<f64>,
    max_closure: Option<f64>,
) -> Result<(), String> {
    let compliant = check_contact_stiffness(normal).unwrap_or(None).is_some();
    if law == NormalLaw::Overlap && !compliant {
        return Err(
            "simulation.normal_law = \"overlap\" needs compliant contacts: set \
                    simulation.contact_stiffness (> 0 N/m) too"
                .to_string(),
        );
    }
    if let Some(c) = cap {
        let vm = check_max_closure(max_closure, normal).unwrap_or(None);
        if !(c.is_finite() && c > 0.0 && vm.is_none_or(|vm| c < vm)) {
            return Err(format!(
                "simulation.overlap_cap = {c} must be > 0 m{}",
                vm.map_or(String::new(), |vm| format!(
                    " and below max_closure = {vm} m"
                ))
            ));
        }
        if law != NormalLaw::Overlap {
            return Err(format!(
                "simulation.overlap_cap = {c} needs simulation.normal_law = \"overlap\""
            ));
        }
    }
    Ok(())
}

/// Checks a scenario's `simulation.overlap_recovery` (β ∈ [0, 1]) and `simulation.overlap_slop`
/// (m, finite and ≥ 0).
pub fn check_overlap_recovery(beta: f64, slop: f64) -> Result<(), String> {
    if !(0.0..=1.0).contains(&beta) {
        return Err(format!(
            "simulation.overlap_recovery = {beta} must be in [0, 1] (0: off)"
        ));
    }
    if !(slop.is_finite() && slop >= 0.0) {
        return Err(format!("simulation.overlap_slop = {slop} must be ≥ 0 m"));
    }
    Ok(())
}

/// Default [`StepSettings::reuse_distance`]: 10 µm, a hundredth of the engine's default alert
/// distance (a settled grain is re-examined once its points have moved that far).
pub fn default_reuse_distance() -> f64 {
    1e-5
}

/// What one step did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StepReport {
    pub step: u64,
    /// Time at the end of the step.
    pub time: f64,
    pub contacts: usize,
    pub solve: SolveReport,
    /// Largest overlap `max(−g, 0)` among the contacts detected at the start of the step (m).
    pub max_penetration: f64,
    /// The two bodies of that overlap (meaningful when it is positive).
    #[serde(default)]
    pub deepest: [u32; 2],
    pub times: PhaseTimes,
}

/// A simulation: bodies, contacts, laws, settings, clock and timers.
#[derive(Debug)]
pub struct World {
    pub bodies: BodySet,
    /// The step's contacts; in a domain-decomposed run shared between ranks, those this rank
    /// holds (see [`World::holds_contact`], [`World::gather_contacts`]).
    pub contacts: ContactSet,
    pub friction: FrictionTable,
    pub settings: StepSettings,
    /// Current time (s).
    pub time: f64,
    /// Steps done.
    pub step_index: u64,
    /// Cumulated phase times.
    pub timers: PhaseTimes,
    /// Names of the body groups, indexed by group number (empty when the builder gave none):
    /// messages name a body's group with them.
    pub group_names: Vec<String>,
    /// [`initial_state_digest`] of the state the run started from, recorded at its first step
    /// (or read from the checkpoint it resumed from): checkpoints carry it, so a checkpoint is
    /// never resumed under a scenario with another initial state.
    pub(crate) origin: Option<u64>,
    pub(crate) detector: Detector,
    /// Work done by each force-limited drive since t = 0 (J), by driven body, in body order:
    /// `Σ λ · v̄` over the steps, with `v̄ = θ v⁺ + (1 − θ) v⁻` the velocity the update moves
    /// the body with (translation and rotation).
    pub(crate) drive_work: Vec<(u32, f64)>,
    /// How far each force-limited translation lags behind its program (m, world axes), by
    /// driven body, in body order: `Σ h (p̄ − (v̄ − s̄))` over the steps, with `p̄`, `s̄` the
    /// program's and the superposed velocities weighted like `v̄`.
    pub(crate) drive_lag: Vec<(u32, DVec3)>,
    /// The force-limited drives of the last step: rebuilt by every step, kept as its result
    /// (their impulses are the machine's forces).
    drives: Vec<DriveRows>,
    /// The ranks this world's DDM solves are shared with, in a run distributed over processes
    /// (see [`crate::solver::exchange`]); `None`: it solves alone.
    exchange: Option<Arc<dyn Exchange>>,
    /// When each rank holds its own pairs ([`World::holds_contact`]): the step's number of
    /// contacts over all ranks (counted by the solve's census).
    pub(crate) contact_total: usize,
    /// The step pipeline's buffers: nothing in them carries over from one step to the next
    /// (see [`World::release_scratch`]).
    scratch: Scratch,
}

/// The buffers a step works in, kept between steps only to reuse their allocations (Rapier's
/// split of state and pipeline): a step rebuilds every one of them from the [`World`]'s state
/// before reading it, so dropping them changes no result.
#[derive(Debug, Default)]
struct Scratch {
    raw: Vec<RawContact>,
    /// Where the contacts of the step before go while the new ones are built (the warm start
    /// reads them).
    previous: ContactSet,
    locals: Vec<LocalProblem>,
    /// The free velocities, then the solved ones, of the bodies that have a slot (see
    /// `slots`); the free angular velocities and the correction's pseudo-velocities alike.
    solver_bodies: Vec<SolverBody>,
    free_w: Vec<DVec3>,
    pseudo: Vec<SolverBody>,
    /// On ranks that hold their own pairs, where each body's solver body lies in
    /// `solver_bodies` ([`LEFT_OUT`] for a grain neither owned nor read here: a rank keeps
    /// solver bodies of its own grains, its ghosts and the bodies that are not grains only);
    /// empty otherwise (every body at its own index).
    slots: Vec<u32>,
    ddm_workspace: ddm::DdmWorkspace,
    /// Per body, the body whose velocities it takes in the solver (itself, or the body it is
    /// attached to); empty when no body is attached.
    attach: Vec<u32>,
    /// A preparation made by [`World::detect`] that the next [`World::step`] solves.
    pending: Option<(f64, PhaseTimes)>,
    /// The bodies' orders along the axes of the last partition (a starting point only).
    sorted_axes: SortedAxes,
}

impl World {
    /// A world at t = 0.
    /// Kinematic bodies start with their driver's velocity at t = 0.
    pub fn new(mut bodies: BodySet, friction: FrictionTable, settings: StepSettings) -> Self {
        bodies.compact_shapes();
        bodies.shrink_to_fit();
        for i in 0..bodies.len() {
            if let (BodyKind::Kinematic, Some(d)) = (bodies.kind[i], &bodies.driver[i]) {
                let (v, w) = d.velocity(0.0);
                bodies.velocity[i] = v;
                bodies.angular_velocity[i] = w;
            }
        }
        Self {
            bodies,
            contacts: ContactSet::default(),
            friction,
            settings,
            time: 0.0,
            step_index: 0,
            timers: PhaseTimes::default(),
            group_names: Vec::new(),
            origin: None,
            detector: Detector::default(),
            drive_work: Vec::new(),
            drive_lag: Vec::new(),
            drives: Vec::new(),
            exchange: None,
            contact_total: 0,
            scratch: Scratch::default(),
        }
        .with_attached_velocities()
    }

    /// Attached bodies start with the velocity of the body they are part of.
    fn with_attached_velocities(mut self) -> Self {
        self.refresh_attach();
        for i in 0..self.scratch.attach.len() {
            let p = self.scratch.attach[i] as usize;
            if p != i {
                let b = &mut self.bodies;
                let arm = b.position[i] - b.position[p];
                b.velocity[i] = b.velocity[p] + b.angular_velocity[p].cross(arm);
                b.angular_velocity[i] = b.angular_velocity[p];
            }
        }
        self
    }

    /// Recomputes [`World::attach`] from the drivers (an index out of range attaches nothing;
    /// scenario files refuse it).
    fn refresh_attach(&mut self) {
        let b = &self.bodies;
        self.scratch.attach.clear();
        if b.driver.iter().flatten().any(|d| d.attached_to.is_some()) {
            let n = b.len();
            self.scratch.attach.extend((0..n).map(|i| {
                match b.driver[i].as_ref().and_then(|d| d.attached_to) {
                    Some(p) if p < n && p != i && b.kind[i] == BodyKind::Kinematic => p as u32,
                    _ => i as u32,
                }
            }));
        }
    }

    /// The driver of body `i` and its bounds if it is a force-limited driven body this step.
    pub(crate) fn force_limited(&self, i: usize) -> Option<(&crate::bodies::Driver, Limits)> {
        force_limited(&self.bodies, i, self.time, self.time + self.settings.dt)
    }

    /// The name of group `g` (its number when the builder gave no names).
    pub fn group_name(&self, g: u32) -> String {
        self.group_names
            .get(g as usize)
            .cloned()
            .unwrap_or_else(|| g.to_string())
    }

    /// The digest of the state this run started from: recorded at the first step, read from
    /// the checkpoint a run resumed from, or, before the first step, that of the current state.
    /// `None` for a world stepped from a checkpoint written before this was recorded.
    pub fn origin_digest(&self) -> Option<u64> {
        self.origin
            .or_else(|| (self.step_index == 0).then(|| initial_state_digest(&self.bodies)))
    }

    /// The force-limited drives of the last step, in body order: `impulse_v / dt` is the force
    /// each drive exerted on its body (N), `impulse_w / dt` the torque.
    pub fn drives(&self) -> &[DriveRows] {
        &self.drives
    }

    /// The work (J) the drive of body `i` has done on it since t = 0: its force times the
    /// distance it moved, step by step (translation and rotation; 0 for a body that never had
    /// a force-limited drive). Negative when the body was pushed back against its drive.
    pub fn drive_work(&self, i: usize) -> f64 {
        value_of(&self.drive_work, i)
    }

    /// How far (m, per world axis) the force-limited drive of body `i` lags behind its
    /// program: the program's displacement since t = 0 less the body's, the superposed
    /// motion taken out (zero for a drive that never yielded, and for other bodies).
    pub fn drive_lag(&self, i: usize) -> DVec3 {
        value_of(&self.drive_lag, i)
    }

    /// The partition of this step: boxes over the dynamic bodies' centres, weighted by
    /// `1 + number of contacts` when balancing by contacts. On ranks that hold their own
    /// pairs the ranks find it together: a collective, every rank calls it at the same point.
    pub fn partition(&self, d: &DdmSettings) -> Partition {
        self.partition_from(d, &mut SortedAxes::default())
    }

    /// [`World::partition`] from the bodies' orders along the axes of the last call (see
    /// [`Partition::build_from`]).
    fn partition_from(&self, d: &DdmSettings, sorted: &mut SortedAxes) -> Partition {
        let n = self.bodies.len();
        // Force-limited driven bodies are written by the solver: they belong to the subdomain
        // of their centre like the grains.
        let dynamic: Vec<bool> = (0..n)
            .map(|i| self.bodies.kind[i] == BodyKind::Dynamic || self.force_limited(i).is_some())
            .collect();
        if self.detector.hold {
            // The ranks find the cuts together, each counting its own bodies and the bodies
            // of the contacts it holds; then each places its own bodies, and the ranks share
            // those that changed subdomain since the last solve.
            let ex = self.exchange.as_deref().expect("a rank holds pairs");
            let positions = &self.bodies.position;
            let cuts = partition::shared_cuts(
                ex,
                positions,
                &dynamic,
                &self.partition_counts(ex.rank()),
                d.subdomains,
                d.balance,
            );
            let last = self.detector.owners.as_ref();
            let subdomain = partition::shared_subdomains(
                ex,
                positions,
                &dynamic,
                d.subdomains,
                &cuts,
                |i| self.body_owner(i) == ex.rank(),
                |i| last.map_or(STATIC, |o| o.placed(i)),
            );
            return Partition::from_subdomains(d.subdomains, subdomain);
        }
        let mut weights = vec![1.0; n];
        for k in 0..self.contacts.len() {
            weights[self.contacts.body1[k] as usize] += 1.0;
            weights[self.contacts.body2[k] as usize] += 1.0;
        }
        Partition::build_from(
            &self.bodies.position,
            &dynamic,
            d.subdomains,
            d.balance,
            &weights,
            sorted,
        )
    }

    /// How many times rank `rank` counts each body toward the partition's weights: once each
    /// body it owns (the owner of its subdomain at the last solve; rank 0 for a body that had
    /// none), once more each body of each contact it holds. Over the ranks, a body's counts
    /// add up to its weight `1 + contacts`. Before the first solve has placed the pairs (the
    /// first detection on ranks) no rank holds contacts yet, and every body weighs 1.
    fn partition_counts(&self, rank: usize) -> Vec<u32> {
        let n = self.bodies.len();
        if self.detector.owners.is_none() {
            return vec![u32::from(rank == 0); n];
        }
        let mut counts: Vec<u32> = (0..n)
            .map(|i| u32::from(self.body_owner(i) == rank))
            .collect();
        for k in 0..self.contacts.len() {
            counts[self.contacts.body1[k] as usize] += 1;
            counts[self.contacts.body2[k] as usize] += 1;
        }
        counts
    }

    /// Who holds each pair at a run's first detection on ranks (no solve has placed the
    /// pairs yet): the owners of a partition of the current positions, every interface pair
    /// with its lower subdomain. Close to where the step's solve places them, so that few
    /// pairs move then (any rule gives the same results: it only decides where a pair is
    /// tested and kept).
    fn first_owners(&self) -> PairOwners {
        let d = self
            .settings
            .ddm
            .as_ref()
            .expect("a rank holds pairs with [ddm]");
        let size = self.exchange.as_ref().map_or(1, |e| e.size());
        let partition = self.partition_from(d, &mut SortedAxes::default());
        PairOwners::new(&partition, Vec::new(), size, &self.scratch.attach)
    }

    /// The elastic law and the overlap caps (between grains, and of a grain against a body
    /// that is not dynamic) with [`NormalLaw::Overlap`] on compliant contacts (see
    /// [`build_local_problems`]); `None` for the rate form and for rigid contacts.
    fn overlap_law(&self) -> Option<(Elastic, [f64; 2])> {
        let s = &self.settings;
        match (s.normal_law, s.contact_stiffness) {
            (NormalLaw::Overlap, Some(_)) => {
                let cap = s
                    .overlap_cap
                    .unwrap_or_else(|| default_overlap_cap(s.max_closure));
                Some((
                    self.nlgs().elastic(),
                    [cap, driven_overlap_cap(cap, s.max_closure)],
                ))
            }
            _ => None,
        }
    }

    /// The NLGS solver configured for this world.
    pub fn nlgs(&self) -> Nlgs {
        let h = self.settings.dt;
        Nlgs {
            skip_drift: 0.0,
            skip_now: false,
            settings: self.settings.solver.clone(),
            h_theta: h * self.settings.theta,
            compliance: self
                .settings
                .contact_stiffness
                .map_or(0.0, |k| 1.0 / (k * h * h)),
            recovery: self
                .settings
                .contact_stiffness
                .map_or(0.0, |_| self.settings.overlap_recovery),
            tangential_compliance: match (
                self.settings.contact_stiffness,
                self.settings.tangential_stiffness,
            ) {
                (Some(_), Some(kt)) => 1.0 / (kt * h * h),
                _ => 0.0,
            },
            inv_h: 1.0 / h,
            overlap_per_impulse: self
                .settings
                .contact_stiffness
                .map_or(0.0, |k| 1.0 / (k * h)),
            recovery_slop: self.settings.overlap_slop,
            closure_impulse: match (self.settings.contact_stiffness, self.settings.max_closure) {
                (Some(k), Some(vm)) => k * h * vm,
                _ => 0.0,
            },
        }
    }

    /// Candidate pairs whose contact manifold the last detection reused from the step before
    /// (temporal coherence, see [`StepSettings::reuse_distance`]), and candidate pairs in all.
    pub fn detection_reuse(&self) -> (usize, usize) {
        self.detector.reuse_counts()
    }

    /// Bodies whose world geometry the last detection held: every body, except on a rank of
    /// a domain-decomposed run that holds its own pairs, which places only the bodies they
    /// may join (its subdomains' and those within reach of them).
    pub fn detection_bodies(&self) -> usize {
        self.detector.placed_bodies()
    }

    /// The local problems of the step being prepared (after [`World::prepare`] or
    /// [`World::detect`]), in the contacts' order. Empty after a step with `[ddm]` that was not
    /// prepared so, and on ranks that hold their own pairs: the solver builds them straight
    /// into its subdomains' buckets.
    pub fn local_problems(&self) -> &[LocalProblem] {
        &self.scratch.locals
    }

    /// The local problems the domain-decomposed solver built in the last step (see
    /// [`crate::solver::ddm::DdmWorkspace::local_problems`]): over K ranks, this rank's share.
    pub fn ddm_local_problems(&self) -> usize {
        self.scratch.ddm_workspace.local_problems()
    }

    /// The bodies the domain-decomposed solver numbered in the last step (see
    /// [`crate::solver::ddm::DdmWorkspace::bodies`]): over K ranks, those this rank's part read.
    pub fn ddm_bodies(&self) -> usize {
        self.scratch.ddm_workspace.bodies()
    }

    /// The solver bodies (free velocities after [`World::prepare`]), one per body in body
    /// order (on ranks that hold their own pairs, of the bodies up to date on the rank only).
    pub fn solver_bodies(&self) -> &[SolverBody] {
        &self.scratch.solver_bodies
    }

    /// The first phase of a step on its own (LMGC90's ChiPy style): detection at `qᵢ` with
    /// warm start, free velocities and local problems, kept for the next [`World::step`],
    /// which then solves and integrates without detecting again. Between the two the step's
    /// contacts ([`World::local_problems`], [`World::contact_problem`]) can be read. Calling it
    /// again before the step does nothing. Returns the largest overlap (m).
    pub fn detect(&mut self) -> f64 {
        if self.scratch.pending.is_none() {
            self.scratch.pending = Some(self.prepare());
        }
        self.scratch.pending.map_or(0.0, |p| p.0)
    }

    /// Whether [`World::detect`] has prepared the next step.
    pub fn is_detected(&self) -> bool {
        self.scratch.pending.is_some()
    }

    /// Shares this world's domain-decomposed solves with other ranks, each holding the same
    /// scene and stepping it in lockstep (see [`crate::solver::exchange`]); `None`: solves
    /// alone. Results are bit-identical either way; a monolithic solve (no `[ddm]`) runs whole
    /// on every rank.
    pub fn set_exchange(&mut self, exchange: Option<Arc<dyn Exchange>>) {
        self.detector.exchange = exchange.clone();
        self.exchange = exchange;
    }

    /// The ranks this world's solves are shared between (1 when it solves alone).
    pub fn ranks(&self) -> usize {
        self.exchange.as_ref().map_or(1, |e| e.size())
    }

    /// This process's rank among [`World::ranks`] (0 when it solves alone).
    pub fn rank(&self) -> usize {
        self.exchange.as_ref().map_or(0, |e| e.rank())
    }

    /// The ranks' collective, when this world's solves are shared.
    pub(crate) fn exchange(&self) -> Option<&dyn Exchange> {
        self.exchange.as_deref()
    }

    /// Whether each rank holds its own pairs and contacts: a domain-decomposed run shared
    /// between ranks (a monolithic solve runs whole on every rank).
    fn holds_pairs(&self) -> bool {
        self.settings.ddm.is_some() && self.exchange.as_ref().is_some_and(|e| e.size() > 1)
    }

    /// Frees the step pipeline's buffers (local problems, solver bodies, detection output,
    /// domain-decomposition workspace: about 0.5 kB per contact point), as Rapier's pipeline
    /// can be dropped: the next step rebuilds them from the state, with the same result bit
    /// for bit. Between [`World::detect`] and the step it prepared they hold that step, so
    /// nothing is freed then; returns whether they were.
    pub fn release_scratch(&mut self) -> bool {
        if self.scratch.pending.is_some() {
            return false;
        }
        self.scratch = Scratch::default();
        true
    }

    /// The contact problem `(W, q, μ)` of the step being prepared (after [`World::prepare`]),
    /// assembled from its local problems on the free velocities: a value to export, hand to
    /// another solver, or solve with [`crate::solver::ContactProblem::solve_nlgs`].
    pub fn contact_problem(&self) -> crate::solver::ContactProblem {
        let nlgs = self.nlgs();
        crate::solver::ContactProblem::assemble(
            &self.scratch.locals,
            &self.scratch.solver_bodies,
            &nlgs,
        )
    }

    /// The global form `(M, H, v_free, b)` of [`World::contact_problem`]'s problem `problem`
    /// (see [`crate::solver::GlobalProblem`]).
    pub fn global_problem(
        &self,
        problem: &crate::solver::ContactProblem,
    ) -> crate::solver::GlobalProblem {
        crate::solver::GlobalProblem::assemble(
            &self.scratch.locals,
            &self.scratch.solver_bodies,
            problem,
        )
    }

    /// Steps 1–3 up to the local problems: detection at `qᵢ` with warm start, free velocities,
    /// local problems. Returns the largest overlap and the phase times so far.
    pub fn prepare(&mut self) -> (f64, PhaseTimes) {
        self.prepare_with(true)
    }

    /// [`World::prepare`]; without `build`, the local problems are left to the solver, which
    /// builds them straight into its subdomains' buckets ([`World::step`] with `[ddm]`).
    fn prepare_with(&mut self, build: bool) -> (f64, PhaseTimes) {
        if self.origin.is_none() && self.step_index == 0 {
            self.origin = Some(initial_state_digest(&self.bodies));
        }
        self.refresh_attach();
        let s = &self.settings;
        let h = s.dt;
        let t1 = self.time + h;
        let mut lap = Lap::start();
        let mut times = PhaseTimes::default();

        // Driven bodies whose release time has come move freely from this step on.
        self.bodies.apply_releases(self.time);

        // 1. Detection at qᵢ and warm start (of this rank's pairs only, when each rank of a
        // domain-decomposed run holds its own).
        self.detector.hold = self.holds_pairs();
        if self.detector.hold && self.detector.owners.is_none() {
            self.detector.owners = Some(self.first_owners());
        }
        std::mem::swap(&mut self.scratch.previous, &mut self.contacts);
        let d = &mut self.detector;
        let layout_changed = d.begin(&self.bodies, s.alert, s.dt, s.reuse_distance);
        // Ranks that share the bodies: each is sent the other ranks' bodies it reads.
        let mut ghost_seconds = 0.0;
        match self.exchange.as_deref().filter(|_| d.hold) {
            Some(ex) => {
                ghost_seconds = d.share_ghosts(ex, &mut self.bodies, s.alert, s.reuse_distance)
            }
            None => d.fresh.clear(),
        }
        let raw = &mut self.scratch.raw;
        d.finish(&self.bodies, s.alert, s.reuse_distance, layout_changed, raw);
        self.contacts.rebuild(
            &self.scratch.raw,
            &self.bodies,
            &self.friction,
            &self.scratch.previous,
            s.match_fraction,
            self.detector.radii(),
        );
        times.communication = self.detector.shared_seconds + ghost_seconds;
        let max_penetration = self.max_over_contacts(0.0, |c, k| -c.gap[k]);
        times.detection = lap.lap();

        // 2. Free velocities (on ranks that share the bodies, of those up to date here only,
        // each in its slot: no other is read).
        let (b, fresh) = (&self.bodies, &self.detector.fresh);
        let (gravity, t0) = (s.gravity, self.time);
        let slots = &mut self.scratch.slots;
        slots.clear();
        let mut up_to_date = Vec::new();
        if !fresh.is_empty() {
            slots.resize(b.len(), LEFT_OUT);
            for i in (0..b.len()).filter(|&i| fresh[i]) {
                slots[i] = up_to_date.len() as u32;
                up_to_date.push(i as u32);
            }
        }
        let count = if fresh.is_empty() {
            b.len()
        } else {
            up_to_date.len()
        };
        (0..count)
            .into_par_iter()
            .with_min_len(256)
            .map(|k| {
                let i = up_to_date.get(k).map_or(k, |&i| i as usize);
                free_body(b, i, gravity, h, t0, t1)
            })
            .collect_into_vec(&mut self.scratch.solver_bodies);
        let slots = &self.scratch.slots;
        self.drives.clear();
        for i in 0..b.len() {
            if let Some((d, limits)) = force_limited(b, i, t0, t1) {
                let (mut target_v, target_w) = d.velocity(t1);
                if !d.catch_up_speed.iter().all(|&c| c == 0.0) {
                    // The lag left once this step's share of the velocity it starts with
                    // (beyond its program) is counted: `R = L − h (1 − θ) e₀`.
                    let t0 = self.time;
                    let excess = b.velocity[i] - d.program_velocity(t0).0 - d.superposed.at(t0).0;
                    let left = value_of(&self.drive_lag, i) - excess * (h * (1.0 - s.theta));
                    let inv_mass = self.scratch.solver_bodies[slot(slots, i)].inv_mass;
                    for k in 0..3 {
                        let c = d.catch_up_speed[k];
                        if c > 0.0 && limits.force[k].is_finite() {
                            target_v[k] += catch_up(left[k], c, limits.force[k] * inv_mass, h);
                        }
                    }
                }
                self.drives.push(DriveRows {
                    body: i as u32,
                    target_v,
                    target_w,
                    bound_v: DVec3::from_array(limits.force) * h,
                    bound_w: DVec3::from_array(limits.torque) * h,
                    impulse_v: DVec3::ZERO,
                    impulse_w: DVec3::ZERO,
                    translate: limits.translation(),
                    rotate: limits.rotation(),
                });
            }
        }
        self.scratch.free_w.clear();
        self.scratch
            .free_w
            .extend(self.scratch.solver_bodies.iter().map(|sb| sb.w));
        times.other += lap.lap();

        // 3. Local problems.
        // Without warm start the solver starts from zero impulses; the previous ones stay the
        // compliant law's memory.
        // A rank that holds its pairs builds them in its buckets once its pairs have moved to
        // where the solve holds them: built here, they would be of other contacts, unused.
        if build && !self.detector.hold {
            let mut locals = std::mem::take(&mut self.scratch.locals);
            self.local_builder().build_all(&mut locals);
            self.scratch.locals = locals;
        } else {
            // Nothing stale for `local_problems` to show, and no capacity kept: the solver
            // builds them in its buckets, and a first step prepared by `World::detect` would
            // otherwise leave a second copy of every local problem here for the whole run.
            self.scratch.locals = Vec::new();
        }
        times.nlgs += lap.lap();
        (max_penetration, times)
    }

    /// What this step's local problems are built from (after detection and the free
    /// velocities).
    fn local_builder(&self) -> LocalBuilder<'_> {
        LocalBuilder {
            contacts: &self.contacts,
            warm_start: self.settings.solver.warm_start,
            bodies: &self.bodies,
            solver_bodies: &self.scratch.solver_bodies,
            slots: &self.scratch.slots,
            attach: &self.scratch.attach,
            overlap_law: self.overlap_law(),
        }
    }

    /// Takes in, on a rank that holds its pairs, the dynamic bodies its part of the solve
    /// reads and it was not sent as ghosts — those of its subdomains under `owners` (the
    /// solve's) and of the contacts it holds — and makes their solver bodies (a collective).
    /// Returns the seconds spent sharing.
    fn fetch_solved(&mut self, ex: &dyn Exchange, owners: &PairOwners) -> f64 {
        let (me, n, c) = (ex.rank(), self.bodies.len(), &self.contacts);
        let mut held = vec![false; n];
        for k in 0..c.len() {
            held[c.body1[k] as usize] = true;
            held[c.body2[k] as usize] = true;
        }
        let needed = |i: usize| held[i] || ghosts::owner_of(owners, i) == me;
        let (got, seconds) = self.detector.fetch(ex, &mut self.bodies, needed);
        let s = &self.settings;
        let (h, t0) = (s.dt, self.time);
        // Each in a new slot.
        let sc = &mut self.scratch;
        for i in got {
            let sb = free_body(&self.bodies, i, s.gravity, h, t0, t0 + h);
            sc.slots[i] = sc.solver_bodies.len() as u32;
            sc.free_w.push(sb.w);
            sc.solver_bodies.push(sb);
        }
        seconds
    }

    /// Advances one time step.
    pub fn step(&mut self) -> StepReport {
        // A step [`World::detect`] prepared has its local problems; otherwise the domain
        // decomposition builds them in its buckets (one copy of them fewer).
        let (built, (max_penetration, mut times)) = match self.scratch.pending.take() {
            Some(p) => (true, p),
            None => {
                let build = self.settings.ddm.is_none();
                (build, self.prepare_with(build))
            }
        };
        // A rank that holds its pairs builds its local problems once they have moved to it.
        let built = built && !self.detector.hold;
        // The first contact (in pair order) that overlaps the most.
        let deepest = self.gather_contacts(|c, k| -c.gap[k] == max_penetration);
        let deepest = match deepest.len() {
            0 => [0, 0],
            _ => [deepest.body1[0], deepest.body2[0]],
        };
        let mut lap = Lap::start();
        let nlgs = self.nlgs();
        // A copy: the solve's ranks take in bodies (`World::fetch_solved`) while it is read.
        let settings = self.settings.clone();
        let s = &settings;
        let (h, theta) = (s.dt, s.theta);
        // With the overlap recovery the law owns the elastic deflection; without it, the
        // correction heals whole overlaps as before.
        let elastic = if nlgs.recovery > 0.0 {
            nlgs.elastic()
        } else {
            Elastic::NONE
        };

        // 3. NLGS, monolithic or domain-decomposed, then the overlap correction (on the
        // same split).
        let (solve, corrected) = match &s.ddm {
            None => {
                let report = nlgs.solve_with_drives(
                    &mut self.scratch.locals,
                    &mut self.drives,
                    &mut self.scratch.solver_bodies,
                    &mut self.contacts.status,
                );
                let corrected = pseudo_velocities(
                    &s.correction,
                    h,
                    elastic,
                    &self.scratch.locals,
                    &self.scratch.solver_bodies,
                    &mut self.scratch.pseudo,
                );
                (report, corrected)
            }
            Some(d) => {
                let mut sorted = std::mem::take(&mut self.scratch.sorted_axes);
                let mut partition = self.partition_from(d, &mut sorted);
                self.scratch.sorted_axes = sorted;
                self.scratch.ddm_workspace.exchange = self.exchange.clone();
                let hold = self.detector.hold;
                if hold {
                    // Each rank holds its own pairs: the ranks count their contacts per
                    // bucket, the pairs whose bucket another rank solves move there, then
                    // each rank builds its buckets from the contacts it holds.
                    let ex = self.exchange.clone().expect("a rank holds pairs");
                    let mut ws = std::mem::take(&mut self.scratch.ddm_workspace);
                    let (c, attach) = (&self.contacts, &self.scratch.attach);
                    times.communication += ws.census(
                        &partition,
                        c.len(),
                        |k| solved_as(attach, c, k),
                        d.parallel_interface,
                    );
                    let owners = ws.pair_owners(&partition, ex.size(), attach);
                    times.communication += self.detector.migrate(&*ex, &owners);
                    times.communication += self.contacts.migrate(&*ex, &owners);
                    // The bodies this solve gives the rank that it was not sent as ghosts.
                    times.communication += self.fetch_solved(&*ex, &owners);
                    let (c, attach) = (&self.contacts, &self.scratch.attach);
                    ws.place_held(
                        &partition,
                        c.len(),
                        |k| solved_as(attach, c, k),
                        d.parallel_interface,
                    );
                    // The rank numbers only the bodies its part of the solve reads.
                    partition = ws.compact(&partition, &self.drives);
                    let builder = self.local_builder();
                    ws.fill(&partition, |k| builder.at(k));
                    self.contact_total = ws.contact_total();
                    self.scratch.ddm_workspace = ws;
                    // The next detection tests each pair where this solve holds it.
                    self.detector.owners = Some(owners);
                } else if !built {
                    let mut ws = std::mem::take(&mut self.scratch.ddm_workspace);
                    ws.bucket(&partition, &self.local_builder(), d.parallel_interface);
                    self.scratch.ddm_workspace = ws;
                }
                let (sc, cs) = (&mut self.scratch, &mut self.contacts);
                let contacts = if hold {
                    ddm::Contacts::Held {
                        impulse: &mut cs.impulse,
                        status: &mut cs.status,
                    }
                } else if built {
                    ddm::Contacts::Built {
                        locals: &mut sc.locals,
                        status: &mut cs.status,
                    }
                } else {
                    ddm::Contacts::Bucketed {
                        impulse: &mut cs.impulse,
                        status: &mut cs.status,
                    }
                };
                let (report, t, corrected) = ddm::solve_contacts(
                    &mut sc.ddm_workspace,
                    &nlgs,
                    d,
                    &partition,
                    contacts,
                    &mut self.drives,
                    &mut sc.solver_bodies,
                    &sc.slots,
                    Some(ddm::CorrectionPass {
                        settings: &s.correction,
                        h,
                        elastic,
                        pseudo: &mut sc.pseudo,
                    }),
                );
                times.subdomains = t.subdomains;
                times.interface = t.interface;
                times.communication += t.communication;
                (report, corrected)
            }
        };
        if built {
            self.contacts
                .impulse
                .par_iter_mut()
                .with_min_len(4096)
                .zip(self.scratch.locals.par_iter())
                .for_each(|(r, c)| *r = c.r);
        }
        // A driven body moves as its drive says: the position-only overlap correction pushes
        // the grains off it, not it off the grains.
        // (Bodies that are not grains have a slot on every rank.)
        let slots = &self.scratch.slots;
        if corrected {
            for d in &self.drives {
                let k = slot(slots, d.body as usize);
                self.scratch.pseudo[k] = correction::at_rest(&self.scratch.pseudo[k], false);
            }
        }
        // Attached bodies move with the body they are part of.
        for (i, &p) in self.scratch.attach.iter().enumerate() {
            let p = p as usize;
            if p != i {
                let arm = self.bodies.position[i] - self.bodies.position[p];
                let parent = self.scratch.solver_bodies[slot(slots, p)];
                let sb = &mut self.scratch.solver_bodies[slot(slots, i)];
                sb.v = parent.v + parent.w.cross(arm);
                sb.w = parent.w;
            }
        }
        // The drives' work over the step, at the velocities the update below moves with.
        for d in &self.drives {
            let i = d.body as usize;
            let sb = &self.scratch.solver_bodies[slot(slots, i)];
            let vbar = sb.v * theta + self.bodies.velocity[i] * (1.0 - theta);
            let wbar = sb.w * theta + self.bodies.angular_velocity[i] * (1.0 - theta);
            let work = d.impulse_v.dot(vbar) + d.impulse_w.dot(wbar);
            add_to(&mut self.drive_work, d.body, work);
            if d.translate {
                let (t0, t1) = (self.time, self.time + h);
                let driver = self.bodies.driver[i]
                    .as_ref()
                    .expect("a drive has a driver");
                let bar = |(a, b): (DVec3, DVec3)| a * theta + b * (1.0 - theta);
                let pbar = bar((driver.program_velocity(t1).0, driver.program_velocity(t0).0));
                let sbar = bar((driver.superposed.at(t1).0, driver.superposed.at(t0).0));
                let step_lag = (pbar - (vbar - sbar)) * h;
                add_to(&mut self.drive_lag, d.body, step_lag);
            }
        }
        times.nlgs += lap.lap();
        let free_w = &self.scratch.free_w;

        // 4. Update, in parallel over bodies (each body's update reads only its own data). On
        // ranks that hold their own pairs a rank moves only the grains it owns (their owners
        // under this solve): it was given only their velocities, and the others it reads next
        // step are sent to it.
        let (me, owners) = (self.rank(), self.detector.owners.as_ref());
        let owners = owners.filter(|_| self.detector.hold);
        let b = &mut self.bodies;
        let (kind, inertia) = (&b.kind, &b.inertia);
        let (sbs, pseudo) = (&self.scratch.solver_bodies, &self.scratch.pseudo);
        (
            b.position.par_iter_mut(),
            b.orientation.par_iter_mut(),
            b.velocity.par_iter_mut(),
            b.angular_velocity.par_iter_mut(),
            b.angular_momentum.par_iter_mut(),
        )
            .into_par_iter()
            .enumerate()
            .with_min_len(256)
            .for_each(|(i, (x, q, v, w, l))| {
                let other = |o: &PairOwners| ghosts::owner_of(o, i) != me;
                if kind[i] == BodyKind::Fixed
                    || (kind[i] == BodyKind::Dynamic && owners.is_some_and(other))
                {
                    return;
                }
                let k = slot(slots, i);
                let (v1, w1) = (sbs[k].v, sbs[k].w);
                let (pv, pw) = if corrected {
                    (pseudo[k].v, pseudo[k].w)
                } else {
                    (DVec3::ZERO, DVec3::ZERO)
                };
                *x += (v1 * theta + *v * (1.0 - theta) + pv) * h;
                let rot = (w1 * theta + *w * (1.0 - theta) + pw) * h;
                let q_old = *q;
                *q = (DQuat::from_scaled_axis(rot) * q_old).normalize();
                *v = v1;
                let world_inertia = |q: DQuat, d: DVec3| {
                    let r = DMat3::from_quat(q);
                    r * DMat3::from_diagonal(d) * r.transpose()
                };
                if kind[i] == BodyKind::Dynamic {
                    *l += world_inertia(q_old, inertia[i]) * (w1 - free_w[k]);
                    *w = world_inertia(*q, inertia[i].recip()) * *l;
                } else {
                    // Driven: L = I_w ω, so that a release needs no state change.
                    *w = w1;
                    *l = world_inertia(*q, inertia[i]) * w1;
                }
            });
        self.time += h;
        self.step_index += 1;
        times.other += lap.lap();
        times.total = times.detection + times.nlgs + times.other;
        self.timers += times;
        StepReport {
            step: self.step_index,
            time: self.time,
            contacts: self.contact_total(),
            solve,
            max_penetration,
            deepest,
            times,
        }
    }
}

/// The bodies contact `k` of `c` is solved between: its own, or, for a body attached to
/// another (`attach[i]`, empty when none is), that one.
fn solved_as(attach: &[u32], c: &ContactSet, k: usize) -> (u32, u32) {
    let (a, b) = (c.body1[k], c.body2[k]);
    match attach.is_empty() {
        true => (a, b),
        false => (attach[a as usize], attach[b as usize]),
    }
}

/// 64-bit FNV-1a over the exact bits of every body's position, orientation, velocity and
/// angular velocity: what distinguishes two runs of the same scene that start differently.
pub fn initial_state_digest(bodies: &BodySet) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for i in 0..bodies.len() {
        let (p, q) = (bodies.position[i], bodies.orientation[i]);
        let (v, w) = (bodies.velocity[i], bodies.angular_velocity[i]);
        for x in [
            p.x, p.y, p.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z, w.x, w.y, w.z,
        ] {
            for b in x.to_bits().to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
    }
    h
}

/// The velocity beyond its program with which a position servo makes up the lag `left` (m,
/// this step's share of the velocity it starts with already counted), with `accel` = F/m the
/// drive's own braking: in θ-steps the lag left evolves as `R ← R − h e` with `e` the excess
/// velocity at the end of the step, and braking from `e` by `a h` a step consumes
/// `max(0, e (e − a h) / (2a))` more; the largest `e` that can still stop on the program's
/// position is `R/h` when `|R| ≤ a h²` (it stops the next step: the lag is made up in two
/// steps, exactly, whatever θ), else `a (√(h²/4 + 2|R|/a) − h/2)`; no faster than `speed`.
fn catch_up(left: f64, speed: f64, accel: f64, h: f64) -> f64 {
    let r = left.abs();
    let e = if r <= accel * h * h {
        r / h
    } else {
        accel * ((0.25 * h * h + 2.0 * r / accel).sqrt() - 0.5 * h)
    };
    e.min(speed).copysign(left)
}

/// The value of body `i` in a per-drive table (sorted by body), zero when absent.
fn value_of<T: Copy + Default>(table: &[(u32, T)], i: usize) -> T {
    table
        .binary_search_by_key(&(i as u32), |&(b, _)| b)
        .map_or(T::default(), |k| table[k].1)
}

/// Adds `x` to the value of `body` in a per-drive table, inserting it in body order.
fn add_to<T: Copy + std::ops::AddAssign>(table: &mut Vec<(u32, T)>, body: u32, x: T) {
    match table.binary_search_by_key(&body, |&(b, _)| b) {
        Ok(k) => table[k].1 += x,
        Err(k) => table.insert(k, (body, x)),
    }
}

/// The driver of body `i` and its bounds over the step from `t0` to `t1` if it is driven (not
/// yet released) with a force limit.
/// Body `i`'s solver body at the start of the step `t0 → t1` (of length `h`): its free
/// velocity (gravity added, a driven body's program) and inverse inertia.
fn free_body(b: &BodySet, i: usize, gravity: DVec3, h: f64, t0: f64, t1: f64) -> SolverBody {
    if let Some((d, limits)) = force_limited(b, i, t0, t1) {
        return limited_free_body(b, i, d, limits, gravity * h, t0, t1);
    }
    let (v, w) = match b.kind[i] {
        BodyKind::Dynamic => (b.velocity[i] + gravity * h, b.angular_velocity[i]),
        BodyKind::Kinematic => match &b.driver[i] {
            Some(d) => d.velocity(t1),
            None => (DVec3::ZERO, DVec3::ZERO),
        },
        BodyKind::Fixed => (DVec3::ZERO, DVec3::ZERO),
    };
    SolverBody {
        v,
        w,
        inv_mass: if b.kind[i] == BodyKind::Dynamic {
            b.inv_mass[i]
        } else {
            0.0
        },
        inv_inertia: b.inv_inertia_world(i),
        epoch: 0,
        drift: 0.0,
        version: 0,
    }
}

fn force_limited(
    b: &BodySet,
    i: usize,
    t0: f64,
    t1: f64,
) -> Option<(&crate::bodies::Driver, Limits)> {
    match (b.kind[i], &b.driver[i]) {
        (BodyKind::Kinematic, Some(d)) => {
            let limits = d.limits(t0, t1);
            limits.any().then_some((d, limits))
        }
        _ => None,
    }
}

/// Free velocities of a force-limited driven body over `[t0, t1]`: a limited part keeps the
/// velocity it had, less the superposed velocity of `t0`, plus that of `t1` (its weight is
/// carried by the drive, except during a gradual release); an unlimited part takes the
/// program's velocity at `t1`. The body has its mass (inertia) in the solver where its
/// translation (rotation) is limited.
fn limited_free_body(
    b: &BodySet,
    i: usize,
    d: &crate::bodies::Driver,
    limits: Limits,
    gravity_h: DVec3,
    t0: f64,
    t1: f64,
) -> SolverBody {
    let (pv, pw) = d.velocity(t1);
    let (s0v, s0w) = d.superposed.at(t0);
    let (s1v, s1w) = d.superposed.at(t1);
    let (translate, rotate) = (limits.translation(), limits.rotation());
    let r = DMat3::from_quat(b.orientation[i]);
    // A body being released weighs on its drive's falling bound.
    let weight = if d.releasing(t0) {
        gravity_h
    } else {
        DVec3::ZERO
    };
    SolverBody {
        v: if translate {
            b.velocity[i] - s0v + s1v + weight
        } else {
            pv
        },
        w: if rotate {
            b.angular_velocity[i] - s0w + s1w
        } else {
            pw
        },
        inv_mass: if translate { b.inv_mass[i] } else { 0.0 },
        inv_inertia: if rotate {
            r * DMat3::from_diagonal(b.inertia[i].recip()) * r.transpose()
        } else {
            DMat3::ZERO
        },
        epoch: 0,
        drift: 0.0,
        version: 0,
    }
}
