//! Exact mass properties of closed polyhedra.
//!
//! # Mathematics
//!
//! Let `Ω` be the solid bounded by a closed, consistently oriented triangle mesh (outward
//! winding) and `r` any reference point. Each triangle `(a, b, c)` (coordinates relative to `r`)
//! spans with `r` the signed tetrahedron `T = (0, a, b, c)`. The signed tetrahedra cover `Ω` with
//! multiplicity +1 inside and cancel outside (a discrete divergence theorem), so any integral over
//! `Ω` is the sum of the integrals over the signed `T`. For one tetrahedron:
//!
//! * volume: `V_T = a · (b × c) / 6`;
//! * first moment: `∫_T x dV = V_T (a + b + c) / 4` (the centroid is the vertex mean);
//! * second moment (covariance): `C_T = ∫_T x xᵀ dV = V_T/20 · (a aᵀ + b bᵀ + c cᵀ + s sᵀ)` with
//!   `s = a + b + c`. This is the classic closed form for a tetrahedron with vertices `vₖ`:
//!   `∫ x xᵀ = V/20 · (Σₖ vₖ vₖᵀ + (Σₖ vₖ)(Σₖ vₖ)ᵀ)` (Tonon 2004; Eberly, "Polyhedral mass
//!   properties"), here with `v₀ = 0`.
//!
//! Summing gives `V`, the first moment `m` and the covariance `C` about `r`. The centre of mass is
//! `c = r + m / V`; the covariance about it follows from the parallel-axis theorem,
//! `C_c = C − V d dᵀ` with `d = m / V`, and the inertia tensor (per unit density) is
//! `J = tr(C_c) I − C_c`, i.e. `J_ij = ∫ (|x|² δ_ij − x_i x_j) dV`.
//!
//! All of this is exact up to floating-point rounding; choosing `r` at the vertex mean keeps the
//! coordinates small and the cancellations in `C − V d dᵀ` mild.

use crate::math::{DMat3, DQuat, DVec3};

/// Volume, centre of mass and inertia tensor (per unit density) of a closed solid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProperties {
    /// Volume (signed: an inward-wound mesh gives a negative volume and a negated tensor).
    pub volume: f64,
    /// Centre of mass, in the frame of the input vertices.
    pub center: DVec3,
    /// Inertia tensor per unit density about the centre of mass, axes of the input frame:
    /// `J = ∫ (|x|² I − x xᵀ) dV` with `x` measured from [`MassProperties::center`].
    pub inertia: DMat3,
}

impl MassProperties {
    /// Exact mass properties of the solid bounded by a closed triangle mesh with outward
    /// (counter-clockwise seen from outside) winding. See the module documentation for the
    /// formulas.
    ///
    /// Triangles with an out-of-range index are ignored (they cannot be part of a valid mesh);
    /// an empty or zero-volume mesh gives zero volume, centre at the reference point and a zero
    /// tensor, never NaN.
    pub fn of_closed_mesh(vertices: &[DVec3], triangles: &[[u32; 3]]) -> MassProperties {
        if vertices.is_empty() {
            return MassProperties {
                volume: 0.0,
                center: DVec3::ZERO,
                inertia: DMat3::ZERO,
            };
        }
        let r = vertices.iter().copied().sum::<DVec3>() / vertices.len() as f64;
        let n = vertices.len();

        // Six times the volume and 24 × first moment / 120 × covariance are accumulated to defer
        // the divisions to the end.
        let mut vol6 = 0.0;
        let mut mom24 = DVec3::ZERO;
        let mut cov = [[0.0f64; 3]; 3];
        for t in triangles {
            if t.iter().any(|&i| i as usize >= n) {
                continue;
            }
            let a = vertices[t[0] as usize] - r;
            let b = vertices[t[1] as usize] - r;
            let c = vertices[t[2] as usize] - r;
            let d = a.dot(b.cross(c)); // 6 V_T
            vol6 += d;
            let s = a + b + c;
            mom24 += d * s;
            let (aa, bb, cc, ss) = (a.to_array(), b.to_array(), c.to_array(), s.to_array());
            for i in 0..3 {
                for j in i..3 {
                    cov[i][j] +=
                        d * (aa[i] * aa[j] + bb[i] * bb[j] + cc[i] * cc[j] + ss[i] * ss[j]);
                }
            }
        }
        let volume = vol6 / 6.0;
        if volume == 0.0 || !volume.is_finite() {
            return MassProperties {
                volume: if volume.is_finite() { volume } else { 0.0 },
                center: r,
                inertia: DMat3::ZERO,
            };
        }
        // ∫x dV = Σ V_T s / 4 = Σ d s / 24.
        let dcm = mom24 / (24.0 * volume);
        // ∫x xᵀ dV = Σ V_T/20 (…) = Σ d/120 (…); then shift to the centre of mass.
        let mut c = [[0.0f64; 3]; 3];
        let dd = dcm.to_array();
        for i in 0..3 {
            for j in i..3 {
                let v = cov[i][j] / 120.0 - volume * dd[i] * dd[j];
                c[i][j] = v;
                c[j][i] = v;
            }
        }
        let tr = c[0][0] + c[1][1] + c[2][2];
        let inertia = DMat3::from_cols(
            DVec3::new(tr - c[0][0], -c[1][0], -c[2][0]),
            DVec3::new(-c[0][1], tr - c[1][1], -c[2][1]),
            DVec3::new(-c[0][2], -c[1][2], tr - c[2][2]),
        );
        MassProperties {
            volume,
            center: r + dcm,
            inertia,
        }
    }

