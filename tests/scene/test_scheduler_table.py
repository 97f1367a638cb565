"""The [scheduler] table: validated like every other table (unknown keys, bad values, impossible combinations,
the sand's step against its limits under each scheme, naming the key and the fix), the short specs of
``couplekit run --scheduler`` and ``Simulation(..., scheduler=...)``, and what the CLI does with them."""

from __future__ import annotations

import copy

import pytest
from couplekit.schedulers import spec_table
from sim_scenes import TINY_SAND_TOML, tiny_coupled, tiny_fluid, tiny_sand

from couplekit.cli import main
from couplekit.scene import Scene, SceneError
from couplekit.simulation import Simulation, with_scheduler


def _refused(d: dict, key: str, words: str) -> SceneError:
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    assert key in err.value.keys, f"expected a problem at {key!r}, got:\n{err.value}"
    p = next(p for p in err.value.problems if p.key == key)
    assert words in p.message or words in p.fix, str(err.value)
    assert p.fix
    return err.value


def _with(base, table: dict) -> dict:
    d = copy.deepcopy(base())
    d["scheduler"] = table
    return d


@pytest.mark.parametrize(
    ("table", "key", "words"),
    [
        ({"kind": "adaptive"}, "scheduler.kind", "one of"),
        ({"kind": "subcycled"}, "scheduler.kind", "did you mean 'subcycle'"),
        ({"kind": "subcycle", "substep": 4}, "scheduler.substep", "did you mean 'substeps'"),
        ({"kind": "subcycle", "substeps": 0}, "scheduler.substeps", ">= 1"),
        ({"kind": "subcycle", "substeps": "fast"}, "scheduler.substeps", 'or "auto"'),
        ({"kind": "subcycle", "substeps": 2.5}, "scheduler.substeps", "integer"),
        ({"kind": "subcycle", "substeps": True}, "scheduler.substeps", "integer"),
        ({"kind": "subcycle", "interpolation": "cubic"}, "scheduler.interpolation", "one of"),
        ({"kind": "subcycle", "max_substeps": 0}, "scheduler.max_substeps", ">= 1"),
        ({"kind": "multirate"}, "scheduler.sand_every", "required with kind = 'multirate'"),
        ({"kind": "multirate", "sand_every": 0}, "scheduler.sand_every", ">= 1"),
        ({"kind": "multirate", "sand_every": 2, "substeps": 2}, "scheduler.substeps", "only to kind = 'subcycle'"),
        ({"kind": "subcycle", "sand_every": 2}, "scheduler.sand_every", "only to kind = 'multirate'"),
        ({"interpolation": "linear"}, "scheduler.interpolation", "set scheduler.kind = 'subcycle'"),
        ({"kind": "lockstep", "substeps": 1}, "scheduler.substeps", "remove scheduler.substeps"),
    ],
    ids=lambda v: str(v)[:40],
)
def test_malformed_scheduler_tables_are_refused(table, key, words):
    _refused(_with(tiny_coupled, table), key, words)


def test_a_scene_without_sand_takes_only_lockstep():
    _refused(_with(tiny_fluid, {"kind": "subcycle", "substeps": 2}), "scheduler.kind", "no sand")
    Scene.from_dict(_with(tiny_fluid, {"kind": "lockstep"}))


def test_the_sand_step_is_checked_under_each_scheme():
    """tiny_sand at dt = 1e-3 s breaks the elastic limit (2.64e-4 s): lockstep names time.dt; subcycle names
    scheduler.substeps with the smallest k that works (4), which then validates; auto names max_substeps
    when the cap is below 4; multirate at a valid dt names sand_every with the largest m that works."""
    d = tiny_sand()
    d["time"]["dt"] = 1e-3
    _refused(copy.deepcopy(d), "time.dt", "subcycle")
    d["scheduler"] = {"kind": "subcycle", "substeps": 3}
    _refused(copy.deepcopy(d), "scheduler.substeps", "substeps >= 4")
    d["scheduler"]["substeps"] = 4
    assert Scene.from_dict(copy.deepcopy(d)).scheduler.substeps == 4
    d["scheduler"] = {"kind": "subcycle", "substeps": "auto", "max_substeps": 3}
    _refused(copy.deepcopy(d), "scheduler.max_substeps", "max_substeps to >= 4")
    d["scheduler"]["max_substeps"] = 4
    Scene.from_dict(copy.deepcopy(d))
    d = tiny_sand()  # dt = 2e-4: one step fits, two do not
    d["scheduler"] = {"kind": "multirate", "sand_every": 2}
    _refused(d, "scheduler.sand_every", "sand_every <= 1")


