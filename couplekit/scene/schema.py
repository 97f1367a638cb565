"""The scene file schema: every key, its type, default, unit, admissible range and documentation.

The schema is data (:data:`SECTIONS`, :data:`BODY_KEYS`, :data:`GEOMETRY_KEYS`, :data:`INFLOW_KEYS`), read by
three consumers: :func:`read_table`, which checks one TOML table against a key list (unknown key, wrong type,
out-of-range value, missing required key) and collects :class:`Problem` records naming the dotted key and the
fix; :mod:`couplekit.scene.reference`, which renders ``docs/scene-reference.md`` from the same data, so
the documentation cannot drift from what is validated; and :mod:`couplekit.scene.jsonschema`, which renders
it as JSON Schema for editors (``couplekit schema``, ``docs/scene.schema.json``).

Conventions: SI units; z is up (gravity defaults to (0, 0, -9.81)); the domain is the box
[0, size_x] × [0, size_y] × [0, size_z]; cell (i, j, k) has its centre at ((i + ½) dx, (j + ½) dx, (k + ½) dx).
"""

from __future__ import annotations

import difflib
import math
import reprlib
from dataclasses import dataclass
from typing import Any

from ..faces import SCENE_FACES

__all__ = [
    "REQUIRED",
    "Key",
    "Problem",
    "ProblemError",
    "SceneError",
    "parse_toml",
    "read_toml",
    "SECTIONS",
    "BODY_KEYS",
    "GEOMETRY_KEYS",
    "GEOMETRY_COMMON_KEYS",
    "GEOMETRY_SUBTRACT",
    "GEOMETRY_SUBTRACT_DOC",
    "INFLOW_KEYS",
    "OUTLET_KEYS",
    "SAND_WALL_KEYS",
    "SAND_WALL_KINDS",
    "FACES",
    "BOUNDARY_KINDS",
    "FIELD_NAMES",
    "read_table",
    "show",
    "too_deep",
    "MAX_MAGNITUDE",
    "MIN_MAGNITUDE",
    "MAX_INT",
    "MAX_DEPTH",
]


class _Required:
    def __repr__(self) -> str:
        return "required"


REQUIRED: Any = _Required()
"""Marker default of a key that must be given."""

FACES = SCENE_FACES
BOUNDARY_KINDS = ("wall", "periodic", "inflow", "outflow")
FIELD_NAMES = ("phi", "velocity", "pressure", "density", "solid", "sand_fraction", "sand_velocity")
"""Grid fields an output can ask for (a field that the scene's physics does not produce is skipped)."""


@dataclass(frozen=True)
class Key:
    """One scene key.

    kind: ``float``, ``int``, ``int_or_auto`` (an integer or the string "auto"), ``bool``, ``str``, ``choice`` (one
    of ``choices``), ``vec3`` (3 floats),
    ``ivec3`` (3 ints), ``floats`` (a list of ``length`` floats, any length when 0), ``strs`` (list of
    strings from ``choices``), ``grid`` (a 2-D list of floats). ``lo``/``hi`` bound numbers (and every
    component of vectors); ``lo_open``/``hi_open`` make the bound strict.
    """

    name: str
    kind: str
    default: Any = REQUIRED
    doc: str = ""
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple = ()
    length: int = 0

    def range_text(self) -> str:
        """The admissible range in words (for messages and the reference)."""
        if self.choices:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        parts = []
        if self.lo is not None:
            parts.append(f"{'>' if self.lo_open else '>='} {self.lo:g}")
        if self.hi is not None:
            parts.append(f"{'<' if self.hi_open else '<='} {self.hi:g}")
        return " and ".join(parts)


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a scene: the dotted key, what is wrong, and how to fix it."""

    key: str
    message: str
    fix: str

    def __str__(self) -> str:
        return f"{_clip(self.key)}: {_clip(self.message)}. Fix: {_clip(self.fix)}"


MESSAGE_CLIP = 400
"""Longest key, message or fix a problem line shows (a 200 kB key name in a hostile file is cut, not echoed)."""
MESSAGE_PROBLEMS = 50
"""Most problems a refusal lists; the rest are counted (``ProblemError.problems`` keeps them all)."""


def _clip(text: str) -> str:
    text = str(text)
    if len(text) <= MESSAGE_CLIP:
        return text
    return f"{text[: MESSAGE_CLIP - 40]}... ({len(text) - MESSAGE_CLIP + 40:,} characters more)"


class ProblemError(ValueError):
    """An input file was refused; ``problems`` lists every :class:`Problem` found (the message shows them all)."""

    def __init__(self, problems: list[Problem], source: str = "input"):
        self.problems = list(problems)
        self.source = source
        lines = [f"{_clip(source)} is invalid ({len(problems)} problem{'s' if len(problems) != 1 else ''}):"]
        lines += [f"  - {p}" for p in problems[:MESSAGE_PROBLEMS]]
        if len(problems) > MESSAGE_PROBLEMS:
            lines.append(f"  ... and {len(problems) - MESSAGE_PROBLEMS:,} more problems (fix these first)")
        super().__init__("\n".join(lines))

    @property
    def keys(self) -> list[str]:
        """The dotted keys of the problems."""
        return [p.key for p in self.problems]


class SceneError(ProblemError):
    """A scene was refused; ``problems`` lists every :class:`Problem` found (the message shows them all)."""

    def __init__(self, problems: list[Problem], source: str = "scene"):
        super().__init__(problems, source)


MAX_FILE_BYTES = 16 << 20
"""Largest scene (or sweep) file read: far beyond any hand-written TOML, small enough to read at once."""


def read_toml(path, error: type[ProblemError] = SceneError) -> dict:
    """The TOML file at ``path`` as a dict; a file that cannot be read or is not TOML raises ``error`` with one
    :class:`Problem` (key ``(file)`` or ``(syntax)``) naming the file and the fix."""
    from pathlib import Path

    path = Path(path)
    try:
        if path.exists() and not path.is_file():  # a folder, a device (/dev/zero), a pipe: refused before reading
            kind = "a folder" if path.is_dir() else "not a regular file"
            raise error([Problem("(file)", f"{path} is {kind}", "give the path of a TOML scene file")], str(path))
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise error(
                [
                    Problem(
                        "(file)",
                        f"{path} holds {size:,} bytes; a scene file holds at most {MAX_FILE_BYTES:,} "
                        "(geometry goes in mesh or height files)",
                        "give the scene's TOML file; put large data in mesh / height files it names",
                    )
                ],
                str(path),
            )
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise error([Problem("(file)", f"cannot read {path}: {exc.strerror}", "check the path")], str(path)) from None
    except UnicodeDecodeError as exc:  # a binary file (TOML is UTF-8 text)
        raise error(
            [Problem("(file)", f"{path} is not a text file (byte {exc.start} is not UTF-8)", "give a TOML text file")],
            str(path),
        ) from None
    return parse_toml(text, str(path), error)


def parse_toml(text: str, source: str = "<string>", error: type[ProblemError] = SceneError) -> dict:
    """TOML ``text`` as a dict; text that is not TOML raises ``error`` with one :class:`Problem` (key
    ``(syntax)``) naming ``source`` (a path, or ``"<string>"``) and the fix: :func:`read_toml`'s messages."""
    import tomllib

    if not isinstance(text, str):
        raise error(
            [Problem("(file)", f"TOML text must be a str, got {type(text).__name__}", "decode bytes as UTF-8 first")],
            source,
        )
    if text.startswith("\ufeff"):  # a UTF-8 byte-order mark, as some Windows editors save: not part of the TOML
        text = text[1:]
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(
            [Problem("(syntax)", f"not valid TOML: {exc}", "fix the TOML syntax at that line")], source
        ) from None
    except RecursionError:  # arrays or inline tables nested thousands deep
        raise error(
            [Problem("(syntax)", "arrays or tables are nested too deeply to read", "flatten the nesting")], source
        ) from None
    except (ValueError, OverflowError) as exc:  # e.g. an integer literal of more digits than Python converts
        raise error([Problem("(syntax)", f"not valid TOML: {exc}", "fix the value")], source) from None


