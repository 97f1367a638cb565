"""Set-ups a scene may ask for that were measured to diverge or to come out wrong, or that lie beyond what was
measured: one ``caution:`` line each, printed by ``couplekit validate`` and logged when a run starts
(:func:`stability_cautions`). Cautions, not refusals: what validation refuses is in :mod:`couplekit.scene.model`.
Each caution's docstring gives the measurement behind it and its test."""

from __future__ import annotations

import math

import numpy as np

from .assembly import fluid_params, sand_retention_flags
from .scene import Scene

__all__ = [
    "mobility_caution",
    "narrow_interface_caution",
    "sand_entry_caution",
    "sand_entry_speeds",
    "stability_cautions",
]


def stability_cautions(scene: Scene) -> list[str]:
    """Set-ups a scene may ask for that were measured to diverge, or lie beyond what was measured, one line each
    (empty when none): printed by ``couplekit validate`` and logged when a run starts. Not refusals: the paper's
    own collision is one. Besides :func:`_input_cautions` (a density ratio beyond the measured one, a liquid let
    into a box with no outflow):

    * The odd-moment rate floor off (``fluid.odd_lambda = 0``, or too small to act) where the fluid's lowest
      lattice viscosity is below ``FluidParams.odd_nu_max`` (5e-4) and there are no-slip edges (walls on two
      axes, an obstacle, or an outlet's rim): the paper's collision is linearly unstable at bounce-back edges and
      corners there (docs/fluid-stability.md: at ν = 1e-4 the linearised step grows ×e every ~150 steps, a
      still 800:1 tank blew up near step 2500; ν = 1e-3 is stable). Flat walls on one axis only and periodic
      faces are stable."""
    fl = scene.fluid
    out = _frame_caution(scene)
    if fl is None:
        return out
    out += _input_cautions(scene)
    prm = fluid_params(scene, scene.units())
    two = fl.phases == 2
    nu_ref = prm.odd_reference_viscosity(two)
    if prm.odd_floor_acts(two) or nu_ref >= prm.odd_nu_max:
        return out
    wall_axes = {face[0] for face, kind in scene.domain.boundary.items() if kind in ("wall", "inflow")}
    obstacles = any(b.kind == "obstacle" for b in scene.bodies)
    outlets = any(i.shape != "face" for i in scene.inflows)
    if len(wall_axes) < 2 and not obstacles and not outlets:
        return out
    where = "walls on two axes" if len(wall_axes) >= 2 else ("an obstacle" if obstacles else "an outlet in a wall")
    steps = scene.time.frames * scene.time.steps_per_frame
    floor = (
        "fluid.odd_lambda = 0"
        if fl.odd_lambda == 0
        else f"fluid.odd_lambda = {fl.odd_lambda:g} (too small to act here)"
    )
    return out + [
        f"{floor} at lattice viscosity {nu_ref:g} (< {prm.odd_nu_max:g}) with no-slip edges ({where}): the paper's "
        f"collision is linearly unstable at bounce-back edges and corners at this viscosity (it grows by a factor e about "
        f"every 150 steps at 1e-4; a still tank diverged near step 2500; this scene runs {steps:,} steps); "
        "keep fluid.odd_lambda = 0.015 with fluid.smagorinsky = 0.1 (the scene defaults) unless you mean to run "
        "the paper's collision (docs/fluid-stability.md)"
    ]


MEASURED_DENSITY_RATIO = 1000.0
"""The largest density ratio the two-phase validations ran at (the static drop of
tests/fluid/test_two_phase_validation.py, 1000:1; the paper's scenes are 800:1)."""


FP16_RESOLUTION = 2.0**-11
"""Half a binary16 ulp relative to the value (fluid.storage = 'fp16' rounds each stored f − w to nearest)."""


