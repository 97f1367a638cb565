"""The scene: typed dataclasses, loading from TOML, and every check that needs more than one key.

:meth:`Scene.load` (a TOML file) and :meth:`Scene.from_dict` (a dict, e.g. built in Python) run the schema
checks of :mod:`couplekit.scene.schema` and then the cross-key checks below, and raise one
:class:`~couplekit.scene.schema.SceneError` listing every problem (dotted key, what is wrong, the fix)
before anything is allocated:

* the grid: ``dx`` or ``resolution`` (not both, consistent with ``size``, whole number of cells);
* boundaries: periodic on both faces of an axis; an ``inflow`` face needs an ``[[inflows]]`` entry and an
  entry needs an ``inflow`` face (an inflow on a periodic face is refused); inflow velocity pointing in;
  an outlet (an inflow with ``shape = "rect"`` or ``"disc"``) lies on a wall or outflow face, inside the
  face, covers at least one cell and overlaps no other outlet;
* stirring: needs a [fluid]; its axis is not zero, its centre lies in the domain and its cylinder holds a cell
  centre (else it forces nothing);
* every number finite and in scale, no nesting deeper than :data:`~couplekit.scene.schema.MAX_DEPTH`
  (:mod:`couplekit.scene.schema`); a value that fails is None to every later check;
* bodies: every shape builds as the solvers build it (any exception of a mesh or height-file reader is a
  problem of ``bodies[i].geometry``); geometry inside the domain (sand at least two cells from each face,
  where the MPM walls are); files exist; what each body kind needs ([fluid] for water and inflows, sand keys
  only on sand bodies); every sand body gets particles outside the obstacles (:func:`_check_seeding`);
* sand: ``[sand.walls]`` names only faces, takes ``friction`` only on 'separate' faces; ``bodies[i].saturation``
  on sand bodies only, at most the pore volume 1 − ε0 and, with a fluid, only on a body that retains water,
  within its capacity (r = S / ε0 ≤ r_max); ``sand.grain_diameter`` at most ``dx``;
* ``time.max_speed`` at least every velocity the scene gives (bodies, inflows);
* time step: the lattice Mach number of the fastest expected flow (:class:`couplekit.units.Units`), the
  relaxation time of both viscosities, weak compressibility under gravity, the capillary time-step limit,
  and the MPM elastic and particle CFL limits (:func:`couplekit.sand.solver.elastic_dt_limit`).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..faces import PLANE_AXES, SCENE_FACES, face_extent, face_plane_shape, region_bounds, region_mask, solver_face
from ..lattice import CS2
from ..sand.emission import inflow_sites
from ..sand.params import friction_angle_range
from ..units import Units
from .geometry import Box, Cylinder, Difference, Inverted, Shape, Sphere, Transformed
from .schema import (
    BODY_KEYS,
    FACES,
    GEOMETRY_COMMON_KEYS,
    GEOMETRY_KEYS,
    GEOMETRY_SUBTRACT,
    INFLOW_KEYS,
    OUTLET_KEYS,
    REQUIRED,
    SAND_WALL_KEYS,
    SECTIONS,
    TOP_LEVEL,
    Problem,
    SceneError,
    parse_toml,
    read_table,
    read_toml,
    show,
    too_deep,
)

__all__ = [
    "Scene",
    "Domain",
    "Time",
    "Fluid",
    "Sand",
    "SandWall",
    "Body",
    "Geometry",
    "Inflow",
    "Stirring",
    "Outputs",
    "Effects",
    "Scheduler",
    "LIMITS",
]

LIMITS = {
    "min_lattice_viscosity": 1e-5,
    "max_lattice_viscosity": 1.0,
    "max_density_variation": 0.1,
    "sand_wall_cells": 2,
    "max_cells_per_axis": 2**31 - 1,
    "max_outlet_face_cells": 2**28,
}
"""Fixed limits of the cross checks (see docs/scene-reference.md, 'Time-step checks'):
lattice viscosity in [1e-5, 1] (τ in [0.50003, 3.5]; the paper's smallest is 1e-4, the NOCM-MRT scheme is
untested below a tenth of that); hydrostatic density variation g_lat·H_lat/c_s² ≤ 0.1 (weak compressibility);
sand kept 2 cells from each face (the MPM walls take two node layers); at most 2³¹ − 1 cells along an axis
(the kernels index an axis with 32-bit integers). Outlets are checked on the grid (a mask of their face) only
on faces of at most 2²⁸ cells: a larger face belongs to a grid of more than 10⁹ cells, which no device holds
(the memory estimate refuses it), and its mask alone would take gigabytes."""

_DEFAULT_LATTICE_VISCOSITY = {"water": 1e-4, "air": 1e-2}  # the most common Table 1 values


class FrozenDict(dict):
    """A read-only dict: the mappings inside a validated, frozen :class:`Scene` (``domain.boundary``,
    ``sand.walls``). Changing one in place would bypass validation and leave ``to_dict()`` (what a checkpoint
    stores) saying something else; build a changed scene with :func:`couplekit.simulation.with_settings`."""

    def _refuse(self, *args, **kwargs):
        raise TypeError(
            "a validated scene cannot be changed in place (its to_dict() and checkpoints would disagree): build a "
            "changed one with couplekit.with_settings(scene, {'domain.boundary.x_min': 'wall'}) or Scene.from_dict"
        )

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = __ior__ = _refuse

    def __reduce__(self):  # pickle and deepcopy without __setitem__
        return (type(self), (dict(self),))

    def __hash__(self) -> int:  # read-only, so a frozen Scene holding one hashes (a probe: hash(scene) failed)
        return hash(tuple(sorted(self.items())))


class FrozenList(list):
    """A read-only list: the lists inside a validated scene's :attr:`Scene.source` (see :class:`FrozenDict`)."""

    def _refuse(self, *args, **kwargs):
        FrozenDict._refuse(self)

    __setitem__ = __delitem__ = append = extend = insert = pop = remove = clear = sort = reverse = _refuse
    __iadd__ = __imul__ = _refuse

    def __reduce__(self):
        return (type(self), (list(self),))

    def __hash__(self) -> int:
        return hash(tuple(self))


def _frozen(x: Any) -> Any:
    """``x`` with every dict and list inside it read-only (:class:`FrozenDict`, :class:`FrozenList`)."""
    if isinstance(x, dict):
        return FrozenDict({k: _frozen(v) for k, v in x.items()})
    if isinstance(x, list):
        return FrozenList(_frozen(v) for v in x)
    return x


@dataclass(frozen=True)
class Domain:
    size: tuple[float, float, float]
    dx: float
    resolution: tuple[int, int, int]  # (nx, ny, nz)
    gravity: tuple[float, float, float]
    boundary: dict[str, str]

    @property
    def shape(self) -> tuple[int, int, int]:
        """Array shape (nz, ny, nx) of a field."""
        nx, ny, nz = self.resolution
        return (nz, ny, nx)

    @property
    def cells(self) -> int:
        return math.prod(int(n) for n in self.resolution)  # Python integers: no overflow at any size


@dataclass(frozen=True)
class Time:
    dt: float
    frame_duration: float
    frames: int
    max_speed: float | None
    mach_limit: float

    @property
    def steps_per_frame(self) -> int:
        """Whole steps per output frame (at least 1)."""
        return max(1, int(round(self.frame_duration / self.dt)))


MAX_STEPS_PER_FRAME = 10**8
"""Most steps per output frame a scene may ask for: at a billion cell-steps per second (a fast GPU) a 100³ grid
takes 10 days for that many steps; more is a unit mistake (a frame_duration in ms given as s, say)."""
MAX_TOTAL_STEPS = 10**10
"""Most steps in all (frames × steps per frame)."""


@dataclass(frozen=True)
class Fluid:
    phases: int
    water_density: float
    air_density: float
    water_lattice_viscosity: float
    air_lattice_viscosity: float
    surface_tension: float
    interface_width: float
    mobility: float
    controller_eta: float
    odd_lambda: float = 0.015
    smagorinsky: float = 0.1
    gravity: tuple[float, float, float] | None = None
    """The fluid's acceleration (None: domain.gravity)."""
    initial_pressure: str = "resting"
    storage: str = "fp32"
    """Storage precision of the populations f and h: 'fp32' or 'fp16' (couplekit.fluid.storage)."""
    odd_ramp: float = 0.0
    """Cells over which the odd-rate floor is ramped to the paper's rate 1 away from the walls (0: everywhere)."""


@dataclass(frozen=True)
class SandWall:
    """The sand's domain wall on one face (``[sand.walls]``): ``kind`` 'separate' (Coulomb ``friction``),
    'slip' or 'sticky' (couplekit.sand.boundaries)."""

    kind: str = "separate"
    friction: float = 0.5


@dataclass(frozen=True)
class Sand:
    density: float
    youngs_modulus: float
    poisson_ratio: float
    hardening: tuple[float, float, float, float]
    cohesion: float
    cohesion_saturation: tuple[float, float, float]
    particles_per_cell: int
    jitter: float
    seed: int
    wall_friction: float
    cfl: float
    elastic_cfl: float
    retention: bool
    absorption_rate: float
    max_moisture: float
    packing_fraction: float = 0.6
    """ε0: sand volume fraction of a seeded body (particle volume ε0 dx³ / particles_per_cell; ``density`` is
    the grain density, mass per grain volume)."""
    wall_layers: int = 2
    """Node layers of the MPM domain walls; sand keeps this many cells from each face."""
    periodic_walls: bool = False
    """Periodic faces allowed with sand (the sand meets a wall there)."""
    absorption_time: float | None = None
    """``sand.absorption_time`` (s) when the scene gave R_a that way; ``absorption_rate`` is then time.dt / it."""
    walls: dict[str, SandWall] = field(default_factory=dict)
    """The sand's wall on every face (scene names x_min … z_max); faces not in ``[sand.walls]`` are 'separate'
    with ``wall_friction``."""
    grain_diameter: float | None = None
    """Drag option: None for paper 000's one-ball drag area, a grain diameter (m) for the grains' area."""
    viscosity: float = 0.0
    """Viscoplastic overstress η (Pa s) of the plastic flow (SandParams.viscosity); 0: rate-independent."""

    @property
    def particles_per_axis(self) -> int:
        return round(self.particles_per_cell ** (1 / 3))

    def p_wave_speed(self, density: float | None = None) -> float:
        """c_p = sqrt((λ + 2μ)/ϱ) of this material (at ``density`` if given)."""
        e, nu = self.youngs_modulus, self.poisson_ratio
        modulus = e * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
        return math.sqrt(modulus / (density or self.density))


SAMPLE_SPACING_CELLS = 0.25
"""Surface sampling of mesh and height-field SDFs, in cells (:meth:`Geometry.solver_shape`): what the solvers
build and validation builds, so that both read and sample a file the same way."""


@dataclass(frozen=True)
class Geometry:
    """A checked ``geometry`` table; :meth:`shape` builds the SDF (files resolved against ``base_dir``).

    Built shapes are kept (per domain and sample spacing): validation builds each body's shape once, and the
    solvers take the same object instead of reading a mesh file again. The cache is not pickled or copied."""

    type: str
    params: dict[str, Any]
    scale: float = 1.0
    rotate: tuple[float, float, float] = (0.0, 0.0, 0.0)
    translate: tuple[float, float, float] = (0.0, 0.0, 0.0)
    invert: bool = False
    subtract: tuple[Geometry, ...] = ()
    """Shapes cut out of this one (``subtract = [{...}, ...]``: a colander's holes, a ring wall), each in world
    coordinates with its own transforms."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "_shapes", {})

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "_shapes"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.__dict__["_shapes"] = {}

    @staticmethod
    def _domain_key(domain: Domain | None):
        return None if domain is None else (tuple(domain.size), float(domain.dx))

    def shape(self, domain: Domain | None = None, sample_spacing: float | None = None) -> Shape:
        """The solid as a :class:`~couplekit.scene.geometry.Shape` in world coordinates (built once per domain
        and sample spacing)."""
        cache = self.__dict__.setdefault("_shapes", {})
        key = (self._domain_key(domain), sample_spacing)
        if key not in cache:
            cache[key] = self._build_shape(domain, sample_spacing)
        return cache[key]

    def solver_shape(self, domain: Domain) -> Shape:
        """The shape the solvers use: surfaces sampled every :data:`SAMPLE_SPACING_CELLS` cells."""
        return self.shape(domain, SAMPLE_SPACING_CELLS * domain.dx)

    def _build_shape(self, domain: Domain | None, sample_spacing: float | None) -> Shape:
        from .mesh import HeightField, load_heights, load_mesh

        p = self.params
        if self.type == "box":
            s: Shape = Box(p["min"], p["max"])
        elif self.type == "sphere":
            s = Sphere(p["center"], p["radius"])
        elif self.type == "cylinder":
            s = Cylinder(p["center"], p["radius"], p["height"], p["axis"])
        elif self.type == "heightfield":
            h = np.asarray(p["heights"]) if p.get("heights") is not None else load_heights(p["file"])
            base = p.get("base")
            if base is None:
                base = -(domain.dx if domain else 1e-3)
            s = HeightField(h, p["x_range"], p["y_range"], base, sample_spacing)
        elif self.type == "mesh":
            # the surface is sampled in the file's own units, which `scale` turns into metres: dx/4 in the world
            # is dx/(4 scale) there (a probe: a cube in mm with scale 0.001 was sampled every dx/4 mm, 1000x
            # too finely, and refused at run time after validating; at scale 0.1 one SDF pass took 57 s)
            s = load_mesh(p["file"], None if sample_spacing is None else sample_spacing / self.scale)
        else:
            raise ValueError(f"unknown geometry type {self.type!r}")
        if self.scale != 1.0 or any(self.rotate) or any(self.translate):
            s = Transformed(s, self.scale, self.rotate, self.translate)
        if self.invert:
            if domain is None:
                raise ValueError("an inverted shape needs the domain for its bounds")
            s = Inverted(s, (0.0, 0.0, 0.0), domain.size)
        if self.subtract:
            s = Difference(s, [g.shape(domain, sample_spacing) for g in self.subtract])
        return s

    def bounds(self, domain: Domain | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds in world coordinates (a mesh file is read to get them, unless a shape was built
        for this domain already: the sample spacing changes the distance search only, not the bounds)."""
        dkey = self._domain_key(domain)
        for (d, _spacing), built in self.__dict__.get("_shapes", {}).items():
            if d == dkey:
                return built.bounds()
        return self.shape(domain).bounds()


