//! A track scenario through the `ballast` command, on a bed small enough for CI (about 270
//! grains, prepared once into a temporary cache):
//!
//! * a run stopped mid-squeeze and resumed twice (once just after the block's release, then
//!   to the end of the cycle) ends bit-identical to one straight run, with the same
//!   `series.csv` rows and `summary.json`;
//! * `series.csv`: units in the column names, and values checked against the scenario's
//!   geometry and tamping cycle (time, block height, tine forces, compacity, overlaps,
//!   timings) and against `summary.json`;
//! * `report.md` shows every figure as PNG and links its SVG, the track indicators' ones
//!   included (see `figures/mod.rs` for what is checked of each), the figures that do not
//!   show wall-clock times are the same bytes for the straight and the resumed run, and the
//!   report gives the final indicators of `summary.json`.
//!
//! The three runs are made once, by whichever test comes first (about 40 s in release on 2
//! cores, the bed's preparation included).

use ballast_railway::TrackScenario;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

mod figures;

/// A tiny track: a 0.10 × 0.18 × 0.08 m block on 0.08 m of 31.5/50 ballast (8–12 vertices, as
/// in `crates/railway/tests/tamping.rs`), 0.32 × 0.26 m bed; cheap deposition (dt 1e-3 s,
/// short settling); a fast cycle of 0.47 s (1175 steps of 4e-4 s), tines scaled to the block.
///
/// * Every phase and ramp lasts a whole number of steps: the drivers' positions are then
///   exact (with `lift_time = 0.03` the ramp is cut to 7.5 ms, between two steps, and the
///   block ends 1.8 µm short of the lift).
/// * The tips start 45 mm above the block tops, the highest grain centre: clear of every grain
///   (the largest, 63 mm, elongation 1.4, flatness 1.2, reach 42 mm from their centre).
/// * The bed's ends are 58 mm from the tines' outer faces, more than a grain. `mini()` and the
///   default preset leave 25 and 30 mm; in a first version of this bed, with 33 mm, two grains
///   jammed there by the plunging tine overlapped by 1 cm for dozens of steps.
/// * One `series.csv` row per step.
const SCENARIO: &str = r#"
[simulation]
dt = 4e-4
contact_stiffness = 2.5e5
tangential_stiffness = 2.5e5
output_interval = 1
vtk_interval = 0
checkpoint_interval = 200

[track]
blocks = 1
block_size = [0.10, 0.18, 0.08]
spacing = 0.32
depth = 0.08
width = 0.26

[ballast]
grading = "31.5/50"
vertices = [8, 12]
seed = 3

[preparation]
dt = 1e-3
settle_time = 0.1
max_extra_time = 0.15

[tamping]
lift = 0.01
lift_time = 0.04
blade = [0.012, 0.04, 0.05]
shaft = [0.015, 0.015]
tine_y = [-0.045, 0.045]
open_gap = 0.04
squeeze = 0.02
clearance = 0.045
depth_below_soffit = 0.01
amplitude = 0.0015
insertion_time = 0.15
squeeze_time = 0.12
hold_time = 0.02
withdraw_time = 0.08
lower_time = 0.06
ramp = 0.01

[indicators]
depth = 0.05

[solver]
tolerance = 1e-3
max_iterations = 200
"#;

/// Nominal lower size of the 31.5/50 grading (m): 87 % of the mass is coarser.
const D_LOWER: f64 = 0.0315;

/// Overlap tolerated in the prepared bed (the tamping test's bound on the preparation).
const BED_OVERLAP: f64 = 2e-3;

/// Columns the track model adds for one block and 4 tines, in order.
const TRACK_COLUMNS: [&str; 42] = [
    "compacity_under_block_1",
    "compacity_crib_0",
    "compacity_crib_1",
    "block_z_1_m",
    "tine_force_1_x_N",
    "tine_force_1_z_N",
    "tine_force_2_x_N",
    "tine_force_2_z_N",
    "tine_force_3_x_N",
    "tine_force_3_z_N",
    "tine_force_4_x_N",
    "tine_force_4_z_N",
    "tine_drive_1_x_N",
    "tine_drive_1_z_N",
    "tine_drive_2_x_N",
    "tine_drive_2_z_N",
    "tine_drive_3_x_N",
    "tine_drive_3_z_N",
    "tine_drive_4_x_N",
    "tine_drive_4_z_N",
    "tine_travel_1_x_m",
    "tine_travel_1_x_command_m",
    "tine_travel_1_z_m",
    "tine_travel_1_z_command_m",
    "tine_travel_2_x_m",
    "tine_travel_2_x_command_m",
    "tine_travel_2_z_m",
    "tine_travel_2_z_command_m",
    "tine_travel_3_x_m",
    "tine_travel_3_x_command_m",
    "tine_travel_3_z_m",
    "tine_travel_3_z_command_m",
    "tine_travel_4_x_m",
    "tine_travel_4_x_command_m",
    "tine_travel_4_z_m",
    "tine_travel_4_z_command_m",
    "coordination",
    "tine_work_1_J",
    "tine_work_2_J",
    "tine_work_3_J",
    "tine_work_4_J",
    "block_drive_1_z_N",
];

