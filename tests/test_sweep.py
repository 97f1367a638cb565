"""`couplekit sweep`: sweep files checked before anything runs, points run on a Dask LocalCluster, results
table, reference errors, resuming, failing points recorded, the CLI's exit codes."""

from __future__ import annotations

import io
import json
import math
import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent / "scene"))
from sim_scenes import tiny_sand  # noqa: E402

from couplekit.backend import cpu_status  # noqa: E402
from couplekit.cli import main  # noqa: E402
from couplekit.sweep import (  # noqa: E402
    KeyPathError,
    SweepError,
    compare_with_reference,
    load_results,
    load_sweep,
    parse_key,
    parse_sweep,
    run_sweep,
    set_key,
    stability,
)

distributed = pytest.importorskip("distributed", reason="the sweep extra: pip install 'couplekit[sweep]'")
pytest.importorskip("pyarrow", reason="the sweep extra: pip install 'couplekit[sweep]'")

HUGE = [30.0, 30.0, 30.0]
"""A domain.size that validates but is refused when the solvers are built (thousands of GiB)."""


@pytest.fixture(scope="module", autouse=True)
def _needs_cpu_backend():
    ok, why = cpu_status()
    if not ok:
        pytest.skip(f"cpu backend unavailable: {why}")


@pytest.fixture(scope="module")
def cluster_address():
    """One LocalCluster (2 worker processes, 1 thread each) shared by the tests that pass ``address``."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        yield cluster.scheduler_address


# ------------------------------------------------------------------------------------------------ files
def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(v)


def _toml(data: dict) -> str:
    """A scene or sweep dict as TOML: top-level values first, then one [table] per dict (nested as inline)."""
    lines = [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for name, table in data.items():
        if isinstance(table, dict):
            lines.append(f"[{name}]")
            lines += [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def _write_sweep(tmp_path: Path, sweep: dict, base: dict | None = None, name: str = "tiny.toml") -> Path:
    """``base.toml`` (default tiny_sand) and a sweep file whose [sweep] table is ``sweep`` (base = base.toml)."""
    (tmp_path / "base.toml").write_text(_toml(base if base is not None else tiny_sand(frames=2)))
    path = tmp_path / name
    path.write_text(_toml({"sweep": {"base": "base.toml", "backend": "cpu", "frames": 2, **sweep}}))
    return path


def _by_name(rows: list[dict]) -> dict[str, dict]:
    return {r["name"]: r for r in rows}


def _same(a, b) -> bool:
    """Equal, with NaN equal to NaN."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


# ------------------------------------------------------------------------------------------------ running
def test_two_point_sweep_runs_on_a_local_cluster(tmp_path):
    path = _write_sweep(tmp_path, {"grid": {"time.dt": [1e-4, 2e-4]}})
    out = tmp_path / "out"
    rows = run_sweep(path, out, workers=2, progress=False)  # its own LocalCluster: 2 processes, 1 thread each

    assert (out / "results.parquet").is_file() and (out / "results.json").is_file()
    loaded = load_results(out)
    assert len(loaded) == 2 and [r["id"] for r in loaded] == [r["id"] for r in rows]
    table = _by_name(loaded)
    assert set(table) == {"time.dt=0.0001", "time.dt=0.0002"}
    assert table["time.dt=0.0001"]["time.dt"] == 1e-4 and table["time.dt=0.0002"]["time.dt"] == 2e-4
    assert table["time.dt=0.0001"]["steps"] == 20 and table["time.dt=0.0002"]["steps"] == 10  # 1 ms frames
    costs = [c for c in loaded[0] if c.startswith("cost_") and c.endswith("_ms")]
    assert costs, "no per-stage cost columns"
    for row in loaded:
        assert row["status"] == "done" and row["error"] is None and row["frames"] == 2
        assert row["wall_s"] > 0 and row["sand_steps_per_step"] == 1.0
        assert all(row[c] > 0 for c in costs)
        assert math.isnan(row["error_centroid_path"]) and row["matched_frames"] == 0  # no reference
        assert row["unstable"] is False and math.isnan(row["max_lattice_speed"])  # sand only: no lattice speed
        point = json.loads((out / "points" / f"{row['id']}.json").read_text())
        assert point["status"] == "done" and len(point["diagnostics"]) == 3  # frames 0, 1, 2
        run_dir = out / row["run_dir"]
        assert (run_dir / "diagnostics.jsonl").is_file()
        assert not [p for p in run_dir.iterdir() if p.suffix in (".png", ".vti", ".vtp", ".ply")]  # sweep defaults
    assert [p.id for p in load_sweep(path).points] == [r["id"] for r in rows]  # ids are stable


