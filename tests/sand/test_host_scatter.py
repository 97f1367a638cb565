"""The host's tiled particle-to-grid scatter (kernels/host_scatter.cuh), used by the MPM P2G and the bound water's
P2G (Eq. 53): the same bits for any thread count, the NumPy reference's values, the guard's count, and scratch
memory that grows with the particles, not with the grid times the threads (the private grids it replaced held
5 floats per node per thread)."""

from __future__ import annotations

import numpy as np
import pytest
from sand_states import DT, DX, particles

from couplekit.backend import BackendUnavailableError, get_backend
from couplekit.backend.host_scatter import host_scatter_scratch, host_scatter_scratch_size
from couplekit.coupling import CouplingParams
from couplekit.coupling.kernel_ops import KernelOps as CouplingKernelOps
from couplekit.coupling.reference import ReferenceOps as CouplingReferenceOps
from couplekit.sand import KernelOps, ReferenceOps

THREADS = (1, 2, 3)
# (nz, ny, nx): odd sizes, so the last tile of a row is short; a grid one tile wide in y
SHAPES = [(17, 11, 9), (13, 4, 15)]


def _backend(threads: int):
    try:
        return get_backend("cpu", threads=threads)
    except BackendUnavailableError as exc:  # pragma: no cover - CI always has g++
        pytest.skip(f"cpu backend unavailable: {exc}")


def _rel(a, b):
    return float(np.max(np.abs(a.astype(np.float64) - b.astype(np.float64))) / max(np.max(np.abs(b)), 1e-30))


def _clustered(rng, shape, n):
    """n particles (above MPM_SERIAL_PARTICLES, so the team is not one thread), a third of them inside one
    tile's 2 x 2 node rows (all particles of a colour's busiest tile in one thread's hands), the rest spread."""
    p = particles(rng, n, shape)
    k = n // 3
    nz, ny, nx = shape
    centre = np.array([nx / 2, ny / 2, nz / 2]) * DX
    p["x"][:, :k] = (centre[:, None] + (rng.random((3, k)) - 0.5) * 0.9 * DX).astype(np.float32)
    return p


@pytest.mark.parametrize("shape", SHAPES, ids=["17x11x9", "13x4x15"])
def test_p2g_same_bits_for_every_thread_count(shape):
    p = _clustered(np.random.default_rng(5), shape, 12_000)
    results = []
    for t in THREADS:
        ops = KernelOps(_backend(t))
        grids = tuple(np.full(s, np.nan, np.float32) for s in (shape, (3, *shape), shape))  # overwritten
        ops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], *grids, DX, DT)
        assert ops.skipped_particles() == 0
        results.append(grids)
    ref = tuple(np.zeros(s, np.float32) for s in (shape, (3, *shape), shape))
    ReferenceOps().p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], *ref, DX, DT)
    for got in results:
        for a, b, r in zip(got, results[0], ref, strict=True):
            assert np.array_equal(a, b)
            assert _rel(a, r) < 1e-5  # test_kernels_vs_reference.py's tolerance


def test_p2g_counts_left_out_particles_once_for_every_thread_count():
    shape = SHAPES[0]
    p = particles(np.random.default_rng(6), 10_000, shape)
    p["x"][0, :7] = np.nan
    p["x"][2, 7:12] = 0.5 * DX  # the stencil would leave the grid
    for t in THREADS:
        ops = KernelOps(_backend(t))
        grids = tuple(np.zeros(s, np.float32) for s in (shape, (3, *shape), shape))
        ops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], *grids, DX, DT)
        assert ops.skipped_particles() == 12
        kept = float(p["mass"][12:].astype(np.float64).sum())
        assert abs(float(grids[0].astype(np.float64).sum()) - kept) <= 1e-5 * kept


def test_bound_water_p2g_same_bits_for_every_thread_count():
    shape = SHAPES[0]
    rng = np.random.default_rng(7)
    p = _clustered(rng, shape, 12_000)
    r = (0.3 * rng.random(p["x"].shape[1])).astype(np.float32)
    params = CouplingParams(retention=True)
    out = []
    for t in THREADS:
        got = np.full(shape, -7.0, np.float32)
        CouplingKernelOps(_backend(t), params, True).bound_water_p2g(p["x"], r, p["volume"], got, DX)
        out.append(got)
    want = np.zeros(shape, np.float32)
    CouplingReferenceOps(params, True).bound_water_p2g(p["x"], r, p["volume"], want, DX)
    for got in out:
        assert np.array_equal(got, out[0])
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * float(want.max()))


def test_scratch_grows_with_the_particles_not_with_the_grid():
    """The scratch of a 64³ grid on 3 threads is about one int per particle (the private grids were 3 × 5 × 64³
    floats = 15.7 MB); it is kept while large enough and regrown, with room to spare, as particles are added."""
    shape = (64, 64, 64)
    ops = KernelOps(_backend(3))
    grids = tuple(np.zeros(s, np.float32) for s in (shape, (3, *shape), shape))
    p = particles(np.random.default_rng(8), 9000, shape)
    ops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], *grids, DX, DT)
    first = ops._scratch
    assert first.dtype == np.int32
    assert first.size >= host_scatter_scratch_size(9000, 64, 64, 3)
    assert first.nbytes <= 4 * host_scatter_scratch_size(9000 + 9000 // 4, 64, 64, 3)
    assert first.nbytes < 4 * (1.25 * 9000 + 4 * 32 * 32 + 2)  # 32 × 32 tiles: as many as the smallest tile makes
    more = particles(np.random.default_rng(9), 11_000, shape)  # 22 % more: within the spare room
    ops.p2g(more["x"], more["v"], more["C"], more["tau"], more["mass"], more["volume"], *grids, DX, DT)
    assert ops._scratch is first
    many = particles(np.random.default_rng(10), 30_000, shape)
    ops.p2g(many["x"], many["v"], many["C"], many["tau"], many["mass"], many["volume"], *grids, DX, DT)
    assert ops._scratch.size >= host_scatter_scratch_size(30_000, 64, 64, 3)
    ref = tuple(np.zeros(s, np.float32) for s in (shape, (3, *shape), shape))
    ReferenceOps().p2g(many["x"], many["v"], many["C"], many["tau"], many["mass"], many["volume"], *ref, DX, DT)
    for a, b in zip(grids, ref, strict=True):
        assert _rel(a, b) < 1e-5


def test_scratch_refuses_more_particles_than_32_bit_ints_index():
    with pytest.raises(ValueError, match="cuda backend"):
        host_scatter_scratch(None, 2**31, 10, 10, 2)


def test_each_backend_reports_its_own_thread_count():
    """OpenMP's default count is the process's: a module asked for its count returned what another backend's
    module had set last, and the P2G sized its team and scratch from that (probe, session 23)."""
    one, four = _backend(1), _backend(4)
    m1, m4 = one.module("mpm_p2g.cu"), four.module("mpm_p2g.cu")
    shape = SHAPES[0]
    p = particles(np.random.default_rng(12), 9000, shape)
    for ops, module, want in ((KernelOps(one), m1, 1), (KernelOps(four), m4, 4), (KernelOps(one), m1, 1)):
        grids = tuple(np.zeros(s, np.float32) for s in (shape, (3, *shape), shape))
        ops.p2g(p["x"], p["v"], p["C"], p["tau"], p["mass"], p["volume"], *grids, DX, DT)
        assert module.num_threads() == want
        assert ops._scratch.size >= host_scatter_scratch_size(9000, shape[1], shape[0], want)
