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

use crate::bodies::{BodyKind, BodySet};
use crate::contacts::ContactSet;
use crate::detection::{Detector, RawContact};
use crate::laws::FrictionTable;
use crate::math::{DMat3, DQuat, DVec3};
use crate::solver::correction::pseudo_velocities;
use crate::solver::delassus::build_local_problems;
use crate::solver::{
    ddm, CorrectionSettings, DdmSettings, LocalProblem, Nlgs, Partition, SolveReport, SolverBody,
    SolverSettings,
};
use crate::timing::{Lap, PhaseTimes};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

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
    /// NLGS settings.
    pub solver: SolverSettings,
    /// Overlap post-stabilisation.
    pub correction: CorrectionSettings,
    /// Domain decomposition (Algorithm 1); `None` = monolithic NLGS.
    pub ddm: Option<DdmSettings>,
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
            solver: SolverSettings::default(),
            correction: CorrectionSettings::default(),
            ddm: None,
        }
    }
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
    pub times: PhaseTimes,
}

/// A simulation: bodies, contacts, laws, settings, clock and timers.
#[derive(Debug)]
pub struct World {
    pub bodies: BodySet,
    pub contacts: ContactSet,
    pub friction: FrictionTable,
    pub settings: StepSettings,
    /// Current time (s).
    pub time: f64,
    /// Steps done.
    pub step_index: u64,
    /// Cumulated phase times.
    pub timers: PhaseTimes,
    pub(crate) detector: Detector,
    raw: Vec<RawContact>,
    previous: ContactSet,
    locals: Vec<LocalProblem>,
    solver_bodies: Vec<SolverBody>,
    free_w: Vec<DVec3>,
    pseudo: Vec<SolverBody>,
    ddm_workspace: ddm::DdmWorkspace,
}