def test_reference_errors_and_resuming_runs_nothing(tmp_path, cluster_address):
    path = _write_sweep(tmp_path, {"grid": {"time.dt": [1e-4, 2e-4]}, "reference": {"time.dt": 5e-5}})
    out = tmp_path / "out"
    first = run_sweep(path, out, address=cluster_address, progress=False)

    table = _by_name(first)
    assert list(table) == ["reference", "time.dt=0.0001", "time.dt=0.0002"]
    ref = table["reference"]
    assert ref["status"] == "done" and ref["time.dt"] == 5e-5 and ref["matched_frames"] == 2
    for metric in ("error_centroid_path", "error_sand_front", "error_sand_top", "error_kinetic_energy"):
        assert ref[metric] == 0.0, metric
        assert table["time.dt=0.0002"][metric] >= 0.0 and math.isfinite(table["time.dt=0.0002"][metric])
    assert table["time.dt=0.0002"]["error_centroid_path"] > 0.0
    assert all(math.isnan(r["error_fluid_volume"]) and math.isnan(r["error_free_surface"]) for r in first)
    assert all(r["matched_frames"] == 2 for r in first)

    run_logs = [out / r["run_dir"] / "diagnostics.jsonl" for r in first]
    stamps = [p.stat().st_mtime_ns for p in run_logs]
    log = io.StringIO()
    # nothing is left to run, so no scheduler is contacted: an address nobody listens on does no harm
    second = run_sweep(path, out, address="tcp://127.0.0.1:9", stream=log)
    assert "skipped 3 points" in log.getvalue() and "running" not in log.getvalue()
    assert [p.stat().st_mtime_ns for p in run_logs] == stamps
    assert len(second) == len(first)
    for a, b in zip(first, second, strict=True):
        assert a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a), a["name"]


def test_an_interrupted_sweep_tables_the_points_it_finished(tmp_path, cluster_address, monkeypatch):
    """A probe (session 25): Ctrl-C during a sweep kept each finished point's JSON but wrote no results table.
    The table is written with the points finished before the interrupt, which is raised on."""
    from couplekit.sweep import runner

    real = runner._finished_line

    def stop_after_first(i, n, rec):
        real(i, n, rec)
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "_finished_line", stop_after_first)
    path = _write_sweep(tmp_path, {"grid": {"time.dt": [1e-4, 2e-4]}})
    out = tmp_path / "out"
    log = io.StringIO()
    with pytest.raises(KeyboardInterrupt):
        run_sweep(path, out, address=cluster_address, stream=log)
    assert "interrupted; 1 of 2 points in" in log.getvalue()
    tables = list(out.glob("results.*"))
    assert tables, list(out.iterdir())
    rows = json.loads((out / "results.json").read_text())
    assert len(rows) == 1 and rows[0]["status"] == "done"


def test_invalid_and_failing_points_are_recorded_and_the_others_run(tmp_path, cluster_address):
    sweep = {
        "grid": {"time.dt": [2e-4, 5e-3]},  # 5e-3 breaks the MPM elastic limit: refused up front
        "cases": [{"name": "small"}, {"name": "huge", "set": {"domain.size": HUGE}}],  # huge: refused at run time
    }
    path = _write_sweep(tmp_path, sweep)
    out = tmp_path / "out"
    log = io.StringIO()
    rows = _by_name(run_sweep(path, out, address=cluster_address, stream=log))

    assert rows["small time.dt=0.0002"]["status"] == "done" and rows["small time.dt=0.0002"]["wall_s"] > 0
    for name in ("small time.dt=0.005", "huge time.dt=0.005"):
        assert rows[name]["status"] == "invalid" and "time.dt" in rows[name]["error"]
        assert math.isnan(rows[name]["wall_s"]) and rows[name]["steps"] is None
    huge = rows["huge time.dt=0.0002"]
    assert huge["status"] == "error" and "InsufficientMemoryError" in huge["error"]
    assert huge["domain.size"] == HUGE and rows["small time.dt=0.0002"]["domain.size"] is None
    assert "traceback" in json.loads((out / "points" / f"{huge['id']}.json").read_text())
    assert "[2/2]" in log.getvalue() and "invalid: small time.dt=0.005" in log.getvalue()

    log = io.StringIO()
    again = _by_name(run_sweep(path, out, address=cluster_address, stream=log))
    assert "skipped 1 point " in log.getvalue() and "[1/1] huge time.dt=0.0002: error" in log.getvalue()
    assert {n: r["status"] for n, r in again.items()} == {n: r["status"] for n, r in rows.items()}


