"""Arguments of the Python API that are not what they should be are refused with a message naming them:
step counts and frame counts that are not whole numbers ≥ 0 (a negative count once moved the step and the time
backwards, and the outputs after it carried the wrong time), a backend that is not a name, and
``with_settings`` takes a scene file's path as ``Simulation`` does."""

from __future__ import annotations

import numpy as np
import pytest

import couplekit as ck
from couplekit.simulation import with_settings

SCENE = "examples/sand_drop_small.toml"


@pytest.fixture(scope="module")
def sim():
    return ck.Simulation(ck.Scene.load(SCENE), "cpu", log=None)


@pytest.mark.parametrize(
    ("n", "error", "match"),
    [
        (-1, ValueError, "n must be 0 or more"),
        (2.5, ValueError, "n must be a whole number"),
        ("3", TypeError, "n must be a whole number of steps"),
        (True, TypeError, "n must be a whole number of steps"),
        (None, TypeError, "n must be a whole number of steps"),
        (float("nan"), ValueError, "n must be a whole number"),
    ],
)
def test_step_refuses_what_is_not_a_count(sim, n, error, match):
    before = (sim.step_count, sim.time)
    with pytest.raises(error, match=match):
        sim.step(n)
    assert (sim.step_count, sim.time) == before


def test_step_takes_whole_numbers_of_any_kind(sim):
    start = sim.step_count
    sim.step(0)
    sim.step(np.int64(2))
    sim.step(1.0)
    assert sim.step_count == start + 3


def test_run_refuses_a_fractional_frame_count(sim, tmp_path):
    with pytest.raises(ValueError, match="frames must be a whole number"):
        sim.run(frames=1.5, out=tmp_path / "r", progress=False)
    assert not (tmp_path / "r").exists() or not any((tmp_path / "r").iterdir())


def test_a_backend_that_is_not_a_name_is_named():
    with pytest.raises(TypeError, match=r"backend must be a name .*'cpu'.* got 3"):
        ck.Simulation(ck.Scene.load(SCENE), 3, log=None)


def test_with_settings_takes_a_scene_file():
    scene = with_settings(SCENE, {"time.frames": 3})
    assert scene.time.frames == 3
    assert scene.to_dict() == with_settings(ck.Scene.load(SCENE), {"time.frames": 3}).to_dict()
    with pytest.raises(TypeError, match="scene must be a Scene or a scene file's path, got int"):
        with_settings(3, {"time.frames": 3})


# ---------------------------------------------------------------------------- found by a probe (session 22)
def test_save_refuses_what_it_would_replace_that_is_not_a_file(sim, tmp_path):
    """save() writes a temporary file and moves it over the path: a FIFO (or, as root, /dev/null) or a symbolic
    link became a regular file. Refused, as is a folder that does not exist (an h5py error about '.tmp')."""
    import os

    from couplekit.io import CheckpointError

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(CheckpointError, match="not a regular file"):
        sim.save(fifo)
    assert fifo.is_fifo()
    target = tmp_path / "real.h5"
    sim.save(target)
    link = tmp_path / "link.h5"
    link.symlink_to(target)
    with pytest.raises(CheckpointError, match="symbolic link"):
        sim.save(link)
    assert link.is_symlink()
    with pytest.raises(CheckpointError, match="does not exist; create it first"):
        sim.save(tmp_path / "missing" / "c.h5")
    sim.save(target)  # a regular file is replaced, as before
    with pytest.raises(TypeError, match="path must be a file path .* got int"):  # a probe (session 24): pathlib's
        sim.save(5)  # own message named no argument


def test_ctrl_c_while_a_command_loads_is_a_message(monkeypatch, capsys):
    """A probe (session 24): Ctrl-C in the first second of ``couplekit run`` (while its modules load, before the
    command's own handler) printed a KeyboardInterrupt traceback; now a message and exit 130."""
    from couplekit import cli

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_cmd_run", interrupted)
    assert cli.main(["run", str(SCENE)]) == 130
    assert capsys.readouterr().err.startswith("interrupted before the command started")


