"""The Python API (`import ballast`) against physics and against the CLI.

Run from the repository root after `pip install .`: `python3 -m pytest tests/python`.
"""

import json
import math
import os
import re
import signal
import subprocess
import threading
import time

import numpy as np
import pytest

import ballast

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
G = 9.81


def block_on_slab(mu, tilt_deg, dt=1e-3, steps=10):
    """A 0.1 m cube resting on a fixed slab under gravity tilted by `tilt_deg` about y: the
    inclined-plane problem with the plane horizontal."""
    a = math.radians(tilt_deg)
    gx, gz = G * math.sin(a), -G * math.cos(a)
    return f"""
[simulation]
dt = {dt}
steps = {steps}
gravity = [{gx!r}, 0.0, {gz!r}]

[solver]
tolerance = 1e-10
residual_tolerance = 1e-10
max_iterations = 2000
norm = "natural_map"

[correction]
fraction = 0.0

[materials]
stone = 2700

[friction]
default = {mu}

[[body]]
shape = "box"
kind = "fixed"
group = "slab"
half_extents = [1.0, 1.0, 0.1]
center = [0, 0, -0.1]

[[body]]
shape = "box"
group = "block"
material = "stone"
half_extents = [0.05, 0.05, 0.05]
center = [0, 0, 0.05]
"""


def test_block_sticks_below_the_friction_angle():
    sim = ballast.Simulation.from_toml(block_on_slab(mu=0.5, tilt_deg=20.0))
    x0 = sim.positions[1].copy()
    sim.step(200)
    # tan 20° = 0.36 < 0.5: the block stays.
    assert np.abs(sim.positions[1] - x0).max() < 1e-9
    assert np.abs(sim.velocities[1]).max() < 1e-9


def test_block_slides_with_the_analytic_acceleration():
    mu, tilt = 0.2, 30.0
    sim = ballast.Simulation.from_toml(block_on_slab(mu=mu, tilt_deg=tilt))
    sim.step(300)
    a = math.radians(tilt)
    acc = G * (math.sin(a) - mu * math.cos(a))
    v = sim.velocities[1]
    # The velocity grows by a h per step exactly (the θ-scheme integrates a constant force).
    assert v[0] == pytest.approx(acc * sim.time, rel=1e-6)
    assert abs(v[2]) < 1e-9 and abs(v[1]) < 1e-12


def test_arrays_have_shapes_dtypes_and_the_summary_keys():
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "sliding_block.toml"))
    sim.step(20)
    n = 3
    assert sim.step_index == 20 and sim.time == pytest.approx(20 * sim.dt)
    for name, shape in [
        ("positions", (n, 3)),
        ("velocities", (n, 3)),
        ("angular_velocities", (n, 3)),
        ("orientations", (n, 4)),
        ("masses", (n,)),
        ("groups", (n,)),
    ]:
        a = getattr(sim, name)
        assert a.shape == shape, name
    assert sim.positions.dtype == np.float64 and sim.groups.dtype == np.uint32
    assert np.allclose(np.linalg.norm(sim.orientations, axis=1), 1.0)
    assert sim.kinds == ["fixed", "dynamic", "kinematic"]
    assert sim.masses[1] == pytest.approx(2700 * 0.1**3)
    s = sim.summary()
    for key in ["steps", "time", "bodies", "solver", "contacts", "state_digest"]:
        assert key in s
    assert s["steps"] == 20 and s["state_digest"] == sim.state_digest()
    c = sim.contacts
    k = len(c["gap"])
    assert k > 0 and c["point"].shape == (k, 3) and c["impulse"].shape == (k, 3)
    assert set(np.unique(c["status"])) <= {0, 1, 2}


def cli_exe():
    exe = os.path.join(ROOT, "target", "release", "ballast")
    if not os.path.exists(exe):
        subprocess.run(["cargo", "build", "--release", "-p", "ballast-cli"], cwd=ROOT, check=True)
    return exe


def series_without_timings(path):
    """`series.csv`'s header and rows without the wall-clock columns (`t_*`)."""
    lines = path.read_text().splitlines()
    keep = [i for i, name in enumerate(lines[0].split(",")) if not name.startswith("t_")]
    return [[row.split(",")[i] for i in keep] for row in lines]


def run_files(out):
    """The files of a run folder, relative to it."""
    return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())