# ------------------------------------------------------------------------------------------------ the schema
_FACE_DOC = "boundary of the {face} face: 'wall' (no-slip, sand slides with wall friction), 'periodic' (both faces of the axis), 'inflow' (needs an [[inflows]] entry on this face), 'outflow' (zero-gradient, fluid leaves; where fluid comes back in, the face takes its inward velocity out)"

SECTIONS: dict[str, list[Key]] = {
    "scene": [
        Key(
            "name",
            "str",
            "scene",
            "a short name, a plain folder name (no '/', '\\' or '..'); the default output folder is runs/<name>",
        ),
        Key("description", "str", "", "free text, e.g. which figure of which paper the scene reproduces"),
    ],
    "domain": [
        Key("size", "vec3", REQUIRED, "extent of the box (x, y, z); z is up", "m", lo=0.0, lo_open=True),
        Key(
            "dx",
            "float",
            None,
            "grid spacing (one LBM node = one MPM node = one cell); give dx or resolution",
            "m",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "resolution",
            "ivec3",
            None,
            "cells along (x, y, z); give dx or resolution (size / resolution must be the same on every axis)",
            "",
            lo=5,
        ),
        Key("gravity", "vec3", [0.0, 0.0, -9.81], "gravitational acceleration", "m/s²"),
    ],
    "domain.boundary": [Key(f, "choice", "wall", _FACE_DOC.format(face=f), choices=BOUNDARY_KINDS) for f in FACES],
    "time": [
        Key(
            "dt",
            "float",
            REQUIRED,
            "time step of the fluid, the coupling step (Table 1 'Time Step'); the sand steps dt too with the default "
            "[scheduler] (lockstep), dt / substeps when sub-cycled, sand_every × dt when multi-rate",
            "s",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "frame_duration",
            "float",
            1.0 / 30.0,
            "simulated time between two output frames (rounded to whole steps)",
            "s",
            lo=0.0,
            lo_open=True,
        ),
        Key("frames", "int", 10, "number of frames `couplekit run` simulates (overridden by --frames)", "", lo=1),
        Key(
            "max_speed",
            "float",
            None,
            "fastest flow speed you expect; default: estimated from gravity, body velocities and inflows "
            "(see 'Time-step checks')",
            "m/s",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "mach_limit",
            "float",
            0.3,
            "largest admissible lattice Mach number u Δt/(Δx c_s) of max_speed",
            "",
            lo=0.0,
            lo_open=True,
            hi=1.0,
        ),
    ],
    "fluid": [
        Key(
            "phases", "int", 2, "2: water and air with the phase field; 1: the domain is full of water", "", lo=1, hi=2
        ),
        Key(
            "water_density",
            "float",
            1000.0,
            "density ρ_h of the heavy phase (paper: 1000)",
            "kg/m³",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "air_density", "float", 1.25, "density ρ_l of the light phase (paper: 1.25)", "kg/m³", lo=0.0, lo_open=True
        ),
        Key(
            "water_viscosity",
            "float",
            None,
            "kinematic viscosity ν_h in SI units; give this or water_lattice_viscosity",
            "m²/s",
            lo=0.0,
            lo_open=True,
        ),
        Key("air_viscosity", "float", None, "kinematic viscosity ν_l in SI units", "m²/s", lo=0.0, lo_open=True),
        Key(
            "water_lattice_viscosity",
            "float",
            None,
            "ν_h in lattice units, as Table 1 gives it (default 1e-4 when neither form is given)",
            "lattice",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "air_lattice_viscosity",
            "float",
            None,
            "ν_l in lattice units (Table 1; default 1e-2 when neither form is given)",
            "lattice",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "surface_tension",
            "float",
            0.0728,
            "surface tension σ (water-air at 20 °C: 0.0728); 0 switches it off",
            "N/m",
            lo=0.0,
        ),
        Key("interface_width", "float", 4.0, "phase-field interface width ξ", "cells", lo=2.0, hi=10.0),
        Key(
            "mobility",
            "float",
            0.02,
            "phase-field mobility M; below 0.02 (the examples') a flow expected faster than a measured u/M "
            "is cautioned: a moving interface at 800:1 tears (couplekit.cautions.mobility_caution)",
            "lattice",
            lo=0.0,
            lo_open=True,
            hi=1.0,
        ),
        Key(
            "controller_eta",
            "float",
            2.0,
            "volume-controller bound η of Eq. 52 (Table 1: 1 or 2); 0 = off. It scales the source term S_φ, so it "
            "acts in scenes with sand; without sand the phase field conserves the water by itself",
            "",
            lo=0.0,
            hi=10.0,
        ),
        Key(
            "odd_lambda",
            "float",
            0.015,
            "floor Λ of the odd-moment relaxation (keeps no-slip wall edges stable at ν_h < 5e-4, "
            "docs/fluid-stability.md); 0 = the paper's rate 1",
            "",
            lo=0.0,
            hi=0.1,
        ),
        Key(
            "odd_ramp",
            "float",
            0.0,
            "the odd_lambda floor near the walls only: ramped to the paper's rate 1 over this many cells from "
            "every wall, solid cell and open face (3 measured; lets a light 1.7-cell sand ball float at interface "
            "width 4, docs/examples.md Fig. 8); needs every gap between them >= 8 cells; 0 = the floor everywhere",
            "cells",
            lo=0.0,
            hi=16.0,
        ),
        Key(
            "gravity",
            "vec3",
            None,
            "acceleration the fluid feels; default domain.gravity. A periodic column whose floor carries a "
            "suspension's weight replaces it by the mean pressure gradient (couplekit.coupling.scenes."
            "uniform_suspension); the sand always feels domain.gravity",
            "m/s²",
        ),
        Key(
            "initial_pressure",
            "choice",
            "resting",
            "the pressure the fluid starts from: 'resting', hydrostatic for the water resting on the floor (water "
            "hanging in the air, e.g. a poured block, adds nothing, so the air beside it stays at rest); 'column', "
            "every column integrated straight through (a water layer spanning the domain over trapped air, e.g. a "
            "dry sand bed in a closed tank); 'zero', p = 0 (the water then falls by g dt in the first step and "
            "rings)",
            choices=("resting", "column", "zero"),
        ),
        Key(
            "smagorinsky",
            "float",
            0.1,
            "Smagorinsky constant C of a subgrid viscosity (keeps violent flows at ν_h = 1e-4 finite, "
            "docs/fluid-stability.md); 0 = off, the paper's collision",
            "",
            lo=0.0,
            hi=0.5,
        ),
        Key(
            "storage",
            "choice",
            "fp32",
            "storage precision of the populations f and h: 'fp32', or 'fp16' (IEEE half, scaled; float32 "
            "arithmetic), which halves their memory at a cost in accuracy measured in docs/precision.md "
            "('fp16 storage')",
            choices=("fp32", "fp16"),
        ),
    ],
    "sand": [
        Key(
            "density",
            "float",
            1500.0,
            "density ϱ of the sand material (Table 1 'Sand Density'); a body may override it",
            "kg/m³",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "youngs_modulus",
            "float",
            3.537e5,
            "Young's modulus E (Hencky elasticity; not reported by the paper)",
            "Pa",
            lo=0.0,
            lo_open=True,
        ),
        Key("poisson_ratio", "float", 0.3, "Poisson ratio", "", lo=-1.0, lo_open=True, hi=0.5, hi_open=True),
        Key(
            "hardening",
            "floats",
            [35.0, 9.0, 0.2, 10.0],
            "Klár hardening (h0 °, h1 °, h2, h3 °); paper: 35, 9, 0.2, 10",
            "",
            length=4,
        ),
        Key(
            "cohesion",
            "float",
            1000.0,
            "largest cohesion c_C of the saturation-dependent Drucker–Prager cone (Eq. 28); 0 = cohesionless",
            "Pa",
            lo=0.0,
        ),
        Key(
            "cohesion_saturation",
            "floats",
            [0.05, 0.18, 0.36],
            "breakpoints S1 ≤ S2 < S3 of the trapezoid c_C(S): rises to `cohesion` at S1, falls to 0 at S3",
            "",
            length=3,
            lo=0.0,
            hi=1.0,
        ),
        Key("particles_per_cell", "int", 8, "particles seeded per cell: a cube k³ (1, 8, 27, 64)", "", lo=1, hi=512),
        Key(
            "packing_fraction",
            "float",
            0.6,
            "sand volume fraction ε0 of a seeded body: a particle's volume is ε0 dx³ / particles_per_cell and its mass `density` × that volume, so `density` is the grain density of Eq. 31's balance (sand lighter than water floats); at most ε_max = 0.64 (Eq. 25)",
            "",
            lo=0.0,
            lo_open=True,
            hi=0.64,
        ),
        Key(
            "jitter", "float", 0.5, "random displacement of seeded particles, in sub-cell spacings", "", lo=0.0, hi=1.0
        ),
        Key("seed", "int", 0, "random seed of the jitter", "", lo=0),
        Key(
            "wall_friction",
            "float",
            0.5,
            "Coulomb friction of sand on domain walls and obstacles; a face of [sand.walls] may override it",
            "",
            lo=0.0,
        ),
        Key(
            "wall_layers",
            "int",
            2,
            "node layers the MPM domain walls take at every face; sand bodies and sand-carrying outlets must keep "
            "this many cells from each face (1 lets a bed reach the first cell, so that water cannot bypass it "
            "along the walls; with a fluid it draws a caution: a bed's fringe there grows a current at floor-wall "
            "edges after ~3000 steps)",
            "",
            lo=1,
            hi=4,
        ),
        Key(
            "periodic_walls",
            "bool",
            False,
            "allow periodic domain faces in a scene with sand: the fluid wraps around, the sand meets a wall there "
            "(the MPM grid has no periodic wrap; keep the sand wall_layers cells away). false refuses periodic "
            "faces with sand",
        ),
        Key("cfl", "float", 0.5, "particle CFL number C_v: Δt ≤ C_v Δx / max speed", "", lo=0.0, lo_open=True, hi=1.0),
        Key(
            "elastic_cfl",
            "float",
            0.5,
            "elastic CFL number C_e: Δt ≤ C_e Δx / c_p (P-wave speed)",
            "",
            lo=0.0,
            lo_open=True,
            hi=1.0,
        ),
        Key("retention", "bool", False, "water retention (Sec. 4.5, Figs. 4, 10, 17, 18); a body may override it", ""),
        Key(
            "absorption_rate",
            "float",
            0.003,
            "absorption coefficient R_a of Eq. 55 (Table 1, lattice units): the share of the free water a particle's "
            "pores can still take that it absorbs per lattice step; above 0.03 a caution (a dry bed under water "
            "diverged at 0.05)",
            "lattice",
            lo=0.0,
            hi=1.0,
        ),
        Key(
            "absorption_time",
            "float",
            None,
            "R_a in seconds instead (give this or absorption_rate): the time in which sand under water would take up "
            "its whole capacity at Eq. 55's rate, R_a = time.dt / absorption_time per lattice step, so the bound "
            "water's history in seconds is the same at any time.dt (a per-step R_a binds twice as fast per second "
            "at half the dt). Table 1's R_a at its dt: absorption_time = dt / R_a (Fig. 17: 1.2e-4 s / 0.001 = "
            "0.12 s). At least time.dt",
            "s",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "max_moisture",
            "float",
            0.28,
            "retention capacity r_max: the bound water a node's sand holds per sand volume is at most r_max (Eqs. "
            "55-56; not in the paper: at 0.28 sand packed at ε_max holds (1 − ε_max)/2 of its volume as bound "
            "water, the paper's wet threshold). A particle's own moisture ratio, gathered from the nodes around it "
            "(Eq. 58), can exceed it (measured up to +14 % at the default absorption rate, +29 % at 0.1)",
            "",
            lo=0.0,
            hi=0.56,
        ),
        Key(
            "grain_diameter",
            "float",
            None,
            "drag option of the coupling (CouplingParams.grain_diameter): none (default) takes paper 000 §4.3's "
            "drag area, one ball holding all of a node's sand (a node settles like a sphere of diameter "
            "(6 ε dx³/π)^(1/3), so the settling speed grows like √dx); a grain diameter d takes the total "
            "cross-section of the node's grains, A = 1.5 ε dx³ / d (a node settles like one grain of diameter d, at "
            "any dx). At most domain.dx (a cell must hold many grains); scenes with a fluid only",
            "m",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "viscosity",
            "float",
            0.0,
            "viscoplastic overstress η of the Drucker–Prager flow (SandParams.viscosity, Duvaut–Lions): 0 (default) "
            "is the paper's rate-independent return, whose granular-collapse runout grows with resolution; 1.5 Pa s "
            "makes the Lube-calibrated collapse converge (docs/sand-validation.md)",
            "Pa s",
            lo=0.0,
        ),
    ],
    "outputs": [
        Key("directory", "str", None, "output folder (default runs/<scene.name>; `couplekit run --out` overrides it)"),
        Key("fields", "strs", list(FIELD_NAMES), "grid fields written to the .vti files", choices=FIELD_NAMES),
        Key(
            "vtk",
            "bool",
            True,
            "ParaView series: fields_NNNN.vti (image data), particles_NNNN.vtp (poly data), .pvd indexes",
        ),
        Key("ply", "bool", True, "particle PLY sequence particles_NNNN.ply (Blender)"),
        Key(
            "surface",
            "bool",
            True,
            "water surface (φ = ½) of every frame as a closed triangle mesh with outward normals (docs/outputs.md): "
            "surface_NNNN.ply / .obj (per surface_format) beside the particles, and with vtk surface_NNNN.vtp indexed by "
            "surface.pvd; two-phase fluids only (skipped without a phase field)",
        ),
        Key(
            "surface_format",
            "strs",
            ["ply"],
            "renderer formats of the surface meshes: 'ply' (binary, vertex normals) and/or 'obj' (text, vn normals); "
            "[] writes only the ParaView .vtp",
            choices=("ply", "obj"),
        ),
        Key("preview", "bool", True, "PNG preview of every preview_every-th frame, rendered off-screen"),
        Key("preview_every", "int", 1, "frames between previews", "", lo=1),
        Key(
            "preview_colour",
            "choice",
            "auto",
            "what colours the sand in the previews: 'wetness' (as paper 000 §5.1 renders: with retention the "
            "retained water r_p from dry to wet colour, 0 to r_max; without it two colours, wet where S_r,p > "
            "(1 - eps_max)/2), 'speed' (sand speed on the run's fixed scale) or 'auto' (wetness where sand meets "
            "water, else speed)",
            choices=("auto", "wetness", "speed"),
        ),
        Key(
            "checkpoint_every",
            "int",
            10,
            "frames between HDF5 checkpoints (the last frame is always written); 0 = only at the end",
            "",
            lo=0,
        ),
        Key("diagnostics", "bool", True, "per-frame diagnostics log diagnostics.jsonl (one JSON object per line)"),
    ],
    "effects": [
        Key("surface_tension", "bool", True, "false switches the surface-tension force off (ablation)"),
        Key("volume_controller", "bool", True, "false switches the Eq. 52 volume controller off (Fig. 14 b)"),
        Key("source_term", "bool", True, "false drops the phase-field source term S_φ (Fig. 14 a; coupled scenes)"),
        Key("drag", "bool", True, "false switches fluid-sand drag off (coupled scenes)"),
        Key("buoyancy", "bool", True, "false switches buoyancy off (coupled scenes)"),
        Key("cohesion", "bool", True, "false makes the sand cohesionless"),
        Key("hardening", "bool", True, "false keeps the friction angle at h0"),
    ],
    "scheduler": [
        Key(
            "kind",
            "choice",
            "lockstep",
            "how the fluid and the sand are stepped (couplekit.schedulers): 'lockstep', paper 000's Algorithm 1, one "
            "MPM step per LBM step of time.dt; 'subcycle', `substeps` MPM steps of time.dt / substeps inside each LBM "
            "step (the fluid may then take a step the sand alone could not); 'multirate', one MPM step of "
            "sand_every × time.dt per sand_every LBM steps (sand that moves slowly, e.g. a settled bed under "
            "flowing water). Needs sand (a fluid-only scene has one rate)",
            choices=("lockstep", "subcycle", "multirate"),
        ),
        Key(
            "substeps",
            "int_or_auto",
            "auto",
            "kind = 'subcycle': MPM substeps per LBM step, an integer k >= 1 (the sand steps time.dt / k; k = 1 is "
            "lockstep to round-off) or 'auto': each step the smallest k whose substep meets the MPM elastic and "
            "particle CFL limits at the particles' current speed",
            lo=1,
            hi=4096,
        ),
        Key(
            "max_substeps",
            "int",
            64,
            "kind = 'subcycle' with substeps = 'auto': the most substeps one LBM step may take; a run whose sand "
            "needs more stops with an error naming this key, and validation refuses a time.dt that needs more for "
            "the expected speed (ignored with a fixed substeps)",
            lo=1,
            hi=4096,
        ),
        Key(
            "interpolation",
            "choice",
            "hold",
            "kind = 'subcycle': the fluid velocity the sand exchanges momentum with across the substeps: 'hold' (the "
            "LBM step's start, as the Granule-In-Cell paper holds its fluid) or 'linear' (linear in time through the "
            "last two LBM steps, extrapolated to each substep's start); either way plus the velocity the fluid gains "
            "from the drag the earlier substeps exchanged",
            choices=("hold", "linear"),
        ),
        Key(
            "sand_every",
            "int",
            None,
            "kind = 'multirate' (required there): LBM steps per MPM step m; the sand steps m × time.dt and "
            "exchanges drag over that step, handed to the fluid as m equal forces",
            lo=1,
            hi=100000,
        ),
    ],
    "stirring": [
        Key(
            "center",
            "vec3",
            REQUIRED,
            "a point on the stirring axis, the middle of the stirred cylinder (paper 000 Fig. 11: a tangential "
            "force on the water starts the swirl)",
            "m",
        ),
        Key(
            "axis",
            "vec3",
            [0.0, 0.0, 1.0],
            "direction of the axis (any length); a positive acceleration turns the water counter-clockwise "
            "seen from the axis tip (right-hand rule)",
        ),
        Key("radius", "float", REQUIRED, "radius of the stirred cylinder", "m", lo=0.0, lo_open=True),
        Key(
            "length",
            "float",
            None,
            "extent of the cylinder along the axis, centred on center; default: unbounded (through the domain)",
            "m",
            lo=0.0,
            lo_open=True,
        ),
        Key(
            "acceleration",
            "float",
            REQUIRED,
            "tangential acceleration of the water at r = radius; inside the cylinder a = acceleration × r / "
            "radius (a solid-body spin-up, nothing on the axis), 0 outside; it acts on the water only: force "
            "density ρ_water φ ε a, added to the drag in coupled scenes",
            "m/s²",
        ),
        Key("start", "float", 0.0, "time the forcing starts", "s", lo=0.0),
        Key(
            "duration",
            "float",
            None,
            "how long it lasts (steps starting in [start, start + duration)); default: to the end of the run",
            "s",
            lo=0.0,
            lo_open=True,
        ),
    ],
}
"""The single tables of a scene, by dotted name."""

