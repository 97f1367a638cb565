"""The water surface of a frame as a triangle mesh: the φ = ½ level set, for renderers and ParaView.

:func:`water_surface` contours φ with PyVista's (VTK's) flying-edges marching cubes, so the mesh is made by a
well-kept library, not by couplekit. Conventions:

* **Coordinates**: metres, in the domain's frame: φ of cell (i, j, k) sits at the cell centre
  ((i + ½) dx, (j + ½) dx, (k + ½) dx) (plus ``origin``), as in the .vti fields (:mod:`couplekit.io.vtk`).
* **Closed water bodies**: φ is padded with one layer of air (φ = 0) outside the domain before contouring, so
  the mesh is the whole boundary of the water: the free surface *and* the faces where the water meets the
  domain walls, on the wall planes x = 0, x = size_x, ...: φ = ½ is interpolated between the padding, φ = 0
  half a cell outside, and the last cell centre, φ_c, so the wall lies ½/φ_c − ½ cells inside the face (0.004
  cells where φ_c = 0.992; more only within the interface width of the free surface, where the mesh rounds
  the edge between wall and free surface). A pool is a closed box-like mesh whose top is the free
  surface; a drop in the air is a closed sphere-like mesh. Every water body is a closed, watertight, consistently
  oriented manifold, which is what renderers need for refraction and volume shading. This holds for periodic
  and open faces too (the water is closed at the face; the mesh does not continue periodically).
* **Obstacles**: φ is set to 0 in solid cells (as the previews do), so the water's boundary runs along the
  obstacle faces, half-way between a solid and a fluid cell centre, and no surface is drawn inside obstacles.
* **Normals**: per vertex, from the gradient of φ (VTK's contour normals), unit length, pointing *out of the
  water* (towards decreasing φ); the triangles are wound counter-clockwise seen from outside, so the winding
  agrees with the normals.

Writers: :func:`write_surface_ply` (binary little-endian PLY with vertex normals, Blender / MeshLab),
:func:`write_surface_obj` (Wavefront OBJ with ``vn`` normals), :func:`write_surface_vtp` (VTK poly data for
the ParaView series ``surface.pvd``). A frame without water gives an empty mesh, which every writer writes as
a valid file with no vertices (so a sequence has no gaps).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = [
    "water_surface",
    "write_surface",
    "write_surface_ply",
    "write_surface_obj",
    "write_surface_vtp",
    "SURFACE_FORMATS",
]

SURFACE_FORMATS = ("ply", "obj")
"""Renderer formats of the per-frame surface files (the .vtp for ParaView comes with ``outputs.vtk``)."""


def water_surface(
    phi: np.ndarray,
    dx: float,
    solid: np.ndarray | None = None,
    *,
    level: float = 0.5,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
):
    """The closed φ = ``level`` surface of the water as a triangulated ``pyvista.PolyData`` (module docstring).

    ``phi``: the phase field (nz, ny, nx) at the cell centres (1 water, 0 air); NaN counts as air. ``dx``: cell
    size in metres. ``solid``: obstacle cells (nz, ny, nx), True inside obstacles, or None. Returns points in
    metres (float32), triangles only, and the point array ``Normals`` (float32, unit, out of the water)."""
    import pyvista as pv

    phi = np.asarray(phi)
    if phi.ndim != 3:
        raise ValueError(f"phi must be a grid field of shape (nz, ny, nx), got shape {phi.shape}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie strictly between 0 (air) and 1 (water), got {level}")
    if not dx > 0:
        raise ValueError(f"dx must be a positive cell size in metres, got {dx}")
    phi = np.nan_to_num(phi.astype(np.float32), nan=0.0)
    if solid is not None:
        solid = np.asarray(solid, dtype=bool)
        if solid.shape != phi.shape:
            raise ValueError(f"solid has shape {solid.shape} but phi {phi.shape}; pass both from the same frame")
        phi = np.where(solid, np.float32(0.0), phi)
    if not phi.max(initial=0.0) > level:
        return _empty()
    padded = np.pad(phi, 1, mode="constant", constant_values=0.0)  # air outside the domain: closed bodies
    nz, ny, nx = padded.shape
    o = np.asarray(origin, dtype=np.float64) - 0.5 * dx  # padded cell 0 is centred half a cell outside
    grid = pv.ImageData(dimensions=(nx, ny, nz), spacing=(dx, dx, dx), origin=tuple(o))
    grid.point_data["phi"] = np.ascontiguousarray(padded).reshape(-1)
    contour = grid.contour([level], scalars="phi", method="flying_edges", compute_normals=True)
    if contour.n_points == 0:
        return _empty()
    contour = contour.triangulate()
    mesh = pv.PolyData(np.asarray(contour.points, dtype=np.float32), faces=contour.faces)
    normals = np.asarray(contour.point_data["Normals"], dtype=np.float32)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), np.float32(1e-30))
    mesh.point_data["Normals"] = normals
    mesh.point_data.active_normals_name = "Normals"
    return mesh


def _empty():
    """The surface of a frame without water: no points, no triangles."""
    import pyvista as pv

    return pv.PolyData()


def _arrays(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (N, 3) float32, normals (N, 3) float32, triangles (M, 3) int32) of a surface mesh."""
    points = np.asarray(mesh.points, dtype=np.float32).reshape(-1, 3)
    if len(points) == 0:
        return points, np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    faces = np.asarray(mesh.faces).reshape(-1, 4) if mesh.n_cells else np.zeros((0, 4), np.int64)
    if len(faces) and not np.all(faces[:, 0] == 3):
        raise ValueError("the surface mesh has faces that are not triangles; build it with water_surface()")
    if "Normals" not in mesh.point_data:
        raise ValueError("the surface mesh has no point array 'Normals'; build it with water_surface()")
    normals = np.asarray(mesh.point_data["Normals"], dtype=np.float32).reshape(-1, 3)
    return points, normals, faces[:, 1:].astype(np.int32)