def test_the_same_run_as_the_cli(tmp_path):
    exe = cli_exe()
    scenario = os.path.join(ROOT, "examples", "sliding_block.toml")
    out = tmp_path / "run"
    subprocess.run(
        [exe, "run", scenario, "--out", str(out), "--steps", "300", "--quiet", "--threads", "1"],
        check=True,
    )
    cli = json.loads((out / "summary.json").read_text())
    sim = ballast.Simulation.from_toml(scenario)
    sim.step(300)
    assert sim.state_digest() == cli["state_digest"]
    assert sim.summary()["solver"]["mean_iterations"] == cli["solver"]["mean_iterations"]


def test_run_writes_the_cli_run_folder(tmp_path):
    scenario = os.path.join(ROOT, "examples", "pile.toml")
    cli, py = tmp_path / "cli", tmp_path / "py"
    subprocess.run(
        [cli_exe(), "run", scenario, "--out", str(cli), "--steps", "120", "--quiet",
         "--threads", "1"],
        check=True,
    )
    sim = ballast.Simulation.from_toml(scenario)
    summary = sim.run(py, steps=120, quiet=True)
    expected = json.loads((cli / "summary.json").read_text())
    assert summary == json.loads((py / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["steps"] == 120
    assert summary["state_digest"] == expected["state_digest"] == sim.state_digest()
    assert sim.step_index == 120 and sim.summary()["state_digest"] == summary["state_digest"]
    rows = series_without_timings(py / "series.csv")
    assert rows == series_without_timings(cli / "series.csv")
    assert [r[0] for r in rows] == ["step", "50", "100", "120"]
    assert (py / "scenario.toml").read_text() == (cli / "scenario.toml").read_text()
    assert run_files(py) == run_files(cli)
    assert "report.md" in run_files(py) and "plots/solver.png" in run_files(py)
    # The report names the scenario file, as the CLI's does.
    title = "# ballast run report: `pile.toml`"
    assert (py / "report.md").read_text().splitlines()[0] == title
    assert (cli / "report.md").read_text().splitlines()[0] == title


def test_run_resumes_and_stops_bit_identically(tmp_path):
    scenario = os.path.join(ROOT, "examples", "pile.toml")
    whole = ballast.Simulation.from_toml(scenario)
    whole.run(tmp_path / "whole", steps=100, quiet=True)
    # An exception in `progress` stops the run after the step, checkpointed.
    seen = []

    def stop_at_40(k, t):
        seen.append(k)
        if k >= 40:
            raise RuntimeError("enough")

    out = tmp_path / "parts"
    with pytest.raises(RuntimeError, match="enough"):
        ballast.Simulation.from_toml(scenario).run(
            out, steps=100, progress=stop_at_40, every=20, quiet=True
        )
    assert seen == [20, 40]
    stopped = json.loads((out / "summary.json").read_text())
    assert stopped["status"] == "interrupted" and stopped["steps"] == 40
    sim = ballast.Simulation.from_toml(scenario)
    done = sim.run(out, steps=100, resume=True, quiet=True)
    assert done["status"] == "completed" and sim.step_index == 100
    assert done["state_digest"] == whole.state_digest()
    assert series_without_timings(out / "series.csv") == series_without_timings(
        tmp_path / "whole" / "series.csv"
    )


def test_ctrl_c_stops_a_run_after_the_step(tmp_path):
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "pile.toml"))

    def ctrl_c(k, t):
        if k == 30:
            os.kill(os.getpid(), signal.SIGINT)

    # Python's own Ctrl-C handler, whatever the suite was started under: a shell starts a
    # background job with SIGINT ignored, and Python then keeps it ignored.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt, match="interrupted at step 30 of 100"):
            sim.run(tmp_path / "run", steps=100, progress=ctrl_c, every=10, quiet=True)
    finally:
        signal.signal(signal.SIGINT, previous)
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["status"] == "interrupted" and s["steps"] == 30 and sim.step_index == 30


