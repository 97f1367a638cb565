"""The command line: `couplekit validate`, `couplekit run` (outputs, refusals, Ctrl-C, --resume), `info` kept."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from couplekit.cli import main
from couplekit.io import read_diagnostics, read_pvd

ROOT = Path(__file__).resolve().parents[1]

TINY_SAND = """
[scene]
name = "tiny"

[domain]
size = [0.06, 0.06, 0.06]
dx = 0.005

[time]
dt = 2e-4
frame_duration = 1e-3
frames = {frames}

[sand]
density = 1500.0
youngs_modulus = 1e5

[[bodies]]
kind = "sand"
velocity = [0.0, 0.0, -0.5]
[bodies.geometry]
type = "box"
min = [0.02, 0.02, 0.03]
max = [0.04, 0.04, 0.045]

[outputs]
preview = {preview}
"""


def _scene(tmp_path: Path, frames: int = 2, preview: bool = False, name: str = "tiny.toml") -> Path:
    p = tmp_path / name
    p.write_text(TINY_SAND.format(frames=frames, preview="true" if preview else "false"))
    return p


def test_validate_valid_and_invalid(tmp_path, capsys):
    assert main(["validate", str(_scene(tmp_path))]) == 0
    assert "valid" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text(_scene(tmp_path).read_text().replace("dx = 0.005", "dx = -0.005\nspeed = 3"))
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "domain.dx" in err and "domain.speed" in err and "Fix:" in err


def test_validate_every_example():
    for path in sorted((ROOT / "examples").glob("*.toml")):
        assert main(["validate", str(path)]) == 0, path


def test_run_writes_frames(tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(["run", str(_scene(tmp_path, preview=True)), "--frames", "1", "--out", str(out), "--backend", "cpu"])
    assert rc == 0
    text = capsys.readouterr()
    assert "backend: cpu" in text.out and "memory estimate" in text.out
    assert "frame 1/1" in text.err  # the progress bar (one line per frame when not a terminal)
    assert [e[1] for e in read_pvd(out / "particles.pvd")] == ["particles_0000.vtp", "particles_0001.vtp"]
    assert (out / "preview_0001.png").exists() and (out / "checkpoint.h5").exists()
    assert len(read_diagnostics(out / "diagnostics.jsonl")) == 2


def test_run_set_changes_scene_keys_for_the_run(tmp_path, capsys):
    """--set KEY=VALUE (repeatable): dotted keys as in sweeps, TOML values (a bare word is a string); the
    changed scene is validated again and the run follows it (here: no VTK, a sand body twice as dense)."""
    out = tmp_path / "out"
    args = ["run", str(_scene(tmp_path)), "--frames", "1", "--out", str(out), "--backend", "numpy", "--no-progress"]
    rc = main([*args, "--set", "outputs.vtk=false", "--set", "sand.density=3000", "--set", "scene.name=renamed"])
    assert rc == 0, capsys.readouterr().err
    assert not list(out.glob("*.vtp")) and (out / "checkpoint.h5").exists()
    from couplekit.simulation import Simulation

    sim = Simulation.load(out / "checkpoint.h5", backend="numpy")
    assert sim.scene.sand.density == 3000.0 and sim.scene.name == "renamed" and sim.scene.outputs.vtk is False


@pytest.mark.parametrize(
    "setting, code, message",
    [
        ("outputs.vtkk=false", 2, "did you mean 'vtk'"),  # an unknown key: the nearest one named
        ("outputs.vtk", 2, "write KEY=VALUE"),  # no value
        ("=3", 2, "write KEY=VALUE"),  # no key
        ("outputs.vtk=3", 2, "outputs.vtk: must be true or false"),  # the scene's own validation
        ("bodies[5].density=900", 2, "beyond it"),  # an index past the list
        ("sand.density=-1", 2, "sand.density"),
    ],
)
def test_run_set_refuses_bad_settings_before_running(tmp_path, capsys, setting, code, message):
    out = tmp_path / "out"
    rc = main(["run", str(_scene(tmp_path)), "--out", str(out), "--backend", "numpy", "--set", setting])
    assert rc == code
    assert message in capsys.readouterr().err
    assert not out.exists()  # refused before the output folder was made


def test_run_set_cannot_change_a_resumed_run(tmp_path, capsys):
    rc = main(["run", str(_scene(tmp_path)), "--resume", str(tmp_path / "x.h5"), "--set", "time.frames=3"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "--set cannot change a resumed run" in err
    # the way on (a probe, session 25: a diverged run's last_good.h5 could only be resumed with the settings
    # that diverged, and the refusal said nothing more)
    assert f"couplekit run {_scene(tmp_path)} --set KEY=VALUE --out NEW_DIR" in err


def test_validate_set_checks_the_changed_scene(tmp_path, capsys):
    """validate --set: the scene as run --set would run it (a bad value refused with its key, exit 2)."""
    scene = str(_scene(tmp_path))
    assert main(["validate", scene, "--set", "sand.particles_per_cell=27"]) == 0
    assert main(["validate", scene, "--set", "sand.density=-3"]) == 2
    assert "sand.density" in capsys.readouterr().err
    assert main(["validate", scene, "--set", "sand.densty=3"]) == 2
    assert "did you mean 'density'" in capsys.readouterr().err


def test_parse_setting_reads_toml_values_and_bare_words():
    from couplekit.simulation import parse_setting

    assert parse_setting("time.frames=5") == ("time.frames", 5)
    assert parse_setting(" bodies[0].velocity = [0, 0, -1.5] ") == ("bodies[0].velocity", [0, 0, -1.5])
    assert parse_setting("fluid.storage=fp16") == ("fluid.storage", "fp16")
    assert parse_setting('scene.name="a b"') == ("scene.name", "a b")
    assert parse_setting("outputs.preview=false") == ("outputs.preview", False)


def test_run_refuses_what_the_coupler_cannot_do(tmp_path, capsys):
    text = _scene(tmp_path).read_text() + "\n[effects]\ndrag = false\n\n[fluid]\nphases = 2\n"
    p = tmp_path / "coupled.toml"
    p.write_text(text.replace("dt = 2e-4", "dt = 2e-5").replace("frame_duration = 1e-3", "frame_duration = 1e-4"))
    assert main(["run", str(p), "--out", str(tmp_path / "o"), "--backend", "cpu"]) == 3
    assert "effects.drag = false" in capsys.readouterr().err


def test_info_still_works(capsys):
    assert main(["info", "--backend", "numpy"]) == 0
    assert "backend: numpy" in capsys.readouterr().out


def _interrupted_run(scene: Path, out: Path, sig: int) -> tuple[int, str, str]:
    """``couplekit run scene --out out`` in a subprocess, sent ``sig`` a second after its first frame is logged:
    (exit code, stdout, stderr)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "couplekit", "run", str(scene), "--out", str(out), "--backend", "cpu"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )  # fmt: skip
    deadline = time.time() + 300  # a cold kernel cache compiles the sand kernels first
    while time.time() < deadline and not (out / "diagnostics.jsonl").exists():
        time.sleep(0.2)
    time.sleep(1.0)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=120)
    return proc.returncode, stdout, stderr


