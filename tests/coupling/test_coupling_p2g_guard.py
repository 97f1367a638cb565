"""The sand P2G guard (kernels/mpm_p2g.cu), asked for by the coupled runs: a particle with a non-finite
position, or one whose stencil would leave the grid, scatters nothing (a NaN position made the host build
write out of bounds and crash with "double free") and is counted.  Valid particles' transfer is unchanged:
compared bitwise with a P2G of the valid particles alone (same summation order on one thread)."""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.sand.kernel_ops import KernelOps

SHAPE = (6, 7, 8)
DX = 0.01


@pytest.mark.parametrize("host_atomics", [False, True])
def test_p2g_skips_nan_and_out_of_grid_particles(cpu1, host_atomics):
    rng = np.random.default_rng(0)
    nz, ny, nx = SHAPE
    n = 40
    x = np.stack([rng.uniform(1.0, s - 1.0, n) for s in (nx, ny, nz)]).astype(np.float32) * DX
    bad = x.copy()[:, :4]
    bad[0, 0] = np.nan
    bad[2, 1] = np.inf
    bad[1, 2] = 0.5 * DX  # stencil would start at node -1
    bad[0, 3] = (nx - 0.9) * DX  # stencil would end at node nx
    allx = np.ascontiguousarray(np.concatenate([bad, x], axis=1))

    def particle_arrays(m):
        r = np.random.default_rng(1)
        return (
            np.ascontiguousarray(r.normal(size=(3, m)).astype(np.float32)),
            np.ascontiguousarray(0.1 * r.normal(size=(9, m)).astype(np.float32)),
            np.ascontiguousarray(10 * r.normal(size=(6, m)).astype(np.float32)),
            np.full(m, 1e-3, np.float32),
            np.full(m, 1e-6, np.float32),
        )

    v, C, tau, mass, vol = particle_arrays(n + 4)
    ops = KernelOps(cpu1, host_atomics=host_atomics)
    grids = [np.zeros(SHAPE, np.float32), np.zeros((3, *SHAPE), np.float32), np.zeros(SHAPE, np.float32)]
    ops.p2g(allx, v, C, tau, mass, vol, *grids, DX, 1e-4)
    assert ops.skipped_particles() == 4
    assert all(np.isfinite(g).all() for g in grids)
    ref = [np.zeros_like(g) for g in grids]
    keep = slice(4, None)
    ops.p2g(
        np.ascontiguousarray(x), *(np.ascontiguousarray(a[..., keep]) for a in (v, C, tau, mass, vol)), *ref, DX, 1e-4
    )
    assert ops.skipped_particles() == 0
    for g, r in zip(grids, ref, strict=True):
        np.testing.assert_array_equal(g, r)
