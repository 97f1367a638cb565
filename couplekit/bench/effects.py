"""What each effect costs: time per step and memory (as allocated) with each effect on and off, on one
coupled scene and, where an effect applies without the other phase, on its fluid-only or sand-only variant.

The scene (:func:`base_scene`): a water pool with a sand ball above it in a closed box, the Fig. 13 setup at
``n``³ cells.  Each effect is switched by the scene keys a user would set (``[effects]``, ``sand.retention``,
``fluid.odd_lambda`` / ``smagorinsky``, ``[stirring]``, an ``[[inflows]]`` entry's ``sand_fraction``), and the
memory each costs is checked against :func:`couplekit.effect_memory.effect_memory`."""

from __future__ import annotations

import copy

import numpy as np

from ..assembly import CouplingUnavailableError
from ..effect_memory import effect_memory
from .memory import allocated_summary
from .timing import time_steps


def base_scene(n: int = 16, frames: int = 2) -> dict:
    """The coupled scene as a TOML-structured dict: n³ cells of 6 mm, water up to 40 %, a sand ball above."""
    dx = 0.006
    L = n * dx
    return {
        "scene": {"name": f"effect_costs_{n}", "description": "water pool and a sand ball (effect costs)"},
        "domain": {"size": [L, L, L], "dx": dx},
        "time": {"dt": 0.000144, "frame_duration": 0.000144 * 4, "frames": frames},
        "fluid": {
            "phases": 2,
            "water_density": 1000.0,
            "air_density": 1.25,
            "water_lattice_viscosity": 0.0005,
            "air_lattice_viscosity": 0.01,
            "surface_tension": 0.073,
            "controller_eta": 2.0,
        },
        "sand": {"density": 1500.0, "youngs_modulus": 350000.0, "poisson_ratio": 0.3, "particles_per_cell": 8},
        "bodies": [
            {"kind": "water", "name": "pool", "geometry": {"type": "box", "min": [0, 0, 0], "max": [L, L, 0.4 * L]}},
            {
                "kind": "sand",
                "name": "ball",
                "geometry": {"type": "sphere", "center": [L / 2, L / 2, 0.62 * L], "radius": 0.18 * L},
            },
        ],
    }


def _set(data: dict, path: str, value) -> dict:
    d = copy.deepcopy(data)
    *head, last = path.split(".")
    node = d
    for k in head:
        node = node.setdefault(k, {})
    if value is None:
        node.pop(last, None)
    else:
        node[last] = value
    return d


def _one_phase(data: dict, keep: str) -> dict:
    """The scene without its other phase: ``keep`` = "fluid" drops the sand (its section and bodies),
    "sand" the fluid (its section and the water bodies)."""
    drop_section, drop_kind = ("sand", "sand") if keep == "fluid" else ("fluid", "water")
    d = copy.deepcopy(data)
    d.pop(drop_section, None)
    d["bodies"] = [b for b in d["bodies"] if b["kind"] != drop_kind]
    d["scene"]["name"] += f"_{keep}"
    return d


def fluid_only(data: dict) -> dict:
    return _one_phase(data, "fluid")


def sand_only(data: dict) -> dict:
    return _one_phase(data, "sand")


def _stirring(data: dict) -> dict:
    L = data["domain"]["size"][0]
    return _set(
        data,
        "stirring",
        {"center": [L / 2, L / 2, 0.2 * L], "axis": [0.0, 0.0, 1.0], "radius": 0.4 * L, "acceleration": 1.5},
    )


def _inflow(data: dict, sand_fraction: float) -> dict:
    L = data["domain"]["size"][0]
    d = copy.deepcopy(data)
    jet = {"face": "x_min", "kind": "water", "velocity": [0.3, 0.0, 0.0], "shape": "rect"}
    jet.update({"center": [L / 2, 0.25 * L], "size": [0.4 * L, 0.2 * L]})
    if sand_fraction:
        jet["sand_fraction"] = sand_fraction
    d["inflows"] = [jet]
    return d