BODY_KEYS: list[Key] = [
    Key(
        "kind",
        "choice",
        REQUIRED,
        "'water' (initial liquid), 'sand' (seeded particles) or 'obstacle' (rigid, fixed)",
        choices=("water", "sand", "obstacle"),
    ),
    Key("name", "str", "", "a label used in messages and outputs"),
    Key("velocity", "vec3", [0.0, 0.0, 0.0], "initial velocity of the water or sand of this body", "m/s"),
    Key("density", "float", None, "sand bodies: overrides sand.density", "kg/m³", lo=0.0, lo_open=True),
    Key("retention", "bool", None, "sand bodies: overrides sand.retention (Fig. 10 has one pipe with, one without)"),
    Key(
        "friction", "float", None, "obstacles: Coulomb friction of sand on it (default sand.wall_friction)", "", lo=0.0
    ),
    Key(
        "saturation",
        "float",
        None,
        "sand bodies: initial water saturation S of its particles (pore water per volume, paper 000 §4.2), so "
        "the sand is cohesive from step 0 without any water: c_C(S) of sand.cohesion_saturation (S in [S1, S2] "
        "gives the full sand.cohesion, e.g. 0.1 with the defaults). Default: dry (0). Sand-only scenes keep it "
        "(no water changes it). With a fluid the coupler recomputes every particle's saturation from the water "
        "each step, so the body must retain water (bodies[i].retention or sand.retention): it starts holding "
        "S as bound water (moisture ratio r = S / sand.packing_fraction, at most sand.max_moisture; the coupler "
        "then reads S inside the body, less at its surface, where the nodes are partly filled). At most "
        "1 − sand.packing_fraction (the pores full)",
        "",
        lo=0.0,
        hi=1.0,
    ),
    Key(
        "container_until",
        "float",
        None,
        "sand bodies: the body starts in an invisible box-shaped container, the vertical walls of its bounding "
        "box (frictionless, for the sand only: water passes through them), removed at this time (paper 000 "
        "Fig. 17: the block stands in a container while the water is poured, then the container is removed). "
        "Default: no container",
        "s",
        lo=0.0,
        lo_open=True,
    ),
]
"""Keys of one ``[[bodies]]`` entry (its shape is the ``geometry`` sub-table)."""

