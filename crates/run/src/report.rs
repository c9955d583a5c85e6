//! Run report and scaling plots, drawn by the run itself (see [`crate::charts`], no Python).
//!
//! * [`write_run_report`]: after `ballast run`, `DIR/plots/NAME.svg` and `DIR/plots/NAME.png`
//!   from `DIR/series.csv` and `DIR/report.md` with the scenario, the Table-1-style timing
//!   table, the final indicators and the plots: what a user forwards to a colleague.
//! * [`write_scaling_plots`]: after `ballast bench --scaling`, speedup and efficiency versus
//!   threads (the paper's Fig. 4) and the time per phase (its Table 1) as stacked bars.
//!
//! Every file is written atomically (temporary file, then rename), so an interrupted run
//! never leaves a half-written report or image.

use crate::charts::{
    write_figure, BarChart, Figure, LineChart, ScatterMap, Series, Style, REFERENCE,
};
use serde_json::Value;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// The per-phase bar of a run (figure name), shown under the timing table.
const PHASES_FIG: &str = "phases";
/// Segments of the per-phase bars, in stacking order (Table 1's columns).
const PHASES: [&str; 4] = ["detection", "NLGS subdomains", "NLGS interface", "other"];

/// One configuration × thread count of a scaling study: configuration label (e.g.
/// `"DDM 2x2x1"`), threads, speedup, efficiency (0..1), and seconds spent in detection,
/// NLGS subdomains (the whole NLGS time for monolithic NLGS), NLGS interface, and other.
pub type ScalingPoint = (String, usize, f64, f64, [f64; 4]);

/// `series.csv` as numbers: column names and rows (unparsable cells are NaN).
struct Table {
    names: Vec<String>,
    rows: Vec<Vec<f64>>,
}

impl Table {
    fn parse(text: &str) -> Table {
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let names: Vec<String> = lines
            .next()
            .unwrap_or("")
            .split(',')
            .map(|s| s.trim().to_string())
            .collect();
        let rows = lines
            .map(|l| {
                let mut r: Vec<f64> = l
                    .split(',')
                    .map(|c| c.trim().parse().unwrap_or(f64::NAN))
                    .collect();
                // A truncated last line (interrupted run) is padded, not dropped.
                r.resize(names.len(), f64::NAN);
                r
            })
            .collect();
        Table { names, rows }
    }

    fn col(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// `(x, y × scale)` points of columns `x` and `y`.
    fn xy(&self, x: usize, y: usize, scale: f64) -> Vec<(f64, f64)> {
        self.rows.iter().map(|r| (r[x], r[y] * scale)).collect()
    }

    /// Last finite value of column `i`.
    fn last(&self, i: usize) -> Option<f64> {
        self.rows.iter().rev().map(|r| r[i]).find(|v| v.is_finite())
    }

    /// Largest finite |value| of column `i` (0 if none).
    fn max_abs(&self, i: usize) -> f64 {
        self.rows
            .iter()
            .map(|r| r[i].abs())
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max)
    }
}

/// A family of per-object columns (`compacity_*`, `tine_force_*`, `block_z_*`, and the
/// `coordination` column alone).
struct Family {
    /// Column-name prefix.
    prefix: &'static str,
    /// Figure name (`NAME.svg`, `NAME.png`).
    file: &'static str,
    title: &'static str,
    /// Quantity for the y label, and what a numbered column is called in the legend.
    quantity: &'static str,
    noun: &'static str,
    /// Unit assumed when the column name carries none.
    default_unit: &'static str,
}

const FAMILIES: [Family; 8] = [
    Family {
        prefix: "compacity_",
        file: "compacity",
        title: "Compacity per control volume",
        quantity: "compacity",
        noun: "CV",
        default_unit: "-",
    },
    Family {
        prefix: "tine_force_",
        file: "tines",
        title: "Tine forces",
        quantity: "tine force",
        noun: "tine",
        default_unit: "N",
    },
    Family {
        prefix: "block_z_",
        file: "blocks",
        title: "Block position",
        quantity: "block height z",
        noun: "block",
        default_unit: "m",
    },
    Family {
        prefix: "coordination",
        file: "coordination",
        title: "Coordination number",
        quantity: "contacts per grain",
        noun: "mean",
        default_unit: "-",
    },
    Family {
        prefix: "tine_drive_",
        file: "tine_drives",
        title: "Forces of the tamping unit on the tines",
        quantity: "drive force",
        noun: "tine",
        default_unit: "N",
    },
    Family {
        prefix: "tine_travel_",
        file: "tine_travel",
        title: "Tine travel, achieved and commanded",
        quantity: "displacement",
        noun: "tine",
        default_unit: "m",
    },
    Family {
        prefix: "tine_work_",
        file: "tine_work",
        title: "Work of the tamping unit on the tines",
        quantity: "work",
        noun: "tine",
        default_unit: "J",
    },
    Family {
        prefix: "block_drive_",
        file: "block_drives",
        title: "Force of the lifting unit on the blocks as it lets them down",
        quantity: "drive force",
        noun: "block",
        default_unit: "N",
    },
];

/// Units a column name may end with (`tine_force_2_N`, `block_z_left_m`).
const UNITS: [&str; 9] = ["N", "kN", "MN", "m", "mm", "s", "J", "Pa", "kPa"];

/// Legend name and unit of a family column: `compacity_3` → ("CV 3", "-"),
/// `tine_force_left_N` → ("left", "N"), `tine_force_2_x_N` (the track model's per-axis
/// columns) → ("tine 2 x", "N").
fn member(f: &Family, column: &str) -> (String, String) {
    let rest = &column[f.prefix.len()..];
    let (stem, unit) = match rest.rsplit_once('_') {
        Some((stem, u)) if UNITS.contains(&u) => (stem, u),
        _ if UNITS.contains(&rest) => ("", rest),
        _ => (rest, f.default_unit),
    };
    // A number first names the object by the family's noun, whatever follows (an axis).
    let numbered = stem
        .split('_')
        .next()
        .is_some_and(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()));
    let name = if stem.is_empty() {
        f.noun.to_string()
    } else if numbered {
        format!("{} {}", f.noun, stem.replace('_', " "))
    } else {
        stem.replace('_', " ")
    };
    (name, unit.to_string())
}

