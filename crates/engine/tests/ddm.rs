//! Domain decomposition (Algorithm 1): equivalence with monolithic NLGS, independence from the
//! number of threads, agreement at convergence.

use ballast_engine::digest::state_digest;
use ballast_engine::laws::{ContactStatus, Elastic};
use ballast_engine::math::DVec3;
use ballast_engine::scenario::presets::pile;
use ballast_engine::solver::correction::{self, CorrectionSettings};
use ballast_engine::solver::ddm::{self, DdmProblem};
use ballast_engine::solver::delassus::LocalProblem;
use ballast_engine::solver::{Balance, DdmSettings, SolverSettings};
use ballast_engine::world::World;

/// A pile of 150 grains after 500 steps of pouring (many contacts, grains still moving).
fn poured(steps: u64) -> World {
    let mut w = pile(150, [0.025, 0.05], 11, 0).build().unwrap();
    for _ in 0..steps {
        w.step();
    }
    w
}

fn settings(dims: [usize; 3], parallel_interface: bool, balance: Balance) -> DdmSettings {
    DdmSettings {
        subdomains: dims,
        inner_sweeps: 1,
        interface_sweeps: 1,
        balance,
        parallel_interface,
        // Dispatch every phase, however small, so the parallel paths are what is tested.
        min_parallel_contacts: 0,
    }
}

/// With n = m = 1, DDM iterates are bit-identical to monolithic NLGS run in the order
/// [subdomain 1 contacts, …, subdomain k contacts, Γ contacts].
#[test]
fn ddm_with_single_sweeps_equals_monolithic_in_partition_order() {
    let mut w = poured(1500);
    w.settings.solver = SolverSettings {
        tolerance: 1e-300,
        max_iterations: 25,
        ..Default::default()
    };
    w.prepare();
    let nlgs = w.nlgs();
    let (locals, bodies) = (w.local_problems().to_vec(), w.solver_bodies().to_vec());
    assert!(
        locals.len() > 200,
        "want a real problem, got {} contacts",
        locals.len()
    );
    for (dims, par, bal) in [
        ([2, 2, 1], true, Balance::Contacts),
        ([3, 1, 2], false, Balance::Volume),
        ([4, 4, 1], true, Balance::Volume),
    ] {
        let d = settings(dims, par, bal);
        let partition = w.partition(&d);
        let problem = DdmProblem::build(&partition, &locals, par);
        assert!(
            problem.interface_len() > 0,
            "{dims:?}: no interface contact"
        );
        assert!(problem.sub.iter().filter(|s| !s.is_empty()).count() > 1);
        // DDM.
        let (mut l1, mut v1) = (locals.clone(), bodies.clone());
        let mut s1 = vec![ContactStatus::NoContact; l1.len()];
        let (r1, _) = ddm::solve(&nlgs, &d, &partition, &mut l1, &mut v1, &mut s1);
        // Monolithic NLGS in the equivalent order.
        let order = problem.equivalent_order();
        assert_eq!(order.len(), locals.len());
        let mut l2: Vec<_> = order.iter().map(|&i| locals[i as usize]).collect();
        let mut v2 = bodies.clone();
        let mut s2 = vec![ContactStatus::NoContact; l2.len()];
        let r2 = nlgs.solve(&mut l2, &mut v2, &mut s2);
        assert_eq!(r1.iterations, 25);
        assert_eq!(r2.iterations, 25);
        for (a, b) in v1.iter().zip(&v2) {
            assert_eq!(
                (a.v.to_array(), a.w.to_array()),
                (b.v.to_array(), b.w.to_array()),
                "{dims:?}"
            );
        }
        for (k, &i) in order.iter().enumerate() {
            assert_eq!(
                l1[i as usize].r.to_array(),
                l2[k].r.to_array(),
                "{dims:?}: contact {i}"
            );
            assert_eq!(s1[i as usize], s2[k]);
        }
        // The overlap correction on the same split equals the sequential correction in the
        // equivalent order, bit for bit.
        let correction = CorrectionSettings {
            slop: 0.0,
            ..Default::default()
        };
        let h = w.settings.dt;
        let (mut l3, mut v3) = (locals.clone(), bodies.clone());
        let mut s3 = vec![ContactStatus::NoContact; l3.len()];
        let mut p_ddm = Vec::new();
        let (_, _, corrected) = ddm::solve_and_correct(
            &mut ddm::DdmWorkspace::default(),
            &nlgs,
            &d,
            &partition,
            &mut l3,
            &mut [],
            &mut v3,
            &mut s3,
            Some(ddm::CorrectionPass {
                settings: &correction,
                h,
                elastic: Elastic::NONE,
                pseudo: &mut p_ddm,
            }),
        );
        let mut rows = Vec::new();
        let overlapping = correction::overlaps(&correction, h, Elastic::NONE, &l2, &mut rows);
        assert!(
            corrected && overlapping > 10,
            "{dims:?}: {overlapping} overlaps"
        );
        let mut p_mono = Vec::new();
        assert!(correction::pseudo_velocities(
            &correction,
            h,
            Elastic::NONE,
            &l2,
            &v2,
            &mut p_mono
        ));
        assert_eq!(p_ddm.len(), p_mono.len());
        let moved = p_mono.iter().filter(|b| b.v != DVec3::ZERO).count();
        assert!(moved > 10, "{dims:?}: {moved} bodies corrected");
        for (a, b) in p_ddm.iter().zip(&p_mono) {
            assert_eq!(
                (a.v.to_array(), a.w.to_array()),
                (b.v.to_array(), b.w.to_array()),
                "{dims:?}: pseudo-velocities"
            );
        }
    }
}

