"""NumPy reference ops of the velocity-based D3Q27 NOCM-MRT fluid: the executable specification.

Written for clarity, vectorised over cells and independent of the kernels (the collision goes through the
explicit moment matrices of :mod:`couplekit.fluid.moments`, Eq. 11, where the kernel uses a specialised
chimera back-transform). Every method has the signature of the matching :class:`~couplekit.fluid.kernel_ops.KernelOps`
method. Arrays are padded (see :mod:`couplekit.fluid.grid`): distributions ``f (27, Pz, Py, Px)``, vectors
``(3, Pz, Py, Px)``, scalars ``(Pz, Py, Px)``, all float32; flags ``uint8``.

**Shifted storage.** The arrays hold ``f_j − w_j`` (w_j the D3Q27 weight), not ``f_j``, as lbmpy and FluidX3D
do: the populations are close to w_j and, at low viscosity and low speed, the non-equilibrium part that
carries the viscous stress is ~1e-7 of them, below the float32 round-off of ``f_j`` itself (docs/precision.md).
:func:`to_stored` / :func:`from_stored` convert. Here :meth:`ReferenceOps.load` returns the full ``f_j``
(float64, the shift added back exactly) and :meth:`ReferenceOps.store` subtracts it again in float64, so every
stage below is written for the full populations; the rules of streaming, bounce-back (w_ĵ = w_j) and the
ghosts are the same for ``f − w`` and ``f``.

Streaming is the AA pattern (Bailey et al. 2009; lbm-method note §1d) with one copy of f. At an even
``parity`` the populations are stored in natural order ``F[j][x] = f_j(x)``; the step collides locally and
writes ``F[ĵ][x] = f*_j``. At an odd parity ``f_j(x) = F[ĵ][x − c_j]`` (pull) and the step writes
``F[j][x + c_j] = f*_j`` (push), which restores the natural order. All boundary rules act in the odd step:

* wall / inflow neighbour ``x − c_j`` (half-way bounce-back, moving wall ``u_w``, note §1f):
  ``f_j(x) = f*_ĵ(x) + 6 w_j c_j·u_w`` which after the even step sits in ``F[j][x]``;
  a push towards a wall ``x + c_j`` is written back as ``F[ĵ][x] = f*_j − 6 w_j c_j·u_w``;
* outflow ghosts are read and pushed to as if they were fluid: :meth:`ReferenceOps.halo_copy` fills them
  from their nearest interior cell before an odd step (zero normal gradient of f*), and
  :meth:`ReferenceOps.outflow_fix` sets, after it, what they would have pushed (zero-gradient outflow:
  waves leave with a small reflection instead of the full reflection of an equilibrium or pressure boundary).

Scalar stencils (isotropic gradient Eq. 18, filter Eq. 40) use a neighbour's value when it is a ``FLUID``
cell (periodic ghosts hold copies of their images) or an ``OUTFLOW`` ghost (which keeps the outlet reference
value, p = 0: a pressure Dirichlet condition half a link outside); otherwise (walls, inflow, solids) the
centre value for φ, ε, v (zero normal gradient, note §1f) and, for the pressure (filter and gradient), the
linear extrapolation 2 p(x) − p(x − c_j), which keeps a hydrostatic profile in balance at walls.
"""

from __future__ import annotations

import numpy as np

from ..lattice import C27, CS2, OPP27, W27
from . import moments
from .grid import FLUID, INTERIOR, OUTFLOW, padded_coords, stencil_cell, three_point_links
from .storage import check_storage, decode_f, encode_f, weights27


def shifted(a: np.ndarray, c) -> np.ndarray:
    """View of padded array ``a`` (..., Pz, Py, Px) at ``x + c`` for every interior cell x (c = (cx, cy, cz))."""
    cx, cy, cz = (int(v) for v in c)
    pz, py, px = a.shape[-3:]
    return a[..., 1 + cz : pz - 1 + cz, 1 + cy : py - 1 + cy, 1 + cx : px - 1 + cx]


def interior(a: np.ndarray) -> np.ndarray:
    """View of the interior cells of a padded array."""
    return a[(Ellipsis, *INTERIOR)]


def link_wall_velocity(velocity: np.ndarray, c) -> np.ndarray:
    """The wall velocity (3, nz, ny, nx, float64) that the bounce-back link from ``x − c`` carries into every
    interior cell x: the wall's velocity where the link crosses it (half-way bounce-back, note §1f). Where
    ``x − c`` is a ghost of exactly one face of the box, the link crosses that face half-way between that ghost
    and x's own ghost across the face, x − c_a e_a (a the face's axis; the same cell for the straight link),
    and carries the mean of their two velocities (linear along the face). Ghosts of two or three faces (the
    box's edges and corners) and interior solid cells give their own velocity. Where a face's velocity is
    uniform this is the neighbour's velocity exactly.

    Why: with the neighbour's velocity alone, the diagonal links of a narrow outlet put part of its volume flux
    into the cells beside it (~31 % for a 2 × 2 outlet) while the phase field's D3Q7 inflow puts all its water
    into the outlet's cells; a water jet from a 2-cell outlet into air at 800:1 diverged at lattice speed 0.06
    (docs/fluid-stability.md, "Water outlets at 800:1")."""
    c = np.asarray(c, int)
    own = shifted(velocity, -c).astype(np.float64)
    shape = own.shape[1:]  # (nz, ny, nx)
    beyond = []  # per axis (x, y, z): x − c lies in that axis' ghost layer
    for a in range(3):
        n, ax = shape[2 - a], 2 - a
        pos = np.arange(1, n + 1) - c[a]
        hit = (pos == 0) | (pos == n + 1)
        beyond.append(np.broadcast_to(hit.reshape([-1 if k == ax else 1 for k in range(3)]), shape))
    count = beyond[0].astype(int) + beyond[1] + beyond[2]
    out = own.copy()
    for a in range(3):
        if c[a] == 0:
            continue
        face = np.zeros(3, int)
        face[a] = c[a]
        one = beyond[a] & (count == 1)
        mean = 0.5 * (own + shifted(velocity, -face).astype(np.float64))
        out = np.where(one, mean, out)
    return out


