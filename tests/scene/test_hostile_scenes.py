"""Hostile scene input (issue 15): no input, however broken, gives a traceback; `couplekit validate` and
`couplekit run` refuse the same scenes, before any allocation, each problem naming the dotted key and the fix.

A randomised part mutates the valid scenes of test_scene_validation.py and sim_scenes.py (a value anywhere in
the nested dict replaced by a hostile one, or its key removed; fixed seed): Scene.from_dict returns a Scene or
raises SceneError, nothing else; for the scenes it accepts, the memory estimate and the coupling refusal raise
nothing but their documented errors. The named classes of the issue follow, one test each.
"""

from __future__ import annotations

import copy
import math
import os
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sim_scenes import tiny_coupled, tiny_fluid, tiny_sand
from test_scene_validation import fluid_scene, sand_scene

from couplekit.assembly import CouplingUnavailableError, build_sand, check_run, memory_estimate, refuse_unsupported
from couplekit.backend import get_backend
from couplekit.cli import main
from couplekit.scene import Scene, SceneError

BASES = {
    "fluid_scene": fluid_scene,
    "sand_scene": sand_scene,
    "tiny_sand": tiny_sand,
    "tiny_fluid": tiny_fluid,
    "tiny_coupled": tiny_coupled,
}
_DELETE = object()
HOSTILE = [0, -1, 1e300, -1e300, 1e-300, math.inf, -math.inf, math.nan, "x", "\x00", [], {}, [[[[1]]]], True,
           _DELETE, 10**30, 10**400, -(10**400)]  # fmt: skip
"""The replacement values: zero, negatives, huge and tiny floats, non-finite floats, strings, empty and nested
containers, a boolean, removal of the key, huge integers (10**400 cannot become a float)."""


def _paths(d, prefix=()):
    """Every key path (tuple of dict keys and list indices) in a nested scene dict."""
    out = []
    items = d.items() if isinstance(d, dict) else enumerate(d) if isinstance(d, list) else ()
    for k, v in items:
        out.append((*prefix, k))
        out += _paths(v, (*prefix, k))
    return out


def _mutated(rng: random.Random) -> tuple[dict, str]:
    name = rng.choice(sorted(BASES))
    d = BASES[name]()
    path = rng.choice(_paths(d))
    value = rng.choice(HOSTILE)
    parent = d
    for k in path[:-1]:
        parent = parent[k]
    if value is _DELETE:
        del parent[path[-1]]
    else:
        parent[path[-1]] = copy.deepcopy(value)
    return d, f"{name}: {'.'.join(map(str, path))} = {'<deleted>' if value is _DELETE else repr(value)[:40]}"


def _check_problems(err: SceneError) -> None:
    assert err.problems
    for p in err.problems:
        assert p.key and p.message and p.fix, str(p)
    assert len(str(err)) < 20_000  # a huge or deeply nested value is shown shortened


def test_random_mutations_give_a_scene_or_a_scene_error():
    """1000 random mutations (seed 15): nothing but SceneError escapes; the accepted scenes' memory estimate is
    finite and their refusals are the documented ones."""
    rng = random.Random(15)
    escaped, accepted = [], []
    for _ in range(1000):
        d, what = _mutated(rng)
        try:
            scene = Scene.from_dict(d)
        except SceneError as err:
            _check_problems(err)
            continue
        except Exception as exc:  # noqa: BLE001 - what the test is looking for
            escaped.append(f"{what}: {type(exc).__name__}: {exc}")
            continue
        accepted.append((what, scene))
    assert not escaped, "\n".join(escaped)
    assert len(accepted) > 10  # the mutations also hit keys whose new value is admissible
    for what, scene in accepted:
        est = memory_estimate(scene)
        assert math.isfinite(est["total"]) and est["total"] >= 0, what
        try:
            refuse_unsupported(scene)
            check_run(scene, available=(math.inf, "test memory"))
        except CouplingUnavailableError:
            pass


