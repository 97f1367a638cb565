"""Fig. 8 at the default interface width: the smallest ball (radius in cells) that floats at Archimedes' depth.

    python benchmarks/fig08_interface_width.py [--radii 1.74 2.0 2.4 3.0] [--widths 4] [--also 1.74:8] [--time 3.0]
        [--set KEY=VALUE ...] [--small-variant]

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

One factor at a time (issue 16): ``--set KEY=VALUE ...`` changes the keys of DEFAULTS for every case, e.g.
``--set drop=0 odd_lambda=0`` (released at rest touching the surface, the odd moments at the paper's rate 1);
each record keeps what it changed, the ball's water fraction φ against the far field's at its height, and the
pore fluid's and the sand's vertical speed per frame. ``pressure_buoyancy`` is an experiment of this script
only (a wrapper around the coupler's exchange, NumPy gradient), not a solver option. ``--small-variant`` runs
the example scene itself at each ``--widths`` (odd_lambda, smagorinsky, odd_ramp from ``--set``): each ball's centre,
the max lattice speed and where it is. What was found: docs/examples.md, the fig08_sand_densities_small bullet.

Results: benchmarks/results/fig08_interface_width.json (one record per case; a case run again replaces its
record, ``--replace`` starts the file afresh), and a table printed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np
from _args import positive_float

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


#: the factors one experiment may change (``--set KEY=VALUE``), with the small variant's values
DEFAULTS = {
    "nu_h": 1e-4,  # water lattice viscosity
    "drop": DROP,  # m, the ball's bottom above the surface at release (0: touching it, at rest)
    "speed": 0.0,  # m/s, the ball's initial downward speed
    "sigma": 0.073,  # N/m
    "eta": 2.0,  # volume controller
    "odd_lambda": None,  # None: the scene default
    "smagorinsky": None,  # None: the scene default
    "odd_ramp": None,  # None: the scene default (the floor everywhere); D: the floor ramped to rate 1 over D cells
    "drag_coefficient": None,  # None: CouplingParams' 0.39
    "ppc": 8,  # particles per cell
    "substeps": None,  # None: lockstep; k: the subcycle scheduler with k MPM substeps per LBM step
    "depth": DEPTH,  # m, the pool depth
    "pressure_buoyancy": 0.0,  # 1: the sand feels -eps_s grad(p) of the fluid's pressure instead of Eq. 31's
    #                           hydrostatic -eps_s rho(phi) g (2: also the capillary force eps_s mu grad(phi))
}


def factors(text: str) -> tuple[str, float | None]:
    """A ``--set`` item KEY=VALUE (a key of DEFAULTS; VALUE a number or 'none')."""
    key, _, value = text.partition("=")
    if key not in DEFAULTS or not value:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE with KEY one of {', '.join(DEFAULTS)}, got {text!r}")
    return key, None if value.lower() == "none" else float(value)


def scene(radius_cells: float, xi: float, t_end: float, f: dict | None = None) -> dict:
    f = {**DEFAULTS, **(f or {})}
    r = radius_cells * DX
    depth, drop = f["depth"], f["drop"]
    width = max(0.6, 8 * r)
    width = DX * math.ceil(width / DX)
    height = DX * math.ceil((depth + drop + 2 * r + 0.3) / DX)
    frames = max(1, int(round(t_end / 0.05)))
    fluid = {
        "phases": 2,
        "water_lattice_viscosity": f["nu_h"],
        "air_lattice_viscosity": 1e-2,
        "surface_tension": f["sigma"],
        "controller_eta": f["eta"],
        "interface_width": xi,
    }
    for key in ("odd_lambda", "smagorinsky", "odd_ramp"):
        if f[key] is not None:
            fluid[key] = f[key]
    ball = {
        "kind": "sand",
        "density": GRAIN_DENSITY,
        "geometry": {"type": "sphere", "center": [width / 2, width / 2, depth + drop + r], "radius": r},
    }
    if f["speed"]:
        ball["velocity"] = [0.0, 0.0, -abs(f["speed"])]
    d = {
        "scene": {"name": f"fig08_ball_r{radius_cells:g}_xi{xi:g}"},
        "domain": {"size": [width, width, height], "dx": DX},
        "time": {"dt": DT, "frame_duration": 0.05, "frames": frames},
        "fluid": fluid,
        "sand": {
            "density": 1200.0,
            "youngs_modulus": 350000.0,
            "poisson_ratio": 0.3,
            "particles_per_cell": int(f["ppc"]),
        },
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [width, width, depth]}},
            ball,
        ],
        "outputs": {"preview": False},
    }
    if f["substeps"] is not None:
        d["scheduler"] = {"kind": "subcycle", "substeps": int(f["substeps"])}
    return d


def ball_water(sim) -> tuple[float, float, float]:
    """The water fraction the ball's buoyancy sees, the one it would see in undisturbed water, the pore fluid's
    upward speed (m/s, ε_s-weighted over the ball's cells).

    First: Σ ε_s φ / Σ ε_s over the cells holding sand (Eq. 31's buoyancy is Σ ε_s ρ(φ) V g, so a resting ball
    balances its weight where this is (ϱ − ρ_l)/(ρ_h − ρ_l) ≈ 0.6). Second: the same weights on the far
    field's φ(z), the mean over the domain's outermost columns at the same height: above it the ball has
    lifted the water with it (the pores or the surface under it wetter than the undisturbed profile)."""
    host = sim.backend.to_host
    es = sim.coupler.fields()["sand_fraction"].astype(np.float64)
    phi = np.clip(host(sim.fluid.phi)[1:-1, 1:-1, 1:-1].astype(np.float64), 0.0, 1.0)
    edge = np.ones(phi.shape[1:], bool)
    edge[1:-1, 1:-1] = False  # the outermost columns
    far_z = phi[:, edge].mean(axis=1)[:, None, None]
    total = es.sum()
    if total <= 0:
        return float("nan"), float("nan"), float("nan")
    uz = host(sim.fluid.velocity)[2, 1:-1, 1:-1, 1:-1].astype(np.float64) * DX / DT  # m/s (lockstep: LBM step DT)
    return float((es * phi).sum() / total), float((es * far_z).sum() / total), float((es * uz).sum() / total)


def use_pressure_buoyancy(sim, capillary: bool) -> None:
    """Experiment: Δt ε_s V (ρ g − ∇p̄) added to the sand's grid momentum before each exchange, so that its
    buoyancy is −ε_s V ∇p̄ (the pressure gradient the fluid's collision used) instead of Eq. 31's −ε_s V ρ(φ) g
    (adding to (mv) before the exchange is the same as changing F_b inside it: v* = ((mv) + Δt F_b)/m)."""
    from couplekit.fluid.reference import isotropic_gradient

    c, fl, sand = sim.coupler, sim.fluid, sim.sand
    host, prm, u = sim.backend.to_host, fl.params, c.units
    mass_scale = u.rho * u.dx**3
    g = np.asarray(sand.gravity, np.float64).reshape(3, 1, 1, 1) * u.dt**2 / u.dx  # lattice
    exchange = c.exchange

    def exchange_with_pressure(*args, **kw):
        flags = host(fl.flags)
        pbar = host(fl.p if prm.store_filtered_pressure else fl.pbar)
        grad = isotropic_gradient(pbar, flags, extrapolate=True)
        phi = np.clip(host(fl.phi)[1:-1, 1:-1, 1:-1].astype(np.float64), 0.0, 1.0)
        rho = prm.rho_l + (prm.rho_h - prm.rho_l) * phi
        extra = rho * g - grad  # lattice force density per unit ε_s
        mu = fl.phase_gradients()[1] if capillary else None
        if mu is not None:
            extra = extra + host(mu)[1:-1, 1:-1, 1:-1] * isotropic_gradient(host(fl.phi), flags)
        es = c.fields()["sand_fraction"].astype(np.float64)
        m = host(sand.grid_m)
        active = (m > 0) & (flags[1:-1, 1:-1, 1:-1] == 0)
        impulse = np.where(active, es * extra, 0.0) * mass_scale * (u.dx / u.dt) / u.dt * sand.dt
        sand.grid_mv[...] = sand.grid_mv + sim.backend.asarray(impulse.astype(np.float32))
        return exchange(*args, **kw)

    c.exchange = exchange_with_pressure


def run_case(radius_cells: float, xi: float, t_end: float, backend: str, f: dict | None = None) -> dict:
    f = {**DEFAULTS, **(f or {})}
    d = scene(radius_cells, xi, t_end, f)
    sim = Simulation(Scene.from_dict(d), backend=backend, log=None)
    if f["drag_coefficient"] is not None:  # not a scene key: the coupling constants' c of §4.3
        ops = sim.coupler.ops
        ops.params = dataclasses.replace(ops.params, drag_coefficient=f["drag_coefficient"])
        sim.coupler.params = ops.params
    if f["pressure_buoyancy"]:
        use_pressure_buoyancy(sim, capillary=f["pressure_buoyancy"] >= 2)
    steps_per_frame = int(round(0.05 / DT))
    frames = d["time"]["frames"]
    centres, tops, bottoms, phi_ball, phi_far, pore_uz, sand_vz = [], [], [], [], [], [], []
    centre0 = float(sim.particles()["x"][2].mean() / DX)
    t0 = time.perf_counter()
    for _ in range(frames):
        sim.step(steps_per_frame)
        z = sim.particles()["x"][2] / DX
        centres.append(float(z.mean()))
        tops.append(float(z.max()))
        bottoms.append(float(z.min()))
        a, b, c = ball_water(sim)
        phi_ball.append(a)
        phi_far.append(b)
        pore_uz.append(c)
        sand_vz.append(float(sim.particles()["v"][2].mean()))
    tail = max(1, frames // 2)
    surface = f["depth"] / DX
    t = archimedes_cap_ratio(GRAIN_DENSITY / 1000.0)
    expected = surface + (1.0 - t) * radius_cells
    centre = float(np.mean(centres[-tail:]))
    return {
        "radius_cells": radius_cells,
        "interface_width": xi,
        "factors": {k: f[k] for k in DEFAULTS},
        "changed": {k: f[k] for k in DEFAULTS if f[k] != DEFAULTS[k]},
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
        "phi_ball_history": phi_ball,
        "phi_far_history": phi_far,
        "pore_fluid_uz_history": pore_uz,
        "sand_vz_history": sand_vz,
        "highest_centre_above_release_cells": float(max(centres) - centre0),
        "phi_ball_tail": float(np.mean(phi_ball[-tail:])),
        "phi_far_tail": float(np.mean(phi_far[-tail:])),
        "wall_s": time.perf_counter() - t0,
    }


def run_small_variant(xi: float, backend: str, f: dict | None = None, frames: int | None = None) -> dict:
    """examples/fig08_sand_densities_small.toml at interface width ``xi`` (and the fluid factors odd_lambda,
    smagorinsky of ``f`` where set): each ball's centre height per frame (the balls told apart by their
    release x), the max lattice speed, the water volume drift."""
    import tomllib

    f = {**DEFAULTS, **(f or {})}
    path = ROOT / "examples" / "fig08_sand_densities_small.toml"
    d = tomllib.loads(path.read_text())
    d["fluid"]["interface_width"] = xi
    for key in ("odd_lambda", "smagorinsky", "odd_ramp"):
        if f[key] is not None:
            d["fluid"][key] = f[key]
    d["outputs"] = {"preview": False}
    frames = int(frames or d["time"]["frames"])
    sim = Simulation(Scene.from_dict(d, base_dir=path.parent), backend=backend, log=None)
    balls = [b for b in d["bodies"] if b["kind"] == "sand"]
    x0 = sim.particles()["x"][0]
    centres_x = np.array([b["geometry"]["center"][0] for b in balls])
    which = np.argmin(np.abs(x0[:, None] - centres_x[None, :]), axis=1)
    steps = int(round(d["time"]["frame_duration"] / d["time"]["dt"]))
    hist = {b["name"]: [] for b in balls}
    speed, drift, where = [], [], []
    t0 = time.perf_counter()
    for _ in range(frames):
        sim.step(steps)
        z = sim.particles()["x"][2]
        for k, b in enumerate(balls):
            hist[b["name"]].append(float(z[which == k].mean()))
        diag = sim.diagnostics()
        speed.append(float(diag["max_lattice_speed"]))
        fl = sim.fields(lattice=True)
        mag = np.sqrt((fl["velocity"] ** 2).sum(axis=0))
        k, j, i = (int(v) for v in np.unravel_index(int(np.argmax(mag)), mag.shape))
        n = mag.shape
        where.append({"cell": [i, j, k], "to_wall": min(i, j, k, n[2] - 1 - i, n[1] - 1 - j, n[0] - 1 - k),
                      "phi": float(fl["phi"][k, j, i]), "sand_fraction": float(fl["sand_fraction"][k, j, i])})  # fmt: skip
        drift.append(float(diag.get("fluid_volume_drift", float("nan"))))
    surface = balls and d["bodies"][0]["geometry"]["max"][2]
    return {
        "case": "small_variant",
        "interface_width": xi,
        "changed": {k: f[k] for k in ("odd_lambda", "smagorinsky", "odd_ramp") if f[k] is not None},
        "time_s": frames * d["time"]["frame_duration"],
        "surface_m": surface,
        "centre_history_m": hist,
        "max_lattice_speed_history": speed,
        "fluid_volume_drift_history": drift,
        "max_speed_at_history": where,  # the largest speed's cell (x, y, z index), cells to the nearest wall
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
    ap.add_argument("--radii", type=positive_float(), nargs="+", default=[1.74, 2.0, 2.4, 3.0])
    ap.add_argument("--widths", type=positive_float(), nargs="+", default=[4.0])
    ap.add_argument(
        "--also",
        nargs="*",
        type=radius_and_width,
        default=[(1.74, 8.0)],
        help="extra R:XI cases (default the small variant's 1.74:8)",
    )
    ap.add_argument(
        "--time",
        type=positive_float(),
        default=3.0,
        help="simulated seconds (default 3: at 1 s, the small variant's end, the balls still bob)",
    )
    ap.add_argument(
        "--set",
        nargs="*",
        type=factors,
        default=[],
        metavar="KEY=VALUE",
        help=f"change one factor for every case (one experiment), keys: {', '.join(DEFAULTS)}",
    )
    ap.add_argument(
        "--replace", action="store_true", help="overwrite the results file (default: add to it, same case replaced)"
    )
    ap.add_argument("--backend", choices=("cpu", "numpy", "cuda", "cpu-device"), default="cpu")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "fig08_interface_width.json"))
    ap.add_argument(
        "--small-variant",
        action="store_true",
        help="run examples/fig08_sand_densities_small.toml at each --widths (with --set odd_lambda/smagorinsky/odd_ramp) "
        "instead of the one-ball cases",
    )
    a = ap.parse_args()
    f = dict(a.set)
    results = []
    if a.small_variant:
        for xi in a.widths:
            res = run_small_variant(xi, a.backend, f, frames=max(1, int(round(a.time / 0.05))))
            results.append(res)
            print(f"small variant xi {xi:g} {res['changed']}: max lattice speed {max(res['max_lattice_speed_history']):.3f}, "
                  f"volume drift {res['fluid_volume_drift_history'][-1]:+.2e}, {res['wall_s']:.0f} s", flush=True)  # fmt: skip
            print("    largest speed every 0.25 s at (cell, cells to a wall, phi):", " ".join(
                f"{w['cell']}/{w['to_wall']}/{w['phi']:.2f}" for w in res["max_speed_at_history"][4::5]), flush=True)  # fmt: skip
            for name, h in res["centre_history_m"].items():
                print(f"    {name}: centre every 0.25 s (m) " + " ".join(f"{z:.3f}" for z in h[4::5]), flush=True)
        a.radii, a.also = [], []
    print("r (cells)  xi   centre - Archimedes (cells)  (radii)   lowest bottom  surface   wall s")
    cases = [(r, xi) for r in a.radii for xi in a.widths]
    cases += list(a.also)
    for r, xi in cases:
        res = run_case(r, xi, a.time, a.backend, f)
        results.append(res)
        print(f"{r:8.2f} {xi:4.0f} {res['error_cells']:+14.2f} {res['error_radii']:+18.2f} "
                  f"{res['lowest_bottom_cells']:12.2f} {res['surface_cells']:9.1f} {res['wall_s']:8.0f}  {res['changed']}", flush=True)  # fmt: skip
        print(f"    phi at the ball {res['phi_ball_tail']:.3f}, far-field phi at its cells {res['phi_far_tail']:.3f}"
              " (second half)", flush=True)  # fmt: skip
        print(f"    highest centre above its release height {res['highest_centre_above_release_cells']:+.2f} cells",
              flush=True)  # fmt: skip
        print("    centre - Archimedes every 0.25 s:", " ".join(f"{c - res['archimedes_centre_cells']:+.2f}"
              for c in res["centre_history_cells"][4::5]), flush=True)  # fmt: skip
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)

    def key(r: dict) -> tuple:
        return (r.get("case", "ball"), r.get("radius_cells"), r["interface_width"], r["time_s"], json.dumps(r.get("changed", {})))  # fmt: skip

    new = {key(r) for r in results}
    old = [] if a.replace or not out.exists() else json.loads(out.read_text())["runs"]
    runs = [r for r in old if key(r) not in new] + results
    out.write_text(json.dumps({"command": "python benchmarks/fig08_interface_width.py", "runs": runs}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
