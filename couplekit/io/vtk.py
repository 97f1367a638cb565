"""ParaView time series: VTK image data (.vti) for grid fields, poly data (.vtp) for particles, .pvd indexes.

Grid fields follow the couplekit layout: scalars ``(nz, ny, nx)``, vectors ``(3, nz, ny, nx)``, x contiguous,
which is VTK's point order, so a field is written without reordering. Points of the image are the cell
centres: origin (½dx, ½dx, ½dx) (plus the domain origin), spacing dx.

Writing is safe on a full disk (:func:`save_vtk`): VTK's XML writer crashes the process (SIGSEGV/SIGABRT) or
leaves a cut-off file when the disk fills under it, which Python cannot catch, so each file is checked against
the folder's free space *before* VTK runs, written under a temporary name and renamed onto its own only when
complete. Every failure is an :class:`OSError` (``couplekit run``: exit 2 and a message), and no cut-off file is
left under a frame's name.
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import secrets
import shutil
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .outputs import OutputIndexError

__all__ = ["write_fields_vti", "write_particles_vtp", "PvdIndex", "read_pvd", "save_vtk", "vtk_bytes_bound"]

_SIZE_FACTOR = 1.4
"""Bound of a VTK XML file's size per raw byte of its arrays: base64 (4/3) where VTK encodes, and zlib blocks
that can grow incompressible data by a little; the binary appended files pyvista writes measure 1.0-1.15x."""
_SIZE_SLACK = 64 * 1024
"""Bytes added to the bound: the XML header, block headers and a small file's file-system block."""


def vtk_bytes_bound(dataset) -> int:
    """A safe upper bound of the bytes ``dataset.save(...)`` will write as VTK XML: the raw bytes of its
    point, cell and field data, of its points (not for image data, which stores only its extent) and of its
    cells (verts, lines, faces, strips, or an unstructured grid's cells and types: VTK writes them as offsets +
    connectivity, as many bytes), times
    :data:`_SIZE_FACTOR`, plus :data:`_SIZE_SLACK`."""
    import pyvista as pv

    raw = 0
    for attrs in (dataset.point_data, dataset.cell_data, dataset.field_data):
        for name in attrs.keys():
            raw += np.asarray(attrs[name]).nbytes
    if not isinstance(dataset, pv.ImageData):  # ImageData.points would build the coordinates: none are written
        points = getattr(dataset, "points", None)
        if points is not None:
            raw += np.asarray(points).nbytes
        kinds = ("verts", "lines", "faces", "strips") if isinstance(dataset, pv.PolyData) else ("cells", "celltypes")
        for cells in kinds:  # an unstructured grid's cells and types; none for the structured kinds
            a = getattr(dataset, cells, None)
            if a is not None:
                raw += np.asarray(a).nbytes
    return int(math.ceil(raw * _SIZE_FACTOR)) + _SIZE_SLACK


def _mib(n: float) -> str:
    return f"{n / 2**20:.3g} MiB"


