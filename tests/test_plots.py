"""Plots of runs (couplekit.io.plots, ``couplekit plot`` / ``compare``), the per-frame stage costs they draw, the
summary.png every run writes, and the previews' fixed colour scale."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

import couplekit.io
from couplekit.cli import main
from couplekit.io import read_diagnostics
from couplekit.io.plots import RunLogError, compare_runs, load_run, panels_for, plot_run
from couplekit.io.preview import preview_speed_range
from couplekit.scene import Scene
from couplekit.simulation import Simulation

sys.path.insert(0, str(Path(__file__).parent / "scene"))
from sim_scenes import tiny_coupled, tiny_fluid, tiny_sand  # noqa: E402

SCENES = {"fluid": tiny_fluid, "sand": tiny_sand, "coupled": tiny_coupled}
FLUID_PANELS = {"Fluid volume drift", "Largest lattice speed", "Free surface"}
SAND_PANELS = {"Sand height and runout"}


def _sim(d: dict) -> Simulation:
    return Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)


def _png(path: Path) -> np.ndarray:
    """The image, checked to be a real picture: readable, of some size, not one flat colour."""
    assert path.is_file() and path.stat().st_size > 0, path
    img = imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100, img.shape
    assert img[..., :3].std() > 0.01, f"{path} is blank"
    return img


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """A fluid-only, a sand-only and a coupled run of 2 frames (each folder holds its diagnostics and summary)."""
    base = tmp_path_factory.mktemp("runs")
    out = {}
    for name, make in SCENES.items():
        result = _sim(make()).run(out=base / name, progress=False)
        assert result.status == "done"
        out[name] = base / name
    return out


# ------------------------------------------------------------------ plot_run
@pytest.mark.parametrize("kind", list(SCENES))
def test_a_run_writes_summary_png_and_plot_run_redraws_it(runs, kind, tmp_path):
    """Simulation.run left summary.png; plot_run draws the panels of what the run has (no sand panel for water
    alone, no fluid panel for sand alone, both coupled) and the stage costs."""
    _png(runs[kind] / "summary.png")
    paths = plot_run(runs[kind], out=tmp_path)
    assert paths == [tmp_path / "summary.png"]
    _png(paths[0])
    titles = {p.title for p in panels_for([load_run(runs[kind])])}
    assert (FLUID_PANELS <= titles) == (kind != "sand"), titles
    assert (SAND_PANELS <= titles) == (kind != "fluid"), titles
    assert "Kinetic energy" in titles and "Largest speed" in titles
    assert load_run(runs[kind]).stage_names(), "the stage costs are logged per frame"


def test_plot_run_to_a_png_path(runs, tmp_path):
    target = tmp_path / "sub" / "mine.png"
    assert plot_run(runs["coupled"], out=target) == [target]
    _png(target)


# ------------------------------------------------------------------ per-frame stage costs
def test_frame_stage_costs_are_the_mean_of_the_frames_steps():
    """stage_<name>_ms is each stage's mean ms per step over the steps since the last written frame: the mean of
    the steps' own stage times."""
    sim = _sim(tiny_sand())
    sim.step(1)  # the warm-up step (kernel loading) is not timed
    sim._mark_stage_costs()
    per_step = []
    for _ in range(3):
        sim.step(1)
        per_step.append(sim.stage_times())
    costs = sim.frame_stage_costs()
    assert set(costs) == {f"stage_{s}_ms" for s in per_step[0]} and costs
    for s in per_step[0]:
        assert costs[f"stage_{s}_ms"] == pytest.approx(1e3 * np.mean([t[s] for t in per_step]), rel=1e-9)
    sim._mark_stage_costs()
    assert sim.frame_stage_costs() == {}, "no step since the mark: no cost"
    sim.step(1)
    assert sim.frame_stage_costs()[f"stage_{next(iter(per_step[0]))}_ms"] == pytest.approx(
        1e3 * next(iter(sim.stage_times().values())), rel=1e-9
    )


def test_the_log_holds_stage_costs_from_the_first_frame_on(runs):
    records = read_diagnostics(runs["coupled"] / "diagnostics.jsonl")
    assert not any(k.startswith("stage_") for k in records[0]), "frame 0: no step yet"
    for r in records[1:]:
        ms = [v for k, v in r.items() if k.startswith("stage_") and k.endswith("_ms")]
        assert len(ms) > 5 and all(v >= 0 for v in ms) and sum(ms) > 0


