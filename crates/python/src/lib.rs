//! `ballast._ballast`: the compiled core of the Python package `ballast` (see
//! `python/ballast/__init__.py` for the public API and its documentation). A thin front end
//! over the engine's and the railway crate's library API, like the CLI: scenarios in, steps
//! (with the GIL released), arrays, contact problems and summaries out.

use ballast_engine::laws::ContactStatus;
use ballast_engine::math::DVec3;
use ballast_engine::output::checkpoint::{read_checkpoint_with_stats, write_checkpoint_with_stats};
use ballast_engine::output::vtk::VtkWriter;
use ballast_engine::solver::{BlockMatrix, ContactProblem, ConvergenceNorm, SolverSettings};
use ballast_engine::world::{StepReport, World};
use ballast_railway::TrackScenario;
use ballast_run::{ArgNames, BuildOptions, Failure, Job, Observer, Plain, RunOptions};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use numpy::{PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyIOError, PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};

/// A scenario's error as Python's `ValueError`, with the engine's message (it names the
/// field, the value and what is allowed).
fn value_error(e: impl ToString) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// A [`Failure`] of the run library as the Python exception of its kind (a diverged or
/// interrupted run is raised by `Simulation.run`, which sees the observer's exception too).
fn failure_error(f: Failure) -> PyErr {
    match f {
        Failure::Io(m) => PyIOError::new_err(m),
        Failure::Diverged(m) => DivergedError::new_err(m),
        Failure::Interrupted(m) => PyKeyboardInterrupt::new_err(m),
        Failure::Error(m) => value_error(m),
    }
}

/// `(n, 3)` array of vectors.
fn vec3_array<'py>(py: Python<'py>, v: &[DVec3]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = v.iter().flat_map(|x| x.to_array()).collect();
    flat.into_pyarray(py)
        .reshape([v.len(), 3])
        .expect("n × 3 elements")
}

pyo3::create_exception!(
    ballast,
    DivergedError,
    PyRuntimeError,
    "A run or a step stopped by the health check: its state stopped being physical (the \
     message names the step, the bodies and the quantity). After `run`, its run folder is \
     written; after `step`, the simulation is back at its last healthy step."
);

/// A simulation: a world stepping through a scenario (engine scenario or track scenario),
/// with what its run folder needs (the run library's [`Job`]).
#[pyclass(module = "ballast._ballast")]
struct Simulation {
    job: Job,
    /// The ParaView series `write_vtk` last wrote, and its folder.
    vtk: Option<(PathBuf, VtkWriter)>,
}

/// How `Simulation.run`'s messages name its arguments.
const NAMES: ArgNames = ArgNames {
    out: |d| format!("out='{}'", d.display()),
    resume: |d| format!("resume=True (out='{}')", d.display()),
    resume_command: |d| format!("`run('{}', resume=True)`", d.display()),
    overwrite: "overwrite=True",
    steps: "steps",
    subdomains: "subdomains",
};

/// Builds a simulation from scenario text; `source` names it in messages and reports.
fn build(source: &str, text: &str, cache: Option<&Path>) -> PyResult<Simulation> {
    let options = BuildOptions {
        cache,
        subdomains: None,
        quiet: true,
        names: &NAMES,
        exchange: None,
    };
    let job = Job::build(source, text, &options, &mut Plain).map_err(failure_error)?;
    Ok(Simulation { job, vtk: None })
}

/// `Simulation.run`'s view of a run: `progress(step_index, time)` every `every` steps and at
/// the end, Python's signals (Ctrl-C) looked at between steps, messages on `sys.stderr`. The
/// first exception (from `progress` or a signal) stops the run after the step.
struct PyObserver {
    progress: Option<Py<PyAny>>,
    every: u64,
    total: u64,
    error: Option<PyErr>,
    /// When Python's signals were last looked at.
    checked: std::time::Instant,
}

/// How often a run looks at Python's signals (s): often enough for Ctrl-C, seldom enough not
/// to wait on other Python threads for the GIL every step.
const SIGNAL_CHECK_S: f64 = 0.1;

impl Observer for PyObserver {
    fn start(&mut self, total: u64) {
        self.total = total;
    }