/// The result depends on the partition only: bit-identical for 1, 2 and 4 threads.
#[test]
fn ddm_is_independent_of_the_thread_count() {
    let run = |threads: usize, par: bool, min_parallel_contacts: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut sc = pile(120, [0.025, 0.05], 5, 0);
            sc.ddm = Some(DdmSettings {
                subdomains: [3, 2, 1],
                parallel_interface: par,
                min_parallel_contacts,
                ..Default::default()
            });
            let mut w = sc.build().unwrap();
            for _ in 0..1500 {
                w.step();
            }
            assert!(w.contacts.len() > 100);
            state_digest(&w.bodies)
        })
    };
    for par in [true, false] {
        let one = run(1, par, 0);
        // Running small phases on the calling thread changes scheduling only.
        assert_eq!(
            one,
            run(2, par, usize::MAX),
            "sequential phases differ (parallel interface {par})"
        );
        assert_eq!(
            one,
            run(2, par, 0),
            "2 threads differ (parallel interface {par})"
        );
        assert_eq!(
            one,
            run(4, par, 0),
            "4 threads differ (parallel interface {par})"
        );
    }
}

/// A step builds its local problems straight into the subdomains' buckets; a step prepared by
/// `detect` (its local problems readable in the contacts' order) buckets copies of them. Both
/// give the same run, bit for bit.
#[test]
fn local_problems_built_in_buckets_equal_copies_in_contact_order() {
    let run = |detect_first: bool| {
        let mut sc = pile(120, [0.025, 0.05], 5, 0);
        sc.ddm = Some(DdmSettings {
            subdomains: [3, 2, 1],
            min_parallel_contacts: 0,
            ..Default::default()
        });
        let mut w = sc.build().unwrap();
        for _ in 0..1200 {
            if detect_first {
                w.detect();
                assert_eq!(w.local_problems().len(), w.contacts.len());
            }
            w.step();
        }
        assert!(w.contacts.len() > 100);
        let impulses: Vec<[u64; 3]> = w
            .contacts
            .impulse
            .iter()
            .map(|r| r.to_array().map(f64::to_bits))
            .collect();
        (state_digest(&w.bodies), impulses, w.contacts.status.clone())
    };
    let (direct, copied) = (run(false), run(true));
    assert_eq!(direct.0, copied.0, "bodies differ");
    assert_eq!(direct.1, copied.1, "impulses differ");
    assert_eq!(direct.2, copied.2, "statuses differ");
}

