//! The narrow phase divided between the ranks of a distributed run (see
//! [`crate::solver::exchange`]): every rank holds the same bodies, finds the same candidate
//! pairs and reuses the same manifolds; the pairs left to test are cut into one contiguous
//! share per rank, each rank tests its share, and an all-gather gives every rank every
//! outcome. An outcome is the same whichever rank computes it, so detection is bit-identical
//! to one process.

use super::{FaceHint, ManifoldPoint, PairGeometry};
use crate::math::DVec3;
use crate::solver::Exchange;
use rayon::prelude::*;
use std::time::Instant;

/// Values of one shared outcome.
const VALUES: usize = 25;

fn put(g: &PairGeometry, out: &mut Vec<f64>) {
    out.extend_from_slice(&[
        f64::from(g.body1),
        f64::from(g.body2),
        g.normal.x,
        g.normal.y,
        g.normal.z,
    ]);
    for p in &g.points {
        out.extend_from_slice(&[p.point.x, p.point.y, p.point.z, p.gap]);
    }
    out.extend_from_slice(&[
        f64::from(g.len),
        f64::from(g.hint.to_bits()),
        f64::from(u8::from(g.reused)),
        f64::from(u8::from(g.reusable)),
    ]);
}

fn take(x: &[f64]) -> PairGeometry {
    let mut points = [ManifoldPoint {
        point: DVec3::ZERO,
        gap: 0.0,
    }; 4];
    for (k, p) in points.iter_mut().enumerate() {
        let y = &x[5 + 4 * k..9 + 4 * k];
        *p = ManifoldPoint {
            point: DVec3::new(y[0], y[1], y[2]),
            gap: y[3],
        };
    }
    PairGeometry {
        body1: x[0] as u32,
        body2: x[1] as u32,
        normal: DVec3::new(x[2], x[3], x[4]),
        points,
        len: x[21] as u8,
        hint: FaceHint::from_bits(x[22] as u32),
        reused: x[23] == 1.0,
        reusable: x[24] == 1.0,
    }
}

/// The outcomes of `pairs` into `results`: `reused(k)` for each pair whose manifold is reused
/// (every rank), `compute(k)` for this rank's share of the others, the rest from the ranks
/// that computed them. Returns the seconds spent sharing.
pub(super) fn narrow_on_ranks(
    ex: &dyn Exchange,
    pairs: usize,
    reused: impl Fn(usize) -> Option<PairGeometry> + Sync,
    compute: impl Fn(usize) -> PairGeometry + Sync,
    results: &mut Vec<PairGeometry>,
) -> f64 {
    let blank = PairGeometry::new(0, 0, None, FaceHint::NONE);
    let first: Vec<Option<PairGeometry>> = (0..pairs).into_par_iter().map(&reused).collect();
    let todo: Vec<u32> = (0..pairs as u32)
        .filter(|&k| first[k as usize].is_none())
        .collect();
    results.clear();
    results.par_extend(first.into_par_iter().map(|g| g.unwrap_or(blank)));
    // Contiguous shares of the pairs to test, one per rank.
    let (me, size) = (ex.rank(), ex.size());
    let cut = |r: usize| r * todo.len() / size;
    let mine = &todo[cut(me)..cut(me + 1)];
    let computed: Vec<PairGeometry> = mine.par_iter().map(|&k| compute(k as usize)).collect();
    let t = Instant::now();
    let mut send = Vec::with_capacity(computed.len() * VALUES);
    for g in &computed {
        put(g, &mut send);
    }
    let counts: Vec<usize> = (0..size).map(|r| (cut(r + 1) - cut(r)) * VALUES).collect();
    let mut all = vec![0.0; todo.len() * VALUES];
    ex.all_gather(&send, &counts, &mut all);
    for (&k, x) in todo.iter().zip(all.chunks_exact(VALUES)) {
        results[k as usize] = take(x);
    }
    t.elapsed().as_secs_f64()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An outcome round-trips exactly through its shared values.
    #[test]
    fn outcomes_round_trip() {
        let mut g = PairGeometry::new(7, 4_000_000_000, None, FaceHint::new(true, 17));
        g.normal = DVec3::new(0.6, -0.8, 1e-300);
        g.len = 3;
        g.points[2] = ManifoldPoint {
            point: DVec3::new(1.0 / 3.0, -2.5, 7e8),
            gap: -1.25e-4,
        };
        g.reusable = true;
        let mut x = Vec::new();
        put(&g, &mut x);
        assert_eq!(x.len(), VALUES);
        let h = take(&x);
        let mut y = Vec::new();
        put(&h, &mut y);
        assert_eq!(
            x.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            y.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(
            (h.hint, h.reused, h.reusable, h.len),
            (g.hint, false, true, 3)
        );
    }
}
