//! Ghosts: the bodies a rank is sent each step so that it reads no body it does not own.
//!
//! When the ranks of a domain-decomposed run hold their own pairs, a dynamic body is kept up
//! to date by its owner (the owner of its subdomain at the last solve) alone. At each
//! detection, once every rank has its own bodies' margins and anchors ([`Detector::begin`]),
//! the owners bound their subdomains (the union of their bodies' bounds) and share the
//! bounds; then each owner sends each of its bodies to every rank whose regions its bound
//! meets — the bodies that rank's pairs may join ([`super::ranks::bodies_needed`]) — with
//! the body's state, margin and anchor. Those copies, the *ghosts*, are what the rank reads
//! of other ranks' bodies this step; a body that its solve gives it besides (a body that
//! changes subdomain, the body of a pair that moves to it) is fetched from its owner
//! ([`Detector::fetch`]). Bodies that are not dynamic are stepped alike on every rank.
//!
//! A body's bound, margin and anchor are the same on every rank that has it, so each rank
//! places, tests and keeps exactly what one process does for its pairs.

use super::ranks::{needs, regions, subdomain_extents};
use super::{Aabb, Detector};
use crate::bodies::{BodyKind, BodySet};
use crate::digest::body_state;
use crate::math::{DQuat, DVec3};
use crate::solver::exchange::{exchange_parts, gather_varying, PairOwners};
use crate::solver::partition::STATIC;
use crate::solver::Exchange;
use std::time::Instant;

/// Values sent of a body: its index, position, orientation, velocity, angular velocity and
/// momentum, margin, then its anchor (position, orientation, re-anchored, rotation, at
/// anchor).
const BODY: usize = 1 + 16 + 1 + 3 + 4 + 1 + 4 + 1;

/// The rank that keeps body `i` up to date under `owners` (rank 0 for a body of no subdomain).
pub(crate) fn owner_of(owners: &PairOwners, i: usize) -> usize {
    match owners.subdomain(i) {
        STATIC => 0,
        s => owners.of_subdomain(s as usize),
    }
}

impl Detector {
    /// Sends this rank's bodies to the ranks that need them and takes in those it needs (a
    /// collective; see the module); leaves in [`Detector::fresh`] the bodies up to date here
    /// and in [`Detector::extents`] the subdomains' bounds. Returns the seconds spent sharing.
    pub(crate) fn share_ghosts(
        &mut self,
        ex: &dyn Exchange,
        bodies: &mut BodySet,
        alert: f64,
        reuse: f64,
    ) -> f64 {
        let owners = self.owners.as_ref().expect("ranks that hold their pairs");
        let (me, n) = (ex.rank(), bodies.len());
        let mine = |i: usize| owner_of(owners, i) == me;
        let bound: Vec<Aabb> = (0..n)
            .map(|i| match mine(i) || bodies.kind[i] != BodyKind::Dynamic {
                true => self.bound(i, alert, reuse),
                false => Aabb::EMPTY,
            })
            .collect();
        // Each owner bounds its subdomains (all their bodies are up to date on it).
        let own = subdomain_extents(owners, &bound, mine);
        let mut send = Vec::new();
        for (s, e) in own.iter().enumerate() {
            if owners.of_subdomain(s) == me {
                send.extend([
                    s as f64, e.min.x, e.min.y, e.min.z, e.max.x, e.max.y, e.max.z,
                ]);
            }
        }
        let clock = Instant::now();
        let (all, _) = gather_varying(ex, &send);
        let mut extents = vec![Aabb::EMPTY; owners.count()];
        for e in all.chunks_exact(7) {
            extents[e[0] as usize] = Aabb {
                min: DVec3::new(e[1], e[2], e[3]),
                max: DVec3::new(e[4], e[5], e[6]),
            };
        }
        // This rank's dynamic bodies, to every other rank that needs them.
        let others: Vec<(usize, Option<Vec<Aabb>>)> = (0..ex.size())
            .filter(|&r| r != me)
            .map(|r| (r, regions(owners, r, &extents)))
            .collect();
        let mut send = vec![Vec::new(); ex.size()];
        for i in (0..n).filter(|&i| bodies.kind[i] == BodyKind::Dynamic && mine(i)) {
            for (r, regions) in &others {
                if regions
                    .as_ref()
                    .is_none_or(|g| needs(owners, g, i, &bound[i]))
                {
                    self.put_body(bodies, i, &mut send[*r]);
                }
            }
        }
        let (all, _) = exchange_parts(ex, &send);
        let seconds = clock.elapsed().as_secs_f64();
        let mut fresh: Vec<bool> = (0..n)
            .map(|i| bodies.kind[i] != BodyKind::Dynamic || mine(i))
            .collect();
        for x in all.chunks_exact(BODY) {
            let i = self.take_body(bodies, x);
            fresh[i] = true;
        }
        self.fresh = fresh;
        self.extents = extents;
        seconds
    }

