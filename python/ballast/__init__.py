"""ballast: Non-Smooth Contact Dynamics of railway ballast, scripted from Python.

The time loop is yours, as in LMGC90's ChiPy or a YADE script::

    import ballast
    sim = ballast.Simulation.from_toml("examples/pile.toml")
    sim.step(100)                       # the GIL is released while it runs
    print(sim.time, sim.positions.shape, sim.summary()["solver"])

    track = ballast.Simulation.track("default", cache="~/.cache/ballast",
                                     tamping={"frequency": 30.0})
    track.step(50)
    print(track.indicators()["compacity_under_block_1"])

A step's phases: ``sim.detect()`` (contacts and local problems of the next step),
``sim.contact_problem()`` (its ``(W, q, mu)``), ``sim.step()`` (solve and integrate). Any
contact problem ``u = W r + q`` with Signorini-Coulomb friction can be solved with
:func:`solve_fc3d` (ballast's NLGS).

Units are SI. Arrays are copies (changing them does not change the simulation).
"""

import json
import os

import numpy as np

from ._ballast import DivergedError, __version__, preset_toml
from ._ballast import Simulation as _Core
from ._ballast import solve_fc3d_blocks as _solve_blocks

__all__ = [
    "Simulation",
    "DivergedError",
    "solve_fc3d",
    "write_fclib",
    "read_fclib",
    "preset_toml",
    "__version__",
]


def _toml_value(key, v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if v != v:
            return "nan"
        if v in (float("inf"), float("-inf")):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(key, x) for x in v) + "]"
    raise TypeError(f"{key} = {v!r}: a number, a boolean, a string or a list of them")


def _overlay_toml(overrides):
    """``table={"key": value}`` keyword arguments as TOML text."""
    lines = []
    for table, values in overrides.items():
        if not isinstance(values, dict):
            raise TypeError(
                f"{table} = {values!r}: give a table as a dict, e.g. "
                f"{table}={{'key': value}}"
            )
        lines.append(f"[{table}]")
        for k, v in values.items():
            lines.append(f"{k} = {_toml_value(f'{table}.{k}', v)}")
    return "\n".join(lines) + "\n"


def _whole(name, v, minimum):
    """``v`` as a whole number ≥ ``minimum``, else ``ValueError`` naming ``name``."""
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= minimum:
        return int(v)
    raise ValueError(f"{name} = {v!r}: expected a whole number ≥ {minimum}")


def _cache(cache):
    return None if cache is None else os.path.expanduser(os.fspath(cache))


