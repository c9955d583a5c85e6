//! Broad phase: candidate pairs of bodies whose bounding boxes (inflated by the alert distance)
//! overlap, on a uniform hashed grid, in expected O(N).
//!
//! Every "small" body (extent ≤ cell size) is entered in the cells its box overlaps, at most 8.
//! Cells are hashed into a table of about twice as many slots as entries and bucketed by a
//! counting sort (O(N), no comparison sort). A pair is reported only from the cell that holds the
//! minimum corner of the intersection of the two boxes, so exactly once. Large bodies (big boxes,
//! blocks) are tested against every small body by box overlap: they are few. Half-spaces are
//! handled by the caller. The output is sorted, so it does not depend on hashing.
//!
//! Every stage runs in parallel (entries, hashing, the pairs of each range of slots, large
//! bodies, the final sort) except the prefix sum and the scatter of the counting sort, which are
//! memory-bound single passes; the result is the same on any number of threads.

use crate::math::DVec3;
use rayon::prelude::*;

/// Slots of the hashed grid per parallel task of the pair search.
const SLOTS_PER_TASK: usize = 4096;
/// Box tests above which [`BroadPhase::update_pairs`] runs a full pass instead (about a
/// millisecond of tests: the order of a full pass over 20,000 boxes).
const INCREMENTAL_TESTS: usize = 4_000_000;
/// An enlarged box's growth on every side, as a fraction of the median box extent: a larger
/// skin lets bodies leave their enlarged box less often but keeps more pairs to filter.
const SKIN_FRACTION: f64 = 0.05;

/// Each candidate's largest box extent, in the candidates' order.
fn extents(aabbs: &[Aabb], candidates: &[u32]) -> Vec<f64> {
    candidates
        .par_iter()
        .with_min_len(1024)
        .map(|&i| (aabbs[i as usize].max - aabbs[i as usize].min).max_element())
        .collect()
}

/// The bodies of `now` not in `was`, and of `was` not in `now` (both sorted).
fn changes(was: &[u32], now: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let (mut joined, mut left) = (Vec::new(), Vec::new());
    let (mut a, mut b) = (was.iter().peekable(), now.iter().peekable());
    loop {
        match (a.peek(), b.peek()) {
            (Some(&&x), Some(&&y)) if x == y => {
                a.next();
                b.next();
            }
            (Some(&&x), Some(&&y)) if x < y => {
                left.push(x);
                a.next();
            }
            (_, Some(&&y)) => {
                joined.push(y);
                b.next();
            }
            (Some(&&x), None) => {
                left.push(x);
                a.next();
            }
            (None, None) => return (joined, left),
        }
    }
}

/// The median of `values` (the upper one of an even count; they are reordered). Not empty.
pub(super) fn median(values: &mut [f64]) -> f64 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
}

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: DVec3,
    pub max: DVec3,
}

impl Aabb {
    /// The box that holds nothing (the identity of [`Aabb::union`]).
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    /// The smallest box that holds both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// The boxes' common part (empty when they do not overlap).
    pub fn intersection(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.max(o.min),
            max: self.max.min(o.max),
        }
    }

    /// True when the box holds no point.
    pub fn is_empty(&self) -> bool {
        !self.min.cmple(self.max).all()
    }

    /// True when the boxes overlap (touching counts).
    #[inline]
    pub fn overlaps(&self, o: &Aabb) -> bool {
        self.min.cmple(o.max).all() && o.min.cmple(self.max).all()
    }
}

/// Reusable broad-phase buffers.
#[derive(Default, Debug)]
pub(crate) struct BroadPhase {
    /// Enlarged boxes: each body's box when it was last entered, grown by `skin` on every side
    /// (see [`BroadPhase::update_pairs`]).
    fat: Vec<Aabb>,
    /// Every pair (not skipped) whose enlarged boxes overlap, sorted.
    fat_pairs: Vec<(u32, u32)>,
    /// The candidates `fat_pairs` was found among.
    fat_candidates: Vec<u32>,
    /// Growth of an enlarged box (m), set at each full pass.
    skin: f64,
    /// Scratch: which bodies left their enlarged box at this call.
    escaped: Vec<bool>,
    /// Full passes so far.
    full_passes: u64,
    entries: Vec<(u32, [i32; 3])>,
    slot_of: Vec<u32>,
    start: Vec<u32>,
    sorted: Vec<(u32, [i32; 3])>,
}

