"""The phase-field mobility a moving water-air interface needs at 800:1: which (mobility, speed) pairs run.

    python benchmarks/mobility_map.py [--kinds wall,air] [--widths 2.5,3,4,5,6,8]
        [--mobilities 0.04,0.02,0.01,0.005,0.0025] [--speeds 0.02,0.04,0.08,0.11] [--out FILE.json]

A water ball of radius 6 cells (couplekit.fluid.interface_cases: the scenes' fluid, 800:1, no gravity) is thrown
at a wall through still air (``wall``, 600 steps) or moves through open air in a periodic box (``air``, 1000
steps), at each interface width, lattice mobility M and lattice speed u; a run that goes non-finite or above
lattice speed 0.5 has diverged. What the map showed (session 32): the limit is mostly the ratio u/M and grows
with the width; the wall impact is the harsher case (width 4: it runs to u/M = 4 and diverges from 5.5, the
ball in open air runs to 8). ``couplekit.cautions.MOBILITY_IMPACT_LIMITS`` holds the wall's numbers, which
``couplekit validate`` reads (docs/fluid-stability.md, 'The mobility a moving interface needs').

Writes benchmarks/results/mobility_map.json (``--out``) and, next to it, mobility_map.png: one panel per kind,
u against M on log axes, a marker per run (filled: ran; open: diverged), a colour per width. The whole default
map is 240 runs of 1-4 s each on one thread.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from _args import float_list, name_list

from couplekit.fluid.interface_cases import ball, steps_to_diverge

ROOT = Path(__file__).resolve().parents[1]
KINDS = {"wall": 600, "air": 1000}
"""Kind of run → steps."""


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description="Map which phase-field mobilities and lattice speeds a moving water ball at 800:1 runs at, "
        "for each interface width, thrown at a wall or through open air."
    )
    ap.add_argument(
        "--kinds", type=name_list("kind", KINDS), default=list(KINDS), help="comma-separated: wall, air (default both)"
    )
    ap.add_argument("--widths", type=float_list(2.0, lo_open=False), default=[2.5, 3.0, 4.0, 5.0, 6.0, 8.0])
    ap.add_argument("--mobilities", type=float_list(0.0), default=[0.04, 0.02, 0.01, 0.005, 0.0025])
    ap.add_argument("--speeds", type=float_list(0.0), default=[0.02, 0.04, 0.08, 0.11])
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "mobility_map.json")
    return ap.parse_args(argv)


def plot(runs: list[dict], path: Path) -> None:
    """u against M per kind; filled markers ran, open ones diverged; colour by width."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = sorted({r["kind"] for r in runs}, key=list(KINDS).index)
    widths = sorted({r["width"] for r in runs})
    colours = {w: plt.cm.viridis(i / max(1, len(widths) - 1)) for i, w in enumerate(widths)}
    fig, axes = plt.subplots(1, len(kinds), figsize=(6.5 * len(kinds), 4.5), squeeze=False)
    for ax, kind in zip(axes[0], kinds, strict=True):
        for r in (r for r in runs if r["kind"] == kind):
            shift = 1.0 + 0.06 * (widths.index(r["width"]) - (len(widths) - 1) / 2)  # widths side by side
            c = colours[r["width"]]
            ax.scatter(r["mobility"] * shift, r["speed"], s=36, marker="o",
                       facecolors=c if r["ran"] else "none", edgecolors=c)  # fmt: skip
        ax.set_xscale("log")
        ax.set_yscale("log")
        ms, us = sorted({r["mobility"] for r in runs}), sorted({r["speed"] for r in runs})
        ax.set_xticks(ms, [f"{m:g}" for m in ms])
        ax.set_yticks(us, [f"{u:g}" for u in us])
        ax.minorticks_off()
        ax.set_xlabel("lattice mobility M")
        ax.set_ylabel("lattice speed u of the ball")
        ax.set_title(f"{'thrown at a wall' if kind == 'wall' else 'through open air'} (filled: ran, open: diverged)")
        for w in widths:
            ax.scatter([], [], color=colours[w], label=f"width {w:g}")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    args = parse_args(argv)
    runs = []
    for kind in args.kinds:
        for width in args.widths:
            for mobility in args.mobilities:
                for speed in args.speeds:
                    t0 = time.perf_counter()
                    d = ball(width, speed, mobility=mobility, at_wall=kind == "wall")
                    diverged, peak, _ = steps_to_diverge(d, steps=KINDS[kind])
                    runs.append({"kind": kind, "width": width, "mobility": mobility, "speed": speed,
                                 "ran": diverged is None, "diverged_by_step": diverged, "peak_speed": peak,
                                 "u_over_M": speed / mobility})  # fmt: skip
                    verdict = "ran" if diverged is None else f"diverged by step {diverged}"
                    print(f"{kind:4s} width {width:g} M {mobility:g} u {speed:g} (u/M {speed / mobility:.3g}): "
                          f"{verdict}, peak {peak:.3f} ({time.perf_counter() - t0:.0f} s)", flush=True)  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    command = "python benchmarks/mobility_map.py " + " ".join(
        f"--{k} " + ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in getattr(args, k))
        for k in ("kinds", "widths", "mobilities", "speeds")
    )
    args.out.write_text(json.dumps({"command": command, "runs": runs}, indent=1) + "\n")
    plot(runs, args.out.with_suffix(".png"))
    print(f"wrote {args.out} and {args.out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
