"""HDF5 checkpoints: the scene, the solver states and the run counters, for an exact restart.

Layout: attribute ``format`` = "couplekit-checkpoint", ``version`` = 3, ``scene`` (the scene dict as JSON),
``meta`` (JSON: step, frame, time, backend, ...), ``checksum`` (SHA-256 of the scene and meta text); one group
per solver (``fluid``, ``sand``, ``coupler``, ``emission`` for the accumulators of sand-carrying inflows,
:mod:`couplekit.sand.emission`, and ``scheduler`` for the scheduler's state: the sub-cycling scheduler's last
fluid velocity and, in a scene with sand, the frame's sand-step statistics) holding its
:meth:`state` arrays as datasets, stored without compression or conversion so a restart is bitwise, each with
a ``sha256`` attribute of its dtype, shape and bytes. The sand group's particle count is the one at the
checkpoint (jets add particles as a run goes on). The file is written to a temporary name and renamed, so a
crash never leaves a half-written checkpoint in place.

:func:`load_checkpoint` verifies everything it reads and refuses a defective file with a
:class:`CheckpointError` naming the file and what is wrong: not HDF5, not a couplekit checkpoint, another
version, the scene or metadata missing or not JSON, a dataset whose bytes do not match its checksum (a file
changed after it was written). Version-1 checkpoints (before checksums) still load, unverified.

Version 3 stores the fluid populations as the solver holds them since the shifted storage (``fluid/f`` holds
f − w, :mod:`couplekit.fluid.reference`); versions 1 and 2 stored the full f, and :func:`load_checkpoint`
converts them (f − w formed in float64, rounded to float32), so such a run restarts, though not bitwise
identically to the run that wrote it: the populations are rounded once more, ~1e-8 (docs/precision.md).

The fluid's storage precision (``fluid.storage``, fp32 or fp16) is recorded three times: in the stored scene,
in ``meta["fluid_storage"]`` and as the dtype of ``fluid/f`` and ``fluid/h`` (float32, or float16 holding the
scaled values of :mod:`couplekit.fluid.storage`). A state restarts only into the storage that wrote it:
:meth:`couplekit.fluid.FluidSolver.load_state` refuses fp16 populations in an fp32 fluid and the reverse,
naming ``fluid.storage`` (a conversion would not be an exact restart). Files from before the option hold
float32 populations and a scene without the key, so they load as fp32, as before.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["save_checkpoint", "load_checkpoint", "checkpoint_scene", "CheckpointError", "FORMAT", "dataset_checksum"]

FORMAT = "couplekit-checkpoint"
VERSION = 3
READABLE = (1, 2, 3)
"""Versions :func:`load_checkpoint` reads (1: no checksums; 1 and 2: full populations, converted on load)."""
SHIFTED_SINCE = 3
"""First version whose ``fluid/f`` holds f − w (shifted storage)."""


def _shift_full_populations(states: dict[str, dict[str, np.ndarray]]) -> None:
    """Versions before :data:`SHIFTED_SINCE`: the stored full f (27, ...) of the fluid becomes f − w."""
    fluid = states.get("fluid")
    if fluid is None or "f" not in fluid:
        return
    from ..lattice import W27

    f = np.asarray(fluid["f"], np.float64)
    fluid["f"] = (f - W27.reshape((27,) + (1,) * (f.ndim - 1))).astype(np.float32)


class CheckpointError(ValueError):
    """A file that is not a readable, intact couplekit checkpoint (the message names the file and the defect)."""


def dataset_checksum(a: np.ndarray) -> str:
    """SHA-256 (hex) of an array's dtype, shape and C-order bytes."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def _text_checksum(scene: str, meta: str) -> str:
    return hashlib.sha256((scene + "\0" + meta).encode()).hexdigest()


def save_checkpoint(
    path: str | Path, scene: Mapping[str, Any], states: Mapping[str, Mapping[str, np.ndarray]], meta: Mapping[str, Any]
) -> Path:
    """Write ``states`` ({solver: {name: array}}), the scene dict and ``meta`` to ``path`` atomically."""
    import h5py

    path = Path(path).expanduser()
    if path.is_dir():
        raise CheckpointError(f"{path} is a folder: give the checkpoint a file name, e.g. {path / 'state.h5'}")
    if path.is_symlink() or (path.exists() and not path.is_file()):
        # written by replacing whatever is at the path: a device (/dev/null), a FIFO or a link would become a file
        kind = "a symbolic link" if path.is_symlink() else "not a regular file (a device, a FIFO or a socket)"
        raise CheckpointError(f"{path} is {kind}: a checkpoint replaces the file at its path; give a new or a "
                              "regular file's path")  # fmt: skip
    if not path.parent.is_dir():
        raise CheckpointError(f"cannot write {path}: its folder {path.parent} does not exist; create it first")
    if path.is_file() and not _is_checkpoint_file(path):
        # a checkpoint replaces an earlier checkpoint at its path, never another file (a probe: save("scene.toml")
        # replaced the user's scene file)
        raise CheckpointError(
            f"{path} holds a file that is not a couplekit checkpoint: saving would replace it; give a new path "
            "(e.g. one ending in .h5), or delete the file first"
        )
    tmp = path.with_name(path.name + ".tmp")
    scene_text, meta_text = json.dumps(scene), json.dumps(dict(meta))
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["version"] = VERSION
            f.attrs["scene"] = scene_text
            f.attrs["meta"] = meta_text
            f.attrs["checksum"] = _text_checksum(scene_text, meta_text)
            for solver, state in states.items():
                g = f.create_group(solver)
                for name, arr in state.items():
                    a = np.asarray(arr)
                    ds = g.create_dataset(name, data=a)
                    ds.attrs["sha256"] = dataset_checksum(a)
        os.replace(tmp, path)
    except BaseException:  # a full disk, Ctrl-C: no half-written file is left, and the previous checkpoint stays
        tmp.unlink(missing_ok=True)
        raise
    return path