    fn step(&mut self, done: u64, r: &StepReport) {
        if self.error.is_some() {
            return;
        }
        let report = done.is_multiple_of(self.every) || done == self.total;
        let check = self.checked.elapsed().as_secs_f64() >= SIGNAL_CHECK_S;
        if !report && !check {
            return;
        }
        self.checked = std::time::Instant::now();
        Python::attach(|py| {
            let called = match (&self.progress, report) {
                (Some(f), true) => f.call1(py, (r.step, r.time)).map(|_| ()),
                _ => Ok(()),
            };
            if let Err(e) = called.and_then(|()| py.check_signals()) {
                self.error = Some(e);
            }
        });
    }

    fn stop_requested(&mut self) -> bool {
        self.error.is_some()
    }

    fn message(&mut self, line: &str) {
        let written = Python::attach(|py| -> PyResult<()> {
            let err = py.import("sys")?.getattr("stderr")?;
            err.call_method1("write", (format!("{line}\n"),))?;
            Ok(())
        });
        if written.is_err() {
            eprintln!("{line}");
        }
    }
}

/// `base` with every key of `over` set over it, table by table.
fn overlay(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => overlay(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

#[pymethods]
impl Simulation {
    /// A simulation from scenario text, or from the path of a scenario file.
    #[staticmethod]
    #[pyo3(signature = (text_or_path, cache = None))]
    fn from_toml(text_or_path: &str, cache: Option<PathBuf>) -> PyResult<Self> {
        let path = Path::new(text_or_path);
        // Messages and the report name a file by its path, text as "scenario".
        let (source, text) = if !text_or_path.contains('\n') && path.is_file() {
            let text = std::fs::read_to_string(path)
                .map_err(|e| PyIOError::new_err(format!("cannot read {text_or_path}: {e}")))?;
            (text_or_path, text)
        } else {
            ("scenario", text_or_path.to_string())
        };
        build(source, &text, cache.as_deref())
    }

    /// A built-in track scenario (`default`, `paper`) with `overlay` (TOML text) set over it.
    #[staticmethod]
    #[pyo3(signature = (preset = "default", cache = None, overlay_toml = ""))]
    fn track(preset: &str, cache: Option<PathBuf>, overlay_toml: &str) -> PyResult<Self> {
        let base = TrackScenario::preset(preset).map_err(value_error)?;
        let mut table: toml::Table = toml::from_str(&base.to_toml()).map_err(value_error)?;
        let over: toml::Table =
            toml::from_str(overlay_toml).map_err(|e| value_error(format!("overrides: {e}")))?;
        overlay(&mut table, over);
        let text = toml::to_string(&table).map_err(value_error)?;
        build(&format!("preset {preset}"), &text, cache.as_deref())
    }

    /// Advances `n` steps with the GIL released; `progress(step_index, time)` is called
    /// (with the GIL) every `every` steps. With `check`, every step is under the run's health
    /// check: a step that diverges raises `DivergedError` naming the step, the bodies and the
    /// quantity, the simulation put back to its state before that step (see
    /// `Job::checked_step`).
    #[pyo3(signature = (n = 1, progress = None, every = 100, check = true))]
    fn step(
        &mut self,
        py: Python<'_>,
        n: u64,
        progress: Option<Py<PyAny>>,
        every: u64,
        check: bool,
    ) -> PyResult<()> {
        let every = every.max(1);
        let mut done = 0;
        while done < n {
            let chunk = (n - done).min(every);
            let job = &mut self.job;
            let stepped = py.detach(|| -> Result<(), String> {
                for _ in 0..chunk {
                    if !check {
                        job.step();
                        continue;
                    }
                    let restorable = !job.world().is_detected();
                    job.checked_step().map_err(|d| {
                        let now = job.world().step_index;
                        let left = if d.step == 0 {
                            "the simulation is left at its initial state (step 0)".to_string()
                        } else if restorable {
                            format!(
                                "the simulation is put back to step {now}, its last healthy state"
                            )
                        } else {
                            format!(
                                "the simulation is left in the diverged state of step {now} \
                                 (the step was detected by detect() first)"
                            )
                        };
                        format!("{d}; {left}")
                    })?;
                }
                Ok(())
            });
            stepped.map_err(DivergedError::new_err)?;
            done += chunk;
            if let Some(f) = &progress {
                f.call1(py, (self.world().step_index, self.world().time))?;
            }
        }
        Ok(())
    }

    /// Runs the simulation into the run folder `out`, as `ballast run` does (`scenario.toml`,
    /// `series.csv`, `summary.json`, `report.md`, `plots/`, `*.pvd` with `vtk/`,
    /// `checkpoints/`, `sections/` for track runs), up to step `steps` (the scenario's count
    /// when `None`), with the GIL released; or continues the run in `out` from its newest
    /// checkpoint (`resume`). Returns `summary.json` as JSON text.
    #[pyo3(signature = (out, steps = None, overwrite = false, resume = false, progress = None, every = 100, quiet = false))]
    #[allow(clippy::too_many_arguments)]
    fn run(
        &mut self,
        py: Python<'_>,
        out: PathBuf,
        steps: Option<u64>,
        overwrite: bool,
        resume: bool,
        progress: Option<Py<PyAny>>,
        every: u64,
        quiet: bool,
    ) -> PyResult<String> {
        if every == 0 {
            return Err(value_error(
                "every = 0: must be a whole number of steps ≥ 1",
            ));
        }
        if overwrite && resume {
            return Err(value_error(
                "overwrite=True with resume=True: a resumed run keeps its folder's files; give \
                 one of them",
            ));
        }
        if self.job.world().is_detected() {
            // A run's first step detects and checks its own contacts.
            return Err(PyRuntimeError::new_err(
                "run: a step is detected but not solved; call step() first",
            ));
        }
        self.vtk = None;
        let options = RunOptions {
            out: &out,
            resume,
            overwrite,
            steps,
            threads: rayon_threads(),
            quiet,
            names: &NAMES,
        };
        let mut observer = PyObserver {
            progress,
            every,
            total: 0,
            error: None,
            checked: std::time::Instant::now(),
        };
        let job = &mut self.job;
        let result = py.detach(|| job.run(&options, &mut observer));
        match (result, observer.error) {
            (Err(Failure::Interrupted(m)), Some(e))
                if e.is_instance_of::<PyKeyboardInterrupt>(py) =>
            {
                Err(PyKeyboardInterrupt::new_err(m))
            }
            (_, Some(e)) => Err(e),
            (Ok(o), None) => serde_json::to_string(&o.summary)
                .map_err(|e| PyRuntimeError::new_err(e.to_string())),
            (Err(f), None) => Err(failure_error(f)),
        }
    }

    /// Simulated time (s).
    #[getter]
    fn time(&self) -> f64 {
        self.world().time
    }

    /// Steps done.
    #[getter]
    fn step_index(&self) -> u64 {
        self.world().step_index
    }

    /// Number of bodies.
    #[getter]
    fn body_count(&self) -> usize {
        self.world().bodies.len()
    }

    /// The scenario's step count (a track scenario: its whole cycle).
    #[getter]
    fn steps(&self) -> u64 {
        self.job.steps()
    }

    /// Time step (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.world().settings.dt
    }

    /// The resolved scenario (TOML).
    #[getter]
    fn scenario(&self) -> String {
        self.job.scenario().to_string()
    }

    /// Hash of every body's position, orientation and velocities (as in `summary.json`).
    fn state_digest(&self) -> String {
        self.world().state_digest()
    }

    /// The keys of `summary.json`, as JSON text.
    fn summary_json(&self) -> PyResult<String> {
        let s = self
            .job
            .summary(rayon_threads())
            .map_err(PyRuntimeError::new_err)?;
        serde_json::to_string(&s).map_err(|e| PyRuntimeError::new_err(e.to_string()))
    }

    /// Body centres, `(N, 3)` (m).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, &self.world().bodies.position)
    }

    /// Body orientations as unit quaternions `(x, y, z, w)` (scalar last), `(N, 4)`.
    #[getter]
    fn orientations<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let q = &self.world().bodies.orientation;
        let flat: Vec<f64> = q.iter().flat_map(|q| q.to_array()).collect();
        flat.into_pyarray(py)
            .reshape([q.len(), 4])
            .expect("n × 4 elements")
    }

    /// Body velocities, `(N, 3)` (m/s).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, &self.world().bodies.velocity)
    }

    /// Body angular velocities (world frame), `(N, 3)` (rad/s).
    #[getter]
    fn angular_velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vec3_array(py, &self.world().bodies.angular_velocity)
    }

    /// Body masses (kg; `inf` for bodies without one: fixed bodies and planes).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let b = &self.world().bodies;
        let m: Vec<f64> = b
            .inv_mass
            .iter()
            .map(|&im| if im > 0.0 { 1.0 / im } else { f64::INFINITY })
            .collect();
        m.into_pyarray(py)
    }

    /// Body kinds: `"dynamic"`, `"kinematic"` or `"fixed"`.
    #[getter]
    fn kinds(&self) -> Vec<String> {
        self.world()
            .bodies
            .kind
            .iter()
            .map(|k| format!("{k:?}").to_lowercase())
            .collect()
    }

    /// Body friction groups.
    #[getter]
    fn groups<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        self.world().bodies.group.clone().into_pyarray(py)
    }

    /// The contacts of the last step (or of the step detected by `detect()`): arrays
    /// `body1`, `body2`, `point`, `normal`, `gap`, `impulse` (local frame `(n, t, s)`, N·s),
    /// `status` (0 open, 1 stick, 2 slide).
    fn contacts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = &self.world().contacts;
        let d = PyDict::new(py);
        d.set_item("body1", c.body1.clone().into_pyarray(py))?;
        d.set_item("body2", c.body2.clone().into_pyarray(py))?;
        d.set_item("point", vec3_array(py, &c.point))?;
        let normals: Vec<DVec3> = c.frame.iter().map(|f| f[0]).collect();
        d.set_item("normal", vec3_array(py, &normals))?;
        d.set_item("gap", c.gap.clone().into_pyarray(py))?;
        d.set_item("impulse", vec3_array(py, &c.impulse))?;
        let status: Vec<u8> = c
            .status
            .iter()
            .map(|s| match s {
                ContactStatus::NoContact => 0,
                ContactStatus::Stick => 1,
                ContactStatus::Slide => 2,
            })
            .collect();
        d.set_item("status", status.into_pyarray(py))?;
        Ok(d)
    }

    /// Detects the next step's contacts and builds its local problems (the step's first
    /// phase); the next `step()` solves them. Returns the largest overlap (m).
    fn detect(&mut self) -> f64 {
        self.job.world_mut().detect()
    }

    /// The contact problem of the next step (detected first if needed): block-sparse `W`
    /// (`indptr`, `indices`, `blocks` of shape `(nnzb, 3, 3)`), `q` `(n, 3)`, `mu` `(n,)`,
    /// `scale` (`‖Hᵀ V_free‖`); and its global form (see `GlobalProblem`): `bodies` `(nb,)`,
    /// `mass` `(nb,)` and `inertia` `(nb, 3, 3)` (world frame), the solver's `inv_mass` and
    /// `inv_inertia` (zero on a degree of freedom a drive imposes), `v_free` `(nb, 6)`,
    /// `H` as blocks `H_blocks` `(nh, 6, 3)` at `H_body`, `H_contact`, and `b` `(n, 3)`.
    fn contact_problem<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.job.world_mut().detect();
        let p = self.world().contact_problem();
        let d = problem_dict(py, &p)?;
        let g = self.world().global_problem(&p);
        let b = &self.world().bodies;
        let nb = g.bodies.len();
        let mat_array = |ms: Vec<ballast_engine::math::DMat3>| {
            let k = ms.len();
            let flat: Vec<f64> = ms
                .iter()
                .flat_map(|m| m.transpose().to_cols_array())
                .collect();
            flat.into_pyarray(py)
                .reshape([k, 3, 3])
                .expect("k × 3 × 3 elements")
        };
        let ids: Vec<i64> = g.bodies.iter().map(|&i| i64::from(i)).collect();
        d.set_item("bodies", ids.into_pyarray(py))?;
        let mass: Vec<f64> = g.bodies.iter().map(|&i| b.mass(i as usize)).collect();
        d.set_item("mass", mass.into_pyarray(py))?;
        d.set_item(
            "inertia",
            mat_array(
                g.bodies
                    .iter()
                    .map(|&i| b.inertia_world(i as usize))
                    .collect(),
            ),
        )?;
        d.set_item("inv_mass", g.inv_mass.clone().into_pyarray(py))?;
        d.set_item("inv_inertia", mat_array(g.inv_inertia.clone()))?;
        let vf: Vec<f64> = g
            .v_free
            .iter()
            .flat_map(|[v, w]| v.to_array().into_iter().chain(w.to_array()))
            .collect();
        d.set_item(
            "v_free",
            vf.into_pyarray(py).reshape([nb, 6]).expect("nb × 6"),
        )?;
        let nh = g.h.len();
        let hb: Vec<f64> =
            g.h.iter()
                .flat_map(|h| {
                    // Rows: force x y z, torque x y z; columns: n, t, s.
                    let (f, t) = (h.force.transpose(), h.torque.transpose());
                    f.to_cols_array().into_iter().chain(t.to_cols_array())
                })
                .collect();
        d.set_item(
            "H_blocks",
            hb.into_pyarray(py).reshape([nh, 6, 3]).expect("nh × 6 × 3"),
        )?;
        let hbody: Vec<i64> = g.h.iter().map(|h| i64::from(h.body)).collect();
        let hcontact: Vec<i64> = g.h.iter().map(|h| i64::from(h.contact)).collect();
        d.set_item("H_body", hbody.into_pyarray(py))?;
        d.set_item("H_contact", hcontact.into_pyarray(py))?;
        d.set_item("b", vec3_array(py, &g.b))?;
        Ok(d)
    }

    /// Writes the current state as a frame of the ParaView series in `dir` (`grains.pvd`,
    /// `bodies.pvd`, `contacts.pvd` and `dir/vtk/*.vtu`, the CLI's layout). Successive calls
    /// on one folder add frames; a folder written before keeps its frames up to the current
    /// time (as a resumed run does).
    fn write_vtk(&mut self, dir: PathBuf) -> PyResult<()> {
        let io =
            |e: std::io::Error| PyIOError::new_err(format!("write_vtk {}: {e}", dir.display()));
        let same = matches!(&self.vtk, Some((d, _)) if *d == dir);
        if !same {
            let w = VtkWriter::resume(&dir, self.world().time).map_err(io)?;
            self.vtk = Some((dir.clone(), w));
        }
        let (_, w) = self.vtk.as_mut().expect("opened above");
        w.write_frame(self.job.world()).map_err(io)
    }

    /// The track indicators (the columns `series.csv` adds) at the current state.
    fn indicators<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let Some(ind) = self.job.indicators() else {
            return Err(PyValueError::new_err(
                "indicators: this simulation is not a track scenario (no [track] table)",
            ));
        };
        let d = PyDict::new(py);
        for (name, v) in ind.names().iter().zip(ind.values(self.world())) {
            d.set_item(name, v)?;
        }
        Ok(d)
    }

    /// Writes a checkpoint (atomic) from which `resume` continues bit-identically.
    fn checkpoint(&self, path: PathBuf) -> PyResult<()> {
        if self.world().is_detected() {
            return Err(PyRuntimeError::new_err(
                "checkpoint: a step is detected but not solved; call step() first",
            ));
        }
        write_checkpoint_with_stats(self.world(), Some(self.job.stats()), &path)
            .map_err(|e| PyIOError::new_err(format!("checkpoint {}: {e}", path.display())))
    }

    /// Reads a checkpoint written by `checkpoint` into this simulation, which must be built
    /// from the same scenario.
    fn load_checkpoint(&mut self, path: PathBuf) -> PyResult<()> {
        let stats = read_checkpoint_with_stats(&path, self.job.world_mut())
            .map_err(|e| value_error(format!("checkpoint {}: {e}", path.display())))?;
        *self.job.stats_mut() = stats.unwrap_or_default();
        Ok(())
    }
}

