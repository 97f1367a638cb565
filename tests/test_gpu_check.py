"""scripts/gpu_check.sh without a GPU: it parses, its dry run lists every step within the 8-minute budget and
names files that exist; the tests' backend selection (COUPLEKIT_TEST_BACKEND) reads as documented."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "gpu_check.sh"
STEPS = ("info", "kernels", "solvers", "memcheck", "throughput", "fig13")

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="bash is not on the PATH")


def _dry_run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SCRIPT), "--dry-run", *args], capture_output=True, text=True, timeout=30)


def test_script_parses():
    proc = subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 0, proc.stderr


def test_dry_run_lists_every_step_within_nine_minutes(tmp_path):
    proc = _dry_run("--out", str(tmp_path / "res"))
    assert proc.returncode == 0, proc.stderr
    steps = re.findall(r"^step (\w+)\s+limit\s+(\d+)s: (.+)$", proc.stdout, re.MULTILINE)
    assert [s[0] for s in steps] == list(STEPS)
    assert sum(int(s[1]) for s in steps) < 9 * 60
    assert str(tmp_path / "res") in proc.stdout
    assert not (tmp_path / "res").exists()  # a dry run creates nothing
    commands = {name: cmd for name, _, cmd in steps}
    assert "--backend cuda" in commands["info"] and "--selfcheck" in commands["info"]
    assert "COUPLEKIT_TEST_BACKEND=cuda" in commands["kernels"] and "COUPLEKIT_TEST_BACKEND=cuda" in commands["solvers"]
    assert "--cells 256" in commands["throughput"] and "--particles 1 4 16" in commands["throughput"]
    assert "examples/fig13_sand_drop_beaker_small.toml --backend cuda" in commands["fig13"]
    assert "tests/test_simulation_on_backend.py" in commands["solvers"]
    assert (
        "compute-sanitizer --tool memcheck" in commands["memcheck"]
        and "scripts/gpu_memcheck.py" in commands["memcheck"]
    )
    # every repository file a step names exists
    for path in re.findall(r"\b((?:tests|benchmarks|examples|scripts)/[\w/.-]+\.(?:py|toml))", proc.stdout):
        assert (ROOT / path).is_file(), f"gpu_check.sh names {path}, which does not exist"


def test_unknown_argument_is_a_usage_error():
    proc = subprocess.run(["bash", str(SCRIPT), "--bogus"], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2
    assert "--bogus" in proc.stderr and "--dry-run" in proc.stderr


def _collect(env_value: str | None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "COUPLEKIT_TEST_BACKEND"}
    if env_value is not None:
        env["COUPLEKIT_TEST_BACKEND"] = env_value
    cmd = [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
           "tests/test_solvers_on_backend.py::test_sand_solver_matches_reference"]  # fmt: skip
    return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    "value, ids",
    [(None, ["cpu", "cpu-device"]), ("cuda", ["cuda"]), ("cpu, cuda,cpu", ["cpu", "cuda"])],
    ids=["unset", "cuda", "list"],
)
def test_test_backend_selection(value, ids):
    """COUPLEKIT_TEST_BACKEND picks the kernel_backend fixture's backends (tests/conftest.py)."""
    proc = _collect(value)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert re.findall(r"test_sand_solver_matches_reference\[([\w-]+)\]", proc.stdout) == ids


def test_unknown_test_backend_is_refused():
    proc = _collect("gpu")
    assert proc.returncode != 0
    assert "unknown backend" in proc.stdout + proc.stderr and "cuda" in proc.stdout + proc.stderr


def test_a_named_backend_that_cannot_run_fails_instead_of_skipping():
    """COUPLEKIT_TEST_BACKEND=cuda on a machine without a GPU: the kernel tests fail, so a GPU check whose
    device was not found cannot pass by skipping every test (tests/conftest.py)."""
    from couplekit.backend import cuda_status

    if cuda_status()[0]:
        pytest.skip("a GPU is present: the cuda backend runs")
    env = {k: v for k, v in os.environ.items() if k != "COUPLEKIT_TEST_BACKEND"}
    env["COUPLEKIT_TEST_BACKEND"] = "cuda"
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
           "tests/test_solvers_on_backend.py::test_sand_solver_matches_reference"]  # fmt: skip
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert "COUPLEKIT_TEST_BACKEND names cuda, which is unavailable here" in proc.stdout


def test_memcheck_script_runs_the_simulation_test_scenes():
    """scripts/gpu_memcheck.py steps the scenes of tests/test_simulation_on_backend.py (one list of scenes)."""
    text = (ROOT / "scripts" / "gpu_memcheck.py").read_text()
    assert "from test_simulation_on_backend import CASES" in text
    assert "set_allocator(None)" in text  # each array its own allocation, so memcheck sees overruns


def test_the_gpu_checks_test_path_runs_on_the_stand_in_device(tmp_path):
    """The kernels and solvers steps' tests with COUPLEKIT_TEST_BACKEND=cuda, "cuda" being the stand-in device
    (COUPLEKIT_TEST_STAND_IN=1: CuPy-like arrays that refuse implicit host conversion): the tests' NumPy states
    reach the kernels through HostArrayBackend, results come back to the host, solvers get the bare backend.
    A sample (a sand kernel returning device arrays, the phase-field runner fed a host velocity, a coupled
    simulation) keeps the check's own path working without a GPU."""
    env = {k: v for k, v in os.environ.items() if k not in ("COUPLEKIT_TEST_BACKEND", "COUPLEKIT_TEST_STAND_IN")}
    env.update(COUPLEKIT_TEST_BACKEND="cuda", COUPLEKIT_TEST_STAND_IN="1")
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
           "tests/sand/test_svd.py::test_svd_never_nan_for_degenerate_or_inverted",
           "tests/fluid/test_phasefield_kernels.py::test_full_step_sequence_matches_reference_with_every_boundary",
           "tests/test_simulation_on_backend.py::test_simulation_matches_reference"]  # fmt: skip
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    assert re.search(r"\b8 passed\b", out), out[-3000:]
    assert "skipped" not in out
