"""NumPy reference of the coupling stages: the executable specification the kernels are tested against.

Written for clarity in float64, vectorised, with paper 000's equation numbers; independent of the kernels
(its own B-spline stencil, its own ghost mapping).  Inputs and outputs are the solvers' float32 arrays,
written in place like the kernels.  Layouts:

* fluid fields padded with one ghost layer (``(nz+2, ny+2, nx+2)``, vectors ``(3, nz+2, ny+2, nx+2)``;
  interior cell ``(z, y, x)`` at ``[z+1, y+1, x+1]``), flags ``uint8`` (0 = FLUID) as in
  :mod:`couplekit.fluid.grid`;
* MPM grid arrays unpadded (``(nz, ny, nx)``, ``(3, nz, ny, nx)``), node ``(i, j, k)`` at
  ``((i+½)dx, (j+½)dx, (k+½)dx)`` — the centre of the same LBM cell;
* particles ``x (3, P)``, ``r``, ``vol``, ``saturation`` ``(P,)``.

Units: the sand grid is in SI (kg, kg·m/s, m³, N; couplekit.sand); the fluid in lattice units (dx = dt = 1,
density 1 = the reference density of :class:`couplekit.units.Units`).  The drag converts at the one
interface with ``mass_scale`` = ρ_ref dx³ (kg per lattice mass unit) and ``velocity_scale`` = dx/dt_LBM.

Readings of the extracted paper text chosen here (the PDF extraction garbles accents):

* Eq. 54's effective porosity is written ε̃ = 1 − ε − R (the tilde is lost in the text); Eq. 57 and Eq. 59
  use ε̃; Eq. 55's "ε_i φ_i" is the free water ε̃_i φ_i (the outer min "caps the intake at the currently
  available fluid volume").
* Eq. 55's R_a Δt r_max ε with Δt = 1 lattice step (Table 1 gives R_a "in dimensionless space"), times φ:
  the uptake rate of a node whose pores hold the water fraction φ is φ R_a Δt r_max ε (the paper's rate in
  water, φ = 1).  Why: with the paper's rate the only limit in a partly wet node is the outer min ε̃ φ, so
  every node of the phase field's diffuse tail (φ ~ 1e-4 … 0.1, up to 3 cells deep in a dry plug's
  air-filled pores) loses ALL its water in one step.  Measured on the dry plug under water
  (tests/coupling/test_coupled_validation.py): φ then undershoots below 0 in the air-filled pores (−0.004
  by step 10 at R_a = 0.01, the emptied cells' D3Q7 populations far from equilibrium), the density there
  flips between ρ_l and tail water each step while the pressure still carries the old hydrostatic gradient,
  which in cells of air density accelerates the air by (Δρ/ρ_l) g (2.5 g by step 5, 10³ g by step 50): the
  air jets through the pores, advects the tail deeper and the run is NaN at step ~97 (~1900 at R_a =
  0.001).  Ruled out by the same measurement: the volume controller (η = 0 diverges too), surface tension
  (σ = 0 too), the shrinking ε̃ seen by the fluid (Eqs. 39/16 with ε̃ but no water removed: stable), and
  the D3Q7 spreading of the sink (applied to the rest population only: diverges too).  With the rate ∝ φ
  a node loses at most R_a r_max ε / ε̃ of its water per step (0.34 % at R_a = 0.01), φ stays ≥ 0 and the
  plug runs; the capacity bound (inner min) and the conservation (Eq. 57) are unchanged.
* The drag's (ε_i^n)^(−χ) is the fluid fraction 1 − ε (Eq. 33) — retention only replaces it in Eqs. 39
  and 16; the fluid mass the exchange moves is ρ ε̃ V_cell, the mass the fluid solver accelerates.
* φ is clamped to [0, 1] where it measures water (density, Eq. 55, Eq. 59), not in the source term
  (so that the source conserves Σ ε̃ φ exactly, see :meth:`ReferenceOps.phase_source`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..lattice import C27, W27
from ..units import Units
from .params import CouplingParams

__all__ = ["ReferenceOps", "bspline_stencil", "drag_scales", "source_index"]


def drag_scales(units: Units, dt: float | None = None) -> tuple[float, float, float, float]:
    """(mass_scale kg, velocity_scale m/s, dt s, dt in LBM steps) of the drag's unit conversion."""
    dt = float(units.dt if dt is None else dt)
    return units.rho * units.dx**3, units.dx / units.dt, dt, dt / units.dt