/// Display unit and factor for values in `unit` whose largest magnitude is `max_abs`: forces
/// in kN from 1 kN on, lengths in mm (block heights move by millimetres).
fn display_unit(unit: &str, max_abs: f64) -> (String, f64) {
    match unit {
        "N" if max_abs >= 1e3 => ("kN".into(), 1e-3),
        "m" => ("mm".into(), 1e3),
        u => (u.into(), 1.0),
    }
}

/// Writes `text` to `path` atomically (temporary sibling file, then rename).
fn write_atomic(path: &Path, text: &str) -> std::io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let tmp = std::path::PathBuf::from(tmp);
    let res = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if res.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    res
}

/// Number at JSON pointer `ptr` of `v`.
fn num(v: &Value, ptr: &str) -> Option<f64> {
    v.pointer(ptr).and_then(Value::as_f64)
}

/// `x` with 4 significant digits, or `n/a`.
fn sig(x: Option<f64>) -> String {
    match x {
        Some(v) if v.is_finite() => {
            if v == 0.0 {
                "0".into()
            } else if (1e-3..1e6).contains(&v.abs()) {
                let d = (3 - (v.abs().log10() + 1e-9).floor() as i32).max(0) as usize;
                format!("{v:.d$}")
            } else {
                format!("{v:.3e}")
            }
        }
        _ => "n/a".into(),
    }
}

/// Lines of the scenario copied into the report (the whole file is `scenario.toml`).
const REPORT_LINES: usize = 400;
/// Characters of a scenario line copied into the report.
const REPORT_LINE_CHARS: usize = 300;

/// `text` cut to `max_lines` lines of at most `max_chars` characters each, each cut said in a
/// TOML comment: a scenario of thousands of bodies, or a 50 MB value, is not copied whole.
pub fn excerpt(text: &str, max_lines: usize, max_chars: usize) -> String {
    let mut out = String::new();
    let total = text.lines().count();
    for line in text.lines().take(max_lines) {
        let n = line.chars().count();
        if n > max_chars {
            out.extend(line.chars().take(max_chars));
            out.push_str(&format!(
                " # … {} more characters, in scenario.toml",
                n - max_chars
            ));
        } else {
            out.push_str(line);
        }
        out.push('\n');
    }
    if total > max_lines {
        out.push_str(&format!(
            "# … {} more lines, in scenario.toml\n",
            total - max_lines
        ));
    }
    out
}

/// A code fence longer than any backtick run in `text`, so the text cannot close it.
fn fence_for(text: &str) -> String {
    let longest = text.split(|c| c != '`').map(str::len).max().unwrap_or(0);
    "`".repeat(longest.max(2) + 1)
}

/// Figures written so far: `(name, caption)` for the report, and failures.
#[derive(Default)]
struct Plots {
    made: Vec<(String, String)>,
    errors: Vec<String>,
}

impl Plots {
    /// Writes `fig` as `dir/NAME.svg` and `dir/NAME.png` and records it (or its failure).
    fn write(&mut self, dir: &Path, name: &str, caption: &str, fig: &Figure) {
        match write_figure(dir, name, fig) {
            Ok(()) => self.made.push((name.into(), caption.into())),
            Err(e) => self.errors.push(format!("{name}: {e}")),
        }
    }
}

/// The markdown of figure `name`: the PNG, and a link to its SVG.
fn figure_markdown(name: &str, caption: &str) -> String {
    format!("![{caption}](plots/{name}.png)\n\n[{caption} (SVG)](plots/{name}.svg)\n")
}

fn chart(title: &str, x_label: &str, y_label: &str, series: Vec<Series>) -> LineChart {
    LineChart {
        title: title.into(),
        x_label: x_label.into(),
        y_label: y_label.into(),
        series,
        log_y: false,
        x_range: None,
        y_range: None,
    }
}