/// The runs shared by the tests.
struct Runs {
    scenario: TrackScenario,
    /// `--steps a --out chained`, `--resume chained --steps c`, `--resume chained` (to the end
    /// of the cycle, the scenario's step count).
    chained: PathBuf,
    /// `--steps b --out straight`.
    straight: PathBuf,
    a: u64,
    c: u64,
    b: u64,
    /// `state_digest` after `a` and after `c` steps.
    digest_a: String,
    digest_c: String,
    /// stderr of the four runs, in order.
    logs: Vec<String>,
}

/// A scratch folder. Left in place: the runs in it are shared by every test of this file (a
/// static fixture, never dropped), so it lives under cargo's `target/tmp` (cleaned with the
/// build) rather than the system's temporary folder.
fn tmp(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("ballast-track-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn summary(dir: &Path) -> Result<Value, String> {
    let p = dir.join("summary.json");
    let text = std::fs::read_to_string(&p).map_err(|e| format!("{}: {e}", p.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", p.display()))
}

/// Runs `ballast run ARGS`; its stderr, or why it failed.
fn ballast(args: &[&str]) -> Result<String, String> {
    let out = Command::new(env!("CARGO_BIN_EXE_ballast"))
        .arg("run")
        .args(args)
        .output()
        .map_err(|e| e.to_string())?;
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    if out.status.success() {
        Ok(err)
    } else {
        Err(format!("ballast run {args:?} failed:\n{err}"))
    }
}

fn make_runs() -> Result<Runs, String> {
    let start = std::time::Instant::now();
    let root = tmp("runs");
    std::fs::create_dir_all(&root).map_err(|e| e.to_string())?;
    let file = root.join("track.toml");
    std::fs::write(&file, SCENARIO).map_err(|e| e.to_string())?;
    let scenario = TrackScenario::from_toml(SCENARIO)?;
    let dt = scenario.simulation.dt;
    let cycle = scenario.tamping.build(&scenario.track);
    let p = cycle.phases[0];
    // Stop mid-squeeze, then just after the release, then at the end of the cycle.
    let a = (0.5 * (p.squeeze + p.hold) / dt).round() as u64;
    let c = (cycle.release / dt).round() as u64 + 25;
    let b = scenario.steps();
    if !(a < c && c < b) {
        return Err(format!("steps a = {a}, c = {c}, b = {b} out of order"));
    }
    let (chained, straight) = (root.join("chained"), root.join("straight"));
    let cache = root.join("cache");
    let (file, cache, ch, st) = (
        file.to_str().unwrap(),
        cache.to_str().unwrap(),
        chained.to_str().unwrap(),
        straight.to_str().unwrap(),
    );
    let (a_s, c_s, b_s) = (a.to_string(), c.to_string(), b.to_string());
    let mut logs = Vec::new();
    logs.push(ballast(&[
        file,
        "--steps",
        &a_s,
        "--out",
        ch,
        "--cache",
        cache,
        "--threads",
        "2",
    ])?);
    let digest_a = summary(&chained)?["state_digest"].to_string();
    logs.push(ballast(&[
        "--resume",
        ch,
        "--steps",
        &c_s,
        "--cache",
        cache,
        "--threads",
        "2",
    ])?);
    let digest_c = summary(&chained)?["state_digest"].to_string();
    // No --steps: the scenario's own count, the whole cycle.
    logs.push(ballast(&[
        "--resume",
        ch,
        "--cache",
        cache,
        "--threads",
        "2",
    ])?);
    // One thread for the straight run: the track indicators too are thread-independent.
    logs.push(ballast(&[
        file,
        "--steps",
        &b_s,
        "--out",
        st,
        "--cache",
        cache,
        "--threads",
        "1",
    ])?);
    eprintln!(
        "runs of {a}, {c}, {b} and {b} steps: {:.1} s, preparation included",
        start.elapsed().as_secs_f64()
    );
    Ok(Runs {
        scenario,
        chained,
        straight,
        a,
        c,
        b,
        digest_a,
        digest_c,
        logs,
    })
}

fn runs() -> &'static Runs {
    static RUNS: OnceLock<Result<Runs, String>> = OnceLock::new();
    match RUNS.get_or_init(make_runs) {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    }
}

/// `series.csv` as column names and rows of numbers.
struct Series {
    names: Vec<String>,
    rows: Vec<Vec<f64>>,
    /// The rows as written.
    lines: Vec<String>,
}

impl Series {
    fn read(dir: &Path) -> Series {
        let text = std::fs::read_to_string(dir.join("series.csv")).unwrap();
        let mut lines = text.lines();
        let names: Vec<String> = lines
            .next()
            .unwrap()
            .split(',')
            .map(str::to_string)
            .collect();
        let lines: Vec<String> = lines.map(str::to_string).collect();
        let rows = lines
            .iter()
            .map(|l| {
                let r: Vec<f64> = l
                    .split(',')
                    .map(|c| c.parse().unwrap_or_else(|_| panic!("{c:?} in {l}")))
                    .collect();
                assert_eq!(r.len(), names.len(), "{l}");
                assert!(r.iter().all(|v| v.is_finite()), "{l}");
                r
            })
            .collect();
        Series { names, rows, lines }
    }

    fn col(&self, name: &str) -> usize {
        self.names
            .iter()
            .position(|n| n == name)
            .unwrap_or_else(|| panic!("no column {name}"))
    }

    fn values(&self, name: &str) -> Vec<f64> {
        let i = self.col(name);
        self.rows.iter().map(|r| r[i]).collect()
    }
}

fn num(v: &Value, ptr: &str) -> f64 {
    v.pointer(ptr)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("summary.json has no number at {ptr}"))
}

/// `a` and `b` equal to a relative `rel` (values printed with limited digits).
fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-300
}

