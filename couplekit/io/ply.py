"""Particle sequences as binary PLY point clouds (Blender imports them; one file per frame).

Each vertex has x, y, z (float32) and any number of float32 per-particle properties (a (C, P) array becomes
properties name_0 … name_{C-1}). :func:`read_ply` reads them back (for tests and scripts).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["write_particles_ply", "read_ply"]


def write_particles_ply(path: str | Path, x: np.ndarray, data: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write positions (3, P) and per-particle arrays as a binary little-endian PLY point cloud."""
    x = np.asarray(x, dtype=np.float32)
    if x.ndim != 2 or x.shape[0] != 3:
        raise ValueError(f"positions must have shape (3, P), got {x.shape}")
    n = x.shape[1]
    columns = {"x": x[0], "y": x[1], "z": x[2]}
    for name, a in (data or {}).items():
        a = np.asarray(a, dtype=np.float32)
        if a.ndim == 1:
            columns[name] = a
        else:
            for c in range(a.shape[0]):
                columns[f"{name}_{c}"] = a[c]
    for name, a in columns.items():
        if a.shape != (n,):
            raise ValueError(f"particle array {name!r} has shape {a.shape}, expected ({n},)")
    rec = np.empty(n, dtype=[(k, "<f4") for k in columns])
    for k, a in columns.items():
        rec[k] = a
    header = "ply\nformat binary_little_endian 1.0\ncomment couplekit particles\n"
    header += f"element vertex {n}\n" + "".join(f"property float {k}\n" for k in columns) + "end_header\n"
    path = Path(path)
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(rec.tobytes())
    return path


def read_ply(path: str | Path) -> dict[str, np.ndarray]:
    """The float vertex properties of a binary little-endian PLY written by :func:`write_particles_ply`."""
    with open(path, "rb") as fh:
        if fh.readline().strip() != b"ply":
            raise ValueError(f"{path} is not a PLY file")
        names, n = [], 0
        while True:
            line = fh.readline().decode("ascii").strip()
            if line.startswith("format") and "binary_little_endian" not in line:
                raise ValueError(f"{path}: only binary_little_endian PLY is read here")
            if line.startswith("element vertex"):
                n = int(line.split()[2])
            elif line.startswith("property float"):
                names.append(line.split()[2])
            elif line == "end_header":
                break
        rec = np.frombuffer(fh.read(n * 4 * len(names)), dtype=[(k, "<f4") for k in names], count=n)
    return {k: np.array(rec[k]) for k in names}