/// Renders the plots of `table` into `dir` (which exists).
fn run_plots(dir: &Path, t: &Table, summary: &Value) -> Plots {
    let mut p = Plots::default();
    let (x, x_label) = match (t.col("time_s"), t.col("step")) {
        (Some(i), _) => (i, "time (s)"),
        (None, Some(i)) => (i, "step"),
        (None, None) => {
            p.errors
                .push("series.csv has neither a time_s nor a step column".into());
            return p;
        }
    };
    let line =
        |name: &str, col: usize, scale: f64| Series::new(name, t.xy(x, col, scale), Style::Line);

    // Solver: contacts, NLGS iterations and residual (against the tolerance) in panels.
    let mut panels = Vec::new();
    if let Some(c) = t.col("contacts") {
        panels.push(chart(
            "Contact points",
            x_label,
            "contacts (-)",
            vec![line("contacts", c, 1.0)],
        ));
    }
    if let Some(c) = t.col("iterations") {
        panels.push(chart(
            "NLGS iterations per step",
            x_label,
            "iterations (-)",
            vec![line("iterations", c, 1.0)],
        ));
    }
    if let Some(c) = t.col("residual") {
        // Both measures, and the tolerance labelled with the norm it applies to.
        let mut series = vec![line("natural-map residual", c, 1.0)];
        if let Some(q) = t.col("quad") {
            series.push(line("Quad norm", q, 1.0));
        }
        if let (Some(tol), Some((x0, x1))) = (num(summary, "/solver/tolerance"), x_span(t, x)) {
            let norm = summary
                .pointer("/solver/norm")
                .and_then(|v| v.as_str())
                .unwrap_or("?");
            series.push(
                Series::new(
                    format!("tolerance ({norm})"),
                    vec![(x0, tol), (x1, tol)],
                    Style::Dashed,
                )
                .with_color(REFERENCE),
            );
        }
        let mut ch = chart("NLGS convergence", x_label, "residual (-)", series);
        ch.log_y = true;
        panels.push(ch);
    }
    if !panels.is_empty() {
        // One time axis for all panels, whatever each column lacks.
        let span = x_span(t, x);
        for ch in &mut panels {
            ch.x_range = span;
        }
        p.write(
            dir,
            "solver",
            "Contact points, NLGS iterations and residual versus time",
            &Figure::Panels(panels),
        );
    }

    if let Some(c) = t.col("kinetic_energy_J") {
        let mut ch = chart(
            "Kinetic energy",
            x_label,
            "kinetic energy (J)",
            vec![line("kinetic energy", c, 1.0)],
        );
        // Settling spans decades: a log axis shows the tail.
        ch.log_y = decades(t, c) > 3.0;
        p.write(
            dir,
            "energy",
            "Kinetic energy versus time",
            &Figure::chart(ch),
        );
    }

    if let Some(c) = t.col("max_penetration_m") {
        let ch = chart(
            "Largest interpenetration",
            x_label,
            "max interpenetration (mm)",
            vec![line("max interpenetration", c, 1e3)],
        );
        p.write(
            dir,
            "penetration",
            "Largest interpenetration versus time",
            &Figure::chart(ch),
        );
    }

    // Per-phase times: every `t_<phase>_s` column, in ms per step.
    let phases: Vec<Series> = t
        .names
        .iter()
        .enumerate()
        .filter_map(|(i, n)| {
            let phase = n.strip_prefix("t_")?.strip_suffix("_s")?;
            Some(line(phase, i, 1e3))
        })
        .collect();
    if !phases.is_empty() {
        let ch = chart(
            "Time per step by phase",
            x_label,
            "time per step (ms)",
            phases,
        );
        p.write(
            dir,
            "timings",
            "Time per step of each phase versus time",
            &Figure::chart(ch),
        );
    }

    for f in &FAMILIES {
        let cols: Vec<usize> = (0..t.names.len())
            .filter(|&i| t.names[i].starts_with(f.prefix))
            .collect();
        if cols.is_empty() {
            continue;
        }
        let max_abs = cols.iter().map(|&i| t.max_abs(i)).fold(0.0, f64::max);
        let unit = member(f, &t.names[cols[0]]).1;
        let (shown, scale) = display_unit(&unit, max_abs);
        let series = cols
            .iter()
            .map(|&i| line(&member(f, &t.names[i]).0, i, scale))
            .collect();
        let ch = chart(
            f.title,
            x_label,
            &format!("{} ({shown})", f.quantity),
            series,
        );
        p.write(
            dir,
            f.file,
            &format!("{} versus time", f.title),
            &Figure::chart(ch),
        );
    }
    p
}

/// Smallest and largest finite value of column `x`.
fn x_span(t: &Table, x: usize) -> Option<(f64, f64)> {
    let (lo, hi) = t
        .rows
        .iter()
        .map(|r| r[x])
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    (lo <= hi).then_some((lo, hi))
}

/// Decades spanned by the positive values of column `i` (0 if fewer than two).
fn decades(t: &Table, i: usize) -> f64 {
    let pos = t
        .rows
        .iter()
        .map(|r| r[i])
        .filter(|v| *v > 0.0 && v.is_finite());
    let (lo, hi) = pos.fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    if lo.is_finite() && hi > lo {
        (hi / lo).log10()
    } else {
        0.0
    }
}

/// The Table-1-style rows: (phase, seconds) from `summary["timings_s"]`.
fn timing_rows(summary: &Value) -> Vec<(&'static str, Option<f64>)> {
    let t = |k: &str| num(summary, &format!("/timings_s/{k}"));
    vec![
        ("detection", t("detection")),
        ("nlgs", t("nlgs")),
        ("of which subdomains", t("subdomains")),
        ("of which interface", t("interface")),
        ("other", t("other")),
        ("total", t("total")),
    ]
}

/// Per-phase seconds for the stacked bar: detection, NLGS outside the interface (all of it
/// for monolithic NLGS), interface, other.
fn phase_segments(summary: &Value) -> [f64; 4] {
    let t = |k: &str| num(summary, &format!("/timings_s/{k}")).unwrap_or(0.0);
    let interface = t("interface");
    [
        t("detection"),
        (t("nlgs") - interface).max(0.0),
        interface,
        t("other"),
    ]
}

/// Writes `out/plots/*.{svg,png}` from `out/series.csv` and `out/report.md`: scenario file name,
/// parameters (the scenario TOML), the Table-1-style timing table from
/// `summary["timings_s"]`, the solver, contact and energy indicators of `summary`, the last
/// values of the per-object columns (compacity, tine forces, block heights), and the plots.
///
/// `summary` is `summary.json` as a JSON value (missing keys show as `n/a`). A missing
/// `series.csv` gives a report without time plots. The report is written even when some
/// plot fails; the failures are then returned as the error.
pub fn write_run_report(
    out: &Path,
    scenario_file: &Path,
    scenario_text: &str,
    summary: &Value,
) -> Result<(), String> {
    let plots_dir = out.join("plots");
    std::fs::create_dir_all(&plots_dir)
        .map_err(|e| format!("cannot create {}: {e}", plots_dir.display()))?;
    let series_path = out.join("series.csv");
    let table = std::fs::read_to_string(&series_path)
        .ok()
        .map(|s| Table::parse(&s));
    let mut plots = match &table {
        Some(t) => run_plots(&plots_dir, t, summary),
        None => Plots::default(),
    };
    section_plots(&out.join("sections"), &plots_dir, &mut plots);
    let breakdown = BarChart {
        title: "Time per phase (Table 1)".into(),
        y_label: "wall-clock time (s)".into(),
        categories: vec![format!(
            "this run\n{} thread(s), {}",
            summary.get("threads").and_then(Value::as_u64).unwrap_or(0),
            summary
                .get("subdomains")
                .and_then(Value::as_str)
                .unwrap_or("1x1x1")
        )],
        segments: PHASES.iter().map(|s| s.to_string()).collect(),
        values: vec![phase_segments(summary).to_vec()],
    };
    plots.write(
        &plots_dir,
        PHASES_FIG,
        "Time per phase (Table 1)",
        &Figure::Bars(breakdown),
    );

    let md = report_markdown(
        scenario_file,
        scenario_text,
        summary,
        table.as_ref(),
        &plots,
    );
    let path = out.join("report.md");
    write_atomic(&path, &md).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    if plots.errors.is_empty() {
        Ok(())
    } else {
        Err(format!("some plots failed: {}", plots.errors.join("; ")))
    }
}

