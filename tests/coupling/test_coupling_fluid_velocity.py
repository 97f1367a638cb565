"""The drag's fluid velocity: SandFluidCoupler.fluid_velocity reads FluidSolver.current_velocity (a fluid
kernel), which must be exactly what the drag needs — Σ_j f_j c_j of the populations after the last
streaming, under the AA read rule of the next step's parity, without the half-force shift.

The oracle is the NumPy read the coupler used before the kernel existed (:func:`numpy_current_velocity`,
kept here): a host copy of f whose ghosts are filled the way FluidSolver fills them before an odd step,
read with :meth:`couplekit.fluid.reference.ReferenceOps.load`.  Tolerance 2e-6 lattice units: both sum 27
float32 populations of magnitude ≤ 1 (kernel in float32, reference in float64), so they differ by a few
float32 roundings of the sum, ~27 · 6e-8.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.coupling import SandFluidCoupler
from couplekit.coupling.reference import source_index
from couplekit.fluid.grid import Boundaries
from couplekit.fluid.reference import ReferenceOps as FluidReference
from couplekit.fluid.solver import FluidParams, FluidSolver
from couplekit.lattice import C27
from couplekit.sand import SandParams
from couplekit.sand.solver import SandSolver
from couplekit.units import Units

SHAPE = (9, 7, 8)


def numpy_current_velocity(fluid: FluidSolver) -> np.ndarray:
    """Σ_j f_j c_j (3, nz, ny, nx) of the current populations, host float64, by the NumPy read rule."""
    be = fluid.backend
    f = np.asarray(be.to_host(fluid.f))
    parity = fluid.step_count & 1
    if parity:  # periodic ghosts from their image, the others from the nearest interior cell (outflow)
        nz, ny, nx = fluid.shape
        per = [fluid.boundaries.face(a + "-").kind == "periodic" for a in "xyz"]
        iz = source_index(nz, per[2])[:, None, None] + 1
        iy = source_index(ny, per[1])[None, :, None] + 1
        ix = source_index(nx, per[0])[None, None, :] + 1
        f = f[:, iz, iy, ix]
    fi = FluidReference.load(f, be.to_host(fluid.flags), be.to_host(fluid.velocity), parity)
    u = np.einsum("jd,j...->d...", C27.astype(np.float64), fi)
    return u * (be.to_host(fluid.flags)[1:-1, 1:-1, 1:-1] == 0)[None]


def _fluid(backend) -> FluidSolver:
    """Walls in z, periodic x and y, a solid block, a swirling start, gravity and a body force: every read
    rule (pulled, bounced off walls and the block, wrapped through periodic ghosts) is exercised."""
    rng = np.random.default_rng(3)
    nz, ny, nx = SHAPE
    solid = np.zeros(SHAPE, bool)
    solid[3:5, 2:4, 3:5] = True
    vel = 0.03 * rng.standard_normal((3, *SHAPE))
    fl = FluidSolver(backend, SHAPE, FluidParams(nu_h=0.05, gravity=(0.0, 1e-4, -2e-4)),
                     boundaries=Boundaries.channel("z"), solid=solid, velocity=vel, mixture=True,
                     external_force=True)  # fmt: skip
    force = np.zeros((3, nz + 2, ny + 2, nx + 2), np.float32)
    force[0, 1:-1, 1:-1, 1:-1] = 1e-4 * rng.standard_normal(SHAPE)
    fl.force[...] = backend.asarray(force)
    return fl


@pytest.mark.parametrize("backend_name", ["cpu", "numpy"])
@pytest.mark.parametrize("steps", [4, 5])
def test_current_velocity_matches_the_numpy_read(cpu, backend_name, steps):
    be = cpu if backend_name == "cpu" else get_backend("numpy")
    fl = _fluid(be)
    fl.step(steps)
    expected = numpy_current_velocity(fl)
    got = be.to_host(fl.current_velocity())[:, 1:-1, 1:-1, 1:-1]
    assert np.abs(expected).max() > 1e-3  # a real, non-trivial flow
    np.testing.assert_allclose(got, expected, atol=2e-6, rtol=0)
    # it is the state "now": the Guo-shifted post-collision field of the last step differs from it
    shifted = be.to_host(fl.velocity)[:, 1:-1, 1:-1, 1:-1] * (be.to_host(fl.flags)[1:-1, 1:-1, 1:-1] == 0)
    assert np.abs(shifted - expected).max() > 1e-5


def test_coupler_fluid_velocity_is_the_current_velocity(cpu):
    """The coupler's ``fluid_u`` after :meth:`fluid_velocity` equals the NumPy read on interior fluid cells and
    is zero on solid cells (the drag must not exchange momentum there)."""
    units = Units(dx=0.005, dt=1e-4)
    fl = _fluid(cpu)
    pos = (np.array([[4.0], [3.5], [6.5]]) * units.dx).repeat(8, axis=1) + 1e-4 * np.arange(8)
    sand = SandSolver(cpu, SHAPE, units.dx, units.dt, SandParams(), pos, 1e-8)
    coupler = SandFluidCoupler(sand, fl, units)
    fl.step(3)
    coupler.fluid_velocity()
    got = cpu.to_host(coupler.fluid_u)[:, 1:-1, 1:-1, 1:-1]
    np.testing.assert_allclose(got, numpy_current_velocity(fl), atol=2e-6, rtol=0)
    assert (got[:, 3:5, 2:4, 3:5] == 0).all()
