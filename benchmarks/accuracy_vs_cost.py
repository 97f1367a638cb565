"""What accuracy costs in time: lockstep (paper Algorithm 1) against sub-cycled and multi-rate coupling, on three
scenes, each against a fine lockstep reference.

    python benchmarks/accuracy_vs_cost.py                      # run the sweeps (resumable), analyse, plot
    python benchmarks/accuracy_vs_cost.py --analyse-only       # analyse sweeps already run
    python benchmarks/accuracy_vs_cost.py --scenes ball_into_water --workers 2

Scenes (benchmarks/scenes/*.toml, 3–6 k cells, viscosities in SI so that a larger fluid step changes the
lattice viscosity and Mach number, not the fluid): a sand layer settling through water, a sand ball dropped into
a pool (paper Figs. 13/14, small), a sand column collapsing into water (paper Fig. 15, small). The sweeps
(benchmarks/sweeps/<scene>.toml, run by :func:`couplekit.sweep.run_sweep` on a Dask LocalCluster): lockstep at
Δt = 3.125e-5 … 1.25e-4 s (the sand's elastic limit is 1.40e-4 s), sub-cycling with the fluid held or linear at
Δt = 1.25e-4 … 1e-3 s and k = 1 … 16 (every integer), "auto", the multi-rate converse, and, in
<scene>_resolution.toml, dx = 5 and 2.5 mm. Points the scene checker refuses (a substep past the MPM limit, a
fluid step past the Mach or compressibility limit) are recorded as refused: that is where each scheme's Δt is
bound.

Analysis, per scene:

* error of each run against the reference (couplekit.sweep.metrics: sand centroid path, runout, pile height,
  fluid volume, free-surface height, kinetic energy) against its wall time (one machine state: every point of a
  sweep runs on the same LocalCluster, one thread per worker);
* the Pareto front of each scheme (no other point of the scheme is both faster and more accurate);
* ``speedup_at_equal_error``: for the lockstep run at its largest admissible Δt (what a user runs) the error e_L
  of the scene's primary metric and its wall time t_L; the fastest multi-rate run (any non-lockstep scheme) with
  error ≤ e_L, t_M; speed-up t_L / t_M. Also the best such ratio over lockstep's Pareto front
  (``best_speedup_at_equal_error``), and ``speedup_every_metric``: the fastest multi-rate run at most as wrong as
  the production lockstep run in every metric; ``speedup_within_1.5x_error`` / ``_2x_``: the fastest multi-rate
  run within 1.5 / 2 times that error (what a looser error buys). Sub-cycling with k = 1 and multi-rate with
  m = 1 are lockstep itself and never count as multi-rate runs;
* the stability map: per scheme and (k, Δt) whether the run stayed stable (finite, max lattice speed ≤ 0.3),
  went unstable, or was refused by validation (and by which limit).

Writes benchmarks/results/accuracy_vs_cost.json, accuracy_vs_cost_<scene>.png (work-precision, one panel per
metric, Pareto fronts drawn) and accuracy_vs_cost_stability.png, and the sweeps into runs/accuracy_vs_cost/;
with ``--out DIR`` all of them (sweep folders, JSON, PNGs) go into DIR.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path

from _args import int_in

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
SWEEPS = ROOT / "benchmarks" / "sweeps"

SCENES = {
    "settling_suspension": "error_centroid_path",
    "ball_into_water": "error_centroid_path",
    "column_into_water": "error_sand_front",
}
"""Scene → its primary error metric (the behaviour the scene is about: where the sand goes, how far it runs)."""

METRICS = {
    "error_centroid_path": ("sand centroid path", "m"),
    "error_sand_front": ("sand runout", "m"),
    "error_sand_top": ("pile height", "m"),
    "error_fluid_volume": ("fluid volume", "relative"),
    "error_free_surface": ("free-surface height", "m"),
    "error_kinetic_energy": ("kinetic energy", "relative"),
}
SCHEMES = ("lockstep", "subcycle-hold", "subcycle-linear", "subcycle-auto", "multirate")
STYLE = {
    "lockstep": ("k", "s"),
    "subcycle-hold": ("tab:blue", "o"),
    "subcycle-linear": ("tab:orange", "^"),
    "subcycle-auto": ("tab:green", "D"),
    "multirate": ("tab:purple", "v"),
}


def _f(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def _stable(row: dict) -> bool:
    return row.get("status") == "done" and not bool(row.get("unstable"))


def _refusal(row: dict) -> str:
    """Which limit refused an invalid point, in a few words."""
    text = str(row.get("error") or "")
    for needle, why in (
        ("elastic limit", "MPM elastic limit"),
        ("particle CFL", "MPM particle CFL"),
        ("Mach", "lattice Mach number"),
        ("compresses the fluid", "weak compressibility"),
        ("capillary", "capillary time step"),
        ("lattice viscosity", "relaxation time"),
    ):
        if needle in text:
            return why
    return text.splitlines()[-1][:80] if text else "refused"


def _multi_rate(row: dict) -> bool:
    """A run whose sand takes other steps than its fluid: sub-cycling with k = 1 and multi-rate with m = 1 are
    lockstep itself (bitwise, tests/test_subcycle.py), so beating lockstep with them would measure timing noise."""
    if row["case"] in ("lockstep", "reference"):
        return False
    return not math.isclose(_f(row.get("sand_steps_per_step")), 1.0)


def pareto(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The (time, error) points no other point beats in both, sorted by time."""
    front, best = [], math.inf
    for t, e in sorted(p for p in points if math.isfinite(p[0]) and math.isfinite(p[1])):
        if e < best:
            front.append((t, e))
            best = e
    return front


