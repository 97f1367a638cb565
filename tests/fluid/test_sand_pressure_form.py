"""The form of Eq. 39's porosity terms (couplekit.fluid.reference.sand_pressure_terms; session 27): two-phase,
(φ [(1 − ε) ∇·v − v·∇ε] + u·∇ε') / ε' with the effective porosity ε' = 1 − φ (1 − ε). Checked on random padded
states (tests/fluid/fluid_states.py): in water it is the paper's form, in air it vanishes, the fluid's part is
u·∇ε'/ε' with ∇ε' the Eq. 18 gradient of the ε' field itself, and the parts sum to the whole. The kernels against
this reference: tests/coupling/test_coupling_kernels.py, tests/fluid/test_lbm_kernels.py."""

from __future__ import annotations

import numpy as np
import pytest
from fluid_states import BOUNDARY_SETS, random_state

from couplekit.fluid.reference import (
    effective_porosity,
    interior,
    isotropic_gradient,
    sand_pressure_terms,
    slip_fluid_term,
)


def _state(seed: int, boundaries: str = "periodic") -> dict:
    return random_state(seed, BOUNDARY_SETS[boundaries], obstacle=boundaries != "periodic")


def _terms(s: dict, phi, with_u: bool = True, two_phase: bool = True) -> np.ndarray:
    u = s["velocity"] if with_u else None
    return sand_pressure_terms(u, phi, s["eps"], s["sand_v"], s["slip"], s["flags"], two_phase)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("boundaries", ["periodic", "mixed"])
def test_in_water_the_two_phase_terms_are_the_papers(seed, boundaries):
    """φ = 1 everywhere: ε' = ε, and the terms are the paper's ((1 − ε) ∇·v + (u − v)·∇ε) / ε (the single-phase
    form), to round-off."""
    s = _state(seed, boundaries)
    water = np.ones_like(s["phi"])
    np.testing.assert_allclose(_terms(s, water), _terms(s, water, two_phase=False), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("seed", [1, 2])
def test_in_air_sand_changes_no_pressure(seed):
    """φ ≤ 0 everywhere (φ is clamped): ε' = 1, and both parts vanish whatever the sand and the fluid do."""
    s = _state(seed)
    air = np.full_like(s["phi"], -0.01)
    assert np.abs(_terms(s, air)).max() == 0.0


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("boundaries", ["periodic", "mixed"])
def test_the_fluid_part_is_u_dot_grad_of_the_effective_porosity_and_the_parts_sum(seed, boundaries):
    """u·∇ε'/ε' in the slip cells, ∇ε' the Eq. 18 gradient of the padded ε' field (not the product rule
    φ∇ε − (1 − ε)∇φ, which differs at second order), 0 elsewhere; and the whole is that part plus the terms
    without u."""
    s = _state(seed, boundaries)
    e_eff = effective_porosity(s["eps"], s["phi"])
    assert e_eff.shape == s["eps"].shape
    np.testing.assert_allclose(e_eff, 1.0 - np.clip(s["phi"], 0, 1) * (1.0 - s["eps"].astype(np.float64)))
    grad = isotropic_gradient(e_eff, s["flags"])
    u = interior(s["velocity"]).astype(np.float64)
    expect = np.where(interior(s["slip"]) != 0, sum(u[d] * grad[d] for d in range(3)) / interior(e_eff), 0.0)
    fluid = slip_fluid_term(s["velocity"], s["phi"], s["eps"], s["slip"], s["flags"], True)
    np.testing.assert_allclose(fluid, expect, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(_terms(s, s["phi"]), _terms(s, s["phi"], with_u=False) + fluid, rtol=1e-12, atol=1e-15)


def test_sand_falling_through_a_still_interface_displaces_water_only_where_there_is_water():
    """A slab of sand (ε = 0.5) moving down at v through a still, flat interface (φ from 0 above to 1 below,
    u = 0): the terms are φ ∇·((1 − ε) v) / ε', the sand flux's divergence counted in the water. At the slab's
    leading (lower) face, in the water, they are the paper's ∇·((1 − ε) v) / ε (negative where the sand arrives,
    so the pressure rises and pushes the water away) times φ ε / ε'; at its upper face, in the air, they vanish
    (below 1 % of the paper's, φ < 0.01 there)."""
    shape = (18, 5, 5)  # padded (nz, ny, nx), every cell fluid
    z = np.arange(shape[0], dtype=np.float64)[:, None, None] * np.ones(shape)
    phi = 0.5 * (1.0 - np.tanh(2.0 * (z - 9.0) / 4.0))  # water below z = 9, width 4
    eps = np.where((z >= 3) & (z <= 14), 0.5, 1.0)  # the slab reaches from the water into the air
    v = np.zeros((3,) + shape)
    v[2] = np.where(eps < 1.0, -0.01, 0.0)
    slip = np.ones(shape, np.uint8)
    flags = np.zeros(shape, np.uint8)
    terms = sand_pressure_terms(None, phi, eps, v, slip, flags, True)
    paper = sand_pressure_terms(None, phi, eps, v, slip, flags, False)
    lower, upper = 3 - 1, 14 - 1  # interior indices of the slab's lower face (water) and upper face (air)
    assert phi[3].min() > 0.99 and phi[14].max() < 0.01
    assert paper[lower].max() < 0  # sand arriving: ∇·((1 − ε) v) < 0, so p − c²ρ (… + terms) rises there
    w = phi[3, 1:-1, 1:-1]
    np.testing.assert_allclose(terms[lower], paper[lower] * w * 0.5 / (1 - w * 0.5), rtol=1e-12)
    assert np.abs(terms[upper]).max() < 0.01 * np.abs(paper[upper]).max()