def _fp16_gravity_caution(scene: Scene) -> list[str]:
    """fp16 storage rounds each stored f − w to ~2^-11 of itself every step (docs/precision.md). Gravity adds
    ~3 w_q c_q·g to a population per step, while f_q − w_q ~ 3 w_q c_q·u where the fluid moves at lattice speed u:
    above u ≈ g / 2^-11 the increment is under half a binary16 step and is rounded away, so gravity stops
    accelerating the flow there (a body-force-driven channel at ν = 0.01, 16 cells across, stalled at 0.81× its
    speed with fp16, 0.5 % off with fp32). A caution when the scene's fastest expected flow is above that speed."""
    units = scene.units()
    g_lat = float(np.linalg.norm(fluid_params(scene, units).gravity))  # the fluid's (fluid.gravity or domain's)
    if g_lat <= 0:
        return []
    speed, _ = scene.expected_max_speed()
    u_lat = units.to_lattice(speed, "velocity")
    u_lost = g_lat / FP16_RESOLUTION
    if u_lat <= u_lost:
        return []
    return [
        f"fluid.storage = 'fp16': gravity adds {g_lat:.2g} (lattice units) to the flow's velocity per step, under "
        f"half a binary16 step of the stored populations wherever the fluid moves faster than {u_lost:.2g} "
        f"(this scene expects up to {u_lat:.2g}): there each step's gravity is rounded away, and slow gravity-driven "
        "flow stalls (a body-forced channel reached 0.81x its speed); use fluid.storage = 'fp32' where that "
        "matters (docs/precision.md)"
    ]


NARROW_INTERFACE_RATIO = 400.0
"""The largest density ratio at which a water ball moving at lattice speed 0.04 ran at interface width 2
(:func:`narrow_interface_caution`)."""

NARROW_INTERFACE_SPEED = 0.01
"""The lattice speed a water ball ran at through air at 800:1 and interface width 2 (:func:`narrow_interface_caution`)."""


def narrow_interface_caution(scene: Scene) -> list[str]:
    """An interface narrower than :data:`couplekit.scene.model.OUTLET_MIN_INTERFACE_WIDTH` cells at a density
    ratio above :data:`NARROW_INTERFACE_RATIO` in a scene whose fastest expected flow is above
    :data:`NARROW_INTERFACE_SPEED` (lattice): a moving interface that sharp diverges at 800:1.

    Measured (session 30; tests/fluid/test_narrow_interface.py): a water ball of radius 6 cells moving through
    still air in a periodic 24 × 24 × 32 box with the scenes' fluid (lattice viscosities 1e-4 / 1e-2, their
    closures, M = 0.02, σ = 0.0728 N/m at dx = 1 cm, dt = 1 ms), 1000 steps: at 800:1 width 2 diverges at lattice
    speed 0.02 (by step 200; runs at 0.01, also with radius 4), width 2.25 at 0.04 (by step 220; runs at 0.02 and
    0.03); widths 2.4 and 2.5 run at 0.04, 2.5 at 0.06 (0.08 diverges by step 80, as a Mach limit would); at
    width 2, 400:1 and 200:1 run at 0.04. On a case not measured for it, Fig. 16's water-only dam break (small
    variant, lattice speed 0.084 at its end at width 4) diverges by step 800 of 960 at width 2 and runs to its end at 2.5 (and 4).
    Water outlets, whose speed is known, are refused below that width
    (:func:`couplekit.scene.model.water_outlet_speed_limit`); elsewhere the speed is an estimate
    (``Scene.expected_max_speed``), hence a caution."""
    from .scene.model import OUTLET_MIN_INTERFACE_WIDTH

    fl = scene.fluid
    ratio = fl.water_density / fl.air_density
    if fl.phases != 2 or fl.interface_width >= OUTLET_MIN_INTERFACE_WIDTH or ratio <= NARROW_INTERFACE_RATIO:
        return []
    speed, _ = scene.expected_max_speed()
    u_lat = scene.units().to_lattice(speed, "velocity")
    if u_lat <= NARROW_INTERFACE_SPEED:
        return []
    return [
        f"fluid.interface_width = {fl.interface_width:g} cells at {ratio:.3g}:1 with flow expected up to lattice "
        f"speed {u_lat:.2g}: an interface this sharp is under-resolved once it moves (a water ball moving through "
        f"air at 800:1 diverged at lattice speed 0.02 at width 2 and 0.04 at width 2.25, and ran at 0.06 at width "
        f"2.5); set fluid.interface_width >= {OUTLET_MIN_INTERFACE_WIDTH:g} (4, the default, is the validated one)"
    ]


