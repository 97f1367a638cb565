"""The mixture pressure update (Eq. 39) next to walls: a water column at rest with a frozen sand-bed porosity
profile stays at rest.

A settled bed's porosity has a step right above the floor: the MPM's wall layer keeps the grains one cell
off it, so the first cell holds ε = 0.92 under 0.59 and 0.515 in the bed (the profile of the saturated-bed
scene, couplekit.coupling.scenes.saturated_bed, at 32³).  With the slip term (u − v)·∇ε of Eq. 39 evaluated
with u = Σ f c, the fluid alone (no drag, no sand motion) grew a grid-scale mode at the floor from
round-off (1.5e-5) to NaN by step 1100; with the Eq. 13 velocity it still grew ×2 every 200 steps from
step ~1000; the slip term only in cells away from walls keeps it at round-off (reference.macro_pressure
docstring).  In the coupled saturated bed the first version ended at lattice speed 0.035 after 1000 steps
with φ up to 1.18 and the fluid volume drifting 19 % over 1 s (benchmark run before the fix, docs/fluid-stability.md).

Bound: 5e-5 lattice speed after 1500 steps, 3× the round-off level of the still column without sand
(1.5e-5 measured, the float32 hydrostatic balance); the two rejected forms were at ~1.2e-4 (growing ×2 per 200 steps) and NaN by then.
"""

from __future__ import annotations

import numpy as np

from couplekit.fluid.grid import Boundaries
from couplekit.fluid.solver import FluidParams, FluidSolver
from couplekit.units import Units

BED = [0.92, 0.59, 0.515, 0.515, 0.515, 0.515, 0.515, 0.515, 0.526, 0.77]  # ε per layer from the floor


def _column(backend, shape=(16, 6, 6), nu=1e-3):
    nz, ny, nx = shape
    units = Units(dx=0.005, dt=1e-4)
    g = units.to_lattice(-9.81, "acceleration")
    zc = np.arange(nz) + 0.5
    pressure = np.broadcast_to((abs(g) * (nz - zc))[:, None, None], shape).astype(np.float32)
    params = FluidParams(rho_h=1.0, rho_l=1.0, nu_h=nu, nu_l=nu, gravity=(0.0, 0.0, g))
    fluid = FluidSolver(backend, shape, params, boundaries=Boundaries.channel("xyz"), pressure=pressure,
                        mixture=True, external_force=True)  # fmt: skip
    eps = np.ones(nz)
    eps[: len(BED)] = BED
    host = backend.to_host(fluid.fluid_fraction)
    host[1:-1] = eps[:, None, None]
    host[0], host[-1] = host[1], host[-2]
    fluid.fluid_fraction[...] = backend.asarray(host)
    return fluid


def _max_speed(fluid) -> float:
    u = fluid.backend.to_host(fluid.velocity)[:, 1:-1, 1:-1, 1:-1].astype(np.float64)
    return float(np.sqrt((u**2).sum(axis=0)).max())


def test_water_at_rest_over_a_bed_next_to_the_floor_stays_at_rest(cpu1):
    fluid = _column(cpu1)
    fluid.step(1500)
    speed = _max_speed(fluid)
    assert np.isfinite(speed)
    assert speed < 5e-5, f"max lattice speed {speed:.2e} after 1500 steps (round-off level 1.5e-5)"


def test_slip_term_is_dropped_exactly_in_wall_adjacent_cells():
    """The reference's mask: interior cells with a non-stencil neighbour (walls on every face here)."""
    from couplekit.fluid.grid import build_flags
    from couplekit.fluid.reference import ReferenceOps

    flags, _, _ = build_flags((6, 5, 4), Boundaries.channel("xyz"), None)
    away = ReferenceOps._away_from_walls(flags)
    expected = np.zeros((6, 5, 4), dtype=bool)
    expected[1:-1, 1:-1, 1:-1] = True
    np.testing.assert_array_equal(away, expected)
