"""Wetting front through dry sand with and without water retention (paper 000 Fig. 10, issue 5), written to
benchmarks/results/wetting_front.json.

    python benchmarks/wetting_front.py [--scene partition|plug] [--shape nz,ny,nx] [--steps N] [--every N]
                                       [--ra 0.01 0.001] [--nu 1e-3] [--eta 2] [--jobs 2] [--out ...]

``--scene partition`` (default; the paper's geometry, where the displaced air can leave):
couplekit.coupling.scenes.bed_under_partition — a dry bed (ε = 0.55, 1500 kg/m³, no cohesion) on the
floor, a partition wall over it from x = 0.2 nx to 0.8 nx, from the bed up to 0.8 nz, water on the left up
to 0.75 nz, air above and on the right (the air displaced from the pores rises on the right and returns
over the wall).  Front: x (cells right of the wall's left face) where the mean φ over the bed's layers
(z = 1 … bed − 1) and the fluid rows first drops below 0.5; ``arrival_steps``: the step at which it first
reaches 2, 4, 6, … cells.  ν_h = 1e-3 (closed tank; see below).  Measured (20 × 8 × 48: bed 5 cells, wall
x = 10–38, top 16, water 15; 8000 steps; one thread, one run at a time, 21–26 s each, while other benchmarks
shared the machine; results/wetting_front.json), front (cells under the wall) at steps 2000 / 4000 / 8000 and
arrival at 4 / 6:

    η = 2, no retention      2.74   5.87  10.17   2740 / 4106   max |u| 0.012, water drift +9.6e-4
    η = 2, R_a = 0.001       2.04   4.44   7.91   3590 / 5617   max |u| 0.012, drift +9.6e-4
    η = 2, R_a = 0.01        1.53   4.17   7.74   3843 / 5852   max |u| 0.015, drift +9.6e-4
    η = 0, no retention      2.76   5.90  10.28   2726 / 4080   drift +2.4 %
    η = 0, R_a = 0.01        1.54   4.18   7.68   3832 / 5883   drift +3.8 %
    η = 0, R_a = 0.001       2.07   4.42   7.83   3601 / 5675   drift +3.8 %

With retention the front reaches 6 cells 1.37× (R_a = 0.001) to 1.43× (0.01) later and is 22–24 % behind at
step 8000.  Water (free + bound) is conserved to 1e-3 with the controller in every run.  Before session 3's
fixes of Eq. 39's slip term the η = 2, R_a = 0.01 run created 2.7 % water: the controller's lever
Σ ε̃ S_φ dropped to ~1e-5 cell volumes (absorption and the transport part cancel) while V0 − V was ~0.3, so
γ saturated with a sign that flipped each step.  It no longer does (re-measured in session 4, this table);
tests/coupling/test_retention_controller.py runs it for 3000 steps, and the CI version of the front
(tests/coupling/test_retention_front_partition.py, 16 × 6 × 28, bed 5) tests the delay.

``--scene plug`` (the former closed-tank measurement): couplekit.coupling.scenes.dry_plug_under_water — a dry plug (ε = 0.55, 1500 kg/m³, no cohesion)
filling the cross-section from cell 1 to ``plug_top`` with air in its pores, a water layer above it, air
above the water, closed tank.  One run without retention and one per absorption rate R_a.

Measured every ``every`` steps (interior columns only: the wall-adjacent columns hold only the B-spline
tail of the sand, ε ≈ 0.09, and are a bypass channel):

* ``front_depth[level]``: depth below the plug top (cells) where the horizontal mean of the pores' free
  water fraction φ first drops below ``level`` going down (linear interpolation; 0 = not below the top);
* ``free_water_in_plug`` Σ ε̃ φ and ``bound_water`` Σ R over the plug cells (cell volumes);
* ``max_lattice_speed``, ``fluid_volume_drift``, ``finite`` (a run stops at its first non-finite state and
  records the step).

Water viscosity ν_h = 1e-3 (lattice) by default: at the paper's 1e-4 the closed-tank fluid core is not
stable on its own (tests/coupling/test_coupled_validation.py).  Volume controller off (η = 0) by default
(the plug measurement below predates session 3's fixes).

Measured (32 × 12 × 12, 3000 steps, 1 thread; results/wetting_front.json): with η = 0 all three runs stay
finite, but the front is not monotonic in any of them (water and the pores' air exchange places: the
air can only leave by bubbling up through the water of this closed tank) and the max lattice speed
reaches 0.09 without retention, 0.20 with R_a = 0.01 and 0.11 with 0.001; the plug's free water is lower
with retention at every 100-step sample except step 400 (at step 1000: 136 (R_a = 0.01) and 188 (0.001)
vs 202 cell volumes, with 59 and 14 bound).  With η = 2
the retention runs go NaN at step ~1500 (R_a = 0.01) and ~2200 (0.001); without retention it runs.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
from _args import float_in, int_in, one_line, positive_float, shape3

from couplekit.backend import get_backend
from couplekit.coupling.scenes import bed_under_partition, dry_plug_under_water

LEVELS = (0.5, 0.2, 0.1)


def plug_profile(scene, plug_top: float) -> tuple[np.ndarray, float, float]:
    """(horizontal mean of φ per z over interior columns, free water Σ ε̃ φ and bound water Σ R in the plug)."""
    be = scene.fluid.backend
    phi = be.to_host(scene.fluid.phi)[1:-1, 1:-1, 1:-1].astype(np.float64)
    eps = be.to_host(scene.fluid.fluid_fraction)[1:-1, 1:-1, 1:-1].astype(np.float64)
    nz = phi.shape[0]
    inside = (np.arange(nz) + 0.5) < plug_top
    profile = phi[:, 1:-1, 1:-1].mean(axis=(1, 2))
    free = float((eps * np.clip(phi, 0.0, 1.0))[inside].sum())
    bound = 0.0
    if scene.coupler.retention:
        bound = float(be.to_host(scene.coupler.bound).astype(np.float64)[inside].sum())
    return profile, free, bound


def front_depth(profile: np.ndarray, plug_top: float, level: float) -> float:
    """Depth (cells) below ``plug_top`` of the first crossing of ``level`` going down from the top cell."""
    z = np.arange(profile.size) + 0.5
    k = int(np.floor(plug_top - 0.5))  # the plug's top cell
    if profile[k] < level:
        return 0.0
    while k >= 0 and profile[k] >= level:
        k -= 1
    if k < 0:
        return float(plug_top)
    crossing = z[k] + (level - profile[k]) / (profile[k + 1] - profile[k])
    return float(plug_top - crossing)


def plug_scene(be, shape, ra: float, nu: float, plug_top: float, water_top: float, eta: float):
    """The dry_plug_under_water scene of one plug run."""
    return dry_plug_under_water(be, shape, retention=ra > 0, absorption_rate=max(ra, 0.0), plug=(1.0, plug_top),
                                water=(plug_top, water_top), nu_h=nu, youngs_modulus=1e5, eta=eta,
                                sand_params={"cohesion_max": 0.0})  # fmt: skip


def plug_levels(shape) -> tuple[int, int]:
    """The plug's top and the water's top (cells) for a grid ``shape``."""
    nz = shape[0]
    return round(nz / 2), round(nz / 2) + round(nz / 3)


def run_case(
    be, shape, steps: int, every: int, ra: float, nu: float, plug_top: float, water_top: float, eta: float = 0.0
) -> dict:
    """One plug run; ``ra`` = 0: retention off; ``eta``: volume controller strength (0 = off)."""
    sc = plug_scene(be, shape, ra, nu, plug_top, water_top, eta)
    rec: dict = {"absorption_rate": ra, "retention": ra > 0, "steps": [], "max_lattice_speed": [],
                 "fluid_volume_drift": [], "free_water_in_plug": [], "bound_water": [],
                 "front_depth": {str(v): [] for v in LEVELS}}  # fmt: skip

    def sample(s: int) -> None:
        profile, free, bound = plug_profile(sc, plug_top)
        rec["steps"].append(s)
        rec["max_lattice_speed"].append(sc.max_lattice_speed())
        rec["fluid_volume_drift"].append(sc.fluid_volume_drift())
        rec["free_water_in_plug"].append(free)
        rec["bound_water"].append(bound)
        for v in LEVELS:
            rec["front_depth"][str(v)].append(front_depth(profile, plug_top, v))

    return _sampled_run(sc, steps, every, rec, sample)


def _sampled_run(sc, steps: int, every: int, rec: dict, sample) -> dict:
    """Step ``sc`` in chunks of ``every`` up to ``steps``, calling ``sample(step)`` after each chunk, and stop at
    the first non-finite value; adds ``finite``, ``first_non_finite_by_step`` and ``seconds`` to ``rec``."""
    t0 = time.perf_counter()
    finite = True
    for s in range(every, steps + 1, every):
        sc.step(every)
        if not sc.finite():
            finite = False
            rec["first_non_finite_by_step"] = s
            break
        sample(s)
    rec["finite"] = finite
    rec["seconds"] = time.perf_counter() - t0
    return rec


def partition_front(phi: np.ndarray, bed: int, wall_x: float, level: float = 0.5) -> float:
    """x (cells right of ``wall_x``) where the mean φ over the bed layers z = 1 … bed − 1 and the fluid rows
    (y = 1 … ny − 2) first drops below ``level`` going right from the wall's left face."""
    prof = phi[1:bed, 1:-1].astype(np.float64).mean(axis=(0, 1))
    xc = np.arange(prof.size) + 0.5
    k = int(np.floor(wall_x - 0.5))
    while k + 1 < prof.size and prof[k + 1] >= level:
        k += 1
    if k + 1 >= prof.size:
        return float(prof.size) - wall_x
    return float(xc[k] + (prof[k] - level) / (prof[k] - prof[k + 1]) - wall_x)


