"""FluidSolver: the two-phase (or single-phase) velocity-based LBM of paper 000 §4.1/§4.4, one step at a time.

The solver owns the padded fields (layout: :mod:`couplekit.fluid.grid`) and calls only ops objects, so one
code path serves every backend: :class:`KernelOps` + :class:`PhaseFieldKernelOps` on cpu/cuda,
:class:`ReferenceOps` + :class:`PhaseFieldReferenceOps` on numpy. One step (Algorithm 1's LBM stages):

1. (odd parity) periodic and outflow ghosts of f are filled from the interior (outflow: backflow taken out,
   ``ReferenceOps.outflow_fill``);
2. pressure update, Eq. 39, from the current populations and φ (``macro_pressure``);
3. 27-point filter, Eq. 40 (by default the stored p is replaced by p̄, see FluidParams);
4. fused forces (Eqs. 15-20) + NOCM-MRT collision + AA streaming of f, writing the velocity u^n;
5. (odd parity) populations pushed into periodic / outflow ghosts are folded back;
6. two-phase: phase-field collide + stream with u^n (Eq. 48, volume controller Eq. 52 when η > 0),
   then φ, ∇φ and the chemical potential of the next step.

Effects (DESIGN "Effects"): a single-phase solver (``phi=None``) allocates no phase field; σ = 0 compiles the
chemical potential out of both the phase field and the flow kernel; the fluid-fraction / sand-velocity
inputs (``mixture=True``) and the force-density input (``external_force=True``) exist only when asked for.

Streaming: f and h both use the AA pattern with the same cell flags (walls, inflow carrying a phase value
stored in ``phi`` at the inflow cells, outflow), so one step parity and one flag array serve both.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields
from typing import Any

import numpy as np

from ..arguments import is_real, whole_count
from ..backend import Backend, get_backend
from ..lattice import CS2
from ..slabs import host_slabs
from .grid import (
    FLUID,
    INFLOW,
    INTERIOR,
    OUTFLOW,
    Boundaries,
    build_flags,
    ghost_faces,
    inflow_front_ramp,
    link_box_arrays,
    outflow_directions,
    outflow_lists,
    padded_shape,
    periodic_link_boxes,
    periodic_lists,
    slip_cells,
    slip_wall_layers,
    wall_rule_axes,
)
from .kernel_ops import KernelOps
from .odd_ramp import check_gaps, ramp_weights
from .reference import ReferenceOps, equilibrium, to_stored
from .storage import check_storage, dtype_of


def _checked_solid(solid: Any, shape: tuple[int, int, int]) -> np.ndarray | None:
    """The ``solid`` argument of :class:`FluidSolver` as a boolean mask of ``shape``: a boolean array, or numbers
    that are all 0 or 1. Anything else is refused: ``np.asarray(solid, bool)`` made every nonzero cell solid, so
    a signed distance field passed instead of ``sdf < 0`` turned the whole box into a wall."""
    if solid is None:
        return None
    mask = np.asarray(solid)
    if mask.shape != shape:
        raise ValueError(f"solid must be a boolean mask of the interior shape {shape}, got shape {mask.shape}")
    if mask.dtype == bool:
        return mask
    if mask.dtype.kind not in "iuf" or not np.isin(mask, (0, 1)).all():
        raise ValueError(
            f"solid must be a boolean mask (True = obstacle cell), got {mask.dtype} values that are not all 0 or 1: "
            "for a signed distance field pass solid=sdf < 0"
        )
    return mask.astype(bool)


@dataclass(frozen=True)
class FluidParams:
    """Lattice-unit parameters of the fluid (Δx = Δt = 1).

    ``rho_h``, ``rho_l``: densities of the heavy and light phase (ρ_h = 1 is the usual reference);
    ``nu_h``, ``nu_l``: their kinematic viscosities (μ interpolates linearly in φ, Eq. 4);
    ``gravity``: acceleration (x, y, z); ``sigma``: surface tension (0 compiles the chemical potential out);
    ``mobility``, ``width``: phase-field mobility M and interface width ξ (cells);
    ``eta``: volume-controller bound η of Eq. 52 (0 = off); with ``mixture`` the controller's sums are
    ε-weighted (``FluidSolver._controller_sums``). A single-phase solver uses ``rho_h``, ``nu_h``.
    ``store_filtered_pressure``: True (default, the paper's reading of Eq. 40: "a filter is applied to the
    pressure field") replaces p by p̄ every step; False keeps p unfiltered and uses p̄ only for the force.
    The stored filter is what keeps the 800:1, ν_h = 1e-4 regime stable: without it the pressure of the
    light phase grows exponentially within ~300 steps of a column collapse (measured at 32³). Unfiltered, even a
    single-phase periodic box is linearly unstable at low viscosity (an acoustic mode; a shear wave, which has no
    pressure perturbation, is stable): 1e-6 noise on 16³ blows up by step ~1400 at ν = 0.02 and ~2000 at 0.03, and
    still grows at 0.05; it decays at 0.1 and 0.3, and with the filter stored at every viscosity (a probe, session 23;
    ``tests/fluid/test_unfiltered_pressure.py``). A Taylor–Green vortex at N = 32 blows up by step ~800 at
    ν = 0.005 and ~1700 at 0.02: the unfiltered Taylor–Green accuracy of tests/fluid/test_flow_validation.py holds for
    its runs of at most ~700 steps only. A study option, not for scenes.
    ``odd_lambda``: floor Λ of the two-relaxation-time product (1/r_s − ½)(1/r_o − ½) that sets the rate r_o of
    the odd central moments (orders 3, 5; :func:`~couplekit.fluid.reference.odd_rate`). The paper relaxes
    them at 1, which at its ν_h = 1e-4 makes the edges and corners of no-slip walls linearly unstable (a
    period-2 oscillation along the edge, ×e every ~150 steps; docs/fluid-stability.md). Scenes use 0.015,
    inside the window measured stable (linear ≥ 0.01, non-linear noise tests ≤ 0.02; 0.03 diverges in a
    closed box), together with ``smagorinsky`` = 0.1: alone, the floor makes violent flows at ν = 1e-4 fail
    sooner (an 800:1 column collapse at 32³ diverged near step 750 instead of running). Default 0 here (the
    paper's collision, which the validations test). The rate is one number for the whole fluid, from its
    lowest molecular viscosity (:func:`~couplekit.fluid.reference.odd_rates`: a rate varying with each
    cell's viscosity fed energy into an 800:1 interface, docs/fluid-stability.md), and the floor is off when
    that viscosity is at least ``odd_nu_max`` (default 5e-4: ν = 1e-3 is stable at rate 1, and there the floor
    was measured to disturb the coupled validations: a floating ball 0.8 cell high). 0 = the paper's collision
    exactly.
    ``odd_ramp``: D, in cells (default 0: the floor everywhere). With D > 0 the floor acts only near the
    boundaries: r_o = r_floor + (1 − r_floor) s with s a cosine ramp from 0 in the cells touching a wall (or a
    solid cell, an inflow or outflow face) to 1 from D + ½ cells in (:mod:`couplekit.fluid.odd_ramp`), so that
    the fluid away from walls relaxes its odd moments at the paper's rate 1. Measured stable at D = 3 wherever
    boundaries are ≥ 8 cells apart; :class:`FluidSolver` refuses narrower gaps. It is what lets a 600 kg/m³
    ball of 1.7 cells float at interface width 4 (docs/examples.md, Fig. 8). Costs one float32 per cell.
    ``smagorinsky``: Smagorinsky constant C of a subgrid viscosity ν_t = (C Δx)² |S̄| added to ν (0 = off, the
    default and the paper's model); 0.1–0.17 is usual for under-resolved turbulent flows.
    ``phase_trt_lambda``: Λ_h of a two-relaxation-time collision of the phase field (the symmetric
    non-equilibrium of each population pair relaxed at ω₊ with (1/ω − ½)(1/ω₊ − ½) = Λ_h; the mobility is
    unchanged; 0 = the paper's single rate, Eq. 48). ``None`` (default): :data:`PHASE_TRT_LAMBDA_INFLOW` when the
    boundaries have an inflow (a face or a region), else 0 (:meth:`phase_lambda_for`). Why: with the single rate
    (ω = 1.72 at M = 0.02) the front an inflow builds at the face has a tail alternating in sign (φ < 0 in the
    second layer from step 5 on); where that meets air (ρ_l) next to a cell with φ ≈ 0.1, the adjacent density
    ratio passes ~100 and the pressure update (Eq. 39) and −∇p̄/ρ grow a period-2 mode there (narrow outlets
    diverged at 800:1, tests/fluid/test_inflow_region.py). Two rates make that tail monotone.

    **Defaults differ from a scene's.** ``FluidParams()`` is the paper's collision on a generic fluid, what the
    solver validations test; a scene's ``[fluid]`` table defaults to the paper's viscosities with the
    closures on. :meth:`scene_defaults` gives exactly the scene's (the assembly builds every scene's fluid
    through it), and :class:`~couplekit.fluid.grid.Boundaries` likewise (all periodic here, walls in a scene:
    ``Boundaries.scene_defaults()``):

    ========================== ===================== ==================================================
    field                      ``FluidParams()``     ``FluidParams.scene_defaults()`` (scene key)
    ========================== ===================== ==================================================
    ``nu_h``, ``nu_l``         0.1, 0.1              1e-4, 1e-2 (``water_/air_lattice_viscosity``)
    ``rho_l``                  1.0                   1.25 / 1000 (``air_density / water_density``)
    ``odd_lambda``             0 (off)               0.015 (``odd_lambda``): acts, ν_h = 1e-4 < 5e-4
    ``smagorinsky``            0 (off)               0.1 (``smagorinsky``)
    ``eta``                    0 (off)               2.0 (``controller_eta``)
    ``mobility``, ``width``    0.02, 4               0.02, 4 (``mobility``, ``interface_width``)
    ``gravity``, ``sigma``     0, 0                  0, 0 (SI in a scene: ``Units.to_lattice`` of them)
    ========================== ===================== ==================================================

    **When ``odd_lambda`` acts:** only when the fluid's lowest molecular viscosity ν_ref (ν_h single-phase,
    min(ν_h, ν_l) two-phase) is below both 2Λ/3 (above it the paper's rate 1 already gives Λ) and
    ``odd_nu_max``: :meth:`odd_floor_acts`. Otherwise the floor does nothing, and :class:`FluidSolver` warns
    (:class:`OddFloorInactiveWarning`) when it was asked for (``odd_lambda`` > 0); a scene logs a note instead.
    """

    rho_h: float = 1.0
    rho_l: float = 1.0
    nu_h: float = 0.1
    nu_l: float = 0.1
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sigma: float = 0.0
    mobility: float = 0.02
    width: float = 4.0
    eta: float = 0.0
    store_filtered_pressure: bool = True
    smagorinsky: float = 0.0
    odd_lambda: float = 0.0
    odd_nu_max: float = 5e-4
    phase_trt_lambda: float | None = None
    odd_ramp: float = 0.0

    # (lowest, highest, lowest excluded, what it is / the usual value) of every numeric field: each a finite real
    # number (bool is not) in its range. The phase-field ranges follow the scene keys' (couplekit/scene/schema.py:
    # interface_width >= 2, mobility in (0, 1]); viscosities and densities only > 0, as a scene's lattice values
    # are checked by the scene itself
    _RANGES = {
        "rho_h": (0.0, math.inf, True, "density of the heavy phase (phi = 1), usually 1"),
        "rho_l": (0.0, math.inf, True, "density of the light phase (phi = 0), e.g. 1/800"),
        "nu_h": (0.0, math.inf, True, "lattice viscosity, tau = 3 nu + 1/2 > 1/2"),
        "nu_l": (0.0, math.inf, True, "lattice viscosity, tau = 3 nu + 1/2 > 1/2"),
        "sigma": (0.0, math.inf, False, "0 = no surface tension"),
        "mobility": (0.0, 1.0, True, "scenes use 0.02"),
        "width": (2.0, math.inf, False, "cells; scenes refuse interface_width < 2 and use 4"),
        "eta": (0.0, math.inf, False, "0 = controller off; Table 1 uses 1 or 2"),
        "smagorinsky": (0.0, 1.0, False, "typical 0.1-0.2"),
        "odd_lambda": (0.0, 1.0, False, "e.g. 0.015"),
        "odd_nu_max": (0.0, math.inf, True, "default 5e-4"),
        "odd_ramp": (0.0, 64.0, False, "0: the floor everywhere; 3 measured"),
        "phase_trt_lambda": (0.0, 1.0, False, "None: 1/6 with an inflow, else 0"),
    }

    def __post_init__(self) -> None:
        problems = []
        for name, (lo, hi, lo_open, what) in self._RANGES.items():
            value = getattr(self, name)
            if value is None and name == "phase_trt_lambda":
                continue
            bounds = ("(" if lo_open else "[") + f"{lo:g}, " + (f"{hi:g}]" if math.isfinite(hi) else "inf)")
            if not is_real(value):
                problems.append(
                    f"{name} must be a finite number in {bounds} ({what}), got {value!r} ({type(value).__name__})"
                )
            elif not (math.isfinite(value) and (lo < value if lo_open else lo <= value) and value <= hi):
                problems.append(f"{name} must be a finite number in {bounds} ({what}), got {value!r}")
        g = self.gravity
        try:
            components = list(g) if not isinstance(g, (str, bytes)) else None
        except TypeError:
            components = None
        if components is None or len(components) != 3:
            problems.append(f"gravity must be 3 numbers (x, y, z) in lattice units, e.g. (0, 0, -1e-5), got {g!r}")
        elif not all(is_real(c) and math.isfinite(c) for c in components):
            problems.append(f"gravity must be 3 finite numbers (x, y, z) in lattice units, got {g!r}")
        if not isinstance(self.store_filtered_pressure, (bool, np.bool_)):
            problems.append(f"store_filtered_pressure must be True or False, got {self.store_filtered_pressure!r}")
        rho_h, rho_l = self.rho_h, self.rho_l
        if all(is_real(r) and math.isfinite(r) and r > 0 for r in (rho_h, rho_l)) and rho_h < rho_l:
            problems.append(
                f"rho_h = {rho_h:g} is below rho_l = {rho_l:g}: rho_h is the heavy phase, the one phi = 1 marks (the "
                "solver's checks of a sharp interface read rho_h / rho_l). Swap the densities and give phi -> 1 - phi "
                "(a single-phase fluid uses rho_h alone: leave rho_l at or below it)"
            )
        if problems:
            raise ValueError("invalid FluidParams: " + "; ".join(problems))

    @classmethod
    def scene_defaults(cls, **overrides: Any) -> FluidParams:
        """The lattice parameters a scene's fluid gets where its ``[fluid]`` table sets nothing (the class
        docstring's table; the values are read from the scene schema, so they cannot drift), with
        ``overrides`` (any field) applied. Gravity and surface tension are SI in a scene and stay 0 here: give
        them in lattice units (:meth:`couplekit.units.Units.to_lattice`)."""
        from ..scene.model import _DEFAULT_LATTICE_VISCOSITY
        from ..scene.schema import SECTIONS

        key = {k.name: k.default for k in SECTIONS["fluid"]}
        values: dict[str, Any] = dict(
            rho_h=1.0,
            rho_l=key["air_density"] / key["water_density"],
            nu_h=_DEFAULT_LATTICE_VISCOSITY["water"],
            nu_l=_DEFAULT_LATTICE_VISCOSITY["air"],
            mobility=key["mobility"],
            width=key["interface_width"],
            eta=key["controller_eta"],
            odd_lambda=key["odd_lambda"],
            smagorinsky=key["smagorinsky"],
        )
        names = [f.name for f in dataclass_fields(cls)]
        unknown = set(overrides) - set(names)
        if unknown:
            raise TypeError(f"FluidParams has no field(s) {sorted(unknown)}; its fields are {', '.join(names)}")
        values.update(overrides)
        return cls(**values)

    def phase_lambda_for(self, has_inflow: bool) -> float:
        """The phase field's TRT Λ_h a solver uses: ``phase_trt_lambda``, or when that is None
        :data:`PHASE_TRT_LAMBDA_INFLOW` with an inflow and 0 (the paper's Eq. 48) without."""
        if self.phase_trt_lambda is not None:
            return float(self.phase_trt_lambda)
        return PHASE_TRT_LAMBDA_INFLOW if has_inflow else 0.0

    def odd_reference_viscosity(self, two_phase: bool = True) -> float:
        """ν_ref of the odd-moment rate: the lowest molecular viscosity (ν_h single-phase, min(ν_h, ν_l))."""
        return min(self.nu_h, self.nu_l) if two_phase else self.nu_h

    def odd_floor_acts(self, two_phase: bool = True) -> bool:
        """Whether the ``odd_lambda`` floor changes the collision: Λ > 0 and ν_ref < min(2Λ/3, ``odd_nu_max``)
        (:func:`~couplekit.fluid.reference.odd_rates`); False means the solver runs the paper's rate 1."""
        nu_ref = self.odd_reference_viscosity(two_phase)
        return self.odd_lambda > 0 and nu_ref < min(2.0 * self.odd_lambda / 3.0, self.odd_nu_max)


PHASE_TRT_LAMBDA_INFLOW = 1.0 / 6.0
"""Λ_h of the phase field's two-relaxation-time collision in a fluid with an inflow (``FluidParams.phase_trt_lambda``
= None): a measured choice, not an optimum. On the outlet jets of
tests/fluid/test_inflow_region.py (12 × 12 × 24, 800:1, M = 0.02; session 13's map, 1000-1500 steps, Λ = 0.1
against 1/6):

* ν = 0.01: with 0.1 a 5-cell outlet at ξ = 3, u = 0.08 diverged (step 100), with 1/6 it runs; every outlet of
  3-8 cells at ξ ≥ 3 runs to 0.08 with either;
* the scenes' ν_h = 1e-4, ν_l = 0.01 with their closures (odd-rate floor, Smagorinsky): with 0.1 outlets of 3-6
  cells at ξ = 3 and of 3 cells at ξ = 4 diverged at 0.08 (steps 100-150), with 1/6 every outlet at ξ ≥ 4 runs
  to 0.08, 2-cell ones included;
* Fig. 1's ν_h = 5e-4, ν_l = 0.1: with 0.1 outlets of 4-8 cells at ξ = 3 and 4-5 cells at ξ = 4 diverged at 0.08;
  with 1/6 every outlet of ≥ 3 cells at ξ ≥ 4 runs to 0.08.

What is left is limited by scene validation (couplekit.scene.model.water_outlet_speed_limit). Λ = 1/4 gave
nearly the same map (session 13). Before session 12, examples/fig04_colander_small.toml diverged with 1/8 and
1/6 at its ceiling outlet (steps 640, 730: φ = −0.03 in the ceiling's first layer), which led to 0.1; since
session 12's three-point wall rule of the pressure filter (which removed a period-2 pressure mode in that
ceiling layer, docs/fluid-stability.md) it runs with 1/6 too: 20 frames (max lattice speed 0.098, volume drift +2.4e-4), and the other scenes with
inflows (Figs. 1, 2, 5, 9) run as with 0.1. Larger values make drops at ξ = 2 diverge sooner (a drop through
still air at u = 0.02: step 160 with 1/4, 520 with 1/6; the single rate ran it 600 steps); scenes refuse water
outlets at ξ < 2.5 and caution a moving interface there (tests/fluid/test_narrow_interface.py)."""


class OddFloorInactiveWarning(UserWarning):
    """``FluidParams.odd_lambda`` > 0 was given with a viscosity at which the floor does nothing."""


class SharpInterfaceWarning(UserWarning):
    """The initial φ of a high-density-ratio fluid jumps by more than a resolved interface allows."""


SHARP_JUMP = 0.75
"""Largest jump of the initial φ between face neighbours that :class:`FluidSolver` takes without a
:class:`SharpInterfaceWarning` at a density ratio above :data:`SHARP_RATIO`. The equilibrium profile
(``phasefield_layout.tanh_profile``) jumps by at most tanh(1/ξ) between neighbours (0.46 at ξ = 2, 0.24 at
ξ = 4). Measured (12 × 10 × 9 closed box, water below air at rest, ν = 0.01, σ = 1e-4, 200 steps): a one-cell
step (jump 1) runs at 100:1 and goes non-finite at 200:1 and 800:1 within 3 steps (the air cell next to the step
reached 0.23 lattice speed after one step at 800:1); a 2-cell linear ramp (jump 0.5) runs at 800:1."""

SHARP_RATIO = 100.0
"""Density ratio ρ_h/ρ_l above which :data:`SHARP_JUMP` is checked."""


def _max_phi_jump(phi: np.ndarray, fluid: np.ndarray, periodic: tuple[bool, bool, bool] = (False,) * 3) -> float:
    """Largest |φ(x) − φ(x + e_a)| over face-neighbouring interior cells that are both fluid (``fluid``: interior
    boolean mask), along the three axes; across the wrap too on the ``periodic`` (x, y, z) axes, where the last
    layer's neighbour is the first."""
    jump = 0.0
    for axis in range(3):
        wrap = periodic[2 - axis]  # arrays are (z, y, x)
        nxt_phi = np.roll(phi, -1, axis=axis) if wrap else np.delete(phi, 0, axis=axis)
        nxt_fluid = np.roll(fluid, -1, axis=axis) if wrap else np.delete(fluid, 0, axis=axis)
        here_phi = phi if wrap else np.delete(phi, -1, axis=axis)
        here_fluid = fluid if wrap else np.delete(fluid, -1, axis=axis)
        both = here_fluid & nxt_fluid
        if both.any():
            jump = max(jump, float(np.abs(nxt_phi - here_phi)[both].max()))
    return jump


def _check_initial(name: str, a: np.ndarray) -> None:
    """A ValueError naming ``name`` and the first cell where the initial field ``a`` is NaN or infinite."""
    bad = ~np.isfinite(a)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{name} is not finite at index {where} ({a[where]}): give finite initial values")


class FluidSolver:
    """Velocity-based D3Q27 NOCM-MRT flow, optionally with the D3Q7 conservative phase field.

    Parameters
    ----------
    backend: a :class:`~couplekit.backend.Backend` or a backend name (``"auto"``, ``"cuda"``, ``"cpu"``,
        ``"numpy"``; :func:`couplekit.backend.get_backend`); numpy runs the reference ops.
    shape: interior grid ``(nz, ny, nx)``.
    params: :class:`FluidParams` in lattice units (``FluidParams.scene_defaults()`` for a scene's fluid;
        ``FluidParams()`` differs: see its docstring). ``odd_floor_active``: whether its odd-rate floor acts.
    boundaries: the six faces (:class:`~couplekit.fluid.grid.Boundaries`); default ``None`` = **all periodic**
        (a scene's faces default to walls: ``Boundaries.scene_defaults()``).
    solid: interior boolean mask of stationary obstacle cells (e.g. ``sdf < 0`` of a signed distance field;
        numbers other than 0 and 1, such as the distances themselves, are refused).
    phi: initial phase field ``(nz, ny, nx)`` (1 = heavy); ``None`` makes a single-phase solver.
    velocity: initial velocity ``(3, nz, ny, nx)`` (x, y, z components), default rest.
    pressure: initial pressure ``(nz, ny, nx)`` (e.g. hydrostatic), default 0.
    mixture: allocate the ``fluid_fraction`` (ε, ones) and ``sand_velocity`` (zeros) inputs.
    sand_velocity: with ``mixture``, allocate ``sand_velocity`` (default). ``False`` for a coupling that folds
        Eq. 39's sand terms into the pressure update's kept population sum instead
        (:meth:`fold_sand_pressure_terms`; the lockstep scheduler does), 12 B per cell less;
        :meth:`keep_sand_velocity` allocates it later.
    external_force: allocate the ``force`` input (force density, e.g. drag; zeros).
    force_in_velocity: with ``external_force``, keep the force in the ``velocity`` buffer (:meth:`share_force_buffer`;
        the lockstep scheduler does), 12 B per cell less.
    source_term: allocate the phase field's source ``source_term`` (S_φ, zeros; two-phase only); default
        ``None`` = with ``mixture`` (the coupling writes it). Without it the phase-field kernels are built with
        ``CK_PF_SOURCE=0`` (S_φ compiled out) and ``source_term`` is ``None``.
    storage: ``"fp32"`` (default) or ``"fp16"``: the precision the populations f and h are stored in (the
        arithmetic stays float32 in the kernels, float64 in the reference). fp16 halves their memory (and the
        traffic of the streaming) at a cost in accuracy (docs/precision.md, "fp16 storage");
        :attr:`f` and :attr:`h` are then float16 arrays of scaled values (:mod:`couplekit.fluid.storage`;
        :func:`couplekit.fluid.from_stored` decodes f).

    Inputs the coupling fills (padded backend arrays, present only when enabled): ``fluid_fraction``,
    ``sand_velocity``, ``force``, and ``source_term`` (S_φ of the phase field, two-phase only).
    """

    def __init__(
        self,
        backend: Backend | str | None,
        shape: tuple[int, int, int],
        params: FluidParams,
        boundaries: Boundaries | None = None,
        solid: np.ndarray | None = None,
        phi: np.ndarray | None = None,
        velocity: np.ndarray | None = None,
        pressure: np.ndarray | None = None,
        mixture: bool = False,
        external_force: bool = False,
        source_term: bool | None = None,
        storage: str = "fp32",
        sand_velocity: bool = True,
        force_in_velocity: bool = False,
    ):
        self.backend = backend = backend if isinstance(backend, Backend) else get_backend(backend)
        self.storage = check_storage(storage, "FluidSolver storage")
        if isinstance(shape, (str, bytes)) or not hasattr(shape, "__len__") or len(shape) != 3:
            raise ValueError(f"shape must be (nz, ny, nx) with every extent >= 2, got {shape!r}")
        # whole numbers of cells: (6.0, 7, 8) or a NaN once became int() silently (a probe, session 25)
        self.shape = tuple(whole_count(f"shape[{i}]", s, least=2, what="cells") for i, s in enumerate(shape))
        if not isinstance(params, FluidParams):
            raise TypeError(
                f"params must be a FluidParams, got {type(params).__name__}: build one, e.g. FluidParams(nu_h=0.1) "
                "or FluidParams.scene_defaults(...), from the values"
            )
        if boundaries is not None and not isinstance(boundaries, Boundaries):
            raise TypeError(
                f"boundaries must be a Boundaries or None (all periodic), got {type(boundaries).__name__}: build one, "
                "e.g. Boundaries.channel('xyz') or Boundaries.scene_defaults()"
            )
        solid = _checked_solid(solid, self.shape)
        self.params = params
        # the odd-rate floor acts only where nu < 2 Λ / 3 (see reference.odd_rate); 0 when no cell can reach it,
        # so the kernel keeps its rate-1 fast path
        self.odd_floor_active = params.odd_floor_acts(two_phase=phi is not None)
        self._odd_lambda = params.odd_lambda if self.odd_floor_active else 0.0
        if params.odd_lambda > 0 and not self.odd_floor_active:
            nu_ref = params.odd_reference_viscosity(two_phase=phi is not None)
            warnings.warn(
                OddFloorInactiveWarning(
                    f"FluidParams.odd_lambda = {params.odd_lambda:g} does nothing here: the fluid's lowest viscosity "
                    f"{nu_ref:g} is not below min(2 odd_lambda / 3, odd_nu_max = {params.odd_nu_max:g}) = "
                    f"{min(2 * params.odd_lambda / 3, params.odd_nu_max):g}, so the odd moments relax at the "
                    "paper's rate 1. Set odd_lambda = 0 to say so, or lower the viscosity"
                ),
                stacklevel=2,
            )
        self.boundaries = boundaries or Boundaries()
        self.two_phase = phi is not None
        self.surface_tension = self.two_phase and params.sigma > 0
        self.mixture = bool(mixture)
        self.external_force = bool(external_force)
        xp = backend.xp
        self.xp = xp
        effects = dict(
            two_phase=self.two_phase,
            surface_tension=self.surface_tension,
            mixture=self.mixture,
            external_force=self.external_force,
            les=params.smagorinsky > 0,
            odd_rate=self._odd_lambda > 0,
            storage=self.storage,
            # the ramp only where the floor acts (without it the odd moments relax at 1 everywhere anyway)
            odd_ramp=self._odd_lambda > 0 and params.odd_ramp > 0,
        )
        self.ops = KernelOps(backend, **effects) if backend.has_kernels else ReferenceOps(**effects)
        pshape = padded_shape(self.shape)

        flags, wall_u, wall_phi = build_flags(self.shape, self.boundaries, solid)
        fluid_host = flags[INTERIOR] == FLUID
        self.phase_trt_lambda = params.phase_lambda_for(bool((flags == INFLOW).any()))
        ghost, image = periodic_lists(self.shape, self.boundaries)
        out_ghost, out_src = outflow_lists(self.shape, flags)
        self.flags = backend.asarray(flags)
        periodic_axes = self.boundaries.periodic_axes
        # the weights of rate 1 of the ramped odd-rate floor (FluidParams.odd_ramp), refused in narrow gaps
        self.odd_ramp = None
        if self.ops.odd_ramp:
            check_gaps(flags, periodic_axes, params.odd_ramp)
            self.odd_ramp = backend.asarray(ramp_weights(flags, periodic_axes, params.odd_ramp))
        self._ghost, self._image = backend.asarray(ghost), backend.asarray(image)
        # the periodic ghosts' links of the odd step (halo_pull, fold)
        self._link_boxes = link_box_arrays(periodic_link_boxes(self.shape, self.boundaries)).on(backend)
        self._out_ghost, self._out_src = backend.asarray(out_ghost), backend.asarray(out_src)
        # the axes on which each outflow ghost takes backflow out (ReferenceOps.outflow_fill)
        self._out_dir = backend.asarray(outflow_directions(self.shape, out_ghost, periodic_axes))
        self._out_du = xp.zeros((3, out_ghost.size), dtype=np.float32)  # fill -> fix of an odd step (12 B per ghost)

        u0 = np.zeros((3,) + self.shape) if velocity is None else np.asarray(velocity, np.float64)
        if u0.shape != (3,) + self.shape:
            raise ValueError(f"velocity must have shape {(3,) + self.shape}, got {u0.shape}")
        _check_initial("velocity", u0)
        speed = float(np.sqrt((u0**2).sum(axis=0)).max()) if u0.size else 0.0
        if speed >= math.sqrt(CS2):  # a probe: 1000 lattice units was taken and went NaN in one step
            raise ValueError(
                f"velocity reaches {speed:.3g} lattice units (Δx/Δt), at or above the lattice speed of sound "
                f"{math.sqrt(CS2):.3f}: the LBM cannot carry it (keep it below ~0.1); give the velocity in lattice "
                "units, or use a finer Δt"
            )
        u0 = np.where(fluid_host[None], u0, 0.0)
        vel = wall_u.astype(np.float32)
        vel[(slice(None), *INTERIOR)] = np.where(fluid_host[None], u0, vel[(slice(None), *INTERIOR)])
        # stored as f - w (shifted storage, reference.py); 0 in the ghost / wall cells, which are written before
        # they are read
        f = np.zeros((27,) + pshape, dtype_of(self.storage))
        # parity 0: natural order.  By slabs of z: the float64 equilibrium of the whole grid took 216 B per cell
        # and its conversion 108 more at once (1.3 GB above the solver's own 325 MB at 1.8 M cells)
        for z0, z1 in host_slabs(self.shape, 27 * 8 * 3):
            f[:, 1 + z0 : 1 + z1, 1:-1, 1:-1] = to_stored(equilibrium(u0[:, z0:z1]), self.storage)
        self.f = backend.asarray(f)
        self.velocity = backend.asarray(vel)
        p0 = np.zeros(pshape, np.float32)
        if pressure is not None:
            p_host = np.asarray(pressure, np.float32)
            if p_host.shape != self.shape:
                raise ValueError(f"pressure must have the interior shape {self.shape}, got {p_host.shape}")
            _check_initial("pressure", p_host)
            p0[INTERIOR] = p_host
        self.p = backend.asarray(p0)
        self.pbar = xp.zeros(pshape, dtype=np.float32)

        self.fluid_fraction = xp.ones(pshape, dtype=np.float32) if self.mixture else None
        self.sand_velocity = None
        if sand_velocity:
            self.keep_sand_velocity()  # with mixture only
        # the cells where Eq. 39 keeps its porosity-slip term: not in the layers next to a wall, 3 with the
        # odd-rate floor, 1 with the paper's collision (grid.slip_wall_layers)
        self._slip_cells = None
        if self.mixture:
            layers = slip_wall_layers(self.odd_floor_active)
            self._slip_cells = backend.asarray(slip_cells(flags, periodic_axes, layers))
        self.force = None
        if self.external_force:
            self.force = self.velocity if force_in_velocity else xp.zeros((3,) + pshape, dtype=np.float32)
        self._force_step = None  # the step whose force the coupling wrote into the velocity's buffer (shared)
        self._slip_step = None  # the step whose slip part take_slip_fluid_part left in p̄
        # the walls whose flat layers take the pressure filter's three-point rule: those normal to gravity
        self._wall_rule_axes = wall_rule_axes(self.params.gravity)

        self.step_count = 0
        self._fsum_step = None  # the step whose Σ (f − w) current_velocity(keep_fsum=True) left in p̄
        self._fsum_sand = False  # that sum also holds minus Eq. 39's sand terms (fold_sand_pressure_terms)
        self.gamma = 1.0
        # water held outside the phase field that V of Eq. 52 counts (the sand's bound water, Eq. 53; set by
        # the coupler every step, 0 otherwise)
        self.held_volume = 0.0
        self.phi = self.h = self.source_term = None
        if self.two_phase:
            from . import phasefield as pf  # only two-phase scenes need (and load) the phase field

            self._pf = pf
            has_source = bool(mixture if source_term is None else source_term)
            self.pf_ops = pf.make_phase_field_ops(
                backend, periodic_axes, self.surface_tension, has_source, self.storage
            )
            self.beta, self.kappa = pf.chemical_potential_coefficients(params.sigma, params.width)
            phi0 = np.asarray(phi, np.float32)
            if phi0.shape != self.shape:
                raise ValueError(f"phi must have the interior shape {self.shape}, got {phi0.shape}")
            _check_initial("phi", phi0)
            self._check_interface(phi0, fluid_host)
            phi_p = wall_phi.astype(np.float32)  # inflow cells carry their phase value
            phi_p[INTERIOR] = phi0
            self.phi = backend.asarray(phi_p)
            self.h = xp.zeros((7,) + pshape, dtype=dtype_of(self.storage))
            self.source_term = xp.zeros(pshape, dtype=np.float32) if has_source else None
            self._setup_inflow_front(flags, wall_u, wall_phi, phi_p)
            self.pf_ops.set_equilibrium(self.h, self.phi, self.velocity, self.flags, 0)
            self._phase_macroscopic()
        self.volume0 = self._volume()
        self._setup_open_faces(flags)

    def _check_interface(self, phi0: np.ndarray, fluid: np.ndarray) -> None:
        """Warn (:class:`SharpInterfaceWarning`) when the initial φ is sharper than a resolved interface at a
        density ratio where that diverges (:data:`SHARP_JUMP`, :data:`SHARP_RATIO`); scenes build the equilibrium
        profile themselves. ``fluid``: the interior FLUID cells (host bool array)."""
        ratio = self.params.rho_h / self.params.rho_l if self.params.rho_l > 0 else math.inf
        if ratio <= SHARP_RATIO:
            return
        periodic = self.boundaries.periodic_axes
        jump = _max_phi_jump(np.clip(phi0.astype(np.float64), 0.0, 1.0), fluid, periodic)
        if jump > SHARP_JUMP:
            warnings.warn(
                SharpInterfaceWarning(
                    f"the initial phi jumps by {jump:.2f} between neighbouring cells at density ratio {ratio:.0f}:1: "
                    f"an interface that sharp goes non-finite within a few steps above {SHARP_RATIO:.0f}:1 (a "
                    "resolved one jumps by at most tanh(1/width) between neighbours). Give phi the equilibrium "
                    "profile (1 + tanh(2 s / width)) / 2 of the signed distance s into the water "
                    "(couplekit.fluid.phasefield_layout.tanh_profile), as scenes do"
                ),
                stacklevel=3,
            )

    # ------------------------------------------------------------------------------------------ stepping
    def _setup_open_faces(self, flags) -> None:
        """Whether water can enter or leave the box (an inflow or outflow face): then the volume controller's
        target follows what the faces let in and out (:meth:`_open_face_step`)."""
        self._closed_box = not bool(np.isin(flags, (INFLOW, OUTFLOW)).any())
        self._phi_sum = None  # Σφ after the last step (_open_face_step); None: not known, summed before the next

    def _open_face_step(self, source_scale: float) -> None:
        """Move the controller's target V0 (Eq. 52, and ``fluid_volume_drift``'s reference) by the water the open
        faces let in minus what they let out in the phase-field step just taken, measured, not estimated: the
        phase field's transport conserves Σ_k h_k cell by cell except through inflow and outflow links, and
        its source adds γ S_φ per cell (Eq. 51: Σ_k S_k = γ S_φ), so that flux is
        Σφ(after) − Σφ(before) − γ Σ S_φ over the interior fluid cells (φ unweighted by ε: the transport's
        own sum; the faces' fluid fraction is 1 where no sand reaches them).

            Why not an estimate from the face cells (Σ φ_b u_b·n_in at inflow ghosts, Σ φ min(u·n_in, 0)
            behind outflow ghosts, until session 29): an outflow link carries the phase field's Allen–Cahn
            sharpening and diffusive fluxes too, not only φ u. Under Fig. 2's 12 m/s wind without sand
            (dx = 15 mm) the air at the ceiling holds φ ≈ 0.006 and the estimate counted 4.7 units of water
            leaving per 100 steps while Σφ changed by +0.18 … −0.09: the target fell 7 % below the water in
            0.6 s (``fluid_volume_drift`` +4.6 %), and in a coupled scene the controller would have taken
            that water out through S_φ (tests/fluid/test_open_face_volume.py).

        One reduction per step: Σφ before the step is the last step's Σφ after it (nothing else writes φ: the
        coupling only reads it; :meth:`load_state` forgets it), and Σ S_φ is read with it (the step does not
        change S_φ; the interface correction that does acts only in closed boxes). Measured on Fig. 4 small (cpu,
        2 threads, `benchmarks/compare_commits.py ed97ed7 bfe56f5`): the volume-controller stage 0.24 ms per step
        with two reductions, 0.15 with one, of a 4.5 ms step (0.09-0.12 with the former estimate)."""
        raw_after, raw_source = self.pf_ops.volume_sums(self.phi, self.source_term, self.flags)
        self.volume0 += raw_after - self._phi_sum - source_scale * raw_source
        self._phi_sum = raw_after

    def _setup_inflow_front(
        self, flags: np.ndarray, wall_u: np.ndarray, wall_phi: np.ndarray, phi_p: np.ndarray
    ) -> None:
        """Prepare the inflow front ramp (:func:`~couplekit.fluid.grid.inflow_front_ramp`).

        Why: an inflow cell carrying φ_w next to interior fluid of another phase is a one-cell-sharp jump of
        φ, and at 800:1 of ρ. The water-hammer pressure of the impulsive start, p ≈ ρ(φ) c_s² u_in per step
        in the cell behind the jump, then acts through the collocated gradient −∇p̄/ρ on the light neighbour
        with 1/ρ_l: measured (8×8×32, u_in = 0.02, abrupt start): after step 1 the air cell next to the
        inflow cell moved at 0.22 = 11 u_in, after step 2 at 14, NaN at step 4. So each inflow ghost's phase
        value goes from the phase of the interior cell it faces (at construction) to the face's φ_w along
        the equilibrium interface profile, as if an interface of width ξ were carried in at the inflow's
        normal speed: the front enters resolved, and neighbouring cells never differ by more than the
        resolved profile allows. Where the adjacent fluid is already of phase φ_w nothing changes.
        """
        idx = np.flatnonzero(flags.reshape(-1) == INFLOW)
        inward, near = ghost_faces(idx, flags.shape)
        norm = np.sqrt((inward**2).sum(axis=0))
        u_w = wall_u.reshape(3, -1)[:, idx].astype(np.float64)
        speed = (u_w * inward).sum(axis=0) / np.where(norm > 0, norm, 1.0)
        start = phi_p.reshape(-1)[near].astype(np.float64)
        target = wall_phi.reshape(-1)[idx].astype(np.float64)
        changing = np.abs(target - start) > 1e-6
        self._inflow_front = (idx[changing], start[changing], target[changing], speed[changing])
        self._inflow_front_done = not changing.any()
        self._set_inflow_front()

    def _set_inflow_front(self) -> None:
        """Write the inflow ghosts' phase values of the current step (see :meth:`_setup_inflow_front`)."""
        if self._inflow_front_done:
            return
        idx, start, target, speed = self._inflow_front
        ramp = inflow_front_ramp(speed * (self.step_count + 0.5), self.params.width)
        self.phi.reshape(-1)[self.backend.asarray(idx)] = self.backend.asarray(
            (start + (target - start) * ramp).astype(np.float32)
        )
        self._inflow_front_done = bool((ramp >= 1.0).all())

    def _phase_macroscopic(self) -> None:
        """φ of the current step, ghosts included: grad φ and μ_φ are computed from it inside the two collides."""
        self.pf_ops.macroscopic(self.h, self.phi, self.velocity, self.flags, self.step_count)

    def phase_gradients(self) -> tuple[Any, Any]:
        """(grad φ, μ_φ) of the current φ (Eqs. 21-23) as padded backend arrays (μ_φ None without surface
        tension): a diagnostic computed on demand; the step computes both inside its collides, stores neither.
        The stencils take only FLUID neighbours' values (the phase field's rule, as its collide's grad φ); the
        flow's collide also takes outflow ghosts' values for its μ_φ, so next to an outflow face the two differ."""
        if not self.two_phase:
            raise ValueError("phase_gradients needs a two-phase fluid (FluidParams phases = 2)")
        return self._pf.gradient_fields(self.pf_ops, self.phi, self.flags, self.beta, self.kappa)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` LBM steps; ``n`` a whole number >= 0 (as :meth:`couplekit.simulation.Simulation.step`)."""
        ops, prm = self.ops, self.params
        for _ in range(whole_count("n", n)):
            parity = self.step_count & 1
            # Σ (f − w) of these populations, if current_velocity(keep_fsum=True) left it in p̄ at this step
            fsum = self.pbar if self._fsum_step == self.step_count else None
            sand_in_fsum = fsum is not None and self._fsum_sand
            self._check_coupled_inputs(sand_in_fsum)  # before anything changes: a refused step changes nothing
            self._fsum_step, self._fsum_sand, self._force_step = None, False, None
            if parity:
                ops.halo_pull(self.f, self._ghost, self._image, self._link_boxes)
                ops.outflow_fill(self.f, self._out_ghost, self._out_src, self._out_dir, self._out_du)
            if self.mixture:
                ops.halo_copy(self.fluid_fraction, self._ghost, self._image)
                if self.sand_velocity is not None:
                    ops.halo_copy(self.sand_velocity, self._ghost, self._image)
            ops.macro_pressure(
                self.f, self.flags, self.velocity, self.phi, self.fluid_fraction, self.sand_velocity,
                self._slip_cells, self.p, parity, prm.rho_h, prm.rho_l, fsum=fsum, sand_in_fsum=sand_in_fsum,
            )  # fmt: skip
            ops.halo_copy(self.p, self._ghost, self._image)
            ops.pressure_filter(self.p, self.flags, self.pbar, self._wall_rule_axes)
            if prm.store_filtered_pressure:
                # p^{n+1} := p̄: swap the buffers (non-fluid cells of both hold the same boundary values)
                self.p, self.pbar = self.pbar, self.p
                force_p = self.p
            else:
                force_p = self.pbar
            ops.halo_copy(force_p, self._ghost, self._image)
            ops.collide_stream(
                self.f, self.flags, self.velocity, self.phi, self.fluid_fraction, self.force, force_p,
                parity, prm.rho_h, prm.rho_l, prm.nu_h, prm.nu_l, *prm.gravity, prm.smagorinsky, self._odd_lambda,
                prm.odd_nu_max, chemical_potential=(self.beta, self.kappa) if self.surface_tension else None,
                odd_ramp=self.odd_ramp,
                prefilled=True,  # macro_pressure prefilled this odd step's wall links; nothing since wrote f or u
            )  # fmt: skip
            if parity:
                ops.fold(self.f, self._ghost, self._image, self._link_boxes)
                ops.outflow_fix(self.f, self._out_ghost, self._out_src, self._out_du)
            if self.two_phase:
                self._set_inflow_front()
                if not self._closed_box and self._phi_sum is None:  # the water the faces pass: _open_face_step
                    self._phi_sum = self.pf_ops.volume_sums(self.phi, self.source_term, self.flags)[0]
                if prm.eta > 0 and self.source_term is not None:
                    volume, source_sum = self._controller_sums()
                    self.gamma = self._pf.volume_controller_gamma(self.volume0, volume, source_sum, prm.eta)
                    source_scale = self._interface_correction(volume, source_sum)
                else:
                    if prm.eta > 0:  # S_φ compiled out: Eq. 52's γ with Σ S = 0, without summing the volume
                        self.gamma = 0.0
                    source_scale = self.gamma
                self.pf_ops.collide_stream(
                    self.h, self.phi, self.velocity, self.source_term, self.flags, self.step_count,
                    prm.mobility, prm.width, source_scale, self.phase_trt_lambda,
                )  # fmt: skip
            self.step_count += 1
            if self.two_phase:
                self._phase_macroscopic()
                if not self._closed_box:
                    self._open_face_step(source_scale)

    def _check_coupled_inputs(self, sand_in_fsum: bool) -> None:
        """Refuse a step whose coupling inputs were not written at this step: Eq. 39's sand terms of a fluid that
        keeps no sand velocity, the force of a fluid that keeps it in the velocity's buffer."""
        if self.mixture and self.sand_velocity is None and not sand_in_fsum:
            raise RuntimeError(
                "this fluid keeps no sand velocity (FluidSolver(sand_velocity=False)) and Eq. 39's sand "
                "terms were not folded into this step's pressure update: call "
                "SandFluidCoupler.sand_velocity() after the fluid_velocity() of the same step, or build "
                "the fluid with sand_velocity=True (keep_sand_velocity())"
            )
        if self.force_shares_velocity and not self.force_was_written:
            raise RuntimeError(
                "this fluid keeps its force in the velocity's buffer (share_force_buffer) and no force was "
                "written into it at this step: call SandFluidCoupler.exchange() after fluid_velocity() in "
                "the same step (the lockstep scheduler's order), or share_force_buffer(False)"
            )

    def current_velocity(self, out: Any = None, keep_fsum: bool = False) -> Any:
        """Σ_j f_j c_j of the current populations (before the next collision, no force shift) as a padded
        backend array (3, Pz, Py, Px), interior fluid cells set: the velocity the sand–fluid exchange must
        see. ``out`` may be a preallocated array of that shape. Prepares the ghosts the way the next step
        does (idempotent), so it can be called between steps at no cost to the state.

        ``keep_fsum``: also keep Σ_j (f_j − w_j) of the same populations, in p̄'s fluid cells (p̄ is a scratch
        array between steps: the step writes it before it reads it), for the next :meth:`step`'s pressure
        update, which then reads that instead of the 27 populations again: one pass over f less per coupled
        step, bitwise the same result (the kernels sum in the same order; the reference in float64). The value
        is used only by the step at this ``step_count`` and dropped by it (and by :meth:`load_state`); nothing
        may change :attr:`f` in between (the coupling stages do not)."""
        if out is None:
            out = self.xp.zeros_like(self.velocity)
        parity = self.step_count & 1
        if parity:
            self.ops.halo_pull(self.f, self._ghost, self._image, self._link_boxes)
            self.ops.outflow_fill(self.f, self._out_ghost, self._out_src, self._out_dir, self._out_du)
        fsum = self.pbar if keep_fsum else None
        held = keep_fsum and self._slip_step == self.step_count
        self.ops.momentum(self.f, self.flags, self.velocity, out, parity, fsum=fsum, held=held)
        self._fsum_step = self.step_count if keep_fsum else None
        self._fsum_sand = False
        self._slip_step = None
        return out

    def take_slip_fluid_part(self, take: Callable[[Any], None]) -> None:
        """Have ``take(pbar)`` write the fluid velocity's part of Eq. 39's slip term (φ u·∇ε / ε from this
        :attr:`velocity`, the last collision's) into p̄'s fluid cells, for the :meth:`current_velocity`
        (``keep_fsum=True``) of the same step to subtract from the population sum it keeps: the coupling takes it
        while u is still stored, when the velocity's buffer is about to hold Σ f c and the force
        (:meth:`share_force_buffer`; kernels/coupling_pressure.cu).  :meth:`fold_sand_pressure_terms` then
        subtracts the rest of the sand's terms.  Refused once the sum was kept at this step: the velocity's buffer
        may hold Σ f c by then, not u (a second exchange-velocity pass read it as u, silently)."""
        if self._fsum_step == self.step_count:
            raise RuntimeError(
                "the exchange velocity was already computed at this step: its buffer now holds Σ f c (or the "
                "force), not the last collision's u that Eq. 39's slip term reads; fluid_velocity() ran already at "
                "this step, call it once per step"
            )
        take(self.pbar)
        self._slip_step = self.step_count

    @property
    def force_shares_velocity(self) -> bool:
        """Whether the ``force`` input is the ``velocity`` buffer (:meth:`share_force_buffer`)."""
        return self.force is not None and self.force is self.velocity

    def share_force_buffer(self, share: bool) -> None:
        """Keep the ``force`` input in the ``velocity`` buffer (``share``), 12 B per padded cell less, or give it
        one of its own (zeros).  For a coupling step in which nothing reads the velocity of the last collision
        once the exchange velocity Σ f c has been written over it (:meth:`current_velocity` with ``out=velocity``),
        and the force is written over that (each cell reading its own Σ f c first) before this step's collision
        reads it cell by cell and writes u there: the lockstep step (SandFluidCoupler.fold_sand_velocity).  Wall
        and ghost cells keep the walls' velocities (neither writes them).  A step of a sharing fluid whose force
        was not written at this step (:meth:`force_written`) is refused.  No-op without a force input."""
        if self.force is None or share == self.force_shares_velocity:
            return
        self.force = self.velocity if share else self.xp.zeros_like(self.velocity)
        self._force_step = None

    def force_written(self) -> None:
        """Record that the coupling wrote this step's force (into the velocity's buffer, when shared)."""
        self._force_step = self.step_count

    @property
    def force_was_written(self) -> bool:
        """Whether the coupling wrote a force at this step (:meth:`force_written`) that no step has used yet."""
        return self._force_step == self.step_count

    @property
    def slip_cells(self) -> Any:
        """The padded uint8 mask of the cells where Eq. 39 keeps its slip term (None without ``mixture``;
        :func:`couplekit.fluid.grid.slip_cells`)."""
        return self._slip_cells

    def keep_sand_velocity(self) -> None:
        """Allocate the ``sand_velocity`` input (zeros) if this mixture fluid was built without it."""
        if self.mixture and self.sand_velocity is None:
            self.sand_velocity = self.xp.zeros((3,) + padded_shape(self.shape), dtype=np.float32)

    def release_sand_velocity(self) -> None:
        """Drop the ``sand_velocity`` input: every step's pressure update then needs its sand terms folded in
        (:meth:`fold_sand_pressure_terms`)."""
        self.sand_velocity = None

    def fold_sand_pressure_terms(self, fold: Callable[[Any], None]) -> None:
        """Have ``fold(fsum)`` subtract Eq. 39's sand terms from the Σ (f − w) that :meth:`current_velocity`
        (``keep_fsum=True``) kept at this step, in place (the coupling computes them from the MPM grid velocity:
        kernels/coupling_pressure.cu), so that this step's pressure update adds none of its own and reads no
        ``sand_velocity``; bitwise the same pressure as with the sand velocity stored.  Once per step."""
        if self._fsum_step != self.step_count:
            raise RuntimeError(
                "no population sum kept at this step to fold the sand's pressure terms into: call "
                "current_velocity(keep_fsum=True) first in the same step (SandFluidCoupler.fluid_velocity)"
            )
        if self._fsum_sand:
            raise RuntimeError("the sand's pressure terms are already folded into this step's population sum")
        fold(self.pbar)
        self._fsum_sand = True

    # ------------------------------------------------------------------------------------------ outputs
    @property
    def _fluid_host(self) -> np.ndarray:
        """The interior FLUID cells (host bool array, nz × ny × nx), read from the flags when asked: not kept
        (1 B per cell; it is wanted only by outputs and diagnostics, once a frame)."""
        return self._host_interior(self.flags) == FLUID

    def _host_interior(self, a) -> np.ndarray:
        return np.asarray(self.backend.to_host(a)[(Ellipsis, *INTERIOR)])

    def _volume(self) -> float:
        """The fluid volume V of Eq. 52: Σφ, or with a mixture Σ ε φ (water in the pores) + ``held_volume``."""
        if self.two_phase:
            eps = self.fluid_fraction if self.mixture else None
            return self.pf_ops.volume_sums(self.phi, self.source_term, self.flags, eps)[0] + self.held_volume
        return float(self._fluid_host.sum())

    def _controller_sums(self) -> tuple[float, float]:
        """(V, Σ ε S_φ) for the volume controller (Eq. 52).

        A mixture's water volume is Σ ε φ (φ is the water fraction of the pores), and one phase-field step
        with source γ S changes it by γ Σ ε S (φ' = φ + γ S cell by cell).  So both sums are ε-weighted:
        then γ = (V0 − V)/Σ ε S is 1 when the source term already does its job (the S_φ of Eq. 45 carries
        Σ ε φ from one step to the next) and corrects only the transport and rounding error.  With the
        plain sums (Σφ, ΣS) the controller fights the source: the mixture's Σφ must change as sand enters
        the water, so γ drives S towards 0 (measured: the drift returned to the no-source −2.5 % at η = 2).
        Σ ε S is the first sum of ``volume_sums`` with S in place of φ.  Called only with an S_φ: without one
        (a fluid alone, or the source term's ablation) γ is 0 and nothing is summed (:meth:`step`).
        """
        if not self.mixture:
            return self.pf_ops.volume_sums(self.phi, self.source_term, self.flags)
        eps = self.fluid_fraction
        volume, weighted_source = self.pf_ops.mixture_sums(self.phi, eps, self.source_term, self.flags)
        return volume + self.held_volume, weighted_source

    INTERFACE_CORRECTION_MAX = 0.01
    """Largest β of :meth:`_interface_correction`: at most 0.25 β = 0.0025 of φ per step at the interface's
    middle (φ = ½), so a large residual (a restart onto another V0, a burst at an open face) is taken up over
    many steps instead of moving the interface in one."""

    def _interface_correction(self, volume: float, source_sum: float) -> float:
        """What the controller's γ S (Eq. 52) cannot supply, added at the interface; returns the source scale.

        In a mixture the phase field's transport (its advection and Allen–Cahn flux) conserves Σ φ, not the
        water Σ ε̃ φ, wherever it crosses a porosity gradient, and Eq. 45's advective part only cancels that to
        the order of the discretisation.  The controller can only scale S_φ, which is near zero once the sand
        is still: then γ sits at its bound ±η and the water drifts (Fig. 17's wet block: +4.9 % in 0.37 s after
        its container went, with the controller at −2; docs/examples.md).  So the residual
        r = V0 − V − γ Σ ε̃ S is put back by a Lagrange-multiplier term localised at the interface,
        S ← γ S + β φ(1 − φ) with β = r / Σ ε̃ φ(1 − φ) (φ clamped to [0, 1]; the conservative Allen–Cahn model
        with a volume multiplier, Brassel & Bretin 2011, Kim et al. 2014), |β| ≤ INTERFACE_CORRECTION_MAX.
        It acts only in coupled two-phase fluids (a mixture with S_φ) in a closed box, and only where γ cannot
        close the gap: with |γ| < η the step is the plain Eq. 52 step, bit for bit.  Not with inflow or outflow
        faces: there V0 followed the water let in and out by an estimate until session 29, and the term turned
        that estimate's error into a sink (measured: Fig. 4's and Fig. 9's jets lost their water downstream,
        tests/test_paper_scenes.py); V0 now follows the measured flux (:meth:`_open_face_step`), with which the
        term has not been tried at open faces."""
        if not self.mixture or self.source_term is None:
            return self.gamma
        if not self._closed_box:
            return self.gamma
        if source_sum != 0.0 and abs(self.gamma) < self.params.eta:  # γ closes the gap itself
            return self.gamma
        residual = self.volume0 - volume - self.gamma * source_sum
        if residual == 0.0:
            return self.gamma
        xp = self.xp
        inner = (slice(1, -1),) * 3
        phi = xp.clip(self.phi[inner], 0.0, 1.0)
        shape = phi * (1.0 - phi) * (self.flags[inner] == FLUID)
        weight = float((shape * self.fluid_fraction[inner]).sum(dtype=np.float64))
        if weight <= 0.0:
            return self.gamma
        beta = float(np.clip(residual / weight, -self.INTERFACE_CORRECTION_MAX, self.INTERFACE_CORRECTION_MAX))
        src = self.source_term[inner]
        src[...] = (self.gamma * src + beta * shape).astype(np.float32)
        return 1.0

    def reset_volume_reference(self, volume: float | None = None) -> None:
        """Set V0 of Eq. 52 (and of ``fluid_volume_drift``) to ``volume``, or to the current :meth:`_volume`.

        The coupler calls it on its first step, once the fluid fraction ε is known (at construction ε ≡ 1)."""
        self.volume0 = float(self._volume() if volume is None else volume)

    def density(self) -> np.ndarray:
        """ρ(φ) of Eq. 4 on the interior (host float32); ρ_h everywhere for a single-phase solver."""
        if not self.two_phase:
            return np.full(self.shape, self.params.rho_h, np.float32)
        ph = np.clip(self._host_interior(self.phi), 0.0, 1.0)
        return (self.params.rho_l + (self.params.rho_h - self.params.rho_l) * ph).astype(np.float32)

    def fields(self) -> dict[str, np.ndarray]:
        """Host copies of the interior fields: velocity (3, nz, ny, nx), pressure, density, solid, and phi
        (two-phase only). Velocity includes the half-force shift (Eq. 13 with Guo forcing); pressure is the
        stored p of Eqs. 39-40."""
        fluid = self._fluid_host
        out = {
            # 0 outside the fluid (where, not a product: a lockstep drag writes −0 into obstacle cells' u buffer)
            "velocity": np.where(fluid[None], self._host_interior(self.velocity), np.float32(0.0)),
            "pressure": self._host_interior(self.p),
            "density": self.density(),
            "solid": ~fluid,
        }
        if self.two_phase:
            out["phi"] = self._host_interior(self.phi)
        return out

    def diagnostics(self) -> dict[str, float]:
        """Float64 global quantities: fluid_volume (Σφ; Σ ε φ + held_volume with a mixture; the fluid cell
        count single-phase),
        fluid_volume_drift (relative to the target V0: the start, moved by what open faces let in and out,
        :meth:`_open_face_step`), max_lattice_speed, momentum_x/y/z (Σ ρu) and
        kinetic_energy (½ Σ ρ|u|²) over fluid cells, step; two-phase also max_lattice_speed_water and
        max_lattice_speed_air, the fastest cell with φ ≥ ½ and with φ < ½ (0 where there is none): at 800:1 the
        fastest cell is often air beside the water, whose interface tail Eq. 4 makes heavy (docs/fluid-stability.md,
        'The air beside water'), so the water's own speed is reported apart."""
        fluid = self._fluid_host
        u = self._host_interior(self.velocity).astype(np.float64) * fluid[None]
        rho = self.density().astype(np.float64) * fluid
        volume = self._volume()
        mom = np.einsum("dzyx,zyx->d", u, rho)
        speed = np.sqrt((u * u).sum(axis=0))
        out = {
            "step": float(self.step_count),
            "fluid_volume": volume,
            "fluid_volume_drift": (volume - self.volume0) / self.volume0 if self.volume0 else 0.0,
            "max_lattice_speed": float(speed.max()),
            "momentum_x": float(mom[0]),
            "momentum_y": float(mom[1]),
            "momentum_z": float(mom[2]),
            "kinetic_energy": float(0.5 * np.einsum("dzyx,dzyx,zyx->", u, u, rho)),
        }
        if self.two_phase:
            water = self._host_interior(self.phi) >= 0.5
            for key, cells in (("water", water & fluid), ("air", ~water & fluid)):
                out[f"max_lattice_speed_{key}"] = float(speed[cells].max()) if cells.any() else 0.0
        return out

    # ------------------------------------------------------------------------------------------ restart
    # pbar: its non-fluid cells hold boundary values and it swaps with p every step (stored filter), so it is
    # state; phi: its inflow ghosts carry the (ramped) inflow phase value, which h does not determine
    _STATE_ARRAYS = (
        "f", "velocity", "p", "pbar", "phi", "h", "fluid_fraction", "sand_velocity", "force", "source_term",
    )  # fmt: skip

    def state(self) -> dict[str, np.ndarray]:
        """Everything a bitwise-exact restart needs (host NumPy copies of padded arrays, plus counters).

        ``f`` is the stored form f − w of the populations (shifted storage; :func:`couplekit.fluid.from_stored`
        gives the full f), as :attr:`f` itself is; ``f`` and ``h`` keep their storage dtype (float16 with
        fp16 storage, which is how a checkpoint records the storage)."""
        shared = self.force_shares_velocity  # the force in the velocity's buffer: saved once, as the velocity
        out = {
            k: self.backend.to_host(getattr(self, k))
            for k in self._STATE_ARRAYS
            if getattr(self, k) is not None and not (shared and k == "force")
        }
        out["step_count"] = np.array(self.step_count, np.int64)
        out["gamma"] = np.array(self.gamma, np.float64)
        out["volume0"] = np.array(self.volume0, np.float64)
        out["held_volume"] = np.array(self.held_volume, np.float64)
        return out

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a :meth:`state` of a solver built with the same shape, parameters and effects."""
        shared = self.force_shares_velocity
        for k in self._STATE_ARRAYS:
            mine = getattr(self, k)
            if mine is None or (shared and k == "force"):
                continue  # a shared force is the velocity's buffer (its values: the next step writes them first)
            if k not in state and k in ("pbar", "phi"):
                continue  # checkpoints from before they were saved: rebuilt as well as those could
            if k not in state and k in ("sand_velocity", "force"):
                continue  # a lockstep run keeps neither (fold_sand_pressure_terms, share_force_buffer): written first
            if k not in state:
                raise KeyError(f"state has no {k!r}: it was saved by a solver with other effects")
            arr = np.asarray(state[k])
            if arr.shape != tuple(mine.shape):
                raise ValueError(f"state[{k!r}] has shape {arr.shape}, this solver needs {tuple(mine.shape)}")
            if k in ("f", "h"):
                # the populations restart only into the storage that wrote them: a conversion would not be the
                # exact restart a checkpoint promises (fp32 -> fp16 rounds; fp16 -> fp32 continues a run with
                # other rounding), so it is refused, naming the scene key
                theirs = "fp16" if arr.dtype == np.float16 else "fp32"
                if theirs != self.storage:
                    raise ValueError(
                        f"state[{k!r}] holds {theirs} populations but this fluid stores them as {self.storage}: "
                        f"set fluid.storage = {theirs!r} in the scene to restart it (a checkpoint restarts only "
                        "with the storage that wrote it)"
                    )
                setattr(self, k, self.backend.asarray(arr.astype(dtype_of(self.storage))))
                continue
            setattr(self, k, self.backend.asarray(arr.astype(np.float32)))
        if shared:
            self.force = self.velocity
        self.step_count = int(state["step_count"])
        self._fsum_step, self._fsum_sand = None, False
        self._force_step = self._slip_step = None
        self.gamma = float(state["gamma"])
        self.volume0 = float(state["volume0"])
        self.held_volume = float(state.get("held_volume", 0.0))  # absent from checkpoints before it existed
        self._phi_sum = None  # the open faces' bookkeeping sums φ again before the next step
        if self.two_phase:
            self._inflow_front_done = False  # re-derive from step_count (the ramp is a function of it)
            self._phase_macroscopic()