def test_ctrl_c_writes_checkpoint_and_resume_finishes(tmp_path):
    """SIGINT during a run: exit 130 with interrupted.h5; --resume from it completes the run."""
    scene = _scene(tmp_path, frames=400)
    out = tmp_path / "out"
    rc, stdout, stderr = _interrupted_run(scene, out, signal.SIGINT)
    assert rc == 130, stdout + stderr
    assert (out / "interrupted.h5").exists() and "--resume" in stdout
    rc = main(
        [
            "run",
            str(scene),
            "--frames",
            "2",
            "--out",
            str(out),
            "--backend",
            "cpu",
            "--resume",
            str(out / "interrupted.h5"),
            "--no-progress",
        ]
    )
    assert rc == 0


def test_sigterm_writes_checkpoint_and_resume_goes_on_in_the_same_folder(tmp_path, monkeypatch, capsys):
    """SIGTERM (batch schedulers, `timeout`) is an interrupt like Ctrl-C: exit 143 with interrupted.h5 and the
    hint; --resume without --out continues in the folder the checkpoint lies in (the run was started with
    --out), not in the scene's default folder."""
    scene = _scene(tmp_path, frames=400)
    out = tmp_path / "given"
    rc, stdout, stderr = _interrupted_run(scene, out, signal.SIGTERM)
    assert rc == 143, stdout + stderr
    assert (out / "interrupted.h5").exists() and f"--out {out}" in stdout and "SIGTERM" in stdout
    frames_before = len(list(out.glob("fields_*.vti")))
    monkeypatch.chdir(tmp_path)  # the default folder would be runs/<name> here
    frames = frames_before + 2  # frame files 0 .. frames
    rc = main(["run", str(scene), "--frames", str(frames), "--backend", "cpu", "--resume",
               str(out / "interrupted.h5"), "--no-progress"])  # fmt: skip
    assert rc == 0
    assert f"in {out}" in capsys.readouterr().out
    assert len(list(out.glob("fields_*.vti"))) == frames + 1 and not (tmp_path / "runs").exists()