def test_a_worker_crash_is_recorded_on_the_client(tmp_path, monkeypatch):
    import dask

    from couplekit.sweep import runner

    real = runner.run_point

    def crash_on_coarse_dt(task):
        if task["overrides"]["time.dt"] == 2e-4:
            os._exit(3)  # the worker process dies without returning
        return real(task)

    monkeypatch.setattr(runner, "run_point", crash_on_coarse_dt)
    path = _write_sweep(tmp_path, {"grid": {"time.dt": [1e-4, 2e-4]}})
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):  # no retry on another worker
        rows = _by_name(run_sweep(path, tmp_path / "out", workers=2, progress=False))
    assert rows["time.dt=0.0001"]["status"] == "done"
    crashed = rows["time.dt=0.0002"]
    assert crashed["status"] == "error" and "the task failed on the cluster" in crashed["error"]


# ------------------------------------------------------------------------------------------------ checking
BAD_SWEEPS = {
    "unknown [sweep] key": ({"colour": "red", "grid": {"time.dt": [1e-4]}}, None, "sweep.colour"),
    "grid value not a list": ({"grid": {"time.dt": 1e-4}}, None, 'sweep.grid."time.dt"'),
    "empty grid list": ({"grid": {"time.dt": []}}, None, 'sweep.grid."time.dt"'),
    "index beyond the bodies": ({"grid": {"bodies[7].density": [1000.0]}}, None, 'sweep.grid."bodies[7].density"'),
    "unknown scene key": ({"set": {"time.dtt": 1e-4}}, None, 'sweep.set."time.dtt"'),
    "missing base file": ({"base": "nowhere.toml", "grid": {"time.dt": [1e-4]}}, None, "sweep.base"),
    "invalid base scene": ({"grid": {"time.dt": [1e-4]}}, {"domain": {"size": [0.06] * 3, "dx": -0.005}}, "sweep.base"),
    "unnamed case among several": ({"cases": [{"set": {"time.dt": 1e-4}}, {"name": "b"}]}, None, "sweep.cases[0].name"),
    "refused reference": ({"grid": {"time.dt": [1e-4]}, "reference": {"time.dt": 1.0}}, None, "sweep.reference"),
    # sweep.frames (2 in _write_sweep) would replace these in every point: refused, not silently overridden
    "time.frames in the grid": ({"grid": {"time.frames": [1, 2]}}, None, 'sweep.grid."time.frames"'),
    "time.frames in the set": ({"set": {"time.frames": 3}}, None, 'sweep.set."time.frames"'),
    "time.frames in a case": (
        {"cases": [{"grid": {"time.frames": [1, 3]}}]},
        None,
        'sweep.cases[0].grid."time.frames"',
    ),
    "time.frames in the reference": ({"reference": {"time.frames": 4}}, None, 'sweep.reference."time.frames"'),
    # a probe (session 25): --threads 99999 ended in a segmentation fault; each point's backend would refuse it
    "threads beyond the machine": ({"threads": 99999, "grid": {"time.dt": [1e-4]}}, None, "sweep.threads"),
    # a probe (session 25): each point writes into points/<id>/run whatever outputs.directory says
    "outputs.directory in the set": (
        {"set": {"outputs.directory": "elsewhere"}, "grid": {"time.dt": [1e-4]}},
        None,
        'sweep.set."outputs.directory"',
    ),
}


@pytest.mark.parametrize("case", list(BAD_SWEEPS))
def test_malformed_sweep_files_are_refused_naming_the_key(tmp_path, case):
    sweep, base, key = BAD_SWEEPS[case]
    if base is not None:
        base = {**tiny_sand(frames=2), **base}
    path = _write_sweep(tmp_path, sweep, base)
    with pytest.raises(SweepError) as err:
        load_sweep(path)
    assert key in err.value.keys, str(err.value)
    assert key in str(err.value) and "Fix:" in str(err.value)


