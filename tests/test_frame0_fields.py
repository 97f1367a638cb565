"""A run's frame 0 shows the sand: before the first step no P2G has run, and ``fields()`` (hence
``fields_0000.vti``) had sand_fraction 0, no sand velocity and, coupled, a porosity of 1 beside particles that
exist. They now come from the seeded particles (SandSolver.seeded_grid, SandFluidCoupler.fields): the sand
fraction is the one the first step's P2G computes from the same positions, the porosity the one its fractions
stage computes (no uptake yet), and the sand velocity the particles' (one step of gravity from the first
step's grid velocity)."""

from __future__ import annotations

import numpy as np
import pytest

import couplekit as ck


@pytest.mark.parametrize(
    "name", ["sand_drop_small", "fig13_sand_drop_beaker_small", "fig10_retention_small", "fig17_wet_column_small"]
)
def test_frame_zero_shows_the_seeded_sand(name):
    sim = ck.Simulation(ck.Scene.load(f"examples/{name}.toml"), "cpu", log=None)
    dt, g = sim.scene.time.dt, np.linalg.norm(sim.scene.domain.gravity)
    before = sim.fields()
    assert before["sand_fraction"].max() > 0.3
    sim.step(1)
    after = sim.fields()
    np.testing.assert_allclose(before["sand_fraction"], after["sand_fraction"], atol=1e-6)
    # the particles' velocity on the grid: the first step's grid velocity is it plus one step of gravity (and the
    # drag and stress impulses of that step)
    sand = before["sand_fraction"] > 0.05
    speed0 = np.abs(before["sand_velocity"][:, sand]).max()
    assert np.abs(after["sand_velocity"] - before["sand_velocity"])[:, sand].max() <= 2.0 * g * dt + 0.05 * speed0
    if "fluid_fraction" in before:  # coupled: the porosity of Eq. 54 (measured within 1e-4 of the first step's)
        assert before["fluid_fraction"].min() < 0.7
        np.testing.assert_allclose(before["fluid_fraction"], after["fluid_fraction"], atol=1e-3)
        np.testing.assert_allclose(before["water"], after["water"], atol=0.1)  # ε φ: φ moves in the step (0.07)