SAND_WALL_KINDS = ("separate", "slip", "sticky")
"""Kinds of a sand domain wall (couplekit.sand.boundaries.MODES)."""

SAND_WALL_KEYS: list[Key] = [
    Key(
        "kind",
        "choice",
        "separate",
        "how the sand meets this face (couplekit.sand.boundaries): 'separate' (default: Coulomb friction "
        "`friction`, the sand may leave the wall), 'slip' (frictionless, and the sand cannot leave the wall: "
        "the normal velocity is always removed; a symmetry plane), 'sticky' (no-slip: the sand stops on it)",
        choices=SAND_WALL_KINDS,
    ),
    Key(
        "friction",
        "float",
        None,
        "Coulomb friction μ of a 'separate' face (default sand.wall_friction); 0 = frictionless, the sand may lift off",
        "",
        lo=0.0,
    ),
]
"""Keys of one face of ``[sand.walls]`` (``x_min = { friction = 0.3 }``): the sand's domain wall on that face."""

GEOMETRY_COMMON_KEYS: list[Key] = [
    Key("type", "choice", REQUIRED, "the shape", choices=("box", "sphere", "cylinder", "heightfield", "mesh")),
    Key(
        "scale", "float", 1.0, "uniform scale about the shape's own origin (first transform)", "", lo=0.0, lo_open=True
    ),
    Key("rotate", "vec3", [0.0, 0.0, 0.0], "rotation about the x, then y, then z axis (second transform)", "degrees"),
    Key("translate", "vec3", [0.0, 0.0, 0.0], "translation (last transform)", "m"),
    Key("invert", "bool", False, "swap inside and outside (e.g. a container: the solid is outside the shape)"),
]

