"""The fluid and sand solvers on each kernel backend against the NumPy reference solvers: the solver-level
check scripts/gpu_check.sh runs on the cuda backend (COUPLEKIT_TEST_BACKEND=cuda); here it runs on cpu and
cpu-device.  Small scenes: a 5x6x7 two-phase jet with walls, a 12x12x16 falling sand block."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid.solver import FluidSolver
from couplekit.sand import DomainWalls, SandParams
from couplekit.sand.seeding import seed_box
from couplekit.sand.solver import SandSolver

sys.path.insert(0, str(Path(__file__).parent / "fluid"))
from test_fluid_solver import JET, _solver  # noqa: E402


def _fluid(backend, two_phase: bool) -> FluidSolver:
    """The jet-in-a-channel state of tests/fluid/test_fluid_solver.py (one builder for both files)."""
    return _solver(backend, JET, two_phase=two_phase)


@pytest.mark.parametrize("two_phase", [False, True], ids=["single", "two_phase"])
def test_fluid_solver_matches_reference(solver_backend, two_phase):
    """9 steps (both parities, inflow, outflow, moving wall) agree with the float64 reference to the float32
    round-off growth tests/fluid/test_fluid_solver.py allows (5e-6 single phase, 5e-5 two-phase)."""
    tol = 5e-5 if two_phase else 5e-6
    a, b = _fluid(get_backend("numpy"), two_phase), _fluid(solver_backend, two_phase)
    a.step(9)
    b.step(9)
    fa, fb = a.fields(), b.fields()
    for key in ("velocity", "pressure") + (("phi",) if two_phase else ()):
        np.testing.assert_allclose(fb[key], fa[key], rtol=0, atol=tol, err_msg=f"{key} on {solver_backend.name}")
    assert np.abs(fa["velocity"]).max() > 1e-3  # the flow moved: the comparison is not of two resting states


def test_sand_solver_matches_reference(solver_backend):
    """10 steps of a falling block hitting the floor (most of it yields) agree with the reference solver as in
    tests/sand/test_solver.py: 1e-6 m in x, 1e-4 m/s in v, 1e-4 in F."""
    dx = 0.01
    body = seed_box((0.04, 0.04, 0.025), (0.10, 0.08, 0.09), dx, ppc=2, jitter=0.5, seed=5)
    kw = dict(velocities=(0.3, 0.0, -1.0), walls=DomainWalls.uniform("separate", 0.5))
    a = SandSolver(solver_backend, (12, 12, 16), dx, 1e-4, SandParams(), body.x, body.volume, **kw)
    b = SandSolver("numpy", (12, 12, 16), dx, 1e-4, SandParams(), body.x, body.volume, **kw)
    a.step(10)
    b.step(10)
    pa, pb = a.particles(), b.particles()
    assert np.max(np.abs(pa["x"] - pb["x"])) < 1e-6
    assert np.max(np.abs(pa["v"] - pb["v"])) < 1e-4
    assert np.max(np.abs(pa["F"] - pb["F"])) < 1e-4
    assert np.max(np.abs(pb["v"])) > 0.5  # still falling / impacting: not a trivial state