/// `--steps a`, `--resume --steps c`, `--resume` (to the end of the cycle) end bit-identical
/// to one straight run on another thread count: same state digest, same rows (but for the
/// timing columns), same summary (but for timings and threads); the bed is prepared once and
/// read from the cache by the later runs.
#[test]
fn resumed_track_run_is_bit_identical_to_a_straight_one() {
    let r = runs();
    let (sc, ss) = (summary(&r.chained).unwrap(), summary(&r.straight).unwrap());
    assert_eq!(sc["steps"], r.b);
    assert_eq!(ss["steps"], r.b);
    assert_eq!(
        r.b,
        (r.scenario.tamping.duration() / r.scenario.simulation.dt).round() as u64
    );
    assert!(close(
        num(&sc, "/time"),
        r.b as f64 * r.scenario.simulation.dt,
        1e-12
    ));
    assert_eq!(sc["threads"], 2);
    assert_eq!(ss["threads"], 1);
    // The state moved between the stops, and ends the same.
    let digest = sc["state_digest"].to_string();
    assert!(
        r.digest_a != r.digest_c && r.digest_c != digest,
        "{} {} {digest}",
        r.digest_a,
        r.digest_c
    );
    assert_eq!(sc["state_digest"], ss["state_digest"]);
    // Prepared once, then read from the cache; each resume starts where the last run stopped.
    assert!(r.logs[0].contains("bed prepared"), "{}", r.logs[0]);
    for log in &r.logs[1..] {
        assert!(log.contains("bed read from the cache"), "{log}");
    }
    assert!(
        r.logs[1].contains(&format!("(step {})", r.a)),
        "{}",
        r.logs[1]
    );
    assert!(
        r.logs[2].contains(&format!("(step {})", r.c)),
        "{}",
        r.logs[2]
    );
    // Rows: one per step, identical but for the wall-clock timings.
    let (dc, ds) = (Series::read(&r.chained), Series::read(&r.straight));
    assert_eq!(dc.names, ds.names);
    assert_eq!(dc.rows.len() as u64, r.b);
    assert_eq!(ds.rows.len() as u64, r.b);
    let timing: Vec<bool> = dc.names.iter().map(|n| n.starts_with("t_")).collect();
    let strip = |l: &str| -> String {
        l.split(',')
            .zip(&timing)
            .filter(|(_, &t)| !t)
            .map(|(c, _)| c)
            .collect::<Vec<_>>()
            .join(",")
    };
    for (k, (lc, ls)) in dc.lines.iter().zip(&ds.lines).enumerate() {
        assert_eq!(strip(lc), strip(ls), "row {}", k + 1);
    }
    // Summary: everything but the wall-clock timings and the thread count.
    let without = |v: &Value| {
        let mut v = v.clone();
        let m = v.as_object_mut().unwrap();
        m.remove("timings_s");
        m.remove("threads");
        v
    };
    assert_eq!(without(&sc), without(&ss));
    // The bodies: 5 walls, the block, 2 boxes per tine, the grains.
    let grains = sc["grains"].as_u64().unwrap();
    let tines = 2 * r.scenario.tamping.tine_y.len() as u64;
    assert_eq!(sc["bodies"].as_u64().unwrap(), grains + 5 + 1 + 2 * tines);
    let prep = &sc["preparation"];
    assert_eq!(prep["grains"].as_u64().unwrap(), grains);
    assert_eq!(
        prep["generated"].as_u64().unwrap(),
        grains
            + prep["removed_in_blocks"].as_u64().unwrap()
            + prep["removed_above"].as_u64().unwrap()
            + prep["removed_wedged"].as_u64().unwrap()
    );
    // The preparation healed its overlaps (this bed stops settling with a grain wedged 6 mm
    // deep).
    let healed = prep["max_penetration"].as_f64().unwrap();
    assert!(healed < r.scenario.preparation.heal_overlap, "{prep}");
    eprintln!(
        "{grains} grains, {} bodies, digest {digest}; stops at steps {}, {}, {}",
        sc["bodies"], r.a, r.c, r.b
    );
}

