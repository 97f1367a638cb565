"""D3Q7 conservative Allen–Cahn phase field (paper 000 §4.4, Eqs. 44–52) and the quantities the flow needs.

Stages (one kernel each in ``kernels/phasefield.cu``; NumPy twin :class:`PhaseFieldReferenceOps`):

``set_equilibrium``  h := h^eq(phi, u) as loaded at a given step parity (initialisation);
``macroscopic``      phi = sum_k h_k (Eq. 47) on every cell, ghost layer included;
``gradients``        grad phi (Eq. 21) and the chemical potential mu (Eqs. 22–23, compiled out when
                     sigma = 0) as fields: a diagnostic, not a stage of the step (the collision computes
                     grad phi itself, the flow's collision mu for its surface tension force F_s = mu grad phi,
                     Eq. 20);
``collide_stream``   Eq. 48 with the interface term (Eqs. 49–50, with the (1 - omega/2) factor), the source
                     term (Eq. 51) scaled by the volume controller gamma, in-place streaming, no-flux walls;
``volume_sums``      sum phi (or sum eps phi) and sum S_phi in float64, for the controller (Eq. 52,
                     :func:`volume_controller_gamma`);
``mixture_sums``     a mixture's two: sum eps phi and sum eps S_phi, in one pass.

Per step, in this order: ``macroscopic(h, phi, u, flags, t)`` -> (flow stages) -> ``volume_sums`` +
``volume_controller_gamma`` (only when a source is present) -> ``collide_stream(h, phi, u, source, flags, t,
...)`` -> t += 1.

Storage: the flow's padded grid (:mod:`couplekit.fluid.grid`)
-------------------------------------------------------------
* Interior extents ``(nz, ny, nx)``; every field is stored with ONE ghost layer on every side:
  scalars ``(nz+2, ny+2, nx+2)``, vectors ``(3, nz+2, ny+2, nx+2)``, ``h`` ``(7, nz+2, ny+2, nx+2)``,
  float32, C order (x contiguous).  Interior cell (x, y, z) is at padded index ``[z+1, y+1, x+1]``.
* ``flags``: the flow's padded uint8 cell flags (``grid.build_flags``, or :func:`pad_flags` for walls
  and obstacles): FLUID 0 cells are updated; WALL 1 is a no-flux wall (halfway bounce-back of h, Sigma phi
  conserved); INFLOW 2 is that wall plus the advective flux phi_in d_q.u_in of the phase value and velocity
  stored at that cell (``phi`` and ``u`` there): each face link lets in exactly phi_in u_in.n, no diffusive
  or interface flux (:func:`inflow_flux`); OUTFLOW 3 is that wall less the advective flux phi max(d_q.u, 0) of
  the cell's own phase value and velocity (d_q out of the box): phi leaves only by advection where the fluid
  leaves, nothing comes in on backflow (as the flow's outflow takes the inward velocity out), and no diffusive
  or interface flux crosses (``phasefield_reference._outflux``).
  Ghost cells of non-periodic axes must not be FLUID (:func:`check_flags`).
* D3Q7 directions in the order of :mod:`couplekit.lattice`: rest, (+x, -x), (+y, -y), (+z, -z); weights
  1/4, 1/8 (cs^2 = 1/4).

Neighbours and periodic faces
-----------------------------
The neighbour of an interior cell along d_q is the cell at a constant offset, except on a periodic axis,
where a step out of the interior wraps to the other side: the kernels never read h in periodic ghosts, so
h needs no halo copies.  ``macroscopic`` fills the ghost layer of ``phi`` with the image values (wrap on
periodic axes, nearest interior cell otherwise; INFLOW cells keep their phase value), and the stencils of
``gradients`` use a neighbour's value only when it is FLUID, the centre value otherwise (as the flow's
stencils: zero normal gradient, a 90° contact angle at walls).

In-place streaming: the AA pattern (Bailey et al. 2009), the same as the flow's f
--------------------------------------------------------------------------------
One copy of h.  ``parity`` = step counter t (only t & 1 matters).
* even t: f_q = h[q, c]; collide; store h[opp q, c] = f*_q (purely local);
* odd t:  f_q = h[opp q, c - d_q] (pull); collide; store h[q, c + d_q] = f*_q (push).
Boundary rules act in odd steps only: pulling from a WALL gives f_q = h[q, c] (this cell's own
f*_{opp q} of the even step: halfway bounce-back, exact in time); a push towards a WALL is written to
h[opp q, c], where the next even step reads it.  INFLOW / OUTFLOW links are filled with the equilibria
described above (on a push: into h[opp q, c] for the next even step).  After an even step the
populations sit in reversed slots, after an odd step in natural order; :meth:`set_equilibrium` writes a
state that loads as h^eq at a given parity (use it to initialise).  Non-FLUID cells are never updated.

Numerical choices
-----------------
* Source term in the paper's form (Eq. 48/51): S_k = w_k gamma S_phi added without the (1 - omega/2)
  factor and phi = sum_k h_k, so one step changes Sigma phi by exactly gamma Sigma S_phi (first order in
  time for the source, notes §1c); the interface term H_k does carry the (1 - omega/2) factor.
* h^eq is first order in u (notes §1c); the normal is zero where |grad phi|^2 <= 1e-12.
* Mass in float32: the kernel sums the populations with compensated (TwoSum) float arithmetic and sets
  the rest population from the exact local balance sum h* = sum h + S, so Sigma phi changes only by one
  float32 rounding per cell and step (plain float32 sums drifted ~50x more in steady states, where the
  same rounding repeats every step).  The reference computes in float64 and rounds each h* once.
* Volume V (Eq. 52): Sigma phi over interior FLUID cells, or Sigma eps phi with the mixture's fluid
  fraction (``volume_sums(..., eps=...)``, or ``mixture_sums`` with Σ ε S_φ); gamma from :func:`volume_controller_gamma` (eta = 0: off).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..backend import Backend
from .phasefield_layout import (
    FLUID,
    INFLOW,
    OUTFLOW,
    WALL,
    as_periodic,
    check_flags,
    chemical_potential_coefficients,
    continuum_coefficients,
    discrete_surface_tension_factor,
    interior,
    interior_shape,
    pad_flags,
    padded_shape,
    relaxation_rate,
    tanh_profile,
    volume_controller_gamma,
)
from .phasefield_reference import PhaseFieldReferenceOps
from .storage import check_storage, dtype_of

__all__ = [
    "FLUID",
    "INFLOW",
    "OUTFLOW",
    "WALL",
    "check_flags",
    "PhaseFieldKernelOps",
    "PhaseFieldReferenceOps",
    "PhaseFieldRunner",
    "chemical_potential_coefficients",
    "continuum_coefficients",
    "discrete_surface_tension_factor",
    "gradient_fields",
    "interior",
    "interior_shape",
    "make_phase_field_ops",
    "pad_flags",
    "padded_shape",
    "relaxation_rate",
    "tanh_profile",
    "volume_controller_gamma",
]

KERNEL_SOURCE = "phasefield.cu"


class PhaseFieldKernelOps:
    """Phase-field stages as compiled kernels (cuda or cpu backend); same methods as the reference.

    ``periodic``: (x, y, z) periodicity; ``surface_tension``: False compiles the chemical potential out
    (``CK_PF_SURFACE_TENSION=0``) and :meth:`gradients` then takes ``mu=None``; ``source``: False compiles
    the source term S_φ out (``CK_PF_SOURCE=0``): :meth:`collide_stream` and :meth:`volume_sums` then take
    ``source=None`` and the volume sums report Σ S_φ = 0. ``storage``: ``"fp32"`` or ``"fp16"`` (h stored as
    binary16, ``CK_STORAGE_FP16=1``; h is then a float16 array, :mod:`couplekit.fluid.storage`).
    """

    def __init__(
        self,
        backend: Backend,
        periodic: bool | Sequence[bool] = True,
        surface_tension: bool = True,
        source: bool = True,
        storage: str = "fp32",
    ):
        self.backend = backend
        self.xp = backend.xp
        self.periodic = as_periodic(periodic)
        self.surface_tension = bool(surface_tension)
        self.source = bool(source)
        self.storage = check_storage(storage)
        defines = {"CK_PF_SURFACE_TENSION": int(self.surface_tension), "CK_PF_SOURCE": int(self.source)}
        if self.storage == "fp16":
            defines["CK_STORAGE_FP16"] = 1
        self.module = backend.module(KERNEL_SOURCE, defines=defines)
        self._flags = tuple(int(p) for p in self.periodic)
        self._no_mu = None if self.surface_tension else self.xp.zeros(1, dtype=np.float32)
        self._no_source = None if self.source else self.xp.zeros(1, dtype=np.float32)  # never read

    def _source(self, source):
        if self.source:
            if source is None:
                raise ValueError("these phase-field ops were built with the source term: pass the S_phi array")
            return source
        return self._no_source

    def _fn(self, name: str):
        return self.module.function(name)

    def set_equilibrium(self, h, phi, u, flags, parity: int) -> None:
        """Fill h so that the populations of step ``parity`` are h^eq(phi, u) in every interior fluid cell."""
        nz, ny, nx = interior_shape(flags.shape)
        self._fn("phase_set_equilibrium")(nx * ny * nz, h, phi, u, flags, nx, ny, nz, *self._flags, int(parity))

    def macroscopic(self, h, phi, u, flags, parity: int) -> None:
        """phi = sum_k h_k (Eq. 47) at ``parity``; ghost cells take their image; INFLOW cells keep theirs."""
        nz, ny, nx = interior_shape(flags.shape)
        n = (nx + 2) * (ny + 2) * (nz + 2)
        self._fn("phase_macroscopic")(n, h, phi, u, flags, nx, ny, nz, *self._flags, int(parity))

    def gradients(self, phi, flags, grad, mu, beta: float, kappa: float) -> None:
        """grad phi (Eq. 21) and, with surface tension, mu (Eqs. 22–23) in interior cells."""
        if self.surface_tension == (mu is None):
            raise ValueError("mu must be an array exactly when the ops were built with surface_tension=True")
        nz, ny, nx = interior_shape(flags.shape)
        out_mu = mu if mu is not None else self._no_mu
        self._fn("phase_gradients")(
            nx * ny * nz, phi, flags, grad, out_mu, nx, ny, nz, np.float32(beta), np.float32(kappa)
        )

    def collide_stream(
        self,
        h,
        phi,
        u,
        source,
        flags,
        parity: int,
        mobility: float,
        width: float,
        source_scale: float = 1.0,
        trt_lambda: float = 0.0,
    ) -> None:
        """One step of Eq. 48 with in-place (AA) streaming and the boundary rules of the flags, grad phi computed
        in the kernel from ``phi`` (``trt_lambda``: see :meth:`PhaseFieldReferenceOps.collide_stream`)."""
        nz, ny, nx = interior_shape(flags.shape)
        self._fn("phase_collide_stream")(
            nx * ny * nz, h, phi, u, self._source(source), flags, nx, ny, nz, *self._flags, int(parity),
            np.float32(mobility), np.float32(width), np.float32(source_scale), np.float32(trt_lambda),
        )  # fmt: skip

    def volume_sums(self, phi, source, flags, eps=None) -> tuple[float, float]:
        """(V, sum S_phi) over interior FLUID cells in float64: V = sum phi, or sum eps phi with ``eps``."""
        nz, ny, nx = interior_shape(flags.shape)
        out = self.xp.zeros(2, dtype=np.float64)
        source = self._source(source)
        if eps is None:
            self._fn("phase_volume_sums")(ny * nz, phi, source, flags, out, nx, ny, nz)
        else:
            self._fn("phase_volume_sums_eps")(ny * nz, phi, eps, source, flags, out, nx, ny, nz)
        host = self.backend.to_host(out)
        return float(host[0]), float(host[1])

    def mixture_sums(self, phi, eps, source, flags) -> tuple[float, float]:
        """(Σ ε φ, Σ ε S_φ) over interior FLUID cells in float64, in one pass: the two sums of a mixture's volume
        controller (Eq. 52), bitwise ``volume_sums(phi, ., flags, eps)[0]`` and ``volume_sums(source, ., flags,
        eps)[0]``."""
        nz, ny, nx = interior_shape(flags.shape)
        out = self.xp.zeros(2, dtype=np.float64)
        self._fn("phase_volume_sums_mixture")(ny * nz, phi, eps, source, flags, out, nx, ny, nz)
        host = self.backend.to_host(out)
        return float(host[0]), float(host[1])


def make_phase_field_ops(
    backend: Backend,
    periodic: bool | Sequence[bool] = True,
    surface_tension: bool = True,
    source: bool = True,
    storage: str = "fp32",
) -> PhaseFieldKernelOps | PhaseFieldReferenceOps:
    """Kernel ops on the cuda/cpu backends, the NumPy reference on the numpy backend."""
    if backend.has_kernels:
        return PhaseFieldKernelOps(backend, periodic, surface_tension, source, storage)
    return PhaseFieldReferenceOps(periodic, surface_tension, source, storage)


def gradient_fields(ops, phi, flags, beta: float, kappa: float):
    """(grad phi, mu) of ``phi`` (Eqs. 21-23) as new padded arrays of the ops' backend, mu None without surface
    tension: the on-demand diagnostic of :meth:`PhaseFieldRunner.gradients` and ``FluidSolver.phase_gradients``
    (the steps compute both inside their collides and store neither)."""
    xp = ops.xp
    grad = xp.zeros((3, *phi.shape), dtype=np.float32)
    mu = xp.zeros(phi.shape, dtype=np.float32) if ops.surface_tension else None
    ops.gradients(phi, flags, grad, mu, beta, kappa)
    return grad, mu


class PhaseFieldRunner:
    """The phase field alone in a prescribed velocity field (validation, benchmarks, and a usage example).

    Holds h, phi, the source S_phi (zeros; assign to it) and the step counter; grad phi is computed inside the
    collision, mu on demand (:meth:`gradients`, with surface tension ``sigma``).  ``solid``: interior obstacle mask, or ``flags``: the padded cell flags (then ``solid`` must be
    None).  ``eta`` > 0 switches the volume controller (Eq. 52) on, with V0 recorded at construction.
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
        flags: np.ndarray | None = None,
        u: np.ndarray | None = None,
        eta: float = 0.0,
    ):
        xp = ops.xp
        nz, ny, nx = np.shape(phi0)
        shape = padded_shape((nz, ny, nx))
        if flags is None:
            flags = pad_flags(solid, (nz, ny, nx), ops.periodic)
        elif solid is not None:
            raise ValueError("give either solid or flags, not both")
        check_flags(flags, ops.periodic)
        self.ops, self.mobility, self.width, self.eta = ops, float(mobility), float(width), float(eta)
        self.beta, self.kappa = chemical_potential_coefficients(sigma, width)
        self.flags = xp.asarray(np.ascontiguousarray(flags, dtype=np.uint8))
        # u may be a host array on a device backend (xp.asarray copies it over; a device array stays)
        self.u = (
            xp.zeros((3, *shape), dtype=np.float32)
            if u is None
            else xp.ascontiguousarray(xp.asarray(u, dtype=np.float32))
        )
        self.source = xp.zeros(shape, dtype=np.float32)
        self.phi = xp.zeros(shape, dtype=np.float32)
        self.phi[1:-1, 1:-1, 1:-1] = xp.asarray(np.asarray(phi0, dtype=np.float32))
        self.h = xp.zeros((7, *shape), dtype=dtype_of(getattr(ops, "storage", "fp32")))
        self.step_count = 0
        self.gamma = 1.0
        ops.set_equilibrium(self.h, self.phi, self.u, self.flags, 0)
        self.update_macroscopic()
        self.v0 = self.volume()

    def update_macroscopic(self) -> None:
        """phi of the current step (before its collision), ghost layer included."""
        self.ops.macroscopic(self.h, self.phi, self.u, self.flags, self.step_count)

    def gradients(self):
        """(grad phi, mu) of the current phi (:func:`gradient_fields`): a diagnostic, the step does not need them
        stored."""
        return gradient_fields(self.ops, self.phi, self.flags, self.beta, self.kappa)

    def volume(self) -> float:
        """Sigma phi over interior fluid cells (float64)."""
        return self.ops.volume_sums(self.phi, self.source, self.flags)[0]

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps: controller factor, collide + stream, then phi."""
        for _ in range(n):
            if self.eta > 0:
                volume, source_sum = self.ops.volume_sums(self.phi, self.source, self.flags)
                self.gamma = volume_controller_gamma(self.v0, volume, source_sum, self.eta)
            self.ops.collide_stream(
                self.h, self.phi, self.u, self.source, self.flags, self.step_count, self.mobility,
                self.width, self.gamma,
            )  # fmt: skip
            self.step_count += 1
            self.update_macroscopic()

    def to_host(self, a) -> np.ndarray:
        """A NumPy copy of an array of the ops' backend."""
        backend = getattr(self.ops, "backend", None)
        return backend.to_host(a) if backend is not None else np.array(a, copy=True)

    def phi_host(self) -> np.ndarray:
        """Interior phi as a NumPy float64 array (nz, ny, nx)."""
        return np.asarray(self.to_host(self.phi)[1:-1, 1:-1, 1:-1], dtype=np.float64)
