"""Faults in checkpoints, states and output folders are refused with a message naming the file and the defect,
before anything is computed; a used output folder is never silently mixed with another run."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from couplekit.cli import main
from couplekit.io import CheckpointError, load_checkpoint
from couplekit.io.checkpoint import dataset_checksum
from couplekit.io.outputs import OutputFolderError, default_output, prepare_output, run_files
from couplekit.lattice import W27
from couplekit.scene import Scene
from couplekit.simulation import Simulation

sys.path.insert(0, str(Path(__file__).parents[1] / "scene"))
from sim_scenes import TINY_SAND_TOML, tiny_coupled, tiny_sand  # noqa: E402


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    """A coupled checkpoint after 3 steps (fluid, sand, coupler groups)."""
    sim = Simulation(Scene.from_dict(tiny_coupled()), backend="cpu", threads=1, log=None)
    sim.step(3)
    return sim.save(tmp_path_factory.mktemp("ckpt") / "c.h5")


def _copy(src: Path, dst: Path) -> Path:
    dst.write_bytes(src.read_bytes())
    return dst


def _refused(path: Path, *words: str) -> CheckpointError:
    with pytest.raises(CheckpointError) as err:
        Simulation.load(path, backend="cpu", threads=1, log=None)
    text = str(err.value)
    assert str(path) in text and all(w in text for w in words), text
    return err.value


# ------------------------------------------------------------------ checkpoints
def test_an_intact_checkpoint_verifies_and_restarts(checkpoint):
    scene, states, meta = load_checkpoint(checkpoint)
    assert meta["step"] == 3 and {"fluid", "sand", "coupler"} <= set(states)
    assert Simulation.load(checkpoint, backend="cpu", threads=1, log=None).step_count == 3


def test_flipped_bytes_inside_a_dataset_are_caught(checkpoint, tmp_path):
    """A single changed float in the populations (written back through h5py, as a disk error or a careless edit
    would leave it) no longer matches the dataset's checksum."""
    path = _copy(checkpoint, tmp_path / "flipped.h5")
    with h5py.File(path, "r+") as f:
        ds = f["fluid"]["f"]
        a = ds[()]
        a.reshape(-1)[1234] = np.nextafter(a.reshape(-1)[1234], np.float32(1.0))
        ds[...] = a
    _refused(path, "fluid/f", "checksum")


def test_a_missing_dataset_is_named(checkpoint, tmp_path):
    path = _copy(checkpoint, tmp_path / "missing.h5")
    with h5py.File(path, "r+") as f:
        del f["sand"]["x"]
    _refused(path, "does not fit", "x")
    path = _copy(checkpoint, tmp_path / "no_coupler.h5")
    with h5py.File(path, "r+") as f:
        del f["coupler"]
    _refused(path, "coupler")


@pytest.mark.parametrize("attr", ["scene", "meta"])
def test_missing_or_changed_scene_and_metadata(checkpoint, tmp_path, attr):
    path = _copy(checkpoint, tmp_path / f"no_{attr}.h5")
    with h5py.File(path, "r+") as f:
        del f.attrs[attr]
    _refused(path, f"no {attr!r} attribute")
    path = _copy(checkpoint, tmp_path / f"changed_{attr}.h5")
    with h5py.File(path, "r+") as f:
        f.attrs[attr] = "{not json"
    _refused(path, "changed after")


def test_metadata_that_is_not_json_is_named_in_an_unchecksummed_file(checkpoint, tmp_path):
    """A version-1 checkpoint (no checksums, before this session) still loads; its metadata is still parsed
    with a message naming the file."""
    path = _copy(checkpoint, tmp_path / "v1.h5")
    with h5py.File(path, "r+") as f:
        f.attrs["version"] = 1
        del f.attrs["checksum"]
        full = f["fluid"]["f"][()].astype(np.float64) + W27.reshape(27, 1, 1, 1)  # versions 1, 2: full f
        del f["fluid"]["f"]
        f["fluid"].create_dataset("f", data=full.astype(np.float32))
    assert Simulation.load(path, backend="cpu", threads=1, log=None).step_count == 3
    with h5py.File(path, "r+") as f:
        f.attrs["meta"] = "[1, 2"
    _refused(path, "metadata is not valid JSON")