impl World {
    /// A world at t = 0.
    /// Kinematic bodies start with their driver's velocity at t = 0.
    pub fn new(mut bodies: BodySet, friction: FrictionTable, settings: StepSettings) -> Self {
        bodies.compact_shapes();
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
            detector: Detector::default(),
            raw: Vec::new(),
            previous: ContactSet::default(),
            locals: Vec::new(),
            solver_bodies: Vec::new(),
            free_w: Vec::new(),
            pseudo: Vec::new(),
            ddm_workspace: ddm::DdmWorkspace::default(),
        }
    }

    /// The partition of this step: boxes over the dynamic bodies' centres, weighted by
    /// `1 + number of contacts` when balancing by contacts.
    pub fn partition(&self, d: &DdmSettings) -> Partition {
        let n = self.bodies.len();
        let mut weights = vec![1.0; n];
        for k in 0..self.contacts.len() {
            weights[self.contacts.body1[k] as usize] += 1.0;
            weights[self.contacts.body2[k] as usize] += 1.0;
        }
        let dynamic: Vec<bool> = self
            .bodies
            .kind
            .iter()
            .map(|k| *k == BodyKind::Dynamic)
            .collect();
        Partition::build(
            &self.bodies.position,
            &dynamic,
            d.subdomains,
            d.balance,
            &weights,
        )
    }

    /// The NLGS solver configured for this world.
    pub fn nlgs(&self) -> Nlgs {
        Nlgs {
            settings: self.settings.solver.clone(),
            h_theta: self.settings.dt * self.settings.theta,
        }
    }

    /// Candidate pairs whose contact manifold the last detection reused from the step before
    /// (temporal coherence, see [`StepSettings::reuse_distance`]), and candidate pairs in all.
    pub fn detection_reuse(&self) -> (usize, usize) {
        self.detector.reuse_counts()
    }

    /// The local problems of the step being prepared (after [`World::prepare`]).
    pub fn local_problems(&self) -> &[LocalProblem] {
        &self.locals
    }

    /// The solver bodies (free velocities after [`World::prepare`]).
    pub fn solver_bodies(&self) -> &[SolverBody] {
        &self.solver_bodies
    }

    /// Steps 1–3 up to the local problems: detection at `qᵢ` with warm start, free velocities,
    /// local problems. Returns the largest overlap and the phase times so far.
    pub fn prepare(&mut self) -> (f64, PhaseTimes) {
        let s = &self.settings;
        let h = s.dt;
        let t1 = self.time + h;
        let mut lap = Lap::start();
        let mut times = PhaseTimes::default();

        // Driven bodies whose release time has come move freely from this step on.
        self.bodies.apply_releases(self.time);

        // 1. Detection at qᵢ and warm start.
        std::mem::swap(&mut self.previous, &mut self.contacts);
        self.detector
            .detect(&self.bodies, s.alert, s.dt, s.reuse_distance, &mut self.raw);
        self.contacts.rebuild(
            &self.raw,
            &self.bodies,
            &self.friction,
            &self.previous,
            s.match_fraction,
        );
        if !s.solver.warm_start {
            self.contacts
                .impulse
                .iter_mut()
                .for_each(|r| *r = DVec3::ZERO);
        }
        let max_penetration = self.contacts.gap.iter().fold(0.0f64, |m, &g| m.max(-g));
        times.detection = lap.lap();

        // 2. Free velocities.
        let b = &self.bodies;
        let gravity = s.gravity;
        (0..b.len())
            .into_par_iter()
            .with_min_len(256)
            .map(|i| {
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
                }
            })
            .collect_into_vec(&mut self.solver_bodies);
        self.free_w.clear();
        self.free_w.extend(self.solver_bodies.iter().map(|sb| sb.w));
        times.other += lap.lap();

        // 3. Local problems.
        build_local_problems(&self.contacts, b, &self.solver_bodies, &mut self.locals);
        times.nlgs += lap.lap();
        (max_penetration, times)
    }

    /// Advances one time step.
    pub fn step(&mut self) -> StepReport {
        let (max_penetration, mut times) = self.prepare();
        let mut lap = Lap::start();
        let nlgs = self.nlgs();
        let s = &self.settings;
        let (h, theta) = (s.dt, s.theta);

        // 3. NLGS, monolithic or domain-decomposed, then the overlap correction (on the
        // same split).
        let (solve, corrected) = match &s.ddm {
            None => {
                let report = nlgs.solve(
                    &mut self.locals,
                    &mut self.solver_bodies,
                    &mut self.contacts.status,
                );
                let corrected = pseudo_velocities(
                    &s.correction,
                    h,
                    &self.locals,
                    &self.solver_bodies,
                    &mut self.pseudo,
                );
                (report, corrected)
            }
            Some(d) => {
                let partition = self.partition(d);
                let (report, t, corrected) = ddm::solve_and_correct(
                    &mut self.ddm_workspace,
                    &nlgs,
                    d,
                    &partition,
                    &mut self.locals,
                    &mut self.solver_bodies,
                    &mut self.contacts.status,
                    Some(ddm::CorrectionPass {
                        settings: &s.correction,
                        h,
                        pseudo: &mut self.pseudo,
                    }),
                );
                times.subdomains = t.subdomains;
                times.interface = t.interface;
                (report, corrected)
            }
        };
        for (r, c) in self.contacts.impulse.iter_mut().zip(&self.locals) {
            *r = c.r;
        }
        times.nlgs += lap.lap();
        let free_w = &self.free_w;

        // 4. Update, in parallel over bodies (each body's update reads only its own data).
        let b = &mut self.bodies;
        let (kind, inertia) = (&b.kind, &b.inertia);
        let (sbs, pseudo) = (&self.solver_bodies, &self.pseudo);
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
                if kind[i] == BodyKind::Fixed {
                    return;
                }
                let (v1, w1) = (sbs[i].v, sbs[i].w);
                let (pv, pw) = if corrected {
                    (pseudo[i].v, pseudo[i].w)
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
                    *l += world_inertia(q_old, inertia[i]) * (w1 - free_w[i]);
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
            contacts: self.contacts.len(),
            solve,
            max_penetration,
            times,
        }
    }
}