/// Converged DDM and converged monolithic NLGS agree within the tolerance on a settled pile.
#[test]
fn converged_ddm_agrees_with_monolithic() {
    let mut w = poured(2500);
    // Converged by the natural-map residual, to 1e-8: after 20,000 sweeps the Quad norm (the
    // change of one sweep) is 5e-9 and the residual 1.5e-9, both still falling slowly.
    w.settings.solver = SolverSettings {
        tolerance: 1e-8,
        max_iterations: 20_000,
        norm: ballast_engine::solver::ConvergenceNorm::NaturalMap,
        ..Default::default()
    };
    w.prepare();
    let nlgs = w.nlgs();
    let (locals, bodies) = (w.local_problems().to_vec(), w.solver_bodies().to_vec());
    let (mut l2, mut v2) = (locals.clone(), bodies.clone());
    let mut s2 = vec![ContactStatus::NoContact; l2.len()];
    let mono = nlgs.solve(&mut l2, &mut v2, &mut s2);
    assert!(mono.converged, "{mono:?}");
    for (dims, n, m) in [([2, 2, 1], 1, 1), ([3, 3, 1], 3, 2)] {
        let d = DdmSettings {
            subdomains: dims,
            inner_sweeps: n,
            interface_sweeps: m,
            ..Default::default()
        };
        let partition = w.partition(&d);
        let (mut l1, mut v1) = (locals.clone(), bodies.clone());
        let mut s1 = vec![ContactStatus::NoContact; l1.len()];
        let (rep, _) = ddm::solve(&nlgs, &d, &partition, &mut l1, &mut v1, &mut s1);
        assert!(rep.converged, "{dims:?}: DDM did not converge");
        // Relative velocities at every contact agree to the tolerance scale.
        let scale = locals
            .iter()
            .map(|c| c.velocity(bodies.as_slice()).length())
            .fold(0.0, f64::max);
        for (a, b) in l1.iter().zip(&l2) {
            let (ua, ub) = (a.velocity(v1.as_slice()), b.velocity(v2.as_slice()));
            assert!(
                (ua - ub).length() <= 1e-5 * scale,
                "{dims:?}: {ua} vs {ub} (scale {scale})"
            );
        }
        // The contact impulses of a settled pile are not unique (it is hyperstatic), but the
        // impulse the pile exerts on the fixed bodies is: momentum balance fixes it once the
        // velocities are.
        let on_static = |ls: &[LocalProblem]| -> DVec3 {
            ls.iter()
                .map(|c| {
                    let [n, t, s] = c.frame3();
                    let p = n * c.r.x + t * c.r.y + s * c.r.z;
                    let mut f = DVec3::ZERO;
                    if !c.dynamic1 {
                        f -= p;
                    }
                    if !c.dynamic2 {
                        f += p;
                    }
                    f
                })
                .sum()
        };
        let (na, nb) = (on_static(&l1), on_static(&l2));
        assert!(
            (na - nb).length() <= 1e-5 * nb.length(),
            "{dims:?}: impulse on the fixed bodies {na} vs {nb}"
        );
    }
}

/// Whether two subdomain pairs share a subdomain.
fn meets(a: (u32, u32), b: (u32, u32)) -> bool {
    a.0 == b.0 || a.0 == b.1 || a.1 == b.0 || a.1 == b.1
}

/// Interface colouring: the groups of one colour join disjoint subdomains (they run
/// concurrently), and the groups come in `(colour, pair)` order.
#[test]
fn interface_groups_of_one_colour_are_disjoint() {
    let mut w = poured(1500);
    w.prepare();
    let locals = w.local_problems().to_vec();
    let partition = w.partition(&settings([4, 4, 1], true, Balance::Contacts));
    let p = DdmProblem::build(&partition, &locals, true);
    assert!(
        p.groups.len() > 10 && p.colours > 2,
        "{} groups",
        p.groups.len()
    );
    for (i, g) in p.groups.iter().enumerate() {
        for h in &p.groups[i + 1..] {
            if h.colour == g.colour {
                assert!(
                    !meets(g.pair, h.pair),
                    "{:?} and {:?} share colour",
                    g.pair,
                    h.pair
                );
            }
        }
    }
    let keys: Vec<_> = p.groups.iter().map(|g| (g.colour, g.pair)).collect();
    assert!(
        keys.windows(2).all(|k| k[0] < k[1]),
        "groups in (colour, pair) order"
    );
}

/// The colouring is greedy, largest group first: every group took the smallest colour left
/// free by the groups coloured before it (larger ones, or as large with a smaller pair), so
/// each colour below its own is held by an earlier group it meets.
#[test]
fn interface_colouring_is_greedy_largest_first() {
    let mut w = poured(1500);
    w.prepare();
    let locals = w.local_problems().to_vec();
    for split in [[4, 4, 1], [3, 3, 1], [8, 2, 1]] {
        let partition = w.partition(&settings(split, true, Balance::Contacts));
        let p = DdmProblem::build(&partition, &locals, true);
        let before = |g: &ddm::InterfaceGroup, h: &ddm::InterfaceGroup| {
            (std::cmp::Reverse(h.bucket.len()), h.pair)
                < (std::cmp::Reverse(g.bucket.len()), g.pair)
        };
        let sizes: Vec<usize> = p.groups.iter().map(|g| g.bucket.len()).collect();
        assert!(
            sizes.iter().any(|&n| n != sizes[0]),
            "{split:?}: groups of different sizes"
        );
        for g in &p.groups {
            for c in 0..g.colour {
                assert!(
                    p.groups
                        .iter()
                        .any(|h| h.colour == c && meets(g.pair, h.pair) && before(g, h)),
                    "{split:?}: group {:?} ({} contacts, colour {}) could have taken colour {c}",
                    g.pair,
                    g.bucket.len(),
                    g.colour
                );
            }
        }
    }
}

