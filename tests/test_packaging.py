"""The wheel carries the kernel sources and the schedulers package; installed and editable imports work."""

from __future__ import annotations

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

import couplekit
from couplekit.backend.sources import kernel_dir

ROOT = Path(__file__).resolve().parents[1]


def test_kernel_sources_importable_as_package():
    import couplekit.kernels  # noqa: F401
    import couplekit.schedulers  # noqa: F401

    assert (kernel_dir() / "common.cuh").is_file() and (kernel_dir() / "selfcheck.cu").is_file()


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(ROOT)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    (path,) = out.glob("couplekit-*.whl")
    return path


def test_wheel_contains_kernels_and_schedulers(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for src in kernel_dir().iterdir():
        if src.suffix in (".cu", ".cuh"):
            assert f"couplekit/kernels/{src.name}" in names, f"{src.name} missing from the wheel"
    assert "couplekit/schedulers/__init__.py" in names
    for init in (ROOT / "couplekit").rglob("__init__.py"):  # every subpackage is found and shipped
        assert init.relative_to(ROOT).as_posix() in names, f"{init} missing from the wheel"
    assert "couplekit/backend/host.py" in names


def test_installed_wheel_builds_and_runs_kernels(wheel, tmp_path):
    target = tmp_path / "site"
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
    code = (
        "import couplekit, couplekit.backend.sources as s;"
        "from couplekit.selfcheck import run_selfcheck;"
        "print(s.kernel_dir());"
        "print(all(r.ok for r in run_selfcheck(couplekit.get_backend('cpu'))))"
    )
    env = {
        "PYTHONPATH": str(target),
        "PATH": "/usr/bin:/bin:/usr/local/bin",
        "COUPLEKIT_CACHE_DIR": str(tmp_path / "c"),
    }
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    kdir, ok = run.stdout.split()
    assert Path(kdir).is_relative_to(target) and ok == "True"


def test_version_is_exposed():
    assert couplekit.__version__ == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