def test_a_validated_scene_cannot_be_changed_in_place(sim):
    """domain.boundary and sand.walls were plain dicts of the frozen Scene: changing one built and ran a scene its
    to_dict() (and checkpoints) did not describe. Refused; pickling and the to_dict round trip still hold."""
    import copy
    import pickle

    scene = sim.scene
    with pytest.raises(TypeError, match="cannot be changed in place"):
        scene.domain.boundary["x_min"] = "wall"
    with pytest.raises(TypeError, match="cannot be changed in place"):
        scene.domain.boundary.update({"x_min": "wall"})
    if scene.sand is not None:
        with pytest.raises(TypeError):
            scene.sand.walls["z_min"] = "slip"
    # scene.source, the record to_dict() and checkpoints give, is read-only to its leaves (a probe, session 25:
    # changing its time.dt in place made a checkpoint restore another scene than the one that ran)
    with pytest.raises(TypeError, match="cannot be changed in place"):
        scene.source["time"]["dt"] = 5e-4
    with pytest.raises(TypeError, match="cannot be changed in place"):
        scene.source["bodies"].append({})
    assert type(scene.to_dict()["bodies"]) is list and type(scene.to_dict()["time"]) is dict  # plain copies
    with pytest.raises(TypeError, match="cannot be changed in place"):  # a body's geometry too
        scene.bodies[0].geometry.params["center"][0] = 1.0
    assert hash(scene) == hash(ck.Scene.from_dict(scene.to_dict()))  # a frozen scene hashes (it raised)
    assert pickle.loads(pickle.dumps(scene)) == scene == copy.deepcopy(scene)
    assert ck.Scene.from_dict(scene.to_dict()) == scene
    changed = with_settings(scene, {"sand.walls.z_min.kind": "slip"})  # the way to change one
    assert changed.sand.walls["z_min"].kind == "slip" and scene.sand.walls["z_min"].kind == "separate"


@pytest.mark.parametrize("value", ["no", 1, None])
def test_fields_lattice_must_be_a_bool(sim, value):
    """fields(lattice="no") returned lattice units: any non-empty string is true."""
    with pytest.raises(TypeError, match="lattice must be True or False"):
        sim.fields(lattice=value)
    assert sim.fields(lattice=np.bool_(False)).keys() == sim.fields().keys()


@pytest.mark.parametrize("threads", [1.5, "x", True, 0])
def test_threads_must_be_a_whole_number(threads):
    """threads=1.5 became 1 and 'x' raised int()'s message."""
    from couplekit.backend import get_backend

    with pytest.raises(ValueError, match="threads must be a whole number >= 1"):
        get_backend("numpy", threads=threads)


def test_an_empty_backend_name_is_refused():
    """backend='' silently meant auto."""
    from couplekit.backend import get_backend

    with pytest.raises(ValueError, match="empty name"):
        get_backend("")


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (
            lambda sim, tmp: sim.run(frames=1, out=tmp, overwrite="no", progress=False),
            "overwrite must be True or False",
        ),
        (lambda sim, tmp: sim.run(frames=1, out=tmp, progress="no"), "progress must be True or False"),
        (lambda sim, tmp: sim.run(frames=1, out=tmp, progress=False, summary=1), "summary must be True or False"),
        (lambda sim, tmp: sim.run(frames=1, out=tmp, progress=False, stop=True), "stop must be a function"),
        (lambda sim, tmp: sim.run(frames=1, out=tmp, progress=False, stream=123), "stream must be a text stream"),
        (lambda sim, tmp: sim.run(frames=1, out=123, progress=False), "out must be a folder path"),
        (lambda sim, tmp: sim.cost_summary(top=1.5), "top must be a whole number"),
        (lambda sim, tmp: sim.cost_summary(top=0), "top must be 1 or more"),
    ],
)
def test_run_and_report_arguments_are_checked_before_anything_is_written(sim, tmp_path, call, match):
    """A probe (session 25): overwrite="no" (a true string) deleted an earlier run's frames; stop=True, stream=123
    and out=123 failed deep inside (stop after the run marker was written); cost_summary(top=1.5) failed on a
    slice. Each is refused naming the argument, and the folder is left as it was."""
    with pytest.raises((TypeError, ValueError), match=match):
        call(sim, tmp_path / "run")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("kw", "match"),
    [({"log": 123}, "log must be a function"), ({"timing": "no"}, "timing must be True or False"),
     ({"check_memory": "no"}, "check_memory must be True or False")],
)  # fmt: skip
def test_simulation_arguments_are_checked(kw, match):
    with pytest.raises(TypeError, match=match):
        ck.Simulation(ck.Scene.load(SCENE), "cpu", **{"log": None, **kw})


def test_from_dict_takes_tuples_and_numpy_values():
    """A probe (session 25): a tuple or NumPy-array ``size`` and an ``np.int64`` frame count were refused by
    Scene.from_dict while step() and run() take NumPy numbers; they are TOML's lists and numbers now. A float for an
    integer key is still refused (TOML would not make one)."""
    plain = ck.Scene.load(SCENE)
    d = plain.to_dict()
    d["domain"]["size"] = np.array(d["domain"]["size"])
    d["time"]["frames"] = np.int64(d["time"]["frames"])
    d["bodies"][0]["geometry"] = {
        k: tuple(v) if isinstance(v, list) else v for k, v in d["bodies"][0]["geometry"].items()
    }
    scene = ck.Scene.from_dict(d)
    assert scene == plain and scene.to_dict() == plain.to_dict()
    d["time"]["frames"] = 2.0
    with pytest.raises(ck.SceneError, match="time.frames"):
        ck.Scene.from_dict(d)
    with pytest.raises(TypeError, match="base_dir must be a folder path"):
        ck.Scene.from_dict(plain.to_dict(), base_dir=None)
