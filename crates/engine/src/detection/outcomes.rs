//! A step's narrow-phase outcomes, one per candidate pair in pair order, kept for the next
//! step's reuse, stored compactly: about half of the candidate pairs are apart and a manifold
//! averages two points, so a fixed slot of four points per pair (168 bytes) held more than
//! twice what the outcomes need (about 70 bytes a pair). Each pair has a 24-byte head; the
//! manifolds' normals and points are kept per run of [`CHUNK`] pairs, in pair order, in
//! vectors that live from step to step (no joining copy; an allocation only when a run grows,
//! and then the room its growth doubled is given back).

use super::{FaceHint, ManifoldPoint, PairGeometry};
use crate::math::DVec3;
use crate::slices::trim;
use rayon::prelude::*;
use std::ops::Range;

/// Pairs per run: enough that a run's search of last step's outcomes and its two small
/// vectors cost little against its narrow-phase tests.
const CHUNK: usize = 512;

/// A pair's outcome without its manifold: bodies (body 1 first), point count, face hint,
/// whether it was reused and whether it may be, and where its manifold is in its run.
#[derive(Clone, Copy, Debug)]
pub(super) struct Head {
    pub body1: u32,
    pub body2: u32,
    pub hint: FaceHint,
    /// Index of the normal in its run's normals (when `len > 0`).
    manifold: u32,
    /// Index of the first point in its run's points.
    first: u32,
    pub len: u8,
    pub reused: bool,
    pub reusable: bool,
}

impl Head {
    const BLANK: Head = Head {
        body1: 0,
        body2: 0,
        hint: FaceHint::NONE,
        manifold: 0,
        first: 0,
        len: 0,
        reused: false,
        reusable: false,
    };
}

/// The manifolds of one run of pairs: normals, and points, in pair order.
#[derive(Clone, Debug, Default)]
pub(super) struct Run {
    normals: Vec<DVec3>,
    points: Vec<ManifoldPoint>,
}

impl Run {
    /// The normal of `h`'s manifold (`h` of this run, with points).
    pub fn normal(&self, h: &Head) -> DVec3 {
        self.normals[h.manifold as usize]
    }

    /// The points of `h`'s manifold (`h` of this run).
    pub fn points(&self, h: &Head) -> &[ManifoldPoint] {
        let first = h.first as usize;
        &self.points[first..first + h.len as usize]
    }

    /// Number of points of the run's manifolds.
    pub fn point_count(&self) -> usize {
        self.points.len()
    }
}

/// The outcomes of a step's candidate pairs (see the module's documentation).
#[derive(Debug, Default)]
pub(super) struct Outcomes {
    heads: Vec<Head>,
    /// Run `c` holds the manifolds of pairs `c·CHUNK..(c + 1)·CHUNK`.
    runs: Vec<Run>,
}

