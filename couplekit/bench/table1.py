"""Paper 000's Table 1, row by row: the paper's values, the scene files that reproduce each figure, a
measurement of each row's small scene on this machine, its memory as allocated, and the projected s/frame at
the paper's size on the paper's GPU, an H100 and an H200 (:mod:`couplekit.bench.traffic`).

Frame duration: the paper does not give one; :data:`FRAME_DURATION` (1/30 s, the frame rate of its videos'
renders is not stated either) is used, so steps per frame = FRAME_DURATION / Δt.  Memory at the paper's size:
the bytes per padded cell and per particle measured on the row's small scene (everything but the particle
arrays, divided by the padded cells (nx+2)(ny+2)(nz+2); the particle arrays divided by the particles) times the paper's cells and particles."""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from .memory import allocated_summary
from .timing import time_steps
from .traffic import GPUS, projected_step

FRAME_DURATION = 1.0 / 30.0
MEMORY_SIZES_GB = (24, 48, 80, 96, 141)
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@dataclass(frozen=True)
class Row:
    """One row of Table 1 as printed (grid as the paper writes it, y up; viscosities in lattice units)."""

    figure: int
    grid: tuple[int, int, int]
    particles_k: int  # thousands
    dx: float
    retention: str  # "no" or "yes/R_a"
    eta: float
    nu_h: float
    nu_l: float
    density: str  # kg/m3; Fig. 8 lists three
    dt: float
    s_per_frame: float

    @property
    def cells(self) -> int:
        return math.prod(self.grid)


# Table 1 of paper 000 (/work/shared/papers/000_*.txt, "Table 1. Parameters and timings"), in its order
TABLE1 = (
    Row(1, (800, 320, 400), 5838, 0.0075, "no", 2, 5e-4, 1e-1, "2000", 1.0e-4, 252.0),
    Row(2, (600, 180, 600), 6174, 0.001, "no", 2, 5e-4, 2e-3, "600", 5.8e-5, 71.6),
    Row(3, (800, 400, 400), 11579, 0.0010, "no", 2, 1e-4, 1e-2, "1400", 2.9e-5, 147.7),
    Row(4, (600, 500, 600), 1715, 0.00083, "yes/0.003", 2, 1e-4, 1e-2, "1000", 3.0e-5, 288.3),
    Row(5, (600, 200, 600), 31879, 0.0025, "no", 1, 1e-4, 1e-2, "1200", 5.6e-5, 82.6),
    Row(6, (300, 240, 300), 28800, 0.0001, "no", 1, 1e-4, 1e-2, "1200", 7.5e-6, 4.9),
    Row(8, (300, 400, 300), 524, 0.0050, "no", 2, 1e-4, 1e-2, "600/950/1500", 1.6e-5, 13.2),
    Row(9, (800, 400, 400), 52895, 0.005625, "no", 2, 1e-4, 1e-2, "1200", 1.0e-4, 136.6),
    Row(10, (720, 400, 400), 10486, 0.0025, "yes/0.001", 2, 1e-4, 1e-2, "1200", 8.0e-5, 226.6),
    Row(11, (300, 450, 300), 12960, 0.00050, "no", 1, 1e-4, 1e-2, "1200", 2.1e-5, 93.3),
    Row(12, (800, 320, 400), 5289, 0.01, "no", 2, 1e-4, 1e-1, "1200", 6.0e-5, 118.3),
    Row(13, (320, 500, 320), 524, 0.00050, "no", 2, 5e-4, 1e-2, "1500", 1.2e-5, 52.3),
    Row(15, (1000, 400, 80), 9918, 0.002, "no", 2, 1e-4, 1e-2, "900", 3.4e-5, 35.3),
    Row(14, (200, 400, 200), 14137, 0.0005, "no", 2, 1e-4, 1e-2, "1200", 1.5e-5, 26.5),
    Row(16, (800, 400, 400), 27648, 0.01, "no", 1, 1e-4, 1e-2, "900", 6.5e-5, 312.3),
    Row(17, (200, 300, 200), 4042, 0.002, "yes/0.001", 2, 1e-2, 1e-2, "1200", 1.2e-4, 29.4),
    Row(18, (1000, 320, 800), 19971, 0.50, "yes/0.003", 2, 3e-4, 1e-2, "1300", 1.2e-4, 286.8),
)