def test_not_toml_is_refused(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[sweep\nbase = 'x'\n")
    with pytest.raises(SweepError) as err:
        load_sweep(path)
    assert err.value.keys == ["(syntax)"]


def test_sweep_frames_with_time_frames_in_the_grid_is_refused_naming_both(tmp_path):
    path = _write_sweep(tmp_path, {"frames": 1, "grid": {"time.frames": [1, 2]}})
    with pytest.raises(SweepError) as err:
        load_sweep(path)
    text = str(err.value)
    assert err.value.keys == ['sweep.grid."time.frames"'], text
    assert "sweep.frames" in text and "remove sweep.frames" in text and "drop time.frames from the grid" in text
    # without sweep.frames each point runs the frames its grid value names
    data = {"sweep": {"base": "base.toml", "backend": "cpu", "grid": {"time.frames": [1, 2]}}}
    spec = parse_sweep(data, base_dir=tmp_path)
    assert [(p.name, p.frames) for p in spec.points] == [("time.frames=1", 1), ("time.frames=2", 2)]


def test_dotted_keys_create_tables_and_check_indexes():
    scene = tiny_sand()
    assert parse_key("bodies[1].geometry.radius") == ("bodies", 1, "geometry", "radius")
    set_key(scene, "scheduler.kind", "subcycle")  # the scene has no [scheduler] table yet
    set_key(scene, "bodies[0].density", 2000.0)
    set_key(scene, "domain.size[2]", 0.08)
    assert scene["scheduler"] == {"kind": "subcycle"} and scene["bodies"][0]["density"] == 2000.0
    assert scene["domain"]["size"] == [0.06, 0.06, 0.08]
    with pytest.raises(KeyPathError, match=r"bodies has 2 entries, so \[2\] is beyond it"):
        set_key(scene, "bodies[2].density", 1.0)
    with pytest.raises(KeyPathError, match="not a table"):
        set_key(scene, "time.dt.x", 1.0)


def test_points_names_ids_and_overrides():
    data = {
        "sweep": {
            "set": {"outputs": {"checkpoint_every": 0}},  # an unquoted dotted key is the same as "outputs...."
            "grid": {"time.dt": [1e-4, 2e-4]},
            "cases": [
                {"name": "lockstep", "set": {"scheduler.kind": "lockstep"}},
                {"name": "subcycle", "set": {"scheduler.kind": "subcycle"}, "grid": {"scheduler.substeps": [1, 4]}},
            ],
        },
        "base": tiny_sand(),
    }
    spec = parse_sweep(data)
    names = [p.name for p in spec.points]
    assert names == [
        "lockstep time.dt=0.0001",
        "lockstep time.dt=0.0002",
        "subcycle time.dt=0.0001 scheduler.substeps=1",
        "subcycle time.dt=0.0001 scheduler.substeps=4",
        "subcycle time.dt=0.0002 scheduler.substeps=1",
        "subcycle time.dt=0.0002 scheduler.substeps=4",
    ]
    assert all(p.invalid is None for p in spec.points)
    last = spec.points[-1]
    assert last.case == "subcycle"
    assert last.overrides == {
        "outputs.checkpoint_every": 0,
        "scheduler.kind": "subcycle",
        "time.dt": 2e-4,
        "scheduler.substeps": 4,
    }
    assert last.scene["scheduler"] == {"kind": "subcycle", "substeps": 4} and last.scene["outputs"]["vtk"] is False
    assert len({p.id for p in spec.points}) == 6 and all(len(p.id) == 10 for p in spec.points)
    assert [p.id for p in parse_sweep(data).points] == [p.id for p in spec.points]
    assert spec.keys[:2] == ("time.dt", "scheduler.substeps")


# ------------------------------------------------------------------------------------------------ the folder
def _files(folder: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_folder_holding_another_sweep_is_refused_and_kept(tmp_path, cluster_address):
    a = _write_sweep(tmp_path, {"name": "A", "grid": {"time.dt": [1e-4, 2e-4]}}, name="A.toml")
    out = tmp_path / "out"
    first = run_sweep(a, out, address=cluster_address, progress=False)
    before = _files(out)

    (tmp_path / "b").mkdir()  # another base scene (another file), another name, one point shared with A's ids
    b = _write_sweep(tmp_path / "b", {"name": "B", "frames": 1, "grid": {"time.dt": [1e-4]}}, tiny_sand(frames=1))
    (tmp_path / "c").mkdir()  # the name of A, the base scene of another file
    c = _write_sweep(tmp_path / "c", {"name": "A", "grid": {"time.dt": [1e-4]}})
    d = _write_sweep(tmp_path, {"name": "D", "grid": {"time.dt": [1e-4]}}, name="D.toml")  # A's base, another name
    for path, differs in [(b, ("'A'", "'B'", "base scene")), (c, ("base scene",)), (d, ("'A'", "'D'"))]:
        with pytest.raises(SweepError) as err:
            run_sweep(path, out, address="tcp://127.0.0.1:9", progress=False)  # refused before any cluster
        text = str(err.value)
        assert str(out.resolve()) in text and "another sweep" in text and "--out" in text, text
        assert all(s in text for s in differs), text
        assert ("'B'" in text) == (path == b) and ("sweep.name" in text) == (path != c), text
        assert _files(out) == before  # A's point files, runs, sweep.json and table are untouched
    assert [r["id"] for r in load_results(out)] == [r["id"] for r in first]

    # the same sweep resumes in its own folder, also with a value added to its grid (5e-3: invalid, not run)
    a = _write_sweep(tmp_path, {"name": "A", "grid": {"time.dt": [1e-4, 2e-4, 5e-3]}}, name="A.toml")
    log = io.StringIO()
    again = run_sweep(a, out, address="tcp://127.0.0.1:9", stream=log)
    assert "skipped 2 points" in log.getvalue() and "running" not in log.getvalue()
    assert [r["status"] for r in again] == ["done", "done", "invalid"]
    assert json.loads((out / "sweep.json").read_text())["name"] == "A"


# ------------------------------------------------------------------------------------------------ metrics
def test_errors_compare_frames_at_the_same_times():
    def rec(t, x, ke, front=0.0):
        return {"time": t, "sand_centroid_x": x, "sand_centroid_y": 0.0, "sand_centroid_z": 0.0,
                "total_kinetic_energy_si": ke, "sand_front": front}  # fmt: skip

    reference = [rec(0.0, 9.0, 9.0), rec(0.1, 0.0, 1.0), rec(0.2, 0.0, 1.0)]
    series = [rec(0.0, 5.0, 5.0), rec(0.1, 3.0, 2.0), rec(0.2 * (1 + 1e-12), 4.0, 0.0, math.nan), rec(0.3, 1.0, 1.0)]
    err = compare_with_reference(series, reference)
    assert err["matched_frames"] == 2  # t = 0 is left out, t = 0.3 has no reference frame
    assert err["error_centroid_path"] == pytest.approx(math.sqrt((9 + 16) / 2))
    assert err["error_kinetic_energy"] == pytest.approx(1.0)  # RMS(1, -1) / RMS(1, 1)
    assert err["error_sand_front"] == 0.0  # the NaN frame is skipped
    assert math.isnan(err["error_fluid_volume"])  # no frame has fluid_volume
    assert stability([{"max_lattice_speed": 0.1}, {"max_lattice_speed": 0.31}], "done")["unstable"] is True
    assert stability([{"max_lattice_speed": 0.1}], "diverged") == {"unstable": True, "max_lattice_speed": 0.1}


# ------------------------------------------------------------------------------------------------ the CLI
def test_cli_sweep_exit_codes(tmp_path, cluster_address, capsys, monkeypatch):
    good = _write_sweep(tmp_path, {"grid": {"time.dt": [2e-4, 5e-3]}}, name="good.toml")  # one invalid: final
    args = ["--address", cluster_address, "--no-progress"]
    assert main(["sweep", str(good), "--out", str(tmp_path / "a"), *args]) == 0
    assert "good: 2 points, 0 failed" in capsys.readouterr().out

    failing = _write_sweep(tmp_path, {"set": {"domain.size": HUGE}}, name="failing.toml")
    assert main(["sweep", str(failing), "--out", str(tmp_path / "b"), *args]) == 1
    assert "did not finish" in capsys.readouterr().err

    bad = _write_sweep(tmp_path, {"grid": {"time.dt": 1e-4}}, name="bad.toml")
    assert main(["sweep", str(bad), "--out", str(tmp_path / "c")]) == 2
    assert 'sweep.grid."time.dt"' in capsys.readouterr().err

    # another sweep into a's folder: refused, exit 2 (not a traceback); a file in place of the folder: named
    other = _write_sweep(tmp_path, {"name": "other", "grid": {"time.dt": [2e-4]}}, name="other.toml")
    assert main(["sweep", str(other), "--out", str(tmp_path / "a"), *args]) == 2
    assert "holds the results of another sweep" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert main(["sweep", str(other), "--out", str(tmp_path / "file"), *args]) == 2
    err = capsys.readouterr().err
    assert "cannot write the sweep's results" in err and "LocalCluster" not in err

    monkeypatch.setitem(sys.modules, "distributed", None)  # as if dask.distributed were not installed
    assert main(["sweep", str(good), "--out", str(tmp_path / "d")]) == 2
    assert "pip install 'couplekit[sweep]'" in capsys.readouterr().err
