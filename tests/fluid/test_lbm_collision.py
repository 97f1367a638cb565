"""Collision invariants of the NOCM-MRT operator (paper Eqs. 9, 11, 12; lbm-method note §1a/§1b).

Without forces the collision resets the zeroth moment to exactly 1 and conserves momentum Σ f c; with an
acceleration a it adds exactly a to the momentum (Guo forcing in central-moment space: first central
moments go from −a/2 to +a/2). With r_s = 1 (ν = 1/6) every moment relaxes fully, so f* is the product-form
equilibrium of Eq. 12 at u. Checked on the reference and on the cpu kernel. Both store f in float32, so a sum
of the 27 stored populations carries up to 27 · 2⁻²⁴ · 0.3 ≈ 5e-7 of storage round-off (plus the float32
arithmetic of the kernel, same order): tolerance 1e-6, while the effects checked are ≥ 1e-4.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.backend import get_backend
from couplekit.fluid import KernelOps, ReferenceOps, equilibrium, from_stored, to_stored
from couplekit.fluid.grid import Boundaries, build_flags, padded_shape
from couplekit.lattice import C27, OPP27

SHAPE = (4, 5, 6)


def _state(seed):
    rng = np.random.default_rng(seed)
    pshape = padded_shape(SHAPE)
    u = rng.uniform(-0.08, 0.08, (3,) + pshape)
    f = equilibrium(u) * (1.0 + 0.02 * rng.standard_normal((27,) + pshape)) + 0.002 * rng.standard_normal(pshape)
    flags, _, _ = build_flags(SHAPE, Boundaries())
    return to_stored(f), flags, np.zeros((3,) + pshape, np.float32), np.zeros(pshape, np.float32)


def _collide(ops, f, flags, vel, pbar, nu, g):
    fpre = f.copy()
    # parity 0: purely local, the post-collision f*_j is stored in slot opp(j) of the same cell
    ops.collide_stream(f, flags, vel, None, None, None, pbar, 0, 1.0, 1.0, nu, nu, *g)
    inner = (slice(None), slice(1, -1), slice(1, -1), slice(1, -1))
    # full populations (the arrays hold f - w)
    return from_stored(fpre)[inner], from_stored(f[OPP27])[inner], vel[inner].astype(np.float64)


@pytest.fixture(params=["numpy", "cpu"])
def ops_tol(request):
    if request.param == "numpy":
        return ReferenceOps(), 1e-7
    return KernelOps(get_backend("cpu")), 1e-7


@pytest.mark.parametrize("nu", [1e-4, 0.01, 0.3])
def test_zeroth_moment_reset_and_momentum_conserved_without_force(ops_tol, nu):
    ops, tol = ops_tol
    f, flags, vel, pbar = _state(1)
    pre, post, u = _collide(ops, f, flags, vel, pbar, nu, (0.0, 0.0, 0.0))
    assert np.abs(pre.sum(0) - 1).max() > 1e-3  # the input is really off the reset value
    np.testing.assert_allclose(post.sum(0), 1.0, rtol=0, atol=tol * 10)
    mom_pre = np.einsum("jd,j...->d...", C27, pre)
    mom_post = np.einsum("jd,j...->d...", C27, post)
    np.testing.assert_allclose(mom_post, mom_pre, rtol=0, atol=tol * 10)
    np.testing.assert_allclose(u, mom_pre, rtol=0, atol=tol * 10)


def test_force_adds_exactly_its_acceleration(ops_tol):
    ops, tol = ops_tol
    f, flags, vel, pbar = _state(2)
    g = (2e-4, -1e-4, 3e-4)
    pre, post, u = _collide(ops, f, flags, vel, pbar, 0.02, g)
    mom_pre = np.einsum("jd,j...->d...", C27, pre)
    mom_post = np.einsum("jd,j...->d...", C27, post)
    np.testing.assert_allclose(
        mom_post - mom_pre, np.broadcast_to(np.array(g)[:, None, None, None], mom_pre.shape), atol=tol * 10
    )
    np.testing.assert_allclose(u, mom_pre + 0.5 * np.array(g)[:, None, None, None], atol=tol * 10)


def test_unit_shear_rate_gives_the_equilibrium_of_eq12(ops_tol):
    ops, tol = ops_tol
    f, flags, vel, pbar = _state(3)
    _, post, u = _collide(ops, f, flags, vel, pbar, 1.0 / 6.0, (0.0, 0.0, 0.0))  # r_s = 1/(3ν + 1/2) = 1
    np.testing.assert_allclose(post, equilibrium(u), rtol=0, atol=tol * 10)