def test_run_refuses_bad_arguments_naming_them(tmp_path):
    scenario = os.path.join(ROOT, "examples", "sliding_block.toml")
    sim = ballast.Simulation.from_toml(scenario)
    for kwargs, field in [
        ({"steps": -1}, "steps"),
        ({"steps": "10"}, "steps"),
        ({"steps": 2.5}, "steps"),
        ({"every": 0}, "every"),
        ({"overwrite": "yes"}, "overwrite"),
        ({"progress": 3}, "progress"),
        ({"overwrite": True, "resume": True}, "resume"),
    ]:
        with pytest.raises(ValueError, match=field):
            sim.run(tmp_path / "a", **kwargs)
    with pytest.raises(ValueError, match="out"):
        sim.run(None)
    with pytest.raises(ValueError, match=r"resume=True .*no valid checkpoint"):
        sim.run(tmp_path / "empty", steps=10, resume=True)
    sim.run(tmp_path / "a", steps=10, quiet=True)
    # A folder holds one run, and a run starts at step 0.
    with pytest.raises(ValueError, match=r"out='.*': the folder holds another run.*overwrite=True"):
        ballast.Simulation.from_toml(scenario).run(tmp_path / "a", steps=10)
    with pytest.raises(ValueError, match="at step 10"):
        sim.run(tmp_path / "b", steps=20)
    again = ballast.Simulation.from_toml(scenario)
    assert again.run(tmp_path / "a", steps=10, overwrite=True, quiet=True)["steps"] == 10
    with pytest.raises(ValueError, match=r"steps asks for 5 steps"):
        ballast.Simulation.from_toml(scenario).run(tmp_path / "a", steps=5, resume=True)


def test_run_into_a_folder_that_cannot_be_made_raises_oserror(tmp_path):
    # A file where the folder's parent should be: refused by the file system, even for root.
    (tmp_path / "file").write_text("not a folder")
    out = tmp_path / "file" / "run"
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "sliding_block.toml"))
    with pytest.raises(OSError, match=r"cannot create output folder .*file/run") as e:
        sim.run(out, steps=10, quiet=True)
    assert not isinstance(e.value, ValueError)
    assert sim.step_index == 0


def test_run_stopped_by_the_health_check_raises(tmp_path):
    text = block_on_slab(0.5, 0.0).replace("gravity = [0.0, 0.0, -9.81]", "gravity = [0, 0, -1e200]")
    assert "1e200" in text
    with pytest.raises(ballast.DivergedError, match="step 1"):
        ballast.Simulation.from_toml(text).run(tmp_path / "d", quiet=True)
    s = json.loads((tmp_path / "d" / "summary.json").read_text())
    assert s["status"] == "diverged" and s["divergence"]["step"] == 1


def pile_text(*replace):
    """``examples/pile.toml`` (300 grains) with each ``(old, new)`` of ``replace`` applied."""
    with open(os.path.join(ROOT, "examples", "pile.toml")) as f:
        text = f.read()
    for old, new in replace:
        assert old in text
        text = text.replace(old, new, 1)
    return text


def test_step_stops_a_diverging_simulation_at_its_last_healthy_step():
    sim = ballast.Simulation.from_toml(pile_text(("gravity = [0, 0, -9.81]", "gravity = [0, 0, -1e200]")))
    initial = sim.state_digest()
    with pytest.raises(
        ballast.DivergedError,
        match=r'diverged at step 1 \(t = 2\.000e-4 s\): body \d+ \(group "grain"\) moves at '
        r"2\.000e196 m/s, more than the bound .*; the simulation is put back to step 0",
    ):
        sim.step(10)
    assert sim.step_index == 0 and sim.state_digest() == initial
    assert np.isfinite(sim.velocities).all()


def test_checked_steps_are_bit_identical_and_put_back_exactly():
    checked = ballast.Simulation.from_toml(pile_text())
    plain = ballast.Simulation.from_toml(pile_text())
    checked.step(300)
    plain.step(300, check=False)
    assert checked.state_digest() == plain.state_digest()
    # Falling grains pass 0.05 m/s at step 26 (dt = 2e-4 s): put back to step 25, from which
    # the same step follows.
    slow = pile_text(("alert = 1e-3", "alert = 1e-3\nmax_speed = 0.05"))
    sim = ballast.Simulation.from_toml(slow)
    with pytest.raises(ballast.DivergedError, match="step 26 .* put back to step 25"):
        sim.step(100, every=7)
    assert sim.step_index == 25 and sim.summary()["steps"] == 25
    ref = ballast.Simulation.from_toml(slow)
    ref.step(25, check=False)
    assert sim.state_digest() == ref.state_digest()
    sim.step(1, check=False)
    ref.step(1, check=False)
    assert sim.state_digest() == ref.state_digest()


