"""Two-phase validation of the coupled flow + phase field (FluidSolver, cpu backend, one thread).

* Static droplet at density ratio 1000 (issue 3): Laplace jump p_in − p_out = 2σ/R within 5 %, with R the
  radius of the φ = ½ contour, and spurious currents max|u| < 1e-3 (lattice). ξ = 5 cells (lbmpy's
  default): at ξ = 4 the discrete stencils under-resolve the interface and the jump came out 6–9 % low,
  at ξ = 5 it is 3 % low (measured 0.966–0.971 of 2σ/R between 500 and 1000 steps, max|u| ≈ 6e-4 with the
  stored pressure filter, 3e-4 without).
  p_in / p_out are averaged over φ > 0.999 / φ < 0.001, far from the interface.
* Two layers at 800:1 at rest under gravity (paper regime ν_h = 1e-4, ν_l = 1e-2, with surface tension):
  the time-averaged pressure gradient equals ρg in each phase within 2 % and the interface stays put.
  Measured: within 0.1 % (heavy) and 0.3 % (light) (the pressure filter and gradient extrapolate linearly
  into walls, so the hydrostatic profile is a discrete equilibrium); with σ = 1e-3 as well (session 23: 1.0000 heavy,
  1.0024 light; early on the heavy slope had come out 3 % off with σ, an open question the later surface-tension
  changes closed, found by a probe); the remaining acoustic oscillation (ν_h = 1e-4 hardly
  damps it) is averaged out over 500 steps (≈ 2 periods of the box's lowest mode, 2·64/c_s ≈ 222 steps).
* Water column collapse at 800:1, ν_h = 1e-4, ν_l = 1e-2: stays finite, max lattice speed < 0.3, phase
  volume drift < 0.5 % with the controller on. CI runs 32³ for 600 steps; the issue's 64³ × 2000 steps
  case is marked slow (≈ 3 minutes on 2 shared cores) and run with the benchmarks.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid.grid import Boundaries
from couplekit.fluid.solver import FluidParams, FluidSolver


@pytest.fixture(scope="module")
def cpu():
    return get_backend("cpu", threads=1)


def static_droplet(cpu, n: int = 40, radius: float = 12.0, steps: int = 800, storage: str = "fp32") -> dict:
    """The static droplet of the test below: {jump over 2σ/R, R, max|u|, volume drift} after ``steps``."""
    width, sigma = 5.0, 0.005
    c = np.arange(n) + 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt((x - n / 2) ** 2 + (y - n / 2) ** 2 + (z - n / 2) ** 2)
    phi = 0.5 * (1 + np.tanh(2 * (radius - r) / width))
    params = FluidParams(rho_h=1.0, rho_l=1e-3, nu_h=0.05, nu_l=0.05, sigma=sigma, mobility=0.05, width=width)
    solver = FluidSolver(cpu, (n, n, n), params, phi=phi, storage=storage)
    solver.step(steps)
    f = solver.fields()
    p, ph = f["pressure"], f["phi"]
    jump = p[ph > 0.999].mean() - p[ph < 0.001].mean()
    line = ph[n // 2 - 1 : n // 2 + 1, n // 2 - 1 : n // 2 + 1, n // 2 :].mean(axis=(0, 1))
    r_half = float(np.interp(0.5, line[::-1], (c[n // 2 :] - n / 2)[::-1]))
    return {
        "jump_ratio": float(jump / (2 * sigma / r_half)),
        "radius": r_half,
        "max_speed": float(np.abs(f["velocity"]).max()),
        "volume_drift": float(solver.diagnostics()["fluid_volume_drift"]),
    }


def test_static_droplet_laplace_jump_and_spurious_currents(cpu):
    d = static_droplet(cpu)
    assert abs(d["jump_ratio"] - 1) < 0.05, f"Laplace jump {d['jump_ratio']:.4f} of 2σ/R (R = {d['radius']:.2f})"
    assert d["max_speed"] < 1e-3
    assert abs(d["volume_drift"]) < 1e-5  # conservative phase field, no source


def laplace_cylinder(cpu, radius: float, width: float, steps: int = 4000, average: int = 1500) -> float:
    """A water cylinder of ``radius`` cells along x in a periodic 2 × 4R × 4R slab (1000:1, ν = 0.05,
    σ = 0.005, M = 0.05): the pressure jump over σ / R, R at the φ = ½ contour, averaged every 25 steps over the
    last ``average`` steps (the jump rings acoustically by ~1 % at R = 32)."""
    sigma, n = 0.005, int(4 * radius)
    c = np.arange(n) + 0.5
    y, x = np.meshgrid(c, c, indexing="ij")
    r = np.broadcast_to(np.sqrt((x - n / 2) ** 2 + (y - n / 2) ** 2), (2, n, n))
    phi = 0.5 * (1 + np.tanh(2 * (radius - r) / width))
    params = FluidParams(rho_h=1.0, rho_l=1e-3, nu_h=0.05, nu_l=0.05, sigma=sigma, mobility=0.05, width=width)
    solver = FluidSolver(cpu, (2, n, n), params, phi=phi)
    solver.step(steps - average)
    jumps = []
    for _ in range(average // 25):
        solver.step(25)
        f = solver.fields()
        p, ph = f["pressure"], f["phi"]
        jumps.append(p[ph > 0.99].mean() - p[ph < 0.01].mean())
    line = ph[0, n // 2 - 1 : n // 2 + 1, n // 2 :].mean(axis=0)
    r_half = float(np.interp(0.5, line[::-1], (c[n // 2 :] - n / 2)[::-1]))
    return float(np.mean(jumps) / (sigma / r_half))


@pytest.mark.parametrize(("radius", "width"), [(24.0, 3.0), (24.0, 4.0), (24.0, 5.0), (16.0, 4.0)])
def test_laplace_jump_of_a_large_cylinder_at_the_scenes_widths(cpu, radius, width):
    """The Laplace jump σ/R of a cylinder of R = 24 cells (a nearly flat interface, W/R <= 0.21) at the
    interface widths scenes use (default 4). With the continuum coefficients β = 12σ/W, κ = 3σW/2 the lattice
    carried 0.866, 0.918, 0.947 of it at W = 3, 4, 5 (session 21; flat limit 0.863, 0.912, 0.940): the
    coefficients now carry the lattice's correction (phasefield_layout.discrete_surface_tension_factor).
    Bound 1.5 % (the fit's residual is under 0.5 %, the jump's curvature term +0.2 to +0.7 % at R = 24). At the
    default width a second resolution, R = 16 (W/R = 0.25): 0.922 before, 1.0069 now."""
    assert laplace_cylinder(cpu, radius, width) == pytest.approx(1.0, abs=0.015)


@pytest.mark.parametrize("sigma", [0.0, 1e-3])
def test_two_layers_800_to_1_hydrostatic(cpu, sigma):
    nz, width, g, rho_l = 64, 4.0, -1e-5, 1.0 / 800.0
    zc = np.arange(nz) + 0.5
    phi1 = 0.5 * (1 + np.tanh(2 * (nz / 2 - zc) / width))
    rho = rho_l + (1 - rho_l) * phi1
    p = np.zeros(nz)  # hydrostatic start (trapezoid rule from the top); the solver must keep it
    for k in range(nz - 2, -1, -1):
        p[k] = p[k + 1] - 0.5 * (rho[k] + rho[k + 1]) * g
    shape = (nz, 4, 4)
    params = FluidParams(
        rho_h=1.0, rho_l=rho_l, nu_h=1e-4, nu_l=1e-2, gravity=(0.0, 0.0, g), sigma=sigma, mobility=0.02, width=width
    )
    solver = FluidSolver(
        cpu,
        shape,
        params,
        Boundaries.channel("z"),
        phi=np.broadcast_to(phi1[:, None, None], shape),
        pressure=np.broadcast_to(p[:, None, None], shape),
    )
    solver.step(1500)
    mean_p = np.zeros(nz)
    for _ in range(50):
        solver.step(10)
        mean_p += solver.fields()["pressure"].mean(axis=(1, 2)) / 50
    heavy, light = slice(6, nz // 2 - 8), slice(nz // 2 + 8, nz - 6)
    slope_h = np.polyfit(zc[heavy], mean_p[heavy], 1)[0] / (1.0 * g)
    slope_l = np.polyfit(zc[light], mean_p[light], 1)[0] / (rho_l * g)
    assert abs(slope_h - 1) < 0.02, f"heavy phase dp/dz = {slope_h:.4f} ρ_h g"
    assert abs(slope_l - 1) < 0.02, f"light phase dp/dz = {slope_l:.4f} ρ_l g"
    ph = solver.fields()["phi"].mean(axis=(1, 2))
    z_interface = np.interp(0.5, ph[::-1], zc[::-1])
    assert abs(z_interface - nz / 2) < 0.05


def _column_collapse(cpu, n: int, steps: int) -> dict[str, float]:
    c = np.arange(n) + 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    width = 4.0
    # water block in the corner x < n/2, z < n/2 (all y), smooth edges
    dist = np.minimum(n / 2 - x, n / 2 - z)
    phi = 0.5 * (1 + np.tanh(2 * dist / width))
    g = -0.5 * (0.05**2) / n  # free-fall speed over the column height ≈ 0.05 (low Mach)
    params = FluidParams(
        rho_h=1.0, rho_l=1.0 / 800.0, nu_h=1e-4, nu_l=1e-2, gravity=(0.0, 0.0, g), sigma=1e-4, mobility=0.02,
        width=width, eta=1.0,
    )  # fmt: skip
    solver = FluidSolver(cpu, (n, n, n), params, Boundaries.channel("xyz"), phi=phi)
    peak = 0.0
    for _ in range(steps // 50):
        solver.step(50)
        d = solver.diagnostics()
        assert np.isfinite(d["max_lattice_speed"]) and np.isfinite(d["fluid_volume"])
        peak = max(peak, d["max_lattice_speed"])
    d = solver.diagnostics()
    d["peak_speed"] = peak
    return d


def test_column_collapse_is_stable_ci_size(cpu):
    d = _column_collapse(cpu, 32, 600)
    assert d["peak_speed"] < 0.3
    assert d["max_lattice_speed"] > 1e-3  # the column really collapses
    assert abs(d["fluid_volume_drift"]) < 0.005


@pytest.mark.slow
def test_column_collapse_is_stable_64_cubed_2000_steps():
    d = _column_collapse(get_backend("cpu"), 64, 2000)
    assert d["peak_speed"] < 0.3
    assert abs(d["fluid_volume_drift"]) < 0.005


def test_water_jet_into_air_800_to_1_volume_inflow(cpu):
    """Inflow face carrying φ = 1 at u_in into air (800:1), walls around, outflow downstream. The volume of
    water grows at the inflow rate u_in·A (less the no-slip corners, cf. the single-phase inflow test where
    the plug delivers 0.97 u_in·A on 12 rows; here 8×8 rows): measured 0.93 u_in·A t over 200 steps;
    tolerance 10 %. The jet starts from a smooth water plug (tanh, ξ = 4) moving at u_in; the abrupt start into air at
    rest is covered by test_inflow_front.py (the inflow's phase value enters along the interface profile)."""
    from fluid_states import JET_SHAPE, JET_SPEED, water_jet_into_air

    n, u_in = JET_SHAPE, JET_SPEED
    solver = water_jet_into_air(cpu)
    v0 = solver.diagnostics()["fluid_volume"]
    solver.step(200)
    d = solver.diagnostics()
    assert np.isfinite(d["fluid_volume"]) and d["max_lattice_speed"] < 0.1
    inflow = (d["fluid_volume"] - v0) / (u_in * n[0] * n[1] * 200)
    assert 0.9 < inflow < 1.02, f"water inflow {inflow:.3f} u_in A"