def scene_files(figure: int, examples: Path = EXAMPLES) -> tuple[list[Path], list[Path]]:
    """(full-size scene files, small variants) in ``examples/`` for a figure (``figNN_*.toml``)."""
    files = sorted(examples.glob(f"fig{figure:02d}_*.toml"))
    return [f for f in files if not f.stem.endswith("_small")], [f for f in files if f.stem.endswith("_small")]


def coarsened(scene, factor: float):
    """``scene`` with dx and dt multiplied by ``factor`` (every lattice number kept, the examples' rule for
    their small variants; the domain rounded to whole cells); ``factor`` 1 returns it unchanged."""
    if factor == 1:
        return scene
    from ..scene import Scene

    data = scene.to_dict()
    dx = scene.domain.dx * factor
    data["domain"]["dx"] = dx
    data["domain"]["size"] = [max(4, round(s / dx)) * dx for s in data["domain"]["size"]]  # whole cells
    data["time"]["dt"] = scene.time.dt * factor
    return Scene.from_dict(data, source_name=f"{scene.name} x{factor:g} coarser")


def measure_scene(scene, backend: str = "cpu", steps: int = 10, threads: int | None = None, repeats: int = 3) -> dict:
    """Build ``scene`` and time its steps (:func:`~couplekit.bench.timing.time_steps`): s/step, cell and
    particle updates per second, the per-stage cost report, memory as allocated against the estimate."""
    from ..simulation import Simulation

    t0 = time.perf_counter()
    sim = Simulation(scene, backend=backend, threads=threads, log=None, check_memory=False)
    build_s = time.perf_counter() - t0
    step_s = time_steps(sim, steps, repeats, warmup=1 if repeats == 1 else 3)
    mem = allocated_summary(sim)
    cells = mem["cells"]
    particles = sim.sand.n_particles if sim.sand is not None else 0
    return {
        "scene": scene.name,
        "backend": sim.backend.describe(),
        "resolution": list(scene.domain.resolution),
        "cells": cells,
        "particles": particles,
        "build_s": build_s,
        "steps": steps,
        "s_per_step": step_s,
        "cell_updates_per_s": cells / step_s,
        "particle_updates_per_s": particles / step_s if particles else 0.0,
        "stages_ms_per_step": {k: 1e3 * v["mean"] for k, v in sim.cost_report().items()},
        "memory_allocated": mem,
        "memory_estimate": dict(sim.memory),
        "estimate_over_allocated": sim.memory["total"] / mem["total"] if mem["total"] else None,
        "effects": sim.effects,
    }


def project_row(row: Row, bytes_per_cell: float, bytes_per_particle: float) -> dict:
    """``bytes_per_cell``: per padded cell.  The projection of ``row`` at the paper's size: memory, and s/step, s/frame per GPU."""
    cells, particles = row.cells, row.particles_k * 1e3
    padded = math.prod(n + 2 for n in row.grid)
    memory = bytes_per_cell * padded + bytes_per_particle * particles
    steps_per_frame = FRAME_DURATION / row.dt
    gpus = {}
    for g in GPUS:
        p = projected_step(g, cells, particles)
        gpus[g.name] = {
            "s_per_step": p["step_s"],
            "s_per_frame": p["step_s"] * steps_per_frame,
            "stages_s_per_step": p["stages_s"],
            "fits": memory <= g.memory_gb * 1e9,
        }
    return {
        "steps_per_frame": steps_per_frame,
        "memory_bytes": memory,
        "fits_gb": {str(s): memory <= s * 1e9 for s in MEMORY_SIZES_GB},
        "gpus": gpus,
    }


