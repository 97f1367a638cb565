"""Kernel self-check: run the reduction, scatter and stencil kernels of ``kernels/selfcheck.cu`` and compare
them with NumPy. Used by ``couplekit info --selfcheck`` and by the tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .backend import Backend
from .lattice import C27, W27

SOURCE = "selfcheck.cu"


def reference_sum(x: np.ndarray) -> float:
    """Σ x in float64."""
    return float(np.sum(x, dtype=np.float64))


def reference_scatter(idx: np.ndarray, val: np.ndarray, size: int, scale: float) -> np.ndarray:
    """out[idx[i]] += scale * val[i], accumulated in float64."""
    out = np.zeros(size, dtype=np.float64)
    np.add.at(out, idx, scale * val.astype(np.float64))
    return out


def reference_stencil27(field: np.ndarray) -> np.ndarray:
    """Periodic 27-point weighted average Σ_q w_q s(x + c_q), field shape (nz, ny, nx), in float64."""
    out = np.zeros(field.shape, dtype=np.float64)
    for (cx, cy, cz), w in zip(C27, W27, strict=True):
        out += w * np.roll(field.astype(np.float64), shift=(-cz, -cy, -cx), axis=(0, 1, 2))
    return out


@dataclass
class CheckResult:
    """One self-check: its name, the worst relative error seen and the tolerance it must meet."""

    name: str
    error: float
    tolerance: float

    @property
    def ok(self) -> bool:
        return bool(np.isfinite(self.error) and self.error <= self.tolerance)


def run_selfcheck(backend: Backend, seed: int = 0, shape: tuple[int, int, int] = (24, 20, 16)) -> list[CheckResult]:
    """Run the three self-check kernels on ``backend`` and compare with the NumPy references.

    Tolerances: float32 inputs, float64 or float32 accumulation. The reduction accumulates in float64, so
    it matches to ~1e-12 relative. The scatter sums ≤ ~200 float32 terms per target in an arbitrary order:
    float32 round-off bounds the relative error by ~200 · 6e-8 ≈ 1e-5. The stencil sums 27 positive
    float32 products: ≤ 27 · 6e-8 ≈ 2e-6.
    """
    xp = backend.xp
    rng = np.random.default_rng(seed)
    mod = backend.module(SOURCE)
    results = []

    x = rng.random(1_000_003, dtype=np.float32)
    out = xp.zeros(1, dtype=np.float64)
    mod.function("sum_reduce")(x.size, backend.asarray(x), out)
    ref = reference_sum(x)
    results.append(CheckResult("reduction (float64 sum of 1e6 floats)", abs(float(out[0]) - ref) / ref, 1e-12))

    n, size = 200_000, 1_000
    idx = rng.integers(0, size, n).astype(np.int32)
    val = rng.random(n, dtype=np.float32)
    target = xp.zeros(size, dtype=np.float32)
    mod.function("scatter_add")(n, backend.asarray(idx), backend.asarray(val), target, np.float32(0.5))
    ref = reference_scatter(idx, val, size, 0.5)
    err = np.max(np.abs(backend.to_host(target) - ref) / np.maximum(ref, 1e-30))
    results.append(CheckResult("scatter with float atomics (2e5 -> 1e3)", float(err), 1e-5))

    nz, ny, nx = shape
    field = rng.random(shape, dtype=np.float32) + 0.5
    outf = xp.zeros(shape, dtype=np.float32)
    mod.function("stencil27_periodic")(field.size, backend.asarray(field), outf, nx, ny, nz)
    ref = reference_stencil27(field)
    err = np.max(np.abs(backend.to_host(outf) - ref) / ref)
    results.append(CheckResult(f"periodic 27-point stencil {nx}x{ny}x{nz}", float(err), 2e-6))
    return results
