"""MPM sand solver (paper 000 §§3.2, 4.2): APIC/MLS-MPM with quadratic B-splines on the LBM lattice,
Hencky elasticity, Drucker–Prager plasticity with Klár hardening and saturation-dependent cohesion.

Stages are ops (:class:`KernelOps` on cuda/cpu, :class:`ReferenceOps` in NumPy); :class:`SandSolver`
owns the particle and grid arrays and calls them.
"""

from __future__ import annotations

from .boundaries import Collider, DomainWalls, SdfCollider, Wall
from .kernel_ops import KernelOps
from .params import ConstitutiveModel, SandParams
from .reference import ReferenceOps

__all__ = [
    "Collider",
    "ConstitutiveModel",
    "DomainWalls",
    "KernelOps",
    "ReferenceOps",
    "SandParams",
    "SdfCollider",
    "Wall",
]
