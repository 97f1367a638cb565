"""The benchmark scripts (benchmarks/*.py) as a user runs them: bad options are refused by argparse (exit 2,
usage and one line naming the option, nothing written) before anything runs, and every --help has a whole
sentence as its description."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_"))
ENV = dict(os.environ, OMP_NUM_THREADS="1")


def _run(script: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, f"benchmarks/{script}", *args],
        cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


REFUSALS = [
    ("effect_costs.py", ["--only", "bogus_effect"], "--only", "unknown effect 'bogus_effect'"),
    ("effect_costs.py", ["--only"], "--only", "expected at least one argument"),
    ("effect_costs.py", ["--n", "8"], "--n", ">= 11"),
    ("effect_costs.py", ["--n", "0"], "--n", ">= 11"),
    ("effect_costs.py", ["--steps", "0"], "--steps", ">= 1"),
    ("collapse_study.py", ["--cells", "0"], "--cells", ">= 1"),
    ("collapse_study.py", ["--t-end", "-1"], "--t-end", "> 0"),
    ("collapse_study.py", ["--cfl", "0.6"], "--cfl", "(0, 0.5]"),
    ("collapse_study.py", ["--transfer", "flip:x"], "--transfer", "flip:B"),
    ("row_lengths.py", ["--lengths", "0"], "--lengths", ">= 2"),
    ("row_lengths.py", ["--repeats", "0"], "--repeats", ">= 1"),
    ("fluid_throughput.py", ["--sizes", "1"], "--sizes", ">= 2"),
    ("fluid_throughput.py", ["--threads", "0"], "--threads", ">= 1"),
    ("gpu_throughput.py", ["--particles", "0"], "--particles", "(0, 120]"),
    ("gpu_throughput.py", ["--cells", "1"], "--cells", ">= 2"),
    ("sand_throughput.py", ["--steps", "0"], "--steps", ">= 1"),
    ("sand_throughput.py", ["--sizes", "5"], "--sizes", "invalid choice"),
    ("compare_commits.py", ["HEAD", "--threads", "0"], "--threads", ">= 1"),
    ("coupled_stability.py", ["--shape", "8,8,8"], "--shape", "sand must stay"),
    ("coupled_stability.py", ["--cases", "bogus"], "--cases", "unknown case 'bogus'"),
    ("coupled_stability.py", ["--steps", "0"], "--steps", ">= 1"),
    ("volume_ablation.py", ["--steps", "50"], "--steps", ">= 100"),
    ("volume_ablation.py", ["--shape", "0,1,2"], "--shape", ">= 5"),
    ("wetting_front.py", ["--every", "300", "--steps", "100"], "--every", "<= --steps"),
    ("wetting_front.py", ["--shape", "5,5,5"], "--shape", "does not build"),
    ("example_timings.py", ["--only", "no_such_scene"], "--only", "no small scene matches"),
    ("example_timings.py", ["--threads", "0"], "--threads", ">= 1"),
    ("fp16_accuracy.py", ["--only", "bogus"], "--only", "unknown case 'bogus'"),
    ("fig08_interface_width.py", ["--radii", "0"], "--radii", "> 0"),
    ("odd_floor_ramp.py", ["linear", "--box", "4x12"], "--box", "NZxNYxNX"),
    ("odd_floor_ramp.py", ["wave", "--ramps", "none"], "--ramps", "give ramps >= 0"),
    ("kernel_build_report.py", ["--only", "nope.cu"], "--only", "unknown kernel source 'nope.cu'"),
    ("accuracy_vs_cost.py", ["--workers", "0"], "--workers", ">= 1"),
    ("mobility_map.py", ["--widths", "1.5"], "--widths", ">= 2"),
    ("mobility_map.py", ["--mobilities", "0,0.02"], "--mobilities", "> 0"),
    ("mobility_map.py", ["--kinds", "wall,bogus"], "--kinds", "bogus"),
]


@pytest.mark.parametrize(("script", "args", "option", "message"), REFUSALS, ids=lambda v: str(v))
def test_bad_option_is_refused_before_anything_runs(tmp_path, script, args, option, message):
    out = tmp_path / "out"
    out_args = ["--out", str(out / "result.json")] if script != "accuracy_vs_cost.py" else ["--out", str(out)]
    if script == "example_timings.py":
        out_args += ["--out-dir", str(out / "runs")]
    proc = _run(script, *args, *out_args)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    error = [line for line in proc.stderr.splitlines() if ": error: " in line]
    assert len(error) == 1, proc.stderr
    assert option in error[0] and message in error[0], error[0]
    assert not out.exists()


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_help_describes_the_script_in_whole_sentences(script):
    proc = _run(script.name, "--help")
    assert proc.returncode == 0, proc.stderr[-2000:]
    # argparse: the usage block, a blank line, the description, a blank line, the arguments
    description = proc.stdout.split("\n\n")[1].strip()
    assert description and not description.startswith(("positional arguments", "options")), proc.stdout
    assert description.endswith("."), f"{script.name}: description ends mid-sentence: ...{description[-80:]!r}"


def test_table1_help_says_it_writes_the_effect_costs_too():
    proc = _run("table1.py", "--help")
    assert proc.returncode == 0
    assert "effect_costs.json" in proc.stdout


def test_fp16_accuracy_docstring_shows_only_options_the_parser_has():
    doc = (ROOT / "benchmarks" / "fp16_accuracy.py").read_text()
    options = _run("fp16_accuracy.py", "--help").stdout.split("\noptions:\n")[1]  # the parser's, not the doc's
    for option in ("--quick", "--only", "--threads", "--out"):
        assert (option in doc.split('"""')[1]) <= (option in options), option


