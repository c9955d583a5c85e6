//! Imposed velocities of kinematic bodies, per degree of freedom, as functions of time.
//!
//! A [`Profile`] is a sum of [`Term`]s; a [`Driver`] holds one optional profile per degree of
//! freedom (vx, vy, vz, ωx, ωy, ωz in the world frame, ω about the centre of mass). A degree of
//! freedom without a profile has zero velocity.
//!
//! # Force-limited drives
//!
//! By default a driven body is kinematic: it follows its program whatever force that takes
//! (infinite mass). With `max_force` (N, per world axis) or `max_torque` (N·m) it is a machine
//! with a relief valve: per degree of freedom d, the drive is a bilateral velocity constraint
//! with a bounded impulse,
//!
//! ```text
//! v_d = p_d(t) + s_d(t)   while |λ_d| < F_d h,   else λ_d = ±F_d h and v_d is free,
//! ```
//!
//! solved in the same Gauss-Seidel sweeps as the contacts (see [`crate::solver::drive`]). The
//! body then has its mass and inertia; `p` is the force-limited program and `s`
//! (`superposed`) a velocity imposed on top of it whatever the force, such as a vibrator's
//! stroke riding on a hydraulic cylinder. A degree of freedom left at `inf` keeps following
//! its program exactly; with every limit infinite the body is the kinematic body, bit for bit.
//!
//! A drive that yielded lags behind its program. By default it follows the program's
//! *velocity* from there (a cylinder under flow control: the distance lost stays lost). With
//! `catch_up_speed` (m/s per world axis) it is a position servo as well: the target velocity
//! of each step gets the lag `L` (the program's displacement less the body's, the superposed
//! motion taken out) divided by `θ h`, clamped to `±catch_up_speed`, so the body makes the
//! lost distance up at that speed at most, within its force limit, and ends where its program
//! ends.
//!
//! # Gradual release
//!
//! `release_at` lets a driven body go: from then on it is dynamic. Let go at once, a body
//! held against loaded contacts is launched by them (a block held at its lift over freshly
//! squeezed ballast). With `release_over = T` the release is a machine lowering its load:
//! from `release_at` the drive keeps the program's velocity with a bound that falls linearly
//! from `release_force` to zero over `T`, the body's weight included (its drive no longer
//! carries it for free), and the body is dynamic from `release_at + T`. The contacts take
//! the load over as the bound falls, at a rate the drive sets, and the drive absorbs the
//! energy they give back.
//!
//! # Attached bodies
//!
//! `attached_to = N` makes a body a rigid part of body N (a tine's shaft on its blade): it
//! has no program of its own, moves with N, and the impulses of its contacts act on N.

use crate::error::ScenarioError;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// One elementary velocity law `v(t)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Term {
    /// `v(t) = value`.
    Constant { value: f64 },
    /// Linear from `from` at `start` to `to` at `end`, held constant outside.
    Ramp {
        start: f64,
        end: f64,
        from: f64,
        to: f64,
    },
    /// Piecewise-linear interpolation of `(times[k], values[k])`, held constant outside.
    Table { times: Vec<f64>, values: Vec<f64> },
    /// `amplitude · sin(2π frequency (t − start) + phase)` for `start ≤ t ≤ end`, else 0.
    Sine {
        amplitude: f64,
        frequency: f64,
        #[serde(default)]
        phase: f64,
        #[serde(default)]
        start: f64,
        #[serde(default = "infinity")]
        end: f64,
    },
}

fn infinity() -> f64 {
    f64::INFINITY
}

impl Term {
    /// Value at time `t`.
    pub fn eval(&self, t: f64) -> f64 {
        match self {
            Term::Constant { value } => *value,
            Term::Ramp {
                start,
                end,
                from,
                to,
            } => {
                if t <= *start {
                    *from
                } else if t >= *end {
                    *to
                } else {
                    from + (to - from) * (t - start) / (end - start)
                }
            }
            Term::Table { times, values } => table_eval(times, values, t),
            Term::Sine {
                amplitude,
                frequency,
                phase,
                start,
                end,
            } => {
                if t < *start || t > *end {
                    0.0
                } else {
                    amplitude * (TAU * frequency * (t - start) + phase).sin()
                }
            }
        }
    }

