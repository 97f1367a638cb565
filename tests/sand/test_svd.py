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
import pytest


@pytest.fixture(scope="module")
def kops(kernel_backend):
    """KernelOps on cpu and on cpu-device in turn: the host and the CUDA code paths of the sand kernels."""
    from couplekit.sand import KernelOps

    return KernelOps(kernel_backend)


def _svd3(kops, flat):
    """kops.svd3 with its results on the host (on cuda they are device arrays)."""
    return tuple(kops.backend.to_host(a) for a in kops.svd3(flat))


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
    U, s, V = _svd3(kops, flat)
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


def _degenerate_cases(rng) -> np.ndarray:
    """Matrices that break naive SVDs: zero / rank-deficient, repeated and exactly equal singular values
    (the Jacobi half-angle is 0/0 there), inverted and flattened F, huge and tiny scales."""
    q, _ = np.linalg.qr(rng.normal(size=(40, 3, 3)))
    q *= np.sign(np.linalg.det(q))[:, None, None]
    mats = [
        np.zeros((3, 3)),
        -0.0 * np.eye(3),
        np.eye(3),
        -np.eye(3),
        np.diag([1.0, -1.0, 1.0]),
        np.diag([0.0, 0.0, 1.0]),
        np.diag([0.0, 1.0, 0.0]),
        np.diag([1.0, 0.0, 0.0]),
        np.diag([3.0, 3.0, 0.0]),
        np.diag([1.0, 1.0, -1e-7]),  # just inverted
        np.diag([1.0, 1e-7, 1e-7]),  # flattened to a line
        np.ones((3, 3)),  # rank 1, equal entries
        np.outer([1.0, -1.0, 0.0], [0.0, 1.0, 1.0]),
        np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 2.0]]),  # symmetric, equal diagonal
        np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]),  # zero diagonal of A^T A pairs
        np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [1.0, 1.0, 1.0]]),  # rank 2
        np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),  # rank 2, inverted
        1e35 * np.eye(3),
        1e-35 * np.diag([1.0, 2.0, -3.0]),
        1e-40 * np.ones((3, 3)),  # subnormal entries: treated as the zero matrix
        np.diag([1e30, 1e-30, -1.0]),
    ]
    for k in range(40):  # rotations of repeated / vanishing / negative spectra
        s = [(2.0, 2.0, 2.0), (1.0, 1.0, 0.0), (1.0, 0.0, 0.0), (1.5, 1.5, -1.5), (1.0, 1.0, -1e-6)][k % 5]
        mats.append(q[k] @ np.diag(s) @ q[(k + 7) % 40].T)
    return np.array(mats)


def test_svd_never_nan_for_degenerate_or_inverted(kops):
    """Degenerate and inverted F, mixed with ordinary matrices so that they share SIMD batches with them
    (and the count is no multiple of any SIMD width), give finite rotations U, V (det +1) and ordered
    singular values with sigma_3 carrying the sign of det A.

    Tolerances: reconstruction <= 1e-4 ||A|| (the ill-conditioned limit of the module docstring),
    orthogonality / det <= 1e-5, ordering to 1e-5 sigma_1 (round-off of the sorted QR diagonal).
    Matrices whose largest entry is subnormal (< 1e-36) are the zero matrix by design: sigma = 0.
    """
    rng = np.random.default_rng(7)
    bad = _degenerate_cases(rng)
    A = np.concatenate([bad, rng.normal(size=(333, 3, 3))])
    A = A[rng.permutation(len(A))].astype(np.float32)
    flat = np.ascontiguousarray(A.reshape(-1, 9).T)
    U, s, V = _svd3(kops, flat)
    assert np.all(np.isfinite(U)) and np.all(np.isfinite(s)) and np.all(np.isfinite(V))
    Um, Vm, sv = _as_mats(U), _as_mats(V), s.T.astype(np.float64)
    M = A.astype(np.float64)
    amax = np.abs(M).max(axis=(1, 2))
    zero = amax < 1e-36
    assert zero.sum() == 3  # the zero, -0 and subnormal matrices
    assert np.all(sv[zero] == 0)
    eye = np.eye(3)
    assert np.max(np.abs(np.einsum("pba,pbc->pac", Um, Um) - eye)) < 1e-5
    assert np.max(np.abs(np.einsum("pba,pbc->pac", Vm, Vm) - eye)) < 1e-5
    assert np.max(np.abs(np.linalg.det(Um) - 1)) < 1e-5
    assert np.max(np.abs(np.linalg.det(Vm) - 1)) < 1e-5
    live = ~zero
    rec = np.einsum("pab,pb,pcb->pac", Um, sv, Vm)
    err = np.linalg.norm(rec - M, axis=(1, 2)) / np.maximum(np.linalg.norm(M, axis=(1, 2)), 1e-300)
    assert np.max(err[live]) < 1e-4
    top = sv[:, 0]
    assert np.all(sv[:, 0] >= -1e-5 * top) and np.all(sv[:, 1] >= -1e-5 * top)
    assert np.all(sv[:, 0] - sv[:, 1] >= -1e-5 * top)
    assert np.all(sv[:, 1] - np.abs(sv[:, 2]) >= -1e-5 * top)
    det = np.linalg.det(M / np.maximum(amax, 1e-300)[:, None, None])  # scale-free, no overflow
    clear = det < -1e-6
    assert clear.sum() > 10
    assert np.all(sv[clear, 2] < 0)