EXAMPLE_MOBILITY = 0.02
"""The phase-field mobility (lattice) every shipped example and validation runs at (the scene default)."""

EXAMPLE_INTERFACE_WIDTH = 4.0
"""The interface width (cells) every shipped example but Fig. 1's small variant (6) runs at (the scene default)."""

MOBILITY_IMPACT_LIMITS: dict[float, tuple[float, float]] = {
    2.5: (1.0, 2.0),
    3.0: (2.75, 4.0),
    4.0: (4.0, 5.5),
    5.0: (5.5, 8.0),
    6.0: (8.0, 11.0),
    8.0: (8.0, 11.0),
}
"""Interface width (cells) → (u/M at or below which every run ran, the smallest u/M at which one diverged), u
the lattice speed and M the lattice mobility, for a water ball of radius 6 cells thrown at a wall through still air at 800:1 (the scenes'
fluid; session 32: tests/fluid/test_mobility_limit.py has the whole map, `python benchmarks/mobility_map.py`
runs it again). :func:`mobility_caution` reads the
second number at the widest measured width not above the scene's."""


def mobility_caution(scene: Scene) -> list[str]:
    """A phase-field mobility below the examples' (:data:`EXAMPLE_MOBILITY`), or an interface narrower than theirs
    (:data:`EXAMPLE_INTERFACE_WIDTH`, down to the 2.5 cells below which :func:`narrow_interface_caution` speaks), at
    a density ratio above :data:`NARROW_INTERFACE_RATIO`, in a scene whose expected lattice speed u makes u/M at
    least the ratio at which a moving interface was measured to diverge (:data:`MOBILITY_IMPACT_LIMITS`).

    Why: the conservative phase field keeps its tanh profile by the mobility's sharpening flux, ∝ M/ξ; a flow that
    strains the interface faster than that (an impact squeezing the air between water and a wall) tears the
    profile, φ leaves [0, 1] and the 800:1 density jump diverges within a few dozen steps. Measured (session 32,
    the ball of :data:`MOBILITY_IMPACT_LIMITS`, 600 steps): at width 4 every run up to u/M = 4 ran (M = 0.02,
    0.01 and 0.005 each reached it) and runs diverged from 5.5 (M = 0.02, u = 0.11) and 8 (M = 0.01, 0.005); at
    M = 0.0025 even u = 0.02 diverged. A ball moving through open air tolerates about twice the ratio (width 4: ran to 8, diverged at
    11). On cases not measured for it, Fig. 6's raindrop (small variant, u/M = 7.6 expected at M = 0.02 and width 4,
    where it runs) diverged by step 70 at M = 0.01 and 0.0075 and at width 3, and at Δt/4 with M = 0.005.
    The examples' own (M, width) = (0.02, 4) run up to u/M = 8.1 expected (estimates are upper bounds: the
    raindrop's impact peaks at 0.124, u/M = 6.2), so they and wider, more mobile interfaces are not cautioned."""
    fl = scene.fluid
    if fl.phases != 2 or fl.water_density / fl.air_density <= NARROW_INTERFACE_RATIO:
        return []
    width, mobility = fl.interface_width, fl.mobility
    if width < min(MOBILITY_IMPACT_LIMITS) or (mobility >= EXAMPLE_MOBILITY and width >= EXAMPLE_INTERFACE_WIDTH):
        return []
    measured = max(w for w in MOBILITY_IMPACT_LIMITS if w <= width)
    ran, diverged = MOBILITY_IMPACT_LIMITS[measured]
    speed, source = scene.expected_max_speed()
    u_lat = scene.units().to_lattice(speed, "velocity")
    ratio = u_lat / mobility
    if ratio < diverged:
        return []
    departs = []
    if mobility < EXAMPLE_MOBILITY:
        departs.append(f"fluid.mobility = {mobility:g} (examples: {EXAMPLE_MOBILITY:g})")
    if width < EXAMPLE_INTERFACE_WIDTH:
        departs.append(f"fluid.interface_width = {width:g} (examples: {EXAMPLE_INTERFACE_WIDTH:g})")
    return [
        f"{' and '.join(departs)} with flow expected up to lattice speed {u_lat:.2g} ({source}): u/M = {ratio:.3g}, "
        f"where a water ball hitting a wall through air at 800:1 diverged (width {measured:g}: ran to u/M = {ran:g}, "
        f"diverged from {diverged:g}); the phase field cannot hold so sharp an interface against such a flow. Keep "
        f"the examples' fluid.mobility = {EXAMPLE_MOBILITY:g} and fluid.interface_width = {EXAMPLE_INTERFACE_WIDTH:g} "
        f"(they run such flows), or lower time.dt to <= {scene.time.dt * ran / ratio:.3g} s (u/M = {ran:g}; u/M "
        "falls with dt) (docs/fluid-stability.md, 'The mobility a moving interface needs')"
    ]