/// `quality.csv` names every step that missed the tolerance or overlapped by more than 1 mm:
/// with a `series.csv` row per step, its rows are exactly those steps' rows (the same values),
/// the deepest overlap's two bodies added; as many unconverged rows as `summary.json` counts;
/// a resumed run's file equals a straight run's.
#[test]
fn quality_csv_names_every_unconverged_or_deep_step() {
    let r = runs();
    let read = |dir: &Path| std::fs::read_to_string(dir.join("quality.csv")).unwrap();
    let (qc, qs) = (read(&r.chained), read(&r.straight));
    assert_eq!(qc, qs);
    let mut lines = qs.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        [
            "step",
            "time_s",
            "contacts",
            "iterations",
            "quad",
            "residual",
            "converged",
            "max_penetration_m",
            "body1",
            "body2"
        ]
    );
    let s = Series::read(&r.straight);
    let (conv, pen) = (s.col("converged"), s.col("max_penetration_m"));
    let expected: Vec<&Vec<f64>> = s
        .rows
        .iter()
        .filter(|row| row[conv] == 0.0 || row[pen] > 1e-3)
        .collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), expected.len());
    let unconverged = rows.iter().filter(|q| q[6] == "0").count() as u64;
    let sum = summary(&r.straight).unwrap();
    assert_eq!(
        Some(unconverged),
        sum["solver"]["steps_not_converged"].as_u64()
    );
    assert!(
        unconverged > 0,
        "the bed should leave some step unconverged"
    );
    let grains_and_all = sum["bodies"].as_u64().unwrap();
    for (q, e) in rows.iter().zip(&expected) {
        // The first eight columns are series.csv's, printed the same way.
        for (j, name) in header[..8].iter().enumerate() {
            let v: f64 = q[j].parse().unwrap();
            assert_eq!(v, e[s.col(name)], "{name} in {q:?}");
        }
        let [b1, b2] = [q[8], q[9]].map(|b| b.parse::<u64>().ok());
        if e[pen] > 0.0 {
            let (b1, b2) = (b1.unwrap(), b2.unwrap());
            assert!(b1 != b2 && b1.max(b2) < grains_and_all, "{q:?}");
        } else {
            assert_eq!((b1, b2), (None, None), "{q:?}");
        }
    }
    eprintln!("{} steps flagged, {unconverged} unconverged", rows.len());
}