def _as_version_2(src: Path, dst: Path) -> Path:
    """The checkpoint as version 2 wrote it: full populations f in ``fluid/f`` (now f − w), checksummed."""
    path = _copy(src, dst)
    with h5py.File(path, "r+") as f:
        f.attrs["version"] = 2
        full = (f["fluid"]["f"][()].astype(np.float64) + W27.reshape(27, 1, 1, 1)).astype(np.float32)
        del f["fluid"]["f"]
        ds = f["fluid"].create_dataset("f", data=full)
        ds.attrs["sha256"] = dataset_checksum(full)
    return path


def test_a_version_2_checkpoint_with_full_populations_still_restarts(checkpoint, tmp_path):
    """Shifted storage (checkpoint version 3): a version-2 file's full f is converted to f − w on load, and the
    run continues as the one restarted from the version-3 file, to float32 round-off of the conversion
    (f rounded at ~6e-8 of w, once)."""
    path = _as_version_2(checkpoint, tmp_path / "v2.h5")
    _, states, _ = load_checkpoint(path)
    _, states3, _ = load_checkpoint(checkpoint)
    np.testing.assert_allclose(states["fluid"]["f"], states3["fluid"]["f"], rtol=0, atol=1e-7)
    assert np.abs(states3["fluid"]["f"]).max() < 0.1  # the version-3 file holds f - w (|f - w| << w)
    old, new = (Simulation.load(p, backend="cpu", threads=1, log=None) for p in (path, checkpoint))
    assert old.step_count == new.step_count == 3
    old.step(3)
    new.step(3)
    u_old, u_new = (s.fluid.fields()["velocity"] for s in (old, new))
    assert np.abs(u_new).max() > 1e-5  # the fluid moves, so the comparison means something
    np.testing.assert_allclose(u_old, u_new, rtol=0, atol=1e-6)


def test_files_that_are_not_checkpoints(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(os.urandom(4096))
    _refused(junk, "not a readable HDF5 file")
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.create_dataset("x", data=np.zeros(3))
    _refused(other, "not a couplekit checkpoint")


@pytest.mark.parametrize(
    ("group", "name", "index"), [("fluid", "f", (5, 3, 3, 3)), ("sand", "x", (2, 7)), ("sand", "v", (0, 1))]
)
def test_a_state_holding_nan_is_refused_before_it_runs(checkpoint, tmp_path, group, name, index):
    """NaN in the populations or in one particle's position or velocity (a position is what the scatter kernels
    index memory with): the restart is refused, naming the field, before any step."""
    scene, states, meta = load_checkpoint(checkpoint)
    states[group][name][index] = np.nan
    from couplekit.io import save_checkpoint

    path = save_checkpoint(tmp_path / f"nan_{group}_{name}.h5", scene, states, meta)
    _refused(path, "non-finite", repr(name))


def test_a_cli_resume_from_a_bad_checkpoint_exits_2(checkpoint, tmp_path, capsys):
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(TINY_SAND_TOML)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"nope")
    assert main(["run", str(scene_file), "--resume", str(junk), "--out", str(tmp_path / "r"), "--no-progress"]) == 2
    assert "not a readable HDF5 file" in capsys.readouterr().err