def _small_drop_cautions(scene: Scene) -> list[str]:
    """A water body smaller than its own interface on every axis (under 2 interface widths across): the phase
    field's tanh profile (``build_fluid``) holds far more water than the body (a probe's sphere of 0.2 cell took
    ~800x its volume, one of 2 cells 3.6x). The initial water of such a body, summed on its cells, against its
    volume (sub-cell points inside); a caution above 1.25x."""
    dom, w = scene.domain, scene.fluid.interface_width
    out = []
    for i, b in enumerate(scene.bodies):
        if b.kind != "water":
            continue
        try:
            shape = b.geometry.shape(dom, 0.25 * dom.dx)
            lo, hi = (np.asarray(v, np.float64) for v in shape.bounds())
        except Exception:  # a shape that does not build is validation's problem
            continue
        if np.any(hi - lo >= 2 * w * dom.dx):
            continue
        pad = 2 * w * dom.dx
        a = np.floor((lo - pad) / dom.dx).astype(int)
        z = np.ceil((hi + pad) / dom.dx).astype(int)
        axes = [(np.arange(a[k], z[k]) + 0.5) * dom.dx for k in range(3)]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        phi = 0.5 * (1.0 - np.tanh(2.0 * np.asarray(shape.sdf(pts)) / (dom.dx * w)))
        fine = [(np.arange(4 * a[k], 4 * z[k]) + 0.5) * dom.dx / 4 for k in range(3)]
        sub = np.stack(np.meshgrid(*fine, indexing="ij"), axis=-1).reshape(-1, 3)
        volume = float((np.asarray(shape.sdf(sub)) < 0).sum()) / 64  # in cells
        ratio = float(phi.sum()) / volume if volume > 0 else np.inf
        if ratio > 1.25:
            across = float((hi - lo).max() / dom.dx)
            amount = f"{ratio:.3g}x its volume of water" if np.isfinite(ratio) else f"{phi.sum():.3g} cells of water"
            out.append(
                f"bodies[{i}] (water) is only {across:.3g} cells across, less than 2 interface widths "
                f"(fluid.interface_width = {w:g} cells): the phase field's interface profile starts it with "
                f"{amount}; make it at least {2 * w:g} cells across (or lower domain.dx)"
            )
    return out


