"""Render the scene reference (``docs/scene-reference.md``) from the schema, so every key is documented.

``python -m couplekit.scene.reference > docs/scene-reference.md`` regenerates it; a test checks that the file
in the repository matches.
"""

from __future__ import annotations

from .model import LIMITS
from .schema import (
    BODY_KEYS,
    GEOMETRY_COMMON_KEYS,
    GEOMETRY_KEYS,
    GEOMETRY_SUBTRACT,
    GEOMETRY_SUBTRACT_DOC,
    INFLOW_KEYS,
    MAX_DEPTH,
    MAX_MAGNITUDE,
    MIN_MAGNITUDE,
    REQUIRED,
    SAND_WALL_KEYS,
    SECTIONS,
    Key,
)

__all__ = ["render"]

_INTRO = """# Scene reference

A scene is a TOML file in SI units. `couplekit validate SCENE` checks it; `couplekit run SCENE` runs it;
in Python, `couplekit.Scene.load(path)`. A scene is refused before anything is allocated when a key is
unknown, has the wrong type or an out-of-range value, when geometry lies outside the domain, when an inflow
sits on a periodic face, or when the time step breaks the lattice Mach or MPM limits; the message names the
dotted key (e.g. `bodies[0].geometry.radius`) and the fix, and lists every problem at once (the full list:
'What validate and run refuse', at the end).

Conventions: z is up (gravity defaults to (0, 0, -9.81) m/s²); the domain is the box [0, size_x] × [0, size_y]
× [0, size_z]; cell (i, j, k) is centred at ((i + ½) dx, (j + ½) dx, (k + ½) dx); one grid serves the LBM and
the MPM (paper 000 Table 1 lists one resolution). Paper 000's figures have y up: its resolution
`X × Y × Z` is written here as `resolution = [X, Z, Y]`.

What runs: fluid-only scenes (one or two phases, water bodies, obstacles, inflows, outflows), sand-only
scenes (sand bodies, obstacles), and both together, coupled as in the paper's Algorithm 1 (drag, buoyancy,
the phase-field source term, water retention) in lockstep or with the sand at its own rate (`[scheduler]`),
with a density and a `retention` setting per sand body, and water jets carrying sand (MPM particles emitted
at the inflow: `inflows[i].sand_fraction`, `sand_start`, `sand_ramp`). Refused for now by `validate` and `run` alike (exit 3),
naming the key: `effects.drag` or `effects.buoyancy` = false with sand and a fluid.

Example (the demo, `examples/sand_drop_small.toml`):

```toml
[scene]
name = "sand_drop_small"

[domain]
size = [0.2, 0.2, 0.2]
dx = 0.005

[time]
dt = 1e-4
frame_duration = 0.02
frames = 20

[sand]
density = 1500.0

[[bodies]]
kind = "sand"
velocity = [0.0, 0.0, -0.5]
[bodies.geometry]
type = "sphere"
center = [0.1, 0.1, 0.12]
radius = 0.04
```
"""

