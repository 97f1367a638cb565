"""Lattice constants: D3Q27 (flow) and D3Q7 (phase field) velocities and weights.

The same tables are written in ``kernels/lattice.cuh``; ``tests/test_lattice.py`` checks they agree.
Order (both lattices): rest first, then opposite pairs adjacent, so ``OPPOSITE[q] = q + 1`` for odd q and
``q - 1`` for even q > 0 (the order of FluidX3D, which makes esoteric-pull streaming a two-line rule):
faces (+x,-x), (+y,-y), (+z,-z); then the 12 edges; then the 8 corners.
"""

from __future__ import annotations

import numpy as np

CS2 = 1.0 / 3.0
"""Lattice speed of sound squared of D3Q27."""

_FACES = [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
_EDGES = [(1, 1, 0), (1, 0, 1), (0, 1, 1), (1, -1, 0), (1, 0, -1), (0, 1, -1)]
_CORNERS = [(1, 1, 1), (1, 1, -1), (1, -1, 1), (-1, 1, 1)]


def _paired(half: list[tuple[int, int, int]]) -> np.ndarray:
    rows = [(0, 0, 0)]
    for c in half:
        rows += [c, tuple(-v for v in c)]
    return np.array(rows, dtype=np.int32)


C27 = _paired(_FACES + _EDGES + _CORNERS)
"""D3Q27 velocities, shape (27, 3), columns (x, y, z)."""

W27 = np.prod(np.where(C27 == 0, 2.0 / 3.0, 1.0 / 6.0), axis=1)
"""D3Q27 weights: 8/27 rest, 2/27 faces, 1/54 edges, 1/216 corners (float64)."""

C7 = _paired(_FACES)
"""D3Q7 velocities, shape (7, 3)."""

W7 = np.array([1.0 / 4.0] + [1.0 / 8.0] * 6)
"""D3Q7 weights (w0 = 1/4, w1..6 = 1/8), giving CS2_7 = 1/4."""

CS2_7 = 1.0 / 4.0
"""Speed of sound squared of the D3Q7 phase-field lattice with weights W7."""


def opposite(c: np.ndarray) -> np.ndarray:
    """Index of the opposite velocity for every direction of the velocity table ``c``."""
    index = {tuple(v): i for i, v in enumerate(c.tolist())}
    return np.array([index[tuple(-v for v in row)] for row in c.tolist()], dtype=np.int32)


OPP27 = opposite(C27)
OPP7 = opposite(C7)