def test_mutated_toml_files_are_refused_alike_by_validate_and_run(tmp_path, capsys):
    """A few hostile values written as TOML: `validate` and `run` give the same exit code (2) and no traceback."""
    cases = []
    for path, value in [("domain.dx", 0.0), ("domain.size", [math.inf, 0.06, 0.06]), ("time.frames", 10**30),
                        ("bodies.0.geometry.min", [0.02, 0.02, math.nan]), ("sand.particles_per_cell", 1e300)]:  # fmt: skip
        d = tiny_sand()
        keys = path.split(".")
        parent = d
        for k in keys[:-1]:
            parent = parent[int(k)] if isinstance(parent, list) else parent[k]
        parent[keys[-1]] = value
        f = tmp_path / f"{len(cases)}.toml"
        f.write_text(_toml(d))
        cases.append((f, path))
    for f, path in cases:
        assert main(["validate", str(f)]) == 2, path
        out = capsys.readouterr()
        assert path.replace(".0.", "[0].").split(".")[0] in out.err and "Traceback" not in out.err
        assert main(["run", str(f), "--backend", "numpy", "--out", str(tmp_path / "o")]) == 2, path
        assert "Traceback" not in capsys.readouterr().err


def _toml(d: dict) -> str:
    """A scene dict as TOML (tables, arrays of tables, sub-tables; floats as TOML writes inf and nan)."""

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return "nan" if v != v else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        if isinstance(v, str):
            return '"' + v + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return str(v)

    lines = []

    def table(name, t, array=False):
        lines.append(f"[[{name}]]" if array else f"[{name}]")
        subs = [(k, v) for k, v in t.items() if isinstance(v, dict)]
        lines.extend(f"{k} = {value(v)}" for k, v in t.items() if not isinstance(v, dict))
        for k, v in subs:
            table(f"{name}.{k}", v)

    for name, t in d.items():
        for item in t if isinstance(t, list) else [t]:
            table(name, item, array=isinstance(t, list))
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------------ files
def _refused(d: dict | None = None, key: str = "", words: str = "", base_dir: Path | str = ".", **load):
    with pytest.raises(SceneError) as err:
        if load:
            Scene.load(load["path"])
        else:
            Scene.from_dict(d, base_dir=base_dir)
    _check_problems(err.value)
    problem = next((p for p in err.value.problems if p.key == key), None)
    assert problem is not None, f"no problem at {key!r}:\n{err.value}"
    assert words in problem.message + problem.fix, str(err.value)
    return err.value


def test_binary_file_and_deep_nesting(tmp_path):
    binary = tmp_path / "scene.toml"
    binary.write_bytes(bytes(range(256)) * 8)
    _refused(key="(file)", words="not a text file", path=binary)
    deep = tmp_path / "deep.toml"
    deep.write_text("[domain]\nsize = " + "[" * 5000 + "]" * 5000 + "\n")
    _refused(key="(syntax)", words="nested too deeply", path=deep)
    d = sand_scene()
    inner = d["domain"]
    for _ in range(3000):  # a dict nested beyond any recursion limit
        inner["a"] = {}
        inner = inner["a"]
    err = _refused(d, key="domain" + ".a" * 15, words="nested more than 16")
    assert len(err.problems) == 1
    d = sand_scene()
    d["domain"]["self"] = d  # a cycle
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    (problem,) = err.value.problems
    assert problem.key.startswith("domain.self.domain.self") and "nested more than 16" in problem.message


@pytest.mark.parametrize(
    ("table", "value"), [("fluid", 3), ("sand", "x"), ("stirring", [1]), ("scheduler", 2.5), ("outputs", None)]
)
def test_a_table_given_as_a_value(table, value):
    d = fluid_scene() if table in ("fluid", "stirring") else sand_scene()
    d[table] = value
    _refused(d, key=table, words="must be a table")


