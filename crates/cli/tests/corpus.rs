//! The regression corpus of malformed input (issue 16): every case of `corpus/cases.toml` runs
//! the `ballast` binary and must end in one short error that names the field, with the expected
//! exit code, never a panic, an abort or a hang. All failing cases are reported together, so
//! that a regression shows everything it broke.
//!
//! A case (see the header of `cases.toml`) is a command line, and usually a scenario: the text
//! `scenario`, or a `base` scenario of the file with the keys of `set` written over it and the
//! dotted paths of `unset` removed (one mistake per case, the rest valid).

use std::collections::BTreeSet;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The command line of a case that gives none: one step, nothing prepared or cached, quiet.
const DEFAULT_ARGS: [&str; 8] = [
    "run",
    "{scenario}",
    "--out",
    "{out}",
    "--steps",
    "1",
    "--no-cache",
    "--quiet",
];

/// A refusal is one clear error: a few lines of text at most (blank lines not counted: clap's
/// usage errors space out their 4 lines).
const MAX_LINES: usize = 6;
const MAX_BYTES: usize = 2000;

/// Every case is refused at validation, in milliseconds; a case still running after this has
/// slipped through to a run (or a bed preparation) or hangs.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Rust panics exit with 101; an abort or a kill is a signal (no exit code).
const PANIC_EXIT: i32 = 101;

/// Text that only a panic, an abort or Rust debug formatting would put on stderr.
const FORBIDDEN: [&str; 5] = [
    "panicked",
    "RUST_BACKTRACE",
    "memory allocation",
    "DVec3(",
    "DQuat(",
];

fn corpus_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus")
}

fn load() -> toml::Table {
    let path = corpus_dir().join("cases.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    text.parse()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Writes `top` over `base` key by key, tables merged recursively (any other value replaces).
fn overlay(base: &mut toml::Table, top: &toml::Table) {
    for (k, v) in top {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(t)) => overlay(b, t),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

/// Removes the key at a dotted path (`simulation.steps`); the path must exist, so that a case
/// cannot silently test nothing.
fn unset(table: &mut toml::Table, path: &str) -> Result<(), String> {
    let mut keys: Vec<&str> = path.split('.').collect();
    let last = keys.pop().unwrap();
    let mut t = table;
    for k in keys {
        t = t
            .get_mut(k)
            .and_then(toml::Value::as_table_mut)
            .ok_or_else(|| format!("unset {path}: no table {k}"))?;
    }
    t.remove(last)
        .map(|_| ())
        .ok_or_else(|| format!("unset {path}: no key {last}"))
}

/// The scenario text of a case, if it has one.
fn scenario(case: &toml::Table, bases: &toml::Table) -> Result<Option<String>, String> {
    if let Some(text) = case.get("scenario") {
        return text
            .as_str()
            .map(|s| Some(s.to_string()))
            .ok_or_else(|| "scenario must be a string".into());
    }
    let Some(base) = case.get("base").and_then(toml::Value::as_str) else {
        return Ok(None);
    };
    let text = bases
        .get(base)
        .and_then(toml::Value::as_str)
        .ok_or_else(|| format!("no base {base:?} in [base]"))?;
    let mut table: toml::Table = text.parse().map_err(|e| format!("base {base}: {e}"))?;
    if let Some(set) = case.get("set") {
        overlay(
            &mut table,
            set.as_table().ok_or("set must be a table".to_string())?,
        );
    }
    for p in case
        .get("unset")
        .and_then(toml::Value::as_array)
        .into_iter()
        .flatten()
    {
        unset(&mut table, p.as_str().ok_or("unset holds strings")?)?;
    }
    toml::to_string(&table).map(Some).map_err(|e| e.to_string())
}

fn strings(case: &toml::Table, key: &str) -> Result<Option<Vec<String>>, String> {
    let Some(v) = case.get(key) else {
        return Ok(None);
    };
    v.as_array()
        .and_then(|a| a.iter().map(|x| x.as_str().map(String::from)).collect())
        .map(Some)
        .ok_or_else(|| format!("{key} must be an array of strings"))
}

/// What a finished (or killed) command left.
struct Outcome {
    code: Option<i32>,
    stderr: String,
    timed_out: bool,
}

fn run(args: &[String], dir: &Path) -> Result<Outcome, String> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_ballast"))
        .args(args)
        .current_dir(dir)
        // Nothing is read from or written to the user's cache, whatever a case's flags.
        .env("BALLAST_CACHE", dir.join("cache"))
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| e.to_string())?;
    // Read stderr on a thread: a chatty child would block on a full pipe otherwise.
    let mut pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = pipe.read_to_end(&mut buf);
        buf
    });
    let start = Instant::now();
    let (status, timed_out) = loop {
        if let Some(s) = child.try_wait().map_err(|e| e.to_string())? {
            break (s, false);
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            break (child.wait().map_err(|e| e.to_string())?, true);
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let stderr = String::from_utf8_lossy(&reader.join().unwrap()).into_owned();
    Ok(Outcome {
        code: status.code(),
        stderr,
        timed_out,
    })
}

/// Runs one case; `Err` lists what is wrong with its outcome.
fn check(
    k: usize,
    name: &str,
    case: &toml::Table,
    bases: &toml::Table,
    root: &Path,
) -> Result<(), String> {
    // Numbered: two names may read the same once sanitised.
    let dir = root.join(format!(
        "{k:03}-{}",
        name.replace(|c: char| !c.is_ascii_alphanumeric(), "_")
    ));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let field = case
        .get("field")
        .and_then(toml::Value::as_str)
        .ok_or("no field")?;
    let also = strings(case, "also")?.unwrap_or_default();
    let exit = case
        .get("exit")
        .and_then(toml::Value::as_integer)
        .ok_or("no exit")?;
    if exit == 0 || exit == PANIC_EXIT as i64 {
        return Err(format!(
            "exit = {exit}: a refusal exits non-zero, and not as a panic"
        ));
    }
    let text = scenario(case, bases)?;
    let scenario_path = dir.join("scenario.toml");
    if let Some(t) = &text {
        std::fs::write(&scenario_path, t).map_err(|e| e.to_string())?;
    }
    if let Some(files) = case.get("files") {
        for (rel, content) in files.as_table().ok_or("files must be a table")? {
            let p = dir.join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).map_err(|e| e.to_string())?;
            std::fs::write(&p, content.as_str().ok_or("files hold strings")?)
                .map_err(|e| e.to_string())?;
        }
    }
    let args: Vec<String> = strings(case, "args")?
        .unwrap_or_else(|| DEFAULT_ARGS.iter().map(|s| s.to_string()).collect())
        .iter()
        .map(|a| {
            a.replace("{scenario}", scenario_path.to_str().unwrap())
                .replace("{out}", dir.join("out").to_str().unwrap())
                .replace("{dir}", dir.to_str().unwrap())
        })
        .collect();
    let mut o = run(&args, &dir)?;
    // Messages quote the scenario's path: the case's folder must not supply the field.
    o.stderr = o.stderr.replace(dir.to_str().unwrap(), "{dir}");
    let mut wrong = Vec::new();
    if o.timed_out {
        wrong.push(format!("still running after {TIMEOUT:?}: killed"));
    }
    match o.code {
        None if !o.timed_out => wrong.push("killed by a signal (an abort?)".into()),
        Some(PANIC_EXIT) => wrong.push("exit code 101: a panic".into()),
        Some(c) if i64::from(c) != exit => wrong.push(format!("exit code {c}, expected {exit}")),
        _ => {}
    }
    for bad in FORBIDDEN {
        if o.stderr.contains(bad) {
            wrong.push(format!("stderr contains {bad:?}"));
        }
    }
    for want in std::iter::once(field).chain(also.iter().map(String::as_str)) {
        if !o.stderr.contains(want) {
            wrong.push(format!("stderr does not name {want:?}"));
        }
    }
    let lines = o.stderr.lines().filter(|l| !l.trim().is_empty()).count();
    if lines > MAX_LINES || o.stderr.len() > MAX_BYTES {
        wrong.push(format!(
            "stderr has {lines} non-blank lines and {} bytes (at most {MAX_LINES} and {MAX_BYTES})",
            o.stderr.len()
        ));
    }
    if wrong.is_empty() {
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    } else {
        Err(format!(
            "{}\n  args: {args:?}\n  stderr:\n{}",
            wrong.join("; "),
            o.stderr
                .lines()
                .map(|l| format!("    | {l}"))
                .collect::<Vec<_>>()
                .join("\n")
        ))
    }
}