def partition_geometry(shape) -> dict:
    """bed_under_partition's geometry for a grid ``shape`` (cells)."""
    nz, ny, nx = shape
    return {"bed": round(0.25 * nz), "partition": (round(0.2 * nx), round(0.8 * nx)),
            "partition_top": round(0.8 * nz), "water_top": round(0.75 * nz)}  # fmt: skip


def partition_scene(be, shape, ra: float, nu: float, eta: float):
    """The bed_under_partition scene of one partition run."""
    geo = partition_geometry(shape)
    return bed_under_partition(be, shape, retention=ra > 0, absorption_rate=max(ra, 0.0), nu_h=nu, eta=eta,
                               youngs_modulus=1e5, sand_params={"cohesion_max": 0.0}, bed=float(geo["bed"]),
                               partition=tuple(float(v) for v in geo["partition"]),
                               partition_top=float(geo["partition_top"]), water_top=float(geo["water_top"]))  # fmt: skip


def run_partition(shape, steps: int, every: int, ra: float, nu: float, eta: float, threads: int | None) -> dict:
    """One bed_under_partition run; ``ra`` = 0: retention off."""
    be = get_backend("cpu", threads=threads)
    geo = partition_geometry(shape)
    sc = partition_scene(be, shape, ra, nu, eta)
    sc.step(1)
    w0 = sc.water_volume()
    rec: dict = {"absorption_rate": ra, "retention": ra > 0, "steps": [], "front": [], "max_lattice_speed": [],
                 "water_drift": [], "bound_water": []}  # fmt: skip

    def sample(s: int) -> None:
        phi = be.to_host(sc.fluid.phi)[1:-1, 1:-1, 1:-1]
        rec["steps"].append(s)
        rec["front"].append(partition_front(phi, geo["bed"], float(geo["partition"][0])))
        rec["max_lattice_speed"].append(sc.max_lattice_speed())
        rec["water_drift"].append(sc.water_volume() / w0 - 1)
        rec["bound_water"].append(float(sc.coupler.bound.sum(dtype=np.float64)) if ra > 0 else 0.0)

    _sampled_run(sc, steps, every, rec, sample)
    rec["arrival_steps"] = {}
    for depth in range(2, int(geo["partition"][1] - geo["partition"][0]) + 1, 2):
        fr, st = rec["front"], rec["steps"]
        hit = next((i for i in range(1, len(fr)) if fr[i - 1] < depth <= fr[i]), None)
        if hit is not None:
            f0, f1 = fr[hit - 1], fr[hit]
            rec["arrival_steps"][str(depth)] = st[hit - 1] + (depth - f0) / (f1 - f0) * (st[hit] - st[hit - 1])
    return rec