def back2(a: np.ndarray, c) -> np.ndarray:
    """``a`` at ``x − 2c`` for every interior cell x; where that is outside the padded grid, the nearest value
    on its edge (callers use it only where :func:`couplekit.fluid.grid.three_point_links` holds, which keeps
    x − 2c inside)."""
    cx, cy, cz = (-2 * int(v) for v in c)
    big = np.pad(a, [(0, 0)] * (a.ndim - 3) + [(1, 1)] * 3, mode="edge")
    pz, py, px = big.shape[-3:]
    return big[..., 2 + cz : pz - 2 + cz, 2 + cy : py - 2 + cy, 2 + cx : px - 2 + cx]


def neighbour_values(
    s: np.ndarray, flags: np.ndarray, c, extrapolate: bool, three_point: np.ndarray | None = None
) -> np.ndarray:
    """s(x + c) for every interior x, with the wall rule: a wall / inflow / solid neighbour takes the centre
    value, or with ``extrapolate`` the linear extrapolation 2 s(x) − s(x − c) when x − c is a stencil cell;
    ``three_point`` (interior bool mask, the filter's): there the three-point s(x) + s(x − c) − s(x − 2c)
    instead (:func:`couplekit.fluid.grid.three_point_links`)."""
    centre = interior(s).astype(np.float64)
    ok = stencil_cell(shifted(flags, c))
    out = np.where(ok, shifted(s, c), centre)
    if extrapolate:
        back = stencil_cell(shifted(flags, -np.asarray(c)))
        sb = shifted(s, -np.asarray(c)).astype(np.float64)
        ext = 2.0 * centre - sb
        if three_point is not None:
            ext = np.where(three_point, centre + sb - back2(s, c), ext)
        out = np.where(~ok & back, ext, out)
    return out


def isotropic_gradient(s: np.ndarray, flags: np.ndarray, extrapolate: bool = False) -> np.ndarray:
    """Eq. 18: ∇s = Σ_j 3 w_j c_j s(x + c_j), with the wall rule of :func:`neighbour_values` (centre value
    for φ, ε, v — zero normal gradient; linear extrapolation for the pressure, whose hydrostatic wall-normal
    gradient is ρg, not 0)."""
    centre = interior(s).astype(np.float64)
    grad = np.zeros((3,) + centre.shape)
    for j in range(1, 27):
        nb = neighbour_values(s, flags, C27[j], extrapolate)
        for d in range(3):
            if C27[j, d]:
                grad[d] += 3.0 * W27[j] * C27[j, d] * (nb - centre)
    return grad


def local_average(s: np.ndarray, flags: np.ndarray, links: np.ndarray | None = None) -> np.ndarray:
    """Eq. 40: s̄ = Σ_j w_j s(x + c_j), wall/inflow/solid neighbours linearly extrapolated (see
    :func:`neighbour_values`), so a hydrostatic profile passes the filter unchanged; in flat wall layers, the
    links of ``links`` (padded uint32, :func:`couplekit.fluid.grid.three_point_links` of ``flags`` when None)
    take the three-point rule."""
    if links is None:
        links = three_point_links(flags)
    bits = interior(links)
    centre = interior(s).astype(np.float64)
    out = W27[0] * centre
    for j in range(1, 27):
        rule = ((bits >> np.uint32(j)) & np.uint32(1)).astype(bool)
        out = out + W27[j] * neighbour_values(s, flags, C27[j], True, rule)
    return out