_CHECKS = f"""## Time-step checks

All run at load time, from the scene alone:

- **Lattice Mach number.** The fastest expected speed U is `time.max_speed` if given, else the largest of
  |v0| + √(2 g h) over water and sand bodies (h: the fall from the body's top to the lowest point of the
  domain along gravity) and |v| + √(2 g H) over inflows (H: the domain's extent along gravity). With a fluid,
  U Δt / (Δx c_s) must not exceed `time.mach_limit` (c_s = 1/√3).
- **Relaxation time.** Each lattice viscosity (given, or ν Δt/Δx² from SI) must lie in
  [{LIMITS["min_lattice_viscosity"]:g}, {LIMITS["max_lattice_viscosity"]:g}], i.e. τ = ν/c_s² + ½ in
  [0.50003, 3.5]; Table 1 of paper 000 uses 1e-4 … 1e-1, and the scheme is untested below a tenth of its
  smallest value. SI water viscosity (1e-6 m²/s) at the paper's Δx/Δt is far below this: give the lattice
  value as the paper does.
- **Weak compressibility.** g Δt²/Δx × (largest cell count) / c_s², the relative hydrostatic density
  variation, must not exceed {LIMITS["max_density_variation"]:g}.
- **Capillary time step** (two phases, σ > 0): σ Δt²/(ρ_h Δx³) ≤ (1 + ρ_l/ρ_h)/(4π) (Brackbill et al. 1992).
- **MPM elastic limit:** Δt_s ≤ C_e Δx / c_p, c_p = √((λ + 2μ)/ϱ) of each sand body (C_e = `sand.elastic_cfl`).
- **MPM particle CFL:** Δt_s ≤ C_v Δx / U (C_v = `sand.cfl`, U as above).

The fluid's checks apply to `time.dt`; the MPM's to the sand's step Δt_s, which the scheduler makes of it:
Δt_s = `time.dt` (lockstep; a violation names `time.dt`), `time.dt` / `substeps` (subcycle; names
`scheduler.substeps` and the smallest k that meets the limits), `time.dt` / `max_substeps` for `substeps =
"auto"` (names `scheduler.max_substeps`: the run would need more substeps than it may take), `sand_every` ×
`time.dt` (multirate; names `scheduler.sand_every` and the largest m that meets them). Only the tightest
limit is reported. During a run, `substeps = "auto"` re-evaluates the particle CFL limit at the particles'
actual speed every step, and a sub-cycled or multi-rate run checks it every 20 sand steps as lockstep does.

## Schedulers

`[time] dt` is the fluid's step, the coupling step; `[scheduler]` decides how the sand keeps pace
(`couplekit.schedulers`; `couplekit run --scheduler SPEC` and `Simulation(..., scheduler=...)` replace the
table):

- `kind = "lockstep"` (default): paper 000's Algorithm 1, one MPM step per LBM step of `dt`.
- `kind = "subcycle"`: `substeps` MPM steps of `dt / substeps` per LBM step (`"auto"`: each step the fewest
  that meet the MPM limits, at most `max_substeps`). The fluid velocity the sand sees is held or linear in
  time (`interpolation`), plus what the fluid gains from the drag already exchanged; the substeps' drag
  impulse is handed to the fluid as one force (fluid + sand momentum conserved to round-off), and the fluid
  sees the substeps' mean sand fraction and velocity, with the source term computed from that fraction
  (volume-conserving). `substeps = 1` is lockstep (to round-off: docs/schedulers.md). A fixed `substeps` above a given
  `max_substeps` is refused (the cap applies to `"auto"`), as is `interpolation = "linear"` in a scene without
  a fluid. During a run, sand that would need more substeps than `max_substeps` (or, in lockstep, a smaller
  step than its particle CFL allows) stops the run before it goes non-finite, keeping the last good state as a
  divergence does.
- `kind = "multirate"`: one MPM step of `sand_every × dt` per `sand_every` LBM steps, its drag handed to the
  fluid as `sand_every` equal forces; for sand that moves slowly.

The keys of one kind are refused with another (`scheduler.substeps` with `kind = "multirate"`, ...), and a
scene without sand takes only `lockstep`.

Geometry: water and sand bodies must lie inside the domain, sand at least `sand.wall_layers` cells (default
{LIMITS["sand_wall_cells"]}) from every face (the MPM walls take that many node layers); an obstacle must meet
the domain.

## What validate and run refuse

`couplekit validate` and `couplekit run` read a scene through the same checks, before anything is allocated;
no input, however broken, gives a traceback. Every problem names the dotted key and the fix, and all of them
are listed at once (exit 2):

- **The file:** not readable, not UTF-8 text (a binary file: key `(file)`), not TOML, or nested too deeply to
  read (`(syntax)`); any table or array nested more than {MAX_DEPTH} deep (the key where it happens).
- **Types:** a table given as a value (`fluid = 3`), a value of the wrong type, an unknown key or table (with
  the closest name), a missing required key.
- **Numbers:** every number, also each component of a vector, each height of a height grid and each height
  read from a height file, must be finite (no `nan`, `inf`) and 0 or between {MIN_MAGNITUDE:g} and
  {MAX_MAGNITUDE:g} in magnitude (so no product or quotient the checks and solvers form overflows or divides by
  zero), integers at most 2⁶³ − 1, and each within its key's range. A value that fails is not used by any later
  check (`dx = 0` is reported, never divided by).
- **The grid:** `dx` or `resolution`, a whole number of cubic cells, at least 5 and at most
  {LIMITS["max_cells_per_axis"]} cells per axis (the kernels index an axis with 32-bit integers).
- **Geometry:** every body's shape is built as the solvers build it; any error of a mesh or height-file
  reader (a file that is not a mesh, a mesh meshio cannot read, non-finite vertices, an open, non-watertight
  mesh, whose inside is undefined; a surface that would need more than 2³¹ samples) is a problem of
  `bodies[i].geometry` (or of its `file`).
- **Seeding:** every sand body gets particles: no particle is seeded inside an obstacle, and a body thinner
  than the particle spacing dx / k (k³ = `sand.particles_per_cell`) or wholly inside obstacles is refused
  naming `bodies[i].geometry` (its seeding lattice is searched block by block, so this is cheap).
- **Speeds:** `time.max_speed`, which the time-step checks trust when given, must be at least every speed the
  scene gives itself: each body's and each inflow's velocity.
- **Time step, boundaries, inflows, outlets, stirring, scheduler:** the checks above ('Time-step checks',
  'Schedulers', the tables' notes).

What `run` refuses for a reason outside the file is refused after validation, with exit 3 and the message
`refused: ...`: a scene whose memory estimate (`couplekit.assembly.memory_estimate`) exceeds 90 % of the
available memory (on the cpu and numpy backends the host's MemAvailable, on cuda the free GPU memory), and an
effect the coupling cannot switch off yet (`effects.drag` or `effects.buoyancy` = false with sand and a
fluid). `validate` runs the same check (`couplekit.assembly.check_run`, against the host's available memory)
and refuses, with `run`'s message and exit 3, the coupling switch and a scene no machine holds (an estimate
beyond 16 TiB, e.g. a 10¹⁵-cell grid); what `run` refuses on this machine only, for its memory, it notes with
`run`'s message and exit 0, so that a file validates alike on every host (a paper-scale scene validates on a
laptop before it runs on a GPU). What was measured to diverge but is admitted, because the paper asks for
it, both print as a `caution:` line (exit 0; `couplekit.cautions.stability_cautions`): the paper's collision
(`fluid.odd_lambda = 0`, or a Λ too small to act) below lattice viscosity 5e-4 where no-slip walls meet at
edges (docs/fluid-stability.md); so is what was measured to come out wrong: sand that falls onto the water and
meets it at a lattice speed U Δt/Δx below 0.01, the slowest the examples were checked at (at a smaller time step
for its Δx sand at the water surface is pumped back out of it: `couplekit.cautions.sand_entry_caution`), and the
other cautions `stability_cautions` lists. `run --frames` and `--threads` must be 1 or more (exit 2). A closed standard output
(`couplekit validate scene.toml | head -1`) ends either command quietly, exit 141.
"""