# ------------------------------------------------------------------ compare_runs
def test_compare_two_runs(runs, tmp_path):
    paths = compare_runs([runs["fluid"], runs["coupled"]], tmp_path, labels=["water", "water + sand"])
    assert paths == [tmp_path / "compare.png", tmp_path / "compare_stages.png"]
    for p in paths:
        _png(p)
    paths = compare_runs([runs["sand"], runs["coupled"]], tmp_path / "ab.png")
    assert paths == [tmp_path / "ab.png", tmp_path / "ab_stages.png"]
    with pytest.raises(RunLogError, match="one label per run"):
        compare_runs([runs["sand"], runs["coupled"]], tmp_path, labels=["only one"])


# ------------------------------------------------------------------ the commands
def test_cli_plot_and_compare(runs, tmp_path, capsys):
    assert main(["plot", str(runs["sand"]), "--out", str(tmp_path / "p")]) == 0
    assert str(tmp_path / "p" / "summary.png") in capsys.readouterr().out
    _png(tmp_path / "p" / "summary.png")
    rc = main(["compare", str(runs["fluid"]), str(runs["coupled"]), "--out", str(tmp_path / "c"), "--labels", "a", "b"])
    assert rc == 0
    _png(tmp_path / "c" / "compare.png")
    assert main(["compare", str(runs["fluid"]), str(runs["coupled"]), "--labels", "a"]) == 2
    assert "one label per run" in capsys.readouterr().err


