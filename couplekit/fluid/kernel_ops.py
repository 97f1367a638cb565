"""Compiled fluid stages (cuda or cpu build of ``kernels/lbm_*.cu``), same signatures as :class:`ReferenceOps`.

Effects are compile-time defines (DESIGN "Effects"): ``CK_TWO_PHASE``, ``CK_SURFACE_TENSION``,
``CK_MIXTURE``, ``CK_EXT_FORCE``, and the fluid closures ``CK_LES`` (Smagorinsky), ``CK_ODD_RATE``
(odd-moment rate floor) and ``CK_ODD_RAMP`` (the floor ramped to rate 1 away from the walls, per-cell weights);
one cached module per flag set. Inputs of switched-off effects are not read
by the kernels and may be ``None``. ``storage="fp16"`` builds every module that touches f with
``CK_STORAGE_FP16=1`` (f a float16 array; :mod:`couplekit.fluid.storage`).
"""

from __future__ import annotations

import numpy as np

from ..backend import Backend
from .reference import check_chemical_potential, check_closures, check_odd_ramp, check_odd_ramp_effect
from .storage import check_storage


class KernelOps:
    """The fluid stages as kernels on ``backend`` (``cpu`` or ``cuda``); see :class:`ReferenceOps` for the maths."""

    skip_sand_free_rows = True
    """Host pressure update of a mixture: rows with no sand in their 3 × 3-row neighbourhood (fluid fraction
    exactly 1, sand velocity exactly 0) skip the mixture's four stencils (∇ε, ∇·v), whose terms are exactly 0
    there (bitwise the same results; ``lbm_rows_sand_free`` in kernels/lbm_core.cuh). False runs every row's
    stencils (tests compare)."""

    def __init__(
        self,
        backend: Backend,
        two_phase: bool = False,
        surface_tension: bool = False,
        mixture: bool = False,
        external_force: bool = False,
        les: bool = False,
        odd_rate: bool = False,
        storage: str = "fp32",
        odd_ramp: bool = False,
    ):
        self.backend = backend
        self.name = backend.name
        self.two_phase = bool(two_phase)
        self.surface_tension = bool(surface_tension) and self.two_phase
        self.mixture = bool(mixture)
        self.external_force = bool(external_force)
        self.les = bool(les)
        self.odd_rate = bool(odd_rate)
        self.odd_ramp = check_odd_ramp_effect(odd_ramp, self.odd_rate)
        self.storage = check_storage(storage)
        defines = self.defines()
        # fp16 storage: CK_STORAGE_FP16=1 in every module that reads or writes f (absent for fp32, so the fp32
        # modules are the ones built before the option existed)
        store = {"CK_STORAGE_FP16": 1} if self.storage == "fp16" else {}
        collide = backend.module("lbm_collide.cu", defines)
        pressure = backend.module(
            "lbm_pressure.cu", {"CK_TWO_PHASE": defines["CK_TWO_PHASE"], "CK_MIXTURE": defines["CK_MIXTURE"], **store}
        )
        halo = backend.module("lbm_halo.cu", store)
        self._collide = collide.function("lbm_collide_stream")
        self._macro = pressure.function("lbm_macro_pressure")
        self._filter = pressure.function("lbm_pressure_filter")
        self._filter_wall = pressure.function("lbm_filter_wall_rule")
        self._momentum = pressure.function("lbm_momentum")
        self._halo = halo.function("lbm_halo_copy")
        self._halo_pop = halo.function("lbm_halo_copy_pop")
        self._halo_boxes = halo.function("lbm_halo_boxes")
        self._outflow_fix = halo.function("lbm_outflow_fix")
        self._outflow_fill = halo.function("lbm_outflow_fill")
        self._prefill = halo.function("lbm_wall_prefill")
        self._bounce = halo.function("lbm_wall_bounce")
        self._links_flags = None  # the flags array the cached wall links belong to
        self._links = None
        self._rule_flags = None  # the flags array (and axes) the cached three-point wall rule's cells belong to
        self._rule_axes = None
        self._rule = None
        self._dummy = backend.xp.zeros(1, dtype=np.float32)
        self._dummy_mask = backend.xp.zeros(1, dtype=np.uint8)

    def defines(self) -> dict[str, int]:
        """The preprocessor flags of the collide kernel for this effect set."""
        return {
            "CK_TWO_PHASE": int(self.two_phase),
            "CK_SURFACE_TENSION": int(self.surface_tension),
            "CK_MIXTURE": int(self.mixture),
            "CK_EXT_FORCE": int(self.external_force),
            "CK_LES": int(self.les),
            "CK_ODD_RATE": int(self.odd_rate),
            # absent without the ramp, so the modules without it are the ones built before it existed
            **({"CK_ODD_RAMP": 1} if self.odd_ramp else {}),
            **({"CK_STORAGE_FP16": 1} if self.storage == "fp16" else {}),
        }

    def _wall_links(self, flags):
        """Wall links of ``flags``, ``(cell, direction, mate)`` (:func:`~couplekit.fluid.grid.wall_links`,
        :func:`~couplekit.fluid.grid.wall_link_mates`; built once per flags array; flags are treated as immutable
        — call :meth:`forget_links` after changing one in place)."""
        if self._links_flags is not flags:
            from .grid import wall_link_mates, wall_links

            host = self.backend.to_host(flags)
            cell, d = wall_links(host)
            mate = wall_link_mates(cell, d, host.shape)
            self._links = (self.backend.asarray(cell), self.backend.asarray(d), self.backend.asarray(mate))
            self._links_flags = flags
        return self._links

    def _three_point_cells(self, flags, axes=(True, True, True)):
        """``(cell, links)`` of the filter's three-point wall rule: the padded index (int64) of every cell with a
        link in :func:`couplekit.fluid.grid.three_point_links` (walls normal to ``axes``) and its link mask
        (uint32), built once per flags array and axes (as the wall links)."""
        axes = tuple(bool(a) for a in axes)
        if self._rule_flags is not flags or self._rule_axes != axes:
            from .grid import three_point_links

            links = three_point_links(self.backend.to_host(flags), axes).ravel()
            cell = np.flatnonzero(links).astype(np.int64)
            self._rule = (self.backend.asarray(cell), self.backend.asarray(links[cell].astype(np.uint32)))
            self._rule_flags, self._rule_axes = flags, axes
        return self._rule

    def forget_links(self) -> None:
        """Drop the cached wall links and three-point rule cells (after editing a flags array in place)."""
        self._links_flags = self._links = None
        self._rule_flags = self._rule = None

    def _wall_call(self, fn, f, flags, velocity) -> None:
        cell, d, mate = self._wall_links(flags)
        if cell.size:
            pz, py, px = flags.shape
            fn(int(cell.size), f, velocity, cell, d, mate, np.int32(px - 2), np.int32(py - 2), np.int32(pz - 2))

    def _or_dummy(self, a, used: bool):
        return a if (used and a is not None) else self._dummy

    @staticmethod
    def _interior(flags) -> tuple[int, int, int, int]:
        pz, py, px = flags.shape
        nz, ny, nx = pz - 2, py - 2, px - 2
        return nx * ny * nz, nx, ny, nz

    def macro_pressure(
        self,
        f,
        flags,
        velocity,
        phi,
        eps,
        sand_v,
        slip,
        p,
        parity: int,
        rho_h: float,
        rho_l: float,
        fsum=None,
        sand_in_fsum: bool = False,
    ) -> None:
        """Eq. 39 pressure update in place (see ReferenceOps.macro_pressure; ``fsum``: Σ_j (f_j − w_j) of these
        populations from :meth:`momentum`, read instead of f; ``sand_in_fsum``: it also holds minus the sand's
        terms, kernels/coupling_pressure.cu, and ``sand_v`` may be None).

        An odd step's wall links are prefilled here for the collide that follows (its ``prefilled``), unless
        ``fsum`` is given: then :meth:`momentum` ran on these same populations and wall velocities at this step
        (FluidSolver's kept-sum contract: nothing writes f in between, and the coupling stages between them write
        no fluid velocity) and prefilled them already; a second prefill wrote the same values again."""
        n, nx, ny, nz = self._interior(flags)
        if parity & 1 and fsum is None:
            self._wall_call(self._prefill, f, flags, velocity)
        self._macro(
            n,
            f,
            flags,
            velocity,
            self._or_dummy(phi, self.two_phase),
            self._or_dummy(eps, self.mixture),
            self._or_dummy(sand_v, self.mixture),
            slip if (self.mixture and slip is not None) else self._dummy_mask,
            self._dummy if fsum is None else fsum,
            p,
            np.int32(parity),
            np.int32(0 if fsum is None else (2 if sand_in_fsum and self.mixture else 1)),
            np.int32(self.skip_sand_free_rows),
            np.int32(nx),
            np.int32(ny),
            np.int32(nz),
            np.float32(rho_h),
            np.float32(rho_l),
        )

    def momentum(self, f, flags, velocity, out, parity: int, fsum=None, held: bool = False) -> None:
        """Σ_j f_j c_j of the current populations into ``out``, and Σ_j (f_j − w_j) into ``fsum`` if given, minus
        what ``fsum`` held with ``held`` (see ReferenceOps.momentum)."""
        n, nx, ny, nz = self._interior(flags)
        if parity & 1:
            self._wall_call(self._prefill, f, flags, velocity)
        mode = 0 if fsum is None else (2 if held else 1)
        self._momentum(
            n, f, flags, out, self._dummy if fsum is None else fsum, np.int32(parity), np.int32(mode),
            np.int32(nx), np.int32(ny), np.int32(nz),
        )  # fmt: skip

    def pressure_filter(self, p, flags, pbar, axes=(True, True, True)) -> None:
        """Eq. 40 filter (see ReferenceOps.pressure_filter)."""
        n, nx, ny, nz = self._interior(flags)
        self._filter(n, p, flags, pbar, np.int32(nx), np.int32(ny), np.int32(nz))
        cell, links = self._three_point_cells(flags, axes)
        if cell.size:
            self._filter_wall(int(cell.size), p, pbar, cell, links, np.int32(nx), np.int32(ny), np.int32(nz))

    def collide_stream(
        self,
        f,
        flags,
        velocity,
        phi,
        eps,
        force,
        pbar,
        parity: int,
        rho_h: float,
        rho_l: float,
        nu_h: float,
        nu_l: float,
        gx: float,
        gy: float,
        gz: float,
        smagorinsky: float = 0.0,
        odd_lambda: float = 0.0,
        odd_nu_max: float = 1.0,
        chemical_potential: tuple[float, float] | None = None,
        odd_ramp=None,
        prefilled: bool = False,
    ) -> None:
        """Fused forces + NOCM-MRT collision + AA streaming (see ReferenceOps.collide_stream). ``prefilled``: an
        odd step's wall links were already prefilled for these populations and wall velocities (by this step's
        :meth:`macro_pressure`, with nothing in between that writes f or the velocities); the prefill is then not
        repeated (it would write the same values)."""
        check_closures(self, smagorinsky, odd_lambda)
        check_odd_ramp(self, odd_ramp)
        beta, kappa = check_chemical_potential(self, chemical_potential)
        n, nx, ny, nz = self._interior(flags)
        if parity & 1 and not prefilled:
            self._wall_call(self._prefill, f, flags, velocity)
        self._collide(
            n,
            f,
            flags,
            velocity,
            self._or_dummy(phi, self.two_phase),
            self._or_dummy(eps, self.mixture),
            self._or_dummy(force, self.external_force),
            pbar,
            self._or_dummy(odd_ramp, self.odd_ramp),
            np.int32(parity),
            np.int32(nx),
            np.int32(ny),
            np.int32(nz),
            *(np.float32(v) for v in (rho_h, rho_l, nu_h, nu_l, gx, gy, gz, smagorinsky, odd_lambda, odd_nu_max)),
            np.float32(beta),
            np.float32(kappa),
        )
        if parity & 1:
            self._wall_call(self._bounce, f, flags, velocity)

    def halo_copy(self, a, ghost, image) -> None:
        """Copy every component of ``a`` from the interior images to the periodic ghosts."""
        if ghost.size == 0:
            return
        ncomp = 1 if a.ndim == 3 else int(np.prod(a.shape[:-3]))
        ncell = int(np.prod(a.shape[-3:]))
        # the populations' storage type may differ from the other fields' float32
        fn = self._halo_pop if a.dtype == np.float16 else self._halo
        fn(int(ghost.size), a, ghost, image, np.int32(ncomp), np.int64(ncell))

    def halo_pull(self, f, ghost, image, boxes) -> None:
        """Before an odd step: the populations the pull reads from the periodic ghosts, copied from their images
        (ReferenceOps.halo_pull); ``boxes``: :func:`couplekit.fluid.grid.link_box_arrays` of
        :func:`~couplekit.fluid.grid.periodic_link_boxes`, arrays on the backend (the lists ``ghost``, ``image``
        are the reference's)."""
        self._run_boxes(f, boxes, 0)

    def fold(self, f, ghost, image, boxes) -> None:
        """After an odd step, move populations pushed into periodic ghosts to their images (ReferenceOps.fold;
        ``boxes`` as in :meth:`halo_pull`)."""
        self._run_boxes(f, boxes, 1)

    def _run_boxes(self, f, boxes, fold: int) -> None:
        rows, start, total = boxes.rows, boxes.start, boxes.total
        if total == 0:
            return
        pz, py, px = f.shape[-3:]
        self._halo_boxes(
            total, f, rows, start, np.int32(rows.size // 10), np.int32(fold), np.int32(px - 2), np.int32(py - 2),
            np.int32(pz - 2),
        )  # fmt: skip

    def outflow_fill(self, f, ghost, src, outward, du) -> None:
        """Before an odd step, fill the outflow ghosts' populations from their interior cells, backflow taken out;
        each ghost's Δu into ``du`` (3, n) for :meth:`outflow_fix` (ReferenceOps.outflow_fill)."""
        if ghost.size == 0:
            return
        pz, py, px = f.shape[-3:]
        self._outflow_fill(
            int(ghost.size), f, ghost, src, outward, du, np.int32(px - 2), np.int32(py - 2), np.int32(pz - 2)
        )

    def outflow_fix(self, f, ghost, src, du) -> None:
        """After an odd step, set what the outflow ghosts would have pushed (zero gradient, backflow taken out:
        ReferenceOps.outflow_fix)."""
        if ghost.size == 0:
            return
        pz, py, px = f.shape[-3:]
        self._outflow_fix(int(ghost.size), f, ghost, src, du, np.int32(px - 2), np.int32(py - 2), np.int32(pz - 2))