def speedups(rows: list[dict], metric: str) -> dict:
    """Speed-up at equal error over lockstep (module docstring)."""
    lock = [r for r in rows if r["case"] == "lockstep" and _stable(r) and math.isfinite(_f(r.get(metric)))]
    multi = [r for r in rows if _multi_rate(r) and _stable(r) and math.isfinite(_f(r.get(metric)))]
    if not lock or not multi:
        return {"note": "no stable lockstep or multi-rate point"}

    def best_at(err: float) -> dict | None:
        ok = [r for r in multi if _f(r[metric]) <= err]
        return min(ok, key=lambda r: _f(r["wall_s"])) if ok else None

    production = max(lock, key=lambda r: _f(r["time.dt"]))
    out = {"metric": metric}
    entries = []
    for L in sorted(lock, key=lambda r: _f(r["time.dt"])):
        M = best_at(_f(L[metric]))
        entry = {
            "lockstep_dt": _f(L["time.dt"]),
            "lockstep_error": _f(L[metric]),
            "lockstep_wall_s": _f(L["wall_s"]),
        }
        if M is None:
            closest = min(multi, key=lambda r: _f(r[metric]))
            entry.update(
                speedup=None,
                best_multirate=closest["name"],
                best_multirate_error=_f(closest[metric]),
                best_multirate_wall_s=_f(closest["wall_s"]),
                missed_by=_f(closest[metric]) / _f(L[metric]),
            )
        else:
            entry.update(
                speedup=_f(L["wall_s"]) / _f(M["wall_s"]),
                multirate=M["name"],
                multirate_error=_f(M[metric]),
                multirate_wall_s=_f(M["wall_s"]),
            )
        entries.append(entry)
        if L is production:
            out["at_production_lockstep"] = entry
    out["per_lockstep_point"] = entries
    # what a looser error buys: the fastest multi-rate run within 1.5x and 2x the production lockstep error
    e_prod, t_prod = _f(production[metric]), _f(production["wall_s"])
    for factor in (1.5, 2.0):
        M = best_at(factor * e_prod)
        out[f"speedup_within_{factor:g}x_error"] = (
            None if M is None else {"speedup": t_prod / _f(M["wall_s"]), "run": M["name"],
                                    "error_ratio": _f(M[metric]) / e_prod if e_prod > 0 else math.nan}
        )  # fmt: skip
    # the best ratio over lockstep's Pareto front only: a lockstep point that a faster lockstep point beats in
    # error too (errors need not fall with Δt) would flatter the multi-rate schemes
    front = {(t, e) for t, e in pareto([(_f(L["wall_s"]), _f(L[metric])) for L in lock])}
    on_front = [e for e in entries if (e["lockstep_wall_s"], e["lockstep_error"]) in front]
    found = [e["speedup"] for e in on_front if e.get("speedup") is not None]
    out["speedup_at_equal_error"] = out["at_production_lockstep"].get("speedup")
    out["best_speedup_at_equal_error"] = max(found) if found else None
    return out


