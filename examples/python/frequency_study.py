"""A tamping study from Python: the vibration frequency of the tines against the compacity
gained under the block, on a small bed (about 750 grains; a few minutes on 2 cores).

    pip install . matplotlib
    python3 examples/python/frequency_study.py [--out frequency_study.png]

Every run starts from the same prepared bed (cached in ``--cache``), so the frequency is the
only difference between them.
"""

import argparse
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import ballast  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def run(frequency, cache, steps=None):
    with open(os.path.join(HERE, "small_track.toml")) as f:
        text = f.read()
    # An overlay: the [tamping] table of the file, with the frequency set.
    text = text.replace("[tamping]", f"[tamping]\nfrequency = {frequency!r}", 1)
    sim = ballast.Simulation.from_toml(text, cache=cache)
    before = sim.indicators()["compacity_under_block_1"]
    sim.step(steps or sim.steps)
    after = sim.indicators()
    s = sim.summary()
    return {
        "frequency": frequency,
        "gain": 100.0 * (after["compacity_under_block_1"] - before) / before,
        "crib": after["compacity_crib_1"],
        "unconverged": s["solver"]["steps_not_converged"] / s["steps"],
        "max_overlap_mm": 1e3 * s["max_penetration"],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="frequency_study.png")
    ap.add_argument("--cache", default=os.path.expanduser("~/.cache/ballast"))
    ap.add_argument("--frequencies", default="20,35,50")
    ap.add_argument("--steps", type=int, default=None,
                    help="steps of each run (default: the whole cycle; fewer for a quick look)")
    a = ap.parse_args()
    rows = []
    for f in [float(x) for x in a.frequencies.split(",")]:
        rows.append(run(f, a.cache, a.steps))
        r = rows[-1]
        print(f"{f:5.1f} Hz: compacity under the block {r['gain']:+.2f} %, "
              f"{100 * r['unconverged']:.0f} % of the steps unconverged, "
              f"largest overlap {r['max_overlap_mm']:.1f} mm")
    fig, ax = plt.subplots(figsize=(6, 4), dpi=150)
    ax.plot([r["frequency"] for r in rows], [r["gain"] for r in rows], "o-")
    # The run's numerical quality belongs with its result.
    for r in rows:
        ax.annotate(f"{100 * r['unconverged']:.0f} % unconverged\nmax overlap {r['max_overlap_mm']:.1f} mm",
                    (r["frequency"], r["gain"]), textcoords="offset points", xytext=(0, 8),
                    ha="center", fontsize=7, color="0.35")
    ax.axhline(0.0, color="0.6", lw=0.8)
    # Room above the highest point for its annotation.
    gains = [r["gain"] for r in rows]
    top = max(gains + [0.0])
    ax.set_ylim(min(gains + [0.0]) - 0.1 * abs(top) - 1.0, top + 0.3 * abs(top) + 1.0)
    ax.margins(x=0.15)
    ax.set_xlabel("vibration frequency of the tines (Hz)")
    ax.set_ylabel("compacity gained under the block (%)")
    ax.set_title("Tamping one block: effect of the vibration frequency")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(a.out)
    print(f"figure: {a.out}")


if __name__ == "__main__":
    main()
