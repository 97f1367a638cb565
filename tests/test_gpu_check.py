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
STEPS = ("info", "kernels", "solvers", "throughput", "fig13")

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="bash is not on the PATH")


def _dry_run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SCRIPT), "--dry-run", *args], capture_output=True, text=True, timeout=30)


def test_script_parses():
    proc = subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 0, proc.stderr


def test_dry_run_lists_every_step_within_eight_minutes(tmp_path):
    proc = _dry_run("--out", str(tmp_path / "res"))
    assert proc.returncode == 0, proc.stderr
    steps = re.findall(r"^step (\w+)\s+limit\s+(\d+)s: (.+)$", proc.stdout, re.MULTILINE)
    assert [s[0] for s in steps] == list(STEPS)
    assert sum(int(s[1]) for s in steps) < 8 * 60
    assert str(tmp_path / "res") in proc.stdout
    assert not (tmp_path / "res").exists()  # a dry run creates nothing
    commands = {name: cmd for name, _, cmd in steps}
    assert "--backend cuda" in commands["info"] and "--selfcheck" in commands["info"]
    assert "COUPLEKIT_TEST_BACKEND=cuda" in commands["kernels"] and "COUPLEKIT_TEST_BACKEND=cuda" in commands["solvers"]
    assert "--cells 256" in commands["throughput"] and "--particles 1 4 16" in commands["throughput"]
    assert "examples/fig13_sand_drop_beaker_small.toml --backend cuda" in commands["fig13"]
    # every repository file a step names exists
    for path in re.findall(r"\b((?:tests|benchmarks|examples)/[\w/.-]+\.(?:py|toml))", proc.stdout):
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