def source_index(n: int, periodic: bool) -> np.ndarray:
    """Interior node (0-based) each padded coordinate 0 … n+1 reads: wrap if periodic, else clamp."""
    padded = np.arange(n + 2) - 1
    return np.mod(padded, n) if periodic else np.clip(padded, 0, n - 1)


def bspline_stencil(x: np.ndarray, dx: float, shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Node linear indices (P, 27) and quadratic B-spline weights N_i(x_p) (P, 27) of particles x (3, P).

    N(s) = ¾ − s² for |s| < ½, ½(3/2 − |s|)² for ½ ≤ |s| < 3/2, s = x/dx − ½ − i (node i at (i + ½) dx).
    A particle whose stencil would leave the grid (or whose position is not finite) gets node 1's stencil and
    zero weights: it reads and writes nothing (kernels/coupling_moisture.cu).
    """
    nz, ny, nx = shape
    X = x.astype(np.float64) / dx - 0.5
    with np.errstate(invalid="ignore"):
        ok = np.all((X >= 0.5) & (X < np.array([nx, ny, nz], np.float64)[:, None] - 1.5), axis=0)
    X = np.where(ok, X, 1.0)
    base = np.floor(X - 0.5).astype(np.int64)  # (3, P)
    offs = np.arange(3)
    nodes = base[:, :, None] + offs  # (3, P, 3)
    s = np.abs(nodes - X[:, :, None])
    w1 = np.where(s < 0.5, 0.75 - s**2, np.where(s < 1.5, 0.5 * (1.5 - s) ** 2, 0.0))
    # 27 = (a, b, c) with a fastest (x)
    a, b, c = np.meshgrid(offs, offs, offs, indexing="ij")
    a, b, c = c.ravel(), b.ravel(), a.ravel()
    index = nodes[0][:, a] + nx * (nodes[1][:, b] + ny * nodes[2][:, c])
    weight = np.where(ok[:, None], w1[0][:, a] * w1[1][:, b] * w1[2][:, c], 0.0)
    return index, weight


def _interior(a: np.ndarray) -> np.ndarray:
    return a[..., 1:-1, 1:-1, 1:-1]


def _isotropic_gradient(s: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Eq. 18 on interior cells: ∇s = Σ_j 3 w_j c_j s(x + c_j), non-FLUID neighbours replaced by the centre."""
    pz, py, px = s.shape
    centre = _interior(s).astype(np.float64)
    grad = np.zeros((3,) + centre.shape)
    for j in range(1, 27):
        cx, cy, cz = (int(v) for v in C27[j])
        sl = (slice(1 + cz, pz - 1 + cz), slice(1 + cy, py - 1 + cy), slice(1 + cx, px - 1 + cx))
        nb = np.where(flags[sl] == 0, s[sl].astype(np.float64), centre)
        for d in range(3):
            grad[d] += 3.0 * W27[j] * C27[j, d] * (nb - centre)
    return grad


def sand_fraction(grid_vol, dx: float, eps_max: float, volume_scale: float = 1.0) -> np.ndarray:
    """ε = min(ε_max, V_i / V_cell) (Eq. 25) of the node volume V_i = ``volume_scale`` × ``grid_vol`` (unpadded;
    float64): the P2G's node volume, or the node mass over the one particle density
    (:attr:`couplekit.sand.SandSolver.node_volume`). The drag and the porosity both take it from there
    (kernels/coupling_fields.cuh)."""
    return np.minimum(eps_max, np.asarray(grid_vol).astype(np.float64) * (volume_scale / dx**3))


def water_fraction(eps_fluid, phi=None, bound=None) -> np.ndarray:
    """The water volume fraction of each MPM node that drives cohesion, R' + ε̃ φ (Eq. 59's summand; ε̃ φ without
    retention, the text after Eq. 28): ``eps_fluid`` and ``phi`` padded (φ clamped to [0, 1]; None: single-phase
    water, φ = 1), ``bound`` R' unpadded (None: no retention).  Unpadded float64."""
    ef = _interior(eps_fluid).astype(np.float64)
    wet = ef if phi is None else ef * np.clip(_interior(phi).astype(np.float64), 0.0, 1.0)
    return wet if bound is None else np.asarray(bound).astype(np.float64) + wet


class ReferenceOps:
    """The coupling stages in NumPy; same methods and arguments as :class:`~couplekit.coupling.kernel_ops.KernelOps`.

    ``params``: the coupling constants (retention on/off included); ``two_phase``: φ is read (else the
    fluid is single-phase water, φ ≡ 1, ρ ≡ ρ_h).  Arrays of switched-off effects may be ``None``.
    """

    name = "numpy"

    def __init__(self, params: CouplingParams | None = None, two_phase: bool = True):
        self.params = params or CouplingParams()
        self.two_phase = bool(two_phase)
        self.retention = bool(self.params.retention)
        self.xp = np

    def _phi_water(self, phi: np.ndarray | None, like: np.ndarray) -> np.ndarray:
        if not self.two_phase:
            return np.ones_like(like, dtype=np.float64)
        return np.clip(phi.astype(np.float64), 0.0, 1.0)

    # ------------------------------------------------------------------ volume fractions, Eqs. 25, 33, 54-56
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
        """The porosity (padded, ghosts filled) from the sand fraction ε (Eq. 25, :func:`sand_fraction` of the node
        volume ``volume_scale`` × ``grid_vol``), and on
        the MPM grid the bound-water increment dR and bound water R'.  Neither ε nor the water fraction that
        drives cohesion (Eq. 59, :func:`water_fraction`) is stored: the drag and the moisture recompute them.

        ``retentive`` (per-body retention, else None): the retentive sand's fraction ε_r = Σ_p V_p N_i / V_cell
        over retentive particles (:meth:`bound_water_p2g` with r_p = 1 on them); the capacity of Eqs. 55–56
        is then r_max min(ε, ε_r): only retentive sand binds water.

        ``periodic`` = (x, y, z): a ghost on a periodic axis copies its periodic image, else its nearest
        interior node (zero normal gradient).  ``bound_in``: R from :meth:`bound_water_p2g` (retention).
        ``eps_prev``: last step's porosity (padded; retention): the free water Eq. 55 may take is
        min(1 − ε − R, ε̃_prev) φ, the water the phase field actually holds (kernels/coupling_fractions.cu).

        ``share`` s: the part of one fluid step this sand step covers (a substep of k: 1/k; a multi-rate block of
        m fluid steps: m; lockstep: 1). The uptake rate is R_a s and the free water it may take min(s, 1) of
        the free water, so the k substeps of a fluid step absorb what one lockstep step would, and never more
        than the phase field holds.
        """
        p = self.params
        nz, ny, nx = grid_vol.shape
        iz = source_index(nz, periodic[2])[:, None, None]
        iy = source_index(ny, periodic[1])[None, :, None]
        ix = source_index(nx, periodic[0])[None, None, :]
        eps_node = sand_fraction(grid_vol, dx, p.eps_max, volume_scale)  # Eq. 25
        if self.retention:
            ph_node = self._phi_water(_interior(phi) if self.two_phase else None, grid_vol)
            R = bound_in.astype(np.float64)
            retaining = eps_node if retentive is None else np.minimum(eps_node, retentive.astype(np.float64))
            cap = p.r_max * retaining  # retention capacity r_max ε (of the retentive sand)
            free = np.maximum(np.minimum(1.0 - eps_node - R, _interior(eps_prev)), 0.0)  # Eq. 54 before the update
            # Eq. 55 (Δt = share fluid steps), uptake rate scaled by the pores' water fraction φ (module docstring)
            rate = p.absorption_rate * share
            dR = np.minimum(min(share, 1.0) * free * ph_node, np.minimum(rate * cap * ph_node, cap - R))
            R_new = R + dR  # Eq. 56
            ef_node = 1.0 - eps_node - R_new  # Eq. 54
            d_bound[...] = dR
            bound_out[...] = R_new
        else:
            ef_node = 1.0 - eps_node  # Eq. 33
        eps_fluid[...] = ef_node[iz, iy, ix]

    def sand_velocity(self, grid_v, sand_v, units: Units, periodic: Sequence[bool] = (True, True, True)) -> None:
        """The MPM grid velocity (SI, unpadded) in lattice units on the padded layout: the ``sand_velocity``
        input of the mixture pressure update (Eq. 39); ghosts as in :meth:`fractions`."""
        nz, ny, nx = grid_v.shape[1:]
        iz = source_index(nz, periodic[2])[:, None, None]
        iy = source_index(ny, periodic[1])[None, :, None]
        ix = source_index(nx, periodic[0])[None, None, :]
        sand_v[...] = grid_v.astype(np.float64)[:, iz, iy, ix] / (units.dx / units.dt)

    def pressure_slip_fluid(self, flags, velocity, phi, eps, slip, fsum) -> None:
        """``fsum`` := the fluid velocity's part of Eq. 39's slip term, φ u·∇ε / ε (:func:`couplekit.fluid.
        reference.slip_fluid_term`), on the interior fluid cells (0 outside the slip cells), its other cells left
        as they are: taken before u's buffer takes the exchange velocity and the force (lockstep, where the three
        share one); the fluid's ``momentum`` (``held``) then subtracts it from the population sum it keeps, and
        :meth:`pressure_sand_terms` the rest of the terms."""
        from ..fluid.grid import FLUID
        from ..fluid.reference import interior, slip_fluid_term

        terms = slip_fluid_term(velocity, phi, eps, slip, flags, self.two_phase)
        fluid = interior(flags) == FLUID
        interior(fsum)[fluid] = terms[fluid]

    def pressure_sand_terms(
        self, grid_v, flags, phi, eps, slip, fsum, units: Units, periodic: Sequence[bool] = (True, True, True)
    ) -> None:
        """Fold the rest of Eq. 39's sand terms into the kept population sum: ``fsum`` −= ((1 − ε) ∇·v − φ v·∇ε) / ε
        on the interior fluid cells (:func:`couplekit.fluid.reference.sand_pressure_terms` without the fluid
        velocity's part, which :meth:`pressure_slip_fluid` took out), v the MPM grid velocity ``grid_v`` in
        lattice units with the ghosts of :meth:`sand_velocity`.  The fluid's pressure update then adds none
        (``sand_in_fsum``): the update from a stored ``sand_velocity`` to round-off, without keeping one (the
        lockstep step; :meth:`couplekit.fluid.solver.FluidSolver.fold_sand_pressure_terms`)."""
        from ..fluid.grid import FLUID
        from ..fluid.reference import interior, sand_pressure_terms

        sand_v = np.zeros((3,) + tuple(flags.shape))
        self.sand_velocity(grid_v, sand_v, units, periodic)
        terms = sand_pressure_terms(None, phi, eps, sand_v, slip, flags, self.two_phase)
        fluid = interior(flags) == FLUID
        interior(fsum)[fluid] = (interior(fsum).astype(np.float64) - terms)[fluid]

    # ------------------------------------------------------------------ buoyancy (Eq. 31) + implicit drag (§4.3)
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
        """Implicit drag impulse J and Δt × buoyancy F_b (Eq. 31) added to ``grid_mv`` (kg·m/s), −J/Δt to the
        fluid ``force`` (lattice force density); the sand's grid update then takes v = (mv)/m + Δt g (Eq. 29).  See kernels/coupling_drag.cu for the formulas
        (notes §3.4).  ``u`` must be the fluid's current macroscopic velocity Σ_j f_j c_j (populations after
        the last streaming, no force shift), not the post-collision velocity field of a Guo-forced step:
        with that stale value strong drag makes the LBM unstable (kernels/coupling_drag.cu).

        ``grid_vol``: the node volume V_i over ``volume_scale``, the sand fraction's source (Eq. 25); ``units``: the lattice
        unit system (dx, LBM step, reference density); ``gravity`` in m/s²;
        ``rho_h``, ``rho_l`` lattice densities; ``dt``: the MPM step in s (default: the LBM step).
        """
        p = self.params
        mass_scale, velocity_scale, dt, dt_lattice = drag_scales(units, dt)
        grain_diameter = p.grain_diameter_lattice(units.dx)
        g = np.asarray(gravity, np.float64).reshape(3, 1, 1, 1)
        m = grid_m.astype(np.float64)
        active = (m > 0) & (_interior(flags) == 0)
        if self.two_phase:
            rho = rho_l + (rho_h - rho_l) * np.clip(_interior(phi).astype(np.float64), 0.0, 1.0)  # Eq. 4
        else:
            rho = np.full(m.shape, float(rho_h))
        es = sand_fraction(grid_vol, units.dx, p.eps_max, volume_scale)  # Eq. 25, as fractions computes it
        ef = _interior(eps_fluid).astype(np.float64)
        f_b = -es * rho * mass_scale * g  # Eq. 31: −V_cell ε ρ g  (ρ·mass_scale = ρ_SI V_cell)
        m_safe = np.where(active, m, 1.0)
        v_star = ((grid_mv.astype(np.float64) + dt * f_b) / m_safe + dt * g) / velocity_scale  # lattice
        m_s = m_safe / mass_scale
        m_f = rho * ef  # fluid mass of the cell, V_cell = 1
        r_star = _interior(u).astype(np.float64) - v_star  # slip u − v before the exchange
        if grain_diameter > 0:
            area = 1.5 * es / grain_diameter  # all grains' cross-sections (notes §3.2 option)
        else:
            area = np.pi * (3.0 * es / (4.0 * np.pi)) ** (2.0 / 3.0)  # one ball of the node's sand (§4.3)
        beta = 0.5 * p.drag_coefficient * np.maximum(1.0 - es, 1e-6) ** (-p.drag_exponent) * rho * area
        k = dt_lattice * beta * (1.0 / m_s + 1.0 / m_f)
        speed = np.sqrt((r_star**2).sum(axis=0))
        # backward Euler, implicit in |r| too: k|r'|² + |r'| − |r*| = 0  (notes §3.4)
        r_new = r_star * 2.0 / (1.0 + np.sqrt(1.0 + 4.0 * k * speed))
        impulse = (m_s * m_f / (m_s + m_f)) * (r_star - r_new)  # J on the sand = m_s (v' − v*)
        impulse = np.where(active, impulse, 0.0)
        f_b = np.where(active, f_b, 0.0)
        grid_mv[...] = grid_mv.astype(np.float64) + (impulse * mass_scale * velocity_scale + dt * f_b)  # Eq. 26
        _interior(force)[...] = -impulse / dt_lattice  # F_d = −𝔽_d / V_cell (§4.3)

    # ------------------------------------------------------------------ multi-rate coupling (schedulers/subcycle.py)
    def fluid_view(self, u0, u_prev, impulse, phi, eps_fluid, flags, u_seen, theta: float, rho_h, rho_l) -> None:
        """The fluid velocity a sand substep exchanges momentum with (lattice units, padded), on interior FLUID
        cells: u_s = u0 + θ (u0 − u_prev) + A / (ρ ε_f); elsewhere u0 (interior) and the ghosts untouched.

        u0: Σ f c at the start of the fluid step; ``u_prev``: the same one fluid step earlier, or None to hold
        the fluid (θ unused); θ = s/k, the substep's start in fluid steps (linear in time through the last two
        fluid states); ``impulse`` A: the fluid force summed over the earlier substeps, −Σ J (lattice momentum
        per cell); ρ(φ) ε_f: the cell's fluid mass. A / (ρ ε_f) is the velocity the fluid will have gained from
        the drag already exchanged, so the implicit exchange of each substep sees the fluid it acts on
        (kernels/coupling_subcycle.cu).
        """
        u = _interior(u0).astype(np.float64)
        if u_prev is not None:
            u = u + theta * (u - _interior(u_prev).astype(np.float64))
        if self.two_phase:
            rho = rho_l + (rho_h - rho_l) * np.clip(_interior(phi).astype(np.float64), 0.0, 1.0)  # Eq. 4
        else:
            rho = float(rho_h)
        u = u + _interior(impulse).astype(np.float64) / (rho * _interior(eps_fluid).astype(np.float64))
        fluid = _interior(flags) == 0
        _interior(u_seen)[...] = np.where(fluid, u, _interior(u0))

    def accumulate(self, acc, x, weight: float, first: bool) -> None:
        """``acc = weight x`` (first) or ``acc += weight x``, in place: the substeps' average (weight 1/k) or
        sum (weight 1) of a field."""
        w = np.float32(weight)
        if first:
            acc[...] = w * x
        else:
            acc[...] = acc + w * x

    # ------------------------------------------------------------------ phase-field source, Eqs. 45, 57
    def phase_source(self, eps, eps_prev, phi, u, flags, d_bound, source) -> None:
        """S_φ = −(φ/ε̃)[(ε̃ − ε̃_prev) + u·∇ε̃] (Eq. 45) − dR/ε̃ (Eq. 57, retention) on interior FLUID cells.

        Why this discretisation: with u = 0 the phase-field update φ' = φ + S gives
        ε̃ φ' = ε̃ φ − φ(ε̃ − ε̃_prev) − dR = ε̃_prev φ − dR, so Σ ε̃ φ (free water) + Σ R (bound water) is
        carried from one step to the next exactly; the advective part is the continuum identity
        ε̃ ∇·(φu) + φ u·∇ε̃ = ∇·(ε̃ φ u).
        """
        e = _interior(eps).astype(np.float64)
        grad = _isotropic_gradient(eps, flags)
        uu = _interior(u).astype(np.float64)
        advect = (uu * grad).sum(axis=0)
        inv = 1.0 / np.maximum(e, 1e-6)
        s = -_interior(phi).astype(np.float64) * inv * ((e - _interior(eps_prev)) + advect)
        if self.retention:
            s = s - d_bound.astype(np.float64) * inv
        _interior(source)[...] = np.where(_interior(flags) == 0, s, 0.0)

    # ------------------------------------------------------------------ particles: Eqs. 53, 58, 59
    def bound_water_p2g(self, x, r, vol, bound, dx: float) -> None:
        """R_i = (1/V_cell) Σ_p r_p V_p N_i(x_p)  (Eq. 53), overwriting ``bound``."""
        index, w = bspline_stencil(x, dx, bound.shape)
        q = r.astype(np.float64) * vol.astype(np.float64) / dx**3
        acc = np.zeros(bound.size)
        np.add.at(acc, index.ravel(), (w * q[:, None]).ravel())
        bound[...] = acc.reshape(bound.shape)

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
        """S_p = Σ_i water_i N_i(x_p) (Eq. 59), water_i = :func:`water_fraction` of this step's porosity
        ``eps_fluid`` (padded), ``phi`` (padded) and bound water ``bound`` (R', retention); with retention
        r_p += Σ_i dR_i / ε̂_i N_i(x_p) (Eq. 58),
        ε̂_i = V_i / V_cell unclamped, V_i = ``volume_scale`` × ``grid_vol`` (so that bound water is conserved; see
        kernels/coupling_moisture.cu).

        Per-body retention: ``retain`` (P,) is 1 on retentive particles, 0 elsewhere, ``retentive`` their
        fraction ε_r (see :meth:`fractions`); then r_p += retain_p Σ_i dR_i / ε_r,i N_i(x_p): the bound water
        goes to the retentive particles only, and Σ_p r_p V_p still grows by V_cell Σ_i dR_i."""
        water = water_fraction(eps_fluid, phi if self.two_phase else None, bound if self.retention else None)
        index, w = bspline_stencil(x, dx, water.shape)
        lost = ~w.any(axis=1)  # outside the grid or not finite (bspline_stencil): saturation NaN, r unchanged
        saturation[...] = np.where(lost, np.nan, (w * water.astype(np.float64).ravel()[index]).sum(axis=1))
        if self.retention:
            if retentive is None:
                vol = grid_vol.astype(np.float64).ravel() * (volume_scale / dx**3)
                keep = 1.0
            else:
                vol = retentive.astype(np.float64).ravel()
                keep = retain.astype(np.float64)
            ratio = np.where(vol > 0, d_bound.astype(np.float64).ravel() / np.where(vol > 0, vol, 1.0), 0.0)
            r[...] = r.astype(np.float64) + keep * (w * ratio[index]).sum(axis=1)
