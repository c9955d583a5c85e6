//! Ballast grains: seeded random convex polyhedra whose sizes follow a grading curve.
//!
//! # Method
//!
//! The grain sizes are planned first, **stratified by size class** of the grading curve (see
//! [`crate::grading`]), so that even a small sample follows the curve closely:
//!
//! * [`Amount::Count`]`(n)`: class `k` receives `nₖ` grains, `nₖ` being `n × number fractionₖ`
//!   rounded by the largest-remainder rule (ties to the smaller class);
//! * [`Amount::SolidVolume`]`(V)`: class `k` receives grains until its solid volume reaches
//!   `V × mass fractionₖ` to within half a grain (a draw is kept while the running volume plus
//!   half the new grain stays at or below the target).
//!
//! Within its class each size is drawn from the number distribution (exact inverse transform,
//! [`SizeClass::sample_mm`]), so the mass distribution of the sample follows the curve; the size
//! is the grain's volume-equivalent diameter (the crate's size convention). The planned sizes
//! are then shuffled, so that placing grains in order does not sort the bed by size.
//!
//! Each grain's shape is then built by [`random_grain`] (volume-equivalent diameter exactly the
//! planned size) and given a uniformly random orientation.
//!
//! # Reproducibility
//!
//! Everything derives from `seed` through ChaCha8 generators: stream 0 plans the sizes and the
//! shuffle, stream `k + 1` builds grain `k`. Grains are therefore independent of one another
//! and of the order in which they are built (which leaves room to build them in parallel),
//! and the same seed gives bit-identical grains on every platform.

use crate::grading::{GradingCurve, SizeClass};
use ballast_engine::math::DVec3;
use ballast_engine::random_rotation;
use ballast_engine::shapes::random::{random_grain, GrainParams};
use ballast_engine::shapes::{PolyhedronBuild, ShapeError};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Most grains one call may generate (over 10 GB of polyhedra): beyond, the request is taken for
/// a unit mistake.
pub const MAX_GRAINS: usize = 5_000_000;

/// What a set of ballast grains is made of.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GrainSpec {
    /// Grading curve (mass fraction passing versus sieve size = volume-equivalent diameter).
    pub grading: GradingCurve,
    /// Range of hull vertex counts `[min, max]`, `4 ≤ min ≤ max`.
    pub vertices: [usize; 2],
    /// Ratio of the longest to the intermediate axis of the sampling ellipsoid (≥ 1).
    pub elongation: f64,
    /// Ratio of the intermediate to the shortest axis of the sampling ellipsoid (≥ 1).
    pub flatness: f64,
    /// Density of the stone, kg/m³ (not used to build the shapes; carried for the bodies).
    pub density: f64,
}

impl Default for GrainSpec {
    /// EN 13450 31.5/50 ballast ([`GradingCurve::en13450_31_5_50`]), 12–20 vertices,
    /// elongation 1.4 and flatness 1.2 (the engine's defaults), 2700 kg/m³.
    fn default() -> Self {
        let shape = GrainParams::default();
        GrainSpec {
            grading: GradingCurve::en13450_31_5_50(),
            vertices: [12, 20],
            elongation: shape.elongation,
            flatness: shape.flatness,
            density: 2700.0,
        }
    }
}

/// How many grains to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Amount {
    /// This number of grains.
    Count(usize),
    /// Grains up to this total solid volume, m³ (e.g. bed volume × target compacity).
    SolidVolume(f64),
}

/// Why grains could not be generated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GrainError {
    /// A field of the request is invalid.
    #[error("{field} = {value}: {allowed}")]
    Field {
        /// Path of the field, e.g. `grains.vertices`.
        field: String,
        /// The offending value.
        value: String,
        /// What is allowed.
        allowed: String,
    },
    /// The shape of grain `index` could not be built.
    #[error("grain {index} (diameter {diameter} m): {source}")]
    Shape {
        /// Index of the grain in the output.
        index: usize,
        /// Its planned volume-equivalent diameter, m.
        diameter: f64,
        /// The engine's reason.
        source: ShapeError,
    },
}