GEOMETRY_KEYS: dict[str, list[Key]] = {
    "box": [
        Key("min", "vec3", REQUIRED, "lower corner", "m"),
        Key("max", "vec3", REQUIRED, "upper corner", "m"),
    ],
    "sphere": [
        Key("center", "vec3", REQUIRED, "centre", "m"),
        Key("radius", "float", REQUIRED, "radius", "m", lo=0.0, lo_open=True),
    ],
    "cylinder": [
        Key("center", "vec3", REQUIRED, "centre (middle of the axis)", "m"),
        Key("radius", "float", REQUIRED, "radius", "m", lo=0.0, lo_open=True),
        Key("height", "float", REQUIRED, "length along the axis", "m", lo=0.0, lo_open=True),
        Key("axis", "choice", "z", "axis direction before rotation", choices=("x", "y", "z")),
    ],
    "heightfield": [
        Key("heights", "grid", None, "surface heights z(x, y) as rows along y of values along x; or give file", "m"),
        Key("file", "str", None, ".npy or .csv/.txt file of the height grid (relative to the scene file)"),
        Key("x_range", "floats", REQUIRED, "x of the first and last column", "m", length=2),
        Key("y_range", "floats", REQUIRED, "y of the first and last row", "m", length=2),
        Key(
            "base",
            "float",
            None,
            "z of the bottom of the solid under the surface (default: one cell below the domain)",
            "m",
        ),
    ],
    "mesh": [
        Key(
            "file",
            "str",
            REQUIRED,
            "closed triangle mesh, OBJ, STL or PLY (read with meshio), relative to the scene file",
        ),
    ],
}
"""Type-specific keys of a ``geometry`` table."""

