"""PNG previews rendered off-screen with PyVista: the domain outline with axes in metres, the water surface
(φ = ½), obstacles, sand particles coloured by speed, a legend and a colour bar beside the box.

The sand is coloured by its wetness or by its speed (``colour_by``). By wetness as paper 000 renders it
(§5.1): with water retention by the water each particle has retained, r_p (Eq. 58), on a ramp from the dry
sand colour to :data:`WET_SAND_COLOUR` over the fixed range 0 to r_max; without retention in two colours, wet
where the particle's saturation exceeds (1 − ε_max)/2 (wetness ½, :mod:`couplekit.coupling.wetness`).

The colour scale of the sand speed is fixed for a run, so frames can be compared: :func:`preview_speed_range`
takes it from the scene (``time.max_speed`` when the scene gives it, otherwise the speed estimate every
time-step check uses, :meth:`couplekit.scene.Scene.expected_max_speed`: body and inflow speeds plus free fall
over the domain). A pile at rest is then drawn dark, not stretched to full contrast; particles faster than the
scale are drawn in :data:`ABOVE_COLOUR` (and the legend says so).

Headless rendering works through VTK's EGL (or OSMesa) render window; on Debian/Ubuntu the system libraries
are ``libegl1 libegl-mesa0 libgl1`` (Mesa's software rasteriser is enough, no GPU or X server needed).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["render_preview", "preview_speed_range", "ABOVE_COLOUR", "WET_SAND_COLOUR", "COLOUR_BY"]

WATER_COLOUR, OBSTACLE_COLOUR, SAND_COLOUR = "#3a7bd5", "#888888", "#c2a46b"
WET_SAND_COLOUR = "#5c4426"
"""Sand at the wet end of the wetness colouring: the dry sand colour darkened, as wet sand looks."""
COLOUR_BY = ("speed", "wetness")
"""What :func:`render_preview` can colour the sand by."""
ABOVE_COLOUR = "#7b3294"
"""Particles faster than the run's colour scale."""
SPEED_COLOURS = (SAND_COLOUR, "#e08a2c", "#c0392b", "#5e0b15")
"""The sand-speed colour map: sand at rest in the sand colour of the legend, faster ever redder and darker."""


def _speed_cmap():
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list("sand_speed", SPEED_COLOURS)


def _wet_cmap():
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list("sand_wetness", (SAND_COLOUR, WET_SAND_COLOUR))


def _scalar_bar(title: str) -> dict:
    return dict(
        title=title + "\n",
        vertical=True,
        position_x=0.86,
        position_y=0.12,
        width=0.05,
        height=0.6,
        n_labels=5,
        fmt="%.3g",
        color="black",
        title_font_size=14,
        label_font_size=12,
        above_label="",
    )