def test_svd_result_does_not_depend_on_batch_position(kops):
    """The host kernel runs one matrix per SIMD lane in batches, with a shorter tail: a matrix's result
    must be the same wherever it sits (bitwise: every lane runs the same instructions; this is what makes
    the sand step independent of the particle order within the batches and of the thread count)."""
    rng = np.random.default_rng(8)
    A = np.concatenate([_cases(rng, 60), _degenerate_cases(rng).astype(np.float32)])
    perm = rng.permutation(len(A))
    outs = []
    for order in (np.arange(len(A)), perm):
        flat = np.ascontiguousarray(A[order].reshape(-1, 9).T)
        U, s, V = _svd3(kops, flat)
        inv = np.argsort(order)
        outs.append((U[:, inv], s[:, inv], V[:, inv]))
    for a, b in zip(*outs, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("plasticity", [True, False])
def test_constitutive_update_finite_for_degenerate_f(kops, plasticity):
    """The whole constitutive update (SVD, clamped logs, return mapping, Kirchhoff stress) on degenerate and
    inverted trial F returns finite F, tau, q, vc (the |sigma| >= 1e-4 clamp before the log bounds the
    strains)."""
    from couplekit.sand import SandParams

    rng = np.random.default_rng(9)
    bad = _degenerate_cases(rng)
    bad = bad[np.abs(bad).max(axis=(1, 2)) < 1e3]  # F of a sand step: no 1e30 stretches (tau would overflow)
    n = len(bad)
    F = np.ascontiguousarray(bad.reshape(n, 9).T.astype(np.float32))
    tau = np.zeros((6, n), np.float32)
    q = (5 * rng.random(n)).astype(np.float32)
    vc = (0.01 * rng.random(n)).astype(np.float32)
    sat = (0.3 * rng.random(n)).astype(np.float32)
    model = SandParams(plasticity=plasticity, cohesion_max=1000.0).model()
    kops.constitutive(F, tau, q, vc, sat, model)
    for a in (F, tau, q, vc):
        assert np.all(np.isfinite(a))


def test_simd_log_exp_match_libm(cpu):
    """mpm_logf / mpm_expf (kernels/mpm_simd_math.cuh), which the host G2P uses inside its vectorised
    loops, against float64 log / exp of the same float32 inputs.  Cephes' minimax polynomials have a peak
    error of ~1 ulp; rounding of the argument reduction adds < 1 ulp: <= 2 ulp of the result everywhere
    checked (measured 0.74 ulp for log, 0.97 ulp for exp).  Ranges: log over 1e-37 .. 3e38 (every
    exponent, mantissas across the sqrt(1/2) switch), exp over -87 .. 88 (strains in the model stay
    within +-10)."""
    rng = np.random.default_rng(10)
    xs_log = np.concatenate(
        [
            np.exp(rng.uniform(np.log(1e-37), np.log(3e38), 200_000)),
            np.exp(rng.normal(scale=0.1, size=50_000)),  # near 1, where log is small
            [1.0, 2.0, 0.5, np.sqrt(0.5), np.sqrt(2.0), 1e-4, 1e-37, 3.4e38],
        ]
    ).astype(np.float32)
    xs_exp = np.concatenate([rng.uniform(-87, 88, 200_000), rng.uniform(-10, 10, 50_000), [0.0, 1.0, -1.0]])
    xs_exp = xs_exp.astype(np.float32)
    mod = cpu.module("mpm_constitutive.cu")
    fn = mod.function("mpm_simd_log_exp")
    for xs, ref_fn, which in ((xs_log, np.log, 0), (xs_exp, np.exp, 1)):
        out = (np.empty_like(xs), np.empty_like(xs))
        fn(xs.size, xs, *out)
        got = out[which].astype(np.float64)
        ref = ref_fn(xs.astype(np.float64))
        ulp = np.spacing(np.abs(ref).astype(np.float32)).astype(np.float64)
        ulp = np.where(ref == 0, np.spacing(np.float32(0)), ulp)
        err = np.abs(got - ref) / ulp
        assert np.all(np.isfinite(got))
        assert np.max(err) <= 2.0, (which, float(np.max(err)), xs[np.argmax(err)])


def test_svd_of_rotations_is_accurate_to_a_few_ulp(kops):
    """F near a rotation (particles at rest or in rigid motion) is the common case of a sand step; its SVD is
    re-synthesised into F = U exp(e) V^T every step, so its round-off becomes spurious strain.  The Jacobi
    threshold of mpm_svd.cuh keeps it at a few ulp: reconstruction error of pure rotations <= 8e-7
    (max, ~7 ulp of 1) and <= 2e-7 on average (measured 5.3e-7 / 1.4e-7; without the threshold
    1.4e-6 / 3.3e-7); the identity is decomposed exactly (U = V = I, sigma = 1)."""
    rng = np.random.default_rng(14)
    q, _ = np.linalg.qr(rng.normal(size=(20000, 3, 3)))
    q *= np.sign(np.linalg.det(q))[:, None, None]
    A = np.concatenate([q, np.eye(3)[None]]).astype(np.float32)
    flat = np.ascontiguousarray(A.reshape(-1, 9).T)
    U, s, V = _svd3(kops, flat)
    Um, Vm, sv = _as_mats(U), _as_mats(V), s.T.astype(np.float64)
    err = np.abs(np.einsum("pab,pb,pcb->pac", Um, sv, Vm) - A.astype(np.float64)).max(axis=(1, 2))
    assert err.max() <= 8e-7
    assert err.mean() <= 2e-7
    assert np.array_equal(U[:, -1], np.eye(3, dtype=np.float32).ravel())
    assert np.array_equal(V[:, -1], np.eye(3, dtype=np.float32).ravel())
    assert np.array_equal(s[:, -1], np.ones(3, np.float32))
