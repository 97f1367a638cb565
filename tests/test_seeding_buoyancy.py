"""Simulation's sand seeding (particle volume = packing fraction × cell volume / ppc, mass = grain density ×
particle volume): the initial sand fraction inside a body is the packing fraction, and in water (a scene built
from TOML) sand lighter than water rises while sand heavier than water sinks (paper 000 Fig. 8, Eq. 31)."""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.scene import Scene
from couplekit.simulation import Simulation

DX = 0.01
BALL_Z = 0.09  # ball centre, m (9 cells up in a 24-cell tank filled with water to 18 cells)
BALL_R = 0.03

# A closed 12 x 12 x 24 tank, water to 18 cells under air (800:1), a submerged sand ball of radius 3 cells.
# Lattice numbers: g_lat = 9.81 dt²/dx = 3.9e-5; water viscosity 1e-3 (lattice), ten times the paper's, as in
# tests/coupling/test_coupled_validation.py (at 1e-4 the fluid core is not stable in a closed tank).
TANK = """
[scene]
name = "ball_in_tank"

[domain]
size = [0.12, 0.12, 0.24]
dx = {dx}

[time]
dt = 2e-4
frame_duration = 0.01
frames = 4

[fluid]
phases = 2
water_lattice_viscosity = 1e-3
air_lattice_viscosity = 1e-2
surface_tension = 0.073

[sand]
density = {density}
youngs_modulus = 1e5
particles_per_cell = 8
{packing}

[[bodies]]
kind = "water"
[bodies.geometry]
type = "box"
min = [0.0, 0.0, 0.0]
max = [0.12, 0.12, 0.18]

[[bodies]]
kind = "sand"
name = "ball"
[bodies.geometry]
type = "sphere"
center = [0.06, 0.06, {z}]
radius = {r}

[outputs]
preview = false
"""


def _tank(tmp_path, density: float, packing: float | None = None, radius: float = BALL_R) -> Simulation:
    text = TANK.format(
        dx=DX, density=density, z=BALL_Z, r=radius, packing=f"packing_fraction = {packing}" if packing else ""
    )
    path = tmp_path / f"tank_{density:g}.toml"
    path.write_text(text)
    return Simulation(Scene.load(path), backend="cpu", log=None)


@pytest.mark.parametrize("packing", [None, 0.5])
def test_initial_sand_fraction_inside_a_body_is_the_packing_fraction(tmp_path, packing):
    """Eq. 25 rasterised from the seeded particles (before any motion): on the nodes at least 1.5 cells
    inside the ball (the quadratic B-spline's reach, so every contributing sub-cell is seeded), ε has mean
    ε0 within 1 % and every node within 10 % of ε0. Why these bounds: the jitter (0.5 sub-cell spacings,
    the default) makes ε fluctuate about ε0; on a 12³ block at 8 particles per cell, an independent
    rasterisation gave a node standard deviation of 2.3 % and extremes of −6.2 / +7.5 %, and the mean of the
    ~65 interior nodes has a standard error of ~0.3 %. The total particle volume is ε0 × the seeded
    sub-cells' volume, the total mass the grain density × that, exactly (float32)."""
    eps0 = packing or 0.6
    radius = 0.04  # 4 cells: ~65 nodes lie 1.5 cells inside
    sim = _tank(tmp_path, 1500.0, packing, radius)
    sim.sand.p2g()
    eps = sim.sand.fields()["sand_fraction"]
    nz, ny, nx = eps.shape
    z, y, x = np.meshgrid(*((np.arange(n) + 0.5) * DX for n in (nz, ny, nx)), indexing="ij")
    inner = np.sqrt((x - 0.06) ** 2 + (y - 0.06) ** 2 + (z - BALL_Z) ** 2) < radius - 1.5 * DX
    assert inner.sum() >= 50
    e = eps[inner]
    assert abs(e.mean() / eps0 - 1) < 0.01, e.mean()
    assert np.abs(e / eps0 - 1).max() < 0.10, (e.min(), e.max())
    p = sim.particles()
    sub = (DX / 2) ** 3
    np.testing.assert_allclose(p["volume"], eps0 * sub, rtol=1e-6)
    np.testing.assert_allclose(p["mass"], 1500.0 * eps0 * sub, rtol=1e-6)


@pytest.mark.parametrize(("density", "direction"), [(600.0, 1), (950.0, 1), (1500.0, -1)])
def test_submerged_ball_rises_when_lighter_than_water_and_sinks_when_heavier(tmp_path, density, direction):
    """A ball released at rest 9 cells under the surface: after 400 steps (t = 0.08 s) its centre has moved
    up (600, 950 kg/m³) or down (1500 kg/m³), and it is still moving that way.

    Bounds from the drag-free motion d = ½ a t², a = (ϱ − ρ_w) g / ϱ (the grains' weight against Eq. 31's
    buoyancy): 21, 1.7 and −10.5 mm. Drag only slows the ball (the water has no other way to push it), so
    |dz| ≤ 1.02 d (2 % for the float32 sums and the first step's start), and it must reach 30 % of d
    (measured: 44 %, 64 % and 69 %; the water moves along with the ball, so the slip, and with it the drag,
    stays below the terminal one). The old seeding (particle volume (dx/2)³, ε clamped at 0.64, mass
    ϱ V_cell) fails this: 950 sank (weight 950 V_cell g > buoyancy 640 V_cell g) and 600 could move at most
    ½ (40/600) g t² = 2.1 mm < 0.3 × 21 mm."""
    sim = _tank(tmp_path, density)
    z0 = sim.particles()["x"][2].mean()
    steps, dt = 400, 2e-4
    sim.step(steps)
    p = sim.particles()
    dz = float(p["x"][2].mean() - z0)
    vz = float(p["v"][2].mean())
    free = -0.5 * (density - 1000.0) * 9.81 / density * (steps * dt) ** 2
    print(f"{density}: dz {1e3 * dz:.3f} mm ({dz / free:.2f} of drag-free), vz {1e3 * vz:.1f} mm/s")
    assert np.isfinite(p["x"]).all()
    assert direction * vz > 0, vz
    assert 0.3 < dz / free < 1.02, (dz, free)