@pytest.mark.parametrize(
    ("spec", "table"),
    [
        ("lockstep", {"kind": "lockstep"}),
        ("subcycle", {"kind": "subcycle"}),
        ("subcycle:8", {"kind": "subcycle", "substeps": 8}),
        ("subcycle:auto", {"kind": "subcycle", "substeps": "auto"}),
        ("subcycle:3:linear", {"kind": "subcycle", "substeps": 3, "interpolation": "linear"}),
        ("multirate:4", {"kind": "multirate", "sand_every": 4}),
    ],
)
def test_scheduler_specs(spec, table):
    assert spec_table(spec) == table


@pytest.mark.parametrize(
    "spec",
    ["sub", "subcycle:0", "subcycle:x", "subcycle:2:cubic", "multirate", "lockstep:2", "subcycle:²", "multirate:٣"],
)
def test_bad_scheduler_specs_say_what_works(spec):
    with pytest.raises(ValueError, match="subcycle|whole number|interpolation|multirate|lockstep"):
        spec_table(spec)


@pytest.mark.parametrize("spec", ["multirate:2:linear", "multirate:2:3", "subcycle:2:linear:x"])
def test_a_spec_with_parts_too_many_says_so(spec):
    """A probe (session 25): multirate:2:linear was told that multirate needs the LBM steps per MPM step."""
    with pytest.raises(ValueError, match="too many parts"):
        spec_table(spec)


def test_a_fixed_count_above_its_cap_and_linear_data_without_fluid_are_refused():
    """max_substeps below a fixed substeps count was silently ignored (the cap applies to 'auto'), and 'linear'
    fluid data was accepted on a scene without a fluid: both now name the key and the fix."""
    d = tiny_coupled()
    d["scheduler"] = {"kind": "subcycle", "substeps": 10, "max_substeps": 2}
    _refused(d, "scheduler.max_substeps", "substeps = 'auto'")
    d["scheduler"] = {"kind": "subcycle", "substeps": 2, "max_substeps": 2}
    Scene.from_dict(d)  # equal is fine
    s = tiny_sand()
    s["scheduler"] = {"kind": "subcycle", "substeps": 2, "interpolation": "linear"}
    _refused(s, "scheduler.interpolation", "'hold'")


def test_simulation_takes_a_scheduler_and_validates_it():
    sim = Simulation(Scene.from_dict(tiny_coupled()), backend="cpu", log=None, scheduler="subcycle:2")
    assert sim.scheduler.kind == "subcycle" and sim.scheduler.substeps == 2
    assert sim.scene.scheduler.kind == "subcycle"  # what a checkpoint keeps
    with pytest.raises(SceneError, match="scheduler.kind"):
        with_scheduler(Scene.from_dict(tiny_fluid()), {"kind": "multirate", "sand_every": 2})


def test_cli_run_with_a_scheduler(tmp_path, capsys):
    """`couplekit run --scheduler subcycle:2` runs the scene sub-cycled (the cost summary names it) and keeps
    the scheduler in the checkpoint; a bad spec exits 2 naming what works; --scheduler with --resume is
    refused (the checkpoint keeps its own scheduler)."""
    path = tmp_path / "scene.toml"
    path.write_text(TINY_SAND_TOML)
    assert main(["run", str(path), "--out", str(tmp_path / "run"), "--no-progress", "--scheduler", "subcycle:2"]) == 0
    out = capsys.readouterr().out
    assert "subcycle" in out and "sand steps per step" in out
    resumed = Simulation.load(tmp_path / "run" / "checkpoint.h5", backend="cpu", log=None)
    assert resumed.scheduler.kind == "subcycle" and resumed.scheduler.substeps == 2
    assert main(["run", str(path), "--out", str(tmp_path / "bad"), "--no-progress", "--scheduler", "fast"]) == 2
    assert "subcycle[:K|auto]" in capsys.readouterr().err
    ckpt = str(tmp_path / "run" / "checkpoint.h5")
    assert main(["run", str(path), "--resume", ckpt, "--no-progress", "--scheduler", "lockstep"]) == 2
