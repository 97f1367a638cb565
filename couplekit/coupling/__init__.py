"""Sand–water–air coupling (paper 000 §§4.3–4.5): volume fractions, buoyancy and implicit drag, the
phase-field source term S_φ and water retention with the saturation that drives cohesion.

* :mod:`.params` — :class:`CouplingParams` (defaults and their sources) and the node-level closed forms;
* :mod:`.reference` — :class:`ReferenceOps`, the NumPy specification of every stage;
* :mod:`.kernel_ops` — :class:`KernelOps`, the same stages compiled from ``kernels/coupling_*.cu``;
* :mod:`.coupler` — :class:`SandFluidCoupler`, the coupling fields and stages between a SandSolver and a
  FluidSolver in Algorithm 1's order.

Per lockstep step (paper Algorithm 1), with the MPM grid after P2G:
``bound_water_p2g`` (retention only) → ``fractions`` → ``pressure_slip_fluid`` (the part of Eq. 39's slip
term that reads the fluid velocity, into the pressure update's kept population sum, before the fluid's Σ f c
is written over its velocity) → ``phase_source`` → ``drag_buoyancy`` (before the
sand's grid update, which then divides the momentum by the mass and applies the boundaries) → ``particle_moisture`` (before the
sand's G2P, which reads the saturation) → ``pressure_sand_terms`` (after the grid update: the rest of Eq. 39's
sand terms into the kept sum; the sub-cycling and multi-rate schedulers store the fluid's
``sand_velocity`` input instead).  The outputs map onto :class:`couplekit.fluid.solver.FluidSolver`'s inputs:
``eps_fluid`` → ``fluid_fraction``, ``force`` → ``force``, ``source`` → ``source_term``, ``sand_v`` →
``sand_velocity``.  :func:`make_coupling_ops` picks the implementation.
"""

from __future__ import annotations

from ..backend import Backend
from .kernel_ops import KernelOps
from .params import CouplingParams, drag_area, node_terminal_velocity
from .reference import ReferenceOps

__all__ = [
    "CouplingParams",
    "KernelOps",
    "ReferenceOps",
    "drag_area",
    "make_coupling_ops",
    "node_terminal_velocity",
]


def make_coupling_ops(
    backend: Backend, params: CouplingParams | None = None, two_phase: bool = True
) -> KernelOps | ReferenceOps:
    """Kernel ops on the cuda/cpu backends, the NumPy reference on the numpy backend."""
    if backend.has_kernels:
        return KernelOps(backend, params, two_phase)
    return ReferenceOps(params, two_phase)


from .coupler import SandFluidCoupler  # noqa: E402  (uses make_coupling_ops)

__all__ += ["SandFluidCoupler"]
