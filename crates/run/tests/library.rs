//! The run library called directly, as a front end other than the command does: an observer
//! sees every step and stops the run, the run resumes bit-identically, and refusals name the
//! arguments the way the front end's `ArgNames` says.

use ballast_engine::world::StepReport;
use ballast_run::{ArgNames, BuildOptions, Failure, Job, Observer, RunOptions};
use std::path::{Path, PathBuf};

/// The sliding block example with a row every 10 steps.
fn scenario() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/sliding_block.toml");
    let text = std::fs::read_to_string(path).unwrap();
    text.replace("alert = 1e-3", "alert = 1e-3\noutput_interval = 10")
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("library_{name}"));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Names as a scripting front end would write them.
const NAMES: ArgNames = ArgNames {
    out: |d| format!("out={}", d.display()),
    resume: |d| format!("resume in {}", d.display()),
    resume_command: |d| format!("resume({})", d.display()),
    overwrite: "overwrite",
    steps: "steps",
    subdomains: "subdomains",
};

/// Records what it sees, asks to stop after `stop_at` steps of the session, keeps messages.
#[derive(Default)]
struct Recorder {
    total: Option<u64>,
    steps: Vec<(u64, u64)>,
    finished: bool,
    stop_at: Option<u64>,
    messages: Vec<String>,
}

impl Observer for Recorder {
    fn start(&mut self, total: u64) {
        self.total = Some(total);
    }
    fn step(&mut self, done: u64, r: &StepReport) {
        self.steps.push((done, r.step));
    }
    fn finish(&mut self) {
        self.finished = true;
    }
    fn stop_requested(&mut self) -> bool {
        self.stop_at
            .is_some_and(|k| self.steps.last().is_some_and(|s| s.0 >= k))
    }
    fn message(&mut self, line: &str) {
        self.messages.push(line.to_string());
    }
}

fn build(observer: &mut Recorder) -> Job {
    let options = BuildOptions {
        cache: None,
        subdomains: None,
        quiet: false,
        names: &NAMES,
        exchange: None,
    };
    Job::build("sliding_block.toml", &scenario(), &options, observer).unwrap()
}

fn options(out: &Path, steps: u64, resume: bool) -> RunOptions<'_> {
    RunOptions {
        out,
        resume,
        overwrite: false,
        steps: Some(steps),
        threads: 1,
        quiet: false,
        names: &NAMES,
    }
}

#[test]
fn an_observer_sees_the_steps_stops_the_run_and_it_resumes_bit_identically() {
    let whole_dir = scratch("whole");
    let mut seen = Recorder::default();
    let mut whole = build(&mut seen);
    let done = whole
        .run(&options(&whole_dir, 60, false), &mut seen)
        .unwrap();
    assert_eq!(done.steps, 60);
    assert_eq!(done.summary["status"], "completed");
    assert_eq!(seen.total, Some(60));
    assert_eq!(seen.steps.len(), 60);
    assert_eq!(seen.steps[59], (60, 60));
    assert!(seen.finished);
    // The closing line goes through the observer, not to stderr.
    assert!(
        seen.messages
            .iter()
            .any(|m| m.starts_with("60 steps, 3 bodies")),
        "{:?}",
        seen.messages
    );

    let dir = scratch("parts");
    let mut stopper = Recorder {
        stop_at: Some(25),
        ..Recorder::default()
    };
    let mut first = build(&mut stopper);
    let Err(Failure::Interrupted(m)) = first.run(&options(&dir, 60, false), &mut stopper) else {
        panic!("the run should stop at step 25");
    };
    assert!(
        m.contains("interrupted at step 25 of 60") && m.contains("resume("),
        "{m}"
    );
    assert_eq!(first.world().step_index, 25);

    let mut rest = Recorder::default();
    let mut second = build(&mut rest);
    let done = second.run(&options(&dir, 60, true), &mut rest).unwrap();
    assert_eq!(rest.total, Some(35));
    assert_eq!(rest.steps.first(), Some(&(1, 26)));
    assert_eq!(done.summary["state_digest"], digest_in(&whole_dir));
    assert_eq!(
        series_without_timings(&dir),
        series_without_timings(&whole_dir)
    );
}

/// The `state_digest` of the run in `dir`.
fn digest_in(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    serde_json::from_str::<serde_json::Value>(&text).unwrap()["state_digest"].clone()
}

/// `series.csv` without its wall-clock columns (`t_*`).
fn series_without_timings(dir: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(dir.join("series.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !header[i].starts_with("t_"))
        .collect();
    std::iter::once(header.join(","))
        .chain(lines.map(str::to_string))
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| cells[i].to_string()).collect()
        })
        .collect()
}

