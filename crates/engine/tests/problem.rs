//! The contact problem as a value (`World::contact_problem`): `W` assembled in 3×3 blocks is
//! symmetric, positive semi-definite, has the local problems' blocks on its diagonal and gives
//! the same local velocities as the engine's matrix-free `V = V_free + M⁻¹ H r`; NLGS on the
//! assembled `(W, q, μ)` reproduces the engine's sweep, impulses and residual.

mod common;

use ballast_engine::laws::ContactStatus;
use ballast_engine::laws::FrictionTable;
use ballast_engine::math::{DMat3, DVec3};
use ballast_engine::scenario::generate::GrainPack;
use ballast_engine::solver::SolverSettings;
use ballast_engine::world::{StepSettings, World};

/// A pile of 80 grains poured in a box, 0.8 s later (settling), its next step prepared.
fn prepared_pile() -> World {
    prepared_pile_with(None)
}

/// [`prepared_pile`] with contacts of the given stiffness (N/m; `None`: rigid).
fn prepared_pile_with(contact_stiffness: Option<f64>) -> World {
    let mut bodies = common::open_box(0.15);
    let pack = GrainPack {
        count: 80,
        min: [0.0, 0.0, 0.002],
        max_xy: [0.15, 0.15],
        diameter: [0.025, 0.04],
        vertices: [10, 14],
        elongation: 1.3,
        flatness: 1.1,
        seed: 11,
    };
    common::pour(&mut bodies, &pack, 2700.0, 1);
    let settings = StepSettings {
        dt: 5e-4,
        contact_stiffness,
        solver: SolverSettings {
            tolerance: 1e-3,
            max_iterations: 200,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut w = World::new(bodies, FrictionTable::new(0.8), settings);
    for _ in 0..1600 {
        w.step();
    }
    w.prepare();
    w
}

/// Seeded numbers in [-1, 1) (a linear congruential generator: the test needs no more).
fn noise(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

/// Largest absolute entry.
fn maxabs(m: DMat3) -> f64 {
    m.to_cols_array()
        .into_iter()
        .fold(0.0, |a, x| a.max(x.abs()))
}

#[test]
fn assembled_delassus_matches_the_matrix_free_operator() {
    let w = prepared_pile();
    let locals = w.local_problems();
    let v_free = w.solver_bodies();
    let p = w.contact_problem();
    let n = p.len();
    assert!(n > 100, "{n} contacts");
    let norm =
        p.w.blocks
            .iter()
            .map(|b| b.abs().to_cols_array().into_iter().fold(0.0, f64::max))
            .fold(0.0, f64::max);
    // Symmetric, with the local problems' blocks on the diagonal.
    for (i, local) in locals.iter().enumerate() {
        for (j, b) in p.w.row(i) {
            let t = p.w.get(j, i).expect("the transposed block is stored");
            assert!(
                maxabs(*b - t.transpose()) <= 1e-12 * norm,
                "W[{i},{j}] is not W[{j},{i}]ᵀ"
            );
        }
        let d = p.w.get(i, i).unwrap();
        assert!(maxabs(*d - local.w.to_mat()) <= 1e-12 * norm);
    }
    let off = p.w.blocks.len() - n;
    eprintln!("{n} contacts, {off} off-diagonal blocks");
    assert!(
        off > n,
        "the grains' contacts couple: {off} off-diagonal blocks"
    );
    // `W r + q` against `V = V_free + M⁻¹ H r` read back at each contact (plus the gap shift).
    let h_theta = w.settings.dt * w.settings.theta;
    let mut rand = noise(7);
    for _ in 0..3 {
        let r: Vec<DVec3> = (0..n)
            .map(|_| DVec3::new(rand(), rand(), rand()) * 1e-3)
            .collect();
        let u = p.velocity(&r);
        let mut v = v_free.to_vec();
        for (c, ri) in locals.iter().zip(&r) {
            c.apply(&mut v[..], *ri);
        }
        let mut worst = 0.0f64;
        let scale = u.iter().map(|x| x.length()).fold(0.0, f64::max);
        for (a, c) in locals.iter().enumerate() {
            let mut m = c.velocity(&v[..]);
            if c.gap > 0.0 {
                m.x += c.gap / h_theta;
            }
            worst = worst.max((m - u[a]).length());
        }
        assert!(
            worst <= 1e-12 * scale,
            "matrix-free vs assembled: {worst:e} of {scale:e}"
        );
        // Positive semi-definite: rᵀ W r ≥ 0 (to rounding).
        let wr = p.w.mul(&r);
        let quad: f64 = r.iter().zip(&wr).map(|(a, b)| a.dot(*b)).sum();
        let r2: f64 = r.iter().map(|x| x.length_squared()).sum();
        assert!(quad >= -1e-12 * norm * r2, "rᵀWr = {quad:e}");
    }
}

#[test]
fn nlgs_on_the_assembled_problem_reproduces_the_engine_sweep() {
    // Rigid contacts, and compliant ones (the law's `c`, `r̄ₙ` and overlap recovery folded
    // into `W` and `q`).
    for stiffness in [None, Some(1e6)] {
        assembled_sweep_matches(stiffness);
    }
}

fn assembled_sweep_matches(stiffness: Option<f64>) {
    let mut w = prepared_pile_with(stiffness);
    // No slop: the overlap recovery's speeds are part of the compliant problem.
    w.settings.overlap_recovery = 0.2;
    w.settings.overlap_slop = 0.0;
    assert_eq!(w.contact_problem().compliance > 0.0, stiffness.is_some());
    let settings = SolverSettings {
        tolerance: 1e-300,
        max_iterations: 40,
        residual_tolerance: f64::INFINITY,
        ..Default::default()
    };
    let mut nlgs = w.nlgs();
    nlgs.settings = settings.clone();
    let p = w.contact_problem();
    // The engine: matrix-free sweeps from the warm start.
    let mut locals = w.local_problems().to_vec();
    let mut v = w.solver_bodies().to_vec();
    let mut status = vec![ContactStatus::NoContact; locals.len()];
    let engine = nlgs.solve(&mut locals, &mut v, &mut status);
    // The same sweeps on (W, q, μ) from the same warm start.
    let mut r: Vec<DVec3> = w.local_problems().iter().map(|c| c.r).collect();
    let assembled = p.solve_nlgs(&mut r, &settings);
    assert_eq!(engine.iterations, assembled.iterations);
    let big = r.iter().map(|x| x.length()).fold(0.0, f64::max);
    let diff = locals
        .iter()
        .zip(&r)
        .map(|(c, x)| (c.r - *x).length())
        .fold(0.0, f64::max);
    eprintln!(
        "largest impulse {big:.3e}, largest difference {diff:.3e}; residual engine {:.6e}, assembled {:.6e}",
        engine.residual, assembled.residual
    );
    assert!(big > 0.0);
    assert!(
        diff <= 1e-9 * big,
        "impulses differ by {diff:e} (largest {big:e})"
    );
    assert!(
        (engine.residual - assembled.residual).abs() <= 1e-6 * engine.residual,
        "residual {} vs {}",
        engine.residual,
        assembled.residual
    );
    assert!((p.residual(&r) - assembled.residual).abs() <= 1e-12 * assembled.residual.max(1e-300));
}

/// `detect()` then `step()` is one step: the same state digest as `step()` alone, and the
/// contact problem read in between is the one the step solves.
#[test]
fn detect_then_step_is_one_step() {
    let mut a = prepared_pile();
    let mut b = prepared_pile();
    for _ in 0..3 {
        a.step();
        let overlap = b.detect();
        assert!(b.is_detected() && overlap >= 0.0);
        let n = b.contact_problem().len();
        assert_eq!(b.detect(), overlap, "a second detect does nothing");
        let r = b.step();
        assert!(!b.is_detected());
        assert_eq!(r.contacts, n);
        assert_eq!(
            ballast_engine::digest::state_digest(&a.bodies),
            ballast_engine::digest::state_digest(&b.bodies)
        );
    }
}

/// The step pipeline's buffers hold no state: freeing them before every step (with compliant
/// contacts, whose law remembers the last step's impulses) changes no bit of the run; between
/// `detect()` and the step it prepared nothing is freed.
#[test]
fn releasing_the_scratch_changes_nothing() {
    for stiffness in [None, Some(1e6)] {
        let mut a = prepared_pile_with(stiffness);
        let mut b = prepared_pile_with(stiffness);
        for _ in 0..20 {
            a.step();
            assert!(b.release_scratch());
            b.step();
        }
        a.detect();
        b.detect();
        assert!(!b.release_scratch(), "a detected step keeps its buffers");
        a.step();
        b.step();
        assert_eq!(
            ballast_engine::digest::state_digest(&a.bodies),
            ballast_engine::digest::state_digest(&b.bodies)
        );
    }
}

#[test]
fn global_form_gives_w_and_q_through_the_bodies() {
    for stiffness in [None, Some(1e6)] {
        global_form_matches(stiffness);
    }
}

fn global_form_matches(stiffness: Option<f64>) {
    let mut w = prepared_pile_with(stiffness);
    // No slop: every overlap deeper than its deflection gets a recovery speed in `q`.
    w.settings.overlap_recovery = 0.2;
    w.settings.overlap_slop = 0.0;
    let p = w.contact_problem();
    let g = w.global_problem(&p);
    let n = p.len();
    // The grains in contact are the problem's bodies; the planes are not.
    assert!(g.bodies.len() > 30, "{} bodies", g.bodies.len());
    assert!(g.bodies.windows(2).all(|x| x[0] < x[1]));
    assert!(g.bodies.iter().all(|&b| b >= 5), "a plane is not moved");
    // Each contact has one block per grain: two between grains, one against a wall.
    let walls = w
        .local_problems()
        .iter()
        .filter(|c| !(c.dynamic1 && c.dynamic2))
        .count();
    assert_eq!(g.h.len(), 2 * n - walls);
    // W = Hᵀ M⁻¹ H + c Iₙ.
    let c = g.compliance;
    assert_eq!(c, p.compliance);
    let norm =
        p.w.blocks
            .iter()
            .map(|b| b.abs().to_cols_array().into_iter().fold(0.0, f64::max))
            .fold(0.0, f64::max);
    let mut rand = noise(3);
    let r: Vec<DVec3> = (0..n).map(|_| DVec3::new(rand(), rand(), rand())).collect();
    let via_bodies: Vec<DVec3> = g
        .w_times(&r)
        .iter()
        .zip(&r)
        .map(|(u, x)| *u + DVec3::new(c * x.x, 0.0, 0.0))
        .collect();
    let assembled = p.w.mul(&r);
    let r_max = r.iter().map(|x| x.length()).fold(0.0, f64::max);
    for (a, b) in via_bodies.iter().zip(&assembled) {
        assert!(
            (*a - *b).length() <= 1e-12 * norm * r_max * 8.0,
            "Hᵀ M⁻¹ H r = {a} but W r = {b}"
        );
    }
    // The walls are fixed, so q − Hᵀ v_free is the gap shift alone (less c r̄ₙ, less the
    // overlap recovery's speed `min(β, h √(k W_nn) / 16) / h · (δ − r̄ₙ/(k h))⁺`).
    let h = w.settings.dt;
    let h_theta = h * w.settings.theta;
    let q_max = p.q.iter().map(|x| x.length()).fold(0.0, f64::max);
    let mut recovering = 0;
    for (a, (l, b)) in w.local_problems().iter().zip(&g.b).enumerate() {
        let recovery = match stiffness {
            Some(k) if l.gap <= 0.0 => {
                let excess = -l.gap - l.r_prev.max(0.0) / (k * h);
                let w_nn = p.w.get(a, a).unwrap().x_axis.x - c;
                let beta = w
                    .settings
                    .overlap_recovery
                    .min(h * (k * w_nn).sqrt() / 16.0);
                beta / h * excess.max(0.0)
            }
            _ => 0.0,
        };
        recovering += usize::from(recovery > 0.0);
        let shift = DVec3::new(l.gap.max(0.0) / h_theta - c * l.r_prev - recovery, 0.0, 0.0);
        assert!(
            (*b - shift).length() <= 1e-12 * q_max,
            "b = {b}, gap shift {shift}"
        );
    }
    assert_eq!(
        recovering > 10,
        stiffness.is_some(),
        "{recovering} recovering"
    );
}