def test_an_unusable_out_folder_is_an_error_not_a_traceback(tmp_path, capsys):
    """A folder name the file system cannot take (here too long): exit 2 and a message naming the fix."""
    assert main(["run", str(_scene(tmp_path)), "--out", str(tmp_path / ("a" * 300)), "--backend", "numpy"]) == 2
    err = capsys.readouterr().err
    assert "File name too long" in err and "another --out" in err


@pytest.mark.parametrize("name", ["sand_drop_small.toml"])
def test_demo_scene_loads(name):
    from couplekit.scene import Scene

    scene = Scene.load(ROOT / "examples" / name)
    assert scene.has_sand and not scene.has_fluid


def test_resume_takes_the_stored_scene_when_the_file_changed_or_is_gone(tmp_path, capsys, monkeypatch):
    """run --resume resumes the checkpoint's scene: the scene file may since have become invalid or been deleted
    (a note says so; it was refused with exit 2), and without --out the run continues in the stored scene's
    default folder, not in one named after whatever file was given (it wrote a fig16 run into
    runs/<other scene>)."""
    monkeypatch.chdir(tmp_path)
    scene = _scene(tmp_path, frames=3)
    assert main(["run", str(scene), "--frames", "1", "--no-progress", "--backend", "cpu"]) == 0
    ckpt = tmp_path / "runs" / "tiny" / "checkpoint.h5"
    assert ckpt.exists()
    scene.write_text(scene.read_text().replace("dt = 2e-4", "dt = -1"))  # edited: no longer valid
    assert main(["run", str(scene), "--frames", "2", "--resume", str(ckpt), "--no-progress", "--backend", "cpu"]) == 0
    out = capsys.readouterr().out
    assert "does not load" in out and "time.dt" in out and "resumed from" in out
    other = _scene(tmp_path, name="other.toml")
    other.write_text(other.read_text().replace('name = "tiny"', 'name = "other"'))
    scene.unlink()
    for path in (scene, other):  # gone, then another scene's file: the stored scene's folder either way
        assert main(["run", str(path), "--resume", str(ckpt), "--no-progress", "--backend", "cpu"]) == 0
    assert not (tmp_path / "runs" / "other").exists()
    assert [e[1] for e in read_pvd(tmp_path / "runs" / "tiny" / "particles.pvd")][-1] == "particles_0003.vtp"
