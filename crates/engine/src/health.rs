//! The health check of a run: after every step, a run whose state is no longer a physical one
//! is stopped with the step, the bodies and the quantity named, instead of writing nonsense.
//!
//! Three faults are looked for, in this order:
//!
//! 1. **Non-finite state**: a position, orientation, velocity or angular velocity that is NaN
//!    or infinite.
//! 2. **Speed**: a body whose fastest point, `|v| + |ω| ρ` (ρ its bounding radius), moves
//!    faster than [`HealthCheck::max_speed`]. By default that bound is
//!    [`SPEED_FACTOR`] × max(fastest driver, `√(2 |g| H)`, [`SPEED_FLOOR`]): `√(2 |g| H)` is
//!    the speed of a fall through the scene's height `H` (the extent of its bodies along
//!    gravity when the check is built), the fastest driver the largest speed any driven body's
//!    program can command (a bound summed over its terms), and 1 m/s a floor for scenes
//!    without gravity or drivers. A body ten times faster than anything gravity or the
//!    machines can give has been launched by the solver, not by the physics. A scene that
//!    legitimately throws a body faster (an initial velocity is not counted) sets the bound
//!    itself (`[simulation] max_speed`).
//! 3. **Overlap**: a contact detected at the start of the step whose overlap is deeper than
//!    [`OVERLAP_FRACTION`] = 2 times the smaller inradius of its two bodies (the radius of the
//!    largest sphere about a body's centre of mass that fits inside it; a plane has none): one
//!    body has then been pushed into the other by more than its own inner diameter, which no
//!    rigid-body contact solution allows. Flat grains pressed by tamping tines legitimately
//!    go beyond their inradius: in the default tamping job an overlap reaches 1.12 inradii
//!    at step 387 (6.57 mm against 5.89 mm; the most over its 2,205 steps), so a bound at the
//!    inradius itself stops that run, and this one leaves it a margin of 1.8. Its fastest
//!    point moves at 0.17 m/s, against a speed bound of 45.8 m/s. A fixed bound in metres can be given instead (`[simulation] max_overlap`).
//!
//! The state a run starts from is checked with a bound of [`INITIAL_OVERLAP_FRACTION`] = 1
//! inradius instead ([`HealthCheck::initial`]): two bodies placed in the same spot overlap by
//! their width, at least twice the inradius, which the running bound would let pass; the
//! default job's prepared bed starts at 0.09 inradii. [`initial_warnings`] names smaller initial
//! overlaps and bodies lying under a fixed plane.
//!
//! The check reads the world and changes nothing, so a checked run is bit-identical to an
//! unchecked one. It costs one pass over the bodies and one over the contacts.

use crate::bodies::{BodyKind, Driver};
use crate::math::DVec3;
use crate::output::shared::gather;
use crate::shapes::Shape;
use crate::world::World;
use std::fmt;

/// The default speed bound is this multiple of the scene's speed scale.
pub const SPEED_FACTOR: f64 = 10.0;
/// The smallest speed scale (m/s), for scenes without gravity or drivers.
pub const SPEED_FLOOR: f64 = 1.0;
/// An overlap deeper than this multiple of the smaller inradius of the two bodies in contact
/// is a divergence (see the module documentation for why 2).
pub const OVERLAP_FRACTION: f64 = 2.0;

/// The overlap bound of a run's initial state, in inradii ([`HealthCheck::initial`]): a
/// scene should start (nearly) without overlaps, and two bodies placed in the same spot
/// overlap by at least twice the smaller inradius, which the running bound would let pass.
pub const INITIAL_OVERLAP_FRACTION: f64 = 1.0;

/// How deep an overlap may be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OverlapBound {
    /// This fraction of the smaller inradius of the two bodies in contact.
    Fraction(f64),
    /// This depth (m), whatever the bodies.
    Absolute(f64),
}