@pytest.mark.parametrize(
    ("path", "value", "key", "words"),
    [
        ("domain.dx", 0, "domain.dx", "> 0"),
        ("domain.dx", 1e-300, "domain.dx", "out of scale"),
        ("domain.dx", 1e-11, "domain.size[0]", "more than the solvers index"),
        ("domain.size", [math.inf, 0.1, 0.1], "domain.size[0]", "finite"),
        ("domain.size", [1e300, 0.1, 0.1], "domain.size[0]", "out of scale"),
        ("domain.gravity", [0.0, 0.0, math.nan], "domain.gravity[2]", "finite"),
        ("time.frames", 10**400, "time.frames", "too large"),
        ("time.dt", 10**400, "time.dt", "out of scale"),
        ("sand.youngs_modulus", 1e-31, "sand.youngs_modulus", "out of scale"),
        ("bodies.0.velocity", [0.0, -math.inf, 0.0], "bodies[0].velocity[1]", "finite"),
        ("bodies.0.geometry.max", [0.07, 0.07, 1e40], "bodies[0].geometry.max[2]", "out of scale"),
    ],
)
def test_numbers_are_finite_and_in_scale(path, value, key, words):
    """No refused value reaches a division or a product (dx = 0 used to divide by zero, size = inf or a tiny dx
    to overflow the cell count)."""
    d = sand_scene()
    del d["domain"]["resolution"]
    d["domain"]["dx"] = 0.005
    keys = path.split(".")
    parent = d
    for k in keys[:-1]:
        parent = parent[int(k)] if isinstance(parent, list) else parent[k]
    parent[keys[-1]] = value
    _refused(d, key=key, words=words)


def _body_file(tmp_path, name: str, content: bytes | str) -> dict:
    f = tmp_path / name
    f.write_bytes(content if isinstance(content, bytes) else content.encode())
    d = sand_scene()
    d["bodies"][0]["geometry"] = {"type": "mesh", "file": name}
    return d


_CUBE_V = "".join(f"v {x} {y} {z}\n" for x in (0.03, 0.07) for y in (0.03, 0.07) for z in (0.03, 0.07))
_CUBE_F = [(1, 3, 7), (1, 7, 5), (2, 6, 8), (2, 8, 4), (1, 5, 6), (1, 6, 2), (3, 4, 8), (3, 8, 7), (1, 2, 4),
           (1, 4, 3), (5, 7, 8), (5, 8, 6)]  # fmt: skip


def _obj(faces, vertices: str = _CUBE_V) -> str:
    return vertices + "".join(f"f {a} {b} {c}\n" for a, b, c in faces)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # meshio's STL sniffing of a foreign file
@pytest.mark.parametrize(
    ("name", "content", "words"),
    [
        ("junk.stl", b"solid x\n garbage \x00\x01\x02\n", "not a mesh meshio can read"),
        ("junk.ply", bytes(range(256)) * 4, "not a mesh meshio can read"),
        ("junk.obj", "v 1 2\nf 1 2 3\n", "cannot build the shape"),
        ("empty.obj", "", "cannot build the shape"),
        ("open.obj", _obj(_CUBE_F[:-2]), "not closed (watertight): 4 edges"),
        ("nan.obj", _obj(_CUBE_F, _CUBE_V.replace("0.07 0.07 0.07", "nan 0.07 0.07")), "not finite"),
        ("huge.obj", _obj(_CUBE_F, _CUBE_V.replace("0.07 0.07 0.07", "1e200 0.07 0.07")), "cannot build"),
    ],
)
def test_a_bad_mesh_file_is_a_problem_of_its_geometry(tmp_path, name, content, words):
    """Any exception of the mesh reader or the shape (meshio's ReadError, a foreign file's ValueError, an open
    surface) becomes a problem of bodies[i].geometry; an open mesh used to pass validation and fail at run."""
    _refused(_body_file(tmp_path, name, content), key="bodies[0].geometry", words=words, base_dir=tmp_path)


