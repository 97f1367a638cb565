"""Fig. 8 at the default interface width: the smallest ball (radius in cells) that floats at Archimedes' depth.

    python benchmarks/fig08_interface_width.py [--radii 1.74 2.0 2.4 3.0] [--widths 4] [--also 1.74:8] [--time 3.0]

Paper 000 Fig. 8's 600 kg/m³ sand ball floats. Our small variant (examples/fig08_sand_densities_small.toml,
10× coarser than Table 1: balls of 1.74 cells radius) needs interface width ξ = 8: at ξ = 4 the light ball
rides on top of the water. This script drops one 600 kg/m³ ball at the small variant's lattice numbers
(dx = 5 cm, dt = 1.6e-4 s, ν_h = 1e-4, ν_l = 1e-2, surface tension 0.073 N/m, impact ≈ 3.4 m/s from 0.6 m
above the surface, as in the small variant) with its radius r given in cells, for each width ξ, and records
where it ends: the centre height of its particles (mean over the frames of the second half of the run, which
averages the ball's bobbing) against Archimedes'
floating height. Archimedes (the pore water is neutral; only the grain volume's density counts): a sphere
of grain density 600 kg/m³ floats with a cap of height t·r submerged, t²(3 − t)/4 = 0.6 → t = 1.134, so its
centre is at surface + (1 − t)·r. The domain is 8 r wide (at least 0.6 m) so the walls stay away from the
ball; the pool 0.8 m deep as in the small variant.

Results: benchmarks/results/fig08_interface_width.json (one record per (r, ξ)), and a table printed.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from couplekit.scene import Scene
from couplekit.simulation import Simulation

ROOT = Path(__file__).resolve().parent.parent
DX, DT, DEPTH, DROP = 0.05, 0.00016, 0.8, 0.6  # m, s, pool depth m, bottom of the ball above the surface m
GRAIN_DENSITY = 600.0


def archimedes_cap_ratio(density_ratio: float) -> float:
    """t with t²(3 − t)/4 = density_ratio (a floating sphere's submerged cap height over its radius)."""
    lo, hi = 0.0, 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid * mid * (3 - mid) / 4 < density_ratio else (lo, mid)
    return 0.5 * (lo + hi)


def scene(radius_cells: float, xi: float, t_end: float) -> dict:
    r = radius_cells * DX
    width = max(0.6, 8 * r)
    width = DX * math.ceil(width / DX)
    height = DX * math.ceil((DEPTH + DROP + 2 * r + 0.3) / DX)
    frames = max(1, int(round(t_end / 0.05)))
    return {
        "scene": {"name": f"fig08_ball_r{radius_cells:g}_xi{xi:g}"},
        "domain": {"size": [width, width, height], "dx": DX},
        "time": {"dt": DT, "frame_duration": 0.05, "frames": frames},
        "fluid": {
            "phases": 2,
            "water_lattice_viscosity": 1e-4,
            "air_lattice_viscosity": 1e-2,
            "surface_tension": 0.073,
            "controller_eta": 2.0,
            "interface_width": xi,
        },
        "sand": {"density": 1200.0, "youngs_modulus": 350000.0, "poisson_ratio": 0.3, "particles_per_cell": 8},
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [width, width, DEPTH]}},
            {
                "kind": "sand",
                "density": GRAIN_DENSITY,
                "geometry": {"type": "sphere", "center": [width / 2, width / 2, DEPTH + DROP + r], "radius": r},
            },
        ],
        "outputs": {"preview": False},
    }


def run_case(radius_cells: float, xi: float, t_end: float, backend: str) -> dict:
    d = scene(radius_cells, xi, t_end)
    sim = Simulation(Scene.from_dict(d), backend=backend, log=None)
    steps_per_frame = int(round(0.05 / DT))
    frames = d["time"]["frames"]
    centres, tops, bottoms = [], [], []
    t0 = time.perf_counter()
    for _ in range(frames):
        sim.step(steps_per_frame)
        z = sim.particles()["x"][2] / DX
        centres.append(float(z.mean()))
        tops.append(float(z.max()))
        bottoms.append(float(z.min()))
    tail = max(1, frames // 2)
    surface = DEPTH / DX
    t = archimedes_cap_ratio(GRAIN_DENSITY / 1000.0)
    expected = surface + (1.0 - t) * radius_cells
    centre = float(np.mean(centres[-tail:]))
    return {
        "radius_cells": radius_cells,
        "interface_width": xi,
        "time_s": frames * 0.05,
        "centre_cells": centre,
        "archimedes_centre_cells": expected,
        "error_cells": centre - expected,
        "error_radii": (centre - expected) / radius_cells,
        "lowest_centre_cells": float(min(centres)),
        "lowest_bottom_cells": float(min(bottoms)),
        "final_bottom_cells": bottoms[-1],
        "final_top_cells": tops[-1],
        "surface_cells": surface,
        "entered_the_water": bool(min(bottoms) < surface),
        "centre_history_cells": centres,
        "wall_s": time.perf_counter() - t0,
    }


def radius_and_width(text: str) -> tuple[float, float]:
    """An ``--also`` case R:XI (radius in cells, interface width) as floats; argparse reports a bad one."""
    try:
        r, xi = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected RADIUS_CELLS:WIDTH, e.g. 1.74:8, got {text!r}") from None
    if not (r > 0 and xi > 0):
        raise argparse.ArgumentTypeError(f"radius and width must be > 0, got {text!r}")
    return r, xi


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radii", type=float, nargs="+", default=[1.74, 2.0, 2.4, 3.0])
    ap.add_argument("--widths", type=float, nargs="+", default=[4.0])
    ap.add_argument(
        "--also",
        nargs="*",
        type=radius_and_width,
        default=[(1.74, 8.0)],
        help="extra R:XI cases (default the small variant's 1.74:8)",
    )
    ap.add_argument(
        "--time",
        type=float,
        default=3.0,
        help="simulated seconds (default 3: at 1 s, the small variant's end, the balls still bob)",
    )
    ap.add_argument("--backend", default="cpu")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "fig08_interface_width.json"))
    a = ap.parse_args()
    results = []
    print("r (cells)  xi   centre - Archimedes (cells)  (radii)   lowest bottom  surface   wall s")
    cases = [(r, xi) for r in a.radii for xi in a.widths]
    cases += list(a.also)
    for r, xi in cases:
        res = run_case(r, xi, a.time, a.backend)
        results.append(res)
        print(f"{r:8.2f} {xi:4.0f} {res['error_cells']:+14.2f} {res['error_radii']:+18.2f} "
                  f"{res['lowest_bottom_cells']:12.2f} {res['surface_cells']:9.1f} {res['wall_s']:8.0f}", flush=True)  # fmt: skip
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"command": "python benchmarks/fig08_interface_width.py", "runs": results}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
