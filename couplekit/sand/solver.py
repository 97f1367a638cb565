"""SandSolver: the standalone MPM sand solver (dry sand, or sand with a given saturation per particle).

One step (paper 000 Alg. 1, MPM lines) is three stages, each an ops call:

1. :meth:`SandSolver.p2g` — node mass, momentum (with the stress impulse) and sand volume (Eqs. 24, 25, 27);
2. :meth:`SandSolver.grid_update` — node velocity with gravity (Eq. 29), then walls and colliders, in place:
   ``grid_v`` is the same array as ``grid_mv``, momentum before this stage and velocity after it (one
   3-vector per node instead of two).  Other forces on the nodes go into ``grid_mv`` as impulses between
   stages 1 and 2: the fluid coupling adds its drag impulse and Δt × buoyancy there (Eq. 26);
3. :meth:`SandSolver.g2p` — particle velocity, APIC affine matrix, F update with Drucker–Prager
   plasticity, Kirchhoff stress for the next P2G, advection (Eq. 30).

The grid is the LBM lattice: shape (nz, ny, nx), node (i, j, k) at ((i + ½) dx, (j + ½) dx, (k + ½) dx),
domain [0, nx dx] × [0, ny dx] × [0, nz dx].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..arguments import is_real, whole_count
from ..backend import Backend, get_backend
from ..slabs import host_slabs
from .boundaries import Collider, DomainWalls, SdfCollider, node_positions, pack_colliders, pack_walls
from .kernel_ops import KernelOps
from .params import SandParams
from .reference import ReferenceOps

__all__ = ["SandSolver", "TimeStepError", "EPS_MAX", "elastic_dt_limit"]

EPS_MAX = 0.64
"""Maximum sand volume fraction (random close packing; paper 000 Eq. 25, Baranau & Tallarek 2014)."""

_PARTICLE_FIELDS = ("x", "v", "C", "F", "tau", "q", "vc", "saturation", "mass", "volume")


class TimeStepError(ValueError):
    """Δt above the MPM stability limit."""


def _positive_number(name: str, value: Any, hint: str, hi: float = math.inf) -> float:
    """``value`` as a float in (0, ``hi``], else a ValueError naming ``name``, the value and ``hint``."""
    if not (is_real(value) and math.isfinite(value) and 0 < value <= hi):
        bounds = f"in (0, {hi:g}]" if math.isfinite(hi) else "> 0"
        raise ValueError(f"{name} must be a finite number {bounds} ({hint}), got {value!r}")
    return float(value)


def _as_floats(name: str, value: Any) -> np.ndarray:
    """``value`` as a float64 array, else a ValueError naming ``name`` (a string or a ragged list)."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None


def _least(a: np.ndarray) -> str:
    """The smallest of ``a``, for a message."""
    return f"{float(a.min()):g}" + ("" if a.size < 2 else f" (the smallest of {a.size})")


def _per_particle(name: str, value: Any, n: int, unit: str) -> np.ndarray:
    """``value`` (one number or one per particle, shape (n,)) as float64 (n,), refused with a ValueError naming
    ``name`` when it has another shape or a value that is not finite."""
    a = _as_floats(name, value)
    if a.ndim != 0 and a.shape != (n,):
        raise ValueError(
            f"{name} must be one number or one per particle, shape ({n},), got shape {a.shape}"
            + (f": transpose or flatten it to ({n},)" if a.size == n else "")
        )
    if not np.isfinite(a).all():
        if a.ndim == 0:
            raise ValueError(f"{name} must be a finite number ({unit}), got {float(a)!r}")
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise ValueError(f"{name} must be finite ({unit}): {bad} of {n} values are not")
    return np.broadcast_to(a, (n,))