/// Checks one run's `series.csv` against the scenario and its `summary.json`.
fn check_series(r: &Runs, dir: &Path) {
    let s = Series::read(dir);
    let sum = summary(dir).unwrap();
    // The scenario as the run wrote it: dt and the geometry come from there.
    let sc = TrackScenario::from_toml(&std::fs::read_to_string(dir.join("scenario.toml")).unwrap())
        .unwrap();
    assert_eq!(sc, r.scenario);
    let dt = sc.simulation.dt;
    let n = s.rows.len();

    // Header: the engine's columns, then the track's; every name carries its unit.
    let mut expected: Vec<String> = ballast_engine::output::SERIES_HEADER
        .split(',')
        .map(str::to_string)
        .collect();
    expected.extend(TRACK_COLUMNS.iter().map(|c| c.to_string()));
    assert_eq!(s.names, expected);
    let dimensionless = [
        "step",
        "contacts",
        "iterations",
        "quad",
        "residual",
        "converged",
        "coordination",
    ];
    for name in &s.names {
        let unit = ["_s", "_m", "_J", "_N"].iter().any(|u| name.ends_with(u));
        assert!(
            unit || dimensionless.contains(&name.as_str()) || name.starts_with("compacity_"),
            "column {name}: no unit suffix and not a known dimensionless column"
        );
    }

    // One row per step; time = step × dt.
    let steps = s.values("step");
    let time = s.values("time_s");
    for (k, (&st, &t)) in steps.iter().zip(&time).enumerate() {
        assert_eq!(st, (k + 1) as f64);
        assert!((t - st * dt).abs() <= 1e-12, "step {st}: time {t}");
    }

    // Solver columns.
    let contacts = s.values("contacts");
    let iterations = s.values("iterations");
    let converged = s.values("converged");
    for k in 0..n {
        assert!(contacts[k] >= 0.0 && contacts[k].fract() == 0.0);
        assert!(iterations[k] >= 1.0 && iterations[k] <= sc.solver.max_iterations as f64);
        assert!(converged[k] == 0.0 || converged[k] == 1.0);
    }

    // Overlaps: none beyond the prepared bed's before the tines move; while they plunge and
    // squeeze, a grain jammed between a driven tine (infinite mass) and a wall or a wedged
    // neighbour can only overlap (measured up to 16 mm in this tiny bed), but none passes
    // through another; once the tines are out, the overlap correction heals them.
    let cycle = sc.tamping.build(&sc.track);
    let p = cycle.phases[0];
    let pen = s.values("max_penetration_m");
    assert!(pen.iter().all(|&v| v >= 0.0));
    let before = (0..n)
        .filter(|&k| time[k] <= p.insertion + 1e-9)
        .map(|k| pen[k])
        .fold(0.0, f64::max);
    let max_pen = pen.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "{}: max overlap {:.2} mm before the insertion, {:.2} mm over the run",
        dir.display(),
        before * 1e3,
        max_pen * 1e3
    );
    assert!(
        before < BED_OVERLAP,
        "overlap {before} m before the insertion"
    );
    assert!(
        max_pen < D_LOWER / 1.5,
        "overlap {max_pen} m: a grain passes through another"
    );
    let healed = (0..n)
        .filter(|&k| time[k] >= p.end + 0.02)
        .map(|k| pen[k])
        .fold(0.0, f64::max);
    assert!(
        healed < BED_OVERLAP,
        "overlap {healed} m 20 ms after the tines are out"
    );
    let ke = s.values("kinetic_energy_J");
    assert!(ke.iter().all(|&v| v >= 0.0));

    // Timings: non-negative; every step has a row, so the rows add up to the summary's
    // per-phase times (timers restored on resume), and the phases to the whole steps.
    let mut phases_sum = 0.0;
    for phase in ["detection", "nlgs", "other"] {
        let col = s.values(&format!("t_{phase}_s"));
        assert!(col.iter().all(|&v| v >= 0.0), "t_{phase}_s < 0");
        let total: f64 = col.iter().sum();
        let reported = num(&sum, &format!("/timings_s/{phase}"));
        assert!(
            (total - reported).abs() <= 1e-4 * reported + 1e-6,
            "{phase}: rows add up to {total} s, summary {reported} s"
        );
        phases_sum += total;
    }
    let total = num(&sum, "/timings_s/total");
    assert!(
        phases_sum <= total * (1.0 + 1e-6) + 1e-6 && phases_sum >= 0.95 * total,
        "phases {phases_sum} s, total {total} s"
    );

    // Compacity: a solid fraction, and the squeeze compacts the ballast under the block.
    for name in TRACK_COLUMNS.iter().filter(|c| c.starts_with("compacity_")) {
        let c = s.values(name);
        assert!(
            c.iter().all(|&v| v > 0.1 && v < 0.74),
            "{name} out of (0.1, 0.74): {:?}",
            c.iter()
                .copied()
                .fold((1.0f64, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)))
        );
    }
    let under = s.values("compacity_under_block_1");
    eprintln!(
        "compacity under the block: {:.3} → {:.3}",
        under[0],
        under[n - 1]
    );
    // Measured +0.027 with force-limited tines (3.9 kN each); the kinematic tines they
    // replace gained more (+0.05 and beyond) by crushing whatever they met.
    assert!(
        under[n - 1] > under[0] + 0.015,
        "{} → {}",
        under[0],
        under[n - 1]
    );

    // Block centre: floor at z = 0, soffit at the ballast depth; lifted by `lift` during the
    // lift, held there until the release, then resting on the tamped ballast.
    let z0 = sc.track.depth + 0.5 * sc.track.block_size[2];
    let lift = sc.tamping.lift;
    let z = s.values("block_z_1_m");
    assert!(
        (-1e-9..1e-4).contains(&(z[0] - z0)),
        "z {} at step 1, z0 {z0}",
        z[0]
    );
    for k in 0..n {
        let t = time[k];
        if t <= sc.tamping.lift_time {
            assert!(
                z[k] >= z0 - 1e-9 && z[k] <= z0 + lift + 1e-9,
                "t {t}: z {}",
                z[k]
            );
            if k > 0 {
                assert!(z[k] >= z[k - 1] - 1e-12, "t {t}: lowered during the lift");
            }
        } else if t < cycle.release - 1e-9 {
            assert!((z[k] - z0 - lift).abs() < 1e-6, "t {t}: z {} held?", z[k]);
        } else {
            assert!(
                z[k] > z0 - 0.005 && z[k] < z0 + lift + 1e-3,
                "t {t}: released block at z {} (design {z0}, lift {lift})",
                z[k]
            );
        }
    }

    // The lifting unit's force on the block: none while it holds the block kinematically or
    // after the lowering; during it, within its bound falling from `lowering_force` to zero.
    let drive = s.values("block_drive_1_z_N");
    let (start, over) = (cycle.release, sc.tamping.lowering());
    let f0 = sc.tamping.lowering_force(&sc.track);
    let mut lowering_rows = 0;
    for k in 0..n {
        let t = time[k];
        if t <= start + 1e-9 || t > start + over + dt {
            assert_eq!(drive[k], 0.0, "t {t}: block drive {} N", drive[k]);
        } else {
            let bound = f0 * (1.0 - (t - start) / over).max(0.0);
            assert!(
                drive[k].abs() <= bound * (1.0 + 1e-9) + 1e-9,
                "t {t}: block drive {} N, bound {bound} N",
                drive[k]
            );
            lowering_rows += 1;
        }
    }
    assert!(lowering_rows > 0, "no row during the lowering");

    // Tine forces: finite, zero while the tines wait above the bed, and pushing them up
    // (on average) while they plunge into the ballast.
    for j in 1..=4 {
        let fx = s.values(&format!("tine_force_{j}_x_N"));
        let fz = s.values(&format!("tine_force_{j}_z_N"));
        let (mut up, mut rows) = (0.0, 0.0);
        for k in 0..n {
            assert!(fx[k].is_finite() && fz[k].is_finite());
            if time[k] <= p.insertion + 1e-9 {
                assert!(
                    fx[k] == 0.0 && fz[k] == 0.0,
                    "tine {j} loaded at t {} before the insertion",
                    time[k]
                );
            } else if time[k] <= p.squeeze {
                up += fz[k];
                rows += 1.0;
            }
        }
        eprintln!(
            "tine {j}: mean vertical force {:.1} kN during the insertion",
            up / rows * 1e-3
        );
        assert!(
            up / rows > 0.0,
            "tine {j}: mean vertical force {} N",
            up / rows
        );
    }
    // The work the unit reports is its drive force times the tine's travel, step by step
    // (rows are steps here; the tines neither move across the track nor turn).
    for j in 1..=4 {
        let work = s.values(&format!("tine_work_{j}_J"));
        let (fx, fz) = (
            s.values(&format!("tine_drive_{j}_x_N")),
            s.values(&format!("tine_drive_{j}_z_N")),
        );
        let (x, z) = (
            s.values(&format!("tine_travel_{j}_x_m")),
            s.values(&format!("tine_travel_{j}_z_m")),
        );
        let scale = work.iter().map(|w| w.abs()).fold(1.0, f64::max);
        for k in 1..n {
            let step = fx[k] * (x[k] - x[k - 1]) + fz[k] * (z[k] - z[k - 1]);
            assert!(
                (work[k] - work[k - 1] - step).abs() <= 1e-6 * scale,
                "tine {j}, row {k}: work grew by {} J, force × travel {step} J",
                work[k] - work[k - 1]
            );
        }
        eprintln!("tine {j}: work of the unit {:.1} J", work[n - 1]);
    }
    // The tamping unit's forces stay within its limits at every step; a tine below its limits
    // is where its program puts it, one that met more resistance lags behind (never ahead).
    let limits = [sc.tamping.squeeze_force, sc.tamping.insertion_force];
    for j in 1..=4 {
        for (axis, limit) in ["x", "z"].into_iter().zip(limits) {
            let drive = s.values(&format!("tine_drive_{j}_{axis}_N"));
            let peak = drive.iter().map(|f| f.abs()).fold(0.0, f64::max);
            assert!(
                peak <= limit * (1.0 + 1e-9),
                "tine {j} {axis}: drive force {peak} N > limit {limit} N"
            );
            let moved = s.values(&format!("tine_travel_{j}_{axis}_m"));
            let commanded = s.values(&format!("tine_travel_{j}_{axis}_command_m"));
            let lag = (0..n)
                .map(|k| (commanded[k] - moved[k]).abs())
                .fold(0.0, f64::max);
            eprintln!(
                "tine {j} {axis}: peak drive force {:.2} kN (limit {:.2}), largest lag {:.1} mm",
                peak * 1e-3,
                limit * 1e-3,
                lag * 1e3
            );
            for k in 0..n {
                if time[k] <= p.insertion + 1e-9 {
                    assert!(
                        (moved[k] - commanded[k]).abs() < 1e-9,
                        "tine {j} {axis} off its program before touching the ballast"
                    );
                }
            }
        }
    }
    let coord = s.values("coordination");
    assert!(coord.iter().all(|&v| (0.0..12.0).contains(&v)));
    assert!(
        (2.0..8.0).contains(&coord[0]),
        "coordination {} of the bed at rest",
        coord[0]
    );

    // summary.json agrees with the rows.
    let last = &s.rows[n - 1];
    assert_eq!(sum["steps"].as_u64().unwrap() as f64, last[0]);
    assert_eq!(
        num(&sum, "/contacts/max"),
        contacts.iter().copied().fold(0.0, f64::max)
    );
    assert!(close(
        num(&sum, "/contacts/mean"),
        contacts.iter().sum::<f64>() / n as f64,
        1e-12
    ));
    assert!(close(
        num(&sum, "/solver/mean_iterations"),
        iterations.iter().sum::<f64>() / n as f64,
        1e-12
    ));
    assert_eq!(
        num(&sum, "/solver/steps_not_converged"),
        converged.iter().filter(|&&c| c == 0.0).count() as f64
    );
    let residual = s.values("residual").into_iter().fold(0.0, f64::max);
    assert!(close(num(&sum, "/solver/max_residual"), residual, 1e-6));
    assert!(close(num(&sum, "/max_penetration"), max_pen, 1e-6));
    assert!(close(num(&sum, "/kinetic_energy"), ke[n - 1], 1e-9));
    let ind = sum["indicators"].as_object().unwrap();
    assert_eq!(ind.len(), TRACK_COLUMNS.len());
    for name in TRACK_COLUMNS {
        let v = ind[name].as_f64().unwrap();
        let row = last[s.col(name)];
        assert!(close(v, row, 1e-9), "{name}: summary {v}, last row {row}");
    }
}