#[test]
fn every_malformed_input_is_refused_with_its_field_named() {
    let corpus = load();
    let bases = corpus
        .get("base")
        .and_then(toml::Value::as_table)
        .cloned()
        .unwrap_or_default();
    let cases = corpus
        .get("case")
        .and_then(toml::Value::as_array)
        .expect("cases.toml has [[case]] entries");
    let mut names = BTreeSet::new();
    let mut duplicates = Vec::new();
    for c in cases {
        let name = c.get("name").and_then(toml::Value::as_str).unwrap_or("");
        if name.is_empty() || !names.insert(name) {
            duplicates.push(name);
        }
    }
    assert!(
        duplicates.is_empty(),
        "case names must be unique and non-empty: {duplicates:?}"
    );
    assert!(
        cases.len() >= 100,
        "the corpus has {} cases, issue 16 asks for at least 100",
        cases.len()
    );
    let root = std::env::temp_dir().join(format!("ballast-corpus-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let mut failures = Vec::new();
    for (k, c) in cases.iter().enumerate() {
        let case = c.as_table().expect("a [[case]] is a table");
        let name = case["name"].as_str().unwrap();
        if let Err(e) = check(k, name, case, &bases, &root) {
            failures.push(format!("- {name}: {e}"));
        }
    }
    // Folders of failing cases are kept, to look at.
    if failures.is_empty() {
        let _ = std::fs::remove_dir_all(&root);
    }
    assert!(
        failures.is_empty(),
        "{} of {} corpus cases failed (folders kept in {}):\n{}",
        failures.len(),
        cases.len(),
        root.display(),
        failures.join("\n")
    );
}