_SAND_WALLS = """## [sand.walls]

Optional: the sand's domain wall per face, one entry per face named as in `[domain.boundary]` (`x_min`, `x_max`,
`y_min`, `y_max`, `z_min`, `z_max`). A face not named is `kind = "separate"` with `sand.wall_friction` (so a
scene without the table is unchanged). These walls act on the sand only; the fluid's boundary is
`[domain.boundary]`. Example: a floor of friction 0.3 and two frictionless symmetry planes:

```toml
[sand.walls]
z_min = { friction = 0.3 }
x_min = { kind = "slip" }
y_min = { kind = "slip" }
```

Keys of one face:

"""


def _default(key: Key) -> str:
    if key.default is REQUIRED:
        return "**required**"
    if key.default is None:
        return "—"
    if isinstance(key.default, bool):
        return "true" if key.default else "false"
    if isinstance(key.default, str):
        return f'"{key.default}"'
    if isinstance(key.default, float):
        return f"{key.default:.6g}"
    if isinstance(key.default, list):
        return "[" + ", ".join(f'"{v}"' if isinstance(v, str) else f"{v:g}" for v in key.default) + "]"
    return str(key.default)


def _type(key: Key) -> str:
    return {
        "float": "number",
        "int": "integer",
        "int_or_auto": 'integer or "auto"',
        "bool": "boolean",
        "str": "string",
        "choice": "string",
        "vec3": "3 numbers",
        "ivec3": "3 integers",
        "floats": f"{key.length} numbers" if key.length else "numbers",
        "strs": "list of strings",
        "grid": "2-D list of numbers",
    }[key.kind]


def _table(keys: list[Key]) -> str:
    rows = ["| key | type | default | unit | allowed | meaning |", "| --- | --- | --- | --- | --- | --- |"]
    for k in keys:
        rows.append(f"| `{k.name}` | {_type(k)} | {_default(k)} | {k.unit or ''} | {k.range_text()} | {k.doc} |")
    return "\n".join(rows)