    /// Checks the parameters; the error says what is wrong and what is allowed.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let finite = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("{name} = {v} must be a finite number").into())
            }
        };
        match self {
            Term::Constant { value } => finite("value", *value),
            Term::Ramp {
                start,
                end,
                from,
                to,
            } => {
                finite("start", *start)?;
                finite("end", *end)?;
                finite("from", *from)?;
                finite("to", *to)?;
                if end <= start {
                    return Err(
                        format!("ramp end = {end} must be greater than start = {start}").into(),
                    );
                }
                Ok(())
            }
            Term::Table { times, values } => {
                if times.is_empty() || times.len() != values.len() {
                    return Err(format!(
                        "table needs as many times as values, at least one (got {} times, {} values)",
                        times.len(),
                        values.len()
                    ).into());
                }
                for (k, w) in times.windows(2).enumerate() {
                    if w[1] <= w[0] {
                        return Err(format!(
                            "table times must increase strictly (times[{}] = {} ≥ times[{}] = {})",
                            k,
                            w[0],
                            k + 1,
                            w[1]
                        )
                        .into());
                    }
                }
                for v in times.iter().chain(values) {
                    finite("table entry", *v)?;
                }
                Ok(())
            }
            Term::Sine {
                amplitude,
                frequency,
                phase,
                start,
                end,
            } => {
                finite("amplitude", *amplitude)?;
                finite("phase", *phase)?;
                finite("start", *start)?;
                if !(frequency.is_finite() && *frequency >= 0.0) {
                    return Err(
                        format!("frequency = {frequency} must be finite and ≥ 0 (Hz)").into(),
                    );
                }
                if end.is_nan() || end < start {
                    return Err(format!("sine end = {end} must be ≥ start = {start}").into());
                }
                Ok(())
            }
        }
    }
}

fn table_eval(times: &[f64], values: &[f64], t: f64) -> f64 {
    let n = times.len();
    if t <= times[0] {
        return values[0];
    }
    if t >= times[n - 1] {
        return values[n - 1];
    }
    // First index with times[k] > t; 1 ≤ k ≤ n-1 here.
    let k = times.partition_point(|&x| x <= t);
    let (t0, t1) = (times[k - 1], times[k]);
    values[k - 1] + (values[k] - values[k - 1]) * (t - t0) / (t1 - t0)
}

/// A sum of terms.
pub type Profile = Vec<Term>;

/// Fewest time steps per period of a sine term for the motion to be followed (twice Nyquist's
/// 2: at 2 a sine can be sampled at its zeros every step).
pub const MIN_SAMPLES_PER_PERIOD: f64 = 4.0;