class Simulation:
    """A simulation: bodies, contacts and a clock stepping through a scenario."""

    def __init__(self, core):
        self._core = core

    @classmethod
    def from_toml(cls, text_or_path, cache=None):
        """From scenario text or a scenario file (an engine scenario, or a track scenario with
        a ``[track]`` table, prepared or read from ``cache``). Raises ``ValueError`` naming
        the field, the value and what is allowed."""
        return cls(_Core.from_toml(os.fspath(text_or_path), _cache(cache)))

    @classmethod
    def track(cls, preset="default", cache=None, **overrides):
        """A built-in track scenario (``"default"``: one block, its 4 tines, the paper's cycle;
        ``"paper"``: 7 blocks) with tables overridden, e.g.
        ``tamping={"squeeze_force": 5000.0}, simulation={"dt": 4e-4}``."""
        return cls(_Core.track(preset, _cache(cache), _overlay_toml(overrides)))

    @classmethod
    def resume(cls, path, scenario, cache=None):
        """The simulation of ``scenario`` (text or file) continued from the checkpoint at
        ``path``: stepping on gives bit-identically what the run that wrote it would have."""
        sim = cls.from_toml(scenario, cache)
        sim._core.load_checkpoint(os.fspath(path))
        return sim

    def step(self, n=1, progress=None, every=100, check=True):
        """Advances ``n`` steps, with the GIL released (other Python threads run meanwhile);
        ``progress(step_index, time)`` is called every ``every`` steps.

        Every step is under the health check of ``ballast run`` (the README's Running
        section): a state that is no longer physical (non-finite, a body faster than
        ``max_speed``, an overlap beyond ``max_overlap``) raises ``DivergedError`` naming the
        step, the bodies and the quantity. The simulation is then put back to its state
        before the diverged step (``step_index`` is the last healthy step; stepping on repeats
        the same step), unless that step was detected first by :meth:`detect`, which leaves
        the diverged state; an initial state out of bounds is refused before the first step
        and left as it is. ``check=False`` skips the check (and the copy of the state it
        keeps: about 240 bytes per body and 170 per contact point); checked and unchecked
        steps give the same states."""
        self._core.step(int(n), progress, int(every), bool(check))

    def run(self, out, steps=None, overwrite=False, resume=False, progress=None, every=100,
            quiet=False):
        """Runs the simulation into the run folder ``out``, the folder ``ballast run`` writes:
        ``scenario.toml``, ``series.csv``, ``summary.json``, ``report.md``, ``plots/``, the
        ParaView series (``*.pvd``, ``vtk/``), ``checkpoints/``, and ``sections/`` for track
        runs; up to step ``steps`` (the scenario's count when ``None``), with the GIL
        released. A new run starts at step 0 (on a simulation not stepped yet), in a folder
        holding no other run unless ``overwrite`` (which deletes that run's files first);
        ``resume=True`` continues the run in ``out`` from its newest checkpoint instead.

        ``progress(step_index, time)`` is called every ``every`` steps and at the end; an
        exception it raises, or Ctrl-C, stops the run after the step in progress, its state
        checkpointed and ``summary.json`` saying ``"interrupted"``, and is raised (Ctrl-C as
        ``KeyboardInterrupt``). Messages (warnings, the closing line; only warnings when
        ``quiet``) go to ``sys.stderr``. Returns ``summary.json`` as a dict. Raises
        ``ValueError`` naming the argument, ``DivergedError`` when the health check stops the
        run (its folder is written)."""
        try:
            out = os.fspath(out)
        except TypeError:
            raise ValueError(f"out = {out!r}: expected a folder path (str or os.PathLike)") from None
        if steps is not None:
            steps = _whole("steps", steps, 0)
        every = _whole("every", every, 1)
        if progress is not None and not callable(progress):
            raise ValueError(f"progress = {progress!r}: expected None or progress(step_index, time)")
        for name, flag in [("overwrite", overwrite), ("resume", resume), ("quiet", quiet)]:
            if not isinstance(flag, (bool, np.bool_)):
                raise ValueError(f"{name} = {flag!r}: expected True or False")
        summary = self._core.run(
            out, steps, bool(overwrite), bool(resume), progress, every, bool(quiet)
        )
        return json.loads(summary)

    @property
    def time(self):
        """Simulated time (s)."""
        return self._core.time

    @property
    def step_index(self):
        """Steps done."""
        return self._core.step_index

    @property
    def steps(self):
        """The scenario's step count (a track scenario: its whole tamping cycle)."""
        return self._core.steps

    @property
    def dt(self):
        """Time step (s)."""
        return self._core.dt

    @property
    def scenario(self):
        """The resolved scenario (TOML text)."""
        return self._core.scenario

    def state_digest(self):
        """Hash of every body's state: equal digests, equal runs."""
        return self._core.state_digest()

    def summary(self):
        """The keys of the CLI's ``summary.json`` for the steps run so far."""
        return json.loads(self._core.summary_json())

    @property
    def positions(self):
        """Body centres, ``(N, 3)``."""
        return self._core.positions

    @property
    def orientations(self):
        """Unit quaternions ``(x, y, z, w)``, scalar last, ``(N, 4)``."""
        return self._core.orientations

    @property
    def velocities(self):
        """``(N, 3)`` (m/s)."""
        return self._core.velocities

    @property
    def angular_velocities(self):
        """World frame, ``(N, 3)`` (rad/s)."""
        return self._core.angular_velocities

    @property
    def masses(self):
        """``(N,)`` (kg; ``inf`` for bodies without a mass: fixed bodies and planes)."""
        return self._core.masses

    @property
    def kinds(self):
        """``"dynamic"``, ``"kinematic"`` or ``"fixed"`` per body."""
        return self._core.kinds

    @property
    def groups(self):
        """Friction group per body, ``(N,)``."""
        return self._core.groups

    @property
    def contacts(self):
        """Contacts of the last step: ``body1``, ``body2``, ``point`` ``(n, 3)``, ``normal``
        ``(n, 3)``, ``gap``, ``impulse`` ``(n, 3)`` in the contact frame ``(n, t, s)`` (N·s),
        ``status`` (0 open, 1 stick, 2 slide)."""
        return self._core.contacts()

    def detect(self):
        """Detects the next step's contacts (its first phase); ``step()`` then solves them.
        Returns the largest overlap (m)."""
        return self._core.detect()

    def contact_problem(self):
        """The next step's contact problem ``u = W r + q`` (Signorini-Coulomb with ``mu``):
        a dict with ``W`` (``scipy.sparse.bsr_matrix`` of 3×3 blocks when scipy is
        installed, else ``None``), its parts ``indptr``, ``indices``, ``blocks``, ``q``
        ``(n, 3)``, ``mu`` ``(n,)``, ``scale`` (the norm the residual is relative to) and
        ``compliance`` (``c = 1/(k h²)`` of compliant contacts, already in ``W`` and ``q``; 0
        for rigid ones) and ``tangential_compliance`` (``1/(k_t h²)`` with a tangential
        stiffness, on the tangential diagonal of ``W``; 0 without); ``compliances`` ``(n, 2)``
        holds each contact's normal and tangential compliance as in ``W`` (the two above, or
        less for a loaded contact under ``max_closure``'s hyperbolic law, linearised at the
        force it carried; with ``normal_law = "overlap"``, at the force its overlap holds).

        Its global form (FCLIB's ``fclib_global``, Siconos' ``GlobalFrictionContactProblem``)
        over the ``bodies`` the contacts move (world indices, 6 velocities each: linear then
        angular): ``v = v_free + M_inv H r``, ``u = H.T v + b``, so ``W = H.T M_inv H`` (plus
        ``compliances`` on the diagonal: normal, then tangential twice, per contact)
        and ``q = H.T v_free + b`` (``b``: the driven and fixed bodies' motion, the gap shift
        and minus the compliances times the previous step's impulses, or with
        ``normal_law = "overlap"`` the impulses the contacts' overlaps hold).
        ``H`` ``(6 nb, 3 n)``, ``M`` (masses, world inertia tensors) and ``M_inv`` (the
        solver's: zero on a degree of freedom a drive imposes) are scipy sparse matrices,
        ``v_free`` ``(6 nb,)``; their parts ``H_blocks``, ``H_body``, ``H_contact``, ``mass``,
        ``inertia``, ``inv_mass``, ``inv_inertia`` are in the dict too."""
        p = self._core.contact_problem()
        p["W"] = _bsr(p)
        p.update(_global(p))
        p["v_free"] = p["v_free"].reshape(-1)
        return p

    def write_vtk(self, dir):
        """Writes the current state as a frame of the ParaView series in ``dir``
        (``grains.pvd``, ``bodies.pvd``, ``contacts.pvd``, ``dir/vtk/*.vtu``: the layout of a
        CLI run). Successive calls on one folder add frames; a folder written before keeps its
        frames up to the current time."""
        self._core.write_vtk(os.fspath(dir))

    def indicators(self):
        """Track runs: compacity, block heights, tine forces, … at the current state."""
        return self._core.indicators()

    def checkpoint(self, path):
        """Writes a checkpoint (atomically) to ``path``; see :meth:`resume`."""
        self._core.checkpoint(os.fspath(path))