@dataclass(frozen=True)
class Body:
    kind: str
    name: str
    geometry: Geometry
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    density: float | None = None
    retention: bool | None = None
    friction: float | None = None
    saturation: float | None = None
    """Sand bodies: initial saturation of the particles (None: dry)."""
    container_until: float | None = None
    """Sand bodies: time (s) at which the invisible container around the body's bounding box is removed (None:
    no container; :func:`couplekit.assembly.build_sand`)."""


@dataclass(frozen=True)
class Inflow:
    """A velocity inlet: the whole ``face`` (``shape = "face"``) or an outlet in it (``"rect"``: ``center``,
    ``size``; ``"disc"``: ``center``, ``radius``; face coordinates in metres, see
    :mod:`couplekit.fluid.inflow`)."""

    face: str
    kind: str
    velocity: tuple[float, float, float]
    sand_fraction: float = 0.0
    shape: str = "face"
    center: tuple[float, float] | None = None
    size: tuple[float, float] | None = None
    radius: float | None = None
    sand_start: float = 0.0
    """Time (s) at which the jet starts carrying sand (couplekit.sand.emission)."""
    sand_ramp: float = 0.0
    """Time (s) over which its sand fraction rises from 0 to ``sand_fraction`` after ``sand_start``."""


@dataclass(frozen=True)
class Stirring:
    """A swirling body force on the water in a cylinder (paper 000 Fig. 11), SI units: tangential
    acceleration ``acceleration × r / radius`` about the axis through ``center`` along ``axis`` (unit),
    within ``radius`` and ``length`` (None: unbounded) of it, on steps starting in [start, start + duration)
    (duration None: to the end). See :mod:`couplekit.scene.forces`."""

    center: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius: float
    length: float | None
    acceleration: float
    start: float = 0.0
    duration: float | None = None


@dataclass(frozen=True)
class Outputs:
    directory: str | None
    fields: tuple[str, ...]
    vtk: bool
    ply: bool
    preview: bool
    preview_every: int
    checkpoint_every: int
    diagnostics: bool
    surface: bool = True
    """Write the water surface mesh of every frame (two-phase fluids; :mod:`couplekit.io.surface`)."""
    surface_format: tuple[str, ...] = ("ply",)
    """Renderer formats of the surface meshes ('ply', 'obj'); the ParaView .vtp comes with ``vtk``."""
    preview_colour: str = "auto"
    """What colours the sand in the previews: 'wetness', 'speed' or 'auto' (:mod:`couplekit.io.preview`)."""


@dataclass(frozen=True)
class Scheduler:
    """How the fluid and the sand are stepped (:mod:`couplekit.schedulers`): ``kind`` 'lockstep', 'subcycle'
    (``substeps`` k or 'auto', capped at ``max_substeps``, fluid data ``interpolation`` 'hold' or 'linear') or
    'multirate' (one sand step per ``sand_every`` fluid steps)."""

    kind: str = "lockstep"
    substeps: int | str = "auto"
    max_substeps: int = 64
    interpolation: str = "hold"
    sand_every: int = 1

    @property
    def sand_dt_factor(self) -> float | None:
        """The sand's Δt over time.dt: 1 (lockstep), 1/k (subcycle, fixed k), m (multirate); None with
        substeps = 'auto' (chosen every step)."""
        if self.kind == "subcycle":
            return None if self.substeps == "auto" else 1.0 / int(self.substeps)
        if self.kind == "multirate":
            return float(self.sand_every)
        return 1.0

    def describe(self) -> str:
        """One line for summaries."""
        if self.kind == "subcycle":
            k = "auto" if self.substeps == "auto" else str(self.substeps)
            cap = f" (at most {self.max_substeps})" if self.substeps == "auto" else ""
            return f"subcycle, {k} MPM substeps per LBM step{cap}, fluid data {self.interpolation}"
        if self.kind == "multirate":
            return f"multirate, one MPM step per {self.sand_every} LBM steps"
        return "lockstep (one MPM step per LBM step, paper Algorithm 1)"


@dataclass(frozen=True)
class Effects:
    surface_tension: bool = True
    volume_controller: bool = True
    source_term: bool = True
    drag: bool = True
    buoyancy: bool = True
    cohesion: bool = True
    hardening: bool = True


