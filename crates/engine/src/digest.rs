//! A bit-exact digest of the dynamic state, so two runs can be compared in one line.

use crate::bodies::BodySet;

/// 64-bit FNV-1a over the IEEE-754 bits of every position, orientation, velocity, angular
/// velocity and angular momentum, in body order. Any bit difference changes it (with
/// overwhelming probability); it is not a cryptographic hash.
pub fn state_digest(bodies: &BodySet) -> String {
    digest_of((0..bodies.len()).map(|i| body_state(bodies, i)))
}

/// The digest of bodies' states ([`body_state`]), in the order given.
pub(crate) fn digest_of<S: AsRef<[f64]>>(states: impl Iterator<Item = S>) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for state in states {
        for &x in state.as_ref() {
            for b in x.to_bits().to_le_bytes() {
                h ^= b as u64;
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
    }
    format!("{h:016x}")
}

/// Body `i`'s position, orientation, velocity, angular velocity and angular momentum, in the
/// digest's order.
pub(crate) fn body_state(bodies: &BodySet, i: usize) -> [f64; 16] {
    let (p, q) = (bodies.position[i], bodies.orientation[i]);
    let (v, w, l) = (
        bodies.velocity[i],
        bodies.angular_velocity[i],
        bodies.angular_momentum[i],
    );
    [
        p.x, p.y, p.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z, w.x, w.y, w.z, l.x, l.y, l.z,
    ]
}
