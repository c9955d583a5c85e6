//! A bit-exact digest of the dynamic state, so two runs can be compared in one line.

use crate::bodies::BodySet;

/// 64-bit FNV-1a over the IEEE-754 bits of every position, orientation, velocity, angular
/// velocity and angular momentum, in body order. Any bit difference changes it (with
/// overwhelming probability); it is not a cryptographic hash.
pub fn state_digest(bodies: &BodySet) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |x: f64| {
        for b in x.to_bits().to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for i in 0..bodies.len() {
        let (p, q) = (bodies.position[i], bodies.orientation[i]);
        let (v, w, l) = (
            bodies.velocity[i],
            bodies.angular_velocity[i],
            bodies.angular_momentum[i],
        );
        for x in [
            p.x, p.y, p.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z, w.x, w.y, w.z, l.x, l.y, l.z,
        ] {
            eat(x);
        }
    }
    format!("{h:016x}")
}