/// Imposed velocity of a kinematic body: one optional profile per degree of freedom.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Driver {
    #[serde(default)]
    pub vx: Profile,
    #[serde(default)]
    pub vy: Profile,
    #[serde(default)]
    pub vz: Profile,
    #[serde(default)]
    pub wx: Profile,
    #[serde(default)]
    pub wy: Profile,
    #[serde(default)]
    pub wz: Profile,
    /// Time (s) from which the body is no longer driven: it becomes dynamic, with the mass and
    /// inertia it was given, and keeps the velocity it had. `None`: driven for ever.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub release_at: Option<f64>,
    /// Largest force (N) the drive exerts along the world x, y, z axes (`inf`: no limit).
    #[serde(
        default = "unlimited",
        skip_serializing_if = "is_unlimited",
        deserialize_with = "limits"
    )]
    pub max_force: [f64; 3],
    /// Largest torque (N·m) the drive exerts about the world x, y, z axes (`inf`: no limit).
    #[serde(
        default = "unlimited",
        skip_serializing_if = "is_unlimited",
        deserialize_with = "limits"
    )]
    pub max_torque: [f64; 3],
    /// Velocities imposed on top of the program whatever the force (a vibrator's stroke on a
    /// force-limited cylinder); same degrees of freedom and terms as the program.
    #[serde(default, skip_serializing_if = "Velocities::is_empty")]
    pub superposed: Velocities,
    /// Body this one is a rigid part of (see the module documentation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attached_to: Option<usize>,
    /// Largest speed (m/s, per world axis) at which a force-limited translation makes up the
    /// distance it lags behind its program (see the module documentation); 0: none, the
    /// program's velocity only.
    #[serde(default, skip_serializing_if = "is_zero3")]
    pub catch_up_speed: [f64; 3],
    /// Duration (s) of a gradual release from `release_at` (see the module documentation);
    /// 0: the body is let go at once.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub release_over: f64,
    /// Force (N, per world axis) the drive can still exert at `release_at`, falling linearly
    /// to zero over `release_over`; `inf`: that axis follows its program to the end of the
    /// release.
    #[serde(
        default = "unlimited",
        skip_serializing_if = "is_unlimited",
        deserialize_with = "limits"
    )]
    pub release_force: [f64; 3],
}

/// The bounds a drive works under over one step: force (N) and torque (N·m) per world axis,
/// `inf` where it follows its program whatever that takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    pub force: [f64; 3],
    pub torque: [f64; 3],
}

impl Limits {
    /// True when a translational bound is finite (the body has its mass in the solver).
    pub fn translation(&self) -> bool {
        !is_unlimited(&self.force)
    }

    /// True when a rotational bound is finite (the body has its inertia in the solver).
    pub fn rotation(&self) -> bool {
        !is_unlimited(&self.torque)
    }

    /// True when some degree of freedom is bounded.
    pub fn any(&self) -> bool {
        self.translation() || self.rotation()
    }
}

impl Default for Driver {
    /// No motion, no limit (a kinematic body at rest).
    fn default() -> Self {
        Driver {
            vx: Profile::new(),
            vy: Profile::new(),
            vz: Profile::new(),
            wx: Profile::new(),
            wy: Profile::new(),
            wz: Profile::new(),
            release_at: None,
            max_force: unlimited(),
            max_torque: unlimited(),
            superposed: Velocities::default(),
            attached_to: None,
            catch_up_speed: [0.0; 3],
            release_over: 0.0,
            release_force: unlimited(),
        }
    }
}

/// Velocity profiles of the six degrees of freedom (world frame, about the centre of mass).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Velocities {
    #[serde(default)]
    pub vx: Profile,
    #[serde(default)]
    pub vy: Profile,
    #[serde(default)]
    pub vz: Profile,
    #[serde(default)]
    pub wx: Profile,
    #[serde(default)]
    pub wy: Profile,
    #[serde(default)]
    pub wz: Profile,
}

