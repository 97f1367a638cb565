"""Seeding sand bodies with particles: boxes, spheres and arbitrary SDFs, k³ particles per cell, jitter.

Particles are placed on the sub-lattice of the MPM grid with spacing dx/k (k = ``ppc`` per axis, so k³
particles per full cell), at the centres of the sub-cells, then optionally jittered by up to ±jitter/2
sub-cell spacings (uniform, reproducible with ``seed``).  Every particle gets the volume (dx/k)³ of its
sub-cell, so a body's particle volumes add up to its volume up to the staircase of the sub-lattice.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Seeded", "seed_box", "seed_sphere", "seed_sdf", "combine"]


@dataclass
class Seeded:
    """Particle positions (3, P) float64 in metres and per-particle volumes (P,) in m³."""

    x: np.ndarray
    volume: np.ndarray

    @property
    def count(self) -> int:
        return self.x.shape[1]


def _lattice(lo, hi, dx: float, ppc: int) -> np.ndarray:
    if ppc < 1:
        raise ValueError(f"ppc (particles per cell per axis) must be >= 1, got {ppc}")
    h = dx / ppc
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if np.any(hi <= lo):
        raise ValueError(f"empty seeding box: lo={lo.tolist()}, hi={hi.tolist()}")
    # sub-cells of the global sub-lattice whose centres lie inside [lo, hi)
    first = np.ceil(lo / h - 0.5).astype(np.int64)
    last = np.ceil(hi / h - 0.5).astype(np.int64)
    axes = [(np.arange(first[a], last[a]) + 0.5) * h for a in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()])


def _finish(pts: np.ndarray, dx: float, ppc: int, jitter: float, seed: int | None) -> Seeded:
    if not 0.0 <= jitter <= 1.0:
        raise ValueError(f"jitter must be in [0, 1] sub-cell spacings, got {jitter}")
    h = dx / ppc
    if jitter > 0 and pts.size:
        rng = np.random.default_rng(seed)
        pts = pts + (rng.random(pts.shape) - 0.5) * jitter * h
    return Seeded(pts, np.full(pts.shape[1], h**3))


def seed_box(
    lo: Sequence[float], hi: Sequence[float], dx: float, ppc: int = 2, jitter: float = 0.0, seed: int | None = 0
) -> Seeded:
    """Particles filling the axis-aligned box [lo, hi) (metres)."""
    return _finish(_lattice(lo, hi, dx, ppc), dx, ppc, jitter, seed)


def seed_sphere(
    centre: Sequence[float], radius: float, dx: float, ppc: int = 2, jitter: float = 0.0, seed: int | None = 0
) -> Seeded:
    """Particles filling a ball."""
    c = np.asarray(centre, dtype=np.float64)
    return seed_sdf(lambda p: np.linalg.norm(p - c, axis=1) - radius, c - radius, c + radius, dx, ppc, jitter, seed)


def seed_sdf(
    sdf: Callable[[np.ndarray], np.ndarray],
    lo: Sequence[float],
    hi: Sequence[float],
    dx: float,
    ppc: int = 2,
    jitter: float = 0.0,
    seed: int | None = 0,
) -> Seeded:
    """Particles where ``sdf(points (N, 3)) < 0`` inside the bounding box [lo, hi)."""
    pts = _lattice(lo, hi, dx, ppc)
    inside = np.asarray(sdf(pts.T)) < 0
    return _finish(pts[:, inside], dx, ppc, jitter, seed)


def combine(*bodies: Seeded) -> Seeded:
    """Concatenate several seeded bodies."""
    return Seeded(np.concatenate([b.x for b in bodies], axis=1), np.concatenate([b.volume for b in bodies]))