    /// Principal moments (ascending; rounding-level ties keep the input axis order) and principal
    /// axes of [`MassProperties::inertia`].
    ///
    /// Returns `(moments, q)` where `q` rotates the body (principal) frame into the input frame:
    /// `inertia = R diag(moments) Rᵀ` with `R = Mat3::from_quat(q)`, i.e. the columns of `R` are
    /// the principal axes. See [`symmetric_eigen`] for the method and the sign conventions that
    /// make the result deterministic and right-handed.
    pub fn principal(&self) -> (DVec3, DQuat) {
        let (values, axes) = symmetric_eigen(&self.inertia);
        (values, DQuat::from_mat3(&axes).normalize())
    }
}

/// Eigen-decomposition `A = R diag(λ) Rᵀ` of a symmetric 3×3 matrix by cyclic Jacobi rotations.
///
/// Each rotation in the plane `(p, q)` zeroes `A_pq`; with `θ = (A_qq − A_pp) / (2 A_pq)` the
/// rotation tangent is the smaller root `t = sgn(θ) / (|θ| + √(θ² + 1))` of `t² + 2θt − 1 = 0`,
/// which keeps the rotation angle ≤ π/4 and the update numerically stable (Golub & Van Loan,
/// §8.5; Numerical Recipes `jacobi`). Sweeps over the three planes repeat until the off-diagonal
/// part is below rounding (`|A_pq| ≤ 1e-18·‖A‖`, or exactly zero); convergence is quadratic, so
/// this takes a handful of sweeps. Only the upper triangle of `a` is read; couplings below
/// `1e-15·‖A‖` are treated as zero (rounding noise).
///
/// Output conventions, for determinism: eigenvalues sorted ascending, where values within
/// `1e-12·‖A‖` count as ties and keep the Jacobi order (so they may be out of order by that
/// much); the first two eigenvectors have their largest-magnitude component positive
/// (first such component on ties); the third is their cross product, so `R` is a proper rotation
/// (`det R = +1`).
#[doc(hidden)] // exposed for the crate's tests; not part of the supported API
pub fn symmetric_eigen(a: &DMat3) -> (DVec3, DMat3) {
    let cols = a.to_cols_array_2d(); // cols[j][i] = A_ij
    let mut m = [[0.0f64; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            // Symmetrise from the upper triangle.
            *v = if i <= j { cols[j][i] } else { cols[i][j] };
        }
    }
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]; // v[i][k]: eigenvector k
    let norm = m.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
    if !norm.is_finite() || norm == 0.0 {
        let d = DVec3::new(m[0][0], m[1][1], m[2][2]);
        return (d, DMat3::IDENTITY);
    }
    // Couplings at rounding level carry no information, but with (nearly) equal diagonal terms
    // they would select an arbitrary 45° frame (e.g. for a cube); dropping them keeps the input
    // axes in that case and moves the result by no more than the input's own rounding.
    for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
        if m[p][q].abs() <= 1e-15 * norm {
            m[p][q] = 0.0;
            m[q][p] = 0.0;
        }
    }
    for _sweep in 0..64 {
        let off = (m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2]).sqrt();
        if off <= 1e-18 * norm {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = m[p][q];
            if apq == 0.0 {
                continue;
            }
            let theta = (m[q][q] - m[p][p]) / (2.0 * apq);
            let t = if theta.is_finite() {
                theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
            } else {
                // |θ| overflowed: A_pq is negligible against the diagonal gap.
                0.5 / theta
            };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A ← Jᵀ A J with J the rotation in the (p, q) plane.
            for row in m.iter_mut() {
                let (xp, xq) = (row[p], row[q]);
                row[p] = c * xp - s * xq;
                row[q] = s * xp + c * xq;
            }
            let (row_p, row_q) = (m[p], m[q]);
            for k in 0..3 {
                m[p][k] = c * row_p[k] - s * row_q[k];
                m[q][k] = s * row_p[k] + c * row_q[k];
            }
            m[p][q] = 0.0;
            m[q][p] = 0.0;
            for row in v.iter_mut() {
                let (xp, xq) = (row[p], row[q]);
                row[p] = c * xp - s * xq;
                row[q] = s * xp + c * xq;
            }
        }
    }
    // Insertion sort that treats rounding-level differences as ties and keeps the Jacobi order
    // for them: a cube then keeps its input axes instead of a permutation picked by rounding.
    let tie = 1e-12 * norm;
    let mut order = [0usize, 1, 2];
    for i in 1..3 {
        let mut j = i;
        while j > 0 && m[order[j - 1]][order[j - 1]] > m[order[j]][order[j]] + tie {
            order.swap(j - 1, j);
            j -= 1;
        }
    }
    let values = DVec3::new(
        m[order[0]][order[0]],
        m[order[1]][order[1]],
        m[order[2]][order[2]],
    );
    let column = |k: usize| DVec3::new(v[0][k], v[1][k], v[2][k]);
    let canonical = |e: DVec3| {
        let e = e.normalize();
        let abs = e.abs();
        let big = if abs.x >= abs.y && abs.x >= abs.z {
            e.x
        } else if abs.y >= abs.z {
            e.y
        } else {
            e.z
        };
        if big < 0.0 {
            -e
        } else {
            e
        }
    };
    let e0 = canonical(column(order[0]));
    // Re-orthogonalise against rounding before completing the right-handed triad.
    let e1 = canonical(column(order[1]) - e0 * e0.dot(column(order[1])));
    let e2 = e0.cross(e1).normalize();
    (values, DMat3::from_cols(e0, e1, e2))
}
