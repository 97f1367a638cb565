"""The mixture pressure update (Eq. 39) with moving sand at low viscosity (request from the coupling work):
a single-phase box with walls and a prescribed ε_s = 0.5 ball moving down at 0.01 cells/step, no drag,
blew up at ~670 steps at ν = 0.02 (stable at ν = 0.1).

Why (measured, /tmp experiments recorded here): the sand terms only *seed* it.  With the pressure update
run on the unfiltered p (FluidParams.store_filtered_pressure=False, the force alone seeing p̄):

* keeping only ε_s ∇·v, or only (u − v)·∇ε, or dropping the u in (u − v) (no feedback through the slip),
  each still grows at the same rate (e-folding ≈ 85 steps) — no single sand term is the cause;
* the plain single-phase fluid, no sand, no ε, started from 0.003 lattice-unit white noise, blows up the
  same way at ν = 0.02 (~800 steps), and not at ν = 0.1.
So the instability is the velocity-based pressure evolution itself: p is advanced from 1 − Σf, whose
grid-scale part the 27-point stencils of the force barely see (the filter passes 1/27 of the (π, π, π)
mode and the isotropic gradient none), so a grid-scale pressure mode grows undamped unless the viscosity
damps the populations that feed it.  The fix is the fluid module's stored filter (c1de455: p := p̄ every
step, paper Eq. 40 "a filter is applied to the pressure field"), which damps exactly those modes; it is
the default.  This test pins the coupled case: stable with it, unstable without it (so it can fail).
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.fluid.grid import Boundaries
from couplekit.fluid.solver import FluidParams, FluidSolver

SHAPE = (24, 12, 12)
RADIUS, SPEED, NU = 3.5, 0.01, 0.02


def _run(backend, store: bool, steps: int) -> list[float]:
    nz, ny, nx = SHAPE
    zz, yy, xx = np.meshgrid(np.arange(nz) + 0.5, np.arange(ny) + 0.5, np.arange(nx) + 0.5, indexing="ij")
    fl = FluidSolver(backend, SHAPE, FluidParams(nu_h=NU, store_filtered_pressure=store),
                     boundaries=Boundaries.channel("xyz"), mixture=True)  # fmt: skip
    speeds = []
    for n in range(steps):
        d = np.sqrt((xx - nx / 2) ** 2 + (yy - ny / 2) ** 2 + (zz - (17.0 - SPEED * n)) ** 2)
        es = 0.5 * np.clip(RADIUS + 0.5 - d, 0.0, 1.0)
        fl.fluid_fraction[1:-1, 1:-1, 1:-1] = 1.0 - es
        fl.sand_velocity[2, 1:-1, 1:-1, 1:-1] = np.where(es > 0, -SPEED, 0.0)
        fl.step(1)
        if n % 50 == 49:
            u = fl.velocity[:, 1:-1, 1:-1, 1:-1]
            speeds.append(
                float(np.sqrt((u.astype(np.float64) ** 2).sum(axis=0)).max()) if np.isfinite(u).all() else np.inf
            )
            if speeds[-1] > 0.3:
                break
    return speeds


@pytest.mark.parametrize("store", [True, False])
def test_moving_sand_ball_at_low_viscosity(cpu, store):
    """Stored filter: 700 steps, max speed ≤ 0.01 (the ball moves at 0.01; the displaced flow around it is
    of that order) and not growing (last ≤ 1.5 × the max of the first half).  Unfiltered storage: the
    speed exceeds 20× the ball's speed within the same 700 steps (measured here: stored 0.0029–0.0038 all
    along; unfiltered 0.004 until step 200, then ×1.7 per 50 steps: 0.21 at step 600, 0.35 at 650)."""
    speeds = _run(cpu, store, 700)
    if store:
        assert max(speeds) < 0.01, speeds
        assert speeds[-1] <= 1.5 * max(speeds[: len(speeds) // 2]), speeds
    else:
        assert max(speeds) > 20 * SPEED, speeds
