"""PNG previews rendered off-screen with PyVista: the domain outline, the water surface (φ = ½), obstacles
and sand particles coloured by speed.

Headless rendering works through VTK's EGL (or OSMesa) render window; on Debian/Ubuntu the system libraries
are ``libegl1 libegl-mesa0 libgl1`` (Mesa's software rasteriser is enough, no GPU or X server needed).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["render_preview"]


def _image(field: np.ndarray, dx: float):
    import pyvista as pv

    nz, ny, nx = field.shape
    g = pv.ImageData(dimensions=(nx, ny, nz), spacing=(dx, dx, dx), origin=(0.5 * dx,) * 3)
    g.point_data["v"] = np.ascontiguousarray(field, dtype=np.float32).reshape(-1)
    return g


def render_preview(
    path: str | Path,
    size: tuple[float, float, float],
    dx: float,
    fields: Mapping[str, np.ndarray] | None = None,
    particles: Mapping[str, np.ndarray] | None = None,
    title: str = "",
    window: tuple[int, int] = (800, 600),
) -> Path:
    """Render a preview PNG of a frame. ``fields`` may hold ``phi``, ``solid``; ``particles`` ``x`` (3, P)
    and ``v`` (3, P). Returns the path written."""
    if not os.environ.get("DISPLAY"):
        # without an X server go straight to EGL (VTK would try X first and print a warning)
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    fields, particles = fields or {}, particles or {}
    p = pv.Plotter(off_screen=True, window_size=list(window))
    p.set_background("white")
    p.add_mesh(pv.Box(bounds=(0, size[0], 0, size[1], 0, size[2])).outline(), color="black")
    phi = fields.get("phi")
    if phi is not None and fields.get("solid") is not None:
        phi = np.where(np.asarray(fields["solid"], bool), 0.0, phi)  # no water surface drawn inside obstacles
    if phi is not None and np.nanmax(phi) > 0.5 > np.nanmin(phi):
        surf = _image(np.nan_to_num(phi), dx).contour([0.5], scalars="v")
        if surf.n_points:
            p.add_mesh(surf, color="#3a7bd5", opacity=0.55, smooth_shading=True)
    solid = fields.get("solid")
    if solid is not None and np.any(solid) and not np.all(solid):
        surf = _image(np.asarray(solid, np.float32), dx).contour([0.5], scalars="v")
        if surf.n_points:
            p.add_mesh(surf, color="#888888", opacity=0.2)  # see-through, so containers do not hide the scene
    x = particles.get("x")
    if x is not None and np.asarray(x).shape[1] > 0:
        x = np.asarray(x, dtype=np.float32)
        cloud = pv.PolyData(np.ascontiguousarray(x.T))
        v = particles.get("v")
        if v is not None:
            speed = np.linalg.norm(np.asarray(v, np.float32), axis=0)
            cloud.point_data["speed (m/s)"] = speed
            top = float(np.nanmax(speed)) if np.isfinite(speed).any() else 1.0
            p.add_mesh(cloud, scalars="speed (m/s)", cmap="copper", clim=(0.0, max(top, 1e-6)), point_size=3)
        else:
            p.add_mesh(cloud, color="#c2a46b", point_size=3)
    if title:
        p.add_text(title, font_size=10, color="black")
    p.camera_position = "iso"
    p.camera.azimuth = 20
    p.reset_camera()
    path = Path(path)
    p.screenshot(str(path))
    p.close()
    return path
