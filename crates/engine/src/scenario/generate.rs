//! Generated packs of random grains: a loose lattice of seeded random polyhedra inside a box,
//! ready to be poured (used by scenarios, tests and benchmarks).

use crate::error::ScenarioError;
use crate::math::{DQuat, DVec3};
use crate::shapes::random::{random_grain, GrainParams};
use crate::shapes::{PolyhedronBuild, ShapeError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// A pack of random grains on a lattice.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GrainPack {
    /// Number of grains.
    pub count: usize,
    /// Lower corner of the region filled by the lattice (m).
    pub min: [f64; 3],
    /// Upper x and y of the region (m); the lattice grows upward in z as far as needed.
    pub max_xy: [f64; 2],
    /// Range of volume-equivalent diameters (m), sampled uniformly.
    pub diameter: [f64; 2],
    /// Range of vertex counts.
    #[serde(default = "default_vertices")]
    pub vertices: [usize; 2],
    /// Ratio of the longest to the intermediate axis.
    #[serde(default = "one")]
    pub elongation: f64,
    /// Ratio of the intermediate to the shortest axis.
    #[serde(default = "one")]
    pub flatness: f64,
    /// Random seed.
    #[serde(default)]
    pub seed: u64,
}

pub(crate) fn default_vertices() -> [usize; 2] {
    [12, 20]
}
pub(crate) fn one() -> f64 {
    1.0
}

impl GrainPack {
    /// Checks the parameters; errors name the field.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        if self.count == 0 {
            return Err("count = 0 must be ≥ 1".into());
        }
        let [d0, d1] = self.diameter;
        if !(d0 > 0.0 && d1 >= d0 && d1.is_finite()) {
            return Err(format!("diameter = [{d0}, {d1}] must satisfy 0 < min ≤ max").into());
        }
        let [v0, v1] = self.vertices;
        if !(4..=200).contains(&v0) || v1 < v0 || v1 > 200 {
            return Err(format!("vertices = [{v0}, {v1}] must satisfy 4 ≤ min ≤ max ≤ 200").into());
        }
        for (name, x) in [("elongation", self.elongation), ("flatness", self.flatness)] {
            if !(x.is_finite() && (1.0..=10.0).contains(&x)) {
                return Err(format!("{name} = {x} must be in [1, 10]").into());
            }
        }
        // Before the span: a NaN in min would otherwise be blamed on max_xy.
        if self.min.iter().any(|x| !x.is_finite()) {
            return Err(format!("min = {:?} must be finite", self.min).into());
        }
        if self.max_xy.iter().any(|x| !x.is_finite()) {
            return Err(format!("max_xy = {:?} must be finite", self.max_xy).into());
        }
        let span = |k: usize| self.max_xy[k] - self.min[k];
        if !(span(0) >= d1 && span(1) >= d1) {
            return Err(format!(
                "max_xy = {:?} must exceed min by at least the largest diameter {d1} m",
                self.max_xy
            )
            .into());
        }
        Ok(())
    }

    /// Builds the grains with random orientations, placed on a lattice whose pitch is the
    /// largest circumscribed diameter (+2 %), filling layer after layer from `min` upward, so
    /// that no two grains overlap. Deterministic in `seed`.
    pub fn build(&self) -> Result<Vec<PolyhedronBuild>, ShapeError> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let params = GrainParams {
            vertices_min: self.vertices[0],
            vertices_max: self.vertices[1],
            elongation: self.elongation,
            flatness: self.flatness,
        };
        let mut out = Vec::with_capacity(self.count);
        for _ in 0..self.count {
            let d = rng.gen_range(self.diameter[0]..=self.diameter[1]);
            let mut g = random_grain(&mut rng, &params, d)?;
            let q = random_rotation(&mut rng);
            g.orientation = (q * g.orientation).normalize();
            out.push(g);
        }
        // Lattice pitch: the largest circumscribed sphere, plus a margin, so no two grains touch.
        let r_max = out.iter().map(|g| g.shape.radius).fold(0.0, f64::max);
        let pitch = 2.0 * r_max * 1.02;
        let nx = (((self.max_xy[0] - self.min[0]) / pitch).floor() as usize).max(1);
        let ny = (((self.max_xy[1] - self.min[1]) / pitch).floor() as usize).max(1);
        for (k, g) in out.iter_mut().enumerate() {
            let (ix, iy, iz) = (k % nx, (k / nx) % ny, k / (nx * ny));
            g.position = DVec3::new(
                self.min[0] + (ix as f64 + 0.5) * pitch,
                self.min[1] + (iy as f64 + 0.5) * pitch,
                self.min[2] + (iz as f64 + 0.5) * pitch,
            );
        }
        Ok(out)
    }
}

/// A uniformly distributed random rotation (Shoemake's method).
pub fn random_rotation<R: Rng>(rng: &mut R) -> DQuat {
    let (u1, u2, u3): (f64, f64, f64) = (rng.gen(), rng.gen(), rng.gen());
    let tau = std::f64::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    DQuat::from_xyzw(
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
        b * (tau * u3).cos(),
    )
    .normalize()
}