def _frame_caution(scene: Scene) -> list[str]:
    """A frame is a whole number of steps (round(frame_duration / dt), at least 1); a caution when that is more
    than 2 % off the frame_duration asked for (the shipped examples are within 1.0 %) (a probe: 5e-5 s at dt = 2e-5 s ran frames of 4e-5 s, silently)."""
    t = scene.time
    got = t.steps_per_frame * t.dt
    if abs(got - t.frame_duration) <= 0.02 * t.frame_duration:
        return []
    return [
        f"time.frame_duration = {t.frame_duration:g} s is {t.frame_duration / t.dt:.3g} steps of dt = {t.dt:g} s: "
        f"frames are {t.steps_per_frame} steps ({got:g} s, {100 * (got / t.frame_duration - 1):+.0f} %); make "
        "time.frame_duration a multiple of time.dt"
    ]


def _multirate_frame_caution(scene: Scene) -> list[str]:
    """A multi-rate block of m fluid steps takes its one sand step at its first fluid step, so inside a block the
    sand is ahead of the fluid's clock by up to m − 1 steps. Where m does not divide the steps of a frame, frames
    fall inside blocks and show (and their diagnostics stamp) the sand that far ahead of the frame's time (a probe:
    m = 3, 5 steps per frame, the sand's velocity that of t + dt at t); a caution naming the divisors that align.
    Sand steps longer than a frame are refused (couplekit.scene.model)."""
    sch, n = scene.scheduler, scene.time.steps_per_frame
    if sch.kind != "multirate" or sch.sand_every <= 1 or n % sch.sand_every == 0 or sch.sand_every > n:
        return []
    m = sch.sand_every
    fit = [d for d in range(2, m) if n % d == 0]
    fix = f"scheduler.sand_every = {fit[-1]} divides them" if fit else f"no sand_every in 2..{m} divides them"
    return [
        f"scheduler.sand_every = {m} does not divide the {n} fluid steps of a frame: frames inside a block show the "
        f"sand up to {m - 1} fluid steps ({(m - 1) * scene.time.dt:.3g} s) ahead of the frame's time (a block's sand "
        f"step is taken at its first fluid step); {fix}, or make time.frame_duration a multiple of {m} steps"
    ]


def _input_cautions(scene: Scene) -> list[str]:
    """Cautions about what a scene asks of the fluid beyond what was measured or what can have a steady state:
    a density ratio beyond :data:`MEASURED_DENSITY_RATIO`; a water body smaller than its interface
    (:func:`_small_drop_cautions`); a moving interface narrower than 2.5 cells at 800:1
    (:func:`narrow_interface_caution`); a mobility or interface width below the examples' against a flow that
    tears the interface (:func:`mobility_caution`); multi-rate blocks that do not fit a frame (:func:`_multirate_frame_caution`);
    a single-phase fluid let in through an inflow with no
    outflow face (the liquid has nowhere to go: its pressure rises for as long as the inflow runs); sand kept only
    one cell off the walls (:func:`_wall_layer_caution`); an absorption rate beyond the measured one
    (:func:`_absorption_caution`); sand that falls onto the water at a lattice speed below the examples'
    (:func:`sand_entry_caution`)."""
    fl, out = scene.fluid, []
    if fl.storage == "fp16":
        out += _fp16_gravity_caution(scene)
    if fl.phases == 2 and fl.water_density / fl.air_density > MEASURED_DENSITY_RATIO:
        out.append(
            f"fluid.water_density / fluid.air_density = {fl.water_density / fl.air_density:.3g} is beyond the "
            f"{MEASURED_DENSITY_RATIO:g}:1 the two-phase validations ran at (the paper's scenes: 800:1): the "
            "interface may not hold; check it on a small variant first"
        )
    if fl.phases == 2:
        out += _small_drop_cautions(scene)
        out += narrow_interface_caution(scene)
        out += mobility_caution(scene)
    out += _multirate_frame_caution(scene)
    out += _wall_layer_caution(scene)
    out += _absorption_caution(scene)
    out += sand_entry_caution(scene)
    if fl.phases == 1 and scene.inflows and "outflow" not in scene.domain.boundary.values():
        out.append(
            "a single-phase fluid enters through inflows[0] but no face is an outflow: the liquid has nowhere to "
            "go, so its pressure and density rise for as long as the inflow runs (weakly compressible LBM); make "
            'a face an outflow (domain.boundary.<face> = "outflow") unless the run is short'
        )
    return out