def write_surface_ply(path: str | Path, mesh) -> Path:
    """Write a surface mesh as binary little-endian PLY: vertices x, y, z, nx, ny, nz (float32; the layout
    of :mod:`couplekit.io.ply`'s particle files plus the normals) and triangles (``vertex_indices``)."""
    points, normals, tris = _arrays(mesh)
    vert = np.empty(len(points), dtype=[(k, "<f4") for k in ("x", "y", "z", "nx", "ny", "nz")])
    for c, k in enumerate("xyz"):
        vert[k] = points[:, c]
        vert[f"n{k}"] = normals[:, c]
    face = np.empty(len(tris), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face["n"] = 3
    face["i"] = tris
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment couplekit water surface (phi = 1/2), metres\n"
        f"element vertex {len(points)}\n"
        + "".join(f"property float {k}\n" for k in ("x", "y", "z", "nx", "ny", "nz"))
        + f"element face {len(tris)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    path = Path(path)
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(vert.tobytes())
        fh.write(face.tobytes())
    return path


def write_surface_obj(path: str | Path, mesh) -> Path:
    """Write a surface mesh as Wavefront OBJ: ``v`` positions (m), ``vn`` unit normals, ``f a//a b//b c//c``
    triangles (1-based; vertex i has normal i)."""
    points, normals, tris = _arrays(mesh)
    path = Path(path)
    with open(path, "w", encoding="ascii") as fh:
        fh.write("# couplekit water surface (phi = 1/2), metres\n")
        if len(points):
            np.savetxt(fh, points, fmt="v %.7g %.7g %.7g")
            np.savetxt(fh, normals, fmt="vn %.6g %.6g %.6g")
        if len(tris):
            t = tris.astype(np.int64) + 1
            np.savetxt(fh, np.repeat(t, 2, axis=1), fmt="f %d//%d %d//%d %d//%d")
    return path


def write_surface_vtp(path: str | Path, mesh) -> Path:
    """Write a surface mesh as VTK XML poly data (.vtp) with its ``Normals`` (the ParaView series), through
    :func:`couplekit.io.vtk.save_vtk` (checked against the free space first, never a cut-off file)."""
    from .vtk import save_vtk

    return save_vtk(mesh, path)


_WRITERS = {"ply": write_surface_ply, "obj": write_surface_obj, "vtp": write_surface_vtp}


def write_surface(path: str | Path, mesh) -> Path:
    """Write a surface mesh in the format its suffix names: ``.ply``, ``.obj`` or ``.vtp``."""
    path = Path(path)
    kind = path.suffix.lower().lstrip(".")
    if kind not in _WRITERS:
        raise ValueError(f"cannot write a surface as {path.name!r}: use a .ply, .obj or .vtp file name")
    return _WRITERS[kind](path, mesh)