GEOMETRY_SUBTRACT = "subtract"
"""The key of a geometry table that lists shapes cut out of it (each a geometry table of its own)."""

GEOMETRY_SUBTRACT_DOC = (
    "shapes cut out of this one, each a geometry table of any type with its own keys and transforms (in world "
    "coordinates, not relative to this shape): the body is this shape, after its transforms and invert, less "
    "every listed shape (a colander's holes, the inside of a ring wall). An entry may have a subtract list of "
    "its own. Nothing is left of a sand body wholly cut away, which validation refuses as it refuses a body "
    "inside obstacles"
)
"""What ``subtract`` does (the reference and the JSON Schema show it)."""

INFLOW_KEYS: list[Key] = [
    Key(
        "face",
        "choice",
        REQUIRED,
        "the domain face it enters through (its domain.boundary must be 'inflow')",
        choices=FACES,
    ),
    Key(
        "kind",
        "choice",
        "water",
        "'water' (a jet, optionally carrying sand) or 'wind' (air)",
        choices=("water", "wind"),
    ),
    Key("velocity", "vec3", REQUIRED, "inflow velocity; its normal component must point into the domain", "m/s"),
    Key(
        "sand_fraction",
        "float",
        0.0,
        "sand volume fraction carried by a water jet: the sand enters as MPM particles of the [sand] material "
        "(grain density sand.density), emitted in layers (dx/k apart, k³ = sand.particles_per_cell) 2 cells inside "
        "the face, moving at the inflow velocity, each of volume sand_fraction × (dx/k)³, so the jet's sand "
        "fraction is sand_fraction and the sand flux sand_fraction × area × normal speed (couplekit.sand.emission; "
        "a whole-face inflow emits over the face less a 2-cell rim, an outlet carrying sand must keep 2 cells from "
        "the face's edges). The memory estimate counts the particles emitted over time.frames",
        "",
        lo=0.0,
        hi=0.64,
    ),
    Key(
        "shape",
        "choice",
        "face",
        "'face': the whole face (its domain.boundary must be 'inflow'); 'rect' or 'disc': an outlet in the face "
        "(a jet), the rest of the face keeps its domain.boundary ('wall' or 'outflow'); several outlets may "
        "share a face if they do not overlap. A water outlet needs fluid.interface_width >= 2.5; at "
        "interface_width >= 4 outlets at least 2 cells across are not limited (measured to lattice speed 0.08) and "
        "1-cell outlets are limited to lattice speed 0.04 with an air_lattice_viscosity above 0.01; from 3 to 4 "
        "the limit is 0.06 (0.02 for outlets under 3 cells with the more viscous air); from 2.5 to 3 it is 0.04 "
        "(with the more viscous air 0.02, and 0.01 for outlets under 3 cells) (measured to diverge beyond: "
        "couplekit.scene.model.water_outlet_speed_limit, tests/fluid/test_inflow_region.py)",
        choices=("face", "rect", "disc"),
    ),
    Key(
        "center",
        "floats",
        None,
        "centre of an outlet in the face's two in-plane coordinates in x, y, z order: (y, z) on x faces, "
        "(x, z) on y faces, (x, y) on z faces, from the domain's origin",
        "m",
        length=2,
    ),
    Key(
        "size",
        "floats",
        None,
        "side lengths of a 'rect' outlet along the same two axes (it takes the cells whose centres lie inside)",
        "m",
        lo=0.0,
        lo_open=True,
        length=2,
    ),
    Key(
        "radius",
        "float",
        None,
        "radius of a 'disc' outlet (it takes the cells whose centres lie inside)",
        "m",
        lo=0.0,
        lo_open=True,
    ),
    Key(
        "sand_start",
        "float",
        0.0,
        "time at which a jet with sand_fraction > 0 starts carrying sand: clean water before it (paper Fig. 1's "
        "first stage)",
        "s",
        lo=0.0,
    ),
    Key(
        "sand_ramp",
        "float",
        0.0,
        "after sand_start the jet's sand fraction rises linearly from 0 to sand_fraction over this time (0: at "
        "once), as the sand ratio of paper Fig. 1's jet increases; each emitted layer takes the fraction of its "
        "step (its particles' volume sand fraction × (dx/k)³)",
        "s",
        lo=0.0,
    ),
]
"""Keys of one ``[[inflows]]`` entry."""

