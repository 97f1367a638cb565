"""VTK frame files on a full or failing disk, and damaged .pvd indexes.

VTK's XML writer crashes the process (SIGSEGV) or leaves a cut-off file when the disk fills under it, so the
writers check the free space first and write under a temporary name (couplekit.io.vtk.save_vtk); a damaged index
is rebuilt from the run's other records on --resume, or refused naming the file and the fix (PvdIndex)."""

from __future__ import annotations

import errno
import json
import shutil
import sys
from collections import namedtuple
from pathlib import Path

import numpy as np
import pytest

from couplekit.cli import main
from couplekit.io import PvdIndex, read_pvd, write_fields_vti, write_particles_vtp
from couplekit.io.outputs import OutputFolderError, OutputIndexError
from couplekit.io.vtk import vtk_bytes_bound

pv = pytest.importorskip("pyvista")

sys.path.insert(0, str(Path(__file__).parents[1] / "scene"))
from sim_scenes import TINY_SAND_TOML  # noqa: E402

RNG = np.random.default_rng(11)
Usage = namedtuple("Usage", "total used free")


def _fields(n=6):
    return {"phi": RNG.random((n, n, n), dtype=np.float32), "velocity": RNG.random((3, n, n, n), dtype=np.float32)}


def _particles(p=50):
    return RNG.random((3, p)), {"saturation": RNG.random(p, dtype=np.float32), "v": RNG.random((3, p))}


WRITERS = {
    "vti": lambda path: write_fields_vti(path, _fields(), 0.01),
    "vtp": lambda path: write_particles_vtp(path, *_particles()),
}


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ------------------------------------------------------------------ defect 1: a full disk
@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_too_little_free_space_is_refused_before_vtk_writes(kind, tmp_path, monkeypatch):
    """VTK is never called when the frame cannot fit: its crash on ENOSPC cannot be caught."""
    monkeypatch.setattr(shutil, "disk_usage", lambda p: Usage(10**9, 10**9 - 4096, 4096))
    monkeypatch.setattr(pv.DataObject, "save", lambda *a, **k: pytest.fail("VTK was called on a full disk"))
    path = tmp_path / f"frame_0001.{kind}"
    with pytest.raises(OSError) as err:
        WRITERS[kind](path)
    text = str(err.value.strerror)
    assert err.value.errno == errno.ENOSPC and str(tmp_path) in text and path.name in text, text
    assert "4096 bytes" in text and "needs up to" in text and "--out" in text, text
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_enough_free_space_writes_the_file(kind, tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "disk_usage", lambda p: Usage(10**9, 10**9 - 2**20, 2**20))
    path = WRITERS[kind](tmp_path / f"frame_0001.{kind}")
    assert pv.read(path).n_points > 0 and _leftovers(tmp_path) == [path.name]  # no temporary file beside it


@pytest.mark.parametrize("dtype", [np.uint8, np.float32, np.float64, np.int64])
def test_the_size_bound_holds_for_incompressible_data(dtype, tmp_path):
    n, p = 24, 5000
    grid = pv.ImageData(dimensions=(n, n, n))
    grid.point_data["a"] = RNG.integers(0, 2**8 if dtype == np.uint8 else 2**31, n**3).astype(dtype)
    grid.point_data["b"] = RNG.random((n**3, 3)).astype(dtype) if dtype not in (np.uint8, np.int64) else grid["a"]
    cloud = pv.PolyData(RNG.random((p, 3)))
    cloud.verts = np.column_stack([np.ones(p, np.int64), np.arange(p)]).ravel()
    cloud.point_data["a"] = RNG.integers(0, 255, p).astype(dtype)
    for ds, name in ((grid, "g.vti"), (cloud, "c.vtp"), (pv.PolyData(), "e.vtp")):
        ds.save(tmp_path / name)
        assert (tmp_path / name).stat().st_size <= vtk_bytes_bound(ds), name


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_a_failing_vtk_write_leaves_no_file_under_the_frame_name(kind, tmp_path, monkeypatch):
    """VTK writes part of the file, then fails: neither the part nor a temporary file stays; a file written
    before under the same name (a resumed run rewriting a frame) is kept as it was."""

    def half_then_fail(self, filename, *a, **k):
        Path(filename).write_bytes(b"<?xml version='1.0'?><VTKFile")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pv.DataObject, "save", half_then_fail)
    fresh, kept = tmp_path / f"frame_0001.{kind}", tmp_path / f"frame_0000.{kind}"
    kept.write_bytes(b"the earlier frame")
    for path in (fresh, kept):
        with pytest.raises(OSError, match="No space left"):
            WRITERS[kind](path)
    assert _leftovers(tmp_path) == [kept.name] and kept.read_bytes() == b"the earlier frame"


@pytest.mark.parametrize("written", [b"", b"<?xml version='1.0'?>\n<VTKFile type='PolyData'>\n  <Poly"])
def test_a_file_vtk_cut_short_without_raising_is_an_error(written, tmp_path, monkeypatch):
    monkeypatch.setattr(pv.DataObject, "save", lambda self, filename, *a, **k: Path(filename).write_bytes(written))
    path = tmp_path / "particles_0001.vtp"
    with pytest.raises(OSError) as err:
        WRITERS["vtp"](path)
    assert err.value.errno == errno.EIO and path.name in err.value.strerror and "--out" in err.value.strerror
    assert _leftovers(tmp_path) == []


