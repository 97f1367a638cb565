"""Memory as allocated: every array the solvers of a :class:`~couplekit.simulation.Simulation` hold, found by
walking their attributes (measured from the arrays' ``nbytes``, not estimated).

Views are counted once, at the array that owns the memory; an array reachable from two solvers is counted for
the first one walked, in the order sand, coupler, fluid, scheduler, emitter (so the scheduler's own buffers are
the ones only it holds)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

OWNERS = ("sand", "coupler", "fluid", "scheduler", "emitter")


@dataclass(frozen=True)
class AllocatedArray:
    """One allocated array: the solver holding it, its attribute path, shape and bytes."""

    owner: str
    path: str
    shape: tuple[int, ...]
    nbytes: int


def _owning(a: Any) -> Any:
    """The array that owns ``a``'s memory (numpy: follow ``base``; cupy and the stand-in device: ``a``)."""
    while _is_array(getattr(a, "base", None)):
        a = a.base
    return a


def _is_array(obj: Any) -> bool:
    return hasattr(obj, "nbytes") and hasattr(obj, "shape") and hasattr(obj, "dtype")


def allocated_arrays(sim) -> list[AllocatedArray]:
    """Every distinct array the solvers of ``sim`` hold (see the module docstring for the attribution)."""
    found: dict[int, AllocatedArray] = {}
    visited: set[int] = set()

    def walk(obj: Any, owner: str, path: str, depth: int) -> None:
        if obj is None or depth > 8:
            return
        if _is_array(obj):
            base = _owning(obj)
            if id(base) not in found:
                found[id(base)] = AllocatedArray(owner, path, tuple(base.shape), int(base.nbytes))
            return
        if isinstance(obj, (list, tuple)):
            for i, o in enumerate(obj):
                walk(o, owner, f"{path}[{i}]", depth + 1)
            return
        if isinstance(obj, dict):
            for k, o in obj.items():
                walk(o, owner, f"{path}[{k!r}]", depth + 1)
            return
        mod = type(obj).__module__
        if not mod.startswith("couplekit") or mod.startswith("couplekit.backend") or not hasattr(obj, "__dict__"):
            return
        if id(obj) in visited:
            return
        visited.add(id(obj))
        for k, o in vars(obj).items():
            walk(o, owner, f"{path}.{k}", depth + 1)

    for owner in OWNERS:
        walk(getattr(sim, owner, None), owner, owner, 0)
    return sorted(found.values(), key=lambda a: -a.nbytes)


def allocated_summary(sim) -> dict[str, float]:
    """Bytes allocated per owner and in total, and bytes per fluid cell (padded grid, everything but the
    particle arrays) and per particle (arrays whose last axis is the particle count)."""
    arrays = allocated_arrays(sim)
    n_p = sim.sand.n_particles if getattr(sim, "sand", None) is not None else 0
    out: dict[str, float] = {o: 0.0 for o in OWNERS}
    particle_bytes = 0.0
    for a in arrays:
        out[a.owner] += a.nbytes
        if n_p and a.shape and a.shape[-1] == n_p and len(a.shape) <= 2:
            particle_bytes += a.nbytes
    out["total"] = float(sum(a.nbytes for a in arrays))
    out["particle_arrays"] = particle_bytes
    out["grid_arrays"] = out["total"] - particle_bytes
    nx, ny, nz = sim.scene.domain.resolution
    out["cells"] = float(nx * ny * nz)
    out["particles"] = float(n_p)
    out["padded_cells"] = float((nx + 2) * (ny + 2) * (nz + 2))
    out["bytes_per_cell"] = out["grid_arrays"] / out["cells"]
    # the same per padded cell: what scales to a larger grid (a small grid's ghost layers weigh more)
    out["bytes_per_padded_cell"] = out["grid_arrays"] / out["padded_cells"]
    out["bytes_per_particle"] = particle_bytes / n_p if n_p else 0.0
    return out
