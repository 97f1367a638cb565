"""Inflow regions of the fluid: a rectangle or a disc on a domain face, rasterised to an
:class:`~couplekit.fluid.grid.InflowRegion` mask.

A jet issuing from an outlet in a wall (paper 000 Fig. 1's rectangular outlet) is a velocity inlet over part
of a face: :func:`region_mask` marks the face's ghost cells whose centres lie inside the outlet, and the rest
of the face keeps its own kind (:class:`~couplekit.fluid.grid.InflowRegion`).

The geometry (face coordinates, rasterisation, areas) is shared with the sand emitted at such outlets and with
scene validation, so it lives in the neutral :mod:`couplekit.faces`; this module re-exports it for the fluid.
"""

from __future__ import annotations

from ..faces import PLANE_AXES, SHAPES, face_extent, region_area, region_bounds, region_mask

__all__ = ["PLANE_AXES", "SHAPES", "face_extent", "region_bounds", "region_mask", "region_area"]