def _is_checkpoint_file(path: Path) -> bool:
    """Whether ``path`` is an HDF5 file a couplekit checkpoint was written into (its format attribute; a damaged
    one counts, its contents are not verified)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return f.attrs.get("format") == FORMAT
    except (OSError, ValueError):
        return False


def _attr_text(f, path, name: str) -> str:
    if name not in f.attrs:
        raise CheckpointError(f"{path}: the checkpoint has no {name!r} attribute (a damaged or foreign file)")
    value = f.attrs[name]
    return value.decode() if isinstance(value, bytes) else str(value)


def _json(text: str, path, name: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CheckpointError(f"{path}: the checkpoint's {name} is not valid JSON ({exc})") from None
    if not isinstance(value, dict):
        raise CheckpointError(f"{path}: the checkpoint's {name} is not a table (got {type(value).__name__})")
    return value


def _open(path):
    import h5py

    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a checkpoint file's path (a str or a pathlib.Path), got {type(path).__name__}")
    file = Path(path).expanduser()
    if not file.exists():
        raise CheckpointError(f"{path}: no such file (give the path of a checkpoint a run saved, e.g. checkpoint.h5)")
    if file.is_dir():
        raise CheckpointError(f"{path} is a folder: give the checkpoint file in it (e.g. {file / 'checkpoint.h5'})")
    try:
        return h5py.File(file, "r")
    except OSError as exc:
        raise CheckpointError(f"{path}: not a readable HDF5 file ({exc})") from None


def _header(f, path) -> tuple[dict, dict, int]:
    """(scene dict, meta, version) of an open checkpoint, its format, version and checksum verified."""
    if f.attrs.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a couplekit checkpoint (format attribute {f.attrs.get('format')!r})")
    try:
        version = int(f.attrs["version"])
    except (KeyError, TypeError, ValueError):
        raise CheckpointError(f"{path}: the checkpoint has no readable version attribute") from None
    if version not in READABLE:
        raise CheckpointError(f"{path}: checkpoint version {version} (this couplekit reads {READABLE})")
    scene_text, meta_text = _attr_text(f, path, "scene"), _attr_text(f, path, "meta")
    if version >= 2 and _attr_text(f, path, "checksum") != _text_checksum(scene_text, meta_text):
        raise CheckpointError(f"{path}: the scene or metadata was changed after the checkpoint was written")
    return _json(scene_text, path, "scene"), _json(meta_text, path, "metadata"), version


def checkpoint_scene(path: str | Path) -> dict:
    """The scene dict stored in a checkpoint, verified as :func:`load_checkpoint` verifies it, without reading
    the solver arrays; :class:`CheckpointError` naming the file and the defect."""
    with _open(path) as f:
        return _header(f, path)[0]


def checkpoint_meta(path: str | Path) -> dict:
    """The metadata (step, time, backend, ...) stored in a checkpoint, verified as :func:`load_checkpoint`
    verifies it, without reading the solver arrays; :class:`CheckpointError` naming the file and the defect."""
    with _open(path) as f:
        return _header(f, path)[1]


def load_checkpoint(path: str | Path) -> tuple[dict, dict[str, dict[str, np.ndarray]], dict]:
    """(scene dict, states, meta) of a checkpoint written by :func:`save_checkpoint`, verified (module
    docstring); raises :class:`CheckpointError` naming the file and the defect."""
    import h5py

    with _open(path) as f:
        scene, meta, version = _header(f, path)
        if "step" not in meta:
            raise CheckpointError(f"{path}: the checkpoint's metadata has no step count")
        states: dict[str, dict[str, np.ndarray]] = {}
        for name, g in f.items():
            if not isinstance(g, h5py.Group):
                raise CheckpointError(f"{path}: {name!r} is not a group of solver arrays")
            states[name] = {}
            for k, ds in g.items():
                try:
                    a = np.array(ds[()])
                except OSError as exc:
                    raise CheckpointError(f"{path}: dataset {name}/{k} cannot be read ({exc})") from None
                if version >= 2:
                    want = ds.attrs.get("sha256")
                    if want is None:
                        raise CheckpointError(f"{path}: dataset {name}/{k} has no checksum")
                    if dataset_checksum(a) != (want.decode() if isinstance(want, bytes) else str(want)):
                        raise CheckpointError(
                            f"{path}: dataset {name}/{k} does not match its checksum: the file was changed or "
                            "damaged after it was written; resume from another checkpoint"
                        )
                states[name][k] = a
    if version < SHIFTED_SINCE:
        _shift_full_populations(states)
    return scene, states, meta