#[inline]
fn cell_of(p: DVec3, inv_cell: f64) -> [i32; 3] {
    let c = (p * inv_cell).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

#[inline]
fn hash(c: [i32; 3], mask: u32) -> u32 {
    let h = (c[0] as u32).wrapping_mul(0x8da6_b343)
        ^ (c[1] as u32).wrapping_mul(0xd816_3841)
        ^ (c[2] as u32).wrapping_mul(0xcb1a_b31f);
    h & mask
}

impl Aabb {
    /// True when `inner` lies within this box (NaN corners never do).
    #[inline]
    fn contains(&self, inner: &Aabb) -> bool {
        self.min.cmple(inner.min).all() && inner.max.cmple(self.max).all()
    }

    /// The box grown by `d` on every side.
    #[inline]
    fn grown(&self, d: f64) -> Aabb {
        Aabb {
            min: self.min - DVec3::splat(d),
            max: self.max + DVec3::splat(d),
        }
    }
}

impl BroadPhase {
    /// [`BroadPhase::find_pairs`] for a scene that moves a little between calls (a Verlet
    /// list): each body keeps an enlarged box, its box grown by a skin (a twentieth of the
    /// median box extent), and the pairs of overlapping enlarged boxes are kept between calls.
    /// A body whose box left its enlarged box is entered again (a new enlarged box, its pairs
    /// found by testing it against every candidate); the answer is the kept pairs whose boxes
    /// overlap. Every box lies within its enlarged box, so no overlapping pair is missed: the
    /// result is the same set as a full pass (every overlapping pair not skipped, sorted), and
    /// callers cannot tell the two apart. Bodies moving slower than the skin per step leave
    /// their enlarged box once in many steps, so most calls test a few boxes instead of
    /// hashing them all. A body that joined the candidates (`candidates` are sorted) is
    /// entered like an escaped one, and the pairs of a body that left them are dropped. Every
    /// enlarged box is computed afresh by a full pass on the first call, when `same_skip` is
    /// false (the skip rule changed since the last call), or when the escaped and joining
    /// boxes times the candidates exceed `INCREMENTAL_TESTS` box tests.
    pub(crate) fn update_pairs(
        &mut self,
        aabbs: &[Aabb],
        candidates: &[u32],
        skip: impl Fn(u32, u32) -> bool + Sync,
        same_skip: bool,
        pairs: &mut Vec<(u32, u32)>,
    ) {
        let comparable = same_skip && self.fat.len() == aabbs.len();
        let (joined, left) = match comparable && self.fat_candidates != candidates {
            true => changes(&self.fat_candidates, candidates),
            false => (Vec::new(), Vec::new()),
        };
        let escaped: Vec<u32> = if comparable {
            let fat = &self.fat;
            // A joining body's enlarged box is stale: it is entered again.
            let mut e: Vec<u32> = candidates
                .par_iter()
                .with_min_len(4096)
                .filter(|&&i| !fat[i as usize].contains(&aabbs[i as usize]))
                .copied()
                .collect();
            if !joined.is_empty() {
                e.extend_from_slice(&joined);
                e.sort_unstable();
                e.dedup();
            }
            e
        } else {
            Vec::new()
        };
        if !comparable || escaped.len().saturating_mul(candidates.len()) > INCREMENTAL_TESTS {
            let mut e = extents(aabbs, candidates);
            let m = if e.is_empty() { 0.0 } else { median(&mut e) };
            self.skin = SKIN_FRACTION * if m.is_finite() { m } else { 0.0 };
            self.full_passes += 1;
            let skin = self.skin;
            let mut fat = std::mem::take(&mut self.fat);
            fat.clear();
            fat.par_extend(aabbs.par_iter().with_min_len(4096).map(|b| b.grown(skin)));
            let mut fat_pairs = std::mem::take(&mut self.fat_pairs);
            self.find_pairs(&fat, candidates, &skip, &mut fat_pairs);
            self.fat = fat;
            self.fat_pairs = fat_pairs;
            self.fat_candidates.clear();
            self.fat_candidates.extend_from_slice(candidates);
        } else if !escaped.is_empty() || !left.is_empty() {
            // Marked: the bodies whose kept pairs are dropped (escaped, joined or left).
            self.escaped.clear();
            self.escaped.resize(aabbs.len(), false);
            for &c in &escaped {
                self.fat[c as usize] = aabbs[c as usize].grown(self.skin);
                self.escaped[c as usize] = true;
            }
            for &c in &left {
                self.escaped[c as usize] = true;
            }
            let (fat, is_escaped) = (&self.fat, &self.escaped);
            let mut kept: Vec<(u32, u32)> = Vec::with_capacity(self.fat_pairs.len());
            kept.par_extend(
                self.fat_pairs
                    .par_iter()
                    .with_min_len(4096)
                    .filter(|&&(i, j)| !is_escaped[i as usize] && !is_escaped[j as usize])
                    .copied(),
            );
            // A pair of two escaped boxes is reported by its lower index only.
            let mut fresh: Vec<(u32, u32)> = escaped
                .par_iter()
                .flat_map_iter(|&c| {
                    let bc = fat[c as usize];
                    candidates
                        .iter()
                        .filter(move |&&o| {
                            o != c
                                && !(is_escaped[o as usize] && o < c)
                                && bc.overlaps(&fat[o as usize])
                        })
                        .map(move |&o| (c.min(o), c.max(o)))
                })
                .filter(|&(p, q)| !skip(p, q))
                .collect();
            fresh.par_sort_unstable();
            super::merge_sorted(&kept, &fresh, &mut self.fat_pairs);
            self.fat_candidates.clear();
            self.fat_candidates.extend_from_slice(candidates);
        }
        pairs.clear();
        pairs.par_extend(
            self.fat_pairs
                .par_iter()
                .with_min_len(4096)
                .filter(|&&(i, j)| aabbs[i as usize].overlaps(&aabbs[j as usize]))
                .copied(),
        );
    }

    /// Appends to `pairs` every `(i, j)`, `i < j`, whose boxes overlap, among the bodies
    /// `candidates`, skipping pairs for which `skip(i, j)` is true (e.g. two fixed bodies).
    /// `pairs` is sorted on return.
    pub(crate) fn find_pairs(
        &mut self,
        aabbs: &[Aabb],
        candidates: &[u32],
        skip: impl Fn(u32, u32) -> bool + Sync,
        pairs: &mut Vec<(u32, u32)>,
    ) {
        pairs.clear();
        if candidates.is_empty() {
            return;
        }
        // Cell size: the largest extent among the bodies that move (the grains); anything bigger
        // than 2 cells is "large".
        let mut extents = extents(aabbs, candidates);
        let cell = {
            // Median × 2 bounds the cell by typical grains even when a few bodies are huge.
            let median = median(&mut extents.clone());
            let max_small = extents
                .iter()
                .copied()
                .filter(|&x| x <= 4.0 * median)
                .fold(0.0f64, f64::max);
            max_small.max(f64::MIN_POSITIVE)
        };
        let inv_cell = 1.0 / cell;
        let mut small = Vec::with_capacity(candidates.len());
        let mut large = Vec::new();
        for (k, &i) in candidates.iter().enumerate() {
            if extents[k] <= 2.0 * cell {
                small.push(i);
            } else {
                large.push(i);
            }
        }
        extents.clear();

        // 1. Entries (body, cell) for the small bodies.
        self.entries.clear();
        self.entries
            .par_extend(small.par_iter().with_min_len(1024).flat_map_iter(|&i| {
                let b = &aabbs[i as usize];
                let lo = cell_of(b.min, inv_cell);
                let hi = cell_of(b.max, inv_cell);
                (lo[0]..=hi[0]).flat_map(move |x| {
                    (lo[1]..=hi[1]).flat_map(move |y| (lo[2]..=hi[2]).map(move |z| (i, [x, y, z])))
                })
            }));
        // 2. Counting sort of the entries by hashed slot.
        let slots = (2 * self.entries.len()).next_power_of_two().max(2);
        let mask = (slots - 1) as u32;
        self.start.clear();
        self.start.resize(slots + 1, 0);
        self.slot_of.clear();
        self.slot_of.par_extend(
            self.entries
                .par_iter()
                .with_min_len(4096)
                .map(|e| hash(e.1, mask)),
        );
        for &s in &self.slot_of {
            self.start[s as usize + 1] += 1;
        }
        for s in 0..slots {
            self.start[s + 1] += self.start[s];
        }
        self.sorted.clear();
        self.sorted.resize(self.entries.len(), (0, [0; 3]));
        {
            let mut fill = self.start.clone();
            for (e, &s) in self.entries.iter().zip(&self.slot_of) {
                self.sorted[fill[s as usize] as usize] = *e;
                fill[s as usize] += 1;
            }
        }
        // 3. Pairs within each slot, reported from the owner cell only.
        let (sorted, start) = (&self.sorted, &self.start);
        let skip = &skip;
        pairs.par_extend(
            (0..slots.div_ceil(SLOTS_PER_TASK))
                .into_par_iter()
                .flat_map_iter(|task| {
                    let mut found = Vec::new();
                    let end = ((task + 1) * SLOTS_PER_TASK).min(slots);
                    for s in task * SLOTS_PER_TASK..end {
                        let bucket = &sorted[start[s] as usize..start[s + 1] as usize];
                        for (a, &(i, ci)) in bucket.iter().enumerate() {
                            for &(j, cj) in &bucket[a + 1..] {
                                if i == j || ci != cj {
                                    continue;
                                }
                                let (bi, bj) = (&aabbs[i as usize], &aabbs[j as usize]);
                                if !bi.overlaps(bj) {
                                    continue;
                                }
                                if cell_of(bi.min.max(bj.min), inv_cell) != ci {
                                    continue;
                                }
                                let (p, q) = (i.min(j), i.max(j));
                                if !skip(p, q) {
                                    found.push((p, q));
                                }
                            }
                        }
                    }
                    found
                }),
        );
        // 4. Large bodies against everything else.
        for (k, &l) in large.iter().enumerate() {
            let bl = &aabbs[l as usize];
            pairs.par_extend(
                small
                    .par_iter()
                    .chain(large[k + 1..].par_iter())
                    .with_min_len(1024)
                    .filter(|&&i| bl.overlaps(&aabbs[i as usize]))
                    .map(|&i| (i.min(l), i.max(l)))
                    .filter(|&(p, q)| !skip(p, q)),
            );
        }
        pairs.par_sort_unstable();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// `n` random cubes (half-sides up to `half`) in a cube of side `side`, then one large box
    /// reaching into negative coordinates.
    fn random_boxes(
        rng: &mut rand_chacha::ChaCha8Rng,
        n: usize,
        side: f64,
        half: f64,
    ) -> Vec<Aabb> {
        let mut boxes: Vec<Aabb> = (0..n)
            .map(|_| {
                let c = DVec3::new(rng.gen(), rng.gen(), rng.gen()) * side;
                let h = DVec3::splat(rng.gen_range(0.01..half));
                Aabb {
                    min: c - h,
                    max: c + h,
                }
            })
            .collect();
        boxes.push(Aabb {
            min: DVec3::splat(-1.0),
            max: DVec3::new(1.0, 1.0, 0.02),
        });
        boxes
    }

    /// The grid finds exactly the overlapping pairs that brute force finds.
    #[test]
    fn grid_equals_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // 5000 boxes: many tasks of the parallel pair search.
        for n in [1usize, 2, 10, 300, 5000] {
            let boxes = random_boxes(&mut rng, n, 0.5, 0.05);
            let all: Vec<u32> = (0..boxes.len() as u32).collect();
            let mut bp = BroadPhase::default();
            let mut pairs = Vec::new();
            bp.find_pairs(&boxes, &all, |_, _| false, &mut pairs);
            // The same on 1 and 4 threads.
            for threads in [1, 4] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut again = Vec::new();
                pool.install(|| {
                    BroadPhase::default().find_pairs(&boxes, &all, |_, _| false, &mut again)
                });
                assert_eq!(again, pairs, "n = {n}, {threads} threads");
            }
            let mut brute = Vec::new();
            for i in 0..boxes.len() {
                for j in i + 1..boxes.len() {
                    if boxes[i].overlaps(&boxes[j]) {
                        brute.push((i as u32, j as u32));
                    }
                }
            }
            assert_eq!(pairs, brute, "n = {n}");
        }
    }

    /// Updating from the last call's pairs finds the same pairs as brute force, step after step
    /// of random moves of a few boxes (the incremental path), of many (the full pass), of many
    /// small ones within the enlarged boxes, and when the skip rule changes.
    #[test]
    fn updated_pairs_equal_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let n = 2000;
        let mut boxes = random_boxes(&mut rng, n, 0.4, 0.04);
        let all: Vec<u32> = (0..boxes.len() as u32).collect();
        let mut bp = BroadPhase::default();
        let mut pairs = Vec::new();
        let mut incremental = 0;
        for step in 0..40 {
            // Skip pairs of two multiples of `m`; the rule changes at step 20.
            let m = if step < 20 { 7 } else { 5 };
            let skip = move |i: u32, j: u32| i.is_multiple_of(m) && j.is_multiple_of(m);
            let moved = [0, 1, 3, 40, 2001, 1500][step % 6];
            // Every sixth step, many small moves that mostly stay within the enlarged boxes.
            let reach = if step % 6 == 5 { 1e-3 } else { 0.02 };
            for _ in 0..moved {
                let k = rng.gen_range(0..n);
                let shift = (DVec3::new(rng.gen(), rng.gen(), rng.gen()) - 0.5) * reach;
                boxes[k] = Aabb {
                    min: boxes[k].min + shift,
                    max: boxes[k].max + shift,
                };
            }
            let before = bp.fat_pairs.len();
            bp.update_pairs(&boxes, &all, skip, step != 20, &mut pairs);
            incremental += usize::from(moved != 2001 && step != 20 && before > 0);
            let mut brute = Vec::new();
            for i in 0..boxes.len() {
                for j in i + 1..boxes.len() {
                    if boxes[i].overlaps(&boxes[j]) && !skip(i as u32, j as u32) {
                        brute.push((i as u32, j as u32));
                    }
                }
            }
            assert_eq!(pairs, brute, "step {step}, {moved} boxes moved");
        }
        assert!(incremental > 20);
    }

    /// Updating when bodies join and leave the candidates (a rank's detection as its region
    /// moves) finds the same pairs as brute force over the candidates, incrementally.
    #[test]
    fn updated_pairs_follow_the_candidates() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let n = 1500;
        let mut boxes = random_boxes(&mut rng, n, 0.4, 0.04);
        let mut bp = BroadPhase::default();
        let mut pairs = Vec::new();
        let mut incremental = 0;
        let mut left_out: Vec<bool> = (0..=n).map(|_| rng.gen_bool(0.3)).collect();
        for step in 0..30 {
            // A few bodies join or leave (every body at step 10), a few move.
            let flips = if step == 10 {
                0
            } else {
                [1, 5, 30, 0][step % 4]
            };
            for _ in 0..flips {
                let k = rng.gen_range(0..=n);
                left_out[k] = !left_out[k];
            }
            if step == 10 {
                left_out.iter_mut().for_each(|l| *l = false);
            }
            for _ in 0..3 {
                let k = rng.gen_range(0..n);
                let shift = (DVec3::new(rng.gen(), rng.gen(), rng.gen()) - 0.5) * 0.02;
                boxes[k] = Aabb {
                    min: boxes[k].min + shift,
                    max: boxes[k].max + shift,
                };
            }
            let candidates: Vec<u32> = (0..=n as u32).filter(|&i| !left_out[i as usize]).collect();
            let (full, changed) = (bp.full_passes, bp.fat_candidates != candidates);
            bp.update_pairs(&boxes, &candidates, |_, _| false, true, &mut pairs);
            incremental += usize::from(step > 0 && changed && bp.full_passes == full);
            let mut brute = Vec::new();
            for (a, &i) in candidates.iter().enumerate() {
                for &j in &candidates[a + 1..] {
                    if boxes[i as usize].overlaps(&boxes[j as usize]) {
                        brute.push((i, j));
                    }
                }
            }
            assert_eq!(pairs, brute, "step {step}, {flips} bodies joined or left");
            assert_eq!(bp.fat_candidates, candidates);
        }
        // Every call after the first with new candidates, but for the one where every body
        // joins and those whose joining bodies make too many box tests.
        assert!(
            incremental > 15,
            "{incremental} incremental calls with new candidates"
        );
    }

    /// The bodies that joined and left, between two sorted lists.
    #[test]
    fn changes_between_sorted_lists() {
        assert_eq!(
            changes(&[1, 3, 5, 9], &[0, 3, 4, 5, 10]),
            (vec![0, 4, 10], vec![1, 9])
        );
        assert_eq!(changes(&[], &[2, 3]), (vec![2, 3], vec![]));
        assert_eq!(changes(&[2, 3], &[]), (vec![], vec![2, 3]));
        assert_eq!(changes(&[7], &[7]), (vec![], vec![]));
    }
}
