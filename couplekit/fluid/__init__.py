"""The LBM fluid: velocity-based D3Q27 NOCM-MRT flow (paper Sec. 4.1) on a padded grid with AA streaming.

* :mod:`.grid` — padded layout, cell flags, face boundary conditions;
* :mod:`.reference` — :class:`ReferenceOps`, the NumPy specification of every stage;
* :mod:`.kernel_ops` — :class:`KernelOps`, the same stages compiled from ``kernels/lbm_*.cu``;
* :mod:`.solver` — :class:`FluidSolver` and :class:`FluidParams`, which own the fields and call the ops
  (both importable from here: ``from couplekit.fluid import FluidSolver, FluidParams, Boundaries``).

The D3Q7 phase field lives in :mod:`.phasefield` (its own module and owner).
"""

from .grid import INFLOW, OUTFLOW, WALL, Boundaries, Face
from .kernel_ops import KernelOps
from .reference import ReferenceOps, equilibrium, from_stored, to_stored
from .solver import FluidParams, FluidSolver, OddFloorInactiveWarning, SharpInterfaceWarning

__all__ = [
    "Boundaries",
    "Face",
    "FluidParams",
    "FluidSolver",
    "KernelOps",
    "OddFloorInactiveWarning",
    "SharpInterfaceWarning",
    "ReferenceOps",
    "equilibrium",
    "from_stored",
    "to_stored",
    "WALL",
    "INFLOW",
    "OUTFLOW",
]
