"""Shared fixtures: backends to test on, and a private kernel cache per test session."""

from __future__ import annotations

import os

import numpy as np
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

# COUPLEKIT_TEST_STAND_IN=1 with COUPLEKIT_TEST_BACKEND=cuda: "cuda" is the stand-in device of
# couplekit/backend/standin.py (CuPy-like arrays, the kernels' CUDA code paths built for the host), so that the
# GPU check's test path (HostArrayBackend below) runs without a GPU (tests/test_gpu_check.py)
STAND_IN_ENV = "COUPLEKIT_TEST_STAND_IN"


def pytest_configure(config):
    if os.environ.get(STAND_IN_ENV) == "1" and "cuda" in KERNEL_BACKENDS:
        from couplekit.backend.standin import stand_in_device

        config._couplekit_stand_in = stand_in_device()
        config._couplekit_stand_in.__enter__()


def pytest_unconfigure(config):
    stand_in = getattr(config, "_couplekit_stand_in", None)
    if stand_in is not None:
        stand_in.__exit__(None, None, None)


class _HostArrayFunction:
    """A cuda kernel called with NumPy arrays: each is copied to the device for the launch and back after it (so
    the kernel's in-place outputs land in the caller's array); device arrays and scalars pass through."""

    def __init__(self, fn, backend):
        self._fn, self._backend = fn, backend

    def __getattr__(self, name):
        return getattr(self._fn, name)

    def __call__(self, n, *args):
        dev = [self._backend.asarray(a) if isinstance(a, np.ndarray) else a for a in args]
        self._fn(n, *dev)
        for a, d in zip(args, dev, strict=True):
            if isinstance(a, np.ndarray) and a.flags.writeable:
                a[...] = self._backend.to_host(d)


class _HostArrayModule:
    def __init__(self, module, backend):
        self._module, self._backend = module, backend

    def __getattr__(self, name):
        return getattr(self._module, name)

    def function(self, name):
        return _HostArrayFunction(self._module.function(name), self._backend)


class HostArrayBackend:
    """The cuda backend as the kernel-vs-reference tests use it: they build NumPy states and pass them to the
    kernels (through ``module(...).function(...)`` or ``KernelOps``), which on a GPU take CuPy arrays only; here
    every launch copies its NumPy arrays to the device and back (:class:`_HostArrayFunction`). Everything else
    is the cuda backend's own."""

    def __init__(self, backend):
        self._backend = backend
        self._modules = {}

    def __getattr__(self, name):
        return getattr(self._backend, name)

    def __repr__(self):
        return f"HostArrayBackend({self._backend!r})"

    def to_host(self, a):
        """A NumPy copy of a device array, or of the test's NumPy array (ops read their inputs back, e.g. flags)."""
        return np.array(a, copy=True) if isinstance(a, np.ndarray) else self._backend.to_host(a)

    def module(self, source, defines=None):
        key = (source, tuple(sorted((defines or {}).items())))
        if key not in self._modules:
            self._modules[key] = _HostArrayModule(self._backend.module(source, defines), self._backend)
        return self._modules[key]


def _backend_status(name: str) -> tuple[bool, str]:
    return cuda_status() if name == "cuda" else cpu_status()


def _named_backend(name: str):
    ok, why = _backend_status(name)
    if not ok:
        if os.environ.get(TEST_BACKEND_ENV, "").strip():  # asked for by name: a check that must not pass by skipping
            pytest.fail(f"{TEST_BACKEND_ENV} names {name}, which is unavailable here: {why}")
        pytest.skip(f"{name} backend unavailable: {why}")
    return get_backend(name)


@pytest.fixture(scope="session", params=KERNEL_BACKENDS)
def kernel_backend(request):
    """Each kernel backend in turn (cpu: the host code paths; cpu-device: the CUDA code paths built for the
    host; cuda when COUPLEKIT_TEST_BACKEND names it, wrapped in :class:`HostArrayBackend` so that the tests'
    NumPy states reach the kernels), for kernel-vs-NumPy-reference tests; skips, saying why, where a default
    backend cannot run (no C++ compiler), and fails where one that COUPLEKIT_TEST_BACKEND names cannot (no GPU
    or CuPy): a GPU check must not pass by skipping."""
    backend = _named_backend(request.param)
    return HostArrayBackend(backend) if request.param == "cuda" else backend


@pytest.fixture(scope="session", params=KERNEL_BACKENDS)
def solver_backend(request):
    """The kernel backends of :func:`kernel_backend` as solvers and ``Simulation`` take them (they move their
    own arrays to the device): the same choice, skips and failures, no wrapper."""
    return _named_backend(request.param)


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