fn refuse<T>(field: &str, value: impl std::fmt::Debug, allowed: &str) -> Result<T, GrainError> {
    Err(GrainError::Field {
        field: field.into(),
        value: format!("{value:?}"),
        allowed: allowed.into(),
    })
}

impl GrainSpec {
    /// Checks every field (the grading curve is valid by construction).
    ///
    /// # Errors
    ///
    /// [`GrainError::Field`] naming the first invalid field.
    pub fn validate(&self) -> Result<(), GrainError> {
        let [lo, hi] = self.vertices;
        if lo < 4 || hi < lo {
            return refuse(
                "grains.vertices",
                self.vertices,
                "[min, max] with 4 ≤ min ≤ max",
            );
        }
        if !(self.elongation.is_finite() && self.elongation >= 1.0) {
            return refuse("grains.elongation", self.elongation, "finite and ≥ 1");
        }
        if !(self.flatness.is_finite() && self.flatness >= 1.0) {
            return refuse("grains.flatness", self.flatness, "finite and ≥ 1");
        }
        if !(self.density.is_finite() && self.density > 0.0) {
            return refuse("grains.density", self.density, "finite and > 0 kg/m³");
        }
        Ok(())
    }

    /// The engine's shape parameters for these grains.
    pub(crate) fn params(&self) -> GrainParams {
        GrainParams {
            vertices_min: self.vertices[0],
            vertices_max: self.vertices[1],
            elongation: self.elongation,
            flatness: self.flatness,
        }
    }
}

/// Generates ballast grains (see the [module documentation](self)): each is a convex polyhedron
/// in its body frame with `position` zero and a uniformly random `orientation`; callers place
/// them. The sample's mass distribution follows `spec.grading`, sizes being volume-equivalent
/// diameters.
///
/// # Errors
///
/// [`GrainError::Field`] for an invalid spec (see [`GrainSpec::validate`]), a solid volume that
/// is not finite and ≥ 0, or a request of more than [`MAX_GRAINS`] grains (the expected count for
/// a volume); [`GrainError::Shape`] if the engine cannot build a grain.
pub fn generate_grains(
    spec: &GrainSpec,
    amount: Amount,
    seed: u64,
) -> Result<Vec<PolyhedronBuild>, GrainError> {
    spec.validate()?;
    let classes = spec.grading.size_classes();
    let mut plan_rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sizes_mm = match amount {
        Amount::Count(n) => {
            if n > MAX_GRAINS {
                return refuse("amount.count", n, &format!("at most {MAX_GRAINS} grains"));
            }
            plan_by_count(classes, n, &mut plan_rng)
        }
        Amount::SolidVolume(v) => {
            if !(v.is_finite() && v >= 0.0) {
                return refuse("amount.solid_volume", v, "finite and ≥ 0 m³");
            }
            let expected: f64 = classes
                .iter()
                .filter(|c| c.mass_fraction > 0.0)
                .map(|c| v * c.mass_fraction / mean_grain_volume_m3(c))
                .sum();
            if expected > MAX_GRAINS as f64 {
                return refuse(
                    "amount.solid_volume",
                    v,
                    &format!("about {expected:.3e} grains expected, at most {MAX_GRAINS} allowed"),
                );
            }
            plan_by_volume(classes, v, &mut plan_rng)
        }
    };
    sizes_mm.shuffle(&mut plan_rng);

    let params = spec.params();
    let mut grains = Vec::with_capacity(sizes_mm.len());
    for (index, &size_mm) in sizes_mm.iter().enumerate() {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(index as u64 + 1);
        let diameter = size_mm * 1e-3;
        let mut grain =
            random_grain(&mut rng, &params, diameter).map_err(|source| GrainError::Shape {
                index,
                diameter,
                source,
            })?;
        grain.position = DVec3::ZERO;
        grain.orientation = random_rotation(&mut rng);
        grains.push(grain);
    }
    Ok(grains)
}

/// Mean grain volume (m³) of a class: `π/6 · E[s³]`.
fn mean_grain_volume_m3(class: &SizeClass) -> f64 {
    PI / 6.0 * class.mean_size_cubed_mm3() * 1e-9
}

