"""Shared fixtures: backends to test on, and a private kernel cache per test session."""

from __future__ import annotations

import os

import pytest

from couplekit.backend import cpu_status, get_backend


@pytest.fixture(scope="session")
def cpu_backend():
    """The host-build backend; skips (saying why) where no C++ compiler is present."""
    ok, why = cpu_status()
    if not ok:
        pytest.skip(f"cpu backend unavailable: {why}")
    return get_backend("cpu")


@pytest.fixture(scope="session")
def cpu1():
    """The cpu backend on one OpenMP thread (grids of a few thousand cells); skips where it cannot run. The
    coupling tests' conftest defines its own of the same name."""
    ok, why = cpu_status()
    if not ok:
        pytest.skip(f"cpu backend unavailable: {why}")
    return get_backend("cpu", threads=1)


@pytest.fixture(scope="session")
def cpu_device():
    """The cpu-device backend: the kernels' CUDA code paths (CK_ON_GPU) built by the host compiler, one OpenMP
    loop iteration per CUDA thread; skips where no C++ compiler is present."""
    ok, why = cpu_status()
    if not ok:
        pytest.skip(f"cpu-device backend unavailable: {why}")
    return get_backend("cpu-device")


# the kernel backends a kernel-vs-reference test runs on: the host code paths and the CUDA ones
KERNEL_BACKENDS = ("cpu", "cpu-device")


@pytest.fixture(scope="session", params=KERNEL_BACKENDS)
def kernel_backend(request):
    """Each kernel backend in turn (cpu: the host code paths; cpu-device: the CUDA code paths built for the
    host), for kernel-vs-NumPy-reference tests; skips where no C++ compiler is present."""
    ok, why = cpu_status()
    if not ok:
        pytest.skip(f"{request.param} backend unavailable: {why}")
    return get_backend(request.param)


@pytest.fixture(scope="session")
def numpy_backend():
    """The NumPy reference backend."""
    return get_backend("numpy")


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    """A fresh, empty kernel cache directory for tests that count builds."""
    cache = tmp_path / "kernel-cache"
    monkeypatch.setenv("COUPLEKIT_CACHE_DIR", str(cache))
    return cache


def pytest_report_header(config):
    return f"couplekit kernel cache: {os.environ.get('COUPLEKIT_CACHE_DIR', 'default')}"
