"""The planar column collapse of issue 16 with one thing changed at a time (docs/sand-validation.md).

The set-up is ``planar_collapse`` of tests/sand/test_collapse_convergence.py (a = 1, L0 = 8 cm, ``--cells``
across, two cells thick in y, slip back wall, separating floor with Coulomb friction, 2^3 particles per
cell), on the cpu backend.  The experimental variants are monkey-patches of the solver's ops, for the study
only:

* ``--transfer pic``: P2G without the APIC affine term (C = 0 in the momentum transfer);
* ``--transfer flip:B``: an APIC/FLIP blend of the particle velocity, v = v_APIC + B (v_old - I(v_grid_old)),
  with the grid velocity before forces from a second, stress-free P2G (B = 1: pure FLIP velocity update,
  C and positions from APIC as before);
* ``--float64``: the NumPy reference with every particle and grid array in float64 (slow).

Prints one JSON line: the raw runout (99.5th percentile of x, (L - L0)/L0), the deposit fronts at 0.2, 0.1
and 0.05 L0 thickness, the final height and kinetic energy per mass.

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/collapse_study.py --cells 8 --cfl 0.35 --viscosity 0
    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/collapse_study.py --cells 8 --transfer flip:1
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from _args import float_in, int_in, positive_float

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "sand"))

from test_collapse_convergence import BOUND, L0, deposit_front  # noqa: E402

from couplekit.backend import get_backend  # noqa: E402
from couplekit.sand import DomainWalls, SandParams, Wall  # noqa: E402
from couplekit.sand.reference import _stencil  # noqa: E402
from couplekit.sand.seeding import seed_box  # noqa: E402
from couplekit.sand.solver import SandSolver  # noqa: E402


def _pic(sol) -> None:
    p2g = sol.ops.p2g

    def patched(x, v, C, *rest):
        p2g(x, v, np.zeros_like(C), *rest)

    sol.ops.p2g = patched


def _flip(sol, blend: float) -> None:
    p2g, g2p = sol.ops.p2g, sol.ops.g2p
    old = {}

    def patched_p2g(x, v, C, tau, mass, vol, gm, gmv, gvol, dx, dt):
        p2g(x, v, C, tau, mass, vol, gm, gmv, gvol, dx, dt)
        # grid_vol is None with one particle density (SandSolver.node_volume)
        m0, mv0, vol0 = np.zeros_like(gm), np.zeros_like(gmv), None if gvol is None else np.zeros_like(gvol)
        p2g(x, v, C, np.zeros_like(tau), mass, vol, m0, mv0, vol0, dx, dt)  # no stress: momentum before forces
        old["v"] = np.where(m0 > 0, mv0 / np.where(m0 > 0, m0, 1.0), 0.0).astype(np.float64)

    def patched_g2p(x, v, C, F, tau, q, vc, sat, grid_v, dx, dt, model):
        x0, v0 = x.copy(), v.astype(np.float64)
        g2p(x, v, C, F, tau, q, vc, sat, grid_v, dx, dt, model)
        index, w, _ = _stencil(x0, dx, grid_v.shape[1:])
        gathered = np.einsum("pk,apk->ap", w, old["v"].reshape(3, -1)[:, index])
        v[...] = v + blend * (v0 - gathered)

    sol.ops.p2g, sol.ops.g2p = patched_p2g, patched_g2p


def run(args) -> dict:
    params = SandParams(hardening=False, h0=args.h0, viscosity=args.viscosity)
    dx = L0 / args.cells
    nx = BOUND + int(args.cells * (4.2 if args.friction > 0 else 5.5)) + 4
    nz, ny, o = BOUND + args.cells + 4, 2 * BOUND + 2, BOUND * dx
    body = seed_box((o, o, o), (o + L0, o + 2 * dx, o + L0), dx, ppc=args.ppc, jitter=0.5, seed=args.seed)
    walls = DomainWalls.from_dict(
        {"-x": Wall("slip"), "-y": Wall("slip"), "+y": Wall("slip"), "-z": Wall("separate", args.friction)},
        default=Wall("separate"),
    )
    dt = args.cfl * dx / params.p_wave_speed
    backend = get_backend("numpy" if args.float64 else "cpu")
    sol = SandSolver(backend, (nz, ny, nx), dx, dt, params, body.x, body.volume, walls=walls)
    if args.float64:
        for k in ("x", "v", "C", "F", "tau", "vc", "volume", "mass", "grid_m", "grid_mv", "grid_vol"):
            if getattr(sol, k) is not None:  # grid_vol: None with one particle density (SandSolver.node_volume)
                setattr(sol, k, getattr(sol, k).astype(np.float64))
        sol.grid_v = sol.grid_mv  # one node array for momentum and velocity, as SandSolver allocates it
    if args.transfer == "pic":
        _pic(sol)
    elif args.transfer.startswith("flip:"):
        _flip(sol, float(args.transfer.split(":", 1)[1]))
    elif args.transfer != "apic":
        raise SystemExit(f"--transfer: apic, pic or flip:B, got {args.transfer!r}")
    t0 = time.perf_counter()
    sol.step(int(round(args.t_end / dt)))
    x = sol.particles()["x"].astype(np.float64)
    d = sol.diagnostics()
    out = {"cells": args.cells, "cfl": args.cfl, "viscosity": args.viscosity, "transfer": args.transfer}
    out["runout"] = float(np.percentile(x[0] - o, 99.5) / L0 - 1.0)
    for h in (0.2, 0.1, 0.05) if args.friction > 0 else ():
        try:
            out[f"front_{h}"] = deposit_front(x, o, h)
        except ValueError:
            out[f"front_{h}"] = None
    out["height"] = float((np.percentile(x[2], 99.5) - o) / L0)
    out["kinetic_energy"] = d["kinetic_energy"] / d["mass"]
    out["wall_s"] = time.perf_counter() - t0
    return out


def transfer(text: str) -> str:
    """--transfer: apic, pic or flip:B with B a number."""
    kind, _, blend = text.partition(":")
    ok = text in ("apic", "pic")
    if kind == "flip" and blend:
        try:
            ok = math.isfinite(float(blend))
        except ValueError:
            ok = False
    if not ok:
        raise argparse.ArgumentTypeError(f"must be apic, pic or flip:B (B the FLIP blend, e.g. flip:1), got {text!r}")
    return text


def main() -> int:
    ap = argparse.ArgumentParser(
        description="The planar column collapse of issue 16 with one thing changed at a time "
        "(docs/sand-validation.md); prints one JSON line."
    )
    ap.add_argument("--cells", type=int_in(1), default=8, help="cells across the column (L0)")
    ap.add_argument("--cfl", type=float_in(0.0, 0.5, lo_open=True, why="the MPM elastic limit 0.5 dx / c_p"),
                    default=0.35, help="dt = cfl dx / c_p")  # fmt: skip
    ap.add_argument("--viscosity", type=float_in(0.0), default=1.5, help="SandParams.viscosity, Pa s (0: Klar)")
    ap.add_argument("--h0", type=float_in(0.0, 90.0, lo_open=True, hi_open=True), default=20.0,
                    help="constant friction angle, deg")  # fmt: skip
    ap.add_argument("--friction", type=float_in(0.0), default=0.5, help="floor Coulomb friction")
    ap.add_argument("--t-end", type=positive_float(), default=0.45, help="simulated seconds")
    ap.add_argument("--ppc", type=int_in(1), default=2, help="particles per cell per axis")
    ap.add_argument("--seed", type=int, default=1, help="seed of the particle jitter")
    ap.add_argument("--transfer", type=transfer, default="apic", help="apic, pic or flip:B (B the FLIP blend)")
    ap.add_argument("--float64", action="store_true", help="the NumPy reference on float64 state")
    print(json.dumps(run(ap.parse_args())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