# effect -> (variant: coupled / fluid / sand, scene "on", scene "off")
def effect_variants(data: dict) -> dict[str, tuple[str, dict, dict]]:
    """For each effect the (variant, on, off) scene dicts (the off one is the scene's default where it is)."""
    fl, sd = fluid_only(data), sand_only(data)
    eff = lambda d, k, v: _set(d, f"effects.{k}", v)  # noqa: E731
    both = lambda d, v: eff(eff(d, "drag", v), "buoyancy", v)  # noqa: E731
    low_nu = _set(data, "fluid.water_lattice_viscosity", 1e-4)
    out = {
        "surface_tension": ("coupled", data, eff(data, "surface_tension", False)),
        "volume_controller": ("coupled", data, eff(data, "volume_controller", False)),
        "source_term": ("coupled", data, eff(data, "source_term", False)),
        "retention": ("coupled", _set(data, "sand.retention", True), data),
        "drag_buoyancy": ("coupled", data, both(data, False)),
        "cohesion": ("coupled", data, eff(data, "cohesion", False)),
        "hardening": ("coupled", data, eff(data, "hardening", False)),
        "odd_rate_floor": ("coupled", data, _set(data, "fluid.odd_lambda", 0.0)),
        "smagorinsky": ("coupled", data, _set(data, "fluid.smagorinsky", 0.0)),
        # the floor acts (and so its ramp) below ν = 5e-4 only: the paper's water viscosity for this pair
        "odd_rate_ramp": ("coupled", _set(low_nu, "fluid.odd_ramp", 3.0), low_nu),
        "stirring": ("coupled", _stirring(data), data),
        "sand_emission": ("coupled", _inflow(data, 0.3), _inflow(data, 0.0)),
        "surface_tension (fluid only)": ("fluid", fl, eff(fl, "surface_tension", False)),
        "volume_controller (fluid only)": ("fluid", fl, eff(fl, "volume_controller", False)),
        "odd_rate_floor (fluid only)": ("fluid", fl, _set(fl, "fluid.odd_lambda", 0.0)),
        "smagorinsky (fluid only)": ("fluid", fl, _set(fl, "fluid.smagorinsky", 0.0)),
        "stirring (fluid only)": ("fluid", _stirring(fl), fl),
        "cohesion (sand only)": ("sand", sd, eff(sd, "cohesion", False)),
        "hardening (sand only)": ("sand", sd, eff(sd, "hardening", False)),
    }
    return out


def _build(data: dict, backend: str):
    from ..scene import Scene
    from ..simulation import Simulation

    scene = Scene.from_dict(data, source_name=data["scene"]["name"])
    return scene, Simulation(scene, backend=backend, log=None, check_memory=False)


def _memory(scene, sim) -> dict:
    mem = allocated_summary(sim)
    return {
        "allocated_bytes": mem["total"],
        "particles": mem["particles"],
        "bytes_per_cell": mem["bytes_per_cell"],
        "bytes_per_particle": mem["bytes_per_particle"],
        "effect_memory": effect_memory(scene),
    }


def measure(data: dict, backend: str = "cpu", steps: int = 10, repeats: int = 3) -> dict:
    """One scene: s/step (:func:`~couplekit.bench.timing.time_steps`), stage costs over all timed steps,
    memory as allocated."""
    scene, sim = _build(data, backend)
    s = time_steps(sim, steps, repeats)
    return {
        "s_per_step": s,
        "stages_ms_per_step": {k: 1e3 * v["mean"] for k, v in sim.cost_report().items()},
        **_memory(scene, sim),
    }


MIN_PAIRS_95 = 6
"""The fewest values whose range covers the median with 95 % confidence (1 − 2·2⁻ⁿ ≥ 0.95 from n = 6): below
it no interval of order statistics is a 95 % one (2 values: 50 %), so no cost is called resolved."""


