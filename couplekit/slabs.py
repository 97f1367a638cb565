"""Set-up work on whole grids done by slabs of z layers, so that building a solver needs little more host memory
than it keeps (the memory check, :func:`couplekit.assembly.memory_estimate`, counts what the solvers keep)."""

from __future__ import annotations

from collections.abc import Iterator

__all__ = ["HOST_SLAB_BYTES", "host_slabs"]

HOST_SLAB_BYTES = 64 * 2**20
"""What a set-up step may allocate at once on the host for one slab of a field (:func:`host_slabs`)."""


def host_slabs(
    shape: tuple[int, int, int], bytes_per_cell: int, budget: int | None = None
) -> Iterator[tuple[int, int]]:
    """(z0, z1) ranges of the interior's z layers, each slab's cells times ``bytes_per_cell`` within ``budget``
    (default :data:`HOST_SLAB_BYTES`; at least one layer): set-up work on whole fields done by slabs keeps its
    host temporaries bounded, so that building a solver does not need several times the memory it keeps (the
    memory check counts what it keeps)."""
    nz, ny, nx = shape
    budget = HOST_SLAB_BYTES if budget is None else budget
    step = max(1, budget // max(1, bytes_per_cell * ny * nx))
    for z0 in range(0, nz, step):
        yield z0, min(nz, z0 + step)