def test_a_closed_mesh_still_loads(tmp_path):
    d = _body_file(tmp_path, "cube.obj", _obj(_CUBE_F))
    scene = Scene.from_dict(d, base_dir=tmp_path)
    lo, hi = scene.bodies[0].geometry.bounds(scene.domain)
    np.testing.assert_allclose(lo, 0.03) and np.testing.assert_allclose(hi, 0.07)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_height_fields_with_non_finite_heights(tmp_path, bad):
    d = sand_scene()
    hf = {"type": "heightfield", "heights": [[0.01, bad], [0.01, 0.02]], "x_range": [0.0, 0.1], "y_range": [0, 0.1]}
    d["bodies"].append({"kind": "obstacle", "geometry": hf})
    _refused(d, key="bodies[1].geometry.heights[0][1]", words="finite")
    np.save(tmp_path / "h.npy", np.array([[0.01, bad], [0.01, 0.02]]))
    np.savetxt(tmp_path / "h.csv", np.array([[0.01, bad], [0.01, 0.02]]), delimiter=",")
    (tmp_path / "junk.npy").write_bytes(b"\x93NUMPY garbage")
    for name, words in (("h.npy", "not finite"), ("h.csv", "not finite"), ("junk.npy", "unreadable")):
        d["bodies"][1]["geometry"] = {"type": "heightfield", "file": name, "x_range": [0.0, 0.1], "y_range": [0, 0.1]}
        _refused(d, key="bodies[1].geometry.file", words=words, base_dir=tmp_path)


def test_a_height_file_whose_base_is_not_below_its_heights_names_the_base(tmp_path):
    """Fuzz finding: inline heights named `base`, a height file's were reported under `geometry` at sampling."""
    d = sand_scene()
    np.save(tmp_path / "h.npy", np.array([[0.01, 0.03], [0.02, 0.02]]))
    hf = {"type": "heightfield", "file": "h.npy", "x_range": [0.0, 0.1], "y_range": [0, 0.1], "base": 0.015}
    d["bodies"].append({"kind": "obstacle", "geometry": hf})
    _refused(d, key="bodies[1].geometry.base", words="lowest 0.01", base_dir=tmp_path)
    hf["base"] = 0.005  # below every height: accepted
    Scene.from_dict(d, base_dir=tmp_path)


def test_sand_above_a_height_field_obstacle_is_seeded():
    """Found with the test above: a sand box above a height-field obstacle was refused with NumPy's "zero-size
    array to reduction operation minimum" (the mesh's inside test, when the triangles near a point's ray are all
    missed by it)."""
    d = sand_scene()  # sand box z 0.03-0.07
    hf = {"type": "heightfield", "heights": [[0.01, 0.03], [0.02, 0.02]], "x_range": [0.0, 0.1], "y_range": [0, 0.1]}
    d["bodies"].append({"kind": "obstacle", "geometry": hf})
    scene = Scene.from_dict(d)
    shape = scene.bodies[1].geometry.solver_shape(scene.domain)
    inside = shape.sdf(np.array([[0.05, 0.05, 0.01], [0.05, 0.05, 0.05], [0.02, 0.08, 0.005]])) < 0
    assert inside.tolist() == [True, False, True]


def test_a_tall_height_field_is_refused_not_sampled():
    """Heights far outside the domain would need ~1e16 surface samples: refused by the sample count."""
    d = sand_scene()
    hf = {"type": "heightfield", "heights": [[0.01, 1e6], [0.01, 0.02]], "x_range": [0.0, 0.1], "y_range": [0, 0.1]}
    d["bodies"].append({"kind": "obstacle", "geometry": hf})
    _refused(d, key="bodies[1].geometry", words="surface every")


