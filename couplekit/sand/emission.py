"""Sand entering through an inflow: MPM particles emitted layer by layer at a jet's outlet (paper 000 Fig. 1).

A water inflow with ``sand_fraction`` s > 0 carries sand at volume fraction s through its open area A at the
inflow velocity u (normal component u_n): a sand volume flux s A u_n. :class:`InflowEmitter` turns that into
particles on a regular sub-lattice, deterministically:

* **In the face plane** the sites are the sub-lattice of the MPM grid that seeds bodies
  (:mod:`couplekit.sand.seeding`): spacing h = dx / k with k = particles per cell per axis, k² sites per open
  face cell, at the sub-cell centres. The open cells are the inflow's own cells (the outlet's mask,
  :func:`couplekit.faces.region_mask`, or the whole face), less the cells within ``bound`` cells of the
  face's edges, where the MPM domain walls are and where the quadratic stencil would leave the grid (a
  whole-face inflow loses that rim; a scene refuses an outlet carrying sand that reaches into it). The
  emission area A_e = sites × h² is what the flux uses.
* **Along the jet** an accumulator L (float64, per inflow) grows by u_n Δt every step; each time it passes h a
  layer of particles is emitted and L −= h. The layer stands for the slab of sand that entered during the last
  h / u_n: it is placed with its centre at L + h/2 beyond the *emission plane*, the plane ``bound`` cells inside
  the face (the first plane the MPM accepts particles on, like the 2-cell margin of sand bodies), so in a
  uniform jet consecutive layers are exactly h apart. After N steps, floor(u_n N Δt / h) layers have been
  emitted: the emitted volume is s A_e u_n t to within one layer.
* **Each particle** carries the grain-volume convention of seeded bodies (``couplekit.simulation``): a body
  particle has volume ε0 h³ (ε0 = ``sand.packing_fraction``) so that the body's sand fraction is ε0; an emitted
  particle has volume s h³, so the jet's sand fraction (Eq. 25) is s, with mass ϱ s h³ (ϱ the grain density,
  ``sand.density``). The alternative, body-sized particles (ε0 h³) on every (ε0 / s)-th layer, gives the same
  flux but sheets of sand ε0 / s sub-cells apart, not a jet of fraction s. A new particle moves with the
  inflow velocity (all three components), in its reference state (F = I, C = 0, no hardening,
  :meth:`couplekit.sand.solver.SandSolver.append_particles`).
* **Over time** a jet may start clean and carry sand from ``sand_start`` on, its fraction rising linearly to
  s over ``sand_ramp`` (paper Fig. 1: clean water first, then a jet whose sand ratio increases): a layer takes
  the fraction s(t) at the end of the step that completes it (volume s(t) h³ per particle), and no particle
  is emitted while s(t) = 0, though the accumulator runs from t = 0 so the layers keep their spacing.

The accumulators are the emitter's whole state (:meth:`InflowEmitter.state`), so a run resumed from a
checkpoint emits exactly the layers an uninterrupted run does, at the same float64 positions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..faces import PLANE_AXES, face_plane_shape, region_mask, solver_face

__all__ = [
    "JetSource",
    "InflowEmitter",
    "emission_sites",
    "expected_particles",
    "inflow_sites",
    "match_particle_count",
]

_AXIS = {"x": 0, "y": 1, "z": 2}
_ROUND_OFF = 1e-9
"""Relative slack of the layer test L >= h: a jet advancing exactly h in m steps (u_n Δt = h / m) emits on
step m, not m + 1, although the float64 sum of m increments may fall an ulp short of h."""


def emission_sites(
    grid: tuple[int, int, int], dx: float, face: str, mask: np.ndarray | None, per_axis: int, bound: int = 2
) -> np.ndarray:
    """In-plane sub-lattice sites (2, N) in metres of an inflow, in the face's in-plane axes (x, y, z order).

    ``grid``: interior shape (nz, ny, nx); ``face``: ``x-, x+, y-, y+, z-, z+``; ``mask``: the open cells of the
    face plane (:func:`couplekit.faces.face_plane_shape`; None: the whole face); ``per_axis``: k
    particles per cell per axis; ``bound``: cells along the face's edges left out (the MPM walls).
    Sites are ordered cell by cell (the face's cells row-major), then by sub-cell: a fixed particle order.
    """
    rows, cols = face_plane_shape(grid, face)  # rows: second in-plane axis, cols: first
    open_cells = np.ones((rows, cols), bool) if mask is None else np.asarray(mask, bool).copy()
    if open_cells.shape != (rows, cols):
        raise ValueError(f"mask has shape {open_cells.shape}, face {face} has {(rows, cols)}")
    open_cells[:bound, :] = open_cells[rows - bound :, :] = False
    open_cells[:, :bound] = open_cells[:, cols - bound :] = False
    k = int(per_axis)
    sub = (np.arange(k) + 0.5) * (dx / k)  # sub-cell centres within a cell
    jj, ii = np.nonzero(open_cells)  # open cells, row-major
    shape = (jj.size, k, k)  # (cell, second-axis sub-cell, first-axis sub-cell)
    u = np.broadcast_to(ii[:, None, None] * dx + sub[None, None, :], shape)
    v = np.broadcast_to(jj[:, None, None] * dx + sub[None, :, None], shape)
    return np.stack([u.reshape(-1), v.reshape(-1)])


def inflow_sites(inflow, grid: tuple[int, int, int], dx: float, per_axis: int, bound: int) -> tuple[str, np.ndarray]:
    """(solver face, :func:`emission_sites`) of a scene inflow (:class:`couplekit.scene.model.Inflow`): its
    outlet rasterised as the fluid does (:func:`couplekit.faces.region_mask`), or the whole face."""
    face = solver_face(inflow.face)
    mask = None
    if inflow.shape != "face":
        mask = region_mask(grid, dx, face, inflow.shape, inflow.center, inflow.size, inflow.radius)
    return face, emission_sites(grid, dx, face, mask, per_axis, bound)


@dataclass(frozen=True)
class JetSource:
    """One sand-carrying inflow, in SI units.

    ``face``: ``x-, x+, y-, y+, z-, z+``; ``sites``: in-plane positions (2, N) (:func:`emission_sites`);
    ``velocity``: inflow velocity (3,) m/s, its normal component pointing into the domain; ``sand_fraction``:
    s; ``spacing``: h = dx / k; ``offset``: distance of the emission plane from the face (bound · dx), m;
    ``density``: grain density ϱ, kg/m³; ``extent``: the domain's size along the face normal, m; ``start``,
    ``ramp``: the jet carries no sand before ``start`` (s), then a fraction rising linearly to ``sand_fraction``
    over ``ramp`` seconds (:meth:`fraction_at`).
    """

    face: str
    sites: np.ndarray
    velocity: tuple[float, float, float]
    sand_fraction: float
    spacing: float
    offset: float
    density: float
    extent: float
    start: float = 0.0
    ramp: float = 0.0

    def fraction_at(self, t: float) -> float:
        """The jet's sand fraction at time ``t``: 0 before ``start``, then rising linearly over ``ramp``."""
        if t < self.start:
            return 0.0
        if self.ramp <= 0.0 or t >= self.start + self.ramp:
            return self.sand_fraction
        return self.sand_fraction * (t - self.start) / self.ramp

    @property
    def axis(self) -> int:
        """The face normal's axis (0 = x, 1 = y, 2 = z)."""
        return _AXIS[self.face[0]]

    @property
    def normal_speed(self) -> float:
        """u_n: the inflow velocity's component into the domain, m/s (> 0)."""
        sign = 1.0 if self.face[1] == "-" else -1.0
        return sign * float(self.velocity[self.axis])

    @property
    def area(self) -> float:
        """Emission area A_e = sites × h², m²."""
        return self.sites.shape[1] * self.spacing**2

    @property
    def particle_volume(self) -> float:
        """Grain volume of one emitted particle at the full sand fraction, s h³ (module docstring), m³."""
        return self.sand_fraction * self.spacing**3

    @property
    def volume_flux(self) -> float:
        """Sand volume flux s A_e u_n, m³/s."""
        return self.sand_fraction * self.area * self.normal_speed

    def layer(self, depth: float) -> np.ndarray:
        """Positions (3, N) of a layer whose centre lies ``depth`` beyond the emission plane."""
        a0, a1 = PLANE_AXES[self.face[0]]
        d = self.offset + depth
        normal = d if self.face[1] == "-" else self.extent - d
        x = np.empty((3, self.sites.shape[1]))
        x[self.axis] = normal
        x[a0] = self.sites[0]
        x[a1] = self.sites[1]
        return x


class InflowEmitter:
    """Emits the particles of every :class:`JetSource` into a :class:`~couplekit.sand.solver.SandSolver`.

    Call :meth:`advance` after every time step of length Δt (the Simulation does, between scheduler steps):
    it adds u_n Δt to each source's accumulator and appends the layers that completed (module docstring).
    ``coupler``: a :class:`~couplekit.coupling.coupler.SandFluidCoupler` whose per-particle moisture ratio
    (water retention) grows with the particles (new particles start dry, r_p = 0, like seeded bodies).
    """

    def __init__(self, sources: Sequence[JetSource], coupler=None):
        self.sources = tuple(sources)
        self.coupler = coupler
        self.length = np.zeros(len(self.sources))
        """Per source: how far (m) the jet has advanced since its last emitted layer (float64)."""
        self.layers = np.zeros(len(self.sources), np.int64)
        """Per source: layers emitted so far (layers due while a jet carries no sand yet are skipped)."""
        self.volume = np.zeros(len(self.sources))
        """Per source: sand volume emitted so far, m³ (float64)."""
        self.steps = 0
        """Steps advanced: the time of :meth:`advance`'s layers is ``steps × Δt``."""

    @classmethod
    def from_scene(cls, scene, bound: int | None = None, coupler=None) -> InflowEmitter | None:
        """The emitter of a :class:`~couplekit.scene.Scene`'s inflows with ``sand_fraction`` > 0 (None if none):
        outlets rasterised as the fluid does (:func:`couplekit.faces.region_mask`), k =
        ``sand.particles_per_axis``, ϱ = ``sand.density``, the rim ``bound`` (default ``sand.wall_layers``)."""
        dom, sd = scene.domain, scene.sand
        bound = sd.wall_layers if bound is None else int(bound)
        sources = []
        for inf in scene.inflows:
            if inf.sand_fraction <= 0:
                continue
            k = sd.particles_per_axis
            face, sites = inflow_sites(inf, dom.shape, dom.dx, k, bound)
            sources.append(
                JetSource(
                    face,
                    sites,
                    tuple(float(v) for v in inf.velocity),
                    float(inf.sand_fraction),
                    dom.dx / k,
                    bound * dom.dx,
                    float(sd.density),
                    float(dom.size[_AXIS[face[0]]]),
                    float(inf.sand_start),
                    float(inf.sand_ramp),
                )
            )
        return cls(sources, coupler) if sources else None

    def advance(self, sand, dt: float) -> int:
        """Advance every jet by Δt and append the completed layers to ``sand``; returns particles added.

        A layer completed at time t = steps × Δt (after this step) carries the fraction s(t) of
        :meth:`JetSource.fraction_at`: particle volume s(t) h³; none while s(t) = 0."""
        self.steps += 1
        t = self.steps * dt
        added = 0
        for i, src in enumerate(self.sources):
            self.length[i] += src.normal_speed * dt
            depths = []
            while self.length[i] >= src.spacing * (1.0 - _ROUND_OFF):
                self.length[i] -= src.spacing
                depths.append(self.length[i] + 0.5 * src.spacing)
            s = src.fraction_at(t)
            if not depths or s <= 0.0:
                continue
            x = np.concatenate([src.layer(d) for d in reversed(depths)], axis=1)  # oldest layer first
            n = x.shape[1]
            volume = s * src.spacing**3
            sand.append_particles(x, volume, np.asarray(src.velocity), src.density, 0.0)
            self.layers[i] += len(depths)
            self.volume[i] += n * volume
            added += n
        if added and self.coupler is not None:
            match_particle_count(self.coupler, sand.n_particles)
        return added

    def emitted_volume(self) -> float:
        """Sand volume emitted so far, m³ (float64)."""
        return float(self.volume.sum())

    def emitted_particles(self) -> int:
        """Particles emitted so far."""
        return int(sum(n * s.sites.shape[1] for n, s in zip(self.layers, self.sources, strict=True)))

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict[str, np.ndarray]:
        """The accumulators, layer counts, emitted volumes and steps (a bitwise restart needs nothing else)."""
        return {
            "length": self.length.copy(),
            "layers": self.layers.copy(),
            "volume": self.volume.copy(),
            "steps": np.array(self.steps),
        }

    def load_state(self, st: dict) -> None:
        """Restore a :meth:`state` dict (same number of sources)."""
        length = np.asarray(st["length"], np.float64)
        if length.shape != self.length.shape:
            raise ValueError(f"emission state has {length.size} sources, this scene {self.length.size}")
        self.length = length.copy()
        self.layers = np.asarray(st["layers"], np.int64).copy()
        self.volume = np.asarray(st["volume"], np.float64).copy()
        self.steps = int(st["steps"])

    def __repr__(self) -> str:
        parts = ", ".join(f"{s.face}: {s.sites.shape[1]} sites, {s.volume_flux:.3g} m³/s" for s in self.sources)
        return f"InflowEmitter({parts})"


def expected_particles(emitter: InflowEmitter | None, duration: float) -> float:
    """Particles the emitter adds over ``duration`` seconds: Σ sites × ceil(u_n (t − start) / h) (an upper
    bound)."""
    if emitter is None:
        return 0.0
    return float(
        sum(
            s.sites.shape[1] * math.ceil(max(0.0, s.normal_speed * (duration - s.start)) / s.spacing)
            for s in emitter.sources
        )
    )


def match_particle_count(coupler, n: int) -> None:
    """Resize a coupler's per-particle moisture ratio r_p (water retention; nothing without) to ``n``
    particles: existing values kept, new particles dry (r_p = 0). Used after an emission and before a
    checkpoint's coupler state is loaded into a coupler built for fewer particles."""
    r = getattr(coupler, "moisture_ratio", None)
    if r is None or r.shape[0] == n:
        return
    xp = coupler.fluid.backend.xp
    grown = xp.zeros(n, dtype=np.float32)
    keep = min(n, r.shape[0])
    grown[:keep] = r[:keep]
    coupler.moisture_ratio = grown