def test_missing_folder_and_missing_log_are_named(tmp_path, capsys):
    missing = tmp_path / "nowhere"
    assert main(["plot", str(missing)]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "does not exist" in err and "--out" in err
    (tmp_path / "empty").mkdir()
    assert main(["plot", str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "empty") in err and "no diagnostics.jsonl" in err and "outputs.diagnostics" in err
    (tmp_path / "empty" / "diagnostics.jsonl").write_text("\n")
    with pytest.raises(RunLogError, match="is empty"):
        load_run(tmp_path / "empty")
    assert main(["compare", str(tmp_path / "empty"), str(missing)]) == 2
    # a sweep point's folder (points/<id>) holds its run in run/: named (a probe, session 25, after the docs'
    # example left the run/ out)
    point = tmp_path / "points" / "a"
    (point / "run").mkdir(parents=True)
    (point / "run" / "diagnostics.jsonl").write_text('{"frame": 0, "time": 0.0}\n')
    with pytest.raises(RunLogError, match=r"sweep point's folder: its run is in .*run; give that folder"):
        load_run(point)


def test_a_truncated_last_line_is_plotted_up_to_it(runs, tmp_path, capsys):
    """A run killed while writing its log leaves half a line: the frames before it are plotted, with a note; a
    damaged line before the last is refused, naming the line."""
    run = tmp_path / "crashed"
    run.mkdir()
    lines = (runs["coupled"] / "diagnostics.jsonl").read_text().splitlines()
    (run / "diagnostics.jsonl").write_text("\n".join(lines[:-1] + [lines[-1][: len(lines[-1]) // 2]]))
    log = load_run(run)
    assert len(log.records) == len(lines) - 1 and "cut short" in log.notes[0]
    assert main(["plot", str(run)]) == 0
    assert "cut short" in capsys.readouterr().err
    _png(run / "summary.png")
    (run / "diagnostics.jsonl").write_text("\n".join([lines[0], "{oops", *lines[1:]]))
    with pytest.raises(RunLogError, match="line 2 is not a JSON object"):
        load_run(run)


def test_a_resumed_runs_repeated_frames_are_kept_once(runs, tmp_path):
    run = tmp_path / "resumed"
    run.mkdir()
    records = read_diagnostics(runs["sand"] / "diagnostics.jsonl")
    again = dict(records[-1], sand_top=123.0)
    with open(run / "diagnostics.jsonl", "w") as fh:
        for r in [*records, again]:
            fh.write(json.dumps(r) + "\n")
    log = load_run(run)
    assert len(log.records) == len(records) and log.records[-1]["sand_top"] == 123.0
    assert "logged twice" in log.notes[0]


# ------------------------------------------------------------------ summary.png at the end of every run
def test_an_interrupted_run_still_writes_its_summary(tmp_path):
    steps = {"n": 0}

    def stop() -> bool:
        steps["n"] += 1
        return steps["n"] > 2  # after one frame of the tiny sand scene, during the second

    result = _sim(tiny_sand(frames=3)).run(out=tmp_path / "r", progress=False, stop=stop)
    assert result.status == "interrupted"
    _png(tmp_path / "r" / "summary.png")
    assert load_run(tmp_path / "r").status == "interrupted"


def test_a_failing_plot_does_not_fail_the_run(tmp_path, monkeypatch):
    import couplekit.io.plots as plots

    def broken(*a, **k):
        raise RuntimeError("no fonts")

    monkeypatch.setattr(plots, "plot_run", broken)
    said = []
    sim = Simulation(Scene.from_dict(tiny_sand(frames=1)), backend="cpu", threads=1, log=said.append)
    assert sim.run(out=tmp_path / "r", progress=False).status == "done"
    assert not (tmp_path / "r" / "summary.png").exists()
    assert any("summary.png not written" in s and "no fonts" in s and "couplekit plot" in s for s in said), said


# ------------------------------------------------------------------ previews
def test_previews_share_one_colour_scale(tmp_path, monkeypatch):
    """Every preview of a run gets the scene's speed scale, while the particles' speeds change from frame to
    frame (the issue: 0-1.09 m/s at one frame, 0-0.001 at another)."""
    seen = []

    def record(path, size, dx, fields, particles, title="", speed_range=None, **kw):
        seen.append((speed_range, float(np.linalg.norm(particles["v"], axis=0).max())))
        return Path(path)

    monkeypatch.setattr(couplekit.io, "render_preview", record)
    d = tiny_sand(frames=2)
    d["outputs"]["preview"] = True
    sim = _sim(d)
    sim.run(out=tmp_path / "r", progress=False)
    assert len(seen) == 3
    ranges = {r for r, _ in seen}
    assert ranges == {preview_speed_range(sim.scene)[0]}
    assert len({round(v, 6) for _, v in seen}) == 3, "the frames' own top speeds differ"
    (lo, hi), why = preview_speed_range(sim.scene)
    assert lo == 0.0 and hi == pytest.approx(sim.scene.expected_max_speed()[0]) and "sqrt(2 g h)" in why


def test_preview_scale_from_time_max_speed():
    d = tiny_sand()
    d["time"]["max_speed"] = 3.0
    assert preview_speed_range(Scene.from_dict(d)) == ((0.0, 3.0), "time.max_speed")


def test_a_preview_renders_with_a_fixed_scale(tmp_path):
    """Off-screen rendering with the run's scale, axes, legend and colour bar (the machine renders through EGL,
    as tests/io/test_outputs.py checks)."""
    sim = _sim(tiny_coupled())
    sim.step(2)
    path = couplekit.io.render_preview(
        tmp_path / "p.png", sim.scene.domain.size, sim.scene.domain.dx, sim.fields(), sim.particles(),
        title="tiny_coupled", speed_range=sim.preview_scale(),
    )  # fmt: skip
    img = _png(path)
    assert img.shape[:2] == (600, 800)


def test_summary_false_writes_no_png(tmp_path):
    """Sweep points run with summary=False: their folders hold no PNG unless the sweep turns outputs on."""
    assert _sim(tiny_sand(frames=1)).run(out=tmp_path / "r", progress=False, summary=False).status == "done"
    assert (tmp_path / "r" / "diagnostics.jsonl").is_file() and not list((tmp_path / "r").glob("*.png"))


def test_a_one_frame_runs_stage_costs_are_drawn(tmp_path):
    """A probe (session 25): a 1-frame run logs stage costs in one record (frame 0 has none), and a stack plot of
    one point draws nothing: the summary's stage panel was empty. It is one stacked bar now, as tall as the
    frame's cost per step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from couplekit.io.plots import _stage_panel_single

    d = tiny_coupled()
    d["time"]["frames"] = 1
    assert _sim(d).run(out=tmp_path / "one", progress=False).status == "done"
    run = load_run(tmp_path / "one")
    timed = [r for r in run.records if any(k.startswith("stage_") for k in r)]
    assert len(timed) == 1
    fig, ax = plt.subplots()
    _stage_panel_single(ax, run)
    heights = [p.get_height() for p in ax.patches]
    total = sum(v for k, v in timed[0].items() if k.startswith("stage_") and k.endswith("_ms"))
    assert heights and sum(heights) == pytest.approx(total, rel=1e-6)
    plt.close(fig)


# ------------------------------------------------------------------ hostile inputs (session 26 probe)
def test_compare_writes_all_or_nothing_and_drops_a_stale_stage_chart(runs, tmp_path, monkeypatch, capsys):
    """A compare into a folder an earlier compare used removes that compare's stage chart when these runs logged
    no stage costs (it showed other runs); Ctrl-C while writing leaves neither new PNG and no folder it made."""
    out = tmp_path / "cmp"
    compare_runs([runs["fluid"], runs["coupled"]], out)
    assert (out / "compare_stages.png").is_file()
    bare = tmp_path / "bare"
    bare.mkdir()
    records = [json.loads(s) for s in (runs["fluid"] / "diagnostics.jsonl").read_text().splitlines()]
    (bare / "diagnostics.jsonl").write_text(
        "\n".join(json.dumps({k: v for k, v in r.items() if not k.startswith("stage_")}) for r in records) + "\n"
    )
    assert compare_runs([bare, bare], out) == [out / "compare.png"]
    assert not (out / "compare_stages.png").exists()

    import matplotlib.figure

    calls = {"n": 0}
    real = matplotlib.figure.Figure.savefig

    def interrupted(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:  # the second PNG: the first is already written (to its temporary name)
            raise KeyboardInterrupt
        return real(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", interrupted)
    fresh = tmp_path / "new" / "deeper"
    assert main(["compare", str(runs["fluid"]), str(runs["coupled"]), "--out", str(fresh)]) == 130
    assert "interrupted: nothing written" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_compare_refuses_unusable_outputs_and_labels_and_notes_duplicates(runs, tmp_path, capsys):
    assert main(["compare", str(runs["fluid"]), "--out", str(tmp_path / "x.jpg")]) == 2
    assert "PNG images" in capsys.readouterr().err and not (tmp_path / "x.jpg").exists()
    assert main(["compare", str(runs["fluid"]), str(runs["sand"]), "--labels", "", "", "--out", str(tmp_path)]) == 2
    assert "label 1 is empty" in capsys.readouterr().err
    assert main(["compare", str(runs["fluid"]), str(runs["fluid"]), "--out", str(tmp_path / "d")]) == 0
    assert "given twice" in capsys.readouterr().err
    assert main(["compare", str(runs["fluid"]), str(runs["sand"]), "--labels", "a", "a", "--out", str(tmp_path)]) == 0
    assert "label 'a' is given to runs 1 and 2" in capsys.readouterr().err


def test_damaged_logs_are_named_with_the_right_fix(runs, tmp_path, capsys):
    # the log file given instead of its folder: the folder is suggested
    assert main(["compare", str(runs["fluid"] / "diagnostics.jsonl"), "--out", str(tmp_path)]) == 2
    assert f"give the run folder that holds it ({runs['fluid']})" in capsys.readouterr().err
    # whole JSON that is not a record: damage, not a cut-short line
    run = tmp_path / "list"
    run.mkdir()
    (run / "diagnostics.jsonl").write_text("[1, 2]\n")
    with pytest.raises(RunLogError, match=r"line 1 is JSON but not an object \(a list\)"):
        load_run(run)
    # diagnostics.jsonl a folder
    run = tmp_path / "folderlog"
    (run / "diagnostics.jsonl").mkdir(parents=True)
    with pytest.raises(RunLogError, match="is not a file"):
        load_run(run)
    # a time that is not a number is plotted as missing, not a traceback (plot and compare)
    run = tmp_path / "badtime"
    run.mkdir()
    records = [json.loads(s) for s in (runs["fluid"] / "diagnostics.jsonl").read_text().splitlines()]
    records[0]["time"] = None
    records[-1]["time"] = "0.02s"
    (run / "diagnostics.jsonl").write_text("\n".join(json.dumps(r) for r in records) + "\n")
    assert main(["plot", str(run)]) == 0
    assert main(["compare", str(run), str(runs["fluid"]), "--out", str(tmp_path / "c")]) == 0
