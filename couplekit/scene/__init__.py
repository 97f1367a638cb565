"""Scenes: TOML files in SI units, validated before anything is allocated, and their geometry as SDFs.

>>> from couplekit.scene import Scene
>>> scene = Scene.load("examples/sand_drop_small.toml")   # SceneError names every bad key and the fix

* :mod:`.schema` — every key (type, default, unit, range, documentation) and the table checker;
* :mod:`.model` — the :class:`Scene` dataclasses and the cross-key checks (grid, boundaries, time step);
* :mod:`.geometry` — box, sphere, cylinder, transforms, unions, sampling an SDF on the grid;
* :mod:`.mesh` — triangle meshes (OBJ/STL/PLY via meshio) and height fields as SDFs;
* :mod:`.reference` — renders ``docs/scene-reference.md`` from the schema;
* :mod:`.jsonschema` — the schema as JSON Schema for TOML editors (``couplekit schema``).
"""

from __future__ import annotations

from .geometry import Box, Cylinder, Inverted, Shape, Sphere, Transformed, Union, cell_centres, sdf_on_grid
from .mesh import HeightField, TriangleMesh, load_mesh
from .model import Body, Domain, Effects, Fluid, Geometry, Inflow, Outputs, Sand, Scene, Time
from .schema import Problem, SceneError

__all__ = [
    "Body",
    "Box",
    "Cylinder",
    "Domain",
    "Effects",
    "Fluid",
    "Geometry",
    "HeightField",
    "Inflow",
    "Inverted",
    "Outputs",
    "Problem",
    "Sand",
    "Scene",
    "SceneError",
    "Shape",
    "Sphere",
    "Time",
    "Transformed",
    "TriangleMesh",
    "Union",
    "cell_centres",
    "load_mesh",
    "sdf_on_grid",
]