/// Loads below this (N) are drawn at this value on the log colour scale: a grain touching
/// nothing (or only open contacts) carries nothing, and log 0 is not a colour.
const LOAD_FLOOR: f64 = 0.1;

/// Draws every `sections/*.csv` of the run (see `ballast_railway::sections`): each coloured
/// by the load its grains carry, and the sections at the end of a squeeze also by speed.
fn section_plots(dir: &Path, plots_dir: &Path, plots: &mut Plots) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    // Start, squeezes, then the end: the order of the moments in the cycle.
    files.sort_by_key(|p| {
        let n = p.file_stem().map(|s| s.to_string_lossy().into_owned());
        let n = n.unwrap_or_default();
        let rank = if n.starts_with("start") {
            0
        } else if n.starts_with("end-of-squeeze") {
            1
        } else {
            2
        };
        (rank, n)
    });
    for f in files {
        let Some(stem) = f.file_stem().map(|s| s.to_string_lossy().into_owned()) else {
            continue;
        };
        let Some((moment, plane)) = stem.split_once('_') else {
            continue;
        };
        let Ok(text) = std::fs::read_to_string(&f) else {
            plots.errors.push(format!("cannot read {}", f.display()));
            continue;
        };
        let t = Table::parse(&text);
        let (Some(u), Some(z), Some(v), Some(l)) = (
            t.col("u_m"),
            t.col("z_m"),
            t.col("speed_m_s"),
            t.col("load_N"),
        ) else {
            plots
                .errors
                .push(format!("{}: not a section file", f.display()));
            continue;
        };
        let (axis, words) = match plane {
            "tine-plane" => ("x (m)", "along the track through a tine row"),
            "block-axis" => ("y (m)", "across the track through the block's axis"),
            _ => ("u (m)", plane),
        };
        let when = moment.replace('-', " ");
        let span = t
            .rows
            .iter()
            .map(|r| r[u])
            .fold((f64::MAX, f64::MIN), |a, x| (a.0.min(x), a.1.max(x)));
        // Markers about a grain wide: a 35 mm grain over the plot's width in pixels.
        let plot_px = f64::from(crate::charts::WIDTH) - 560.0;
        let radius = (0.5 * 0.035 * plot_px / (span.1 - span.0).max(0.1)).clamp(3.0, 30.0);
        let map = |value_label: &str, value: &dyn Fn(&[f64]) -> f64| ScatterMap {
            title: format!("Section {words}: {when}"),
            x_label: axis.into(),
            y_label: "z (m)".into(),
            value_label: value_label.into(),
            points: t.rows.iter().map(|r| (r[u], r[z], value(r))).collect(),
            radius,
            value_range: None,
        };
        let load = map("log10 of the load carried (N)", &|r| {
            r[l].max(LOAD_FLOOR).log10()
        });
        plots.write(
            plots_dir,
            &format!("section_{stem}_load"),
            &format!("Section {words}, {when}: load carried by each grain"),
            &Figure::Map(load),
        );
        if moment.starts_with("end-of-squeeze") {
            let speed = map("speed (m/s)", &|r| r[v]);
            plots.write(
                plots_dir,
                &format!("section_{stem}_speed"),
                &format!("Section {words}, {when}: grain speed"),
                &Figure::Map(speed),
            );
        }
    }
}

