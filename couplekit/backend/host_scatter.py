"""The scratch of the host's tiled particle scatter (kernels/host_scatter.cuh): its size in ints, from the tile
size the header defines, and the one check the ints impose on the particle count."""

from __future__ import annotations

import re
from functools import lru_cache

import numpy as np

from .sources import kernel_dir

__all__ = ["host_scatter_scratch", "host_scatter_scratch_size"]

_TILE = re.compile(r"#define\s+HOST_SCATTER_TILE\s+(\d+)")
_MAX_PARTICLES = 2**31 - 1  # the particle order and the tiles' counts are 32-bit ints


@lru_cache(maxsize=1)
def _tile() -> int:
    m = _TILE.search((kernel_dir() / "host_scatter.cuh").read_text())
    if m is None:
        raise RuntimeError("kernels/host_scatter.cuh defines no HOST_SCATTER_TILE")
    return int(m.group(1))


def host_scatter_scratch_size(n: int, ny: int, nz: int, threads: int) -> int:
    """Ints the scatter of ``n`` particles into a grid of ``ny`` × ``nz`` node rows needs with ``threads``
    threads: the particle order, each thread's count per tile and the tiles' starts (kernels/host_scatter.cuh's
    host_scatter reads them in that order)."""
    t = _tile()
    tiles = -(-ny // t) * -(-nz // t)
    return n + threads * tiles + tiles + 1


def host_scatter_scratch(old: np.ndarray | None, n: int, ny: int, nz: int, threads: int) -> np.ndarray:
    """``old`` if it is large enough for :func:`host_scatter_scratch_size`'s ints, else a new int32 array (with a quarter
    more room for particles to come: emitted sand grows ``n`` step by step).  A clear error past 2³¹ − 1 particles,
    which the 32-bit particle order cannot index (the GPU's atomic scatter has no such limit)."""
    if n > _MAX_PARTICLES:
        raise ValueError(
            f"{n:,} particles: the host's particle-to-grid scatter indexes at most {_MAX_PARTICLES:,} "
            "(kernels/host_scatter.cuh); run this scene on the cuda backend, or with fewer particles per cell"
        )
    need = host_scatter_scratch_size(n, ny, nz, threads)
    if old is not None and old.size >= need:
        return old
    spare = host_scatter_scratch_size(min(_MAX_PARTICLES, n + n // 4), ny, nz, threads)
    return np.zeros(spare, dtype=np.int32)
