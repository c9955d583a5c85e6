//! Linear algebra types (glam, double precision) and small helpers.

pub use glam::{DMat3, DQuat, DVec3};

/// A right-handed orthonormal frame `(n, t, s)` built from a unit normal, deterministically
/// (Duff et al.'s branchless construction, as in glam's `any_orthonormal_pair`).
#[inline]
pub(crate) fn frame_from_normal(n: DVec3) -> (DVec3, DVec3) {
    n.any_orthonormal_pair()
}

/// Skew-symmetric cross-product matrix `[a×]` such that `[a×] b = a × b`.
#[inline]
pub(crate) fn skew(a: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, a.z, -a.y),
        DVec3::new(-a.z, 0.0, a.x),
        DVec3::new(a.y, -a.x, 0.0),
    )
}

/// A symmetric 3×3 matrix stored as its 6 distinct entries: the Delassus blocks `W` take 48
/// bytes instead of 72 in the local problems, which the NLGS sweep streams from memory at
/// large scale.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sym3 {
    /// `xx, yy, zz, xy, xz, yz`.
    e: [f64; 6],
}

impl Sym3 {
    /// The symmetric part `(m + mᵀ)/2` of `m`.
    #[inline]
    pub(crate) fn from_mat(m: DMat3) -> Self {
        Sym3 {
            e: [
                m.x_axis.x,
                m.y_axis.y,
                m.z_axis.z,
                0.5 * (m.y_axis.x + m.x_axis.y),
                0.5 * (m.z_axis.x + m.x_axis.z),
                0.5 * (m.z_axis.y + m.y_axis.z),
            ],
        }
    }

    /// The first diagonal entry (`W_nn` of a Delassus block).
    #[inline(always)]
    pub(crate) fn xx(self) -> f64 {
        self.e[0]
    }

    /// The full matrix.
    #[inline(always)]
    pub fn to_mat(self) -> DMat3 {
        let [xx, yy, zz, xy, xz, yz] = self.e;
        DMat3::from_cols(
            DVec3::new(xx, xy, xz),
            DVec3::new(xy, yy, yz),
            DVec3::new(xz, yz, zz),
        )
    }
}

impl std::ops::Mul<DVec3> for Sym3 {
    type Output = DVec3;
    #[inline(always)]
    fn mul(self, v: DVec3) -> DVec3 {
        self.to_mat() * v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sym3_acts_as_its_matrix() {
        let a = DMat3::from_cols(
            DVec3::new(2.0, 0.3, -0.1),
            DVec3::new(0.3, 1.5, 0.2),
            DVec3::new(-0.1, 0.2, 0.9),
        );
        let s = Sym3::from_mat(a);
        assert_eq!(s.to_mat(), a);
        assert_eq!(s.xx(), 2.0);
        let v = DVec3::new(0.7, -1.1, 0.4);
        assert_eq!(s * v, a * v);
        // A nearly symmetric matrix (rounding in `Eᵀ A E`) keeps its symmetric part.
        let mut b = a;
        b.x_axis.y += 1e-3;
        assert!((Sym3::from_mat(b).to_mat().y_axis.x - 0.3005).abs() < 1e-15);
    }
}