def assert_releases_the_gil(call):
    """A second Python thread ticks about once a millisecond while `call()` runs: none would
    with the GIL held."""
    ticks = []
    stop = threading.Event()

    def other():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=other)
    t.start()
    time.sleep(0.01)
    start = time.perf_counter()
    call()
    end = time.perf_counter()
    stop.set()
    t.join()
    during = [x for x in ticks if start < x < end]
    assert end - start > 0.05
    assert len(during) > 10, f"{len(during)} ticks in {end - start:.3f} s"


def test_run_releases_the_gil(tmp_path):
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "pile.toml"))
    assert_releases_the_gil(lambda: sim.run(tmp_path / "run", steps=1500, every=10000, quiet=True))


def test_step_releases_the_gil():
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "pile.toml"))
    assert_releases_the_gil(lambda: sim.step(3000, every=10000))


def test_progress_is_called():
    sim = ballast.Simulation.from_toml(block_on_slab(mu=0.5, tilt_deg=0.0))
    seen = []
    sim.step(25, progress=lambda k, t: seen.append((k, t)), every=10)
    assert [k for k, _ in seen] == [10, 20, 25]


def test_checkpoint_and_resume_are_bit_identical(tmp_path):
    scenario = os.path.join(ROOT, "examples", "pile.toml")
    a = ballast.Simulation.from_toml(scenario)
    a.step(150)
    a.checkpoint(tmp_path / "k.bin")
    a.step(100)
    b = ballast.Simulation.resume(tmp_path / "k.bin", scenario)
    assert b.step_index == 150
    b.step(100)
    assert a.state_digest() == b.state_digest()


def test_contact_problem_of_a_resting_block_gives_its_weight():
    sim = ballast.Simulation.from_toml(block_on_slab(mu=0.5, tilt_deg=0.0))
    sim.step(50)
    p = sim.contact_problem()
    n = len(p["mu"])
    assert n >= 4 and p["q"].shape == (n, 3) and p["blocks"].shape[1:] == (3, 3)
    W = p["W"]
    assert W.shape == (3 * n, 3 * n)
    assert abs(W - W.T).max() <= 1e-12 * abs(W).max()
    r, u, info = ballast.solve_fc3d(W, p["q"], p["mu"], tolerance=1e-10, max_iterations=5000)
    assert info["converged"], info
    weight = 2700 * 0.1**3 * G * sim.dt
    assert r[:, 0].sum() == pytest.approx(weight, rel=1e-8)
    assert np.abs(u[:, 0]).max() < 1e-9
    # The step then solves the same problem: its impulses carry the same weight.
    sim.step()
    assert sim.contacts["impulse"][:, 0].sum() == pytest.approx(weight, rel=1e-8)


def test_solve_fc3d_on_a_hand_made_problem():
    # One contact, W = I: r = −q projected on the cone (here inside it: stick).
    W = {"indptr": np.array([0, 1]), "indices": np.array([0]), "blocks": np.eye(3)[None]}
    r, u, info = ballast.solve_fc3d(W, [-1.0, 0.2, 0.0], [0.5], tolerance=1e-12)
    assert info["converged"]
    assert r[0] == pytest.approx([1.0, -0.2, 0.0])
    assert u[0] == pytest.approx([0.0, 0.0, 0.0], abs=1e-15)
    # Slide: |q_t| large, the impulse on the cone's edge opposing q_t.
    r, u, info = ballast.solve_fc3d(W, [-1.0, 2.0, 0.0], [0.5], tolerance=1e-12)
    assert r[0] == pytest.approx([1.0, -0.5, 0.0])


