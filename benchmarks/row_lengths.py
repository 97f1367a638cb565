"""Host throughput of the flow stages against the length of the x rows, in a walled two-phase box (every row a
wall row, so the masked row path): the collide-stream, the pressure update and its filter, in MLUPS, for row
lengths around multiples of the vector width (16 float lanes with AVX-512).

    python benchmarks/row_lengths.py [--lengths 24 26 31 32 33 47 48 64 128] [--threads 1] [--repeats 7]
        [--out benchmarks/results/row_lengths.json]

An `omp simd` loop runs its last (length mod 16) cells in a scalar epilogue, which cost about as much per cell
as a whole vector before the row loops ended with one whole vector (kernels/lbm_core.cuh, lbm_row_tail): this
is the measurement that shows it. Run it on two checkouts, alternating, to compare them (timings drift by up to
3x between runs, DESIGN); each length keeps its best of ``--repeats`` blocks.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
from _args import int_in

from couplekit.backend import get_backend
from couplekit.fluid import FluidParams, FluidSolver
from couplekit.fluid.grid import Boundaries, Face

RESULTS = Path(__file__).resolve().parent / "results"
NZ, NY = 16, 24


def walled_box(backend, nx: int) -> FluidSolver:
    """A 16 × 24 × nx box, walls on all six faces, water under air (800:1, a tanh interface of width 4)."""
    n = (NZ, NY, nx)
    params = FluidParams(rho_h=1.0, rho_l=1 / 800, nu_h=1e-3, nu_l=1e-2, sigma=1e-4, gravity=(0.0, 0.0, -1e-6))
    zc = np.arange(NZ)[:, None, None] + 0.5
    phi = np.broadcast_to(0.5 * (1 + np.tanh(2 * (NZ / 2 - zc) / 4.0)), n).copy()
    faces = {k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")}
    return FluidSolver(backend, n, params, Boundaries(faces), phi=phi)


def stage_calls(s: FluidSolver) -> dict:
    """One even and one odd call of each stage on ``s``'s state (callables)."""
    ops, prm = s.ops, s.params

    def collide():
        for parity in (0, 1):
            ops.collide_stream(
                s.f, s.flags, s.velocity, s.phi, None, None, s.pbar, parity, prm.rho_h, prm.rho_l, prm.nu_h,
                prm.nu_l, *prm.gravity, chemical_potential=(s.beta, s.kappa),
            )  # fmt: skip

    def pressure():
        for parity in (0, 1):
            ops.macro_pressure(s.f, s.flags, s.velocity, s.phi, None, None, None, s.p, parity, prm.rho_h, prm.rho_l)

    def pressure_filter():
        for _ in range(2):
            ops.pressure_filter(s.p, s.flags, s.pbar)

    return {"collide_stream": collide, "macro_pressure": pressure, "pressure_filter": pressure_filter}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lengths", type=int_in(2), nargs="+", default=[24, 26, 31, 32, 33, 47, 48, 64, 128],
                        help="x row lengths nx (cells)")  # fmt: skip
    parser.add_argument("--threads", type=int_in(1), default=1)
    parser.add_argument("--repeats", type=int_in(1), default=7)
    parser.add_argument("--out", type=Path, default=RESULTS / "row_lengths.json")
    args = parser.parse_args()
    backend = get_backend("cpu", threads=args.threads)
    result = {
        "machine": {"platform": platform.platform(), "threads": args.threads},
        "backend": backend.describe(),
        "box": f"{NZ} x {NY} x nx, walls on every face, 800:1",
        "mlups": {},
    }
    for nx in args.lengths:
        s = walled_box(backend, nx)
        calls = stage_calls(s)
        cells = NZ * NY * nx
        inner = max(1, int(2e5 // cells))
        row = {}
        for name, fn in calls.items():
            fn()  # warm-up (and the kernel build)
            best = float("inf")
            for _ in range(args.repeats):
                t = time.perf_counter()
                for _ in range(inner):
                    fn()
                best = min(best, (time.perf_counter() - t) / (2 * inner))
            row[name] = cells / best / 1e6
        result["mlups"][str(nx)] = row
        print(nx, {k: round(v, 1) for k, v in row.items()}, flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
