"""A prototype closure, measured: the odd-moment rate floor near the no-slip walls only, ramped to the paper's rate 1.

    python benchmarks/odd_floor_ramp.py linear [--box 4x12x12] [--ramps 0 1 3 5]
    python benchmarks/odd_floor_ramp.py noise|tank|wave [--ramps 3 none]   (none: the paper's collision, 0: floor everywhere)
    python benchmarks/odd_floor_ramp.py ball [--ramps 3] [--time 0.75]

Why (issue 16, Fig. 8 at interface width 4; docs/examples.md): the scenes' floor keeps the odd moments relaxing at
r_o ≈ 0.02 everywhere at ν_h = 1e-4 (``FluidParams.odd_lambda``), which cures the bounce-back walls' edge
instability (docs/fluid-stability.md, "Why") but throws a 600 kg/m³ ball two cells up at ξ = 4. Here the floor's
rate is blended with 1 by a cosine ramp of the distance d (cells) of a cell centre from the nearest wall face:
r_o(d) = r_floor + (1 − r_floor) s(d), s = ½ − ½ cos(π t), t = clip((d − ½) / D, 0, 1), so the wall cells keep the
floor and cells D cells further in relax at 1 (with Smagorinsky, its ν_t still enters r_floor). ``D = 0`` is
the floor everywhere (the scenes' closure), ``none`` the paper's collision (floor off).

The session-14 prototype of what is now ``FluidParams.odd_ramp`` / ``fluid.odd_ramp`` (couplekit/fluid/odd_ramp.py,
built into the kernels in session 15 from these measurements; tests/fluid/test_odd_ramp.py). Here the NumPy
reference's :func:`couplekit.fluid.reference.odd_rates` is wrapped for the run (numpy backend, so the runs are
slow) with the distance to the walls of whole faces only; the linear case is what chose the solver's gap rule.

* ``linear``: spectral radius of one collide + half-way bounce-back + stream step linearised at rest (walls on
  x and y, periodic z; tests/fluid/test_wall_stability.py's step) by matrix-free Arnoldi (scipy ``eigs``).
* ``noise``: tests/fluid/test_wall_stability.py's 0.003-noise box (8 × 24 × 24, walls on x and y, ν = 1e-4):
  kinetic energy every 500 steps.
* ``tank``: a still 800:1 tank (16³, walls on every face, ν_h = 1e-4, ν_l = 1e-2, gravity, hydrostatic start,
  Smagorinsky 0.1): max lattice speed every 500 steps over 4000.
* ``wave``: tests/fluid/test_standing_wave.py's standing wave (30 × 4 × 40, walls on x and z), one period:
  the kinetic energy's peak in each half period over the wave's energy.
* ``ball``: benchmarks/fig08_interface_width.py's single 600 kg/m³ ball (radius 1.74 cells, ξ = 4, the Fig. 8
  small variant's lattice numbers) released at rest touching the surface: its centre against Archimedes'.

Results: benchmarks/results/odd_floor_ramp.json (one record per case, replaced when rerun) and printed lines.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests" / "fluid"))

from _args import float_in, positive_float, shape3  # noqa: E402

import couplekit.fluid.reference as ref  # noqa: E402
from couplekit.backend import get_backend  # noqa: E402
from couplekit.fluid.grid import Boundaries  # noqa: E402
from couplekit.fluid.solver import FluidParams, FluidSolver  # noqa: E402

NU = 1e-4
LAMBDA = 0.015  # the scenes' floor
_ODD_RATES = ref.odd_rates


def ramp(shape: tuple[int, int, int], walls: str, D: float) -> np.ndarray:
    """s(d) on the interior cells (nz, ny, nx): 0 in the wall cells, 1 from D + ½ cells from every wall in
    ``walls`` (axes 'x', 'y', 'z' with walls on both faces)."""
    d = np.full(shape, np.inf)
    for axis, name in ((2, "x"), (1, "y"), (0, "z")):
        if name in walls:
            n = shape[axis]
            c = np.arange(n) + 0.5
            view = [1, 1, 1]
            view[axis] = n
            d = np.minimum(d, np.minimum(c, n - c).reshape(view))
    t = np.clip((d - 0.5) / D, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * t)


def use_ramp(walls: str, D: float | None) -> None:
    """Wrap the reference's odd_rates: the floor blended with 1 by ramp(walls, D) (D None or 0: unwrapped)."""
    cache: dict[tuple, np.ndarray] = {}

    def ramped(r_s, nu, nu_ref, odd_lambda, odd_nu_max):
        base = _ODD_RATES(r_s, nu, nu_ref, odd_lambda, odd_nu_max)
        if np.isscalar(base):  # the floor is off (rate 1 everywhere)
            return base
        shape = np.shape(r_s)
        if shape not in cache:
            cache[shape] = ramp(shape, walls, D)
        return base + (1.0 - base) * cache[shape]

    ref.odd_rates = _ODD_RATES if not D else ramped


def floor_of(D: float | None) -> float:
    return 0.0 if D is None else LAMBDA


# ------------------------------------------------------------------------------------------------- linear
def linear(box: tuple[int, int, int], D: float | None) -> dict:
    from scipy.sparse.linalg import LinearOperator, eigs
    from test_wall_stability import _bounce_back_step  # the test's step: pull, half-way bounce-back

    r_s = 1.0 / (3.0 * NU + 0.5)
    base_ro = float(ref.odd_rate(r_s, floor_of(D)))
    r_o = base_ro if not D else base_ro + (1.0 - base_ro) * ramp(box, "xy", D)
    step = _bounce_back_step(box, "xy", NU, floor_of(D), r_o)

    f0 = ref.equilibrium(np.zeros((3, *box)))
    base, h = step(f0), 1e-6

    def matvec(v):
        return ((step(f0 + h * np.asarray(v).real.reshape(f0.shape)) - base) / h).reshape(-1)

    op = LinearOperator((f0.size, f0.size), matvec=matvec, dtype=np.float64)
    vals = eigs(op, k=6, which="LM", return_eigenvectors=False, maxiter=5000, tol=1e-9, ncv=40)
    top = vals[np.argmax(np.abs(vals))]
    return {"spectral_radius": float(np.abs(vals).max()), "eigenvalue": [float(top.real), float(top.imag)]}