class SandSolver:
    """MPM sand on a collocated grid.

    Parameters
    ----------
    backend: a :class:`~couplekit.backend.Backend` or a backend name (``"auto"``, ``"cuda"``, ``"cpu"``,
        ``"numpy"``); the numpy backend runs :class:`ReferenceOps`, the others :class:`KernelOps`.
    shape: grid shape (nz, ny, nx) — the LBM lattice's.
    dx: node spacing, m.   dt: time step, s (refused when above :meth:`max_stable_dt`).
    params: the sand material (:class:`SandParams`).
    positions: particle positions (3, P) in m (see :mod:`couplekit.sand.seeding`).
    volumes: particle volumes (P,) or one number, m³; particle mass = density × volume.
    densities: per-particle density (P,) or one number, kg/m³ (default ``params.density``), e.g. sand bodies
        of different densities in one scene; the elastic time-step limit uses the smallest (fastest c_p).
    velocities: initial particle velocities (3, P) or one 3-vector, m/s (default 0).
    gravity: m/s², default (0, 0, −9.81) (z up).
    walls: :class:`DomainWalls` (default: every face separating, friction 0.5, 2 node layers).
    colliders: analytic :class:`Collider` list; moving ones are advanced by Δt·velocity every step.
    sdf_collider: optional :class:`SdfCollider` sampled on the nodes (with the per-node friction of a
        :meth:`SdfCollider.union` of solids of different friction).
    saturation: per-particle saturation S_r,p (P,) driving the cohesion (default 0 = dry). Not allocated
        (``self.saturation`` None) when the cohesion is compiled out and no saturation is given, unless
        ``keep_saturation``; the hardening state ``q`` likewise without hardening. :meth:`particles` reports
        a field not allocated as zeros (made on the host).
    cfl: particle CFL number C_v (Δt ≤ C_v dx / max|v_p|); elastic_cfl: C_e (Δt ≤ C_e dx / c_p).
    cfl_check_every: check the particle CFL every this many steps (0 = never; a violation raises).
    host_atomics: cpu backend only — use the non-deterministic atomic P2G (benchmarking).
    allow_empty: accept zero particles (a scene whose sand only enters through an inflow, see
        :mod:`couplekit.sand.emission`); the stages then run on an empty particle set (the grid stays empty)
        until :meth:`append_particles` adds some.

    Growth: :meth:`append_particles` reallocates every particle array to the new count (one concatenation
    per call). The arrays stay exactly (·, P) C-contiguous, as the kernels index them (x[p], x[P + p], ...),
    so a capacity buffer with a live prefix would not be a valid (3, P) array; an emission adds a layer every
    few steps, and the copy costs about as much as one G2P over the same particles.
    """

    def __init__(
        self,
        backend: Backend | str | None,
        shape: Sequence[int],
        dx: float,
        dt: float,
        params: SandParams,
        positions: np.ndarray,
        volumes: np.ndarray | float,
        velocities: np.ndarray | Sequence[float] | None = None,
        gravity: Sequence[float] = (0.0, 0.0, -9.81),
        walls: DomainWalls | None = None,
        colliders: Sequence[Collider] = (),
        sdf_collider: SdfCollider | None = None,
        saturation: np.ndarray | float | None = None,
        densities: np.ndarray | float | None = None,
        cfl: float = 0.5,
        elastic_cfl: float = 0.5,
        cfl_check_every: int = 20,
        host_atomics: bool = False,
        allow_empty: bool = False,
        keep_saturation: bool = False,
    ):
        self.backend = backend if isinstance(backend, Backend) else get_backend(backend)
        be, xp = self.backend, self.backend.xp
        self.ops = KernelOps(be, host_atomics=host_atomics) if be.has_kernels else ReferenceOps()
        self.shape = tuple(int(s) for s in shape)
        if len(self.shape) != 3 or min(self.shape) < 5:
            raise ValueError(f"shape must be (nz, ny, nx) with every extent >= 5, got {shape}")
        if not isinstance(params, SandParams):
            raise TypeError(
                f"params must be a SandParams, got {type(params).__name__}: build one, e.g. "
                "SandParams(density=1500, youngs_modulus=1e5), from the values"
            )
        self.dx = _positive_number("dx", dx, "the node spacing in m")
        self.params = params
        self.model = params.model()
        g = _as_floats("gravity", gravity)
        if g.shape != (3,) or not np.isfinite(g).all():
            raise ValueError(f"gravity must be 3 finite numbers (x, y, z) in m/s², e.g. (0, 0, -9.81), got {gravity!r}")
        self.gravity = tuple(float(c) for c in g)
        self.walls = walls if walls is not None else DomainWalls.uniform("separate", 0.5)
        self.colliders = list(colliders)
        self.sdf_collider = sdf_collider
        # the CFL numbers bound dt (max_stable_dt): a NaN one made the limit NaN, and "dt > NaN" never refused
        self.cfl = _positive_number("cfl", cfl, "the particle CFL number C_v, usually 0.5", hi=1.0)
        self.elastic_cfl = _positive_number(
            "elastic_cfl", elastic_cfl, "the elastic CFL number C_e, usually 0.5", hi=1.0
        )
        self.cfl_check_every = whole_count("cfl_check_every", cfl_check_every, what="steps (0 = never)")
        self.time = 0.0
        self.steps = 0

        pos = np.asarray(positions, dtype=np.float64)
        if pos.ndim != 2 or pos.shape[0] != 3:
            raise ValueError(f"positions must have shape (3, P), got {pos.shape}")
        n = pos.shape[1]
        if n == 0 and not allow_empty:
            raise ValueError("no particles: the sand body is empty")
        pos, vol, vel, sat, rho = self._checked_particles(pos, volumes, velocities, saturation, densities)
        self.min_density = float(rho.min()) if n else float(params.density)
        """Smallest particle density, kg/m³ (sets the P-wave speed of the elastic time-step limit); with no
        particle yet, ``params.density``."""

        f32 = np.float32
        self.n_particles = n
        self.x = be.asarray(pos, f32)
        self.v = be.asarray(vel, f32)
        self.C = xp.zeros((9, n), dtype=f32)
        self.F = be.asarray(np.repeat(np.eye(3, dtype=f32).reshape(9, 1), n, axis=1), f32)
        self.tau = xp.zeros((6, n), dtype=f32)
        # fields of effects that are compiled out are not allocated (None; the kernels take a placeholder):
        # q without hardening; the saturation without cohesion, unless it was given (the particles carry
        # the seeded value as data) or ``keep_saturation`` (a coupled scene: the coupling's moisture writes it)
        self.q = xp.zeros(n, dtype=f32) if params.hardening else None
        self.vc = xp.zeros(n, dtype=f32)
        keep = params.cohesion_on() or keep_saturation or saturation is not None
        self.saturation = be.asarray(sat, f32) if keep else None
        self.volume = be.asarray(vol, f32)
        self.mass = be.asarray(vol * rho, f32)

        self.grid_m = xp.zeros(self.shape, dtype=f32)
        self.grid_mv = xp.zeros((3, *self.shape), dtype=f32)
        """Node momentum (kg m/s) from P2G to the grid update, which overwrites it with the node velocity."""
        # one density ϱ for every particle: the node volume is m_i / ϱ (node_volume), no volume grid is kept
        self._one_density = float(rho[0]) if n and bool(np.all(rho == rho[0])) else None
        if n == 0:
            self._one_density = float(params.density)  # until particles of another density arrive
        self.grid_vol = None if self._one_density is not None else xp.zeros(self.shape, dtype=f32)
        """The P2G's node sand volume Σ_p w_ip V_p (m³), or None where :attr:`node_volume` takes it from the mass."""
        self.grid_v = self.grid_mv
        """Node velocity (m/s) after the grid update: the same array as ``grid_mv`` (module docstring)."""

        self._walls = be.asarray(pack_walls(self.walls), f32)
        self._sdf = xp.zeros(self.shape if sdf_collider else (1,), dtype=f32)
        self._sdf_friction = None
        """Per-node friction of the SDF collider (None: its one ``friction``, read from ``_sdf_params``)."""
        self._sdf_params = be.asarray(sdf_collider.params() if sdf_collider else np.zeros(5), f32)
        self._upload_colliders()
        if sdf_collider is not None:
            self._sample_sdf()
        self.set_dt(dt)

    def _checked_particles(self, pos, volumes, velocities, saturation, densities):
        """Float64 (x, volume, v, saturation, density) of new particles, refused outside the domain interior
        [bound·dx, extent − bound·dx] or with non-positive volume or density."""
        n = pos.shape[1]
        nz, ny, nx = self.shape
        b = self.walls.bound
        ext = np.array([nx, ny, nz], dtype=np.float64) * self.dx
        inside = np.all((pos >= b * self.dx) & (pos <= (ext - b * self.dx)[:, None]), axis=0)
        if not inside.all():
            bad = int(np.count_nonzero(~inside))
            raise ValueError(
                f"{bad} of {n} particles lie outside the domain interior [{b}·dx, extent − {b}·dx] "
                f"(extent {ext.tolist()} m, walls take {b} node layers); enlarge the grid or move the body"
            )
        vol = _per_particle("volumes", volumes, n, "m³")
        if np.any(vol <= 0):
            raise ValueError(f"particle volumes must be > 0 m³, got {_least(vol)}")
        if velocities is None:
            vel = np.zeros((3, n))
        else:
            vel = _as_floats("velocities", velocities)
            if vel.shape == (3,):
                vel = vel[:, None]
            elif vel.shape != (3, n):
                hint = ": transpose it (velocities.T)" if vel.shape == (n, 3) else ""
                raise ValueError(
                    f"velocities must be one 3-vector (x, y, z) or one per particle, shape (3, {n}), got shape "
                    f"{vel.shape}{hint}"
                )
            if not np.isfinite(vel).all():
                raise ValueError("velocities must be finite (m/s): some components are NaN or infinite")
            vel = np.broadcast_to(vel, (3, n))
        if saturation is None:
            sat = np.zeros(n)
        else:
            sat = _per_particle("saturation", saturation, n, "water volume fraction")
            if not np.all((sat >= 0) & (sat <= 1)):
                bad = sat[(sat < 0) | (sat > 1)][0]
                raise ValueError(
                    f"saturation must be in [0, 1] (water per volume: 0 dry, at most 1 - packing fraction when the "
                    f"pores are full, e.g. 0.1 for moist sand), got {bad:g}"
                )
        dens = self.params.density if densities is None else densities
        rho = _per_particle("densities", dens, n, "kg/m³")
        if not np.all(rho > 0):
            raise ValueError(f"particle densities must be > 0 kg/m³, got {_least(rho)}")
        with np.errstate(over="ignore"):
            stored = np.concatenate([vol, vol * rho]).astype(np.float32)  # volume and mass as the solver holds them
        if not np.isfinite(stored).all():
            raise ValueError(
                f"particle volume and mass ϱ V must fit float32 (at most 3.4e38 m³ / kg), got up to "
                f"{float(np.max(vol)):.3g} m³ and {float(np.max(vol * rho)):.3g} kg: check the densities (kg/m³) "
                "and volumes (m³)"
            )
        return pos, vol, vel, sat, rho

    def append_particles(
        self,
        positions: np.ndarray,
        volumes: np.ndarray | float,
        velocities: np.ndarray | Sequence[float] | None = None,
        densities: np.ndarray | float | None = None,
        saturation: np.ndarray | float | None = None,
    ) -> int:
        """Add particles at rest in their reference configuration (F = I, C = 0, τ = 0, hardening q = 0,
        volume correction 0), e.g. sand entering through an inflow (:mod:`couplekit.sand.emission`).

        Arguments as in the constructor: positions (3, k) in m, inside the domain interior; volumes (k,) or one
        number, m³; velocities (3, k) or one 3-vector, m/s; densities (k,) or one number (default
        ``params.density``), kg/m³; saturation (k,) or one number (default 0). Every particle array is
        reallocated to the new count (class docstring). A density below :attr:`min_density` raises the P-wave
        speed: Δt is re-checked first and a violation is refused (TimeStepError) without changing anything.
        Returns the index of the first new particle.
        """
        pos = np.asarray(positions, dtype=np.float64)
        if pos.ndim != 2 or pos.shape[0] != 3:
            raise ValueError(f"positions must have shape (3, k), got {pos.shape}")
        first = self.n_particles
        k = pos.shape[1]
        if k == 0:
            return first
        pos, vol, vel, sat, rho = self._checked_particles(pos, volumes, velocities, saturation, densities)
        min_density = min(self.min_density, float(rho.min())) if first else float(rho.min())
        if min_density < self.min_density:
            old, self.min_density = self.min_density, min_density
            try:
                self._check_dt(self.dt)
            except TimeStepError:
                self.min_density = old
                raise
        self.min_density = min_density
        if self._one_density is not None and not bool(np.all(rho == self._one_density)):
            self._keep_volume_grid()
        f32 = np.float32
        new = {
            "x": pos,
            "v": vel,
            "C": np.zeros((9, k)),
            "F": np.repeat(np.eye(3).reshape(9, 1), k, axis=1),
            "tau": np.zeros((6, k)),
            "q": np.zeros(k),
            "vc": np.zeros(k),
            "saturation": sat,
            "volume": vol,
            "mass": vol * rho,
        }
        xp = self.backend.xp
        for name in self._fields():
            grown = xp.concatenate([getattr(self, name), self.backend.asarray(new[name], f32)], axis=-1)
            setattr(self, name, xp.ascontiguousarray(grown))
        self.n_particles = first + k
        return first

    @property
    def node_volume(self) -> tuple[Any, float]:
        """(array, scale): the node sand volume V_i = Σ_p w_ip V_p of the last P2G (Eq. 25's numerator, m³) is
        scale × array. Where every particle has one density ϱ, V_p = m_p / ϱ, so V_i = m_i / ϱ: the node mass and
        1/ϱ, and no volume grid is kept (4 B per node; the P2G scatters four fields instead of five). Else the
        P2G's own volume grid and 1. Particles of another density (:meth:`append_particles`, a loaded state)
        make the solver keep the volume grid from then on."""
        if self.grid_vol is not None:
            return self.grid_vol, 1.0
        return self.grid_m, 1.0 / self._one_density

    def _host_node_volume(self) -> np.ndarray:
        """:attr:`node_volume` as a float32 host array (m³)."""
        arr, scale = self.node_volume
        return (self.backend.to_host(arr).astype(np.float64) * scale).astype(np.float32)

    def _keep_volume_grid(self) -> None:
        """Keep the P2G's volume grid from now on (particles of more than one density), filled from the mass of
        the last P2G so that :attr:`node_volume` holds until the next one."""
        if self.grid_vol is None:
            arr, scale = self.node_volume
            self.grid_vol = (arr * np.float32(scale)).astype(np.float32)
            self._one_density = None

    # ------------------------------------------------------------------ time step
    @property
    def p_wave_speed(self) -> float:
        """c_p = sqrt((λ + 2μ)/ϱ) at the smallest particle density, m/s (the fastest elastic wave)."""
        return self.params.p_wave_speed * (self.params.density / self.min_density) ** 0.5

    def max_stable_dt(self) -> float:
        """Largest stable Δt: min(C_e dx / c_p, C_v dx / max|v_p|) (notes §4; c_p the P-wave speed)."""
        elastic = self.elastic_cfl * self.dx / self.p_wave_speed
        vmax = self._max_speed()
        return min(elastic, self.cfl * self.dx / vmax) if vmax > 0 else elastic

    def set_dt(self, dt: float) -> None:
        """Change Δt; refused (TimeStepError, with the limit) when above :meth:`max_stable_dt`."""
        if not (is_real(dt) and math.isfinite(dt) and dt > 0):
            raise TimeStepError(f"dt must be a finite number > 0 s, got {dt!r}")
        self._check_dt(float(dt))
        self.dt = float(dt)

    def _check_dt(self, dt: float) -> None:
        limit = self.max_stable_dt()
        if not dt <= limit:  # a NaN limit refuses too ("dt > NaN" never fired)
            elastic = self.elastic_cfl * self.dx / self.p_wave_speed
            vmax = self._max_speed()
            raise TimeStepError(
                f"MPM time step {dt:.4g} s exceeds the stability limit {limit:.4g} s "
                f"(elastic: {self.elastic_cfl} dx / c_p = {elastic:.4g} s with c_p = "
                f"{self.p_wave_speed:.4g} m/s; particle CFL: {self.cfl} dx / max|v| with max|v| = "
                f"{vmax:.4g} m/s); use dt <= {limit:.4g} s, or a softer sand / coarser grid"
            )

    # ------------------------------------------------------------------ stages
    def p2g(self) -> None:
        """Stage 1: particles -> grid mass, momentum (with stress impulse), sand volume."""
        self.ops.p2g(
            self.x,
            self.v,
            self.C,
            self.tau,
            self.mass,
            self.volume,
            self.grid_m,
            self.grid_mv,
            self.grid_vol,
            self.dx,
            self.dt,
        )

    def grid_update(self) -> None:
        """Stage 2: node velocities with gravity, then boundary conditions, in place (``grid_v is grid_mv``)."""
        self.ops.grid_update(
            self.grid_m,
            self.grid_mv,
            self.grid_v,
            self.dx,
            self.dt,
            self.gravity,
            self.walls.bound,
            self._walls,
            self._colliders,
            len(self.colliders),
            self._sdf,
            int(self.sdf_collider is not None),
            self._sdf_params,
            sdf_friction=self._sdf_friction,
        )

    SDF_DEPTH = 0.25
    """How deep (in cells) a particle may lie inside the grid SDF collider after G2P before it is pulled back
    (kernels/mpm_sdf_project.cu): sand at rest on a flat face settles 0.24 dx inside it."""

    def g2p(self) -> None:
        """Stage 3: grid -> particles, plasticity, advection; then moving colliders advance, and particles deeper
        than :attr:`SDF_DEPTH` cells in the grid SDF collider are pulled back to that depth
        (kernels/mpm_sdf_project.cu)."""
        self.ops.g2p(
            self.x,
            self.v,
            self.C,
            self.F,
            self.tau,
            self.q,
            self.vc,
            self.saturation,
            self.grid_v,
            self.dx,
            self.dt,
            self.model,
        )
        self.time += self.dt
        self.steps += 1
        moved = False
        for c in self.colliders:
            if c.moving:
                c.centre = c.centre + self.dt * c.velocity
                moved = True
        if moved:
            self._upload_colliders()
        if self.sdf_collider is not None:
            if self.sdf_collider.changes_after(self._sdf_time):
                self._sample_sdf()
            # particles that G2P left deeper than a quarter cell inside the collider back to that depth, where sand
            # resting on a flat face settles (kernels/mpm_sdf_project.cu)
            self.ops.sdf_project(self.x, self._sdf, self.dx, self.SDF_DEPTH * self.dx)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` MPM steps of Δt; ``n`` a whole number >= 0 (as :meth:`couplekit.simulation.Simulation.step`)."""
        for _ in range(whole_count("n", n)):
            self.p2g()
            self.grid_update()
            self.g2p()
            if self.cfl_check_every and self.steps % self.cfl_check_every == 0:
                self._check_dt(self.dt)

    # ------------------------------------------------------------------ outputs
    def particles(self) -> dict[str, np.ndarray]:
        """Host copies: x, v (3, P); C, F (9, P); tau (6, P); q (hardening), vc, saturation, mass, volume
        (P,); friction_angle (P,) in degrees."""
        out = {k: self.backend.to_host(getattr(self, k)) for k in self._fields()}
        for k in _PARTICLE_FIELDS:  # a field of an effect that is off: zeros, made here on the host
            out.setdefault(k, np.zeros(self.n_particles, np.float32))
        # float32 like every other particle array (the model computes in float64)
        out["friction_angle"] = np.degrees(self.model.friction_angle(out["q"])).astype(np.float32)
        return out

    def fields(self) -> dict[str, np.ndarray]:
        """Host copies of the grid fields of the last step: sand_fraction ε = min(ε_max, ΣV_p w_ip / V_cell)
        (Eq. 25), velocity (3, nz, ny, nx), mass, sand_volume. Before the first step (no P2G has run; a run's
        frame 0) those of the seeded particles (:meth:`seeded_grid`)."""
        if self.steps == 0:
            mass, mv, vol = self.seeded_grid()
            v = np.divide(mv, mass, out=np.zeros_like(mv), where=mass > 0).astype(np.float32)
            mass, vol = mass.astype(np.float32), vol.astype(np.float32)
        else:
            vol = self._host_node_volume()
            v, mass = self.backend.to_host(self.grid_v), self.backend.to_host(self.grid_m)
        return {"sand_fraction": np.minimum(EPS_MAX, vol / self.dx**3), "velocity": v, "mass": mass, "sand_volume": vol}

    def seeded_grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grid mass, momentum (3, ...) and sand volume of the particles as they are (Eq. 24's P2G without the
        stress impulse and the affine term; host float64): what a run's frame 0 shows of the sand before its
        first step computes the grid (else ε = 0 and no sand velocity there, beside particles that exist)."""
        scatter = self._seeded_scatter()
        m = self.backend.to_host(self.mass).astype(np.float64)
        v = self.backend.to_host(self.v).astype(np.float64)
        mv = np.stack([scatter(m * v[a]) for a in range(3)])
        return scatter(m), mv, scatter(self.backend.to_host(self.volume).astype(np.float64))

    def seeded_volume(self) -> np.ndarray:
        """The sand volume of :meth:`seeded_grid` alone (one scatter instead of five)."""
        return self._seeded_scatter()(self.backend.to_host(self.volume).astype(np.float64))

    def _seeded_scatter(self):
        """A function scattering a per-particle quantity onto the grid with the particles' B-spline weights
        (host float64), for :meth:`seeded_grid`."""
        from .reference import _stencil

        index, w, _ = _stencil(self.backend.to_host(self.x).astype(np.float64), self.dx, self.shape)
        size = int(np.prod(self.shape))

        def scatter(q: np.ndarray) -> np.ndarray:
            out = np.zeros(size)
            np.add.at(out, index.ravel(), (w * q[:, None]).ravel())
            return out.reshape(self.shape)

        return scatter

    def diagnostics(self) -> dict[str, float]:
        """Float64 sums over particles: mass, momentum_x/y/z, kinetic_energy (½ Σ m v²), max_speed; time, step."""
        m = self.backend.to_host(self.mass).astype(np.float64)
        v = self.backend.to_host(self.v).astype(np.float64)
        mom = (m * v).sum(axis=1)
        speed = np.sqrt((v**2).sum(axis=0)) if self.n_particles else np.zeros(1)
        return {
            "time": self.time,
            "step": float(self.steps),
            "mass": float(m.sum()),
            "momentum_x": float(mom[0]),
            "momentum_y": float(mom[1]),
            "momentum_z": float(mom[2]),
            "kinetic_energy": float(0.5 * (m * speed**2).sum()),
            "max_speed": float(speed.max()),
        }

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict[str, np.ndarray]:
        """Everything needed for a bitwise restart (host arrays; scalars as 0-d arrays), and the grid of the
        last step.

        The grid (``grid_m``, ``grid_vol``, ``grid_v``) is not needed by the restart (the next P2G overwrites
        it), but :meth:`fields` and the coupler's ``sand_fraction`` read it: without it a loaded solver
        reported ε = 0 and no grid velocity until its first step. It is stored sparsely, as the flat indexes
        of the nodes where any of the three is not +0.0 bit for bit (``grid_nodes``, int32 or int64) and the
        values there (``grid_m``, ``grid_vol`` (N,), ``grid_v`` (3, N)): 24 bytes per node the sand touches
        (28 beyond 2³¹ nodes), where a dense copy would cost 20 bytes per cell of the domain. Every other node
        is +0.0, as :meth:`load_state` restores it, so the grid comes back bit for bit."""
        st = {k: self.backend.to_host(getattr(self, k)) for k in self._fields()}
        st["time"] = np.array(self.time)
        st["steps"] = np.array(self.steps)
        st["dt"] = np.array(self.dt)
        st["min_density"] = np.array(self.min_density)
        st["one_density"] = np.array(np.nan if self._one_density is None else self._one_density)
        st["collider_centres"] = np.array([c.centre for c in self.colliders]).reshape(-1, 3)
        to_host = self.backend.to_host
        m = np.ascontiguousarray(to_host(self.grid_m), np.float32).reshape(-1)
        vol = self._host_node_volume().reshape(-1)  # the state keeps the node volume either way (its format is one)
        v = np.ascontiguousarray(to_host(self.grid_v), np.float32).reshape(3, -1)
        touched = (m.view(np.uint32) != 0) | (vol.view(np.uint32) != 0) | (v.view(np.uint32) != 0).any(axis=0)
        nodes = np.flatnonzero(touched)
        st["grid_nodes"] = nodes.astype(np.int32 if m.size < 2**31 else np.int64)
        st["grid_m"], st["grid_vol"], st["grid_v"] = m[nodes], vol[nodes], v[:, nodes]
        return st

    def load_state(self, st: dict, resize: bool = False) -> None:
        """Restore a :meth:`state` dict (same colliders; same particle count unless ``resize``, which
        reallocates the particle arrays to the state's count: a run whose inflows emitted particles). A state
        that does not fit is refused before anything of this solver changes."""
        n = np.asarray(st["x"]).shape[1]
        if n != self.n_particles and not resize:
            raise ValueError(f"state has {n} particles, this solver {self.n_particles}")
        centres = np.asarray(st["collider_centres"]).reshape(-1, 3)
        if len(centres) != len(self.colliders):
            raise ValueError(f"state has {len(centres)} colliders, this solver {len(self.colliders)}")
        # a field this solver does not allocate (its effect is off) is skipped: a checkpoint written before
        # those fields went unallocated still loads; one this solver has must be in the state
        for k in self._fields():
            if k not in st:
                raise ValueError(f"state has no {k!r}: it was written with an effect off that is on here")
            want = tuple(getattr(self, k).shape[:-1]) + (n,)
            if np.asarray(st[k]).shape != want:
                raise ValueError(f"state's {k!r} has shape {np.asarray(st[k]).shape}, expected {want}")
        grid = self._state_grid(st)
        # from here on nothing is refused
        if n != self.n_particles:
            xp = self.backend.xp
            for k in self._fields():
                setattr(self, k, xp.zeros(np.asarray(st[k]).shape[:-1] + (n,), dtype=np.float32))
            self.n_particles = n
        for k in self._fields():
            getattr(self, k)[...] = self.backend.asarray(np.asarray(st[k]), np.float32)
        self.time = float(st["time"])
        self.steps = int(st["steps"])
        self.dt = float(st["dt"])
        if "min_density" in st:
            self.min_density = float(st["min_density"])
        if self._one_density is not None and self._state_densities_differ(st):
            self._keep_volume_grid()
        for c, centre in zip(self.colliders, centres, strict=True):
            c.centre = centre.astype(np.float64)
        self._upload_colliders()
        if self.sdf_collider is not None:
            self._sample_sdf()
        self._set_grid(*grid)

    def _state_densities_differ(self, st: dict) -> bool:
        """Whether the particles of a loaded state are not all of this solver's one density: the state's
        ``one_density`` (NaN once its solver kept the volume grid), or, in a state written before that key (session
        23), the particles' mass over volume, which float32 rounds to ~6e-8 of ϱ (a density within 1e-5 of this
        one passes: such a state's restart is then not bitwise, its results the same to round-off)."""
        if "one_density" in st:
            rho = float(st["one_density"])
            return not rho == self._one_density  # NaN: several densities
        if not self.n_particles:
            return False
        ratio = self.backend.to_host(self.mass).astype(np.float64) / self.backend.to_host(self.volume)
        return not bool(np.abs(ratio / self._one_density - 1.0).max() <= 1e-5)  # NaN counts as different

    def _state_grid(self, st: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The grid of :meth:`state` as host arrays (m, vol, v) (sparse in the state: ``grid_nodes`` and the values
        there), +0.0 elsewhere; a state written before the grid was saved gives the whole grid +0.0, as a fresh
        solver holds it (the restart is the same: the next P2G overwrites the grid). Refuses a grid that does not
        fit this solver's."""
        size = int(np.prod(self.shape))
        m, vol, v = np.zeros(size, np.float32), np.zeros(size, np.float32), np.zeros((3, size), np.float32)
        if "grid_nodes" in st:
            nodes = np.asarray(st["grid_nodes"]).reshape(-1)
            n = nodes.shape[0]
            given = {k: np.asarray(st.get(k, np.zeros(0, np.float32))) for k in ("grid_m", "grid_vol", "grid_v")}
            if (
                nodes.dtype.kind not in "iu"
                or (n and (int(nodes.min()) < 0 or int(nodes.max()) >= size))
                or given["grid_m"].shape != (n,)
                or given["grid_vol"].shape != (n,)
                or given["grid_v"].shape != (3, n)
            ):
                raise ValueError(
                    f"state's sand grid (grid_nodes, grid_m, grid_vol, grid_v) does not fit this solver's grid "
                    f"{self.shape}"
                )
            m[nodes], vol[nodes], v[:, nodes] = given["grid_m"], given["grid_vol"], given["grid_v"]
        return m, vol, v

    def _set_grid(self, m: np.ndarray, vol: np.ndarray, v: np.ndarray) -> None:
        """Write :meth:`_state_grid`'s arrays into the solver's grid."""
        self.grid_m[...] = self.backend.asarray(m.reshape(self.shape), np.float32)
        if self.grid_vol is not None:  # else the node volume is the mass over the one density (node_volume)
            self.grid_vol[...] = self.backend.asarray(vol.reshape(self.shape), np.float32)
        self.grid_v[...] = self.backend.asarray(v.reshape((3, *self.shape)), np.float32)  # grid_v is grid_mv

    # ------------------------------------------------------------------ helpers
    def _fields(self) -> tuple[str, ...]:
        """The particle fields this solver allocates (:data:`_PARTICLE_FIELDS` less those of effects off)."""
        return tuple(k for k in _PARTICLE_FIELDS if getattr(self, k, None) is not None)

    def _max_speed(self) -> float:
        if self.n_particles == 0:
            return 0.0
        v = self.backend.to_host(self.v)
        return float(np.sqrt((v.astype(np.float64) ** 2).sum(axis=0).max()))

    def _upload_colliders(self) -> None:
        self._colliders = self.backend.asarray(pack_colliders(self.colliders), np.float32)

    def _sample_sdf(self) -> None:
        # by slabs of z: the nodes' float64 positions and the colliders' distances of the whole grid at once took
        # ~70 B per node above the 4 B kept
        phi = np.empty(self.shape, np.float32)
        mu_all = None
        for z0, z1 in host_slabs(self.shape, 8 * 3 * 4):
            slab, mu = self.sdf_collider.sample(node_positions(self.shape, self.dx, z0, z1), self.time)
            phi[z0:z1] = np.asarray(slab, dtype=np.float64).reshape((z1 - z0,) + self.shape[1:])
            if mu is not None:
                if mu_all is None:
                    mu_all = np.empty(self.shape, np.float32)
                mu_all[z0:z1] = mu.reshape((z1 - z0,) + self.shape[1:])
        self._sdf_time = self.time  # when this sample was taken (SdfCollider.changes_after)
        self._sdf = self.backend.asarray(phi, np.float32)
        self._sdf_friction = None if mu_all is None else self.backend.asarray(mu_all, np.float32)

    def __repr__(self) -> str:
        return (
            f"SandSolver({self.n_particles} particles, grid {self.shape}, dx={self.dx:g} m, dt={self.dt:g} s, "
            f"ops={self.ops.name})"
        )


def elastic_dt_limit(params: SandParams, dx: float, elastic_cfl: float = 0.5) -> float:
    """C_e dx / c_p without building a solver (for schedulers and scene validation)."""
    return elastic_cfl * dx / params.p_wave_speed
