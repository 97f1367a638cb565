"""Random but valid MPM states for the kernel-vs-reference tests."""

from __future__ import annotations

import numpy as np

SHAPE = (12, 10, 14)  # (nz, ny, nx): uneven, so an x/z mix-up cannot pass
DX = 0.01
DT = 1e-4


def particles(rng: np.random.Generator, n: int = 4000, shape=SHAPE, dx: float = DX) -> dict[str, np.ndarray]:
    """Particles strictly inside the 2-node wall band, with velocities, affine C, stress and mass of the
    sizes a sand step sees (|v| ~ 1 m/s, |C| ~ 10/s, |tau| ~ 1 kPa, F within 5 % of a rotation-free I)."""
    nz, ny, nx = shape
    lo = 2 * dx
    hi = np.array([nx - 2, ny - 2, nz - 2]) * dx
    f32 = np.float32
    return {
        "x": (lo + rng.random((3, n)) * (hi - lo)[:, None]).astype(f32),
        "v": rng.normal(size=(3, n)).astype(f32),
        "C": (10 * rng.normal(size=(9, n))).astype(f32),
        "F": (np.eye(3).reshape(9, 1) + 0.05 * rng.normal(size=(9, n))).astype(f32),
        "tau": (1e3 * rng.normal(size=(6, n))).astype(f32),
        "q": (10 * rng.random(n)).astype(f32),
        "vc": (0.1 * rng.random(n)).astype(f32),
        "saturation": (0.4 * rng.random(n)).astype(f32),
        "mass": (1e-3 * (0.5 + rng.random(n))).astype(f32),
        "volume": (1e-6 * (0.5 + rng.random(n))).astype(f32),
    }


def grids(shape=SHAPE):
    f32 = np.float32
    return np.zeros(shape, f32), np.zeros((3, *shape), f32), np.zeros(shape, f32)