/// Skipping contacts whose bodies did not move (`solver.skip`) reaches the same solution as
/// full sweeps, monolithic and decomposed, bit-identical on any thread count; a threshold so
/// large that a sweep skips nearly everything still converges, on the full sweeps it keeps.
#[test]
fn skipping_sweeps_reach_the_same_solution() {
    let mut w = poured(2500);
    let solver = |skip: f64| SolverSettings {
        tolerance: 1e-6,
        max_iterations: 20_000,
        norm: ballast_engine::solver::ConvergenceNorm::NaturalMap,
        skip,
        ..Default::default()
    };
    w.settings.solver = solver(0.0);
    w.prepare();
    let (locals, bodies) = (w.local_problems().to_vec(), w.solver_bodies().to_vec());
    let solve_mono = |skip: f64| {
        let mut nlgs = w.nlgs();
        nlgs.settings = solver(skip);
        let (mut l, mut v) = (locals.clone(), bodies.clone());
        let mut s = vec![ContactStatus::NoContact; l.len()];
        let rep = nlgs.solve(&mut l, &mut v, &mut s);
        (rep, l, v)
    };
    let (full, l0, v0) = solve_mono(0.0);
    assert!(full.converged, "{full:?}");
    let scale = locals
        .iter()
        .map(|c| c.velocity(bodies.as_slice()).length())
        .fold(0.0, f64::max);
    let agree = |what: &str, l: &[LocalProblem], v: &[ballast_engine::solver::SolverBody]| {
        for (a, b) in l.iter().zip(&l0) {
            let (ua, ub) = (a.velocity(v), b.velocity(v0.as_slice()));
            assert!(
                // Measured: at most 1.6e-6 of the scale, for a residual tolerance of 1e-6.
                (ua - ub).length() <= 1e-5 * scale,
                "{what}: {ua} vs {ub} (scale {scale})"
            );
        }
    };
    for skip in [1.0, 1e6] {
        let (rep, l, v) = solve_mono(skip);
        eprintln!("skip {skip}: {rep:?}; full sweeps: {full:?}");
        assert!(
            rep.converged && rep.residual <= 1e-6,
            "skip {skip}: {rep:?}"
        );
        // Every eighth sweep is a full one: at most eight times the sweeps.
        assert!(
            rep.iterations <= 8 * full.iterations + 8,
            "skip {skip}: {} sweeps, {} without skipping",
            rep.iterations,
            full.iterations
        );
        agree(&format!("monolithic, skip {skip}"), &l, &v);
        if skip > 1e3 {
            // Nearly every contact skipped between the full sweeps: the iterate differs from
            // plain Gauss-Seidel's (measured: 961 sweeps against 151).
            assert!(rep.iterations > full.iterations, "{rep:?}");
        }
    }
    // Decomposed, with skipping: converged, and the same digits on 1 and 2 threads.
    let mut nlgs = w.nlgs();
    nlgs.settings = solver(1.0);
    let d = settings([2, 2, 1], true, Balance::Contacts);
    let partition = w.partition(&d);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (mut l, mut v) = (locals.clone(), bodies.clone());
            let mut s = vec![ContactStatus::NoContact; l.len()];
            let (rep, _) = ddm::solve(&nlgs, &d, &partition, &mut l, &mut v, &mut s);
            (rep, l, v)
        })
    };
    let (rep1, l1, v1) = run(1);
    let (rep2, l2, v2) = run(2);
    assert!(rep1.converged, "{rep1:?}");
    assert_eq!(rep1, rep2);
    assert!(l1.iter().zip(&l2).all(|(a, b)| a.r == b.r));
    assert!(v1.iter().zip(&v2).all(|(a, b)| a.v == b.v && a.w == b.w));
    agree("DDM 2x2x1, skip 1", &l1, &v1);
}
