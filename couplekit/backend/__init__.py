"""Backends: run one kernel source on a GPU (cuda), on the CPU (cpu, host build) or not at all (numpy).

A fourth, ``cpu-device``, is the host build of the kernels' CUDA code paths (``#if CK_ON_GPU``: one loop
iteration per CUDA thread, ``omp atomic`` for atomics; kernels/common.cuh): the algorithms a GPU runs, run
and tested on a machine without one.  It is never chosen by ``auto``.

>>> from couplekit.backend import get_backend
>>> be = get_backend("auto")          # cuda -> cpu -> numpy
>>> print(be.name, "-", be.reason)
>>> mod = be.module("selfcheck.cu", defines={"SOME_EFFECT": 1})
>>> mod.function("scale")(n, x, 2.0)  # arrays of be.xp, checked against the C signature

``COUPLEKIT_BACKEND`` overrides ``auto``; a backend asked for by name that cannot run here is an error
(:class:`BackendUnavailableError`) that says why, never a silent fallback.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from .errors import BackendUnavailableError, KernelArgumentError, KernelBuildError, KernelCacheError
from .host import cache_dir, compiler_version, ensure_cache_dir, find_compiler, no_compiler_message

__all__ = [
    "Backend",
    "BackendUnavailableError",
    "KernelArgumentError",
    "KernelBuildError",
    "KernelCacheError",
    "BACKENDS",
    "NAMED_BACKENDS",
    "cpu_device_status",
    "cpu_status",
    "cuda_status",
    "get_backend",
]

BACKENDS = ("cuda", "cpu", "numpy")
# backends that run only when asked for by name (never picked by "auto")
NAMED_BACKENDS = ("cpu-device",)
# backends whose kernels take the CUDA code paths: the Python side must drive them as it drives a GPU
# (clear a grid before an atomic scatter, no per-thread scratch grids)
GPU_CODE_PATH_BACKENDS = ("cuda", "cpu-device")


def cuda_status() -> tuple[bool, str]:
    """(usable, why): whether CuPy imports and finds a CUDA device."""
    try:
        import cupy
    except Exception as exc:  # ImportError, or a broken CUDA install
        return False, f"CuPy is not importable ({type(exc).__name__}: {exc}); install couplekit[cuda]"
    try:
        count = cupy.cuda.runtime.getDeviceCount()
    except Exception as exc:
        return False, f"CuPy {cupy.__version__} finds no usable CUDA device ({exc})"
    if count < 1:
        return False, f"CuPy {cupy.__version__} finds no CUDA device"
    name = cupy.cuda.runtime.getDeviceProperties(0)["name"]
    name = name.decode() if isinstance(name, bytes) else name
    return True, f"CUDA device 0: {name} (CuPy {cupy.__version__})"


def cpu_status() -> tuple[bool, str]:
    """(usable, why): whether a host C++ compiler with OpenMP is present."""
    cxx = find_compiler()
    if cxx is None:
        return False, no_compiler_message()
    return True, f"host build with {compiler_version(cxx)}"


def cpu_device_status() -> tuple[bool, str]:
    """(usable, why): the cpu-device backend needs what the cpu backend needs, a host C++ compiler."""
    ok, why = cpu_status()
    if not ok:
        return ok, why
    return True, f"CUDA code paths (CK_DEVICE_PATH) {why}"


@dataclass
class Backend:
    """A place to run solver stages: array module ``xp`` plus, for cuda/cpu, compiled kernel modules."""

    name: str
    reason: str
    threads: int | None = None
    _modules: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if self.name in ("cpu", "cpu-device"):  # a kernel cache that is a file: refused now, not at the first build
            ensure_cache_dir()

    @property
    def xp(self) -> ModuleType:
        """The array module of this backend: ``cupy`` for cuda, ``numpy`` otherwise."""
        if self.name == "cuda":
            import cupy

            return cupy
        return np

    @property
    def gpu_code_paths(self) -> bool:
        """True when the kernels run their CUDA code paths (cuda, and cpu-device: the same code on the host)."""
        return self.name in GPU_CODE_PATH_BACKENDS

    @property
    def has_kernels(self) -> bool:
        """True when stages run as compiled kernels (cuda, cpu); False for the NumPy reference."""
        return self.name != "numpy"

    def module(self, source: str, defines: dict[str, Any] | None = None):
        """The compiled kernel module for ``source`` (a file in ``kernels/``) and ``defines``, built once."""
        if not self.has_kernels:
            raise BackendUnavailableError(
                "the numpy backend runs the NumPy reference ops and compiles no kernels; "
                "use backend='cpu' or 'cuda' for kernels"
            )
        key = (source, tuple(sorted((defines or {}).items())))
        if key not in self._modules:
            if self.name == "cuda":
                from .cuda import CudaModule

                self._modules[key] = CudaModule(source, defines)
            else:
                from .host import HostModule

                self._modules[key] = HostModule(
                    source, defines, threads=self.threads, device_path=self.name == "cpu-device"
                )
        return self._modules[key]

    def asarray(self, a, dtype=None):
        """Copy/convert ``a`` to this backend's array type (C-contiguous)."""
        return self.xp.ascontiguousarray(self.xp.asarray(a, dtype=dtype))

    def to_host(self, a) -> np.ndarray:
        """A NumPy copy of a backend array."""
        if self.name == "cuda":
            return a.get()
        return np.array(a, copy=True)

    def synchronize(self) -> None:
        """Wait for queued GPU work (no-op on the CPU); call before timing."""
        if self.name == "cuda":
            import cupy

            cupy.cuda.Device().synchronize()

    def describe(self) -> str:
        """One line: the backend, and why it was chosen."""
        return f"backend: {self.name} ({self.reason})"