#[test]
fn refusals_name_the_front_ends_arguments() {
    let dir = scratch("refusals");
    let mut o = Recorder::default();
    let mut job = build(&mut o);
    let e = job.run(&options(&dir, 5, true), &mut o).unwrap_err();
    assert!(
        e.to_string()
            .starts_with(&format!("resume in {}: no valid checkpoint", dir.display())),
        "{e}"
    );
    job.run(&options(&dir, 5, false), &mut o).unwrap();
    let mut again = build(&mut o);
    let e = again.run(&options(&dir, 5, false), &mut o).unwrap_err();
    let m = e.to_string();
    assert!(
        m.starts_with(&format!(
            "out={}: the folder holds another run",
            dir.display()
        )) && m.contains(&format!("resume({})", dir.display()))
            && m.contains("add overwrite to delete"),
        "{m}"
    );
    // A run folder starts at step 0.
    let e = job
        .run(&options(&scratch("later"), 10, false), &mut o)
        .unwrap_err();
    assert!(e.to_string().contains("already at step 5"), "{e}");
}

/// `examples/pile.toml` (300 grains) with each `(from, to)` of `replace` applied.
fn pile(replace: &[(&str, &str)]) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/pile.toml");
    let mut text = std::fs::read_to_string(path).unwrap();
    for (from, to) in replace {
        assert!(text.contains(from), "{from}");
        text = text.replacen(from, to, 1);
    }
    text
}

fn build_text(text: &str, subdomains: Option<[usize; 3]>, observer: &mut Recorder) -> Job {
    let options = BuildOptions {
        cache: None,
        subdomains,
        quiet: true,
        names: &NAMES,
        exchange: None,
    };
    Job::build("pile.toml", text, &options, observer).unwrap()
}

fn digest(job: &Job) -> String {
    ballast_engine::digest::state_digest(&job.world().bodies)
}

/// `Job::checked_step`, the health check of a front end that steps on its own (Python's
/// `Simulation.step`): checked steps give the states unchecked ones do; a step that breaks a
/// bound gives its divergence and puts the world and the statistics back to the step before,
/// from which stepping on repeats that step bit for bit; a blow-up at the first step leaves the
/// initial state.
#[test]
fn checked_steps_stop_at_the_last_healthy_step() {
    let mut o = Recorder::default();
    let text = pile(&[]);
    let (mut checked, mut plain) = (
        build_text(&text, None, &mut o),
        build_text(&text, None, &mut o),
    );
    for _ in 0..40 {
        let (a, b) = (checked.checked_step().unwrap(), plain.step());
        assert_eq!((a.step, a.contacts), (b.step, b.contacts));
    }
    assert_eq!(digest(&checked), digest(&plain));

    // Falling grains pass 0.05 m/s after 5.1 ms: step 26 at dt = 2e-4 s.
    let slow = pile(&[("alert = 1e-3", "alert = 1e-3\nmax_speed = 0.05")]);
    let mut job = build_text(&slow, None, &mut o);
    let mut plain = build_text(&slow, None, &mut o);
    let d = loop {
        match job.checked_step() {
            Ok(_) => plain.step(),
            Err(d) => break d,
        };
    };
    assert_eq!((d.step, d.quantity.name()), (26, "speed"), "{d}");
    assert_eq!(job.world().step_index, 25);
    assert_eq!(job.stats().steps, 25);
    assert_eq!(digest(&job), digest(&plain));
    job.step();
    plain.step();
    assert_eq!(digest(&job), digest(&plain));

    let blow_up = pile(&[("gravity = [0, 0, -9.81]", "gravity = [0, 0, -1e200]")]);
    let mut job = build_text(&blow_up, None, &mut o);
    let initial = digest(&job);
    let d = job.checked_step().unwrap_err();
    assert_eq!(d.step, 1);
    assert!(
        d.to_string()
            .contains("group \"grain\") moves at 2.000e196 m/s"),
        "{d}"
    );
    assert_eq!((job.world().step_index, digest(&job)), (0, initial));
}

/// Subdomains of fewer than `WARN_GRAINS_PER_SUBDOMAIN` grains on average are warned, named by
/// the option or the scenario key that set them; 300 grains take 30 subdomains without a word.
#[test]
fn small_subdomains_are_warned() {
    let text = pile(&[]);
    let mut o = Recorder::default();
    build_text(&text, Some([5, 6, 1]), &mut o);
    build_text(&text, Some([1, 1, 1]), &mut o);
    assert_eq!(o.messages, Vec::<String>::new());
    build_text(&text, Some([6, 6, 1]), &mut o);
    let table = format!("{text}\n[ddm]\nsubdomains = [8, 4, 2]\n");
    build_text(&table, None, &mut o);
    assert_eq!(o.messages.len(), 2, "{:?}", o.messages);
    for (m, name, n, per) in [
        (&o.messages[0], "subdomains 6x6x1", 36, "8.3"),
        (&o.messages[1], "ddm.subdomains = [8, 4, 2]", 64, "4.7"),
    ] {
        let head = format!(
            "warning: {name}: {n} subdomains for 300 grains, {per} grains per subdomain on average"
        );
        assert!(m.starts_with(&head), "{m}");
        assert!(m.contains("use at most 30 subdomains here"), "{m}");
        assert_eq!(m.lines().count(), 1);
    }
}
