"""Volume-preservation ablation (paper 000 Fig. 14) at small scale, written to
benchmarks/results/volume_ablation.json.

    python benchmarks/volume_ablation.py [--shape 24,16,16] [--steps 4000] [--nu 1e-3] [--out ...]

A 1500 kg/m³ sand ball (ε = 0.55, radius shape/5 cells) dropped into a pool under air
(couplekit.coupling.scenes.sand_ball_into_water), advanced by the LockstepScheduler, three ways:

* ``none``: no phase-field source term S_φ (and no controller: it can only scale S_φ);
* ``source``: S_φ (Eq. 45), no controller;
* ``source_controller``: S_φ and the volume controller (Eq. 52, η = 2, ε-weighted sums).

Fluid volume V = Σ ε̃ φ (water in the pores, double precision); the drift (V − V0)/V0 is sampled every
100 steps.  Paper Fig. 14 (their scale): ~30 % loss without S_φ, up to 5 % without the controller, < 1 %
with both.  Also recorded: the per-stage cost of the last run (LockstepScheduler.cost_report).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
from _args import int_in, one_line, positive_float, shape3

from couplekit.backend import get_backend
from couplekit.coupling.scenes import sand_ball_into_water

MODES = {
    "none": {"source_term": False, "eta": 0.0},
    "source": {"source_term": True, "eta": 0.0},
    "source_controller": {"source_term": True, "eta": 2.0},
}


def build(be, shape, nu: float, mode: str):
    """The scene of ``mode`` (one of MODES) on ``shape`` cells."""
    return sand_ball_into_water(be, shape, density=1500.0, radius=min(shape) / 5, nu_h=nu, youngs_modulus=1e5,
                                timing=True, **MODES[mode])  # fmt: skip


def run(shape, steps: int, nu: float, threads: int | None) -> dict:
    be = get_backend("cpu", threads=threads)
    out: dict = {}
    for mode in MODES:
        sc = build(be, shape, nu, mode)
        drift, t0 = [], time.perf_counter()
        finite = True
        for _ in range(steps // 100):
            sc.step(100)
            drift.append(sc.fluid_volume_drift())
            if not np.isfinite(drift[-1]):
                finite = False
                break
        wall = time.perf_counter() - t0
        d = np.abs(np.asarray(drift))
        out[mode] = {
            "final_drift": float(drift[-1]),
            "max_abs_drift": float(np.nanmax(d)),
            "drift_every_100_steps": [float(v) for v in drift],
            "finite": finite and sc.finite(),
            "steps": len(drift) * 100,
            "seconds": wall,
            "sand_centre_final_cells": float(sc.sand_centre()[2] / sc.units.dx),
        }
        print(f"{mode:18s} final drift {drift[-1]:+.4%}  max |drift| {np.nanmax(d):.4%}  ({wall:.0f} s)", flush=True)
        if mode == "source_controller":
            out["stage_cost"] = sc.scheduler.cost_report()
            out["scene"] = sc.info
    return out


def steps_type(text: str) -> int:
    """--steps: a positive multiple of 100 (the drift is sampled every 100 steps)."""
    steps = int_in(100, why="the drift is sampled every 100 steps")(text)
    if steps % 100:
        raise argparse.ArgumentTypeError(
            f"must be a multiple of 100 (the drift is sampled every 100 steps), got {text!r}"
        )
    return steps


def main() -> None:
    ap = argparse.ArgumentParser(
        description="Volume-preservation ablation (paper 000 Fig. 14) at small scale, written to "
        "benchmarks/results/volume_ablation.json."
    )
    ap.add_argument("--shape", type=shape3(5), default="24,16,16", help="nz,ny,nx cells")
    ap.add_argument("--steps", type=steps_type, default=4000, help="a multiple of 100 (the drift's sampling)")
    ap.add_argument("--nu", type=positive_float(), default=1e-3, help="water lattice viscosity (paper: 1e-4)")
    ap.add_argument("--threads", type=int_in(1), default=None)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "volume_ablation.json"))
    a = ap.parse_args()
    shape, a.shape = a.shape, ",".join(map(str, a.shape))
    try:  # the scene builds at this shape (cheap), before any run is made or written
        build(get_backend("numpy"), shape, a.nu, "source_controller")
    except ValueError as exc:
        ap.error(f"the scene does not build at --shape {a.shape}: {one_line(exc)}")
    res = run(shape, a.steps, a.nu, a.threads)
    res["meta"] = {"shape_nz_ny_nx": list(shape), "steps": a.steps, "nu_h": a.nu, "machine": platform.platform(),
                   "command": f"python benchmarks/volume_ablation.py --shape {a.shape} --steps {a.steps} --nu {a.nu}"}  # fmt: skip
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1))
    print("wrote", a.out)


if __name__ == "__main__":
    main()