def median_interval(xs: list[float], level: float = 0.95) -> tuple[float, float]:
    """Distribution-free confidence interval of the median: the order statistics x_(k), x_(n+1-k) with the
    largest k for which P(Binomial(n, 1/2) < k) ≤ (1 − level)/2. For fewer than :data:`MIN_PAIRS_95` values
    it returns the whole range, which covers the median with only 1 − 2^(1−n) confidence (50 % for 2 values):
    :func:`ratio_summary` and :func:`stage_cost` then call nothing resolved."""
    from math import comb

    ys, n = sorted(xs), len(xs)
    tail, k, acc = 0.5 * (1.0 - level), 0, 0.0
    while k < n // 2:
        nxt = acc + comb(n, k) / 2.0**n  # P(X <= k)
        if nxt > tail:
            break
        acc, k = nxt, k + 1
    k = max(k, 1)
    return ys[k - 1], ys[n - k]


def ratio_summary(block_ratios: list[float]) -> dict:
    """Median, quartiles, extremes and the 95 % confidence interval of the median of the per-pair on/off
    time ratios, and whether the cost is resolved: it is not when that interval contains 1.0 (the scatter of
    the pairs, over their number, is larger than the effect's own size |median − 1|), nor with fewer than
    :data:`MIN_PAIRS_95` pairs (no 95 % interval exists)."""
    med = float(np.quantile(block_ratios, 0.5))
    lo, hi = median_interval(block_ratios)
    return {
        "ratio_median": med,
        "ratio_q1": float(np.quantile(block_ratios, 0.25)),
        "ratio_q3": float(np.quantile(block_ratios, 0.75)),
        "ratio_min": min(block_ratios),
        "ratio_max": max(block_ratios),
        "ratio_ci95": [lo, hi],
        "pairs": len(block_ratios),
        # fewer pairs than a 95 % interval needs: not resolved, whatever the range (MIN_PAIRS_95)
        "resolved": len(block_ratios) >= MIN_PAIRS_95 and not (lo <= 1.0 <= hi),
    }


# effect -> the stages (scheduler stage timers) whose work it adds or changes; the effect's stage cost is their
# time on minus off, as a fraction of the step off (None: no stage of its own, the step's time only)
EFFECT_STAGES = {
    "surface_tension": ("lbm_collide_stream",),  # μ_φ (from φ's stencil) and the force it adds
    "volume_controller": ("volume_controller",),
    "source_term": ("retention_source", "phase_field_collide_stream"),
    "retention": ("retention_source", "moisture"),
    "drag_buoyancy": ("drag_buoyancy",),
    "cohesion": ("mpm_g2p",),
    "hardening": ("mpm_g2p",),
    "odd_rate_floor": ("lbm_collide_stream",),
    "smagorinsky": ("lbm_collide_stream",),
    "odd_rate_ramp": ("lbm_collide_stream",),
    "stirring": None,
    "sand_emission": None,
}


