"""Single-phase flow validation against closed-form solutions (cpu backend).

* Body-force Poiseuille, H = 32 cells between half-way bounce-back walls, in three orientations:
  u(s) = (g / 2ν) s (H − s), s the distance from the wall (walls half a link outside the first/last node).
  Pass: relative L2 error < 1 % (issue 3). Measured 0.40 % at ν = 0.5: the residual is the O(Δx²)
  error of half-way bounce-back plus the compressibility of p; the 1 % bound leaves a 2.5× margin.
* Taylor–Green vortex (2-D solution in a 3-D box, k_x = k_y = 2π/N): velocity amplitude decays as
  exp(−2νk²t). Measured over the time the amplitude needs to fall to e^{−1/2}. Pass: rate within 1 % at
  N = 48 and observed order ≥ 1.7 between N = 24 and 48 (second order, allowing for the O(Ma²) and
  time-step terms that do not shrink with N; lbm-method note §1g). Measured: +0.35 % at N = 48, order 2.2
  with the unfiltered stored pressure; see the test for the filtered one.
* Couette flow between a resting and a moving wall: linear profile, exact for the lattice to round-off
  up to the slip of the moving-wall bounce-back (which is zero for a linear profile): tolerance 0.5 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid.grid import Boundaries, Face
from couplekit.fluid.solver import FluidParams, FluidSolver


@pytest.fixture(scope="module")
def cpu():
    # one thread: these grids are tiny (≤ 5k cells), so OpenMP barriers would dominate, and on a shared,
    # oversubscribed machine a spinning barrier can cost a whole time slice per kernel launch
    return get_backend("cpu", threads=1)


AXES = {"x": 0, "y": 1, "z": 2}


@pytest.mark.parametrize("flow, walls", [("x", "y"), ("y", "z"), ("z", "x")])
def test_poiseuille_profile_l2_below_one_percent(cpu, flow, walls):
    H, nu = 32, 0.5
    g = 8 * 0.02 * nu / H**2  # centre-line speed 0.02
    shape_xyz = [2, 2, 2]
    shape_xyz[AXES[walls]] = H
    shape = (shape_xyz[2], shape_xyz[1], shape_xyz[0])
    gravity = [0.0, 0.0, 0.0]
    gravity[AXES[flow]] = g
    solver = FluidSolver(cpu, shape, FluidParams(nu_h=nu, gravity=tuple(gravity)), Boundaries.channel(walls))
    # slowest transient mode decays as exp(−π²νt/H²): after 2500 steps by e^{−12}, far below the 1 % bound
    solver.step(2500)
    u = solver.fields()["velocity"][AXES[flow]]
    zyx_axis = 2 - AXES[walls]
    profile = u.mean(axis=tuple(a for a in range(3) if a != zyx_axis))
    s = np.arange(H) + 0.5
    exact = g / (2 * nu) * s * (H - s)
    l2 = np.sqrt(((profile - exact) ** 2).sum() / (exact**2).sum())
    assert l2 < 0.01, f"Poiseuille L2 error {l2:.4f}"
    # the cross-stream velocity stays at round-off
    assert np.abs(solver.fields()["velocity"][AXES[walls]]).max() < 1e-6


def _taylor_green_rate_error(
    cpu, n: int, store_filtered: bool, nu: float = 0.02, u0: float = 0.02, storage: str = "fp32"
) -> float:
    k = 2 * np.pi / n
    c = np.arange(n) + 0.5
    x, y = np.meshgrid(c, c, indexing="xy")  # x varies along the last (contiguous) axis
    vel = np.zeros((3, 2, n, n))
    vel[0] = u0 * np.sin(k * x) * np.cos(k * y)
    vel[1] = -u0 * np.cos(k * x) * np.sin(k * y)
    p = np.broadcast_to(u0**2 / 4 * (np.cos(2 * k * x) + np.cos(2 * k * y)), (2, n, n))
    params = FluidParams(nu_h=nu, store_filtered_pressure=store_filtered)
    solver = FluidSolver(cpu, (2, n, n), params, velocity=vel, pressure=p, storage=storage)
    steps = int(round(0.5 / (2 * nu * k * k)))
    a0 = np.sqrt(solver.diagnostics()["kinetic_energy"])
    solver.step(steps)
    a1 = np.sqrt(solver.diagnostics()["kinetic_energy"])
    return np.log(a0 / a1) / steps / (2 * nu * k * k) - 1.0


@pytest.mark.parametrize("store_filtered, min_order", [(False, 1.7), (True, 1.6)])
def test_taylor_green_decay_rate_and_second_order(cpu, store_filtered, min_order):
    """Unfiltered stored pressure: +0.35 % at N = 48, order 2.2. Stored filtered pressure (the default, what
    keeps 800:1 stable): the filter adds a numerical diffusion of 1/6 lattice unit per step to p (note §0), an
    O(Δx²) term with a large constant; measured +0.53 % at N = 48 and order 1.75 (the note's prototype: 0.67 %,
    1.8), so its order bound is 1.6."""
    e24 = _taylor_green_rate_error(cpu, 24, store_filtered)
    e48 = _taylor_green_rate_error(cpu, 48, store_filtered)
    assert abs(e48) < 0.01, f"decay rate error {e48:+.4f} at N=48"
    order = np.log2(abs(e24 / e48))
    assert order > min_order, f"observed order {order:.2f} (errors {e24:+.4f}, {e48:+.4f})"


def test_couette_moving_wall_gives_linear_profile(cpu):
    H, nu, U = 16, 0.5, 0.02
    b = Boundaries({"y-": Face("wall"), "y+": Face("wall", velocity=(U, 0.0, 0.0))})
    solver = FluidSolver(cpu, (2, H, 2), FluidParams(nu_h=nu), b)
    solver.step(800)  # slowest transient mode exp(−π²νt/H²) = e^{−15}
    profile = solver.fields()["velocity"][0, 0, :, 0]
    exact = U * (np.arange(H) + 0.5) / H
    assert np.abs(profile - exact).max() < 0.005 * U