impl Simulation {
    fn world(&self) -> &World {
        self.job.world()
    }
}

/// The worker threads steps use.
fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn problem_dict<'py>(py: Python<'py>, p: &ContactProblem) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let indptr: Vec<i64> = p.w.row_start.iter().map(|&x| x as i64).collect();
    let indices: Vec<i64> = p.w.cols.iter().map(|&x| i64::from(x)).collect();
    let flat: Vec<f64> =
        p.w.blocks
            .iter()
            // Row-major 3×3 blocks (glam stores columns).
            .flat_map(|b| b.transpose().to_cols_array())
            .collect();
    let nb = p.w.blocks.len();
    d.set_item("indptr", indptr.into_pyarray(py))?;
    d.set_item("indices", indices.into_pyarray(py))?;
    d.set_item(
        "blocks",
        flat.into_pyarray(py)
            .reshape([nb, 3, 3])
            .expect("nnzb × 3 × 3 elements"),
    )?;
    d.set_item("q", vec3_array(py, &p.q))?;
    d.set_item("mu", p.mu.clone().into_pyarray(py))?;
    d.set_item("scale", p.scale)?;
    d.set_item("compliance", p.compliance)?;
    d.set_item("tangential_compliance", p.tangential_compliance)?;
    let flat: Vec<f64> = p.compliances.iter().flatten().copied().collect();
    d.set_item(
        "compliances",
        flat.into_pyarray(py)
            .reshape([p.compliances.len(), 2])
            .expect("n × 2 elements"),
    )?;
    Ok(d)
}