def measure_pair(
    on: dict,
    off: dict,
    backend: str = "cpu",
    steps: int = 4,
    alternations: int = 10,
    warmup: int = 3,
    clock: str = "wall",
) -> dict:
    """The effect on and off, interleaved: both simulations are built, warmed up (``warmup`` steps each:
    kernel compile or load, first touch of memory), then stepped in alternating blocks of ``steps`` steps,
    ``alternations`` pairs, the order inside a pair swapped every other pair (ABBA...) so a steady drift of
    the machine's speed cancels.  Each pair gives one on/off ratio of the two blocks' times, measured
    seconds apart, so the machine's slow drift (up to 3x here) is common to both.  Returns the per-block
    times, :func:`ratio_summary` of the pair ratios, stage costs (ms per step over the timed blocks) and
    memory as allocated of both.

    ``clock``: "wall" (``time.perf_counter``) or "cpu" (``time.process_time``, for both the blocks and the
    stage timers: on a host shared with other processes the time they take the core away does not count;
    meaningful with one OpenMP thread, where the process's CPU time is the step's)."""
    import time

    tick = {"wall": time.perf_counter, "cpu": time.process_time}[clock]
    built = {"on": _build(on, backend), "off": _build(off, backend)}
    for _, sim in built.values():
        sim.scheduler.clock = tick
        sim.step(warmup)
        sim.reset_timing()
    times: dict[str, list[float]] = {"on": [], "off": []}
    stages: dict[str, list[dict[str, float]]] = {"on": [], "off": []}  # per block: stage -> s per step
    for i in range(max(1, int(alternations))):
        for state in ("on", "off") if i % 2 == 0 else ("off", "on"):
            sim = built[state][1]
            sim.reset_timing()
            t = tick()
            sim.step(steps)
            times[state].append((tick() - t) / steps)
            stages[state].append({k: v["mean"] for k, v in sim.cost_report().items()})
    ratios = [a / b for a, b in zip(times["on"], times["off"], strict=True)]
    res = {"block_s_per_step": times, "block_ratios": ratios, "block_stages": stages, **ratio_summary(ratios)}
    for state, (scene, sim) in built.items():
        blocks = stages[state]
        res[state] = {
            "s_per_step": float(np.quantile(times[state], 0.5)),
            "stages_ms_per_step": {k: 1e3 * sum(b.get(k, 0.0) for b in blocks) / len(blocks) for k in blocks[0]},
            **_memory(scene, sim),
        }
    return res


def stage_cost(pair: dict, own: tuple[str, ...]) -> dict:
    """The effect's cost from its own stages: per pair (their time on − off) / the step's time off, median
    and its 95 % interval; resolved when the interval excludes 0.  Sharper than the step ratio: the noise of
    the other stages does not enter."""
    on, off = pair["block_stages"]["on"], pair["block_stages"]["off"]
    t_off = pair["block_s_per_step"]["off"]
    fr = [
        (sum(a.get(s, 0.0) for s in own) - sum(b.get(s, 0.0) for s in own)) / t
        for a, b, t in zip(on, off, t_off, strict=True)
    ]
    lo, hi = median_interval(fr)
    return {"stages": list(own), "fraction_median": float(np.quantile(fr, 0.5)), "fraction_ci95": [lo, hi],
            "pairs": len(fr), "resolved": len(fr) >= MIN_PAIRS_95 and not (lo <= 0.0 <= hi)}  # fmt: skip