def _wall_layer_caution(scene: Scene) -> list[str]:
    """``sand.wall_layers = 1`` in a scene coupling sand to a fluid: a bed whose grains reach the first cell off a
    wall leaves a thin fringe of sand (fraction ~0.01-0.02) in the wall's first cell, and where that fringe meets a
    floor-wall edge the water grows a current after ~3000 steps, driven by Eq. 39's porosity-slip term (measured,
    docs/fluid-stability.md: a 20 x 12 x 12 bed at ν_h = 1e-3, lattice speed 8e-5 to 8e-3 from step 3000 to 6000,
    growing; the same bed at the default 2 stays at 5e-5 for 7000 steps)."""
    if scene.sand is None or scene.sand.wall_layers != 1 or not scene.has_sand:
        return []
    steps = scene.time.frames * scene.time.steps_per_frame
    return [
        f"sand.wall_layers = 1 lets sand rest in the first cell off a wall: where that thin fringe meets a "
        "floor-wall edge the water grows a spurious current after ~3000 steps (docs/fluid-stability.md; this "
        f"scene runs {steps:,} steps); keep 2 (the default) unless water must not pass between the sand and the "
        "walls"
    ]


MEASURED_ABSORPTION_RATE = 0.03
"""The largest ``sand.absorption_rate`` measured to run (a probe, session 25: a dry bed under a pool, dx = 1 cm,
finite for 2000 steps at 0.03; at 0.05 non-finite at step 327, 0.1 at step 171; the paper's scenes 0.001-0.003)."""


def _absorption_caution(scene: Scene) -> list[str]:
    """Water retention at an absorption rate above :data:`MEASURED_ABSORPTION_RATE`: the uptake drains the
    water that seeps into a dry bed's pores about as fast as it arrives, φ there falls below 0, and the air in
    those pores, still under the water's pressure gradient, accelerates until the run diverges (measured at
    0.05: lattice speed 0.034 at step 300, 1.5 at 325, NaN at 327, in cells of φ ≈ −0.01)."""
    if scene.sand is None or True not in sand_retention_flags(scene):
        return []
    rate, tau = scene.sand.absorption_rate, scene.sand.absorption_time
    if rate <= MEASURED_ABSORPTION_RATE:
        return []
    given = (
        f"sand.absorption_time = {tau:g} s gives R_a = time.dt / absorption_time = {rate:.3g} per step, which"
        if tau is not None
        else f"sand.absorption_rate = {rate:g}"
    )
    return [
        f"{given} is above the {MEASURED_ABSORPTION_RATE:g} measured to run: a dry bed under "
        "water went non-finite at 0.05 (step 327) and 0.1 (step 171), its drained pores' air accelerating; the "
        "paper's scenes use 0.001-0.003 (docs/examples.md, Fig. 10)"
    ]


SAND_ENTRY_LATTICE_SPEED = 0.01
"""The smallest lattice speed U Δt/Δx at which the example scenes' sand meets the water surface (Fig. 8's balls,
0.0102 by :func:`sand_entry_speeds`' free fall; Figs. 2, 13, 14: 0.016-0.033): the scenes were checked there
(:func:`sand_entry_caution`)."""


