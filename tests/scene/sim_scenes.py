"""Tiny valid scenes for the Simulation and CLI tests (seconds on 2 cores)."""

from __future__ import annotations


def tiny_sand(frames: int = 2) -> dict:
    """A 12³ box with a small block of sand falling onto a sphere obstacle."""
    return {
        "scene": {"name": "tiny_sand"},
        "domain": {"size": [0.06, 0.06, 0.06], "dx": 0.005},
        "time": {"dt": 2e-4, "frame_duration": 1e-3, "frames": frames},
        "sand": {"density": 1500.0, "youngs_modulus": 1e5, "particles_per_cell": 8},
        "bodies": [
            {
                "kind": "sand",
                "velocity": [0, 0, -0.5],
                "geometry": {"type": "box", "min": [0.02, 0.02, 0.03], "max": [0.04, 0.04, 0.045]},
            },
            {"kind": "obstacle", "geometry": {"type": "sphere", "center": [0.03, 0.03, 0.0], "radius": 0.02}},
        ],
        "outputs": {"preview": False},
    }


def tiny_fluid(frames: int = 2) -> dict:
    """A 12x8x12 two-phase box: a water layer, a falling drop, an obstacle, a wind inflow and an outflow."""
    return {
        "scene": {"name": "tiny_fluid"},
        "domain": {"size": [0.03, 0.02, 0.03], "dx": 0.0025, "boundary": {"x_min": "inflow", "x_max": "outflow"}},
        "time": {"dt": 2e-5, "frame_duration": 1e-4, "frames": frames},
        "fluid": {"water_lattice_viscosity": 1e-2, "air_lattice_viscosity": 1e-1, "surface_tension": 0.07},
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.03, 0.02, 0.01]}},
            {
                "kind": "water",
                "velocity": [0, 0, -0.5],
                "geometry": {"type": "sphere", "center": [0.015, 0.01, 0.02], "radius": 0.005},
            },
            {"kind": "obstacle", "geometry": {"type": "box", "min": [0.02, 0.0, 0.0], "max": [0.025, 0.02, 0.005]}},
        ],
        "inflows": [
            {"face": "x_min", "kind": "wind", "velocity": [0.1, 0, 0]}
        ],  # a water inflow works too (tests/fluid/test_inflow_front.py)
        "outputs": {"preview": False},
    }


def tiny_coupled(retention: bool = True) -> dict:
    """tiny_fluid plus a sand block in the air above the water layer (with retention by default)."""
    d = tiny_fluid()
    d["scene"]["name"] = "tiny_coupled"
    d["bodies"].append(
        {"kind": "sand", "geometry": {"type": "box", "min": [0.005, 0.006, 0.012], "max": [0.011, 0.014, 0.016]}}
    )
    d["sand"] = {"density": 1500.0, "retention": retention}
    return d


def tiny_coupled_moving(scheduler: dict, retention: bool = False) -> dict:
    """tiny_coupled with the sand block half in the water layer and moving (0.2, 0, -0.3) m/s under ``scheduler``
    (a [scheduler] table): drag, the source term and the slip term all act from the first step (the buffer-sharing
    tests of the coupling)."""
    d = tiny_coupled(retention=retention)
    d["bodies"][-1]["geometry"].update({"min": [0.006, 0.006, 0.006], "max": [0.013, 0.014, 0.013]})
    d["bodies"][-1]["velocity"] = [0.2, 0.0, -0.3]
    d["scheduler"] = scheduler
    return d


def tiny_jet() -> dict:
    """tiny_coupled with a water jet carrying sand through an outlet in the x_min wall (particle emission: the
    first particle layer leaves the outlet after ~60 steps)."""
    d = tiny_coupled()
    d["scene"]["name"] = "tiny_jet"
    d["domain"]["boundary"]["x_min"] = "wall"
    d["inflows"] = [
        {"face": "x_min", "kind": "water", "velocity": [1.0, 0, 0], "sand_fraction": 0.2, "shape": "rect",
         "center": [0.01, 0.015], "size": [0.01, 0.01]}
    ]  # fmt: skip
    return d


TINY_SAND_TOML = """
[domain]
size = [0.06, 0.06, 0.06]
dx = 0.005

[time]
dt = 2e-4
frame_duration = 1e-3
frames = 2

[sand]
youngs_modulus = 1e5

[outputs]
preview = false

[[bodies]]
kind = "sand"
velocity = [0.0, 0.0, -0.5]
[bodies.geometry]
type = "box"
min = [0.02, 0.02, 0.03]
max = [0.04, 0.04, 0.045]
"""
"""A tiny sand-only scene file (2 frames of 5 steps) for the command-line tests."""


def run_with_a_nan_after_step_7(sim, out):
    """Run ``sim`` (a tiny_fluid of 3 frames) into ``out`` with a NaN put into the pressure of cell
    (x=3, y=2, z=4) after step 7; returns the run's result and the text of diverged.txt."""
    import numpy as np

    real_step = sim.step

    def poisoned(n=1):
        for _ in range(n):
            real_step(1)
            if sim.step_count == 7:
                sim.fluid.p[4 + 1, 2 + 1, 3 + 1] = np.nan  # padded array: interior cell + 1

    sim.step = poisoned
    result = sim.run(out=out, progress=False)
    return result, (out / "diverged.txt").read_text()
