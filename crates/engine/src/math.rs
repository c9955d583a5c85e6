//! Linear algebra types (glam, double precision) and small helpers.

pub use glam::{DMat3, DQuat, DVec3};

/// A right-handed orthonormal frame `(n, t, s)` built from a unit normal, deterministically
/// (Duff et al.'s branchless construction, as in glam's `any_orthonormal_pair`).
#[inline]
pub fn frame_from_normal(n: DVec3) -> (DVec3, DVec3) {
    n.any_orthonormal_pair()
}

/// Skew-symmetric cross-product matrix `[a×]` such that `[a×] b = a × b`.
#[inline]
pub fn skew(a: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, a.z, -a.y),
        DVec3::new(-a.z, 0.0, a.x),
        DVec3::new(a.y, -a.x, 0.0),
    )
}
