"""The host G2P runs in batches of SIMD lanes (transfer + SVD, scalar yield parameters, vectorised return
mapping and stress; see kernels/mpm_g2p.cu), restating mpm_constitutive of mpm_model.cuh after the SVD.
These tests pin that restatement to the stand-alone constitutive kernel and check that batching changes
nothing a caller sees.
"""

from __future__ import annotations

import numpy as np
import pytest
from sand_states import DT, DX, SHAPE, particles

from couplekit.sand import SandParams


@pytest.fixture(scope="module")
def kops(kernel_backend):
    """KernelOps on cpu and on cpu-device in turn: the host and the CUDA code paths of the sand kernels."""
    from couplekit.sand import KernelOps

    return KernelOps(kernel_backend)


MODELS = {
    "sand": SandParams(cohesion_max=0.0),
    "sand_cohesive": SandParams(cohesion_max=2000.0),
    "sand_no_hardening": SandParams(hardening=False, h0=30.0, volume_correction=False),
    "elastic": SandParams(plasticity=False, youngs_modulus=1e5),
}


def _g2p_state(rng, n):
    p = particles(rng, n)
    gv = (0.5 * rng.normal(size=(3, *SHAPE))).astype(np.float32)
    return p, gv


@pytest.mark.parametrize("name", list(MODELS))
def test_g2p_constitutive_equals_constitutive_kernel(kops, name):
    """With the grid at rest C_new = 0 and the trial F is F_old exactly, so G2P's F, tau, q, vc must equal
    mpm_constitutive_batch applied to F_old.  Both run the same float32 SVD and return mapping; they differ
    in the logs / exps (G2P's vectorisable mpm_logf / mpm_expf, within 1 ulp of libm's, see
    test_svd.py) and in FMA contractions: a few ulp of the strains, so <= 1e-6 of each field's scale and
    q to 1e-6 relative (measured F 1.1e-7, tau 1.6e-7, q 9.5e-7 absolute at q ~ 10, i.e. 1 ulp).  A change
    of the constitutive model in mpm_model.cuh that G2P's restatement misses shows up as an O(1) difference.
    """
    rng = np.random.default_rng(11)
    n = 3001  # not a multiple of the batch or of any SIMD width
    p = particles(rng, n)
    gv = np.zeros((3, *SHAPE), np.float32)
    model = MODELS[name].model()
    keys = ("x", "v", "C", "F", "tau", "q", "vc")
    st = {k: p[k].copy() for k in keys}
    kops.g2p(*(st[k] for k in keys), p["saturation"], gv, DX, DT, model)
    assert np.array_equal(st["C"], np.zeros_like(st["C"]))
    F, tau, q, vc = p["F"].copy(), np.zeros((6, n), np.float32), p["q"].copy(), p["vc"].copy()
    kops.constitutive(F, tau, q, vc, p["saturation"], model)

    def rel(a, b):
        return float(np.max(np.abs(a.astype(np.float64) - b)) / max(np.max(np.abs(b)), 1e-30))

    assert rel(st["F"], F) <= 1e-6
    assert rel(st["tau"], tau) <= 1e-6
    assert np.max(np.abs(st["q"].astype(np.float64) - q)) <= 1e-6 * max(1.0, np.abs(q).max())
    assert np.max(np.abs(st["vc"].astype(np.float64) - vc)) <= 1e-6


def test_g2p_independent_of_particle_order(kops):
    """Shuffling the particles shuffles the G2P output and changes nothing else, bitwise (each particle is
    one SIMD lane; no lane reads another's data), so results do not depend on how particles fall into
    batches or threads."""
    rng = np.random.default_rng(12)
    n = 2999
    p, gv = _g2p_state(rng, n)
    model = MODELS["sand_cohesive"].model()
    keys = ("x", "v", "C", "F", "tau", "q", "vc")
    perm = rng.permutation(n)
    outs = []
    for order in (np.arange(n), perm):
        st = {k: np.ascontiguousarray(p[k][..., order]) for k in keys}
        sat = np.ascontiguousarray(p["saturation"][order])
        kops.g2p(*(st[k] for k in keys), sat, gv, DX, DT, model)
        inv = np.argsort(order)
        outs.append({k: st[k][..., inv] for k in keys})
    for k in keys:
        assert np.array_equal(outs[0][k], outs[1][k]), k


def test_initial_f_identity_gives_zero_stress(kops):
    """F = I (every particle at seeding) stays exactly I with exactly zero stress when the grid is at rest:
    the SVD's Jacobi threshold leaves the already diagonal A^T A = I alone (U = V = I, sigma = 1), so the
    strains are exactly 0 and nothing is re-synthesised with round-off."""
    rng = np.random.default_rng(13)
    n = 1000
    p = particles(rng, n)
    gv = np.zeros((3, *SHAPE), np.float32)
    keys = ("x", "v", "C", "F", "tau", "q", "vc")
    st = {k: p[k].copy() for k in keys}
    eye = np.broadcast_to(np.eye(3, dtype=np.float32).reshape(9, 1), (9, n))
    st["F"][...] = eye
    st["vc"][...] = 0.0
    for name in ("sand", "sand_cohesive", "elastic"):
        kops.g2p(*(st[k] for k in keys), p["saturation"], gv, DX, DT, MODELS[name].model())
        assert np.array_equal(st["F"], eye)
        assert np.array_equal(st["tau"], np.zeros((6, n), np.float32))