def max_threads() -> int:
    """The most OpenMP threads a cpu backend accepts: 8 per core of this machine, at least 64. Far more only
    exhausts memory starting them (a probe: --threads 99999 ended in a segmentation fault)."""
    return max(64, 8 * (os.cpu_count() or 1))


def _threads_from(threads: int | None) -> int | None:
    limit = max_threads()
    if threads is not None:
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
            raise ValueError(
                f"threads must be a whole number >= 1 (OpenMP threads of the cpu backends), got {threads!r}"
            )
        if threads > limit:
            raise ValueError(
                f"threads = {threads} is more than the {limit} couplekit starts on this machine ({os.cpu_count()} "
                f"cores; the limit is 8 per core, at least 64): use at most {os.cpu_count()}, one per core, for speed"
            )
        return int(threads)
    env = os.environ.get("OMP_NUM_THREADS")
    if env:
        try:
            n = max(1, int(env.split(",")[0]))
        except ValueError:
            raise ValueError(f"OMP_NUM_THREADS={env!r} is not a whole number") from None
        if n > limit:
            raise ValueError(
                f"OMP_NUM_THREADS={env} is more than the {limit} threads couplekit starts on this machine "
                f"({os.cpu_count()} cores; the limit is 8 per core, at least 64): set it to at most {os.cpu_count()}"
            )
        return n
    return None


def get_backend(name: str | None = "auto", threads: int | None = None) -> Backend:
    """Choose a backend.

    ``name``: ``"auto"`` (cuda, else cpu, else numpy), ``"cuda"``, ``"cpu"``, ``"numpy"`` or
    ``"cpu-device"`` (the kernels' CUDA code paths built for the host; for testing them without a GPU);
    ``None`` or ``"auto"`` defer to ``$COUPLEKIT_BACKEND`` when it is set. ``threads``: OpenMP threads of
    the cpu and cpu-device backends (default: ``$OMP_NUM_THREADS``, else all cores).
    """
    if name is not None and not isinstance(name, str):
        raise TypeError(
            f"backend must be a name ({', '.join(repr(b) for b in ('auto', *BACKENDS, 'cpu-device'))}) or a "
            f"Backend, got {name!r} ({type(name).__name__})"
        )
    if name is not None and not name.strip():
        raise ValueError("backend is an empty name: give one of auto, cuda, cpu, numpy, cpu-device (or None for auto)")
    source = "argument"
    if name in (None, "auto") and os.environ.get("COUPLEKIT_BACKEND"):
        name, source = os.environ["COUPLEKIT_BACKEND"].strip().lower(), "COUPLEKIT_BACKEND"
    name = (name or "auto").lower()
    threads = _threads_from(threads)
    checks = {
        "cuda": cuda_status,
        "cpu": cpu_status,
        "numpy": lambda: (True, "NumPy reference ops"),
        "cpu-device": cpu_device_status,
    }
    if name == "auto":
        skipped = []
        for candidate in BACKENDS:
            ok, why = checks[candidate]()
            if ok:
                reason = f"auto: {why}" + (f"; skipped {'; '.join(skipped)}" if skipped else "")
                return Backend(candidate, reason, threads)
            skipped.append(f"{candidate}: {why}")
        raise AssertionError("unreachable: the numpy backend is always available")
    if name not in checks:
        raise ValueError(
            f"unknown backend {name!r} (from {source}); choose one of auto, {', '.join(BACKENDS + NAMED_BACKENDS)}"
        )
    ok, why = checks[name]()
    if not ok:
        raise BackendUnavailableError(f"backend {name!r} was requested ({source}) but cannot run here: {why}")
    return Backend(name, f"requested by {source}: {why}", threads)


def host_tools() -> dict[str, str]:
    """Versions of the tools the runtime can use, for ``couplekit info``."""
    cxx = find_compiler()
    nvcc = shutil.which("nvcc")
    return {
        "host compiler": f"{cxx} ({compiler_version(cxx)})" if cxx else "not found",
        "nvcc": nvcc or "not found",
        "kernel cache": str(cache_dir()),
    }