/// Volume (m³) of the sphere of diameter `size_mm` (mm).
fn grain_volume_m3(size_mm: f64) -> f64 {
    let d = size_mm * 1e-3;
    PI / 6.0 * d * d * d
}

/// Sizes (mm) of `n` grains, class by class, counts by largest remainder.
fn plan_by_count(classes: &[SizeClass], n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let ideal: Vec<f64> = classes
        .iter()
        .map(|c| c.number_fraction * n as f64)
        .collect();
    let mut counts: Vec<usize> = ideal.iter().map(|x| x.floor() as usize).collect();
    let assigned: usize = counts.iter().sum();
    let mut order: Vec<usize> = (0..classes.len())
        .filter(|&k| classes[k].number_fraction > 0.0)
        .collect();
    // Largest fractional part first; the stable sort leaves ties in class order.
    order.sort_by(|&a, &b| {
        let (fa, fb) = (ideal[a] - ideal[a].floor(), ideal[b] - ideal[b].floor());
        fb.total_cmp(&fa)
    });
    for &k in order.iter().cycle().take(n.saturating_sub(assigned)) {
        counts[k] += 1;
    }
    let mut sizes = Vec::with_capacity(n);
    for (c, &m) in classes.iter().zip(&counts) {
        sizes.extend((0..m).map(|_| c.sample_mm(rng)));
    }
    sizes
}