/// `series.csv` of the straight and of the resumed run: units in the names, values that fit
/// the scenario's geometry and cycle, and the summary's numbers.
#[test]
fn track_series_has_units_and_sensible_values() {
    let r = runs();
    check_series(r, &r.straight);
    check_series(r, &r.chained);
}

/// The value of the report's results row `| label | value |`.
fn report_value(md: &str, label: &str) -> f64 {
    let prefix = format!("| {label} | ");
    let line = md
        .lines()
        .find(|l| l.starts_with(&prefix))
        .unwrap_or_else(|| panic!("report.md has no row {label:?}"));
    let cell = line[prefix.len()..].trim_end_matches(" |");
    cell.parse()
        .unwrap_or_else(|_| panic!("row {label:?}: {cell:?} is not a number"))
}

/// `report.md` of a track run: every figure, the compacity, tine-force and block ones among
/// them, is shown as PNG and linked as SVG, both files pass `figures::check` with their axis
/// labels; the straight and the resumed run draw the same bytes; the final indicators are
/// those of summary.json.
#[test]
fn track_report_plots_the_indicators() {
    let r = runs();
    for dir in [&r.chained, &r.straight] {
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        let sum = summary(dir).unwrap();
        let links: Vec<&str> = md
            .split("](plots/")
            .skip(1)
            .map(|s| &s[..s.find(')').unwrap()])
            .collect();
        let x = "time (s)";
        for (name, labels) in [
            (
                "compacity",
                &[x, "compacity (-)", "under block 1", "crib 0"][..],
            ),
            ("tines", &[x, "tine 1 x", "tine 4 z"]),
            ("blocks", &[x, "block height z (mm)"]),
            ("coordination", &[x, "contacts per grain (-)"]),
            ("tine_work", &[x, "work (J)", "tine 1"]),
            ("block_drives", &[x, "drive force (N)"]),
            (
                "solver",
                &[x, "contacts (-)", "iterations (-)", "residual (-)"],
            ),
            ("energy", &[x, "kinetic energy (J)"]),
            ("penetration", &[x, "max interpenetration (mm)"]),
            ("timings", &[x, "time per step (ms)", "detection"]),
            ("phases", &["wall-clock time (s)", "detection", "other"]),
        ] {
            for ext in ["png", "svg"] {
                let file = format!("{name}.{ext}");
                assert!(
                    links.contains(&file.as_str()),
                    "report.md does not link {file}"
                );
            }
            figures::check(&dir.join("plots"), name, labels);
        }
        for caption in [
            "Compacity per control volume",
            "Tine forces",
            "Block position",
        ] {
            assert!(md.contains(caption), "no {caption:?} in report.md");
        }
        // The final indicators, to the report's 4 significant digits.
        let ind = &sum["indicators"];
        let f = |name: &str| ind[name].as_f64().unwrap();
        for (label, value) in [
            (
                "final compacity, under block 1 (-)",
                f("compacity_under_block_1"),
            ),
            ("final compacity, crib 0 (-)", f("compacity_crib_0")),
            ("final compacity, crib 1 (-)", f("compacity_crib_1")),
            ("final block height z, block 1 (mm)", 1e3 * f("block_z_1_m")),
        ] {
            let shown = report_value(&md, label);
            assert!(
                close(shown, value, 1e-3),
                "{label}: {shown}, summary {value}"
            );
        }
        for j in 1..=4 {
            for axis in ["x", "z"] {
                let v = f(&format!("tine_force_{j}_{axis}_N"));
                let label = |unit: &str| format!("final tine force, tine {j} {axis} ({unit})");
                // kN when the column reaches 1 kN, as the plot's axis.
                let shown = if md.contains(&format!("| {} |", label("kN"))) {
                    1e3 * report_value(&md, &label("kN"))
                } else {
                    report_value(&md, &label("N"))
                };
                assert!(
                    close(shown, v, 1e-3) || (shown - v).abs() < 1.0,
                    "tine {j} {axis}: report {shown} N, summary {v} N"
                );
            }
        }
        // Nothing but linked figures in plots/.
        for e in std::fs::read_dir(dir.join("plots")).unwrap() {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            assert!(
                links.contains(&name.as_str()),
                "plots/{name} is not in report.md"
            );
        }
    }
    // Same scenario, same state at every row: the same figures, byte for byte (those that do
    // not show wall-clock times), though one run was stopped and resumed twice.
    figures::same(
        &r.chained.join("plots"),
        &r.straight.join("plots"),
        &figures::DETERMINISTIC,
    );
}