# ------------------------------------------------------------------------------------------------ seeding
def test_a_sand_body_thinner_than_the_particle_spacing():
    """It passed validation and build_sand raised a ValueError at run; validation counts its particles."""
    d = sand_scene()
    d["bodies"][0]["geometry"]["max"] = [0.07, 0.07, 0.031]  # 1 mm thick, particles 2.5 mm apart
    _refused(d, key="bodies[0].geometry", words="thinner than the particle spacing")
    d["bodies"][0]["geometry"]["max"] = [0.07, 0.07, 0.0326]  # over a seeding point (z = 0.03125)
    Scene.from_dict(d)


def _sand_over_obstacle(radius: float) -> dict:
    d = sand_scene()
    d["bodies"].append(
        {"kind": "obstacle", "geometry": {"type": "sphere", "center": [0.05, 0.05, 0.05], "radius": radius}}
    )
    return d


def test_no_particle_is_seeded_inside_an_obstacle():
    _refused(_sand_over_obstacle(0.045), key="bodies[0].geometry", words="wholly inside obstacles (bodies[1])")
    scene = Scene.from_dict(_sand_over_obstacle(0.015))  # the ball takes the middle of the block
    sand, _ = build_sand(scene, get_backend("numpy"), lambda s: None)
    x = sand.particles()["x"]
    r = np.linalg.norm(x - 0.05, axis=0)
    assert r.min() >= 0.015 - 0.5 * 0.0025  # none inside the ball (less the seeding jitter)
    box = 8 * 8 * 8 * 8  # the block's 8³ cells × 8 particles
    ball = 4 / 3 * np.pi * 0.015**3 / (0.0025**3)  # seeding points in the ball
    assert abs((box - sand.n_particles) - ball) < 0.1 * ball
    alone = build_sand(Scene.from_dict(sand_scene()), get_backend("numpy"), lambda s: None)[0]
    assert alone.n_particles == box


# ------------------------------------------------------------------------------------------------ speeds
def test_max_speed_below_a_speed_the_scene_gives():
    d = fluid_scene()
    d["time"]["max_speed"] = 0.5
    _refused(d, key="time.max_speed", words="|bodies[1].velocity| = 1")
    d["time"]["max_speed"] = 1.0
    Scene.from_dict(d)  # equal is fine
    d = fluid_scene()
    d["inflows"][0]["velocity"] = [2.0, 0.0, 0.0]
    d["time"]["max_speed"] = 1.5
    d["time"]["dt"] = 1e-6
    _refused(d, key="time.max_speed", words="|inflows[0].velocity| = 2")


# ------------------------------------------------------------------------------------------------ command line
def _huge(tmp_path) -> Path:
    f = tmp_path / "huge.toml"
    f.write_text(
        "[domain]\nsize = [1000.0, 1000.0, 1000.0]\ndx = 0.01\n[time]\ndt = 1e-4\n[sand]\n[[bodies]]\n"
        'kind = "sand"\n[bodies.geometry]\ntype = "box"\nmin = [0.1, 0.1, 0.1]\nmax = [0.2, 0.2, 0.2]\n'
    )
    return f


def test_validate_refuses_what_run_refuses_for_memory(tmp_path, capsys):
    """A 10¹⁵-cell grid: validate called it valid; now both refuse it, exit 3, with run's message."""
    f = _huge(tmp_path)
    assert Scene.load(f).domain.cells == 10**15
    assert main(["validate", str(f)]) == 3
    err = capsys.readouterr().err
    assert err.startswith(
        "refused: scene 'scene' needs about 1.86e+07 GiB but only"
    )  # 20 B per sand-grid cell (grid_v is grid_mv; one density: no volume grid, SandSolver.node_volume)
    assert main(["run", str(f), "--backend", "numpy", "--out", str(tmp_path / "o")]) == 3
    run_err = capsys.readouterr().err
    assert run_err.split(" but only")[0] == err.split(" but only")[0]


