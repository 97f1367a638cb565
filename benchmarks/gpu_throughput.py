"""Fluid and sand throughput on a GPU (the cuda backend) at GPU sizes, against the bandwidth-bound ceilings of
couplekit/backend/traffic.py.

    python benchmarks/gpu_throughput.py [--cells 256] [--particles 1 4 16] [--steps 20] [--out results.json]

Fluid: MLUPS of the single-phase collide-stream and of the full two-phase step (benchmarks/fluid_throughput.py's
scenes) on n^3 cells.  Sand: particle-steps per second of the full MPM step (P2G, grid update, G2P with
Drucker-Prager plasticity, hardening and volume correction) for a block of sand, 8 particles per cell,
dropped onto the floor of a 256^3 grid, at each of ``--particles`` million particles.  Every timing
synchronises the device before reading the clock; best of ``--repeats``.  Each result carries its
bandwidth-bound ceiling on the GPU it ran on (--bandwidth, default the H200's 4.8 TB/s) and the fraction of it
reached.  Used by scripts/gpu_check.sh; needs a CUDA GPU and CuPy.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _args import float_in, int_in, positive_float  # noqa: E402
from fluid_throughput import ours_collide, ours_two_phase_step  # noqa: E402

from couplekit.backend import get_backend  # noqa: E402
from couplekit.backend.traffic import (  # noqa: E402
    BANDWIDTH_EFFICIENCY,
    KERNEL_TRAFFIC,
    TWO_PHASE_STEP,
    projected_items_per_s,
)
from couplekit.sand import DomainWalls, SandParams  # noqa: E402
from couplekit.sand.seeding import seed_box  # noqa: E402
from couplekit.sand.solver import SandSolver  # noqa: E402

SAND_GRID = 256
SAND_PARAMS = SandParams(youngs_modulus=3.537e5, density=2200.0)
MAX_SAND_SIDE = SAND_GRID - 8  # the block starts 4 cells up and stays clear of the 3-cell walls
MAX_MILLIONS = 120.0  # 8 * 248.5^3 / 1e6 = 122.8: the largest block of MAX_SAND_SIDE cells a side, rounded down
SAND_STEP_BYTES = sum(KERNEL_TRAFFIC[k].bytes for k in ("mpm_p2g", "mpm_g2p"))


def timed(backend, fn, repeats: int) -> float:
    """Best wall time of ``fn()`` over ``repeats`` calls, the device synchronised around each."""
    fn()
    backend.synchronize()
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        backend.synchronize()
        best = min(best, time.perf_counter() - t)
    return best


def fluid(backend, n: int, repeats: int, bandwidth: float) -> dict:
    """MLUPS of collide-stream (single phase) and of the two-phase step on n^3, with their ceilings."""
    cells = n**3
    out = {}
    two_phase_bytes = sum(KERNEL_TRAFFIC[k].bytes for k in TWO_PHASE_STEP)
    for name, make, nbytes in (
        ("collide_stream", ours_collide, KERNEL_TRAFFIC["lbm_collide_stream"].bytes),
        ("two_phase_step", ours_two_phase_step, two_phase_bytes),
    ):
        run = make(backend, n)  # each callable runs 2 steps
        mlups = 2 * cells / timed(backend, run, repeats) / 1e6
        ceiling = projected_items_per_s(nbytes, bandwidth, 1.0) / 1e6
        out[name] = {"mlups": mlups, "bytes_per_cell": nbytes, "bandwidth_bound_mlups": ceiling,
                     "fraction_of_bandwidth_bound": mlups / ceiling}  # fmt: skip
        del run
    return out


def sand(backend, millions: float, steps: int, repeats: int, bandwidth: float) -> dict:
    """Particle-steps per second of the MPM step for ``millions`` M particles (8 per cell) on 256^3."""
    dx = 1.0 / SAND_GRID
    cells = int(millions * 1e6 / 8)
    side = max(1, round(cells ** (1 / 3)))
    lo = np.array([0.5 - side * dx / 2, 0.5 - side * dx / 2, 4 * dx])
    body = seed_box(lo, lo + side * dx, dx, ppc=2, jitter=0.5, seed=0)
    dt = 0.4 * dx / SAND_PARAMS.p_wave_speed
    sol = SandSolver(backend, (SAND_GRID,) * 3, dx, dt, SAND_PARAMS, body.x, body.volume,
                     velocities=(0.0, 0.0, -1.0), walls=DomainWalls.uniform("separate", 0.5, bound=3),
                     cfl_check_every=0)  # fmt: skip
    rate = steps * sol.n_particles / timed(backend, lambda: sol.step(steps), repeats)
    ceiling = projected_items_per_s(SAND_STEP_BYTES, bandwidth, 1.0)
    return {"particles": sol.n_particles, "particle_steps_per_s": rate, "bytes_per_particle": SAND_STEP_BYTES,
            "bandwidth_bound_particle_steps_per_s": ceiling, "fraction_of_bandwidth_bound": rate / ceiling}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description="Fluid and sand throughput on a GPU (the cuda backend) at GPU sizes, against the "
        "bandwidth-bound ceilings of couplekit/backend/traffic.py."
    )
    ap.add_argument("--cells", type=int_in(2), nargs="*", default=[256], help="fluid box edges (n^3 cells)")
    ap.add_argument(
        "--particles",
        type=float_in(0.0, MAX_MILLIONS, lo_open=True, why=f"the block must fit the {SAND_GRID}^3 grid"),
        nargs="*",
        default=[1, 4, 16],
        help="millions of sand particles",
    )
    ap.add_argument("--steps", type=int_in(1), default=20, help="sand steps per timing")
    ap.add_argument("--repeats", type=int_in(1), default=3)
    ap.add_argument("--bandwidth", type=positive_float(), default=4.8e12, help="the GPU's peak DRAM bandwidth, bytes/s")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "gpu_throughput.json")
    args = ap.parse_args(argv)
    backend = get_backend("cuda")
    result = {"backend": backend.describe(), "bandwidth_bytes_per_s": args.bandwidth,
              "note": f"ceilings at 100 % of --bandwidth; the build report projects at {BANDWIDTH_EFFICIENCY:.0%}",
              "fluid": {}, "sand": {}}  # fmt: skip
    for n in args.cells:
        result["fluid"][str(n)] = fluid(backend, n, args.repeats, args.bandwidth)
        print(json.dumps({f"fluid {n}^3": result["fluid"][str(n)]}, indent=1), flush=True)
    for m in args.particles:
        result["sand"][f"{m:g}M"] = sand(backend, m, args.steps, args.repeats, args.bandwidth)
        print(json.dumps({f"sand {m:g}M": result["sand"][f"{m:g}M"]}, indent=1), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