/// A section file as `(grain, u, z, speed, load)` rows.
fn section(path: &Path) -> Vec<[f64; 5]> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(ballast_railway::sections::SECTION_HEADER)
    );
    lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4]]
        })
        .collect()
}

/// The sections of the whole cycle: the prepared bed, the end of the squeeze and after the
/// release, through a tine row and the block's axis; the same bytes for the straight and the
/// resumed run; the bed at rest carries more load at its bottom than at its top (its
/// weight); the squeeze loads the tine plane more than the bed at rest; the report draws
/// each section coloured by load, and the end of the squeeze by speed too.
#[test]
fn track_run_writes_sections_through_the_bed() {
    let r = runs();
    let (straight, chained) = (r.straight.join("sections"), r.chained.join("sections"));
    let moments = ["start", "end-of-squeeze-1", "after-release"];
    let planes = ["tine-plane", "block-axis"];
    let track = &r.scenario.track;
    for m in moments {
        for p in planes {
            let name = format!("{m}_{p}.csv");
            let a = std::fs::read(straight.join(&name)).unwrap();
            let b = std::fs::read(chained.join(&name)).unwrap();
            assert!(
                a == b,
                "{name} differs between the straight and the resumed run"
            );
            let rows = section(&straight.join(&name));
            assert!(rows.len() >= 10, "{name}: {} grains", rows.len());
            for row in &rows {
                let [_, u, z, speed, load] = *row;
                let half = if p == "tine-plane" {
                    track.length()
                } else {
                    0.5 * track.width
                };
                assert!(
                    u.abs() <= half + 0.05 && u > -half - 0.05,
                    "{name}: u = {u}"
                );
                // A grain carrying load lies in the bed; one without may be in flight: the
                // tines squeeze a grain out of this small bed at 2.4 m/s, which rises 0.29 m
                // above where it left the bed (z = 0.375 m at the end of the squeeze).
                let ceiling = if load > 0.0 { 0.05 } else { 0.5 };
                assert!(
                    z > 0.0 && z < track.top() + ceiling,
                    "{name}: z = {z}, load {load} N"
                );
                assert!(speed.is_finite() && speed >= 0.0 && load >= 0.0, "{name}");
            }
        }
    }
    // The bed at rest: the lower half of the section carries more than the upper half.
    let rest = section(&straight.join("start_tine-plane.csv"));
    let zs: Vec<f64> = rest.iter().map(|r| r[2]).collect();
    let mid = 0.5
        * (zs.iter().cloned().fold(f64::MAX, f64::min)
            + zs.iter().cloned().fold(f64::MIN, f64::max));
    let mean = |lower: bool| {
        let v: Vec<f64> = rest
            .iter()
            .filter(|r| (r[2] < mid) == lower)
            .map(|r| r[4])
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    assert!(
        mean(true) > mean(false),
        "lower half {} N, upper {} N",
        mean(true),
        mean(false)
    );
    // Squeezed: the tines push into the bed, and the section carries more than at rest
    // (measured: 442 N at rest, 576 N at the end of the squeeze).
    let total = |f: &str| section(&straight.join(f)).iter().map(|r| r[4]).sum::<f64>();
    let (start, squeezed) = (
        total("start_tine-plane.csv"),
        total("end-of-squeeze-1_tine-plane.csv"),
    );
    assert!(
        squeezed > 1.1 * start,
        "section load {start} N at rest, {squeezed} N squeezed"
    );
    let plots = r.straight.join("plots");
    let md = std::fs::read_to_string(r.straight.join("report.md")).unwrap();
    for m in moments {
        for p in planes {
            let name = format!("section_{m}_{p}_load");
            assert!(
                md.contains(&format!("plots/{name}.png")),
                "report.md lacks {name}"
            );
            figures::check(&plots, &name, &["z (m)", "log10 of the load carried (N)"]);
        }
    }
    // The cycle's moments in the summary, and the compacity table they give in the report.
    let sum = summary(&r.straight).unwrap();
    let cycle = r.scenario.tamping.build(track);
    let end = sum["cycle"]["blocks"][0]["end_s"].as_f64().unwrap();
    assert_eq!(sum["cycle"]["blocks"][0]["block"], 1);
    assert!(close(end, cycle.phases[0].end, 1e-12), "{end}");
    assert!(md.contains("## Compacity under each block, cycle by cycle"));
    assert!(
        md.contains("| after tamping block 1 (t = "),
        "no row after block 1"
    );
    for p in planes {
        let name = format!("section_end-of-squeeze-1_{p}_speed");
        figures::check(&plots, &name, &["z (m)", "speed (m/s)"]);
    }
}

/// `ballast bench --paper` on this file's bed (read from the fixture's cache): the contract's
/// JSON, exactly 740 sweeps per step at the paper's stop, at most the scenario's cap at its
/// tolerance stop, the same work on 1 and 2 threads, and the preparation's recorded time.
#[test]
fn paper_bench_times_the_cycle_at_740_sweeps_and_at_the_tolerance_stop() {
    let r = runs();
    let root = r.chained.parent().unwrap();
    let json = root.join("paper.json");
    let out = Command::new(env!("CARGO_BIN_EXE_ballast"))
        .args(["bench", "--paper", "--quiet", "--steps", "2"])
        .args(["--thread-counts", "1,2", "--bed"])
        .arg(root.join("track.toml"))
        .arg("--cache")
        .arg(root.join("cache"))
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("ms/step") && stdout.contains("tolerance"),
        "{stdout}"
    );
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let cases = v["cases"].as_array().unwrap();
    let order: Vec<(&str, u64)> = cases
        .iter()
        .map(|c| (c["stop"].as_str().unwrap(), c["threads"].as_u64().unwrap()))
        .collect();
    assert_eq!(
        order,
        [("740", 1), ("740", 2), ("tolerance", 1), ("tolerance", 2)]
    );
    let prep = summary(&r.straight).unwrap()["preparation"]["wall_s"]
        .as_f64()
        .unwrap();
    let grains = summary(&r.straight).unwrap()["preparation"]["grains"]
        .as_u64()
        .unwrap();
    let cap = r.scenario.solver.max_iterations as f64;
    for c in cases {
        for key in [
            "name",
            "grains",
            "threads",
            "contact_points",
            "ms_per_step",
            "sweeps_per_step",
            "contact_updates_per_s",
            "stop",
            "preparation_s",
            "peak_rss_bytes",
            "timings_s",
        ] {
            assert!(!c[key].is_null(), "{key} missing in {c}");
        }
        for key in [
            "detection",
            "nlgs",
            "subdomains",
            "interface",
            "other",
            "total",
        ] {
            assert!(c["timings_s"][key].as_f64().unwrap() >= 0.0, "{c}");
        }
        assert_eq!(c["grains"].as_u64().unwrap(), grains);
        assert_eq!(c["preparation_s"].as_f64().unwrap(), prep);
        assert!(c["contact_points"].as_f64().unwrap() > grains as f64, "{c}");
        assert!(c["ms_per_step"].as_f64().unwrap() > 0.0, "{c}");
        assert!(c["peak_rss_bytes"].as_u64().unwrap() > 1 << 20, "{c}");
        let sweeps = c["sweeps_per_step"].as_f64().unwrap();
        if c["stop"] == "740" {
            assert_eq!(sweeps, 740.0, "{c}");
            assert_eq!(c["steps_not_converged"].as_u64().unwrap(), 2, "{c}");
        } else {
            assert!(sweeps >= 1.0 && sweeps <= cap, "{c}");
        }
    }
    // Thread counts time the same work.
    for pair in cases.chunks(2) {
        for key in ["contact_points", "sweeps_per_step", "steps_not_converged"] {
            assert_eq!(pair[0][key], pair[1][key], "{key}: {pair:?}");
        }
    }
    let bad = Command::new(env!("CARGO_BIN_EXE_ballast"))
        .args(["bench", "--paper", "--bed", "no-such-preset", "--quiet"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && err.contains("--bed no-such-preset"),
        "{err}"
    );
}