@pytest.mark.parametrize("frames", ["0", "-2"])
def test_run_refuses_a_frame_count_below_one(tmp_path, capsys, frames):
    f = tmp_path / "s.toml"
    f.write_text("[domain]\nsize = [1.0, 1.0, 1.0]\ndx = 0.1\n[time]\ndt = 1e-4\n")
    assert main(["run", str(f), "--frames", frames]) == 2
    assert f"--frames must be 1 or more, got {frames}" in capsys.readouterr().err


def test_a_closed_stdout_ends_quietly(tmp_path):
    """`couplekit validate scene.toml | head -1`: the reader is gone before anything is written."""
    f = tmp_path / "s.toml"
    f.write_text(
        '[domain]\nsize = [0.1, 0.1, 0.1]\ndx = 0.005\n[time]\ndt = 1e-4\n[sand]\n[[bodies]]\nkind = "sand"\n'
        '[bodies.geometry]\ntype = "box"\nmin = [0.03, 0.03, 0.03]\nmax = [0.07, 0.07, 0.07]\n'
    )
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.Popen(
        [sys.executable, "-m", "couplekit", "validate", str(f)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env
    )
    proc.stdout.close()  # no reader: the first write fails with EPIPE
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


@pytest.mark.parametrize(
    "path, bad",
    [
        (("sand", "poisson_ratio"), "x"),
        (("sand", "youngs_modulus"), "x"),
        (("fluid", "phases"), 2.0),
        (("fluid", "interface_width"), "a"),
        (("sand", "hardening"), [35, 9, 0.2]),
        (("domain", "gravity"), [1, 2]),
        (("time", "frames"), "x"),
        (("domain", "size"), [0.03, 0.02]),
        (("time", "dt"), "x"),
    ],
)
def test_a_type_errors_fix_gives_a_value_the_key_admits(path, bad):
    """Probe finding (session 24): the fix of a type error was a fixed placeholder per kind, which often broke the
    key's own rules ("write e.g. poisson_ratio = 1.5", allowed up to 0.5; "phases = 8"). Now the key's default
    where its range admits it, else the kind and the range; following an example gives a valid scene."""
    d = tiny_coupled()
    d["sand"]["hardening"] = [35.0, 9.0, 0.2, 10.0]
    Scene.from_dict(copy.deepcopy(d))  # valid as it is
    d[path[0]][path[1]] = bad
    with pytest.raises(SceneError) as err:
        Scene.from_dict(copy.deepcopy(d))
    (problem,) = [p for p in err.value.problems if p.key == ".".join(path)]
    prefix = f"write e.g. {path[1]} = "
    if not problem.fix.startswith(prefix):
        assert problem.fix.startswith(f"write {path[1]} = a ") and (">" in problem.fix or "<" in problem.fix)
        return
    import tomllib

    d[path[0]][path[1]] = tomllib.loads(f"v = {problem.fix[len(prefix) :]}")["v"]
    Scene.from_dict(d)


@pytest.mark.parametrize(
    ("key", "limit"),
    [("checkpoint_every", ">= 0 and at most 9223372036854775807"), ("particles_per_cell", None)],
)
def test_an_integer_beyond_int64_names_the_real_limit(key, limit):
    """A probe (session 25): 1e20 for outputs.checkpoint_every said "too large (must be >= 0)", a range the value
    meets; the message names the int64 limit where the key has no upper bound of its own, else the key's range."""
    d = tiny_sand()
    table = "outputs" if key == "checkpoint_every" else "sand"
    d.setdefault(table, {})[key] = 10**20
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    text = str(err.value)
    assert f"{table}.{key}: {10**20} is too large" in text
    if limit:
        assert f"must be {limit}" in text
    else:  # the key's own range, which 1e20 breaks
        assert "<=" in text and "9223372036854775807" not in text


@pytest.mark.parametrize("unit", [1.0, 0.001, 0.1])
def test_a_scaled_mesh_is_sampled_in_world_units(tmp_path, unit):
    """A probe (session 25): the surface was sampled every dx/4 in the file's own units, so a cube written in mm
    with scale = 0.001 validated and was then refused at run time (7.7e10 samples), and at scale 0.1 one SDF pass
    took 57 s. The same cube in any unit, scaled to metres, gives the box's cells."""
    from couplekit.scene.geometry import sdf_on_grid

    verts = "".join(
        f"v {x / unit} {y / unit} {z / unit}\n" for x in (0.03, 0.07) for y in (0.03, 0.07) for z in (0.03, 0.07)
    )
    (tmp_path / "cube.obj").write_text(_obj(_CUBE_F, verts))
    d = {
        "domain": {"size": [0.1, 0.1, 0.1], "dx": 0.005},
        "time": {"dt": 1e-4, "frames": 1},
        "bodies": [
            {"kind": "obstacle", "geometry": {"type": "mesh", "file": str(tmp_path / "cube.obj"), "scale": unit}}
        ],
        "fluid": {"phases": 1},
    }
    scene = Scene.from_dict(d)
    dom = scene.domain
    cells = int((sdf_on_grid(scene.bodies[0].geometry.shape(dom, 0.25 * dom.dx), dom.resolution, dom.dx) < 0).sum())
    assert cells == 8**3


def test_an_obj_with_texture_coordinates_and_partly_repeated_faces(tmp_path):
    """A probe (session 25): an OBJ with fewer texture coordinates than vertices (Blender's export: `vt`, `vn`,
    `f v/t/n`, negative indices) was refused as "not a mesh meshio can read"; it builds the cube now. A closed cube
    with two faces repeated was called open ("6 edges belong to one triangle only"); it is named as repeated."""
    from couplekit.scene.geometry import sdf_on_grid

    corners = "".join(f"v {x} {y} {z}\n" for x in (0.03, 0.07) for y in (0.03, 0.07) for z in (0.03, 0.07))
    uv = "vt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
    faces = "".join(f"f {a - 9}/{1 + i % 3 - 4}/-1 {b - 9}/1/1 {c}//1\n" for i, (a, b, c) in enumerate(_CUBE_F))
    (tmp_path / "uv.obj").write_text("o cube\n" + corners + uv + faces)
    d = {
        "domain": {"size": [0.1, 0.1, 0.1], "dx": 0.005},
        "time": {"dt": 1e-4, "frames": 1},
        "bodies": [{"kind": "obstacle", "geometry": {"type": "mesh", "file": str(tmp_path / "uv.obj")}}],
        "fluid": {"phases": 1},
    }
    scene = Scene.from_dict(d)
    dom = scene.domain
    assert (
        int((sdf_on_grid(scene.bodies[0].geometry.shape(dom, 0.25 * dom.dx), dom.resolution, dom.dx) < 0).sum()) == 512
    )
    (tmp_path / "dup.obj").write_text(_obj(_CUBE_F + _CUBE_F[:2]))
    d["bodies"][0]["geometry"]["file"] = str(tmp_path / "dup.obj")
    with pytest.raises(SceneError, match="2 triangles are given more than once"):
        Scene.from_dict(d)


def test_height_files_booleans_an_upper_case_csv_and_an_empty_file(tmp_path, recwarn):
    """A probe (session 25): a boolean .npy was read as heights of 0 and 1 m (then a build that hung), a .CSV
    (upper case) was read as whitespace-separated, and an empty file printed numpy's warning before the refusal."""
    from couplekit.scene.mesh import load_heights

    np.save(tmp_path / "mask.npy", np.ones((3, 4), bool))
    with pytest.raises(ValueError, match="booleans"):
        load_heights(tmp_path / "mask.npy")
    (tmp_path / "slope.CSV").write_text("0.1,0.2,0.3\n0.1,0.2,0.3\n")
    assert load_heights(tmp_path / "slope.CSV").shape == (2, 3)
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(ValueError, match="at least 2 rows"):
        load_heights(tmp_path / "empty.csv")
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]
