"""Backend choice: auto order, COUPLEKIT_BACKEND, forced-but-unavailable errors, threads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import couplekit.backend as backend_mod
from couplekit.backend import BackendUnavailableError, cuda_status, get_backend


def test_auto_prefers_cuda_then_cpu(monkeypatch):
    monkeypatch.delenv("COUPLEKIT_BACKEND", raising=False)
    monkeypatch.setattr(backend_mod, "cuda_status", lambda: (False, "no GPU in this test"))
    monkeypatch.setattr(backend_mod, "cpu_status", lambda: (True, "compiler present"))
    be = get_backend("auto")
    assert be.name == "cpu"
    assert "no GPU in this test" in be.reason  # the reason says why cuda was skipped


def test_auto_falls_back_to_numpy(monkeypatch):
    monkeypatch.delenv("COUPLEKIT_BACKEND", raising=False)
    monkeypatch.setattr(backend_mod, "cuda_status", lambda: (False, "no GPU"))
    monkeypatch.setattr(backend_mod, "cpu_status", lambda: (False, "no compiler"))
    be = get_backend()
    assert be.name == "numpy" and be.xp is np
    assert "no compiler" in be.reason and not be.has_kernels


def test_environment_variable_overrides_auto(monkeypatch):
    monkeypatch.setenv("COUPLEKIT_BACKEND", "numpy")
    be = get_backend("auto")
    assert be.name == "numpy" and "COUPLEKIT_BACKEND" in be.reason


def test_argument_overrides_environment(monkeypatch):
    monkeypatch.setenv("COUPLEKIT_BACKEND", "cpu")
    assert get_backend("numpy").name == "numpy"


def test_forced_unavailable_backend_is_an_error_not_a_fallback(monkeypatch):
    monkeypatch.setattr(backend_mod, "cpu_status", lambda: (False, "no C++ compiler found"))
    with pytest.raises(BackendUnavailableError, match="no C\\+\\+ compiler found"):
        get_backend("cpu")
    monkeypatch.setenv("COUPLEKIT_BACKEND", "cpu")
    with pytest.raises(BackendUnavailableError, match="COUPLEKIT_BACKEND"):
        get_backend("auto")


def test_cuda_forced_without_gpu_says_why():
    ok, why = cuda_status()
    if ok:
        pytest.skip("a GPU is present")
    with pytest.raises(BackendUnavailableError, match="cannot run here"):
        get_backend("cuda")


def test_unknown_backend_name():
    with pytest.raises(ValueError, match="choose one of"):
        get_backend("tpu")


def test_numpy_backend_compiles_nothing():
    with pytest.raises(BackendUnavailableError, match="NumPy reference"):
        get_backend("numpy").module("selfcheck.cu")


def test_threads_from_argument_and_environment(monkeypatch, cpu_backend):
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert get_backend("cpu").threads == 1
    be = get_backend("cpu", threads=2)
    assert be.threads == 2
    assert be.module("selfcheck.cu").num_threads() == 2
    with pytest.raises(ValueError, match="threads must be a whole number >= 1"):
        get_backend("cpu", threads=0)


def test_more_threads_than_the_machine_can_start_are_refused(monkeypatch, tmp_path):
    """A probe (session 25): ``--threads 99999`` ended in a segmentation fault, leaving a half-made run folder.
    Refused above 8 per core (at least 64), by argument and by OMP_NUM_THREADS, before any folder is made."""
    import subprocess
    import sys

    from couplekit.backend import max_threads

    limit = max_threads()
    with pytest.raises(ValueError, match=f"more than the {limit} couplekit starts"):
        get_backend("cpu", threads=limit + 1)
    monkeypatch.setenv("OMP_NUM_THREADS", str(limit + 1))
    with pytest.raises(ValueError, match=f"OMP_NUM_THREADS={limit + 1} is more than"):
        get_backend("cpu")
    monkeypatch.delenv("OMP_NUM_THREADS")
    scene = Path(__file__).resolve().parents[1] / "examples" / "sand_drop_small.toml"
    out = tmp_path / "run"
    r = subprocess.run(
        [sys.executable, "-m", "couplekit", "run", str(scene), "--threads", "99999", "--out", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 2 and "couplekit starts on this machine" in r.stderr, r.stderr
    assert not out.exists()


def test_data_pointer_is_remembered_only_while_the_array_lives():
    """HostFunction passes each array's data pointer, remembered per live array (couplekit.backend.host.
    data_pointer): the same value as ``a.ctypes.data``, for views too; the entry goes with its array, so an
    array born at a dead one's address (the same id) gets its own pointer."""
    import gc

    from couplekit.backend import host

    a = np.zeros((4, 5), np.float32)
    assert host.data_pointer(a) == a.ctypes.data
    assert host.data_pointer(a) == a.ctypes.data  # remembered
    view = a[1:]
    assert host.data_pointer(view) == view.ctypes.data != a.ctypes.data
    key = id(a)
    del a, view
    gc.collect()
    assert key not in host._POINTERS
    for _ in range(200):  # new arrays, some of them at a freed id: each gets its own pointer
        b = np.empty(7, np.float64)
        assert host.data_pointer(b) == b.ctypes.data
        del b


def test_kernel_sees_a_new_array_at_a_reused_id(cpu1):
    """A kernel writes into the array it is given, also when that array reuses the id of one that has died."""
    fn = cpu1.module("coupling_moisture.cu", {"CK_RETENTION": 0, "CK_TWO_PHASE": 1}).function("coupling_clear")
    for k in range(50):
        a = np.full(16 + 8 * k, k + 1.0, np.float32)  # a new size each time: new memory, ids reused
        fn(a.size, a)
        assert not a.any()
        del a


def test_an_unusable_kernel_cache_or_cxx_is_named_with_the_fix(monkeypatch, tmp_path, capsys):
    """A ``COUPLEKIT_CACHE_DIR`` that is a file is refused when a host backend is built (exit 2 from info and
    run, the run's folder not made), not as a raw FileExistsError at the first build; a ``CXX`` that is not an
    executable is named as such (it read "no host C++ compiler found (set CXX ...)" with CXX set)."""
    from couplekit.backend import KernelCacheError, cpu_status
    from couplekit.cli import main

    cache = tmp_path / "afile"
    cache.write_text("")
    monkeypatch.setenv("COUPLEKIT_CACHE_DIR", str(cache))
    with pytest.raises(KernelCacheError, match="is a file, not a folder: set COUPLEKIT_CACHE_DIR"):
        get_backend("cpu")
    assert main(["info", "--backend", "cpu", "--selfcheck"]) == 2
    assert "COUPLEKIT_CACHE_DIR" in capsys.readouterr().err
    scene = Path(__file__).resolve().parents[1] / "examples" / "sand_drop_small.toml"
    out = tmp_path / "run"
    assert main(["run", str(scene), "--backend", "cpu", "--out", str(out), "--no-progress"]) == 2
    assert "COUPLEKIT_CACHE_DIR" in capsys.readouterr().err and not out.exists()
    monkeypatch.delenv("COUPLEKIT_CACHE_DIR")
    monkeypatch.setenv("CXX", str(tmp_path / "no-such-g++"))
    ok, why = cpu_status()
    assert not ok and f"CXX={tmp_path / 'no-such-g++'} is not an executable C++ compiler" in why