def preview_speed_range(scene) -> tuple[tuple[float, float], str]:
    """((0, top) m/s, where top comes from): the sand-speed colour scale of every preview of a run of ``scene``,
    ``time.max_speed`` if the scene sets it, else its speed estimate (:meth:`couplekit.scene.Scene.
    expected_max_speed`). The same for every frame, so a pile at rest is not drawn in full contrast."""
    top, why = scene.expected_max_speed()
    top = float(top)
    if not np.isfinite(top) or top <= 0.0:
        return (0.0, 1.0), f"1 m/s (the scene's speed estimate {top!r} is unusable)"
    return (0.0, top), why


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
    speed_range: tuple[float, float] | None = None,
    colour_by: str = "speed",
    moisture_max: float | None = None,
) -> Path:
    """Render a preview PNG of a frame. ``fields`` may hold ``phi``, ``solid``; ``particles`` ``x`` (3, P)
    and ``v`` (3, P), for ``colour_by="wetness"`` ``moisture`` (P,) or ``wetness`` (P,). ``speed_range``: the
    colour scale of the sand speed, m/s (a run passes :func:`preview_speed_range`, the same for every frame);
    ``None`` scales to this frame's fastest particle. ``colour_by``: 'speed', or 'wetness' (see the module
    docstring: ``moisture`` on the fixed scale 0 to ``moisture_max`` when both are given, else the wet/dry
    classification of ``wetness``; speed when the particles carry neither). Returns the path written."""
    if colour_by not in COLOUR_BY:
        raise ValueError(f"colour_by must be one of {COLOUR_BY}, got {colour_by!r}")
    if not os.environ.get("DISPLAY"):
        # without an X server go straight to EGL (VTK would try X first and print a warning)
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    fields, particles = fields or {}, particles or {}
    p = pv.Plotter(off_screen=True, window_size=list(window))
    p.set_background("white")
    bounds = (0.0, size[0], 0.0, size[1], 0.0, size[2])
    p.add_mesh(pv.Box(bounds=bounds).outline(), color="black")
    legend: list[list[str]] = []
    phi = fields.get("phi")
    if phi is not None and fields.get("solid") is not None:
        phi = np.where(np.asarray(fields["solid"], bool), 0.0, phi)  # no water surface drawn inside obstacles
    if phi is not None and np.nanmax(phi) > 0.5 > np.nanmin(phi):
        surf = _image(np.nan_to_num(phi), dx).contour([0.5], scalars="v")
        if surf.n_points:
            p.add_mesh(surf, color=WATER_COLOUR, opacity=0.55, smooth_shading=True)
            legend.append(["water surface", WATER_COLOUR])
    solid = fields.get("solid")
    if solid is not None and np.any(solid) and not np.all(solid):
        surf = _image(np.asarray(solid, np.float32), dx).contour([0.5], scalars="v")
        if surf.n_points:
            p.add_mesh(surf, color=OBSTACLE_COLOUR, opacity=0.2)  # see-through, so containers do not hide the scene
            legend.append(["obstacles", OBSTACLE_COLOUR])
    x = particles.get("x")
    if x is not None and np.asarray(x).shape[1] > 0:
        x = np.ascontiguousarray(np.asarray(x, dtype=np.float32).T)
        moisture, wet = particles.get("moisture"), particles.get("wetness")
        if colour_by == "wetness" and moisture is not None and moisture_max is not None and moisture_max > 0:
            cloud = pv.PolyData(x)
            cloud.point_data["retained water r_p"] = np.nan_to_num(np.asarray(moisture, np.float32))
            p.add_mesh(cloud, scalars="retained water r_p", cmap=_wet_cmap(), clim=(0.0, float(moisture_max)),
                       render_points_as_spheres=True, point_size=5,
                       scalar_bar_args=_scalar_bar("retained water r_p"))  # fmt: skip
            legend += [["dry sand", SAND_COLOUR], [f"wet sand (r_p = {moisture_max:.3g})", WET_SAND_COLOUR]]
        elif colour_by == "wetness" and wet is not None:
            from ..coupling.wetness import WET_THRESHOLD

            is_wet = np.asarray(wet, np.float32) > WET_THRESHOLD
            cloud = pv.PolyData(x)
            cloud.point_data["wet"] = is_wet.astype(np.float32)  # the ramp's two ends: drawn as r_p would be
            p.add_mesh(cloud, scalars="wet", cmap=_wet_cmap(), clim=(0.0, 1.0), render_points_as_spheres=True,
                       point_size=5, show_scalar_bar=False)  # fmt: skip
            for present, colour, label in ((~is_wet).any(), SAND_COLOUR, "dry sand"), (
                is_wet.any(), WET_SAND_COLOUR, "wet sand (S > (1 - eps_max)/2)"):  # fmt: skip
                if present:
                    legend.append([label, colour])
        elif particles.get("v") is not None:
            cloud = pv.PolyData(x)
            speed = np.linalg.norm(np.asarray(particles["v"], np.float32), axis=0)
            if speed_range is None:
                top = float(np.nanmax(speed)) if np.isfinite(speed).any() else 1.0
                speed_range = (0.0, max(top, 1e-6))
            clim = (float(speed_range[0]), max(float(speed_range[1]), float(speed_range[0]) + 1e-9))
            cloud.point_data["sand speed (m/s)"] = speed
            p.add_mesh(
                cloud,
                scalars="sand speed (m/s)",
                cmap=_speed_cmap(),
                render_points_as_spheres=True,
                clim=clim,
                above_color=ABOVE_COLOUR,
                point_size=5,
                scalar_bar_args=_scalar_bar("sand speed (m/s)"),
            )
            legend.append(["sand at rest (redder: faster)", SAND_COLOUR])
            if np.nanmax(speed) > clim[1]:
                legend.append([f"sand > {clim[1]:.3g} m/s", ABOVE_COLOUR])
        else:
            p.add_mesh(pv.PolyData(x), color=SAND_COLOUR, point_size=5, render_points_as_spheres=True)
            legend.append(["sand", SAND_COLOUR])
    p.show_bounds(
        bounds=bounds,
        xtitle="x (m)",
        ytitle="y (m)",
        ztitle="z (m)",
        n_xlabels=3,
        n_ylabels=3,
        n_zlabels=3,
        fmt="%.3g",
        font_size=12,
        color="black",
        location="outer",
        bold=False,
    )
    if legend:
        p.add_legend(labels=legend, bcolor="white", border=True, face="rectangle", loc="upper left",
                     size=(0.26, 0.045 * len(legend)))  # fmt: skip
    if title:
        p.add_text(title, position="upper_edge", font_size=11, color="black")
    p.camera_position = "iso"
    p.camera.azimuth = 20
    p.reset_camera()
    p.camera.zoom(0.92)
    p.camera.SetWindowCenter(0.12, 0.0)  # the box left of the colour bar, below the title
    path = Path(path)
    p.screenshot(str(path))
    p.close()
    return path
