//! Imposed velocities of kinematic bodies, per degree of freedom, as functions of time.
//!
//! A [`Profile`] is a sum of [`Term`]s; a [`Driver`] holds one optional profile per degree of
//! freedom (vx, vy, vz, ωx, ωy, ωz in the world frame, ω about the centre of mass). A degree of
//! freedom without a profile has zero velocity.

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
    pub fn validate(&self) -> Result<(), String> {
        let finite = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("{name} = {v} must be a finite number"))
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
                    return Err(format!(
                        "ramp end = {end} must be greater than start = {start}"
                    ));
                }
                Ok(())
            }
            Term::Table { times, values } => {
                if times.is_empty() || times.len() != values.len() {
                    return Err(format!(
                        "table needs as many times as values, at least one (got {} times, {} values)",
                        times.len(),
                        values.len()
                    ));
                }
                for (k, w) in times.windows(2).enumerate() {
                    if w[1] <= w[0] {
                        return Err(format!(
                            "table times must increase strictly (times[{}] = {} ≥ times[{}] = {})",
                            k,
                            w[0],
                            k + 1,
                            w[1]
                        ));
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
                    return Err(format!(
                        "frequency = {frequency} must be finite and ≥ 0 (Hz)"
                    ));
                }
                if end.is_nan() || end < start {
                    return Err(format!("sine end = {end} must be ≥ start = {start}"));
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

/// Imposed velocity of a kinematic body: one optional profile per degree of freedom.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
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

    /// Imposed (linear, angular) velocity at time `t`.
    pub fn velocity(&self, t: f64) -> (crate::math::DVec3, crate::math::DVec3) {
        let e = |p: &Profile| p.iter().map(|term| term.eval(t)).sum::<f64>();
        (
            crate::math::DVec3::new(e(&self.vx), e(&self.vy), e(&self.vz)),
            crate::math::DVec3::new(e(&self.wx), e(&self.wy), e(&self.wz)),
        )
    }

    /// True when the body is free (dynamic) at time `t`.
    pub fn released(&self, t: f64) -> bool {
        self.release_at.is_some_and(|r| t >= r)
    }

    /// Checks every term; the error names the degree of freedom and the term index.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(r) = self.release_at {
            if !r.is_finite() {
                return Err(format!("release_at = {r} must be a finite time (s)"));
            }
        }
        for (name, p) in self.dofs() {
            for (k, term) in p.iter().enumerate() {
                term.validate().map_err(|e| format!("{name}[{k}]: {e}"))?;
            }
        }
        Ok(())
    }
}
