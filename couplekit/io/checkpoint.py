"""HDF5 checkpoints: the scene, the solver states and the run counters, for an exact restart.

Layout: attribute ``format`` = "couplekit-checkpoint", ``version`` = 1, ``scene`` (the scene dict as JSON),
``meta`` (JSON: step, frame, time, backend, ...); one group per solver (``fluid``, ``sand``, ``coupler``, and
``emission`` for the accumulators of sand-carrying inflows, :mod:`couplekit.sand.emission`) holding its
:meth:`state` arrays as datasets, stored without compression or conversion so a restart is bitwise. The sand
group's particle count is the one at the checkpoint (jets add particles as a run goes on). The file
is written to a temporary name and renamed, so a crash never leaves a half-written checkpoint in place.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["save_checkpoint", "load_checkpoint", "CheckpointError", "FORMAT"]

FORMAT = "couplekit-checkpoint"
VERSION = 1


class CheckpointError(ValueError):
    """A file that is not a readable couplekit checkpoint."""


def save_checkpoint(
    path: str | Path, scene: Mapping[str, Any], states: Mapping[str, Mapping[str, np.ndarray]], meta: Mapping[str, Any]
) -> Path:
    """Write ``states`` ({solver: {name: array}}), the scene dict and ``meta`` to ``path`` atomically."""
    import h5py

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        f.attrs["scene"] = json.dumps(scene)
        f.attrs["meta"] = json.dumps(dict(meta))
        for solver, state in states.items():
            g = f.create_group(solver)
            for name, arr in state.items():
                g.create_dataset(name, data=np.asarray(arr))
    os.replace(tmp, path)
    return path


def load_checkpoint(path: str | Path) -> tuple[dict, dict[str, dict[str, np.ndarray]], dict]:
    """(scene dict, states, meta) of a checkpoint written by :func:`save_checkpoint`."""
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise CheckpointError(f"{path}: not a readable HDF5 file ({exc})") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise CheckpointError(f"{path}: not a couplekit checkpoint (format attribute {f.attrs.get('format')!r})")
        if int(f.attrs["version"]) != VERSION:
            raise CheckpointError(f"{path}: checkpoint version {f.attrs['version']} (this couplekit reads {VERSION})")
        scene = json.loads(f.attrs["scene"])
        meta = json.loads(f.attrs["meta"])
        states = {name: {k: np.array(ds[()]) for k, ds in g.items()} for name, g in f.items()}
    return scene, states, meta