/// NLGS on a contact problem `(W, q, μ)` given as block-sparse rows: returns `(r, u,
/// iterations, residual, converged)`.
#[pyfunction]
#[pyo3(signature = (indptr, indices, blocks, q, mu, tolerance, max_iterations, r0 = None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn solve_fc3d_blocks<'py>(
    py: Python<'py>,
    indptr: PyReadonlyArray1<'py, i64>,
    indices: PyReadonlyArray1<'py, i64>,
    blocks: PyReadonlyArray3<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    mu: PyReadonlyArray1<'py, f64>,
    tolerance: f64,
    max_iterations: usize,
    r0: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    usize,
    f64,
    bool,
)> {
    let n = q.shape()[0];
    let vec3s = |a: &PyReadonlyArray2<'py, f64>, name: &str| -> PyResult<Vec<DVec3>> {
        if a.shape().len() != 2 || a.shape()[1] != 3 || a.shape()[0] != n {
            return Err(value_error(format!(
                "{name}: shape {:?}, expected ({n}, 3)",
                a.shape()
            )));
        }
        let s = a.as_slice().map_err(value_error)?;
        Ok(s.chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect())
    };
    let qv = vec3s(&q, "q")?;
    let mu = mu.as_slice().map_err(value_error)?.to_vec();
    let ptr: Vec<usize> = indptr
        .as_slice()
        .map_err(value_error)?
        .iter()
        .map(|&x| x as usize)
        .collect();
    let cols: Vec<u32> = indices
        .as_slice()
        .map_err(value_error)?
        .iter()
        .map(|&x| x as u32)
        .collect();
    let b = blocks.as_slice().map_err(value_error)?;
    if mu.len() != n || ptr.len() != n + 1 || ptr.last() != Some(&cols.len()) {
        return Err(value_error(format!(
            "W: {} block rows and {} stored blocks for {n} contacts and {} coefficients",
            ptr.len().saturating_sub(1),
            cols.len(),
            mu.len()
        )));
    }
    if b.len() != 9 * cols.len() || cols.iter().any(|&c| c as usize >= n) {
        return Err(value_error(
            "W: blocks must have shape (nnzb, 3, 3), columns < n",
        ));
    }
    let blocks: Vec<ballast_engine::math::DMat3> = b
        .chunks_exact(9)
        .map(|m| {
            ballast_engine::math::DMat3::from_cols_array(&m.try_into().expect("9")).transpose()
        })
        .collect();
    let scale = qv.iter().map(|x| x.length_squared()).sum::<f64>().sqrt();
    let problem = ContactProblem {
        w: BlockMatrix {
            row_start: ptr,
            cols,
            blocks,
        },
        q: qv,
        mu,
        scale,
        compliance: 0.0,
        tangential_compliance: 0.0,
        compliances: vec![[0.0; 2]; n],
    };
    let mut r = match &r0 {
        Some(a) => vec3s(a, "r0")?,
        None => vec![DVec3::ZERO; n],
    };
    let settings = SolverSettings {
        tolerance,
        residual_tolerance: tolerance,
        max_iterations: max_iterations.max(1),
        norm: ConvergenceNorm::NaturalMap,
        ..Default::default()
    };
    let report = py.detach(|| problem.solve_nlgs(&mut r, &settings));
    let u = problem.velocity(&r);
    Ok((
        vec3_array(py, &r),
        vec3_array(py, &u),
        report.iterations,
        report.residual,
        report.converged,
    ))
}

/// The TOML of a built-in track scenario.
#[pyfunction]
fn preset_toml(name: &str) -> PyResult<String> {
    Ok(TrackScenario::preset(name).map_err(value_error)?.to_toml())
}

#[pymodule]
fn _ballast(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Simulation>()?;
    m.add("DivergedError", m.py().get_type::<DivergedError>())?;
    m.add_function(wrap_pyfunction!(solve_fc3d_blocks, m)?)?;
    m.add_function(wrap_pyfunction!(preset_toml, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
