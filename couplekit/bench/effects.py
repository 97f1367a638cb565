"""What each effect costs: time per step and memory (as allocated) with each effect on and off, on one
coupled scene and, where an effect applies without the other phase, on its fluid-only or sand-only variant.

The scene (:func:`base_scene`): a water pool with a sand ball above it in a closed box, the Fig. 13 setup at
``n``³ cells.  Each effect is switched by the scene keys a user would set (``[effects]``, ``sand.retention``,
``fluid.odd_lambda`` / ``smagorinsky``, ``[stirring]``, an ``[[inflows]]`` entry's ``sand_fraction``), and the
memory each costs is checked against :func:`couplekit.effect_memory.effect_memory`."""

from __future__ import annotations

import copy

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


def fluid_only(data: dict) -> dict:
    d = copy.deepcopy(data)
    d.pop("sand", None)
    d["bodies"] = [b for b in d["bodies"] if b["kind"] != "sand"]
    d["scene"]["name"] += "_fluid"
    return d


def sand_only(data: dict) -> dict:
    d = copy.deepcopy(data)
    d.pop("fluid", None)
    d["bodies"] = [b for b in d["bodies"] if b["kind"] != "water"]
    d["scene"]["name"] += "_sand"
    return d


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


def measure(data: dict, backend: str = "cpu", steps: int = 10, repeats: int = 3) -> dict:
    """One scene: s/step (:func:`~couplekit.bench.timing.time_steps`), stage costs over all timed steps,
    memory as allocated."""
    from ..scene import Scene
    from ..simulation import Simulation

    scene = Scene.from_dict(data, source_name=data["scene"]["name"])
    sim = Simulation(scene, backend=backend, log=None, check_memory=False)
    s = time_steps(sim, steps, repeats)
    mem = allocated_summary(sim)
    return {
        "s_per_step": s,
        "stages_ms_per_step": {k: 1e3 * v["mean"] for k, v in sim.cost_report().items()},
        "allocated_bytes": mem["total"],
        "particles": mem["particles"],
        "bytes_per_cell": mem["bytes_per_cell"],
        "bytes_per_particle": mem["bytes_per_particle"],
        "effect_memory": effect_memory(scene),
    }


def run_effect_costs(
    n: int = 16,
    backend: str = "cpu",
    steps: int = 10,
    effects: list[str] | None = None,
    progress=None,
    repeats: int = 3,
) -> dict:
    """Every effect (or ``effects``) on and off: time, memory allocated, the difference, and the bytes the
    effect table (:mod:`couplekit.effect_memory`) reports for it."""
    variants = effect_variants(base_scene(n))
    cache: dict[str, dict] = {}
    rows = {}
    for name, (variant, on, off) in variants.items():
        if effects is not None and name not in effects:
            continue
        if progress is not None:
            progress(name)
        res = {}
        try:
            for state, d in (("on", on), ("off", off)):
                key = repr(sorted(d.items(), key=lambda kv: kv[0]))
                if key not in cache:
                    cache[key] = measure(d, backend, steps, repeats)
                res[state] = cache[key]
        except CouplingUnavailableError as exc:  # an effect the coupling cannot switch off yet
            rows[name] = {"variant": variant, "unavailable": str(exc)}
            continue
        key = name.split(" (")[0]
        table = res["on"]["effect_memory"].get(key, {})
        rows[name] = {
            "variant": variant,
            "s_per_step_on": res["on"]["s_per_step"],
            "s_per_step_off": res["off"]["s_per_step"],
            "time_ratio_on_off": res["on"]["s_per_step"] / res["off"]["s_per_step"],
            "allocated_on": res["on"]["allocated_bytes"],
            "allocated_off": res["off"]["allocated_bytes"],
            "allocated_difference": res["on"]["allocated_bytes"] - res["off"]["allocated_bytes"],
            "reported_bytes_per_cell": table.get("bytes_per_cell"),
            "reported_bytes_per_particle": table.get("bytes_per_particle"),
            "reported_total": table.get("bytes_total"),
            "kept_when_off": table.get("kept_when_off", ""),
            "stages_ms_on": res["on"]["stages_ms_per_step"],
            "stages_ms_off": res["off"]["stages_ms_per_step"],
        }
    return {"cells": n**3, "backend": backend, "steps": steps, "effects": rows}


def markdown_table(result: dict) -> str:
    """README-ready: effect, variant, ms/step on / off, bytes allocated on − off, bytes per cell reported."""
    lines = [
        "| effect | scene | ms/step on | ms/step off | on/off | allocated on − off (B) | reported B/cell | kept when off |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, r in result["effects"].items():
        if "unavailable" in r:
            why = r["unavailable"].split(": ", 1)[-1]
            lines.append(f"| {name.split(' (')[0]} | {r['variant']} | not switchable: {why} | | | | | |")
            continue
        rep = "-" if r["reported_bytes_per_cell"] is None else f"{r['reported_bytes_per_cell']:.3g}"
        if r["reported_bytes_per_particle"]:
            rep += f" + {r['reported_bytes_per_particle']:.3g}/particle"
        lines.append(
            f"| {name.split(' (')[0]} | {r['variant']} | {1e3 * r['s_per_step_on']:.3g} | {1e3 * r['s_per_step_off']:.3g} "
            f"| {r['time_ratio_on_off']:.2f} | {r['allocated_difference']:,.0f} | {rep} | "
            f"{r['kept_when_off'].split(':')[0] or '-'} |"
        )
    return "\n".join(lines)
