"""ParaView time series: VTK image data (.vti) for grid fields, poly data (.vtp) for particles, .pvd indexes.

Grid fields follow the couplekit layout: scalars ``(nz, ny, nx)``, vectors ``(3, nz, ny, nx)``, x contiguous,
which is VTK's point order, so a field is written without reordering. Points of the image are the cell
centres: origin (½dx, ½dx, ½dx) (plus the domain origin), spacing dx.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["write_fields_vti", "write_particles_vtp", "PvdIndex", "read_pvd"]


def _flat(a: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == bool:
        a = a.astype(np.uint8)
    if a.shape == shape:
        return np.ascontiguousarray(a).reshape(-1)
    if a.ndim == 4 and a.shape[1:] == shape:
        return np.ascontiguousarray(a.reshape(a.shape[0], -1).T)  # (N, components)
    raise ValueError(f"field of shape {a.shape} does not fit the grid {shape}")


def write_fields_vti(path: str | Path, fields: Mapping[str, np.ndarray], dx: float, origin=(0.0, 0.0, 0.0)) -> Path:
    """Write grid fields (scalars (nz, ny, nx) or vectors (C, nz, ny, nx)) as a .vti image at cell centres."""
    import pyvista as pv

    if not fields:
        raise ValueError("no fields to write")
    first = np.asarray(next(iter(fields.values())))
    shape = tuple(first.shape[-3:])
    nz, ny, nx = shape
    grid = pv.ImageData(dimensions=(nx, ny, nz), spacing=(dx, dx, dx), origin=tuple(np.asarray(origin) + 0.5 * dx))
    for name, a in fields.items():
        grid.point_data[name] = _flat(a, shape)
    path = Path(path)
    grid.save(str(path))
    return path


def write_particles_vtp(path: str | Path, x: np.ndarray, data: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write particles (positions (3, P)) with per-particle arrays ((P,) or (C, P)) as .vtp poly data."""
    import pyvista as pv

    pts = np.ascontiguousarray(np.asarray(x, dtype=np.float32).T)
    cloud = pv.PolyData(pts) if len(pts) else pv.PolyData()
    if len(pts):
        cloud.verts = np.column_stack([np.ones(len(pts), np.int64), np.arange(len(pts))]).ravel()
        for name, a in (data or {}).items():
            a = np.asarray(a)
            cloud.point_data[name] = np.ascontiguousarray(a.T if a.ndim == 2 else a)
    path = Path(path)
    cloud.save(str(path))
    return path


class PvdIndex:
    """A ParaView collection (.pvd) listing files by time; rewritten after every :meth:`add` (atomically), so
    a run that stops early leaves a valid index of what it wrote. Entries of an existing index are kept
    (a resumed run appends, dropping entries at or after its first new time)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.entries: list[tuple[float, str]] = read_pvd(self.path) if self.path.exists() else []

    def add(self, time: float, file: str | Path) -> None:
        rel = os.path.relpath(Path(file), self.path.parent)
        self.entries = [e for e in self.entries if e[0] < time] + [(float(time), rel)]
        root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
        coll = ET.SubElement(root, "Collection")
        for t, f in self.entries:
            ET.SubElement(coll, "DataSet", timestep=repr(t), group="", part="0", file=f)
        tmp = self.path.with_suffix(".pvd.tmp")
        try:
            ET.ElementTree(root).write(tmp, xml_declaration=True, encoding="utf-8")
            os.replace(tmp, self.path)
        except BaseException:  # a full disk: the index written before stays, no half-written one beside it
            tmp.unlink(missing_ok=True)
            raise


def read_pvd(path: str | Path) -> list[tuple[float, str]]:
    """(time, file) entries of a .pvd index."""
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]
