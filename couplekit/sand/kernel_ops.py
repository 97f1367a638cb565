"""The sand solver's stages as compiled kernels (cuda or cpu build of ``kernels/mpm_*.cu``).

Same methods and arguments as :class:`couplekit.sand.reference.ReferenceOps`.  On the cpu backend the P2G
is deterministic (particles scattered by tiles, one summation order: kernels/host_scatter.cuh), so a run is
bitwise reproducible, with any thread count; ``host_atomics=True`` selects the `omp atomic` scatter
instead (not reproducible; kept to measure what determinism costs).
"""

from __future__ import annotations

import numpy as np

from ..backend import Backend
from ..backend.host_scatter import host_scatter_scratch
from .params import ConstitutiveModel

__all__ = ["KernelOps"]


class KernelOps:
    """Sand stages on ``backend`` (``cuda`` or ``cpu``)."""

    def __init__(self, backend: Backend, host_atomics: bool = False):
        if not backend.has_kernels:
            raise ValueError(f"KernelOps needs a kernel backend (cuda or cpu), got {backend.name!r}")
        self.backend = backend
        self.name = backend.name
        self.host_atomics = bool(host_atomics) and backend.name == "cpu"
        self._p2g_defines = {"MPM_HOST_ATOMICS": 1} if self.host_atomics else {}
        # the atomic P2G (cuda, cpu-device, host atomics) accumulates into a grid cleared first
        self._clear_first = backend.gpu_code_paths or self.host_atomics
        self.deterministic = backend.name == "cpu" and not self.host_atomics
        self._scratch = None
        self._threads = 1
        self._skipped = backend.xp.zeros(1, dtype=np.int32)
        self._no_friction = backend.xp.zeros(1, dtype=np.float32)  # the pointer passed without a friction field
        # the pointer passed for a particle field an effect that is compiled out does not have (q without
        # hardening, saturation without cohesion): that variant of the kernel never reads or writes it
        self._no_field = backend.xp.zeros(1, dtype=np.float32)

    def _module(self, source: str, defines: dict | None = None):
        return self.backend.module(source, defines)

    def _scratch_for(self, mod, n: int, ny: int, nz: int):
        """(scratch, threads) of the P2G: on the host the tiled scatter's ints (kernels/host_scatter.cuh), kept
        between calls; a 1-int placeholder for the atomic scatter."""
        if self._clear_first:
            if self._scratch is None:
                self._scratch = self.backend.xp.zeros(1, dtype=np.int32)
            return self._scratch, 1
        threads = mod.num_threads()
        self._scratch = host_scatter_scratch(self._scratch, n, ny, nz, threads)
        return self._scratch, threads

    def p2g(self, x, v, C, tau, mass, vol, grid_m, grid_mv, grid_vol, dx: float, dt: float) -> None:
        """Overwrite node mass, momentum (with the stress impulse) and sand volume from the particles
        (``grid_vol`` None: no node volume, the MPM_P2G_VOLUME=0 build)."""
        nz, ny, nx = grid_m.shape
        ncell = nx * ny * nz
        # the volume build is the source's default (one library whether it is named or not)
        defines = self._p2g_defines if grid_vol is not None else {**self._p2g_defines, "MPM_P2G_VOLUME": 0}
        mod = self._module("mpm_p2g.cu", defines)
        scratch, threads = self._scratch_for(mod, x.shape[1], ny, nz)
        volume = self._no_field if grid_vol is None else grid_vol
        if self._clear_first:
            mod.function("mpm_clear_grid")(ncell, grid_m, grid_mv, volume)
        self._skipped.fill(0)
        mod.function("mpm_p2g")(
            x.shape[1],
            x,
            v,
            C,
            tau,
            mass,
            vol,
            grid_m,
            grid_mv,
            volume,
            scratch,
            self._skipped,
            np.int32(threads),
            np.int32(nx),
            np.int32(ny),
            np.int32(nz),
            np.float32(dx),
            np.float32(dt),
        )

    def skipped_particles(self) -> int:
        """Particles the last :meth:`p2g` left out: non-finite positions, or stencils outside the grid
        (kernels/mpm_p2g.cu guard; 0 unless the state diverged).  Reads back one int (a GPU sync)."""
        return int(self.backend.to_host(self._skipped)[0])

    def grid_update(
        self,
        grid_m,
        grid_mv,
        grid_v,
        dx: float,
        dt: float,
        gravity,
        bound: int,
        walls,
        colliders,
        ncolliders: int,
        sdf,
        has_sdf: int,
        sdf_params,
        sdf_friction=None,
    ) -> None:
        """v_i = (mv)_i/m_i + Δt g on nodes with mass (Eq. 29), then boundary conditions.  ``grid_v`` may be
        ``grid_mv`` itself (in place, as SandSolver does); the coupling's forces are already in ``grid_mv``.

        ``sdf_friction``: the SDF collider's Coulomb friction per node (nz, ny, nx), or None for its one friction
        ``sdf_params[1]``."""
        nz, ny, nx = grid_m.shape
        g = [np.float32(c) for c in gravity]
        self._module("mpm_grid.cu").function("mpm_grid_update")(
            nx * ny * nz,
            grid_m,
            grid_mv,
            grid_v,
            np.int32(nx),
            np.int32(ny),
            np.int32(nz),
            np.float32(dx),
            np.float32(dt),
            *g,
            np.int32(bound),
            walls,
            colliders,
            np.int32(ncolliders),
            sdf,
            np.int32(has_sdf),
            sdf_params,
            self._no_friction if sdf_friction is None else sdf_friction,
            np.int32(sdf_friction is not None),
        )

    def g2p(self, x, v, C, F, tau, q, vc, saturation, grid_v, dx: float, dt: float, model: ConstitutiveModel) -> None:
        """Gather v_p and C_p, update F, return-map, Kirchhoff stress, advect x_p (in place)."""
        nz, ny, nx = grid_v.shape[1:]
        self._module("mpm_g2p.cu", model.defines()).function("mpm_g2p")(
            x.shape[1],
            x,
            v,
            C,
            F,
            tau,
            self._no_field if q is None else q,  # q None: hardening off; saturation None: cohesion off
            vc,
            self._no_field if saturation is None else saturation,
            grid_v,
            np.int32(nx),
            np.int32(ny),
            np.int32(nz),
            np.float32(dx),
            np.float32(dt),
            *model.scalars(),
            np.float32(model.plastic_fraction(dt)),
        )

    def sdf_project(self, x, sdf, dx: float, depth: float) -> None:
        """Particles deeper than ``depth`` in the grid SDF collider pulled back to it (kernels/mpm_sdf_project.cu)."""
        nz, ny, nx = sdf.shape
        self._module("mpm_sdf_project.cu").function("mpm_sdf_project")(
            x.shape[1], x, sdf, np.int32(nx), np.int32(ny), np.int32(nz), np.float32(dx), np.float32(depth)
        )

    def svd3(self, A):
        """A (9, P) -> U (9, P), σ (3, P), V (9, P), signed SVD (float32 kernel)."""
        xp = self.backend.xp
        n = A.shape[1]
        U = xp.empty((9, n), dtype=np.float32)
        V = xp.empty((9, n), dtype=np.float32)
        s = xp.empty((3, n), dtype=np.float32)
        self._module("mpm_constitutive.cu").function("mpm_svd3_batch")(n, A, U, s, V)
        return U, s, V

    def constitutive(self, F, tau, q, vc, saturation, model: ConstitutiveModel, dt: float | None = None) -> None:
        """F_trial (9, P) -> elastic F after plasticity, tau (6, P), q, vc (in place); ``dt`` the step for the
        viscoplastic overstress (:meth:`ConstitutiveModel.plastic_fraction`; None: rate-independent)."""
        self._module("mpm_constitutive.cu", model.defines()).function("mpm_constitutive_batch")(
            F.shape[1],
            F,
            tau,
            self._no_field if q is None else q,
            vc,
            self._no_field if saturation is None else saturation,
            *model.scalars(),
            np.float32(model.plastic_fraction(dt)),
        )