/// The paper's question, what tamping one block does to its neighbours: the compacity under
/// every block before tamping, after each tamped block's cycle (its withdrawal), and after
/// the release, from the `series.csv` row at or just before each moment (`summary.json`'s
/// `cycle` gives the moments). `None` for runs without blocks or cycle.
fn cycle_table(summary: &Value, t: &Table) -> Option<String> {
    let time = t.col("time_s")?;
    let blocks: Vec<(usize, usize)> = (1..)
        .map_while(|k| t.col(&format!("compacity_under_block_{k}")).map(|c| (k, c)))
        .collect();
    let cycles = summary.pointer("/cycle/blocks")?.as_array()?;
    if blocks.is_empty() || t.rows.is_empty() {
        return None;
    }
    let at = |when: f64| {
        t.rows
            .iter()
            .take_while(|r| r[time] <= when + 1e-9)
            .last()
            .or(t.rows.first())
    };
    let first = &t.rows[0];
    let mut moments: Vec<(String, &Vec<f64>)> =
        vec![(format!("start (t = {} s)", sig(Some(first[time]))), first)];
    for c in cycles {
        let (Some(b), Some(end)) = (c["block"].as_u64(), c["end_s"].as_f64()) else {
            continue;
        };
        let last = t.rows.last()?;
        if last[time] + 1e-9 < end {
            break;
        }
        moments.push((
            format!("after tamping block {b} (t = {} s)", secs(end)),
            at(end)?,
        ));
    }
    if let (Some(release), Some(last)) = (num(summary, "/cycle/release_s"), t.rows.last()) {
        if last[time] > release {
            moments.push((
                format!("end, after the release (t = {} s)", secs(last[time])),
                last,
            ));
        }
    }
    let mut s = String::new();
    let _ = writeln!(s, "## Compacity under each block, cycle by cycle\n");
    let _ = write!(s, "| moment |");
    for (k, _) in &blocks {
        let _ = write!(s, " block {k} |");
    }
    let _ = write!(s, "\n|---|");
    for _ in &blocks {
        let _ = write!(s, "---:|");
    }
    let _ = writeln!(s);
    for (i, (label, row)) in moments.iter().enumerate() {
        let _ = write!(s, "| {label} |");
        for &(_, c) in &blocks {
            let (v, v0) = (row[c], first[c]);
            let change = if i > 0 && v0 > 0.0 {
                format!(" ({:+.1} %)", 100.0 * (v - v0) / v0)
            } else {
                String::new()
            };
            let _ = write!(s, " {}{change} |", sig(Some(v)));
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(
        s,
        "\nSolid fraction in each block's control volume (its footprint, from the indicators' \
         depth below the design soffit up to it); in brackets the change since the start."
    );
    Some(s)
}

/// A time for a table: to 0.1 ms, no trailing zeros.
fn secs(t: f64) -> String {
    let s = format!("{t:.4}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// The text of `report.md`.
fn report_markdown(
    scenario_file: &Path,
    scenario_text: &str,
    summary: &Value,
    table: Option<&Table>,
    plots: &Plots,
) -> String {
    let name = scenario_file.file_name().map_or_else(
        || scenario_file.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let steps = num(summary, "/steps");
    let text = |p: &str| {
        summary
            .pointer(p)
            .map(|v| v.as_str().map_or_else(|| v.to_string(), str::to_string))
            .unwrap_or_else(|| "n/a".into())
    };
    let mut s = String::new();
    // Writing to a String cannot fail: the results are ignored.
    let _ = writeln!(s, "# ballast run report: `{name}`\n");
    let _ = writeln!(
        s,
        "Scenario `{name}` · {} steps · {} s simulated · {} bodies · {} thread(s) · subdomains {}\n",
        text("/steps"),
        sig(num(summary, "/time")),
        text("/bodies"),
        text("/threads"),
        text("/subdomains"),
    );

    let _ = writeln!(s, "## Parameters\n");
    let shown = excerpt(scenario_text, REPORT_LINES, REPORT_LINE_CHARS);
    let fence = fence_for(&shown);
    let _ = writeln!(s, "{fence}toml\n{}\n{fence}\n", shown.trim_end());

    let _ = writeln!(s, "## Timings (Table 1)\n");
    let total = num(summary, "/timings_s/total").filter(|t| *t > 0.0);
    let _ = writeln!(s, "| phase | time (s) | share of total | per step (ms) |");
    let _ = writeln!(s, "|---|---:|---:|---:|");
    for (phase, secs) in timing_rows(summary) {
        let share = match (secs, total) {
            (Some(v), Some(t)) => format!("{:.1} %", 100.0 * v / t),
            _ => "n/a".into(),
        };
        let per_step = match (secs, steps) {
            (Some(v), Some(n)) if n > 0.0 => format!("{:.3}", 1e3 * v / n),
            _ => "n/a".into(),
        };
        let secs = secs.map_or_else(|| "n/a".into(), |v| format!("{v:.3}"));
        let _ = writeln!(s, "| {phase} | {secs} | {share} | {per_step} |");
    }
    let _ = writeln!(
        s,
        "\nWall-clock seconds over the whole run. `subdomains` and `interface` are parts of \
         `nlgs` and are 0 for monolithic NLGS (subdomains 1x1x1).\n"
    );
    if let Some((name, caption)) = plots.made.iter().find(|(f, _)| f == PHASES_FIG) {
        let _ = writeln!(s, "{}", figure_markdown(name, caption));
    }

    let _ = writeln!(s, "## Results\n");
    let _ = writeln!(s, "| indicator | value |");
    let _ = writeln!(s, "|---|---|");
    let mut row = |k: &str, v: String| {
        let _ = writeln!(s, "| {k} | {v} |");
    };
    row(
        "NLGS iterations per step (mean)",
        sig(num(summary, "/solver/mean_iterations")),
    );
    row(
        "max residual",
        format!(
            "{} (tolerance {}, norm {})",
            sig(num(summary, "/solver/max_residual")),
            sig(num(summary, "/solver/tolerance")),
            text("/solver/norm")
        ),
    );
    let not_converged = text("/solver/steps_not_converged");
    let listed = if not_converged == "0" {
        ""
    } else {
        " (each in `quality.csv`)"
    };
    row(
        "steps not converged",
        format!("{not_converged} of {}{listed}", text("/steps")),
    );
    row(
        "contact points per step (mean / max)",
        format!(
            "{} / {}",
            sig(num(summary, "/contacts/mean")),
            text("/contacts/max")
        ),
    );
    row(
        "max interpenetration (mm)",
        sig(num(summary, "/max_penetration").map(|m| m * 1e3)),
    );
    row(
        "final kinetic energy (J)",
        sig(num(summary, "/kinetic_energy")),
    );
    if let Some(t) = table {
        for f in &FAMILIES {
            for (i, col) in t.names.iter().enumerate() {
                if col.starts_with(f.prefix) {
                    let (member_name, unit) = member(f, col);
                    let (shown, scale) = display_unit(&unit, t.max_abs(i));
                    row(
                        &format!("final {}, {member_name} ({shown})", f.quantity),
                        sig(t.last(i).map(|v| v * scale)),
                    );
                }
            }
        }
    }
    row("state digest", format!("`{}`", text("/state_digest")));
    let _ = writeln!(s);

    if let Some(t) = table {
        if let Some(md) = cycle_table(summary, t) {
            let _ = writeln!(s, "{md}");
        }
    }

    let _ = writeln!(s, "## Plots\n");
    if table.is_none() {
        let _ = writeln!(s, "No `series.csv` in the output folder: no time plots.\n");
    }
    for (name, caption) in plots.made.iter().filter(|(f, _)| f != PHASES_FIG) {
        let _ = writeln!(s, "### {caption}\n\n{}", figure_markdown(name, caption));
    }
    for e in &plots.errors {
        let _ = writeln!(s, "Plot not drawn: {e}\n");
    }
    s
}

/// Writes the scaling plots into `out_dir` (created), each as `NAME.svg` and `NAME.png`:
/// `speedup` (speedup versus threads per configuration, with the ideal line: the paper's
/// Fig. 4), `efficiency` (parallel efficiency in %), and `timings` (time per phase, one
/// stacked bar per configuration and thread count: the paper's Table 1). Configurations keep their order of first
/// appearance in `cases`.
pub fn write_scaling_plots(out_dir: &Path, cases: &[ScalingPoint]) -> Result<(), String> {
    std::fs::create_dir_all(out_dir)
        .map_err(|e| format!("cannot create {}: {e}", out_dir.display()))?;
    let mut labels: Vec<&str> = Vec::new();
    for c in cases {
        if !labels.contains(&c.0.as_str()) {
            labels.push(&c.0);
        }
    }
    let max_threads = cases.iter().map(|c| c.1).max().unwrap_or(1).max(1) as f64;
    let per_config = |value: &dyn Fn(&ScalingPoint) -> f64| -> Vec<Series> {
        labels
            .iter()
            .map(|&l| {
                let mut pts: Vec<(f64, f64)> = cases
                    .iter()
                    .filter(|c| c.0 == l)
                    .map(|c| (c.1 as f64, value(c)))
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                Series::new(l, pts, Style::LineMarkers)
            })
            .collect()
    };
    let ideal = |y: &dyn Fn(f64) -> f64| {
        Series::new(
            "ideal",
            vec![(1.0, y(1.0)), (max_threads, y(max_threads))],
            Style::Dashed,
        )
        .with_color(REFERENCE)
    };
    let write = |name: &str, fig: Figure| {
        write_figure(out_dir, name, &fig)
            .map_err(|e| format!("cannot write {}: {e}", out_dir.join(name).display()))
    };

    let mut series = per_config(&|c| c.2);
    series.push(ideal(&|p| p));
    let mut speedup = chart(
        "Speedup versus threads",
        "threads",
        "speedup T1/Tp (-)",
        series,
    );
    speedup.x_range = Some((0.0, max_threads));
    // From 0, and above the ideal line so it does not hide under the frame.
    let top = cases.iter().map(|c| c.2).fold(max_threads, f64::max);
    speedup.y_range = Some((0.0, top * 1.05));
    write("speedup", Figure::chart(speedup))?;

    let mut series = per_config(&|c| 100.0 * c.3);
    series.push(ideal(&|_| 100.0));
    let mut efficiency = chart(
        "Parallel efficiency versus threads",
        "threads",
        "efficiency speedup/threads (%)",
        series,
    );
    efficiency.x_range = Some((0.0, max_threads));
    let top = cases.iter().map(|c| 100.0 * c.3).fold(100.0, f64::max);
    efficiency.y_range = Some((0.0, top * 1.05));
    write("efficiency", Figure::chart(efficiency))?;

    let bars = BarChart {
        title: "Time per phase (Table 1)".into(),
        y_label: "wall-clock time over the timed steps (s)".into(),
        categories: cases
            .iter()
            .map(|c| format!("{}\n{} thr.", c.0, c.1))
            .collect(),
        segments: PHASES.iter().map(|s| s.to_string()).collect(),
        values: cases.iter().map(|c| c.4.to_vec()).collect(),
    };
    write("timings", Figure::Bars(bars))
}

#[cfg(test)]
mod tests {
    #[test]
    fn long_scenarios_are_cut_in_the_report() {
        let long = format!("a = \"{}\"\nb = 1\nc = 2\n", "x".repeat(1000));
        assert_eq!(
            super::excerpt(&long, 2, 10),
            "a = \"xxxxx # … 996 more characters, in scenario.toml\nb = 1\n\
             # … 1 more lines, in scenario.toml\n"
        );
        let short = "a = 1\nb = 2\n";
        assert_eq!(super::excerpt(short, 400, 300), short);
    }

    use super::*;
    use serde_json::json;
    use std::path::PathBuf;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ballast-report-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Removes a test folder, unless `BALLAST_KEEP_REPORT` is set (to look at the files).
    fn cleanup(dir: &Path) {
        if std::env::var_os("BALLAST_KEEP_REPORT").is_none() {
            let _ = std::fs::remove_dir_all(dir);
        }
    }

    fn summary() -> Value {
        json!({
            "steps": 40, "time": 0.04, "bodies": 120, "threads": 2, "subdomains": "1x1x1",
            "timings_s": {"detection": 0.5, "nlgs": 3.0, "subdomains": 0.0, "interface": 0.0,
                          "other": 0.5, "total": 4.0},
            "contacts": {"mean": 310.5, "max": 402},
            "solver": {"mean_iterations": 57.25, "max_residual": 8.5e-5,
                       "steps_not_converged": 0, "tolerance": 1e-4, "norm": "Quad"},
            "max_penetration": 2.5e-4, "kinetic_energy": 1.5e-3,
            "state_digest": "0123456789abcdef"
        })
    }

    /// An extra column: name and value at time t.
    type Column = (&'static str, fn(f64) -> f64);

    /// A fake `series.csv` with `extra` columns.
    fn write_series(dir: &Path, extra: &[Column]) {
        let mut s = String::from(
            "step,time_s,contacts,iterations,quad,residual,converged,max_penetration_m,\
             kinetic_energy_J,t_detection_s,t_nlgs_s,t_other_s",
        );
        for (n, _) in extra {
            s.push(',');
            s.push_str(n);
        }
        s.push('\n');
        for k in 1..=40 {
            let t = k as f64 * 1e-3;
            let _ = write!(
                s,
                "{k},{t:e},{},{},1e-5,{:e},1,{:e},{:e},0.01,0.07,0.01",
                200 + 5 * k,
                30 + k % 7,
                1e-5 * (1.0 + (k % 3) as f64),
                1e-4 * (k as f64).sqrt(),
                10.0 * (-(k as f64) / 4.0).exp()
            );
            for (_, f) in extra {
                let _ = write!(s, ",{:e}", f(t));
            }
            s.push('\n');
        }
        // An interrupted run's last line: cut short.
        s.push_str("41,4.1e-2,300");
        std::fs::write(dir.join("series.csv"), s).unwrap();
    }

    use crate::charts::tests::check;

    /// Three blocks tamped one after the other: the table takes each block's compacity at the
    /// start, at the end of each block's cycle (the row at or just before it) and at the end
    /// after the release, with the change since the start.
    #[test]
    fn cycle_table_gives_every_block_after_every_cycle() {
        let mut text = String::from(
            "step,time_s,compacity_under_block_1,compacity_under_block_2,compacity_under_block_3\n",
        );
        for k in 0..=100 {
            let t = k as f64 * 0.01;
            // Block j densifies linearly during its cycle [0.2 j, 0.2 j + 0.2] (j = 0, 1, 2).
            let c = |j: f64| 0.5 + 0.05 * ((t - 0.2 * j - 0.1) / 0.2).clamp(0.0, 1.0);
            let _ = writeln!(text, "{k},{t},{},{},{}", c(0.0), c(1.0), c(2.0));
        }
        let t = Table::parse(&text);
        let cycle = |b: u64, end: f64| serde_json::json!({"block": b, "end_s": end});
        let summary = serde_json::json!({"cycle": {
            "blocks": [cycle(1, 0.305), cycle(2, 0.505), cycle(3, 0.705)],
            "release_s": 0.705,
        }});
        let md = cycle_table(&summary, &t).unwrap();
        let lines: Vec<&str> = md.lines().filter(|l| l.starts_with("| ")).collect();
        assert_eq!(lines.len(), 6, "{md}");
        assert!(lines[0].contains("block 1 | block 2 | block 3"), "{md}");
        assert_eq!(lines[1], "| start (t = 0 s) | 0.5000 | 0.5000 | 0.5000 |");
        // At 0.30 s (the row before 0.305 s) block 1 is done, block 2 not started.
        assert_eq!(
            lines[2],
            "| after tamping block 1 (t = 0.305 s) | 0.5500 (+10.0 %) | 0.5000 (+0.0 %) | 0.5000 (+0.0 %) |"
        );
        assert!(lines[4].starts_with("| after tamping block 3 (t = 0.705 s) | 0.5500 (+10.0 %) | 0.5500 (+10.0 %) | 0.5500 (+10.0 %)"), "{md}");
        assert!(
            lines[5].starts_with("| end, after the release (t = 1 s)"),
            "{md}"
        );
        // No cycle in the summary (an engine scenario): no table.
        assert!(cycle_table(&serde_json::json!({}), &t).is_none());
    }

    #[test]
    fn run_report_has_table_plots_and_indicators() {
        let dir = scratch("run");
        write_series(
            &dir,
            &[
                ("compacity_1", |t| 0.58 + t),
                ("compacity_crib_left", |t| 0.6 - t),
                ("tine_force_1_N", |t| 5e4 * t),
                ("block_z_1_m", |t| 0.45 - t * 0.1),
                ("coordination", |t| 4.0 + t),
            ],
        );
        let scenario = "# test scenario\n[simulation]\ndt = 1e-3\n```not a fence```\n";
        // A huge value (a vertex list) and a long file are cut in the report.
        let long_value = format!("vertices = [{}]", "[0.1, 0.2, 0.3], ".repeat(20_000));
        let many_lines = "# a comment line\n".repeat(2_000);
        let scenario = format!("{scenario}{long_value}\n{many_lines}");
        let scenario = scenario.as_str();
        write_run_report(
            &dir,
            Path::new("scenarios/tamping.toml"),
            scenario,
            &summary(),
        )
        .unwrap();
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.len() < 40_000, "report.md is {} bytes", md.len());
        assert!(md.contains(&format!(
            "vertices = [{} # … {} more characters, in scenario.toml",
            &"[0.1, 0.2, 0.3], ".repeat(20)[..REPORT_LINE_CHARS - 12],
            long_value.len() - REPORT_LINE_CHARS
        )));
        assert!(md.contains("more lines, in scenario.toml"));
        for needle in [
            "# ballast run report: `tamping.toml`",
            "````toml\n# test scenario",
            "| detection | 0.500 | 12.5 % | 12.500 |",
            "| nlgs | 3.000 | 75.0 % |",
            "| of which subdomains | 0.000 | 0.0 % |",
            "| of which interface | 0.000 |",
            "| other | 0.500 | 12.5 % |",
            "| total | 4.000 | 100.0 % | 100.000 |",
            "| NLGS iterations per step (mean) | 57.25 |",
            "| steps not converged | 0 of 40 |",
            "| contact points per step (mean / max) | 310.5 / 402 |",
            "| max interpenetration (mm) | 0.2500 |",
            "norm Quad",
            "| final compacity, CV 1 (-) | 0.6200 |",
            "| final compacity, crib left (-) |",
            "| final tine force, tine 1 (kN) | 2.000 |",
            "| final block height z, block 1 (mm) | 446.0 |",
            "| final contacts per grain, mean (-) | 4.040 |",
            "`0123456789abcdef`",
        ] {
            assert!(md.contains(needle), "missing {needle:?} in\n{md}");
        }
        // Every figure in both formats, shown (PNG) and linked (SVG), with its axis labels.
        for (name, labels) in [
            (
                "solver",
                &["time (s)", "contacts (-)", "iterations (-)", "residual (-)"][..],
            ),
            ("energy", &["time (s)", "kinetic energy (J)"]),
            ("penetration", &["time (s)", "max interpenetration (mm)"]),
            ("timings", &["time (s)", "time per step (ms)", "nlgs"]),
            ("phases", &["wall-clock time (s)", "other"]),
            ("compacity", &["time (s)", "compacity (-)", "crib left"]),
            ("tines", &["time (s)", "tine force (kN)"]),
            ("blocks", &["time (s)", "block height z (mm)"]),
            ("coordination", &["time (s)", "contacts per grain (-)"]),
        ] {
            for ext in ["png", "svg"] {
                assert!(
                    md.contains(&format!("](plots/{name}.{ext})")),
                    "no link to {name}.{ext}"
                );
            }
            check::figure(&dir.join("plots"), name, labels);
        }
        // Same data, same figures, byte for byte.
        let again = scratch("run-again");
        std::fs::copy(dir.join("series.csv"), again.join("series.csv")).unwrap();
        write_run_report(&again, Path::new("t.toml"), "", &summary()).unwrap();
        for e in std::fs::read_dir(dir.join("plots")).unwrap() {
            let n = e.unwrap().file_name();
            let (a, b) = (dir.join("plots").join(&n), again.join("plots").join(&n));
            assert!(
                std::fs::read(a).unwrap() == std::fs::read(b).unwrap(),
                "{n:?}"
            );
        }
        cleanup(&again);
        // Nothing temporary left behind.
        for d in [dir.clone(), dir.join("plots")] {
            for e in std::fs::read_dir(d).unwrap() {
                let n = e.unwrap().file_name().to_string_lossy().into_owned();
                assert!(!n.contains(".tmp"), "left over {n}");
            }
        }
        cleanup(&dir);
    }

    #[test]
    fn run_report_without_optional_columns_or_series() {
        let dir = scratch("plain");
        write_series(&dir, &[]);
        write_run_report(&dir, Path::new("a.toml"), "", &json!({})).unwrap();
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.contains("| detection | n/a | n/a | n/a |"));
        assert!(md.contains("](plots/solver.png)") && md.contains("](plots/solver.svg)"));
        assert!(!md.contains("compacity.png") && !dir.join("plots/compacity.png").exists());
        assert!(!dir.join("plots/compacity.svg").exists());

        std::fs::remove_file(dir.join("series.csv")).unwrap();
        write_run_report(&dir, Path::new("a.toml"), "x = 1", &summary()).unwrap();
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.contains("No `series.csv`"));
        assert!(md.contains("](plots/phases.png)"));
        cleanup(&dir);
    }

    #[test]
    fn scaling_plots_decode() {
        let dir = scratch("scaling");
        let mut cases = Vec::new();
        for (label, serial) in [("NLGS", 0.7), ("DDM 2x2x1", 0.9)] {
            for p in [1usize, 2, 4] {
                let s = 1.0 / ((1.0 - serial) + serial / p as f64);
                let total = 10.0 / s;
                cases.push((
                    label.to_string(),
                    p,
                    s,
                    s / p as f64,
                    [0.1 * total, 0.7 * total, 0.1 * total, 0.1 * total],
                ));
            }
        }
        write_scaling_plots(&dir.join("plots"), &cases).unwrap();
        let plots = dir.join("plots");
        check::figure(
            &plots,
            "speedup",
            &["threads", "speedup T1/Tp (-)", "ideal", "NLGS"],
        );
        check::figure(
            &plots,
            "efficiency",
            &["threads", "efficiency speedup/threads (%)"],
        );
        check::figure(
            &plots,
            "timings",
            &[
                "wall-clock time over the timed steps (s)",
                "DDM 2x2x1",
                "4 thr.",
            ],
        );
        write_scaling_plots(&dir.join("empty"), &[]).unwrap();
        for name in ["speedup", "efficiency", "timings"] {
            check::figure(
                &dir.join("empty"),
                name,
                &["threads"][..usize::from(name != "timings")],
            );
        }
        cleanup(&dir);
    }

    #[test]
    fn column_names_give_legend_names_and_units() {
        let f = &FAMILIES[1];
        assert_eq!(member(f, "tine_force_2_N"), ("tine 2".into(), "N".into()));
        assert_eq!(
            member(f, "tine_force_left_kN"),
            ("left".into(), "kN".into())
        );
        assert_eq!(member(f, "tine_force_N"), ("tine".into(), "N".into()));
        // The track model's columns: per tine and axis, per block, per control volume.
        assert_eq!(
            member(f, "tine_force_3_z_N"),
            ("tine 3 z".into(), "N".into())
        );
        assert_eq!(
            member(&FAMILIES[2], "block_z_1_m"),
            ("block 1".into(), "m".into())
        );
        assert_eq!(
            member(&FAMILIES[0], "compacity_under_block_1"),
            ("under block 1".into(), "-".into())
        );
        assert_eq!(
            member(&FAMILIES[0], "compacity_3"),
            ("CV 3".into(), "-".into())
        );
        assert_eq!(fence_for("a ``` b ```` c"), "`````");
        assert_eq!(fence_for("plain"), "```");
        assert_eq!(sig(Some(0.000123456)), "1.235e-4");
        assert_eq!(sig(Some(57.25)), "57.25");
        assert_eq!(sig(None), "n/a");
    }
}