def test_accuracy_vs_cost_out_holds_every_output(tmp_path, monkeypatch):
    """--out takes the JSON and the PNGs too (the analysis stubbed: the sweeps take an hour)."""
    spec = importlib.util.spec_from_file_location(
        "accuracy_vs_cost_under_test", ROOT / "benchmarks" / "accuracy_vs_cost.py"
    )
    mod = importlib.util.module_from_spec(spec)
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    spec.loader.exec_module(mod)
    import couplekit.sweep

    scene = "ball_into_water"
    (tmp_path / scene).mkdir()
    written = []

    def plot(*args):
        path = Path(args[-1])
        path.write_bytes(b"png")
        written.append(path)

    monkeypatch.setattr(couplekit.sweep, "load_results", lambda folder: [])
    monkeypatch.setattr(mod, "analyse", lambda *a: {"speedup_at_equal_error": None,
                                                  "best_speedup_at_equal_error": None,
                                                  "speedups": {mod.SCENES[scene]: {}}})  # fmt: skip
    monkeypatch.setattr(mod, "plot_work_precision", plot)
    monkeypatch.setattr(mod, "plot_stability", plot)
    assert mod.main(["--analyse-only", "--no-resolution", "--scenes", scene, "--out", str(tmp_path)]) == 0
    assert (tmp_path / "accuracy_vs_cost.json").is_file()
    assert written and all(p.parent == tmp_path for p in written)


@pytest.mark.parametrize("extra", [[], ["--float64"]])
def test_collapse_study_runs_with_the_flip_blend(extra):
    """``--transfer flip:B`` crashed in the script's own P2G patch (a zeros_like of the absent grid volume of a
    one-density sand, an object array the kernel refused; a broadcast error with --float64)."""
    proc = _run("collapse_study.py", "--cells", "4", "--t-end", "0.005", "--transfer", "flip:1", *extra)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["transfer"] == "flip:1" and np.isfinite(out["runout"])


def test_mobility_map_writes_its_table_and_plot(tmp_path):
    """One point on each side of the limit (width 4, M = 0.005: u = 0.02 runs, 0.04 diverges by step 220,
    measured): both recorded, and the plot written next to the JSON."""
    out = tmp_path / "map.json"
    proc = _run("mobility_map.py", "--kinds", "wall", "--widths", "4", "--mobilities", "0.005", "--speeds",
                "0.02,0.04", "--out", str(out), timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    runs = json.loads(out.read_text())["runs"]
    assert [(r["speed"], r["ran"]) for r in runs] == [(0.02, True), (0.04, False)], runs
    assert out.with_suffix(".png").stat().st_size > 1000