def speedup_every_metric(rows: list[dict]) -> dict:
    """The stricter reading: the fastest multi-rate run whose error is at most the production lockstep run's in
    every metric both have (finite), and its speed-up."""
    lock = [r for r in rows if r["case"] == "lockstep" and _stable(r)]
    if not lock:
        return {"note": "no stable lockstep point"}
    L = max(lock, key=lambda r: _f(r["time.dt"]))
    metrics = [m for m in METRICS if math.isfinite(_f(L.get(m)))]
    ok = [
        r
        for r in rows
        if _multi_rate(r) and _stable(r)
        and all(_f(r.get(m)) <= _f(L[m]) for m in metrics)
    ]  # fmt: skip
    if not ok:
        return {
            "metrics": metrics,
            "lockstep": L["name"],
            "speedup": None,
            "note": "no multi-rate run is as accurate in every metric",
        }
    M = min(ok, key=lambda r: _f(r["wall_s"]))
    return {
        "metrics": metrics,
        "lockstep": L["name"],
        "multirate": M["name"],
        "speedup": _f(L["wall_s"]) / _f(M["wall_s"]),
    }


def stability_map(rows: list[dict]) -> list[dict]:
    out = []
    for r in rows:
        if r["case"] in ("reference",):
            continue
        if r.get("status") == "invalid":
            state, why = "refused", _refusal(r)
        elif _stable(r):
            state, why = "stable", ""
        else:
            state = "unstable"
            why = (
                "diverged"
                if r.get("status") == "diverged"
                else f"max lattice speed {_f(r.get('max_lattice_speed')):.3g}"
            )
        out.append(
            {
                "scheme": r["case"],
                "dx": _f(r.get("domain.dx")),
                "dt": _f(r.get("time.dt")),
                "k": r.get("scheduler.substeps"),
                "m": r.get("scheduler.sand_every"),
                "state": state,
                "why": why,
            }
        )
    return out


def analyse(scene: str, rows: list[dict], resolution_rows: list[dict] | None) -> dict:
    metric = SCENES[scene]
    ref = next((r for r in rows if r["case"] == "reference"), None)
    schemes = {}
    for s in SCHEMES:
        mine = [r for r in rows if r["case"] == s]
        stable = [r for r in mine if _stable(r)]
        schemes[s] = {
            "points": len(mine),
            "stable": len(stable),
            "unstable": sum(1 for r in mine if r.get("status") not in ("invalid",) and not _stable(r)),
            "refused": sum(1 for r in mine if r.get("status") == "invalid"),
            "pareto": {
                m: [{"wall_s": t, "error": e} for t, e in pareto([(_f(r["wall_s"]), _f(r.get(m))) for r in stable])]
                for m in METRICS
            },
        }
    result = {
        "primary_metric": metric,
        "reference": {
            "dt": _f(ref.get("time.dt")) if ref else None,
            "wall_s": _f(ref.get("wall_s")) if ref else None,
            "steps": ref.get("steps") if ref else None,
            "status": ref.get("status") if ref else None,
        },
        "schemes": schemes,
        "speedups": {m: speedups(rows, m) for m in METRICS},
        "stability_map": stability_map(rows),
        "points": [
            {
                k: (r.get(k) if not isinstance(r.get(k), float) or math.isfinite(r.get(k)) else None)
                for k in (
                    "name",
                    "case",
                    "status",
                    "time.dt",
                    "scheduler.substeps",
                    "scheduler.sand_every",
                    "wall_s",
                    "steps",
                    "sand_steps_per_step",
                    "max_lattice_speed",
                    *METRICS,
                )  # fmt: skip
            }
            for r in rows
        ],
    }
    result["speedup_every_metric"] = speedup_every_metric(rows)
    result["speedup_at_equal_error"] = result["speedups"][metric].get("speedup_at_equal_error")
    result["best_speedup_at_equal_error"] = result["speedups"][metric].get("best_speedup_at_equal_error")
    limits = sorted({_refusal(r) for r in rows if r.get("status") == "invalid" and r["case"] != "lockstep"})
    result["fluid_step_bound_by"] = [w for w in limits if w not in ("MPM elastic limit", "MPM particle CFL")]
    if resolution_rows is not None:
        result["resolution"] = {
            "speedups": {m: speedups(resolution_rows, m) for m in (metric,)},
            "points": [
                {
                    k: (r.get(k) if not isinstance(r.get(k), float) or math.isfinite(r.get(k)) else None)
                    for k in (
                        "name",
                        "case",
                        "status",
                        "domain.dx",
                        "time.dt",
                        "scheduler.substeps",
                        "wall_s",
                        metric,
                    )  # fmt: skip
                }
                for r in resolution_rows
            ],
            "stability_map": stability_map(resolution_rows),
        }
    return result