def run_table1(
    backend: str = "cpu",
    steps: int = 10,
    repeats: int = 3,
    coarsen: float = 1.0,
    figures: list[int] | None = None,
    progress=None,
) -> dict:
    """Every row (or ``figures``): the paper's values, the scene files, a measurement of the first small
    variant (coarsened by ``coarsen``), the projection.  Rows without a small scene take the bytes per cell and
    particle of the coupled scene measured last (named in ``memory_from``).  ``progress(label)`` is called
    before each row."""
    from ..scene import Scene

    rows, stand_in = [], None
    for row in TABLE1:
        if figures is not None and row.figure not in figures:
            continue
        if progress is not None:
            progress(f"Fig. {row.figure}")
        full, small = scene_files(row.figure)
        entry = {
            "paper": asdict(row),
            "scene_files": [str(f.relative_to(EXAMPLES.parent)) for f in full],
            "small_scenes": [str(f.relative_to(EXAMPLES.parent)) for f in small],
        }
        if not full and not small:
            entry["status"] = "no scene file yet (the figure's scene is still to be written)"
        if small:
            m = measure_scene(coarsened(Scene.load(small[0]), coarsen), backend, steps, repeats=repeats)
            entry["measured"] = m
            mem = m["memory_allocated"]
            bpc, bpp, src = mem["bytes_per_padded_cell"], mem["bytes_per_particle"], m["scene"]
            if m["particles"] and m["effects"].get("coupling"):
                stand_in = (bpc, bpp, src)
        elif stand_in is not None:
            bpc, bpp, src = stand_in
        else:
            bpc = bpp = None
        if bpc is not None:
            entry["memory_from"] = src
            entry["bytes_per_padded_cell"], entry["bytes_per_particle"] = bpc, bpp
            entry["projection"] = project_row(row, bpc, bpp)
        rows.append(entry)
    return {
        "frame_duration_s": FRAME_DURATION,
        "memory_sizes_gb": list(MEMORY_SIZES_GB),
        "rows": rows,
    }


def markdown_table(result: dict) -> str:
    """README-ready table: paper's s/frame (RTX PRO 6000, 96 GB) against couplekit's measured s/step here and
    its projected s/frame per GPU, the memory at the paper's size and the memory sizes it fits in."""
    gpus = [g.name for g in GPUS]
    head = (
        "| Fig. | grid | particles | paper s/frame (RTX PRO 6000, 96 GB) | couplekit here: scene, s/step | "
        + " | ".join(f"projected s/frame, {g}" for g in gpus)
        + " | memory at paper size | fits in (GB) |"
    )
    lines = [head, "|" + "---|" * (7 + len(gpus) - 2 + 2)]
    for e in result["rows"]:
        p = e["paper"]
        grid = "×".join(str(n) for n in p["grid"])
        m = e.get("measured")
        here = f"{m['scene']} {m['resolution'][0]}×{m['resolution'][1]}×{m['resolution'][2]}, {m['s_per_step']:.3g}" if m else (
            e.get("status", "no small scene: memory from " + e.get("memory_from", "-"))
        )  # fmt: skip
        pr = e.get("projection")
        proj = [f"{pr['gpus'][g]['s_per_frame']:.3g}" if pr else "-" for g in gpus]
        memory = f"{pr['memory_bytes'] / 1e9:.1f} GB" if pr else "-"
        fits = ", ".join(s for s, ok in pr["fits_gb"].items() if ok) if pr else "-"
        lines.append(
            f"| {p['figure']} | {grid} | {p['particles_k']:,}k | {p['s_per_frame']:g} | {here} | "
            + " | ".join(proj)
            + f" | {memory} | {fits or 'none'} |"
        )
    return "\n".join(lines)


def plot_table1(result: dict, path: Path) -> Path:
    """Bar chart: paper's s/frame against the projected s/frame per GPU, one group per row (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = [e for e in result["rows"] if "projection" in e]
    labels = [f"Fig. {e['paper']['figure']}" for e in rows]
    series = {"paper (RTX PRO 6000)": [e["paper"]["s_per_frame"] for e in rows]}
    for g in GPUS:
        series[f"couplekit projected, {g.name}"] = [e["projection"]["gpus"][g.name]["s_per_frame"] for e in rows]
    fig, ax = plt.subplots(figsize=(max(6, 0.7 * len(rows) + 3), 4.5))
    x = np.arange(len(rows))
    w = 0.8 / len(series)
    for i, (name, vals) in enumerate(series.items()):
        ax.bar(x + (i - (len(series) - 1) / 2) * w, vals, w, label=name)
    ax.set_xticks(x, labels, rotation=45, ha="right")
    ax.set_yscale("log")
    ax.set_ylabel(f"s per frame (frame = {result['frame_duration_s']:.4g} s)")
    ax.set_title("Paper 000 Table 1:\npaper's timings vs couplekit's bandwidth projection", fontsize=10)  # fits
    ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