impl Outcomes {
    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.heads.len()
    }

    /// Forgets every outcome.
    pub fn clear(&mut self) {
        self.heads.clear();
        self.runs.iter_mut().for_each(|r| {
            r.normals.clear();
            r.points.clear();
        });
    }

    /// The pairs' heads, in pair order.
    pub fn heads(&self) -> &[Head] {
        &self.heads
    }

    /// The runs of [`CHUNK`] pairs: each one's heads and manifolds, in pair order.
    pub fn runs(&self) -> impl IndexedParallelIterator<Item = (&[Head], &Run)> {
        self.heads.par_chunks(CHUNK).zip(self.runs.par_iter())
    }

    /// Pair `k`'s outcome, whole.
    pub fn get(&self, k: usize) -> PairGeometry {
        let h = &self.heads[k];
        let mut g = PairGeometry::new(h.body1, h.body2, None, h.hint);
        (g.len, g.reused, g.reusable) = (h.len, h.reused, h.reusable);
        if h.len > 0 {
            let run = &self.runs[k / CHUNK];
            g.normal = run.normal(h);
            for (slot, p) in g.points.iter_mut().zip(run.points(h)) {
                *slot = *p;
            }
        }
        g
    }

    /// Replaces the outcomes by those of `n` pairs: `fill(range, push)` pushes the outcomes
    /// of the pairs `range` (one run), in order, one per pair. Runs are filled in parallel.
    pub fn assemble(
        &mut self,
        n: usize,
        fill: impl Fn(Range<usize>, &mut dyn FnMut(PairGeometry)) + Sync,
    ) {
        self.heads.clear();
        crate::slices::reserve_total(&mut self.heads, n);
        self.heads.resize(n, Head::BLANK);
        self.runs.resize_with(n.div_ceil(CHUNK), Run::default);
        self.heads
            .par_chunks_mut(CHUNK)
            .zip(self.runs.par_iter_mut())
            .enumerate()
            .for_each(|(c, (heads, run))| {
                run.normals.clear();
                run.points.clear();
                let start = c * CHUNK;
                let mut slots = heads.iter_mut();
                let mut filled = 0;
                fill(start..start + slots.len(), &mut |g: PairGeometry| {
                    let slot = slots.next().expect("one outcome per pair");
                    *slot = Head {
                        body1: g.body1,
                        body2: g.body2,
                        hint: g.hint,
                        manifold: run.normals.len() as u32,
                        first: run.points.len() as u32,
                        len: g.len,
                        reused: g.reused,
                        reusable: g.reusable,
                    };
                    if g.len > 0 {
                        run.normals.push(g.normal);
                        // At most four points: pushed one by one, cheaper than a copy call.
                        for p in g.points() {
                            run.points.push(*p);
                        }
                    }
                    filled += 1;
                });
                assert_eq!(filled, heads.len(), "one outcome per pair");
                // Room for next step's few more, not the double a run that grew was given.
                trim(&mut run.normals);
                trim(&mut run.points);
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(k: usize) -> PairGeometry {
        let mut g = PairGeometry::new(
            k as u32,
            3 * k as u32 + 1,
            None,
            FaceHint::new(k.is_multiple_of(2), k),
        );
        // Every third pair apart; the others with 1 to 4 points.
        g.len = if k.is_multiple_of(3) {
            0
        } else {
            (k % 4 + 1) as u8
        };
        if g.len > 0 {
            g.normal = DVec3::new(k as f64, 0.5, -1.0 / (k as f64 + 1.0));
        }
        for (j, p) in g.points[..g.len as usize].iter_mut().enumerate() {
            *p = ManifoldPoint {
                point: DVec3::new(j as f64, k as f64 * 1e-3, 7.0),
                gap: -(j as f64) * 1e-5,
            };
        }
        g.reused = k.is_multiple_of(5);
        g.reusable = !k.is_multiple_of(7);
        g
    }

    /// Whatever the number of pairs (across the chunks' edges), each outcome reads back whole
    /// and the points lie in pair order.
    #[test]
    fn outcomes_read_back_whole_in_pair_order() {
        for n in [0, 1, CHUNK - 1, CHUNK, 3 * CHUNK + 17] {
            let mut o = Outcomes::default();
            o.assemble(n, |range, push| range.for_each(|k| push(outcome(k))));
            assert_eq!(o.len(), n);
            for k in 0..n {
                let (a, b) = (o.get(k), outcome(k));
                assert_eq!(
                    (a.body1, a.body2, a.hint, a.len, a.reused, a.reusable),
                    (b.body1, b.body2, b.hint, b.len, b.reused, b.reusable)
                );
                assert_eq!(a.points(), b.points());
                if b.len > 0 {
                    assert_eq!(a.normal, b.normal);
                }
            }
            // Each run's points are its pairs', in pair order.
            let runs: Vec<_> = o.runs().collect();
            assert_eq!(runs.len(), n.div_ceil(CHUNK));
            for (c, (heads, run)) in runs.into_iter().enumerate() {
                let mut points = Vec::new();
                for (j, h) in heads.iter().enumerate() {
                    assert_eq!(run.points(h), outcome(c * CHUNK + j).points());
                    points.extend_from_slice(run.points(h));
                }
                assert_eq!(run.point_count(), points.len());
            }
        }
        // Assembled again over fewer pairs, nothing of the longer assembly is left.
        let mut o = Outcomes::default();
        o.assemble(3 * CHUNK, |range, push| {
            range.for_each(|k| push(outcome(k)))
        });
        o.assemble(5, |range, push| range.for_each(|k| push(outcome(k + 1))));
        assert_eq!(o.len(), 5);
        assert_eq!(o.get(4).points(), outcome(5).points());
        assert_eq!(o.runs().count(), 1);
    }
}
