"""D3Q7 conservative Allen–Cahn phase field (paper 000 §4.4, Eqs. 44–52) and the quantities the flow needs.

Stages (one kernel each in ``kernels/phasefield.cu``; NumPy twin :class:`PhaseFieldReferenceOps`):

``set_equilibrium``  h := h^eq(phi, u) as loaded at a given step parity (initialisation);
``macroscopic``      phi = sum_k h_k (Eq. 47) on every cell, ghost layer included;
``gradients``        grad phi (Eq. 21) and the chemical potential mu (Eqs. 22–23, compiled out when
                     sigma = 0); the flow's surface tension force is F_s = mu grad phi (Eq. 20);
``collide_stream``   Eq. 48 with the interface term (Eqs. 49–50, with the (1 - omega/2) factor), the source
                     term (Eq. 51) scaled by the volume controller gamma, in-place streaming, no-flux walls;
``volume_sums``      sum phi (or sum eps phi) and sum S_phi in float64, for the controller (Eq. 52,
                     :func:`volume_controller_gamma`).

Per step, in this order: ``macroscopic(h, phi, solid, t)`` -> ``gradients(phi, ...)`` -> (flow stages)
-> ``volume_sums`` + ``volume_controller_gamma`` (only when a source is present) ->
``collide_stream(h, grad, u, source, solid, t, ...)`` -> t += 1.

Storage (all fields share it; it is also the layout of the flow's f)
--------------------------------------------------------------------
* Interior extents ``(nz, ny, nx)``; every field is stored with ONE ghost layer on every side:
  scalars ``(nz+2, ny+2, nx+2)``, vectors ``(3, nz+2, ny+2, nx+2)``, ``h`` ``(7, nz+2, ny+2, nx+2)``,
  float32, C order (x contiguous).  Interior cell (x, y, z) is at padded index ``[z+1, y+1, x+1]``.
* ``solid`` is a padded uint8 mask of obstacle cells (:func:`pad_solid` builds it: each ghost holds the
  mask of its image).  Domain walls are given by the periodicity flags, not by the mask.
* D3Q7 directions in the order of :mod:`couplekit.lattice`: rest, (+x, -x), (+y, -y), (+z, -z); weights
  1/4, 1/8 (cs^2 = 1/4).

Neighbours, periodic faces and walls
------------------------------------
The neighbour of an interior cell along d_q is the cell at a constant offset, except on a periodic axis,
where a step out of the interior wraps to the first/last interior cell (no ghost copies of h are needed).
A link that leaves the interior on a non-periodic axis (a wall) or ends in a solid cell is *blocked*:
its populations bounce back (no-flux wall for h, Sigma phi conserved).  The ghost layer of ``phi`` holds
the image values (wrap / nearest interior cell: zero normal gradient at walls, i.e. a 90° contact angle),
and a solid neighbour contributes the centre value to the stencils of ``gradients``.

In-place streaming: esoteric pull (Lehmann 2022, FluidX3D ``load_f``/``store_f``) — the flow must match
--------------------------------------------------------------------------------------------------------
One copy of h.  Opposite directions are adjacent pairs (j, j+1), j odd, d_{j+1} = -d_j.  At step t
(``parity`` = t, only t & 1 matters) cell c with neighbour m = c + d_j uses the slots
a = (j if t odd else j+1) and b = (j+1 if t odd else j):

    load   f_0 = h[0, c]    f_j = h[a, c]     f_{j+1} = h[b, m]
    store  h[0, c] = f*_0   h[b, m] = f*_j    h[a, c] = f*_{j+1}

(each post-collision value is written where its partner was read from).  Halfway bounce-back (exact in
time): if the link c -> c + d_j is blocked, load f_{j+1} = h[a, m] (this cell's own f*_j of the previous
step, parked in m, which is a wall ghost or a solid cell); if the link c -> c - d_j is blocked, load
f_j = h[b, c] (this cell's own f*_{j+1} of the previous step).  Stores never change.  Equivalently, the
populations of step t are f_q(c) = h[q if t odd else opp(q), c - d_q if q even else c] (with the
blocked fix).  Solid cells are never updated.  Because the stored meaning alternates with the parity,
initialise with :meth:`set_equilibrium` at the parity of the first step.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..backend import Backend
from .phasefield_layout import (
    as_periodic,
    chemical_potential_coefficients,
    interior,
    interior_shape,
    pad_solid,
    padded_shape,
    relaxation_rate,
    tanh_profile,
    volume_controller_gamma,
)
from .phasefield_reference import PhaseFieldReferenceOps

__all__ = [
    "PhaseFieldKernelOps",
    "PhaseFieldReferenceOps",
    "PhaseFieldRunner",
    "chemical_potential_coefficients",
    "interior",
    "interior_shape",
    "make_phase_field_ops",
    "pad_solid",
    "padded_shape",
    "relaxation_rate",
    "tanh_profile",
    "volume_controller_gamma",
]

KERNEL_SOURCE = "phasefield.cu"


class PhaseFieldKernelOps:
    """Phase-field stages as compiled kernels (cuda or cpu backend); same methods as the reference.

    ``periodic``: (x, y, z) periodicity; ``surface_tension``: False compiles the chemical potential out
    (``CK_PF_SURFACE_TENSION=0``) and :meth:`gradients` then takes ``mu=None``.
    """

    def __init__(self, backend: Backend, periodic: bool | Sequence[bool] = True, surface_tension: bool = True):
        self.backend = backend
        self.xp = backend.xp
        self.periodic = as_periodic(periodic)
        self.surface_tension = bool(surface_tension)
        self.module = backend.module(KERNEL_SOURCE, defines={"CK_PF_SURFACE_TENSION": int(self.surface_tension)})
        self._flags = tuple(int(p) for p in self.periodic)
        self._no_mu = None if self.surface_tension else self.xp.zeros(1, dtype=np.float32)

    def _fn(self, name: str):
        return self.module.function(name)

    def set_equilibrium(self, h, phi, u, solid, parity: int) -> None:
        """Fill h so that the populations of step ``parity`` are h^eq(phi, u) in every interior fluid cell."""
        nz, ny, nx = interior_shape(solid.shape)
        self._fn("phase_set_equilibrium")(nx * ny * nz, h, phi, u, solid, nx, ny, nz, *self._flags, int(parity))

    def macroscopic(self, h, phi, solid, parity: int) -> None:
        """phi = sum_k h_k (Eq. 47) in the interior; ghost cells copy their image; solid cells get 0."""
        nz, ny, nx = interior_shape(solid.shape)
        n = (nx + 2) * (ny + 2) * (nz + 2)
        self._fn("phase_macroscopic")(n, h, phi, solid, nx, ny, nz, *self._flags, int(parity))

    def gradients(self, phi, solid, grad, mu, beta: float, kappa: float) -> None:
        """grad phi (Eq. 21) and, with surface tension, mu (Eqs. 22–23) in interior cells."""
        if self.surface_tension == (mu is None):
            raise ValueError("mu must be an array exactly when the ops were built with surface_tension=True")
        nz, ny, nx = interior_shape(solid.shape)
        out_mu = mu if mu is not None else self._no_mu
        self._fn("phase_gradients")(
            nx * ny * nz, phi, solid, grad, out_mu, nx, ny, nz, np.float32(beta), np.float32(kappa)
        )

    def collide_stream(
        self, h, grad, u, source, solid, parity: int, mobility: float, width: float, source_scale: float = 1.0
    ) -> None:
        """One step of Eq. 48 with in-place (esoteric-pull) streaming and no-flux bounce-back."""
        nz, ny, nx = interior_shape(solid.shape)
        self._fn("phase_collide_stream")(
            nx * ny * nz, h, grad, u, source, solid, nx, ny, nz, *self._flags, int(parity),
            np.float32(mobility), np.float32(width), np.float32(source_scale),
        )  # fmt: skip

    def volume_sums(self, phi, source, solid, eps=None) -> tuple[float, float]:
        """(V, sum S_phi) over interior fluid cells in float64: V = sum phi, or sum eps phi with ``eps``."""
        nz, ny, nx = interior_shape(solid.shape)
        out = self.xp.zeros(2, dtype=np.float64)
        if eps is None:
            self._fn("phase_volume_sums")(ny * nz, phi, source, solid, out, nx, ny, nz)
        else:
            self._fn("phase_volume_sums_eps")(ny * nz, phi, eps, source, solid, out, nx, ny, nz)
        host = self.backend.to_host(out)
        return float(host[0]), float(host[1])


def make_phase_field_ops(
    backend: Backend, periodic: bool | Sequence[bool] = True, surface_tension: bool = True
) -> PhaseFieldKernelOps | PhaseFieldReferenceOps:
    """Kernel ops on the cuda/cpu backends, the NumPy reference on the numpy backend."""
    if backend.has_kernels:
        return PhaseFieldKernelOps(backend, periodic, surface_tension)
    return PhaseFieldReferenceOps(periodic, surface_tension)


class PhaseFieldRunner:
    """The phase field alone in a prescribed velocity field (validation, benchmarks, and a usage example).

    Holds h, phi, grad phi, mu (with surface tension) and the step counter; ``eta`` > 0 switches the volume
    controller (Eq. 52) on, with V0 recorded at construction.  All arrays are padded (module docstring).
    """

    def __init__(
        self,
        ops: PhaseFieldKernelOps | PhaseFieldReferenceOps,
        phi0: np.ndarray,
        *,
        mobility: float,
        width: float,
        sigma: float = 0.0,
        solid: np.ndarray | None = None,
        u: np.ndarray | None = None,
        eta: float = 0.0,
    ):
        xp = ops.xp
        nz, ny, nx = np.shape(phi0)
        shape = padded_shape((nz, ny, nx))
        self.ops, self.mobility, self.width, self.eta = ops, float(mobility), float(width), float(eta)
        self.beta, self.kappa = chemical_potential_coefficients(sigma, width)
        self.solid = xp.asarray(pad_solid(solid, (nz, ny, nx), ops.periodic))
        self.u = xp.zeros((3, *shape), dtype=np.float32) if u is None else xp.ascontiguousarray(u, dtype=np.float32)
        self.source = xp.zeros(shape, dtype=np.float32)
        self.phi = xp.zeros(shape, dtype=np.float32)
        self.phi[1:-1, 1:-1, 1:-1] = xp.asarray(np.asarray(phi0, dtype=np.float32))
        self.grad = xp.zeros((3, *shape), dtype=np.float32)
        self.mu = xp.zeros(shape, dtype=np.float32) if ops.surface_tension else None
        self.h = xp.zeros((7, *shape), dtype=np.float32)
        self.step_count = 0
        self.gamma = 1.0
        ops.set_equilibrium(self.h, self.phi, self.u, self.solid, 0)
        self.update_macroscopic()
        self.v0 = self.volume()

    def update_macroscopic(self) -> None:
        """phi, grad phi and mu of the current step (before its collision)."""
        self.ops.macroscopic(self.h, self.phi, self.solid, self.step_count)
        self.ops.gradients(self.phi, self.solid, self.grad, self.mu, self.beta, self.kappa)

    def volume(self) -> float:
        """Sigma phi over interior fluid cells (float64)."""
        return self.ops.volume_sums(self.phi, self.source, self.solid)[0]

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps: controller factor, collide + stream, then phi / grad phi / mu."""
        for _ in range(n):
            if self.eta > 0:
                volume, source_sum = self.ops.volume_sums(self.phi, self.source, self.solid)
                self.gamma = volume_controller_gamma(self.v0, volume, source_sum, self.eta)
            self.ops.collide_stream(
                self.h, self.grad, self.u, self.source, self.solid, self.step_count, self.mobility, self.width,
                self.gamma,
            )  # fmt: skip
            self.step_count += 1
            self.update_macroscopic()

    def phi_host(self) -> np.ndarray:
        """Interior phi as a NumPy float64 array (nz, ny, nx)."""
        return np.asarray(self.ops_to_host(self.phi)[1:-1, 1:-1, 1:-1], dtype=np.float64)

    def ops_to_host(self, a) -> np.ndarray:
        """A NumPy copy of an array of the ops' backend."""
        backend = getattr(self.ops, "backend", None)
        return backend.to_host(a) if backend is not None else np.array(a, copy=True)
