//! The `ballast` command: outputs, the summary contract, bit-identical reruns, clear errors.

use std::path::PathBuf;
use std::process::Command;

mod common;
mod figures;

use common::{
    checkpoint_steps, last_row, rows_without_timings, summary, summary_without_timings, tmp_files,
    Moments,
};

fn ballast() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ballast"))
}

fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

/// A scratch folder, removed when the test is done with it (kept when the test fails, to look
/// at).
struct TmpDir(PathBuf);

impl Drop for TmpDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl AsRef<std::path::Path> for TmpDir {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl std::ops::Deref for TmpDir {
    type Target = PathBuf;
    fn deref(&self) -> &PathBuf {
        &self.0
    }
}

fn tmp(name: &str) -> TmpDir {
    let d = std::env::temp_dir().join(format!("ballast-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    TmpDir(d)
}

#[test]
fn run_writes_summary_and_series_and_is_reproducible() {
    let (a, b) = (tmp("a"), tmp("b"));
    for (dir, threads) in [(&a, "1"), (&b, "2")] {
        let st = ballast()
            .args([
                "run",
                example("pile.toml").to_str().unwrap(),
                "--steps",
                "60",
                "--quiet",
            ])
            .args(["--threads", threads, "--out", dir.to_str().unwrap()])
            .status()
            .unwrap();
        assert!(st.success());
    }
    let (sa, sb) = (summary(&a), summary(&b));
    for key in [
        "steps",
        "bodies",
        "threads",
        "subdomains",
        "timings_s",
        "contacts",
        "solver",
        "state_digest",
    ] {
        assert!(sa.get(key).is_some(), "summary.json lacks {key}");
    }
    for key in ["detection", "nlgs", "other", "total"] {
        assert!(sa["timings_s"][key].as_f64().unwrap() >= 0.0);
    }
    assert_eq!(sa["steps"], 60);
    assert_eq!(sa["status"], "completed");
    assert_eq!(sa["bodies"], 305);
    // Same scene, 1 or 2 threads: bit-identical final state.
    assert_eq!(sa["state_digest"], sb["state_digest"]);
    let csv = std::fs::read_to_string(a.join("series.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].starts_with("step,time_s,contacts,iterations"));
    assert_eq!(lines.len(), 1 + 2, "rows at steps 50 and 60");
    // The report's figures, each as PNG (shown) and SVG (linked), with their axis labels; the
    // same bytes for both runs but where they show wall-clock times.
    let md = std::fs::read_to_string(a.join("report.md")).unwrap();
    let x = "time (s)";
    for (name, labels) in [
        (
            "solver",
            &[x, "contacts (-)", "iterations (-)", "residual (-)"][..],
        ),
        ("energy", &[x, "kinetic energy (J)"]),
        ("penetration", &[x, "max interpenetration (mm)"]),
        ("timings", &[x, "time per step (ms)", "nlgs"]),
        ("phases", &["wall-clock time (s)", "detection"]),
    ] {
        assert!(
            md.contains(&format!("](plots/{name}.png)")),
            "no {name}.png"
        );
        assert!(
            md.contains(&format!("](plots/{name}.svg)")),
            "no link to {name}.svg"
        );
        figures::check(&a.join("plots"), name, labels);
    }
    let drawn: Vec<&str> = figures::DETERMINISTIC
        .into_iter()
        .filter(|n| a.join("plots").join(format!("{n}.svg")).exists())
        .collect();
    assert_eq!(drawn, ["solver", "energy", "penetration"]);
    figures::same(&a.join("plots"), &b.join("plots"), &drawn);
}

#[test]
fn bad_input_is_one_clear_error() {
    let dir = tmp("bad");
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("bad.toml");
    let text = std::fs::read_to_string(example("pile.toml"))
        .unwrap()
        .replace("dt = 2e-4", "dt = 0");
    std::fs::write(&f, text).unwrap();
    let out = ballast()
        .args(["run", f.to_str().unwrap(), "--out"])
        .arg(dir.join("o"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("simulation.dt") && err.contains("(0, 0.1]"),
        "{err}"
    );
    assert!(
        !err.contains("panicked") && !err.contains("backtrace"),
        "{err}"
    );
    let out = ballast()
        .args(["run", "/nonexistent.toml"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot read scenario"));
}

/// `--steps 700 --out D` then `--steps 900 --resume D` ends bit-identical to one `--steps 900`
/// run (contacts and warm start included), and series.csv has the same rows.
#[test]
fn resumed_run_is_bit_identical() {
    let (d, e) = (tmp("resume-d"), tmp("resume-e"));
    let f = example("pile.toml");
    let run = |args: &[&str]| {
        let st = ballast()
            .arg("run")
            .arg(&f)
            .args(args)
            .arg("--quiet")
            .status()
            .unwrap();
        assert!(st.success(), "{args:?}");
    };
    run(&["--steps", "700", "--out", d.to_str().unwrap()]);
    run(&["--steps", "900", "--resume", d.to_str().unwrap()]);
    run(&["--steps", "900", "--out", e.to_str().unwrap()]);
    let (sd, se) = (summary(&d), summary(&e));
    assert!(
        se["contacts"]["max"].as_u64().unwrap() > 10,
        "the run should have contacts"
    );
    assert_eq!(sd["state_digest"], se["state_digest"]);
    assert_eq!(sd["steps"], 900);
    assert_eq!(sd["contacts"], se["contacts"]);
    let rows = |dir: &std::path::Path| -> Vec<String> {
        std::fs::read_to_string(dir.join("series.csv"))
            .unwrap()
            .lines()
            .map(|l| l.split(',').take(9).collect::<Vec<_>>().join(","))
            .collect()
    };
    assert_eq!(rows(&d), rows(&e));
    // Damaged checkpoints: a clear error, no panic.
    for entry in std::fs::read_dir(d.join("checkpoints")).unwrap() {
        let p = entry.unwrap().path();
        let mut bytes = std::fs::read(&p).unwrap();
        let mid = bytes.len() / 2;
        bytes[mid] ^= 0xff;
        std::fs::write(&p, bytes).unwrap();
    }
    let out = ballast()
        .arg("run")
        .arg(&f)
        .args(["--steps", "1000", "--resume", d.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no valid checkpoint") && !err.contains("panicked"),
        "{err}"
    );
}

/// Track scenarios and presets: a bad field or preset name is one clear error, before any
/// preparation; the resolved preset reads back as a valid track scenario.
#[test]
fn bad_track_input_is_one_clear_error() {
    let dir = tmp("badtrack");
    std::fs::create_dir_all(&dir).unwrap();
    for (text, field) in [
        ("[track]\nblocks = 0\n", "track.blocks"),
        ("[track]\nspacing = 0.1\n", "track.spacing"),
        ("[track]\n[tamping]\nfrequency = -35\n", "tamping.frequency"),
        ("[track]\n[tamping]\nblocks = [3]\n", "tamping.blocks"),
        (
            "[track]\n[ballast]\ngrading = \"10/20\"\n",
            "ballast.grading",
        ),
        (
            "[track]\n[preparation]\ncompacity = 0.9\n",
            "preparation.compacity",
        ),
        ("[track]\nwidht = 2\n", "widht"),
    ] {
        let f = dir.join("t.toml");
        std::fs::write(&f, text).unwrap();
        let out = ballast()
            .args(["run", f.to_str().unwrap(), "--no-cache", "--out"])
            .arg(dir.join("o"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{text}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(field), "{text}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(
            err.lines().filter(|l| l.starts_with("error")).count(),
            1,
            "{err}"
        );
    }
    let out = ballast()
        .args(["run", "--preset", "nope", "--out"])
        .arg(dir.join("o"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--preset") && err.contains("default, paper"),
        "{err}"
    );
    for p in ["default", "paper"] {
        let s = ballast_railway::TrackScenario::preset(p).unwrap();
        let back = ballast_railway::TrackScenario::from_toml(&s.to_toml()).unwrap();
        assert_eq!(back, s, "{p}");
    }
}

/// `bench --scaling --thread-counts`: the listed counts are timed (with 1 added, the speedup's
/// base) for every configuration; a count of 0 is one clear error.
#[test]
fn scaling_study_times_the_listed_thread_counts() {
    let dir = tmp("scaling");
    std::fs::create_dir_all(&dir).unwrap();
    let json = dir.join("s.json");
    let out = ballast()
        .args([
            "bench",
            "--scaling",
            "--grains",
            "150",
            "--settle-steps",
            "5",
        ])
        .args(["--steps", "2", "--sweeps", "5", "--partitions", "2x1x1"])
        .args([
            "--thread-counts",
            "3,2",
            "--min-parallel-contacts",
            "0",
            "--json",
        ])
        .arg(&json)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cases: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows: Vec<(String, u64, f64)> = cases
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            (
                c["subdomains"].as_str().unwrap().to_string(),
                c["threads"].as_u64().unwrap(),
                c["speedup"].as_f64().unwrap(),
            )
        })
        .collect();
    let threads: Vec<(&str, u64)> = rows.iter().map(|(s, t, _)| (s.as_str(), *t)).collect();
    assert_eq!(
        threads,
        [
            ("1x1x1", 1),
            ("1x1x1", 2),
            ("1x1x1", 3),
            ("2x1x1", 1),
            ("2x1x1", 2),
            ("2x1x1", 3)
        ]
    );
    assert!(rows.iter().filter(|r| r.1 == 1).all(|r| r.2 == 1.0));
    // The plots beside the JSON, each as SVG and PNG.
    let plots = dir.join("s_plots");
    figures::check(
        &plots,
        "speedup",
        &["threads", "speedup T1/Tp (-)", "ideal", "DDM 2x1x1"],
    );
    figures::check(
        &plots,
        "efficiency",
        &["threads", "efficiency speedup/threads (%)", "NLGS"],
    );
    figures::check(
        &plots,
        "timings",
        &[
            "wall-clock time over the timed steps (s)",
            "detection",
            "3 thr.",
        ],
    );
    let out = ballast()
        .args(["bench", "--scaling", "--thread-counts", "2,0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--thread-counts") && err.contains("≥ 1"),
        "{err}"
    );
}

/// `examples/pile.toml` with `replace` applied (each pair, which must occur), written to
/// `dir/name`.
fn pile_variant(dir: &std::path::Path, name: &str, replace: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(example("pile.toml")).unwrap();
    for (a, b) in replace {
        assert!(text.contains(a), "{a}");
        text = text.replacen(a, b, 1);
    }
    std::fs::create_dir_all(dir).unwrap();
    let f = dir.join(name);
    std::fs::write(&f, text).unwrap();
    f
}

/// A diverging run stops at once with exit code 3, names the step, the body, its group and the
/// quantity, writes `summary.json` with `"status": "diverged"` (infinite numbers as strings,
/// not `null`) and no checkpoint of the diverged state; a normal run says `"completed"`.
#[test]
fn diverging_runs_stop_with_exit_code_3() {
    let dir = tmp("diverge");
    let gravity = pile_variant(
        &dir,
        "gravity.toml",
        &[("gravity = [0, 0, -9.81]", "gravity = [0, 0, -1e200]")],
    );
    // A box above the grains' lattice, thrown sideways: nothing to hit in its first steps.
    let thrown = pile_variant(
        &dir,
        "thrown.toml",
        &[(
            "[[grains]]",
            "[[body]]\nshape = \"box\"\ngroup = \"projectile\"\nmaterial = \"stone\"\n\
             half_extents = [0.02, 0.02, 0.02]\ncenter = [0.1, 0.1, 5]\n\
             velocity = [1e12, 0, 0]\n\n[[grains]]",
        )],
    );
    // The thrown box is named before the first step, not the grains it would launch.
    for (file, step, body, value) in [
        (&gravity, 1, "group \"grain\"", "2.000e196 m/s"),
        (&thrown, 0, "body 5 (group \"projectile\")", "1.000e12 m/s"),
    ] {
        let out_dir = dir.join(file.file_stem().unwrap());
        let start = std::time::Instant::now();
        let out = ballast()
            .arg("run")
            .arg(file)
            .arg("--out")
            .arg(&out_dir)
            .arg("--quiet")
            .output()
            .unwrap();
        let elapsed = start.elapsed().as_secs_f64();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(3), "{err}");
        let at = match step {
            0 => "the initial state (step 0) is out of bounds",
            _ => "diverged at step 1 ",
        };
        for part in [at, body, value, "no checkpoint was written"] {
            assert!(err.contains(part), "{part}: {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(elapsed < 10.0, "{elapsed} s");
        let s = summary(&out_dir);
        assert_eq!(s["status"], "diverged");
        assert_eq!(s["steps"], step);
        assert_eq!(s["divergence"]["step"], step);
        assert_eq!(s["divergence"]["quantity"], "speed");
        assert!(s["divergence"]["message"].as_str().unwrap().contains(body));
        assert_eq!(checkpoint_steps(&out_dir), Vec::<u64>::new());
        // The diverged step's row is written: the last thing the run saw. Infinite kinetic
        // energy is written as such, never as null.
        let csv = std::fs::read_to_string(out_dir.join("series.csv")).unwrap();
        let last = csv.lines().last().unwrap();
        if step == 1 {
            assert!(last.starts_with("1,"), "{csv}");
            assert_eq!(s["kinetic_energy"], "inf", "{}", s["kinetic_energy"]);
        } else {
            assert!(last.starts_with("step,"), "{csv}");
        }
    }

    // `max_speed = 0.5` m/s: the falling grains pass it at step 255 (9.81 m/s² × 255 × 2e-4
    // s = 0.5003 m/s); the checkpoints up to step 250 are kept, none after, and a resume
    // diverges again at the same step.
    let slow = pile_variant(
        &dir,
        "slow.toml",
        &[(
            "output_interval = 50",
            "output_interval = 50\ncheckpoint_interval = 50\nmax_speed = 0.5",
        )],
    );
    let d = dir.join("slow");
    for resume in [false, true] {
        let mut cmd = ballast();
        cmd.arg("run").arg(&slow).arg("--quiet");
        cmd.arg(if resume { "--resume" } else { "--out" }).arg(&d);
        let out = cmd.output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(3), "{err}");
        assert!(
            err.contains("diverged at step 255 ")
                && err.contains("more than the bound 0.5 m/s (set by [simulation] max_speed)")
                && err.contains("its last checkpoint (step 250) is kept"),
            "{err}"
        );
        assert_eq!(checkpoint_steps(&d), [150, 200, 250]);
        assert_eq!(summary(&d)["divergence"]["step"], 255);
    }
}

/// Runs `ballast run ARGS --quiet`: (exit code, stderr).
fn run_args(args: &[&std::ffi::OsStr]) -> (Option<i32>, String) {
    let out = ballast()
        .arg("run")
        .args(args)
        .arg("--quiet")
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A folder holding a run is refused to another run (unless `--overwrite`, which leaves a
/// clean folder: the same result as a fresh one), and a checkpoint never resumes under a
/// scenario that started from another state, even with the same bodies.
#[test]
fn run_folders_belong_to_one_run() {
    let dir = tmp("owned");
    let a = example("pile.toml");
    // Same bodies, the grains 1 mm higher: same scene, another initial state.
    let b = pile_variant(
        &dir,
        "b.toml",
        &[("min = [0, 0, 0.002]", "min = [0, 0, 0.003]")],
    );
    let (d, e) = (dir.join("d"), dir.join("e"));
    let os = |s: &str| std::ffi::OsString::from(s);
    let steps = [os("--steps"), os("10")];
    let args = |file: &PathBuf, flag: &str, folder: &PathBuf, more: &[&str]| {
        let mut v: Vec<std::ffi::OsString> =
            vec![file.clone().into(), os(flag), folder.clone().into()];
        v.extend(steps.iter().cloned());
        v.extend(more.iter().map(|s| os(s)));
        v
    };
    let call = |v: Vec<std::ffi::OsString>| {
        let refs: Vec<&std::ffi::OsStr> = v.iter().map(|s| s.as_os_str()).collect();
        run_args(&refs)
    };
    assert_eq!(call(args(&a, "--out", &d, &[])).0, Some(0));
    let digest_a = summary(&d)["state_digest"].clone();
    // Another run into the same folder: refused, the folder untouched.
    let (code, err) = call(args(&b, "--out", &d, &[]));
    assert_eq!(code, Some(1), "{err}");
    for part in [
        "holds another run",
        "scenario.toml",
        "1 checkpoint(s)",
        "--resume",
        "--overwrite",
    ] {
        assert!(err.contains(part), "{part}: {err}");
    }
    assert_eq!(summary(&d)["state_digest"], digest_a);
    // The same scenario again is refused too: a folder is one run.
    assert_eq!(call(args(&a, "--out", &d, &[])).0, Some(1));
    // --overwrite: the folder now holds B alone, as a fresh folder would.
    std::fs::write(d.join("notes.txt"), "mine").unwrap();
    assert_eq!(call(args(&b, "--out", &d, &["--overwrite"])).0, Some(0));
    assert_eq!(call(args(&b, "--out", &e, &[])).0, Some(0));
    assert_eq!(summary(&d)["state_digest"], summary(&e)["state_digest"]);
    assert_ne!(summary(&d)["state_digest"], digest_a);
    // Same rows (the last columns are wall-clock times).
    let rows = |dir: &PathBuf| -> Vec<String> {
        std::fs::read_to_string(dir.join("series.csv"))
            .unwrap()
            .lines()
            .map(|l| l.split(',').take(9).collect::<Vec<_>>().join(","))
            .collect()
    };
    assert_eq!(rows(&d), rows(&e));
    assert_eq!(checkpoint_steps(&d), [10]);
    assert_eq!(
        std::fs::read_to_string(d.join("notes.txt")).unwrap(),
        "mine",
        "--overwrite deletes the run's files only"
    );
    // B's checkpoints under A's scenario.toml: refused, naming the initial state.
    std::fs::copy(&a, d.join("scenario.toml")).unwrap();
    let (code, err) = call(vec![
        os("--resume"),
        d.clone().into(),
        os("--steps"),
        os("20"),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("another initial state"), "{err}");
    assert_eq!(checkpoint_steps(&d), [10]);
}

/// A resume keeps every row up to its checkpoint whatever happens next: killed before its
/// next checkpoint, the rows it had computed are there too (flushed as written).
#[test]
fn a_killed_resume_keeps_the_history() {
    let d = tmp("killed");
    let f = example("pile.toml");
    let st = ballast()
        .arg("run")
        .arg(&f)
        .args(["--steps", "700", "--quiet", "--out"])
        .arg(d.as_path())
        .status()
        .unwrap();
    assert!(st.success());
    let before = std::fs::read_to_string(d.join("series.csv")).unwrap();
    assert_eq!(before.lines().count(), 1 + 14, "rows at 50, 100, …, 700");
    // The scenario's next checkpoint would be at step 1000.
    let mut child = ballast()
        .arg("run")
        .arg(&f)
        .args(["--steps", "100000", "--quiet", "--resume"])
        .arg(d.as_path())
        .spawn()
        .unwrap();
    let last_step = |text: &str| -> u64 {
        text.lines()
            .last()
            .and_then(|l| l.split(',').next())
            .and_then(|s| s.parse().ok())
            .unwrap_or(0)
    };
    let start = std::time::Instant::now();
    let mut seen = 0;
    while seen <= 700 && start.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(5));
        seen = last_step(&std::fs::read_to_string(d.join("series.csv")).unwrap_or_default());
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let after = std::fs::read_to_string(d.join("series.csv")).unwrap();
    let n = last_step(&after);
    assert!(
        n > 700 && n < 1000,
        "a row after step 700 should be on disk before the checkpoint at 1000: last row {n}"
    );
    assert!(after.starts_with(&before), "rows up to the checkpoint lost");
    assert_eq!(checkpoint_steps(&d), [700]);
}

/// `--subdomains` is part of the run: a plain `--resume` continues it; a resume asking for
/// fewer steps than are done, `--steps 1e3` and an absurd `--threads` are clear errors.
#[test]
fn resume_flags_are_checked() {
    let d = tmp("flags");
    let f = example("pile.toml");
    let run = |args: &[&str]| -> (Option<i32>, String) {
        let out = ballast()
            .arg("run")
            .args(args)
            .arg("--quiet")
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (f, ds) = (f.to_str().unwrap(), d.to_str().unwrap());
    let (code, err) = run(&[f, "--steps", "30", "--subdomains", "2x2x1", "--out", ds]);
    assert_eq!(code, Some(0), "{err}");
    let (code, err) = run(&["--resume", ds, "--steps", "40"]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(summary(&d)["subdomains"], "2x2x1");
    assert_eq!(summary(&d)["steps"], 40);
    let (code, err) = run(&["--resume", ds, "--steps", "3"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("--steps asks for 3 steps") && err.contains("already at step 40"),
        "{err}"
    );
    assert_eq!(summary(&d)["steps"], 40);
    let (code, err) = run(&[f, "--steps", "1e3", "--out", ds]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--steps") && err.contains("whole number"),
        "{err}"
    );
    let sub = tmp("flags-sub");
    let (code, err) = run(&[
        f,
        "--subdomains",
        "4096x4096x1",
        "--out",
        sub.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("--subdomains: subdomains = 4096x4096x1 (16777216 subdomains) for 300 grains"),
        "{err}"
    );
    let start = std::time::Instant::now();
    let (code, err) = run(&[f, "--threads", "100000", "--out", ds]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--threads = 100000: must be at most"), "{err}");
    assert!(start.elapsed().as_secs() < 10);
}

/// Bodies placed inside each other, or under the floor, are refused before the first step
/// (exit 3, both named; the initial bound is the smaller inradius); a small initial overlap is
/// a warning naming the bodies, and the run goes on.
#[test]
fn initial_overlaps_are_named() {
    let dir = tmp("initial");
    let cube = |z: &str| {
        format!(
            "[[body]]\nshape = \"box\"\ngroup = \"block\"\nmaterial = \"stone\"\n\
             half_extents = [0.02, 0.02, 0.02]\ncenter = [0.1, 0.1, {z}]\n\n"
        )
    };
    let same = pile_variant(
        &dir,
        "same.toml",
        &[(
            "[[grains]]",
            &format!("{}{}[[grains]]", cube("5"), cube("5.001")),
        )],
    );
    let (code, err) = run_args(&[
        same.as_os_str(),
        "--out".as_ref(),
        dir.join("s").as_os_str(),
    ]);
    assert_eq!(code, Some(3), "{err}");
    assert!(
        err.contains(
            "the initial state (step 0) is out of bounds: body 5 (group \"block\") and body 6 \
             (group \"block\") overlap by 39 mm, more than the bound 20 mm (1 × the smaller \
             inradius"
        ) && err.contains("initial positions"),
        "{err}"
    );
    let mild = pile_variant(
        &dir,
        "mild.toml",
        &[(
            "[[grains]]",
            &format!("{}{}[[grains]]", cube("5"), cube("5.035")),
        )],
    );
    let (code, err) = run_args(&[
        mild.as_os_str(),
        "--steps".as_ref(),
        "3".as_ref(),
        "--out".as_ref(),
        dir.join("m").as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains(
            "warning: bodies 5 (group \"block\") and 6 (group \"block\") overlap by 5 mm at \
             the start"
        ),
        "{err}"
    );
    // Under the floor: inside the floor's half-space, named twice.
    let under = pile_variant(
        &dir,
        "under.toml",
        &[("[[grains]]", &format!("{}[[grains]]", cube("-10")))],
    );
    let (code, err) = run_args(&[
        under.as_os_str(),
        "--out".as_ref(),
        dir.join("u").as_os_str(),
    ]);
    assert_eq!(code, Some(3), "{err}");
    for part in [
        "warning: body 5 (group \"block\") lies wholly beneath the plane of body 0 (group \"wall\"), its centre 10 m under it",
        "out of bounds: body 0 (group \"wall\") and body 5 (group \"block\") overlap by 10020 mm",
    ] {
        assert!(err.contains(part), "{part}: {err}");
    }
}

/// A 5 MB value in a scenario is not echoed whole: the message's lines are cut, saying so.
#[test]
fn huge_values_are_cut_in_messages() {
    let dir = tmp("huge");
    let huge = format!("dt = \"{}\"", "9".repeat(5_000_000));
    let f = pile_variant(&dir, "huge.toml", &[("dt = 2e-4", &huge)]);
    let (code, err) = run_args(&[f.as_os_str(), "--out".as_ref(), dir.join("o").as_os_str()]);
    assert_eq!(code, Some(1));
    assert!(err.len() < 5_000, "{} bytes of message", err.len());
    assert!(
        err.contains("more characters") && err.contains("dt"),
        "{err}"
    );
}

/// A driver's sine sampled too coarsely by the time step is a warning naming the body, the
/// term and the time step needed.
#[test]
fn coarsely_sampled_drivers_are_warned() {
    let dir = tmp("sine");
    let text = std::fs::read_to_string(example("sliding_block.toml"))
        .unwrap()
        .replace("frequency = 5.0", "frequency = 1e5");
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("s.toml");
    std::fs::write(&f, text).unwrap();
    let (code, err) = run_args(&[
        f.as_os_str(),
        "--steps".as_ref(),
        "2".as_ref(),
        "--out".as_ref(),
        dir.join("o").as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("warning: body 2 (group \"paddle\") driver vx[1]: sine at 100000 Hz, 0.050 steps per period at dt = 0.0002 s")
            && err.contains("use dt ≤ 2.5e-6 s"),
        "{err}"
    );
    // At 5 Hz (1000 steps per period): no warning.
    let (code, err) = run_args(&[
        example("sliding_block.toml").as_os_str(),
        "--steps".as_ref(),
        "2".as_ref(),
        "--out".as_ref(),
        dir.join("p").as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("sine"), "{err}");
}

/// Ctrl-C (SIGINT) stops a run after a whole step with exit code 130, a checkpoint of that
/// step and `"status": "interrupted"`; resuming it ends bit-identical to a run never stopped.
#[cfg(unix)]
#[test]
fn ctrl_c_checkpoints_and_resumes() {
    let (d, e) = (tmp("sigint-d"), tmp("sigint-e"));
    let f = example("pile.toml");
    let mut child = ballast()
        .arg("run")
        .arg(&f)
        .args(["--quiet", "--out"])
        .arg(d.as_path())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !std::fs::read_to_string(d.join("series.csv"))
        .unwrap_or_default()
        .contains("\n100,")
        && start.elapsed().as_secs() < 60
    {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let st = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let code = child.wait().unwrap().code();
    assert_eq!(code, Some(130));
    let s = summary(&d);
    assert_eq!(s["status"], "interrupted");
    let at = s["steps"].as_u64().unwrap();
    assert!((100..7500).contains(&at), "{at}");
    assert_eq!(checkpoint_steps(&d).last(), Some(&at));
    let to = (at + 60).to_string();
    for (args, dir) in [(["--resume"], &d), (["--out"], &e)] {
        let mut cmd = ballast();
        cmd.arg("run").arg(&f).args(["--quiet", "--steps", &to]);
        let st = cmd.args(args).arg(dir.as_path()).status().unwrap();
        assert!(st.success());
    }
    assert_eq!(summary(&d)["state_digest"], summary(&e)["state_digest"]);
    assert_eq!(summary(&d)["status"], "completed");
}

/// `kill -9` at a dozen seeded moments — at a step, while a checkpoint is being written,
/// while a `--resume` starts (reading its checkpoint, rewriting `series.csv`, reopening the
/// ParaView series) — each followed by `--resume` (killed again in turn): the run ends with
/// the `summary.json` and the `series.csv` rows of a run never killed. Checkpoints every step
/// on a pile whose steps are cheaper than its checkpoints (fsync'd): most of the run's time is
/// spent writing them.
#[cfg(unix)]
#[test]
fn killed_at_random_moments_resumes_bit_identical() {
    use std::time::{Duration, Instant};
    const STEPS: u64 = 1000;
    const KILLS: u64 = 12;
    let (scen, d, e) = (tmp("kill9-scenario"), tmp("kill9"), tmp("kill9-ref"));
    let f = pile_variant(
        &scen,
        "pile.toml",
        &[(
            "output_interval = 50",
            "output_interval = 1\ncheckpoint_interval = 1\nvtk_interval = 100",
        )],
    );
    let steps = STEPS.to_string();
    let start = |resume: bool, dir: &std::path::Path| {
        let mut cmd = ballast();
        cmd.arg("run")
            .arg(&f)
            .args(["--steps", &steps, "--threads", "1", "--quiet"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        if resume {
            cmd.arg("--resume").arg(dir);
        } else {
            cmd.args(["--overwrite", "--out"]).arg(dir);
        }
        cmd.spawn().unwrap()
    };
    let st = start(false, &e).wait_with_output().unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );

    let series = d.join("series.csv");
    let ckpt = d.join("checkpoints");
    let mut rng = Moments(0x9e37_79b9_7f4a_7c15);
    let clock = Instant::now();
    // How long a resume takes to compute its first row (the longest seen), the window that
    // kills "during a resume" are drawn in.
    let mut startup = Duration::from_millis(5);
    let (mut mid_write, mut mid_resume, mut missed) = (0, 0, Vec::new());
    let mut log = Vec::new();
    for trial in 0..KILLS {
        // A kill meant for a checkpoint write or a resume's start that lands after it is tried
        // again (a fresh seeded moment), so that every such trial hits its phase.
        let mut hit = false;
        for attempt in 0..5 {
            // A run killed before its first checkpoint cannot be resumed: it starts again.
            let resume = !checkpoint_steps(&d).is_empty();
            let newest = checkpoint_steps(&d).last().copied();
            let row = last_row(&series);
            let spawned = Instant::now();
            let mut child = start(resume, &d);
            let kind = if resume { trial % 3 } else { 0 };
            let exited = |c: &mut std::process::Child| c.try_wait().unwrap().is_some();
            match kind {
                // At a step: once a seeded number of rows more are written.
                0 => {
                    let left = STEPS - row.min(STEPS);
                    let target = row + 1 + rng.below(2 * left / (KILLS - trial));
                    let mut first = None;
                    while last_row(&series) < target && !exited(&mut child) {
                        if first.is_none() && last_row(&series) > row {
                            first = Some(spawned.elapsed());
                        }
                        std::thread::sleep(Duration::from_micros(200));
                    }
                    if resume {
                        startup = startup.max(first.unwrap_or_default());
                    }
                }
                // While a checkpoint is written: a few rows on, as soon as a temporary file
                // shows (the resume has deleted those of earlier kills by then).
                1 => {
                    let target = row + 1 + rng.below(50);
                    while (last_row(&series) < target || tmp_files(&ckpt).is_empty())
                        && !exited(&mut child)
                    {
                        std::hint::spin_loop();
                    }
                }
                // While the resume starts: a seeded delay within its start-up time.
                _ => {
                    std::thread::sleep(Duration::from_micros(rng.below(startup.as_micros() as u64)))
                }
            }
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(!err.contains("panicked"), "trial {trial}: {err}");
            let left = tmp_files(&ckpt);
            // In its phase: a checkpoint's temporary file left behind; no new checkpoint.
            let landed = match kind {
                1 => !left.is_empty(),
                2 => checkpoint_steps(&d).last().copied() == newest,
                _ => true,
            };
            mid_write += usize::from(kind == 1 && landed);
            mid_resume += usize::from(kind == 2 && landed);
            log.push(format!(
                "trial {trial}.{attempt}: kind {kind}, {} → row {}, checkpoint {:?}, left \
                 {left:?}",
                if resume { "resume" } else { "start" },
                last_row(&series),
                checkpoint_steps(&d).last()
            ));
            assert!(clock.elapsed().as_secs() < 120, "{log:#?}");
            if landed {
                hit = true;
                break;
            }
        }
        if !hit {
            missed.push(trial);
        }
    }
    let out = start(true, &d).wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}\n{log:#?}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{log:#?}");
    assert!(
        missed.is_empty() && mid_write >= 3 && mid_resume >= 3,
        "kills out of their phase in trials {missed:?}: {log:#?}"
    );
    assert_eq!(summary(&d)["status"], "completed");
    assert!(tmp_files(&ckpt).is_empty(), "a resume deletes cut writes");
    assert_eq!(
        summary_without_timings(&d),
        summary_without_timings(&e),
        "{log:#?}"
    );
    let (rows, expected) = (rows_without_timings(&d), rows_without_timings(&e));
    assert_eq!(rows.len() as u64, 1 + STEPS);
    assert!(rows == expected, "series.csv differs: {log:#?}");
    for name in ["grains.pvd", "contacts.pvd"] {
        let read = |dir: &std::path::Path| std::fs::read_to_string(dir.join(name)).unwrap();
        assert_eq!(read(&d), read(&e), "{name}");
    }
}

/// The run folder's file size limit (`RLIMIT_FSIZE`, a full disk as a run sees it: writes
/// fail with EFBIG) runs out in the middle of a run, once while a checkpoint is written and
/// once while a `series.csv` row is: the run stops with exit code 1 and one line naming the
/// file, with no panic; its rows are whole and consecutive, no temporary file is left, and
/// once the limit is lifted `--resume` ends bit-identical to a run never stopped.
#[cfg(unix)]
#[test]
fn a_full_disk_stops_the_run_and_loses_nothing() {
    use std::os::unix::process::CommandExt;
    const STEPS: &str = "800";
    let (scen, e) = (tmp("fsize-scenario"), tmp("fsize-ref"));
    let f = pile_variant(
        &scen,
        "pile.toml",
        &[(
            "output_interval = 50",
            "output_interval = 1\ncheckpoint_interval = 10\nvtk_interval = 0",
        )],
    );
    let run = |dir: &std::path::Path, limit: Option<u64>, resume: bool| {
        let mut cmd = ballast();
        cmd.arg("run")
            .arg(&f)
            .args(["--steps", STEPS, "--threads", "1", "--quiet"])
            .arg(if resume { "--resume" } else { "--out" })
            .arg(dir);
        if let Some(limit) = limit {
            // In the child, before exec: SIGXFSZ ignored (kept across exec), so that a write
            // past the limit fails with EFBIG instead of killing the process.
            unsafe {
                cmd.pre_exec(move || {
                    libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
                    let mut r = libc::rlimit {
                        rlim_cur: 0,
                        rlim_max: 0,
                    };
                    if libc::getrlimit(libc::RLIMIT_FSIZE, &mut r) != 0 {
                        return Err(std::io::Error::last_os_error());
                    }
                    r.rlim_cur = limit as libc::rlim_t;
                    if libc::setrlimit(libc::RLIMIT_FSIZE, &r) != 0 {
                        return Err(std::io::Error::last_os_error());
                    }
                    Ok(())
                });
            }
        }
        cmd.output()
    };
    let reference = run(&e, None, false).unwrap();
    assert!(reference.status.success());
    let mut failed_files = Vec::new();
    // Checkpoints are 73 kB before the grains touch (step 300) and grow with the contacts
    // after; series.csv grows by 109 bytes a row: at 75 kB a checkpoint fails first, at 80 kB
    // a row of series.csv (at step 734).
    for limit in [75_000u64, 80_000] {
        let d = tmp(&format!("fsize-{limit}"));
        let out = match run(&d, Some(limit), false) {
            Ok(out) => out,
            Err(e) => {
                eprintln!("skipped: cannot set a file size limit here ({e})");
                return;
            }
        };
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        if out.status.success() {
            eprintln!("skipped: the file size limit is not enforced here");
            return;
        }
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert_eq!(err.lines().count(), 1, "one line: {err}");
        assert!(
            !err.contains("panicked") && !err.contains("backtrace"),
            "{err}"
        );
        let prefix = format!("error: write error in {}/", d.display());
        assert!(err.starts_with(&prefix), "{err}");
        let file = err[prefix.len()..].split(':').next().unwrap().to_string();
        assert!(err.contains("(os error"), "{err}");
        assert!(err.contains("the run is stopped after step"), "{err}");
        // Whole, consecutive rows; no temporary file left behind.
        let text = std::fs::read_to_string(d.join("series.csv")).unwrap();
        assert!(
            text.ends_with('\n'),
            "{file}: a cut row is left in series.csv"
        );
        let columns = text.lines().next().unwrap().split(',').count();
        for (k, l) in text.lines().skip(1).enumerate() {
            assert_eq!(l.split(',').count(), columns, "{l}");
            assert!(l.starts_with(&format!("{},", k + 1)), "{l}");
        }
        assert!(tmp_files(&d).is_empty() && tmp_files(&d.join("checkpoints")).is_empty());
        let kept = *checkpoint_steps(&d)
            .last()
            .expect("checkpoints before the limit");
        assert!(
            err.contains(&format!("its last checkpoint (step {kept}) is kept")),
            "{err}"
        );
        // Space is back: the newest valid checkpoint resumes, bit-identical.
        let resumed = run(&d, None, true).unwrap();
        assert!(
            resumed.status.success(),
            "{}",
            String::from_utf8_lossy(&resumed.stderr)
        );
        assert_eq!(summary_without_timings(&d), summary_without_timings(&e));
        assert!(
            rows_without_timings(&d) == rows_without_timings(&e),
            "{file}"
        );
        failed_files.push(file);
    }
    assert!(
        failed_files[0].starts_with("checkpoints/checkpoint_") && failed_files[1] == "series.csv",
        "the limits no longer hit a checkpoint, then series.csv (checkpoint sizes changed?): \
         {failed_files:?}"
    );
}

/// `--subdomains` splitting the grains into subdomains of fewer than 10 on average is warned,
/// naming the option, the value and the grains per subdomain; the run goes on.
#[test]
fn small_subdomains_are_warned() {
    let d = tmp("small-subdomains");
    let (code, err) = run_args(&[
        example("pile.toml").as_os_str(),
        "--steps".as_ref(),
        "2".as_ref(),
        "--subdomains".as_ref(),
        "8x8x1".as_ref(),
        "--out".as_ref(),
        d.as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains(
            "warning: --subdomains 8x8x1: 64 subdomains for 300 grains, 4.7 grains per \
             subdomain on average; below 10"
        ),
        "{err}"
    );
}
