//! Temporal coherence of detection: anchor poses.
//!
//! Each body has an *anchor pose*, the pose at which its world geometry was last computed. A
//! body is re-anchored (its anchor set to its current pose) when any of its points may have
//! moved more than the reuse distance `δ` since its anchor, `|Δx| + ρ θ > δ` (ρ its
//! circumradius, θ the angle of its rotation since), or when it moves fast: its speculative
//! margin `h (|v| + |ω| ρ)` exceeds `δ`. The narrow phase of a pair is computed at the two
//! anchor poses, so as long as neither body is re-anchored the pair's manifold is the same and
//! is reused from the previous step instead of being computed again. Its points are then carried
//! to the current poses rigidly (see `Anchors::transport`).
//!
//! Why this is exact enough: with `δ` a small fraction of the alert distance, a point of either
//! body is within `δ` of where the manifold saw it. Gaps are recomputed from the current poses:
//! for a face–vertex contact (the common case) the recomputed gap is exact whatever the sliding,
//! and in general it is off by at most the rotation since the anchor times the contact's
//! tangential drift (≈ `2δ²/ρ`: 4e-9 m for `δ` = 10 µm and a circumradius of 5 cm). Contact
//! points are off by at most `δ` tangentially. Pairs are detected with the alert distance grown
//! by `2δ` per body (displacement allowance plus slow-body margin), so no point that comes
//! within the alert distance is missed.
//!
//! Why results stay reproducible: the reused manifold is a function of the two anchors alone,
//! so a run resumed from a checkpoint (which stores the anchors) recomputes, at its first step,
//! exactly the manifolds the uninterrupted run reuses, and the thread count plays no part.

use crate::bodies::BodySet;
use crate::math::{DQuat, DVec3};
use rayon::prelude::*;

/// Anchor poses of every body, and which were re-anchored by the last update.
#[derive(Clone, Debug, Default)]
pub(crate) struct Anchors {
    /// Anchor positions (centre of mass).
    pub position: Vec<DVec3>,
    /// Anchor orientations.
    pub orientation: Vec<DQuat>,
    /// Re-anchored at the last update (its geometry must be recomputed, its pairs too).
    pub(crate) moved: Vec<bool>,
    /// Rotation from anchor to current pose, `q q_A⁻¹` (identity where the pose is the anchor).
    pub(crate) rotation: Vec<DQuat>,
    /// Whether the current pose is bit-identical to the anchor (transport is then skipped).
    pub(crate) at_anchor: Vec<bool>,
}

impl Anchors {
    /// Re-anchors the bodies that moved more than `reuse` (m) since their anchor or whose
    /// `margin` exceeds it; every body when `reuse` is 0, when `invalidate` is set, or when the
    /// anchors do not match the body count. `radii`: each body's circumradius, ∞ for a
    /// half-space.
    pub(crate) fn update(
        &mut self,
        bodies: &BodySet,
        radii: &[f64],
        margins: &[f64],
        reuse: f64,
        invalidate: bool,
    ) {
        let n = bodies.len();
        let all =
            reuse <= 0.0 || invalidate || self.position.len() != n || self.orientation.len() != n;
        if all {
            self.position.clone_from(&bodies.position);
            self.orientation.clone_from(&bodies.orientation);
            self.moved.clear();
            self.moved.resize(n, true);
            self.at_anchor.clear();
            self.at_anchor.resize(n, true);
            self.rotation.clear();
            self.rotation.resize(n, DQuat::IDENTITY);
            return;
        }
        let outcome: Vec<(bool, bool, DQuat)> = (0..n)
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| {
                let (x, q) = (bodies.position[i], bodies.orientation[i]);
                let (xa, qa) = (self.position[i], self.orientation[i]);
                if x == xa && q == qa {
                    return (false, true, DQuat::IDENTITY);
                }
                let rotation = q * qa.conjugate();
                // A half-space reaches everywhere: any motion invalidates its pairs.
                let far = radii[i] == f64::INFINITY || {
                    let angle = 2.0 * rotation.xyz().length().min(1.0).asin();
                    (x - xa).length() + angle * radii[i] > reuse || margins[i] > reuse
                };
                if far {
                    (true, true, DQuat::IDENTITY)
                } else {
                    (false, false, rotation)
                }
            })
            .collect();
        self.moved.clear();
        self.at_anchor.clear();
        self.rotation.clear();
        for (i, (moved, at_anchor, rotation)) in outcome.into_iter().enumerate() {
            if moved {
                self.position[i] = bodies.position[i];
                self.orientation[i] = bodies.orientation[i];
            }
            self.moved.push(moved);
            self.at_anchor.push(at_anchor);
            self.rotation.push(rotation);
        }
    }

    /// Carries the point `s` of body `i`, given at the body's anchor pose, to its current pose.
    #[inline]
    pub(crate) fn transport(&self, bodies: &BodySet, i: usize, s: DVec3) -> DVec3 {
        if self.at_anchor[i] {
            s
        } else {
            self.rotation[i] * (s - self.position[i]) + bodies.position[i]
        }
    }

    /// Carries the direction `d` of body `i` from its anchor pose to its current pose.
    #[inline]
    pub(crate) fn turn(&self, i: usize, d: DVec3) -> DVec3 {
        if self.at_anchor[i] {
            d
        } else {
            self.rotation[i] * d
        }
    }

    /// Whether body `i`'s current pose is its anchor (nothing to carry).
    #[inline]
    pub(crate) fn is_at_anchor(&self, i: usize) -> bool {
        self.at_anchor[i]
    }
}
