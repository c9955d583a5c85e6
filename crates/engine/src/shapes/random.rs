//! Seeded random convex polyhedra (angular grains).
//!
//! A grain is the convex hull of points scattered near an ellipsoid with semi-axes
//! `(elongation·flatness, flatness, 1)`: directions uniform on the sphere (`z` uniform in
//! `[−1, 1]`, azimuth uniform, which is exactly uniform by Archimedes' hat-box theorem), radius
//! factor uniform in `[0.85, 1]` for angularity. No random axes are needed: the principal frame
//! of the hull re-orients the grain anyway. The grain is finally scaled so that its
//! volume-equivalent sphere has the requested diameter.

use super::polyhedron::{build_indexed, PolyhedronBuild, ShapeError, MIN_EXTENT};
use crate::math::DVec3;
use rand::Rng;

/// Smallest radius factor of a sampled point (1 is on the ellipsoid).
const JITTER_MIN: f64 = 0.85;
/// Attempts before giving up on reaching the requested vertex count.
const MAX_ATTEMPTS: usize = 1000;

/// Shape parameters of a random angular grain.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GrainParams {
    /// Fewest hull vertices (at least 4).
    pub vertices_min: usize,
    /// Most hull vertices (at least `vertices_min`).
    pub vertices_max: usize,
    /// Ratio of the longest to the intermediate axis (≥ 1).
    pub elongation: f64,
    /// Ratio of the intermediate to the shortest axis (≥ 1).
    pub flatness: f64,
}

impl Default for GrainParams {
    /// Moderately angular, mildly elongated grains, typical of railway ballast.
    fn default() -> Self {
        GrainParams {
            vertices_min: 12,
            vertices_max: 24,
            elongation: 1.4,
            flatness: 1.2,
        }
    }
}

/// Diameter of the sphere of the given volume: `(6V/π)^(1/3)`.
#[inline]
pub fn equivalent_diameter(volume: f64) -> f64 {
    (6.0 * volume / std::f64::consts::PI).cbrt()
}

/// A random convex grain with between `vertices_min` and `vertices_max` hull vertices and a
/// volume-equivalent diameter of exactly `diameter` (up to rounding), in its body
/// frame (centre of mass, principal axes with the longest extent along `x`).
///
/// Deterministic for a given generator state. A vertex count `n` is drawn in the range and `n`
/// points are sampled; points that end up inside the hull are replaced by fresh samples (keeping
/// the hull vertices) until the hull has enough vertices. The returned `position` and
/// `orientation` locate the grain in the (meaningless) sampling frame; callers place grains
/// themselves.
///
/// # Errors
///
/// [`ShapeError::Degenerate`] for invalid parameters (fewer than 4 vertices, an empty range,
/// ratios below 1) or if the vertex count cannot be reached, [`ShapeError::NonFinite`] for
/// non-finite ratios or diameter, [`ShapeError::TooSmall`] for a diameter below
/// [`MIN_EXTENT`].
pub fn random_grain<R: Rng>(
    rng: &mut R,
    params: &GrainParams,
    diameter: f64,
) -> Result<PolyhedronBuild, ShapeError> {
    let GrainParams {
        vertices_min: lo,
        vertices_max: hi,
        elongation,
        flatness,
    } = *params;
    if !(elongation.is_finite() && flatness.is_finite() && diameter.is_finite()) {
        return Err(ShapeError::NonFinite);
    }
    if lo < 4 || hi < lo {
        return Err(ShapeError::Degenerate(format!(
            "grain vertex range {lo}..={hi} is invalid (need 4 ≤ min ≤ max)"
        )));
    }
    if elongation < 1.0 || flatness < 1.0 {
        return Err(ShapeError::Degenerate(format!(
            "grain elongation {elongation} and flatness {flatness} must be ≥ 1"
        )));
    }
    if diameter < MIN_EXTENT {
        return Err(ShapeError::TooSmall(format!(
            "equivalent diameter {diameter:e} m is below the minimum {MIN_EXTENT:e} m"
        )));
    }
    let axes = DVec3::new(elongation * flatness, flatness, 1.0);
    let target = rng.gen_range(lo..=hi);
    let mut points: Vec<DVec3> = (0..target).map(|_| sample(rng, axes)).collect();
    for _ in 0..MAX_ATTEMPTS {
        // Sampling in unit-ish coordinates keeps the hull well away from the size limit; the
        // grain is scaled afterwards.
        match build_indexed(&points) {
            Ok((build, kept)) => {
                let n = build.shape.vertices.len();
                if (lo..=hi).contains(&n) {
                    let factor = diameter / equivalent_diameter(build.shape.volume);
                    return Ok(PolyhedronBuild {
                        shape: build.shape.scaled(factor),
                        position: build.position * factor,
                        orientation: build.orientation,
                    });
                }
                points = kept.iter().map(|&i| points[i]).collect();
            }
            // A rare flat or inconsistent sample: start afresh.
            Err(ShapeError::Degenerate(_)) => points.clear(),
            Err(e) => return Err(e),
        }
        while points.len() < target {
            points.push(sample(rng, axes));
        }
    }
    Err(ShapeError::Degenerate(format!(
        "no grain with {lo}..={hi} hull vertices after {MAX_ATTEMPTS} attempts"
    )))
}

/// A point near the ellipsoid with semi-axes `axes`: uniform direction, radius factor uniform in
/// `[JITTER_MIN, 1]`.
fn sample<R: Rng>(rng: &mut R, axes: DVec3) -> DVec3 {
    let z: f64 = rng.gen_range(-1.0..=1.0);
    let phi: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
    let rho = (1.0 - z * z).max(0.0).sqrt();
    let r: f64 = rng.gen_range(JITTER_MIN..=1.0);
    DVec3::new(rho * phi.cos(), rho * phi.sin(), z) * axes * r
}
