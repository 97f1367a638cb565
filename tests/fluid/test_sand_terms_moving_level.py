"""A requirement on the two-phase form of Eq. 39's sand terms (couplekit.fluid.reference.sand_pressure_terms) that
any new form must meet (docs/fluid-stability.md, 'The slip term at a small time step', sessions 27–28): a water
level moving through a bed at rest raises no pressure.

A bed of uniform porosity at rest (v = 0) and a flat water level rising or falling through it at u: the water
fills or leaves the pores it reaches, the mixture stays incompressible, so the sand's terms must vanish. Session
27's effective-porosity form (φ [(1 − ε)∇·v − v·∇ε] + u·∇ε')/ε', ε' = 1 − φ(1 − ε), carries −(1 − ε) u·∇φ/ε' there:
a pressure at every wetting front inside sand, which made Fig. 6's raindrop diverge in the dry bed ahead of the
drop. The form on main (the φ-weighted slip term) gives exactly 0 there: no ∇ε, no sand velocity."""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.fluid.reference import sand_pressure_terms


@pytest.mark.parametrize("porosity", [0.38, 0.45, 0.7])
@pytest.mark.parametrize("width", [2.0, 4.0, 8.0])
@pytest.mark.parametrize("speed", [-0.02, 0.005, 0.05])
def test_a_water_level_moving_through_a_bed_at_rest_raises_no_pressure(porosity, width, speed):
    shape = (40, 6, 5)  # padded (nz, ny, nx), every cell fluid
    z = np.arange(shape[0], dtype=np.float64)[:, None, None] * np.ones(shape)
    phi = 0.5 * (1.0 - np.tanh(2.0 * (z - 20.0) / width))  # water below z = 20 (phasefield_layout.tanh_profile)
    eps = np.full(shape, porosity)
    u = np.zeros((3,) + shape)
    u[2] = speed
    u[0] = 0.3 * speed  # and along the level
    v = np.zeros((3,) + shape)
    slip = np.ones(shape, np.uint8)
    flags = np.zeros(shape, np.uint8)
    terms = sand_pressure_terms(u, phi, eps, v, slip, flags, True)
    assert np.abs(terms).max() == 0.0
    # the same bed with sand moving (a check that the terms are not zero for another reason): the sand flux's
    # divergence counted in the water, φ (1 − ε) ∇·v / ε, where the sand velocity varies
    v[2] = 0.01 * np.sin(2 * np.pi * z / 20.0)
    moving = sand_pressure_terms(u, phi, eps, v, slip, flags, True)
    assert np.abs(moving[2:-2]).max() > 1e-4