def main_partition(a) -> None:
    """The partition scene: one run without retention and one per R_a, ``--jobs`` at a time."""
    from concurrent.futures import ProcessPoolExecutor

    shape = a.shape
    etas = [2.0, 0.0] if a.eta is None else a.eta
    runs = [(eta, ra) for eta in etas for ra in (0.0, *a.ra)]
    with ProcessPoolExecutor(max_workers=a.jobs) as pool:
        futures = [pool.submit(run_partition, shape, a.steps, a.every, ra, a.nu, eta, 1) for eta, ra in runs]
        recs = [f.result() for f in futures]
    cases = {f"eta_{eta:g}/" + ("no_retention" if ra == 0 else f"retention_Ra_{ra:g}"): r
             for (eta, ra), r in zip(runs, recs, strict=True)}  # fmt: skip
    geo = partition_geometry(shape)
    result = {"scene": "bed_under_partition", "shape_nz_ny_nx": list(shape), **geo, "nu_h_lattice": a.nu,
              "etas": etas, "front_level": 0.5, "cases": cases,
              "machine": {"platform": platform.platform(), "threads_per_run": 1, "jobs": a.jobs}}  # fmt: skip
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(result, indent=1))
    first, stride = 999 // a.every, max(1, 1000 // a.every)  # the samples about every 1000 steps
    for name, rec in cases.items():
        if not rec["steps"]:  # not finite from its first chunk
            print(f"{name}: finite {rec['finite']}, no samples, {rec['seconds']:.0f} s")
            continue
        print(f"{name}: finite {rec['finite']}, front at steps {rec['steps'][first::stride]}: "
              f"{np.round(rec['front'][first::stride], 2).tolist()}, arrival {rec['arrival_steps']}, "
              f"max speed {max(rec['max_lattice_speed']):.3g}, drift {rec['water_drift'][-1]:.1e}, "
              f"{rec['seconds']:.0f} s")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(
        description="Wetting front through dry sand with and without water retention (paper 000 Fig. 10, "
        "issue 5), written to benchmarks/results/wetting_front.json."
    )
    ap.add_argument("--scene", choices=["partition", "plug"], default="partition")
    ap.add_argument("--shape", type=shape3(5), default=None, help="nz,ny,nx cells (partition 20,8,48; plug 32,12,12)")
    ap.add_argument("--steps", type=int_in(1), default=None, help="partition 8000, plug 3000")
    ap.add_argument(
        "--every", type=int_in(1), default=None, help="sampling interval, <= --steps (partition 250, plug 100)"
    )
    ap.add_argument("--jobs", type=int_in(1), default=2, help="partition: runs at a time (one thread each)")
    ap.add_argument("--ra", type=positive_float(), nargs="+", default=[0.01, 0.001],
                    help="absorption rates R_a (retention on)")  # fmt: skip
    ap.add_argument("--nu", type=positive_float(), default=1e-3, help="water lattice viscosity nu_h")
    ap.add_argument("--eta", type=float_in(0.0), nargs="+", default=None,
                    help="volume controller strength(s) (partition: 2 and 0; plug: 0 = off, the first value)")  # fmt: skip
    ap.add_argument("--threads", type=int_in(1), default=None)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "wetting_front.json"))
    a = ap.parse_args()
    partition = a.scene == "partition"
    a.steps = a.steps or (8000 if partition else 3000)
    a.every = a.every or (250 if partition else 100)
    if a.every > a.steps:
        ap.error(f"argument --every: must be <= --steps ({a.steps}), got {a.every}")
    a.shape = a.shape or ((20, 8, 48) if partition else (32, 12, 12))
    check = get_backend("numpy")
    try:  # the scenes build at this shape (cheap), before any run is made or written
        for ra in (0.0, *a.ra):
            if partition:
                partition_scene(check, a.shape, ra, a.nu, 2.0)
            else:
                plug_scene(check, a.shape, ra, a.nu, *plug_levels(a.shape), 0.0)
    except ValueError as exc:
        ap.error(f"the {a.scene} scene does not build at --shape {','.join(map(str, a.shape))}: {one_line(exc)}")
    if partition:
        main_partition(a)
        return
    a.eta = 0.0 if a.eta is None else a.eta[0]
    shape = a.shape
    plug_top, water_top = plug_levels(shape)
    be = get_backend("cpu", threads=a.threads)
    cases = {"no_retention": run_case(be, shape, a.steps, a.every, 0.0, a.nu, plug_top, water_top, a.eta)}
    for ra in a.ra:
        cases[f"retention_Ra_{ra:g}"] = run_case(be, shape, a.steps, a.every, ra, a.nu, plug_top, water_top, a.eta)
    result = {
        "scene": "dry_plug_under_water",
        "shape_nz_ny_nx": list(shape),
        "plug_cells": [1.0, plug_top],
        "water_cells": [plug_top, water_top],
        "nu_h_lattice": a.nu,
        "eta": a.eta,
        "front_levels": list(LEVELS),
        "cases": cases,
        "machine": {"platform": platform.platform(), "threads": be.threads if hasattr(be, "threads") else None},
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(result, indent=1))
    for name, rec in cases.items():
        last = {k: v[-1] if v else None for k, v in rec["front_depth"].items()}
        print(f"{name}: finite {rec['finite']} ({rec.get('first_non_finite_by_step', rec['steps'][-1] if rec['steps'] else 0)} steps), "
              f"front depth {last}, free {rec['free_water_in_plug'][-1] if rec['steps'] else None}, "
              f"bound {rec['bound_water'][-1] if rec['steps'] else None}, {rec['seconds']:.0f} s")  # fmt: skip


if __name__ == "__main__":
    main()
