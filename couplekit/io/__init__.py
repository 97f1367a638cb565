"""Outputs: ParaView series (.vti fields, .vtp particles, .pvd indexes), PLY particle sequences, PNG previews,
the diagnostics log (JSON lines) and HDF5 checkpoints.

* :mod:`.vtk` — :func:`write_fields_vti`, :func:`write_particles_vtp`, :class:`PvdIndex`;
* :mod:`.ply` — :func:`write_particles_ply`, :func:`read_ply`;
* :mod:`.preview` — :func:`render_preview` (off-screen PyVista);
* :mod:`.surface` — :func:`water_surface` (the φ = ½ mesh), :func:`write_surface` (.ply, .obj, .vtp);
* :mod:`.diagnostics` — :class:`DiagnosticsLog`, :func:`read_diagnostics`;
* :mod:`.checkpoint` — :func:`save_checkpoint`, :func:`load_checkpoint`;
* :mod:`.files` — :func:`~couplekit.io.files.write_all` (several files all or none).
* :mod:`.plots` — :func:`~couplekit.io.plots.plot_run`, :func:`~couplekit.io.plots.compare_runs` (matplotlib;
  imported on use, not here).
"""

from __future__ import annotations

from .checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from .diagnostics import DiagnosticsLog, read_diagnostics
from .ply import read_ply, write_particles_ply
from .preview import render_preview
from .surface import water_surface, write_surface
from .vtk import PvdIndex, read_pvd, write_fields_vti, write_particles_vtp

__all__ = [
    "CheckpointError",
    "DiagnosticsLog",
    "PvdIndex",
    "load_checkpoint",
    "read_diagnostics",
    "read_ply",
    "read_pvd",
    "render_preview",
    "save_checkpoint",
    "water_surface",
    "write_fields_vti",
    "write_particles_ply",
    "write_particles_vtp",
    "write_surface",
]