def test_cli_run_on_a_full_disk_exits_2_with_a_message(tmp_path, monkeypatch, capsys):
    """The writers' OSError ends ``couplekit run`` cleanly (README: exit 2 and a message), no cut-off frame."""
    real = shutil.disk_usage
    monkeypatch.setattr(
        shutil, "disk_usage", lambda p: Usage(10**9, 10**9 - 1000, 1000) if Path(p).name == "out" else real(p)
    )
    scene = tmp_path / "scene.toml"
    scene.write_text(TINY_SAND_TOML)
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), "--frames", "1", "--no-progress", "--backend", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "not enough free space in" in err and str(out) in err and "--out" in err, err
    assert not list(out.glob("*.vt?")) and not list(out.glob(".*tmp*"))


# ------------------------------------------------------------------ defect 2: a damaged .pvd index
def _index(path: Path, entries) -> None:
    index = PvdIndex(path)
    for t, f in entries:
        index.add(t, path.parent / f)


def _frame_files(folder: Path, stem: str, ext: str, n: int) -> None:
    for i in range(n):
        (folder / f"{stem}_{i:04d}.{ext}").write_bytes(b"frame")


@pytest.mark.parametrize("content", [b"", b"<?xml version='1.0'?><VTKFile type='Collection'><Coll", b"\x00\x01junk"])
def test_a_damaged_index_is_an_oserror_naming_the_file(content, tmp_path):
    path = tmp_path / "fields.pvd"
    path.write_bytes(content)
    with pytest.raises(OutputIndexError, match=str(path)) as err:
        read_pvd(path)
    assert isinstance(err.value, OSError) and isinstance(err.value, OutputFolderError)


def test_a_damaged_index_is_rebuilt_from_the_other_indexes(tmp_path):
    times = [0.0, 0.001, 0.002]
    _frame_files(tmp_path, "fields", "vti", 3)
    _frame_files(tmp_path, "particles", "vtp", 3)
    (tmp_path / "particles_0000.ply").write_bytes(b"not a vtk frame")
    _index(tmp_path / "particles.pvd", [(t, f"particles_{i:04d}.vtp") for i, t in enumerate(times)])
    (tmp_path / "fields.pvd").write_bytes(b"")
    index = PvdIndex(tmp_path / "fields.pvd")
    expected = [(t, f"fields_{i:04d}.vti") for i, t in enumerate(times)]
    assert index.rebuilt and index.entries == expected and read_pvd(tmp_path / "fields.pvd") == expected
    index.add(0.002, tmp_path / "fields_0002.vti")  # a resumed run goes on as with an intact index
    assert read_pvd(tmp_path / "fields.pvd") == expected


def test_a_damaged_index_is_rebuilt_from_the_diagnostics_log(tmp_path):
    times = [0.0, 0.25, 0.5, 0.75]
    _frame_files(tmp_path, "particles", "vtp", 4)
    lines = [json.dumps({"time": t, "step": 5.0 * i, "frame": float(i)}) for i, t in enumerate(times)]
    (tmp_path / "diagnostics.jsonl").write_text("\n".join(lines) + '\n{"time": 1.0, "fra')  # cut off by a crash
    (tmp_path / "particles.pvd").write_text("<VTKFile type='Collection'><Collection><DataSet timestep='0.0' ")
    index = PvdIndex(tmp_path / "particles.pvd")
    assert index.entries == [(t, f"particles_{i:04d}.vtp") for i, t in enumerate(times)]


def test_an_intact_index_is_read_not_rebuilt(tmp_path):
    _frame_files(tmp_path, "fields", "vti", 2)
    _index(tmp_path / "fields.pvd", [(0.0, "fields_0000.vti")])
    index = PvdIndex(tmp_path / "fields.pvd")
    assert not index.rebuilt and index.entries == [(0.0, "fields_0000.vti")]


@pytest.mark.parametrize("records", ["none", "partial", "conflicting"])
def test_an_index_whose_times_cannot_be_recovered_is_refused(records, tmp_path):
    _frame_files(tmp_path, "fields", "vti", 3)
    if records == "partial":
        _index(tmp_path / "particles.pvd", [(0.0, "particles_0000.vtp"), (0.1, "particles_0001.vtp")])
    if records == "conflicting":
        _index(tmp_path / "particles.pvd", [(i / 10, f"particles_{i:04d}.vtp") for i in range(3)])
        (tmp_path / "diagnostics.jsonl").write_text(json.dumps({"time": 0.5, "frame": 1.0}) + "\n")
    damaged = tmp_path / "fields.pvd"
    damaged.write_bytes(b"")
    with pytest.raises(OutputIndexError) as err:
        PvdIndex(damaged)
    text = str(err.value)
    assert str(damaged) in text and "delete" in text and "--out" in text, text
    missing = {"none": [0, 1, 2], "partial": [2], "conflicting": [1]}[records]
    assert [i for i in range(3) if f"fields_{i:04d}.vti" in text] == missing, text
    assert ("disagree" in text) == (records == "conflicting"), text
    assert damaged.read_bytes() == b""  # left as found


def test_cli_resume_with_an_emptied_index_rebuilds_it(tmp_path, capsys):
    """The reproduction: an emptied fields.pvd made --resume end in an XML traceback."""
    scene = tmp_path / "scene.toml"
    scene.write_text(TINY_SAND_TOML)
    out = tmp_path / "out"
    common = ["--out", str(out), "--no-progress", "--backend", "cpu"]
    assert main(["run", str(scene), "--frames", "1", *common]) == 0
    before = read_pvd(out / "fields.pvd")
    (out / "fields.pvd").write_bytes(b"")
    assert main(["run", str(scene), "--resume", str(out / "checkpoint.h5"), "--frames", "2", *common]) == 0
    after = read_pvd(out / "fields.pvd")
    assert after[:2] == before and [f for _, f in after] == ["fields_0000.vti", "fields_0001.vti", "fields_0002.vti"]
    assert after == [
        (t, f.replace("particles", "fields").replace(".vtp", ".vti")) for t, f in read_pvd(out / "particles.pvd")
    ]