@dataclass(frozen=True)
class Scene:
    """A validated scene (SI units). Build it with :meth:`load` or :meth:`from_dict`; never half-valid."""

    name: str
    description: str
    domain: Domain
    time: Time
    fluid: Fluid | None
    sand: Sand | None
    bodies: tuple[Body, ...]
    inflows: tuple[Inflow, ...]
    outputs: Outputs
    effects: Effects
    stirring: Stirring | None = None
    scheduler: Scheduler = field(default_factory=Scheduler)
    source: dict = field(default_factory=dict, compare=False, repr=False)
    """The checked input dict with file paths made absolute (kept in checkpoints to rebuild the scene)."""

    # ------------------------------------------------------------------------------------ construction
    @classmethod
    def load(cls, path: str | Path) -> Scene:
        """Read and validate a TOML scene file; raises :class:`SceneError` naming every problem."""
        if not isinstance(path, (str, Path)):
            raise TypeError(f"Scene.load takes a file path, got {type(path).__name__} (a dict: Scene.from_dict)")
        path = Path(path)
        return cls.from_dict(read_toml(path, SceneError), base_dir=path.parent, source_name=str(path))

    @classmethod
    def loads(cls, text: str, name: str = "<string>", base_dir: str | Path = ".") -> Scene:
        """Read and validate a scene given as TOML text: :meth:`load` of a string.

        The same checks and messages as :meth:`load`, with ``name`` (default ``"<string>"``) where those name
        the file; relative mesh and height-field files resolve against ``base_dir`` (default the working
        directory), as :meth:`load`'s resolve against the file's folder."""
        return cls.from_dict(parse_toml(text, name, SceneError), base_dir=base_dir, source_name=name)

    @classmethod
    def from_dict(cls, data: dict, base_dir: str | Path = ".", source_name: str = "scene") -> Scene:
        """Validate a scene given as a dict (the TOML structure); relative files resolve against ``base_dir``.
        Python and NumPy values a script has at hand are taken as TOML's: a tuple or a NumPy array as a list, a
        NumPy number as the number (``size = np.array([...])``, ``frames = np.int64(2)``)."""
        if not isinstance(base_dir, (str, os.PathLike)):
            raise TypeError(f"base_dir must be a folder path (a str or a pathlib.Path), got {type(base_dir).__name__}")
        deep = too_deep(data)  # before anything walks the dict recursively (copying it, printing a value)
        if deep is not None:
            raise SceneError([deep], source_name)
        problems: list[Problem] = []
        scene = _build(_toml_values(data), Path(base_dir), problems)
        if problems or scene is None:
            raise SceneError(problems, source_name)
        return scene

    def to_dict(self) -> dict:
        """The scene as a TOML-structured dict (file paths absolute); ``from_dict`` of it gives this scene."""
        return _deep_copy(self.source)

    # ------------------------------------------------------------------------------------ derived
    @property
    def has_fluid(self) -> bool:
        """A fluid is simulated (a ``[fluid]`` table: water and air, or one phase filling the domain)."""
        return self.fluid is not None

    @property
    def has_sand(self) -> bool:
        """Sand bodies, or a water jet carrying sand (``inflows[*].sand_fraction`` > 0: emitted particles)."""
        return any(b.kind == "sand" for b in self.bodies) or self.emits_sand

    @property
    def emits_sand(self) -> bool:
        """Some inflow carries sand (:mod:`couplekit.sand.emission` emits it as particles)."""
        return any(i.sand_fraction > 0 for i in self.inflows)

    def units(self) -> Units:
        """The lattice unit system (dx, dt, ρ_ref = water density)."""
        rho = self.fluid.water_density if self.fluid else 1000.0
        return Units(dx=self.domain.dx, dt=self.time.dt, rho=rho)

    def expected_max_speed(self) -> tuple[float, str]:
        """(speed m/s, what it comes from) used by the Mach and particle-CFL checks."""
        domain = self.domain
        if self.fluid is not None and self.fluid.gravity is not None:
            domain = replace(domain, gravity=tuple(float(v) for v in self.fluid.gravity))
        return _speed_estimate(domain, self.time, self.bodies, self.inflows, {})

    def summary(self) -> str:
        """A few lines: grid, time, physics present."""
        d, t = self.domain, self.time
        kinds = {k: sum(b.kind == k for b in self.bodies) for k in ("water", "sand", "obstacle")}
        lines = [
            f"scene {self.name}: grid {d.resolution[0]}x{d.resolution[1]}x{d.resolution[2]} ({d.cells:,} cells), dx = {d.dx:g} m",
            f"time: dt = {t.dt:g} s, {t.steps_per_frame} steps per frame ({t.steps_per_frame * t.dt:g} s), {t.frames} frames",
            f"bodies: {kinds['water']} water, {kinds['sand']} sand, {kinds['obstacle']} obstacle; inflows: {len(self.inflows)}",
            f"fluid: {'none' if not self.fluid else f'{self.fluid.phases} phase(s)'}; sand: {'yes' if self.has_sand else 'none'}",
        ]
        if self.has_sand:
            lines.append(f"scheduler: {self.scheduler.describe()}")
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- building
def _toml_values(x: Any) -> Any:
    """``x`` with tuples and NumPy arrays as lists and NumPy scalars as Python numbers (a probe, session 25: a tuple
    ``size`` or an ``np.int64`` frame count was refused where the rest of the API takes them); anything else as is,
    for the schema to judge."""
    if isinstance(x, dict):
        return {k: _toml_values(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_toml_values(v) for v in x]
    if isinstance(x, np.ndarray):
        return _toml_values(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def _deep_copy(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _deep_copy(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_deep_copy(v) for v in x]
    return x


def _build(data: Any, base_dir: Path, problems: list[Problem]) -> Scene | None:
    if not isinstance(data, dict):
        problems.append(Problem("(scene)", "a scene must be a table of tables", "start from an example in examples/"))
        return None
    source = _deep_copy(data)
    for name in data:
        if name not in TOP_LEVEL:
            import difflib

            close = difflib.get_close_matches(name, TOP_LEVEL, n=1) if isinstance(name, str) else []
            problems.append(
                Problem(
                    name if isinstance(name, str) else show(name),
                    "unknown table",
                    f"did you mean [{close[0]}]?" if close else f"remove it; the tables are {', '.join(TOP_LEVEL)}",
                )
            )
    for required in ("domain", "time"):
        if required not in data:
            problems.append(Problem(required, "is required", f"add a [{required}] table"))
    n_before = len(problems)

    sc = read_table(data.get("scene", {}), "scene", SECTIONS["scene"], problems)
    name = sc.get("name")
    if isinstance(name, str) and (name in ("", ".", "..") or "/" in name or "\\" in name):
        problems.append(
            Problem(
                "scene.name",
                f"{name!r} is not a plain folder name: the default output folder runs/<name> would lie elsewhere",
                "use letters, digits, '-', '_' and '.' (no '/', '\\' or '..'); set outputs.directory for the folder",
            )
        )
    dom_raw = data.get("domain", {})
    dom_raw = dict(dom_raw) if isinstance(dom_raw, dict) else dom_raw
    boundary_raw = dom_raw.pop("boundary", {}) if isinstance(dom_raw, dict) else {}
    # [[domain]] or domain = 1 is read as given, so that it is said to be no table (as for every other table)
    dom = read_table(dom_raw, "domain", SECTIONS["domain"], problems)
    bnd = read_table(boundary_raw, "domain.boundary", SECTIONS["domain.boundary"], problems)
    tim = read_table(data.get("time", {}), "time", SECTIONS["time"], problems)
    flu = read_table(data["fluid"], "fluid", SECTIONS["fluid"], problems) if "fluid" in data else None
    snd_raw = data.get("sand", {})
    walls_raw = None
    if isinstance(snd_raw, dict) and "walls" in snd_raw:  # [sand.walls]: a table of faces, read by _sand_walls
        snd_raw = dict(snd_raw)
        walls_raw = snd_raw.pop("walls")
    snd = read_table(snd_raw, "sand", SECTIONS["sand"], problems)
    out = read_table(data.get("outputs", {}), "outputs", SECTIONS["outputs"], problems)
    eff = read_table(data.get("effects", {}), "effects", SECTIONS["effects"], problems)
    sch_raw = data.get("scheduler", {})
    sch = read_table(sch_raw, "scheduler", SECTIONS["scheduler"], problems)

    # ---- domain
    domain = None
    if dom["size"] is not None:
        size = dom["size"]
        dx, res = dom["dx"], dom["resolution"]
        if dx is None and res is None and "dx" not in dom_raw and "resolution" not in dom_raw:
            problems.append(
                Problem(
                    "domain.dx",
                    "neither dx nor resolution is given",
                    "add dx = <cell size in m> (or resolution = [nx, ny, nz])",
                )
            )
        elif "dx" in dom_raw and "resolution" in dom_raw:
            problems.append(
                Problem(
                    "domain.resolution",
                    "both dx and resolution are given",
                    "keep one of domain.dx and domain.resolution",
                )
            )
        elif dx is not None:
            counts = [s / dx for s in size]  # finite: size and dx are > 0 and within the schema's magnitudes
            res = [int(round(c)) for c in counts]
            for i, (c, n) in enumerate(zip(counts, res, strict=True)):
                if n > LIMITS["max_cells_per_axis"]:
                    problems.append(
                        Problem(
                            f"domain.size[{i}]",
                            f"{size[i]:g} m is {c:.4g} cells of dx = {dx:g} m, more than the solvers index along "
                            f"one axis ({LIMITS['max_cells_per_axis']})",
                            "use a larger domain.dx or a smaller domain.size",
                        )
                    )
                elif abs(c - n) > 1e-6 * max(1.0, c):
                    problems.append(
                        Problem(
                            f"domain.size[{i}]",
                            f"{size[i]:g} m is not a whole number of cells of dx = {dx:g} m ({c:.4f})",
                            f"use size[{i}] = {max(n, 1) * dx:.6g}",
                        )
                    )
                elif n < 5:
                    problems.append(
                        Problem(
                            f"domain.size[{i}]",
                            f"only {n} cells along {'xyz'[i]} (at least 5 are needed)",
                            f"make size[{i}] >= {5 * dx:g} m or dx smaller",
                        )
                    )
        elif res is not None:
            dxs = [s / n for s, n in zip(size, res, strict=True)]  # n >= 5 (schema)
            for i, n in enumerate(res):
                if n > LIMITS["max_cells_per_axis"]:
                    problems.append(
                        Problem(
                            f"domain.resolution[{i}]",
                            f"{n} cells, more than the solvers index along one axis ({LIMITS['max_cells_per_axis']})",
                            "use fewer cells",
                        )
                    )
            if max(dxs) - min(dxs) > 1e-6 * max(dxs):
                problems.append(
                    Problem(
                        "domain.resolution",
                        f"cells are not cubic: size/resolution = {', '.join(f'{d:.6g}' for d in dxs)} m",
                        "choose resolution proportional to size (or give dx)",
                    )
                )
            dx = dxs[0]
        if dx is not None and res is not None and len(problems) == n_before:
            domain = Domain(
                tuple(size),
                float(dx),
                tuple(int(n) for n in res),
                tuple(dom["gravity"] or (0, 0, -9.81)),
                FrozenDict(bnd),
            )

    # ---- boundaries: periodic pairs
    for axis in "xyz":
        lo, hi = bnd[f"{axis}_min"], bnd[f"{axis}_max"]
        if lo and hi and (lo == "periodic") != (hi == "periodic"):
            problems.append(
                Problem(
                    f"domain.boundary.{axis}_{'max' if lo == 'periodic' else 'min'}",
                    f"{axis}_min is {lo!r} but {axis}_max is {hi!r}; periodic needs both faces of an axis",
                    f"set both domain.boundary.{axis}_min and {axis}_max to 'periodic', or neither",
                )
            )

    # ---- fluid
    fluid = None
    if flu is not None:
        fluid = _fluid(flu, data["fluid"] if isinstance(data["fluid"], dict) else {}, domain, tim, problems)

    # ---- sand material
    sand = _sand(snd, problems)
    if sand is not None:
        sand = _with_sand_walls(_with_absorption_time(sand, snd_raw, tim["dt"], problems), walls_raw, problems)

    # ---- bodies
    bodies, body_ids = [], []  # the bodies that were read, and their index in [[bodies]]
    raw_bodies = data.get("bodies", [])
    if not isinstance(raw_bodies, list):
        problems.append(Problem("bodies", "must be an array of tables", "write each body as [[bodies]] ..."))
        raw_bodies = []
    for i, rb in enumerate(raw_bodies):
        body = _body(rb, f"bodies[{i}]", base_dir, source["bodies"][i] if isinstance(rb, dict) else None, problems)
        if body is not None:
            bodies.append(body)
            body_ids.append(i)
    # the kinds the file asks for, also of bodies that failed (so that one bad key of a sand body does not add
    # "no sand body" problems)
    kinds = {rb.get("kind") for rb in raw_bodies if isinstance(rb, dict) and isinstance(rb.get("kind"), str)}

    # ---- inflows
    inflows = []
    raw_inflows = data.get("inflows", [])
    if not isinstance(raw_inflows, list):
        problems.append(Problem("inflows", "must be an array of tables", "write each inflow as [[inflows]] ..."))
        raw_inflows = []
    failed_inflows = False  # an entry with a bad key: the checks across inflows (which name them by index) wait
    for i, ri in enumerate(raw_inflows):
        n_inflow = len(problems)
        v = read_table(ri, f"inflows[{i}]", INFLOW_KEYS, problems)
        if len(problems) > n_inflow:
            failed_inflows = True
            continue
        inflows.append(
            Inflow(
                v["face"],
                v["kind"],
                tuple(v["velocity"]),
                v["sand_fraction"],
                v["shape"],
                None if v["center"] is None else tuple(v["center"]),
                None if v["size"] is None else tuple(v["size"]),
                v["radius"],
                v["sand_start"] if v["sand_start"] is not None else 0.0,
                v["sand_ramp"] if v["sand_ramp"] is not None else 0.0,
            )
        )
    wall_cells = sand.wall_layers if sand is not None else LIMITS["sand_wall_cells"]
    if not failed_inflows:
        _check_inflows(inflows, bnd, fluid, problems, domain, wall_cells, fluid_given=flu is not None)

    # ---- stirring
    stirring = None
    if "stirring" in data:
        st = read_table(data["stirring"], "stirring", SECTIONS["stirring"], problems)
        stirring = _stirring(st, domain, fluid, problems, fluid_given=flu is not None)

    # ---- what each body needs
    for i, b in zip(body_ids, bodies, strict=True):
        if b.kind == "water" and fluid is None and flu is None:  # (an invalid [fluid] table is reported itself)
            problems.append(
                Problem(
                    f"bodies[{i}].kind",
                    "a water body needs a [fluid] table",
                    "add [fluid] (phases = 2 for water and air)",
                )
            )
        if b.kind == "water" and fluid is not None and fluid.phases == 1:
            problems.append(
                Problem(
                    f"bodies[{i}].kind",
                    "fluid.phases = 1 fills the whole domain with water; a water body needs two phases",
                    "set fluid.phases = 2, or remove the water body",
                )
            )
        if b.kind != "sand" and (b.density is not None or b.retention is not None):
            problems.append(
                Problem(
                    f"bodies[{i}].{'density' if b.density is not None else 'retention'}",
                    f"only sand bodies take this key (this body is {b.kind!r})",
                    "remove it, or make the body kind = 'sand'",
                )
            )
        if b.kind != "obstacle" and b.friction is not None:
            problems.append(
                Problem(
                    f"bodies[{i}].friction",
                    f"only obstacles take friction (this body is {b.kind!r})",
                    "remove it; sand friction on walls is sand.wall_friction",
                )
            )
        if b.saturation is not None:
            _check_saturation(b, i, sand, fluid, problems)
        if b.container_until is not None and b.kind != "sand":
            problems.append(
                Problem(
                    f"bodies[{i}].container_until",
                    f"only sand bodies start in a container (this body is {b.kind!r})",
                    "remove it, or make the body kind = 'sand'",
                )
            )
        if b.kind == "obstacle" and any(b.velocity):
            problems.append(
                Problem(f"bodies[{i}].velocity", "obstacles are fixed", "remove velocity from the obstacle")
            )
    raw_jets = data.get("inflows", []) if isinstance(data.get("inflows", []), list) else []
    sand_jet = any(
        isinstance(r, dict) and isinstance(r.get("sand_fraction"), (int, float)) and r["sand_fraction"] > 0
        for r in raw_jets
    )
    if "sand" in data and "sand" not in kinds and not sand_jet:
        problems.append(
            Problem(
                "sand",
                "a [sand] table but no sand body and no inflow carrying sand",
                "add a [[bodies]] entry with kind = 'sand' (or an inflow with sand_fraction > 0), or remove [sand]",
            )
        )
    if "fluid" not in data and "sand" not in kinds:
        problems.append(
            Problem(
                "bodies",
                "the scene has neither a fluid nor sand: nothing to simulate",
                "add a [fluid] table or a sand body",
            )
        )

    # ---- geometry: every shape builds (any error of a reader or a shape is a problem of its key), inside
    # the domain, and every sand body gets particles outside the obstacles
    if domain is not None:
        n_geometry = len(problems)
        for i, b in zip(body_ids, bodies, strict=True):
            _check_inside(b, i, domain, problems, wall_cells)
        if sand is not None and len(problems) == n_geometry:  # every shape built and in place
            _check_seeding(list(zip(body_ids, bodies, strict=True)), domain, sand, problems)
            _check_sand_overlaps(list(zip(body_ids, bodies, strict=True)), domain, sand, problems)
        if fluid is not None and len(problems) == n_geometry:
            _check_fluid_room(list(zip(body_ids, bodies, strict=True)), domain, problems)
            _check_water_cut_away(list(zip(body_ids, bodies, strict=True)), domain, problems)
        if len(problems) == n_geometry and not failed_inflows:
            _check_jets_clear(inflows, list(zip(body_ids, bodies, strict=True)), domain, wall_cells, problems)
        allowed = sand is not None and sand.periodic_walls
        for name, kind in domain.boundary.items():
            if kind == "periodic" and any(b.kind == "sand" for b in bodies) and not allowed:
                problems.append(
                    Problem(
                        f"domain.boundary.{name}",
                        "sand does not support periodic faces (the MPM grid has walls on every face)",
                        f"set domain.boundary.{name} = 'wall', or sand.periodic_walls = true (the fluid wraps "
                        "around, the sand meets a wall there)",
                    )
                )
                break

    if sand is not None and sand.grain_diameter is not None and domain is not None:
        _check_grain_diameter(sand, domain, problems)

    # ---- scheduler
    has_sand_content = any(b.kind == "sand" for b in bodies) or sand_jet
    scheduler = _scheduler(sch, sch_raw if isinstance(sch_raw, dict) else {}, fluid, has_sand_content, problems)

    time = None
    if tim["dt"] is not None and tim["frame_duration"] is not None:
        time = Time(tim["dt"], tim["frame_duration"], tim["frames"] or 1, tim["max_speed"], tim["mach_limit"] or 0.3)
        if time.frame_duration < time.dt:
            problems.append(
                Problem(
                    "time.frame_duration",
                    f"{time.frame_duration:g} s is shorter than one step dt = {time.dt:g} s",
                    "make frame_duration >= dt",
                )
            )
        elif time.frame_duration / time.dt > MAX_STEPS_PER_FRAME or time.frames * (
            time.frame_duration / time.dt
        ) > float(MAX_TOTAL_STEPS):
            per_frame = time.frame_duration / time.dt
            problems.append(
                Problem(
                    "time.frame_duration",
                    f"{time.frame_duration:g} s is {per_frame:.3g} steps of dt = {time.dt:g} s per frame, "
                    f"{time.frames * per_frame:.3g} steps in all: beyond what any run finishes (at most "
                    f"{MAX_STEPS_PER_FRAME:.0e} per frame and {MAX_TOTAL_STEPS:.0e} in all)",
                    "shorten time.frame_duration or time.frames, or take a larger time.dt",
                )
            )

        if (
            scheduler is not None
            and scheduler.kind == "multirate"
            and scheduler.sand_every > time.steps_per_frame
            and time.frame_duration >= time.dt
        ):
            problems.append(
                Problem(
                    "scheduler.sand_every",
                    f"one sand step of sand_every = {scheduler.sand_every} fluid steps spans more than a frame "
                    f"({time.steps_per_frame} steps): the frames would show the sand ahead of the fluid's clock",
                    f"use sand_every <= {time.steps_per_frame}, or a longer time.frame_duration",
                )
            )

    # ---- the stirring's speed: its rim acceleration for as long as it acts bounds the speed it gives the water
    if stirring is not None and time is not None and fluid is not None and domain is not None:
        total = time.frames * time.steps_per_frame * time.dt
        acts = max(0.0, total - stirring.start)
        if stirring.duration is not None:
            acts = min(acts, stirring.duration)
        speed = stirring.acceleration * acts
        units = Units(dx=domain.dx, dt=time.dt, rho=fluid.water_density)
        if speed > 0 and time.max_speed is None and units.mach(speed) > time.mach_limit:
            problems.append(
                Problem(
                    "stirring.acceleration",
                    f"{stirring.acceleration:g} m/s² at the rim for {acts:.3g} s can spin the water up to "
                    f"{speed:.3g} m/s: lattice Mach {units.mach(speed):.3g} at dt = {time.dt:g} s (limit "
                    f"time.mach_limit = {time.mach_limit:g})",
                    f"lower the acceleration or stirring.duration, use dt <= {_at_most(units.max_dt(speed, time.mach_limit))} s, "
                    "or set time.max_speed if the water will turn slower (friction, the sand)",
                )
            )

    # ---- time-step limits
    if domain is not None and time is not None:
        _check_max_speed(time, zip(body_ids, bodies, strict=True), inflows, problems)
        _check_time_step(domain, time, fluid, sand, bodies, inflows, problems, scheduler, body_ids)
        if not failed_inflows:
            _check_water_outlets(domain, time, fluid, inflows, problems)

    if problems:
        return None
    outputs = Outputs(
        out["directory"],
        tuple(out["fields"]),
        out["vtk"],
        out["ply"],
        out["preview"],
        out["preview_every"],
        out["checkpoint_every"],
        out["diagnostics"],
        surface=out["surface"],
        surface_format=tuple(out["surface_format"]),
        preview_colour=out["preview_colour"],
    )
    effects = Effects(**eff)
    has_sand = any(b.kind == "sand" for b in bodies) or any(i.sand_fraction > 0 for i in inflows)
    return Scene(
        name=sc["name"],
        description=sc["description"],
        domain=domain,
        time=time,
        fluid=fluid,
        sand=sand if has_sand else None,
        bodies=tuple(bodies),
        inflows=tuple(inflows),
        outputs=outputs,
        effects=effects,
        stirring=stirring,
        scheduler=scheduler,
        # read-only: the scene's own record of itself (to_dict(), checkpoints); a probe changed scene.source's dt
        # in place and the checkpoint then restored another scene than the one that ran
        source=_frozen(source),
    )


def _fluid(flu: dict, raw: dict, domain: Domain | None, tim: dict, problems: list[Problem]) -> Fluid | None:
    visc = {}
    for phase in ("water", "air"):
        si, lat = f"{phase}_viscosity", f"{phase}_lattice_viscosity"
        if si in raw and lat in raw:
            problems.append(
                Problem(
                    f"fluid.{si}", f"both {si} and {lat} are given", f"keep one of fluid.{si} (m²/s) and fluid.{lat}"
                )
            )
            continue
        if flu[si] is not None:
            if domain is None or tim["dt"] is None:
                continue
            visc[phase] = Units(domain.dx, tim["dt"]).viscosity(flu[si], "SI")
            key = f"fluid.{si}"
        else:
            visc[phase] = flu[lat] if flu[lat] is not None else _DEFAULT_LATTICE_VISCOSITY[phase]
            key = f"fluid.{lat}"
        lo, hi = LIMITS["min_lattice_viscosity"], LIMITS["max_lattice_viscosity"]
        if not lo <= visc[phase] <= hi:
            tau = visc[phase] / CS2 + 0.5
            problems.append(
                Problem(
                    key,
                    f"gives a lattice viscosity of {visc[phase]:.3g} (τ = {tau:.6g}), outside [{lo:g}, {hi:g}]",
                    f"give fluid.{lat} in [{lo:g}, {hi:g}] directly (Table 1 uses 1e-4 … 1e-1), or change dx/dt (ν_lat = ν dt/dx²)",
                )
            )
    if (
        flu["water_density"] is not None
        and flu["air_density"] is not None
        and flu["air_density"] >= flu["water_density"]
    ):
        problems.append(
            Problem(
                "fluid.air_density",
                f"{flu['air_density']:g} kg/m³ is not below water_density {flu['water_density']:g}",
                "the light phase must be lighter (paper: 1.25 vs 1000)",
            )
        )
    if len(visc) < 2 or any(
        flu[k] is None
        for k in (
            "phases",
            "water_density",
            "air_density",
            "surface_tension",
            "interface_width",
            "mobility",
            "controller_eta",
            "odd_lambda",
            "smagorinsky",
            "initial_pressure",
            "storage",
            "odd_ramp",
        )
    ):
        return None
    return Fluid(
        flu["phases"],
        flu["water_density"],
        flu["air_density"],
        visc["water"],
        visc["air"],
        flu["surface_tension"],
        flu["interface_width"],
        flu["mobility"],
        flu["controller_eta"],
        flu["odd_lambda"],
        flu["smagorinsky"],
        None if flu["gravity"] is None else tuple(flu["gravity"]),
        flu["initial_pressure"],
        flu["storage"],
        flu["odd_ramp"],
    )


def _sand(snd: dict, problems: list[Problem]) -> Sand | None:
    optional = {k.name for k in SECTIONS["sand"] if k.default is None}  # None = not given (grain_diameter)
    if any(v is None for k, v in snd.items() if not isinstance(v, bool) and k not in optional):
        return None
    ppc = snd["particles_per_cell"]
    k = round(ppc ** (1 / 3))
    if k**3 != ppc:
        problems.append(
            Problem(
                "sand.particles_per_cell",
                f"{ppc} is not a cube (particles are seeded k per axis)",
                f"use {k**3 if k**3 > 0 else 1} or {(k + 1) ** 3}",
            )
        )
    s1, s2, s3 = snd["cohesion_saturation"]
    if not 0 < s1 <= s2 < s3:
        problems.append(
            Problem(
                "sand.cohesion_saturation",
                f"breakpoints {snd['cohesion_saturation']} must satisfy 0 < S1 <= S2 < S3",
                "e.g. [0.05, 0.18, 0.36]",
            )
        )
    h = snd["hardening"]
    if h[2] < 0:
        problems.append(Problem("sand.hardening[2]", f"h2 must be >= 0, got {h[2]:g}", "the paper uses h2 = 0.2"))
    else:
        # the friction angle over q >= 0, for any signs of h0, h1, h3 (couplekit.sand.params)
        lo_angle, hi_angle = friction_angle_range(*h)
        if not (0.0 < lo_angle and hi_angle < 90.0):
            problems.append(
                Problem(
                    "sand.hardening",
                    f"[h0, h1, h2, h3] = {list(h)} makes the friction angle h0 + (h1 q - h3) exp(-h2 q) range over "
                    f"[{lo_angle:.3g}, {hi_angle:.3g}] degrees as the plastic strain q grows; it must stay within "
                    "(0, 90) degrees",
                    "the paper's sand: [35, 9, 0.2, 10] (25 to 48 degrees)",
                )
            )
    return Sand(
        snd["density"],
        snd["youngs_modulus"],
        snd["poisson_ratio"],
        tuple(h),
        snd["cohesion"],
        tuple(snd["cohesion_saturation"]),
        ppc,
        snd["jitter"],
        snd["seed"],
        snd["wall_friction"],
        snd["cfl"],
        snd["elastic_cfl"],
        snd["retention"],
        snd["absorption_rate"],
        snd["max_moisture"],
        snd["packing_fraction"],
        snd["wall_layers"],
        snd["periodic_walls"],
        grain_diameter=snd.get("grain_diameter"),
        viscosity=snd["viscosity"],
        absorption_time=snd.get("absorption_time"),
    )


def _with_absorption_time(sand: Sand, raw: Any, dt: float | None, problems: list[Problem]) -> Sand:
    """``sand`` with R_a from ``sand.absorption_time`` (s) where the scene gives it: R_a = dt / absorption_time per
    lattice step (Eq. 55 takes R_a r_max ε per step, so the uptake per second is then the same at any dt).
    Refused together with ``absorption_rate``, and below one time step (R_a > 1)."""
    tau = sand.absorption_time
    if tau is None:
        return sand
    if isinstance(raw, dict) and "absorption_rate" in raw:
        problems.append(
            Problem(
                "sand.absorption_time",
                "both absorption_time and absorption_rate are given",
                "keep one of sand.absorption_time (s) and sand.absorption_rate (per lattice step)",
            )
        )
        return sand
    if dt is None:
        return sand
    if tau < dt:
        problems.append(
            Problem(
                "sand.absorption_time",
                f"{tau:g} s is shorter than one time step (time.dt = {dt:g} s): R_a = dt / absorption_time would be "
                f"{dt / tau:.3g} per step, above 1",
                f"use sand.absorption_time >= {dt:g} s",
            )
        )
        return sand
    return replace(sand, absorption_rate=dt / tau)


def _with_sand_walls(sand: Sand, raw: Any, problems: list[Problem]) -> Sand:
    """``sand`` with the walls of the ``[sand.walls]`` table ``raw`` (None: not given): one entry per face
    (``x_min = { kind = "slip" }``, ``z_min = { friction = 0.3 }``), every face resolved (a face not given,
    or without ``friction``, takes ``sand.wall_friction``); problems for unknown faces, bad entries and a
    friction on a face that is not 'separate'."""
    import dataclasses
    import difflib

    given: dict[str, dict] = {}
    if raw is not None and not isinstance(raw, dict):
        problems.append(
            Problem(
                "sand.walls",
                f"must be a table of faces, got {show(raw)}",
                'write [sand.walls] with lines like z_min = { friction = 0.3 } or x_min = { kind = "slip" }',
            )
        )
    elif raw is not None:
        for face, entry in raw.items():
            if face not in FACES:
                close = difflib.get_close_matches(face, FACES, n=1) if isinstance(face, str) else []
                problems.append(
                    Problem(
                        f"sand.walls.{face if isinstance(face, str) else show(face)}",
                        "unknown face",
                        f"did you mean {close[0]!r}?" if close else f"use the faces {', '.join(FACES)}",
                    )
                )
                continue
            n = len(problems)
            v = read_table(entry, f"sand.walls.{face}", SAND_WALL_KEYS, problems)
            if len(problems) > n:
                continue
            if v["kind"] != "separate" and v["friction"] is not None:
                problems.append(
                    Problem(
                        f"sand.walls.{face}.friction",
                        f"a {v['kind']!r} face has no Coulomb friction (only 'separate' faces do)",
                        f"remove friction, or set kind = 'separate' on sand.walls.{face}",
                    )
                )
                continue
            given[face] = v
    walls = {}
    for face in FACES:
        v = given.get(face, {})
        kind, friction = v.get("kind", "separate"), v.get("friction")
        if kind != "separate":
            friction = 0.0  # slip and sticky faces have no Coulomb friction
        elif friction is None:
            friction = sand.wall_friction
        walls[face] = SandWall(kind, friction)
    return dataclasses.replace(sand, walls=FrozenDict(walls))


def _check_saturation(body: Body, index: int, sand: Sand | None, fluid: Fluid | None, problems: list[Problem]) -> None:
    """``bodies[index].saturation``: on sand bodies only; at most the pore volume 1 − ε0; with a fluid, only on
    a body that retains water, within its retention capacity (the coupler recomputes the saturation from the
    water each step: the body starts holding it as bound water, r = S / ε0 ≤ r_max)."""
    key = f"bodies[{index}].saturation"
    if body.kind != "sand":
        problems.append(Problem(key, f"only sand bodies take saturation (this body is {body.kind!r})", "remove it"))
        return
    if sand is None:
        return
    s, eps0 = body.saturation, sand.packing_fraction
    if s > 1.0 - eps0 + 1e-12:
        problems.append(
            Problem(
                key,
                f"{s:g} is more water than the pores hold (1 − sand.packing_fraction = {1.0 - eps0:g})",
                f"set it to at most {1.0 - eps0:g} (the cohesion peaks on [S1, S2] of sand.cohesion_saturation)",
            )
        )
        return
    if fluid is None or s == 0:
        return
    retains = body.retention if body.retention is not None else sand.retention
    if not retains:
        problems.append(
            Problem(
                key,
                "with a fluid the coupler recomputes every particle's saturation from the water each step, so a "
                "body that does not retain water would lose it after the first step",
                f"set bodies[{index}].retention = true (the body then starts holding S as bound water), or remove "
                "saturation",
            )
        )
    elif s / eps0 > sand.max_moisture * (1 + 1e-12):
        problems.append(
            Problem(
                key,
                f"{s:g} is above the body's retention capacity: bound water r = S / sand.packing_fraction = "
                f"{s / eps0:.4g} > sand.max_moisture = {sand.max_moisture:g}",
                f"set it to at most {sand.max_moisture * eps0:.4g}, or raise sand.max_moisture",
            )
        )


def _check_grain_diameter(sand: Sand, domain: Domain, problems: list[Problem]) -> None:
    """The grain-area drag (``sand.grain_diameter``) needs many grains per cell: d ≤ dx."""
    if sand.grain_diameter > domain.dx:
        problems.append(
            Problem(
                "sand.grain_diameter",
                f"{sand.grain_diameter:g} m is larger than a cell (domain.dx = {domain.dx:g} m): the grain-area "
                "drag counts the grains of a node, which needs many grains per cell",
                "give the grain diameter (e.g. 2e-4 for fine sand), at most domain.dx, or remove it for the "
                "paper's drag area",
            )
        )


def _body(raw: Any, path: str, base_dir: Path, source: dict | None, problems: list[Problem]) -> Body | None:
    if not isinstance(raw, dict):
        problems.append(Problem(path, "must be a table", "write it as [[bodies]] with key = value lines"))
        return None
    raw = dict(raw)
    geo_raw = raw.pop("geometry", None)
    v = read_table(raw, path, BODY_KEYS, problems)
    if geo_raw is None:
        problems.append(
            Problem(
                f"{path}.geometry",
                "is required",
                f"add a [{path.split('[')[0]}.geometry] table with type = 'box', 'sphere', 'cylinder', 'heightfield' or 'mesh'",
            )
        )
        return None
    geo = _geometry(geo_raw, f"{path}.geometry", base_dir, source.get("geometry") if source else None, problems)
    if geo is None or v["kind"] is None or v["velocity"] is None:
        return None
    return Body(
        v["kind"], v["name"] or path, geo, tuple(v["velocity"]), v["density"], v["retention"], v["friction"],
        v["saturation"], v["container_until"],
    )  # fmt: skip


def _geometry(raw: Any, path: str, base_dir: Path, source: dict | None, problems: list[Problem]) -> Geometry | None:
    if not isinstance(raw, dict):
        problems.append(Problem(path, "must be a table", f"write [{path}] with type = ... and the shape's keys"))
        return None
    raw = dict(raw)
    cut_raw = raw.pop(GEOMETRY_SUBTRACT, None)
    cuts = _subtract(cut_raw, f"{path}.{GEOMETRY_SUBTRACT}", base_dir, source, problems)
    gtype = raw.get("type")
    if not isinstance(gtype, str) or gtype not in GEOMETRY_KEYS:
        read_table({"type": gtype} if gtype is not None else {}, path, GEOMETRY_COMMON_KEYS[:1], problems)
        return None
    v = read_table(raw, path, GEOMETRY_COMMON_KEYS + GEOMETRY_KEYS[gtype], problems)
    if any(v[k.name] is None for k in GEOMETRY_KEYS[gtype] if k.default is REQUIRED):
        return None
    params = {k.name: v[k.name] for k in GEOMETRY_KEYS[gtype]}
    if gtype == "box" and params["min"] and params["max"]:
        for a in range(3):
            if params["max"][a] <= params["min"][a]:
                problems.append(
                    Problem(
                        f"{path}.max[{a}]",
                        f"max {params['max'][a]:g} is not above min {params['min'][a]:g}",
                        "swap min and max, or make the box thicker",
                    )
                )
    if gtype == "heightfield":
        if ("heights" in raw) == ("file" in raw):
            problems.append(
                Problem(
                    f"{path}.heights",
                    "give exactly one of heights and file",
                    "inline heights = [[...], ...] or file = 'terrain.npy'",
                )
            )
        for rk in ("x_range", "y_range"):
            r = params[rk]
            if r is not None and not r[1] > r[0]:
                problems.append(Problem(f"{path}.{rk}", f"must be increasing, got {r}", f"write {rk} = [low, high]"))
    for fk in ("file",):
        if params.get(fk):
            f = Path(params[fk])
            f = f if f.is_absolute() else (base_dir / f)
            if not f.is_file():
                what = "is a folder, not a file" if f.is_dir() else "does not exist"
                problems.append(
                    Problem(f"{path}.{fk}", f"file {str(f)!r} {what}", "give a file's path relative to the scene file")
                )
            else:
                params[fk] = str(f.resolve())
                if source is not None:
                    source[fk] = params[fk]
    if gtype == "heightfield" and params.get("file") and Path(params["file"]).is_file():
        try:
            from .mesh import load_heights

            heights = load_heights(params["file"])
            if params.get("base") is not None and float(heights.min()) <= params["base"]:
                problems.append(
                    Problem(
                        f"{path}.base",
                        f"the base {params['base']:g} is not below every height of the file (lowest "
                        f"{float(heights.min()):g})",
                        "lower base",
                    )
                )
        except Exception as exc:  # whatever the reader raises: a file that is no height grid
            problems.append(
                Problem(
                    f"{path}.file",
                    f"unreadable height grid: {_error_text(exc)}",
                    "save a 2-D array of finite numbers with numpy.save or as CSV",
                )
            )
    if gtype == "heightfield" and params.get("heights") is not None and params.get("base") is not None:
        if min(min(r) for r in params["heights"]) <= params["base"]:  # finite numbers (schema)
            problems.append(Problem(f"{path}.base", "the base is not below every height", "lower base"))
    if len([p for p in problems if p.key.startswith(path)]):
        return None
    if cuts is None:
        return None
    return Geometry(gtype, _frozen(params), v["scale"], tuple(v["rotate"]), tuple(v["translate"]), v["invert"], cuts)


def _subtract(
    raw: Any, path: str, base_dir: Path, source: dict | None, problems: list[Problem]
) -> tuple[Geometry, ...] | None:
    """The ``subtract`` list of a geometry table: each entry a geometry table of its own (checked as one,
    ``path[j]`` in messages); () when absent, None when an entry failed."""
    if raw is None:
        return ()
    if not isinstance(raw, list) or not raw:
        problems.append(
            Problem(
                path,
                "must be a non-empty list of geometry tables",
                "write subtract = [{ type = 'cylinder', center = [...], radius = ..., height = ... }, ...] or remove it",
            )
        )
        return None
    sources = source.get(GEOMETRY_SUBTRACT) if source else None
    out = []
    for j, entry in enumerate(raw):
        sub_source = (
            sources[j] if isinstance(sources, list) and j < len(sources) and isinstance(sources[j], dict) else None
        )
        out.append(_geometry(entry, f"{path}[{j}]", base_dir, sub_source, problems))
    return None if any(g is None for g in out) else tuple(out)


def _check_inflows(
    inflows: list[Inflow],
    bnd: dict,
    fluid: Fluid | None,
    problems: list[Problem],
    domain: Domain | None = None,
    wall_cells: int = 2,
    fluid_given: bool = False,
) -> None:
    """Inflows against the faces and the fluid; ``fluid_given``: a [fluid] table was written (when it failed its
    own checks, ``fluid`` is None and its problems are reported already: no "needs a [fluid] table" here)."""
    faces_used: dict[str, int] = {}
    for i, inf in enumerate(inflows):
        key = f"inflows[{i}]"
        kind = bnd.get(inf.face)
        outlet = inf.shape != "face"
        if inf.face in faces_used and not (outlet and inflows[faces_used[inf.face]].shape != "face"):
            problems.append(
                Problem(
                    f"{key}.face",
                    f"face {inf.face} already has inflows[{faces_used[inf.face]}]",
                    "one whole-face inflow per face (several outlets, shape = 'rect' or 'disc', may share a face)",
                )
            )
        faces_used.setdefault(inf.face, i)
        if kind == "periodic":
            problems.append(
                Problem(
                    f"{key}.face",
                    f"face {inf.face} is periodic (domain.boundary.{inf.face} = 'periodic'); an inflow cannot enter through a periodic face",
                    f"set domain.boundary.{inf.face} = 'wall' (around an outlet) or 'inflow' (whole face), and its opposite face to 'wall' or 'outflow'"
                    if outlet
                    else f"set domain.boundary.{inf.face} = 'inflow' and its opposite face to 'wall' or 'outflow'",
                )
            )
        elif outlet and kind == "inflow":
            problems.append(
                Problem(
                    f"domain.boundary.{inf.face}",
                    f"is 'inflow', but inflows[{i}] is an outlet (shape = {inf.shape!r}): the rest of the face keeps domain.boundary.{inf.face}",
                    f"set domain.boundary.{inf.face} = 'wall' (or 'outflow') around the outlet, or shape = 'face' for a whole-face inflow",
                )
            )
        elif not outlet and kind != "inflow":
            problems.append(
                Problem(
                    f"{key}.face",
                    f"domain.boundary.{inf.face} is {kind!r}, not 'inflow'",
                    f"set domain.boundary.{inf.face} = 'inflow', or give the inflow an outlet (shape = 'rect' or 'disc')",
                )
            )
        _check_outlet_keys(inf, key, problems)
        axis, side = "xyz".index(inf.face[0]), (1 if inf.face.endswith("min") else -1)
        if inf.velocity[axis] * side <= 0:
            problems.append(
                Problem(
                    f"{key}.velocity",
                    f"the {inf.face[0]} component {inf.velocity[axis]:g} m/s does not point into the domain through {inf.face}",
                    f"make velocity[{axis}] {'positive' if side > 0 else 'negative'}",
                )
            )
        if inf.sand_fraction == 0 and (inf.sand_start > 0 or inf.sand_ramp > 0):
            which = "sand_start" if inf.sand_start > 0 else "sand_ramp"
            problems.append(
                Problem(
                    f"{key}.{which}",
                    "is set but the inflow carries no sand (sand_fraction = 0)",
                    f"set {key}.sand_fraction > 0, or remove {which}",
                )
            )
        if inf.kind == "wind" and inf.sand_fraction > 0:
            problems.append(
                Problem(f"{key}.sand_fraction", "wind carries no sand", "set sand_fraction = 0 or kind = 'water'")
            )
        if fluid is None:
            if not fluid_given:
                problems.append(Problem(f"{key}", "an inflow needs a [fluid] table", "add [fluid]"))
        elif fluid.phases == 1 and inf.kind == "wind":
            problems.append(Problem(f"{key}.kind", "wind needs two fluid phases", "set fluid.phases = 2"))
    for face in FACES:
        if bnd.get(face) == "inflow" and not any(inf.face == face and inf.shape == "face" for inf in inflows):
            problems.append(
                Problem(
                    f"domain.boundary.{face}",
                    "is 'inflow' but no [[inflows]] entry covers the whole face (shape = 'face')",
                    f"add [[inflows]] with face = '{face}' and a velocity, or make the face a 'wall'",
                )
            )
    if domain is not None:
        _check_outlets_on_grid(inflows, domain, problems)
        _check_sand_jets(inflows, domain, problems, wall_cells)


def _face_too_large(domain: Domain, face: str) -> bool:
    """The face has more cells than outlets are checked on (LIMITS['max_outlet_face_cells'])."""
    rows, cols = face_plane_shape(domain.shape, solver_face(face))
    return rows * cols > LIMITS["max_outlet_face_cells"]


def _check_outlet_keys(inf: Inflow, key: str, problems: list[Problem]) -> None:
    """The keys each shape takes: none for 'face'; center + size for 'rect'; center + radius for 'disc'."""
    given = {k for k in {k for keys in OUTLET_KEYS.values() for k in keys} if getattr(inf, k) is not None}
    needs = set(OUTLET_KEYS[inf.shape])
    for k in sorted(needs - given):
        problems.append(Problem(f"{key}.{k}", f"an outlet with shape = {inf.shape!r} needs {k}", f"add {k} = ..."))
    for k in sorted(given - needs):
        problems.append(
            Problem(
                f"{key}.{k}",
                f"shape = {inf.shape!r} takes no {k}",
                "remove it" if inf.shape != "face" else "remove it, or set shape = 'rect' or 'disc' for an outlet",
            )
        )


def _check_outlets_on_grid(inflows: list[Inflow], domain: Domain, problems: list[Problem]) -> None:
    """Every outlet inside its face, covering at least one cell centre, overlapping no other outlet."""
    masks: dict[str, tuple[int, np.ndarray]] = {}
    for i, inf in enumerate(inflows):
        if inf.shape == "face" or inf.center is None or (inf.size is None and inf.radius is None):
            continue
        if _face_too_large(domain, inf.face):
            continue
        if (inf.shape == "rect" and inf.size is None) or (inf.shape == "disc" and inf.radius is None):
            continue
        key = f"inflows[{i}]"
        lo, hi = region_bounds(inf.shape, inf.center, inf.size, inf.radius)
        extent = face_extent(domain.size, inf.face)
        tol = 1e-9 * max(domain.size)
        names = ["xyz"[a] for a in PLANE_AXES[inf.face[0]]]
        bad = [k for k in range(2) if lo[k] < -tol or hi[k] > extent[k] + tol]
        if bad:
            k = bad[0]
            problems.append(
                Problem(
                    f"{key}.center",
                    f"the outlet reaches outside face {inf.face} along {names[k]}: {lo[k]:.6g} .. {hi[k]:.6g} m, the face spans 0 .. {extent[k]:g} m",
                    f"move or shrink it so that it lies within [0, {extent[k]:g}] m along {names[k]} "
                    f"(center holds the ({names[0]}, {names[1]}) coordinates on this face)",
                )
            )
            continue
        mask = region_mask(domain.shape, domain.dx, inf.face, inf.shape, inf.center, inf.size, inf.radius)
        if not mask.any():
            problems.append(
                Problem(
                    f"{key}.{'size' if inf.shape == 'rect' else 'radius'}",
                    f"the outlet covers no cell centre at dx = {domain.dx:g} m (zero area on the grid)",
                    f"make it at least one cell ({domain.dx:g} m) across, centred on a cell",
                )
            )
            continue
        if inf.face in masks and (masks[inf.face][1] & mask).any():
            problems.append(
                Problem(
                    f"{key}.center",
                    f"the outlet overlaps inflows[{masks[inf.face][0]}] on face {inf.face} ({int((masks[inf.face][1] & mask).sum())} cells)",
                    "move the outlets apart",
                )
            )
            continue
        prev = masks.get(inf.face)
        masks[inf.face] = (i if prev is None else prev[0], mask if prev is None else prev[1] | mask)


def _check_sand_jets(inflows: list[Inflow], domain: Domain, problems: list[Problem], rim: int) -> None:
    """An outlet carrying sand must keep its cells ``rim`` (``sand.wall_layers``) from the face's edges: its
    particles are emitted over its whole area (couplekit.sand.emission), and the MPM walls occupy that rim."""
    for i, inf in enumerate(inflows):
        if inf.sand_fraction <= 0 or inf.shape == "face" or inf.center is None or _face_too_large(domain, inf.face):
            continue
        if (inf.shape == "rect" and inf.size is None) or (inf.shape == "disc" and inf.radius is None):
            continue
        lo, hi = region_bounds(inf.shape, inf.center, inf.size, inf.radius)
        extent = face_extent(domain.size, inf.face)
        if np.any(lo < 0) or np.any(hi > np.asarray(extent)):
            continue  # reported by _check_outlets_on_grid
        face = solver_face(inf.face)
        mask = region_mask(domain.shape, domain.dx, face, inf.shape, inf.center, inf.size, inf.radius)
        rows, cols = face_plane_shape(domain.shape, face)
        inner = np.zeros_like(mask)
        inner[rim : rows - rim, rim : cols - rim] = True
        if (mask & ~inner).any():
            names = ["xyz"[a] for a in PLANE_AXES[face[0]]]
            margin = rim * domain.dx
            problems.append(
                Problem(
                    f"inflows[{i}].center",
                    f"the outlet carries sand (sand_fraction = {inf.sand_fraction:g}) but reaches within {rim} cells "
                    f"({margin:g} m) of the edge of face {inf.face}, where the MPM walls are: its sand would enter "
                    "through part of it only",
                    f"move or shrink it so that it lies within [{margin:g}, {extent[0] - margin:.6g}] m along "
                    f"{names[0]} and [{margin:g}, {extent[1] - margin:.6g}] m along {names[1]}, or set "
                    f"inflows[{i}].sand_fraction = 0",
                )
            )


_SCHEDULER_KEYS = {
    "substeps": "subcycle",
    "max_substeps": "subcycle",
    "interpolation": "subcycle",
    "sand_every": "multirate",
}
"""The [scheduler] keys that belong to one kind only."""


def _scheduler(sch: dict, raw: dict, fluid: Fluid | None, has_sand: bool, problems: list[Problem]) -> Scheduler | None:
    """The [scheduler] table checked across keys: a kind's keys only with that kind, sand_every required for
    multirate, and sand to schedule for the multi-rate kinds. None when a problem was found."""
    n = len(problems)
    kind = sch["kind"]
    if kind is None:
        return None
    for key, owner in _SCHEDULER_KEYS.items():
        if key in raw and kind != owner:
            problems.append(
                Problem(
                    f"scheduler.{key}",
                    f"applies only to kind = '{owner}' (this scene's scheduler is '{kind}')",
                    f"remove scheduler.{key}, or set scheduler.kind = '{owner}'",
                )
            )
    if kind == "multirate" and "sand_every" not in raw:
        problems.append(
            Problem(
                "scheduler.sand_every",
                "is required with kind = 'multirate'",
                "add sand_every = <LBM steps per MPM step>, e.g. sand_every = 4",
            )
        )
    if kind != "lockstep" and not has_sand:
        problems.append(
            Problem(
                "scheduler.kind",
                f"'{kind}' steps the sand at its own rate, but the scene has no sand (a fluid has one rate)",
                "remove the [scheduler] table, or set scheduler.kind = 'lockstep'",
            )
        )
    k, cap = sch["substeps"], sch["max_substeps"]
    if kind == "subcycle" and "max_substeps" in raw and isinstance(k, int) and isinstance(cap, int) and k > cap:
        problems.append(
            Problem(
                "scheduler.max_substeps",
                f"= {cap} is below scheduler.substeps = {k} (the cap applies to substeps = 'auto'; a fixed count "
                "above it would be ignored)",
                f"remove scheduler.max_substeps, raise it to >= {k}, or set substeps = 'auto'",
            )
        )
    if kind == "subcycle" and sch["interpolation"] == "linear" and fluid is None:
        problems.append(
            Problem(
                "scheduler.interpolation",
                "= 'linear' interpolates the fluid's velocity between its steps, but the scene has no fluid",
                "remove scheduler.interpolation (or set it to 'hold')",
            )
        )
    if len(problems) > n or None in (sch["substeps"], sch["max_substeps"], sch["interpolation"]):
        return None
    return Scheduler(kind, sch["substeps"], sch["max_substeps"], sch["interpolation"], sch["sand_every"] or 1)


def _stirring(
    st: dict, domain: Domain | None, fluid: Fluid | None, problems: list[Problem], fluid_given: bool = False
) -> Stirring | None:
    """The [stirring] table checked across keys (it needs a fluid, a non-zero axis, a centre in the domain);
    ``fluid_given`` as in :func:`_check_inflows`."""
    n = len(problems)
    if fluid is None and not fluid_given:
        problems.append(Problem("stirring", "stirring acts on the water: it needs a [fluid] table", "add [fluid]"))
    if st["axis"] is not None and not any(st["axis"]):
        problems.append(Problem("stirring.axis", "is the zero vector", "give the axis direction, e.g. [0.0, 0.0, 1.0]"))
    if st["center"] is not None and domain is not None:
        c, size = np.asarray(st["center"]), np.asarray(domain.size)
        if np.any(c < 0) or np.any(c > size):
            problems.append(
                Problem(
                    "stirring.center",
                    f"{c.tolist()} m lies outside the domain [0, {size.tolist()}] m",
                    "put the axis point inside the domain",
                )
            )
    if len(problems) > n or None in (st["center"], st["radius"], st["acceleration"], st["axis"]):
        return None
    axis = np.asarray(st["axis"], np.float64)
    if domain is not None and not _stirs_a_cell(np.asarray(st["center"], np.float64), axis, st, domain):
        problems.append(
            Problem(
                "stirring.radius",
                f"{st['radius']:g} m: the stirred cylinder holds no cell centre of the grid (dx = {domain.dx:g} m), "
                "so the stirring would do nothing",
                f"use a radius of at least {domain.dx:g} m (one cell), or move stirring.center (or lengthen "
                "stirring.length)",
            )
        )
        return None
    return Stirring(
        tuple(st["center"]),
        tuple((axis / np.linalg.norm(axis)).tolist()),
        st["radius"],
        st["length"],
        st["acceleration"],
        st["start"],
        st["duration"],
    )


def _stirs_a_cell(center: np.ndarray, axis: np.ndarray, st: dict, domain: Domain) -> bool:
    """Whether some cell centre lies in the stirred cylinder (r < radius, and |s| ≤ length/2 along the axis when a
    length is given), the cells :class:`couplekit.scene.forces.StirringForce` forces; plane by plane in z, so a
    large grid needs no grid-sized array."""
    n = axis / np.linalg.norm(axis)
    nz, ny, nx = domain.shape
    dx = domain.dx
    y, x = np.meshgrid((np.arange(ny) + 0.5) * dx - center[1], (np.arange(nx) + 0.5) * dx - center[0], indexing="ij")
    for k in range(nz):
        z = (k + 0.5) * dx - center[2]
        s = n[0] * x + n[1] * y + n[2] * z
        r2 = (x - s * n[0]) ** 2 + (y - s * n[1]) ** 2 + (z - s * n[2]) ** 2
        inside = r2 < st["radius"] ** 2
        if st["length"] is not None:
            inside &= np.abs(s) <= 0.5 * st["length"]
        if inside.any():
            return True
    return False


def _error_text(exc: BaseException) -> str:
    """An exception as message text: its own words, with its type when they do not say what went wrong."""
    text = str(exc).strip()
    if len(text) > 300:
        text = text[:300] + " ..."
    if isinstance(exc, (ValueError, OSError)) and text:
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _check_inside(body: Body, i: int, domain: Domain, problems: list[Problem], wall_cells: int = 2) -> None:
    """Build the body's shape as the solvers will (:meth:`Geometry.solver_shape`) and check that it lies in the
    domain. Any exception of a file reader or a shape becomes a problem of ``bodies[i].geometry``."""
    try:
        lo, hi = body.geometry.solver_shape(domain).bounds()
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError(f"the shape's bounds {lo.tolist()} .. {hi.tolist()} are not finite")
    except Exception as exc:
        problems.append(
            Problem(
                f"bodies[{i}].geometry",
                f"cannot build the shape: {_error_text(exc)}",
                "check the geometry keys and file"
                + (" (a closed triangle mesh, OBJ, STL or PLY)" if body.geometry.type == "mesh" else ""),
            )
        )
        return
    _check_bounds(body, i, lo, hi, domain, problems, wall_cells)


def _check_bounds(body: Body, i: int, lo, hi, domain: Domain, problems: list[Problem], wall_cells: int) -> None:
    size = np.asarray(domain.size)
    tol = 1e-9 * size.max()
    if body.kind == "obstacle":
        if np.any(hi <= 0) or np.any(lo >= size):
            problems.append(
                Problem(
                    f"bodies[{i}].geometry",
                    f"the obstacle (bounds {np.round(lo, 6).tolist()} .. {np.round(hi, 6).tolist()} m) does not meet the domain [0, {size.tolist()}]",
                    "move it into the domain",
                )
            )
        return
    margin = wall_cells * domain.dx if body.kind == "sand" else 0.0
    default_base = body.geometry.type == "heightfield" and body.geometry.params.get("base") is None
    if default_base and body.kind == "water":
        # the default base, one cell below the domain, lies below the floor on purpose: the water fills the
        # domain's cells under the surface; only its sides and top must lie within the domain
        lo = np.array([lo[0], lo[1], max(float(lo[2]), 0.0)])
    if default_base and body.kind == "sand" and lo[2] < margin - tol:
        problems.append(
            Problem(
                f"bodies[{i}].geometry.base",
                f"the sand height field {body.name!r} reaches down to its default base, one cell below the domain, "
                f"inside the MPM walls (sand must stay {wall_cells} cells = {margin:g} m from each face, "
                "sand.wall_layers)",
                f"set geometry.base = {margin:g} (or higher) for a sand height field: the default suits obstacles "
                "and water",
            )
        )
        return
    if np.any(lo < margin - tol) or np.any(hi > size - margin + tol):
        axis = int(np.argmax(np.maximum(margin - lo, hi - (size - margin))))
        where = (
            f" (sand must stay {wall_cells} cells = {margin:g} m from each face, where the MPM walls are, sand.wall_layers)"
            if margin
            else ""
        )
        problems.append(
            Problem(
                f"bodies[{i}].geometry",
                f"the {body.kind} body {body.name!r} reaches outside the domain along {'xyz'[axis]}: bounds {lo[axis]:.6g} .. {hi[axis]:.6g} m, domain 0 .. {size[axis]:g} m{where}",
                f"move or shrink it so that it lies within [{margin:g}, {size[axis] - margin:.6g}] m along {'xyz'[axis]}",
            )
        )


def _seeds_any(sdf, lo, hi, dx: float, per_axis: int, chunk: int = 1 << 18, cap: int = 1 << 27) -> bool | None:
    """Whether :func:`couplekit.sand.seeding.seed_sdf` places any particle where ``sdf`` < 0 in the box [lo, hi)
    (the seeding lattice of spacing dx / per_axis; the jitter moves particles after they are chosen, so it is
    left out). The box is searched block by block (about ``chunk`` lattice points each), the blocks nearest its
    centre first, stopping at the first particle: a solid body costs one block. A box of more than ``cap``
    lattice points is searched in its centre block only, and None (unknown) is returned when that holds none
    (its particles, at most ``cap``, would take gigabytes: the memory estimate speaks for such a body)."""
    from ..sand.seeding import seed_sdf

    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if np.any(hi <= lo):
        return False
    h = dx / per_axis
    first = np.ceil(lo / h - 0.5)  # the lattice points seed_sdf takes: centres in [lo, hi)
    last = np.ceil(hi / h - 0.5)
    n = np.maximum(last - first, 0.0)
    if np.any(n == 0):
        return False
    bx = min(n[0], chunk)
    by = min(n[1], max(1.0, chunk // bx))
    bz = min(n[2], max(1.0, chunk // (bx * by)))
    block = np.array([bx, by, bz])
    if float(np.prod(n)) > cap:  # the block around the centre only
        start = np.floor(0.5 * (first + last) - 0.5 * block)
        starts = [start]
    else:
        counts = np.ceil(n / block).astype(np.int64)
        grid = np.stack(np.meshgrid(*(np.arange(c) for c in counts), indexing="ij"), axis=-1).reshape(-1, 3)
        starts = first + grid * block
        centre = 0.5 * (first + last)
        starts = starts[np.argsort(np.linalg.norm(starts + 0.5 * block - centre, axis=1), kind="stable")]
    for start in starts:
        # block faces at multiples of h lie between lattice points: the blocks share no point
        blo, bhi = np.maximum(lo, start * h), np.minimum(hi, (start + block) * h)
        if np.all(bhi > blo) and seed_sdf(sdf, blo, bhi, dx, per_axis, 0.0).count:
            return True
    return None if float(np.prod(n)) > cap else False


def _shapes_of_kind(built: list[tuple[int, Body]], kind: str, domain: Domain):
    """(index, body, solver shape, box lo, box hi) of each body of ``kind``, its box clipped to the domain."""
    size = np.asarray(domain.size, np.float64)
    for i, b in built:
        if b.kind == kind:
            shape = b.geometry.solver_shape(domain)
            lo, hi = shape.bounds()
            yield i, b, shape, np.maximum(lo, 0.0), np.minimum(hi, size)


def _inside_obstacles(i: int, body: Body, obstacles, cutters, consequence: str) -> Problem:
    """The problem of body ``i`` lying wholly inside the ``cutters`` (among ``obstacles``: (index, shape))."""
    names = ", ".join(f"bodies[{j}]" for j, s in obstacles if s in cutters)
    return Problem(
        f"bodies[{i}].geometry",
        f"the {body.kind} body {body.name!r} lies wholly inside obstacles ({names}): {consequence}",
        f"move the {body.kind} body out of the obstacle, or the obstacle away",
    )


def _seeding_failure(i: int, exc: Exception, obstacles, cutters, lo, hi) -> Problem:
    """The problem of seeding sand body ``i`` failing with ``exc``: under the key of the obstacle whose SDF fails
    over the sand body's box (probed at its corners and centre: a mesh sampled lazily samples that box, so it
    fails there as on the lattice), else under the sand body's own."""
    probe = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    probe = np.vstack([probe, 0.5 * (np.asarray(lo) + np.asarray(hi))])
    for j, shape in obstacles:
        if any(shape is c for c in cutters):
            try:
                shape.sdf(probe)
            except Exception as own:  # this obstacle's SDF is what fails
                return Problem(
                    f"bodies[{j}].geometry",
                    f"cannot be sampled where the sand body bodies[{i}] lies: {_error_text(own)}",
                    "check its geometry",
                )
    return Problem(f"bodies[{i}].geometry", f"cannot seed the sand body: {_error_text(exc)}", "check its geometry")


def _check_seeding(built: list[tuple[int, Body]], domain: Domain, sand: Sand, problems: list[Problem]) -> None:
    """Every sand body gets particles: seeded as :func:`couplekit.assembly.build_sand` seeds it (the seeding
    lattice over its bounding box, less what lies inside an obstacle), searched cheaply (:func:`_seeds_any`)."""
    from .geometry import Difference, overlapping

    k = sand.particles_per_axis
    obstacles = [(i, b.geometry.solver_shape(domain)) for i, b in built if b.kind == "obstacle"]
    for i, b, shape, lo, hi in _shapes_of_kind(built, "sand", domain):
        cutters: list = []
        try:
            cutters = overlapping(shape, [s for _, s in obstacles])
            seeded = _seeds_any(Difference(shape, cutters).sdf if cutters else shape.sdf, lo, hi, domain.dx, k)
            alone = bool(cutters) and seeded is False and _seeds_any(shape.sdf, lo, hi, domain.dx, k)
        except Exception as exc:  # an SDF that fails on the lattice points: the sand's own, or an obstacle's
            problems.append(_seeding_failure(i, exc, obstacles, cutters, lo, hi))
            continue
        if seeded is not False:  # particles found, or a body too large to search (None)
            continue
        spacing = domain.dx / k
        own_cuts = bool(b.geometry.subtract) and isinstance(shape, Difference)
        if alone:
            problems.append(
                _inside_obstacles(
                    i, b, obstacles, cutters, "no particle would be seeded (particles are not seeded inside obstacles)"
                )
            )
        elif own_cuts and _seeds_any(shape.shape.sdf, lo, hi, domain.dx, k) is not False:
            problems.append(
                Problem(
                    f"bodies[{i}].geometry.subtract",
                    f"the sand body {b.name!r} is wholly removed by its own geometry.subtract: no particle would be "
                    "seeded",
                    "make the subtracted shapes smaller than the body (or remove them)",
                )
            )
        else:
            problems.append(
                Problem(
                    f"bodies[{i}].geometry",
                    f"the sand body {b.name!r} is thinner than the particle spacing dx / k = {domain.dx:g} / {k} = "
                    f"{spacing:.4g} m: no seeding point (sub-cell centre) lies inside it, so no particle would be "
                    "seeded",
                    f"make it at least {spacing:.4g} m thick on every axis (or raise sand.particles_per_cell, or "
                    "lower domain.dx)",
                )
            )


def _check_jets_clear(
    inflows: list[Inflow], built: list[tuple[int, Body]], domain: Domain, rim: int, problems: list[Problem]
) -> None:
    """A sand-carrying inflow's particles are emitted ``rim`` cells inside its face (couplekit.sand.emission):
    the cells of its open area from the face to one cell beyond the emission plane must be clear of obstacles,
    or the particles appear inside the solid (they stayed there, or were pushed out through the face and went
    non-finite: a probe's plate in front of an outlet).  Tested at those cells' centres against every obstacle."""
    obstacles = [(i, b.geometry.solver_shape(domain)) for i, b in built if b.kind == "obstacle"]
    if not obstacles:
        return
    for n, inf in enumerate(inflows):
        if _face_too_large(domain, inf.face):
            continue
        if inf.shape != "face" and (
            inf.center is None
            or (inf.shape == "rect" and inf.size is None)
            or (inf.shape == "disc" and inf.radius is None)
        ):
            continue  # an outlet without its keys: refused by the inflow checks
        _check_inflow_open(n, inf, obstacles, domain, problems)
        if inf.sand_fraction <= 0:
            continue
        # the cell centres from the face to beyond the emission plane, in front of the open area
        pts = _cells_in_front(inf, domain, rim + 2, rim)
        if pts.shape[0] == 0:
            continue
        for j, shape in obstacles:
            inside = np.asarray(shape.sdf(pts)) < 0
            if inside.any():
                where = np.round(pts[np.argmax(inside)], 6).tolist()
                problems.append(
                    Problem(
                        f"inflows[{n}]",
                        f"the inflow carries sand (sand_fraction = {inf.sand_fraction:g}), but obstacle bodies[{j}] "
                        f"fills {int(inside.sum())} of the cells within {rim + 2} cells of face {inf.face} where its "
                        f"particles are emitted ({rim} cells inside the face) and enter (e.g. the cell at {where} m): "
                        "they would appear inside the solid",
                        f"move bodies[{j}] at least {(rim + 2) * domain.dx:g} m away from the outlet, move the "
                        f"outlet, or set inflows[{n}].sand_fraction = 0",
                    )
                )
                break


def _cells_in_front(inf: Inflow, domain: Domain, depth: int, rim: int) -> np.ndarray:
    """The centres (N, 3) of the cells in the first ``depth`` layers inside inflow ``inf``'s face, in front of its
    open cells (those ``rim`` cells or more from the face's edges: :func:`couplekit.sand.emission.inflow_sites`)."""
    face, sites = inflow_sites(inf, domain.shape, domain.dx, 1, rim)  # one point per open cell
    axis = "xyz".index(face[0])
    plane = [a for a in range(3) if a != axis]
    along = (np.arange(depth) + 0.5) * domain.dx
    if face[1] == "+":
        along = domain.size[axis] - along
    pts = np.empty((sites.shape[1] * along.size, 3))
    pts[:, plane[0]] = np.tile(sites[0], along.size)
    pts[:, plane[1]] = np.tile(sites[1], along.size)
    pts[:, axis] = np.repeat(along, sites.shape[1])
    return pts


def _check_inflow_open(n: int, inf: Inflow, obstacles, domain: Domain, problems: list[Problem]) -> None:
    """Some cell in front of inflow ``n``'s open area (the interior cells next to its face) is outside every
    obstacle: an outlet wholly behind obstacles delivers nothing (a probe, session 25: a 4 × 4 outlet behind a box
    validated and ran with no water entering)."""
    pts = _cells_in_front(inf, domain, 1, 0)
    if pts.shape[0] == 0:
        return  # an outlet covering no cell centre: refused by the inflow checks
    try:
        blocked = np.zeros(pts.shape[0], bool)
        for _, shape in obstacles:
            blocked |= np.asarray(shape.sdf(pts)) < 0
    except Exception:  # an SDF that fails here: the obstacle's own problem
        return
    if blocked.all():
        names = ", ".join(f"bodies[{j}]" for j, _ in obstacles)
        problems.append(
            Problem(
                f"inflows[{n}]",
                f"every cell in front of the inflow on face {inf.face} is inside an obstacle ({names}): nothing "
                "would enter the domain",
                "move the obstacle at least one cell off the face in front of the outlet, or move the outlet",
            )
        )


def _check_fluid_room(built: list[tuple[int, Body]], domain: Domain, problems: list[Problem]) -> None:
    """The obstacles leave some fluid cell (a cell centre outside every obstacle), and no water body lies wholly
    inside obstacles (its water would be in solid cells: nothing of it would move). Searched on the cell centres
    as :func:`_check_seeding` searches the seeding lattice (:func:`_seeds_any` with one point per cell)."""
    from .geometry import Difference, overlapping

    size = np.asarray(domain.size, np.float64)
    obstacles = [(i, b.geometry.solver_shape(domain)) for i, b in built if b.kind == "obstacle"]
    if not obstacles:
        return
    cutters = [s for _, s in obstacles]
    try:
        room = _seeds_any(Difference(Box(np.zeros(3), size), cutters).sdf, np.zeros(3), size, domain.dx, 1)
    except Exception:  # an SDF that fails on the cell centres: the shape's own problem
        return
    if room is False:
        problems.append(
            Problem(
                "bodies",
                f"the obstacles ({', '.join(f'bodies[{i}]' for i, _ in obstacles)}) fill every cell of the domain: "
                "no fluid cell is left",
                "shrink or remove an obstacle (an inverted shape, invert = true, keeps what lies inside it)",
            )
        )
        return
    for i, shape in obstacles:  # an obstacle thinner than a cell between two cell centres is no solid cell at all
        lo, hi = (np.clip(np.asarray(v, np.float64), 0.0, size) for v in shape.bounds())
        try:
            covers = _seeds_any(shape.sdf, lo, hi, domain.dx, 1)
        except Exception:
            continue
        if covers is False:
            problems.append(
                Problem(
                    f"bodies[{i}].geometry",
                    f"the obstacle covers no cell centre (dx = {domain.dx:g} m): the fluid, whose solid cells are the "
                    "cells whose centre lies inside an obstacle, would not see it and would flow through it",
                    f"make it at least {domain.dx:g} m thick across, or lower domain.dx",
                )
            )
    for i, b, shape, lo, hi in _shapes_of_kind(built, "water", domain):
        hits = overlapping(shape, cutters)
        if not hits:
            continue
        try:
            inside_only = _seeds_any(shape.sdf, lo, hi, domain.dx, 1) and (
                _seeds_any(Difference(shape, hits).sdf, lo, hi, domain.dx, 1) is False
            )
        except Exception:
            continue
        if inside_only:
            problems.append(_inside_obstacles(i, b, obstacles, hits, "its water would be in solid cells"))


def _check_water_cut_away(built: list[tuple[int, Body]], domain: Domain, problems: list[Problem]) -> None:
    """No water body is wholly removed by its own ``geometry.subtract``: no cell centre would lie inside it, and
    the initial φ would be the interface's tail alone (a probe, session 25: a sphere less a larger one started
    with 272 cells of water). The sand bodies' counterpart is :func:`_check_seeding`'s."""
    from .geometry import Difference

    for i, b, shape, lo, hi in _shapes_of_kind(built, "water", domain):
        if not b.geometry.subtract or not isinstance(shape, Difference):
            continue
        try:
            gone = _seeds_any(shape.sdf, lo, hi, domain.dx, 1) is False
            gone = gone and _seeds_any(shape.shape.sdf, lo, hi, domain.dx, 1) is not False
        except Exception:  # an SDF that fails on the cell centres: the shape's own problem
            continue
        if gone:
            problems.append(
                Problem(
                    f"bodies[{i}].geometry.subtract",
                    f"the water body {b.name!r} is wholly removed by its own geometry.subtract: no cell centre lies "
                    "in what is left, so it would start as a diffuse interface with no water inside",
                    "make the subtracted shapes smaller than the body (or remove them)",
                )
            )


def _check_sand_overlaps(built: list[tuple[int, Body]], domain: Domain, sand: Sand, problems: list[Problem]) -> None:
    """No two sand bodies seed particles at the same points: each body is seeded on its own (the seeding lattice
    over its box), so where two overlap the sand would be packed twice as densely (twice sand.packing_fraction,
    beyond ε_max). Searched as :func:`_check_seeding` searches, on the intersection of each pair whose boxes meet."""
    k = sand.particles_per_axis
    shapes = list(_shapes_of_kind(built, "sand", domain))
    for n, (i, bi, si, loi, hii) in enumerate(shapes):
        for j, bj, sj, loj, hij in shapes[n + 1 :]:
            lo, hi = np.maximum(loi, loj), np.minimum(hii, hij)
            if np.any(hi <= lo):
                continue
            try:
                both = _seeds_any(lambda p, a=si, b=sj: np.maximum(a.sdf(p), b.sdf(p)), lo, hi, domain.dx, k)
            except Exception:  # an SDF that fails on the lattice points: reported by _check_seeding
                continue
            if both:
                problems.append(
                    Problem(
                        f"bodies[{j}].geometry",
                        f"the sand bodies {bi.name!r} (bodies[{i}]) and {bj.name!r} (bodies[{j}]) overlap: each is "
                        "seeded on its own, so the sand there would be packed twice as densely (2 × "
                        f"sand.packing_fraction = {2 * sand.packing_fraction:g}, beyond ε_max = 0.64)",
                        "make them disjoint (e.g. subtract one from the other: geometry.subtract), or merge them into "
                        "one body",
                    )
                )


def _check_max_speed(time: Time, bodies, inflows, problems: list[Problem]) -> None:
    """``time.max_speed``, the speed every time-step check trusts when given, is at least every speed the scene
    states itself: each water or sand body's velocity and each inflow's."""
    if time.max_speed is None:
        return
    given = [(math.hypot(*b.velocity), f"bodies[{i}].velocity") for i, b in bodies if b.kind != "obstacle"]
    given += [(math.hypot(*inf.velocity), f"inflows[{i}].velocity") for i, inf in enumerate(inflows)]
    if not given:
        return
    speed, key = max(given, key=lambda item: item[0])
    if speed > time.max_speed * (1.0 + 1e-9):
        problems.append(
            Problem(
                "time.max_speed",
                f"{time.max_speed:g} m/s is below the speed the scene itself gives, |{key}| = {speed:.4g} m/s (the "
                "time-step checks would trust a speed the flow exceeds from the first step)",
                f"set time.max_speed >= {speed:.4g} m/s, or remove it (the default estimates it from gravity, body "
                "velocities and inflows)",
            )
        )


def _viscous_air(air_lattice_viscosity: float) -> bool:
    """An air more viscous than the 0.01 the outlet map's first two viscosity sets used (Fig. 1's 0.1 is)."""
    return air_lattice_viscosity > 0.01 * (1.0 + 1e-9)


def water_outlet_speed_limit(interface_width: float, across_cells: int, air_lattice_viscosity: float = 0.01) -> float:
    """Largest lattice speed (|velocity| dt/dx) at which a water jet from an outlet (``shape`` = 'rect' or
    'disc') into air at 800:1 was measured to stay finite, by interface width ξ (cells), the outlet's narrower
    extent (cells) and the air's lattice viscosity; ``inf`` where no failure was measured up to 0.08; 0 where
    the scene is refused at any speed.

    Measured (session 18) on a 12 × 12 × 24 box, square outlets of 1-5 cells in the z- wall, σ = 1e-4, M = 0.02,
    1000 steps (1500 at the limits), with the phase field's exact inflow flux, its two-rate collision at the
    inflow default Λ_h = 1/6 (``couplekit.fluid.solver.PHASE_TRT_LAMBDA_INFLOW``) and the flow's bounce-back
    links taking the face's velocity where they cross it (``kernels/lbm_halo.cu``, lbm_link_wall_cu: before it,
    narrow outlets put part of their volume flux into the cells beside them and 2-cell outlets diverged at
    0.06), at three viscosity sets: ν_h = ν_l = 0.01; the scenes' ν_h = 1e-4, ν_l = 0.01 with their closures
    (odd-rate floor, Smagorinsky); Fig. 1's ν_h = 5e-4, ν_l = 0.1 with the closures (the "viscous air";
    docs/fluid-stability.md, "Water outlets at 800:1", has the map):

    * ξ ≥ 4: outlets of ≥ 2 cells finite to 0.08 at every viscosity set (ξ = 4 and 6); 1-cell outlets to 0.08
      except with the viscous air (0.04; NaN at 0.08 by step 350 at ξ = 4).
    * 3 ≤ ξ < 4: outlets of ≥ 2 cells finite to 0.06 (NaN at 0.08: 5 cells at ν = 0.01 and ξ = 3; 3 and 5 cells
      with the viscous air, 2 cells with the scenes' closures, at ξ = 3), except 2-cell outlets with the viscous
      air: to 0.02 (NaN at 0.04 by step 200 at ξ = 3). 1-cell outlets as 2-cell ones.
    * 2.5 ≤ ξ < 3 (session 30, the same box and the scenes' closures, 1500 steps): outlets of 1-8 cells finite to
      0.04 (ν_h = 1e-4, ν_l = 0.01: peak ≤ 1.8 u_in; ν_h = ν_l = 0.01 alike); with the viscous air outlets of
      ≥ 3 cells to 0.02 (5 cells ✗ at 0.04 by step 150), under 3 cells to 0.01 (1 cell ✗ at 0.02 by step 1150,
      2 cells by step 300).
    * ξ < 2.5: refused. Below 2.5 cells the interface at 800:1 is under-resolved independently of outlets: a
      water ball moving through still air in a periodic box with the scenes' fluid
      (:func:`couplekit.cautions.narrow_interface_caution`) diverges at 0.02 at ξ = 2 and at 0.04 at ξ = 2.25;
      outlets at ξ = 2 diverge at 0.02 within 1500 steps (2-8 cells, by steps 200-1200; with the viscous air at
      0.01), 2 cells at ξ = 2.25 at 0.02 by step 1150.

    A whole-face inflow is not limited (an 8 × 8 duct runs at ξ = 2, u = 0.02 and at ξ = 4, u = 0.08).
    """
    viscous = _viscous_air(air_lattice_viscosity)
    if interface_width < OUTLET_MIN_INTERFACE_WIDTH:
        return 0.0
    if interface_width < 3.0:
        if viscous:
            return 0.02 if across_cells >= 3 else 0.01
        return 0.04
    if interface_width >= 4.0:
        return 0.04 if (viscous and across_cells < 2) else math.inf
    if viscous and across_cells < 3:
        return 0.02
    return 0.06


OUTLET_MIN_INTERFACE_WIDTH = 2.5
"""The narrowest interface (cells) at which water outlets into air at 800:1 run (:func:`water_outlet_speed_limit`):
below it a moving interface is under-resolved whether or not an outlet makes it."""


def _check_water_outlets(domain: Domain, time: Time, fluid: Fluid | None, inflows, problems: list[Problem]) -> None:
    """Water outlets into air within the measured stable range (:func:`water_outlet_speed_limit`), refused
    before any allocation with the key and the fix."""
    if fluid is None or fluid.phases != 2:
        return
    xi = float(fluid.interface_width)
    nu_air = float(fluid.air_lattice_viscosity)
    for i, inf in enumerate(inflows):
        if inf.kind != "water" or inf.shape == "face" or inf.center is None or inf.face not in SCENE_FACES:
            continue
        if _face_too_large(domain, inf.face):
            continue
        if (inf.shape == "rect" and inf.size is None) or (inf.shape == "disc" and inf.radius is None):
            continue
        mask = region_mask(domain.shape, domain.dx, solver_face(inf.face), inf.shape, inf.center, inf.size, inf.radius)
        if not mask.any():
            continue  # reported by _check_outlets_on_grid
        across = int(min(np.count_nonzero(mask.any(axis=0)), np.count_nonzero(mask.any(axis=1))))
        speed = math.sqrt(sum(v * v for v in inf.velocity))
        lattice = speed * time.dt / domain.dx
        limit = water_outlet_speed_limit(xi, across, nu_air)
        if lattice <= limit * (1.0 + 1e-9):
            continue
        if xi < OUTLET_MIN_INTERFACE_WIDTH:
            what = (
                f"a water outlet at fluid.interface_width = {xi:g} is refused at any speed: at 800:1 an interface "
                f"narrower than {OUTLET_MIN_INTERFACE_WIDTH:g} cells is under-resolved, independently of outlets "
                "(a water ball moving through still air at lattice speed 0.02 diverges at width 2)"
            )
            fix = (
                "set fluid.interface_width >= 4 (outlets at least 2 cells across then run at lattice speeds up to "
                f"0.08; at {OUTLET_MIN_INTERFACE_WIDTH:g} up to 0.04)"
            )
        else:
            cells = f"{across} cell{'s' if across != 1 else ''}"
            why = f"outlets {cells} across at fluid.interface_width {'< 4' if xi < 4.0 else '>= 4'}" + (
                f" with fluid.air_lattice_viscosity = {nu_air:g} > 0.01" if _viscous_air(nu_air) else ""
            )
            options = [f"lower the speed to <= {limit * domain.dx / time.dt:.3g} m/s (lattice {limit:g})"]
            wider = next((n for n in (2, 3) if n > across and water_outlet_speed_limit(xi, n, nu_air) >= lattice), None)
            if wider is not None:
                options.append(f"widen the outlet to >= {wider} cells ({wider * domain.dx:g} m) across")
            if xi < 4.0:
                options.append("set fluid.interface_width >= 4")
            fix = ", or ".join(options)
            what = (
                f"a water jet at lattice speed {lattice:.3g} (|velocity| dt/dx) from an outlet {cells} across "
                f"diverges at fluid.interface_width = {xi:g} ({why}: measured stable up to {limit:g})"
            )
        problems.append(Problem(f"inflows[{i}].velocity", what, fix))


def depth_range(lo, hi, down) -> tuple[float, float]:
    """(shallowest, deepest) of the box [``lo``, ``hi``]'s corners along the unit vector ``down`` (gravity's
    direction): a body's top and bottom, a domain's ceiling and floor."""
    depth = [float(np.dot((x, y, z), down)) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    return min(depth), max(depth)


def _speed_estimate(domain: Domain, time: Time | dict, bodies, inflows, _cache) -> tuple[float, str]:
    g = np.asarray(domain.gravity, dtype=np.float64)
    gmag = float(np.linalg.norm(g))
    down = g / gmag if gmag > 0 else np.array([0.0, 0.0, -1.0])
    ceiling, floor = depth_range((0.0, 0.0, 0.0), domain.size, down)
    best, why = 0.0, "nothing moves"
    for b in bodies:
        if b.kind == "obstacle":
            continue
        top, _ = depth_range(*b.geometry.bounds(domain), down)
        drop = max(0.0, floor - top)
        s = float(np.linalg.norm(b.velocity)) + math.sqrt(2 * gmag * drop)
        if s > best:
            best, why = s, f"body {b.name!r}: |v0| + sqrt(2 g h) with a fall of h = {drop:.4g} m"
    height = floor - ceiling
    for i, inf in enumerate(inflows):
        s = float(np.linalg.norm(inf.velocity)) + math.sqrt(2 * gmag * height)
        if s > best:
            best, why = s, f"inflows[{i}]: |v| + sqrt(2 g H) over the domain height H = {height:.4g} m"
    max_speed = time.max_speed if isinstance(time, Time) else time.get("max_speed")
    if max_speed is not None:
        return float(max_speed), "time.max_speed"
    return best, why


def _check_time_step(
    domain: Domain,
    time: Time,
    fluid: Fluid | None,
    sand: Sand | None,
    bodies,
    inflows,
    problems,
    scheduler: Scheduler | None = None,
    body_ids: list[int] | None = None,
) -> None:
    """The fluid's limits for time.dt (Mach number, weak compressibility, capillary waves; relaxation time is
    checked with the viscosities) and the sand's (elastic, particle CFL) for the sand step the ``scheduler``
    makes of it (:func:`_sand_step_problem` names the key to change)."""
    dt, dx = time.dt, domain.dx
    if fluid is not None and fluid.gravity is not None:  # the fluid's own acceleration replaces domain.gravity
        domain = replace(domain, gravity=tuple(float(v) for v in fluid.gravity))
    try:
        speed, why = _speed_estimate(domain, time, bodies, inflows, {})
    except Exception:
        return  # the geometry problem is already reported (_check_inside)
    if fluid is not None:
        units = Units(dx=dx, dt=dt, rho=fluid.water_density)
        if speed > 0 and units.mach(speed) > time.mach_limit:
            problems.append(
                Problem(
                    "time.dt",
                    f"dt = {dt:g} s makes the fastest expected flow ({speed:.3g} m/s, from {why}) Mach {units.mach(speed):.3g} on the lattice (limit time.mach_limit = {time.mach_limit:g})",
                    f"use dt <= {_at_most(units.max_dt(speed, time.mach_limit))} s, or a larger dx; if the flow is slower than estimated, set time.max_speed",
                )
            )
        g_lat = units.to_lattice(float(np.linalg.norm(domain.gravity)), "acceleration")
        height_cells = max(domain.resolution)
        variation = g_lat * height_cells / CS2
        if variation > LIMITS["max_density_variation"]:
            limit = math.sqrt(
                LIMITS["max_density_variation"] * CS2 * dx / (float(np.linalg.norm(domain.gravity)) * height_cells)
            )
            problems.append(
                Problem(
                    "time.dt",
                    f"gravity in lattice units ({g_lat:.3g}) over {height_cells} cells compresses the fluid by {100 * variation:.0f}% (limit {100 * LIMITS['max_density_variation']:.0f}%: weakly compressible LBM)",
                    f"use dt <= {_at_most(limit)} s",
                )
            )
        if fluid.phases == 2 and fluid.surface_tension > 0:
            sigma_lat = units.to_lattice(fluid.surface_tension, "surface_tension")
            rho_l = fluid.air_density / fluid.water_density
            cap = (1.0 + rho_l) / (4 * math.pi)
            if sigma_lat > cap:
                limit = math.sqrt(cap * fluid.water_density * dx**3 / fluid.surface_tension)
                problems.append(
                    Problem(
                        "time.dt",
                        f"surface tension {fluid.surface_tension:g} N/m is {sigma_lat:.3g} in lattice units, above the capillary-wave limit (ρ_h + ρ_l)/(4π) = {cap:.3g} (Brackbill et al. 1992)",
                        f"use dt <= {_at_most(limit)} s, or lower fluid.surface_tension",
                    )
                )
    jets = [i for i, inf in enumerate(inflows) if inf.sand_fraction > 0]
    if sand is None or scheduler is None or not (any(b.kind == "sand" for b in bodies) or jets):
        return
    # bodies at their density, emitted jet sand (couplekit.sand.emission) at sand.density
    ids = body_ids if body_ids is not None else range(len(bodies))
    carriers = [
        (f"bodies[{i}]", b.density or sand.density) for i, b in zip(ids, bodies, strict=True) if b.kind == "sand"
    ]
    carriers += [(f"the sand of inflows[{i}]", sand.density) for i in jets]
    limits = []  # (limit s, what it is, fix when the sand's own step is what to change)
    for what, rho in carriers:
        cp = sand.p_wave_speed(rho)
        elastic = sand.elastic_cfl * dx / cp
        limits.append(
            (
                elastic,
                f"the MPM elastic limit of {what}: C_e dx / c_p = {sand.elastic_cfl:g} x {dx:g} / {cp:.3g} m/s = {elastic:.3g} s",
                "or a softer sand (lower sand.youngs_modulus)",
            )
        )
    if speed > 0:
        cfl = sand.cfl * dx / speed
        limits.append(
            (
                cfl,
                f"the MPM particle CFL limit C_v dx / v = {cfl:.3g} s for the expected speed {speed:.3g} m/s ({why})",
                "if the sand moves slower, set time.max_speed",
            )
        )
    for limit, what, hint in sorted(limits, key=lambda item: item[0]):  # the tightest first: one message
        problem = _sand_step_problem(dt, limit, what, hint, scheduler)
        if problem is not None:
            problems.append(problem)
            return


def _at_most(x: float) -> str:
    """``x`` rounded down to 3 significant digits, as a fix's bound is printed: rounded to nearest (``:.3g``) it
    could lie above the limit, and following the fix was refused again."""
    if not (x > 0 and math.isfinite(x)):
        return f"{x:.3g}"
    scale = 10.0 ** (math.floor(math.log10(x)) - 2)
    return f"{math.floor(x / scale * (1 + 1e-12)) * scale:.3g}"


def _sand_step_problem(dt: float, limit: float, what: str, hint: str, scheduler: Scheduler) -> Problem | None:
    """The problem (naming the key the scheduler's sand step comes from) when the sand's step breaks ``limit``."""
    tol = 1.0 + 1e-9
    if scheduler.kind == "subcycle" and scheduler.substeps == "auto":
        need = max(1, math.ceil(dt / limit / tol))
        if need <= scheduler.max_substeps:
            return None
        return Problem(
            "scheduler.max_substeps",
            f"the sand needs {need} substeps of dt = {dt:g} s to meet {what}, more than max_substeps = {scheduler.max_substeps}",
            f"raise scheduler.max_substeps to >= {need}, or lower time.dt",
        )
    if scheduler.kind == "subcycle":
        k = int(scheduler.substeps)
        if dt / k <= limit * tol:
            return None
        need = math.ceil(dt / limit / tol)
        return Problem(
            "scheduler.substeps",
            f"the substep dt / substeps = {dt:g} / {k} = {dt / k:.3g} s breaks {what}",
            f'use scheduler.substeps >= {need} (or substeps = "auto"), {hint}',
        )
    if scheduler.kind == "multirate":
        m = int(scheduler.sand_every)
        if m * dt <= limit * tol:
            return None
        most = math.floor(limit * tol / dt)
        # dt above the limit itself: no sand_every helps; the sand step m dt needs dt <= limit / m, or fewer fluid
        # steps per sand step (a probe followed "lower time.dt to <= limit" and was refused again)
        fix = (
            f"use scheduler.sand_every <= {most}"
            if most >= 1
            else f"lower time.dt to <= {_at_most(limit / m)} s (limit / sand_every), or sub-cycle the sand ([scheduler] "
            f'kind = "subcycle")'
        )
        return Problem(
            "scheduler.sand_every",
            f"the sand step sand_every x dt = {m} x {dt:g} = {m * dt:.3g} s breaks {what}",
            f"{fix}, {hint}",
        )
    if dt <= limit:
        return None
    return Problem(
        "time.dt",
        f"dt = {dt:g} s breaks {what}",
        f'use dt <= {_at_most(limit)} s, {hint}; or sub-cycle the sand ([scheduler] kind = "subcycle")',
    )


def scene_dict(scene: Scene) -> dict:
    """The parsed dataclasses as a plain dict (for reports and tests)."""
    return asdict(scene)