# ------------------------------------------------------------------ output folders
def test_output_folder_under_a_file_or_a_file_itself(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    with pytest.raises(OutputFolderError, match="is a file, not a folder"):
        prepare_output(f / "run")
    with pytest.raises(OutputFolderError, match="is a file; choose another --out"):
        prepare_output(f)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_output_folder_that_cannot_be_written(tmp_path):  # pragma: no cover - CI runs as root
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(OutputFolderError, match="cannot"):
            prepare_output(ro / "run")
    finally:
        ro.chmod(0o700)


def test_a_used_folder_is_refused_resumed_or_overwritten(tmp_path):
    """A second run into a used folder is refused (naming the checkpoint to resume from and --overwrite); a run
    resumed from that folder's checkpoint appends to it; overwrite deletes the earlier run's files and only
    them."""
    d = tiny_sand(frames=2)
    out = tmp_path / "run"
    first = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    assert first.run(out=out, progress=False).status == "done"
    assert any(p.name == "checkpoint.h5" for p in run_files(out))
    (out / "notes.txt").write_text("mine")
    second = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    with pytest.raises(OutputFolderError, match=r"earlier run .*--resume .*checkpoint.h5.*--overwrite"):
        second.run(out=out, progress=False)
    resumed = Simulation.load(out / "checkpoint.h5", backend="cpu", threads=1, log=None)
    assert resumed.run(frames=3, out=out, progress=False).status == "done"
    lines = (out / "diagnostics.jsonl").read_text().splitlines()
    assert len(lines) == 4  # frames 0, 1, 2 of the first run and frame 3 of the resumed one
    before = {p.name for p in run_files(out)}
    prepare_output(out, overwrite=True)
    assert run_files(out) == [] and (out / "notes.txt").read_text() == "mine" and "checkpoint.h5" in before


def test_the_used_folders_hint_names_the_newer_checkpoint(tmp_path):
    """A probe (session 24): a run resumed from interrupted.h5 and finished leaves it beside a later
    checkpoint.h5; the refusal of a second run into the folder named the stale interrupted.h5 to resume from."""
    import os

    out = tmp_path / "run"
    out.mkdir()
    (out / "checkpoint.h5").write_bytes(b"new")
    (out / "interrupted.h5").write_bytes(b"old")
    os.utime(out / "interrupted.h5", ns=(1_000_000_000, 1_000_000_000))
    with pytest.raises(OutputFolderError, match=r"--resume \S*checkpoint.h5"):
        prepare_output(out)
    os.utime(out / "checkpoint.h5", ns=(500_000_000, 500_000_000))
    with pytest.raises(OutputFolderError, match=r"--resume \S*interrupted.h5"):
        prepare_output(out)


def test_a_run_resumed_from_a_checkpoint_of_step_0_appends(tmp_path):
    """Ctrl-C before the first step leaves interrupted.h5 of step 0 beside the run's diagnostics: resuming it is
    a resume (found when a slow machine interrupted the CLI test before its first step)."""
    d = tiny_sand(frames=2)
    out = tmp_path / "run"
    first = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    assert first.run(out=out, progress=False, stop=lambda: True).status == "interrupted"
    assert first.step_count == 0 and (out / "interrupted.h5").exists()
    resumed = Simulation.load(out / "interrupted.h5", backend="cpu", threads=1, log=None)
    assert resumed.step_count == 0
    assert resumed.run(frames=1, out=out, progress=False).status == "done"
    fresh = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    with pytest.raises(OutputFolderError):  # a fresh run is still refused there
        fresh.run(out=out, progress=False)


def test_a_finished_run_keeps_an_interrupt_it_did_not_pass(tmp_path):
    """A finished run removes the folder's interrupted.h5 only when its own checkpoint is at or past that step
    (tests/scene/test_simulation.py checks the removal): a state further on, or a file it cannot read, is kept."""
    d = tiny_sand(frames=3)
    out = tmp_path / "run"
    sim = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    assert sim.run(frames=1, out=out, progress=False).status == "done"
    early = Simulation.load(out / "checkpoint.h5", backend="cpu", threads=1, log=None)  # frame 1
    ahead = Simulation.load(out / "checkpoint.h5", backend="cpu", threads=1, log=None)
    ahead.step(3 * ahead.steps_per_frame)
    ahead.save(out / "interrupted.h5")  # as if stopped at frame 4 of a longer run
    assert early.run(frames=2, out=out, progress=False).status == "done"
    assert (out / "interrupted.h5").exists()  # step 20 > the finished run's 10: kept
    (out / "interrupted.h5").write_bytes(b"not a checkpoint")
    again = Simulation.load(out / "checkpoint.h5", backend="cpu", threads=1, log=None)
    assert again.run(frames=3, out=out, progress=False).status == "done"
    assert (out / "interrupted.h5").read_bytes() == b"not a checkpoint"


@pytest.mark.parametrize("name", ["../../x", "a/b", "..", ""])
def test_scene_names_cannot_escape_runs(name):
    with pytest.raises(OutputFolderError, match="not a plain folder name"):
        default_output(name)
    assert default_output("ok_name-1.5") == Path("runs") / "ok_name-1.5"


def test_cli_refuses_a_used_folder_before_building_and_overwrites_on_request(tmp_path, capsys, monkeypatch):
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(TINY_SAND_TOML)
    out = tmp_path / "out"
    assert main(["run", str(scene_file), "--out", str(out), "--no-progress"]) == 0
    built = []
    monkeypatch.setattr(
        Simulation, "__init__", lambda *a, **k: built.append(1) or (_ for _ in ()).throw(AssertionError)
    )
    assert main(["run", str(scene_file), "--out", str(out), "--no-progress"]) == 2
    assert "holds the outputs of an earlier run" in capsys.readouterr().err and not built  # refused before building
    monkeypatch.undo()
    assert main(["run", str(scene_file), "--out", str(out), "--no-progress", "--overwrite"]) == 0


def test_a_resume_from_an_earlier_frame_does_not_silently_replace_later_ones(tmp_path):
    """A probe (session 25): resuming a frame-1 checkpoint into a folder whose run had reached frame 3 cut its log
    back to frame 2, overwrote the frame-3 checkpoint and left frame 3's files indexed by nothing, unasked. It is
    refused now, naming the frames; ``overwrite`` replaces them (frame 3's files deleted, the log cut)."""
    import shutil

    d = tiny_sand(frames=3)
    d["outputs"] = {"checkpoint_every": 1, "preview": False}
    out = tmp_path / "run"
    first = Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)
    assert first.run(frames=1, out=out, progress=False).status == "done"
    shutil.copy(out / "checkpoint.h5", tmp_path / "frame1.h5")
    later = Simulation.load(out / "checkpoint.h5", backend="cpu", threads=1, log=None)
    assert later.run(out=out, progress=False).status == "done"  # frames 2 and 3
    assert (out / "fields_0003.vti").exists() or (out / "particles_0003.vtp").exists()
    before = (out / "diagnostics.jsonl").read_text()
    again = Simulation.load(tmp_path / "frame1.h5", backend="cpu", threads=1, log=None)
    with pytest.raises(OutputFolderError, match=r"frames up to 3, beyond frame 1.*--overwrite"):
        again.run(frames=2, out=out, progress=False)
    assert (out / "diagnostics.jsonl").read_text() == before  # nothing touched
    assert again.run(frames=2, out=out, progress=False, overwrite=True).status == "done"
    assert not list(out.glob("*_0003.*"))
    frames = [json.loads(line)["frame"] for line in (out / "diagnostics.jsonl").read_text().splitlines()]
    assert frames == [0, 1, 2]