def isotropic_laplacian(s: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Eq. 23: ∇²s = (2/c_s²) Σ_j w_j (s(x + c_j) − s(x)), a non-stencil neighbour taking the centre value (the
    rule of :func:`isotropic_gradient` without extrapolation)."""
    centre = interior(s).astype(np.float64)
    lap = np.zeros(centre.shape)
    for j in range(1, 27):
        lap += W27[j] * (neighbour_values(s, flags, C27[j], False) - centre)
    return 6.0 * lap


def chemical_potential(phi: np.ndarray, flags: np.ndarray, beta: float, kappa: float) -> np.ndarray:
    """Eq. 22 on the interior: μ_φ = 4β φ(φ − 1)(φ − ½) − κ ∇²φ (∇² of Eq. 23, :func:`isotropic_laplacian`)."""
    p = interior(phi).astype(np.float64)
    return 4.0 * beta * p * (p - 1.0) * (p - 0.5) - kappa * isotropic_laplacian(phi, flags)


def check_chemical_potential(ops, chemical_potential: tuple[float, float] | None) -> tuple[float, float]:
    """(β, κ) of Eq. 22 for a collide of ``ops``: required exactly when the ops were built with surface tension
    (``couplekit.fluid.phasefield.chemical_potential_coefficients(sigma, width)``), (0, 0) otherwise."""
    if ops.surface_tension != (chemical_potential is not None):
        raise ValueError(
            "chemical_potential=(beta, kappa) must be given exactly when the ops were built with surface "
            "tension (phasefield.chemical_potential_coefficients(sigma, width))"
        )
    if chemical_potential is None:
        return 0.0, 0.0
    beta, kappa = (float(v) for v in chemical_potential)
    return beta, kappa


def check_closures(ops, smagorinsky: float, odd_lambda: float) -> None:
    """Refuse closure values an ops object was not built for (its ``les`` / ``odd_rate`` flags, which the
    kernels compile in): a silently ignored closure would run the paper's collision instead."""
    if smagorinsky > 0 and not ops.les:
        raise ValueError(f"smagorinsky = {smagorinsky} needs ops built with les=True (FluidParams.smagorinsky > 0)")
    if odd_lambda > 0 and not ops.odd_rate:
        raise ValueError(f"odd_lambda = {odd_lambda} needs ops built with odd_rate=True (FluidParams.odd_lambda > 0)")


def check_odd_ramp_effect(odd_ramp: bool, odd_rate: bool) -> bool:
    """The ``odd_ramp`` switch of an ops object: it ramps the floor, so it needs ``odd_rate``."""
    if odd_ramp and not odd_rate:
        raise ValueError("odd_ramp=True needs odd_rate=True: the ramp blends the odd-rate floor with rate 1")
    return bool(odd_ramp)


def check_odd_ramp(ops, odd_ramp) -> None:
    """The ramp weights are given exactly when the ops were built for them (``odd_ramp=True``, which needs
    ``odd_rate``): a ramp the kernels were not compiled for would be ignored silently."""
    if (odd_ramp is not None) != ops.odd_ramp:
        raise ValueError(
            "odd_ramp weights must be given exactly when the ops were built with odd_ramp=True "
            "(FluidParams.odd_ramp > 0 with the odd-rate floor acting; couplekit.fluid.odd_ramp.ramp_weights)"
        )


def odd_rate(r_s, odd_lambda: float):
    """Relaxation rate of the odd central moments (orders 3 and 5): r_o = min(1, 1 / (½ + Λ / (1/r_s − ½))).

    The two-relaxation-time "magic" product Λ = (1/r_s − ½)(1/r_o − ½) (Ginzburg 2008) of the even (shear)
    and odd rates is thereby kept ≥ ``odd_lambda``; with the paper's r_o = 1 it is Λ = 3ν/2, which at
    ν = 1e-4 leaves the half-way bounce-back walls' edges and corners linearly unstable (an eigenvalue
    −1.007 per step of the linearised step at rest, docs/fluid-stability.md). ``odd_lambda`` = 0 keeps
    r_o = 1; cells whose viscosity gives Λ ≥ ``odd_lambda`` at r_o = 1 keep 1.
    """
    if odd_lambda <= 0:
        return 1.0
    return np.minimum(1.0, 1.0 / (0.5 + odd_lambda / (1.0 / np.asarray(r_s, np.float64) - 0.5)))


def odd_rates(r_s, nu, nu_ref: float, odd_lambda: float, odd_nu_max: float):
    """Odd-moment rate of every cell: :func:`odd_rate` at the shear rate of ``nu_ref`` (the fluid's lowest
    molecular viscosity: ν_h, or min(ν_h, ν_l) with two phases) plus the cell's subgrid viscosity
    ν_t = (1/r_s − ½)/3 − ν (0 without Smagorinsky); 1 everywhere when ``nu_ref`` ≥ ``odd_nu_max``.

    So the rate is one number wherever the flow is resolved, whatever the phase: a rate that follows each
    cell's own viscosity (0.02 in water, 1 in air at ν_l = 0.01, varying across the interface) fed energy into
    surface waves (a standing wave held 2.4× its energy a quarter period in and kept gaining; with one rate it
    oscillates at the linear-theory period and decays: docs/fluid-stability.md, "Energy of a standing wave").
    Linearised at rest, a floor applied only within 1–2 cells of the walls leaves the step unstable (spectral
    radius 1.0004–1.006 on a 7 × 7 walled box). Subgrid viscosity raises the rate where the flow is not
    resolved, which keeps Λ there at ``odd_lambda``.
    """
    if nu_ref >= odd_nu_max:
        return 1.0
    odd_tau = (1.0 / np.asarray(r_s, np.float64) - 0.5) - 3.0 * np.asarray(nu, np.float64) + 3.0 * nu_ref
    return odd_rate(1.0 / (odd_tau + 0.5), odd_lambda)


def ramped_odd_rates(r_o, ramp):
    """The floor's rates ``r_o`` ramped to the paper's rate 1 away from the walls (``FluidParams.odd_ramp``,
    :mod:`couplekit.fluid.odd_ramp`): r_o + (1 − r_o) s, with s = ``ramp`` the weight of rate 1 per cell
    (0 at the walls, 1 from D + ½ cells in). ``ramp`` ``None``: ``r_o`` unchanged."""
    if ramp is None or np.isscalar(r_o):  # no ramp, or the floor is off (rate 1 everywhere)
        return r_o
    s = np.asarray(ramp, np.float64)
    return r_o + (1.0 - r_o) * s


def equilibrium(u: np.ndarray) -> np.ndarray:
    """Density-normalised D3Q27 equilibrium (27, ...) for velocity u (3, ...): sixth-order Hermite, product form.

    f_j^eq = Ψ(c_jx, u_x) Ψ(c_jy, u_y) Ψ(c_jz, u_z), Ψ(0, u) = 2/3 − u², Ψ(±1, u) = (1 ± 3u + 3u²)/6
    (note §1b); its central moments are Eq. 12's.
    """
    u = np.asarray(u, np.float64)

    def psi(c, v):
        return np.where(c == 0, 2.0 / 3.0 - v * v, (1.0 + 3.0 * c * v + 3.0 * v * v) / 6.0)

    return np.stack([psi(C27[j, 0], u[0]) * psi(C27[j, 1], u[1]) * psi(C27[j, 2], u[2]) for j in range(27)])


def to_stored(f: np.ndarray, storage: str = "fp32") -> np.ndarray:
    """Stored form of full populations f (27, ...): what the fluid arrays hold (shifted storage, module
    docstring): ``f − w`` as float32 (``storage="fp32"``) or ``(f − w) · F_SCALE`` as float16 (``"fp16"``,
    :mod:`couplekit.fluid.storage`); the difference is taken in float64 and rounded once."""
    f = np.asarray(f, np.float64)
    return encode_f(f - weights27(f.ndim), check_storage(storage))


def from_stored(stored: np.ndarray) -> np.ndarray:
    """Full populations f = stored + w (float64, 27, ...) of a stored array (``FluidSolver.f``; float32, or
    float16 of fp16 storage, whose scale is taken out)."""
    shifted = decode_f(stored)
    return shifted + weights27(shifted.ndim)


def sand_pressure_terms(velocity, phi, eps, sand_v, slip, flags, two_phase: bool) -> np.ndarray:
    """The sand's terms of Eq. 39 on the interior (float64): ((1 − ε) ∇·v + (u − v)·∇ε) / ε, the slip term
    (u − v)·∇ε only in the cells of ``slip`` and weighted by the clamped water fraction φ in two-phase flow
    (why both: :meth:`ReferenceOps.macro_pressure`).  ``velocity``: the Eq. 13 velocity of the last collision,
    or None for the terms without its part (u = 0: what is left once :func:`slip_fluid_term` is taken out);
    ``eps``, ``sand_v``: the padded porosity and sand velocity (lattice units), ghosts filled."""
    e = interior(eps).astype(np.float64)
    v = interior(sand_v).astype(np.float64)
    # Eq. 13 velocity of the last collision (macro_pressure)
    u = np.zeros_like(v) if velocity is None else interior(velocity).astype(np.float64)
    grad_e = isotropic_gradient(eps, flags)
    div_v = sum(isotropic_gradient(sand_v[d], flags)[d] for d in range(3))
    u_grad_e = _slip_weighted(sum((u[d] - v[d]) * grad_e[d] for d in range(3)), phi, slip, two_phase)
    return ((1.0 - e) * div_v + u_grad_e) / e


def slip_fluid_term(velocity, phi, eps, slip, flags, two_phase: bool) -> np.ndarray:
    """The fluid velocity's part of Eq. 39's slip term on the interior (float64): φ u·∇ε / ε in the cells of
    ``slip`` (without φ single-phase), 0 elsewhere; :func:`sand_pressure_terms` with ``velocity`` minus the same
    without it (the lockstep step takes this part out while u is still stored, kernels/coupling_pressure.cu)."""
    e = interior(eps).astype(np.float64)
    u = interior(velocity).astype(np.float64)
    grad_e = isotropic_gradient(eps, flags)
    return _slip_weighted(sum(u[d] * grad_e[d] for d in range(3)), phi, slip, two_phase) / e


def _slip_weighted(slip_term, phi, slip, two_phase: bool) -> np.ndarray:
    """A slip term of Eq. 39 kept only in the cells of ``slip`` (not near walls) and, two-phase, weighted by the
    clamped water fraction φ (the light phase's slip pumped air: why both, :meth:`ReferenceOps.macro_pressure`)."""
    slip_term = np.where(interior(slip) != 0, slip_term, 0.0)
    if two_phase:
        slip_term = np.clip(interior(phi).astype(np.float64), 0.0, 1.0) * slip_term
    return slip_term


def backflow_velocity(m, outward) -> np.ndarray:
    """Δu (3, n, float32) that removes backflow at outflow ghosts: with ``m`` (3, n) the momentum Σ_j f*_j c_j of
    each ghost's interior cell and ``outward`` (3, n) the ghost's offset from it on the axes it lies outside a
    non-periodic face (±1, 0 elsewhere: :func:`couplekit.fluid.grid.outflow_directions`), the velocity's inward
    part on those axes, Δu_a = −o_a min(o_a m_a, 0); 0 where nothing flows in.  float32, as the kernels keep it
    between the fill and the fix.

        Why: a zero-gradient outflow copies inflowing fluid's momentum back in unchanged, and where a wind's
        return flow enters through the outflow face it feeds itself: Fig. 2's small scene without sand at 12 m/s
        (lattice 0.06) diverged by 0.5 s, a quarter to a third of the ceiling's outflow cells taking air in at up
        to 13 m/s; with the inward part removed it runs to 1.5 s (docs/fluid-stability.md, 'Backflow through an
        outflow face')."""
    o = np.asarray(outward, np.float64)
    return (-o * np.minimum(o * np.asarray(m, np.float64), 0.0)).astype(np.float32)


def backflow_correction(du) -> np.ndarray:
    """The change (27, n) of the populations f*_j an outflow ghost sends into the domain for a velocity change
    ``du`` (3, n; :func:`backflow_velocity`): Δ_j = 3 w_j c_j·Δu, the first-order equilibrium term (Σ_j Δ_j = 0: no
    mass; Σ_j Δ_j c_j = Δu).  0 where Δu = 0 (the zero-gradient copy as it was)."""
    return 3.0 * W27[:, None] * (C27.astype(np.float64) @ np.asarray(du, np.float64))


def _pull_links(f, ghost):
    """(j, mask) for j = 1..26: which periodic ghosts g have g − c_j interior (the odd step's links)."""
    pz, py, px = f.shape[-3:]
    gx, gy, gz = padded_coords(ghost, f.shape[-3:])
    for j in range(1, 27):
        sx, sy, sz = gx - C27[j, 0], gy - C27[j, 1], gz - C27[j, 2]
        yield j, (sx >= 1) & (sx <= px - 2) & (sy >= 1) & (sy <= py - 2) & (sz >= 1) & (sz <= pz - 2)


class ReferenceOps:
    """NumPy implementation of the fluid stages (see the module docstring for layouts and rules).

    The switches mirror the kernel defines: ``two_phase`` (ρ, μ from φ; else ρ = rho_h, ν = nu_h),
    ``surface_tension`` (F_s = μ_φ ∇φ from a chemical-potential field), ``mixture`` (fluid fraction ε and
    sand velocity v inputs; else ε ≡ 1), ``external_force`` (a force-density input field, e.g. drag), and the
    closures ``les`` (Smagorinsky) and ``odd_rate`` (odd-moment rate floor), which allow non-zero
    ``smagorinsky`` / ``odd_lambda`` in :meth:`collide_stream`; ``odd_ramp`` (the floor ramped to rate 1
    away from the walls, :mod:`couplekit.fluid.odd_ramp`; needs ``odd_rate``) takes the ramp's weights there.
    Arrays of switched-off effects are ignored (pass ``None``).
    """

    name = "numpy"

    def __init__(
        self,
        two_phase: bool = False,
        surface_tension: bool = False,
        mixture: bool = False,
        external_force: bool = False,
        les: bool = False,
        odd_rate: bool = False,
        storage: str = "fp32",
        odd_ramp: bool = False,
    ):
        self.storage = check_storage(storage)  # what f arrays to allocate; the stages follow f's dtype
        self.two_phase = bool(two_phase)
        self.surface_tension = bool(surface_tension) and self.two_phase
        self.mixture = bool(mixture)
        self.external_force = bool(external_force)
        self.les = bool(les)
        self.odd_rate = bool(odd_rate)
        self.odd_ramp = check_odd_ramp_effect(odd_ramp, self.odd_rate)

    # ------------------------------------------------------------------------------------------ helpers
    @staticmethod
    def load(f: np.ndarray, flags: np.ndarray, velocity: np.ndarray, parity: int) -> np.ndarray:
        """The full populations f_j(x, t) (27, nz, ny, nx, float64) of every interior cell under the AA read rule of
        ``parity``, from the stored f − w (the read rules act on the stored values; w is added at the end).
        An fp16 array (float16) is decoded first (:func:`~couplekit.fluid.storage.decode_f`, exact in float64)."""
        f = decode_f(f)
        if parity % 2 == 0:
            return interior(f).astype(np.float64) + weights27(4)
        out = np.empty((27,) + interior(flags).shape)
        out[0] = interior(f[0])
        for j in range(1, 27):
            c, jo = C27[j], OPP27[j]
            nb_flag = shifted(flags, -c)
            pulled = shifted(f[jo], -c)
            wall_u = link_wall_velocity(velocity, c)
            bounced = interior(f[j]) + 6.0 * W27[j] * (c[0] * wall_u[0] + c[1] * wall_u[1] + c[2] * wall_u[2])
            out[j] = np.where((nb_flag == FLUID) | (nb_flag == OUTFLOW), pulled, bounced)
        return out + weights27(4)

    @staticmethod
    def store(f: np.ndarray, flags: np.ndarray, velocity: np.ndarray, parity: int, fstar: np.ndarray) -> None:
        """Write post-collision populations ``fstar`` (full f*, float64) of the interior fluid cells under the AA
        write rule of ``parity``, as f* − w (shifted storage, formed in float64). An fp16 array is written
        through a float64 copy (decoded exactly, so the values not written come back unchanged) that is encoded
        once at the end: each written value is rounded once, from float64, to nearest even."""
        if f.dtype == np.float16:
            work = decode_f(f)
            ReferenceOps.store(work, flags, velocity, parity, fstar)
            f[...] = encode_f(work, "fp16")
            return
        fstar = np.asarray(fstar, np.float64) - weights27(4)
        fluid = interior(flags) == FLUID
        if parity % 2 == 0:
            for j in range(27):
                interior(f[OPP27[j]])[fluid] = fstar[j][fluid]
            return
        interior(f[0])[fluid] = fstar[0][fluid]
        for j in range(1, 27):
            c, jo = C27[j], OPP27[j]
            nb_flag = shifted(flags, c)
            push = fluid & ((nb_flag == FLUID) | (nb_flag == OUTFLOW))
            shifted(f[j], c)[push] = fstar[j][push]
            wall_u = link_wall_velocity(velocity, -c)
            bounced = fstar[j] - 6.0 * W27[j] * (c[0] * wall_u[0] + c[1] * wall_u[1] + c[2] * wall_u[2])
            wall = fluid & ~push & (nb_flag != FLUID)
            interior(f[jo])[wall] = bounced[wall]

    def _density(self, phi, rho_h: float, rho_l: float) -> np.ndarray | float:
        """Eq. 4: ρ = ρ_l + (ρ_h − ρ_l) φ with φ clamped to [0, 1] for the property only."""
        if not self.two_phase:
            return float(rho_h)
        ph = np.clip(interior(phi).astype(np.float64), 0.0, 1.0)
        return rho_l + (rho_h - rho_l) * ph

    def _viscosity(self, phi, rho_h: float, rho_l: float, nu_h: float, nu_l: float) -> np.ndarray | float:
        """Eq. 4: kinematic viscosity μ/ρ with μ = μ_l + (μ_h − μ_l) φ (φ clamped); ν_h single-phase."""
        if not self.two_phase:
            return float(nu_h)
        ph = np.clip(interior(phi).astype(np.float64), 0.0, 1.0)
        return (rho_l * nu_l + (rho_h * nu_h - rho_l * nu_l) * ph) / self._density(phi, rho_h, rho_l)

    # ------------------------------------------------------------------------------------------ stages
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
        """Pressure update, Eq. 39, in place on the interior fluid cells of ``p``.

        ``fsum``: Σ_j (f_j − w_j) of the current populations (padded, from :meth:`momentum`), which then stands for
        Σ_j f_j − 1 instead of a sum over ``f`` (the coupled step computes it with the exchange velocity, so the
        pressure update does not read the populations again).  ``sand_in_fsum``: ``fsum`` already holds minus
        the sand's terms (:func:`sand_pressure_terms`, subtracted by the coupling from the MPM grid velocity:
        :meth:`couplekit.coupling.reference.ReferenceOps.pressure_sand_terms`), so none are added here and
        ``sand_v`` is not read.

        p^{n+1} = p^n − c_s² ρ^{n+1} [(1 − Σ_j f_j) + (ε_s ∇·v + (u − v)·∇ε)/ε], with 1 − Σf ≈ ∇·u (Eq. 38),
        ε_s = 1 − ε the sand fraction, u the fluid velocity of Eq. 13 as the last collision wrote it
        (``velocity``: this step's forces, hence its half-force shift, are not known yet at this stage).

        Why not u = Σ_j f_j c_j of the current populations: that is u − a/2 with a = −∇p̄/ρ + g + …, so the
        update would carry −(a/2)·∇ε/ε = (∇p̄ − ρg)·∇ε/(2ρε), a pressure-advection term that grows a
        grid-scale mode (u_z alternating in sign from cell to cell) where ε changes next to a wall.  Measured
        on a 16×6×6 walled column of water at rest with a frozen sand-bed porosity profile whose first cell
        above the floor holds ε = 0.92 under 0.59 and 0.515 (the profile a settled bed has, the MPM's wall
        layer keeping the grains one cell off the floor): with Σ f c the speed grew ×3.5 every 100 steps
        from round-off to NaN by step 1100; with the Eq. 13 velocity it stays at 1.5e-5 (round-off); the
        same profile away from walls was stable either way (tests/coupling/test_bed_wall_stability.py).

        Why the slip term (u − v)·∇ε only in the cells of ``slip`` (padded uint8 mask,
        :func:`couplekit.fluid.grid.slip_cells`: not in the layers of cells next to a wall, inflow or solid
        cell, along the 26 lattice directions; one layer with the paper's collision, three where the odd-rate
        floor acts, :func:`~couplekit.fluid.grid.slip_wall_layers`): next to a wall the gradient's wall rule
        (a wall neighbour takes the centre value) cannot express that no fluid crosses the wall, and with the
        Eq. 13 velocity the same column still grew (×2 per 200 steps from step ~1000, a mode alternating in x
        at the floor), as did a porosity step next to the side walls' edge; without the term in wall-adjacent
        cells both stay at round-off for 4000 steps.  One cell is not enough where a bed's vertical edge
        reaches within two cells of a wall, as the beds that scenes build do (ε = 1, 0.9, 0.49 from the
        floor up): with the scene closures at ν_h = 1e-4 (the odd moments relaxing at r_o ≈ 0.02) the mode
        grew ×2.5 per 250 steps to 1.4e-2 by step 3000 with the term dropped in the one layer next to the
        walls, ×2.3 per 500 steps with it dropped in two layers, and stays at 1.8e-6 (round-off) for 4000
        steps with it dropped in three (docs/fluid-stability.md, tests/coupling/test_bed_wall_stability.py).
        With the odd moments at rate 1 (ν ≥ 5e-4, or ``odd_lambda`` = 0) one layer is stable, and three cost
        physics there: a 4-cell bed under a partition wall in a 6-cell wide tank loses the slip term
        everywhere, and retention's slowing of the wetting front fell from 0.81× to 0.90×
        (tests/coupling/test_retention_front_partition.py), so three apply only where the floor acts.  The
        cost: the pressure of a cell in those layers does not see flow into a narrower pore there (its ∇·u
        still does).

        Why the slip term is weighted by the water fraction φ (two-phase): in the light phase the pressure it
        raises accelerates the fluid by ∇p/ρ with ρ down to ρ_l, and a sand ball falling through the air
        side of the interface (cells of ρ ≈ 0.01–0.08) pumped that air upward through itself, the pressure at
        its lower edge and the slip feeding each other (×4 every ~40 steps, the drag ~50× too weak to stop
        it): the fluid in a 1500 kg/m³ ball falling at 0.31 m/s rose at 1.2 m/s after 208 steps, and sand
        balls bounced off the water (tests/test_fig08_sand_densities.py).  Weighted by φ it rises at
        0.03 m/s.  The term keeps its full weight in water, where the mixture continuity matters for the
        sand (air's drag on it is ~800× weaker).  The same loop returns in water at a small Δt, where the drag
        per step (∝ Δt/Δx) no longer outruns it: Fig. 2's floating ring rises out of the pool at Δt = 6e-5 s
        (docs/fluid-stability.md, 'The slip term at a small time step'; a strict xfail in
        tests/test_paper_scenes.py).  Not fixed.
        """
        if fsum is None:
            s0 = self.load(f, flags, velocity, parity).sum(axis=0)
        else:
            s0 = 1.0 + interior(fsum).astype(np.float64)  # Σ_j f_j = Σ_j (f_j − w_j) + Σ_j w_j, Σ_j w_j = 1
        rho = self._density(phi, rho_h, rho_l)
        divergence = 1.0 - s0  # Eq. 38: 1 − Σ_j f_j ≈ ∇·u
        if self.mixture and not sand_in_fsum:
            divergence = divergence + sand_pressure_terms(velocity, phi, eps, sand_v, slip, flags, self.two_phase)
        fluid = interior(flags) == FLUID
        new = interior(p).astype(np.float64) - CS2 * rho * divergence
        interior(p)[fluid] = new[fluid]

    def momentum(self, f, flags, velocity, out, parity: int, fsum=None, held: bool = False) -> None:
        """out = Σ_j f_j c_j of the current populations (Eq. 13 without the force shift) on interior fluid
        cells: the velocity "now", between two steps, as the sand–fluid exchange needs it; and ``fsum`` (if given)
        = Σ_j f_j − 1 = Σ_j (f_j − w_j) there, for :meth:`macro_pressure` (Eq. 38's 1 − Σ_j f_j with the sign
        turned), minus the value ``fsum`` held there with ``held`` (the fluid velocity's part of Eq. 39's slip
        term, :meth:`couplekit.coupling.reference.ReferenceOps.pressure_slip_fluid`).  ``out`` may be
        ``velocity`` itself (its wall cells are read, its fluid cells written)."""
        fi = self.load(f, flags, velocity, parity)
        u = np.einsum("jd,j...->d...", C27.astype(np.float64), fi)
        fluid = interior(flags) == FLUID
        for d in range(3):
            interior(out[d])[fluid] = u[d][fluid]
        if fsum is not None:
            s0 = fi.sum(axis=0) - 1.0
            if held:
                s0 = s0 - interior(fsum).astype(np.float64)
            interior(fsum)[fluid] = s0[fluid]

    def pressure_filter(self, p, flags, pbar, axes=(True, True, True)) -> None:
        """Eq. 40: p̄ = Σ_j w_j p(x + c_j) on interior fluid cells, with :func:`local_average`'s wall rules (the
        three-point rule on the walls normal to ``axes``, :func:`couplekit.fluid.grid.wall_rule_axes`)."""
        fluid = interior(flags) == FLUID
        interior(pbar)[fluid] = local_average(p, flags, three_point_links(flags, axes))[fluid]

    def forces(
        self, fi, flags, phi, eps, force, pbar, rho_h, rho_l, nu_h, nu_l, gravity, smagorinsky=0.0, chem=(0.0, 0.0)
    ):
        """Acceleration a (3, ...) of Eq. 15 and the shifted velocity u = Σ f c + a/2, for populations fi.

        a = F_μ/ρ − ∇p̄/ρ + F_s/ρ + g + F_ext/(ερ), with F_s = μ_φ ∇φ (Eq. 20; μ_φ of Eq. 22 from φ with
        ``chem`` = (β, κ), :func:`chemical_potential`) and the viscous correction
        F_μ = ν ∇^sym u · [∇ρ + (ρ/ε)∇ε] = (ν/ε) ∇^sym u · ∇(ερ) (Eq. 16). F_μ/ρ is Eq. 15's bracket term
        (ν/(ερ)) ∇^sym u · ∇(ερ), what the normalised LBM's ∇·[ν ∇^sym u] lacks of Eq. 3's ∇·[εμ ∇^sym u]/(ερ);
        Eq. 16 already holds the 1/ε, so F_μ is divided by ρ, not by ερ as Eq. 3's F_μ (another quantity) is.
        Until session 20 it was divided by ερ: 1/ε too strong in the sand's pores, where at a water lattice
        viscosity above ~0.2 the explicit term went unstable (docs/fluid-stability.md). ∇^sym u is estimated from the pre-collision
        non-equilibrium central second moments, ∇^sym u ≈ −3 r_s dev(κ_2) + (2/3)(1 − Σf) I (note §1a), about
        the velocity shifted by the other forces. Returns (a, u, r_s).

        ``smagorinsky`` = C > 0 adds the Smagorinsky subgrid viscosity ν_t = (C Δx)² |S̄|, |S̄| = √(2 S:S)
        (Hou et al. 1996), with the strain rate from the same deviatoric non-equilibrium moments,
        S = −dev(κ_2)/(2 c_s² τ): solving τ = τ0 + 3 ν_t(τ) gives τ = (τ0 + √(τ0² + 18√2 C² Q))/2 with
        Q = |dev κ_2| (its equilibrium is 0). ν and r_s of the collision and of F_μ then include ν_t.
        """
        s0 = fi.sum(axis=0)
        m = np.einsum("jd,j...->d...", C27.astype(np.float64), fi)
        rho = self._density(phi, rho_h, rho_l)
        nu = self._viscosity(phi, rho_h, rho_l, nu_h, nu_l) * np.ones(s0.shape)
        e = interior(eps).astype(np.float64) if self.mixture else 1.0
        a = -isotropic_gradient(pbar, flags, extrapolate=True) / rho
        a = a + np.asarray(gravity, np.float64).reshape(3, 1, 1, 1)
        if self.two_phase:
            grad_phi = isotropic_gradient(phi, flags)
            if self.surface_tension:
                a = a + chemical_potential(phi, flags, *chem) * grad_phi / rho
        if self.external_force:
            a = a + interior(force).astype(np.float64) / (e * rho)
        # pre-collision second central moments about the velocity shifted by the forces so far (all but F_μ)
        u0 = m + 0.5 * a
        kappa = moments.to_central(fi, u0).reshape((3, 3, 3) + s0.shape)
        k2 = np.empty((3, 3) + s0.shape)
        unit = np.eye(3, dtype=int)
        for i in range(3):
            for k in range(3):
                a_, b_, c_ = unit[i] + unit[k]
                k2[i, k] = kappa[a_, b_, c_]
        dev_k2 = k2 - np.eye(3).reshape(3, 3, 1, 1, 1) * (k2[0, 0] + k2[1, 1] + k2[2, 2]) / 3.0
        tau = nu / CS2 + 0.5
        if smagorinsky > 0:
            q = np.sqrt(np.einsum("ik...,ik...->...", dev_k2, dev_k2))
            tau = 0.5 * (tau + np.sqrt(tau * tau + 18.0 * np.sqrt(2.0) * smagorinsky**2 * q))
            nu = CS2 * (tau - 0.5)
        r_s = 1.0 / tau
        if self.two_phase or self.mixture:
            sym_grad = -3.0 * r_s * dev_k2
            sym_grad = sym_grad + np.eye(3).reshape(3, 3, 1, 1, 1) * (2.0 / 3.0) * (1.0 - s0)
            g = np.zeros((3,) + s0.shape)
            if self.two_phase:
                g = g + (rho_h - rho_l) * grad_phi
            if self.mixture:
                g = g + (rho / e) * isotropic_gradient(eps, flags)
            f_mu = nu * np.einsum("ik...,k...->i...", sym_grad, g)
            a = a + f_mu / rho  # Eq. 15: (ν/(ερ)) ∇^sym u · ∇(ερ) = F_μ/ρ
        return a, m + 0.5 * a, r_s

    @staticmethod
    def collide(fi: np.ndarray, u: np.ndarray, a: np.ndarray, r_s: np.ndarray, r_o=1.0) -> np.ndarray:
        """NOCM-MRT collision with forcing, Eqs. 9, 11, 12, in the polynomial central-moment basis.

        k* = k − R (k − k^eq) + (I − R/2) k^F, R = diag(r_j): r_s for k4…k8 (shear), ``r_o`` for the odd
        rows k10…k16, k23…k25 (third and fifth order; 1 in the paper, see :func:`odd_rate`), 1 for every
        other row, including k0 (the zeroth moment is reset to 1 each step, note §1a); k^F are the central
        moments of the Guo forcing term. Returns f* (27, ...).
        """
        k = np.einsum("ab,b...->a...", moments.BASIS, moments.to_central(fi, u))
        k_eq = moments.K_EQ.reshape((27,) + (1,) * (fi.ndim - 1))
        k_f = np.einsum("ab,b...->a...", moments.BASIS, moments.kappa_force(a))
        rates = np.ones((27,) + fi.shape[1:])
        for row in moments.SHEAR_ROWS:
            rates[row] = r_s
        for row in moments.ODD_ROWS:
            rates[row] = r_o
        k_star = k - rates * (k - k_eq) + (1.0 - rates / 2.0) * k_f
        return moments.from_central(np.einsum("ab,b...->a...", moments.BASIS_INV, k_star), u)

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
        """Fused collide + stream (Eqs. 8-10): forces, NOCM-MRT collision, AA store; writes u to ``velocity``.
        ``smagorinsky``: the Smagorinsky constant C of the subgrid viscosity (0 = off, the paper's model);
        ``odd_lambda``: the floor Λ of the odd-moment rate (:func:`odd_rate`; 0 = rate 1, the paper's), applied in
        cells whose molecular viscosity is below ``odd_nu_max``; ``chemical_potential``: (β, κ) of Eq. 22, given
        exactly when the ops have surface tension (the collide computes μ_φ from φ itself, no stored field);
        ``odd_ramp``: padded float32 weights s of rate 1 (:func:`ramped_odd_rates`), given exactly when the ops
        were built with ``odd_ramp=True``; ``prefilled``: :meth:`KernelOps.collide_stream`'s (the reference keeps
        no wall-link slots, so it changes nothing here)."""
        del prefilled
        check_closures(self, smagorinsky, odd_lambda)
        check_odd_ramp(self, odd_ramp)
        chem = check_chemical_potential(self, chemical_potential)
        fi = self.load(f, flags, velocity, parity)
        a, u, r_s = self.forces(
            fi, flags, phi, eps, force, pbar, rho_h, rho_l, nu_h, nu_l, (gx, gy, gz), smagorinsky, chem
        )
        nu = self._viscosity(phi, rho_h, rho_l, nu_h, nu_l)
        r_o = odd_rates(r_s, nu, min(nu_h, nu_l) if self.two_phase else nu_h, odd_lambda, odd_nu_max)
        r_o = ramped_odd_rates(r_o, None if odd_ramp is None else interior(odd_ramp))
        fstar = self.collide(fi, u, a, r_s, r_o)
        self.store(f, flags, velocity, parity, fstar)
        fluid = interior(flags) == FLUID
        for d in range(3):
            interior(velocity[d])[fluid] = u[d][fluid]

    @staticmethod
    def halo_copy(a, ghost, image) -> None:
        """Copy every component of ``a`` (…, Pz, Py, Px) from the interior images to the periodic ghosts."""
        flat = a.reshape(a.shape[: a.ndim - 3] + (-1,))
        flat[..., ghost] = flat[..., image]

    @staticmethod
    def outflow_fill(f, ghost, src, outward, du) -> None:
        """Before an odd (pull) step, outflow ghosts: every stored population of ghost g copied from its nearest
        interior cell s (zero gradient), and where s's post-collision momentum m = Σ_j f*_j c_j points into the
        domain across g's face (backflow), the populations g sends inward carry m with that normal part removed
        (:func:`backflow_velocity`, :func:`backflow_correction`; ``outward`` (3, n):
        :func:`couplekit.fluid.grid.outflow_directions`).  After an even step f*_j of s is stored in slot opp(j),
        so m = −Σ_k F[k] c_k over the copied slots.  ``du`` (3, n) receives each ghost's Δu, which
        :meth:`outflow_fix` applies after the step."""
        flat = f.reshape(27, -1)
        flat[:, ghost] = flat[:, src]
        slots = decode_f(flat[:, ghost])  # f − w: Σ_j w_j c_j = 0, so the momentum is the same
        m = -np.einsum("kd,kn->dn", C27.astype(np.float64), slots)
        du[...] = backflow_velocity(m, outward)
        corr = backflow_correction(du)  # (27, n): for f*_j, i.e. slot opp(j)
        back = np.any(corr != 0.0, axis=0)
        if back.any():
            new = slots[OPP27][:, back] + corr[:, back]  # f*_j + Δ_j, in direction order
            flat[np.ix_(OPP27, ghost[back])] = encode_f(new, "fp16" if f.dtype == np.float16 else "fp32")

    @staticmethod
    def outflow_fix(f, ghost, src, du) -> None:
        """After an odd (push) step, outflow ghosts: F[j][g + c_j] = F[j][s + c_j] where both are interior.

        The ghost g "pushes" what its nearest interior cell s pushed in the same direction (zero gradient), with the
        backflow :meth:`outflow_fill` found before the step (``du``) taken out.  Not from what s pushed now: the
        pushes toward a wall or inflow cell are not stored at that cell (bounce-back keeps them at s), so s's
        momentum cannot be summed from its neighbours' slots.
        """
        pz, py, px = f.shape[-3:]
        flat = f.reshape(27, -1)
        g, s = padded_coords(ghost, f.shape[-3:]), padded_coords(src, f.shape[-3:])

        def inside(p):
            x, y, z = p
            return (x >= 1) & (x <= px - 2) & (y >= 1) & (y <= py - 2) & (z >= 1) & (z <= pz - 2)

        def index(p):
            return p[0] + px * (p[1] + py * p[2])

        corr = backflow_correction(du)
        storage = "fp16" if f.dtype == np.float16 else "fp32"
        for j in range(1, 27):
            t, u = g + C27[j][:, None], s + C27[j][:, None]
            ok = inside(t) & inside(u)
            value = flat[j, index(u)[ok]]
            back = corr[j][ok] != 0.0
            if back.any():
                value = value.copy()
                value[back] = encode_f(decode_f(value[back]) + corr[j][ok][back], storage)
            flat[j, index(t)[ok]] = value

    @staticmethod
    def fold(f, ghost, image, boxes=None) -> None:
        """After an odd (push) step: move populations pushed into periodic ghosts to their images.

        For ghost g with image i and direction j, F[j][i] = F[j][g] when g − c_j is an interior cell (the push of
        the interior cell g − c_j wrote it).  ``boxes``: the kernels' form of the same pairs (unused here).
        """
        flat = f.reshape(27, -1)
        for j, inside in _pull_links(f, ghost):
            flat[j, image[inside]] = flat[j, ghost[inside]]

    @staticmethod
    def halo_pull(f, ghost, image, boxes=None) -> None:
        """Before an odd (pull) step: for ghost g with image i and direction j, F[j][g] = F[j][i] when g − c_j is
        an interior cell: the populations an odd step reads from a periodic ghost (the AA pattern's odd step of
        an interior cell c reads F[j] at c + c_j: :meth:`load`), the pairs :meth:`fold` moves back after it.  A
        ghost's other populations are read by no stage and keep what they hold.  ``boxes`` as in :meth:`fold`.
        """
        flat = f.reshape(27, -1)
        for j, inside in _pull_links(f, ghost):
            flat[j, ghost[inside]] = flat[j, image[inside]]
