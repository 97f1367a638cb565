"""A water ball moving through still air, built as a scene dict: the case behind the measured limits of a moving
interface at 800:1, shared by the tests (tests/fluid/test_narrow_interface.py: the interface width;
tests/fluid/test_mobility_limit.py: the phase-field mobility) and the map's benchmark (benchmarks/mobility_map.py). A periodic 24 × 24 × 32 box with the scenes' fluid (lattice viscosities 1e-4 / 1e-2 with
their closures, σ = 0.0728 N/m at dx = 1 cm, dt = 1 ms), no gravity; or, ``at_wall``, the same ball thrown down at
a wall (z faces walls) from 0.55 of the box's height, so that it hits the floor after ~7 cells."""

from __future__ import annotations

import numpy as np

from ..scene import Scene

__all__ = ["DT", "DX", "SHAPE", "ball", "steps_to_diverge"]

DX, DT, SHAPE = 0.01, 1e-3, (24, 24, 32)
"""Cell size (m), time step (s) and box (cells, x y z) of the case."""


def ball(
    width: float,
    speed: float,
    ratio: float = 800.0,
    radius: float = 6.0,
    max_speed: float | None = None,
    mobility: float | None = None,
    at_wall: bool = False,
) -> dict:
    """The moving ball as a scene dict (``speed`` in lattice units; ``mobility`` None keeps the scene default)."""
    size = [n * DX for n in SHAPE]
    boundary = {f: "periodic" for f in ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")}
    velocity, center = [speed * DX / DT, 0.0, 0.0], [0.4 * size[0], size[1] / 2, size[2] / 2]
    if at_wall:
        boundary.update(z_min="wall", z_max="wall")
        velocity, center = [0.0, 0.0, -speed * DX / DT], [size[0] / 2, size[1] / 2, 0.55 * size[2]]
    fluid = {"phases": 2, "water_density": 1000.0, "air_density": 1000.0 / ratio, "interface_width": width}
    if mobility is not None:
        fluid["mobility"] = mobility
    return {
        "scene": {"name": "moving_ball"},
        "domain": {"size": size, "dx": DX, "gravity": [0.0, 0.0, 0.0], "boundary": boundary},
        "time": {
            "dt": DT,
            "frame_duration": DT,
            "frames": 1,
            "max_speed": (1.5 * speed if max_speed is None else max_speed) * DX / DT,
        },
        "fluid": fluid,
        "bodies": [
            {
                "kind": "water",
                "velocity": velocity,
                "geometry": {"type": "sphere", "center": center, "radius": radius * DX},
            }
        ],
        "outputs": {"preview": False},
    }


def steps_to_diverge(d: dict, steps: int = 1000) -> tuple[int | None, float, float]:
    """(the block of 20 steps by which the run diverged or None, peak lattice speed, the last one), on the cpu
    backend, one thread; a lattice speed above 0.5 counts as diverged."""
    from ..simulation import Simulation  # the simulation imports the solvers; this module stays light

    sim = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    peak = s = 0.0
    for k in range(steps // 20):
        sim.step(20)
        s = sim.fluid.diagnostics()["max_lattice_speed"]
        if not np.isfinite(s) or s > 0.5:
            return 20 * (k + 1), peak, s
        peak = max(peak, s)
    return None, peak, s
