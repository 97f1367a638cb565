"""The coupled stability cases of issue 5 at about 32³, shared by the long tests
(tests/coupling/test_long_stability.py) and the benchmark (benchmarks/coupled_stability.py).

Cases (couplekit.coupling.scenes, cpu backend): sand balls of 600, 950, 1500 and 2500 kg/m³ released above a
pool, a 1500 kg/m³ ball hitting the water at 3 m/s, and a fully saturated 2500 kg/m³ bed.  dx = 5 mm,
Δt = 1e-4 s (10,000 steps are 1 s of simulated time); Young's modulus 1e5 Pa.
"""

from __future__ import annotations

from ..backend import Backend
from .scenes import CoupledScene, sand_ball_into_water, saturated_bed

__all__ = ["CASES", "SCENE_CLOSURES", "stability_case"]

CASES = ("ball_600", "ball_950", "ball_1500", "ball_2500", "impact_3mps", "saturated_bed")
SCENE_CLOSURES = {"smagorinsky": 0.1, "odd_lambda": 0.015}
"""The fluid closures scenes default to (docs/fluid-stability.md)."""


def stability_case(
    case: str,
    backend: Backend,
    shape: tuple[int, int, int] = (32, 32, 32),
    nu: float = 1e-4,
    closures: dict | None = None,
    timing: bool = False,
) -> CoupledScene:
    """Build stability ``case`` (one of :data:`CASES`) on ``shape`` cells with water lattice viscosity ``nu``
    and the fluid ``closures`` (default :data:`SCENE_CLOSURES`)."""
    common = {"nu_h": nu, "youngs_modulus": 1e5, "timing": timing, **(SCENE_CLOSURES if closures is None else closures)}
    r = min(shape) / 6  # leaves room above the pool for the drop at 32³
    if case.startswith("ball_") and case in CASES:
        return sand_ball_into_water(backend, shape, density=float(case.split("_")[1]), radius=r, **common)
    if case == "impact_3mps":
        depth = 0.45 * shape[0]
        return sand_ball_into_water(backend, shape, density=1500.0, radius=r, impact_speed=3.0,
                                    centre_height=depth + r + 1.5, **common)  # fmt: skip
    if case == "saturated_bed":
        return saturated_bed(backend, shape, density=2500.0, bed_height=0.3 * shape[0], water_depth=0.7 * shape[0],
                             **common)  # fmt: skip
    raise ValueError(f"unknown stability case {case!r}; choose from {', '.join(CASES)}")