@pytest.mark.parametrize(
    "text, field",
    [
        (block_on_slab(0.5, 0.0).replace("dt = 0.001", "dt = -1"), "simulation.dt"),
        (block_on_slab(0.5, 0.0).replace("default = 0.5", "default = -2"), "friction"),
        ("[track]\nblocks = 0\n", "track.blocks"),
        ('[track]\n[simulation]\ndt = "fast"\n', "dt"),
    ],
)
def test_bad_input_raises_with_the_field_named(text, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        ballast.Simulation.from_toml(text)


def test_bad_overrides_raise():
    with pytest.raises(ValueError, match="tamping.frequency"):
        ballast.Simulation.track(tamping={"frequency": -1.0})
    with pytest.raises(TypeError, match="tamping"):
        ballast.Simulation.track(tamping=3)


def test_fclib_round_trip(tmp_path):
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "pile.toml"))
    sim.step(600)
    p = sim.contact_problem()
    r, u, info = ballast.solve_fc3d(p["W"], p["q"], p["mu"], tolerance=1e-6, max_iterations=3000)
    path = tmp_path / "pile.hdf5"
    ballast.write_fclib(path, p, solution={"r": r, "u": u})
    back = ballast.read_fclib(path)
    assert (back["W"] != p["W"].tocsr()).nnz == 0
    assert np.array_equal(back["q"], p["q"]) and np.array_equal(back["mu"], p["mu"])
    assert np.array_equal(back["solution"]["r"], r)
    # The problem read back is the same problem: the same solve gives the same impulses.
    r2, _, info2 = ballast.solve_fc3d(back["W"], back["q"], back["mu"], tolerance=1e-6,
                                      max_iterations=3000)
    assert info2["iterations"] == info["iterations"]
    assert np.allclose(r2, r, rtol=0, atol=1e-12 * np.abs(r).max())
    import h5py

    with h5py.File(path) as f:
        assert f["fclib_local/spacedim"][0] == 3
        assert f["fclib_local/W/nz"][0] == -2
        assert f["fclib_local/W/m"][0] == 3 * len(p["mu"])


def test_closure_law_compliances_are_those_in_w(tmp_path):
    # With `max_closure` a loaded contact is stiffer than an unloaded one: its compliance in W
    # is c / (1 + F/(k V_m))², F the force it carried (the hyperbola linearised there).
    text = open(os.path.join(ROOT, "examples", "pile.toml")).read()
    assert "contact_stiffness" in text
    text = text.replace("[simulation]\n", "[simulation]\nmax_closure = 2e-7\n", 1)
    path = tmp_path / "pile.toml"
    path.write_text(text)
    sim = ballast.Simulation.from_toml(str(path))
    sim.step(400)
    p = sim.contact_problem()
    n = len(p["mu"])
    c = p["compliances"]
    assert c.shape == (n, 2)
    assert np.all(c[:, 0] <= p["compliance"]) and np.all(c[:, 0] > 0)
    assert np.any(c[:, 0] < 0.5 * p["compliance"])
    # Normal and tangential stiffen by the same factor.
    ratio = p["tangential_compliance"] / p["compliance"]
    assert np.allclose(c[:, 1], ratio * c[:, 0], rtol=1e-12, atol=0)
    W2 = (p["H"].T @ p["M_inv"] @ p["H"]).toarray() + np.diag(
        np.column_stack([c[:, 0], c[:, 1], c[:, 1]]).reshape(-1))
    W = p["W"].toarray()
    assert np.abs(W - W2).max() <= 1e-12 * np.abs(W2).max()


def test_overlap_law_starts_from_the_force_the_overlap_holds(tmp_path):
    # With `normal_law = "overlap"` an overlapping contact's spring starts the step from the
    # force k δ its overlap δ holds: b's normal part is −c k h δ = −δ/h whatever k (the
    # example's overlaps are under the 1 mm cap, the recovery acts beyond F/k only), and an
    # open contact's is its gap shift g/(hθ).
    text = open(os.path.join(ROOT, "examples", "pile.toml")).read()
    text = text.replace("[simulation]\n", '[simulation]\nnormal_law = "overlap"\n', 1)
    path = tmp_path / "pile.toml"
    path.write_text(text)
    sim = ballast.Simulation.from_toml(str(path))
    sim.step(3000)
    p = sim.contact_problem()
    gap = sim.contacts["gap"]
    assert len(gap) == len(p["mu"])
    bn = p["b"][:, 0]
    over, open_ = gap < 0, gap > 0
    assert over.sum() > 50 and open_.sum() > 50 and np.all(-gap[over] < 1e-3)
    h = sim.dt
    assert np.allclose(bn[over], gap[over] / h, rtol=1e-9, atol=0)
    assert np.allclose(bn[open_], gap[open_] / (h * 0.5), rtol=1e-9, atol=0)