/// The bounds a run must stay within, built from its scene (see the module documentation).
#[derive(Clone, Debug)]
pub struct HealthCheck {
    /// Largest speed of any point of a body (m/s).
    pub max_speed: f64,
    /// How [`HealthCheck::max_speed`] was obtained, in words, for messages.
    pub speed_basis: String,
    /// Largest overlap.
    pub overlap: OverlapBound,
    /// Per body: bounding radius (0 for planes) and inradius (infinite for planes), m.
    radius: Vec<f64>,
    inradius: Vec<f64>,
}

/// The quantity a [`Divergence`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    Position,
    Orientation,
    Velocity,
    AngularVelocity,
    /// The speed of a body's fastest point.
    Speed,
    /// The overlap of two bodies in contact.
    Overlap,
}

impl Quantity {
    /// The quantity's name in messages and `summary.json` (`"angular velocity"`).
    pub fn name(self) -> &'static str {
        match self {
            Quantity::Position => "position",
            Quantity::Orientation => "orientation",
            Quantity::Velocity => "velocity",
            Quantity::AngularVelocity => "angular velocity",
            Quantity::Speed => "speed",
            Quantity::Overlap => "overlap",
        }
    }
}

/// A run that left the physical: what, where and when.
#[derive(Clone, Debug, PartialEq)]
pub struct Divergence {
    /// The step after which the fault was found (`World::step_index`).
    pub step: u64,
    /// The time at the end of that step (s).
    pub time: f64,
    pub quantity: Quantity,
    /// The offending value: the speed (m/s), the overlap depth (m), or for a non-finite state
    /// the first non-finite component.
    pub value: f64,
    /// The bound it broke (m/s or m; infinite for a non-finite state).
    pub bound: f64,
    /// The body at fault (the fastest, or the two of the deepest overlap), then no others.
    pub bodies: Vec<u32>,
    /// The group name of each of [`Divergence::bodies`].
    pub groups: Vec<String>,
    /// How many bodies (contacts, for an overlap) broke the bound in all.
    pub count: usize,
    /// Why the bound is what it is, in words.
    pub basis: String,
}

impl std::error::Error for Divergence {}