def _bsr(p):
    try:
        import scipy.sparse as sp
    except ImportError:
        return None
    n = len(p["mu"])
    return sp.bsr_matrix((p["blocks"], p["indices"], p["indptr"]), shape=(3 * n, 3 * n))


def _global(p):
    """``H``, ``M`` and ``M_inv`` as scipy sparse matrices (None without scipy)."""
    try:
        import scipy.sparse as sp
    except ImportError:
        return {"H": None, "M": None, "M_inv": None}
    n, nb = len(p["mu"]), len(p["bodies"])
    blocks, body, contact = p["H_blocks"], p["H_body"], p["H_contact"]
    i, j = np.meshgrid(np.arange(6), np.arange(3), indexing="ij")
    rows = (6 * body[:, None, None] + i[None]).ravel()
    cols = (3 * contact[:, None, None] + j[None]).ravel()
    H = sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(6 * nb, 3 * n))

    def block_diag(lin, rot):
        b = np.zeros((nb, 6, 6))
        b[:, 0, 0] = b[:, 1, 1] = b[:, 2, 2] = lin
        b[:, 3:, 3:] = rot
        return sp.bsr_matrix((b, np.arange(nb), np.arange(nb + 1)), shape=(6 * nb, 6 * nb))

    return {
        "H": H,
        "M": block_diag(p["mass"], p["inertia"]),
        "M_inv": block_diag(p["inv_mass"], p["inv_inertia"]),
    }