def test_global_form_of_the_contact_problem():
    # A settling pile: grains against each other and against the box's fixed walls.
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "pile.toml"))
    sim.step(400)
    p = sim.contact_problem()
    n, nb = len(p["mu"]), len(p["bodies"])
    H, M, M_inv, W = p["H"], p["M"], p["M_inv"], p["W"]
    assert H.shape == (6 * nb, 3 * n) and M.shape == (6 * nb, 6 * nb)
    assert p["v_free"].shape == (6 * nb,)
    # W = Hᵀ M⁻¹ H (the grains are free bodies: M⁻¹ is M's inverse), plus the compliance of
    # the contacts' normal law on the normal rows and that of their tangential spring on the
    # tangential rows (0 for rigid contacts; the example has both).
    normal = np.zeros(3 * n)
    normal[0::3] = 1.0
    assert p["compliance"] > 0 and p["tangential_compliance"] > 0
    assert np.array_equal(p["compliances"][:, 0], np.full(n, p["compliance"]))
    W2 = (H.T @ M_inv @ H).toarray() + np.diag(
        p["compliance"] * normal + p["tangential_compliance"] * (1.0 - normal))
    assert np.abs(W.toarray() - W2).max() <= 1e-12 * np.abs(W2).max()
    assert np.abs((M @ M_inv).toarray() - np.eye(6 * nb)).max() < 1e-9
    # q = Hᵀ v_free + b, where b is the gap shift and the springs' memory (no driven bodies).
    q = p["q"].reshape(-1)
    assert np.abs(H.T @ p["v_free"] + p["b"].reshape(-1) - q).max() <= 1e-12 * np.abs(q).max()
    # The masses are the bodies' own, and v_free is their velocity plus g h.
    assert np.array_equal(p["mass"], sim.masses[p["bodies"]])
    v = sim.velocities[p["bodies"]]
    vf = p["v_free"].reshape(nb, 6)
    assert np.abs(vf[:, :3] - (v + np.array([0, 0, -G]) * sim.dt)).max() < 1e-12


def test_write_vtk_frames_read_back(tmp_path):
    import meshio
    sim = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "pile.toml"))
    out = tmp_path / "frames"
    for _ in range(3):
        sim.step(50)
        sim.write_vtk(out)
    pvd = (out / "grains.pvd").read_text()
    assert pvd.count("<DataSet") == 3
    times = [float(t) for t in re.findall(r'timestep="([^"]+)"', pvd)]
    assert times == pytest.approx([50 * sim.dt, 100 * sim.dt, 150 * sim.dt], rel=1e-12)
    last = sorted((out / "vtk").glob("grains_*.vtu"))[-1]
    m = meshio.read(last)
    ids = np.concatenate([c for c in m.cell_data["id"]])
    vel = np.concatenate([c for c in m.cell_data["velocity"]])
    dynamic = [i for i, k in enumerate(sim.kinds) if k == "dynamic"]
    assert set(ids.tolist()) == set(dynamic)
    # Written as Float32 (7 significant digits: all a picture needs).
    assert vel.dtype == np.float32
    want = sim.velocities[ids]
    assert np.abs(vel - want).max() <= 2.0**-23 * np.abs(want).max()
    # A new Simulation writing into the folder keeps the frames up to its time.
    again = ballast.Simulation.from_toml(os.path.join(ROOT, "examples", "pile.toml"))
    again.step(100)
    again.write_vtk(out)
    assert (out / "grains.pvd").read_text().count("<DataSet") == 2


def test_the_frequency_study_example_draws_its_figure(tmp_path):
    pytest.importorskip("matplotlib")
    script = os.path.join(ROOT, "examples", "python", "frequency_study.py")
    out = tmp_path / "study.png"
    # Two frequencies, the first 40 steps of the cycle each (the lift): a quick look.
    done = subprocess.run(
        ["python3", script, "--out", str(out), "--cache", str(tmp_path / "cache"),
         "--frequencies", "20,50", "--steps", "40"],
        capture_output=True, text=True, check=True,
    )
    lines = [l for l in done.stdout.splitlines() if " Hz: " in l]
    assert len(lines) == 2, done.stdout
    # The lift alone leaves the bed under the block as it was (within a percent).
    for l in lines:
        gain = float(re.search(r"block ([+-][0-9.]+) %", l).group(1))
        assert abs(gain) < 1.0, l
    assert out.stat().st_size > 10_000 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
