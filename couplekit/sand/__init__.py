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
from .seeding import Seeded, combine, seed_box, seed_sdf, seed_sphere
from .solver import EPS_MAX, SandSolver, TimeStepError, elastic_dt_limit

__all__ = [
    "EPS_MAX",
    "Collider",
    "ConstitutiveModel",
    "DomainWalls",
    "KernelOps",
    "ReferenceOps",
    "SandParams",
    "SandSolver",
    "SdfCollider",
    "Seeded",
    "TimeStepError",
    "Wall",
    "combine",
    "elastic_dt_limit",
    "seed_box",
    "seed_sdf",
    "seed_sphere",
]