def save_vtk(dataset, path: str | Path) -> Path:
    """Save a pyvista dataset as the VTK XML file ``path`` (the suffix picks the format), safely on a full disk.

    1. The folder's free space (:func:`shutil.disk_usage`) is compared with :func:`vtk_bytes_bound`; when it is
       short, :class:`OSError` (``errno.ENOSPC``) is raised before VTK runs, naming the folder, the bytes needed
       and free, and the fix. (VTK crashes the whole process on ENOSPC, so this check is what turns a full disk
       into an error; a disk filled by another program between the check and the write can still crash it.)
    2. The file is written to a hidden temporary name in the same folder (``.NAME.<random>.tmp.SUFFIX``) and
       :func:`os.replace`'d onto ``path`` only when complete; on any exception the temporary file is removed,
       so ``path`` is either the whole new file or what it was before.
    3. A file VTK reports as written but that is empty or does not end with ``</VTKFile>`` (VTK can stop
       short on a write error without raising) raises :class:`OSError` (``errno.EIO``).
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    need = vtk_bytes_bound(dataset)
    free = shutil.disk_usage(folder).free  # FileNotFoundError for a missing folder, as pyvista raised
    if free < need:
        raise OSError(
            errno.ENOSPC,
            f"not enough free space in {folder} to write {path.name}: it needs up to {need} bytes "
            f"({_mib(need)}), {free} bytes ({_mib(free)}) are free; free space on that disk, or write the run "
            "elsewhere with --out DIR",
            str(path),
        )
    tmp = folder / f".{path.name}.{secrets.token_hex(4)}.tmp{path.suffix}"
    try:
        dataset.save(str(tmp))
        _check_complete(tmp, path)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _check_complete(tmp: Path, path: Path) -> None:
    """Raise OSError(EIO) when the file VTK wrote to ``tmp`` (for ``path``) is empty or cut off."""
    size = tmp.stat().st_size
    with open(tmp, "rb") as fh:
        fh.seek(max(0, size - 256))
        tail = fh.read()
    if size == 0 or b"</VTKFile>" not in tail:
        raise OSError(
            errno.EIO,
            f"VTK wrote {path.name} incompletely ({size} bytes, {'empty' if size == 0 else 'cut off'}) into "
            f"{path.parent}: the disk may be full or failing; free space on that disk, or write the run "
            "elsewhere with --out DIR",
            str(path),
        )


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
    """Write grid fields (scalars (nz, ny, nx) or vectors (C, nz, ny, nx)) as a .vti image at cell centres.

    Written through :func:`save_vtk`: :class:`OSError` before anything is written when the folder has too
    little free space, and never a cut-off file under ``path``."""
    import pyvista as pv

    if not fields:
        raise ValueError("no fields to write")
    first = np.asarray(next(iter(fields.values())))
    shape = tuple(first.shape[-3:])
    nz, ny, nx = shape
    grid = pv.ImageData(dimensions=(nx, ny, nz), spacing=(dx, dx, dx), origin=tuple(np.asarray(origin) + 0.5 * dx))
    for name, a in fields.items():
        grid.point_data[name] = _flat(a, shape)
    return save_vtk(grid, path)


def write_particles_vtp(path: str | Path, x: np.ndarray, data: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write particles (positions (3, P)) with per-particle arrays ((P,) or (C, P)) as .vtp poly data.

    Written through :func:`save_vtk`: :class:`OSError` before anything is written when the folder has too
    little free space, and never a cut-off file under ``path``."""
    import pyvista as pv

    pts = np.ascontiguousarray(np.asarray(x, dtype=np.float32).T)
    cloud = pv.PolyData(pts) if len(pts) else pv.PolyData()
    if len(pts):
        cloud.verts = np.column_stack([np.ones(len(pts), np.int64), np.arange(len(pts))]).ravel()
        for name, a in (data or {}).items():
            a = np.asarray(a)
            cloud.point_data[name] = np.ascontiguousarray(a.T if a.ndim == 2 else a)
    return save_vtk(cloud, path)


