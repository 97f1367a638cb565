"""The float32 3x3 SVD kernel (kernels/mpm_svd.cuh) against LAPACK, including degenerate and inverted F.

Tolerances: float32 has a unit round-off of 6e-8; the Jacobi sweeps and QR accumulate a few dozen
rounding steps, so for well-conditioned A (sigma_max/sigma_min < 100, every F an MPM step produces)
the reconstruction ||U S V^T - A|| / ||A|| must be <= 2e-5 (measured 6e-6).  For ill-conditioned A the
method's known limit applies: the eigenproblem of A^T A squares the condition number, so V of the small
singular directions is only good to ~eps*sigma_max^2/sigma_min^2 in angle, which showed up as 5.7e-5 for
sigma ratios 1e-3..1e-6 — those cases get <= 1e-4.  Orthogonality / det errors <= 1e-5 (measured 2e-6).  Singular values are compared to LAPACK (float64)
relative to the largest one, <= 1e-5 (measured 1e-6): the small ones of an ill-conditioned matrix can only
be as accurate as sigma_max * eps.
"""

from __future__ import annotations

import numpy as np


def _as_mats(a):
    return a.T.reshape(-1, 3, 3).astype(np.float64)


def _cases(rng, n):
    gauss = rng.normal(size=(n, 3, 3))
    near_identity = np.eye(3) + 0.01 * rng.normal(size=(n, 3, 3))
    # random rotations times diag with repeated / zero / negative / tiny entries
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q *= np.sign(np.linalg.det(q))[:, None, None]
    diags = rng.choice([0.0, 1e-6, 1e-3, 0.5, 1.0, 1.0, 2.0, -1.0], size=(n, 3))
    structured = q @ (diags[:, :, None] * np.eye(3)) @ np.swapaxes(q, 1, 2)
    special = np.array(
        [
            np.zeros((3, 3)),
            np.eye(3),
            -np.eye(3),
            np.diag([1.0, 1.0, -1.0]),
            np.diag([2.0, 2.0, 2.0]),
            np.outer([1.0, 2.0, 3.0], [3.0, 1.0, 1.0]),  # rank 1
            np.diag([1e-30, 1.0, 1.0]),
            np.diag([1e20, 1.0, 1e-20]),  # huge dynamic range: scaled first, no overflow
            [[0, 1, 0], [0, 0, 1], [1, 0, 0]],  # permutation (det +1)
            [[0, 1, 0], [1, 0, 0], [0, 0, 1]],  # reflection (det -1)
        ]
    )
    return np.concatenate([gauss, near_identity, structured, special]).astype(np.float32)


def test_svd_kernel_reconstructs_and_matches_lapack(kops, rops):
    rng = np.random.default_rng(1)
    A = _cases(rng, 4000)
    flat = np.ascontiguousarray(A.reshape(-1, 9).T)
    U, s, V = kops.svd3(flat)
    assert np.all(np.isfinite(U)) and np.all(np.isfinite(s)) and np.all(np.isfinite(V))
    Um, Vm, sv = _as_mats(U), _as_mats(V), s.T.astype(np.float64)
    M = A.astype(np.float64)
    rec = np.einsum("pab,pb,pcb->pac", Um, sv, Vm)
    scale = np.maximum(np.linalg.norm(M, axis=(1, 2)), 1e-300)
    err = np.linalg.norm(rec - M, axis=(1, 2)) / scale
    s_lapack = np.linalg.svd(M, compute_uv=False)
    good = s_lapack[:, 2] > 1e-2 * s_lapack[:, 0]
    assert good.sum() > 8000
    assert np.max(err[good]) < 2e-5
    assert np.max(err) < 1e-4
    eye = np.eye(3)
    assert np.max(np.abs(np.einsum("pba,pbc->pac", Um, Um) - eye)) < 1e-5
    assert np.max(np.abs(np.einsum("pba,pbc->pac", Vm, Vm) - eye)) < 1e-5
    assert np.max(np.abs(np.linalg.det(Um) - 1)) < 1e-5
    assert np.max(np.abs(np.linalg.det(Vm) - 1)) < 1e-5
    # signed SVD: sigma_3 carries sign(det A); magnitudes = LAPACK's
    _, s_ref, _ = rops.svd3(flat)
    s_ref = s_ref.astype(np.float64)
    rel = np.abs(s.astype(np.float64) - s_ref) / np.maximum(np.abs(s_ref[0]), 1e-300)
    assert np.max(rel) < 1e-5
    det = np.linalg.det(M)
    clear = np.abs(det) > 1e-6 * scale**3
    assert np.all(np.sign(s[2][clear]) == np.sign(det[clear]))
