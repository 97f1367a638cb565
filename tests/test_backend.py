"""Backend choice: auto order, COUPLEKIT_BACKEND, forced-but-unavailable errors, threads."""

from __future__ import annotations

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
    with pytest.raises(ValueError, match="threads must be >= 1"):
        get_backend("cpu", threads=0)