def solve_fc3d(W, q, mu, tolerance=1e-8, max_iterations=1000, r0=None):
    """Solves ``u = W r + q`` with Signorini-Coulomb friction at every contact (3 rows per
    contact, frame ``(n, t, s)``) by ballast's Non-Linear Gauss-Seidel, stopped at a relative
    natural-map residual of ``tolerance``.

    ``W``: a scipy sparse matrix (converted to 3×3 blocks) or a dict with ``indptr``,
    ``indices``, ``blocks`` (as :meth:`Simulation.contact_problem` gives); ``q`` of shape
    ``(n, 3)`` or ``(3n,)``. Returns ``(r, u, info)``: ``r`` and ``u`` of shape ``(n, 3)``,
    ``info`` with ``converged``, ``iterations`` and ``residual``."""
    q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, 3))
    mu = np.ascontiguousarray(np.asarray(mu, dtype=np.float64).reshape(-1))
    if isinstance(W, dict):
        indptr, indices, blocks = W["indptr"], W["indices"], W["blocks"]
    else:
        b = W.tobsr(blocksize=(3, 3))
        b.sort_indices()
        indptr, indices, blocks = b.indptr, b.indices, b.data
    if r0 is not None:
        r0 = np.ascontiguousarray(np.asarray(r0, dtype=np.float64).reshape(-1, 3))
    r, u, iterations, residual, converged = _solve_blocks(
        np.ascontiguousarray(indptr, dtype=np.int64),
        np.ascontiguousarray(indices, dtype=np.int64),
        np.ascontiguousarray(blocks, dtype=np.float64),
        q,
        mu,
        float(tolerance),
        int(max_iterations),
        r0,
    )
    info = {"converged": bool(converged), "iterations": int(iterations), "residual": residual}
    return r, u, info


def write_fclib(path, problem, title="ballast contact problem", description="", solution=None):
    """Writes a contact problem (a dict with ``W``, ``q``, ``mu``, as
    :meth:`Simulation.contact_problem` gives) in FCLIB's HDF5 layout (``/fclib_local``: ``W`` in
    compressed rows, ``vectors/q``, ``vectors/mu``, ``spacedim`` = 3, ``info``; a
    ``solution`` dict with ``r`` and ``u`` goes to ``/solution``), the format of the
    Siconos/LMGC90 benchmark collection. Needs ``h5py`` and ``scipy``."""
    import h5py
    import scipy.sparse as sp

    W = problem["W"] if problem.get("W") is not None else _bsr(problem)
    W = sp.csr_matrix(W)
    W.sort_indices()
    q = np.asarray(problem["q"], dtype=np.float64).reshape(-1)
    mu = np.asarray(problem["mu"], dtype=np.float64).reshape(-1)
    if W.shape != (q.size, q.size) or q.size != 3 * mu.size:
        raise ValueError(f"W {W.shape}, q {q.size}, mu {mu.size}: W must be 3n × 3n, q 3n, mu n")
    with h5py.File(os.fspath(path), "w") as f:
        g = f.create_group("fclib_local")
        g["spacedim"] = np.array([3], dtype=np.int32)
        w = g.create_group("W")
        for k, v in [("nzmax", W.nnz), ("m", W.shape[0]), ("n", W.shape[1]), ("nz", -2)]:
            w[k] = np.array([v], dtype=np.int32)
        w["p"] = W.indptr.astype(np.int32)
        w["i"] = W.indices.astype(np.int32)
        w["x"] = W.data.astype(np.float64)
        v = g.create_group("vectors")
        v["q"] = q
        v["mu"] = mu
        info = g.create_group("info")
        info["title"] = title
        info["description"] = description
        info["math_info"] = "u = W r + q, Signorini-Coulomb per contact, frame (n, t, s)"
        if solution is not None:
            s = f.create_group("solution")
            for k in ("r", "u"):
                if k in solution:
                    s[k] = np.asarray(solution[k], dtype=np.float64).reshape(-1)


def read_fclib(path):
    """Reads an FCLIB local problem: a dict with ``W`` (``scipy.sparse.csr_matrix``), ``q``
    ``(n, 3)``, ``mu``, and ``solution`` (``r``, ``u`` as ``(n, 3)``) when the file has one.
    Compressed rows, columns and triplets are read."""
    import h5py
    import scipy.sparse as sp

    with h5py.File(os.fspath(path), "r") as f:
        if "fclib_local" not in f:
            raise ValueError(f"{path}: no /fclib_local group (not an FCLIB local problem)")
        g = f["fclib_local"]
        w = g["W"]
        m, n, nz = int(w["m"][0]), int(w["n"][0]), int(w["nz"][0])
        p, i, x = w["p"][()], w["i"][()], w["x"][()]
        if nz == -2:
            W = sp.csr_matrix((x, i, p), shape=(m, n))
        elif nz == -1:
            W = sp.csc_matrix((x, i, p), shape=(m, n)).tocsr()
        else:
            W = sp.coo_matrix((x[:nz], (i[:nz], p[:nz])), shape=(m, n)).tocsr()
        out = {
            "W": W,
            "q": g["vectors"]["q"][()].reshape(-1, 3),
            "mu": g["vectors"]["mu"][()],
        }
        if "solution" in f:
            out["solution"] = {k: f["solution"][k][()].reshape(-1, 3) for k in f["solution"]}
        return out