def run_effect_costs(
    n: int = 16,
    backend: str = "cpu",
    steps: int = 4,
    effects: list[str] | None = None,
    progress=None,
    alternations: int = 10,
    clock: str = "wall",
) -> dict:
    """Every effect (or ``effects``) on and off, interleaved (:func:`measure_pair`): time ratio with its
    spread, memory allocated, the difference, and the bytes the effect table (:mod:`couplekit.effect_memory`)
    reports for it."""
    variants = effect_variants(base_scene(n))
    rows = {}
    for name, (variant, on, off) in variants.items():
        if effects is not None and name not in effects:
            continue
        if progress is not None:
            progress(name)
        try:
            res = measure_pair(on, off, backend, steps, alternations, clock=clock)
        except CouplingUnavailableError as exc:  # an effect the coupling cannot switch off yet
            rows[name] = {"variant": variant, "unavailable": str(exc)}
            continue
        key = name.split(" (")[0]
        table = res["on"]["effect_memory"].get(key, {})
        own = EFFECT_STAGES.get(key)
        rows[name] = {
            "variant": variant,
            "s_per_step_on": res["on"]["s_per_step"],
            "s_per_step_off": res["off"]["s_per_step"],
            "time_ratio_on_off": res["ratio_median"],
            **{
                k: res[k] for k in ("ratio_q1", "ratio_q3", "ratio_min", "ratio_max", "ratio_ci95", "pairs", "resolved")
            },
            # the fastest block of each (contention only ever adds time): a second estimate
            "ratio_of_fastest": min(res["block_s_per_step"]["on"]) / min(res["block_s_per_step"]["off"]),
            "block_ratios": res["block_ratios"],
            "block_s_per_step": res["block_s_per_step"],
            "allocated_on": res["on"]["allocated_bytes"],
            "allocated_off": res["off"]["allocated_bytes"],
            "allocated_difference": res["on"]["allocated_bytes"] - res["off"]["allocated_bytes"],
            "reported_bytes_per_cell": table.get("bytes_per_cell"),
            "reported_bytes_per_particle": table.get("bytes_per_particle"),
            # the effect table's per-cell total plus its per-particle bytes times the particles the run holds
            "reported_total": None
            if table.get("bytes_total") is None
            else table["bytes_total"] + (table.get("bytes_per_particle") or 0.0) * res["on"]["particles"],
            "kept_when_off": table.get("kept_when_off", ""),
            "stage_cost": stage_cost(res, own) if own else None,
            "stages_ms_on": res["on"]["stages_ms_per_step"],
            "stages_ms_off": res["off"]["stages_ms_per_step"],
        }
    return {
        "cells": n**3,
        "backend": backend,
        "steps_per_block": steps,
        "alternations": alternations,
        "clock": clock,
        "method": "interleaved blocks (measure_pair); ratio = median of the per-pair on/off ratios, spread: "
        "interquartile range of the pairs and the 95 % interval of the median; not resolved when that "
        f"interval contains 1.0 or with fewer than {MIN_PAIRS_95} pairs (then the 'interval' is the pairs' range, "
        "a 1 - 2^(1-n) one)",
        "effects": rows,
    }


def markdown_table(result: dict) -> str:
    """README-ready: effect, variant, ms/step on / off (medians of the blocks), the on/off ratio (median of
    the pairs) with the pairs' interquartile range and the median's 95 % interval, bytes allocated on − off,
    bytes per cell reported."""
    lines = [
        "| effect | scene | ms/step on | ms/step off | on/off (median) | IQR of pairs | 95 % interval | cost "
        "| own stages: on − off, % of step (95 %) | allocated on − off (B) | reported B/cell | kept when off |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in result["effects"].items():
        if "unavailable" in r:
            why = r["unavailable"].split(": ", 1)[-1]
            lines.append(f"| {name.split(' (')[0]} | {r['variant']} | not switchable: {why} | | | | | | | | | |")
            continue
        rep = "-" if r["reported_bytes_per_cell"] is None else f"{r['reported_bytes_per_cell']:.3g}"
        if r["reported_bytes_per_particle"]:
            rep += f" + {r['reported_bytes_per_particle']:.3g}/particle"
        few = r.get("pairs", MIN_PAIRS_95) < MIN_PAIRS_95
        cost = f"{100 * (r['time_ratio_on_off'] - 1):+.0f} %" if r["resolved"] else "not resolved"
        cost += f" ({r['pairs']} pairs: too few for a 95 % interval)" if few else ""
        sc = r.get("stage_cost")
        if sc:
            lo, hi = sc["fraction_ci95"]
            own = f"{100 * sc['fraction_median']:+.1f} ({100 * lo:+.1f}…{100 * hi:+.1f})"
            own += "" if sc["resolved"] else " not resolved"
        else:
            own = "-"
        lines.append(
            f"| {name.split(' (')[0]} | {r['variant']} | {1e3 * r['s_per_step_on']:.3g} | {1e3 * r['s_per_step_off']:.3g} "
            f"| {r['time_ratio_on_off']:.3f} | {r['ratio_q1']:.3f}–{r['ratio_q3']:.3f} "
            f"| {r['ratio_ci95'][0]:.3f}–{r['ratio_ci95'][1]:.3f} | {cost} | {own} "
            f"| {r['allocated_difference']:,.0f} | {rep} | {r['kept_when_off'].split(':')[0] or '-'} |"
        )
    return "\n".join(lines)
