"""Shared fixtures: backends to test on, and a private kernel cache per test session."""

from __future__ import annotations

import os

import pytest

from couplekit.backend import cpu_status, cuda_status, get_backend


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


# the kernel backends a kernel-vs-reference test runs on: the host code paths and the CUDA ones built for the
# host; COUPLEKIT_TEST_BACKEND (comma-separated names, e.g. "cuda" on a GPU machine: scripts/gpu_check.sh)
# replaces them
DEFAULT_KERNEL_BACKENDS = ("cpu", "cpu-device")
TEST_BACKEND_ENV = "COUPLEKIT_TEST_BACKEND"


def kernel_backends_from_env(value: str | None) -> tuple[str, ...]:
    """The kernel backends named by COUPLEKIT_TEST_BACKEND's ``value`` (the defaults when unset or empty);
    a ValueError naming the valid choices for an unknown name."""
    if not value or not value.strip():
        return DEFAULT_KERNEL_BACKENDS
    names = tuple(dict.fromkeys(n.strip() for n in value.split(",") if n.strip()))
    unknown = [n for n in names if n not in ("cpu", "cpu-device", "cuda")]
    if unknown:
        raise ValueError(f"{TEST_BACKEND_ENV}={value!r}: unknown backend(s) {unknown}; use cpu, cpu-device, cuda")
    return names


KERNEL_BACKENDS = kernel_backends_from_env(os.environ.get(TEST_BACKEND_ENV))


def _backend_status(name: str) -> tuple[bool, str]:
    return cuda_status() if name == "cuda" else cpu_status()


@pytest.fixture(scope="session", params=KERNEL_BACKENDS)
def kernel_backend(request):
    """Each kernel backend in turn (cpu: the host code paths; cpu-device: the CUDA code paths built for the
    host; cuda when COUPLEKIT_TEST_BACKEND names it), for kernel-vs-NumPy-reference tests; skips, saying why,
    where a backend cannot run (no C++ compiler; no GPU or CuPy)."""
    ok, why = _backend_status(request.param)
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