def render() -> str:
    """The whole reference as Markdown."""
    parts = [_INTRO]
    notes = {
        "scene": "Optional.",
        "domain": "Required. Give `dx` or `resolution`.",
        "domain.boundary": "Optional; every face defaults to a wall.",
        "time": "Required.",
        "scheduler": "Optional: how the fluid and the sand are stepped (below, 'Schedulers'). Default: lockstep.",
        "fluid": "Present ⇒ the scene has a fluid. Viscosities: give the SI or the lattice form per phase, not both.",
        "sand": 'Material of the sand bodies (used only when a body has `kind = "sand"`).',
        "outputs": "Optional. Files go to `directory`, frame by frame.",
        "effects": "Optional switches for ablations: an effect the scene does not need is off anyway (DESIGN 'Effects').",
        "stirring": "Optional: a swirling body force on the water (paper Fig. 11), added to the drag in coupled scenes. "
        "Its cylinder must hold at least one cell centre (a radius of one cell always does).",
    }
    for name, keys in SECTIONS.items():
        parts.append(f"## [{name}]\n\n{notes.get(name, '')}\n\n{_table(keys)}\n")
        if name == "sand":
            parts.append(_SAND_WALLS + _table(SAND_WALL_KEYS) + "\n")
    parts.append(
        "## [[bodies]]\n\nAny number of bodies; each has a `kind` and a `[bodies.geometry]` table (below).\n"
        "Water bodies set the initial liquid (φ = 1 inside, a tanh profile of width ξ across the surface; water\n"
        "filling a shape up to a wall has no interface along the wall, and water that reaches one end of a\n"
        "periodic axis but not the other meets the air through the wrap with the same profile); sand\n"
        "bodies are seeded with particles; obstacles are fixed solids for the fluid (bounce-back) and colliders\n"
        f"for the sand.\n\n{_table(BODY_KEYS)}\n"
    )
    parts.append(
        "## [bodies.geometry]\n\nKeys every shape takes (transforms apply in the order scale, rotate, translate,\n"
        "which keep distances exact):\n\n" + _table(GEOMETRY_COMMON_KEYS) + "\n"
        f"`{GEOMETRY_SUBTRACT}` (a list of geometry tables, optional): {GEOMETRY_SUBTRACT_DOC}. Example, a\n"
        "sand ring wall (a cylinder less a narrower one) and a plate with a hole:\n\n"
        '```toml\n[bodies.geometry]\ntype = "cylinder"\ncenter = [0.5, 0.5, 0.1]\nradius = 0.3\nheight = 0.2\n'
        'subtract = [{ type = "cylinder", center = [0.5, 0.5, 0.1], radius = 0.2, height = 0.3 }]\n\n'
        '[bodies.geometry]\ntype = "box"\nmin = [0.0, 0.0, 0.3]\nmax = [1.0, 1.0, 0.32]\n'
        'subtract = [{ type = "cylinder", center = [0.5, 0.5, 0.31], radius = 0.05, height = 0.1 }]\n```\n'
    )
    descriptions = {
        "box": "Axis-aligned box (rotate it for any orientation).",
        "sphere": "Ball.",
        "cylinder": "Capped cylinder.",
        "heightfield": "The solid under a surface z = h(x, y), down to `base`; rows of the grid run along y, "
        "columns along x. The default `base`, one cell below the domain, suits obstacles and water (the water "
        "fills the domain's cells under the surface); a sand height field needs `base` at least "
        "`sand.wall_layers` cells above the floor.",
        "mesh": "A closed triangle mesh (an open one, with edges of one triangle only, is refused: its inside is "
        "undefined). Inside: parity of +x ray crossings (orientation-independent); "
        "distance: exact point–triangle distance to candidate triangles found through dense surface samples. "
        "Several closed parts in one file must not overlap: by parity a point inside two of them counts as "
        "outside (their overlap is a hole); join them into one surface in the modeller, or give each its own "
        "body.",
    }
    for gtype, keys in GEOMETRY_KEYS.items():
        parts.append(f'### type = "{gtype}"\n\n{descriptions[gtype]}\n\n{_table(keys)}\n')
    parts.append(
        '## [[inflows]]\n\nA velocity inlet over a whole face whose `domain.boundary` is `inflow` (`shape = "face"`), or\n'
        'an outlet in a wall or outflow face (`shape = "rect"` or `"disc"`: a jet; the rest of the face keeps its\n'
        "boundary). A water inflow carries water (φ = 1), wind carries air (φ = 0). An inflow on a periodic face\n"
        "is refused. Outflows need no entry: set the face's boundary to `outflow`. With the volume controller on,\n"
        "its target follows the water let in and out through these faces.\n\n" + _table(INFLOW_KEYS) + "\n"
    )
    parts.append(_CHECKS)
    return "\n".join(parts)


if __name__ == "__main__":
    print(render(), end="")