# ------------------------------------------------------------------------------------------- non-linear
def noise(D: float | None) -> dict:
    rng = np.random.default_rng(0)
    shape = (8, 24, 24)
    v = (rng.standard_normal((3, *shape)) * 0.003).astype(np.float32)
    use_ramp("xy", D)
    s = FluidSolver(
        get_backend("numpy"), shape, FluidParams(nu_h=NU, nu_l=NU, odd_lambda=floor_of(D)),
        boundaries=Boundaries.channel("xy"), velocity=v,
    )  # fmt: skip
    energy = []
    for _ in range(3):
        s.step(500)
        energy.append(s.diagnostics()["kinetic_energy"])
    return {"kinetic_energy_every_500": energy}


def tank(D: float | None, n: int = 16) -> dict:
    g, rho_l = 2e-5, 1.0 / 800.0
    z = np.arange(n) + 0.5
    phi1 = 0.5 * (1.0 - np.tanh(2.0 * (z - 0.5 * n) / 4.0))
    rho = rho_l + (1.0 - rho_l) * phi1
    p1 = np.cumsum((rho * g)[::-1])[::-1] - 0.5 * rho * g
    phi = np.broadcast_to(phi1[:, None, None], (n, n, n)).astype(np.float32).copy()
    p = np.broadcast_to(p1[:, None, None], (n, n, n)).astype(np.float32).copy()
    params = FluidParams(
        rho_h=1.0, rho_l=rho_l, nu_h=NU, nu_l=1e-2, gravity=(0.0, 0.0, -g), odd_lambda=floor_of(D), smagorinsky=0.1
    )  # fmt: skip
    use_ramp("xyz", D)
    s = FluidSolver(get_backend("numpy"), (n, n, n), params, Boundaries.channel("xyz"), phi=phi, pressure=p)
    speed = []
    for _ in range(8):
        s.step(500)
        speed.append(s.diagnostics()["max_lattice_speed"])
    return {"max_lattice_speed_every_500": speed}


def wave(D: float | None) -> dict:
    import test_standing_wave as tsw

    if D is None:
        raise SystemExit("wave: the standing wave is set up with the scenes' floor; give ramps >= 0")
    use_ramp("xz", D)
    every = 50
    half = int(tsw.PERIOD / 2) // every * every
    ke = tsw._kinetic_energy_history(get_backend("numpy"), 2 * half, every) / tsw.WAVE_ENERGY
    return {
        "peak_first_half_period": float(ke[: half // every].max()),
        "peak_second_half_period": float(ke[half // every :].max()),
        "kinetic_energy_over_wave_energy_every_50": [float(x) for x in ke],
    }


def ball(D: float | None, t_end: float) -> dict:
    import fig08_interface_width as fb

    use_ramp("xyz", D)
    f = {"drop": 0.0} if D is not None else {"drop": 0.0, "odd_lambda": 0.0}
    r = fb.run_case(1.74, 4.0, t_end, "numpy", f)
    keep = ("centre_cells", "archimedes_centre_cells", "error_cells", "highest_centre_above_release_cells")
    out = {k: r[k] for k in keep}
    out["centre_history_cells"] = r["centre_history_cells"]
    out["final_error_cells"] = r["centre_history_cells"][-1] - r["archimedes_centre_cells"]
    return out


def ramp_type(text: str) -> float | None:
    """--ramps: a ramp length D >= 0 in cells, or none (the floor off)."""
    if text.lower() == "none":
        return None
    try:
        return float_in(0.0)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be a number >= 0 (cells) or none, got {text!r}") from None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("case", choices=["linear", "noise", "tank", "wave", "ball"])
    ap.add_argument("--ramps", nargs="+", type=ramp_type, default=[3.0],
                    help="ramp lengths D in cells; 0: floor everywhere; none: off")  # fmt: skip
    ap.add_argument("--box", type=shape3(2, sep="x", label="NZxNYxNX"), default="4x12x12", help="linear: nz x ny x nx")
    ap.add_argument("--time", type=positive_float(), default=0.75, help="ball: simulated seconds")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "odd_floor_ramp.json"))
    args = ap.parse_args()
    if args.case == "wave" and None in args.ramps:
        ap.error("--ramps: wave: the standing wave is set up with the scenes' floor; give ramps >= 0, not none")
    path = Path(args.out)
    records = json.loads(path.read_text()) if path.exists() else []
    for D in args.ramps:
        t0 = time.perf_counter()
        if args.case == "linear":
            res, key = linear(args.box, D), {"box": list(args.box)}
        elif args.case == "ball":
            res, key = ball(D, args.time), {"time_s": args.time}
        else:
            res, key = {"noise": noise, "tank": tank, "wave": wave}[args.case](D), {}
        rec = {"case": args.case, "ramp_cells": D, **key, **res, "wall_s": time.perf_counter() - t0}
        records = [r for r in records if not (r["case"] == rec["case"] and r["ramp_cells"] == D and all(
            r.get(k) == v for k, v in key.items()))] + [rec]  # fmt: skip
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(records, indent=1) + "\n")
        shown = {k: v for k, v in rec.items() if not k.endswith("_history_cells") and not k.endswith("every_50")}
        print(json.dumps(shown), flush=True)


if __name__ == "__main__":
    main()