OUTLET_KEYS: dict[str, tuple[str, ...]] = {"face": (), "rect": ("center", "size"), "disc": ("center", "radius")}
"""The shape keys each ``[[inflows]]`` ``shape`` takes (all of them, and no other of center, size, radius)."""

TOP_LEVEL = (
    "scene",
    "domain",
    "time",
    "scheduler",
    "fluid",
    "sand",
    "bodies",
    "inflows",
    "stirring",
    "outputs",
    "effects",
)
"""Top-level tables of a scene file."""


# ------------------------------------------------------------------------------------------------ checking
MAX_MAGNITUDE = 1e30
"""Largest magnitude of any number in a scene (SI units: nothing physical in a scene comes near it). With
every input between MIN_MAGNITUDE and MAX_MAGNITUDE (or 0), the products and quotients of up to ten of them
that the checks and the solvers form stay finite and non-zero in float64."""
MIN_MAGNITUDE = 1e-30
"""Smallest magnitude of a non-zero number in a scene (see MAX_MAGNITUDE)."""
MAX_INT = 2**63 - 1
"""Largest integer a scene may hold (it must fit the solvers' 64-bit integers)."""
MAX_DEPTH = 16
"""Deepest nesting of tables and arrays a scene may have (a height grid inside a body is 6 deep)."""

_SHOW = reprlib.Repr()
_SHOW.maxlevel, _SHOW.maxlist, _SHOW.maxdict, _SHOW.maxstring, _SHOW.maxother = 3, 6, 4, 60, 60


def show(value: Any) -> str:
    """A short repr of ``value`` for messages: truncated, at most 3 levels deep (so a huge or deeply nested
    value cannot make a message huge or recurse without bound)."""
    try:
        return _SHOW.repr(value)
    except Exception:  # a foreign object whose repr fails
        return f"<{type(value).__name__}>"


def too_deep(data: Any, path: str = "", limit: int = MAX_DEPTH) -> Problem | None:
    """A :class:`Problem` at the dotted key of the first value nested more than ``limit`` tables or arrays deep
    in ``data`` (walked without recursion, so a nesting of any depth, even a cycle, is safe); None if none is."""
    stack = [(data, path, 0)]
    while stack:
        value, where, depth = stack.pop()
        if not isinstance(value, (dict, list)):
            continue
        if depth >= limit:
            return Problem(
                where or "(scene)",
                f"is nested more than {limit} tables or arrays deep",
                "flatten it: no scene key takes values nested that deep (a height grid is a list of lists)",
            )
        if isinstance(value, dict):
            stack.extend((v, f"{where}.{k}" if where else str(k), depth + 1) for k, v in value.items())
        else:
            stack.extend((v, f"{where}[{i}]", depth + 1) for i, v in enumerate(value))
    return None


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _type_name(v: Any) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "a list", dict: "a table"}
    return names.get(type(v), type(v).__name__)


def _check_range(key: Key, value: int | float, path: str) -> Problem | None:
    """The problem with number ``value`` of ``key``: not finite, outside [MIN_MAGNITUDE, MAX_MAGNITUDE] in
    magnitude (0 excepted), an integer key's value beyond MAX_INT, or outside the key's range; None if fine."""
    allowed = f" {key.range_text()}" if key.range_text() else ""
    if isinstance(value, float) and not math.isfinite(value):
        return Problem(path, f"must be a finite number, got {value}", f"set {path} to a finite number{allowed}")
    if key.kind in ("int", "ivec3", "int_or_auto") and abs(value) > MAX_INT:
        limit = key.range_text() if key.hi is not None else ""
        limit = limit or (f"{key.range_text()} and at most {MAX_INT}" if key.range_text() else f"at most {MAX_INT}")
        return Problem(path, f"{show(value)} is too large (must be {limit})", f"set {path} to an integer {limit}")
    if value != 0 and not MIN_MAGNITUDE <= abs(value) <= MAX_MAGNITUDE:  # exact for integers of any size
        shown = f"{value:g}" if isinstance(value, float) else show(value)
        unit = f" {key.unit}" if key.unit else ""
        return Problem(
            path,
            f"{shown}{unit} is out of scale: a number must be 0 or between {MIN_MAGNITUDE:g} and "
            f"{MAX_MAGNITUDE:g} in magnitude (SI units)",
            f"set {path} to a value{allowed} in SI units{f' ({key.unit})' if key.unit else ''}",
        )
    bad = False
    if key.lo is not None and (value < key.lo or (key.lo_open and value == key.lo)):
        bad = True
    if key.hi is not None and (value > key.hi or (key.hi_open and value == key.hi)):
        bad = True
    if bad:
        got = show(value) if isinstance(value, int) else f"{value:g}"  # an integer as written, not 1e+06
        return Problem(path, f"must be {key.range_text()}, got {got}", f"set {path} to a value {key.range_text()}")
    return None


def _type_fix(key: Key, name: str, what: str) -> str:
    """The fix of a type error of ``key``: the key's default as an example where the key's range admits it, else
    the kind of value and its range (a fixed placeholder broke the key's own rules: "poisson_ratio = 1.5")."""
    k = key.kind
    integer = k in ("int", "ivec3")

    def fmt(v: Any) -> str:
        if integer:
            return str(int(v))
        text = f"{float(v):g}"
        return text if any(c in text for c in ".en") else text + ".0"

    def admitted(v: Any) -> bool:
        ok = _is_number(v) and math.isfinite(float(v)) and _check_range(key, v, "") is None
        return ok and (not integer or isinstance(v, int))

    d = key.default
    if k in ("float", "int") and d is not REQUIRED and admitted(d):
        return f"write e.g. {name} = {fmt(d)}"
    if k in ("vec3", "ivec3", "floats") and isinstance(d, (list, tuple)) and d and all(admitted(v) for v in d):
        return f"write e.g. {name} = [" + ", ".join(fmt(v) for v in d) + "]"
    bounds = key.range_text()
    return f"write {name} = {what}" + (f", each {bounds}" if bounds and k not in ("float", "int") else f" {bounds}")