def plot_work_precision(scene: str, rows: list[dict], res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = [m for m in METRICS if any(math.isfinite(_f(r.get(m))) and _f(r.get(m)) > 0 for r in rows)]
    cols = 3
    nrows = math.ceil(len(metrics) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(5.2 * cols, 4.2 * nrows), squeeze=False)
    for ax, m in zip(axes.ravel(), metrics, strict=False):
        for s in SCHEMES:
            pts = [r for r in rows if r["case"] == s and _stable(r) and _f(r.get(m)) > 0]
            if not pts:
                continue
            color, marker = STYLE[s]
            ax.scatter([_f(r["wall_s"]) for r in pts], [_f(r[m]) for r in pts], s=14, c=color, marker=marker,
                       alpha=0.55, label=s)  # fmt: skip
            front = [p for p in res["schemes"][s]["pareto"][m] if p["error"] > 0]
            if front:
                ax.plot([p["wall_s"] for p in front], [p["error"] for p in front], "-", color=color, lw=1.5)
        name, unit = METRICS[m]
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time of the run, s")
        ax.set_ylabel(f"error in {name} ({unit})")
        star = " (primary)" if m == SCENES[scene] else ""
        ax.set_title(f"{name}{star}")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(metrics) :]:
        ax.axis("off")
    if metrics:
        axes.ravel()[0].legend(fontsize=8, loc="best")
    sp = res.get("speedup_at_equal_error")
    fig.suptitle(
        f"{scene}: error against the fine lockstep reference vs wall time (lines: Pareto fronts); "
        f"speed-up at lockstep's error: {sp:.2f}x"
        if sp
        else f"{scene}: no multi-rate run reaches lockstep's error"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_stability(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    schemes = ("subcycle-hold", "subcycle-linear")
    fig, axes = plt.subplots(len(results), len(schemes), figsize=(6 * len(schemes), 3.2 * len(results)), squeeze=False)
    kinds = {
        "refused: MPM limit": ("0.8", "s"),
        "refused: fluid limit": ("0.45", "s"),
        "stable": ("tab:green", "s"),
        "unstable": ("tab:red", "x"),
    }

    def kind(p: dict) -> str:
        if p["state"] != "refused":
            return p["state"]
        return "refused: MPM limit" if p["why"].startswith("MPM") else "refused: fluid limit"

    for i, (scene, res) in enumerate(results.items()):
        for j, s in enumerate(schemes):
            ax = axes[i, j]
            pts = [p for p in res["stability_map"] if p["scheme"] == s and p["k"] is not None]
            for label, (colour, marker) in kinds.items():
                sel = [p for p in pts if kind(p) == label]
                if sel:
                    ax.scatter([int(p["k"]) for p in sel], [p["dt"] * 1e3 for p in sel], c=colour, s=40,
                               marker=marker, label=label)  # fmt: skip
            ax.set_yscale("log")
            ax.set_xlabel("substeps k")
            ax.set_ylabel("fluid step Δt, ms")
            ax.set_title(f"{scene}: {s}")
            ax.grid(True, alpha=0.3)
            if pts:
                ax.legend(fontsize=7, loc="upper left")
    fig.suptitle(
        "Where each scheme is stable: green stable, red unstable (NaN or lattice speed > 0.3), grey refused by the "
        "scene checker (light: the sand's substep, dark: the fluid's step)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def warm_kernels(spec) -> None:
    """Build and step once one scene of every case of a sweep (and its reference), so that every kernel
    variant the sweep needs is compiled into the disk cache before any run is timed: a point's wall time would
    otherwise include compiling its variants when it is the first of its worker to use them (measured: 2–5 s
    on points of 3–5 s)."""
    from couplekit.scene import Scene
    from couplekit.simulation import Simulation

    seen = set()
    for point in [*spec.points, *([spec.reference] if spec.reference is not None else [])]:
        if point is None or point.invalid:
            continue
        if point.case in seen:
            continue
        seen.add(point.case)
        sim = Simulation(Scene.from_dict(point.scene, base_dir=spec.scene_dir), backend=spec.backend, threads=1,
                         log=None)  # fmt: skip
        sim.step(2)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description="What accuracy costs in time: lockstep (paper Algorithm 1) against sub-cycled and multi-rate "
        "coupling, on three scenes, each against a fine lockstep reference."
    )
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--workers", type=int_in(1), default=2, help="LocalCluster worker processes (one thread each)")
    ap.add_argument(
        "--out",
        default=None,
        help="folder of every output: the sweep folders, accuracy_vs_cost.json and the PNGs (default: the sweeps "
        "in runs/accuracy_vs_cost/, the JSON and PNGs in benchmarks/results/)",
    )
    ap.add_argument("--analyse-only", action="store_true", help="do not run: analyse the sweeps in --out")
    ap.add_argument("--no-resolution", action="store_true", help="skip the two-resolution sweeps")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out is not None else ROOT / "runs" / "accuracy_vs_cost"
    results_dir = Path(args.out) if args.out is not None else RESULTS
    if args.analyse_only:
        missing = [
            name
            for scene in args.scenes
            for name in [scene] + ([] if args.no_resolution else [f"{scene}_resolution"])
            if not (out / name).is_dir()
        ]
        if missing:
            ap.error(
                f"--analyse-only: no sweep folder {', '.join(str(out / m) for m in missing)}; run the sweeps first"
            )
    from couplekit.sweep import load_results, load_sweep, run_sweep

    results, timing = {}, {}
    for scene in args.scenes:
        names = [scene] + ([] if args.no_resolution else [f"{scene}_resolution"])
        for name in names:
            if not args.analyse_only:
                spec = load_sweep(SWEEPS / f"{name}.toml")
                warm_kernels(spec)
                t0 = time.perf_counter()
                run_sweep(spec, out / name, workers=args.workers)
                timing[name] = time.perf_counter() - t0
        rows = load_results(out / scene)
        res_rows = None if args.no_resolution else load_results(out / f"{scene}_resolution")
        results[scene] = analyse(scene, rows, res_rows)
        results_dir.mkdir(parents=True, exist_ok=True)
        plot_work_precision(scene, rows, results[scene], results_dir / f"accuracy_vs_cost_{scene}.png")
        sp = results[scene]["speedup_at_equal_error"]
        print(f"{scene}: speed-up at lockstep's {SCENES[scene]}: {sp if sp is None else f'{sp:.2f}x'}; "
              f"best over lockstep points: {results[scene]['best_speedup_at_equal_error']}")  # fmt: skip
        within = results[scene]["speedups"][SCENES[scene]].get("speedup_within_1.5x_error")
        if within:
            print(
                f"  within 1.5x its error: {within['speedup']:.2f}x ({within['run']}, error x{within['error_ratio']:.2f})"
            )
    plot_stability(results, results_dir / "accuracy_vs_cost_stability.png")
    doc = {
        "command": "python benchmarks/accuracy_vs_cost.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": f"{platform.machine()}, {platform.processor() or platform.system()}, workers={args.workers}",
        "sweep_seconds": timing,
        "scenes": results,
    }
    path = results_dir / "accuracy_vs_cost.json"
    if args.analyse_only and path.exists():
        doc["sweep_seconds"] = json.loads(path.read_text()).get("sweep_seconds", {})
    path.write_text(json.dumps(doc, indent=1, default=float))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
