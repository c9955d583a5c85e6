//! The `ballast` command: outputs, the summary contract, bit-identical reruns, clear errors.

use std::path::PathBuf;
use std::process::Command;

mod figures;

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

fn summary(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
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