impl Velocities {
    fn dofs(&self) -> [(&'static str, &Profile); 6] {
        [
            ("vx", &self.vx),
            ("vy", &self.vy),
            ("vz", &self.vz),
            ("wx", &self.wx),
            ("wy", &self.wy),
            ("wz", &self.wz),
        ]
    }

    /// True when no degree of freedom has a term.
    pub fn is_empty(&self) -> bool {
        self.dofs().iter().all(|(_, p)| p.is_empty())
    }

    /// (linear, angular) velocity at time `t`.
    pub fn at(&self, t: f64) -> (crate::math::DVec3, crate::math::DVec3) {
        velocities_at(self.dofs(), t)
    }
}

/// (linear, angular) velocity at time `t` of six profiles in the order vx … wz.
fn velocities_at(
    dofs: [(&'static str, &Profile); 6],
    t: f64,
) -> (crate::math::DVec3, crate::math::DVec3) {
    let e = |k: usize| dofs[k].1.iter().map(|term| term.eval(t)).sum::<f64>();
    (
        crate::math::DVec3::new(e(0), e(1), e(2)),
        crate::math::DVec3::new(e(3), e(4), e(5)),
    )
}

fn unlimited() -> [f64; 3] {
    [f64::INFINITY; 3]
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn is_zero3(x: &[f64; 3]) -> bool {
    x.iter().all(|v| *v == 0.0)
}

fn is_unlimited(l: &[f64; 3]) -> bool {
    l.iter().all(|x| *x == f64::INFINITY)
}

/// Limits read from TOML (`inf` allowed) or JSON (where an infinite limit is written `null`).
fn limits<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    let v = <[Option<f64>; 3]>::deserialize(d)?;
    Ok(v.map(|x| x.unwrap_or(f64::INFINITY)))
}

impl Driver {
    fn dofs(&self) -> [(&'static str, &Profile); 6] {
        [
            ("vx", &self.vx),
            ("vy", &self.vy),
            ("vz", &self.vz),
            ("wx", &self.wx),
            ("wy", &self.wy),
            ("wz", &self.wz),
        ]
    }

    /// Commanded (linear, angular) velocity at time `t`: the program plus the superposed
    /// velocities (what a kinematic body does).
    pub fn velocity(&self, t: f64) -> (crate::math::DVec3, crate::math::DVec3) {
        let (v, w) = velocities_at(self.dofs(), t);
        if self.superposed.is_empty() {
            return (v, w);
        }
        let (sv, sw) = self.superposed.at(t);
        (v + sv, w + sw)
    }

    /// The program's (linear, angular) velocity at time `t`, without the superposed one.
    pub fn program_velocity(&self, t: f64) -> (crate::math::DVec3, crate::math::DVec3) {
        velocities_at(self.dofs(), t)
    }

    /// True when a translational limit is finite: the drive's translation is solved with
    /// the contacts (the body has its mass), not imposed.
    pub fn limits_translation(&self) -> bool {
        self.held_limits().translation()
    }

    /// True when a rotational limit is finite (the body has its inertia in the solver).
    pub fn limits_rotation(&self) -> bool {
        self.held_limits().rotation()
    }

    /// True when some degree of freedom is force-limited.
    pub fn is_force_limited(&self) -> bool {
        self.held_limits().any()
    }

    /// `max_force` and `max_torque`: the bounds outside a gradual release.
    fn held_limits(&self) -> Limits {
        Limits {
            force: self.max_force,
            torque: self.max_torque,
        }
    }

    /// The sine terms that a time step `dt` samples too coarsely to follow: fewer than
    /// [`MIN_SAMPLES_PER_PERIOD`] steps per period (a 1e5 Hz sine at dt = 1e-3 s is sampled at
    /// the same phase every step, so it is seen as a constant), each as
    /// `"vx[0]: sine at 1e5 Hz, 0.01 steps per period"` (`superposed.` before superposed ones).
    pub fn sampling_warnings(&self, dt: f64) -> Vec<String> {
        let mut out = Vec::new();
        for (prefix, dofs) in [("", self.dofs()), ("superposed.", self.superposed.dofs())] {
            for (name, profile) in dofs {
                for (k, t) in profile.iter().enumerate() {
                    if let Term::Sine { frequency, .. } = t {
                        let per_period = 1.0 / (frequency * dt);
                        if *frequency > 0.0 && per_period < MIN_SAMPLES_PER_PERIOD {
                            out.push(format!(
                                "{prefix}{name}[{k}]: sine at {frequency} Hz, {per_period:.3} \
                                 steps per period at dt = {dt} s (at least \
                                 {MIN_SAMPLES_PER_PERIOD} are needed to follow it: use dt ≤ {:e} s)",
                                1.0 / (MIN_SAMPLES_PER_PERIOD * frequency)
                            ));
                        }
                    }
                }
            }
        }
        out
    }

    /// True when the body is free (dynamic) at time `t`: its release, gradual or not, is over.
    pub fn released(&self, t: f64) -> bool {
        self.release_at.is_some_and(|r| t >= r + self.release_over)
    }

    /// True while a gradual release is under way at time `t`.
    pub fn releasing(&self, t: f64) -> bool {
        self.release_at
            .is_some_and(|r| t >= r && t < r + self.release_over)
    }

    /// The bounds of the step from `t0` to `t1`: `max_force` and `max_torque`, or during a
    /// gradual release `release_force` scaled by the fraction of the release left at `t1`
    /// (zero on its last step) and `max_torque`.
    pub fn limits(&self, t0: f64, t1: f64) -> Limits {
        match self.release_at {
            Some(r) if self.releasing(t0) => {
                let left = (1.0 - (t1 - r) / self.release_over).clamp(0.0, 1.0);
                Limits {
                    force: self
                        .release_force
                        .map(|f| if f.is_finite() { f * left } else { f }),
                    torque: self.max_torque,
                }
            }
            _ => self.held_limits(),
        }
    }

    /// Checks every term; the error names the degree of freedom and the term index.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        if let Some(r) = self.release_at {
            if !r.is_finite() {
                return Err(format!("release_at = {r} must be a finite time (s)").into());
            }
        }
        for (name, limits, unit) in [
            ("max_force", self.max_force, "N"),
            ("max_torque", self.max_torque, "N·m"),
        ] {
            if limits.iter().any(|&f| f.is_nan() || f < 0.0) {
                return Err(format!(
                    "{name} = {limits:?} must hold three values ≥ 0 {unit} (inf: no limit)"
                )
                .into());
            }
        }
        if !(self.release_over.is_finite() && self.release_over >= 0.0) {
            return Err(format!(
                "release_over = {} must be a finite duration ≥ 0 s (0: released at once)",
                self.release_over
            )
            .into());
        }
        if self.release_over > 0.0 && self.release_at.is_none() {
            return Err(format!(
                "release_over = {} needs release_at: a gradual release starts at release_at",
                self.release_over
            )
            .into());
        }
        let f = self.release_force;
        if f.iter().any(|&x| x.is_nan() || x < 0.0) {
            return Err(format!(
                "release_force = {f:?} must hold three values ≥ 0 N (inf: no limit)"
            )
            .into());
        }
        if self.release_over == 0.0 && !is_unlimited(&f) {
            return Err(format!(
                "release_force = {f:?} needs release_over > 0 s: the force of a gradual release"
            )
            .into());
        }
        let c = self.catch_up_speed;
        if c.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(format!(
                "catch_up_speed = [{}, {}, {}] must hold three finite speeds ≥ 0 m/s (0: no \
                 catching up)",
                c[0], c[1], c[2]
            )
            .into());
        }
        for (name, p) in self.dofs() {
            for (k, term) in p.iter().enumerate() {
                term.validate().map_err(|e| format!("{name}[{k}]: {e}"))?;
            }
        }
        for (name, p) in self.superposed.dofs() {
            for (k, term) in p.iter().enumerate() {
                term.validate()
                    .map_err(|e| format!("superposed.{name}[{k}]: {e}"))?;
            }
        }
        if let Some(n) = self.attached_to {
            let moves = self.dofs().iter().any(|(_, p)| !p.is_empty())
                || !self.superposed.is_empty()
                || self.is_force_limited()
                || !is_zero3(&self.catch_up_speed)
                || self.release_at.is_some()
                || self.release_over > 0.0
                || !is_unlimited(&self.release_force);
            if moves {
                return Err(format!(
                    "attached_to = {n}: an attached body moves with body {n} only (no \
                     profiles, limits or release_at of its own)"
                )
                .into());
            }
        }
        Ok(())
    }
}