    /// Takes in, from their owners under [`Detector::owners`] (the last solve's), the dynamic
    /// bodies `needed` marks that are not up to date here (a collective): the bodies a
    /// solve gives this rank besides its ghosts. Returns them, in body order, and the seconds
    /// spent sharing.
    pub(crate) fn fetch(
        &mut self,
        ex: &dyn Exchange,
        bodies: &mut BodySet,
        needed: impl Fn(usize) -> bool,
    ) -> (Vec<usize>, f64) {
        if self.fresh.is_empty() {
            return (Vec::new(), 0.0);
        }
        let owners = self.owners.as_ref().expect("ranks that hold their pairs");
        let me = ex.rank();
        // Each request goes to the body's owner, each reply back to the rank that asked.
        let mut asked = vec![Vec::new(); ex.size()];
        for i in (0..bodies.len())
            .filter(|&i| bodies.kind[i] == BodyKind::Dynamic && !self.fresh[i] && needed(i))
        {
            asked[owner_of(owners, i)].push(i as f64);
        }
        let clock = Instant::now();
        let (all, counts) = exchange_parts(ex, &asked);
        let mut send = vec![Vec::new(); ex.size()];
        let mut at = 0;
        for (r, &count) in counts.iter().enumerate() {
            for &i in &all[at..at + count] {
                debug_assert_eq!(owner_of(owners, i as usize), me);
                self.put_body(bodies, i as usize, &mut send[r]);
            }
            at += count;
        }
        let (all, _) = exchange_parts(ex, &send);
        let seconds = clock.elapsed().as_secs_f64();
        let mut got = Vec::new();
        for x in all.chunks_exact(BODY) {
            let i = self.take_body(bodies, x);
            self.fresh[i] = true;
            got.push(i);
        }
        got.sort_unstable();
        (got, seconds)
    }

    /// Body `i`'s index and values ([`BODY`]) appended to `out`.
    pub(crate) fn put_body(&self, b: &BodySet, i: usize, out: &mut Vec<f64>) {
        let a = &self.anchors;
        let (ap, aq, rot) = (a.position[i], a.orientation[i], a.rotation[i]);
        out.push(i as f64);
        out.extend(body_state(b, i));
        out.push(self.margins[i]);
        out.extend([ap.x, ap.y, ap.z, aq.x, aq.y, aq.z, aq.w]);
        out.push(f64::from(u8::from(a.moved[i])));
        out.extend([rot.x, rot.y, rot.z, rot.w]);
        out.push(f64::from(u8::from(a.at_anchor[i])));
    }

    /// Writes the body [`Detector::put_body`] wrote at the start of `x` (its state in
    /// [`body_state`]'s order); returns its index.
    pub(crate) fn take_body(&mut self, b: &mut BodySet, x: &[f64]) -> usize {
        let i = x[0] as usize;
        let v3 = |k: usize| DVec3::new(x[k], x[k + 1], x[k + 2]);
        let q4 = |k: usize| DQuat::from_xyzw(x[k], x[k + 1], x[k + 2], x[k + 3]);
        b.position[i] = v3(1);
        b.orientation[i] = q4(4);
        b.velocity[i] = v3(8);
        b.angular_velocity[i] = v3(11);
        b.angular_momentum[i] = v3(14);
        self.margins[i] = x[17];
        let a = &mut self.anchors;
        a.position[i] = v3(18);
        a.orientation[i] = q4(21);
        a.moved[i] = x[25] == 1.0;
        a.rotation[i] = q4(26);
        a.at_anchor[i] = x[30] == 1.0;
        i
    }
}