/// Sizes (mm) of grains filling `volume` m³, class by class, each class to within half a grain.
fn plan_by_volume(classes: &[SizeClass], volume: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut sizes = Vec::new();
    for c in classes.iter().filter(|c| c.mass_fraction > 0.0) {
        let target = volume * c.mass_fraction;
        let mut filled = 0.0;
        loop {
            let s = c.sample_mm(rng);
            let v = grain_volume_m3(s);
            if filled + 0.5 * v > target {
                break;
            }
            filled += v;
            sizes.push(s);
        }
    }
    sizes
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballast_engine::shapes::random::equivalent_diameter;

    /// Mass fraction of the sample passing each sieve (size = volume-equivalent diameter).
    fn mass_passing(grains: &[PolyhedronBuild], sieves_mm: &[f64]) -> Vec<f64> {
        let total: f64 = grains.iter().map(|g| g.shape.volume).sum();
        sieves_mm
            .iter()
            .map(|&s| {
                grains
                    .iter()
                    .filter(|g| equivalent_diameter(g.shape.volume) * 1e3 < s)
                    .map(|g| g.shape.volume)
                    .sum::<f64>()
                    / total
            })
            .collect()
    }

    #[test]
    fn three_thousand_grains_follow_the_grading_curve() {
        let spec = GrainSpec::default();
        let grains = generate_grains(&spec, Amount::Count(3000), 2024).unwrap();
        assert_eq!(grains.len(), 3000);
        let curve = &spec.grading;
        for (&s, got) in curve
            .sieves_mm()
            .iter()
            .zip(mass_passing(&grains, curve.sieves_mm()))
        {
            let want = curve.passing_at(s);
            // Stratified by class, the sample stays within a few tenths of a point of the
            // curve (±3 points would be the usual acceptance; 1 point keeps the test sharp).
            assert!(
                (got - want).abs() <= 0.01,
                "sieve {s} mm: sample passes {got:.4}, curve {want:.4}"
            );
        }
        for g in &grains {
            let n = g.shape.vertices.len();
            assert!((12..=20).contains(&n), "{n} vertices");
            let d = equivalent_diameter(g.shape.volume) * 1e3;
            assert!((curve.min_size_mm()..=63.0 + 1e-9).contains(&d), "{d} mm");
            assert_eq!(g.position, DVec3::ZERO);
            assert!((g.orientation.length() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn solid_volume_is_met_to_within_a_grain_per_class() {
        let spec = GrainSpec {
            grading: GradingCurve::en13450_25_50(),
            vertices: [8, 12],
            ..GrainSpec::default()
        };
        let target = 0.02; // m³, a few hundred grains
        let grains = generate_grains(&spec, Amount::SolidVolume(target), 5).unwrap();
        let total: f64 = grains.iter().map(|g| g.shape.volume).sum();
        let classes = spec
            .grading
            .size_classes()
            .iter()
            .filter(|c| c.mass_fraction > 0.0)
            .count() as f64;
        let half_largest = 0.5 * grain_volume_m3(63.0);
        assert!(
            (total - target).abs() <= classes * half_largest,
            "{total} m³ for {target} m³"
        );
        let curve = &spec.grading;
        for (&s, got) in curve
            .sieves_mm()
            .iter()
            .zip(mass_passing(&grains, curve.sieves_mm()))
        {
            assert!(
                (got - curve.passing_at(s)).abs() <= 0.03,
                "sieve {s}: {got}"
            );
        }
        assert!(generate_grains(&spec, Amount::SolidVolume(0.0), 5)
            .unwrap()
            .is_empty());
    }

    #[test]
    fn same_seed_gives_bit_identical_grains() {
        let spec = GrainSpec::default();
        let a = generate_grains(&spec, Amount::Count(40), 99).unwrap();
        let b = generate_grains(&spec, Amount::Count(40), 99).unwrap();
        let c = generate_grains(&spec, Amount::Count(40), 100).unwrap();
        let bits = |g: &PolyhedronBuild| {
            let mut v: Vec<u64> = g
                .shape
                .vertices
                .iter()
                .flat_map(|p| p.to_array())
                .map(f64::to_bits)
                .collect();
            v.extend(g.orientation.to_array().map(f64::to_bits));
            v
        };
        assert!(a.iter().zip(&b).all(|(x, y)| bits(x) == bits(y)));
        assert_eq!(a.len(), b.len());
        assert!(a.iter().zip(&c).any(|(x, y)| bits(x) != bits(y)));
    }

    #[test]
    fn counts_are_allocated_exactly() {
        let curve = GradingCurve::en13450_31_5_50();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for n in [0, 1, 7, 100, 1001] {
            assert_eq!(plan_by_count(curve.size_classes(), n, &mut rng).len(), n);
        }
        // 1000 grains: each class within one grain of n × number fraction.
        let sizes = plan_by_count(curve.size_classes(), 1000, &mut rng);
        for c in curve.size_classes() {
            let m = sizes
                .iter()
                .filter(|&&s| s >= c.lower_mm && s < c.upper_mm)
                .count() as f64;
            assert!((m - 1000.0 * c.number_fraction).abs() < 1.0, "{c:?}: {m}");
        }
    }

    #[test]
    fn invalid_requests_name_the_field() {
        let field = |spec: &GrainSpec, amount| match generate_grains(spec, amount, 0) {
            Err(GrainError::Field { field, .. }) => field,
            other => panic!("expected a field error, got {other:?}"),
        };
        let ok = GrainSpec::default();
        let cases = [
            (
                GrainSpec {
                    vertices: [3, 10],
                    ..ok.clone()
                },
                "grains.vertices",
            ),
            (
                GrainSpec {
                    vertices: [12, 10],
                    ..ok.clone()
                },
                "grains.vertices",
            ),
            (
                GrainSpec {
                    elongation: 0.9,
                    ..ok.clone()
                },
                "grains.elongation",
            ),
            (
                GrainSpec {
                    flatness: f64::NAN,
                    ..ok.clone()
                },
                "grains.flatness",
            ),
            (
                GrainSpec {
                    density: 0.0,
                    ..ok.clone()
                },
                "grains.density",
            ),
        ];
        for (spec, name) in cases {
            assert_eq!(field(&spec, Amount::Count(1)), name);
        }
        assert_eq!(field(&ok, Amount::SolidVolume(-1.0)), "amount.solid_volume");
        assert_eq!(field(&ok, Amount::SolidVolume(1e6)), "amount.solid_volume");
        assert_eq!(field(&ok, Amount::Count(MAX_GRAINS + 1)), "amount.count");
        let e = generate_grains(&ok, Amount::SolidVolume(f64::INFINITY), 0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "amount.solid_volume = inf: finite and ≥ 0 m³"
        );
    }
}
