"""What a careless or hostile user can hand couplekit, found by fuzzing the CLI and the API (session 16): each is
refused with a message naming the key or file and the fix, or handled, never a traceback, and no run's files
are lost or mixed with another's."""

from __future__ import annotations

import errno
import os
import sys
import types
from pathlib import Path

import pytest

from couplekit.cli import main
from couplekit.io import CheckpointError, read_diagnostics
from couplekit.io.outputs import run_files
from couplekit.scene import Scene, SceneError
from couplekit.simulation import Simulation, parse_setting, with_settings

sys.path.insert(0, str(Path(__file__).parent / "scene"))
from sim_scenes import TINY_SAND_TOML, tiny_fluid, tiny_sand  # noqa: E402


def _toml(tmp_path: Path, text: str = TINY_SAND_TOML, name: str = "scene.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _fluid_toml(tmp_path: Path, name: str = "fluid.toml") -> Path:
    """tiny_fluid as a TOML file (written through the scene's own dict)."""
    scene = Scene.from_dict(tiny_fluid(frames=3))
    return _write_scene(tmp_path / name, scene.to_dict())


def _write_scene(path: Path, data: dict) -> Path:
    """A TOML file of a scene dict (tables, arrays of tables, scalars and lists)."""

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + "}"
        return repr(v)

    lines = []
    for table, content in data.items():
        if isinstance(content, list) and content and all(isinstance(x, dict) for x in content):
            for entry in content:
                lines.append(f"[[{table}]]")
                lines += [f"{k} = {value(x)}" for k, x in entry.items()]
        elif isinstance(content, dict):
            lines.append(f"[{table}]")
            lines += [f"{k} = {value(x)}" for k, x in content.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


# ------------------------------------------------------------------------------------------ output folders
def test_resume_into_another_scenes_folder_is_refused_and_leaves_it_as_it_was(tmp_path, capsys):
    """Fuzz finding: --resume wrote one scene's frames into another run's folder (exit 0)."""
    a, b = _toml(tmp_path, name="a.toml"), _fluid_toml(tmp_path, "b.toml")
    common = ["--backend", "numpy", "--no-progress"]
    assert main(["run", str(a), "--out", str(tmp_path / "A"), "--frames", "1", *common]) == 0
    assert main(["run", str(b), "--out", str(tmp_path / "B"), "--frames", "1", *common]) == 0
    before = {p.name: p.read_bytes() for p in run_files(tmp_path / "B")}
    capsys.readouterr()
    rc = main(["run", str(b), "--resume", str(tmp_path / "A" / "checkpoint.h5"), "--out", str(tmp_path / "B"), *common])
    assert rc == 2
    assert "holds the outputs of another run" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in run_files(tmp_path / "B")} == before
    # its own folder resumes as before
    assert main(["run", str(a), "--resume", str(tmp_path / "A" / "checkpoint.h5"), "--frames", "2",
                 "--out", str(tmp_path / "A"), *common]) == 0  # fmt: skip
    assert [r["frame"] for r in read_diagnostics(tmp_path / "A" / "diagnostics.jsonl")] == [0, 1, 2]


def test_overwrite_deletes_only_numbered_frame_files(tmp_path):
    """Fuzz finding: --overwrite deleted a user's mesh named surface_scan.obj (it matched surface_*.obj)."""
    out = tmp_path / "out"
    common = ["--backend", "numpy", "--no-progress", "--frames", "1", "--out", str(out)]
    assert main(["run", str(_toml(tmp_path)), *common]) == 0
    (out / "surface_scan.obj").write_text("v 0 0 0\n")
    (out / "preview_final.png").write_bytes(b"mine")
    assert main(["run", str(_toml(tmp_path)), *common, "--overwrite"]) == 0
    assert (out / "surface_scan.obj").read_text() == "v 0 0 0\n" and (out / "preview_final.png").exists()


def test_a_refused_run_with_overwrite_keeps_the_earlier_run(tmp_path, capsys):
    """Probe finding (session 24): a run refused for memory (exit 3) with --overwrite had already deleted the
    earlier run's files, checkpoint included. The folder is checked first and cleared only once the run is built."""
    out = tmp_path / "out"
    common = ["--backend", "numpy", "--no-progress", "--frames", "1", "--out", str(out)]
    assert main(["run", str(_toml(tmp_path)), *common]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "checkpoint.h5" in before
    huge = _toml(
        tmp_path, TINY_SAND_TOML.replace("size = [0.06, 0.06, 0.06]", "size = [600.0, 600.0, 600.0]"), "huge.toml"
    )
    capsys.readouterr()
    assert main(["run", str(huge), *common, "--overwrite"]) == 3
    assert capsys.readouterr().err.startswith("refused: ")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    # and a run that starts still replaces them
    assert main(["run", str(_toml(tmp_path)), *common, "--overwrite"]) == 0
    assert (out / "checkpoint.h5").exists()


def test_a_tilde_in_the_output_folder_is_the_home_folder(tmp_path, monkeypatch):
    """Fuzz finding: --out '~/x' made a folder named '~' while PyVista wrote into $HOME/x (a traceback)."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(_toml(tmp_path)), "--out", "~/x", "--frames", "1", "--backend", "numpy",
                 "--no-progress"]) == 0  # fmt: skip
    assert (tmp_path / "home" / "x" / "checkpoint.h5").exists() and not (tmp_path / "~").exists()


def test_a_failing_disk_ends_the_run_with_a_message_and_no_half_written_file(tmp_path, capsys, monkeypatch):
    """Fuzz finding: a full disk ended `run` in an OSError traceback and left checkpoint.h5.tmp behind."""
    import couplekit.io.checkpoint as ckpt

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    out = tmp_path / "out"
    # the checkpoint's last act fails: the disk fills before it (the checkpoint module's os only: the frame
    # files, written under temporary names too, go through)
    fake_os = types.SimpleNamespace(**{k: getattr(os, k) for k in dir(os) if not k.startswith("__")})
    fake_os.replace = full
    monkeypatch.setattr(ckpt, "os", fake_os)
    rc = main(["run", str(_toml(tmp_path)), "--out", str(out), "--frames", "1", "--backend", "numpy", "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err
    # the run's one checkpoint (at its end) failed: the message says so instead of pointing at a --resume
    assert "No space left on device" in err and "no checkpoint was written yet" in err
    assert not list(out.glob("*.tmp")) and not list(out.glob(".*.tmp*")), list(out.iterdir())
    assert (out / "fields_0001.vti").exists() or (out / "particles_0001.vtp").exists()


# ------------------------------------------------------------------------------------------ numbers
def test_a_divergence_on_the_numpy_backend_is_reported_not_a_traceback(tmp_path, capsys):
    """Fuzz finding: a NaN velocity made the reference's moment transform raise LinAlgError mid-step."""
    out = tmp_path / "out"
    rc = main(["run", str(_fluid_toml(tmp_path)), "--out", str(out), "--frames", "2", "--backend", "numpy",
               "--no-progress", "--set", "fluid.air_density=1e-30"])  # fmt: skip
    assert rc == 1
    assert "diverged" in capsys.readouterr().err
    assert (out / "diverged.txt").exists() and (out / "last_good.h5").exists()


def test_a_scene_whose_particle_mass_overflows_float32_is_refused(tmp_path, capsys):
    """Fuzz finding: every value within the schema's range, but the particle mass overflows float32: the run's
    first finiteness check raised out of `run` (a traceback); then it ended as diverged at step 0; since session 23
    the sand solver refuses such particles when it is built (a mass of inf also made the node volume, the mass
    over the density, inf), exit 2 with what to check."""
    text = TINY_SAND_TOML.replace("size = [0.06, 0.06, 0.06]", "size = [6e28, 6e28, 6e28]")
    text = text.replace("dx = 0.005", "dx = 5e27").replace("dt = 2e-4", "dt = 1e10")
    text = text.replace("frame_duration = 1e-3", "frame_duration = 5e10")
    text = text.replace("min = [0.02, 0.02, 0.03]", "min = [2e28, 2e28, 2e28]")
    text = text.replace("max = [0.04, 0.04, 0.045]", "max = [4e28, 4e28, 4.5e28]")
    text = text.replace("velocity = [0.0, 0.0, -0.5]", "velocity = [0.0, 0.0, 0.0]")
    out = tmp_path / "out"
    rc = main(["run", str(_toml(tmp_path, text)), "--out", str(out), "--backend", "numpy", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "must fit float32" in err and "check the densities" in err and "Traceback" not in err


# ------------------------------------------------------------------------------------------ scene files
@pytest.mark.parametrize("what", ["folder", "device"])
def test_a_folder_or_a_device_as_the_scene_file_is_refused_before_reading(tmp_path, capsys, what):
    """Fuzz finding: `validate /dev/zero` read without end (a MemoryError traceback)."""
    path = str(tmp_path) if what == "folder" else "/dev/zero"
    if what == "device" and not os.path.exists(path):
        pytest.skip("no /dev/zero here")
    assert main(["validate", path]) == 2
    assert "give the path of a TOML scene file" in capsys.readouterr().err


def test_a_scene_file_beyond_the_size_cap_is_refused(tmp_path, monkeypatch, capsys):
    import couplekit.scene.schema as schema

    monkeypatch.setattr(schema, "MAX_FILE_BYTES", 100)
    assert main(["validate", str(_toml(tmp_path))]) == 2
    assert "a scene file holds at most 100" in capsys.readouterr().err


def test_a_byte_order_mark_is_not_a_syntax_error(tmp_path):
    """Fuzz finding: a UTF-8 BOM (Windows Notepad) was 'not valid TOML (line 1, column 1)'."""
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + TINY_SAND_TOML.encode())
    assert Scene.load(path).sand is not None


def test_long_names_and_many_problems_give_a_bounded_message():
    """Fuzz finding: a 200 kB key name gave a 200 kB message; 20,000 unknown keys a 3 MB one."""
    d = tiny_sand()
    d["k" * 200_000] = 1
    for i in range(200):
        d[f"bad{i}"] = 1
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    text = str(err.value)
    assert len(err.value.problems) == 201 and len(text) < 20_000
    assert "characters more" in text and "and 151 more problems" in text


# ------------------------------------------------------------------------------------------ scene values
@pytest.mark.parametrize(
    "setting, key",
    [
        ("time.frame_duration=1e30", "time.frame_duration"),  # 7e33 steps per frame: ran forever
        ("fluid.gravity=[0, 0, -1e5]", "time.dt"),  # the fluid's own gravity skipped the Mach check
        ("sand.hardening=[-35, 9, 0.2, 10]", "sand.hardening"),  # a negative friction angle
        ("sand.hardening=[80, 30, 0.2, 0]", "sand.hardening"),  # beyond 90 degrees as q grows
        ("sand.absorption_rate=2", "sand.absorption_rate"),  # valid, then refused by the coupler unnamed
    ],
)
def test_impossible_values_are_refused_with_their_key(setting, key):
    scene = Scene.from_dict(
        {
            **tiny_fluid(),
            "sand": {"density": 1500.0, "retention": True},
            "bodies": tiny_fluid()["bodies"]
            + [
                {
                    "kind": "sand",
                    "geometry": {"type": "box", "min": [0.005, 0.006, 0.012], "max": [0.011, 0.014, 0.016]},
                }
            ],
        }
    )
    with pytest.raises(SceneError) as err:
        with_settings(scene, dict([parse_setting(setting)]))
    assert key in err.value.keys, str(err.value)


def test_the_papers_hardening_is_accepted():
    scene = Scene.from_dict(tiny_sand())
    assert with_settings(scene, {"sand.hardening": [35, 9, 0.2, 10]}).sand.hardening == (35, 9, 0.2, 10)


def test_an_invalid_fluid_table_is_the_only_problem_reported(tmp_path):
    """Fuzz finding: one bad [fluid] key also said every water body and inflow 'needs a [fluid] table'."""
    d = tiny_fluid()
    d["fluid"]["phases"] = 3
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    assert err.value.keys == ["fluid.phases"], str(err.value)


def test_set_values_nested_too_deeply_are_refused(tmp_path, capsys):
    deep = "[" * 3000 + "]" * 3000
    assert main(["validate", str(_toml(tmp_path)), "--set", f"time.dt={deep}"]) == 2
    assert "nested too deeply" in capsys.readouterr().err


def test_set_into_a_list_the_scene_lacks_says_to_set_the_whole_list(tmp_path, capsys):
    """Fuzz findings: --set inflows[0].velocity on a scene with no inflows said 'inflows is a table', then
    'inflows has 0 entries'; and outputs.fields[0] on a scene taking the default field list said the list had 0
    entries. The key is not in the scene: the message says so and how to set the whole list."""
    for key in ("inflows[0].velocity=[1, 0, 0]", 'outputs.fields[0]="phi"'):
        assert main(["validate", str(_toml(tmp_path)), "--set", key]) == 2
        err = capsys.readouterr().err
        name = key.split("[")[0]
        assert f"{name} is not in the scene (it takes its default), so [0] has no entry to set" in err, err
        assert f"--set '{name}=[...]'" in err


def test_set_file_paths_resolve_against_the_scene_files_folder(tmp_path, monkeypatch):
    """Fuzz finding: a relative mesh path given with --set resolved against the working directory."""
    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "rock.obj").write_text(
        "v 0.02 0.02 0.02\nv 0.04 0.02 0.02\nv 0.03 0.04 0.02\nv 0.03 0.03 0.04\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n"
    )
    scene = _toml(folder)
    monkeypatch.chdir(tmp_path)
    assert main(["validate", str(scene), "--set", 'bodies[0].geometry={type = "mesh", file = "rock.obj"}']) == 0


# ------------------------------------------------------------------------------------------ the API
def test_save_into_a_folder_is_refused_and_leaves_nothing(tmp_path):
    sim = Simulation(Scene.from_dict(tiny_sand()), backend="numpy", log=None)
    with pytest.raises(CheckpointError, match="is a folder"):
        sim.save(tmp_path)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("frames", [0, -3])
def test_run_with_no_frames_is_refused(tmp_path, frames):
    sim = Simulation(Scene.from_dict(tiny_sand()), backend="numpy", log=None)
    with pytest.raises(ValueError, match="frames must be 1 or more"):
        sim.run(frames=frames, out=tmp_path / "out", progress=False)


def test_with_settings_needs_a_mapping():
    with pytest.raises(TypeError, match="mapping of dotted keys"):
        with_settings(Scene.from_dict(tiny_sand()), ["time.dt"])


# ------------------------------------------------------------------------------------------ cautions
def test_a_liquid_let_into_a_closed_box_and_an_extreme_density_ratio_are_cautioned(tmp_path, capsys):
    """Fuzz findings: a single-phase inflow with no outflow face (its pressure rose to 1.6 MPa in 0.05 s) and a
    1e30:1 density ratio were accepted without a word; both now print a caution (not refusals)."""
    closed = tiny_fluid()
    closed["fluid"]["phases"] = 1
    closed["bodies"] = [b for b in closed["bodies"] if b["kind"] != "water"]
    closed["inflows"][0]["kind"] = "water"
    closed["domain"]["boundary"] = {"x_min": "inflow"}
    from couplekit.cautions import stability_cautions

    assert any("no face is an outflow" in c for c in stability_cautions(Scene.from_dict(closed)))
    ratio = tiny_fluid()
    ratio["fluid"]["air_density"] = 0.1
    assert any("beyond the 1000:1" in c for c in stability_cautions(Scene.from_dict(ratio)))
    # the tiny scene's 4-cell drop is named (under 2 interface widths across), and nothing else
    assert [c for c in stability_cautions(Scene.from_dict(tiny_fluid())) if "(water) is only" not in c] == []


def test_overlapping_sand_bodies_are_refused_and_touching_ones_accepted():
    """Fuzz finding: the same sand box given twice doubled the sand's mass in its volume (packing 1.2)."""
    d = tiny_sand()
    box = d["bodies"][0]
    d["bodies"].append({**box, "geometry": dict(box["geometry"])})
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    assert "bodies[2].geometry" in err.value.keys and "packed twice as densely" in str(err.value)
    lo, hi = box["geometry"]["min"], box["geometry"]["max"]
    d["bodies"][2]["geometry"] = {"type": "box", "min": [hi[0], lo[1], lo[2]], "max": [hi[0] + 0.01, hi[1], hi[2]]}
    assert len(Scene.from_dict(d).bodies) == 3  # side by side, sharing a face: no seeding point in both


def test_water_inside_an_obstacle_and_obstacles_filling_the_domain_are_refused():
    """Fuzz findings: a water body wholly inside an obstacle, and an obstacle filling the whole domain, were
    accepted silently (the sand equivalents were refused)."""
    d = tiny_fluid()
    d["bodies"].append(
        {"kind": "obstacle", "geometry": {"type": "sphere", "center": [0.015, 0.01, 0.02], "radius": 0.009}}
    )
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)  # the falling drop (bodies[1], radius 5 mm) lies inside the new sphere
    assert err.value.keys == ["bodies[1].geometry"] and "wholly inside obstacles (bodies[3])" in str(err.value)
    d = tiny_fluid()
    d["bodies"].append({"kind": "obstacle", "geometry": {"type": "box", "min": [0, 0, 0], "max": [0.03, 0.02, 0.03]}})
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    assert "no fluid cell is left" in str(err.value)


def test_set_reaches_the_sand_walls_table(tmp_path, capsys):
    """Fuzz finding: --set sand.walls.z_min.friction said "[sand] has no key 'walls'" (a documented table)."""
    scene = str(_toml(tmp_path))
    assert main(["validate", scene, "--set", "sand.walls.z_min.friction=0.3"]) == 0
    assert main(["validate", scene, "--set", "sand.walls.z_mn.friction=0.3"]) == 2
    assert "did you mean 'z_min'" in capsys.readouterr().err


def test_resuming_from_an_earlier_checkpoint_does_not_log_frames_twice(tmp_path):
    """Fuzz finding: resuming from an earlier checkpoint in the same folder logged frames [0, 1, 2, 3, 4, 3, 4].
    Since session 25 that resume is refused unless --overwrite (it replaces the later frames: a probe found it
    doing so unasked); with it the log holds each frame once."""
    out = tmp_path / "out"
    scene = _toml(tmp_path, TINY_SAND_TOML.replace("frames = 2", "frames = 4"))
    common = ["--backend", "numpy", "--no-progress", "--out", str(out)]
    assert main(["run", str(scene), "--frames", "2", *common]) == 0
    early = out / "early.h5"
    early.write_bytes((out / "checkpoint.h5").read_bytes())
    assert main(["run", str(scene), "--resume", str(out / "checkpoint.h5"), "--frames", "4", *common]) == 0
    assert main(["run", str(scene), "--resume", str(early), "--frames", "4", *common]) == 2
    assert [r["frame"] for r in read_diagnostics(out / "diagnostics.jsonl")] == [0, 1, 2, 3, 4]  # untouched
    assert main(["run", str(scene), "--resume", str(early), "--frames", "4", "--overwrite", *common]) == 0
    assert [r["frame"] for r in read_diagnostics(out / "diagnostics.jsonl")] == [0, 1, 2, 3, 4]


def test_the_api_names_the_wrong_type_and_takes_a_scene_dict():
    """Fuzz findings: Simulation(dict) raised a TypeError from deep inside, scheduler=3 "'int' object is not
    iterable"; a dict is now taken as a scene (Scene.from_dict) and other types are named."""
    assert Simulation(tiny_sand(), backend="numpy", log=None).scene.name == "tiny_sand"
    with pytest.raises(TypeError, match="scene must be a Scene"):
        Simulation(3, backend="numpy", log=None)
    with pytest.raises(TypeError, match="scheduler must be a spec string"):
        Simulation(tiny_sand(), backend="numpy", log=None, scheduler=3)
    with pytest.raises(TypeError, match="Scene.load takes a file path"):
        Scene.load(123)


def test_a_multirate_sand_step_longer_than_a_frame_is_refused():
    """Fuzz finding: sand_every 7 with 5 steps per frame showed the sand ahead of the clock in the frames."""
    from couplekit.simulation import with_scheduler

    scene = Scene.from_dict({**tiny_fluid(), "sand": {"density": 1500.0}, "bodies": tiny_fluid()["bodies"] + [
        {"kind": "sand", "geometry": {"type": "box", "min": [0.005, 0.006, 0.012], "max": [0.011, 0.014, 0.016]}}]})  # fmt: skip
    with pytest.raises(SceneError) as err:
        with_scheduler(scene, "multirate:7")
    assert "scheduler.sand_every" in err.value.keys and "ahead of the fluid's clock" in str(err.value)


def test_complex_heights_are_refused(tmp_path):
    """Fuzz finding: a .npy height grid of complex numbers was taken with its imaginary parts dropped."""
    import numpy as np

    from couplekit.scene.mesh import load_heights

    np.save(tmp_path / "h.npy", np.full((3, 3), 0.01 + 5j))
    with pytest.raises(ValueError, match="complex numbers"):
        load_heights(tmp_path / "h.npy")


def test_a_stirring_beyond_the_lattice_mach_limit_is_refused(tmp_path, capsys):
    """Fuzz finding: stirring.acceleration = 1e30 validated (the speed estimate left the stirring out), then NaN."""
    scene = str(Path(__file__).parents[1] / "examples" / "fig11_stirring_small.toml")
    assert main(["validate", scene]) == 0
    assert main(["validate", scene, "--set", "stirring.acceleration=1e30"]) == 2
    assert "stirring.acceleration" in capsys.readouterr().err


def test_a_domain_that_is_no_table_is_said_to_be_no_table():
    """Fuzz finding: [[domain]] or domain = 1 reported only 'domain.size: is required'."""
    d = tiny_sand()
    d["domain"] = [d["domain"]]
    with pytest.raises(SceneError) as err:
        Scene.from_dict(d)
    assert "domain: must be a table, got a list" in str(err.value)


def test_a_mesh_with_repeated_faces_is_refused_instead_of_losing_its_solid(tmp_path):
    """Found after the fuzz round (its 'thinner than the particle spacing' message for such a mesh): a closed
    cube whose 12 faces are all given twice has every edge used an even number of times, so it passed the
    watertight check, but the parity inside test counted each crossing twice and the obstacle had no solid cell:
    the fluid would have flowed through it. Now refused; the cube given once builds its solid."""
    faces = [(1, 2, 4), (1, 4, 3), (5, 7, 8), (5, 8, 6), (1, 5, 6), (1, 6, 2), (3, 4, 8), (3, 8, 7), (1, 3, 7),
             (1, 7, 5), (2, 6, 8), (2, 8, 4)]  # fmt: skip
    corners = [(x, y, z) for x in (0.02, 0.04) for y in (0.02, 0.04) for z in (0.0, 0.03)]
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in corners)
    scene = {**tiny_fluid(), "bodies": [{"kind": "obstacle", "geometry": {"type": "mesh", "file": "cube.obj"}}]}
    scene["fluid"] = {"phases": 1, "water_lattice_viscosity": 0.01}
    scene.pop("inflows")
    scene["domain"] = {"size": [0.06, 0.06, 0.06], "dx": 0.005}
    (tmp_path / "cube.obj").write_text(text + "".join(f"f {a} {b} {c}\n" for a, b, c in faces) * 2)
    with pytest.raises(SceneError) as err:
        Scene.from_dict(scene, base_dir=tmp_path)
    assert "given more than once" in str(err.value), str(err.value)
    (tmp_path / "cube.obj").write_text(text + "".join(f"f {a} {b} {c}\n" for a, b, c in faces))
    sim = Simulation(Scene.from_dict(scene, base_dir=tmp_path), backend="numpy", log=None)
    assert sim.fields()["solid"].sum() == 4 * 4 * 6  # 0.02-0.04 m in x and y, 0-0.03 m in z at dx = 5 mm