def sand_entry_speeds(scene: Scene) -> list[tuple[int, float, float]]:
    """(body index, fall h in m, speed U in m/s) of each sand body released above a water body's top (under it
    along gravity, where gravity lies along an axis): U = |v0| + sqrt(2 g h), h from the sand's lowest point to the
    highest water top under it (the bodies' bounding boxes; drag in the air ignored, so U is an upper bound: Fig. 8's
    balls measure ~2.7 m/s where this gives 3.2). Two-phase fluids only; empty without gravity."""
    from .scene.model import depth_range

    fl, dom = scene.fluid, scene.domain
    if fl is None or fl.phases != 2:
        return []
    g = np.asarray(dom.gravity, dtype=np.float64)  # the sand falls under domain.gravity (fluid.gravity is the fluid's)
    gmag = float(np.linalg.norm(g))
    if gmag == 0:
        return []
    down = g / gmag
    along = np.flatnonzero(np.abs(down) > 1e-12)
    across = [a for a in range(3) if a != along[0]] if along.size == 1 else []

    def extent(body):  # (lo, hi, depth of the top, depth of the bottom) along gravity
        lo, hi = (np.asarray(v, dtype=np.float64) for v in body.geometry.bounds(dom))
        return (lo, hi, *depth_range(lo, hi, down))

    waters = [extent(b) for b in scene.bodies if b.kind == "water"]
    out = []
    for i, body in enumerate(scene.bodies):
        if body.kind != "sand":
            continue
        lo, hi, _, bottom = extent(body)
        tops = [w_top for w_lo, w_hi, w_top, _ in waters if all(w_hi[a] > lo[a] and w_lo[a] < hi[a] for a in across)]
        if not tops or min(tops) <= bottom:
            continue  # no water under it, or it starts at or in the water
        h = min(tops) - bottom
        out.append((i, h, float(np.linalg.norm(body.velocity)) + math.sqrt(2.0 * gmag * h)))
    return out


def sand_entry_caution(scene: Scene) -> list[str]:
    """A sand body that falls onto the water and meets its surface at a lattice speed U Δt/Δx below
    :data:`SAND_ENTRY_LATTICE_SPEED`: at so small a time step for its Δx the porosity-slip term of Eq. 39 pumps
    water up through sand in the surface's interface and the sand comes back out of the water
    (docs/fluid-stability.md, 'The slip term at a small time step'; not fixed). Measured with the physical
    viscosities kept (session 31; U from :func:`sand_entry_speeds`): Fig. 13's small ball sinks from 0.108 m to
    0.043 m by 0.2 s at its file's Δt (lattice 0.0176), to 0.052 at Δt/2 (0.0088) and rises to 0.110, above the
    surface at 0.08, at Δt/4 (0.0044); Fig. 8's three balls' mean height at 0.8 s is 0.649 m at its Δt (0.0102) and
    0.883, above the surface at 0.80, at Δt/2 (0.0051); the floating ring of Fig. 2 (0.0162 at its Δt) bobs at
    0.0028 and rises out at 0.0014; `tests/coupling/test_surface_pumping.py`'s slab sinks at 0.0115 and rises out
    at 0.0010."""
    units = scene.units()
    slow = [e for e in sand_entry_speeds(scene) if units.to_lattice(e[2], "velocity") < SAND_ENTRY_LATTICE_SPEED]
    if not slow:
        return []
    _, h, speed = min(slow, key=lambda e: e[2])  # the slowest: the time step that lifts it lifts all
    dx = scene.domain.dx
    names = ", ".join(f"bodies[{j}] ({scene.bodies[j].name!r})" for j, _, _ in slow)
    one = len(slow) == 1
    return [
        f"{names} {'falls' if one else 'fall'} onto the water and {'meets' if one else 'meet'} it at "
        f"{'' if one else 'as little as '}{speed:.3g} m/s (a fall of {h:.3g} m, no drag), lattice speed "
        f"{units.to_lattice(speed, 'velocity'):.2g} (U time.dt / dx), "
        f"below the {SAND_ENTRY_LATTICE_SPEED:g} the example scenes were checked at: at so small a time step for this "
        "dx, sand at the water surface is pumped back out of it (Fig. 13's ball ends above the surface at 0.0044, "
        "Fig. 8's balls at 0.0051; docs/fluid-stability.md, 'The slip term at a small time step'); use time.dt >= "
        f"{SAND_ENTRY_LATTICE_SPEED * dx / speed:.3g} s if the other time-step limits allow it, or refine dx and dt "
        "together"
    ]