def test_save_never_replaces_a_file_that_is_not_a_checkpoint(tmp_path):
    """A probe (session 25): sim.save("scene.toml") replaced the user's scene file with a checkpoint. A checkpoint
    replaces an earlier checkpoint (a run's checkpoint.h5 every few frames), never another file."""
    sim = Simulation(Scene.from_dict(tiny_sand()), backend="cpu", threads=1, log=None)
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(TINY_SAND_TOML)
    with pytest.raises(CheckpointError, match="not a couplekit checkpoint: saving would replace it"):
        sim.save(scene_file)
    assert scene_file.read_text() == TINY_SAND_TOML
    sim.save(tmp_path / "a.h5")
    sim.step(1)
    sim.save(tmp_path / "a.h5")  # an earlier checkpoint is replaced
    assert Simulation.load(tmp_path / "a.h5", backend="cpu", threads=1, log=None).step_count == 1


def test_load_names_a_missing_file_a_folder_and_a_non_path(tmp_path):
    """A probe (session 25): a missing file was "not a readable HDF5 file (... errno = 2 ...)", and load(None)
    raised from inside h5py."""
    with pytest.raises(CheckpointError, match="no such file"):
        Simulation.load(tmp_path / "missing.h5", backend="cpu", log=None)
    with pytest.raises(CheckpointError, match="is a folder"):
        Simulation.load(tmp_path, backend="cpu", log=None)
    with pytest.raises(TypeError, match="path must be a checkpoint file's path"):
        Simulation.load(None, backend="cpu", log=None)
