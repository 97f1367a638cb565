"""The coupling stages as compiled kernels (cuda or cpu build of ``kernels/coupling_*.cu``).

Same methods and arguments as :class:`couplekit.coupling.reference.ReferenceOps`.  Effects are compile-time
switches: ``CK_RETENTION`` (bound-water field and Eqs. 55–58) and ``CK_TWO_PHASE`` (φ read; else
single-phase water).  Arrays of switched-off effects may be ``None``: a 1-element placeholder is passed.
The bound-water scatter is deterministic on the cpu backend (particles by tiles, one summation order for any
thread count: kernels/host_scatter.cuh) and uses float atomics on CUDA.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..backend import Backend
from ..backend.host_scatter import host_scatter_scratch
from ..units import Units
from .params import CouplingParams
from .reference import drag_scales

__all__ = ["KernelOps"]


class KernelOps:
    """Coupling stages on ``backend`` (``cuda`` or ``cpu``); see the module docstring."""

    def __init__(self, backend: Backend, params: CouplingParams | None = None, two_phase: bool = True):
        if not backend.has_kernels:
            raise ValueError(f"KernelOps needs a kernel backend (cuda or cpu), got {backend.name!r}")
        self.backend = backend
        self.name = backend.name
        self.xp = backend.xp
        self.params = params or CouplingParams()
        self.two_phase = bool(two_phase)
        self.retention = bool(self.params.retention)
        self._defines = {"CK_RETENTION": int(self.retention), "CK_TWO_PHASE": int(self.two_phase)}
        self._none = self.xp.zeros(1, dtype=np.float32)
        self._no_scratch = self.xp.zeros(1, dtype=np.int32)  # the atomic bound-water scatter's unused scratch
        self._scratch = None

    def _fn(self, source: str, name: str, *keys: str):
        return self.backend.module(source, {k: self._defines[k] for k in keys}).function(name)

    def _opt(self, a, needed: bool, what: str):
        if not needed:
            return self._none
        if a is None:
            raise ValueError(f"{what} is required with the effects these ops were built for")
        return a

    def fractions(
        self,
        grid_vol,
        phi,
        bound_in,
        eps_prev,
        eps_fluid,
        d_bound,
        bound_out,
        dx: float,
        periodic: Sequence[bool] = (True, True, True),
        retentive=None,
        share: float = 1.0,
        volume_scale: float = 1.0,
    ) -> None:
        """The porosity (padded, ghosts filled), dR and R' (MPM grid): one pass of ``coupling_fractions``
        (Eqs. 25, 33, 54–56; the φ-scaled uptake rate of Eq. 55).
        ``retentive``: the retentive sand's fraction for per-body retention (None: all sand retains);
        ``share``: the part of a fluid step this sand step covers (reference docstring); ``volume_scale``: the
        node sand volume is ``volume_scale`` × ``grid_vol`` (SandSolver.node_volume)."""
        nz, ny, nx = grid_vol.shape
        p = self.params
        ret = self.retention
        self._fn("coupling_fractions.cu", "coupling_fractions", "CK_RETENTION", "CK_TWO_PHASE")(
            (nx + 2) * (ny + 2) * (nz + 2), grid_vol, self._opt(phi, self.two_phase, "phi"),
            self._opt(bound_in, ret, "bound_in"), self._none if retentive is None else retentive,
            self._opt(eps_prev, ret, "eps_prev"), eps_fluid,
            self._opt(d_bound, ret, "d_bound"), self._opt(bound_out, ret, "bound_out"),
            np.int32(nx), np.int32(ny), np.int32(nz), *(np.int32(bool(v)) for v in periodic),
            np.float32(volume_scale / dx**3), np.float32(p.eps_max), np.float32(p.r_max),
            np.float32(p.absorption_rate * share), np.float32(min(share, 1.0)), np.int32(retentive is not None and ret),
        )  # fmt: skip

    def sand_velocity(self, grid_v, sand_v, units: Units, periodic: Sequence[bool] = (True, True, True)) -> None:
        """MPM grid velocity (SI) -> padded lattice ``sand_velocity`` input of Eq. 39, ghosts filled."""
        nz, ny, nx = grid_v.shape[1:]
        self._fn("coupling_fractions.cu", "coupling_sand_velocity", "CK_RETENTION", "CK_TWO_PHASE")(
            (nx + 2) * (ny + 2) * (nz + 2), grid_v, sand_v, np.int32(nx), np.int32(ny), np.int32(nz),
            *(np.int32(bool(v)) for v in periodic), np.float32(units.dt / units.dx),
        )  # fmt: skip

    def pressure_slip_fluid(self, flags, velocity, phi, eps, slip, fsum) -> None:
        """``fsum`` := the fluid velocity's part of Eq. 39's slip term on the interior fluid cells:
        ``coupling_pressure_slip_fluid`` (see ReferenceOps.pressure_slip_fluid)."""
        nz, ny, nx = (s - 2 for s in flags.shape)
        self._fn("coupling_pressure.cu", "coupling_pressure_slip_fluid", "CK_TWO_PHASE")(
            (nx + 2) * (ny + 2) * (nz + 2), flags, velocity, self._opt(phi, self.two_phase, "phi"), eps, slip, fsum,
            np.int32(nx), np.int32(ny), np.int32(nz),
        )  # fmt: skip

    def pressure_sand_terms(
        self, grid_v, flags, phi, eps, slip, fsum, units: Units, periodic: Sequence[bool] = (True, True, True)
    ) -> None:
        """``fsum`` −= Eq. 39's sand terms without the fluid velocity's part on the interior fluid cells, the sand
        velocity read from the MPM grid velocity ``grid_v`` (SI) with :meth:`sand_velocity`'s ghost rule:
        ``coupling_pressure_sand_terms`` (see ReferenceOps.pressure_sand_terms)."""
        nz, ny, nx = grid_v.shape[1:]
        self._fn("coupling_pressure.cu", "coupling_pressure_sand_terms", "CK_TWO_PHASE")(
            (nx + 2) * (ny + 2) * (nz + 2), grid_v, flags, self._opt(phi, self.two_phase, "phi"), eps,
            slip, fsum, np.int32(nx), np.int32(ny), np.int32(nz), *(np.int32(bool(v)) for v in periodic),
            np.float32(units.dt / units.dx),
        )  # fmt: skip

    def drag_buoyancy(
        self,
        grid_m,
        grid_mv,
        force,
        u,
        phi,
        grid_vol,
        eps_fluid,
        flags,
        units: Units,
        gravity: Sequence[float],
        rho_h: float,
        rho_l: float,
        dt: float | None = None,
        volume_scale: float = 1.0,
    ) -> None:
        """Implicit drag impulse J + Δt × buoyancy into ``grid_mv`` and −J/Δt into ``force``; the sand fraction
        from the node volume ``volume_scale`` × ``grid_vol`` (Eq. 25, as :meth:`fractions`)."""
        nz, ny, nx = grid_m.shape
        p = self.params
        mass_scale, velocity_scale, dt, dt_lattice = drag_scales(units, dt)
        self._fn("coupling_drag.cu", "coupling_drag_buoyancy", "CK_TWO_PHASE")(
            nx * ny * nz, grid_m, grid_mv, force, u, self._opt(phi, self.two_phase, "phi"), grid_vol,
            eps_fluid, flags, np.int32(nx), np.int32(ny), np.int32(nz), np.float32(dt), np.float32(dt_lattice),
            *(np.float32(g) for g in gravity), np.float32(mass_scale), np.float32(velocity_scale),
            np.float32(rho_h), np.float32(rho_l), np.float32(p.drag_coefficient), np.float32(p.drag_exponent),
            np.float32(p.grain_diameter_lattice(units.dx)), np.float32(volume_scale / units.dx**3), np.float32(p.eps_max),
        )  # fmt: skip

    def fluid_view(self, u0, u_prev, impulse, phi, eps_fluid, flags, u_seen, theta: float, rho_h, rho_l) -> None:
        """The fluid velocity a sand substep sees (``coupling_fluid_view``): u0 + θ (u0 − u_prev) + A / (ρ ε_f)
        on interior fluid cells; ``u_prev`` None holds the fluid (no θ term)."""
        nz, ny, nx = (s - 2 for s in eps_fluid.shape)
        self._fn("coupling_subcycle.cu", "coupling_fluid_view", "CK_TWO_PHASE")(
            nx * ny * nz, u0, self._none if u_prev is None else u_prev, impulse,
            self._opt(phi, self.two_phase, "phi"), eps_fluid, flags, u_seen, np.int32(nx), np.int32(ny),
            np.int32(nz), np.int32(u_prev is not None), np.float32(theta), np.float32(rho_h), np.float32(rho_l),
        )  # fmt: skip

    def accumulate(self, acc, x, weight: float, first: bool) -> None:
        """``acc = weight x`` (first) or ``acc += weight x`` in place (``coupling_accumulate``)."""
        self._fn("coupling_subcycle.cu", "coupling_accumulate", "CK_TWO_PHASE")(
            x.size, acc, x, np.float32(weight), np.int32(bool(first))
        )

    def phase_source(self, eps, eps_prev, phi, u, flags, d_bound, source) -> None:
        """S_φ of Eq. 45 (Eq. 57 with retention) on interior FLUID cells of the padded ``source``."""
        nz, ny, nx = (s - 2 for s in eps.shape)
        self._fn("coupling_source.cu", "coupling_phase_source", "CK_RETENTION")(
            nx * ny * nz, eps, eps_prev, phi, u, flags, self._opt(d_bound, self.retention, "d_bound"), source,
            np.int32(nx), np.int32(ny), np.int32(nz),
        )  # fmt: skip

    def bound_water_p2g(self, x, r, vol, bound, dx: float) -> None:
        """R_i = (1/V_cell) Σ_p r_p V_p N_i(x_p) (Eq. 53), overwriting ``bound``."""
        nz, ny, nx = bound.shape
        ncell = nx * ny * nz
        mod = self.backend.module(
            "coupling_moisture.cu", {k: self._defines[k] for k in ("CK_RETENTION", "CK_TWO_PHASE")}
        )
        if self.backend.gpu_code_paths:  # the atomic scatter (cuda, cpu-device) accumulates into a cleared grid
            mod.function("coupling_clear")(ncell, bound)
            scratch, threads = self._no_scratch, 1
        else:
            threads = mod.num_threads()
            self._scratch = host_scatter_scratch(self._scratch, x.shape[1], ny, nz, threads)
            scratch = self._scratch
        mod.function("coupling_bound_water_p2g")(
            x.shape[1], x, r, vol, bound, scratch, np.int32(threads), np.int32(nx), np.int32(ny), np.int32(nz),
            np.float32(dx),
        )  # fmt: skip

    def particle_moisture(
        self,
        x,
        r,
        saturation,
        eps_fluid,
        phi,
        bound,
        d_bound,
        grid_vol,
        dx: float,
        retentive=None,
        retain=None,
        volume_scale: float = 1.0,
    ) -> None:
        """Saturation S_p (Eq. 59, the water fraction R' + ε φ from ``eps_fluid``, ``phi`` and ``bound``) and,
        with retention, the moisture update r_p (Eq. 58); per-body retention with ``retentive`` (retentive sand
        fraction) and ``retain`` (1 on retentive particles, else 0); the node sand volume is ``volume_scale`` ×
        ``grid_vol``."""
        nz, ny, nx = (s - 2 for s in eps_fluid.shape)
        ret = self.retention
        self._fn("coupling_moisture.cu", "coupling_particle_moisture", "CK_RETENTION", "CK_TWO_PHASE")(
            x.shape[1], x, self._opt(r, ret, "r"), saturation, eps_fluid, self._opt(phi, self.two_phase, "phi"),
            self._opt(bound, ret, "bound"), self._opt(d_bound, ret, "d_bound"),
            self._opt(grid_vol, ret, "grid_vol"), self._none if retentive is None else retentive,
            self._none if retain is None else retain, np.int32(nx), np.int32(ny), np.int32(nz), np.float32(dx),
            np.float32(volume_scale), np.int32(retentive is not None and ret),
        )  # fmt: skip