def _check_value(key: Key, value: Any, path: str) -> tuple[Any, list[Problem]]:
    """(checked value, problems): the value is None whenever a problem was found (so no check or computation
    after this one sees a value that was refused)."""
    k = key.kind
    name = path.rsplit(".", 1)[-1]
    if k == "int_or_auto":
        if value == "auto":
            return value, []
        if not isinstance(value, int) or isinstance(value, bool):
            return None, [
                Problem(
                    path,
                    f'must be an integer or "auto", got {_type_name(value)} ({show(value)})',
                    f'write e.g. {name} = 4, or {name} = "auto"',
                )
            ]
        p = _check_range(key, value, path)
        return (None, [p]) if p else (int(value), [])
    if k in ("float", "int"):
        ok = _is_number(value) if k == "float" else isinstance(value, int) and not isinstance(value, bool)
        if not ok:
            what = "a number" if k == "float" else "an integer"
            return None, [
                Problem(
                    path,
                    f"must be {what}, got {_type_name(value)} ({show(value)})",
                    _type_fix(key, name, what).rstrip(),
                )
            ]
        p = _check_range(key, value, path)
        if p:
            return None, [p]
        return (float(value) if k == "float" else int(value)), []
    if k == "bool":
        if not isinstance(value, bool):
            return None, [
                Problem(
                    path,
                    f"must be true or false, got {_type_name(value)} ({show(value)})",
                    f"write {name} = true or false (no quotes)",
                )
            ]
        return value, []
    if k == "str":
        if not isinstance(value, str):
            return None, [
                Problem(
                    path, f"must be a string, got {_type_name(value)} ({show(value)})", "put the value in double quotes"
                )
            ]
        if "\x00" in value:  # no file name, output folder or label can hold one
            return None, [Problem(path, "contains a NUL character", "remove it")]
        return value, []
    if k == "choice":
        if not isinstance(value, str) or value not in key.choices:
            close = (
                difflib.get_close_matches(value, [str(c) for c in key.choices], n=1) if isinstance(value, str) else []
            )
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            return None, [
                Problem(
                    path, f"must be {key.range_text()}, got {show(value)}{hint}", f"set {path} to {key.range_text()}"
                )
            ]
        return value, []
    if k in ("vec3", "ivec3", "floats"):
        n = 3 if k != "floats" else key.length
        integer = k == "ivec3"
        if (
            not isinstance(value, list)
            or (n and len(value) != n)
            or not all((isinstance(v, int) and not isinstance(v, bool)) if integer else _is_number(v) for v in value)
        ):
            what = f"a list of {n} {'integers' if integer else 'numbers'}" if n else "a list of numbers"
            return None, [Problem(path, f"must be {what}, got {show(value)}", _type_fix(key, name, what).rstrip())]
        problems = [p for i, v in enumerate(value) if (p := _check_range(key, v, f"{path}[{i}]"))]
        if problems:
            return None, problems
        return [int(v) if integer else float(v) for v in value], []
    if k == "strs":
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            return None, [
                Problem(
                    path, f"must be a list of strings, got {show(value)}", f'write e.g. {name} = ["{key.choices[0]}"]'
                )
            ]
        bad = [v for v in value if v not in key.choices]
        if bad:
            return None, [Problem(path, f"unknown entries {show(bad)}", f"use only {key.range_text()}")]
        return list(value), []
    if k == "grid":
        if (
            not isinstance(value, list)
            or len(value) < 2
            or not all(isinstance(r, list) and len(r) == len(value[0]) and len(r) >= 2 for r in value)
            or not all(_is_number(v) for r in value for v in r)
        ):
            return None, [
                Problem(
                    path,
                    "must be a rectangular list of at least 2 rows of at least 2 numbers",
                    "write e.g. heights = [[0.0, 0.1], [0.1, 0.2]]",
                )
            ]
        for j, row in enumerate(value):  # every number finite and in scale; the first bad one is named
            for i, v in enumerate(row):
                p = _check_range(key, v, f"{path}[{j}][{i}]")
                if p:
                    return None, [p]
        return [[float(v) for v in r] for r in value], []
    raise AssertionError(f"unknown key kind {k}")


def read_table(data: Any, path: str, keys: list[Key], problems: list[Problem]) -> dict[str, Any]:
    """Check the TOML table ``data`` found at dotted ``path`` against ``keys``.

    Appends a :class:`Problem` per unknown key (with the closest known name), wrong type, out-of-range
    value or missing required key; returns the checked values with defaults filled in (``None`` for a
    value that failed).
    """
    if not isinstance(data, dict):
        problems.append(
            Problem(path, f"must be a table, got {_type_name(data)}", f"write it as [{path}] with key = value lines")
        )
        data = {}
    known = {k.name: k for k in keys}
    for name in data:
        if name not in known:
            close = difflib.get_close_matches(name, list(known), n=1) if isinstance(name, str) else []
            fix = f"did you mean {close[0]!r}?" if close else f"remove it; the keys of [{path}] are {', '.join(known)}"
            problems.append(Problem(f"{path}.{show(name) if not isinstance(name, str) else name}", "unknown key", fix))
    out: dict[str, Any] = {}
    for key in keys:
        sub = f"{path}.{key.name}"
        if key.name not in data:
            if key.default is REQUIRED:
                problems.append(Problem(sub, "is required", f"add {key.name} = ... ({key.doc})"))
                out[key.name] = None
            else:
                out[key.name] = list(key.default) if isinstance(key.default, list) else key.default
            continue
        value, found = _check_value(key, data[key.name], sub)
        problems.extend(found)
        out[key.name] = value
    return out