class PvdIndex:
    """A ParaView collection (.pvd) listing files by time; rewritten after every :meth:`add` (atomically), so
    a run that stops early leaves a valid index of what it wrote. Entries of an existing index are kept
    (a resumed run appends, dropping entries at or after its first new time).

    A damaged or empty existing index (a crash of the file system or a sync tool, an edit) is **rebuilt**, not
    refused: the index lists the frame files ``<stem>_NNNN.vt?`` beside it (``fields.pvd`` →
    ``fields_0003.vti``), and a frame's time is recovered exactly from the other records of the same run in the
    folder: the other ``*.pvd`` indexes (a run writes every series of a frame at the same time) and
    ``diagnostics.jsonl`` (one line per frame with its ``frame`` and ``time``). These hold the very floats the
    index held, so the rebuilt index is the lost one; guessing times (say frame × a frame duration) could
    silently misplace frames in ParaView, so it is not done: when a frame file's time is in no record, or the
    records disagree, :class:`~couplekit.io.outputs.OutputIndexError` (an OSError) names the index and the fix
    (delete it, so that the run indexes only the frames it writes, or write elsewhere with --out).
    ``rebuilt`` tells whether the index was rebuilt."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.rebuilt = False
        self.entries: list[tuple[float, str]] = []
        if self.path.exists():
            try:
                self.entries = read_pvd(self.path)
            except OutputIndexError as exc:
                self.entries = self._rebuild(exc)
                self.rebuilt = True
                self._write()

    def add(self, time: float, file: str | Path) -> None:
        rel = os.path.relpath(Path(file), self.path.parent)
        self.entries = [e for e in self.entries if e[0] < time] + [(float(time), rel)]
        self._write()

    def _write(self) -> None:
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

    def _rebuild(self, damage: OutputIndexError) -> list[tuple[float, str]]:
        """Entries of the damaged index from its frame files and the run's other records (class docstring)."""
        folder = self.path.parent
        pattern = re.compile(rf"{re.escape(self.path.stem)}_(\d+)\.(vti|vtp|vtu|vts|vtr|vtm)")
        frames = sorted(
            (int(m.group(1)), p.name) for p in folder.iterdir() if (m := pattern.fullmatch(p.name)) and p.is_file()
        )
        times, conflicts = _frame_times(folder, exclude=self.path)
        missing = [name for n, name in frames if n not in times or n in conflicts]
        if missing:
            why = "disagree about" if any(n in conflicts for n, _ in frames) else "do not hold"
            shown = ", ".join(missing[:3]) + (f" and {len(missing) - 3} more" if len(missing) > 3 else "")
            raise OutputIndexError(
                f"the ParaView index {self.path} is damaged ({damage.reason}) and cannot be rebuilt: the other "
                f"*.pvd indexes and diagnostics.jsonl in {folder} {why} the time of {shown}; delete {self.path} "
                "(the run then indexes only the frames it writes from now on; the frame files stay), or write "
                "elsewhere with --out DIR"
            )
        return sorted((times[n], name) for n, name in frames)


def _frame_times(folder: Path, exclude: Path) -> tuple[dict[int, float], set[int]]:
    """Frame number → time from the readable ``*.pvd`` indexes in ``folder`` other than ``exclude`` (the frame
    number is the digits after the last ``_`` of an entry's file name) and from ``diagnostics.jsonl`` (lines
    that do not parse are skipped: a log cut off by a crash); plus the frames whose records disagree."""
    found: dict[int, float] = {}
    conflicts: set[int] = set()

    def note(frame: int, t: float) -> None:
        if not math.isfinite(t):
            return
        if frame in found and not math.isclose(found[frame], t, rel_tol=1e-9, abs_tol=1e-300):
            conflicts.add(frame)
        found.setdefault(frame, t)

    for pvd in sorted(folder.glob("*.pvd")):
        if pvd.name == exclude.name or not pvd.is_file():
            continue
        try:
            entries = read_pvd(pvd)
        except OSError:
            continue
        for t, f in entries:
            m = re.search(r"_(\d+)\.[A-Za-z0-9]+$", Path(f).name)
            if m:
                note(int(m.group(1)), t)
    try:
        with open(folder / "diagnostics.jsonl", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                try:
                    rec = json.loads(line)
                    frame, t = float(rec["frame"]), float(rec["time"])
                except (ValueError, TypeError, KeyError):
                    continue
                if frame.is_integer():
                    note(int(frame), t)
    except OSError:
        pass
    return found, conflicts


def read_pvd(path: str | Path) -> list[tuple[float, str]]:
    """(time, file) entries of a .pvd index. A file that is not a readable index (empty, cut off, not XML, not a
    VTK collection, a ``DataSet`` without a numeric ``timestep`` or a ``file``) raises
    :class:`~couplekit.io.outputs.OutputIndexError` (an OSError; its ``reason`` says what is wrong)."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
        if root.tag != "VTKFile" or root.find("Collection") is None:
            raise ValueError(f"not a VTK collection (root <{root.tag}>)")
        entries = []
        for d in root.iter("DataSet"):
            t, f = float(d.get("timestep")), d.get("file")
            if not f:
                raise ValueError("a DataSet without a file")
            entries.append((t, f))
    except (ET.ParseError, ValueError, TypeError) as exc:
        reason = "empty" if path.is_file() and path.stat().st_size == 0 else str(exc) or type(exc).__name__
        err = OutputIndexError(
            f"{path} is not a readable ParaView index ({reason}); a run resumed into its folder rebuilds it "
            "from the frame files and the run's other records where it can (PvdIndex)"
        )
        err.reason = reason
        raise err from None
    return entries