/// A number for a message: NaN and infinities spelled out, others with 4 significant digits.
fn num(x: f64) -> String {
    if x.is_nan() {
        "NaN".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else if x != 0.0 && !(1e-3..1e5).contains(&x.abs()) {
        format!("{x:.3e}")
    } else {
        let s = format!("{x:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

impl fmt::Display for Divergence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = |k: usize| {
            format!(
                "body {} (group \"{}\")",
                self.bodies[k],
                self.groups.get(k).map_or("?", String::as_str)
            )
        };
        if self.step == 0 {
            write!(f, "the initial state (step 0) is out of bounds: ")?;
        } else {
            write!(
                f,
                "the run diverged at step {} (t = {} s): ",
                self.step,
                num(self.time)
            )?;
        }
        let others = self.count.saturating_sub(1);
        match self.quantity {
            Quantity::Speed => {
                write!(
                    f,
                    "{} moves at {} m/s, more than the bound {} m/s ({})",
                    name(0),
                    num(self.value),
                    num(self.bound),
                    self.basis
                )?;
                if others > 0 {
                    write!(f, "; {others} more bodies exceed it")?;
                }
            }
            Quantity::Overlap => {
                write!(
                    f,
                    "{} and {} overlap by {} mm, more than the bound {} mm ({})",
                    name(0),
                    name(1),
                    num(self.value * 1e3),
                    num(self.bound * 1e3),
                    self.basis
                )?;
                if others > 0 {
                    write!(f, "; {others} more contacts exceed their bound")?;
                }
            }
            q => {
                write!(
                    f,
                    "{} has a non-finite {} ({})",
                    name(0),
                    q.name(),
                    num(self.value)
                )?;
                if others > 0 {
                    write!(f, "; {others} more bodies have non-finite values")?;
                }
            }
        }
        Ok(())
    }
}

/// `|v|` without overflow: `DVec3::length` squares the components, so a velocity of 1e200 m/s
/// would read as infinite.
fn norm(v: DVec3) -> f64 {
    let m = v.abs().max_element();
    if m > 0.0 && m.is_finite() {
        m * (v / m).length()
    } else {
        m
    }
}

/// Largest `|Σ terms|` a profile can reach: each term's largest magnitude, summed.
fn profile_bound(p: &[crate::bodies::driver::Term]) -> f64 {
    use crate::bodies::driver::Term;
    p.iter()
        .map(|t| match t {
            Term::Constant { value } => value.abs(),
            Term::Ramp { from, to, .. } => from.abs().max(to.abs()),
            Term::Table { values, .. } => values.iter().fold(0.0f64, |m, v| m.max(v.abs())),
            Term::Sine { amplitude, .. } => amplitude.abs(),
        })
        .sum()
}

/// Bounds on a driver's (linear, angular) speed over all time: program plus superposed.
fn driver_bounds(d: &Driver) -> (f64, f64) {
    let s = &d.superposed;
    let lin = DVec3::new(
        profile_bound(&d.vx) + profile_bound(&s.vx),
        profile_bound(&d.vy) + profile_bound(&s.vy),
        profile_bound(&d.vz) + profile_bound(&s.vz),
    );
    let ang = DVec3::new(
        profile_bound(&d.wx) + profile_bound(&s.wx),
        profile_bound(&d.wy) + profile_bound(&s.wy),
        profile_bound(&d.wz) + profile_bound(&s.wz),
    );
    (norm(lin), norm(ang))
}

impl HealthCheck {
    /// The default bounds of `world`'s scene, from its current state (build it before the run
    /// starts, or before a checkpoint is read into the world, so that a resumed run checks
    /// against the same bounds as an uninterrupted one).
    pub fn new(world: &World) -> Self {
        let b = &world.bodies;
        let n = b.len();
        let mut radius = vec![0.0; n];
        let mut inradius = vec![f64::INFINITY; n];
        for i in 0..n {
            if let Shape::Polyhedron(p) = &b.shape[i] {
                radius[i] = p.radius;
                inradius[i] = p.face_offsets.iter().copied().fold(f64::INFINITY, f64::min);
            }
        }
        // The scene's height: the extent of its (non-plane) bodies along gravity.
        let g = world.settings.gravity;
        let down = if norm(g) > 0.0 {
            g / norm(g)
        } else {
            DVec3::ZERO
        };
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (i, &r) in radius.iter().enumerate() {
            if matches!(b.shape[i], Shape::Polyhedron(_)) {
                let z = b.position[i].dot(down);
                lo = lo.min(z - r);
                hi = hi.max(z + r);
            }
        }
        let height = if hi >= lo { hi - lo } else { 0.0 };
        let fall = (2.0 * height).sqrt() * norm(g).sqrt();
        // The fastest point a driver can command: an attached body turns with its parent at
        // its distance from it.
        let mut driver = 0.0f64;
        for (i, &r) in radius.iter().enumerate() {
            if b.kind[i] != BodyKind::Kinematic {
                continue;
            }
            let Some(d) = &b.driver[i] else { continue };
            let (p, arm) = match d.attached_to {
                Some(p) if p < n && p != i => (p, norm(b.position[i] - b.position[p])),
                _ => (i, 0.0),
            };
            if let Some(dp) = &b.driver[p] {
                let (lin, ang) = driver_bounds(dp);
                driver = driver.max(lin + ang * (arm + r));
            }
        }
        let scale = driver.max(fall).max(SPEED_FLOOR);
        let max_speed = SPEED_FACTOR * scale;
        let speed_basis = format!(
            "{} × max(fastest driver {} m/s, √(2 g H) = {} m/s for the scene's height H = {} m, \
             {} m/s); [simulation] max_speed sets another",
            num(SPEED_FACTOR),
            num(driver),
            num(fall),
            num(height),
            num(SPEED_FLOOR)
        );
        HealthCheck {
            max_speed,
            speed_basis,
            overlap: OverlapBound::Fraction(OVERLAP_FRACTION),
            radius,
            inradius,
        }
    }

    /// The check of the state a run starts from (after [`World::detect`]): the same, but for
    /// a default overlap bound of [`INITIAL_OVERLAP_FRACTION`] inradii. A fixed
    /// `max_overlap` stays as it is.
    pub fn initial(&self) -> Self {
        let mut h = self.clone();
        if let OverlapBound::Fraction(_) = h.overlap {
            h.overlap = OverlapBound::Fraction(INITIAL_OVERLAP_FRACTION);
        }
        h
    }

    /// Replaces the speed bound (m/s; a scenario's `max_speed`).
    pub fn with_max_speed(mut self, v: f64) -> Self {
        self.max_speed = v;
        self.speed_basis = "set by [simulation] max_speed".into();
        self
    }

    /// Replaces the overlap bound by a fixed depth (m; a scenario's `max_overlap`).
    pub fn with_max_overlap(mut self, depth: f64) -> Self {
        self.overlap = OverlapBound::Absolute(depth);
        self
    }

    /// The overlap bound of a contact between bodies `a` and `b` (m).
    fn overlap_bound(&self, a: usize, b: usize) -> f64 {
        match self.overlap {
            OverlapBound::Absolute(d) => d,
            OverlapBound::Fraction(f) => {
                let r = |i: usize| self.inradius.get(i).copied().unwrap_or(f64::INFINITY);
                f * r(a).min(r(b))
            }
        }
    }

    /// How close `world` is to the bounds: (largest speed / its bound, largest overlap / its
    /// bound) over the bodies and contacts; a healthy world has both at most 1 (non-finite
    /// values are ignored here, [`HealthCheck::check`] reports them).
    pub fn margins(&self, world: &World) -> (f64, f64) {
        let b = &world.bodies;
        let mut speed = 0.0f64;
        for i in (0..b.len()).filter(|&i| world.answers_for(i)) {
            if b.kind[i] != BodyKind::Fixed {
                let r = self.radius.get(i).copied().unwrap_or(0.0);
                let v = norm(b.velocity[i]) + norm(b.angular_velocity[i]) * r;
                if v.is_finite() {
                    speed = speed.max(v / self.max_speed);
                }
            }
        }
        if world.shares_bodies() {
            speed = world.max_over_ranks(speed);
        }
        let overlap = world.max_over_contacts(0.0, |c, k| {
            let ratio = -c.gap[k] / self.overlap_bound(c.body1[k] as usize, c.body2[k] as usize);
            if ratio.is_finite() {
                ratio
            } else {
                0.0
            }
        });
        (speed, overlap)
    }

    /// Checks `world` after a step: `Err` names the first kind of fault found (non-finite
    /// state, then speed, then overlap), its worst instance and how many there are.
    pub fn check(&self, world: &World) -> Result<(), Divergence> {
        let b = &world.bodies;
        let fault = |quantity, value, bound, bodies: Vec<u32>, count, basis: String| {
            let groups = bodies
                .iter()
                .map(|&i| world.group_name(b.group[i as usize]))
                .collect();
            Err(Divergence {
                step: world.step_index,
                time: world.time,
                quantity,
                value,
                bound,
                bodies,
                groups,
                count,
                basis,
            })
        };
        // 1. Non-finite state.
        let mut first: Option<(usize, Quantity, f64)> = None;
        let mut count = 0;
        for i in (0..b.len()).filter(|&i| world.answers_for(i)) {
            // Runs after every step over every body: no allocation here.
            let bad_in =
                |what: Quantity, xs: &[f64]| xs.iter().find(|x| !x.is_finite()).map(|&x| (what, x));
            let bad = bad_in(Quantity::Position, &b.position[i].to_array())
                .or_else(|| bad_in(Quantity::Orientation, &b.orientation[i].to_array()))
                .or_else(|| bad_in(Quantity::Velocity, &b.velocity[i].to_array()))
                .or_else(|| bad_in(Quantity::AngularVelocity, &b.angular_velocity[i].to_array()));
            if let Some((what, x)) = bad {
                count += 1;
                first.get_or_insert((i, what, x));
            }
        }
        if world.shares_bodies() {
            (first, count) = non_finite_over_ranks(world, first, count);
        }
        if let Some((i, what, x)) = first {
            return fault(
                what,
                x,
                f64::INFINITY,
                vec![i as u32],
                count,
                "finite".into(),
            );
        }
        // 2. Speed of the fastest point.
        let mut worst: Option<(usize, f64)> = None;
        let mut count = 0;
        for i in (0..b.len()).filter(|&i| world.answers_for(i)) {
            if b.kind[i] == BodyKind::Fixed {
                continue;
            }
            let r = self.radius.get(i).copied().unwrap_or(0.0);
            let v = norm(b.velocity[i]) + norm(b.angular_velocity[i]) * r;
            if v > self.max_speed {
                count += 1;
                if worst.is_none_or(|(_, w)| v > w) {
                    worst = Some((i, v));
                }
            }
        }
        if world.shares_bodies() {
            (worst, count) = fastest_over_ranks(world, worst, count);
        }
        if let Some((i, v)) = worst {
            return fault(
                Quantity::Speed,
                v,
                self.max_speed,
                vec![i as u32],
                count,
                self.speed_basis.clone(),
            );
        }
        // 3. Overlaps of the contacts detected at the start of the step (those past their
        // bound, from every rank).
        let c = &world.gather_contacts(|c, k| {
            -c.gap[k] > self.overlap_bound(c.body1[k] as usize, c.body2[k] as usize)
        });
        let mut worst: Option<(usize, f64, f64)> = None;
        let mut count = 0;
        for k in 0..c.len() {
            let depth = -c.gap[k];
            if depth <= 0.0 {
                continue;
            }
            let bound = self.overlap_bound(c.body1[k] as usize, c.body2[k] as usize);
            if depth > bound {
                count += 1;
                if worst.is_none_or(|(_, d, bd)| depth / bound > d / bd) {
                    worst = Some((k, depth, bound));
                }
            }
        }
        if let Some((k, depth, bound)) = worst {
            let basis = match self.overlap {
                OverlapBound::Absolute(_) => "set by [simulation] max_overlap".to_string(),
                OverlapBound::Fraction(f) => format!(
                    "{} × the smaller inradius of the two bodies, {} mm; [simulation] \
                     max_overlap sets another",
                    num(f),
                    num(bound / f * 1e3)
                ),
            };
            return fault(
                Quantity::Overlap,
                depth,
                bound,
                vec![c.body1[k], c.body2[k]],
                count,
                basis,
            );
        }
        Ok(())
    }
}

/// Warnings about a world about to take its first step, after [`World::detect`]: pairs of
/// bodies overlapping by more than `depth` (m), and bodies lying wholly beneath a fixed
/// plane (under a floor, say). At most `lines` of each are named, then their number. A
/// scenario can mean neither, but both are usually a mistake in its coordinates.
pub fn initial_warnings(world: &World, depth: f64, lines: usize) -> Vec<String> {
    let b = &world.bodies;
    let name = |i: u32| format!("{i} (group \"{}\")", world.group_name(b.group[i as usize]));
    let mut out = Vec::new();
    let c = &world.gather_contacts(|c, k| -c.gap[k] > depth);
    let mut deep: Vec<(f64, u32, u32)> = (0..c.len())
        .map(|k| (-c.gap[k], c.body1[k], c.body2[k]))
        .collect();
    deep.sort_by(|a, b| b.0.total_cmp(&a.0));
    deep.dedup_by_key(|d| (d.1, d.2));
    for &(d, b1, b2) in deep.iter().take(lines) {
        out.push(format!(
            "bodies {} and {} overlap by {} mm at the start",
            name(b1),
            name(b2),
            num(d * 1e3)
        ));
    }
    if deep.len() > lines {
        out.push(format!(
            "{} pairs of bodies overlap by more than {} mm at the start (the deepest named above)",
            deep.len(),
            num(depth * 1e3)
        ));
    }
    let planes: Vec<(usize, DVec3)> = (0..b.len())
        .filter_map(|p| match b.shape[p] {
            Shape::Plane { normal } if b.kind[p] == BodyKind::Fixed => {
                Some((p, b.orientation[p] * normal))
            }
            _ => None,
        })
        .collect();
    let mut under = Vec::new();
    for i in 0..b.len() {
        let Shape::Polyhedron(poly) = &b.shape[i] else {
            continue;
        };
        for &(p, n) in &planes {
            let d = n.dot(b.position[i] - b.position[p]);
            if d < -poly.radius {
                under.push((i, p, -d));
                break;
            }
        }
    }
    for &(i, p, d) in under.iter().take(lines) {
        out.push(format!(
            "body {} lies wholly beneath the plane of body {}, its centre {} m under it",
            name(i as u32),
            name(p as u32),
            num(d)
        ));
    }
    if under.len() > lines {
        out.push(format!(
            "{} bodies lie wholly beneath a fixed plane (the first named above)",
            under.len()
        ));
    }
    out
}

/// The quantities of a body's state the non-finite pass reads, in its order.
const STATE: [Quantity; 4] = [
    Quantity::Position,
    Quantity::Orientation,
    Quantity::Velocity,
    Quantity::AngularVelocity,
];

/// The non-finite pass's answer over the ranks, from each rank's over its own bodies: the
/// fault of the lowest-numbered body (the first a single process finds) and the sum of the
/// counts. A collective.
fn non_finite_over_ranks(
    world: &World,
    first: Option<(usize, Quantity, f64)>,
    count: usize,
) -> (Option<(usize, Quantity, f64)>, usize) {
    let mine = match first {
        Some((i, what, x)) => {
            let q = STATE.iter().position(|&s| s == what).unwrap_or(0);
            [count as f64, i as f64, q as f64, x]
        }
        None => [count as f64, -1.0, 0.0, 0.0],
    };
    let all = gather(world, &mine);
    let count = all.chunks_exact(4).map(|c| c[0] as usize).sum();
    let first = all
        .chunks_exact(4)
        .filter(|c| c[1] >= 0.0)
        .min_by(|a, b| a[1].total_cmp(&b[1]))
        .map(|c| (c[1] as usize, STATE[c[2] as usize], c[3]));
    (first, count)
}

/// The speed pass's answer over the ranks, from each rank's over its own bodies: the fastest
/// body, the lowest-numbered of equally fast ones (the one a single process keeps), and the
/// sum of the counts. A collective.
fn fastest_over_ranks(
    world: &World,
    worst: Option<(usize, f64)>,
    count: usize,
) -> (Option<(usize, f64)>, usize) {
    let mine = match worst {
        Some((i, v)) => [count as f64, i as f64, v],
        None => [count as f64, -1.0, 0.0],
    };
    let all = gather(world, &mine);
    let count = all.chunks_exact(3).map(|c| c[0] as usize).sum();
    let worst = all
        .chunks_exact(3)
        .filter(|c| c[1] >= 0.0)
        .map(|c| (c[1] as usize, c[2]))
        .reduce(|a, b| match b.1 > a.1 || (b.1 == a.1 && b.0 < a.0) {
            true => b,
            false => a,
        });
    (worst, count)
}

#[cfg(test)]
mod tests {
    use super::num;

    #[test]
    fn numbers_in_messages() {
        assert_eq!(num(f64::NAN), "NaN");
        assert_eq!(num(f64::NEG_INFINITY), "-inf");
        assert_eq!(num(1e12), "1.000e12");
        assert_eq!(num(34.3), "34.3");
        assert_eq!(num(10.0), "10");
        assert_eq!(num(0.0), "0");
    }
}
